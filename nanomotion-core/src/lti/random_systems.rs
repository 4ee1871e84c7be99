//! Seeded random stable systems: the matrices of the `hinfnorm` timings
//! (docs/performance.md), which the `lti_numerics` bench (`hinf_ratio`) times
//! and the `hinf_systems` example writes as JSON for
//! `tools/hinfnorm_vs_ab13dd.py` to time SLICOT's `ab13dd` on — one function
//! for both, so both time the same matrices.

use crate::lti::StateSpace;
use crate::lti::linalg::eigvals;
use crate::rng::Rng;
use nalgebra::DMatrix;

/// An r × c matrix of standard normal entries.
pub fn random(rng: &mut Rng, r: usize, c: usize) -> DMatrix<f64> {
    DMatrix::from_fn(r, c, |_, _| rng.normal())
}

/// A random n × n matrix shifted to spectral abscissa −0.5.
pub fn hurwitz(rng: &mut Rng, n: usize) -> DMatrix<f64> {
    let a = random(rng, n, n);
    let worst = eigvals(&a)
        .iter()
        .map(|p| p.re)
        .fold(f64::NEG_INFINITY, f64::max);
    a - DMatrix::identity(n, n) * (worst + 0.5)
}

/// The issue-29 systems at n = 10, 20, 40, 80: random stable 2 × 2 models
/// without feedthrough, named `c{n}` (continuous, A Hurwitz) and `d{n}`
/// (discrete, T = 0.01 s, the same A scaled to spectral radius 0.95), each
/// drawn from `Rng::new(29 + n)`.
pub fn hinf_ratio_systems() -> Vec<(String, StateSpace)> {
    let mut out = Vec::new();
    for n in [10usize, 20, 40, 80] {
        let mut rng = Rng::new(29 + n as u64);
        let ah = hurwitz(&mut rng, n);
        let rho = eigvals(&ah).iter().map(|p| p.norm()).fold(0.0, f64::max);
        for (kind, a, dt) in [
            ("c", ah.clone(), None),
            ("d", &ah * (0.95 / rho), Some(0.01)),
        ] {
            let (b, c) = (random(&mut rng, n, 2), random(&mut rng, 2, n));
            if let Ok(sys) = StateSpace::new(a, b, c, DMatrix::zeros(2, 2), dt)
                && sys.is_stable()
            {
                out.push((format!("{kind}{n}"), sys));
            }
        }
    }
    out
}
