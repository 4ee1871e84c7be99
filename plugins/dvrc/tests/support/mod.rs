//! Small test systems shared by the lifted-system tests (`lifted_lmi.rs`,
//! `properties.rs`).

use nalgebra::DMatrix;
use nanomotion_core::lti::{StateSpace, TransferFunction, hinfnorm};

/// H(z) = g z⁻¹/(1 − 2r cos θ z⁻¹ + r² z⁻²) at sample time `dt`, scaled to
/// ‖H‖∞ = `norm`.
pub fn resonant_h(r: f64, th: f64, norm: f64, dt: f64) -> StateSpace {
    let den = vec![1.0, -2.0 * r * th.cos(), r * r];
    let ss = TransferFunction::new(vec![0.0, 1.0, 0.0], den, Some(dt))
        .unwrap()
        .to_ss()
        .unwrap();
    let n = hinfnorm(&ss).unwrap().norm;
    ss.scaled(norm / n)
}

/// max |λ(A)|.
pub fn spectral_radius(a: &DMatrix<f64>) -> f64 {
    nanomotion_core::lti::linalg::eigvals(a)
        .iter()
        .map(|z| z.norm())
        .fold(0.0, f64::max)
}
