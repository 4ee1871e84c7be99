//! Issue 29's `hinfnorm` timing systems (the `lti_numerics` bench's
//! `hinf_ratio` group, drawn by `nanomotion_core::lti::random_systems`) as JSON,
//! with our norm, peak frequency and time per call for each, for
//! `tools/hinfnorm_vs_ab13dd.py`, which times SLICOT's `ab13dd` on the same
//! matrices:
//!
//! `cargo run --release -p nanomotion-core --example hinf_systems -- OUT.json [SECONDS]`
//!
//! Each system is timed for about SECONDS (default 0.5) after a warm-up: the
//! median over 7 batches of the time per call, for `hinfnorm` and for the
//! pre-issue-29 `hinfnorm_schur_eigensolver`.

use nanomotion_core::lti::hinf::{HinfNorm, hinfnorm_schur_eigensolver};
use nanomotion_core::lti::{LtiError, StateSpace, hinfnorm};
use serde_json::{Value, json};
use std::hint::black_box;
use std::time::Instant;

/// Median over 7 batches of the seconds per call of `f`, each batch about
/// `budget / 7` s long (batch size from a first timed call).
fn seconds_per_call(budget: f64, f: impl Fn() -> HinfNorm) -> f64 {
    let start = Instant::now();
    black_box(f());
    let once = start.elapsed().as_secs_f64().max(1e-7);
    let reps = ((budget / 7.0 / once) as usize).max(1);
    let mut batches: Vec<f64> = (0..7)
        .map(|_| {
            let t = Instant::now();
            for _ in 0..reps {
                black_box(f());
            }
            t.elapsed().as_secs_f64() / reps as f64
        })
        .collect();
    batches.sort_by(f64::total_cmp);
    batches[3]
}

fn rows(m: &nalgebra::DMatrix<f64>) -> Value {
    json!(
        (0..m.nrows())
            .map(|i| m.row(i).iter().copied().collect::<Vec<f64>>())
            .collect::<Vec<_>>()
    )
}

fn record(name: &str, sys: &StateSpace, budget: f64) -> Result<Value, LtiError> {
    let ours = hinfnorm(sys)?;
    let before = hinfnorm_schur_eigensolver(sys)?;
    Ok(json!({
        "name": name,
        "n": sys.nstates(),
        "dt": sys.dt,
        "a": rows(&sys.a),
        "b": rows(&sys.b),
        "c": rows(&sys.c),
        "d": rows(&sys.d),
        "norm": ours.norm,
        "peak_rad_s": ours.peak_rad_s,
        "seconds": seconds_per_call(budget, || hinfnorm(black_box(sys)).unwrap()),
        "before_norm": before.norm,
        "before_seconds": seconds_per_call(budget, || {
            hinfnorm_schur_eigensolver(black_box(sys)).unwrap()
        }),
    }))
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let mut args = std::env::args().skip(1);
    let out = args
        .next()
        .ok_or("usage: hinf_systems OUT.json [SECONDS]")?;
    let budget: f64 = args.next().map(|s| s.parse()).transpose()?.unwrap_or(0.5);
    let systems = nanomotion_core::lti::random_systems::hinf_ratio_systems()
        .iter()
        .map(|(name, sys)| record(name, sys, budget))
        .collect::<Result<Vec<_>, _>>()?;
    std::fs::write(&out, serde_json::to_string(&systems)?)?;
    Ok(())
}
