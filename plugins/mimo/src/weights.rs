//! The weighting filters of the thesis's mixed-sensitivity design, (7.10)–(7.12):
//!
//! ```text
//! W_S(i,i) = k_S (s + 2πf_S1)(s + 2πf_S2) / ((s + 2πf_S3)(s + 2π·f_ε))     (7.10)
//! W_KS(i,i) = c                                                           (7.11)
//! W_T(i,i) = k_T α_T² (s² + 4πβ_T f_T s + (2πf_T)²)
//!                     / (s² + 4πβ_Tα_T f_T s + (2πα_T f_T)²)              (7.12)
//! ```
//!
//! all diagonal. f_ε is the thesis's near-integrator 10⁻⁶ Hz (an integrator
//! exactly on the axis makes the H∞ problem unsolvable). With f_S2 = f_S3 = 0
//! (the thesis's z-axis) the two factors cancel and W_S(i,i) is first order,
//! k_S (s + 2πf_S1)/(s + 2πf_ε): one integrator instead of two.
//!
//! Our reading of the lost digits (SPEC: the digit 0 was dropped): k_S = 0.5,
//! c = 0.5, k_T = 0.5, α_T = 10 (α_T = 1 would make W_T a constant),
//! β_T = 0.7; Table 7.2 survives only as "z: 4 … 45": f_S1 = 40 Hz, f_S2 =
//! f_S3 = 0, f_T = 45 Hz for z; the x and y rows are lost entirely, and we
//! chose f_S1 = f_S2 = 8 Hz, f_S3 = f_ε (a double integrator, as the text
//! requires), f_T = 45 Hz so that the diagonal crossovers come out close to the
//! decentralised controller's, which is how the thesis says it chose them.

use crate::error::{MimoError, finite, positive, weight};
use nalgebra::DMatrix;
use nanomotion_core::lti::{StateSpace, append};
use serde::{Deserialize, Serialize};
use std::f64::consts::TAU;

/// Per-axis corner frequencies of Table 7.2 (Hz).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct AxisWeights {
    /// f_S1 (Hz), zero of W_S.
    pub f_s1_hz: f64,
    /// f_S2 (Hz), second zero of W_S (0 together with f_S3 = 0: first-order W_S).
    pub f_s2_hz: f64,
    /// f_S3 (Hz), pole of W_S (f_ε gives a second near-integrator).
    pub f_s3_hz: f64,
    /// f_T (Hz), corner of W_T.
    pub f_t_hz: f64,
}

fn default_near_integrator() -> f64 {
    1e-6
}

/// The weights (7.10)–(7.12) (see the [module docs](self)).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct MixedSensitivityWeights {
    /// k_S: high-frequency gain of W_S (1/k_S bounds the sensitivity peak).
    pub k_s: f64,
    /// c: the constant W_KS (control-effort weight, 1/(plant output unit)).
    pub c: f64,
    /// k_T: low-frequency gain of W_T.
    pub k_t: f64,
    /// α_T: W_T rises by α_T² between f_T and α_T f_T.
    pub alpha_t: f64,
    /// β_T: damping of W_T's zeros.
    pub beta_t: f64,
    /// f_ε (Hz): the near-integrator pole of W_S (thesis 10⁻⁶ Hz).
    #[serde(default = "default_near_integrator")]
    pub near_integrator_hz: f64,
    /// Per-axis corners (Table 7.2), one per plant output.
    pub axes: Vec<AxisWeights>,
}

impl MixedSensitivityWeights {
    /// Our reading of (7.10)–(7.12) and Table 7.2 for the x, y, z axes of the AFM
    /// (see the [module docs](self)).
    pub fn thesis_afm() -> Self {
        let xy = AxisWeights {
            f_s1_hz: 8.0,
            f_s2_hz: 8.0,
            f_s3_hz: 1e-6,
            f_t_hz: 45.0,
        };
        Self {
            k_s: 0.5,
            c: 0.5,
            k_t: 0.5,
            alpha_t: 10.0,
            beta_t: 0.7,
            near_integrator_hz: 1e-6,
            axes: vec![
                xy,
                xy,
                AxisWeights {
                    f_s1_hz: 40.0,
                    f_s2_hz: 0.0,
                    f_s3_hz: 0.0,
                    f_t_hz: 45.0,
                },
            ],
        }
    }

    /// Check every number; names the offending field.
    pub fn validate(&self) -> Result<(), MimoError> {
        weight("weights.k_s", self.k_s)?;
        weight("weights.c", self.c)?;
        weight("weights.k_t", self.k_t)?;
        weight("weights.alpha_t", self.alpha_t)?;
        weight("weights.beta_t", self.beta_t)?;
        positive("weights.near_integrator_hz", self.near_integrator_hz)?;
        if self.axes.is_empty() {
            return Err(MimoError::param(
                "weights.axes",
                "is empty",
                "give one {f_s1_hz, f_s2_hz, f_s3_hz, f_t_hz} per plant output",
            ));
        }
        for (i, a) in self.axes.iter().enumerate() {
            positive(&format!("weights.axes[{i}].f_s1_hz"), a.f_s1_hz)?;
            positive(&format!("weights.axes[{i}].f_t_hz"), a.f_t_hz)?;
            finite(&format!("weights.axes[{i}].f_s2_hz"), a.f_s2_hz)?;
            finite(&format!("weights.axes[{i}].f_s3_hz"), a.f_s3_hz)?;
            let first_order = a.f_s2_hz == 0.0 && a.f_s3_hz == 0.0;
            if !(first_order || (a.f_s2_hz > 0.0 && a.f_s3_hz > 0.0)) {
                return Err(MimoError::param(
                    format!("weights.axes[{i}].f_s3_hz"),
                    format!(
                        "f_S2 = {} Hz, f_S3 = {} Hz: a zero or pole at s = 0 makes the H∞ problem unsolvable",
                        a.f_s2_hz, a.f_s3_hz
                    ),
                    "give both > 0 (f_S3 = near_integrator_hz for a double integrator), or both 0 for a first-order W_S",
                ));
            }
        }
        Ok(())
    }

    /// W_S(i,i) as numerator and denominator in s (highest power first).
    pub fn w_s_tf(&self, i: usize) -> (Vec<f64>, Vec<f64>) {
        let a = self.axes[i];
        let (w1, we) = (TAU * a.f_s1_hz, TAU * self.near_integrator_hz);
        if a.f_s2_hz == 0.0 && a.f_s3_hz == 0.0 {
            (vec![self.k_s, self.k_s * w1], vec![1.0, we])
        } else {
            let (w2, w3) = (TAU * a.f_s2_hz, TAU * a.f_s3_hz);
            (
                vec![self.k_s, self.k_s * (w1 + w2), self.k_s * w1 * w2],
                vec![1.0, w3 + we, w3 * we],
            )
        }
    }

    /// W_T(i,i) as numerator and denominator in s.
    pub fn w_t_tf(&self, i: usize) -> (Vec<f64>, Vec<f64>) {
        let w = TAU * self.axes[i].f_t_hz;
        let (al, be) = (self.alpha_t, self.beta_t);
        let k = self.k_t * al * al;
        (
            vec![k, k * 2.0 * be * w, k * w * w],
            vec![1.0, 2.0 * be * al * w, (al * w) * (al * w)],
        )
    }

    /// W_S: diagonal, one axis per plant output; states in modal-like
    /// (diagonal pole) form for conditioning.
    pub fn w_s(&self) -> Result<StateSpace, MimoError> {
        self.validate()?;
        let mut blocks = Vec::new();
        for (i, a) in self.axes.iter().enumerate() {
            let we = TAU * self.near_integrator_hz;
            let w1 = TAU * a.f_s1_hz;
            // k_S (s + w1)/(s + we) = k_S + k_S (w1 − we)/(s + we).
            let first = StateSpace::new(
                DMatrix::from_element(1, 1, -we),
                DMatrix::from_element(1, 1, 1.0),
                DMatrix::from_element(1, 1, self.k_s * (w1 - we)),
                DMatrix::from_element(1, 1, self.k_s),
                None,
            )
            .map_err(MimoError::lti(format!("W_S axis {i}")))?;
            let sys = if a.f_s2_hz == 0.0 && a.f_s3_hz == 0.0 {
                first
            } else {
                // times (s + w2)/(s + w3) = 1 + (w2 − w3)/(s + w3).
                let (w2, w3) = (TAU * a.f_s2_hz, TAU * a.f_s3_hz);
                let second = StateSpace::new(
                    DMatrix::from_element(1, 1, -w3),
                    DMatrix::from_element(1, 1, 1.0),
                    DMatrix::from_element(1, 1, w2 - w3),
                    DMatrix::from_element(1, 1, 1.0),
                    None,
                )
                .map_err(MimoError::lti(format!("W_S axis {i}")))?;
                nanomotion_core::lti::series(&second, &first)
                    .map_err(MimoError::lti(format!("W_S axis {i}")))?
            };
            blocks.push(sys);
        }
        append(&blocks).map_err(MimoError::lti("W_S"))
    }

    /// W_KS = c·I (size `n_inputs`).
    pub fn w_ks(&self, n_inputs: usize) -> StateSpace {
        StateSpace::gain(DMatrix::identity(n_inputs, n_inputs) * self.c, None)
    }

    /// W_T: diagonal second-order sections (7.12).
    pub fn w_t(&self) -> Result<StateSpace, MimoError> {
        self.validate()?;
        let mut blocks = Vec::new();
        for i in 0..self.axes.len() {
            let w = TAU * self.axes[i].f_t_hz;
            let (al, be) = (self.alpha_t, self.beta_t);
            let k = self.k_t * al * al;
            // k (s² + 2βw s + w²)/(s² + 2βαw s + α²w²) = k + k·(r1 s + r0)/den,
            // r1 = 2βw(1 − α), r0 = w²(1 − α²); states scaled by αw.
            let wp = al * w;
            let r1 = 2.0 * be * w * (1.0 - al);
            let r0 = w * w * (1.0 - al * al);
            // x1' = wp x2, x2' = −wp x1 − 2βwp x2 + wp u  ⇒ x1 = wp²/den · u.
            let a = DMatrix::from_row_slice(2, 2, &[0.0, wp, -wp, -2.0 * be * wp]);
            let b = DMatrix::from_column_slice(2, 1, &[0.0, wp]);
            // r0/den = (r0/wp²) x1; s/den·wp² = wp x2 ⇒ r1 s/den = (r1/wp) x2.
            let c = DMatrix::from_row_slice(1, 2, &[k * r0 / (wp * wp), k * r1 / wp]);
            let d = DMatrix::from_element(1, 1, k);
            blocks.push(
                StateSpace::new(a, b, c, d, None)
                    .map_err(MimoError::lti(format!("W_T axis {i}")))?,
            );
        }
        append(&blocks).map_err(MimoError::lti("W_T"))
    }

    /// Number of states of W_S and W_T together.
    pub fn order(&self) -> usize {
        self.axes
            .iter()
            .map(|a| if a.f_s2_hz == 0.0 && a.f_s3_hz == 0.0 { 1 } else { 2 } + 2)
            .sum()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use nanomotion_core::lti::{Complex, TransferFunction};

    #[test]
    fn realisations_match_the_transfer_functions_of_the_thesis() {
        let w = MixedSensitivityWeights::thesis_afm();
        let ws = w.w_s().unwrap();
        let wt = w.w_t().unwrap();
        assert_eq!(ws.nstates() + wt.nstates(), w.order());
        for i in 0..3 {
            let (n, d) = w.w_s_tf(i);
            let tf_s = TransferFunction::new(n, d, None).unwrap();
            let (n, d) = w.w_t_tf(i);
            let tf_t = TransferFunction::new(n, d, None).unwrap();
            for f in [1e-3, 0.1, 3.0, 45.0, 450.0, 1e4] {
                let s = Complex::new(0.0, TAU * f);
                let (a, b) = (ws.evalfr(s)[(i, i)], tf_s.eval(s));
                assert!(
                    (a - b).norm() < 1e-9 * b.norm(),
                    "W_S {i} at {f}: {a} vs {b}"
                );
                let (a, b) = (wt.evalfr(s)[(i, i)], tf_t.eval(s));
                assert!(
                    (a - b).norm() < 1e-9 * b.norm(),
                    "W_T {i} at {f}: {a} vs {b}"
                );
            }
        }
        // Limits: |W_S(j∞)| = k_S (1/k_S = 6 dB sensitivity bound), W_T(0) = k_T,
        // W_T(j∞) = k_T α².
        let s = Complex::new(0.0, 1e9);
        assert!((ws.evalfr(s)[(0, 0)].norm() - 0.5).abs() < 1e-6);
        assert!((wt.evalfr(Complex::new(0.0, 0.0))[(2, 2)].re - 0.5).abs() < 1e-12);
        assert!((wt.evalfr(s)[(2, 2)].norm() - 50.0).abs() < 1e-4);
    }

    /// Audit D7: `k_s: 1e200` passed "finite and > 0" and `synth` never ended;
    /// weights outside 12 decades of 1 are refused at once, naming the field.
    #[test]
    fn weights_beyond_twelve_decades_are_refused() {
        for (v, ok) in [
            (1e200, false),
            (1e13, false),
            (1e12, true),
            (1e-12, true),
            (1e-13, false),
        ] {
            let mut w = MixedSensitivityWeights::thesis_afm();
            w.k_s = v;
            match w.validate() {
                Ok(()) => assert!(ok, "{v}"),
                Err(e) => {
                    assert!(!ok, "{v}: {e}");
                    let e = e.to_string();
                    assert!(e.contains("weights.k_s") && e.contains("outside"), "{e}");
                }
            }
        }
    }

    #[test]
    fn bad_weights_are_named() {
        let mut w = MixedSensitivityWeights::thesis_afm();
        w.axes[1].f_s3_hz = 0.0;
        let e = w.w_s().unwrap_err().to_string();
        assert!(e.contains("weights.axes[1].f_s3_hz"), "{e}");
        let mut w = MixedSensitivityWeights::thesis_afm();
        w.k_s = f64::NAN;
        assert!(
            w.validate()
                .unwrap_err()
                .to_string()
                .contains("weights.k_s")
        );
    }
}
