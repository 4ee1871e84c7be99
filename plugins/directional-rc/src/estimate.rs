//! Sample-rotation estimation from line scans, Sec. 7.4.3, (7.18)–(7.21).
//!
//! Two or more lines are scanned along the fast axis y at constant slow-axis
//! positions x_1, x_2, …; the measured heights z_i(y) show the same features shifted
//! by δ_y = (x_2 − x_1) tan α when the sample is rotated by α about z. Per pair of
//! consecutive lines:
//!
//! 1. the mean-removed cross-correlation (7.18), normalised per lag,
//!    ρ(τ) = Σ_k (z_1\[k\] − µ_1)(z_2\[k + τ\] − µ_2) / (M_τ σ_1 σ_2), over the M_τ
//!    overlapping samples. ρ peaks where z_2\[k + τ\] ≈ z_1\[k\], i.e. where the
//!    features of line 2 lie τ samples further along y. The thesis writes (7.18) as
//!    E{z_1(t) z_2(t − τ')}, so its δ_s of (7.19) is −τ here;
//! 2. the integer peak τ* (7.19) refined to a sub-sample peak by a parabola through
//!    ρ(τ* − 1), ρ(τ*), ρ(τ* + 1);
//! 3. the shift in position δ_y = (y0_2 − y0_1) + τ·Δy (7.20), with Δy = v_y t_s
//!    the signed sample spacing along y;
//! 4. α = arctan(δ_y / (x_2 − x_1)) (7.21).
//!
//! The pair angles are averaged with inverse-variance weights (the thesis averages
//! the angles of subsequent line pairs to reduce non-repetitive disturbances).
//!
//! **Which peak, when the features repeat.** A grating of pitch p correlates equally
//! well at every shift δ_y + n·p. The lag search is restricted to the window
//! |τ| ≤ L with L from the largest angle the caller admits (`max_angle_rad`):
//! L = |x_2 − x_1| tan(α_max)/|Δy| (+ the y0 offset, + 2 samples). Two aliases of one
//! peak lie p/|Δy| samples apart, so at most one lies in the window when the period
//! exceeds 2L. This is checked, not assumed: the autocorrelation of line 1 is
//! evaluated up to 2L and, if it climbs back to [`EstimatorOptions::alias_level`]
//! after its central lobe, the estimate is refused with
//! [`EstimateError::Ambiguous`] naming the period and the fix (lines closer
//! together, or a smaller `max_angle_rad`).
//!
//! **Sub-sample peak.** A sharp (edge-limited) peak is interpolated by the parabola
//! through its three top lags; a broad, noisy peak by a least-squares parabola over
//! the lags until the correlation has dropped by 8 noise levels ([`refine_peak`]).
//!
//! **Uncertainty.** Per pair, the variance of the lag is the least-squares vertex
//! variance σ_ρ²/(4a²Σt²) (σ_ρ the correlation's noise level from its second
//! differences, a the fitted curvature) plus 1/12 sample² (a sample-quantised edge
//! fixes a shift to one sample); it is propagated to
//! σ_α = σ_τ |Δy| / (|x_2 − x_1| (1 + tan²α)). The combined estimate reports this
//! propagated standard error and, with three or more lines, the spread of the pair
//! angles (standard deviation/√pairs); [`RotationEstimate::std_error_rad`] is the
//! larger of the two, because neighbouring lags' correlation noise is not white and
//! the propagated figure alone is optimistic for weak, smooth edges.
//!
//! ```
//! use nanomotion_directional_rc::estimate::{LineScan, estimate_rotation, EstimatorOptions};
//! // A 4 µm-pitch grating rotated by 0.02 rad, lines 1 µm apart, 2.5 nm per sample.
//! let alpha: f64 = 0.02;
//! let h = |x: f64, y: f64| {
//!     let s = (-x * alpha.sin() + y * alpha.cos()) / 4e-6;
//!     if s - s.floor() < 0.4 { 20e-9 } else { 0.0 }
//! };
//! let lines: Vec<LineScan> = (0..3)
//!     .map(|i| {
//!         let x = 1e-6 * i as f64;
//!         LineScan::new(x, -10e-6, 2.5e-9, (0..8000).map(|k| h(x, -10e-6 + 2.5e-9 * k as f64)).collect())
//!     })
//!     .collect();
//! let est = estimate_rotation(&lines, &EstimatorOptions::default()).unwrap();
//! assert!((est.alpha_rad - alpha).abs() < 2e-4, "{est}");
//! ```

use std::fmt;

/// One line scan along the fast axis y at a constant slow-axis position x.
#[derive(Debug, Clone, PartialEq)]
pub struct LineScan {
    /// Slow-axis position x_i of the line (m).
    pub x_m: f64,
    /// y of the first sample (m).
    pub y0_m: f64,
    /// Signed sample spacing along y, Δy = v_y t_s (m), (7.20).
    pub dy_m: f64,
    /// Measured heights z_i (m), one per sample.
    pub z_m: Vec<f64>,
}

impl LineScan {
    /// A line at `x_m` starting at `y0_m` with spacing `dy_m` and heights `z_m`.
    pub fn new(x_m: f64, y0_m: f64, dy_m: f64, z_m: Vec<f64>) -> Self {
        Self {
            x_m,
            y0_m,
            dy_m,
            z_m,
        }
    }
}

/// A borrowed line scan: what the estimator reads ([`LineScan`] owns its heights,
/// the `rotation_estimator` block keeps them in one preallocated buffer).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct LineRef<'a> {
    /// Slow-axis position x_i of the line (m).
    pub x_m: f64,
    /// y of the first sample (m).
    pub y0_m: f64,
    /// Signed sample spacing along y (m).
    pub dy_m: f64,
    /// Measured heights z_i (m).
    pub z_m: &'a [f64],
}

impl LineScan {
    /// The borrowed view the estimator reads.
    pub fn as_ref(&self) -> LineRef<'_> {
        LineRef {
            x_m: self.x_m,
            y0_m: self.y0_m,
            dy_m: self.dy_m,
            z_m: &self.z_m,
        }
    }
}

/// Preallocated work buffers of the estimator: with a workspace built for lines of
/// up to `max_samples` samples and `max_lines` lines, [`estimate_rotation_in`] does
/// not allocate. The lag window L can never exceed (max_samples/4 − 1)/2 (a longer
/// window is refused with [`EstimateError::TooShort`] before it is used), so the
/// correlation buffers need about max_samples/4 values.
#[derive(Debug, Clone)]
pub struct Workspace {
    p1: Prefix,
    p2: Prefix,
    r: Vec<f64>,
    d2: Vec<f64>,
    pairs: Vec<PairEstimate>,
    max_samples: usize,
}

impl Workspace {
    /// Buffers for up to `max_lines` lines of up to `max_samples` samples.
    pub fn new(max_lines: usize, max_samples: usize) -> Self {
        let lags = max_window(max_samples) * 2 + 1;
        Self {
            p1: Prefix::with_capacity(max_samples),
            p2: Prefix::with_capacity(max_samples),
            r: Vec::with_capacity(lags),
            d2: Vec::with_capacity(lags),
            pairs: Vec::with_capacity(max_lines.saturating_sub(1)),
            max_samples,
        }
    }

    /// The pair estimates of the last [`estimate_rotation_in`] call.
    pub fn pairs(&self) -> &[PairEstimate] {
        &self.pairs
    }

    /// Heap bytes held (two prefix-sum pairs of max_samples + 1 values, the
    /// correlation and second-difference buffers, the pairs).
    pub fn memory_bytes(&self) -> usize {
        (4 * (self.max_samples + 1) + self.r.capacity() + self.d2.capacity())
            * std::mem::size_of::<f64>()
            + self.pairs.capacity() * std::mem::size_of::<PairEstimate>()
    }
}

/// The largest lag window L a line of `n` samples admits: 4(2L + 1) ≤ n.
fn max_window(n: usize) -> usize {
    (n / 4).saturating_sub(1) / 2
}

/// The combined estimate without the pairs (what [`estimate_rotation_in`] returns;
/// the pairs stay in the [`Workspace`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Combined {
    /// Inverse-variance weighted mean of the pair angles (rad).
    pub alpha_rad: f64,
    /// Propagated standard error (rad).
    pub propagated_rad: f64,
    /// Spread of the pair angles / √pairs (rad), with ≥ 2 pairs.
    pub spread_rad: Option<f64>,
    /// max(propagated, spread) (rad).
    pub std_error_rad: f64,
}

/// Options of [`estimate_rotation`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct EstimatorOptions {
    /// Largest |α| admitted (rad): sets the lag window (default 0.1 rad).
    pub max_angle_rad: f64,
    /// Smallest acceptable normalised correlation peak (default 0.5): below it the
    /// two lines do not show the same structure.
    pub min_correlation: f64,
    /// Autocorrelation level at which a repeat of line 1's structure inside 2L counts
    /// as an alias of the peak, after the central lobe fell below level − 0.25
    /// (default 0.5, so in (0.25, 1)).
    pub alias_level: f64,
}

impl Default for EstimatorOptions {
    fn default() -> Self {
        Self {
            max_angle_rad: 0.1,
            min_correlation: 0.5,
            alias_level: 0.5,
        }
    }
}

/// The estimate from one pair of lines.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PairEstimate {
    /// Indices of the two lines.
    pub lines: (usize, usize),
    /// Sub-sample lag τ of the correlation peak (samples; −δ_s of (7.19)).
    pub lag_samples: f64,
    /// Shift of the features δ_y (m), (7.20).
    pub shift_m: f64,
    /// α = arctan(δ_y/(x_2 − x_1)) (rad), (7.21).
    pub alpha_rad: f64,
    /// Propagated standard deviation of α (rad) (see the module docs).
    pub sigma_rad: f64,
    /// Normalised correlation at the peak (−1 … 1).
    pub peak_correlation: f64,
    /// Half-width L of the lag window searched (samples).
    pub window_samples: usize,
}

/// The combined estimate ([`estimate_rotation`]).
#[derive(Debug, Clone, PartialEq)]
pub struct RotationEstimate {
    /// Inverse-variance weighted mean of the pair angles (rad).
    pub alpha_rad: f64,
    /// Standard error of `alpha_rad` propagated from the pairs (rad).
    pub propagated_rad: f64,
    /// Standard deviation of the pair angles / √pairs (rad), with ≥ 2 pairs.
    pub spread_rad: Option<f64>,
    /// The reported standard error: max(propagated, spread) (rad).
    pub std_error_rad: f64,
    /// The pairs (consecutive lines).
    pub pairs: Vec<PairEstimate>,
}

impl fmt::Display for RotationEstimate {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "α = {:.6} rad ± {:.2e} (1σ) from {} line pair(s)",
            self.alpha_rad,
            self.std_error_rad,
            self.pairs.len()
        )?;
        for p in &self.pairs {
            write!(
                f,
                "\n  lines {}–{}: lag {:+.3} samples, δ_y = {:+.3} nm, α = {:.6} rad ± {:.2e}, ρ = {:.3}",
                p.lines.0,
                p.lines.1,
                p.lag_samples,
                p.shift_m * 1e9,
                p.alpha_rad,
                p.sigma_rad,
                p.peak_correlation
            )?;
        }
        Ok(())
    }
}

/// Why the rotation could not be determined from the scans.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum EstimateError {
    /// Fewer than two lines.
    #[error("{0} line scan(s) given: the rotation needs at least two lines at different x")]
    TooFewLines(usize),
    /// A line has fewer samples than the estimator needs.
    #[error("line {line} has {len} samples: give at least {need} (the lag window is ±{window})")]
    TooShort {
        /// Line index.
        line: usize,
        /// Its length.
        len: usize,
        /// The minimum.
        need: usize,
        /// Lag window half-width (samples).
        window: usize,
    },
    /// A value is NaN or infinite.
    #[error(
        "line {line}: {what} is not finite (sample {index}); remove invalid samples before estimating"
    )]
    NonFinite {
        /// Line index.
        line: usize,
        /// What is not finite (`z`, `x`, `y0`, `dy`).
        what: &'static str,
        /// Sample index (0 for the scalars).
        index: usize,
    },
    /// The sample spacings of two lines differ.
    #[error(
        "lines {a} and {b} have different sample spacings dy ({dy_a} m, {dy_b} m): scan all lines at the same speed and rate"
    )]
    SpacingMismatch {
        /// First line.
        a: usize,
        /// Second line.
        b: usize,
        /// Its spacing.
        dy_a: f64,
        /// The other spacing.
        dy_b: f64,
    },
    /// dy is zero.
    #[error("line {0}: the sample spacing dy is 0: the fast axis did not move")]
    ZeroSpacing(usize),
    /// Two consecutive lines at the same x.
    #[error("lines {a} and {b} are at the same x ({x} m): (7.21) needs x_2 ≠ x_1")]
    SameX {
        /// First line.
        a: usize,
        /// Second line.
        b: usize,
        /// Their x.
        x: f64,
    },
    /// A line has no height variation.
    #[error(
        "line {line} is flat (standard deviation {std_m:.3e} m): no feature to correlate; scan across the sample's structure"
    )]
    Flat {
        /// Line index.
        line: usize,
        /// Its standard deviation (m).
        std_m: f64,
    },
    /// The structure repeats inside the lag window: the peak is not unique.
    #[error(
        "lines {a}–{b}: the structure repeats every {period_samples} samples ({period_m:.3e} m) but the lag window spans ±{window_samples}: two correlation peaks fit the admitted angles; put the lines closer than {max_dx_m:.3e} m or lower max_angle_rad"
    )]
    Ambiguous {
        /// First line.
        a: usize,
        /// Second line.
        b: usize,
        /// Lag at which line a's autocorrelation repeats (samples).
        period_samples: usize,
        /// The same in metres.
        period_m: f64,
        /// Window half-width L (samples).
        window_samples: usize,
        /// Largest line spacing that makes the peak unique for `max_angle_rad`.
        max_dx_m: f64,
    },
    /// The correlation peak is too weak.
    #[error(
        "lines {a}–{b}: the best correlation is {peak:.3} (< {min}): the lines do not show the same structure (noise, a different sample region, or a rotation above max_angle_rad)"
    )]
    WeakCorrelation {
        /// First line.
        a: usize,
        /// Second line.
        b: usize,
        /// The peak value.
        peak: f64,
        /// The threshold.
        min: f64,
    },
    /// The peak lies on the edge of the window: the angle may exceed `max_angle_rad`.
    #[error(
        "lines {a}–{b}: the correlation peaks at the window edge (lag {lag}, window ±{window}): the rotation is probably above max_angle_rad = {max_angle} rad; raise it"
    )]
    PeakAtEdge {
        /// First line.
        a: usize,
        /// Second line.
        b: usize,
        /// The lag.
        lag: i64,
        /// The window.
        window: usize,
        /// The limit in use.
        max_angle: f64,
    },
    /// A line is longer than the workspace (the block's buffers) holds.
    #[error(
        "line {line} has {len} samples but the estimator holds at most {max}: raise max_line_s (the block) or build a larger workspace"
    )]
    TooLong {
        /// Line index.
        line: usize,
        /// Its length.
        len: usize,
        /// The capacity.
        max: usize,
    },
    /// More lines than the workspace holds.
    #[error("{lines} lines given but the estimator holds at most {max}")]
    TooManyLines {
        /// Lines given.
        lines: usize,
        /// The capacity.
        max: usize,
    },
    /// Bad options.
    #[error(
        "option {0} must be finite and in its range (max_angle_rad in (0, 1.5), levels in (0, 1))"
    )]
    BadOption(&'static str),
}

impl EstimateError {
    /// A number per kind (1 … 13, in declaration order), for the
    /// `rotation_estimator` block's `status` output (−code on failure).
    pub fn code(&self) -> u8 {
        match self {
            Self::TooFewLines(_) => 1,
            Self::TooShort { .. } => 2,
            Self::NonFinite { .. } => 3,
            Self::SpacingMismatch { .. } => 4,
            Self::ZeroSpacing(_) => 5,
            Self::SameX { .. } => 6,
            Self::Flat { .. } => 7,
            Self::Ambiguous { .. } => 8,
            Self::WeakCorrelation { .. } => 9,
            Self::PeakAtEdge { .. } => 10,
            Self::BadOption(_) => 11,
            Self::TooLong { .. } => 12,
            Self::TooManyLines { .. } => 13,
        }
    }
}

/// Mean and standard deviation (population) of `z`.
fn mean_std(z: &[f64]) -> (f64, f64) {
    let n = z.len() as f64;
    let m = z.iter().sum::<f64>() / n;
    let v = z.iter().map(|v| (v - m) * (v - m)).sum::<f64>() / n;
    (m, v.sqrt())
}

/// Prefix sums of z and z² for O(1) overlap statistics.
#[derive(Debug, Clone)]
struct Prefix {
    s: Vec<f64>,
    s2: Vec<f64>,
}

impl Prefix {
    fn with_capacity(n: usize) -> Self {
        Self {
            s: Vec::with_capacity(n + 1),
            s2: Vec::with_capacity(n + 1),
        }
    }
    fn new(z: &[f64]) -> Self {
        let mut p = Self::with_capacity(z.len());
        p.fill(z);
        p
    }
    /// Refill from `z` (no allocation within the capacity).
    fn fill(&mut self, z: &[f64]) {
        self.s.clear();
        self.s2.clear();
        let (mut a, mut b) = (0.0, 0.0);
        self.s.push(0.0);
        self.s2.push(0.0);
        for v in z {
            a += v;
            b += v * v;
            self.s.push(a);
            self.s2.push(b);
        }
    }
    /// (mean, variance) of z\[k0..k1\].
    fn stats(&self, k0: usize, k1: usize) -> (f64, f64) {
        let n = (k1 - k0) as f64;
        let m = (self.s[k1] - self.s[k0]) / n;
        (m, ((self.s2[k1] - self.s2[k0]) / n - m * m).max(0.0))
    }
}

/// Normalised mean-removed correlation ρ(τ) of (7.18) for one lag, over the
/// overlap k ∈ \[k0, k1) of z_1\[k\] and z_2\[k + τ\], with the overlap's own means
/// and standard deviations (a Pearson coefficient per lag, so that partial
/// overlaps of a line whose mean drifts do not bias the peak).
fn rho(a: &[f64], pa: &Prefix, b: &[f64], pb: &Prefix, tau: i64) -> f64 {
    let n = a.len().min(b.len()) as i64;
    let (k0, k1) = if tau >= 0 { (0, n - tau) } else { (-tau, n) };
    if k1 - k0 < 2 {
        return 0.0;
    }
    let (k0, k1) = (k0 as usize, k1 as usize);
    let (j0, j1) = ((k0 as i64 + tau) as usize, (k1 as i64 + tau) as usize);
    let (ma, va) = pa.stats(k0, k1);
    let (mb, vb) = pb.stats(j0, j1);
    if va <= 0.0 || vb <= 0.0 {
        return 0.0;
    }
    let mut s = 0.0;
    for (x, y) in a[k0..k1].iter().zip(&b[j0..j1]) {
        s += (x - ma) * (y - mb);
    }
    s / ((k1 - k0) as f64 * (va * vb).sqrt())
}

/// Cross-correlation ρ(τ) of (7.18), mean-removed and normalised per overlap, for
/// τ ∈ \[−L, L\] (index τ + L). Lines are cut to the shorter length.
pub fn cross_correlation(z1: &[f64], z2: &[f64], max_lag: usize) -> Vec<f64> {
    let n = z1.len().min(z2.len());
    let (z1, z2) = (&z1[..n], &z2[..n]);
    let (p1, p2) = (Prefix::new(z1), Prefix::new(z2));
    let mut r = Vec::with_capacity(2 * max_lag + 1);
    correlation_into(z1, &p1, z2, &p2, max_lag, &mut r);
    r
}

/// [`cross_correlation`] into `r` (cleared; no allocation within its capacity).
fn correlation_into(
    z1: &[f64],
    p1: &Prefix,
    z2: &[f64],
    p2: &Prefix,
    max_lag: usize,
    r: &mut Vec<f64>,
) {
    let l = max_lag as i64;
    r.clear();
    r.extend((-l..=l).map(|t| rho(z1, p1, z2, p2, t)));
}

/// Vertex of the parabola through (−1, r_m), (0, r_0), (1, r_p): offset in (−0.5,
/// 0.5) for a proper local maximum, and the peak value there.
pub fn parabolic_peak(r_m: f64, r_0: f64, r_p: f64) -> (f64, f64) {
    let den = r_m - 2.0 * r_0 + r_p;
    if den >= 0.0 {
        return (0.0, r_0);
    }
    let d = (0.5 * (r_m - r_p) / den).clamp(-0.5, 0.5);
    (d, r_0 - 0.25 * (r_m - r_p) * d)
}

/// Least-squares parabola through r\[c − w ..= c + w\]: (vertex offset from c, peak,
/// curvature a, Σ t²).
fn ls_parabola(r: &[f64], c: usize, w: usize) -> (f64, f64, f64, f64) {
    let (mut s2, mut s4, mut r0, mut r1, mut r2) = (0.0, 0.0, 0.0, 0.0, 0.0);
    for i in 0..=2 * w {
        let t = i as f64 - w as f64;
        let v = r[c + i - w];
        s2 += t * t;
        s4 += t * t * t * t;
        r0 += v;
        r1 += t * v;
        r2 += t * t * v;
    }
    let s0 = (2 * w + 1) as f64;
    let a = (s0 * r2 - s2 * r0) / (s0 * s4 - s2 * s2);
    let b = r1 / s2;
    let c0 = (r0 - a * s2) / s0;
    if a >= 0.0 {
        return (0.0, r[c], 0.0, s2);
    }
    let v = (-b / (2.0 * a)).clamp(-(w as f64), w as f64);
    (v, c0 + b * v + a * v * v, a, s2)
}

/// Sub-sample peak of the correlation `r` around its maximum `imax`: returns
/// the offset, the peak value, the half-width used and the offset's variance.
///
/// A sharp (edge-limited) peak is interpolated by the parabola through its three
/// top samples. A broad peak carries estimation noise (the cross terms of signal and
/// noise) that moves the arg max by several samples; there a least-squares
/// parabola is fitted over the ±w lags around the peak, with w grown until the
/// correlation has dropped by 8 noise levels on both sides (noise level: the median
/// absolute second difference of `r`, scaled for white noise), and refitted once
/// around the vertex found.
pub fn refine_peak(r: &[f64], imax: usize) -> PeakFit {
    let mut d2 = Vec::with_capacity(r.len());
    refine_peak_in(r, imax, &mut d2)
}

/// [`refine_peak`] with a caller's buffer for the second differences (no
/// allocation within its capacity).
fn refine_peak_in(r: &[f64], imax: usize, d2: &mut Vec<f64>) -> PeakFit {
    d2.clear();
    d2.extend(r.windows(3).map(|w| (w[0] - 2.0 * w[1] + w[2]).abs()));
    let sigma = if d2.is_empty() {
        0.0
    } else {
        let m = d2.len() / 2;
        let (_, med, _) = d2.select_nth_unstable_by(m, f64::total_cmp);
        *med / 0.6745 / 6f64.sqrt()
    };
    if imax == 0 || imax + 1 >= r.len() {
        return PeakFit {
            offset: 0.0,
            peak: r[imax],
            half_width: 0,
            var_offset: 1.0 / 12.0,
        };
    }
    let lim = imax.min(r.len() - 1 - imax);
    let mut w = 1;
    while w < lim && r[imax] - r[imax - w].max(r[imax + w]) < 8.0 * sigma {
        w += 1;
    }
    if w <= 1 {
        let (d, p) = parabolic_peak(r[imax - 1], r[imax], r[imax + 1]);
        return PeakFit {
            offset: d,
            peak: p,
            half_width: 1,
            var_offset: 1.0 / 12.0,
        };
    }
    let (mut v, mut p, mut a, mut s2) = ls_parabola(r, imax, w);
    // Refit centred on the vertex.
    let c = (imax as f64 + v).round() as usize;
    let w2 = w.min(c.min(r.len() - 1 - c));
    let mut half = w;
    if w2 >= 2 && c != imax {
        let (v2, p2, a2, s22) = ls_parabola(r, c, w2);
        (v, p, a, s2, half) = (c as f64 + v2 - imax as f64, p2, a2, s22, w2);
    }
    // var(vertex) ≈ var(b)/(4a²) = σ_ρ²/(4a² Σt²), plus the quantisation floor.
    let var_fit = if a < 0.0 {
        sigma * sigma / (4.0 * a * a * s2)
    } else {
        (half * half) as f64
    };
    PeakFit {
        offset: v,
        peak: p,
        half_width: half,
        var_offset: var_fit + 1.0 / 12.0,
    }
}

/// The sub-sample correlation peak ([`refine_peak`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PeakFit {
    /// Offset of the peak from the integer arg max (samples).
    pub offset: f64,
    /// Correlation at the peak.
    pub peak: f64,
    /// Half-width of the fitted lags (1: three-point parabola).
    pub half_width: usize,
    /// Variance of `offset` (samples²): the fit's, from the correlation's noise
    /// level, plus 1/12 (one sample of quantisation of an edge).
    pub var_offset: f64,
}

fn validate(lines: &[LineRef<'_>], o: &EstimatorOptions) -> Result<(), EstimateError> {
    if !(o.max_angle_rad.is_finite() && o.max_angle_rad > 0.0 && o.max_angle_rad < 1.5) {
        return Err(EstimateError::BadOption("max_angle_rad"));
    }
    if !(o.min_correlation > 0.0 && o.min_correlation < 1.0) {
        return Err(EstimateError::BadOption("min_correlation"));
    }
    if !(o.alias_level > 0.25 && o.alias_level < 1.0) {
        return Err(EstimateError::BadOption("alias_level"));
    }
    if lines.len() < 2 {
        return Err(EstimateError::TooFewLines(lines.len()));
    }
    for (i, l) in lines.iter().enumerate() {
        for (what, v) in [("x", l.x_m), ("y0", l.y0_m), ("dy", l.dy_m)] {
            if !v.is_finite() {
                return Err(EstimateError::NonFinite {
                    line: i,
                    what,
                    index: 0,
                });
            }
        }
        if l.dy_m == 0.0 {
            return Err(EstimateError::ZeroSpacing(i));
        }
        if let Some(k) = l.z_m.iter().position(|v| !v.is_finite()) {
            return Err(EstimateError::NonFinite {
                line: i,
                what: "z",
                index: k,
            });
        }
        let d0 = lines[0].dy_m;
        if ((l.dy_m - d0) / d0).abs() > 1e-9 {
            return Err(EstimateError::SpacingMismatch {
                a: 0,
                b: i,
                dy_a: d0,
                dy_b: l.dy_m,
            });
        }
    }
    Ok(())
}

/// Estimate α from one pair of lines (see the module docs).
pub fn estimate_pair(
    lines: &[LineScan],
    a: usize,
    b: usize,
    o: &EstimatorOptions,
) -> Result<PairEstimate, EstimateError> {
    let refs: Vec<LineRef<'_>> = lines.iter().map(LineScan::as_ref).collect();
    let n = lines.iter().map(|l| l.z_m.len()).max().unwrap_or(0);
    pair_in(&refs, a, b, o, &mut Workspace::new(lines.len(), n))
}

/// [`estimate_pair`] in a workspace: allocation-free when the lines fit it.
fn pair_in(
    lines: &[LineRef<'_>],
    a: usize,
    b: usize,
    o: &EstimatorOptions,
    ws: &mut Workspace,
) -> Result<PairEstimate, EstimateError> {
    let (la, lb) = (&lines[a], &lines[b]);
    let dx = lb.x_m - la.x_m;
    if dx == 0.0 {
        return Err(EstimateError::SameX { a, b, x: la.x_m });
    }
    let dy = la.dy_m;
    let y_off = (lb.y0_m - la.y0_m) / dy; // samples
    let window = (dx.abs() * o.max_angle_rad.tan() / dy.abs() + y_off.abs()).ceil() as usize + 2;
    let n = la.z_m.len().min(lb.z_m.len());
    // At least 4 windows of overlap everywhere in the search, and 2L for the alias test.
    let need = 4 * (2 * window + 1);
    for (i, l) in [(a, la), (b, lb)] {
        if l.z_m.len() < need {
            return Err(EstimateError::TooShort {
                line: i,
                len: l.z_m.len(),
                need,
                window,
            });
        }
    }
    if n > ws.max_samples {
        return Err(EstimateError::TooLong {
            line: if la.z_m.len() >= lb.z_m.len() { a } else { b },
            len: n,
            max: ws.max_samples,
        });
    }
    let (z1, z2) = (&la.z_m[..n], &lb.z_m[..n]);
    let (_, s1) = mean_std(z1);
    let (_, s2) = mean_std(z2);
    let scale = z1.iter().chain(z2).fold(0.0f64, |m, v| m.max(v.abs()));
    for (i, s) in [(a, s1), (b, s2)] {
        if s <= 1e-9 * scale.max(1e-300) {
            return Err(EstimateError::Flat { line: i, std_m: s });
        }
    }
    // Alias test: does line a's structure repeat within 2L?
    ws.p1.fill(z1);
    ws.p2.fill(z2);
    let p1 = &ws.p1;
    let mut below = false;
    for t in 1..=(2 * window).min(n / 2) {
        let r = rho(z1, p1, z1, p1, t as i64);
        // Hysteresis: the central lobe must fall clearly below the level (by 0.25)
        // before a climb back counts, so that estimation noise on a slowly
        // decaying lobe is no repeat.
        if r < o.alias_level - 0.25 {
            below = true;
        } else if below {
            // Climb to the repeat's peak: that lag is the period.
            let t_cross = t;
            let (mut t, mut r) = (t, r);
            while t + 1 < n / 2 {
                let r2 = rho(z1, p1, z1, p1, t as i64 + 1);
                if r2 <= r {
                    break;
                }
                r = r2;
                t += 1;
            }
            let period_m = t as f64 * dy.abs();
            return Err(EstimateError::Ambiguous {
                a,
                b,
                period_samples: t,
                period_m,
                window_samples: window,
                // 2L must stay below the lag where the repeat starts (t_cross).
                max_dx_m: ((0.5 * (t_cross as f64 - 1.0) - y_off.abs() - 3.0) * dy.abs()).max(0.0)
                    / o.max_angle_rad.tan(),
            });
        }
    }
    correlation_into(z1, &ws.p1, z2, &ws.p2, window, &mut ws.r);
    let r = &ws.r;
    let (imax, _) = r
        .iter()
        .enumerate()
        .max_by(|x, y| x.1.total_cmp(y.1))
        .expect("window ≥ 2");
    let lag = imax as i64 - window as i64;
    if imax == 0 || imax == r.len() - 1 {
        return Err(EstimateError::PeakAtEdge {
            a,
            b,
            lag,
            window,
            max_angle: o.max_angle_rad,
        });
    }
    let fit = refine_peak_in(r, imax, &mut ws.d2);
    let (frac, peak) = (fit.offset, fit.peak);
    if peak < o.min_correlation {
        return Err(EstimateError::WeakCorrelation {
            a,
            b,
            peak,
            min: o.min_correlation,
        });
    }
    let tau = lag as f64 + frac;
    let shift = (lb.y0_m - la.y0_m) + tau * dy;
    let u = shift / dx;
    let alpha = u.atan();
    let sigma_tau = fit.var_offset.sqrt();
    let sigma = sigma_tau * dy.abs() / (dx.abs() * (1.0 + u * u));
    Ok(PairEstimate {
        lines: (a, b),
        lag_samples: tau,
        shift_m: shift,
        alpha_rad: alpha,
        sigma_rad: sigma,
        peak_correlation: peak,
        window_samples: window,
    })
}

/// Estimate the sample rotation α from `lines` (consecutive pairs, averaged),
/// (7.18)–(7.21); see the module docs for the peak choice and the uncertainty.
pub fn estimate_rotation(
    lines: &[LineScan],
    o: &EstimatorOptions,
) -> Result<RotationEstimate, EstimateError> {
    let refs: Vec<LineRef<'_>> = lines.iter().map(LineScan::as_ref).collect();
    let n = lines.iter().map(|l| l.z_m.len()).max().unwrap_or(0);
    let mut ws = Workspace::new(lines.len(), n);
    let c = estimate_rotation_in(&refs, o, &mut ws)?;
    let est = RotationEstimate {
        alpha_rad: c.alpha_rad,
        propagated_rad: c.propagated_rad,
        spread_rad: c.spread_rad,
        std_error_rad: c.std_error_rad,
        pairs: ws.pairs,
    };
    tracing::debug!(%est, "rotation estimate");
    Ok(est)
}

/// [`estimate_rotation`] in a preallocated [`Workspace`]: the same computation,
/// allocation-free when the lines fit the workspace (more lines or longer lines
/// than it was built for are refused with [`EstimateError::TooLong`] /
/// [`EstimateError::TooManyLines`]). The pairs are left in
/// [`Workspace::pairs`]. Cost: per pair O(n·L) multiply-adds (n samples, L lags).
pub fn estimate_rotation_in(
    lines: &[LineRef<'_>],
    o: &EstimatorOptions,
    ws: &mut Workspace,
) -> Result<Combined, EstimateError> {
    validate(lines, o)?;
    ws.pairs.clear();
    if lines.len() - 1 > ws.pairs.capacity() {
        return Err(EstimateError::TooManyLines {
            lines: lines.len(),
            max: ws.pairs.capacity() + 1,
        });
    }
    for i in 0..lines.len() - 1 {
        let p = pair_in(lines, i, i + 1, o, ws)?;
        ws.pairs.push(p);
    }
    let pairs = &ws.pairs;
    let wsum: f64 = pairs
        .iter()
        .map(|p| 1.0 / (p.sigma_rad * p.sigma_rad))
        .sum();
    let alpha = pairs
        .iter()
        .map(|p| p.alpha_rad / (p.sigma_rad * p.sigma_rad))
        .sum::<f64>()
        / wsum;
    let propagated = 1.0 / wsum.sqrt();
    let spread = (pairs.len() >= 2).then(|| {
        let n = pairs.len() as f64;
        let m = pairs.iter().map(|p| p.alpha_rad).sum::<f64>() / n;
        let v = pairs.iter().map(|p| (p.alpha_rad - m).powi(2)).sum::<f64>() / (n - 1.0);
        (v / n).sqrt()
    });
    Ok(Combined {
        alpha_rad: alpha,
        propagated_rad: propagated,
        spread_rad: spread,
        std_error_rad: propagated.max(spread.unwrap_or(0.0)),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn grating(pitch: f64, h: f64, duty: f64, alpha: f64, off: f64) -> impl Fn(f64, f64) -> f64 {
        move |x, y| {
            let s = (-x * alpha.sin() + y * alpha.cos() - off) / pitch;
            if s - s.floor() < duty { h } else { 0.0 }
        }
    }

    fn lines(h: &dyn Fn(f64, f64) -> f64, xs: &[f64], y0: f64, dy: f64, n: usize) -> Vec<LineScan> {
        xs.iter()
            .map(|&x| {
                LineScan::new(
                    x,
                    y0,
                    dy,
                    (0..n).map(|k| h(x, y0 + dy * k as f64)).collect(),
                )
            })
            .collect()
    }

    #[test]
    fn parabola_vertex_is_exact_for_a_parabola() {
        // r(t) = 1 − 0.3 (t − 0.27)²
        let f = |t: f64| 1.0 - 0.3 * (t - 0.27) * (t - 0.27);
        let (d, p) = parabolic_peak(f(-1.0), f(0.0), f(1.0));
        assert!((d - 0.27).abs() < 1e-12);
        assert!((p - 1.0).abs() < 1e-12);
    }

    #[test]
    fn correlation_matches_a_direct_pearson_computation() {
        let z1: Vec<f64> = (0..200).map(|k| ((k * k) % 17) as f64).collect();
        let z2: Vec<f64> = (0..200).map(|k| ((k * 7 + 3) % 11) as f64).collect();
        let r = cross_correlation(&z1, &z2, 5);
        // lag +3: the Pearson coefficient of (z1[k], z2[k+3]), k = 0..197.
        let (m1, s1) = mean_std(&z1[..197]);
        let (m2, s2) = mean_std(&z2[3..]);
        let mut s = 0.0;
        for k in 0..197 {
            s += (z1[k] - m1) * (z2[k + 3] - m2);
        }
        assert!((r[5 + 3] - s / (197.0 * s1 * s2)).abs() < 1e-12);
        // ρ of a line with itself at lag 0 is 1.
        assert!((cross_correlation(&z1, &z1, 0)[0] - 1.0).abs() < 1e-12);
    }

    #[test]
    fn integer_shift_of_a_smooth_profile_is_exact() {
        // Smooth profile, line 2 shifted by exactly 7 samples: α = atan(7 dy/dx).
        let dy = 2e-9;
        let prof = |y: f64| (y / 0.3e-6).sin() * 5e-9 + (y / 0.71e-6).cos() * 3e-9;
        let a = LineScan::new(
            0.0,
            0.0,
            dy,
            (0..5000).map(|k| prof(k as f64 * dy)).collect(),
        );
        let b = LineScan::new(
            1e-6,
            0.0,
            dy,
            (0..5000).map(|k| prof((k as f64 - 7.0) * dy)).collect(),
        );
        let e = estimate_rotation(&[a, b], &EstimatorOptions::default()).unwrap();
        assert!((e.pairs[0].lag_samples - 7.0).abs() < 1e-3, "{e}");
        assert!((e.alpha_rad - (7.0 * dy / 1e-6f64).atan()).abs() < 1e-5);
    }

    #[test]
    fn y0_offset_and_negative_scan_direction_are_accounted_for() {
        let alpha = -0.031;
        let h = grating(5e-6, 30e-9, 0.4, alpha, 0.0);
        // Line 2 starts 40 nm later; the lines are scanned towards −y.
        let mut l = lines(&h, &[0.0, 1.5e-6], 10e-6, -2.5e-9, 8000);
        l[1] = LineScan::new(
            1.5e-6,
            10e-6 + 40e-9,
            -2.5e-9,
            (0..8000)
                .map(|k| h(1.5e-6, 10e-6 + 40e-9 - 2.5e-9 * k as f64))
                .collect(),
        );
        let e = estimate_rotation(&l, &EstimatorOptions::default()).unwrap();
        assert!((e.alpha_rad - alpha).abs() < 2.0 * e.std_error_rad, "{e}");
        assert!(e.std_error_rad < 5e-4, "{e}");
    }

    #[test]
    fn failures_are_named() {
        let h = grating(1e-6, 20e-9, 0.5, 0.02, 0.0);
        let o = EstimatorOptions::default();
        // Lines 10 µm apart, window = 10 µm · tan 0.1 ≈ 1 µm ≫ pitch/2: ambiguous.
        let l = lines(&h, &[0.0, 10e-6], 0.0, 2.5e-9, 8000);
        let err = estimate_rotation(&l, &o).unwrap_err();
        match err {
            EstimateError::Ambiguous {
                period_samples,
                max_dx_m,
                ..
            } => {
                // The pitch along y is p/cos α = 400.08 samples.
                assert!((period_samples as f64 - 400.0).abs() <= 1.0, "{err}");
                // The proposed spacing makes it unique.
                let l = lines(&h, &[0.0, 0.9 * max_dx_m], 0.0, 2.5e-9, 8000);
                let e = estimate_rotation(&l, &o).unwrap();
                assert!((e.alpha_rad - 0.02).abs() < 2e-3, "{e}");
            }
            other => panic!("{other}"),
        }
        let flat = vec![
            LineScan::new(0.0, 0.0, 1e-9, vec![1e-9; 4000]),
            LineScan::new(1e-6, 0.0, 1e-9, vec![1e-9; 4000]),
        ];
        assert!(matches!(
            estimate_rotation(&flat, &o),
            Err(EstimateError::Flat { line: 0, .. })
        ));
        assert!(matches!(
            estimate_rotation(&flat[..1], &o),
            Err(EstimateError::TooFewLines(1))
        ));
        let mut l = lines(&h, &[0.0, 1e-6], 0.0, 2.5e-9, 4000);
        l[1].z_m[17] = f64::NAN;
        assert!(matches!(
            estimate_rotation(&l, &o),
            Err(EstimateError::NonFinite {
                line: 1,
                what: "z",
                index: 17
            })
        ));
        let l = lines(&h, &[1e-6, 1e-6], 0.0, 2.5e-9, 4000);
        assert!(matches!(
            estimate_rotation(&l, &o),
            Err(EstimateError::SameX { .. })
        ));
        // Pure noise on both lines: no common structure.
        let mut rng = nanomotion_core::rng::Rng::new(3);
        let noise: Vec<LineScan> = (0..2)
            .map(|i| {
                LineScan::new(
                    i as f64 * 1e-6,
                    0.0,
                    2.5e-9,
                    (0..6000).map(|_| rng.normal()).collect(),
                )
            })
            .collect();
        let e = estimate_rotation(&noise, &o).unwrap_err();
        assert!(matches!(e, EstimateError::WeakCorrelation { .. }), "{e}");
        // Rotation beyond max_angle_rad: peak on the window edge.
        let h = grating(8e-6, 20e-9, 0.5, 0.09, 0.0);
        let l = lines(&h, &[0.0, 1e-6], 0.0, 2.5e-9, 8000);
        let small = EstimatorOptions {
            max_angle_rad: 0.03,
            ..o
        };
        let e = estimate_rotation(&l, &small).unwrap_err();
        assert!(matches!(e, EstimateError::PeakAtEdge { .. }), "{e}");
        assert!(e.to_string().contains("raise it"));
    }
}
