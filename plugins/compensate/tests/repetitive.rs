//! Acceptance: a disturbance periodic in time, hidden in a record of a
//! second-order stage, is named by `diagnose` and compensated by standard RC
//! (5.1) with no hand-written compensator; the error cut is checked on the
//! augmented model (as `compensate` reports it) and on the truth (the true
//! disturbance, not the fitted one).

mod support;

use nanomotion_compensate::{Options, compensate, named};
use nanomotion_core::graph::GraphSpec;
use nanomotion_plf::diagnose::{self, diagnose};
use nanomotion_plf::surgery;
use std::f64::consts::PI;
use support::*;

const RATE: f64 = 2000.0;
/// The stage: m = 0.5 kg, f0 = 40 Hz, ζ = 0.05 (force in N, position in m).
const M: f64 = 0.5;
const F0: f64 = 40.0;
const ZETA: f64 = 0.05;
/// The hidden disturbance: 23 Hz (86.96 samples: not an integer), two harmonics (m).
const F_D: f64 = 23.0;
const A1: f64 = 1.5e-7;
const A2: f64 = 0.6e-7;

fn stage() -> String {
    let k = M * (2.0 * PI * F0).powi(2);
    let c = 2.0 * ZETA * M * 2.0 * PI * F0;
    format!(
        "{{ name: stage, type: state_space, a: [[0.0, 1.0], [{:?}, {:?}]], b: [[0.0], [{:?}]], c: [[1.0, 0.0]], discretisation: zoh }}",
        -k / M,
        -c / M,
        1.0 / M
    )
}

fn disturbance_blocks() -> String {
    format!(
        "  - {{ name: d1, type: sinusoid, amplitude: {A1:?}, frequency_hz: {F_D:?} }}\n  - {{ name: d2, type: sinusoid, amplitude: {A2:?}, frequency_hz: {:?}, phase_rad: 0.9 }}\n",
        2.0 * F_D
    )
}

/// A PID for a 80 Hz crossover on the mass line, derivative filtered at 400 Hz.
fn controller_yaml(extra_blocks: &str, measured: &str, extra_connections: &str) -> String {
    let wc = 2.0 * PI * 80.0;
    let kd = M * wc / 1.054;
    let kp = kd * wc / 3.0;
    let ki = kp * wc / 10.0;
    format!(
        "title: PID loop on the stage\nbase_rate_hz: {RATE}\nduration_s: 3.0\nblocks:\n  - {{ name: ref, type: constant, value: 1.0e-6 }}\n  - {{ name: err, type: sum, signs: \"+-\" }}\n  - {{ name: pid, type: pid, kp: {kp:?}, ki: {ki:?}, kd: {kd:?}, derivative_cutoff_hz: 400.0 }}\n  - {}\n{extra_blocks}connections:\n  - {{ from: ref.y, to: err.in0 }}\n  - {{ from: {measured}, to: err.in1 }}\n  - {{ from: err.y, to: pid.e }}\n  - {{ from: pid.u, to: stage.u }}\n{extra_connections}score:\n  - {{ signal: err.y, from_s: 1.5 }}\n",
        stage()
    )
}

#[test]
fn a_disturbance_periodic_in_time_is_cut_by_repetitive_control() {
    let _ = std::any::type_name::<nanomotion_plf::effects::Effect>();
    // The record: the stage driven open loop, the disturbance on the measurement.
    let n = 6000;
    let k = M * (2.0 * PI * F0).powi(2);
    let u = drive(n, RATE, k * 1e-6, 0.0);
    let truth = format!(
        "base_rate_hz: {RATE}\nduration_s: {}\nblocks:\n  - {{ name: drive, type: data_column, column: u }}\n  - {}\n{}  - {{ name: y, type: sum, signs: \"+++\" }}\nconnections:\n  - {{ from: drive.y, to: stage.u }}\n  - {{ from: stage.y, to: y.in0 }}\n  - {{ from: d1.y, to: y.in1 }}\n  - {{ from: d2.y, to: y.in2 }}\n",
        n as f64 / RATE,
        stage(),
        disturbance_blocks()
    );
    let y = simulate_record(&truth, &u, RATE, "y.y", 1e-8, 7);
    let data = dataset(RATE, u, y);
    let nominal = GraphSpec::from_yaml(
        &format!(
            "base_rate_hz: {RATE}\nduration_s: {}\nblocks:\n  - {{ name: drive, type: data_column, column: u }}\n  - {}\nconnections:\n  - {{ from: drive.y, to: stage.u }}\ncompare:\n  - {{ signal: stage.y, column: y }}\n",
            n as f64 / RATE,
            stage()
        ),
        "nominal.yaml",
    )
    .unwrap();
    let rep = diagnose(&nominal, &data, &diagnose::Options::default()).unwrap();
    assert_eq!(
        rep.found,
        vec!["repetitive_disturbance".to_string()],
        "{}",
        rep.stopped_because
    );
    let augmented = rep.augmented.as_ref().unwrap();

    // Compensate the user's loop.
    let controller =
        GraphSpec::from_yaml(&controller_yaml("", "stage.y", ""), "controller.yaml").unwrap();
    let effects = named::from_report(&rep);
    let out = compensate(augmented, &controller, &effects, &Options::default()).unwrap();
    let r = &out.report;
    eprintln!("{}", serde_json::to_string_pretty(r).unwrap());
    assert_eq!(r.compensators.len(), 1);
    let c = &r.compensators[0];
    assert_eq!(c.type_name, "repetitive_control");
    assert!(c.kept);
    // N is the fitted period at the controller's rate: 2000/23 = 86.96 → 87.
    assert_eq!(c.design["n"], 87.0);
    assert!((c.design["period_samples"] - RATE / F_D).abs() < 0.05);
    // Criterion (5.5) as the report gives it, and independently by dvrc's
    // rc-check on the written graph (its own T from the gate's loop model).
    assert!(c.design["criterion_5_5_hinf"] < 1.0);
    let ts = dvrc::check::graph_loop_ts(surgery::clone_spec(&out.compensated).unwrap()).unwrap();
    let check = dvrc::check::rc_check_graph_with(&out.compensated, Ok(&ts));
    assert!(check.all_hold(), "{check:?}");
    assert!(r.gate.passes);
    // The written graph on the wall clock, bit for bit as offline.
    support::runs_on_the_wall_clock_as_offline(
        &out.compensated,
        &["comp_repetitive_disturbance.w"],
    );
    // On the augmented model: the error is cut by more than 80 %.
    assert!(r.cut_percent > 80.0, "{}", r.cut_percent);

    // On the truth: the true disturbance (the sinusoids) on the measurement of the
    // user's loop, before and with the compensated controller.
    let on_truth = |spec: &GraphSpec| {
        let mut g = surgery::clone_spec(spec).unwrap();
        // Every reader of the stage's position reads position + disturbance.
        for c in g.connections.iter_mut().filter(|c| c.from == "stage.y") {
            c.from = "y.y".into();
        }
        g.connect("stage.y", "y.in0");
        let y =
            surgery::block_from_json(serde_json::json!({"type": "sum", "signs": "+++"})).unwrap();
        g.blocks.push(nanomotion_core::graph::BlockSpec {
            name: "y".into(),
            rate_hz: None,
            block: y,
        });
        let mut extra = GraphSpec::from_yaml(
            &format!(
                "base_rate_hz: {RATE}\nduration_s: 1\nblocks:\n{}",
                disturbance_blocks()
            ),
            "d.yaml",
        )
        .unwrap();
        g.blocks.append(&mut extra.blocks);
        g.connect("d1.y", "y.in1").connect("d2.y", "y.in2");
        score_rms(&g)
    };
    let before = on_truth(&controller);
    let after = on_truth(&out.compensated);
    eprintln!("truth: {before:.3e} -> {after:.3e}");
    // The fitted disturbance reproduces the true one in the loop (within 5 %).
    assert!(
        (r.before.rms / before - 1.0).abs() < 0.05,
        "{:e} vs {before:e}",
        r.before.rms
    );
    // Without compensation the disturbance passes through S of the loop: the
    // rms over the scored window is of the disturbance's order times |S|, well
    // above zero; RC removes at least 80 % of it.
    assert!(after < 0.2 * before, "truth: {before:e} -> {after:e}");
}
