//! A hysteretic restoring force inside the loop (Bouc–Wen, as the diagnosis
//! names it on the Noël–Schoukens benchmark): compensated by the fitted force at
//! the reference, subtracted at the plant input. The augmented model is written
//! here as `diagnose` writes it (the force block and its sum).

mod support;

use nanomotion_compensate::{Options, compensate, named};
use nanomotion_core::graph::GraphSpec;

const STAGE: &str = "{ name: stage, type: state_space, a: [[0.0, 1.0], [-1000.0, -10.0]], b: [[0.0], [1000.0]], c: [[1.0, 0.0]], discretisation: zoh }";

#[test]
fn a_hysteretic_force_in_the_loop_gets_a_feed_forward_at_the_reference() {
    let _ = std::any::type_name::<nanomotion_plf::effects::Effect>();
    let aug = GraphSpec::from_yaml(
        &format!("base_rate_hz: 1000\nduration_s: 1\nblocks:\n  - {{ name: drive, type: data_column, column: u }}\n  - {STAGE}\n  - {{ name: plf_hysteresis, type: bouc_wen, a: -0.5, beta: 4.0, gamma: 1.0 }}\n  - {{ name: plf_hysteresis_sum, type: sum, signs: \"++\" }}\nconnections:\n  - {{ from: drive.y, to: plf_hysteresis_sum.in0 }}\n  - {{ from: plf_hysteresis.y, to: plf_hysteresis_sum.in1 }}\n  - {{ from: plf_hysteresis_sum.y, to: stage.u }}\n  - {{ from: stage.y, to: plf_hysteresis.u }}\ncompare:\n  - {{ signal: stage.y, column: y }}\n"),
        "model_augmented.yaml",
    )
    .unwrap();
    let controller = GraphSpec::from_yaml(
        &format!("base_rate_hz: 1000\nduration_s: 3\nblocks:\n  - {{ name: ref, type: sinusoid, amplitude: 0.5, frequency_hz: 2.0 }}\n  - {{ name: err, type: sum, signs: \"+-\" }}\n  - {{ name: pid, type: pid, kp: 2.0, ki: 20.0 }}\n  - {STAGE}\nconnections:\n  - {{ from: ref.y, to: err.in0 }}\n  - {{ from: stage.y, to: err.in1 }}\n  - {{ from: err.y, to: pid.e }}\n  - {{ from: pid.u, to: stage.u }}\nscore:\n  - {{ signal: err.y, from_s: 1.0 }}\n"),
        "controller.yaml",
    )
    .unwrap();
    let out = compensate(
        &aug,
        &controller,
        &named::from_graph(&aug),
        &Options::default(),
    )
    .unwrap();
    let r = &out.report;
    let c = &r.compensators[0];
    assert_eq!(c.type_name, "bouc_wen");
    let g = &out.compensated;
    let reads = |from: &str, to: &str| g.connections.iter().any(|c| c.from == from && c.to == to);
    assert!(reads("ref.y", "comp_hysteresis.u"));
    assert!(reads("comp_hysteresis.y", "comp_hysteresis_sum.in1"));
    assert!(reads("comp_hysteresis_sum.y", "stage.u"));
    // Most of the error the force adds is gone, and the total with it.
    assert!(c.effect_error_cut_percent > 50.0, "{c:?}");
    assert!(c.kept && r.after.rms < r.before.rms, "{r:?}");
    // The written graph on the wall clock, bit for bit as offline.
    assert!(r.gate.passes);
    support::runs_on_the_wall_clock_as_offline(&out.compensated, &["comp_hysteresis.y"]);
}
