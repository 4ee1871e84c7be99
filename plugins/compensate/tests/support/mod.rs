//! Shared pieces of the acceptance tests: records simulated from a truth graph,
//! the diagnosis, and closed loops built from a nominal plant block.

#![allow(dead_code)]

use nanomotion_core::data::Dataset;
use nanomotion_core::graph::GraphSpec;
use nanomotion_core::rng::Rng;
use std::sync::Arc;

/// Run `yaml` (which plays column `u` with a `data_column`) on drive `u` at
/// `rate` Hz and return the logged `signal`, plus white noise of std `noise`.
pub fn simulate_record(
    yaml: &str,
    u: &[f64],
    rate: f64,
    signal: &str,
    noise: f64,
    seed: u64,
) -> Vec<f64> {
    let mut spec = GraphSpec::from_yaml(yaml, "truth.yaml").expect("truth graph");
    spec.log.push(signal.into());
    let data = Dataset::from_columns("drive", rate, 0.0, vec![("u".into(), u.to_vec())]).unwrap();
    let (mut s, _) = spec.build_with_data(Arc::new(data)).expect("truth builds");
    let r = s.run(|_| {});
    let y = &r
        .logs
        .iter()
        .find(|l| l.name == signal)
        .expect("logged")
        .data;
    let mut rng = Rng::new(seed);
    y.iter().map(|v| v + noise * rng.normal()).collect()
}

/// A drive of slow strokes plus a multisine (5–300 Hz), `amp` in the drive's unit.
pub fn drive(n: usize, rate: f64, amp: f64, offset: f64) -> Vec<f64> {
    use std::f64::consts::PI;
    (0..n)
        .map(|k| {
            let t = k as f64 / rate;
            let mut u = 0.6 * (2.0 * PI * 1.3 * t).sin() + 0.3 * (2.0 * PI * 3.7 * t + 1.0).sin();
            for (i, f) in [5.0, 11.0, 23.5, 47.0, 89.0, 151.0, 233.0, 301.0]
                .iter()
                .enumerate()
            {
                u += 0.03 * (2.0 * PI * f * t + 0.7 * i as f64).sin();
            }
            offset + amp * u
        })
        .collect()
}

/// The record as a dataset with columns `u` and `y`.
pub fn dataset(rate: f64, u: Vec<f64>, y: Vec<f64>) -> Dataset {
    Dataset::from_columns("record", rate, 0.0, vec![("u".into(), u), ("y".into(), y)]).unwrap()
}

/// rms of `x[from..]`.
pub fn rms(x: &[f64]) -> f64 {
    (x.iter().map(|v| v * v).sum::<f64>() / x.len() as f64).sqrt()
}

/// Run a closed loop and return its first score's rms.
pub fn score_rms(spec: &GraphSpec) -> f64 {
    let g = nanomotion_plf::surgery::clone_spec(spec).unwrap();
    let (mut s, _) = g.build().expect("loop builds");
    s.run(|_| {}).scores[0].rms
}

/// Compensate in the user's loop `loop_` what the diagnosis `rep` named
/// (every compensator kept with `keep`), printing the report under `label`.
pub fn compensate_named(
    rep: &nanomotion_plf::Report,
    loop_: &GraphSpec,
    keep: bool,
    label: &str,
) -> nanomotion_compensate::Outcome {
    let out = nanomotion_compensate::compensate(
        rep.augmented.as_ref().expect("an augmented model"),
        loop_,
        &nanomotion_compensate::named::from_report(rep),
        &nanomotion_compensate::Options {
            keep,
            ..nanomotion_compensate::Options::default()
        },
    )
    .unwrap();
    eprintln!(
        "{label}\n{}",
        serde_json::to_string_pretty(&out.report).unwrap()
    );
    out
}

/// The PID loop around `stage` (the nominal's state-space block, as JSON) at
/// the generator's rate: a crossover near `fc` Hz on the mass line
/// (k_d = mω_c/1.054, k_p = k_dω_c/3, k_i = k_pω_c/10), the derivative
/// filtered at 5 f_c, the reference block `reference` (a block map without
/// its name), `duration_s` long, scored from `from_s`; `extra` is appended
/// (e.g. a `require:` section).
pub fn pid_loop(
    stage: &serde_json::Value,
    fc: f64,
    reference: &str,
    (duration_s, from_s): (f64, f64),
    extra: &str,
) -> GraphSpec {
    let m = 1.0 / stage["b"][1][0].as_f64().unwrap();
    let wc = 2.0 * std::f64::consts::PI * fc;
    let kd = m * wc / 1.054;
    let kp = kd * wc / 3.0;
    let ki = kp * wc / 10.0;
    let mut stage = stage.clone();
    stage["name"] = "stage".into();
    GraphSpec::from_yaml(
        &format!(
            "title: PID loop\nbase_rate_hz: {}\nduration_s: {duration_s:?}\nblocks:\n  - {{ name: ref, {reference} }}\n  - {{ name: err, type: sum, signs: \"+-\" }}\n  - {{ name: pid, type: pid, kp: {kp:?}, ki: {ki:?}, kd: {kd:?}, derivative_cutoff_hz: {:?} }}\n  - {stage}\nconnections:\n  - {{ from: ref.y, to: err.in0 }}\n  - {{ from: stage.y, to: err.in1 }}\n  - {{ from: err.y, to: pid.e }}\n  - {{ from: pid.u, to: stage.u }}\nscore:\n  - {{ signal: err.y, from_s: {from_s:?} }}\n{extra}",
            nanomotion_plf::generate::RATE_HZ,
            5.0 * fc
        ),
        "controller.yaml",
    )
    .unwrap()
}

/// Compensate in the user's loop `loop_` the effects of the augmented model
/// `aug` found from its `plf_*` blocks (no report), with the default
/// options, printing the report.
pub fn compensate_augmented(aug: &GraphSpec, loop_: &GraphSpec) -> nanomotion_compensate::Outcome {
    let out = nanomotion_compensate::compensate(
        aug,
        loop_,
        &nanomotion_compensate::named::from_graph(aug),
        &nanomotion_compensate::Options::default(),
    )
    .unwrap();
    eprintln!("{}", serde_json::to_string_pretty(&out.report).unwrap());
    out
}

/// [`runs_on_the_wall_clock_as_offline`] on the first `seconds` of `spec` (its
/// duration cut to `seconds` if longer, each score's window starting no later
/// than half of it): a long validation run checked on the wall clock in
/// seconds.
pub fn first_seconds_run_on_the_wall_clock_as_offline(
    spec: &GraphSpec,
    log: &[&str],
    seconds: f64,
) {
    let mut g = nanomotion_plf::surgery::clone_spec(spec).unwrap();
    if g.duration_s > seconds {
        g.duration_s = seconds;
        for s in &mut g.score {
            s.from_s = s.from_s.min(0.5 * seconds);
        }
    }
    runs_on_the_wall_clock_as_offline(&g, log);
}

/// Run `spec` (a compensated graph) offline, as `nanomotion run` does, and on
/// the wall clock by `RealtimeRunner` without a device, as `nanomotion rt
/// --allow-soft` does (SCHED_FIFO 80 where permitted, late ticks caught up so
/// every tick runs), logging `log` besides the graph's own; assert that it
/// completes every tick at the graph's rate and that every logged sample and
/// the scores equal the offline run's bit for bit (a graph without a device
/// computes the same values whenever a tick runs).
pub fn runs_on_the_wall_clock_as_offline(spec: &GraphSpec, log: &[&str]) {
    use nanomotion_rt::{NoDevice, RealtimeRunner, RtConfig, Stop};
    let load = || {
        let mut g = nanomotion_plf::surgery::clone_spec(spec).unwrap();
        g.log.extend(log.iter().map(|s| s.to_string()));
        g.build().unwrap().0
    };
    let mut offline = load();
    let want = offline.run(|_| {});
    let ticks = offline.ticks_done();
    let cfg = RtConfig::soft_catch_up();
    let mut runner = RealtimeRunner::new(load(), NoDevice, cfg).unwrap();
    let report = runner.run(|_| {}).unwrap();
    let (wall, _) = runner.into_parts();
    assert_eq!(report.stopped, Stop::Completed, "{}", report.stop);
    assert_eq!((report.ticks, report.missed_ticks), (ticks, 0));
    assert_eq!(report.rate_hz, spec.base_rate_hz);
    eprintln!(
        "{}: {} ticks at {} Hz on the wall clock ({}), {} overruns caught up",
        spec.title.as_deref().unwrap_or("the graph"),
        report.ticks,
        report.rate_hz,
        report.scheduling,
        report.overruns
    );
    let got = wall.result();
    assert_eq!(got.logs.len(), want.logs.len());
    for (w, g) in want.logs.iter().zip(&got.logs) {
        assert_eq!((&g.name, g.data.len()), (&w.name, w.data.len()));
        assert!(
            w.data
                .iter()
                .zip(&g.data)
                .all(|(a, b)| a.to_bits() == b.to_bits()),
            "{}: the wall-clock run differs from the offline run",
            w.name
        );
    }
    for (w, g) in want.scores.iter().zip(&got.scores) {
        assert_eq!(
            (g.rms.to_bits(), g.max_abs.to_bits()),
            (w.rms.to_bits(), w.max_abs.to_bits()),
            "{}",
            w.signal
        );
    }
}

/// The rate of [`stage_20hz`]'s graphs (Hz).
pub const MAP_RATE: f64 = 2000.0;

/// A stage (position per drive unit): ω = 2π·20, ζ = 0.3, static gain 1.
pub fn stage_20hz() -> String {
    let w = 2.0 * std::f64::consts::PI * 20.0;
    format!(
        "{{ name: stage, type: state_space, a: [[0.0, 1.0], [{:?}, {:?}]], b: [[0.0], [{:?}]], c: [[1.0, 0.0]], discretisation: zoh }}",
        -w * w,
        -2.0 * 0.3 * w,
        w * w
    )
}

/// The augmented model `diagnose` writes for a map `block` (its YAML
/// fields) on the drive of [`stage_20hz`], named `plf_hysteresis`.
pub fn map_on_the_drive(block: &str) -> GraphSpec {
    GraphSpec::from_yaml(
        &format!(
            "base_rate_hz: {MAP_RATE}\nduration_s: 1\nblocks:\n  - {{ name: drive, type: data_column, column: u }}\n  - {{ name: plf_hysteresis, {block} }}\n  - {}\nconnections:\n  - {{ from: drive.y, to: plf_hysteresis.u }}\n  - {{ from: plf_hysteresis.y, to: stage.u }}\ncompare:\n  - {{ signal: stage.y, column: y }}\n",
            stage_20hz()
        ),
        "model_augmented.yaml",
    )
    .unwrap()
}

/// The user's PI loop on [`stage_20hz`] tracking a 2 Hz sine, scored after
/// 1 s; with `map` (its YAML fields), that block on its drive too — the
/// plant as diagnosed, built by hand.
pub fn pi_loop_behind(map: Option<&str>) -> GraphSpec {
    let (block, drive) = match map {
        Some(m) => (
            format!("  - {{ name: h, {m} }}\n"),
            "  - { from: pi.u, to: h.u }\n  - { from: h.y, to: stage.u }\n",
        ),
        None => (String::new(), "  - { from: pi.u, to: stage.u }\n"),
    };
    GraphSpec::from_yaml(
        &format!(
            "base_rate_hz: {MAP_RATE}\nduration_s: 3.0\nblocks:\n  - {{ name: ref, type: sinusoid, amplitude: 0.5, frequency_hz: 2.0 }}\n  - {{ name: err, type: sum, signs: \"+-\" }}\n  - {{ name: pi, type: pi, kp: 2.0, zero_hz: 5.0 }}\n  - {}\n{block}connections:\n  - {{ from: ref.y, to: err.in0 }}\n  - {{ from: stage.y, to: err.in1 }}\n  - {{ from: err.y, to: pi.e }}\n{drive}score:\n  - {{ signal: err.y, from_s: 1.0 }}\n",
            stage_20hz()
        ),
        "controller.yaml",
    )
    .unwrap()
}

/// Compensate the map `map` (its YAML fields) fitted on the drive of
/// [`stage_20hz`] in the user's PI loop ([`pi_loop_behind`]), and check that
/// the inverse cancels it: one compensator of type `type_name`, kept, the
/// gate passing, the written graph on the wall clock as offline; the loop's
/// rms before is the hand-built loop's on the plant as diagnosed (to 1e-12),
/// after it is the loop's on the nominal stage (to 1e-9), and what the effect
/// adds to the error falls to `rounding` of itself. Returns the report.
pub fn inverse_cancels_the_map(
    map: &str,
    type_name: &str,
    rounding: f64,
) -> nanomotion_compensate::Report {
    let out = compensate_augmented(&map_on_the_drive(map), &pi_loop_behind(None));
    let r = out.report;
    let c = &r.compensators[0];
    assert_eq!(c.effect, "hysteresis");
    assert_eq!(c.type_name, type_name);
    assert!(c.kept && r.gate.passes, "{r:?}");
    runs_on_the_wall_clock_as_offline(&out.compensated, &[]);
    let before = score_rms(&pi_loop_behind(Some(map)));
    let nominal = score_rms(&pi_loop_behind(None));
    let close = |a: f64, b: f64, tol: f64| (a - b).abs() <= tol * b.abs();
    assert!(
        close(r.before.rms, before, 1e-12),
        "{} {before}",
        r.before.rms
    );
    assert!(
        close(r.after.rms, nominal, 1e-9),
        "{} {nominal}",
        r.after.rms
    );
    assert!(r.before.rms > nominal, "{r:?}");
    assert!(
        r.effect_error_after <= rounding * r.effect_error_before,
        "{} {}",
        r.effect_error_after,
        r.effect_error_before
    );
    eprintln!(
        "rms {:.4e} -> {:.4e} ({:.1} % cut); the nominal loop: {nominal:.4e}",
        r.before.rms, r.after.rms, r.cut_percent
    );
    r
}
