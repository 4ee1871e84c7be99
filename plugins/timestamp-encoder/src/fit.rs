//! The least-squares polynomial fit (8.1)–(8.4), without allocation.
//!
//! Given n events (t_i, x_i), fit x(t) ≈ Σ_j p_j τ^j, j = 0..m, by least squares
//! (8.4) and evaluate the polynomial and its first two time derivatives at t_c.
//!
//! **Time scaling.** The raw matrix A of (8.1) with t in seconds is hopelessly
//! ill-conditioned (event spacings of microseconds raised to the m-th power). As in
//! Sec. 8.3 the time is shifted and scaled so that the window spans exactly 1:
//! τ = (t − t_ref)/T with T = t_newest − t_oldest. We shift to the **newest event**
//! (t_ref = t_newest, so τ ∈ [−1, 0]) rather than to t_c: it is the same polynomial
//! evaluated at τ_c = (t_c − t_newest)/T, but A stays well conditioned however old
//! the newest event is (standstill). Derivatives are scaled back:
//! ẋ = (dx/dτ)/T, ẍ = (d²x/dτ²)/T².
//!
//! **Solver.** Two paths, both on stack arrays (n ≤ [`MAX_N`], m ≤ [`MAX_M`]), no
//! allocation:
//!
//! - *Fast path* (orders m ≤ [`FAST_MAX_M`], the common case; [`fit_events`] tries it
//!   first): normal equations AᵀA p = Aᵀ(x − x_newest) from the power sums Σ τ^k and
//!   the moments Σ τ^j (x_i − x_newest), solved by an LDLᵀ (square-root-free
//!   Cholesky) factorisation of the (m+1)×(m+1) Gram matrix, with the size a
//!   compile-time constant so that everything unrolls. Normal equations square the
//!   condition number, which is harmless here because the time is scaled: cond(A) ≈
//!   17 for m = 2, n = 5 (test `time_scaling_improves_the_condition_number`), so
//!   cond(AᵀA) ≈ 300 and the loss is ~3 digits of 16. Subtracting the newest event's
//!   level first keeps the moments small however many counts the axis has moved.
//!   The path declines (returns to the QR path) when a pivot d_j ≤ 1e-6·(AᵀA)_jj,
//!   i.e. when the j-th column has less than 1e-3 of its norm outside the span of
//!   the previous ones (clustered times) — there the squared condition would cost
//!   too many digits.
//! - *Householder QR* of the n×(m+1) matrix ([`fit_events_qr`]), then back
//!   substitution: no squaring of the condition number; used for m > [`FAST_MAX_M`]
//!   and whenever the fast path declines.
//!
//! The thesis used LU without pivoting on AᵀA (Sec. 8.3).
//!
//! **Degenerate windows.** With fewer than m + 1 distinct times the order is reduced
//! to (distinct times − 1); a column whose QR pivot is negligible (|r_jj| <
//! 1e-10·|r_00|) also reduces the order. Nothing ever divides by zero; with no event
//! at all [`fit_events`] returns `None`.

/// Largest fit order m supported.
pub const MAX_M: usize = 4;
/// Largest number of events n supported.
pub const MAX_N: usize = 16;
/// Largest order solved by the normal-equation fast path (above: QR only).
pub const FAST_MAX_M: usize = 2;

/// Result of a fit evaluated at t_c.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FitResult {
    /// x̂(t_c) (unit of the x_i).
    pub x: f64,
    /// dx̂/dt at t_c (unit of x per s).
    pub v: f64,
    /// d²x̂/dt² at t_c (unit of x per s²).
    pub a: f64,
    /// The order actually used (≤ m; smaller when the window is degenerate).
    pub order: usize,
    /// The window span T (s); 1 when all events share one time.
    pub span_s: f64,
}

/// Fit a polynomial of order ≤ `m` through the events (`times[i]`, `xs[i]`)
/// (any order, same length ≤ [`MAX_N`]) and evaluate it at `t_eval`.
/// Returns `None` when there is no event. `m` is clamped to [`MAX_M`].
///
/// ```
/// use timestamp_encoder::fit::fit_events;
/// // x = 2 + 3t − t² sampled at five times: recovered exactly.
/// let t = [0.01, 0.013, 0.02, 0.024, 0.03];
/// let x: Vec<f64> = t.iter().map(|t| 2.0 + 3.0 * t - t * t).collect();
/// let f = fit_events(&t, &x, 2, 0.05).unwrap();
/// assert!((f.x - (2.0 + 0.15 - 0.0025)).abs() < 1e-12);
/// assert!((f.v - (3.0 - 0.1)).abs() < 1e-10);
/// assert!((f.a + 2.0).abs() < 1e-7);
/// ```
pub fn fit_events(times: &[f64], xs: &[f64], m: usize, t_eval: f64) -> Option<FitResult> {
    let n = times.len().min(xs.len()).min(MAX_N);
    if n == 0 {
        return None;
    }
    // Fast path: strictly decreasing times (the register's newest-first order,
    // all distinct, so the span is > 0) and m ≤ FAST_MAX_M with n > m, n ≥ 2.
    let (times_n, xs_n) = (&times[..n], &xs[..n]);
    if m <= FAST_MAX_M && n > m && n >= 2 && times_n.windows(2).all(|w| w[1] < w[0]) {
        let f = match m {
            0 => fit_ldl::<1>(times_n, xs_n, t_eval),
            1 => fit_ldl::<2>(times_n, xs_n, t_eval),
            _ => fit_ldl::<3>(times_n, xs_n, t_eval),
        };
        if f.is_some() {
            return f;
        }
    }
    fit_events_qr(times, xs, m, t_eval)
}

/// Normal equations on the scaled time solved by LDLᵀ, for K = m + 1 columns and
/// strictly decreasing `times` (newest first, n > m, n ≥ 2). `None` when the span
/// is not positive and finite or a pivot is
/// negligible (see the module documentation); the caller then uses QR.
#[inline(always)]
fn fit_ldl<const K: usize>(times: &[f64], xs: &[f64], t_eval: f64) -> Option<FitResult> {
    let n = times.len();
    let t_new = times[0];
    let span = t_new - times[n - 1];
    if !(span > 0.0 && span.is_finite()) {
        return None;
    }
    let inv_span = 1.0 / span;
    let x_ref = xs[0];
    // Power sums S_k = Σ τ^k (k ≤ 2m) and moments B_j = Σ τ^j (x_i − x_ref).
    let mut sums = [0.0f64; 2 * MAX_M + 1];
    let mut mom = [0.0f64; K];
    for i in 0..n {
        let tau = (times[i] - t_new) * inv_span;
        let y = xs[i] - x_ref;
        let mut p = 1.0;
        for (k, s) in sums.iter_mut().enumerate().take(2 * K - 1) {
            *s += p;
            if k < K {
                mom[k] += p * y;
            }
            p *= tau;
        }
    }
    // LDLᵀ of G = [S_{i+j}]: l[i][j] (i > j), d[j], and 1/d[j].
    let mut l = [[0.0f64; K]; K];
    let mut d = [0.0f64; K];
    let mut dinv = [0.0f64; K];
    for j in 0..K {
        let mut dj = sums[2 * j];
        for k in 0..j {
            dj -= l[j][k] * l[j][k] * d[k];
        }
        // Also false for NaN: non-finite input goes to the QR path.
        if dj.partial_cmp(&(1e-6 * sums[2 * j])) != Some(std::cmp::Ordering::Greater) {
            return None;
        }
        d[j] = dj;
        dinv[j] = 1.0 / dj;
        for i in j + 1..K {
            let mut g = sums[i + j];
            for k in 0..j {
                g -= l[i][k] * l[j][k] * d[k];
            }
            l[i][j] = g * dinv[j];
        }
    }
    // L z = B, D w = z, Lᵀ p = w.
    let mut p = mom;
    for i in 0..K {
        for k in 0..i {
            p[i] -= l[i][k] * p[k];
        }
    }
    for i in 0..K {
        p[i] *= dinv[i];
    }
    for i in (0..K).rev() {
        for k in i + 1..K {
            p[i] -= l[k][i] * p[k];
        }
    }
    p[0] += x_ref;
    let tau_c = (t_eval - t_new) * inv_span;
    let (mut x, mut dx, mut ddx) = (0.0, 0.0, 0.0);
    for j in (0..K).rev() {
        ddx = ddx * tau_c + 2.0 * dx;
        dx = dx * tau_c + x;
        x = x * tau_c + p[j];
    }
    Some(FitResult {
        x,
        v: dx * inv_span,
        a: ddx * inv_span * inv_span,
        order: K - 1,
        span_s: span,
    })
}

/// [`fit_events`] by Householder QR only (the general path: any event order,
/// repeated times, orders up to [`MAX_M`]).
pub fn fit_events_qr(times: &[f64], xs: &[f64], m: usize, t_eval: f64) -> Option<FitResult> {
    let n = times.len().min(xs.len()).min(MAX_N);
    if n == 0 {
        return None;
    }
    let (times, xs) = (&times[..n], &xs[..n]);
    // Distinct times, newest and oldest.
    let (mut t_new, mut t_old) = (times[0], times[0]);
    let mut distinct = 0;
    for (i, &t) in times.iter().enumerate() {
        if !times[..i].contains(&t) {
            distinct += 1;
        }
        t_new = t_new.max(t);
        t_old = t_old.min(t);
    }
    let mut order = m.min(MAX_M).min(distinct - 1);
    let span = if t_new > t_old { t_new - t_old } else { 1.0 };
    let cols_max = order + 1;
    // A (rows τ^0..τ^m) and b, column-major on the stack.
    let mut a = [[0.0f64; MAX_N]; MAX_M + 1];
    let mut b = [0.0f64; MAX_N];
    for i in 0..n {
        let tau = (times[i] - t_new) / span;
        let mut p = 1.0;
        for col in a.iter_mut().take(cols_max) {
            col[i] = p;
            p *= tau;
        }
        b[i] = xs[i];
    }
    // Householder QR, column by column; stop early on a negligible pivot.
    let mut r = [[0.0f64; MAX_M + 1]; MAX_M + 1];
    let mut r00 = 0.0;
    for j in 0..cols_max {
        let norm = a[j][j..n].iter().map(|v| v * v).sum::<f64>().sqrt();
        if j == 0 {
            r00 = norm;
        }
        if j >= n || norm <= 1e-10 * r00 {
            order = j.saturating_sub(1);
            break;
        }
        let alpha = if a[j][j] > 0.0 { -norm } else { norm };
        // v = a_j − α e_j (stored in a[j][j..n]); H = I − 2vvᵀ/vᵀv.
        a[j][j] -= alpha;
        let vtv: f64 = a[j][j..n].iter().map(|v| v * v).sum();
        let (vcol, rest) = a.split_at_mut(j + 1);
        let v = &vcol[j];
        for col in rest.iter_mut().take(cols_max - j - 1) {
            let dot: f64 = (j..n).map(|i| v[i] * col[i]).sum();
            let f = 2.0 * dot / vtv;
            for i in j..n {
                col[i] -= f * v[i];
            }
        }
        let dot: f64 = (j..n).map(|i| v[i] * b[i]).sum();
        let f = 2.0 * dot / vtv;
        for i in j..n {
            b[i] -= f * v[i];
        }
        r[j][j] = alpha;
        for (jj, col) in rest.iter().enumerate().take(cols_max - j - 1) {
            r[j][j + 1 + jj] = col[j];
        }
        if j == cols_max - 1 {
            order = j;
        }
    }
    // Back substitution R p = Qᵀb for the retained columns.
    let mut p = [0.0f64; MAX_M + 1];
    for j in (0..=order).rev() {
        let mut s = b[j];
        for jj in j + 1..=order {
            s -= r[j][jj] * p[jj];
        }
        p[j] = s / r[j][j];
    }
    // Evaluate x, dx/dτ, d²x/dτ² at τ_c (Horner on the three).
    let tau_c = (t_eval - t_new) / span;
    let (mut x, mut dx, mut ddx) = (0.0, 0.0, 0.0);
    for j in (0..=order).rev() {
        ddx = ddx * tau_c + 2.0 * dx;
        dx = dx * tau_c + x;
        x = x * tau_c + p[j];
    }
    Some(FitResult {
        x,
        v: dx / span,
        a: ddx / (span * span),
        order,
        span_s: span,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::DMatrix;

    fn cond(t: &[f64], m: usize) -> f64 {
        let a = DMatrix::from_fn(t.len(), m + 1, |i, j| t[i].powi((m - j) as i32));
        let sv = a.singular_values();
        sv.max() / sv.min()
    }

    #[test]
    fn exact_polynomials_of_degree_up_to_m_are_recovered() {
        let t: Vec<f64> = (0..9).map(|i| 3.0 + 1e-3 * (i as f64).powf(1.3)).collect();
        for m in 0..=MAX_M {
            // x(t) = Σ c_j (t − 3)^j, degree m.
            let c = [0.7, -40.0, 1.2e3, -3.0e4, 2.0e5];
            let x = |t: f64| {
                (0..=m)
                    .map(|j| c[j] * (t - 3.0).powi(j as i32))
                    .sum::<f64>()
            };
            let v = |t: f64| {
                (1..=m)
                    .map(|j| j as f64 * c[j] * (t - 3.0).powi(j as i32 - 1))
                    .sum::<f64>()
            };
            let acc = |t: f64| {
                (2..=m)
                    .map(|j| (j * (j - 1)) as f64 * c[j] * (t - 3.0).powi(j as i32 - 2))
                    .sum::<f64>()
            };
            let xs: Vec<f64> = t.iter().map(|&t| x(t)).collect();
            let tc = 3.0125;
            let f = fit_events(&t, &xs, m, tc).unwrap();
            assert_eq!(f.order, m);
            assert!(
                (f.x - x(tc)).abs() < 1e-9 * x(tc).abs().max(1.0),
                "m {m}: {} vs {}",
                f.x,
                x(tc)
            );
            assert!(
                (f.v - v(tc)).abs() < 1e-7 * v(tc).abs().max(1.0),
                "m {m}: {} vs {}",
                f.v,
                v(tc)
            );
            assert!(
                (f.a - acc(tc)).abs() < 1e-5 * acc(tc).abs().max(1.0),
                "m {m}: {} vs {}",
                f.a,
                acc(tc)
            );
        }
    }

    /// The register's order: newest first, strictly decreasing times.
    fn register_times(n: usize) -> Vec<f64> {
        (0..n)
            .rev()
            .map(|i| 3.0 + 1e-3 * (i as f64).powf(1.3))
            .collect()
    }

    #[test]
    fn fast_path_recovers_polynomials_far_from_the_origin() {
        // x(t) = X0 + Σ c_j (t − 3)^j with X0 = 10⁶ counts (an axis that has moved
        // far): the newest level is subtracted before the normal equations.
        let c = [1e6 + 0.7, -40.0, 1.2e3];
        for m in 0..=FAST_MAX_M {
            for n in (m + 1).max(2)..=MAX_N {
                let t = register_times(n);
                let x = |t: f64| {
                    (0..=m)
                        .map(|j| c[j] * (t - 3.0).powi(j as i32))
                        .sum::<f64>()
                };
                let v = |t: f64| {
                    (1..=m)
                        .map(|j| j as f64 * c[j] * (t - 3.0).powi(j as i32 - 1))
                        .sum::<f64>()
                };
                let acc = if m == 2 { 2.0 * c[2] } else { 0.0 };
                let xs: Vec<f64> = t.iter().map(|&t| x(t)).collect();
                let tc = t[0] + 0.1 * (t[0] - t[n - 1]);
                let fast = match m {
                    0 => fit_ldl::<1>(&t, &xs, tc),
                    1 => fit_ldl::<2>(&t, &xs, tc),
                    _ => fit_ldl::<3>(&t, &xs, tc),
                }
                .expect("well-conditioned window takes the fast path");
                assert_eq!(Some(fast), fit_events(&t, &xs, m, tc));
                assert_eq!(fast.order, m);
                // Relative to the motion within the window (not to X0).
                assert!(
                    (fast.x - x(tc)).abs() < 1e-8,
                    "m {m} n {n}: {} vs {}",
                    fast.x,
                    x(tc)
                );
                assert!(
                    (fast.v - v(tc)).abs() < 1e-7 * v(tc).abs().max(1.0),
                    "m {m} n {n}: {} vs {}",
                    fast.v,
                    v(tc)
                );
                assert!(
                    (fast.a - acc).abs() < 1e-4 * acc.abs().max(1.0),
                    "m {m} n {n}: {} vs {acc}",
                    fast.a
                );
            }
        }
    }

    #[test]
    fn fast_path_agrees_with_householder_on_noisy_windows() {
        let mut rng = nanomotion_core::rng::Rng::new(11);
        let mut worst = 0.0f64;
        for _ in 0..2000 {
            let n = 2 + (rng.uniform() * 9.0) as usize;
            let m = ((rng.uniform() * 3.0) as usize).min(n - 1).min(FAST_MAX_M);
            // Gaps between events spread over a factor 20, level steps ±1 count
            // plus edge errors, t around 100 s, read up to one span after.
            let mut t = vec![100.0 + rng.uniform()];
            let mut x = vec![(rng.uniform() * 1e5).round()];
            for i in 1..n {
                t.push(t[i - 1] - 1e-4 * (0.05 + rng.uniform()));
                x.push(x[i - 1] - 1.0 + 0.05 * rng.normal());
            }
            let tc = t[0] + rng.uniform() * (t[0] - t[n - 1]);
            let f = fit_events(&t, &x, m, tc).unwrap();
            let q = fit_events_qr(&t, &x, m, tc).unwrap();
            let span = f.span_s;
            assert_eq!(f.order, q.order);
            // Errors in counts, counts per span and counts per span².
            let e = [
                (f.x - q.x).abs(),
                (f.v - q.v).abs() * span,
                (f.a - q.a).abs() * span * span,
            ];
            worst = worst.max(e.into_iter().fold(0.0, f64::max));
        }
        assert!(worst < 1e-9, "largest difference {worst:e} counts");
    }

    #[test]
    fn clustered_times_decline_the_fast_path() {
        // Two clusters of times: τ² is nearly a combination of 1 and τ, the third
        // pivot is ~1e-12 of its diagonal → QR (which keeps order 2 or reduces it).
        let t = [1.0, 1.0 - 1e-6, 2e-6, 1e-6, 0.0];
        let x = [4.0, 3.0, 2.0, 1.0, 0.0];
        assert!(fit_ldl::<3>(&t, &x, 1.1).is_none());
        assert!(fit_ldl::<2>(&t, &x, 1.1).is_some());
        let f = fit_events(&t, &x, 2, 1.1).unwrap();
        assert_eq!(Some(f), fit_events_qr(&t, &x, 2, 1.1));
        assert!(f.x.is_finite() && f.v.is_finite() && f.a.is_finite());
    }

    #[test]
    fn matches_normal_equations_on_noisy_data() {
        let t = [0.0, 0.1, 0.25, 0.3, 0.5, 0.55, 0.8];
        let x = [0.1, 0.9, 2.2, 2.8, 5.3, 5.4, 8.1];
        let f = fit_events(&t, &x, 2, 0.9).unwrap();
        let a = DMatrix::from_fn(7, 3, |i, j| t[i].powi(j as i32));
        let b = nalgebra::DVector::from_column_slice(&x);
        let p = (a.transpose() * &a)
            .lu()
            .solve(&(a.transpose() * b))
            .unwrap();
        let x_ref = p[0] + p[1] * 0.9 + p[2] * 0.81;
        let v_ref = p[1] + 2.0 * p[2] * 0.9;
        assert!(
            (f.x - x_ref).abs() < 1e-12
                && (f.v - v_ref).abs() < 1e-11
                && (f.a - 2.0 * p[2]).abs() < 1e-10
        );
    }

    #[test]
    fn degenerate_windows_reduce_the_order_and_never_divide_by_zero() {
        assert!(fit_events(&[], &[], 2, 0.0).is_none());
        let f = fit_events(&[1.0], &[5.0], 2, 2.0).unwrap();
        assert_eq!((f.x, f.v, f.a, f.order), (5.0, 0.0, 0.0, 0));
        // Two distinct times among four events: a line.
        let f = fit_events(&[1.0, 1.0, 2.0, 2.0], &[0.0, 0.0, 1.0, 1.0], 3, 3.0).unwrap();
        assert_eq!(f.order, 1);
        assert!((f.x - 2.0).abs() < 1e-12 && (f.v - 1.0).abs() < 1e-12 && f.a == 0.0);
        let f = fit_events(&[4.0, 4.0, 4.0], &[1.0, 2.0, 3.0], 2, 5.0).unwrap();
        assert!(f.x.is_finite() && f.v == 0.0 && (f.x - 2.0).abs() < 1e-12);
    }

    #[test]
    fn time_scaling_improves_the_condition_number() {
        // Five events 0.1 ms apart, read 0.05 ms after the newest, at t = 10 s,
        // m = 2, n = 5 (the thesis's Sec. 8.3 example; its digits were lost).
        let raw: Vec<f64> = (0..5).map(|i| 10.0 - 0.05e-3 - 0.1e-3 * i as f64).collect();
        let t_c = 10.0;
        let shifted: Vec<f64> = raw.iter().map(|t| t - t_c).collect();
        let span = raw[0] - raw[4];
        let scaled: Vec<f64> = raw.iter().map(|t| (t - raw[0]) / span).collect();
        let (c_raw, c_shift, c_scaled) = (cond(&raw, 2), cond(&shifted, 2), cond(&scaled, 2));
        assert!(c_raw > 1e11, "raw {c_raw:e}");
        assert!(c_shift > 1e6, "shifted {c_shift:e}");
        assert!(c_scaled < 30.0, "scaled {c_scaled:e}");
        eprintln!(
            "cond(A): absolute time {c_raw:.3e}, shifted to t_c {c_shift:.3e}, shifted and scaled {c_scaled:.3}"
        );
    }
}
