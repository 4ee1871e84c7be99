//! Signal-analysis toolkit: the offline tools the thesis judges every experiment with.
//!
//! - [`window`]: Hann, Hamming and rectangular windows ([`Window`]);
//! - [`spectral`]: Welch power and cross spectral densities ([`psd_welch`],
//!   [`csd_welch`], [`SpectralMatrix`]) in scipy's one-sided `density` convention
//!   (unit²/Hz), and the **cumulative PSD** ([`cumulative_psd`]) whose end value is the
//!   squared RMS of the (detrended) signal;
//! - [`frf`]: non-parametric FRF identification, open loop ([`frf_h1`], H1 = S_yu/S_uu
//!   with coherence) and closed loop from noise injection at the plant input
//!   ([`frf_closed_loop`], P = S_P/S, thesis Fig. 2.8);
//! - [`filter`]: second-order-section filtering ([`lfilter_sos`]) and anti-causal
//!   zero-phase forward-backward filtering ([`filtfilt_sos`], scipy's `sosfiltfilt`
//!   semantics), used for the thesis's low-pass filtered reference signals;
//! - [`metrics`]: [`rms`], [`max_abs`], [`mean`], [`std()`], [`peak_to_peak`] and the
//!   serialisable [`Metrics`] summary;
//! - [`mimo`]: MIMO FRF estimation (open loop and closed loop P = S_P S⁻¹), the
//!   relative gain array [`rga`] (6.2) and [`characteristic_loci`].
//!
//! A note on names: MATLAB's `cpsd` is the *cross* power spectral density
//! ([`csd_welch`] here, scipy's `csd`), while the thesis's "CPSD" plots are
//! *cumulative* power spectral densities ([`cumulative_psd`]).
//!
//! These are offline tools: they allocate their results, but plan every FFT once per
//! call and run in O(N log L) for a signal of N samples analysed in segments of L, so
//! million-sample records are cheap.
//!
//! ```
//! use nanomotion_core::analysis::{psd_welch, WelchOptions};
//! use nanomotion_core::rng::Rng;
//!
//! let fs_hz = 1000.0;
//! let mut rng = Rng::new(1);
//! let x: Vec<f64> = (0..100_000).map(|_| 2.0 * rng.normal()).collect(); // σ = 2 units
//! let psd = psd_welch(&x, fs_hz, &WelchOptions::new(1024)).unwrap();
//! // The end value of the cumulative PSD is the mean square (here the variance, 4 unit²).
//! let ms = *psd.cumulative().last().unwrap();
//! assert!((ms - 4.0).abs() < 0.1);
//! ```

use thiserror::Error;

pub mod filter;
pub mod frf;
pub mod metrics;
pub mod mimo;
pub mod spectral;
pub mod window;

pub use filter::{
    default_padlen, filtfilt_sos, filtfilt_sos_padded, lfilter_sos, lfilter_sos_with_state,
    sosfilt_zi,
};
pub use frf::{ClosedLoopFrf, Frf, frf_closed_loop, frf_h1};
pub use metrics::{Metrics, max_abs, mean, peak_to_peak, rms, std};
pub use mimo::{CMatrix, characteristic_loci, frf_mimo_closed_loop, frf_mimo_h1, rga};
pub use spectral::{
    Csd, Detrend, Psd, SpectralMatrix, WelchOptions, csd_welch, cumulative_psd, psd_welch,
};
pub use window::Window;

/// Complex numbers (the same `num_complex::Complex` that nalgebra and rustfft use).
pub use nalgebra::Complex;

/// What can go wrong in an analysis call (bad arguments only: the algorithms
/// themselves cannot fail).
#[derive(Debug, Clone, PartialEq, Error)]
pub enum AnalysisError {
    /// A signal had no samples (or too few for the requested operation).
    #[error("signal too short: {0}")]
    TooShort(String),
    /// Signals that must be sampled together have different lengths.
    #[error("signal lengths differ: {0} vs {1} samples")]
    Length(usize, usize),
    /// A parameter is out of range (non-finite, non-positive, ...).
    #[error("invalid parameter `{name}`: {problem}")]
    Parameter {
        /// Parameter name.
        name: &'static str,
        /// What is wrong.
        problem: String,
    },
}

impl AnalysisError {
    pub(crate) fn param(name: &'static str, problem: impl Into<String>) -> Self {
        AnalysisError::Parameter {
            name,
            problem: problem.into(),
        }
    }
}
