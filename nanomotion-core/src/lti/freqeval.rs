//! Frequency response at many points for the price of one reduction.
//!
//! G(x) = C (xI − A)⁻¹ B + D costs a dense complex LU of (xI − A), O(n³), at
//! every point. [`FrequencyEvaluator`] balances A (diagonal similarity by powers
//! of two, exact) and reduces it once to upper Hessenberg form H = Qᵀ A Q by an
//! orthogonal similarity, so G(x) = (C Q)(xI − H)⁻¹(Qᵀ B) + D; (xI − H) is
//! Hessenberg too, and its LU with partial pivoting (a choice between two rows
//! per column) and the triangular solves cost O(n²) per input column. Both
//! steps are backward stable, like the dense LU, so the two agree to round-off
//! times the conditioning of (xI − A) (tested against the dense LU and against
//! closed forms).
//!
//! The margins, H∞ norms, Nyquist counts and characteristic loci of the
//! stability gate evaluate loops at thousands of points each; with this they
//! scale as n² per point instead of n³.

use super::linalg::balance;
use super::{Complex, LtiError, StateSpace};
use nalgebra::DMatrix;

/// A state-space model prepared for evaluation at many points (see the
/// module documentation): [`StateSpace::frequency_evaluator`].
#[derive(Debug, Clone)]
pub struct FrequencyEvaluator {
    n: usize,
    /// H row by row (row-major), entries below the subdiagonal zero.
    h: Vec<f64>,
    /// Qᵀ B, row-major (n × m).
    qb: Vec<f64>,
    /// C Q (p × n).
    cq: DMatrix<f64>,
    d: DMatrix<f64>,
    dt: Option<f64>,
    /// The model as given, for the points near one of its poles.
    model: StateSpace,
    /// Eigenvalues of A.
    poles: Vec<Complex<f64>>,
    /// ‖A‖₁.
    a_norm: f64,
}

impl StateSpace {
    /// The model reduced once for its frequency response at many points
    /// ([`FrequencyEvaluator`]); the error of [`StateSpace::validate`] for an
    /// inconsistent hand-built model.
    pub fn frequency_evaluator(&self) -> Result<FrequencyEvaluator, LtiError> {
        self.validate()?;
        Ok(FrequencyEvaluator::new(self))
    }
}

impl FrequencyEvaluator {
    /// The reduction of `sys`, which must be valid ([`StateSpace::validate`]).
    pub(crate) fn new(sys: &StateSpace) -> Self {
        let n = sys.nstates();
        let (m, p) = (sys.ninputs(), sys.noutputs());
        let (a, scale) = balance(&sys.a);
        // Balanced: T⁻¹ A T, T⁻¹ B, C T with T = diag(scale).
        let mut b = sys.b.clone();
        let mut c = sys.c.clone();
        for i in 0..n {
            b.row_mut(i).scale_mut(1.0 / scale[i]);
            c.column_mut(i).scale_mut(scale[i]);
        }
        let (q, h) = if n > 2 {
            nalgebra::linalg::Hessenberg::new(a).unpack()
        } else {
            // Already Hessenberg.
            (DMatrix::identity(n, n), a)
        };
        let qb = q.transpose() * b;
        let cq = c * q;
        let mut hr = vec![0.0; n * n];
        for i in 0..n {
            for j in i.saturating_sub(1)..n {
                hr[i * n + j] = h[(i, j)];
            }
        }
        let mut qbr = vec![0.0; n * m];
        for i in 0..n {
            for j in 0..m {
                qbr[i * m + j] = qb[(i, j)];
            }
        }
        debug_assert_eq!(cq.shape(), (p, n));
        Self {
            n,
            h: hr,
            qb: qbr,
            cq,
            d: sys.d.clone(),
            dt: sys.dt,
            model: sys.clone(),
            poles: super::linalg::eigvals(&sys.a),
            a_norm: super::linalg::norm_1(&sys.a),
        }
    }

    /// The feedthrough D (the value at infinite frequency of a continuous model).
    pub fn feedthrough(&self) -> &DMatrix<f64> {
        &self.d
    }

    /// Number of inputs m.
    pub fn ninputs(&self) -> usize {
        self.d.ncols()
    }

    /// Number of outputs p.
    pub fn noutputs(&self) -> usize {
        self.d.nrows()
    }

    /// G(x) = C (xI − A)⁻¹ B + D at a complex point `x` (s or z): the value of
    /// [`StateSpace::evalfr`], NaN where (xI − A) is exactly singular.
    pub fn evalfr(&self, x: Complex<f64>) -> DMatrix<Complex<f64>> {
        let (n, m, p) = (self.n, self.ninputs(), self.noutputs());
        let mut g = self.d.map(|v| Complex::new(v, 0.0));
        if n == 0 {
            return g;
        }
        if self.near_a_pole(x) {
            return self.model.evalfr(x);
        }
        let Some((xr, xi)) = self.solve(x) else {
            return DMatrix::from_element(p, m, Complex::new(f64::NAN, f64::NAN));
        };
        for j in 0..m {
            for i in 0..p {
                let mut acc = Complex::new(0.0, 0.0);
                for k in 0..n {
                    acc += Complex::new(xr[k * m + j], xi[k * m + j]) * self.cq[(i, k)];
                }
                g[(i, j)] += acc;
            }
        }
        g
    }

    /// Whether `x` is so near an eigenvalue of A that the Hessenberg form's
    /// round-off (a perturbation of A of about ε‖A‖, spread over all its
    /// entries, which splits a repeated eigenvalue by √(ε‖A‖)) could move a
    /// pole across it: within 10⁻⁴ relative or 10⁻⁶‖A‖. There the dense LU of
    /// the model as given is used, which keeps its exact zeros (a double
    /// integrator's Jordan block stays one): the Nyquist contour passes
    /// poles on the unit circle at a distance of 10⁻⁹.
    fn near_a_pole(&self, x: Complex<f64>) -> bool {
        let abs = 1e-6 * self.a_norm;
        self.poles
            .iter()
            .any(|p| (x - p).norm() <= 1e-4 * x.norm().max(p.norm()) + abs)
    }

    /// G at angular frequency `w_rad_s` (rad/s): s = jω, or z = e^{jωT} for a
    /// discrete model (as [`StateSpace::frequency_point`]).
    pub fn at(&self, w_rad_s: f64) -> DMatrix<Complex<f64>> {
        self.evalfr(self.frequency_point(w_rad_s))
    }

    /// The (0, 0) entry of G at `w_rad_s` (rad/s) (as
    /// [`StateSpace::freqresp_siso_at`]); NaN without inputs or outputs.
    pub fn siso_at(&self, w_rad_s: f64) -> Complex<f64> {
        self.at(w_rad_s)
            .get((0, 0))
            .copied()
            .unwrap_or(Complex::new(f64::NAN, f64::NAN))
    }

    /// The point of the s- or z-plane of angular frequency `w_rad_s` (rad/s).
    pub fn frequency_point(&self, w_rad_s: f64) -> Complex<f64> {
        super::ss::frequency_point(self.dt, w_rad_s)
    }

    /// X = (xI − H)⁻¹ Qᵀ B (row-major n × m, real and imaginary parts
    /// apart so that the row operations vectorise) by the LU of the
    /// Hessenberg matrix xI − H with partial pivoting; `None` when a pivot is
    /// exactly zero (x an eigenvalue, as the dense LU's refusal).
    fn solve(&self, x: Complex<f64>) -> Option<(Vec<f64>, Vec<f64>)> {
        let (n, m) = (self.n, self.ninputs());
        let mut ur: Vec<f64> = self.h.iter().map(|&v| -v).collect();
        let mut ui = vec![0.0; n * n];
        for i in 0..n {
            ur[i * n + i] += x.re;
            ui[i * n + i] += x.im;
        }
        let mut rr = self.qb.clone();
        let mut ri = vec![0.0; n * m];
        // Elimination: only row k + 1 has an entry below the diagonal in column k.
        for k in 0..n.saturating_sub(1) {
            let len = n - k;
            let (a, b) = (k * n + k, (k + 1) * n + k);
            let (top_r, bot_r) = ur.split_at_mut(b);
            let (top_i, bot_i) = ui.split_at_mut(b);
            let (pr, pi) = (&mut top_r[a..a + len], &mut top_i[a..a + len]);
            let (qr, qi) = (&mut bot_r[..len], &mut bot_i[..len]);
            let (rtop_r, rbot_r) = rr.split_at_mut((k + 1) * m);
            let (rtop_i, rbot_i) = ri.split_at_mut((k + 1) * m);
            let (sr, si) = (&mut rtop_r[k * m..], &mut rtop_i[k * m..]);
            let (tr, ti) = (&mut rbot_r[..m], &mut rbot_i[..m]);
            if qr[0] * qr[0] + qi[0] * qi[0] > pr[0] * pr[0] + pi[0] * pi[0] {
                pr.swap_with_slice(qr);
                pi.swap_with_slice(qi);
                sr.swap_with_slice(tr);
                si.swap_with_slice(ti);
            }
            let pivot = Complex::new(pr[0], pi[0]);
            if pivot == Complex::new(0.0, 0.0) {
                // Both candidates zero: column k is already eliminated.
                continue;
            }
            let l = Complex::new(qr[0], qi[0]) / pivot;
            qr[0] = 0.0;
            qi[0] = 0.0;
            axpy_complex(l, &pr[1..], &pi[1..], &mut qr[1..], &mut qi[1..]);
            axpy_complex(l, sr, si, tr, ti);
        }
        // Back substitution with the upper triangle, row by row.
        let mut acc_r = vec![0.0; m];
        let mut acc_i = vec![0.0; m];
        for i in (0..n).rev() {
            let piv = Complex::new(ur[i * n + i], ui[i * n + i]);
            if piv == Complex::new(0.0, 0.0) {
                return None;
            }
            let (row_r, row_i) = (&ur[i * n + i + 1..i * n + n], &ui[i * n + i + 1..i * n + n]);
            for j in 0..m {
                let (d_r, d_i) = if m == 1 {
                    dot_complex(row_r, row_i, &rr[i + 1..], &ri[i + 1..])
                } else {
                    let xr: Vec<f64> = (i + 1..n).map(|jj| rr[jj * m + j]).collect();
                    let xi: Vec<f64> = (i + 1..n).map(|jj| ri[jj * m + j]).collect();
                    dot_complex(row_r, row_i, &xr, &xi)
                };
                acc_r[j] = d_r;
                acc_i[j] = d_i;
            }
            for j in 0..m {
                let v = (Complex::new(rr[i * m + j], ri[i * m + j])
                    - Complex::new(acc_r[j], acc_i[j]))
                    / piv;
                rr[i * m + j] = v.re;
                ri[i * m + j] = v.im;
            }
        }
        Some((rr, ri))
    }
}

/// y ← y − l·x for complex vectors kept as real and imaginary parts.
fn axpy_complex(l: Complex<f64>, xr: &[f64], xi: &[f64], yr: &mut [f64], yi: &mut [f64]) {
    let (lr, li) = (l.re, l.im);
    for (((yr, yi), &xr), &xi) in yr.iter_mut().zip(yi.iter_mut()).zip(xr).zip(xi) {
        *yr -= lr * xr - li * xi;
        *yi -= lr * xi + li * xr;
    }
}

/// Σ aⱼ·bⱼ for complex vectors kept as real and imaginary parts, in four
/// interleaved partial sums (so that it vectorises; the order is fixed, so
/// the result is the same on every run).
fn dot_complex(ar: &[f64], ai: &[f64], br: &[f64], bi: &[f64]) -> (f64, f64) {
    let (mut sr, mut si) = ([0.0f64; 4], [0.0f64; 4]);
    let chunks = ar
        .chunks_exact(4)
        .zip(ai.chunks_exact(4))
        .zip(br.chunks_exact(4))
        .zip(bi.chunks_exact(4));
    for (((xr, xi), yr), yi) in chunks {
        for l in 0..4 {
            sr[l] += xr[l] * yr[l] - xi[l] * yi[l];
            si[l] += xr[l] * yi[l] + xi[l] * yr[l];
        }
    }
    for j in ar.len() - ar.len() % 4..ar.len() {
        sr[0] += ar[j] * br[j] - ai[j] * bi[j];
        si[0] += ar[j] * bi[j] + ai[j] * br[j];
    }
    (
        (sr[0] + sr[1]) + (sr[2] + sr[3]),
        (si[0] + si[1]) + (si[2] + si[3]),
    )
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::lti::linalg::norm_1;
    use crate::rng::Rng;

    /// The old evaluation, kept as the oracle: a dense complex LU of (xI − A).
    fn dense(sys: &StateSpace, x: Complex<f64>) -> DMatrix<Complex<f64>> {
        let n = sys.nstates();
        let mut mat = sys.a.map(|v| Complex::new(-v, 0.0));
        for i in 0..n {
            mat[(i, i)] += x;
        }
        let sol = mat
            .lu()
            .solve(&sys.b.map(|v| Complex::new(v, 0.0)))
            .unwrap();
        sys.c.map(|v| Complex::new(v, 0.0)) * sol + sys.d.map(|v| Complex::new(v, 0.0))
    }

    /// Round-off bound of a backward-stable evaluation at `x`: a few n·ε times
    /// κ₁(xI − A) times ‖C‖ ‖(xI − A)⁻¹‖ ‖B‖ (all 1-norms).
    fn roundoff(sys: &StateSpace, x: Complex<f64>) -> f64 {
        let n = sys.nstates();
        let mut mat = sys.a.map(|v| Complex::new(-v, 0.0));
        for i in 0..n {
            mat[(i, i)] += x;
        }
        let norm1 = |m: &DMatrix<Complex<f64>>| {
            m.column_iter()
                .map(|c| c.iter().map(|v| v.norm()).sum::<f64>())
                .fold(0.0, f64::max)
        };
        let inv = mat.clone().try_inverse().unwrap();
        let kappa = norm1(&mat) * norm1(&inv);
        100.0 * n as f64 * f64::EPSILON * kappa * norm_1(&sys.c) * norm1(&inv) * norm_1(&sys.b)
    }

    fn random_system(rng: &mut Rng, n: usize, p: usize, m: usize, dt: Option<f64>) -> StateSpace {
        StateSpace::new(
            DMatrix::from_fn(n, n, |_, _| rng.uniform_in(-1.0, 1.0)),
            DMatrix::from_fn(n, m, |_, _| rng.uniform_in(-1.0, 1.0)),
            DMatrix::from_fn(p, n, |_, _| rng.uniform_in(-1.0, 1.0)),
            DMatrix::from_fn(p, m, |_, _| rng.uniform_in(-1.0, 1.0)),
            dt,
        )
        .unwrap()
    }

    /// A random orthogonal matrix (QR of a random one).
    fn orthogonal(rng: &mut Rng, n: usize) -> DMatrix<f64> {
        DMatrix::from_fn(n, n, |_, _| rng.uniform_in(-1.0, 1.0))
            .qr()
            .q()
    }

    #[test]
    fn hessenberg_evaluation_matches_the_dense_lu_on_random_systems() {
        let mut rng = Rng::new(29);
        for (case, &(n, p, m)) in [
            (1, 1, 1),
            (2, 1, 1),
            (3, 2, 1),
            (5, 1, 3),
            (12, 2, 2),
            (40, 1, 1),
            (90, 3, 2),
        ]
        .iter()
        .enumerate()
        {
            for dt in [None, Some(0.01)] {
                let sys = random_system(&mut rng, n, p, m, dt);
                let ev = sys.frequency_evaluator().unwrap();
                for k in 0..40 {
                    let x = match (k, dt) {
                        (0, None) => Complex::new(0.0, 0.0),
                        (0, Some(_)) => Complex::new(1.0, 0.0),
                        _ => Complex::new(rng.uniform_in(-3.0, 3.0), rng.uniform_in(-30.0, 30.0)),
                    };
                    let (got, want) = (ev.evalfr(x), dense(&sys, x));
                    let err = (&got - &want).iter().map(|v| v.norm()).fold(0.0, f64::max);
                    let tol = roundoff(&sys, x);
                    assert!(
                        err <= tol,
                        "case {case} n={n} x={x}: |Δ| = {err:e} > {tol:e}"
                    );
                }
            }
        }
    }

    /// Stiff systems (poles from 10⁻³ to 10⁶ rad/s) behind a random orthogonal
    /// similarity: G(s) = Σᵢ (C Q)ᵢ (Qᵀ B)ᵢ / (s − λᵢ) in closed form, with
    /// pairs of complex poles as 2 × 2 blocks.
    #[test]
    fn hessenberg_evaluation_matches_the_closed_form_of_stiff_systems() {
        let mut rng = Rng::new(7);
        for &n in &[6usize, 25, 60, 120] {
            let pairs = n / 3;
            let reals = n - 2 * pairs;
            let mut blk = DMatrix::zeros(n, n);
            let mut modes: Vec<(usize, Complex<f64>)> = Vec::new();
            for i in 0..reals {
                let lam = -10f64.powf(-3.0 + 9.0 * i as f64 / (reals.max(2) - 1) as f64);
                blk[(i, i)] = lam;
                modes.push((i, Complex::new(lam, 0.0)));
            }
            for k in 0..pairs {
                let i = reals + 2 * k;
                let wn = 10f64.powf(-2.0 + 8.0 * k as f64 / (pairs.max(2) - 1) as f64);
                let (sigma, wd) = (-0.01 * wn, wn);
                blk[(i, i)] = sigma;
                blk[(i + 1, i + 1)] = sigma;
                blk[(i, i + 1)] = wd;
                blk[(i + 1, i)] = -wd;
                modes.push((i, Complex::new(sigma, wd)));
            }
            let q = orthogonal(&mut rng, n);
            let b0 = DMatrix::from_fn(n, 1, |_, _| rng.uniform_in(-1.0, 1.0));
            let c0 = DMatrix::from_fn(1, n, |_, _| rng.uniform_in(-1.0, 1.0));
            let sys = StateSpace::new(
                &q * &blk * q.transpose(),
                &q * &b0,
                &c0 * q.transpose(),
                DMatrix::zeros(1, 1),
                None,
            )
            .unwrap();
            // Closed form in the block-diagonal coordinates.
            let closed = |s: Complex<f64>| {
                let mut g = Complex::new(0.0, 0.0);
                for &(i, lam) in &modes {
                    if lam.im == 0.0 {
                        g += c0[(0, i)] * b0[(i, 0)] / (s - lam.re);
                    } else {
                        // [σ ω; −ω σ]: (sI − blk)⁻¹ = [[s−σ, ω], [−ω, s−σ]] / ((s−σ)² + ω²).
                        let (sg, w) = (lam.re, lam.im);
                        let det = (s - sg) * (s - sg) + w * w;
                        let (b1, b2) = (b0[(i, 0)], b0[(i + 1, 0)]);
                        let (c1, c2) = (c0[(0, i)], c0[(0, i + 1)]);
                        let x1 = ((s - sg) * b1 + w * b2) / det;
                        let x2 = (-w * b1 + (s - sg) * b2) / det;
                        g += c1 * x1 + c2 * x2;
                    }
                }
                g
            };
            let ev = sys.frequency_evaluator().unwrap();
            for k in 0..60 {
                let w = 10f64.powf(-4.0 + 11.0 * k as f64 / 59.0);
                let s = Complex::new(0.0, w);
                let want = closed(s);
                let (got, old) = (ev.siso_at(w), dense(&sys, s)[(0, 0)]);
                let tol = roundoff(&sys, s);
                assert!(
                    (got - want).norm() <= tol,
                    "n={n} ω={w:e}: new {got} vs closed form {want} (tol {tol:e})"
                );
                assert!(
                    (old - want).norm() <= tol,
                    "n={n} ω={w:e}: dense {old} vs closed form {want}"
                );
            }
        }
    }

    #[test]
    fn static_and_singular_points() {
        let gain = StateSpace::gain(DMatrix::from_element(2, 3, 1.5), Some(0.1));
        let ev = gain.frequency_evaluator().unwrap();
        assert_eq!(
            ev.at(3.0),
            DMatrix::from_element(2, 3, Complex::new(1.5, 0.0))
        );
        // An integrator 1/s: exactly singular at s = 0, like the dense LU.
        let integ = StateSpace::new(
            DMatrix::zeros(1, 1),
            DMatrix::from_element(1, 1, 1.0),
            DMatrix::from_element(1, 1, 1.0),
            DMatrix::zeros(1, 1),
            None,
        )
        .unwrap();
        let ev = integ.frequency_evaluator().unwrap();
        assert!(ev.siso_at(0.0).re.is_nan());
        assert!(integ.freqresp_siso_at(0.0).re.is_nan());
        assert_eq!(ev.siso_at(2.0), Complex::new(0.0, -0.5));
        let mut bad = integ.clone();
        bad.a[(0, 0)] = f64::NAN;
        assert!(bad.frequency_evaluator().is_err());
    }
}
