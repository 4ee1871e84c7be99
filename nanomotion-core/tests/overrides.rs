//! Parameter overrides applied to the shipped quickstart graph
//! (`examples/quickstart.yaml`), checked on the built graph.

use nanomotion_core::GraphError;
use nanomotion_core::graph::GraphSpec;
use nanomotion_core::overrides::Override;

const QUICKSTART: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/../examples/quickstart.yaml");

fn set(list: &[&str]) -> Vec<Override> {
    list.iter().map(|s| Override::parse(s).unwrap()).collect()
}

fn build(list: &[&str]) -> nanomotion_core::Scheduler {
    GraphSpec::from_file_with_overrides(QUICKSTART, &set(list))
        .unwrap()
        .build()
        .unwrap()
        .0
}

/// A field of a built block, read back through its serialised form.
fn field(sched: &nanomotion_core::Scheduler, block: &str, key: &str) -> serde_json::Value {
    serde_json::to_value(sched.block(block).unwrap()).unwrap()[key].clone()
}

#[test]
fn overridden_values_reach_the_built_graph() {
    let plain = build(&[]);
    assert_eq!(field(&plain, "pi", "kp"), serde_json::json!(3.1416e7));
    let s = build(&[
        "blocks.pi.kp=2.0",
        "duration_s=0.6",
        "seed=3",
        "blocks.stage.den.1=50.0",
        "blocks[1].signs=++",
    ]);
    assert_eq!(field(&s, "pi", "kp"), serde_json::json!(2.0));
    assert_eq!(
        field(&s, "stage", "den"),
        serde_json::json!([0.255, 50.0, 3.32837e6, 0.0])
    );
    assert_eq!(field(&s, "err", "signs"), serde_json::json!("++"));
    // 0.6 s at the 40 kHz base rate.
    assert_eq!(s.ticks_total(), 24_000);
    // Untouched fields keep the file's values.
    assert_eq!(field(&s, "encoder", "lsb"), serde_json::json!(5.0e-9));
}

#[test]
fn seed_and_defaults_can_be_set() {
    let spec = GraphSpec::from_file_with_overrides(QUICKSTART, &set(&["seed=3"])).unwrap();
    assert_eq!(spec.seed, 3);
    // `rate_hz` of `stage` is left out of the file (base rate): it may be set.
    let spec =
        GraphSpec::from_file_with_overrides(QUICKSTART, &set(&["blocks.stage.rate_hz=20000"]))
            .unwrap();
    let stage = spec.blocks.iter().find(|b| b.name == "stage").unwrap();
    assert_eq!(stage.rate_hz, Some(20000.0));
}

/// The PI's first output is kp · e(0) (the integrator state starts at zero), so
/// doubling kp by override doubles it: the override acts in the simulation.
#[test]
fn doubling_kp_doubles_the_first_control_output() {
    let first_u = |kp: &str| {
        let mut s = build(&[
            "duration_s=0.01",
            "score.0.from_s=0",
            "score[1].from_s=0",
            &format!("blocks.pi.kp={kp}"),
        ]);
        let r = s.run(|_| {});
        let u = r.logs.iter().find(|l| l.name == "pi.u").unwrap();
        let k = u.data.iter().position(|x| *x != 0.0).unwrap();
        (k, u.data[k])
    };
    let (k1, u1) = first_u("1.0e6");
    let (k2, u2) = first_u("2.0e6");
    assert_eq!(k1, k2);
    assert!(((u2 / u1) - 2.0).abs() < 1e-12, "{u1} {u2}");
}

fn err(list: &[&str]) -> String {
    let e = GraphSpec::from_file_with_overrides(QUICKSTART, &set(list)).unwrap_err();
    assert!(matches!(e, GraphError::Override { .. }), "{e:?}");
    e.to_string()
}

#[test]
fn bad_paths_name_the_path_the_nearest_key_and_the_fix() {
    let e = err(&["blocks.pi.kpp=2"]);
    assert!(
        e.starts_with("override `blocks.pi.kpp`: no key `kpp` in `blocks.pi`"),
        "{e}"
    );
    assert!(e.contains("did you mean `blocks.pi.kp`?"), "{e}");
    let e = err(&["blocks.pl.kp=2"]);
    assert!(e.contains("no entry named `pl` in `blocks`"), "{e}");
    assert!(e.contains("did you mean `blocks.pi`?"), "{e}");
    let e = err(&["durration_s=1"]);
    assert!(e.contains("did you mean `duration_s`?"), "{e}");
    let e = err(&["blocks.stage.den.7=1"]);
    assert!(e.contains("has 4 entries, there is no index 7"), "{e}");
    let e = err(&["blocks.pi.kp.x=1"]);
    assert!(
        e.contains("`blocks.pi.kp` is a number, it has no `x`"),
        "{e}"
    );
}

#[test]
fn type_mismatches_are_errors() {
    let e = err(&["blocks.pi.kp=fast"]);
    assert!(e.contains("is a number") && e.contains("a string"), "{e}");
    let e = err(&["seed=1.5"]);
    assert!(e.contains("give a whole number"), "{e}");
    let e = err(&["blocks.stage.den=3"]);
    assert!(e.contains("give a list"), "{e}");
    // A value of the right type the block then rejects is caught when built.
    let spec = GraphSpec::from_file_with_overrides(QUICKSTART, &set(&["blocks.encoder.lsb=-1.0"]))
        .unwrap();
    let e = spec.build().unwrap_err().to_string();
    assert!(e.contains("encoder") && e.contains("lsb"), "{e}");
}
