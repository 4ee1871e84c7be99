//! Loop-shaped PI (2.10) on the linear model (2.7) at 4 kHz: gains and margins
//! (Sec. 2.4.2). `cargo run -p nanomotion-walking-piezo --example pi_design`
use walking_piezo::{LinearStageParams, design_pi};

fn main() {
    let p = LinearStageParams::default();
    for bw in [10.0, 50.0] {
        let d = design_pi(&p, bw, 75.0, 2.5e-4).expect("design");
        println!(
            "target {bw} Hz: kp = {:.4e} Hz/m, zero = {:.3} Hz, crossover = {:.3} Hz, PM = {:.2} deg, GM = {:.2} dB at {:.1} Hz, modulus margin = {:.3}",
            d.kp,
            d.zero_hz,
            d.crossover_hz(),
            d.margins.phase_margin_deg,
            d.margins.gain_margin_db(),
            d.margins.phase_crossover_rad_s / std::f64::consts::TAU,
            d.margins.modulus_margin
        );
    }
}
