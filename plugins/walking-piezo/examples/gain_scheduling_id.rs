//! Identify the gain variation of the simulated walking stage with the waveform
//! amplitude A and phase difference φ̄ (Sec. 2.5.1, Fig. 2.14) by closed-loop FRF
//! measurements at several operating points, and fit K_A(A), K_φ(φ̄) as
//! first-order power series on a dB scale (2.13).
//!
//! `cargo run --release -p nanomotion-walking-piezo --example gain_scheduling_id`
use gain_scheduling::fit_power_db;
use std::f64::consts::PI;
use walking_piezo::gain_id::{GainIdConfig, gain_variation_db, identify_operating_point};

fn main() {
    let cfg = GainIdConfig::default();
    let t0 = std::time::Instant::now();
    let amps = [46.0, 41.0, 35.0, 29.0, 23.0];
    let a_pts: Vec<_> = amps
        .iter()
        .map(|&a| identify_operating_point(&cfg, a, PI / 2.0).expect("identification"))
        .collect();
    let phis = [
        PI / 2.0,
        7.0 * PI / 16.0,
        3.0 * PI / 8.0,
        5.0 * PI / 16.0,
        PI / 4.0,
    ];
    let p_pts: Vec<_> = phis
        .iter()
        .map(|&p| identify_operating_point(&cfg, 46.0, p).expect("identification"))
        .collect();
    let ka = gain_variation_db(&a_pts);
    let kp = gain_variation_db(&p_pts);
    println!("A (V)   c (um/cycle)  coherence  K_A (dB)");
    for (p, k) in a_pts.iter().zip(&ka) {
        println!(
            "{:6.1}  {:12.4}  {:9.3}  {:8.3}",
            p.amplitude_v,
            p.step_per_cycle_m * 1e6,
            p.coherence,
            k
        );
    }
    println!("phi_bar (rad)  c (um/cycle)  coherence  K_phi (dB)");
    for (p, k) in p_pts.iter().zip(&kp) {
        println!(
            "{:13.4}  {:12.4}  {:9.3}  {:8.3}",
            p.phase_diff_rad,
            p.step_per_cycle_m * 1e6,
            p.coherence,
            k
        );
    }
    let (law_a, rms_a) = fit_power_db(&amps, &ka).expect("fit K_A");
    let (law_p, rms_p) = fit_power_db(&phis, &kp).expect("fit K_phi");
    println!("K_A fit:   {law_a:?}, rms residual {rms_a:.3} dB");
    println!("K_phi fit: {law_p:?}, rms residual {rms_p:.3} dB");
    println!("({:.1} s)", t0.elapsed().as_secs_f64());
}
