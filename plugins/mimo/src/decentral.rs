//! The decentralised controller (7.2): per axis an integrator (z) or double
//! integrator (x, y), a lead filter and a second-order low-pass,
//!
//! ```text
//! k_ii(s) = k / s^{n_I} · (s/ω_z + 1)/(s/ω_p + 1) · 1/(s²/ω_lp² + 2ζ_lp s/ω_lp + 1),
//! ```
//!
//! with the gain k set so that the diagonal loop gain |G_ii k_ii| crosses 1 at
//! the requested frequency (loop shaping, as the thesis does on the FRF).
//!
//! Our reading of (7.2)'s lost digits: lead zero 5 Hz (10π rad/s) and pole 45 Hz
//! (90π rad/s) for x and y, low-pass 120 Hz (240π rad/s, ζ = 0.5) for x and y,
//! 100 Hz (ζ = 0.5) for z with no lead; x and y use the same controller, as in
//! the thesis. The thesis's gains (0.56, 2.2) belong to its own plant and
//! units and are not reused: ours follow from the crossover targets.

use crate::error::{MimoError, positive};
use nanomotion_core::analysis::CMatrix;
use nanomotion_core::lti::linalg::polymul;
use nanomotion_core::lti::{Complex, StateSpace, TransferFunction, append};
use serde::{Deserialize, Serialize};
use std::f64::consts::TAU;

/// One axis of (7.2).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct LoopShapedAxis {
    /// Number of integrators n_I (1 or 2).
    pub integrators: u8,
    /// Lead zero (Hz), with `lead_pole_hz`; none when absent.
    #[serde(default)]
    pub lead_zero_hz: Option<f64>,
    /// Lead pole (Hz).
    #[serde(default)]
    pub lead_pole_hz: Option<f64>,
    /// Low-pass corner (Hz).
    pub lowpass_hz: f64,
    /// Low-pass damping ζ_lp.
    pub lowpass_damping: f64,
    /// Gain k (set by [`tune_gains`]).
    #[serde(default)]
    pub gain: f64,
}

impl LoopShapedAxis {
    fn validate(&self, i: usize) -> Result<(), MimoError> {
        if !(1..=2).contains(&self.integrators) {
            return Err(MimoError::param(
                format!("decentralised[{i}].integrators"),
                format!("is {}", self.integrators),
                "give 1 or 2",
            ));
        }
        positive(&format!("decentralised[{i}].lowpass_hz"), self.lowpass_hz)?;
        positive(
            &format!("decentralised[{i}].lowpass_damping"),
            self.lowpass_damping,
        )?;
        match (self.lead_zero_hz, self.lead_pole_hz) {
            (None, None) => {}
            (Some(z), Some(p)) => {
                positive(&format!("decentralised[{i}].lead_zero_hz"), z)?;
                positive(&format!("decentralised[{i}].lead_pole_hz"), p)?;
            }
            _ => {
                return Err(MimoError::param(
                    format!("decentralised[{i}].lead_pole_hz"),
                    "lead zero and pole must be given together",
                    "give both or neither",
                ));
            }
        }
        Ok(())
    }

    /// Numerator and denominator (highest power first) with gain 1.
    fn shape(&self) -> (Vec<f64>, Vec<f64>) {
        let mut num = vec![1.0];
        let mut den = vec![1.0];
        for _ in 0..self.integrators {
            den = polymul(&den, &[1.0, 0.0]);
        }
        if let (Some(z), Some(p)) = (self.lead_zero_hz, self.lead_pole_hz) {
            num = polymul(&num, &[1.0 / (TAU * z), 1.0]);
            den = polymul(&den, &[1.0 / (TAU * p), 1.0]);
        }
        let w = TAU * self.lowpass_hz;
        den = polymul(&den, &[1.0 / (w * w), 2.0 * self.lowpass_damping / w, 1.0]);
        (num, den)
    }

    /// Frequency response with the present gain.
    pub fn response(&self, f_hz: f64) -> Complex<f64> {
        let (n, d) = self.shape();
        let s = Complex::new(0.0, TAU * f_hz);
        let ev = |p: &[f64]| p.iter().fold(Complex::new(0.0, 0.0), |acc, c| acc * s + c);
        ev(&n) / ev(&d) * self.gain
    }

    /// Continuous state space (cascade realisation).
    pub fn to_ss(&self) -> Result<StateSpace, MimoError> {
        let (n, d) = self.shape();
        let n: Vec<f64> = n.iter().map(|v| v * self.gain).collect();
        TransferFunction::new(n, d, None)
            .and_then(|t| t.to_ss_cascade())
            .map_err(MimoError::lti("decentralised controller"))
    }
}

/// Our reading of (7.2) (see the [module docs](self)); gains still 0.
pub fn thesis_shapes() -> Vec<LoopShapedAxis> {
    let xy = LoopShapedAxis {
        integrators: 2,
        lead_zero_hz: Some(5.0),
        lead_pole_hz: Some(45.0),
        lowpass_hz: 120.0,
        lowpass_damping: 0.5,
        gain: 0.0,
    };
    vec![
        xy,
        xy,
        LoopShapedAxis {
            integrators: 1,
            lead_zero_hz: None,
            lead_pole_hz: None,
            lowpass_hz: 100.0,
            lowpass_damping: 0.5,
            gain: 0.0,
        },
    ]
}

/// Set each axis's gain so that |g_ii(j2πf_c) k_ii(j2πf_c)| = 1 at
/// `crossover_hz[i]`, with `g_diag(i, f)` the diagonal plant response.
/// Axes listed in `share` take the gain of the axis they name (x and y equal).
pub fn tune_gains(
    shapes: &mut [LoopShapedAxis],
    g_diag: &dyn Fn(usize, f64) -> Complex<f64>,
    crossover_hz: &[Option<f64>],
    share: &[(usize, usize)],
) -> Result<(), MimoError> {
    for (i, s) in shapes.iter_mut().enumerate() {
        s.validate(i)?;
        if let Some(fc) = crossover_hz.get(i).copied().flatten() {
            positive(&format!("crossover_hz[{i}]"), fc)?;
            let mut unit = *s;
            unit.gain = 1.0;
            s.gain = 1.0 / (g_diag(i, fc) * unit.response(fc)).norm();
        }
    }
    for &(to, from) in share {
        shapes[to].gain = shapes[from].gain;
    }
    Ok(())
}

/// K_d = diag(k_ii) in state space.
pub fn controller(shapes: &[LoopShapedAxis]) -> Result<StateSpace, MimoError> {
    let blocks: Result<Vec<StateSpace>, MimoError> = shapes.iter().map(|s| s.to_ss()).collect();
    append(&blocks?).map_err(MimoError::lti("K_d"))
}

/// K_d(j2πf) as a diagonal complex matrix.
pub fn response(shapes: &[LoopShapedAxis], f_hz: f64) -> CMatrix {
    let n = shapes.len();
    let mut m = CMatrix::zeros(n, n);
    for (i, s) in shapes.iter().enumerate() {
        m[(i, i)] = s.response(f_hz);
    }
    m
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn tuned_gain_puts_the_crossover_where_asked_and_ss_matches() {
        let mut sh = thesis_shapes();
        let g = |i: usize, f: f64| {
            let (k, fr) = [(850.0, 124.0), (850.0, 126.0), (170.0, 350.0)][i];
            let r = f / fr;
            Complex::new(k, 0.0) / Complex::new(1.0 - r * r, 0.1 * r)
        };
        tune_gains(&mut sh, &g, &[Some(16.7), None, Some(25.4)], &[(1, 0)]).unwrap();
        assert!(((g(0, 16.7) * sh[0].response(16.7)).norm() - 1.0).abs() < 1e-12);
        assert!(((g(2, 25.4) * sh[2].response(25.4)).norm() - 1.0).abs() < 1e-12);
        assert_eq!(sh[0].gain, sh[1].gain);
        let k = controller(&sh).unwrap();
        assert_eq!(k.nstates(), 5 + 5 + 3);
        for f in [1.0, 16.7, 300.0] {
            let a = k.evalfr(Complex::new(0.0, TAU * f));
            let b = response(&sh, f);
            assert!((a - &b).norm() < 1e-9 * b.norm(), "{f}");
        }
    }
}
