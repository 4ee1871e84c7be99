//! The repository's `examples/encoder_hots.yaml` builds and runs with these blocks.

use hots as _;
use timestamp_encoder as _;

#[test]
fn encoder_hots_yaml_runs() {
    let path = concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../../examples/encoder_hots.yaml"
    );
    let graph = nanomotion_core::GraphSpec::from_file(path).expect("parses");
    let (mut sched, _report) = graph.build().expect("builds");
    sched.step_n(20_000);
    let id = sched.signal_id("pos_err.y").expect("pos_err.y exists");
    let e = sched.read(id)[0];
    // Within one count (2π/400 rad) of the truth at the end.
    assert!(e.is_finite() && e.abs() < 0.0157, "{e}");
    let v = sched.read(sched.signal_id("est.y").unwrap())[1];
    assert!(v.is_finite());
}
