//! # nanomotion-dvrc
//!
//! Repetitive control (RC) after R.J.E. Merry, *Performance-driven control of
//! nano-motion systems*, PhD thesis, TU Eindhoven, 2009, **Chapter 5**
//! ("Delay-varying repetitive control"), SPEC §3.
//!
//! | what | thesis | Rust | block `type:` |
//! |---|---|---|---|
//! | learning filter L = ZPETC of T, robustness Q = linear-phase FIR, any FIR/IIR | Sec. 5.2.2, 5.5.3 | [`filters::FilterSpec`], [`filters::Filter`] (implements [`LearningFilter`](nanomotion_core::LearningFilter)) | (fields `learning`, `robustness`) |
//! | standard RC, constant N | (5.1)–(5.5) | [`rc::RepetitiveControl`] | `repetitive_control` |
//! | high-order RC, W(z) = 2 − z^-N | Sec. 5.5.4 | [`rc::HighOrderRc`] | `high_order_rc` |
//! | delay-varying RC, N_k = k − k*(α_k) | (5.6)–(5.8) | [`rc::Dvrc`], [`delay::AlphaDelay`] | `dvrc` |
//! | the memory loop of Fig. 5.1/5.2 | (5.10)–(5.11) | [`rc::MemoryLoop`], [`delay::VaryingDelay`] | — |
//! | criteria (5.5), (5.9), margin, tightest frequency | Sec. 5.2.1, 5.3.2, Cor. 7 | [`stability::rc_criterion`] | — |
//! | Q cut-off design for a delay spread M − m | Sec. 5.5.3 | [`stability::design_q_cutoff`] | — |
//! | lifted switched system | (5.13)–(5.16) | [`stability::lifted_check`] | — |
//! | l2 gain √(M − m + 1) of the varying delay | Theorem 8 | [`stability::worst_case_gain_input`], tests | — |
//! | check a graph before running it | — | [`check::rc_check_graph`] | `nanomotion rc-check` |
//! | N from a measured error | Sec. 5.2.2 | [`estimate_period_samples`] | — |
//!
//! Every RC block adds to a feedback loop as in Fig. 5.1: its output `w` is added to
//! the tracking error before the feedback controller, u = K(e + w). The blocks have
//! no allocation per tick; DVRC's ring buffer is sized for the worst-case delay
//! `n_max` when it is built.
//!
//! ```
//! use dvrc::filters::FilterSpec;
//! use dvrc::rc::{Dvrc, RepetitiveControl};
//! let dt = 1.0 / 4000.0;
//! let n = 200;
//! // Standard RC and DVRC with α = t: identical, bit for bit (Sec. 5.3.1).
//! let mut rc = RepetitiveControl::built(n, FilterSpec::Identity, FilterSpec::q_fir(11, 500.0), dt).unwrap();
//! let mut dv = Dvrc::new(n as f64 * dt, 150, 250, FilterSpec::Identity, FilterSpec::q_fir(11, 500.0))
//!     .with_n_init(n);
//! dv.build_dt(dt).unwrap();
//! for k in 0..2000 {
//!     let e = (k as f64 * 0.05).sin();
//!     let (w, nk) = dv.step(e, k as f64 * dt);
//!     assert_eq!(nk, n);
//!     assert_eq!(rc.step(e).to_bits(), w.to_bits());
//! }
//! ```
//!
//! Stability, (5.9) with the foundation's H∞ norm:
//!
//! ```
//! use dvrc::filters::FilterSpec;
//! use dvrc::stability::{design_q_cutoff, rc_criterion};
//! use nanomotion_core::lti::TransferFunction;
//! let dt = 1.0 / 4000.0;
//! // T(z) = 0.3 z^-1 / (1 − 0.7 z^-1) (a first-order closed loop).
//! let t_spec = FilterSpec::Zpetc { num: vec![0.3], den: vec![1.0, -0.7] };
//! let t = TransferFunction::new(vec![0.3], vec![1.0, -0.7], Some(dt)).unwrap().to_ss().unwrap();
//! // A deliberately imperfect L (97 % of the inverse, one sample preview).
//! let l = FilterSpec::Iir { num: vec![0.97, -0.679], den: vec![0.3, 0.0], delay: 1 }.build(dt).unwrap();
//! let design = design_q_cutoff(&t, &l, 31, 180, 0.05).unwrap();
//! let q = dvrc::filters::Filter::fir(design.taps.clone(), 15, dt);
//! let c = rc_criterion(&t, &l, &q, 100, 280).unwrap();
//! assert!(c.holds(), "{c}");
//! assert!((c.bound - 1.0 / 181f64.sqrt()).abs() < 1e-15);
//! # let _ = t_spec;
//! ```

pub mod check;
pub mod delay;
pub mod filters;
pub mod rc;
pub mod stability;

pub use delay::{AlphaDelay, VaryingDelay};
pub use filters::{Filter, FilterSpec};
pub use rc::{Dvrc, HighOrderRc, MemoryLoop, RepetitiveControl};
pub use stability::{RcCriterion, design_q_cutoff, lifted_check, loop_h, rc_criterion};

/// Estimate the repetitive delay N (samples) of a tracking error `e` measured
/// without RC (Sec. 5.2.2: "from the spectrum of e, the repetitive period is the
/// lowest harmonic"). Uses the autocorrelation (the inverse transform of the power
/// spectrum): the smallest lag in \[`n_min`, `n_max`\] whose normalised
/// autocorrelation is within 10 % of the best one there (so the fundamental wins
/// over its multiples). `None` if `e` is too short or has no energy.
///
/// ```
/// let e: Vec<f64> = (0..4000).map(|k| (2.0 * std::f64::consts::PI * k as f64 / 137.0).sin()
///     + 0.3 * (6.0 * std::f64::consts::PI * k as f64 / 137.0).cos()).collect();
/// assert_eq!(dvrc::estimate_period_samples(&e, 20, 600), Some(137));
/// ```
pub fn estimate_period_samples(e: &[f64], n_min: usize, n_max: usize) -> Option<usize> {
    let n_min = n_min.max(1);
    if e.len() < 2 * n_max.max(n_min) || n_max < n_min {
        return None;
    }
    let mean = e.iter().sum::<f64>() / e.len() as f64;
    let x: Vec<f64> = e.iter().map(|v| v - mean).collect();
    let r0: f64 = x.iter().map(|v| v * v).sum::<f64>();
    if r0 <= 0.0 {
        return None;
    }
    let r: Vec<f64> = (n_min..=n_max)
        .map(|tau| {
            let m = x.len() - tau;
            let s: f64 = (0..m).map(|k| x[k] * x[k + tau]).sum();
            s / m as f64 * x.len() as f64 / r0
        })
        .collect();
    let best = r.iter().copied().fold(f64::MIN, f64::max);
    if best <= 0.0 {
        return None;
    }
    // Smallest lag that is a local maximum within 10 % of the best.
    for i in 0..r.len() {
        let left = if i == 0 { f64::MIN } else { r[i - 1] };
        let right = if i + 1 == r.len() { f64::MIN } else { r[i + 1] };
        if r[i] >= 0.9 * best && r[i] >= left && r[i] >= right {
            return Some(n_min + i);
        }
    }
    None
}
