//! Sec. 8.5 of the thesis on simulation (Figs. 8.7–8.8, the −54 % / −92 % claim):
//! rms estimation errors of a 100-line encoder on x = (π/2) sin(2π t) rad, for
//! differencing, time-stamping (m = 2, n = 5) with each skip σ, and HOTS +
//! calibration, against the true trajectory and against a 5000-line reference
//! encoder filtered forward-backward by a 5th-order 50 Hz Butterworth low-pass —
//! with the real US Digital E2 slit-error profile (read in place from
//! `../shared/data/usdigital_e2_slit_errors/`, relative to the workspace root;
//! `SKIPPED` on stderr if absent), with seeded random per-slit errors, and with an
//! ideal encoder. Each under both out-of-band rules of the estimator: the
//! thesis's (Sec. 8.3: position → count, v̂/â from the fit; the default) and
//! `zero_standstill` (also v̂ = â = 0, plus a 10 ms standstill rule). Then the
//! amplitude variation of Sec. 8.5: x = A sin(2π t) for A ∈ {π/8, π/4, π/2, π}
//! rad, best skip against no skip over all reads, both rules.
//!
//!     cargo run --release -p nanomotion-hots --example sec8_5 [-- PROFILE.csv]
//!
//! The optional argument replaces the in-place profile path (e.g. from a git
//! worktree whose `../shared` is elsewhere).

use hots::sim::{
    Errors, SEC85_AMPLITUDES, SEC85_MOVING_SPEED, Sec85Row, sec8_5_amplitude, sec8_5_reference,
    sec8_5_reference_at, sec8_5_with_fallback,
};
use timestamp_encoder::Fallback;

const RULES: [(Fallback, &str); 2] = [
    (Fallback::Thesis, "fallback: thesis"),
    (Fallback::ZeroStandstill, "fallback: zero_standstill"),
];

const PROFILE: &str =
    "../shared/data/usdigital_e2_slit_errors/us_digital_e2_100cpr_tick_errors.csv";

/// Per-slit errors in counts (angle error in revolutions × 400 counts/rev).
fn profile() -> Option<Vec<f64>> {
    let path = std::env::args().nth(1).unwrap_or_else(|| {
        concat!(
            env!("CARGO_MANIFEST_DIR"),
            "/../../../shared/data/usdigital_e2_slit_errors/us_digital_e2_100cpr_tick_errors.csv"
        )
        .to_string()
    });
    hots::sim::read_slit_profile(std::path::Path::new(&path)).ok()
}

fn cells(e: Option<Errors>) -> String {
    match e {
        Some(e) => format!("{:.4} | {:.4} | {:.3}", 1e3 * e.x, e.v, e.a),
        None => "— | — | —".into(),
    }
}

type Pick = fn(&Sec85Row) -> Option<Errors>;

fn table(rows: &[Sec85Row], window: &str, vs_truth: Pick, vs_ref: Pick) {
    println!("\n### {window}\n");
    println!(
        "| method | vs truth: x (mrad) | v (rad/s) | a (rad/s²) | vs reference: x (mrad) | v (rad/s) | a (rad/s²) |"
    );
    println!("|---|---|---|---|---|---|---|");
    for r in rows {
        println!(
            "| {} | {} | {} |",
            r.method,
            cells(vs_truth(r)),
            cells(vs_ref(r))
        );
    }
    println!();
    for (against, get) in [("truth", vs_truth), ("reference", vs_ref)] {
        for (what, f) in [
            ("velocity", (|e: &Errors| e.v) as fn(&Errors) -> f64),
            ("acceleration", |e: &Errors| e.a),
        ] {
            let (sigma, pct) = best_skip(rows, get, f);
            println!("- best skip for {what} vs {against}: {sigma} ({pct:+.0} % against σ=0)");
        }
    }
}

/// The skip with the smallest error `f` (judged by `get`) and its change against
/// σ = 0 in percent.
fn best_skip(rows: &[Sec85Row], get: Pick, f: fn(&Errors) -> f64) -> (String, f64) {
    let (sigma, pct) =
        hots::sim::best_skip(rows, |r| f(&get(r).expect("scored row"))).expect("rows with σ = 0");
    (format!("σ={sigma}"), pct)
}

/// The amplitude variation: per A and rule, all reads, σ=0's rms and the best
/// skip's change against it (vs truth, then vs the reference of the same A).
fn amplitudes(title: &str, errors: &[f64]) {
    println!("\n## amplitude variation, {title}: x = A sin(2π t), all reads, 0.1–2.1 s\n");
    println!(
        "| A (rad) | rule | σ=0 vs truth: v (rad/s) | a (rad/s²) | best skip v vs truth | best skip a vs truth | best skip v vs reference | best skip a vs reference |"
    );
    println!("|---|---|---|---|---|---|---|---|");
    for amp in SEC85_AMPLITUDES {
        let reference = sec8_5_reference_at(amp).expect("valid settings");
        for (rule, name) in RULES {
            let rows = sec8_5_amplitude(errors, amp, rule, &reference).expect("valid settings");
            let cell = |get: Pick, f: fn(&Errors) -> f64| {
                let (s, p) = best_skip(&rows, get, f);
                format!("{s} ({p:+.0} %)")
            };
            let truth: Pick = |r| Some(r.errors);
            let refr: Pick = |r| r.vs_reference;
            println!(
                "| {:.4} | {name} | {:.4} | {:.3} | {} | {} | {} | {} |",
                amp,
                rows[0].errors.v,
                rows[0].errors.a,
                cell(truth, |e| e.v),
                cell(truth, |e| e.a),
                cell(refr, |e| e.v),
                cell(refr, |e| e.a),
            );
        }
    }
}

fn regime(title: &str, errors: &[f64], reference: &[[f64; 3]]) {
    for (rule, name) in RULES {
        let rows = sec8_5_with_fallback(errors, reference, rule).expect("valid settings");
        println!("\n## {title} — {name}");
        tables(&rows);
    }
}

fn tables(rows: &[Sec85Row]) {
    table(
        rows,
        "all reads, 0.1–2.1 s",
        |r| Some(r.errors),
        |r| r.vs_reference,
    );
    table(
        rows,
        &format!("moving reads only (|v| ≥ {SEC85_MOVING_SPEED} rad/s)"),
        |r| Some(r.moving),
        |r| r.moving_vs_reference,
    );
}

fn main() {
    let reference = sec8_5_reference().expect("valid settings");
    let e2 = profile();
    match &e2 {
        Some(p) => regime(
            "100-line encoder with the US Digital E2 slit-error profile",
            p,
            &reference,
        ),
        None => eprintln!(
            "SKIPPED: {PROFILE} not found (relative to the workspace root): no table for the real slit-error profile"
        ),
    }
    let mut rng = nanomotion_core::rng::Rng::new(5);
    let random: Vec<f64> = (0..100).map(|_| 0.05 * rng.normal()).collect();
    regime(
        "100-line encoder with random per-slit errors (std 0.05 counts, seed 5)",
        &random,
        &reference,
    );
    regime("ideal 100-line encoder (no slit errors)", &[], &reference);
    if let Some(p) = &e2 {
        amplitudes("US Digital E2 profile", p);
    }
    amplitudes("random per-slit errors (std 0.05 counts, seed 5)", &random);
}
