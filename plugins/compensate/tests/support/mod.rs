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
