//! Sec. 8.5 of the thesis on simulation (Figs. 8.7–8.8, the −54 % / −92 % claim):
//! rms estimation errors of a 100-line encoder on x = (π/2) sin(2π t) rad, for
//! differencing, time-stamping (m = 2, n = 5) with each skip σ, and HOTS +
//! calibration, against the true trajectory and against a 5000-line reference
//! encoder filtered forward-backward by a 5th-order 50 Hz Butterworth low-pass —
//! with the real US Digital E2 slit-error profile (read in place from
//! `../shared/data/usdigital_e2_slit_errors/`, relative to the workspace root;
//! `SKIPPED` on stderr if absent), with seeded random per-slit errors, and with an
//! ideal encoder.
//!
//!     cargo run --release -p nanomotion-hots --example sec8_5

use hots::sim::{Errors, SEC85_MOVING_SPEED, Sec85Row, sec8_5_reference, sec8_5_with_reference};

const PROFILE: &str =
    "../shared/data/usdigital_e2_slit_errors/us_digital_e2_100cpr_tick_errors.csv";

/// Per-slit errors in counts (angle error in revolutions × 400 counts/rev).
fn profile() -> Option<Vec<f64>> {
    let path = concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../../../shared/data/usdigital_e2_slit_errors/us_digital_e2_100cpr_tick_errors.csv"
    );
    let text = std::fs::read_to_string(path).ok()?;
    text.lines()
        .skip(1)
        .map(|l| Some(l.split(',').nth(2)?.trim().parse::<f64>().ok()? * 400.0))
        .collect()
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
    let skips: Vec<&Sec85Row> = rows
        .iter()
        .filter(|r| r.method.starts_with("time-stamping"))
        .collect();
    let s0 = skips[0];
    println!();
    for (against, get) in [("truth", vs_truth), ("reference", vs_ref)] {
        for (what, f) in [
            ("velocity", (|e: &Errors| e.v) as fn(&Errors) -> f64),
            ("acceleration", |e: &Errors| e.a),
        ] {
            let e = |r: &Sec85Row| f(&get(r).unwrap());
            let best = skips.iter().min_by(|a, b| e(a).total_cmp(&e(b))).unwrap();
            println!(
                "- best skip for {what} vs {against}: {} ({:+.0} % against σ=0)",
                best.method.rsplit(' ').next().unwrap(),
                100.0 * (e(best) / e(s0) - 1.0)
            );
        }
    }
}

fn regime(title: &str, errors: &[f64], reference: &[[f64; 3]]) {
    let rows = sec8_5_with_reference(errors, reference).expect("valid settings");
    println!("\n## {title}");
    table(
        &rows,
        "all reads, 0.1–2.1 s",
        |r| Some(r.errors),
        |r| r.vs_reference,
    );
    table(
        &rows,
        &format!("moving reads only (|v| ≥ {SEC85_MOVING_SPEED} rad/s)"),
        |r| Some(r.moving),
        |r| r.moving_vs_reference,
    );
}

fn main() {
    let reference = sec8_5_reference().expect("valid settings");
    match profile() {
        Some(p) => regime(
            "100-line encoder with the US Digital E2 slit-error profile",
            &p,
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
}
