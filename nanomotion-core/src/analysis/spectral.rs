//! Welch power and cross spectral densities, and the cumulative PSD.
//!
//! Conventions (those of `scipy.signal.welch`/`csd` with `scaling='density'`,
//! `return_onesided=True`, `average='mean'`):
//! - the record is cut into segments of `segment_len` samples overlapping by
//!   `overlap · segment_len` samples (floor); trailing samples that do not fill a
//!   segment are ignored;
//! - each segment is detrended, multiplied by the periodic window w and transformed
//!   with an FFT of length L = `segment_len` (no zero padding);
//! - a segment's density is |X|² / (f_s Σw²), averaged over segments;
//! - the spectrum is one-sided: every bin except DC (and Nyquist for even L) is
//!   doubled, so that **∑ S(f_k) Δf equals the mean square of the detrended,
//!   windowed segments** — for a rectangular window, a single segment and mean
//!   removal this is exactly the variance (Parseval).
//!
//! Densities are in unit²/Hz when the signal is in `unit` and `fs_hz` in Hz;
//! frequencies are f_k = k f_s / L, k = 0…⌊L/2⌋.

use super::{AnalysisError, Complex, Window};
use realfft::RealFftPlanner;
use serde::{Deserialize, Serialize};

/// Per-segment trend removal before windowing (scipy's `detrend` argument).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Detrend {
    /// Keep the segment as it is.
    None,
    /// Subtract the segment mean (scipy's default, `'constant'`).
    #[default]
    Mean,
    /// Subtract the least-squares straight line through the segment.
    Linear,
}

/// Options of Welch's method.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct WelchOptions {
    /// Segment length L in samples (also the FFT length): the frequency resolution is
    /// f_s / L. Clamped to the record length when the record is shorter.
    pub segment_len: usize,
    /// Overlap between consecutive segments as a **fraction** of `segment_len`, in
    /// [0, 1); the overlap in samples is ⌊overlap · L⌋ (0.5 gives scipy's default).
    pub overlap: f64,
    /// Data window (periodic form).
    pub window: Window,
    /// Per-segment trend removal.
    pub detrend: Detrend,
}

impl Default for WelchOptions {
    /// 1024-sample Hann segments, 50 % overlap, mean removal.
    fn default() -> Self {
        Self::new(1024)
    }
}

impl WelchOptions {
    /// `segment_len`-sample Hann segments with 50 % overlap and mean removal
    /// (scipy's defaults apart from the segment length).
    pub fn new(segment_len: usize) -> Self {
        Self {
            segment_len,
            overlap: 0.5,
            window: Window::Hann,
            detrend: Detrend::Mean,
        }
    }

    /// The same options with another window.
    pub fn with_window(mut self, window: Window) -> Self {
        self.window = window;
        self
    }

    /// The same options with another overlap fraction.
    pub fn with_overlap(mut self, overlap: f64) -> Self {
        self.overlap = overlap;
        self
    }

    /// The same options with another detrending.
    pub fn with_detrend(mut self, detrend: Detrend) -> Self {
        self.detrend = detrend;
        self
    }
}

/// One-sided power spectral density estimate.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Psd {
    /// Bin frequencies f_k = k f_s / L in Hz.
    pub freq_hz: Vec<f64>,
    /// One-sided density S(f_k) in unit²/Hz.
    pub density: Vec<f64>,
    /// Bin spacing Δf = f_s / L in Hz.
    pub df_hz: f64,
    /// Number of averaged segments.
    pub n_segments: usize,
}

impl Psd {
    /// Cumulative PSD C(f_k) = Σ_{i ≤ k} S(f_i) Δf in unit² (see [`cumulative_psd`]);
    /// its end value is the mean square of the detrended signal.
    pub fn cumulative(&self) -> Vec<f64> {
        cumulative_psd(&self.density, self.df_hz)
    }

    /// Mean square ∫S df = Σ S(f_k) Δf in unit² (the end value of the cumulative PSD).
    pub fn mean_square(&self) -> f64 {
        self.density.iter().sum::<f64>() * self.df_hz
    }

    /// Root mean square √(∫S df) in unit.
    pub fn rms(&self) -> f64 {
        self.mean_square().sqrt()
    }

    /// Mean square contributed by the bins with f_lo_hz ≤ f_k ≤ f_hi_hz, in unit².
    pub fn band_mean_square(&self, f_lo_hz: f64, f_hi_hz: f64) -> f64 {
        self.freq_hz
            .iter()
            .zip(&self.density)
            .filter(|(f, _)| **f >= f_lo_hz && **f <= f_hi_hz)
            .map(|(_, s)| s)
            .sum::<f64>()
            * self.df_hz
    }
}

/// One-sided cross spectral density estimate S_xy(f) = E[conj(X) Y] (scipy's
/// `csd(x, y)`, MATLAB's `cpsd(x, y)`); in the control notation of the thesis this
/// is S_yx, the cross spectrum of output y with input x.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Csd {
    /// Bin frequencies in Hz.
    pub freq_hz: Vec<f64>,
    /// One-sided complex density in unit_x·unit_y/Hz.
    pub density: Vec<Complex<f64>>,
    /// Bin spacing in Hz.
    pub df_hz: f64,
    /// Number of averaged segments.
    pub n_segments: usize,
}

/// Cumulative PSD: C_k = Σ_{i ≤ k} S_i Δf (unit² from unit²/Hz and Hz).
///
/// The rectangle rule on the one-sided bin grid is exact for Welch spectra: the DC and
/// Nyquist bins are not doubled, so each bin's share of the mean square is S_i Δf and
/// the end value equals the mean square of the (detrended, windowed) signal —
/// the thesis's squared RMS. A trapezoidal rule would halve DC and Nyquist twice.
///
/// ```
/// use nanomotion_core::analysis::cumulative_psd;
/// assert_eq!(cumulative_psd(&[1.0, 2.0, 3.0], 0.5), vec![0.5, 1.5, 3.0]);
/// ```
pub fn cumulative_psd(density: &[f64], df_hz: f64) -> Vec<f64> {
    let mut acc = 0.0;
    density
        .iter()
        .map(|s| {
            acc += s * df_hz;
            acc
        })
        .collect()
}

/// Welch PSD of `x` sampled at `fs_hz` (one-sided, unit²/Hz; see the module doc).
///
/// ```
/// use nanomotion_core::analysis::{psd_welch, WelchOptions};
/// let fs = 100.0;
/// let x: Vec<f64> = (0..10_000)
///     .map(|k| 3.0 * (std::f64::consts::TAU * 12.5 * k as f64 / fs).sin())
///     .collect();
/// let psd = psd_welch(&x, fs, &WelchOptions::new(256)).unwrap();
/// // Mean square of a sinusoid with amplitude 3: (3/√2)² = 4.5.
/// assert!((psd.mean_square() - 4.5).abs() < 1e-2);
/// ```
pub fn psd_welch(x: &[f64], fs_hz: f64, opts: &WelchOptions) -> Result<Psd, AnalysisError> {
    let m = SpectralMatrix::compute(&[x], fs_hz, opts)?;
    Ok(Psd {
        density: m.auto(0),
        freq_hz: m.freq_hz,
        df_hz: m.df_hz,
        n_segments: m.n_segments,
    })
}

/// Welch cross spectral density S_xy = E[conj(X) Y] of `x` and `y` (same length,
/// sampled together at `fs_hz`); same conventions as [`psd_welch`], so
/// `csd_welch(x, x)` equals `psd_welch(x)`.
#[doc(alias = "cpsd")]
#[doc(alias = "csd")]
pub fn csd_welch(
    x: &[f64],
    y: &[f64],
    fs_hz: f64,
    opts: &WelchOptions,
) -> Result<Csd, AnalysisError> {
    let m = SpectralMatrix::compute(&[x, y], fs_hz, opts)?;
    Ok(Csd {
        density: m.cross(0, 1),
        freq_hz: m.freq_hz,
        df_hz: m.df_hz,
        n_segments: m.n_segments,
    })
}

/// All auto and cross spectral densities of a few signals sampled together,
/// computed in one pass (one FFT per signal and segment): entry (i, j) is
/// S_ij = E[conj(X_i) X_j] in Welch's one-sided density convention. This is what
/// FRF estimation needs (S_uu, S_yy, S_uy at once) and the building block for MIMO
/// identification.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SpectralMatrix {
    /// Bin frequencies in Hz.
    pub freq_hz: Vec<f64>,
    /// Bin spacing in Hz.
    pub df_hz: f64,
    /// Number of averaged segments.
    pub n_segments: usize,
    n_signals: usize,
    /// Upper triangle (i ≤ j), row-major: index of (i, j) is given by `tri_index`.
    data: Vec<Vec<Complex<f64>>>,
}

fn tri_index(n: usize, i: usize, j: usize) -> usize {
    debug_assert!(i <= j && j < n);
    // Rows 0..i hold n, n−1, …, n−i+1 entries: i(2n − i + 1)/2 in all.
    i * (2 * n - i + 1) / 2 + (j - i)
}

impl SpectralMatrix {
    /// Welch spectra of `signals` (all the same length, sampled at `fs_hz`).
    pub fn compute(
        signals: &[&[f64]],
        fs_hz: f64,
        opts: &WelchOptions,
    ) -> Result<Self, AnalysisError> {
        if !(fs_hz.is_finite() && fs_hz > 0.0) {
            return Err(AnalysisError::param(
                "fs_hz",
                format!("must be finite and > 0, got {fs_hz}"),
            ));
        }
        if !(opts.overlap.is_finite() && (0.0..1.0).contains(&opts.overlap)) {
            return Err(AnalysisError::param(
                "overlap",
                format!("must be a fraction in [0, 1), got {}", opts.overlap),
            ));
        }
        if opts.segment_len == 0 {
            return Err(AnalysisError::param("segment_len", "must be ≥ 1"));
        }
        let k = signals.len();
        if k == 0 {
            return Err(AnalysisError::TooShort("no signals given".into()));
        }
        let n = signals[0].len();
        for s in signals {
            if s.len() != n {
                return Err(AnalysisError::Length(n, s.len()));
            }
        }
        if n == 0 {
            return Err(AnalysisError::TooShort("signal has no samples".into()));
        }

        let nper = opts.segment_len.min(n);
        let noverlap = ((opts.overlap * nper as f64).floor() as usize).min(nper - 1);
        let step = nper - noverlap;
        let n_segments = (n - nper) / step + 1;
        let win = opts.window.periodic(nper);
        let win_pow: f64 = win.iter().map(|w| w * w).sum();
        let n_bins = nper / 2 + 1;

        let mut planner = RealFftPlanner::<f64>::new();
        let fft = planner.plan_fft_forward(nper);
        let mut buf = fft.make_input_vec();
        let mut scratch = fft.make_scratch_vec();
        let mut spectra: Vec<Vec<Complex<f64>>> = (0..k).map(|_| fft.make_output_vec()).collect();
        let n_pairs = k * (k + 1) / 2;
        let mut data = vec![vec![Complex::new(0.0, 0.0); n_bins]; n_pairs];
        let detrender = Detrender::new(opts.detrend, nper);

        for seg in 0..n_segments {
            let start = seg * step;
            for (s, spec) in signals.iter().zip(spectra.iter_mut()) {
                buf.copy_from_slice(&s[start..start + nper]);
                detrender.apply(&mut buf);
                for (b, w) in buf.iter_mut().zip(&win) {
                    *b *= w;
                }
                fft.process_with_scratch(&mut buf, spec, &mut scratch)
                    .expect("buffer sizes come from the plan");
            }
            let mut p = 0;
            for i in 0..k {
                for j in i..k {
                    let acc = &mut data[p];
                    if i == j {
                        for (a, x) in acc.iter_mut().zip(&spectra[i]) {
                            a.re += x.norm_sqr();
                        }
                    } else {
                        for ((a, x), y) in acc.iter_mut().zip(&spectra[i]).zip(&spectra[j]) {
                            *a += x.conj() * y;
                        }
                    }
                    p += 1;
                }
            }
        }

        let scale = 1.0 / (fs_hz * win_pow * n_segments as f64);
        // Bins doubled for the one-sided spectrum: all but DC and (even L) Nyquist.
        let last_doubled = if nper.is_multiple_of(2) {
            n_bins - 1
        } else {
            n_bins
        };
        for acc in &mut data {
            for (b, a) in acc.iter_mut().enumerate() {
                let two = if b >= 1 && b < last_doubled { 2.0 } else { 1.0 };
                *a *= scale * two;
            }
        }
        let df_hz = fs_hz / nper as f64;
        Ok(Self {
            freq_hz: (0..n_bins).map(|b| b as f64 * df_hz).collect(),
            df_hz,
            n_segments,
            n_signals: k,
            data,
        })
    }

    /// Number of signals.
    pub fn n_signals(&self) -> usize {
        self.n_signals
    }

    /// Cross density S_ij(f_k) = E[conj(X_i) X_j] (S_ji = conj(S_ij)).
    ///
    /// # Panics
    /// If `i` or `j` is not below [`n_signals`](Self::n_signals).
    pub fn cross(&self, i: usize, j: usize) -> Vec<Complex<f64>> {
        assert!(
            i < self.n_signals && j < self.n_signals,
            "signal index out of range"
        );
        if i <= j {
            self.data[tri_index(self.n_signals, i, j)].clone()
        } else {
            self.data[tri_index(self.n_signals, j, i)]
                .iter()
                .map(|c| c.conj())
                .collect()
        }
    }

    /// Auto density S_ii(f_k) (real, ≥ 0) in unit²/Hz.
    ///
    /// # Panics
    /// If `i` is not below [`n_signals`](Self::n_signals).
    pub fn auto(&self, i: usize) -> Vec<f64> {
        assert!(i < self.n_signals, "signal index out of range");
        self.data[tri_index(self.n_signals, i, i)]
            .iter()
            .map(|c| c.re)
            .collect()
    }

    /// Magnitude-squared coherence γ²_ij = |S_ij|² / (S_ii S_jj) in [0, 1]
    /// (0 where either auto spectrum vanishes).
    pub fn coherence(&self, i: usize, j: usize) -> Vec<f64> {
        let sij = self.cross(i, j);
        let sii = self.auto(i);
        let sjj = self.auto(j);
        sij.iter()
            .zip(sii.iter().zip(&sjj))
            .map(|(c, (a, b))| {
                let d = a * b;
                if d > 0.0 {
                    (c.norm_sqr() / d).min(1.0)
                } else {
                    0.0
                }
            })
            .collect()
    }
}

/// Precomputed per-segment detrending.
struct Detrender {
    kind: Detrend,
    /// Centred time t_k = k − (L−1)/2 and 1/Σt² for the linear fit.
    t: Vec<f64>,
    inv_tt: f64,
}

impl Detrender {
    fn new(kind: Detrend, len: usize) -> Self {
        let (t, inv_tt) = if kind == Detrend::Linear {
            let c = (len as f64 - 1.0) / 2.0;
            let t: Vec<f64> = (0..len).map(|k| k as f64 - c).collect();
            let tt: f64 = t.iter().map(|v| v * v).sum();
            (t, if tt > 0.0 { 1.0 / tt } else { 0.0 })
        } else {
            (Vec::new(), 0.0)
        };
        Self { kind, t, inv_tt }
    }

    fn apply(&self, x: &mut [f64]) {
        match self.kind {
            Detrend::None => {}
            Detrend::Mean => {
                let m = x.iter().sum::<f64>() / x.len() as f64;
                x.iter_mut().for_each(|v| *v -= m);
            }
            Detrend::Linear => {
                // Least squares a + b t with centred t: a = mean, b = Σ t x / Σ t².
                let m = x.iter().sum::<f64>() / x.len() as f64;
                let slope = x.iter().zip(&self.t).map(|(v, t)| v * t).sum::<f64>() * self.inv_tt;
                for (v, t) in x.iter_mut().zip(&self.t) {
                    *v -= m + slope * t;
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rng::Rng;
    use std::f64::consts::{PI, TAU};

    fn white(seed: u64, n: usize, sigma: f64) -> Vec<f64> {
        let mut r = Rng::new(seed);
        (0..n).map(|_| sigma * r.normal()).collect()
    }

    fn variance(x: &[f64]) -> f64 {
        let m = x.iter().sum::<f64>() / x.len() as f64;
        x.iter().map(|v| (v - m) * (v - m)).sum::<f64>() / x.len() as f64
    }

    #[test]
    fn tri_index_is_row_major_upper_triangle() {
        let n = 4;
        let mut p = 0;
        for i in 0..n {
            for j in i..n {
                assert_eq!(tri_index(n, i, j), p);
                p += 1;
            }
        }
    }

    #[test]
    fn parseval_is_exact_for_one_rectangular_segment() {
        // Rectangular window, one segment, mean removed: Σ S Δf is the population
        // variance to rounding, for even (Nyquist bin) and odd lengths.
        for n in [256, 255] {
            let x: Vec<f64> = white(1, n, 1.3).iter().map(|v| v + 4.0).collect();
            let opts = WelchOptions::new(n).with_window(Window::Rectangular);
            let psd = psd_welch(&x, 50.0, &opts).unwrap();
            assert_eq!(psd.n_segments, 1);
            assert_eq!(psd.freq_hz.len(), n / 2 + 1);
            let v = variance(&x);
            assert!((psd.mean_square() - v).abs() < 1e-12 * v, "n = {n}");
            assert!((psd.cumulative().last().unwrap() - v).abs() < 1e-12 * v);
        }
    }

    /// Independent Welch: explicit segments, 2×2 normal equations for the linear
    /// trend, textbook window formula and an O(L²) DFT.
    fn direct_welch(x: &[f64], y: &[f64], fs: f64, l: usize, step: usize) -> Vec<Complex<f64>> {
        let nseg = (x.len() - l) / step + 1;
        let w: Vec<f64> = (0..l)
            .map(|k| 0.5 * (1.0 - (2.0 * PI * k as f64 / l as f64).cos()))
            .collect();
        let detrend = |s: &[f64]| -> Vec<f64> {
            // Minimise Σ (s_k − a − b k)².
            let n = s.len() as f64;
            let (st, stt) =
                (0..s.len()).fold((0.0, 0.0), |(a, b), k| (a + k as f64, b + (k * k) as f64));
            let sy: f64 = s.iter().sum();
            let sty: f64 = s.iter().enumerate().map(|(k, v)| k as f64 * v).sum();
            let det = n * stt - st * st;
            let a = (stt * sy - st * sty) / det;
            let b = (n * sty - st * sy) / det;
            s.iter()
                .enumerate()
                .map(|(k, v)| v - a - b * k as f64)
                .collect()
        };
        let dft = |s: &[f64], f: usize| -> Complex<f64> {
            s.iter()
                .enumerate()
                .map(|(k, v)| {
                    let ph = -2.0 * PI * (f * k) as f64 / l as f64;
                    Complex::new(v * ph.cos(), v * ph.sin())
                })
                .sum()
        };
        let s2: f64 = w.iter().map(|v| v * v).sum();
        let nb = l / 2 + 1;
        let mut out = vec![Complex::new(0.0, 0.0); nb];
        for seg in 0..nseg {
            let xs: Vec<f64> = detrend(&x[seg * step..seg * step + l])
                .iter()
                .zip(&w)
                .map(|(a, b)| a * b)
                .collect();
            let ys: Vec<f64> = detrend(&y[seg * step..seg * step + l])
                .iter()
                .zip(&w)
                .map(|(a, b)| a * b)
                .collect();
            for (f, o) in out.iter_mut().enumerate() {
                let one_sided = if f == 0 || (l.is_multiple_of(2) && f == l / 2) {
                    1.0
                } else {
                    2.0
                };
                *o += dft(&xs, f).conj() * dft(&ys, f) * one_sided / (fs * s2 * nseg as f64);
            }
        }
        out
    }

    #[test]
    fn psd_and_csd_match_a_direct_dft() {
        let x: Vec<f64> = white(2, 61, 1.0)
            .iter()
            .enumerate()
            .map(|(k, v)| v + 0.1 * k as f64)
            .collect();
        let y: Vec<f64> = white(3, 61, 2.0);
        let fs = 8.0;
        for l in [16, 15] {
            let opts = WelchOptions::new(l).with_detrend(Detrend::Linear);
            let step = l - l / 2;
            let reference = direct_welch(&x, &y, fs, l, step);
            let csd = csd_welch(&x, &y, fs, &opts).unwrap();
            assert_eq!(csd.n_segments, (61 - l) / step + 1);
            for (a, b) in csd.density.iter().zip(&reference) {
                assert!((a - b).norm() < 1e-12, "l = {l}: {a} vs {b}");
            }
            let reference = direct_welch(&x, &x, fs, l, step);
            let psd = psd_welch(&x, fs, &opts).unwrap();
            for (a, b) in psd.density.iter().zip(&reference) {
                assert!((a - b.re).abs() < 1e-12 && b.im.abs() < 1e-12);
            }
            for (k, f) in psd.freq_hz.iter().enumerate() {
                assert!((f - k as f64 * fs / l as f64).abs() < 1e-15);
            }
        }
    }

    #[test]
    fn white_noise_is_flat_and_integrates_to_the_variance() {
        let sigma = 2.0;
        let fs = 1000.0;
        let x = white(4, 1 << 18, sigma);
        for window in [Window::Hann, Window::Hamming, Window::Rectangular] {
            let psd = psd_welch(&x, fs, &WelchOptions::new(1024).with_window(window)).unwrap();
            // Cumulative end value = mean square ≈ sample variance (Welch averages the
            // windowed power of overlapping segments: agreement to well under 1 %).
            let end = *psd.cumulative().last().unwrap();
            let v = variance(&x);
            assert!((end / v - 1.0).abs() < 0.01, "{window:?}: {end} vs {v}");
            // Flat at σ² / (f_s/2): averages over 64-bin bands within 4 %
            // (each band averages ≈ 64 · 511 nearly independent χ² values).
            let level = sigma * sigma / (fs / 2.0);
            for band in psd.density[1..513].chunks(64) {
                let m = band.iter().sum::<f64>() / band.len() as f64;
                assert!((m / level - 1.0).abs() < 0.04, "{window:?}: {m} vs {level}");
            }
        }
    }

    #[test]
    fn sinusoids_cumulative_psd_steps_by_half_the_squared_amplitude() {
        // Off-bin frequencies, a phase and an offset (removed by the detrend).
        let fs = 2000.0;
        let (a1, f1, a2, f2) = (3.0, 47.3, 0.5, 313.7);
        let x: Vec<f64> = (0..200_000)
            .map(|k| {
                let t = k as f64 / fs;
                1.0 + a1 * (TAU * f1 * t + 0.4).sin() + a2 * (TAU * f2 * t).cos()
            })
            .collect();
        let psd = psd_welch(&x, fs, &WelchOptions::new(2048)).unwrap();
        let c = psd.cumulative();
        let at = |f: f64| c[(f / psd.df_hz).round() as usize];
        let ms = (a1 * a1 + a2 * a2) / 2.0;
        assert!(
            (c.last().unwrap() / ms - 1.0).abs() < 2e-3,
            "{}",
            c.last().unwrap()
        );
        // The steps sit at the sinusoids' frequencies (Hann leakage: a few bins).
        assert!(at(f1 - 10.0) < 1e-4 * ms);
        assert!((at(f1 + 10.0) / (a1 * a1 / 2.0) - 1.0).abs() < 2e-3);
        assert!((at(f2 - 10.0) / (a1 * a1 / 2.0) - 1.0).abs() < 2e-3);
        assert!((psd.band_mean_square(f2 - 10.0, f2 + 10.0) / (a2 * a2 / 2.0) - 1.0).abs() < 2e-3);
        assert!((psd.rms() - ms.sqrt()).abs() < 2e-3 * ms.sqrt());
        // The peak bin is the one nearest f1.
        let peak = (0..psd.density.len())
            .max_by(|&i, &j| psd.density[i].total_cmp(&psd.density[j]))
            .unwrap();
        assert!((psd.freq_hz[peak] - f1).abs() <= psd.df_hz);
    }

    #[test]
    #[allow(clippy::needless_range_loop)] // bins of several spectra
    fn csd_symmetries_and_delay_phase() {
        let fs = 1000.0;
        let x = white(5, 1 << 16, 1.0);
        let d = 3;
        let y: Vec<f64> = (0..x.len())
            .map(|k| if k >= d { 2.0 * x[k - d] } else { 0.0 })
            .collect();
        let opts = WelchOptions::new(512);
        let sxx = csd_welch(&x, &x, fs, &opts).unwrap();
        let pxx = psd_welch(&x, fs, &opts).unwrap();
        for (c, p) in sxx.density.iter().zip(&pxx.density) {
            assert_eq!(c.re, *p);
            assert_eq!(c.im, 0.0);
        }
        let sxy = csd_welch(&x, &y, fs, &opts).unwrap();
        let syx = csd_welch(&y, &x, fs, &opts).unwrap();
        for (a, b) in sxy.density.iter().zip(&syx.density) {
            assert!((a - b.conj()).norm() < 1e-15 * (1.0 + a.norm()));
        }
        // y = 2 x delayed by d samples: S_xy = 2 e^{−jωd} S_xx up to the (1 − d/L)
        // segment-overlap loss; the phase is exact in expectation.
        let m = SpectralMatrix::compute(&[&x, &y], fs, &opts).unwrap();
        let coh = m.coherence(0, 1);
        for k in 1..200 {
            let f = sxy.freq_hz[k];
            let expected = -TAU * f * d as f64 / fs;
            let err = (sxy.density[k] * Complex::from_polar(1.0, -expected)).arg();
            assert!(err.abs() < 0.05, "bin {k}: phase error {err}");
            let ratio = sxy.density[k].norm() / pxx.density[k];
            assert!((ratio - 2.0).abs() < 0.1, "bin {k}: {ratio}");
            assert!(coh[k] > 0.95);
        }
    }

    #[test]
    fn short_records_and_bad_arguments() {
        let x = white(6, 100, 1.0);
        // A record shorter than the segment is analysed as one segment.
        let psd = psd_welch(&x, 10.0, &WelchOptions::new(1024)).unwrap();
        assert_eq!(psd.n_segments, 1);
        assert_eq!(psd.density.len(), 51);
        let o = WelchOptions::new(16);
        assert!(matches!(
            psd_welch(&x, 0.0, &o),
            Err(AnalysisError::Parameter { .. })
        ));
        assert!(matches!(
            psd_welch(&x, f64::NAN, &o),
            Err(AnalysisError::Parameter { .. })
        ));
        assert!(psd_welch(&x, 1.0, &o.with_overlap(1.0)).is_err());
        assert!(psd_welch(&x, 1.0, &WelchOptions::new(0)).is_err());
        assert!(matches!(
            psd_welch(&[], 1.0, &o),
            Err(AnalysisError::TooShort(_))
        ));
        assert!(matches!(
            csd_welch(&x, &x[1..], 1.0, &o),
            Err(AnalysisError::Length(100, 99))
        ));
        // Zero overlap: floor((100 − 16)/16) + 1 = 6 segments.
        assert_eq!(
            psd_welch(&x, 1.0, &o.with_overlap(0.0)).unwrap().n_segments,
            6
        );
    }

    #[test]
    fn options_round_trip_through_serde() {
        let o = WelchOptions::new(256)
            .with_window(Window::Hamming)
            .with_detrend(Detrend::Linear);
        let json = serde_json::to_string(&o).unwrap();
        assert!(json.contains("\"hamming\"") && json.contains("\"linear\""));
        assert_eq!(serde_json::from_str::<WelchOptions>(&json).unwrap(), o);
    }
}
