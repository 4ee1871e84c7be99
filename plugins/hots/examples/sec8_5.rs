//! Sec. 8.5 of the thesis on simulation (Figs. 8.7–8.8, the −54 % / −92 % claim):
//! rms estimation errors of a 100-line encoder on x = (π/2) sin(2π t) rad, for
//! differencing, time-stamping with each skip σ, and HOTS + calibration, with the
//! real US Digital E2 slit-error profile and with an ideal encoder.
//!
//!     cargo run --release -p nanomotion-hots --example sec8_5

fn profile() -> Option<Vec<f64>> {
    let path = concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../../../shared/data/usdigital_e2_slit_errors/us_digital_e2_100cpr_tick_errors.csv"
    );
    let text = std::fs::read_to_string(path).ok()?;
    Some(
        text.lines()
            .skip(1)
            .map(|l| l.split(',').nth(2).unwrap().trim().parse::<f64>().unwrap() * 400.0)
            .collect(),
    )
}

fn table(title: &str, errors: &[f64]) {
    println!("\n## {title}\n");
    println!("| method | position (mrad) | velocity (rad/s) | acceleration (rad/s²) |");
    println!("|---|---|---|---|");
    for r in hots::sim::sec8_5(errors).expect("valid settings") {
        println!(
            "| {} | {:.4} | {:.4} | {:.3} |",
            r.method,
            1e3 * r.errors.x,
            r.errors.v,
            r.errors.a
        );
    }
}

fn main() {
    match profile() {
        Some(p) => table(
            "100-line encoder with the US Digital E2 slit-error profile",
            &p,
        ),
        None => eprintln!(
            "SKIPPED: ../shared/data/usdigital_e2_slit_errors/ not found; showing random slit errors instead"
        ),
    }
    let mut rng = nanomotion_core::rng::Rng::new(5);
    let random: Vec<f64> = (0..100).map(|_| 0.05 * rng.normal()).collect();
    table(
        "100-line encoder with random per-slit errors (std 0.05 counts)",
        &random,
    );
    table("ideal 100-line encoder (no slit errors)", &[]);
}
