//! Data windows for spectral estimation.

use serde::{Deserialize, Serialize};
use std::f64::consts::TAU;

/// A data window. Spectral estimators use the **periodic** (DFT-even) form, as
/// `scipy.signal.get_window(..., fftbins=True)` and MATLAB's `hann(N, 'periodic')` do;
/// [`Window::symmetric`] gives the symmetric form used for filter design.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Window {
    /// Rectangular (boxcar): all ones.
    Rectangular,
    /// Hann: w = 0.5 − 0.5 cos(2πk/N).
    #[default]
    Hann,
    /// Hamming: w = 0.54 − 0.46 cos(2πk/N).
    Hamming,
}

impl Window {
    /// Periodic window of `n` samples, k = 0…n−1, with the cosine period N = n.
    ///
    /// ```
    /// use nanomotion_core::analysis::Window;
    /// let w = Window::Hann.periodic(4);
    /// assert!((w[0] - 0.0).abs() < 1e-15 && (w[2] - 1.0).abs() < 1e-15);
    /// ```
    pub fn periodic(self, n: usize) -> Vec<f64> {
        self.with_period(n, n as f64)
    }

    /// Symmetric window of `n` samples (cosine period N = n − 1; both ends equal).
    pub fn symmetric(self, n: usize) -> Vec<f64> {
        if n <= 1 {
            return vec![1.0; n];
        }
        self.with_period(n, (n - 1) as f64)
    }

    fn with_period(self, n: usize, period: f64) -> Vec<f64> {
        let (a0, a1) = match self {
            Window::Rectangular => return vec![1.0; n],
            Window::Hann => (0.5, 0.5),
            Window::Hamming => (0.54, 0.46),
        };
        (0..n)
            .map(|k| a0 - a1 * (TAU * k as f64 / period).cos())
            .collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn closed_form_sums() {
        // Periodic Hann: Σw = N/2, Σw² = 3N/8 (exact for N ≥ 3).
        let n = 64;
        let w = Window::Hann.periodic(n);
        let s1: f64 = w.iter().sum();
        let s2: f64 = w.iter().map(|v| v * v).sum();
        assert!((s1 - n as f64 / 2.0).abs() < 1e-12);
        assert!((s2 - 3.0 * n as f64 / 8.0).abs() < 1e-12);
        // Periodic Hamming: Σw = 0.54 N, Σw² = (0.54² + 0.46²/2) N.
        let w = Window::Hamming.periodic(n);
        let s1: f64 = w.iter().sum();
        let s2: f64 = w.iter().map(|v| v * v).sum();
        assert!((s1 - 0.54 * n as f64).abs() < 1e-12);
        assert!((s2 - (0.54f64.powi(2) + 0.46f64.powi(2) / 2.0) * n as f64).abs() < 1e-12);
        assert_eq!(Window::Rectangular.periodic(5), vec![1.0; 5]);
    }

    #[test]
    fn symmetric_is_symmetric() {
        for win in [Window::Hann, Window::Hamming] {
            let w = win.symmetric(9);
            for k in 0..9 {
                assert!((w[k] - w[8 - k]).abs() < 1e-15);
            }
            assert!((w[4] - 1.0).abs() < 1e-15);
        }
        assert_eq!(Window::Hann.symmetric(1), vec![1.0]);
    }
}
