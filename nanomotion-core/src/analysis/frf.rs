//! Non-parametric frequency response function (FRF) identification.
//!
//! - Open loop, [`frf_h1`]: Ĥ₁ = S_yu / S_uu with the magnitude-squared coherence
//!   γ² = |S_yu|² / (S_uu S_yy). H1 is unbiased for noise on the output that is
//!   uncorrelated with the input — which is *not* the case in closed loop, where the
//!   feedback carries the output noise into the input and H1 drifts towards −1/C.
//! - Closed loop, [`frf_closed_loop`] (thesis Fig. 2.8): noise d is injected at the
//!   plant input, u = d − C y. The sensitivity S = 1/(1 + PC) is the FRF from d to u,
//!   the process sensitivity S_P = P S the FRF from d to y, and P = S_P / S. Both are
//!   estimated against the injected noise, which is uncorrelated with the
//!   disturbances, so P is consistent.
//!
//! Notation: S_yu(f) is the cross spectrum E[Y conj(U)] = `csd_welch(u, y)`; every
//! estimate uses the Welch conventions of [`super::spectral`].

use super::{AnalysisError, Complex, SpectralMatrix, WelchOptions};
use serde::{Deserialize, Serialize};

/// An estimated frequency response with its coherence.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Frf {
    /// Frequencies in Hz.
    pub freq_hz: Vec<f64>,
    /// Complex response H(f_k) in unit_y/unit_u.
    pub response: Vec<Complex<f64>>,
    /// Magnitude-squared coherence in [0, 1]: the fraction of the output power
    /// linearly explained by the input. Trust the estimate where it is close to 1.
    pub coherence: Vec<f64>,
}

impl Frf {
    /// |H(f_k)| in unit_y/unit_u.
    pub fn magnitude(&self) -> Vec<f64> {
        self.response.iter().map(|h| h.norm()).collect()
    }

    /// 20 log₁₀ |H(f_k)| in dB.
    pub fn magnitude_db(&self) -> Vec<f64> {
        self.response
            .iter()
            .map(|h| 20.0 * h.norm().log10())
            .collect()
    }

    /// Phase ∠H(f_k) in degrees, wrapped to (−180, 180].
    pub fn phase_deg(&self) -> Vec<f64> {
        self.response.iter().map(|h| h.arg().to_degrees()).collect()
    }
}

/// Open-loop H1 estimate Ĥ(f) = S_yu / S_uu from input `u` and output `y` (same
/// length, sampled together at `fs_hz`), with the coherence. Bins where S_uu = 0
/// give H = 0 and γ² = 0.
///
/// ```
/// use nanomotion_core::analysis::{frf_h1, WelchOptions};
/// use nanomotion_core::rng::Rng;
/// // y_k = 0.5 u_{k-1}: |H| = 0.5 at every frequency.
/// let mut rng = Rng::new(5);
/// let u: Vec<f64> = (0..20_000).map(|_| rng.normal()).collect();
/// let y: Vec<f64> = (0..u.len()).map(|k| if k > 0 { 0.5 * u[k - 1] } else { 0.0 }).collect();
/// let h = frf_h1(&u, &y, 1000.0, &WelchOptions::new(256)).unwrap();
/// assert!((h.magnitude()[30] - 0.5).abs() < 0.01);
/// ```
pub fn frf_h1(u: &[f64], y: &[f64], fs_hz: f64, opts: &WelchOptions) -> Result<Frf, AnalysisError> {
    let m = SpectralMatrix::compute(&[u, y], fs_hz, opts)?;
    let suu = m.auto(0);
    let syu = m.cross(0, 1);
    Ok(Frf {
        response: ratio(&syu, &suu),
        coherence: m.coherence(0, 1),
        freq_hz: m.freq_hz,
    })
}

/// Closed-loop identification from noise injected at the plant input (Fig. 2.8).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ClosedLoopFrf {
    /// Frequencies in Hz.
    pub freq_hz: Vec<f64>,
    /// Sensitivity Ŝ = S_ud / S_dd (injected noise d → plant input u), dimensionless.
    pub sensitivity: Vec<Complex<f64>>,
    /// Process sensitivity Ŝ_P = S_yd / S_dd (d → plant output y), unit_y/unit_u.
    pub process_sensitivity: Vec<Complex<f64>>,
    /// Plant P̂ = Ŝ_P / Ŝ = S_yd / S_ud in unit_y/unit_u.
    pub plant: Vec<Complex<f64>>,
    /// Coherence between d and u.
    pub coherence_sensitivity: Vec<f64>,
    /// Coherence between d and y.
    pub coherence_process_sensitivity: Vec<f64>,
}

impl ClosedLoopFrf {
    /// The plant estimate as an [`Frf`], with the smaller of the two coherences
    /// (P̂ is only as good as the worse of Ŝ and Ŝ_P).
    pub fn plant_frf(&self) -> Frf {
        Frf {
            freq_hz: self.freq_hz.clone(),
            response: self.plant.clone(),
            coherence: self
                .coherence_sensitivity
                .iter()
                .zip(&self.coherence_process_sensitivity)
                .map(|(a, b)| a.min(*b))
                .collect(),
        }
    }

    /// Controller estimate Ĉ = (1/Ŝ − 1) / P̂ for the loop u = d − C y (S = 1/(1 + PC)).
    pub fn controller(&self) -> Vec<Complex<f64>> {
        self.sensitivity
            .iter()
            .zip(&self.plant)
            .map(|(s, p)| (Complex::new(1.0, 0.0) / s - 1.0) / p)
            .collect()
    }
}

/// Closed-loop FRF identification: `noise` is the injected signal d, `plant_input`
/// the plant input u = d − C y and `plant_output` the (measured) plant output y, all
/// of the same length and sampled at `fs_hz`. Returns Ŝ, Ŝ_P and P̂ = Ŝ_P/Ŝ
/// (see the module doc); the feedback sign convention only matters for
/// [`ClosedLoopFrf::controller`].
pub fn frf_closed_loop(
    noise: &[f64],
    plant_input: &[f64],
    plant_output: &[f64],
    fs_hz: f64,
    opts: &WelchOptions,
) -> Result<ClosedLoopFrf, AnalysisError> {
    let m = SpectralMatrix::compute(&[noise, plant_input, plant_output], fs_hz, opts)?;
    let sdd = m.auto(0);
    let sud = m.cross(0, 1);
    let syd = m.cross(0, 2);
    Ok(ClosedLoopFrf {
        sensitivity: ratio(&sud, &sdd),
        process_sensitivity: ratio(&syd, &sdd),
        plant: sud
            .iter()
            .zip(&syd)
            .map(|(su, sy)| {
                if su.norm_sqr() > 0.0 {
                    sy / su
                } else {
                    Complex::new(0.0, 0.0)
                }
            })
            .collect(),
        coherence_sensitivity: m.coherence(0, 1),
        coherence_process_sensitivity: m.coherence(0, 2),
        freq_hz: m.freq_hz,
    })
}

fn ratio(num: &[Complex<f64>], den: &[f64]) -> Vec<Complex<f64>> {
    num.iter()
        .zip(den)
        .map(|(n, d)| {
            if *d > 0.0 {
                n / *d
            } else {
                Complex::new(0.0, 0.0)
            }
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rng::Rng;
    use std::f64::consts::TAU;

    /// A second-order discrete system y_k = b1 u_{k−1} + b2 u_{k−2} − a1 y_{k−1} − a2 y_{k−2}
    /// (strictly proper, so it can sit in a loop without an algebraic loop).
    #[derive(Clone, Copy)]
    struct Biquad {
        b1: f64,
        b2: f64,
        a1: f64,
        a2: f64,
        u: [f64; 2],
        y: [f64; 2],
    }

    impl Biquad {
        /// Resonance with pole radius r at f0_hz, unit DC gain, zero at z = −1.
        fn resonance(r: f64, f0_hz: f64, fs_hz: f64) -> Self {
            let a1 = -2.0 * r * (TAU * f0_hz / fs_hz).cos();
            let a2 = r * r;
            let g = (1.0 + a1 + a2) / 2.0;
            Self {
                b1: g,
                b2: g,
                a1,
                a2,
                u: [0.0; 2],
                y: [0.0; 2],
            }
        }

        /// The output for this sample (depends on past inputs only).
        fn output(&self) -> f64 {
            self.b1 * self.u[0] + self.b2 * self.u[1] - self.a1 * self.y[0] - self.a2 * self.y[1]
        }

        /// Commit this sample's input u and output y.
        fn push(&mut self, u: f64, y: f64) {
            self.u = [u, self.u[0]];
            self.y = [y, self.y[0]];
        }

        /// Exact frequency response at f_hz.
        fn response(&self, f_hz: f64, fs_hz: f64) -> Complex<f64> {
            let z1 = Complex::from_polar(1.0, -TAU * f_hz / fs_hz); // z⁻¹
            (z1 * self.b1 + z1 * z1 * self.b2)
                / (Complex::new(1.0, 0.0) + z1 * self.a1 + z1 * z1 * self.a2)
        }
    }

    fn median(mut v: Vec<f64>) -> f64 {
        v.sort_by(f64::total_cmp);
        v[v.len() / 2]
    }

    #[test]
    fn h1_recovers_a_filtered_white_noise_system() {
        let fs = 1000.0;
        let plant = Biquad::resonance(0.97, 80.0, fs);
        let mut sim = plant;
        let mut rng = Rng::new(11);
        let n = 1 << 18;
        let (mut u, mut y) = (Vec::with_capacity(n), Vec::with_capacity(n));
        for _ in 0..n {
            let uk = rng.normal();
            let yk = sim.output();
            sim.push(uk, yk);
            u.push(uk);
            // Output measurement noise: H1 stays unbiased, the coherence drops.
            y.push(yk + 0.05 * rng.normal());
        }
        let frf = frf_h1(&u, &y, fs, &WelchOptions::new(2048)).unwrap();
        let mut checked = 0;
        for k in 1..frf.freq_hz.len() - 1 {
            let h = plant.response(frf.freq_hz[k], fs);
            if frf.coherence[k] > 0.9 {
                let rel = (frf.response[k] - h).norm() / h.norm();
                assert!(rel < 0.05, "f = {} Hz: rel. error {rel}", frf.freq_hz[k]);
                checked += 1;
            }
        }
        // Coherence is high up to where |P| falls into the output noise (≈ 400 bins).
        assert!(checked > 300, "only {checked} bins with high coherence");
        // Near the resonance (|P| ≈ 9) the estimate is within 3 %.
        let k0 = (80.0 / (fs / 2048.0)) as usize;
        let h0 = plant.response(frf.freq_hz[k0], fs);
        assert!(h0.norm() > 5.0);
        assert!((frf.magnitude()[k0] / h0.norm() - 1.0).abs() < 0.03);
        let dphi = frf.phase_deg()[k0] - h0.arg().to_degrees();
        assert!(dphi.abs() < 2.0, "phase error {dphi} deg");
        assert!((frf.magnitude_db()[k0] - 20.0 * frf.magnitude()[k0].log10()).abs() < 1e-12);
    }

    #[test]
    fn closed_loop_sp_over_s_recovers_the_plant_where_h1_is_biased() {
        // Loop of Fig. 2.8: u = d − K (y + v), y = P u; d injected noise, v sensor noise.
        let fs = 1000.0;
        let plant = Biquad::resonance(0.95, 50.0, fs);
        let k_gain = 1.0;
        let mut sim = plant;
        let mut rng = Rng::new(12);
        let n = 1 << 19;
        let (mut d, mut u, mut ym) = (
            Vec::with_capacity(n),
            Vec::with_capacity(n),
            Vec::with_capacity(n),
        );
        for _ in 0..n {
            let dk = rng.normal();
            let vk = 0.5 * rng.normal();
            let yk = sim.output();
            let y_meas = yk + vk;
            let uk = dk - k_gain * y_meas;
            sim.push(uk, yk);
            d.push(dk);
            u.push(uk);
            ym.push(y_meas);
        }
        assert!(ym.iter().all(|v| v.abs() < 100.0), "loop must be stable");
        let opts = WelchOptions::new(1024);
        let cl = frf_closed_loop(&d, &u, &ym, fs, &opts).unwrap();
        let naive = frf_h1(&u, &ym, fs, &opts).unwrap();

        let (mut err_cl, mut err_naive) = (Vec::new(), Vec::new());
        for k in 1..100 {
            // 1…98 Hz: around and below the resonance.
            let f = cl.freq_hz[k];
            let p = plant.response(f, fs);
            err_cl.push((cl.plant[k] - p).norm() / p.norm());
            err_naive.push((naive.response[k] - p).norm() / p.norm());
            // ... and the bias is the one feedback predicts: with S_dd = 1 and
            // S_vv = 0.25 (white), H1 → (P S_dd − K S_vv) / (S_dd + K² S_vv).
            let h1_theory = (p - 0.25 * k_gain) / (1.0 + 0.25 * k_gain * k_gain);
            assert!(
                (naive.response[k] - h1_theory).norm() / h1_theory.norm() < 0.1,
                "H1 at {f} Hz"
            );
            // Ŝ and Ŝ_P match the closed-form loop functions.
            let s = Complex::new(1.0, 0.0) / (Complex::new(1.0, 0.0) + p * k_gain);
            assert!(
                (cl.sensitivity[k] - s).norm() / s.norm() < 0.1,
                "S at {f} Hz"
            );
            assert!(
                (cl.process_sensitivity[k] - p * s).norm() / (p * s).norm() < 0.1,
                "S_P at {f} Hz"
            );
        }
        let (m_cl, m_naive) = (median(err_cl.clone()), median(err_naive));
        assert!(
            m_cl < 0.03,
            "closed-loop estimate: median rel. error {m_cl}"
        );
        assert!(
            err_cl.iter().all(|e| *e < 0.12),
            "max rel. error {:?}",
            err_cl.iter().cloned().fold(0.0, f64::max)
        );
        assert!(
            m_naive > 0.2,
            "naive H1 should be biased by the feedback, median error {m_naive}"
        );
        // Ĉ = (1/Ŝ − 1)/P̂ recovers the static gain K.
        let c = cl.controller();
        assert!(median((1..100).map(|k| (c[k].re - k_gain).abs()).collect()) < 0.05);
        let pf = cl.plant_frf();
        assert!(
            pf.coherence
                .iter()
                .zip(&cl.coherence_sensitivity)
                .all(|(a, b)| a <= b)
        );
    }
}
