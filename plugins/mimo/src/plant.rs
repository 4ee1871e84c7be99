//! The plant model (7.1) of Sec. 7.2: diagonal second-order terms (the stage's
//! mass on the combined stiffness of piezo stack and flexures) and constant
//! off-diagonal terms (static coupling, e.g. from alignment errors),
//!
//! ```text
//! G(s) = [ G_xx  c_xy  c_xz ;  c_yx  G_yy  c_yz ;  c_zx  c_zy  G_zz ],
//! G_ii(s) = k_i / (s²/ω_i² + 2ζ_i s/ω_i + 1),
//! ```
//!
//! and its fit to a measured (or simulated-measured) FRF as the thesis describes:
//! each diagonal term by least squares on the FRF up to above its resonance; each
//! off-diagonal constant with the mean magnitude of the FRF element over the
//! band of the desired bandwidth and the sign of its low-frequency real part
//! ("some off-diagonal terms have a minus sign in order to let the phase
//! correspond to the phase at low frequencies in the measured FRF").

use crate::error::{MimoError, magnitude, positive};
use crate::optim::nelder_mead;
use nalgebra::DMatrix;
use nanomotion_core::analysis::CMatrix;
use nanomotion_core::lti::{Complex, StateSpace};
use serde::{Deserialize, Serialize};
use std::f64::consts::TAU;

/// One diagonal term k/(s²/ω² + 2ζs/ω + 1).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SecondOrderTerm {
    /// Static gain k (plant output unit per input unit).
    pub gain: f64,
    /// Undamped natural frequency f = ω/2π (Hz).
    pub f_hz: f64,
    /// Relative damping ζ (-).
    pub damping: f64,
}

impl SecondOrderTerm {
    /// Frequency response at `f_hz`.
    pub fn response(&self, f_hz: f64) -> Complex<f64> {
        let r = f_hz / self.f_hz;
        Complex::new(self.gain, 0.0) / Complex::new(1.0 - r * r, 2.0 * self.damping * r)
    }
}

/// The plant (7.1): diagonal second-order terms, constant couplings.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CoupledPlant {
    /// Diagonal terms G_ii, one per axis.
    pub diagonal: Vec<SecondOrderTerm>,
    /// Off-diagonal constants (row = output, column = input); the diagonal of
    /// this matrix is ignored.
    pub coupling: Vec<Vec<f64>>,
}

impl CoupledPlant {
    /// Number of axes.
    pub fn axes(&self) -> usize {
        self.diagonal.len()
    }

    /// Check sizes and numbers.
    pub fn validate(&self) -> Result<(), MimoError> {
        let n = self.axes();
        if n == 0 {
            return Err(MimoError::param(
                "plant.diagonal",
                "is empty",
                "give one term per axis",
            ));
        }
        for (i, t) in self.diagonal.iter().enumerate() {
            magnitude(&format!("plant.diagonal[{i}].gain"), t.gain)?;
            if t.gain == 0.0 {
                return Err(MimoError::param(
                    format!("plant.diagonal[{i}].gain"),
                    "is 0",
                    "the diagonal term must have a non-zero gain",
                ));
            }
            positive(&format!("plant.diagonal[{i}].f_hz"), t.f_hz)?;
            positive(&format!("plant.diagonal[{i}].damping"), t.damping)?;
        }
        if self.coupling.len() != n || self.coupling.iter().any(|r| r.len() != n) {
            return Err(MimoError::param(
                "plant.coupling",
                format!("must be {n}×{n} (one row per output)"),
                "give a square matrix with as many rows as diagonal terms",
            ));
        }
        for (j, r) in self.coupling.iter().enumerate() {
            for (i, v) in r.iter().enumerate() {
                magnitude(&format!("plant.coupling[{j}][{i}]"), *v)?;
            }
        }
        Ok(())
    }

    /// State-space realisation (2 states per axis: position and velocity/ω, so
    /// that the entries stay of the size of k and ω): the couplings are a
    /// direct term.
    pub fn to_ss(&self) -> Result<StateSpace, MimoError> {
        self.validate()?;
        let n = self.axes();
        let mut a = DMatrix::zeros(2 * n, 2 * n);
        let mut b = DMatrix::zeros(2 * n, n);
        let mut c = DMatrix::zeros(n, 2 * n);
        let mut d = DMatrix::zeros(n, n);
        for (i, t) in self.diagonal.iter().enumerate() {
            let w = TAU * t.f_hz;
            let o = 2 * i;
            a[(o, o + 1)] = w;
            a[(o + 1, o)] = -w;
            a[(o + 1, o + 1)] = -2.0 * t.damping * w;
            b[(o + 1, i)] = t.gain * w;
            c[(i, o)] = 1.0;
            for j in 0..n {
                if j != i {
                    d[(j, i)] = self.coupling[j][i];
                }
            }
        }
        StateSpace::new(a, b, c, d, None).map_err(MimoError::lti("plant (7.1)"))
    }

    /// G_d = diag(G_ii): the plant without its couplings.
    pub fn diagonal_only(&self) -> CoupledPlant {
        let n = self.axes();
        CoupledPlant {
            diagonal: self.diagonal.clone(),
            coupling: vec![vec![0.0; n]; n],
        }
    }

    /// G(j2πf).
    pub fn response(&self, f_hz: f64) -> CMatrix {
        let n = self.axes();
        CMatrix::from_fn(n, n, |j, i| {
            if i == j {
                self.diagonal[i].response(f_hz)
            } else {
                Complex::new(self.coupling[j][i], 0.0)
            }
        })
    }
}

/// Options of [`fit_coupled_plant`].
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct FitOptions {
    /// The diagonal terms are fitted on frequencies up to this multiple of the
    /// resonance (the peak of |G_ii|): higher modes are not modelled.
    pub diagonal_up_to: f64,
    /// Band (Hz) of the desired bandwidth over which the coupling magnitudes are
    /// matched.
    pub coupling_band_hz: [f64; 2],
    /// Frequencies (Hz) below which the sign of each coupling is read from the
    /// real part of the FRF.
    pub sign_below_hz: f64,
}

impl Default for FitOptions {
    /// Diagonal up to 1.3 × resonance, couplings over 5–30 Hz (around the ≈ 15–25
    /// Hz crossovers of Ch. 7), signs below 5 Hz.
    fn default() -> Self {
        Self {
            diagonal_up_to: 1.3,
            coupling_band_hz: [5.0, 30.0],
            sign_below_hz: 5.0,
        }
    }
}

/// Fit (7.1) to an FRF `frf[k]` (outputs × inputs) at `freq_hz[k]` (see the
/// [module docs](self)). The FRF must be square, on increasing frequencies.
pub fn fit_coupled_plant(
    freq_hz: &[f64],
    frf: &[CMatrix],
    opts: &FitOptions,
) -> Result<CoupledPlant, MimoError> {
    if freq_hz.len() != frf.len() || freq_hz.len() < 8 {
        return Err(MimoError::param(
            "frf",
            format!("{} frequencies and {} matrices", freq_hz.len(), frf.len()),
            "give the same number (at least 8) of frequencies and FRF matrices",
        ));
    }
    let n = frf[0].nrows();
    if n == 0 || frf.iter().any(|m| m.nrows() != n || m.ncols() != n) {
        return Err(MimoError::param(
            "frf",
            "matrices are not all square of one size",
            "give an n×n FRF",
        ));
    }
    if freq_hz.windows(2).any(|w| !(w[1] > w[0])) || !(freq_hz[0] > 0.0) {
        return Err(MimoError::param(
            "freq_hz",
            "must be positive and increasing",
            "sort the FRF",
        ));
    }
    if frf
        .iter()
        .any(|m| m.iter().any(|v| !v.re.is_finite() || !v.im.is_finite()))
    {
        return Err(MimoError::param(
            "frf",
            "has a non-finite entry",
            "drop the bad bins",
        ));
    }
    let mut diagonal = Vec::with_capacity(n);
    for i in 0..n {
        let g: Vec<Complex<f64>> = frf.iter().map(|m| m[(i, i)]).collect();
        let kpk = (0..g.len())
            .max_by(|&a, &b| g[a].norm().total_cmp(&g[b].norm()))
            .unwrap_or(0);
        let f_peak = freq_hz[kpk];
        let k0 = g[0].re;
        let zeta0 = (k0.abs() / (2.0 * g[kpk].norm())).clamp(1e-3, 0.7);
        let f_top = opts.diagonal_up_to * f_peak;
        let idx: Vec<usize> = (0..g.len()).filter(|&k| freq_hz[k] <= f_top).collect();
        let mut cost = |p: &[f64]| {
            let t = SecondOrderTerm {
                gain: k0.signum() * p[0].exp(),
                f_hz: p[1].exp(),
                damping: p[2].exp(),
            };
            idx.iter()
                .map(|&k| {
                    let e = t.response(freq_hz[k]) - g[k];
                    e.norm_sqr() / g[k].norm_sqr().max(1e-300)
                })
                .sum::<f64>()
        };
        let (p, _) = nelder_mead(
            &mut cost,
            &[k0.abs().max(1e-300).ln(), f_peak.ln(), zeta0.ln()],
            0.1,
            1e-12,
            4000,
        );
        diagonal.push(SecondOrderTerm {
            gain: k0.signum() * p[0].exp(),
            f_hz: p[1].exp(),
            damping: p[2].exp(),
        });
    }
    let [lo, hi] = opts.coupling_band_hz;
    let band: Vec<usize> = (0..freq_hz.len())
        .filter(|&k| freq_hz[k] >= lo && freq_hz[k] <= hi)
        .collect();
    let low: Vec<usize> = (0..freq_hz.len())
        .filter(|&k| freq_hz[k] <= opts.sign_below_hz)
        .collect();
    if band.is_empty() || low.is_empty() {
        return Err(MimoError::param(
            "coupling_band_hz",
            format!(
                "no FRF bins in [{lo}, {hi}] Hz or below {} Hz",
                opts.sign_below_hz
            ),
            "measure the FRF over the desired bandwidth and below it",
        ));
    }
    let mut coupling = vec![vec![0.0; n]; n];
    for (j, row) in coupling.iter_mut().enumerate() {
        for (i, c) in row.iter_mut().enumerate() {
            if i == j {
                continue;
            }
            let mag = band.iter().map(|&k| frf[k][(j, i)].norm()).sum::<f64>() / band.len() as f64;
            let re = low.iter().map(|&k| frf[k][(j, i)].re).sum::<f64>();
            *c = if re < 0.0 { -mag } else { mag };
        }
    }
    Ok(CoupledPlant { diagonal, coupling })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn plant() -> CoupledPlant {
        CoupledPlant {
            diagonal: vec![
                SecondOrderTerm {
                    gain: 850.0,
                    f_hz: 124.0,
                    damping: 0.05,
                },
                SecondOrderTerm {
                    gain: 830.0,
                    f_hz: 126.0,
                    damping: 0.06,
                },
                SecondOrderTerm {
                    gain: 170.0,
                    f_hz: 350.0,
                    damping: 0.04,
                },
            ],
            coupling: vec![
                vec![0.0, 8.5, -4.0],
                vec![8.0, 0.0, 2.5],
                vec![-3.0, 3.5, 0.0],
            ],
        }
    }

    #[test]
    fn state_space_matches_the_closed_form_response() {
        let p = plant();
        let ss = p.to_ss().unwrap();
        for f in [0.5, 20.0, 124.0, 400.0] {
            let a = ss.evalfr(Complex::new(0.0, TAU * f));
            let b = p.response(f);
            assert!((a - &b).norm() < 1e-9 * b.norm(), "{f}");
        }
    }

    #[test]
    fn fit_recovers_a_model_of_its_own_structure() {
        let p = plant();
        let f: Vec<f64> = (0..400).map(|k| 0.5 * 1.02f64.powi(k)).collect();
        let frf: Vec<CMatrix> = f.iter().map(|&ff| p.response(ff)).collect();
        let fit = fit_coupled_plant(&f, &frf, &FitOptions::default()).unwrap();
        for (a, b) in fit.diagonal.iter().zip(&p.diagonal) {
            assert!((a.gain / b.gain - 1.0).abs() < 1e-5, "{a:?} vs {b:?}");
            assert!((a.f_hz / b.f_hz - 1.0).abs() < 1e-5, "{a:?} vs {b:?}");
            assert!((a.damping / b.damping - 1.0).abs() < 1e-4, "{a:?} vs {b:?}");
        }
        for j in 0..3 {
            for i in 0..3 {
                if i != j {
                    assert!((fit.coupling[j][i] - p.coupling[j][i]).abs() < 1e-12);
                }
            }
        }
    }

    #[test]
    fn bad_frf_is_refused_by_name() {
        let e = fit_coupled_plant(&[1.0, 2.0], &[], &FitOptions::default()).unwrap_err();
        assert!(e.to_string().contains("frf"));
        let mut p = plant();
        p.coupling.pop();
        assert!(
            p.to_ss()
                .unwrap_err()
                .to_string()
                .contains("plant.coupling")
        );
    }
}
