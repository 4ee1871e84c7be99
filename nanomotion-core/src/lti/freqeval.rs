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

use super::linalg::{balance, hessenberg_eigvals};
use super::{Complex, LtiError, StateSpace};
use nalgebra::DMatrix;

/// An eigenvalue solver of a real square matrix ([`linalg::eigvals`](super::linalg::eigvals)).
pub(crate) type EigvalsFn = fn(&DMatrix<f64>) -> Vec<Complex<f64>>;

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
    /// Their moduli.
    pole_norms: Vec<f64>,
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
        Self::reduce(sys, None)
    }

    /// The reduction of `sys` with the poles computed from A by `eig` (the
    /// previous implementation of [`hinfnorm`](super::hinfnorm), for its
    /// comparison).
    pub(crate) fn with_eigensolver(sys: &StateSpace, eig: EigvalsFn) -> Self {
        Self::reduce(sys, Some(eig))
    }

    /// The reduction; the poles by `eig`, or by default from the Hessenberg
    /// form itself ([`hessenberg_eigvals`]: no second reduction).
    fn reduce(sys: &StateSpace, eig: Option<EigvalsFn>) -> Self {
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
        let poles = match eig {
            Some(eig) => eig(&sys.a),
            None => hessenberg_eigvals(&mut hr.clone(), n)
                .unwrap_or_else(|| super::linalg::eigvals_fast(&sys.a)),
        };
        Self {
            n,
            h: hr,
            qb: qbr,
            cq,
            d: sys.d.clone(),
            dt: sys.dt,
            model: sys.clone(),
            pole_norms: poles.iter().map(|p| p.norm()).collect(),
            poles,
            a_norm: super::linalg::norm_1(&sys.a),
        }
    }

    /// The eigenvalues of A (poles of the model), in no particular order, by
    /// the eigenvalue-only QR iteration of the Hessenberg form
    /// ([`hessenberg_eigvals`]).
    pub fn poles(&self) -> &[Complex<f64>] {
        &self.poles
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
                    acc += Complex::new(xr[j * n + k], xi[j * n + k]) * self.cq[(i, k)];
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
        let x_norm = x.norm();
        self.poles.iter().zip(&self.pole_norms).any(|(p, &p_norm)| {
            let tol = 1e-4 * x_norm.max(p_norm) + abs;
            (x - p).norm_sqr() <= tol * tol
        })
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

    /// X = (xI − H)⁻¹ Qᵀ B (column-major n × m: column j at j·n, real and
    /// imaginary parts apart so that the row operations vectorise) by the LU
    /// of the Hessenberg matrix xI − H with partial pivoting; `None` when a
    /// pivot is exactly zero (x an eigenvalue, as the dense LU's refusal).
    ///
    /// Only two rows are live during the elimination: the row carried down
    /// from the previous steps and the next row of xI − H, read from H. The
    /// pivot row of each step is appended to the packed upper triangle U (row
    /// k holds columns k..n), the other one, eliminated, is carried on.
    fn solve(&self, x: Complex<f64>) -> Option<(Vec<f64>, Vec<f64>)> {
        let (n, m) = (self.n, self.ninputs());
        let packed = n * (n + 1) / 2;
        let (mut ur, mut ui) = (Vec::with_capacity(packed), Vec::with_capacity(packed));
        let mut rr = vec![0.0; n * m];
        let mut ri = vec![0.0; n * m];
        for j in 0..m {
            for k in 0..n {
                rr[j * n + k] = self.qb[k * m + j];
            }
        }
        // Row k of xI − H, columns k..n, into (vr, vi) at the same positions.
        let row_of = |k: usize, vr: &mut [f64], vi: &mut [f64]| {
            for (v, &h) in vr[k..].iter_mut().zip(&self.h[k * n + k..k * n + n]) {
                *v = -h;
            }
            vi[k..].fill(0.0);
            vr[k] += x.re;
            vi[k] += x.im;
        };
        // The carried row (columns k..n) and its right-hand sides.
        let (mut cr, mut ci) = (vec![0.0; n], vec![0.0; n]);
        let (mut nr, mut ni) = (vec![0.0; n], vec![0.0; n]);
        row_of(0, &mut cr, &mut ci);
        for k in 0..n.saturating_sub(1) {
            // The next row: row k + 1 of xI − H, whose column k is its
            // subdiagonal entry.
            nr[k] = -self.h[(k + 1) * n + k];
            ni[k] = 0.0;
            row_of(k + 1, &mut nr, &mut ni);
            // Pivot: the larger of the two candidates in column k.
            if nr[k] * nr[k] + ni[k] * ni[k] > cr[k] * cr[k] + ci[k] * ci[k] {
                std::mem::swap(&mut cr, &mut nr);
                std::mem::swap(&mut ci, &mut ni);
                for j in 0..m {
                    rr.swap(j * n + k, j * n + k + 1);
                    ri.swap(j * n + k, j * n + k + 1);
                }
            }
            // (cr, ci) is the pivot row, (nr, ni) the row to eliminate.
            let pivot = Complex::new(cr[k], ci[k]);
            if pivot != Complex::new(0.0, 0.0) {
                let l = Complex::new(nr[k], ni[k]) / pivot;
                axpy_complex(
                    l,
                    &cr[k + 1..],
                    &ci[k + 1..],
                    &mut nr[k + 1..],
                    &mut ni[k + 1..],
                );
                for j in 0..m {
                    let (s, t) = (j * n + k, j * n + k + 1);
                    let v = Complex::new(rr[t], ri[t]) - l * Complex::new(rr[s], ri[s]);
                    rr[t] = v.re;
                    ri[t] = v.im;
                }
            }
            // Both candidates zero: column k is already eliminated.
            ur.extend_from_slice(&cr[k..]);
            ui.extend_from_slice(&ci[k..]);
            std::mem::swap(&mut cr, &mut nr);
            std::mem::swap(&mut ci, &mut ni);
        }
        ur.push(cr[n - 1]);
        ui.push(ci[n - 1]);
        // Back substitution with the upper triangle, row by row (row i
        // starts at i·n − i(i − 1)/2).
        for i in (0..n).rev() {
            let start = i * n - i * i.saturating_sub(1) / 2;
            let piv = Complex::new(ur[start], ui[start]);
            if piv == Complex::new(0.0, 0.0) {
                return None;
            }
            let end = start + n - i;
            let (row_r, row_i) = (&ur[start + 1..end], &ui[start + 1..end]);
            for j in 0..m {
                let col = j * n;
                let (d_r, d_i) = dot_complex(
                    row_r,
                    row_i,
                    &rr[col + i + 1..col + n],
                    &ri[col + i + 1..col + n],
                );
                let v = (Complex::new(rr[col + i], ri[col + i]) - Complex::new(d_r, d_i)) / piv;
                rr[col + i] = v.re;
                ri[col + i] = v.im;
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

    /// The poles from the Hessenberg form against nalgebra's Schur form of A
    /// (each pole near one of the other set and the reverse; sums equal the
    /// trace).
    #[test]
    fn poles_from_the_hessenberg_form_match_the_schur_form() {
        let mut rng = Rng::new(2930);
        for &n in &[1usize, 2, 3, 8, 31, 77] {
            let sys = random_system(&mut rng, n, 1, 2, None);
            let ev = sys.frequency_evaluator().unwrap();
            let (got, want) = (ev.poles(), crate::lti::linalg::eigvals(&sys.a));
            assert_eq!(got.len(), n);
            let tol = 1e-9 * norm_1(&sys.a);
            let near = |x: &Complex<f64>, set: &[Complex<f64>]| {
                set.iter()
                    .map(|y| (x - y).norm())
                    .fold(f64::INFINITY, f64::min)
            };
            for p in got {
                assert!(near(p, &want) <= tol, "n={n}: {p} not a pole");
            }
            for p in &want {
                assert!(near(p, got) <= tol, "n={n}: pole {p} missed");
            }
            let trace: f64 = sys.a.trace();
            let sum: Complex<f64> = got.iter().sum();
            assert!((sum.re - trace).abs() <= tol * n as f64 && sum.im.abs() <= tol * n as f64);
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
