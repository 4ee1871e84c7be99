//! Statistics the workflow decides with, written out and tested against closed
//! forms: normal, χ² and Student-t distributions; residual whiteness (Ljung–Box);
//! residual–input cross-correlation with Bartlett's variance; Fisher's g test for a
//! periodic line; a batch-means test that one residual beats another on held-out
//! data; a robust noise-floor estimate; linear least squares with covariance.

use std::f64::consts::PI;

/// ln Γ(x) for x > 0 (Lanczos, g = 7, n = 9; |error| < 1e-14 relative).
pub fn ln_gamma(x: f64) -> f64 {
    const G: f64 = 7.0;
    const C: [f64; 9] = [
        0.999_999_999_999_809_9,
        676.520_368_121_885_1,
        -1_259.139_216_722_402_8,
        771.323_428_777_653_1,
        -176.615_029_162_140_6,
        12.507_343_278_686_905,
        -0.138_571_095_265_720_12,
        9.984_369_578_019_572e-6,
        1.505_632_735_149_311_6e-7,
    ];
    if x < 0.5 {
        // Reflection.
        return (PI / (PI * x).sin()).ln() - ln_gamma(1.0 - x);
    }
    let x = x - 1.0;
    let mut a = C[0];
    let t = x + G + 0.5;
    for (i, c) in C.iter().enumerate().skip(1) {
        a += c / (x + i as f64);
    }
    0.5 * (2.0 * PI).ln() + (x + 0.5) * t.ln() - t + a.ln()
}

/// Regularised upper incomplete gamma Q(a, x) = Γ(a, x)/Γ(a).
pub fn gamma_q(a: f64, x: f64) -> f64 {
    if x <= 0.0 {
        return 1.0;
    }
    if x < a + 1.0 {
        // Series for P.
        let mut sum = 1.0 / a;
        let mut term = sum;
        let mut ap = a;
        for _ in 0..1000 {
            ap += 1.0;
            term *= x / ap;
            sum += term;
            if term.abs() < sum.abs() * 1e-16 {
                break;
            }
        }
        let p = sum * (-x + a * x.ln() - ln_gamma(a)).exp();
        (1.0 - p).clamp(0.0, 1.0)
    } else {
        // Continued fraction (modified Lentz) for Q.
        let tiny = 1e-300;
        let mut b = x + 1.0 - a;
        let mut c = 1.0 / tiny;
        let mut d = 1.0 / b;
        let mut h = d;
        for i in 1..1000 {
            let an = -(i as f64) * (i as f64 - a);
            b += 2.0;
            d = an * d + b;
            if d.abs() < tiny {
                d = tiny;
            }
            c = b + an / c;
            if c.abs() < tiny {
                c = tiny;
            }
            d = 1.0 / d;
            let del = d * c;
            h *= del;
            if (del - 1.0).abs() < 1e-16 {
                break;
            }
        }
        ((-x + a * x.ln() - ln_gamma(a)).exp() * h).clamp(0.0, 1.0)
    }
}

/// P(χ²_k > x): survival function of the χ² distribution with k degrees of freedom.
pub fn chi2_sf(x: f64, k: f64) -> f64 {
    gamma_q(0.5 * k, 0.5 * x)
}

/// Complementary error function, erfc(x) = Q(1/2, x²) for x ≥ 0 (accurate to
/// round-off through [`gamma_q`]).
pub fn erfc(x: f64) -> f64 {
    let q = gamma_q(0.5, x * x);
    if x >= 0.0 { q } else { 2.0 - q }
}

/// P(Z > z) for a standard normal Z.
pub fn normal_sf(z: f64) -> f64 {
    0.5 * erfc(z / std::f64::consts::SQRT_2)
}

/// Regularised incomplete beta I_x(a, b) (continued fraction).
pub fn beta_inc(a: f64, b: f64, x: f64) -> f64 {
    if x <= 0.0 {
        return 0.0;
    }
    if x >= 1.0 {
        return 1.0;
    }
    let ln_front = ln_gamma(a + b) - ln_gamma(a) - ln_gamma(b) + a * x.ln() + b * (1.0 - x).ln();
    let cf = |a: f64, b: f64, x: f64| -> f64 {
        let tiny = 1e-300;
        let (qab, qap, qam) = (a + b, a + 1.0, a - 1.0);
        let mut c = 1.0;
        let mut d = 1.0 - qab * x / qap;
        if d.abs() < tiny {
            d = tiny;
        }
        d = 1.0 / d;
        let mut h = d;
        for m in 1..1000 {
            let m = m as f64;
            let m2 = 2.0 * m;
            let aa = m * (b - m) * x / ((qam + m2) * (a + m2));
            d = 1.0 + aa * d;
            if d.abs() < tiny {
                d = tiny;
            }
            c = 1.0 + aa / c;
            if c.abs() < tiny {
                c = tiny;
            }
            d = 1.0 / d;
            h *= d * c;
            let aa = -(a + m) * (qab + m) * x / ((a + m2) * (qap + m2));
            d = 1.0 + aa * d;
            if d.abs() < tiny {
                d = tiny;
            }
            c = 1.0 + aa / c;
            if c.abs() < tiny {
                c = tiny;
            }
            d = 1.0 / d;
            let del = d * c;
            h *= del;
            if (del - 1.0).abs() < 1e-15 {
                break;
            }
        }
        h
    };
    if x < (a + 1.0) / (a + b + 2.0) {
        ln_front.exp() * cf(a, b, x) / a
    } else {
        1.0 - ln_front.exp() * cf(b, a, 1.0 - x) / b
    }
}

/// P(T > t) for Student's t with `dof` degrees of freedom.
pub fn student_t_sf(t: f64, dof: f64) -> f64 {
    let x = dof / (dof + t * t);
    let tail = 0.5 * beta_inc(0.5 * dof, 0.5, x);
    if t >= 0.0 { tail } else { 1.0 - tail }
}

/// Mean of `x` (0 for an empty slice).
pub fn mean(x: &[f64]) -> f64 {
    if x.is_empty() {
        0.0
    } else {
        x.iter().sum::<f64>() / x.len() as f64
    }
}

/// Mean square of `x`.
pub fn mean_square(x: &[f64]) -> f64 {
    if x.is_empty() {
        0.0
    } else {
        x.iter().map(|v| v * v).sum::<f64>() / x.len() as f64
    }
}

/// Normalised sample autocorrelation ρ(0..=max_lag) (biased estimator, mean removed).
/// O(n·L) by direct sums for a few lags, O(n log n) by FFT for many
/// ([`lag_products`]).
pub fn autocorrelation(x: &[f64], max_lag: usize) -> Vec<f64> {
    let n = x.len();
    let m = mean(x);
    let c0: f64 = x.iter().map(|v| (v - m) * (v - m)).sum();
    let lags = max_lag.min(n.saturating_sub(1));
    if c0 == 0.0 {
        return (0..=lags).map(|k| if k == 0 { 1.0 } else { 0.0 }).collect();
    }
    let centred: Vec<f64> = x.iter().map(|v| v - m).collect();
    let s = lag_products(&centred, &centred, lags);
    s[lags..].iter().map(|v| v / c0).collect()
}

/// Normalised cross-correlation ρ_xy(τ) = Σ x(t+τ) y(t) / √(Σx² Σy²) for τ in
/// −max_lag..=max_lag (means removed), returned with index τ + max_lag
/// ([`lag_products`]: O(n log n) for many lags).
pub fn cross_correlation(x: &[f64], y: &[f64], max_lag: usize) -> Vec<f64> {
    let n = x.len().min(y.len());
    let (mx, my) = (mean(&x[..n]), mean(&y[..n]));
    let sx: f64 = x[..n].iter().map(|v| (v - mx) * (v - mx)).sum();
    let sy: f64 = y[..n].iter().map(|v| (v - my) * (v - my)).sum();
    let norm = (sx * sy).sqrt();
    if norm == 0.0 {
        return vec![0.0; 2 * max_lag + 1];
    }
    let xc: Vec<f64> = x[..n].iter().map(|v| v - mx).collect();
    let yc: Vec<f64> = y[..n].iter().map(|v| v - my).collect();
    lag_products(&xc, &yc, max_lag)
        .into_iter()
        .map(|s| s / norm)
        .collect()
}

/// Lagged product sums s(τ) = Σ_t a(t+τ)·b(t) over every t where both samples
/// exist, for τ = −max_lag..=max_lag (index τ + max_lag; lags beyond the record
/// give 0). Direct sums cost n·(2L+1) multiply–adds; above [`FFT_MIN_LAGS`] lags
/// they are computed by FFT of the zero-padded signals in O(n log n) — the same
/// sums up to round-off: |error| ≤ ~10⁻¹⁵·log₂(n)·√(Σa²·Σb²), which is the scale
/// every caller normalises by (pinned against the direct sums in the tests).
pub fn lag_products(a: &[f64], b: &[f64], max_lag: usize) -> Vec<f64> {
    let n = a.len().min(b.len());
    let (a, b) = (&a[..n], &b[..n]);
    let lags = 2 * max_lag + 1;
    if max_lag < FFT_MIN_LAGS || n < 2 {
        return (0..lags)
            .map(|i| {
                let tau = i as isize - max_lag as isize;
                let s = tau.unsigned_abs();
                if s >= n {
                    0.0
                } else if tau >= 0 {
                    a[s..].iter().zip(&b[..n - s]).map(|(x, y)| x * y).sum()
                } else {
                    a[..n - s].iter().zip(&b[s..]).map(|(x, y)| x * y).sum()
                }
            })
            .collect();
    }
    use rustfft::{FftPlanner, num_complex::Complex};
    // Zero padding to m ≥ n + L keeps the circular sums of lags |τ| ≤ L free of
    // wrap-around; m is a product of 2s and 3s (fast sizes).
    let m = fast_size(n + max_lag.min(n));
    // a as the real part, b as the imaginary part: one forward transform. Both
    // are scaled to unit norm first, so that a signal much smaller than the other
    // does not drown in its round-off.
    let norm = |x: &[f64]| {
        let s = x.iter().map(|v| v * v).sum::<f64>().sqrt();
        if s > 0.0 && s.is_finite() { s } else { 1.0 }
    };
    let (na, nb) = (norm(a), norm(b));
    let mut z: Vec<Complex<f64>> = (0..m)
        .map(|k| {
            if k < n {
                Complex::new(a[k] / na, b[k] / nb)
            } else {
                Complex::new(0.0, 0.0)
            }
        })
        .collect();
    let mut planner = FftPlanner::new();
    planner.plan_fft_forward(m).process(&mut z);
    // A_k = (Z_k + Z*_{m−k})/2, B_k = (Z_k − Z*_{m−k})/(2i); S_k = A_k·B*_k.
    let mut s: Vec<Complex<f64>> = (0..m)
        .map(|k| {
            let zk = z[k];
            let zm = z[(m - k) % m].conj();
            let ak = (zk + zm) * 0.5;
            let bk = (zk - zm) * Complex::new(0.0, -0.5);
            ak * bk.conj()
        })
        .collect();
    planner.plan_fft_inverse(m).process(&mut s);
    let scale = na * nb / m as f64;
    (0..lags)
        .map(|i| {
            let tau = i as isize - max_lag as isize;
            if tau.unsigned_abs() >= n {
                0.0
            } else {
                s[tau.rem_euclid(m as isize) as usize].re * scale
            }
        })
        .collect()
}

/// Below this many lags [`lag_products`] sums directly: 2L+1 passes over the
/// data cost about what two FFTs of the padded length do near L = 32 (so the
/// Ljung–Box test's 20 lags stay direct sums, bit for bit as before).
pub const FFT_MIN_LAGS: usize = 32;

/// The smallest 2^i·3^j ≥ n.
fn fast_size(n: usize) -> usize {
    let mut best = usize::MAX;
    let mut p3 = 1usize;
    while p3 < 2 * n.max(1) {
        let mut p = p3;
        while p < n {
            p *= 2;
        }
        best = best.min(p);
        p3 *= 3;
    }
    best
}

/// Result of a hypothesis test.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct Test {
    /// The test statistic.
    pub statistic: f64,
    /// Its p-value under the null hypothesis.
    pub p_value: f64,
}

/// Ljung–Box test of whiteness on lags 1..=lags: Q = N(N+2) Σ ρ_k²/(N−k) ~ χ²(lags)
/// for a white residual.
pub fn ljung_box(r: &[f64], lags: usize) -> Test {
    let n = r.len() as f64;
    let rho = autocorrelation(r, lags);
    let q: f64 = rho
        .iter()
        .enumerate()
        .skip(1)
        .map(|(k, p)| p * p / (n - k as f64))
        .sum::<f64>()
        * n
        * (n + 2.0);
    let dof = (rho.len().saturating_sub(1)).max(1) as f64;
    Test {
        statistic: q,
        p_value: chi2_sf(q, dof),
    }
}

/// Residual–input independence test over lags −max_lag..=max_lag: each
/// ρ̂_ru(τ) is compared with its standard deviation under independence from
/// Bartlett's formula, √(Σ_k ρ_rr(k) ρ_uu(k) / N), so that neither signal needs to
/// be white; the statistic is the largest |z| and the p-value is Bonferroni
/// corrected over the lags. Returns the test and the lag of the largest |z| (in
/// samples; positive: the residual follows the input).
pub fn input_correlation(r: &[f64], u: &[f64], max_lag: usize) -> (Test, isize) {
    let n = r.len().min(u.len());
    let k_max = (4 * max_lag).min(n.saturating_sub(1));
    let rr = autocorrelation(&r[..n], k_max);
    let uu = autocorrelation(&u[..n], k_max);
    let mut p_sum = 1.0;
    for k in 1..rr.len().min(uu.len()) {
        p_sum += 2.0 * rr[k] * uu[k];
    }
    let sd = (p_sum.max(1.0 / n as f64) / n as f64).sqrt();
    let xc = cross_correlation(&r[..n], &u[..n], max_lag);
    let (mut best, mut lag) = (0.0f64, 0isize);
    for (i, c) in xc.iter().enumerate() {
        let z = (c / sd).abs();
        if z > best {
            best = z;
            lag = i as isize - max_lag as isize;
        }
    }
    let p = (2.0 * normal_sf(best) * xc.len() as f64).min(1.0);
    (
        Test {
            statistic: best,
            p_value: p,
        },
        lag,
    )
}

/// Periodogram of `x` at the Fourier frequencies k/N (k = 1..N/2), mean removed,
/// by a direct DFT over the ones asked for — `bins` of them, evenly spaced.
fn periodogram(x: &[f64]) -> Vec<f64> {
    use rustfft::{FftPlanner, num_complex::Complex};
    let n = x.len();
    let m = mean(x);
    let mut buf: Vec<Complex<f64>> = x.iter().map(|v| Complex::new(v - m, 0.0)).collect();
    FftPlanner::new().plan_fft_forward(n).process(&mut buf);
    (1..n.div_ceil(2))
        .map(|k| buf[k].norm_sqr() / n as f64)
        .collect()
}

/// The share of `x`'s power (mean removed) within ± `TONE_BINS` periodogram
/// bins of its strongest line, and that line's frequency (cycles per sample):
/// near 1 for a single sine whatever its frequency between bins (the
/// rectangular window leaks at most 2/(π²·5) ≈ 4 % of a tone's power beyond
/// ± 5 bins, at half a bin off), small for a multisine, steps or noise.
/// `(0, 0)` for a record too short or constant.
pub fn tone_share(x: &[f64]) -> (f64, f64) {
    let per = periodogram(x);
    let total: f64 = per.iter().sum();
    if per.len() < 2 * TONE_BINS + 2 || total.is_nan() || total <= 0.0 {
        return (0.0, 0.0);
    }
    let k = (0..per.len()).fold(0, |b, k| if per[k] > per[b] { k } else { b });
    let near: f64 = per[k.saturating_sub(TONE_BINS)..(k + TONE_BINS + 1).min(per.len())]
        .iter()
        .sum();
    (near / total, (k + 1) as f64 / x.len() as f64)
}

/// Bins each side of a line that [`tone_share`] counts as the line's.
pub const TONE_BINS: usize = 5;

/// The frequency (cycles per sample) of the line of `x` near the periodogram
/// bin `f0`, refined off the bin grid: the maximum of |Σ xₖ e^{−i2πfk}| over
/// f0 ± one bin (golden-section search). A bin is 1/N wide, so a line between
/// bins is found to a small fraction of it — what a phase comparison over the
/// whole record needs.
pub fn refine_line(x: &[f64], f0: f64) -> f64 {
    let n = x.len();
    if n < 8 || f0.is_nan() || f0 <= 0.0 {
        return f0;
    }
    let m = mean(x);
    let power = |f: f64| dtft_power(x, m, f);
    let bin = 1.0 / n as f64;
    let (a, b, _, _) = nanomotion_core::lti::linalg::golden_section_max(
        &power,
        (f0 - bin).max(0.5 * bin),
        (f0 + bin).min(0.5),
        30,
    );
    let f = 0.5 * (a + b);
    if power(f) >= power(f0) { f } else { f0 }
}

/// The periodogram of `x` (its mean removed) at any frequency `f` (cycles
/// per sample), on or off the bin grid: |Σ (xₖ − x̄) e^{−i2πfk}|² / N, so a
/// sine of amplitude A at `f` gives about N·A²/4.
pub fn power_at(x: &[f64], f: f64) -> f64 {
    dtft_power(x, mean(x), f)
}

/// |Σ (xₖ − m) e^{−i2πfk}|² / N: the periodogram of `x` (its mean `m` removed) at any
/// frequency `f` (cycles per sample), on or off the bin grid.
fn dtft_power(x: &[f64], m: f64, f: f64) -> f64 {
    let (mut re, mut im) = (0.0, 0.0);
    let w = 2.0 * PI * f;
    for (k, v) in x.iter().enumerate() {
        let (s, c) = (w * k as f64).sin_cos();
        re += (v - m) * c;
        im -= (v - m) * s;
    }
    (re * re + im * im) / x.len() as f64
}

/// About how many independent periodogram bins [`line_near`]'s search over
/// ± one bin takes the largest of (the mean of the largest of three
/// exponential variates of mean 1 is 1 + ½ + ⅓ ≈ 1.8).
pub const LINE_NEAR_SEARCHED: f64 = 3.0;

/// The standard deviation (cycles per sample) of a line's frequency as
/// [`line_near`] finds it, from its `ratio` over `n` samples: the Cramér–Rao
/// bound for a real sine of amplitude A in white noise σ², var(ω̂) =
/// 12/(SNR·N(N² − 1)) with SNR = A²/(2σ²), ≈ 6/(R·N²) with R = N·A²/(4σ²)
/// the ratio, i.e. √(6/R)/(2πN) — a small part of a bin for a clear line.
pub fn line_frequency_sd(ratio: f64, n: usize) -> f64 {
    (6.0 / ratio.max(f64::MIN_POSITIVE)).sqrt() / (2.0 * PI * n as f64)
}

/// Bins each side of a frequency whose periodogram's median is the local
/// level a line is judged against in [`line_near`] (the line's own
/// ± [`TONE_BINS`] left out).
pub const LOCAL_BINS: usize = 60;

/// The strongest line of `x` within one bin (1/N) of the frequency `f0`
/// (cycles per sample), refined off the grid ([`refine_line`]), and its
/// power over the local level of `x`'s periodogram: the median of the bins
/// within ± [`LOCAL_BINS`] of it (its own ± [`TONE_BINS`] left out) over
/// ln 2. A periodogram bin of a noise with a smooth spectrum is an
/// exponential variate whose median is ln 2 times its mean, so at one
/// frequency chosen beforehand the ratio exceeds ln(1/p) with probability p
/// (Schuster's test); a sine of amplitude A in noise of variance σ² per bin
/// gives about N·A²/(4σ²).
/// The strongest of ± one bin is about the largest of
/// [`LINE_NEAR_SEARCHED`] independent bins: without a line, above ln(1/p)
/// with probability about that many times p.
/// `None` for a record too short for the local level or `f0` outside (0, ½).
pub fn line_near(x: &[f64], f0: f64) -> Option<(f64, f64)> {
    let n = x.len();
    let per = periodogram(x);
    if !(f0 > 0.0 && f0 < 0.5) || per.len() < 2 * LOCAL_BINS + 1 {
        return None;
    }
    let f = refine_line(x, f0);
    // Bin k (1-based) of frequency k/N sits at per[k − 1].
    let k = ((f * n as f64).round() as usize).clamp(1, per.len());
    let lo = k.saturating_sub(LOCAL_BINS).max(1);
    let hi = (k + LOCAL_BINS).min(per.len());
    let mut local: Vec<f64> = (lo..=hi)
        .filter(|&j| j.abs_diff(k) > TONE_BINS)
        .map(|j| per[j - 1])
        .collect();
    if local.is_empty() {
        return None;
    }
    local.sort_by(f64::total_cmp);
    let level = local[local.len() / 2] / std::f64::consts::LN_2;
    Some((f, power_at(x, f) / level.max(f64::MIN_POSITIVE)))
}

/// The frequency (cycles per sample) where `x`'s spectrum stands highest
/// over its own smooth level, and that ratio: a peak, not merely the most
/// power. The spectrum is Welch's (Hann-windowed segments of
/// [`PEAK_SEGMENT`] samples or a sixteenth of the record, half overlapping,
/// their periodograms averaged), its smooth level at each bin the median of
/// the bins within half an octave either side. An unmodelled mode rings at
/// its frequency after every transient and stands out of its neighbours;
/// a misfit of the slow dynamics, drift or coloured noise have smooth
/// spectra that hold the most power at the lowest frequencies — where
/// [`fisher_g`]'s strongest bin then sits. The two lowest bins are not
/// searched (a half octave has no bins below them). `None` for fewer than
/// four segments' worth of samples or no power.
pub fn prominent_peak(x: &[f64]) -> Option<(f64, f64)> {
    use rustfft::{FftPlanner, num_complex::Complex};
    let n = x.len();
    let seg = (n / 16).clamp(64, PEAK_SEGMENT).min(n);
    if n < 4 * 64 {
        return None;
    }
    let m = mean(x);
    let fft = FftPlanner::new().plan_fft_forward(seg);
    let window: Vec<f64> = (0..seg)
        .map(|k| 0.5 - 0.5 * (2.0 * PI * k as f64 / seg as f64).cos())
        .collect();
    let bins = seg / 2;
    let mut power = vec![0.0; bins];
    let mut buf = vec![Complex::new(0.0, 0.0); seg];
    let mut start = 0;
    while start + seg <= n {
        for (k, b) in buf.iter_mut().enumerate() {
            *b = Complex::new((x[start + k] - m) * window[k], 0.0);
        }
        fft.process(&mut buf);
        for (p, b) in power.iter_mut().zip(&buf[1..=bins]) {
            *p += b.norm_sqr();
        }
        start += seg / 2;
    }
    // power[j] is bin j + 1 (frequency (j + 1)/seg).
    let mut best: Option<(usize, f64)> = None;
    let mut near = Vec::with_capacity(bins);
    for j in 2..bins.saturating_sub(1) {
        let k = (j + 1) as f64;
        let lo = ((k / std::f64::consts::SQRT_2).floor() as usize).max(1);
        let hi = ((k * std::f64::consts::SQRT_2).ceil() as usize).min(bins);
        near.clear();
        near.extend((lo..=hi).map(|b| power[b - 1]));
        let level = median(&mut near);
        if level > 0.0 && power[j].is_finite() {
            let ratio = power[j] / level;
            if best.is_none_or(|(_, r)| ratio > r) {
                best = Some((j, ratio));
            }
        }
    }
    best.map(|(j, r)| ((j + 1) as f64 / seg as f64, r))
}

/// The longest segment [`prominent_peak`] averages over (samples).
pub const PEAK_SEGMENT: usize = 2048;

/// Fisher's g test for one periodic line hidden in white noise: g = max I_k / Σ I_k
/// over the periodogram, p ≈ m(1 − g)^{m−1} (first term of the exact series).
/// Returns the test and the frequency of the line as a fraction of the sample
/// rate.
pub fn fisher_g(x: &[f64]) -> (Test, f64) {
    let per = periodogram(x);
    let m = per.len();
    if m < 2 {
        return (
            Test {
                statistic: 0.0,
                p_value: 1.0,
            },
            0.0,
        );
    }
    let total: f64 = per.iter().sum();
    let (k, peak) = per.iter().enumerate().fold(
        (0, 0.0),
        |(bk, bv), (k, &v)| if v > bv { (k, v) } else { (bk, bv) },
    );
    let g = if total > 0.0 { peak / total } else { 0.0 };
    let p = (m as f64 * (1.0 - g).powf(m as f64 - 1.0)).min(1.0);
    (
        Test {
            statistic: g,
            p_value: p,
        },
        (k + 1) as f64 / x.len() as f64,
    )
}

/// A line of `r` periodic in the position `pos` (not in time): what a
/// rounding error (period = the lsb), a slit error (period = slits × pitch)
/// or a cogging force leaves in a residual.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SpatialLine {
    /// Spatial period (unit of `pos`).
    pub period: f64,
    /// Phase φ of the fundamental: r ≈ A·cos(2π(pos − origin)/period + φ).
    pub phase: f64,
    /// The position the phase is counted from (the smallest one).
    pub origin: f64,
    /// The line's power over its neighbourhood's mean (the statistic), and
    /// the chance of so strong a line in noise over the frequencies searched.
    pub test: Test,
}

impl SpatialLine {
    /// The offset o ∈ [0, period) of a rounding grid o + k·period whose
    /// error q·round((x − o)/q) + o − x left this line. That error's
    /// fundamental is −(q/π)·sin(2π(x − o)/q) = (q/π)·cos(2π(x − o)/q + π/2),
    /// so φ = π/2 − 2π(o − origin)/q.
    pub fn rounding_offset(&self) -> f64 {
        let q = self.period;
        (self.origin + q * (0.5 * PI - self.phase) / (2.0 * PI)).rem_euclid(q)
    }
}

/// The strongest line of `r` as a function of the position `pos`, with a
/// period in [`min_period`, `max_period`]: the residual is summed in 8 or
/// more bins per shortest period over the range travelled (at most 2²⁰ bins;
/// shorter periods are not searched), the binned sums transformed (FFT), the
/// line taken where the power stands highest over its neighbourhood and
/// refined off the grid by a golden-section search of
/// |Σ rₖ e^{−i2πf(posₖ − origin)}| over ± one bin, on the samples themselves.
/// `None` when fewer than 64 samples, no range or no period in the interval.
/// O(N + B log B) for N samples and B bins.
pub fn spatial_line(
    r: &[f64],
    pos: &[f64],
    min_period: f64,
    max_period: f64,
) -> Option<SpatialLine> {
    use rustfft::{FftPlanner, num_complex::Complex};
    let n = r.len().min(pos.len());
    let (r, pos) = (&r[..n], &pos[..n]);
    if n < 64 || r.iter().chain(pos).any(|v| !v.is_finite()) {
        return None;
    }
    let lo = pos.iter().copied().fold(f64::INFINITY, f64::min);
    let span = pos.iter().copied().fold(f64::NEG_INFINITY, f64::max) - lo;
    if span <= 0.0 || min_period <= 0.0 || max_period < min_period {
        return None;
    }
    const MAX_BINS: usize = 1 << 20;
    let j_lo = ((span / max_period).ceil() as usize).max(1);
    let j_hi = ((span / min_period).floor().min((MAX_BINS / 8) as f64)) as usize;
    if j_hi < j_lo {
        return None;
    }
    let bins = (8 * j_hi).next_power_of_two().max(1024);
    let m = mean(r);
    let mut buf = vec![Complex::new(0.0, 0.0); bins];
    for (v, p) in r.iter().zip(pos) {
        let b = (((p - lo) / span) * bins as f64) as usize;
        buf[b.min(bins - 1)].re += v - m;
    }
    FftPlanner::new().plan_fft_forward(bins).process(&mut buf);
    // A residual's continuum is red (a model error smooth in the position
    // dominates the few-cycle end), so a line is judged against its own
    // neighbourhood: the power at j over the mean power at 0.85j–1.15j (the
    // line's ±2 bins left out), which is exponential with mean 1 under noise;
    // p = m·e^{−ratio} over the m frequencies searched (Bonferroni).
    let power: Vec<f64> = buf[..=(j_hi * 23 / 20 + 3).min(bins / 2)]
        .iter()
        .map(|c| c.norm_sqr())
        .collect();
    let mut prefix = vec![0.0; power.len() + 1];
    for (i, p) in power.iter().enumerate() {
        prefix[i + 1] = prefix[i] + p;
    }
    let sum = |a: usize, b: usize| prefix[b] - prefix[a];
    let mut best: Option<(f64, usize)> = None;
    for j in j_lo..=j_hi {
        let (a, b) = ((j * 17 / 20).max(1), (j * 23 / 20 + 1).min(power.len()));
        let (la, lb) = (j.saturating_sub(2).max(a), (j + 3).min(b));
        let count = (b - a) - (lb - la);
        if count < 4 {
            continue;
        }
        let background = (sum(a, b) - sum(la, lb)) / count as f64;
        if background <= 0.0 {
            continue;
        }
        let ratio = power[j] / background;
        if best.is_none_or(|(r, _)| ratio > r) {
            best = Some((ratio, j));
        }
    }
    let (ratio, j) = best?;
    let p_value = ((j_hi - j_lo + 1) as f64 * (-ratio).exp()).min(1.0);
    // The line off the grid: the sum over the samples themselves.
    let sum_at = |f: f64| {
        let (mut re, mut im) = (0.0, 0.0);
        let w = 2.0 * PI * f;
        for (v, p) in r.iter().zip(pos) {
            let (s, c) = (w * (p - lo)).sin_cos();
            re += (v - m) * c;
            im -= (v - m) * s;
        }
        (re, im)
    };
    let (f, (re, im)) = off_the_grid(sum_at, j, span);
    Some(SpatialLine {
        period: 1.0 / f,
        phase: im.atan2(re),
        origin: lo,
        test: Test {
            statistic: ratio,
            p_value,
        },
    })
}

/// A line found at FFT bin `j` over a `span`, refined off the grid: the
/// frequency within ± one bin where |`sum_at`(f)|² (the sum over the samples
/// themselves, as (re, im)) is largest (golden section), with that sum.
fn off_the_grid(sum_at: impl Fn(f64) -> (f64, f64), j: usize, span: f64) -> (f64, (f64, f64)) {
    let j = j as f64;
    let (a, b, _, _) = nanomotion_core::lti::linalg::golden_section_max(
        |f| {
            let (re, im) = sum_at(f);
            re * re + im * im
        },
        (j - 1.0).max(0.5) / span,
        (j + 1.0) / span,
        40,
    );
    let f = 0.5 * (a + b);
    (f, sum_at(f))
}

/// Test whether residual `better` is smaller than `worse` on held-out data: the
/// candidate changed the model output by δ = worse − better, and the held-out
/// sum of squares drops by ΔSSE = 2·Σ r δ − Σ δ² (r = `worse`). If the candidate
/// only fitted noise, the held-out residual r is independent of δ (δ comes from
/// the estimation data and the held-out inputs), so Σ r δ has mean 0 and variance
///
/// ```text
/// V = Σ_{|j| ≤ L} w_j · γ_r(j) · Σ_k δ_k δ_{k+j}
/// ```
///
/// (γ_r the autocovariance of r's noise, Bartlett weights w_j = 1 − |j|/(L+1), so a
/// coloured residual is accounted for), and P(ΔSSE ≥ observed) = P(Z ≥ Σ r δ/√V).
/// γ_r is estimated from `better` = r − δ: under the null it is r's noise
/// plus an independent δ (a slightly larger, conservative V); estimated from
/// r itself it would count the very misfit δ removes as noise — a smooth
/// misfit then inflates V in proportion, and z can never exceed about
/// √(n/L) however complete the cut (2 on a held-out part of 400 samples,
/// where a name needs 3.5).
/// This is the significance of the cross-correlation between the held-out
/// residual and the correction — a Diebold–Mariano-type comparison of two
/// predictors that stays powerful when the effect acts only in bursts (a
/// saturation reached at the largest strokes), where a test over batches sees
/// only a few informative batches. `max_lag` is L (capped at n/4). Returns the test
/// (p small: the improvement is real) and the relative reduction of the overall
/// mean square.
pub fn improvement_test(worse: &[f64], better: &[f64], max_lag: usize) -> (Test, f64) {
    let n = worse.len().min(better.len());
    let ms_w = mean_square(&worse[..n]);
    let ms_b = mean_square(&better[..n]);
    let rel = if ms_w > 0.0 { 1.0 - ms_b / ms_w } else { 0.0 };
    let none = Test {
        statistic: 0.0,
        p_value: 1.0,
    };
    if n < 8 {
        return (none, rel);
    }
    let r = &worse[..n];
    let delta: Vec<f64> = r.iter().zip(&better[..n]).map(|(w, b)| w - b).collect();
    let cross: f64 = r.iter().zip(&delta).map(|(a, b)| a * b).sum();
    let m = mean(&better[..n]);
    let l = max_lag.min(n / 4);
    let centred: Vec<f64> = better[..n].iter().map(|v| v - m).collect();
    // Lags 0..=l of both lagged sums ([`lag_products`]: by FFT for many lags).
    let sums_r = lag_products(&centred, &centred, l);
    let sums_delta = lag_products(&delta, &delta, l);
    let mut v = 0.0;
    for j in 0..=l {
        let gamma_r = sums_r[l + j] / n as f64;
        let c_delta = sums_delta[l + j];
        let w = 1.0 - j as f64 / (l + 1) as f64;
        v += if j == 0 { 1.0 } else { 2.0 * w } * gamma_r * c_delta;
    }
    if v.is_nan() || v <= 0.0 || !cross.is_finite() {
        return (none, rel);
    }
    let z = cross / v.sqrt();
    (
        Test {
            statistic: z,
            p_value: normal_sf(z),
        },
        rel,
    )
}

/// Robust estimate of the standard deviation of the white part of `r`: the
/// median absolute first difference, scaled for a normal variable
/// (σ ≈ 1.4826·MAD(Δr)/√2). A smooth (low-frequency) misfit hardly moves it, so it
/// tells how far a residual is above its noise floor.
pub fn noise_floor(r: &[f64]) -> f64 {
    if r.len() < 3 {
        return 0.0;
    }
    let mut d: Vec<f64> = r.windows(2).map(|w| w[1] - w[0]).collect();
    let med = median(&mut d);
    let mut dev: Vec<f64> = d.iter().map(|v| (v - med).abs()).collect();
    1.4826 * median(&mut dev) / std::f64::consts::SQRT_2
}

/// [`noise_floor`] of `r` with its significant periodic lines taken out
/// first. A line is structure, not noise, however fast it is: a disturbance
/// periodic in position on a fast scan, or any line near the Nyquist
/// frequency, makes large sample-to-sample differences that the plain
/// estimate counts as white, so a residual holding little else looks "at its
/// noise floor" and nothing is looked for. Lines are found one at a time by
/// Fisher's g over the periodogram bins not yet taken (the strongest bin
/// against their sum, `p = m(1 − g)^{m−1}` for `m` bins), each removing its
/// bin ± [`TONE_BINS`] from the spectrum, while `p < level`, until a quarter
/// of the bins is gone (a residual with more than that in lines is not
/// "lines on white noise", and what is left would be too few bins to speak
/// for the noise); the floor is then [`noise_floor`] of what is left
/// (inverse FFT). With no line found it is `noise_floor(r)` exactly.
pub fn noise_floor_without_lines(r: &[f64], level: f64) -> f64 {
    use rustfft::{FftPlanner, num_complex::Complex};
    let n = r.len();
    let bins = n.div_ceil(2).saturating_sub(1); // k = 1..N/2, as `periodogram`
    if bins < 4 * (2 * TONE_BINS + 1) {
        return noise_floor(r);
    }
    let m = mean(r);
    let mut spectrum: Vec<Complex<f64>> = r.iter().map(|v| Complex::new(v - m, 0.0)).collect();
    let mut planner = FftPlanner::new();
    planner.plan_fft_forward(n).process(&mut spectrum);
    // Bin k (1-based Fourier index) at power[k − 1]; NaN once taken.
    let mut power: Vec<f64> = (1..=bins).map(|k| spectrum[k].norm_sqr()).collect();
    let mut taken = 0;
    while taken < bins / 4 {
        let (mut total, mut left, mut peak, mut at) = (0.0, 0usize, 0.0, 0);
        for (j, &p) in power.iter().enumerate() {
            if p.is_nan() {
                continue;
            }
            total += p;
            left += 1;
            if p > peak {
                (peak, at) = (p, j);
            }
        }
        if total.is_nan() || total <= 0.0 {
            break;
        }
        let g = peak / total;
        if left as f64 * (1.0 - g).powf(left as f64 - 1.0) >= level {
            break;
        }
        for j in at.saturating_sub(TONE_BINS)..(at + TONE_BINS + 1).min(bins) {
            if !power[j].is_nan() {
                power[j] = f64::NAN;
                taken += 1;
            }
            // Bin k = j + 1 and its mirror N − k: the line's whole power.
            spectrum[j + 1] = Complex::new(0.0, 0.0);
            spectrum[n - j - 1] = Complex::new(0.0, 0.0);
        }
    }
    if taken == 0 {
        return noise_floor(r);
    }
    planner.plan_fft_inverse(n).process(&mut spectrum);
    let clean: Vec<f64> = spectrum.iter().map(|c| c.re / n as f64).collect();
    noise_floor(&clean)
}

/// Median (reorders the slice).
pub fn median(x: &mut [f64]) -> f64 {
    if x.is_empty() {
        return 0.0;
    }
    let mid = x.len() / 2;
    x.select_nth_unstable_by(mid, |a, b| a.total_cmp(b));
    x[mid]
}

/// Linear least squares y ≈ Φθ by QR on the column-scaled regressors; returns θ
/// and the covariance σ²(ΦᵀΦ)⁻¹ with σ² = SSE/(N − p). `None` if Φ is rank
/// deficient.
pub fn least_squares(
    phi: &nalgebra::DMatrix<f64>,
    y: &[f64],
) -> Option<(Vec<f64>, nalgebra::DMatrix<f64>)> {
    let (n, p) = phi.shape();
    if n <= p || p == 0 {
        return None;
    }
    let scales: Vec<f64> = (0..p)
        .map(|j| {
            let s = phi.column(j).norm();
            if s > 0.0 { s } else { 1.0 }
        })
        .collect();
    let mut a = phi.clone();
    for (j, s) in scales.iter().enumerate() {
        a.column_mut(j).scale_mut(1.0 / s);
    }
    let svd = a.clone().svd(true, true);
    let smax = svd.singular_values.max();
    if svd.singular_values.min() <= smax * 1e-12 {
        return None;
    }
    let yv = nalgebra::DVector::from_column_slice(y);
    let z = svd.solve(&yv, 0.0).ok()?;
    let resid = &yv - &a * &z;
    let sigma2 = resid.norm_squared() / (n - p) as f64;
    let ata_inv = (a.transpose() * &a).try_inverse()?;
    let mut theta = vec![0.0; p];
    let mut cov = nalgebra::DMatrix::zeros(p, p);
    for i in 0..p {
        theta[i] = z[i] / scales[i];
        for j in 0..p {
            cov[(i, j)] = sigma2 * ata_inv[(i, j)] / (scales[i] * scales[j]);
        }
    }
    Some((theta, cov))
}

/// The values of a moving signal sitting on a grid o + m·q: what a rounding
/// (an encoder's count, an ADC's code) leaves in a measured record, read off
/// the record alone — no model needed, so it holds where a simulation cannot
/// reproduce the rounding's pattern (a model off by more than a step, a loop
/// closed over the rounded signal).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ValueGrid {
    /// The grid's step q (unit of the signal).
    pub pitch: f64,
    /// Its offset o ∈ [0, q).
    pub offset: f64,
    /// Rayleigh's z = |Σ e^{i2πy/q}|/√n over the n samples in motion, and the
    /// chance of so large a z without a grid over the pitches searched.
    pub test: Test,
    /// The samples in motion the test used.
    pub samples: usize,
    /// The mean number of them per occupied bin (≥ 1), which z² is divided by.
    pub repeats: f64,
}

/// The grid of `y`'s values ([`ValueGrid`]), with 30 to 4096 steps over the
/// range travelled (coarser grids are told from a few levels the signal rests
/// at by nothing; finer ones by too few samples per step). Only samples **in
/// motion** count — the signal moved at least three steps between the tenth
/// samples around it: a signal resting at a few levels has a "grid" of any
/// step dividing their distances; a moving one spreads over many levels, and
/// only a true grid keeps its values on the levels while it moves. The
/// pitches are searched an octave at a time (the motion threshold set by the
/// octave's largest step): the values in motion are binned (eight bins per
/// smallest step) and transformed (FFT), |Σ e^{i2πy/q}|² read at every
/// pitch, and the best refined off the grid (golden section over ± one bin on
/// the samples themselves). Without a grid the phases e^{i2πy/q} of values
/// spread smoothly over many steps are uniform, and z² = |Σ|²/n is
/// exponential with mean 1 — for independent values. A signal that passes
/// the same positions again (a periodic motion, a slow crossing) repeats its
/// values, and r repeats of each multiply z² by r: z² is divided by the mean
/// number of samples per occupied bin (r ≥ 1; a grid's own levels are
/// occupied as densely, so what that costs a grid is its noise's share of a
/// step). p = m·e^{−z²} over the m pitches searched (Bonferroni). `None` when
/// no octave has 200 samples in motion, or when the values concentrate on the
/// grid far less than its own noise allows: values rounded to q with noise σ
/// after the rounding have a mean resultant |Σ e^{i2πy/q}|/n of
/// e^{−2π²σ²/q²}, and one below half of that (σ from the second differences,
/// which a rounded signal's level jumps only raise) at the pitch found and
/// at its multiples up to four (the best pitch of a grid can be half its
/// step: held-out 4817) is a chance alignment of many values that sit on no
/// grid — a periodic motion sampled on whole
/// periods repeats its values and aligns some of them with some pitch
/// (held-out scenarios 4422 and 4515, sines in a PID loop: a "grid" at z =
/// 3.9, p = 10⁻³, concentration 0.04 where σ/q = 0.02 asks 0.99, was named).
/// O(N + B log B).
pub fn value_grid(y: &[f64]) -> Option<ValueGrid> {
    use rustfft::{FftPlanner, num_complex::Complex};
    const MIN_STEPS: f64 = 30.0;
    const MAX_STEPS: f64 = 4096.0;
    const HALF_WINDOW: usize = 5;
    const MIN_SAMPLES: usize = 200;
    let n = y.len();
    if n < 2 * HALF_WINDOW + MIN_SAMPLES || y.iter().any(|v| !v.is_finite()) {
        return None;
    }
    let lo = y.iter().copied().fold(f64::INFINITY, f64::min);
    let span = y.iter().copied().fold(f64::NEG_INFINITY, f64::max) - lo;
    if span <= 0.0 {
        return None;
    }
    // How far the signal moves around each sample.
    let motion: Vec<f64> = (0..n)
        .map(|k| {
            if k < HALF_WINDOW || k + HALF_WINDOW >= n {
                0.0
            } else {
                (y[k + HALF_WINDOW] - y[k - HALF_WINDOW]).abs()
            }
        })
        .collect();
    let mut planner = FftPlanner::new();
    let mut searched = 0usize;
    // (z², frequency index, motion threshold, repeats)
    let mut best: Option<(f64, usize, f64, f64)> = None;
    let mut steps_lo = MIN_STEPS;
    while steps_lo < MAX_STEPS {
        let steps_hi = (2.0 * steps_lo).min(MAX_STEPS);
        let threshold = 3.0 * span / steps_lo;
        let moving = in_motion(y, &motion, threshold);
        let (j_lo, j_hi) = (steps_lo.ceil() as usize, steps_hi.floor() as usize);
        steps_lo = steps_hi;
        if moving.len() < MIN_SAMPLES {
            continue;
        }
        let bins = (8 * j_hi).next_power_of_two();
        let mut buf = vec![Complex::new(0.0, 0.0); bins];
        for v in &moving {
            let b = (((v - lo) / span) * bins as f64) as usize;
            buf[b.min(bins - 1)].re += 1.0;
        }
        let m = moving.len() as f64;
        let repeats = (m / buf.iter().filter(|c| c.re > 0.0).count() as f64).max(1.0);
        planner.plan_fft_forward(bins).process(&mut buf);
        for (j, c) in buf.iter().enumerate().take(j_hi + 1).skip(j_lo) {
            searched += 1;
            let z2 = c.norm_sqr() / (m * repeats);
            if best.is_none_or(|(b, ..)| z2 > b) {
                best = Some((z2, j, threshold, repeats));
            }
        }
    }
    let (_, j, threshold, repeats) = best?;
    let moving = in_motion(y, &motion, threshold);
    let sum_at = |f: f64| {
        let (mut re, mut im) = (0.0, 0.0);
        for v in &moving {
            let (s, c) = (2.0 * PI * f * (v - lo)).sin_cos();
            re += c;
            im += s;
        }
        (re, im)
    };
    let (f, _) = off_the_grid(sum_at, j, span);
    // σ of a white sequence from its second differences (variance 6σ²),
    // robust to a smooth motion.
    let mut second: Vec<f64> = y
        .windows(3)
        .map(|w| (w[2] - 2.0 * w[1] + w[0]).abs())
        .collect();
    let noise = 1.4826 * median(&mut second) / 6f64.sqrt();
    // The grid is the pitch found or a multiple of it (a grid of step q
    // shows at q/2 as well, less tightly): the first whose values
    // concentrate as the noise allows.
    let n_moving = moving.len() as f64;
    (1..=4).find_map(|m| {
        let pitch = m as f64 / f;
        let (re, im) = sum_at(1.0 / pitch);
        let concentration = re.hypot(im) / n_moving;
        (concentration >= 0.5 * (-2.0 * PI * PI * (noise / pitch).powi(2)).exp()).then(|| {
            let z2 = (re * re + im * im) / (n_moving * repeats);
            ValueGrid {
                pitch,
                offset: (lo + pitch * im.atan2(re) / (2.0 * PI)).rem_euclid(pitch),
                test: Test {
                    statistic: z2.sqrt(),
                    p_value: (searched as f64 * (-z2).exp()).min(1.0),
                },
                samples: moving.len(),
                repeats,
            }
        })
    })
}

/// `n` samples of a triangle that moves `step` per sample, `ramp` samples up
/// then `ramp` down, from 0 (tests of [`value_grid`] and `diagnose`).
#[cfg(test)]
pub(crate) fn sampled_triangle(step: f64, ramp: usize, n: usize) -> Vec<f64> {
    (0..n)
        .map(|k| {
            let i = k % (2 * ramp);
            step * i.min(2 * ramp - i) as f64
        })
        .collect()
}

/// The samples of `y` around which the signal moves at least `threshold`
/// over ten samples (see [`value_grid`]).
fn in_motion(y: &[f64], motion: &[f64], threshold: f64) -> Vec<f64> {
    y.iter()
        .zip(motion)
        .filter(|(_, m)| **m >= threshold)
        .map(|(v, _)| *v)
        .collect()
}

/// The grid of a quantised record: if the values of `y` sit on levels
/// o + m·q (plus noise small next to q), returns (q, o) with o ∈ [0, q).
///
/// The sorted values are split into clusters at the threshold that separates
/// the log spacings best (Otsu's rule; the class means at least 5× apart: gaps
/// between levels against spacings inside one); the spacings of adjacent cluster centres must be whole
/// multiples of one step (nine in ten within 15 %: a fast record skips levels; at
/// least 5 clusters, none wider than half a step); then q and o are refined by least squares of the centres
/// on their integer level numbers (counted between neighbours, then re-assigned
/// from the fitted grid), which is
/// precise enough to place the grid over thousands of levels. `None` when the
/// record shows no grid.
pub fn lattice(y: &[f64]) -> Option<(f64, f64)> {
    let mut v: Vec<f64> = y.iter().copied().filter(|x| x.is_finite()).collect();
    if v.len() < 40 {
        return None;
    }
    v.sort_by(f64::total_cmp);
    // The gaps between levels are far larger than the spacings inside a level.
    // Two ways to find the split, tried in turn (the first that gives a
    // consistent grid wins): the largest drop (by ratio, at least 5×) of the
    // spacings sorted descending — right when there are few levels, each visited
    // many times; and Otsu's rule on the log spacings (the threshold maximising
    // the between-class variance, class means at least 5× apart) — right when a
    // fast record visits thousands of levels a few times each.
    let mut lg: Vec<f64> = v
        .windows(2)
        .map(|w| w[1] - w[0])
        .filter(|g| *g > 0.0)
        .map(f64::ln)
        .collect();
    if lg.len() < 20 {
        return None;
    }
    lg.sort_by(|a, b| b.total_cmp(a));
    let n = lg.len();
    let mut thresholds = Vec::new();
    let (mut drop_at, mut drop) = (0usize, 0.0f64);
    for i in 3..(n / 2).max(5).min(n - 1) {
        if lg[i] - lg[i + 1] > drop {
            (drop_at, drop) = (i, lg[i] - lg[i + 1]);
        }
    }
    if drop >= 5f64.ln() {
        thresholds.push((0.5 * (lg[drop_at] + lg[drop_at + 1])).exp());
    }
    let total: f64 = lg.iter().sum();
    let (mut best, mut cut, mut sum_hi) = (f64::NEG_INFINITY, 0usize, 0.0);
    for (i, l) in lg[..n - 1].iter().enumerate() {
        sum_hi += l;
        let (n_hi, n_lo) = ((i + 1) as f64, (n - i - 1) as f64);
        let (m_hi, m_lo) = (sum_hi / n_hi, (total - sum_hi) / n_lo);
        let between = n_lo * n_hi * (m_hi - m_lo).powi(2);
        if between > best {
            (best, cut) = (between, i);
        }
    }
    let m_hi = lg[..=cut].iter().sum::<f64>() / (cut + 1) as f64;
    let m_lo = lg[cut + 1..].iter().sum::<f64>() / (n - cut - 1) as f64;
    if m_hi - m_lo >= 5f64.ln() && cut >= 3 {
        thresholds.push((0.5 * (lg[cut] + lg[cut + 1])).exp());
    }
    // A digital reading without noise repeats its levels exactly: the spacings
    // inside a level are zero (filtered out above), so every positive spacing
    // is a gap between levels and any threshold below the smallest one splits.
    let repeats = v.len() - 1 - n;
    if repeats >= n {
        thresholds.push(0.5 * lg[n - 1].exp());
    }
    thresholds
        .into_iter()
        .find_map(|threshold| grid_at(&v, threshold))
}

/// The grid of sorted values `v` split into levels at spacings above `threshold`
/// (see [`lattice`]).
fn grid_at(v: &[f64], threshold: f64) -> Option<(f64, f64)> {
    // Cluster centres (means) and the widest cluster.
    let mut centres = Vec::new();
    let mut widest = 0.0f64;
    let mut first = v[0];
    let (mut sum, mut cnt) = (v[0], 1usize);
    for w in v.windows(2) {
        if w[1] - w[0] > threshold {
            centres.push(sum / cnt as f64);
            widest = widest.max(w[0] - first);
            first = w[1];
            sum = 0.0;
            cnt = 0;
        }
        sum += w[1];
        cnt += 1;
    }
    centres.push(sum / cnt as f64);
    widest = widest.max(v[v.len() - 1] - first);
    if centres.len() < 5 {
        return None;
    }
    // Adjacent centres are one step apart, or several where the record skipped
    // levels (a fast stage): the step is the typical smallest spacing (the median
    // of the lowest fifth), and nine in ten spacings must be whole multiples of
    // it within 15 %.
    let d: Vec<f64> = centres.windows(2).map(|w| w[1] - w[0]).collect();
    let mut sorted = d.clone();
    sorted.sort_by(f64::total_cmp);
    let q10 = sorted[sorted.len() / 10];
    if q10.is_nan() || q10 <= 0.0 {
        return None;
    }
    // Refined: the median of each spacing divided by its whole number of steps.
    let mut per_step: Vec<f64> = d
        .iter()
        .filter_map(|x| {
            let m = (x / q10).round();
            (m >= 1.0).then(|| x / m)
        })
        .collect();
    if per_step.is_empty() {
        return None;
    }
    let q0 = median(&mut per_step);
    if q0.is_nan() || q0 <= 0.0 || widest > 0.5 * q0 {
        return None;
    }
    let whole = d
        .iter()
        .filter(|x| {
            let m = *x / q0;
            (m - m.round()).abs() < 0.15
        })
        .count();
    if (whole as f64) < 0.9 * d.len() as f64 {
        return None;
    }
    // Least squares c_j = o + q·m_j on integer level numbers m_j, counted from
    // neighbour to neighbour (a level the record skipped counts twice); then
    // re-counted from the fitted grid.
    let (mut q, mut o) = (q0, centres[0]);
    for pass in 0..2 {
        let m: Vec<f64> = if pass == 0 {
            let mut acc = 0.0;
            std::iter::once(0.0)
                .chain(d.iter().map(|dj| {
                    acc += (dj / q0).round();
                    acc
                }))
                .collect()
        } else {
            centres.iter().map(|c| ((c - o) / q).round()).collect()
        };
        let n = m.len() as f64;
        let (sm, sc) = (m.iter().sum::<f64>(), centres.iter().sum::<f64>());
        let smm: f64 = m.iter().map(|x| x * x).sum();
        let smc: f64 = m.iter().zip(&centres).map(|(a, b)| a * b).sum();
        let det = n * smm - sm * sm;
        if det <= 0.0 {
            return None;
        }
        q = (n * smc - sm * sc) / det;
        o = (sc - q * sm) / n;
        if q.is_nan() || q <= 0.0 {
            return None;
        }
    }
    Some((q, o.rem_euclid(q)))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A sine half-way between bins (the worst leakage) keeps ≥ 95 % of its
    /// power within ± 5 bins, a triangle wave less, noise and a multisine of
    /// ten lines far less; the line's frequency is the sine's to a bin.
    #[test]
    fn a_single_tone_holds_its_power_at_one_frequency() {
        let n = 4000;
        let f = 12.5 / n as f64; // half-way between bins 12 and 13
        let sine: Vec<f64> = (0..n).map(|k| (2.0 * PI * f * k as f64).sin()).collect();
        let (share, line) = tone_share(&sine);
        assert!(share > 0.95, "{share}");
        assert!((line - f).abs() <= 1.0 / n as f64, "{line} vs {f}");
        let tri: Vec<f64> = (0..n)
            .map(|k| {
                let p = (f * k as f64).fract();
                if p < 0.5 {
                    4.0 * p - 1.0
                } else {
                    3.0 - 4.0 * p
                }
            })
            .collect();
        // Its harmonics (3f, 5f, … at 1/n² in amplitude) hold power away
        // from the line: less of a single tone than the sine.
        assert!(tone_share(&tri).0 < share, "{}", tone_share(&tri).0);
        let multi: Vec<f64> = (0..n)
            .map(|k| {
                (1..=10)
                    .map(|h| {
                        (2.0 * PI * (7.0 * h as f64 + 0.3) / n as f64 * k as f64 + h as f64).sin()
                    })
                    .sum::<f64>()
            })
            .collect();
        assert!(tone_share(&multi).0 < 0.2, "{}", tone_share(&multi).0);
        let mut rng = Rng::new(3);
        let noise: Vec<f64> = (0..n).map(|_| rng.normal()).collect();
        assert!(tone_share(&noise).0 < 0.05, "{}", tone_share(&noise).0);
        assert_eq!(tone_share(&[1.0; 64]), (0.0, 0.0));
    }
    use nanomotion_core::rng::Rng;

    /// Schuster's statistic near a frequency chosen beforehand: in white
    /// noise the largest of about three exponential variates of mean 1 (mean
    /// ≈ 1.8; above ln 100 in about 3 % of frequencies); with a sine of
    /// amplitude A off the bin grid, N·A²/(4σ²) plus that noise, at the
    /// sine's frequency to a small part of a bin.
    #[test]
    fn a_line_is_judged_against_its_spectrums_local_level() {
        let n = 8000;
        let mut rng = Rng::new(17);
        let noise: Vec<f64> = (0..n).map(|_| rng.normal()).collect();
        let ratios: Vec<f64> = (0..400)
            .map(|j| {
                line_near(&noise, (40.0 + 9.37 * j as f64) / n as f64)
                    .unwrap()
                    .1
            })
            .collect();
        let mean_ratio = mean(&ratios);
        let above = ratios.iter().filter(|&&r| r > 100f64.ln()).count();
        assert!((1.5..2.3).contains(&mean_ratio), "{mean_ratio}");
        let expected_above = 400.0 * LINE_NEAR_SEARCHED / 100.0;
        assert!(
            (above as f64) < 2.5 * expected_above,
            "{above} of 400 above ln 100 (about {expected_above} expected)"
        );
        let (a, f) = (0.2, 1234.3 / n as f64);
        let x: Vec<f64> = noise
            .iter()
            .enumerate()
            .map(|(k, v)| v + a * (2.0 * PI * f * k as f64 + 0.4).sin())
            .collect();
        let (found, ratio) = line_near(&x, f + 0.6 / n as f64).unwrap();
        let expected = n as f64 * a * a / 4.0;
        assert!(
            (found - f).abs() < 0.05 / n as f64,
            "{} bins off",
            (found - f) * n as f64
        );
        assert!(
            (ratio / expected - 1.0).abs() < 0.3,
            "{ratio} against N·A²/(4σ²) = {expected}"
        );
        assert!(line_near(&x, 0.0).is_none() && line_near(&x[..100], f).is_none());
        // The frequency found scatters over noise draws as the Cramér–Rao
        // bound says (40 draws: the sample sd within ± 35 % of it).
        let found: Vec<f64> = (0..40)
            .map(|_| {
                let x: Vec<f64> = (0..n)
                    .map(|k| rng.normal() + a * (2.0 * PI * f * k as f64 + 0.4).sin())
                    .collect();
                line_near(&x, f).unwrap().0
            })
            .collect();
        let m = mean(&found);
        let sd = (found.iter().map(|v| (v - m) * (v - m)).sum::<f64>() / 39.0).sqrt();
        let bound = line_frequency_sd(expected, n);
        assert!(
            (sd / bound - 1.0).abs() < 0.35,
            "sd {sd:.3e} against the bound {bound:.3e}"
        );
    }

    /// A stage swept over ±1 by a sine and a chirp-like second sine, 12 000 samples.
    fn sweep(k: usize) -> f64 {
        let t = k as f64 / 2000.0;
        0.8 * (2.0 * PI * 0.7 * t).sin() + 0.2 * (2.0 * PI * 3.1 * t + 0.4).sin()
    }

    #[test]
    fn a_rounded_moving_signal_shows_its_grid() {
        let mut rng = Rng::new(11);
        let (q, o) = (2.0 / 437.0, 0.3 / 437.0);
        // Rounded to o + m·q, noise q/8 after the rounding.
        let rounded: Vec<f64> = (0..12_000)
            .map(|k| o + q * ((sweep(k) - o) / q).round() + q / 8.0 * rng.normal())
            .collect();
        let g = value_grid(&rounded).unwrap();
        assert!((g.pitch / q - 1.0).abs() < 1e-3, "{g:?}");
        let d = (g.offset - o).rem_euclid(q);
        assert!(d.min(q - d) < 0.02 * q, "{g:?}");
        // z²·r/n = |E e^{i2πy/q}|² = e^{−(2πσ/q)²} for noise σ: here e^{−π²/16}.
        let r2 = g.test.statistic.powi(2) * g.repeats / g.samples as f64;
        assert!(
            (r2 / (-(PI / 4.0).powi(2)).exp() - 1.0).abs() < 0.1,
            "{g:?}: {r2}"
        );
        assert!(g.test.p_value < 1e-100);
    }

    #[test]
    fn a_constant_speed_sweep_sampled_at_a_fixed_rate_sits_on_a_grid_of_its_own() {
        // Why `diagnose` asks whether a grid is a sweep's sampling before
        // naming a rounding (`sampled_sweep`): a triangle at 2.37·10⁻³ per
        // sample, 1000 samples per ramp, passes the same places on every ramp —
        // a grid of step v·dt (or a divisor of it) in the values of a signal
        // nothing rounds.
        let y = sampled_triangle(2.37e-3, 1000, 12_000);
        let g = value_grid(&y).unwrap();
        assert!(g.test.p_value < 1e-6, "{g:?}");
        let per_step = 2.37e-3 / g.pitch;
        assert!(
            (per_step - per_step.round()).abs() < 0.01,
            "{g:?}: v·dt = {per_step} steps"
        );
    }

    #[test]
    fn signals_whose_values_sit_on_no_grid_show_none() {
        let mut rng = Rng::new(3);
        // The sweep of the test above, same noise, without the rounding.
        let smooth: Vec<f64> = (0..12_000)
            .map(|k| sweep(k) + 2.0 / 437.0 / 8.0 * rng.normal())
            .collect();
        // 500 samples per period, 24 periods, noise far below any step searched:
        // each value comes 24 times, which alone would make z² 24 times too large.
        let periodic: Vec<f64> = (0..12_000)
            .map(|k| (2.0 * PI * k as f64 / 500.0).sin() + 1e-7 * rng.normal())
            .collect();
        // Steps between seven levels, settling in 40 samples, resting 600: the
        // resting values alone sit on "grids" of many steps; in motion they do not.
        let levels = [-0.9, -0.41, 0.13, 0.52, 0.05, 0.77, -0.2];
        let mut x = 0.0;
        let resting: Vec<f64> = (0..12_000)
            .map(|k| {
                x += (levels[(k / 640) % levels.len()] - x) * 0.1;
                x + 1e-3 * rng.normal()
            })
            .collect();
        for (name, y) in [
            ("smooth", smooth),
            ("periodic", periodic),
            ("resting", resting),
        ] {
            if let Some(g) = value_grid(&y) {
                assert!(g.test.p_value > 1e-3, "{name}: {g:?}");
            }
        }
    }

    #[test]
    fn a_rounding_error_is_a_line_in_the_position_with_the_lsb_and_offset() {
        // y = o + q·round((x − o)/q) + noise, the model position x known: the
        // residual y − x is a sawtooth of period q in x whatever the noise after
        // the rounding, and its fundamental's phase gives o (closed form in
        // `rounding_offset`).
        let (q, o) = (0.0137, 0.0041);
        let mut rng = Rng::new(7);
        let x: Vec<f64> = (0..20_000)
            .map(|k| 0.8 * (k as f64 * 1.3e-3).sin() + 0.05 * (k as f64 * 0.031).sin())
            .collect();
        let r: Vec<f64> = x
            .iter()
            .map(|x| o + q * ((x - o) / q).round() - x + 0.6 * q * rng.normal())
            .collect();
        let line = spatial_line(&r, &x, 1e-4, 0.2).expect("a line");
        assert!(line.test.p_value < 1e-6, "{line:?}");
        assert!((line.period / q - 1.0).abs() < 2e-4, "{line:?}");
        let off = line.rounding_offset();
        let d = (off - o).rem_euclid(q).min((o - off).rem_euclid(q));
        assert!(d < 0.02 * q, "offset {off} vs {o}");
        // Noise alone: no significant line.
        let white: Vec<f64> = (0..20_000).map(|_| rng.normal()).collect();
        let none = spatial_line(&white, &x, 1e-4, 0.2).expect("searched");
        assert!(none.test.p_value > 1e-3, "{none:?}");
    }

    #[test]
    fn special_functions_match_closed_forms() {
        // Γ(5) = 24, Γ(1/2) = √π.
        assert!((ln_gamma(5.0) - 24f64.ln()).abs() < 1e-13);
        assert!((ln_gamma(0.5) - PI.sqrt().ln()).abs() < 1e-13);
        // χ²(2) survival is e^{−x/2}.
        for x in [0.1, 1.0, 3.0, 10.0, 40.0] {
            assert!((chi2_sf(x, 2.0) - (-x / 2.0).exp()).abs() < 1e-12, "{x}");
        }
        // χ²(1): P(χ² > 3.841459) = 0.05.
        assert!((chi2_sf(3.841_458_820_694_124, 1.0) - 0.05).abs() < 1e-6);
        assert!((normal_sf(1.959_963_984_540_054) - 0.025).abs() < 1e-7);
        assert!((normal_sf(0.0) - 0.5).abs() < 1e-9);
        // Student t with 1 dof is Cauchy: P(T > t) = 1/2 − atan(t)/π.
        for t in [-2.0, 0.3, 1.0, 5.0] {
            assert!(
                (student_t_sf(t, 1.0) - (0.5 - f64::atan(t) / PI)).abs() < 1e-10,
                "{t}"
            );
        }
        // Large dof approaches the normal.
        assert!((student_t_sf(1.5, 1e6) - normal_sf(1.5)).abs() < 1e-5);
        // I_x(1, 1) = x; I_x(a, 1) = x^a.
        assert!((beta_inc(1.0, 1.0, 0.3) - 0.3).abs() < 1e-13);
        assert!((beta_inc(2.5, 1.0, 0.4) - 0.4f64.powf(2.5)).abs() < 1e-13);
    }

    fn white(n: usize, seed: u64) -> Vec<f64> {
        let mut rng = Rng::new(seed);
        (0..n).map(|_| rng.normal()).collect()
    }

    #[test]
    fn whiteness_test_has_its_nominal_false_alarm_rate_and_power() {
        // 400 white records: about 5 % fall below p = 0.05.
        let alarms = (0..400)
            .filter(|&s| ljung_box(&white(2000, s), 20).p_value < 0.05)
            .count();
        assert!((8..=36).contains(&alarms), "{alarms} of 400");
        // AR(1) with a = 0.3 is found every time.
        let e = white(2000, 7);
        let mut x = vec![0.0; e.len()];
        for k in 1..e.len() {
            x[k] = 0.3 * x[k - 1] + e[k];
        }
        assert!(ljung_box(&x, 20).p_value < 1e-10);
    }

    #[test]
    fn input_correlation_finds_a_delayed_copy_and_not_independent_coloured_signals() {
        let u = white(4000, 1);
        let e = white(4000, 2);
        let r: Vec<f64> = (0..4000)
            .map(|k| e[k] + if k >= 5 { 0.3 * u[k - 5] } else { 0.0 })
            .collect();
        let (t, lag) = input_correlation(&r, &u, 20);
        assert!(t.p_value < 1e-6);
        assert_eq!(lag, 5);
        // Two independent, strongly coloured signals: false alarms near nominal.
        let colour = |x: Vec<f64>| {
            let mut y = vec![0.0; x.len()];
            for k in 1..x.len() {
                y[k] = 0.95 * y[k - 1] + x[k];
            }
            y
        };
        let alarms = (0..200)
            .filter(|&s| {
                let a = colour(white(2000, 100 + s));
                let b = colour(white(2000, 500 + s));
                input_correlation(&a, &b, 10).0.p_value < 0.05
            })
            .count();
        assert!(alarms <= 24, "{alarms} of 200 at nominal 5 %");
    }

    #[test]
    fn fisher_g_finds_a_line() {
        let e = white(1024, 3);
        let x: Vec<f64> = (0..1024)
            .map(|k| e[k] + 0.5 * (2.0 * PI * 50.0 * k as f64 / 1024.0).sin())
            .collect();
        let (t, f) = fisher_g(&x);
        assert!(t.p_value < 1e-10);
        assert!((f - 50.0 / 1024.0).abs() < 1e-12);
        let alarms = (0..200)
            .filter(|&s| fisher_g(&white(512, 900 + s)).0.p_value < 0.05)
            .count();
        assert!(alarms <= 20, "{alarms}");
    }

    /// A mode ringing after every step of a staircase (80 Hz at 500 Hz, ζ =
    /// 0.015), under a slow misfit a hundred times its power and white
    /// noise: the strongest bin is the slow misfit's, the peak over its
    /// neighbours the mode's (to the segment's resolution, 500/128 Hz).
    /// White noise alone has no bin twice its neighbours' median over a
    /// hundred records of 16 segments or more (the level that starts a fit).
    #[test]
    fn prominent_peak_finds_a_ring_under_a_slow_misfit() {
        let (fs, n) = (500.0, 8192);
        let e = white(n, 21);
        let (f_ring, zeta) = (80.0, 0.015);
        let x: Vec<f64> = (0..n)
            .map(|k| {
                let t = k as f64 / fs;
                // Steps every 1.024 s; the ring since the last one.
                let since = t % 1.024;
                let wd = 2.0 * PI * f_ring;
                let ring = (-zeta * wd * since).exp() * (wd * since).sin();
                let slow = 20.0 * (2.0 * PI * 0.35 * t).sin();
                slow + ring + 0.05 * e[k]
            })
            .collect();
        assert!(
            fisher_g(&x).1 * fs < 1.0,
            "the strongest line is the slow misfit"
        );
        let (f, ratio) = prominent_peak(&x).expect("a peak");
        let resolution = fs / PEAK_SEGMENT.min(n / 16) as f64;
        assert!((f * fs - f_ring).abs() <= resolution, "{} Hz", f * fs);
        assert!(ratio > 10.0, "{ratio}");
        let loudest = (0..100)
            .map(|s| {
                prominent_peak(&white(4096, 300 + s))
                    .expect("noise has a spectrum")
                    .1
            })
            .fold(0.0, f64::max);
        assert!(loudest < 2.0, "{loudest}");
    }

    #[test]
    fn improvement_test_detects_a_real_cut_and_not_noise() {
        // A correction that removes a fifth of the residual is found at once.
        let a = white(5000, 4);
        let b: Vec<f64> = a.iter().map(|v| 0.8 * v).collect();
        let (t, rel) = improvement_test(&a, &b, 50);
        assert!(t.p_value < 1e-6);
        assert!((rel - 0.36).abs() < 1e-12);
        // A correction acting only in three short bursts, where it removes a
        // misfit 5× the noise: significant although 97 % of the record is untouched.
        let noise = white(3600, 5);
        let burst = |k: usize| [400usize, 1700, 3000].iter().any(|&c| k >= c && k < c + 40);
        let misfit: Vec<f64> = (0..3600)
            .map(|k| {
                if burst(k) {
                    5.0 * (k as f64 * 0.3).sin()
                } else {
                    0.0
                }
            })
            .collect();
        let worse: Vec<f64> = noise.iter().zip(&misfit).map(|(e, s)| e + s).collect();
        let (t, _) = improvement_test(&worse, &noise, 200);
        assert!(t.p_value < 1e-8, "{}", t.p_value);
        // A smooth misfit ten times the noise, removed whole, on a held-out
        // part of 400 samples (a 500 Hz record of 4.5 s): significant far
        // beyond a name's level. With the noise's autocovariance taken from
        // the residual before the cut (misfit included), z stayed near
        // √(n/L) = 2 (p ≈ 0.02) whatever the cut.
        let noise = white(400, 6);
        let worse: Vec<f64> = noise
            .iter()
            .enumerate()
            .map(|(k, e)| e + 10.0 * (k as f64 * 0.01).sin())
            .collect();
        let (t, _) = improvement_test(&worse, &noise, 200);
        assert!(t.p_value < 1e-6, "{}", t.p_value);
        // False alarms: corrections independent of the residual, on white and on
        // strongly coloured (AR(1), a = 0.95) residuals, at the nominal 5 % level.
        for coloured in [false, true] {
            let alarms = (0..400)
                .filter(|&s| {
                    let e = white(2000, 10 + s);
                    let r: Vec<f64> = if coloured {
                        let mut x = 0.0;
                        e.iter()
                            .map(|v| {
                                x = 0.95 * x + v;
                                x
                            })
                            .collect()
                    } else {
                        e
                    };
                    // δ: a smooth random correction (itself coloured).
                    let d0 = white(2000, 5000 + s);
                    let mut y = 0.0;
                    let delta: Vec<f64> = d0
                        .iter()
                        .map(|v| {
                            y = 0.9 * y + 0.1 * v;
                            y
                        })
                        .collect();
                    let better: Vec<f64> = r.iter().zip(&delta).map(|(a, d)| a - d).collect();
                    improvement_test(&r, &better, 200).0.p_value < 0.05
                })
                .count();
            assert!(alarms <= 32, "coloured {coloured}: {alarms} of 400");
        }
    }

    /// The lagged sums as they were computed before the FFT path: one direct
    /// sum per lag, O(n·L).
    fn direct_lag_products(a: &[f64], b: &[f64], max_lag: usize) -> Vec<f64> {
        let n = a.len().min(b.len()) as isize;
        (-(max_lag as isize)..=max_lag as isize)
            .map(|tau| {
                (0..n)
                    .filter(|t| (0..n).contains(&(t + tau)))
                    .map(|t| a[(t + tau) as usize] * b[t as usize])
                    .sum()
            })
            .collect()
    }

    /// The held-out variance V of [`improvement_test`] by direct lagged sums (the
    /// code before the FFT path).
    fn direct_improvement_z(worse: &[f64], better: &[f64], max_lag: usize) -> f64 {
        let n = worse.len();
        let delta: Vec<f64> = worse.iter().zip(better).map(|(w, b)| w - b).collect();
        let cross: f64 = worse.iter().zip(&delta).map(|(a, b)| a * b).sum();
        let m = mean(better);
        let l = max_lag.min(n / 4);
        let mut v = 0.0;
        for j in 0..=l {
            let gamma_r = (0..n - j)
                .map(|t| (better[t] - m) * (better[t + j] - m))
                .sum::<f64>()
                / n as f64;
            let c_delta: f64 = (0..n - j).map(|t| delta[t] * delta[t + j]).sum();
            let w = 1.0 - j as f64 / (l + 1) as f64;
            v += if j == 0 { 1.0 } else { 2.0 * w } * gamma_r * c_delta;
        }
        cross / v.sqrt()
    }

    #[test]
    fn fft_lag_products_equal_the_direct_sums() {
        // Seeded coloured and offset signals, lengths with awkward factors
        // (primes, powers of two, shorter than the lags), few and many lags.
        let mut rng = Rng::new(41);
        for &n in &[2usize, 3, 17, 64, 97, 1000, 1024, 4099, 20_000] {
            let e = white(n, 1000 + n as u64);
            let mut y = 0.0;
            let a: Vec<f64> = e
                .iter()
                .map(|v| {
                    y = 0.9 * y + v;
                    3.0 + y
                })
                .collect();
            let b: Vec<f64> = (0..n).map(|_| 1e-6 * rng.normal()).collect();
            // Lags beyond the record only where the direct sums stay cheap.
            let beyond = if n < 2000 { vec![n + 3] } else { vec![] };
            for &lags in [0usize, 5, FFT_MIN_LAGS, 50, 200].iter().chain(&beyond) {
                for (x, w) in [(&a, &b), (&a, &a), (&b, &a)] {
                    let fast = lag_products(x, w, lags);
                    let slow = direct_lag_products(x, w, lags);
                    assert_eq!(fast.len(), slow.len());
                    // Relative to the scale every caller normalises by.
                    let scale = (mean_square(x) * mean_square(w)).sqrt() * n as f64;
                    for (tau, (f, s)) in fast.iter().zip(&slow).enumerate() {
                        assert!(
                            (f - s).abs() <= 1e-12 * scale,
                            "n {n}, lags {lags}, τ index {tau}: {f} vs {s}"
                        );
                    }
                }
            }
        }
    }

    #[test]
    fn correlation_statistics_equal_their_direct_forms() {
        for seed in 0..6u64 {
            let n = 3000 + 977 * seed as usize;
            let u = white(n, 300 + seed);
            let mut y = 0.0;
            let r: Vec<f64> = white(n, 600 + seed)
                .iter()
                .zip(&u)
                .map(|(e, v)| {
                    y = 0.8 * y + e + 0.2 * v;
                    y
                })
                .collect();
            // ρ normalised by c0: absolute agreement to 1e-12.
            let m = mean(&r);
            let centred: Vec<f64> = r.iter().map(|v| v - m).collect();
            let c0: f64 = centred.iter().map(|v| v * v).sum();
            let slow = direct_lag_products(&centred, &centred, 300);
            for (k, rho) in autocorrelation(&r, 300).iter().enumerate() {
                assert!((rho - slow[300 + k] / c0).abs() < 1e-12, "lag {k}");
            }
            let (mr, mu) = (mean(&r), mean(&u));
            let rc: Vec<f64> = r.iter().map(|v| v - mr).collect();
            let uc: Vec<f64> = u.iter().map(|v| v - mu).collect();
            let norm = (mean_square(&rc) * mean_square(&uc)).sqrt() * n as f64;
            let slow = direct_lag_products(&rc, &uc, 120);
            for (i, c) in cross_correlation(&r, &u, 120).iter().enumerate() {
                assert!((c - slow[i] / norm).abs() < 1e-12, "τ index {i}");
            }
            // The improvement test's z against its direct computation.
            let better: Vec<f64> = r.iter().zip(&u).map(|(a, v)| a - 0.1 * v).collect();
            let (t, _) = improvement_test(&r, &better, 200);
            let z = direct_improvement_z(&r, &better, 200);
            assert!(
                (t.statistic - z).abs() <= 1e-12 * z.abs(),
                "{} vs {z}",
                t.statistic
            );
        }
    }

    #[test]
    fn a_fast_line_is_not_counted_in_the_noise_floor() {
        // White noise of σ = 1 and a sine at 0.31 of the sample rate, amplitude
        // 3: the differences see the sine (2A·sin(π·0.31) ≈ 4.9 against the
        // noise's √2), the floor without lines sees σ alone.
        let noise = white(4000, 17);
        let r: Vec<f64> = noise
            .iter()
            .enumerate()
            .map(|(k, e)| e + 3.0 * (2.0 * std::f64::consts::PI * 0.31 * k as f64 + 0.4).sin())
            .collect();
        let plain = noise_floor(&r);
        let clean = noise_floor_without_lines(&r, 1e-3);
        let truth = noise_floor(&noise);
        assert!(plain > 2.0 * truth, "plain {plain}, noise {truth}");
        assert!(
            (clean - truth).abs() < 0.05 * truth,
            "without lines {clean}, noise {truth}"
        );
        // White noise alone has no line: the same estimate to the bit.
        assert_eq!(noise_floor_without_lines(&noise, 1e-3), truth);
    }

    #[test]
    fn noise_floor_ignores_smooth_misfit() {
        let e = white(20000, 5);
        let r: Vec<f64> = (0..20000)
            .map(|k| 0.01 * e[k] + (k as f64 * 1e-3).sin())
            .collect();
        let s = noise_floor(&r);
        assert!((s / 0.01 - 1.0).abs() < 0.05, "{s}");
    }

    #[test]
    fn least_squares_recovers_a_line_with_honest_uncertainty() {
        let e = white(1000, 6);
        let n = 1000;
        let phi =
            nalgebra::DMatrix::from_fn(n, 2, |i, j| if j == 0 { 1.0 } else { i as f64 * 1e-3 });
        let y: Vec<f64> = (0..n)
            .map(|i| 2.0 + 3.0 * i as f64 * 1e-3 + 0.1 * e[i])
            .collect();
        let (th, cov) = least_squares(&phi, &y).unwrap();
        assert!((th[0] - 2.0).abs() < 4.0 * cov[(0, 0)].sqrt());
        assert!((th[1] - 3.0).abs() < 4.0 * cov[(1, 1)].sqrt());
        // Standard error of the slope for unit-spaced x on [0, 1): σ√(12/N).
        let se = cov[(1, 1)].sqrt();
        assert!(
            (se / (0.1 * (12.0f64 / n as f64).sqrt()) - 1.0).abs() < 0.1,
            "{se}"
        );
    }

    #[test]
    fn lattice_recovers_a_grid_over_thousands_of_levels_and_refuses_none() {
        // Closed form: values o + q·round((x − o)/q) + noise, x sweeping 1300 levels.
        let (q, o) = (7.666e-8, 2.1e-8);
        let mut rng = nanomotion_core::rng::Rng::new(9);
        let y: Vec<f64> = (0..8400)
            .map(|k| {
                let x = 1e-4 * (k as f64 / 8400.0 * 7.0).sin();
                o + q * ((x - o) / q).round() + 2e-9 * rng.normal()
            })
            .collect();
        let (qe, oe) = lattice(&y).expect("a grid");
        assert!((qe / q - 1.0).abs() < 1e-5, "{qe} vs {q}");
        // Across the whole travel the fitted grid is within a small part of an lsb.
        assert!(
            ((oe - o) / q + 0.5).rem_euclid(1.0) - 0.5 < 0.02,
            "{oe} vs {o}"
        );
        assert!(1e-4 * (qe - q).abs() / q < 0.05 * q);
        // A fast stage that skips levels: 2400 levels of 42 nm, ~3 samples each.
        let fast: Vec<f64> = (0..8400)
            .map(|k| {
                let x = 1e-4 * (k as f64 / 8400.0 * 11.0).sin();
                4.2e-8 * (x / 4.2e-8).round() + 2e-9 * rng.normal()
            })
            .collect();
        let (qs, _) = lattice(&fast).expect("a grid with skipped levels");
        assert!((qs / 4.2e-8 - 1.0).abs() < 1e-4, "{qs}");
        // Few levels, slowly visited (many samples per level).
        let few: Vec<f64> = (0..8400)
            .map(|k| {
                let x = 1e-6 * (k as f64 / 8400.0 * 9.0).sin();
                2.2e-7 * (x / 2.2e-7).round() + 1e-8 * rng.normal()
            })
            .collect();
        let (qf, of) = lattice(&few).expect("a grid of 9 levels");
        assert!((qf / 2.2e-7 - 1.0).abs() < 1e-3, "{qf}");
        assert!(
            ((of / 2.2e-7 + 0.5).rem_euclid(1.0) - 0.5).abs() < 0.01,
            "{of}"
        );
        // Not quantised: no grid.
        let smooth: Vec<f64> = (0..8400)
            .map(|k| 1e-4 * (k as f64 / 8400.0 * 7.0).sin() + 2e-9 * rng.normal())
            .collect();
        assert_eq!(lattice(&smooth), None);
        // A noiseless digital reading repeats its levels exactly (no spread
        // inside a level): 41 levels of 0.05, each held for many samples.
        let held: Vec<f64> = (0..4000)
            .map(|k| ((k as f64 * 0.0017).sin() / 0.05).round() * 0.05)
            .collect();
        let (qh, oh) = lattice(&held).expect("a grid without noise");
        assert!(
            (qh / 0.05 - 1.0).abs() < 1e-9 && (oh.min(0.05 - oh)).abs() < 1e-9,
            "{qh} {oh}"
        );
        let noise: Vec<f64> = (0..8400).map(|_| rng.normal()).collect();
        assert_eq!(lattice(&noise), None);
    }
}
