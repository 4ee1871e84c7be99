//! Scalar performance metrics of a signal (typically a tracking error).
//!
//! All functions return values in the unit of the signal (nm in, nm out); an empty
//! slice gives 0 (and NaN-free results), so that a metric over an empty window is
//! harmless rather than a panic.

use serde::{Deserialize, Serialize};

/// Arithmetic mean (1/N) Σ x_k.
pub fn mean(x: &[f64]) -> f64 {
    if x.is_empty() {
        return 0.0;
    }
    x.iter().sum::<f64>() / x.len() as f64
}

/// Root mean square √((1/N) Σ x_k²) — **not** mean-removed (the thesis's rms error).
///
/// ```
/// use nanomotion_core::analysis::rms;
/// assert!((rms(&[3.0, -3.0, 3.0, -3.0]) - 3.0).abs() < 1e-15);
/// ```
pub fn rms(x: &[f64]) -> f64 {
    if x.is_empty() {
        return 0.0;
    }
    (x.iter().map(|v| v * v).sum::<f64>() / x.len() as f64).sqrt()
}

/// Population standard deviation √((1/N) Σ (x_k − x̄)²), so that rms² = mean² + std².
pub fn std(x: &[f64]) -> f64 {
    if x.is_empty() {
        return 0.0;
    }
    let m = mean(x);
    (x.iter().map(|v| (v - m) * (v - m)).sum::<f64>() / x.len() as f64).sqrt()
}

/// Largest absolute value max |x_k| (0 for an empty slice).
pub fn max_abs(x: &[f64]) -> f64 {
    x.iter().fold(0.0, |m, v| m.max(v.abs()))
}

/// Peak-to-peak value max x_k − min x_k (0 for an empty slice).
pub fn peak_to_peak(x: &[f64]) -> f64 {
    if x.is_empty() {
        return 0.0;
    }
    let (lo, hi) = min_max(x);
    hi - lo
}

fn min_max(x: &[f64]) -> (f64, f64) {
    x.iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), &v| {
            (lo.min(v), hi.max(v))
        })
}

/// Summary of a signal over a window, in the signal's unit. Serialisable so that
/// experiment reports can write it out as JSON/YAML.
///
/// ```
/// use nanomotion_core::analysis::Metrics;
/// // 1 kHz samples; skip the first 0.5 s (a transient) before computing the metrics.
/// let e: Vec<f64> = (0..2000).map(|k| if k < 500 { 100.0 } else { 1.0 }).collect();
/// let m = Metrics::after_settle(&e, 1000.0, 0.5);
/// assert_eq!(m.n_samples, 1500);
/// assert_eq!(m.max_abs, 1.0);
/// ```
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
pub struct Metrics {
    /// Number of samples the metrics were computed over.
    pub n_samples: usize,
    /// Mean.
    pub mean: f64,
    /// Population standard deviation (1/N).
    pub std: f64,
    /// Root mean square (not mean-removed).
    pub rms: f64,
    /// Largest absolute value.
    pub max_abs: f64,
    /// Smallest value (0 when empty).
    pub min: f64,
    /// Largest value (0 when empty).
    pub max: f64,
    /// max − min.
    pub peak_to_peak: f64,
}

impl Metrics {
    /// Metrics over the whole slice.
    pub fn of(x: &[f64]) -> Self {
        if x.is_empty() {
            return Self::default();
        }
        let (min, max) = min_max(x);
        Self {
            n_samples: x.len(),
            mean: mean(x),
            std: std(x),
            rms: rms(x),
            max_abs: max_abs(x),
            min,
            max,
            peak_to_peak: max - min,
        }
    }

    /// Metrics over the samples at t_k = k / fs_hz ≥ `settle_s` seconds (the first
    /// ⌈settle_s · fs_hz⌉ samples are skipped; all of them when the record is shorter).
    pub fn after_settle(x: &[f64], fs_hz: f64, settle_s: f64) -> Self {
        let skip = (settle_s * fs_hz).max(0.0);
        // Guard against 0.5 s · 1000 Hz = 500.0000000001 pushing one sample too far.
        let skip = (skip - 1e-9).ceil().max(0.0) as usize;
        Self::of(&x[skip.min(x.len())..])
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rng::Rng;

    #[test]
    fn closed_forms() {
        let x = [1.0, 2.0, 3.0, 4.0];
        assert_eq!(mean(&x), 2.5);
        assert!((rms(&x) - (30.0f64 / 4.0).sqrt()).abs() < 1e-15);
        assert!((std(&x) - 1.25f64.sqrt()).abs() < 1e-15);
        assert_eq!(max_abs(&[-5.0, 3.0]), 5.0);
        assert_eq!(peak_to_peak(&[-5.0, 3.0, 1.0]), 8.0);
        for f in [mean, rms, std, max_abs, peak_to_peak] {
            assert_eq!(f(&[]), 0.0);
        }
    }

    #[test]
    fn sinusoid_rms_and_pythagoras() {
        // A whole number of periods: rms = A/√2, peak-to-peak = 2A; rms² = mean² + std².
        let n = 1000;
        let a = 3.0;
        let x: Vec<f64> = (0..n)
            .map(|k| 0.5 + a * (std::f64::consts::TAU * 7.0 * k as f64 / n as f64).sin())
            .collect();
        assert!((std(&x) - a / 2f64.sqrt()).abs() < 1e-12);
        assert!((rms(&x).powi(2) - (0.25 + a * a / 2.0)).abs() < 1e-12);
        let m = Metrics::of(&x);
        assert!((m.peak_to_peak - 2.0 * a).abs() < 1e-3);
        assert!((m.rms.powi(2) - m.mean.powi(2) - m.std.powi(2)).abs() < 1e-12);

        let mut r = Rng::new(3);
        let y: Vec<f64> = (0..100).map(|_| r.normal()).collect();
        let m = Metrics::of(&y);
        assert!((m.rms.powi(2) - m.mean.powi(2) - m.std.powi(2)).abs() < 1e-12);
        assert_eq!(m.max_abs, m.max.max(-m.min));
    }

    #[test]
    fn settle_window_and_serde() {
        let x: Vec<f64> = (0..10).map(|k| k as f64).collect();
        let m = Metrics::after_settle(&x, 10.0, 0.3);
        assert_eq!(m.n_samples, 7);
        assert_eq!(m.min, 3.0);
        assert_eq!(Metrics::after_settle(&x, 10.0, 5.0), Metrics::default());
        assert_eq!(Metrics::after_settle(&x, 10.0, -1.0).n_samples, 10);
        let json = serde_json::to_string(&m).unwrap();
        assert!(json.contains("\"rms\""));
        let back: Metrics = serde_json::from_str(&json).unwrap();
        assert_eq!(back, m);
    }
}
