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
        let Some(sol) = self.solve(x) else {
            return DMatrix::from_element(p, m, Complex::new(f64::NAN, f64::NAN));
        };
        for j in 0..m {
            for i in 0..p {
                let mut acc = Complex::new(0.0, 0.0);
                for k in 0..n {
                    acc += sol[k * m + j] * self.cq[(i, k)];
                }
                g[(i, j)] += acc;
            }
        }
        g
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

    /// X = (xI − H)⁻¹ Qᵀ B (row-major n × m) by the LU of the Hessenberg
    /// matrix xI − H with partial pivoting; `None` when a pivot is exactly
    /// zero (x an eigenvalue, as the dense LU's refusal).
    fn solve(&self, x: Complex<f64>) -> Option<Vec<Complex<f64>>> {
        let (n, m) = (self.n, self.ninputs());
        let mut u: Vec<Complex<f64>> = self.h.iter().map(|&v| Complex::new(-v, 0.0)).collect();
        for i in 0..n {
            u[i * n + i] += x;
        }
        let mut r: Vec<Complex<f64>> = self.qb.iter().map(|&v| Complex::new(v, 0.0)).collect();
        // Elimination: only row k + 1 has an entry below the diagonal in column k.
        for k in 0..n.saturating_sub(1) {
            let (top, bottom) = u.split_at_mut((k + 1) * n);
            let row_k = &mut top[k * n + k..k * n + n];
            let row_k1 = &mut bottom[k..n];
            if row_k1[0].norm_sqr() > row_k[0].norm_sqr() {
                row_k.swap_with_slice(row_k1);
                let (rt, rb) = r.split_at_mut((k + 1) * m);
                rt[k * m..].swap_with_slice(&mut rb[..m]);
            }
            if row_k[0] == Complex::new(0.0, 0.0) {
                // Both candidates zero: column k is already eliminated.
                continue;
            }
            let l = row_k1[0] / row_k[0];
            row_k1[0] = Complex::new(0.0, 0.0);
            for j in 1..row_k.len() {
                let v = row_k[j];
                row_k1[j] -= l * v;
            }
            let (rt, rb) = r.split_at_mut((k + 1) * m);
            for j in 0..m {
                rb[j] -= l * rt[k * m + j];
            }
        }
        // Back substitution with the upper triangle.
        for i in (0..n).rev() {
            let piv = u[i * n + i];
            if piv == Complex::new(0.0, 0.0) {
                return None;
            }
            let (head, tail) = r.split_at_mut((i + 1) * m);
            let ri = &mut head[i * m..];
            for (jj, uij) in u[i * n + i + 1..i * n + n].iter().enumerate() {
                let xj = &tail[jj * m..jj * m + m];
                for (a, b) in ri.iter_mut().zip(xj) {
                    *a -= uij * b;
                }
            }
            for a in ri.iter_mut() {
                *a /= piv;
            }
        }
        Some(r)
    }
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
        let sol = mat.lu().solve(&sys.b.map(|v| Complex::new(v, 0.0))).unwrap();
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
                        _ => Complex::new(
                            rng.uniform_in(-3.0, 3.0),
                            rng.uniform_in(-30.0, 30.0),
                        ),
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
        assert_eq!(ev.at(3.0), DMatrix::from_element(2, 3, Complex::new(1.5, 0.0)));
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
