//! Acceptance: a ripple periodic in the position (a walking stage's step, Ch. 5),
//! hidden in a record of the stage's low-frequency model x_s = c ∫ f_α dt
//! (c = 4 µm per cycle, 4 kHz: P(z) = c T_s/(z − 1), the loop of
//! examples/rc_dvrc.yaml), is named by `diagnose` as periodic in the position and
//! compensated by delay-varying RC (5.7)–(5.8) on that position, with (5.9)
//! for the delay range the loop's speed gives. The truth is simulated here in
//! plain Rust (not with the effect block the workflow fits).

mod support;

use nanomotion_compensate::{Options, compensate, named};
use nanomotion_core::data::Dataset;
use nanomotion_core::graph::GraphSpec;
use nanomotion_core::rng::Rng;
use nanomotion_plf::diagnose::{self, diagnose};
use nanomotion_plf::surgery;
use std::f64::consts::PI;
use support::score_rms;

const RATE: f64 = 4000.0;
/// c·T_s: metres per (Hz of f_α) per sample.
const CTS: f64 = 1e-9;
/// The ripple's pitch (m) and harmonics (m).
const PITCH: f64 = 0.5e-6;
const A1: f64 = 5e-9;
const A2: f64 = 2e-9;

fn ripple(x: f64) -> f64 {
    A1 * (2.0 * PI * x / PITCH).sin() + A2 * (4.0 * PI * x / PITCH + 0.7).sin()
}

fn controller() -> GraphSpec {
    GraphSpec::from_yaml(
        &format!(
            "title: P loop on the walking stage's low-frequency model\nbase_rate_hz: {RATE}\nduration_s: 3.0\nblocks:\n  - {{ name: ref, type: constant_velocity, velocity_m_s: 1.0e-5 }}\n  - {{ name: err, type: sum, signs: \"+-\" }}\n  - {{ name: k, type: gain, k: 2.0e8 }}\n  - {{ name: stage, type: transfer_function, num: [{CTS:?}], den: [1.0, -1.0], discrete: true }}\nconnections:\n  - {{ from: ref.y, to: err.in0 }}\n  - {{ from: stage.y, to: err.in1 }}\n  - {{ from: err.y, to: k.u }}\n  - {{ from: k.y, to: stage.u }}\nscore:\n  - {{ signal: err.y, from_s: 1.5 }}\n"
        ),
        "controller.yaml",
    )
    .unwrap()
}

#[test]
fn a_ripple_periodic_in_position_is_cut_by_delay_varying_rc() {
    let _ = std::any::type_name::<nanomotion_plf::effects::Effect>();
    // The record: f_α strokes of ±10 µm at 0.3 Hz plus a little multisine,
    // position by the exact integrator, the ripple of the position on the
    // measurement, 0.3 nm noise.
    let n = 12_000;
    let mut rng = Rng::new(11);
    let (mut x, mut u, mut y) = (0.0, Vec::new(), Vec::new());
    for k in 0..n {
        let t = k as f64 / RATE;
        let f = 2.0 * PI * 0.3 * 10e-6 / (CTS * RATE) * (2.0 * PI * 0.3 * t).cos()
            + 0.5 * (2.0 * PI * 7.0 * t).sin()
            + 0.3 * (2.0 * PI * 31.0 * t + 1.0).sin();
        u.push(f);
        y.push(x + ripple(x) + 3e-10 * rng.normal());
        x += CTS * f;
    }
    let data =
        Dataset::from_columns("record", RATE, 0.0, vec![("u".into(), u), ("y".into(), y)]).unwrap();
    let nominal = GraphSpec::from_yaml(
        &format!(
            "base_rate_hz: {RATE}\nduration_s: {}\nblocks:\n  - {{ name: drive, type: data_column, column: u }}\n  - {{ name: stage, type: transfer_function, num: [{CTS:?}], den: [1.0, -1.0], discrete: true }}\nconnections:\n  - {{ from: drive.y, to: stage.u }}\ncompare:\n  - {{ signal: stage.y, column: y }}\n",
            n as f64 / RATE
        ),
        "nominal.yaml",
    )
    .unwrap();
    let rep = diagnose(&nominal, &data, &diagnose::Options::default()).unwrap();
    assert_eq!(
        rep.found.first().map(String::as_str),
        Some("repetitive_disturbance"),
        "{}",
        rep.stopped_because
    );
    let out = compensate(
        rep.augmented.as_ref().unwrap(),
        &controller(),
        &named::from_report(&rep),
        &Options::default(),
    )
    .unwrap();
    let r = &out.report;
    eprintln!("{}", serde_json::to_string_pretty(r).unwrap());
    let c = &r.compensators[0];
    assert_eq!(c.type_name, "dvrc");
    // The pitch fitted, and the delay range the loop's 10 µm/s gives:
    // N = pitch / (v T_s) = 0.5 µm / (10 µm/s · 0.25 ms) = 200 samples.
    assert!(
        (c.design["period"] / PITCH - 1.0).abs() < 0.01,
        "{:?}",
        c.design
    );
    assert!(
        c.design["n_min"] <= 200.0 && 200.0 <= c.design["n_max"],
        "{:?}",
        c.design
    );
    assert!(c.design["criterion_5_9_hinf"] < c.design["criterion_5_9_bound"]);
    assert!(
        (c.design["criterion_5_9_bound"]
            - 1.0 / (c.design["n_max"] - c.design["n_min"] + 1.0).sqrt())
        .abs()
            < 1e-12
    );
    assert!(r.gate.passes && c.kept);
    // The written graph on the wall clock, bit for bit as offline.
    support::runs_on_the_wall_clock_as_offline(
        &out.compensated,
        &[
            "comp_repetitive_disturbance.w",
            "comp_repetitive_disturbance.n",
        ],
    );
    assert!(r.cut_percent > 80.0, "{}", r.cut_percent);
    // Most of the P loop's error is its ramp-following error v/(K c) =
    // 10 µm/s / (2e8 · 4 µm) = 12.5 nm (constant), which the memory learns too;
    // what is left is also far below what the ripple adds (e − e_nominal).
    assert!(
        (r.nominal.rms / 12.5e-9 - 1.0).abs() < 1e-6,
        "{}",
        r.nominal.rms
    );
    assert!(r.after.rms < 0.05 * r.effect_error_before, "{r:?}");

    // On the truth: the true ripple of the true position on the measurement.
    let on_truth = |spec: &GraphSpec| -> f64 {
        let mut g = surgery::clone_spec(spec).unwrap();
        // y = x + ripple(x): the ripple as a plf `repetitive_disturbance` with the
        // TRUE pitch and amplitudes (sin(θ + 0.7) = cos 0.7 sin θ + sin 0.7 cos θ).
        let d = surgery::block_from_json(serde_json::json!({
            "type": "repetitive_disturbance", "period": PITCH, "variable": "signal",
            "cos": [0.0, A2 * 0.7f64.sin()], "sin": [A1, A2 * 0.7f64.cos()]}))
        .unwrap();
        let site = surgery::Site::Sensor {
            compare: 0,
            signal: "stage.y".into(),
        };
        surgery::insert(&mut g, "truth", d, &site, &["stage.y".into()], None).unwrap();
        score_rms(&g)
    };
    let (before, after) = (on_truth(&controller()), on_truth(&out.compensated));
    eprintln!("truth: {before:.3e} -> {after:.3e}");
    assert!(after < 0.2 * before, "{before:e} -> {after:e}");
}
