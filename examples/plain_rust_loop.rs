//! A closed loop in plain Rust, without YAML or a scheduler: the role traits
//! (`Source`, `Controller`, `Sensor`) and the LTI toolkit are enough.
//!
//! The walking piezo stage's linear model (thesis (2.3)) is discretised by ZOH at
//! 4 kHz, a PI controller (2.10) drives the frequency f_α, a 5 nm encoder closes the
//! loop. Before running, the loop's stability is *computed*: the poles of the
//! discrete closed loop T = CP/(1+CP) must lie inside the unit circle.
//!
//! Run: `cargo run --release --example plain_rust_loop`

use nanomotion::core::blocks::control::Pi;
use nanomotion::core::blocks::sensors::{Quantizer, Rounding};
use nanomotion::core::blocks::sources::ConstantVelocity;
use nanomotion::core::lti::{
    C2dMethod, SsStepper, TransferFunction, feedback, series, stability_margins,
};
use nanomotion::core::{Controller, Sensor, Source};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let dt = 1.0 / 4000.0; // 4 kHz control
    // Stage: P(s) = c (b s + k) / (s (M s² + b s + k)), thesis (2.3).
    let (c, m, f_res, zeta) = (4e-6, 0.255, 575.0, 0.05);
    let k = 4.0 * std::f64::consts::PI.powi(2) * m * f_res * f_res;
    let b = 2.0 * zeta * (k * m).sqrt();
    let plant_c = TransferFunction::new(vec![c * b, c * k], vec![m, b, k, 0.0], None)?;
    let plant = plant_c.to_ss_cascade()?.c2d(dt, C2dMethod::Zoh)?;

    // PI on f_α: crossover near 20 Hz (below the 575 Hz resonance with margin), integral zero at 4 Hz.
    let kp = 2.0 * std::f64::consts::PI * 20.0 / c;
    let mut pi = Pi::new(kp, 4.0, dt)?;

    // Stability, computed: poles of the closed loop.
    let open_loop = series(&plant, &pi.as_pid().state_space())?;
    let closed = feedback(
        &open_loop,
        &nanomotion::core::lti::StateSpace::gain(nalgebra::DMatrix::identity(1, 1), Some(dt)),
        -1.0,
    )?;
    let max_pole = closed.poles().iter().map(|p| p.norm()).fold(0.0, f64::max);
    println!(
        "closed-loop spectral radius: {max_pole:.6} (stable: {})",
        max_pole < 1.0
    );
    assert!(max_pole < 1.0, "the loop must be stable before it runs");
    let m = stability_margins(&open_loop)?;
    println!(
        "margins: phase {:.1}° at {:.1} Hz, gain {:.1} dB, modulus {:.2}",
        m.phase_margin_deg,
        m.gain_crossover_rad_s / std::f64::consts::TAU,
        m.gain_margin_db(),
        m.modulus_margin
    );

    let mut stage = SsStepper::new(&plant)?;
    let mut reference = ConstantVelocity::new(10e-6); // 10 µm/s
    let mut encoder = Quantizer::new(5e-9, Rounding::Round);
    let (mut r, mut y, mut ym, mut u) = ([0.0; 2], [0.0], [0.0], [0.0]);
    let mut sum_sq = 0.0;
    let mut n = 0usize;
    for step in 0..8000 {
        let t = step as f64 * dt;
        reference.sample(t, &mut r);
        stage.output(&u, &mut y); // strictly proper: y[k] from the state
        encoder.measure(t, &y, &mut ym);
        pi.control(&[r[0] - ym[0]], &mut u);
        stage.update(&u);
        if t >= 0.5 {
            sum_sq += (r[0] - y[0]).powi(2);
            n += 1;
        }
    }
    println!(
        "true tracking error after 0.5 s: {:.3} nm rms over {n} samples",
        (sum_sq / n as f64).sqrt() * 1e9
    );
    Ok(())
}
