//! The example graph `examples/afm_hysteresis_ff.yaml` builds and runs, and the
//! hysteresis feed-forward keeps the x error of the second scan period small.

use afm_stage as _; // link the crate so that its blocks are registered
use nanomotion_core::GraphSpec;

#[test]
fn afm_hysteresis_ff_example_runs() {
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../../examples/afm_hysteresis_ff.yaml");
    let spec = GraphSpec::from_file(&path).unwrap();
    let (mut sched, _report) = spec.build().unwrap();
    let res = sched.run(|_| {});
    let s = &res.scores[0];
    eprintln!(
        "example: rms {:.2} nm, max {:.2} nm over {} samples",
        s.rms * 1e9,
        s.max_abs * 1e9,
        s.samples
    );
    // Noise alone gives σ ≈ 1.7 nm; the feed-forward leaves a few nm of hysteresis
    // misfit plus the ringing after each turnaround.
    assert!(s.rms < 10e-9, "rms {}", s.rms);
    assert!(s.samples > 40_000);
}
