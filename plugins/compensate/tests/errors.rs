//! Bad input to `compensate`: each a typed error naming the place and the fix.

use nanomotion_compensate::{CompError, NamedEffect, Options, compensate, named};
use nanomotion_core::graph::GraphSpec;

/// An augmented model as `diagnose` writes it: a hysteresis on the drive.
fn augmented() -> GraphSpec {
    let _ = std::any::type_name::<nanomotion_plf::effects::Effect>();
    GraphSpec::from_yaml(
        "base_rate_hz: 1000\nduration_s: 1\nblocks:\n  - { name: drive, type: data_column, column: u }\n  - { name: stage, type: state_space, a: [[0.0, 1.0], [-1000.0, -10.0]], b: [[0.0], [1000.0]], c: [[1.0, 0.0]], discretisation: zoh }\n  - { name: plf_hysteresis, type: hysteresis, alpha: 2.0, b: 1.0, c: 0.7 }\nconnections:\n  - { from: drive.y, to: plf_hysteresis.u }\n  - { from: plf_hysteresis.y, to: stage.u }\ncompare:\n  - { signal: stage.y, column: y }\n",
        "model_augmented.yaml",
    )
    .unwrap()
}

fn controller(score: &str) -> GraphSpec {
    GraphSpec::from_yaml(
        &format!("base_rate_hz: 1000\nduration_s: 1\nblocks:\n  - {{ name: ref, type: sinusoid, amplitude: 0.5, frequency_hz: 2.0 }}\n  - {{ name: err, type: sum, signs: \"+-\" }}\n  - {{ name: pid, type: pid, kp: 2.0, ki: 20.0 }}\n  - {{ name: stage, type: state_space, a: [[0.0, 1.0], [-1000.0, -10.0]], b: [[0.0], [1000.0]], c: [[1.0, 0.0]], discretisation: zoh }}\nconnections:\n  - {{ from: ref.y, to: err.in0 }}\n  - {{ from: stage.y, to: err.in1 }}\n  - {{ from: err.y, to: pid.e }}\n  - {{ from: pid.u, to: stage.u }}\n{score}"),
        "controller.yaml",
    )
    .unwrap()
}

#[test]
fn the_effects_are_found_in_the_augmented_graph_without_a_report() {
    let e = named::from_graph(&augmented());
    assert_eq!(
        e,
        vec![NamedEffect {
            effect: "hysteresis".into(),
            block: "plf_hysteresis".into(),
            site: String::new()
        }]
    );
}

#[test]
fn a_loop_without_a_score_is_refused_naming_the_section() {
    let aug = augmented();
    let e = compensate(
        &aug,
        &controller(""),
        &named::from_graph(&aug),
        &Options::default(),
    )
    .unwrap_err();
    assert!(matches!(e, CompError::Input { .. }), "{e}");
    assert!(
        e.to_string().contains("`score:`") && e.to_string().contains("fix:"),
        "{e}"
    );
}

#[test]
fn no_named_effect_is_refused() {
    let e = compensate(
        &augmented(),
        &controller("score:\n  - { signal: err.y }\n"),
        &[],
        &Options::default(),
    )
    .unwrap_err();
    assert!(e.to_string().contains("names no effect"), "{e}");
}

#[test]
fn a_report_that_is_not_a_diagnosis_is_refused() {
    let e = named::from_report_json("{\"found\": []}", "r.json").unwrap_err();
    assert!(
        e.to_string().contains("r.json") && e.to_string().contains("`steps`"),
        "{e}"
    );
    let e =
        named::from_report_json("{\"steps\": [{\"effect\": \"friction\"}]}", "r.json").unwrap_err();
    assert!(e.to_string().contains("steps[0].block.name"), "{e}");
}

#[test]
fn the_inverse_on_a_small_loop_cuts_the_error_and_passes_the_gate() {
    let aug = augmented();
    let out = compensate(
        &aug,
        &controller("score:\n  - { signal: err.y, from_s: 0.5 }\n"),
        &named::from_graph(&aug),
        &Options::default(),
    )
    .unwrap();
    let r = &out.report;
    assert_eq!(r.compensators[0].type_name, "hysteresis_inverse");
    // The stage's static gain 1000/1000 = 1: the probe (the mean of the last
    // tenth of a 1 s open-loop run, settled to 1 %) finds it within 1 %.
    assert!(
        (r.compensators[0].design["static_gain"] - 1.0).abs() < 0.01,
        "{r:?}"
    );
    assert!(r.gate.passes);
    assert!(r.after.rms < r.before.rms);
}

#[test]
fn a_time_delay_states_the_phase_margin_it_takes_in_the_re_tune() {
    let aug = GraphSpec::from_yaml(
        "base_rate_hz: 1000\nduration_s: 1\nblocks:\n  - { name: drive, type: data_column, column: u }\n  - { name: stage, type: state_space, a: [[0.0, 1.0], [-1000.0, -10.0]], b: [[0.0], [1000.0]], c: [[1.0, 0.0]], discretisation: zoh }\n  - { name: plf_time_delay, type: time_delay, max_delay_s: 0.01, delay_s: 0.002 }\nconnections:\n  - { from: drive.y, to: plf_time_delay.u }\n  - { from: plf_time_delay.y, to: stage.u }\ncompare:\n  - { signal: stage.y, column: y }\n",
        "model_augmented.yaml",
    )
    .unwrap();
    let out = compensate(
        &aug,
        &controller("score:\n  - { signal: err.y, from_s: 0.5 }\n"),
        &named::from_graph(&aug),
        &Options::default(),
    )
    .unwrap();
    // The loop is a core `pid`: it is re-tuned for the delay (tests/delay.rs),
    // and the re-tune's design figures state what the delay takes.
    let c = &out.report.compensators[0];
    assert_eq!((c.effect.as_str(), c.block.as_str()), ("time_delay", "pid"));
    assert!(c.why.starts_with("re-tune for the delay"), "{}", c.why);
    let f = &c.design;
    assert_eq!(f["delay_s"], 0.002);
    // The gate's delay margin is PM/ω_c: the phase margin over 360° per cycle of
    // the crossover; the delay takes 360°·f_c·d of it.
    assert!(
        (f["delay_margin_s"] - f["phase_margin_deg"] / (360.0 * f["crossover_hz"])).abs()
            < 1e-9 * f["delay_margin_s"],
        "{f:?}"
    );
    assert!(
        (f["phase_margin_left_deg"] - (f["phase_margin_deg"] - 360.0 * f["crossover_hz"] * 0.002))
            .abs()
            < 1e-9,
        "{f:?}"
    );
    assert!(out.report.not_compensated.is_empty());
}

#[test]
fn a_saturation_before_a_pid_gives_it_the_limits_with_how_often_the_loop_asks_for_more() {
    // Limits at ±0.3 on a loop whose PID command (a 0.5 sine on a unit-gain
    // stage) is about ±0.5: clipped for a good part of the window. The pid
    // drives the saturating input, so it is given the limits (anti-windup).
    let aug = GraphSpec::from_yaml(
        "base_rate_hz: 1000\nduration_s: 1\nblocks:\n  - { name: drive, type: data_column, column: u }\n  - { name: stage, type: state_space, a: [[0.0, 1.0], [-1000.0, -10.0]], b: [[0.0], [1000.0]], c: [[1.0, 0.0]], discretisation: zoh }\n  - { name: plf_saturation, type: saturation, lower: -0.3, upper: 0.3 }\nconnections:\n  - { from: drive.y, to: plf_saturation.u }\n  - { from: plf_saturation.y, to: stage.u }\ncompare:\n  - { signal: stage.y, column: y }\n",
        "model_augmented.yaml",
    )
    .unwrap();
    let ctl = controller("score:\n  - { signal: err.y, from_s: 0.5 }\n");
    let out = compensate(&aug, &ctl, &named::from_graph(&aug), &Options::default()).unwrap();
    let c = &out.report.compensators[0];
    assert_eq!((c.effect.as_str(), c.block.as_str()), ("saturation", "pid"));
    assert!(c.why.contains("anti-windup"), "{}", c.why);
    assert_eq!(
        (c.design["output_min"], c.design["output_max"]),
        (-0.3, 0.3)
    );
    // Kept exactly when it cuts the rms by 1 %; then the written pid has them.
    assert_eq!(c.kept, c.cut_percent >= 1.0, "{c:?}");
    let p = out
        .compensated
        .blocks
        .iter()
        .find(|b| b.name == "pid")
        .unwrap();
    let p = nanomotion_plf::surgery::block_to_json(p.block.as_ref());
    assert_eq!(p["output_max"].as_f64(), c.kept.then_some(0.3), "{p}");
    // Independently: the share of |pid.u| > 0.3 over t ≥ 0.5 s of the user's loop.
    let mut g = nanomotion_plf::surgery::clone_spec(&ctl).unwrap();
    g.log = vec!["pid.u".into()];
    let (mut s, _) = g.build().unwrap();
    let u = s.run(|_| {}).logs[0].data.clone();
    let tail = &u[500..];
    let share = tail.iter().filter(|v| v.abs() > 0.3).count() as f64 / tail.len() as f64;
    assert!(share > 0.1, "{share}");
    assert_eq!(c.design["clipped_share"], share);
    eprintln!("{}", serde_json::to_string_pretty(&out.report).unwrap());
}
