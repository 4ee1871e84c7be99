//! Offline filtering with cascaded second-order sections: a causal forward pass
//! ([`lfilter_sos`], scipy's `sosfilt`) and anti-causal zero-phase forward-backward
//! filtering ([`filtfilt_sos`], scipy's `sosfiltfilt`).
//!
//! The thesis's reference signals are low-pass filtered forward and backward with a
//! 5th-order filter: the result has zero phase and magnitude |H(e^{jωT})|², so a
//! filter with a −3 dB cut-off f_c acts as one with a −6 dB cut-off f_c.
//!
//! Sections use scipy's layout `[b0, b1, b2, a0, a1, a2]` ([`SosSection`]); a
//! section with a0 ≠ 1 is normalised on the fly. Each section runs in direct form II
//! transposed with state `[z0, z1]`:
//! y = b0 x + z0, z0 ← b1 x − a1 y + z1, z1 ← b2 x − a2 y.

use crate::lti::SosSection;

/// Section normalised to a0 = 1: `[b0, b1, b2, a1, a2]`.
fn normalise(s: &SosSection) -> [f64; 5] {
    let a0 = s[3];
    [s[0] / a0, s[1] / a0, s[2] / a0, s[4] / a0, s[5] / a0]
}

/// Causal filtering of `x` by the cascade `sos`, starting from zero state.
///
/// ```
/// use nanomotion_core::analysis::lfilter_sos;
/// // y_k = 0.5 x_k + 0.5 x_{k-1}
/// let y = lfilter_sos(&[[0.5, 0.5, 0.0, 1.0, 0.0, 0.0]], &[2.0, 4.0, 4.0]);
/// assert_eq!(y, vec![1.0, 3.0, 4.0]);
/// ```
pub fn lfilter_sos(sos: &[SosSection], x: &[f64]) -> Vec<f64> {
    let mut state = vec![[0.0; 2]; sos.len()];
    lfilter_sos_with_state(sos, x, &mut state)
}

/// Causal filtering of `x` by `sos` from (and updating) the per-section DF-II-T
/// state `state[s] = [z0, z1]` (scipy's `zi`/`zf`), so that a long record can be
/// filtered in pieces.
///
/// # Panics
/// If `state.len() != sos.len()`.
pub fn lfilter_sos_with_state(sos: &[SosSection], x: &[f64], state: &mut [[f64; 2]]) -> Vec<f64> {
    assert_eq!(state.len(), sos.len(), "one state per section");
    let mut y = x.to_vec();
    // Section by section over the whole record: the inner loop is a tight recursion.
    for (s, z) in sos.iter().zip(state.iter_mut()) {
        let [b0, b1, b2, a1, a2] = normalise(s);
        let [mut z0, mut z1] = *z;
        for v in y.iter_mut() {
            let xin = *v;
            let out = b0 * xin + z0;
            z0 = b1 * xin - a1 * out + z1;
            z1 = b2 * xin - a2 * out;
            *v = out;
        }
        *z = [z0, z1];
    }
    y
}

/// Steady-state initial state of the cascade for a unit-step input (scipy's
/// `sosfilt_zi`): starting [`lfilter_sos_with_state`] from `x₀ · zi` makes a constant
/// input x₀ give a constant output (DC gain · x₀) from the first sample.
///
/// A section with a pole at z = 1 (Σa = 0) has no steady state; its state is 0 and
/// the sections after it are scaled as if its DC gain were 1.
pub fn sosfilt_zi(sos: &[SosSection]) -> Vec<[f64; 2]> {
    let mut scale = 1.0;
    sos.iter()
        .map(|s| {
            let [b0, b1, b2, a1, a2] = normalise(s);
            let sa = 1.0 + a1 + a2;
            if sa.abs() < 1e-300 {
                return [0.0, 0.0];
            }
            let g = (b0 + b1 + b2) / sa;
            // Steady state of y = g for x = 1: z1 = b2 − a2 g, z0 = b1 − a1 g + z1.
            let z1 = b2 - a2 * g;
            let z0 = b1 - a1 * g + z1;
            let zi = [scale * z0, scale * z1];
            scale *= g;
            zi
        })
        .collect()
}

/// scipy's default padding for [`filtfilt_sos`]:
/// 3 · (2 · sections + 1 − min(#{b2 = 0}, #{a2 = 0})) samples.
pub fn default_padlen(sos: &[SosSection]) -> usize {
    let nb = sos.iter().filter(|s| s[2] == 0.0).count();
    let na = sos.iter().filter(|s| s[5] == 0.0).count();
    3 * (2 * sos.len() + 1 - nb.min(na))
}

/// Zero-phase forward-backward filtering with scipy's `sosfiltfilt` semantics and
/// its default padding [`default_padlen`] (clamped to `x.len() − 1` for short
/// records, where scipy would refuse).
///
/// The record is extended at both ends by odd reflection (2x₀ − x_{k}, …), filtered
/// forward from the steady state for its first sample ([`sosfilt_zi`]), reversed,
/// filtered again from the steady state for the last output, reversed back and
/// trimmed. A constant input therefore comes out as the constant times the squared DC
/// gain, a sinusoid in the pass band with zero phase shift, and the overall
/// magnitude is |H|².
///
/// ```
/// use nanomotion_core::analysis::filtfilt_sos;
/// // First-order low-pass y_k = 0.2 x_k + 0.8 y_{k-1} (unit DC gain).
/// let sos = [[0.2, 0.0, 0.0, 1.0, -0.8, 0.0]];
/// let y = filtfilt_sos(&sos, &[1.5; 50]);
/// assert!(y.iter().all(|v| (v - 1.5).abs() < 1e-12));
/// ```
pub fn filtfilt_sos(sos: &[SosSection], x: &[f64]) -> Vec<f64> {
    filtfilt_sos_padded(sos, x, default_padlen(sos))
}

/// [`filtfilt_sos`] with an explicit odd-extension length `padlen` (samples at each
/// end, clamped to `x.len() − 1`; 0 disables padding but keeps the steady-state
/// initial conditions).
pub fn filtfilt_sos_padded(sos: &[SosSection], x: &[f64], padlen: usize) -> Vec<f64> {
    let n = x.len();
    if n == 0 || sos.is_empty() {
        return x.to_vec();
    }
    let edge = padlen.min(n - 1);
    let mut ext = Vec::with_capacity(n + 2 * edge);
    let (x0, xn) = (x[0], x[n - 1]);
    ext.extend((1..=edge).rev().map(|k| 2.0 * x0 - x[k]));
    ext.extend_from_slice(x);
    ext.extend((1..=edge).map(|k| 2.0 * xn - x[n - 1 - k]));

    let zi = sosfilt_zi(sos);
    let mut state: Vec<[f64; 2]> = zi.iter().map(|z| [z[0] * ext[0], z[1] * ext[0]]).collect();
    let mut y = lfilter_sos_with_state(sos, &ext, &mut state);
    y.reverse();
    let y0 = y[0];
    for (st, z) in state.iter_mut().zip(&zi) {
        *st = [z[0] * y0, z[1] * y0];
    }
    let mut y = lfilter_sos_with_state(sos, &y, &mut state);
    y.reverse();
    y.drain(..edge);
    y.truncate(n);
    y
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::lti::Complex;
    use crate::rng::Rng;
    use std::f64::consts::{PI, TAU};

    /// Butterworth low-pass of order `n` (bilinear transform with pre-warping), as
    /// sections: the analog poles ω_a e^{jπ(2k+n−1)/(2n)} paired into quadratics.
    fn butter(n: usize, fc_hz: f64, fs_hz: f64) -> Vec<SosSection> {
        let kk = 2.0 * fs_hz;
        let wa = kk * (PI * fc_hz / fs_hz).tan();
        let mut sos = Vec::new();
        if n % 2 == 1 {
            // ω_a / (s + ω_a)
            sos.push([wa, wa, 0.0, kk + wa, wa - kk, 0.0]);
        }
        for k in 1..=n / 2 {
            let theta = PI * (2 * k + n - 1) as f64 / (2 * n) as f64;
            let (re, m2) = (wa * theta.cos(), wa * wa); // pole real part (< 0), |p|²
            sos.push([
                m2,
                2.0 * m2,
                m2,
                kk * kk - 2.0 * re * kk + m2,
                2.0 * m2 - 2.0 * kk * kk,
                kk * kk + 2.0 * re * kk + m2,
            ]);
        }
        sos
    }

    fn response(sos: &[SosSection], f_hz: f64, fs_hz: f64) -> Complex<f64> {
        let z1 = Complex::from_polar(1.0, -TAU * f_hz / fs_hz);
        sos.iter()
            .map(|s| (z1 * z1 * s[2] + z1 * s[1] + s[0]) / (z1 * z1 * s[5] + z1 * s[4] + s[3]))
            .product()
    }

    fn polymul(a: &[f64], b: &[f64]) -> Vec<f64> {
        let mut c = vec![0.0; a.len() + b.len() - 1];
        for (i, x) in a.iter().enumerate() {
            for (j, y) in b.iter().enumerate() {
                c[i + j] += x * y;
            }
        }
        c
    }

    /// Fit y ≈ c cos(ωk) + s sin(ωk) by least squares; returns (amplitude, phase)
    /// relative to sin(ωk).
    fn sine_fit(y: &[f64], w: f64, k0: usize) -> (f64, f64) {
        let (mut scc, mut sss, mut scs, mut syc, mut sys) = (0.0, 0.0, 0.0, 0.0, 0.0);
        for (i, v) in y.iter().enumerate() {
            let (s, c) = (w * (k0 + i) as f64).sin_cos();
            scc += c * c;
            sss += s * s;
            scs += s * c;
            syc += v * c;
            sys += v * s;
        }
        let det = scc * sss - scs * scs;
        let c = (syc * sss - sys * scs) / det;
        let s = (sys * scc - syc * scs) / det;
        ((c * c + s * s).sqrt(), c.atan2(s))
    }

    #[test]
    fn butterworth_helper_is_a_butterworth() {
        let (fs, fc) = (1000.0, 50.0);
        let sos = butter(5, fc, fs);
        assert_eq!(sos.len(), 3);
        assert!((response(&sos, 0.0, fs).norm() - 1.0).abs() < 1e-12);
        assert!((response(&sos, fc, fs).norm() - 0.5f64.sqrt()).abs() < 1e-12);
    }

    #[test]
    fn lfilter_matches_the_direct_difference_equation() {
        // Independent method: multiply the sections into one polynomial pair and run
        // the textbook difference equation.
        let sos = butter(5, 120.0, 1000.0);
        let (mut b, mut a) = (vec![1.0], vec![1.0]);
        for s in &sos {
            b = polymul(&b, &[s[0] / s[3], s[1] / s[3], s[2] / s[3]]);
            a = polymul(&a, &[1.0, s[4] / s[3], s[5] / s[3]]);
        }
        let mut rng = Rng::new(21);
        let x: Vec<f64> = (0..500).map(|_| rng.normal()).collect();
        let mut y_ref = vec![0.0; x.len()];
        for k in 0..x.len() {
            let mut acc = 0.0;
            for (i, bi) in b.iter().enumerate() {
                if k >= i {
                    acc += bi * x[k - i];
                }
            }
            for (i, ai) in a.iter().enumerate().skip(1) {
                if k >= i {
                    acc -= ai * y_ref[k - i];
                }
            }
            y_ref[k] = acc;
        }
        let y = lfilter_sos(&sos, &x);
        for (p, q) in y.iter().zip(&y_ref) {
            assert!((p - q).abs() < 1e-10, "{p} vs {q}");
        }
        // Filtering in two pieces with the carried state gives the same result.
        let mut st = vec![[0.0; 2]; sos.len()];
        let mut y2 = lfilter_sos_with_state(&sos, &x[..123], &mut st);
        y2.extend(lfilter_sos_with_state(&sos, &x[123..], &mut st));
        assert_eq!(y, y2);
        // a0 ≠ 1 is normalised.
        let scaled: Vec<SosSection> = sos.iter().map(|s| s.map(|c| 3.0 * c)).collect();
        let y3 = lfilter_sos(&scaled, &x);
        for (p, q) in y.iter().zip(&y3) {
            assert!((p - q).abs() < 1e-12);
        }
    }

    #[test]
    fn steady_state_initial_conditions() {
        // A DC gain ≠ 1 in the first section, to exercise the cascade scaling.
        let mut sos = butter(4, 30.0, 1000.0);
        sos[0][0] *= 2.0;
        sos[0][1] *= 2.0;
        sos[0][2] *= 2.0;
        let g = response(&sos, 0.0, 1000.0).re;
        assert!((g - 2.0).abs() < 1e-12);
        let zi = sosfilt_zi(&sos);
        let x0 = -1.7;
        let mut st: Vec<[f64; 2]> = zi.iter().map(|z| [z[0] * x0, z[1] * x0]).collect();
        let y = lfilter_sos_with_state(&sos, &[x0; 200], &mut st);
        assert!(y.iter().all(|v| (v - g * x0).abs() < 1e-12));
        // An integrator section (pole at z = 1) gets a zero state instead of a panic.
        assert_eq!(
            sosfilt_zi(&[[1.0, 0.0, 0.0, 1.0, -1.0, 0.0]]),
            vec![[0.0, 0.0]]
        );
    }

    #[test]
    fn filtfilt_keeps_a_constant() {
        let sos = butter(5, 10.0, 1000.0);
        for n in [1000, 40, 5, 1] {
            let y = filtfilt_sos(&sos, &vec![3.25; n]);
            assert_eq!(y.len(), n);
            assert!(y.iter().all(|v| (v - 3.25).abs() < 1e-10), "n = {n}");
        }
        assert!(filtfilt_sos(&sos, &[]).is_empty());
        assert_eq!(default_padlen(&sos), 3 * (2 * 3 + 1 - 1));
    }

    #[test]
    fn filtfilt_has_zero_phase_and_squared_magnitude() {
        let (fs, fc) = (1000.0, 40.0);
        let sos = butter(5, fc, fs);
        let n = 4000;
        for f in [2.0, 25.0, 40.0, 55.0] {
            let w = TAU * f / fs;
            let x: Vec<f64> = (0..n).map(|k| (w * k as f64).sin()).collect();
            let y = filtfilt_sos(&sos, &x);
            // Away from the ends (the extension only approximates the continuation).
            let (amp, phase) = sine_fit(&y[1000..3000], w, 1000);
            let h2 = response(&sos, f, fs).norm_sqr();
            assert!(
                (amp - h2).abs() < 1e-6,
                "{f} Hz: amplitude {amp} vs |H|² {h2}"
            );
            assert!(phase.abs() < 1e-6, "{f} Hz: phase {phase} rad");
            // The one-way filter does shift the phase.
            let (_, phase1) = sine_fit(&lfilter_sos(&sos, &x)[1000..3000], w, 1000);
            assert!((phase1 - response(&sos, f, fs).arg()).abs() < 1e-6);
        }
        // At the −3 dB cut-off the forward-backward filter halves the amplitude.
        let w = TAU * fc / fs;
        let x: Vec<f64> = (0..n).map(|k| (w * k as f64).sin()).collect();
        let (amp, _) = sine_fit(&filtfilt_sos(&sos, &x)[1000..3000], w, 1000);
        assert!((amp - 0.5).abs() < 1e-6);
    }

    #[test]
    fn filtfilt_is_time_reversal_symmetric() {
        // Zero phase ⇔ filtering the reversed record gives the reversed result. Only
        // the start-up transients (forward-then-backward vs backward-then-forward)
        // differ, and they decay away from the ends.
        let sos = butter(3, 60.0, 1000.0);
        let mut rng = Rng::new(22);
        let x: Vec<f64> = (0..300).map(|_| rng.normal()).collect();
        let y = filtfilt_sos(&sos, &x);
        let mut xr = x.clone();
        xr.reverse();
        let mut yr = filtfilt_sos(&sos, &xr);
        yr.reverse();
        let diff = |r: std::ops::Range<usize>| r.map(|k| (y[k] - yr[k]).abs()).fold(0.0, f64::max);
        assert!(diff(0..300) < 0.2);
        assert!(
            diff(60..240) < 1e-6,
            "interior difference {}",
            diff(60..240)
        );
        // A sample far from the ends matches the two-sided impulse response h ⋆ h(−·).
        let mut imp = vec![0.0; 301];
        imp[150] = 1.0;
        let g = filtfilt_sos(&sos, &imp);
        let h = lfilter_sos(&sos, &{
            let mut d = vec![0.0; 151];
            d[0] = 1.0;
            d
        });
        for lag in 0..20 {
            let expect: f64 = (0..151 - lag).map(|k| h[k] * h[k + lag]).sum();
            assert!((g[150 + lag] - expect).abs() < 1e-9, "lag {lag}");
            assert!((g[150 - lag] - expect).abs() < 1e-9, "lag −{lag}");
        }
    }
}
