//! Discrete (and continuous) LTI toolkit.
//!
//! Models are kept as state space or cascaded second-order sections: SPEC §1 notes
//! that the Ch. 5 plant discretised at 4 kHz as one high-order polynomial transfer
//! function is too ill-conditioned to simulate from its coefficients.

//!
//! Map of the toolkit (python-control names where one exists):
//! - [`StateSpace`]: construction, [`series`], [`parallel`], [`feedback`], poles,
//!   stability, [`freqresp`](StateSpace::freqresp), delays as states
//!   ([`delay`], [`StateSpace::with_input_delay`]), discretisation
//!   ([`StateSpace::c2d`], [`c2d`]);
//! - [`TransferFunction`]: evaluation, poles/zeros, [`zpk`], `tf2ss`/`ss2tf`;
//! - [`hinfnorm`]: H∞ norm and peak frequency (Hamiltonian / Bruinsma–Steinbuch);
//! - [`fir_lowpass`], [`butter_lowpass`], [`SosCascade`]: filter design and
//!   second-order-section simulation;
//! - [`stability_margins`]: gain, phase and modulus margins of a loop gain;
//! - [`care`], [`care_general`], [`dare`], [`lyap`], [`dlyap`]: stabilising
//!   Riccati solutions (sign function, doubling) and Lyapunov equations;
//!   [`care_general_solution`], [`lyap_solution`] and [`dlyap_solution`]
//!   return a solution struct with the residual, backward error and
//!   iterations, as [`care`] and [`dare`] do ([`RiccatiSolution`]);
//! - [`hinfsyn()`], [`augw`], [`lft`]: H∞ output-feedback synthesis by
//!   γ-iteration on the two DGKF Riccati equations, mixed-sensitivity plants;
//! - [`LmiProblem`]: a small dense LMI feasibility solver (Lyapunov and
//!   switched-system LMIs such as the thesis's (5.16));
//! - [`zpetc()`]: Tomizuka's zero-phase-error tracking controller;
//! - [`SsStepper`], [`lsim`], [`step_response`], [`impulse`]: allocation-free
//!   simulation.
//!
//! # Units
//!
//! Time is in seconds (`dt`, sample periods). **Frequency is angular, in rad/s**,
//! wherever the toolkit evaluates or reports a frequency response: every
//! frequency grid (`w_rad_s` of [`StateSpace::freqresp`], [`StateSpace::bode`],
//! [`TransferFunction::freqresp`], [`sos_freqresp`], [`Zpetc::freqresp`]) and
//! every returned frequency ([`HinfNorm::peak_rad_s`], the `*_rad_s` fields of
//! [`Margins`]); poles are in rad/s (s-plane) or on the z-plane. Design
//! frequencies that engineers specify in hertz are in **Hz** and say so in
//! their names: the cut-offs `cutoff_hz` of [`fir_lowpass`] and
//! [`butter_lowpass`], and the Tustin pre-warp frequency `prewarp_hz` of
//! [`C2dMethod::Tustin`] — for which [`C2dMethod::tustin_prewarp_rad_s`] takes
//! the same frequency in rad/s. Every frequency argument or field carries its
//! unit as a `_rad_s` or `_hz` suffix.
//!
//! # Building models without nalgebra
//!
//! The matrices are nalgebra's [`DMatrix`]; `nanomotion_core` re-exports the
//! nalgebra it is built with ([`crate::nalgebra`]), so a caller needs no
//! nalgebra dependency of a matching version. [`StateSpace::from_rows`] and
//! [`TransferFunction::from_slices`] build models from plain rows
//! (`&[Vec<f64>]`, `&[&[f64]]`, `&[[f64; N]]`), with a typed
//! [`LtiError::RaggedRows`] for rows of unequal length:
//!
//! ```
//! use nanomotion_core::lti::StateSpace;
//! // Mass-spring-damper, x = (position, velocity).
//! let sys = StateSpace::from_rows(
//!     &[[0.0, 1.0], [-4.0, -0.4]],
//!     &[[0.0], [1.0]],
//!     &[[1.0, 0.0]],
//!     &[[0.0]],
//!     None,
//! )
//! .unwrap();
//! assert_eq!((sys.nstates(), sys.ninputs(), sys.noutputs()), (2, 1, 1));
//! let a: nanomotion_core::nalgebra::DMatrix<f64> = sys.a.clone();
//! assert_eq!(a[(1, 0)], -4.0);
//! ```

use nalgebra::DMatrix;
use serde::{Deserialize, Serialize};
use thiserror::Error;

pub mod balred;
pub mod discretise;
pub mod filters;
pub mod freqeval;
pub mod hinf;
pub mod hinfsyn;
pub mod linalg;
pub mod lmi;
pub mod margins;
pub mod random_systems;
pub mod riccati;
mod schur;
pub mod sim;
pub mod ss;
pub mod tf;
pub mod zpetc;

pub use discretise::{C2dMethod, c2d};
pub use filters::{
    SosCascade, butter_lowpass, butter_lowpass_into, fir_lowpass, fir2ss, sos_freqresp,
    sos_realise_into, sos2ss, ss2sos, tustin_section,
};
pub use freqeval::FrequencyEvaluator;
pub use hinf::{HinfNorm, hinfnorm};
pub use hinfsyn::{HinfSyn, HinfSynOptions, augw, hinfsyn, lft};
pub use lmi::{LmiConstraint, LmiError, LmiOptions, LmiProblem, LmiSolution, LmiStatus, LmiVar};
pub use margins::{Margins, stability_margins};
pub use riccati::{
    CareGeneralSolution, LyapunovSolution, RiccatiSolution, care, care_general,
    care_general_solution, dare, dlyap, dlyap_solution, lyap, lyap_solution,
};
pub use sim::{SsStepper, impulse, lsim, lsim_siso, step_response};
pub use ss::{append, delay, feedback, parallel, series, ss2tf, unwrap_phase};
pub use tf::{tf2sos, tf2ss, zpk, zpk_checked, zpk2sos, zpk2ss};
pub use zpetc::{Zpetc, ZpetcFilter, zpetc, zpetc_ss};

/// Complex numbers (nalgebra's re-export of `num_complex::Complex`).
pub use nalgebra::Complex;

/// What can go wrong in an LTI operation.
#[derive(Debug, Clone, PartialEq, Error)]
pub enum LtiError {
    /// Matrix or polynomial dimensions do not fit together.
    #[error("dimension mismatch: {0}")]
    Dimension(String),
    /// Two systems with different sample periods were combined.
    #[error("sample periods differ ({0:?} s vs {1:?} s): discretise both at the same rate")]
    SampleTime(Option<f64>, Option<f64>),
    /// The operation needs a continuous-time (or discrete-time) system.
    #[error("wrong time domain: {0}")]
    Domain(String),
    /// A transfer function with more zeros than poles (not realisable).
    #[error("improper transfer function: numerator degree {num} > denominator degree {den}")]
    Improper {
        /// Numerator degree.
        num: usize,
        /// Denominator degree.
        den: usize,
    },
    /// A parameter is out of range (non-finite, non-positive, above Nyquist, ...).
    #[error("invalid parameter `{name}`: {problem}")]
    Parameter {
        /// Parameter name.
        name: &'static str,
        /// What is wrong.
        problem: String,
    },
    /// A singular matrix where an inverse is needed (e.g. an algebraic loop
    /// I − D₁D₂ in [`feedback`]).
    #[error("singular matrix: {0}")]
    Singular(String),
    /// The system is unstable where a stable one is required (H∞ norm).
    #[error("system is not stable: {0}")]
    Unstable(String),
    /// Rows of unequal length where a matrix is built from rows
    /// ([`StateSpace::from_rows`]).
    #[error("matrix `{matrix}`: row {row} has {len} entries, expected {expected} (ragged rows)")]
    RaggedRows {
        /// Which matrix ("a", "b", "c" or "d").
        matrix: &'static str,
        /// Index of the first offending row.
        row: usize,
        /// Its length.
        len: usize,
        /// The length the matrix's shape requires.
        expected: usize,
    },
}

impl LtiError {
    pub(crate) fn param(name: &'static str, problem: impl Into<String>) -> Self {
        LtiError::Parameter {
            name,
            problem: problem.into(),
        }
    }
}

/// State-space model x' = A x + B u, y = C x + D u; `dt = None` for continuous
/// time (x' = dx/dt), `Some(T)` for discrete time with period T seconds
/// (x' = x[k+1]).
///
/// The fields are public; [`StateSpace::new`] and [`StateSpace::from_rows`]
/// check that the sizes fit and the entries are finite, deserialisation runs
/// the same checks, and every fallible toolkit function re-checks a model
/// whose fields were set directly ([`StateSpace::validate`]), so an
/// inconsistent model is a typed [`LtiError`], never a panic.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(try_from = "StateSpaceParts")]
pub struct StateSpace {
    /// State matrix A (n × n).
    pub a: DMatrix<f64>,
    /// Input matrix B (n × m).
    pub b: DMatrix<f64>,
    /// Output matrix C (p × n).
    pub c: DMatrix<f64>,
    /// Feed-through matrix D (p × m).
    pub d: DMatrix<f64>,
    /// Sample period in seconds, `None` for continuous time.
    pub dt: Option<f64>,
}

/// The serialised form of [`StateSpace`], checked by [`StateSpace::new`] on
/// the way in.
#[derive(Deserialize)]
struct StateSpaceParts {
    a: DMatrix<f64>,
    b: DMatrix<f64>,
    c: DMatrix<f64>,
    d: DMatrix<f64>,
    dt: Option<f64>,
}

impl TryFrom<StateSpaceParts> for StateSpace {
    type Error = LtiError;
    fn try_from(p: StateSpaceParts) -> Result<Self, LtiError> {
        StateSpace::new(p.a, p.b, p.c, p.d, p.dt)
    }
}

/// SISO transfer function num(s)/den(s) or num(z)/den(z), coefficients in
/// **descending** powers (as python-control and MATLAB write them); `dt` as for
/// [`StateSpace`].
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct TransferFunction {
    /// Numerator coefficients, highest power first.
    pub num: Vec<f64>,
    /// Denominator coefficients, highest power first.
    pub den: Vec<f64>,
    /// Sample period in seconds, `None` for continuous time.
    pub dt: Option<f64>,
}

/// One second-order section in scipy's `sos` layout `[b0, b1, b2, a0, a1, a2]`:
/// H(z) = (b0 + b1 z⁻¹ + b2 z⁻²) / (a0 + a1 z⁻¹ + a2 z⁻²). A cascade of sections is
/// a `Vec<SosSection>`.
pub type SosSection = [f64; 6];

/// The SPEC's Ch. 5 plant (integrator, resonance 527 Hz, anti-resonance 624 Hz,
/// resonance 650 Hz, 3 samples delay at 4 kHz), kept as a state-space cascade.
#[cfg(test)]
mod ch5_plant_tests {
    use super::*;
    use crate::lti::linalg::{polymul, polyval};
    use std::f64::consts::PI;

    const DT: f64 = 1.0 / 4000.0;
    const K: f64 = 1.0e3;
    const F1: f64 = 527.0;
    const FA: f64 = 624.0;
    const F2: f64 = 650.0;
    const Z1: f64 = 0.03;
    const ZA: f64 = 0.02;
    const Z2: f64 = 0.04;

    fn w(f: f64) -> f64 {
        2.0 * PI * f
    }

    /// Continuous sections: K/s, ω1²/(s² + 2ζ1ω1 s + ω1²), (s² + 2ζaωa s + ωa²)/ωa²,
    /// ω2²/(s² + 2ζ2ω2 s + ω2²).
    fn sections() -> Vec<TransferFunction> {
        let (w1, wa, w2) = (w(F1), w(FA), w(F2));
        vec![
            TransferFunction {
                num: vec![K],
                den: vec![1.0, 0.0],
                dt: None,
            },
            TransferFunction {
                num: vec![w1 * w1],
                den: vec![1.0, 2.0 * Z1 * w1, w1 * w1],
                dt: None,
            },
            TransferFunction {
                num: vec![1.0, 2.0 * ZA * wa, wa * wa],
                den: vec![wa * wa],
                dt: None,
            },
            TransferFunction {
                num: vec![w2 * w2],
                den: vec![1.0, 2.0 * Z2 * w2, w2 * w2],
                dt: None,
            },
        ]
    }

    /// Discrete plant: series of the sections (anti-resonance merged with the
    /// second resonance to stay proper), ZOH at 4 kHz, 3 samples output delay.
    fn plant() -> StateSpace {
        c2d(&continuous_plant(), DT, C2dMethod::Zoh)
            .unwrap()
            .with_output_delay(3)
            .unwrap()
    }

    /// The continuous series of the sections, no delay.
    fn continuous_plant() -> StateSpace {
        let s = sections();
        let res2 = TransferFunction {
            num: s[2]
                .num
                .iter()
                .map(|c| c * s[3].num[0] / s[2].den[0])
                .collect(),
            den: s[3].den.clone(),
            dt: None,
        };
        series(
            &series(&s[0].to_ss().unwrap(), &s[1].to_ss().unwrap()).unwrap(),
            &res2.to_ss().unwrap(),
        )
        .unwrap()
    }

    /// Independent ZOH equivalent by partial fractions of P(s)/s:
    /// G(z) = (1 − z⁻¹)·Z{P(s)/s}, with the double pole at 0 handled in closed form.
    fn zoh_by_residues(zz: Complex<f64>) -> Complex<f64> {
        let (w1, wa, w2) = (w(F1), w(FA), w(F2));
        let kk = K * w1 * w1 * w2 * w2 / (wa * wa);
        let num = vec![1.0, 2.0 * ZA * wa, wa * wa];
        let d1 = vec![1.0, 2.0 * Z1 * w1, w1 * w1];
        let d2 = vec![1.0, 2.0 * Z2 * w2, w2 * w2];
        let dd = polymul(&d1, &d2);
        // F(s) = kk·num/(s²·dd); c2/s² + c1/s + Σ rᵢ/(s − pᵢ).
        let c = |x: f64| Complex::new(x, 0.0);
        let num0 = polyval(&num, c(0.0)).re;
        let dd0 = polyval(&dd, c(0.0)).re;
        let num_d0 = num[1];
        let dd_d0 = dd[dd.len() - 2];
        let c2 = kk * num0 / dd0;
        let c1 = kk * (num_d0 * dd0 - num0 * dd_d0) / (dd0 * dd0);
        let poles = linalg::roots(&dd);
        let mut g = c2 * DT / (zz - 1.0) + c1;
        for (i, &p) in poles.iter().enumerate() {
            let mut den = p * p;
            for (j, &q) in poles.iter().enumerate() {
                if j != i {
                    den *= p - q;
                }
            }
            let r = kk * polyval(&num, p) / den;
            g += r * (zz - 1.0) / (zz - (p * DT).exp());
        }
        g * zz.powi(-3)
    }

    #[test]
    fn cascade_matches_frequency_domain_model() {
        let p = plant();
        assert_eq!(p.nstates(), 5 + 3);
        assert!(!p.has_feedthrough());
        let s = sections();
        for f in [
            1.0, 10.0, 100.0, 300.0, 520.0, 527.0, 600.0, 624.0, 650.0, 1000.0, 1999.0,
        ] {
            let om = w(f);
            let zz = Complex::from_polar(1.0, om * DT);
            let got = p.freqresp_siso_at(om);
            let want = zoh_by_residues(zz);
            assert!(
                (got - want).norm() < 1e-6 * want.norm(),
                "f = {f}: {got} vs {want}"
            );
            // At low frequency ZOH ≈ the continuous model times the half-sample and
            // 3-sample delays.
            if f <= 10.0 {
                let cont: Complex<f64> = s.iter().map(|t| t.eval(Complex::new(0.0, om))).product();
                let approx = cont * Complex::from_polar(1.0, -3.5 * om * DT);
                assert!(
                    (got - approx).norm() < 1e-3 * approx.norm(),
                    "f = {f}: {got} vs {approx}"
                );
            }
        }
    }

    /// The Ch. 5 closed loop without the output delay, PI k(s + 2π·2)/s at a
    /// 20 Hz crossover (the structure of the Table 5.1 design on an identified,
    /// delay-free stage). Its realisation weighs B and C on different states (the PI's
    /// integrator against the stage's), which made the determinant-difference
    /// numerator cancel to noise: ZPETC of this T used to give |1 − T·L| ≈ 0.98
    /// at 1 Hz.
    #[test]
    fn zpetc_of_the_delay_free_pi_loop_is_exact_in_the_passband() {
        let p = plant();
        // The plant without its three samples of output delay.
        let g = c2d(&continuous_plant(), DT, C2dMethod::Zoh).unwrap();
        assert_eq!(g.nstates() + 3, p.nstates());
        // PI: u = kp (e + 2π·2 ∫e), discretised by ZOH of the integrator.
        let kp = w(20.0) / K;
        let wi = w(2.0);
        let pi = StateSpace::new(
            DMatrix::from_element(1, 1, 1.0),
            DMatrix::from_element(1, 1, DT),
            DMatrix::from_element(1, 1, kp * wi),
            DMatrix::from_element(1, 1, kp),
            Some(DT),
        )
        .unwrap();
        let one = StateSpace::gain(DMatrix::from_element(1, 1, 1.0), Some(DT));
        let t = feedback(&series(&pi, &g).unwrap(), &one, -1.0).unwrap();
        assert!(t.is_stable());
        // The same T in badly scaled coordinates x' = S x, S = diag(10^±6).
        let n = t.nstates();
        let sc: Vec<f64> = (0..n)
            .map(|i| 10f64.powi(if i % 2 == 0 { 6 } else { -6 }))
            .collect();
        let mut t_bad = t.clone();
        for i in 0..n {
            for j in 0..n {
                t_bad.a[(i, j)] = t.a[(i, j)] * sc[i] / sc[j];
            }
            t_bad.b[(i, 0)] = t.b[(i, 0)] * sc[i];
            t_bad.c[(0, i)] = t.c[(0, i)] / sc[i];
        }
        for sys in [&t, &t_bad] {
            let tf = sys.to_tf().unwrap();
            for f in [0.1, 1.0, 10.0, 50.0, 200.0, 527.0, 1000.0, 1999.0] {
                let om = w(f);
                let want = t.freqresp_siso_at(om);
                let got = tf.freqresp(&[om])[0];
                assert!(
                    (got - want).norm() < 1e-8 * want.norm(),
                    "f = {f}: tf {got} vs ss {want}"
                );
            }
            // ZPETC: T·L real and ≈ 1 where T has no unstable zeros' effect.
            let z = zpetc_ss(sys).unwrap();
            for f in [0.01, 1.0, 10.0] {
                let om = w(f);
                let tl = t.freqresp_siso_at(om) * z.freqresp(&[om])[0];
                assert!((tl - 1.0).norm() < 1e-4, "f = {f}: T·L = {tl}");
            }
            for f in [50.0, 500.0, 1500.0] {
                let om = w(f);
                let tl = t.freqresp_siso_at(om) * z.freqresp(&[om])[0];
                assert!(
                    tl.im.abs() < 1e-8 * tl.norm().max(1e-3) && tl.re > 0.0,
                    "f = {f}: {tl}"
                );
            }
        }
    }

    #[test]
    fn closed_loop_simulation_matches_frequency_domain_model() {
        let p = plant();
        // Proportional controller, crossover ≈ 15 Hz: K·kp/ω = 1.
        let kp = w(15.0) / K;
        let ctrl = StateSpace::gain(DMatrix::from_element(1, 1, kp), Some(DT));
        let open = series(&ctrl, &p).unwrap();
        let one = StateSpace::gain(DMatrix::from_element(1, 1, 1.0), Some(DT));
        let t_cl = feedback(&open, &one, -1.0).unwrap();
        assert!(t_cl.is_stable());
        // Sensitivity S = 1/(1 + PC) and its peak (H∞ norm) against a dense grid.
        let s_cl = feedback(&one, &open, -1.0).unwrap();
        let hs = hinfnorm(&s_cl).unwrap();
        let grid = (1..40000)
            .map(|i| s_cl.freqresp_siso_at(PI / DT * i as f64 / 40000.0).norm())
            .fold(0.0, f64::max);
        assert!(
            hs.norm >= grid * (1.0 - 1e-9) && hs.norm <= grid * (1.0 + 1e-3),
            "{} vs {grid}",
            hs.norm
        );
        // Simulate the loop sample by sample: y = P x, e = r − y, u = kp e.
        for f in [5.0, 40.0, 527.0] {
            let mut plant = SsStepper::new(&p).unwrap();
            let n = 16000;
            let om = w(f);
            let (mut sn, mut cs) = (0.0, 0.0);
            let mut y = [0.0];
            for k in 0..n {
                let ph = om * k as f64 * DT;
                plant.output(&[], &mut y);
                let e = ph.sin() - y[0];
                plant.update(&[kp * e]);
                if k >= n / 2 {
                    sn += y[0] * ph.sin();
                    cs += y[0] * ph.cos();
                }
            }
            let m = (n / 2) as f64 / 2.0;
            let sim = Complex::new(sn / m, cs / m);
            let model = t_cl.freqresp_siso_at(om);
            let l = open.freqresp_siso_at(om);
            assert!((model - l / (1.0 + l)).norm() < 1e-10 * model.norm().max(1e-6));
            assert!(
                (sim - model).norm() < 1e-3 * model.norm().max(1e-3),
                "f = {f}: sim {sim} model {model}"
            );
        }
        // ZPETC of the closed loop T (the learning filter of SPEC §3): T·L has
        // zero phase.
        let z = zpetc_ss(&t_cl).unwrap();
        let tf = t_cl.to_tf().unwrap();
        for f in [1.0, 50.0, 500.0, 1500.0] {
            let om = w(f);
            let tl = t_cl.freqresp_siso_at(om) * z.freqresp(&[om])[0];
            assert!(tl.im.abs() < 1e-6 * tl.norm().max(1e-3), "f = {f}: {tl}");
            assert!(
                (tf.freqresp(&[om])[0] - t_cl.freqresp_siso_at(om)).norm()
                    < 1e-6 * tl.norm().max(1.0)
            );
        }
        let tl0 = t_cl.freqresp_siso_at(w(0.01)) * z.freqresp(&[w(0.01)])[0];
        assert!((tl0 - 1.0).norm() < 1e-6, "{tl0}");
    }
}
