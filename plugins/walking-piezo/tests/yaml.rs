//! The blocks from YAML: every tag registers and deserialises with its defaults,
//! unknown fields and bad values are refused by name, and the shipped example graph
//! runs.

use nanomotion_core::graph::GraphSpec;
use nanomotion_core::{Block, BuildContext};
// Anchor: linking alone must register the blocks (see DEPENDENCIES.md).
use walking_piezo as _;

const TAGS: [&str; 7] = [
    "walking_piezo_driver",
    "walking_piezo_switched",
    "walking_piezo_linear",
    "walking_piezo_fitted",
    "walking_piezo_legs",
    "walking_piezo_stage",
    "walking_waveform",
];

#[test]
fn every_tag_deserialises_with_defaults_and_builds() {
    let registered = nanomotion_core::block::registered_types();
    let docs: Vec<&str> = nanomotion_core::block::block_docs()
        .iter()
        .map(|d| d.type_name)
        .collect();
    for tag in TAGS {
        assert!(
            registered.iter().any(|t| t == tag),
            "{tag} not registered: {registered:?}"
        );
        assert!(docs.contains(&tag), "{tag} has no BlockDoc");
        let mut b: Box<dyn Block> =
            nanomotion_core::yaml::from_str(&format!("type: {tag}\n"), "test").unwrap();
        b.build(&BuildContext::new("b", 1.0 / 4000.0, 1)).unwrap();
        assert!(!b.outputs().is_empty());
    }
}

#[test]
fn unknown_fields_and_bad_values_name_the_field() {
    let e = nanomotion_core::yaml::from_str::<Box<dyn Block>>(
        "type: walking_piezo_stage\nmass_kg: 1.0\n",
        "t",
    )
    .unwrap_err();
    assert!(e.to_string().contains("mass_kg"), "{e}");
    let mut b: Box<dyn Block> =
        nanomotion_core::yaml::from_str("type: walking_piezo_stage\npreload_n: -5\n", "t").unwrap();
    let e = b.build(&BuildContext::new("s", 25e-6, 0)).unwrap_err();
    assert_eq!(e.field, "preload_n");
}

#[test]
fn plant_blocks_expose_their_discrete_models() {
    let mut b: Box<dyn Block> =
        nanomotion_core::yaml::from_str("type: walking_piezo_fitted\n", "t").unwrap();
    b.build(&BuildContext::new("g", 1.0 / 4000.0, 0)).unwrap();
    let l = b.lti().unwrap();
    assert_eq!(l.dt, Some(1.0 / 4000.0));
    assert_eq!(l.nstates(), 8);
    assert!(!b.direct_feedthrough());
}

#[test]
fn example_graph_runs_and_walks() {
    let path = concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../../examples/walking_piezo_open_loop.yaml"
    );
    let mut spec = GraphSpec::from_file(path).unwrap();
    spec.duration_s = 0.2; // keep the test short
    let (mut sched, _report) = spec.build().unwrap();
    let res = sched.run(|_| {});
    sched.check_finite().unwrap();
    let x = res
        .logs
        .iter()
        .find(|l| l.name == "stage.x_s")
        .unwrap()
        .column(0);
    let nonconv = res
        .logs
        .iter()
        .find(|l| l.name == "stage.nonconverged")
        .unwrap()
        .column(0);
    // 0.2 s at 10 Hz: two cycles of several µm.
    let travel = x.last().unwrap() - x[0];
    assert!(travel > 4e-6 && travel < 20e-6, "travel {travel}");
    assert_eq!(*nonconv.last().unwrap(), 0.0);
}

/// `shape.overlap_q` ∈ (0, 1) is declared on the waveform's variants and
/// reached through `#[param(nested)]` (#26): the same field is refused, the
/// schema states the open interval.
#[test]
fn overlap_q_is_a_declared_open_interval() {
    use nanomotion_core::doc::Params;
    use walking_piezo::driver::{DriverParams, WaveformShape};
    for q in [0.0, 1.0, f64::NAN] {
        for shape in [
            WaveformShape::Asymmetric { overlap_q: q },
            WaveformShape::AsymmetricFourier { overlap_q: q },
        ] {
            let e = DriverParams {
                shape,
                ..Default::default()
            }
            .validate()
            .unwrap_err();
            assert_eq!(e.field, "shape.overlap_q");
            if q.is_finite() {
                assert_eq!(e.problem, format!("is {q}, not in (0, 1)"));
                assert_eq!(
                    e.fix,
                    "give a value in (0, 1), the relative overlap, e.g. 0.3333 (thesis)"
                );
            }
        }
    }
    assert!(DriverParams::default().validate().is_ok());
    let docs = DriverParams::param_docs();
    let shape = &docs.iter().find(|p| p.name == "shape").unwrap().schema;
    let asym = shape["anyOf"]
        .as_array()
        .unwrap()
        .iter()
        .find(|b| b["properties"]["kind"]["const"] == "asymmetric")
        .unwrap();
    assert_eq!(asym["properties"]["overlap_q"]["exclusiveMinimum"], 0);
    assert_eq!(asym["properties"]["overlap_q"]["exclusiveMaximum"], 1);
}

#[test]
fn the_stage_has_the_ports_its_block_declares_and_fills_every_output() {
    // `f_ext` exists with `external_force_input: true`; the outputs are the
    // 18 values the model writes per tick (`WalkingPiezoStage::plant_output`).
    let ports = |text: &str| {
        let b: Box<dyn Block> = nanomotion_core::yaml::from_str(text, "t").unwrap();
        let named = |p: Vec<nanomotion_core::Port>| -> Vec<(String, usize, Option<String>)> {
            p.into_iter().map(|p| (p.name, p.width, p.unit)).collect()
        };
        (named(b.inputs()), named(b.outputs()))
    };
    let (ins, outs) = ports("type: walking_piezo_stage\n");
    assert_eq!(ins, [("u".to_string(), 4, Some("V".to_string()))]);
    let (ins_f, outs_f) = ports("type: walking_piezo_stage\nexternal_force_input: true\n");
    assert_eq!(
        ins_f,
        [
            ("u".to_string(), 4, Some("V".to_string())),
            ("f_ext".to_string(), 1, Some("N".to_string()))
        ]
    );
    assert_eq!(outs, outs_f);
    let widths: Vec<(&str, usize)> = outs.iter().map(|(n, w, _)| (n.as_str(), *w)).collect();
    assert_eq!(
        widths,
        [
            ("x_s", 1),
            ("v_s", 1),
            ("x_legs", 2),
            ("y_legs", 2),
            ("y_h", 1),
            ("f_n", 2),
            ("friction", 2),
            ("slip", 2),
            ("mu", 2),
            ("iterations", 1),
            ("nonconverged", 1),
            ("faults", 1)
        ]
    );
    assert_eq!(widths.iter().map(|(_, w)| w).sum::<usize>(), 18);
    assert!(outs.iter().all(|(_, _, unit)| unit.is_none()));
}
