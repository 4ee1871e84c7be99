//! Fixed 3-axis geometry (x, y, z) of a 3-DOF stage such as the thesis's
//! metrological AFM (Ch. 7), with glam's `DVec3` for positions, displacements
//! and per-axis figures. The rest of the crate is generic in the number of axes
//! (nalgebra for the dynamic-size algebra); this module is the typed view a
//! 3-axis user works in.
//!
//! * [`Stage3`]: a 3-input, 3-output plant (nm/V or m/V) as a map of actuator
//!   vectors to displacement vectors: static gain, frequency response amplitude
//!   and the coupling of a unit push along one axis into the others.
//! * [`positions`], [`rms_per_axis`]: traces of `pos`-like 3-wide signals as
//!   `DVec3`, and the rms of a position error per axis.

use crate::error::MimoError;
pub use glam::DVec3;
use nanomotion_core::analysis::CMatrix;
use nanomotion_core::lti::{Complex, StateSpace};
use std::f64::consts::TAU;

/// Axis labels, in the order of the plant's inputs and outputs.
pub const AXES: [&str; 3] = ["x", "y", "z"];

/// Unit vector of axis `i` (0 = x, 1 = y, 2 = z).
pub fn axis(i: usize) -> DVec3 {
    [DVec3::X, DVec3::Y, DVec3::Z][i % 3]
}

/// A 3×3 plant seen as a map of actuator vectors (x, y, z) to stage
/// displacement vectors.
#[derive(Debug, Clone, Copy)]
pub struct Stage3<'a> {
    plant: &'a StateSpace,
}

impl<'a> Stage3<'a> {
    /// The view of `plant`, which must be continuous with 3 inputs and 3 outputs.
    pub fn new(plant: &'a StateSpace) -> Result<Self, MimoError> {
        if plant.ninputs() != 3 || plant.noutputs() != 3 || plant.dt.is_some() {
            return Err(MimoError::param(
                "plant",
                format!(
                    "is {}×{}{}: a 3-axis stage view needs a continuous 3×3 plant",
                    plant.noutputs(),
                    plant.ninputs(),
                    if plant.dt.is_some() { ", discrete" } else { "" }
                ),
                "use the generic functions for other sizes",
            ));
        }
        Ok(Self { plant })
    }

    /// G(j2πf) (3×3).
    pub fn frf(&self, f_hz: f64) -> CMatrix {
        self.plant.evalfr(Complex::new(0.0, TAU * f_hz))
    }

    /// Static displacement G(0)·v for actuator vector `v`.
    pub fn static_displacement(&self, v: DVec3) -> DVec3 {
        let g = self.plant.evalfr(Complex::new(0.0, 0.0));
        apply_re(&g, v)
    }

    /// Amplitude |G(j2πf)·v| per axis for a sinusoidal actuator vector `v`.
    pub fn amplitude(&self, f_hz: f64, v: DVec3) -> DVec3 {
        amplitude(&self.frf(f_hz), v)
    }

    /// Coupling of a push along `axis_in`: the displacement amplitude of each
    /// axis relative to that of `axis_in` itself at `f_hz`.
    pub fn relative_coupling(&self, f_hz: f64, axis_in: usize) -> DVec3 {
        let a = self.amplitude(f_hz, axis(axis_in));
        a / a[axis_in % 3]
    }
}

/// |G·v| per axis of a 3×3 complex matrix.
pub fn amplitude(g: &CMatrix, v: DVec3) -> DVec3 {
    let r = |i: usize| (g[(i, 0)] * v.x + g[(i, 1)] * v.y + g[(i, 2)] * v.z).norm();
    DVec3::new(r(0), r(1), r(2))
}

fn apply_re(g: &CMatrix, v: DVec3) -> DVec3 {
    let r = |i: usize| (g[(i, 0)] * v.x + g[(i, 1)] * v.y + g[(i, 2)] * v.z).re;
    DVec3::new(r(0), r(1), r(2))
}

/// A 3-wide trace stored sample by sample ([x₀, y₀, z₀, x₁, …], as logged) as
/// positions; None when its length is not a multiple of 3.
pub fn positions(data: &[f64]) -> Option<Vec<DVec3>> {
    if !data.len().is_multiple_of(3) {
        return None;
    }
    Some(
        data.chunks_exact(3)
            .map(|c| DVec3::new(c[0], c[1], c[2]))
            .collect(),
    )
}

/// Rms per axis of reference − position over the samples from `from` on
/// (equal lengths; zero for no sample).
pub fn rms_per_axis(reference: &[DVec3], position: &[DVec3], from: usize) -> DVec3 {
    let mut acc = DVec3::ZERO;
    let mut n = 0usize;
    for (r, p) in reference.iter().zip(position).skip(from) {
        let e = *r - *p;
        acc += e * e;
        n += 1;
    }
    if n == 0 {
        DVec3::ZERO
    } else {
        (acc / n as f64).map(f64::sqrt)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::plant::{CoupledPlant, SecondOrderTerm};

    #[test]
    fn stage_view_matches_the_coupled_plant() {
        let t = |k, f| SecondOrderTerm {
            gain: k,
            f_hz: f,
            damping: 0.05,
        };
        let cp = CoupledPlant {
            diagonal: vec![t(850.0, 124.0), t(835.0, 126.0), t(170.0, 350.0)],
            coupling: vec![
                vec![0.0, 8.0, 1.0],
                vec![9.0, 0.0, 1.0],
                vec![3.0, 3.5, 0.0],
            ],
        };
        let g = cp.to_ss().unwrap();
        let s = Stage3::new(&g).unwrap();
        // (7.1) at DC: diagonal gains and constant couplings, G_ji = coupling[j][i].
        let d = s.static_displacement(DVec3::new(1.0, 0.0, 0.0));
        assert!(
            (d - DVec3::new(850.0, 9.0, 3.0)).abs().max_element() < 1e-9,
            "{d}"
        );
        let c = s.relative_coupling(1e-3, 2);
        assert!(
            (c - DVec3::new(1.0 / 170.0, 1.0 / 170.0, 1.0))
                .abs()
                .max_element()
                < 1e-9
        );
        // Linearity: amplitude of a sum below the sum of amplitudes.
        let a = s.amplitude(124.0, DVec3::ONE);
        let b = s.amplitude(124.0, DVec3::X)
            + s.amplitude(124.0, DVec3::Y)
            + s.amplitude(124.0, DVec3::Z);
        assert!(a.cmple(b + 1e-9).all());
        let bad = StateSpace::gain(nalgebra::DMatrix::identity(2, 2), None);
        assert!(Stage3::new(&bad).unwrap_err().to_string().contains("3×3"));
    }

    #[test]
    fn positions_and_rms() {
        let p = positions(&[1.0, 2.0, 3.0, 1.0, 2.0, 5.0]).unwrap();
        assert_eq!(p[1], DVec3::new(1.0, 2.0, 5.0));
        assert!(positions(&[1.0]).is_none());
        let r = vec![DVec3::new(1.0, 2.0, 4.0); 2];
        // errors (0, 0, 1) and (0, 0, −1): rms 1 on z only.
        assert_eq!(rms_per_axis(&r, &p, 0), DVec3::new(0.0, 0.0, 1.0));
    }
}
