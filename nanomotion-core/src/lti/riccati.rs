//! Algebraic Riccati and Lyapunov equations: the stabilising solutions that LQ
//! and H∞ synthesis are built from (SPEC §4: the Ch. 7 mixed-sensitivity design
//! needs two Riccati equations per γ).
//!
//! - [`care`]: AᵀX + XA − (XB + S)R⁻¹(BᵀX + Sᵀ) + Q = 0 with A − BK Hurwitz,
//!   K = R⁻¹(BᵀX + Sᵀ);
//! - [`care_general`]: AᵀX + XA − XGX + Q = 0 with G, Q symmetric and possibly
//!   **indefinite** (the H∞ form G = B₂B₂ᵀ − γ⁻²B₁B₁ᵀ), A − GX Hurwitz;
//! - [`dare`]: AᵀXA − X − (AᵀXB + S)(R + BᵀXB)⁻¹(BᵀXA + Sᵀ) + Q = 0 with A − BK
//!   Schur, K = (R + BᵀXB)⁻¹(BᵀXA + Sᵀ);
//! - [`lyap`] (AᵀX + XA + Q = 0) and [`dlyap`] (AᵀXA − X + Q = 0) by
//!   Bartels–Stewart: balance A, real Schur form A = UTUᵀ, then the
//!   quasi-triangular solve with 1×1/2×2 blocks; O(n³) time, O(n²) memory.
//!
//! # Methods
//!
//! **Scaling.** Every Riccati problem is first scaled by powers of two: x = Dx̃
//! with D from a symplectic balancing of the Hamiltonian [A, G; Q, Aᵀ]
//! (Parlett–Reinsch balancing of the 2n × 2n matrix, D = √(t₁/t₂) so that the
//! similarity diag(D, D⁻¹) keeps the structure), X̃ = σX̂ with σ equilibrating
//! ‖G‖ and ‖Q‖, and for the DARE the inputs scaled to a unit-diagonal R. A
//! stage model with B = [1, 0, ω²]ᵀ and R = 1e-6 then becomes an ordinary
//! problem.
//!
//! **CARE: matrix sign function** (Roberts 1971; determinant scaling, Byers 1987).
//! The Hamiltonian H = [A, −G; −Q, −Aᵀ] has no eigenvalue on the imaginary axis
//! exactly when a stabilising solution can exist; Z ← (cZ + (cZ)⁻¹)/2 with
//! c = |det Z|^(−1/2n) converges quadratically to W = sign(H), and the stable
//! invariant subspace [I; X] satisfies (W + I)[I; X] = 0, i.e.
//! [W₁₂; W₂₂ + I] X = −[W₁₁ + I; W₂₁], solved by least squares.
//!
//! **DARE: structure-preserving doubling** (SDA; Chu, Fan, Lin & Wang 2004) on
//! X = AᵀX(I + GX)⁻¹A + H, G = BR⁻¹Bᵀ, H = Q (after removing S):
//! A ← A(I + GH)⁻¹A, G ← G + A(I + GH)⁻¹GAᵀ, H ← H + AᵀH(I + GH)⁻¹A; H → X
//! quadratically.
//!
//! **Refinement, at every size.** Newton's method (Kleinman for the CARE:
//! (A − GX)ᵀΔ + Δ(A − GX) = −Res(X); Hewer for the DARE: A_cℓᵀΔA_cℓ − Δ +
//! Res(X) = 0), one Bartels–Stewart solve per step, while the residual falls;
//! the DARE's residual is evaluated in the R-form (no R⁻¹).
//!
//! **Fallback: ordered Schur** (Laub 1979). When the sign function or the
//! doubling fails or leaves a residual above round-off, the stable invariant
//! subspace is taken from an ordered Schur form of the Hamiltonian (CARE) or
//! of the symplectic matrix [A + GA⁻ᵀQ, −GA⁻ᵀ; −A⁻ᵀQ, A⁻ᵀ] (DARE, A
//! invertible): nalgebra's real Schur form, made triangular by one unitary
//! rotation per 2×2 block, then reordered by unitary swaps of adjacent
//! diagonal entries. The better of the two answers is kept.
//!
//! Every answer is **checked independently of the method** before it is returned:
//! the residual of the equation itself (relative to the size of its terms, or —
//! for badly scaled data whose terms cancel — against the round-off floor of
//! evaluating the equation, [`RiccatiSolution::backward_error`]) and the
//! eigenvalues of the closed loop. An equation without a stabilising solution
//! is a [`LtiError::Singular`] naming the cause — "(A, B) is not stabilisable"
//! with the unreachable mode, "(Q, A) is not detectable" with the unobservable
//! mode on the axis/circle, and the distance of the Hamiltonian's nearest
//! eigenvalue to the imaginary axis — never a wrong X.
//!
//! ```
//! use nalgebra::DMatrix;
//! use nanomotion_core::lti::riccati::care;
//! // Double integrator, Q = I, R = 1: X = [√3, 1; 1, √3] (closed form).
//! let a = DMatrix::from_row_slice(2, 2, &[0.0, 1.0, 0.0, 0.0]);
//! let b = DMatrix::from_row_slice(2, 1, &[0.0, 1.0]);
//! let sol = care(&a, &b, &DMatrix::identity(2, 2), &DMatrix::identity(1, 1), None).unwrap();
//! assert!((sol.x[(0, 0)] - 3f64.sqrt()).abs() < 1e-12 && (sol.x[(0, 1)] - 1.0).abs() < 1e-12);
//! ```

use super::linalg::{balance, eigvals};
use super::schur::{lyap_quasi_triangular, ordered_schur, real_schur, stein_quasi_triangular};
use super::{Complex, LtiError};
use nalgebra::DMatrix;

/// A stabilising Riccati solution with its gain and the checks it passed.
#[derive(Debug, Clone, PartialEq)]
pub struct RiccatiSolution {
    /// The symmetric stabilising solution X.
    pub x: DMatrix<f64>,
    /// The optimal state-feedback gain K (u = −Kx).
    pub gain: DMatrix<f64>,
    /// Eigenvalues of the closed loop A − BK (Hurwitz for CARE, Schur for DARE).
    pub closed_loop_poles: Vec<Complex<f64>>,
    /// ‖residual‖_F / (sum of the Frobenius norms of the equation's terms).
    pub relative_residual: f64,
    /// Sign-function or doubling iterations used (plus Newton steps).
    pub iterations: usize,
    /// maxᵢⱼ |residualᵢⱼ| / (Σ |term|)ᵢⱼ with the absolute values taken
    /// entrywise (|Aᵀ||X| + |X||A| + |XB||K| + |Q| for the CARE), invariant
    /// under diagonal state scaling: the residual against
    /// the round-off floor of evaluating the equation itself. Badly scaled
    /// problems whose terms cancel have a `relative_residual` far above
    /// machine precision even for the exact X; this stays near 1e-16.
    pub backward_error: f64,
}

/// The stabilising solution of the general CARE AᵀX + XA − XGX + Q = 0
/// ([`care_general_solution`]) with the checks it passed: the same fields as
/// [`RiccatiSolution`] except the gain (there is no B and R here; the
/// closed loop is A − GX).
#[derive(Debug, Clone, PartialEq)]
pub struct CareGeneralSolution {
    /// The symmetric stabilising solution X.
    pub x: DMatrix<f64>,
    /// Eigenvalues of the closed loop A − GX (all in the open left half plane).
    pub closed_loop_poles: Vec<Complex<f64>>,
    /// ‖AᵀX + XA − XGX + Q‖_F / (2‖AᵀX‖_F + ‖XGX‖_F + ‖Q‖_F).
    pub relative_residual: f64,
    /// Sign-function iterations plus Newton steps used (0 when X = 0 is exact,
    /// Q = 0 with A Hurwitz).
    pub iterations: usize,
    /// maxᵢⱼ |residualᵢⱼ| / (|Aᵀ||X| + |X||A| + |X||G||X| + |Q|)ᵢⱼ: the residual
    /// against the round-off floor of evaluating the equation (see
    /// [`RiccatiSolution::backward_error`]).
    pub backward_error: f64,
}

/// The solution of a Lyapunov equation ([`lyap_solution`]: AᵀX + XA + Q = 0;
/// [`dlyap_solution`]: AᵀXA − X + Q = 0) with its residual, in the layout of
/// [`RiccatiSolution`].
#[derive(Debug, Clone, PartialEq)]
pub struct LyapunovSolution {
    /// The symmetric solution X.
    pub x: DMatrix<f64>,
    /// ‖residual‖_F / (sum of the Frobenius norms of the equation's terms):
    /// 2‖AᵀX‖ + ‖Q‖ (continuous), ‖AᵀXA‖ + ‖X‖ + ‖Q‖ (discrete).
    pub relative_residual: f64,
    /// Steps of iterative refinement taken after the Bartels–Stewart solve
    /// (X ← X + Δ with Δ solving the same equation for the residual; at most
    /// two, only while the backward error is above round-off and falls).
    pub iterations: usize,
    /// maxᵢⱼ |residualᵢⱼ| / (Σ |term|)ᵢⱼ with entrywise absolute values
    /// (|Aᵀ||X| + |X||A| + |Q|, or |Aᵀ||X||A| + |X| + |Q|): the residual
    /// against the round-off floor of evaluating the equation.
    pub backward_error: f64,
}

/// Largest accepted relative residual before a solution is refused.
const RESIDUAL_TOL: f64 = 1e-8;
const MAX_ITERATIONS: usize = 100;
/// A solution whose relative residual exceeds [`RESIDUAL_TOL`] is still
/// accepted when its residual is at the round-off floor of evaluating the
/// equation (backward error below this).
const BACKWARD_TOL: f64 = 1e-12;

fn check_square(name: &'static str, m: &DMatrix<f64>, n: usize) -> Result<(), LtiError> {
    if m.nrows() != n || m.ncols() != n {
        return Err(LtiError::Dimension(format!(
            "`{name}` is {}×{}, expected {n}×{n}",
            m.nrows(),
            m.ncols()
        )));
    }
    finite(name, m)
}

fn finite(name: &'static str, m: &DMatrix<f64>) -> Result<(), LtiError> {
    if m.iter().all(|v| v.is_finite()) {
        Ok(())
    } else {
        Err(LtiError::param(name, "has a non-finite entry"))
    }
}

fn check_symmetric(name: &'static str, m: &DMatrix<f64>) -> Result<(), LtiError> {
    let asym = (m - m.transpose()).norm();
    if asym > 1e-10 * m.norm().max(1e-300) {
        return Err(LtiError::param(
            name,
            format!("must be symmetric (‖M − Mᵀ‖ = {asym:.3e}); pass (M + Mᵀ)/2"),
        ));
    }
    Ok(())
}

fn symmetrise(m: &DMatrix<f64>) -> DMatrix<f64> {
    (m + m.transpose()) * 0.5
}

/// The dimensions of (A, B, Q, R, S) and the symmetry of Q and R.
fn check_lq(
    a: &DMatrix<f64>,
    b: &DMatrix<f64>,
    q: &DMatrix<f64>,
    r: &DMatrix<f64>,
    s: Option<&DMatrix<f64>>,
) -> Result<(usize, usize), LtiError> {
    let n = a.nrows();
    check_square("a", a, n)?;
    finite("b", b)?;
    if b.nrows() != n {
        return Err(LtiError::Dimension(format!(
            "`b` has {} rows, A is {n}×{n}",
            b.nrows()
        )));
    }
    let m = b.ncols();
    check_square("q", q, n)?;
    check_square("r", r, m)?;
    check_symmetric("q", q)?;
    check_symmetric("r", r)?;
    if let Some(s) = s {
        finite("s", s)?;
        if s.nrows() != n || s.ncols() != m {
            return Err(LtiError::Dimension(format!(
                "`s` is {}×{}, expected {n}×{m} (like B)",
                s.nrows(),
                s.ncols()
            )));
        }
    }
    Ok((n, m))
}

/// R⁻¹ by Cholesky: R must be positive definite.
fn inverse_pd(name: &'static str, r: &DMatrix<f64>) -> Result<DMatrix<f64>, LtiError> {
    r.clone()
        .cholesky()
        .map(|c| c.inverse())
        .ok_or_else(|| LtiError::param(name, "must be positive definite"))
}

/// Remove the cross term: A − BR⁻¹Sᵀ and Q − SR⁻¹Sᵀ (same X, same closed loop).
fn without_cross_term(
    a: &DMatrix<f64>,
    b: &DMatrix<f64>,
    q: &DMatrix<f64>,
    r_inv: &DMatrix<f64>,
    s: Option<&DMatrix<f64>>,
) -> (DMatrix<f64>, DMatrix<f64>) {
    match s {
        Some(s) => (
            a - b * r_inv * s.transpose(),
            symmetrise(&(q - s * r_inv * s.transpose())),
        ),
        None => (a.clone(), q.clone()),
    }
}

/// Checks of (A, B, Q, R, S), R⁻¹ and the problem without cross term:
/// (n, R⁻¹, A − BR⁻¹Sᵀ, Q − SR⁻¹Sᵀ).
type PreparedLq = (usize, DMatrix<f64>, DMatrix<f64>, DMatrix<f64>);

fn prepare_lq(
    a: &DMatrix<f64>,
    b: &DMatrix<f64>,
    q: &DMatrix<f64>,
    r: &DMatrix<f64>,
    s: Option<&DMatrix<f64>>,
) -> Result<PreparedLq, LtiError> {
    let (n, _) = check_lq(a, b, q, r, s)?;
    let r_inv = inverse_pd("r", r)?;
    let (a0, q0) = without_cross_term(a, b, q, &r_inv, s);
    Ok((n, r_inv, a0, q0))
}

/// Continuous algebraic Riccati equation with cross term `s` (see the
/// [module docs](self)); `r` must be positive definite.
pub fn care(
    a: &DMatrix<f64>,
    b: &DMatrix<f64>,
    q: &DMatrix<f64>,
    r: &DMatrix<f64>,
    s: Option<&DMatrix<f64>>,
) -> Result<RiccatiSolution, LtiError> {
    let (_, r_inv, a0, q0) = prepare_lq(a, b, q, r, s)?;
    let g = symmetrise(&(b * &r_inv * b.transpose()));
    let (x, iterations) = care_general(&a0, &g, &q0)?;
    let xb_s = match s {
        Some(s) => &x * b + s,
        None => &x * b,
    };
    let gain = &r_inv * xb_s.transpose();
    let acl = a - b * &gain;
    let res = a.transpose() * &x + &x * a - &xb_s * &gain + q;
    let scale = (a.transpose() * &x).norm() * 2.0 + (&xb_s * &gain).norm() + q.norm();
    let ax_abs = a.transpose().abs() * x.abs();
    // |XB + S| ≤ |X||B| + |S|, |K| ≤ |R⁻¹|(|Bᵀ||X| + |Sᵀ|).
    let xb_abs = match s {
        Some(s) => x.abs() * b.abs() + s.abs(),
        None => x.abs() * b.abs(),
    };
    let floor = &ax_abs + ax_abs.transpose() + &xb_abs * r_inv.abs() * xb_abs.transpose() + q.abs();
    Ok(RiccatiSolution {
        closed_loop_poles: eigvals(&acl),
        relative_residual: res.norm() / scale.max(f64::MIN_POSITIVE),
        backward_error: componentwise(&res, &floor),
        x,
        gain,
        iterations,
    })
}

/// AᵀX + XA − XGX + Q = 0 for symmetric G, Q (either may be indefinite): the
/// stabilising X (A − GX Hurwitz). Returns X and the iterations used (sign
/// function steps plus Newton steps).
///
/// The problem is first scaled (a symplectic diagonal balancing of the
/// Hamiltonian, then X = σX̂ to equilibrate ‖G‖ and ‖Q‖, all by powers of two),
/// solved by the matrix sign function, refined by Newton's method (one
/// Lyapunov equation per step), and solved again by the ordered Schur method
/// when the sign function fails or leaves a residual above 1e-13.
///
/// Kept for its callers; [`care_general_solution`] returns the same X with its
/// residual, backward error and closed-loop poles.
pub fn care_general(
    a: &DMatrix<f64>,
    g: &DMatrix<f64>,
    q: &DMatrix<f64>,
) -> Result<(DMatrix<f64>, usize), LtiError> {
    care_general_solution(a, g, q).map(|s| (s.x, s.iterations))
}

/// [`care_general`] returning a [`CareGeneralSolution`]: X with its relative
/// residual, backward error, iterations and the poles of A − GX, as [`care`]
/// and [`dare`] return a [`RiccatiSolution`].
///
/// ```
/// use nanomotion_core::nalgebra::DMatrix;
/// use nanomotion_core::lti::care_general_solution;
/// // 2ax − gx² + q = 0 with a = 1, g = 1, q = 0: the stabilising root x = 2.
/// let one = DMatrix::from_element(1, 1, 1.0);
/// let sol = care_general_solution(&one, &one, &DMatrix::zeros(1, 1)).unwrap();
/// assert!((sol.x[(0, 0)] - 2.0).abs() < 1e-12);
/// assert!(sol.backward_error < 1e-14 && sol.closed_loop_poles[0].re < 0.0);
/// ```
pub fn care_general_solution(
    a: &DMatrix<f64>,
    g: &DMatrix<f64>,
    q: &DMatrix<f64>,
) -> Result<CareGeneralSolution, LtiError> {
    let n = a.nrows();
    check_square("a", a, n)?;
    check_square("g", g, n)?;
    check_square("q", q, n)?;
    check_symmetric("g", g)?;
    check_symmetric("q", q)?;
    if n == 0 {
        return Ok(CareGeneralSolution {
            x: DMatrix::zeros(0, 0),
            closed_loop_poles: Vec::new(),
            relative_residual: 0.0,
            iterations: 0,
            backward_error: 0.0,
        });
    }
    // Q = 0 with A Hurwitz: X = 0 is the stabilising solution, exactly (A − G·0 =
    // A). The sign iteration would return round-off instead, which no relative
    // residual can judge (every term of the equation is then round-off too).
    // This is the Y equation of every mixed-sensitivity H∞ problem with y = e.
    // (Q must be exactly zero: any threshold relative to A or G would depend on
    // the problem's scaling, X ↦ tX, G ↦ G/t, Q ↦ tQ.)
    if q.iter().all(|v| *v == 0.0) {
        let poles = eigvals(a);
        if poles.iter().all(|l| l.re < 0.0) {
            return Ok(CareGeneralSolution {
                x: DMatrix::zeros(n, n),
                closed_loop_poles: poles,
                relative_residual: 0.0,
                iterations: 0,
                backward_error: 0.0,
            });
        }
    }
    let g = symmetrise(g);
    let q = symmetrise(q);
    let sc = Scaling::new(a, &g, &q);
    let (a_s, g_s, q_s) = sc.apply(a, &g, &q);
    let stabilising = |x: &DMatrix<f64>| {
        eigvals(&(&a_s - &g_s * x))
            .iter()
            .all(|p| p.re < 0.0 && p.re.is_finite())
    };
    let mut best: Option<(DMatrix<f64>, f64, usize)> = None;
    let mut reasons = Vec::new();
    match care_sign(&a_s, &g_s, &q_s) {
        Ok((x, it)) => {
            let (x, rel, steps) = care_newton(&a_s, &g_s, &q_s, x, 6);
            if stabilising(&x) {
                best = Some((x, rel, it + steps));
            } else {
                reasons.push("the sign function's solution is not stabilising".to_string());
            }
        }
        Err(why) => reasons.push(why),
    }
    if best
        .as_ref()
        .is_none_or(|b| b.1 > 1e-13 && care_backward(&a_s, &g_s, &q_s, &b.0) > 1e-14)
    {
        tracing::debug!(
            target: "nanomotion_core::lti::riccati",
            n = a_s.nrows(),
            reasons = %reasons.join("; "),
            "CARE: sign iteration not accurate enough; trying the ordered Schur method"
        );
        match care_schur(&a_s, &g_s, &q_s) {
            Ok(x) => {
                let (x, rel, steps) = care_newton(&a_s, &g_s, &q_s, x, 6);
                if stabilising(&x) && best.as_ref().is_none_or(|b| rel < b.1) {
                    best = Some((x, rel, steps));
                }
            }
            Err(why) => reasons.push(why),
        }
    }
    let fail = |reasons: &[String]| {
        let mut causes = diagnose(&a_s, &g_s, &q_s, false);
        let h = hamiltonian(&a_s, &g_s, &q_s);
        let hn = h.norm();
        let dist = eigvals(&h)
            .iter()
            .map(|l| l.re.abs())
            .fold(f64::INFINITY, f64::min);
        causes.extend(reasons.iter().cloned());
        causes.push(format!(
            "the Hamiltonian's eigenvalue nearest the imaginary axis is at distance {dist:.2e} (relative {:.2e}; scaled ‖H‖ = {hn:.2e})",
            dist / hn.max(f64::MIN_POSITIVE)
        ));
        LtiError::Singular(format!(
            "CARE has no stabilising solution: {}",
            causes.join("; ")
        ))
    };
    let Some((xs, _, iterations)) = best else {
        return Err(fail(&reasons));
    };
    let x = sc.unscale(&xs);
    // A last Newton step on the unscaled data removes the scaling's round-off.
    let (x, rel, _) = care_newton(a, &g, &q, x, 2);
    let backward = care_backward(a, &g, &q, &x);
    if rel.is_nan() || (rel > RESIDUAL_TOL && backward > BACKWARD_TOL) {
        reasons.push(format!(
            "relative residual {rel:.2e} (backward error {backward:.2e})"
        ));
        return Err(fail(&reasons));
    }
    let poles = eigvals(&(a - &g * &x));
    let worst = poles.iter().map(|p| p.re).fold(f64::NEG_INFINITY, f64::max);
    if worst.is_nan() || worst >= 0.0 {
        reasons.push(format!(
            "the closed loop A − GX has an eigenvalue with real part {worst:.3e}"
        ));
        return Err(fail(&reasons));
    }
    Ok(CareGeneralSolution {
        x,
        closed_loop_poles: poles,
        relative_residual: rel,
        iterations,
        backward_error: backward,
    })
}

/// Powers of two (exact scalings) nearest to `v`.
fn pow2(v: f64) -> f64 {
    if v.is_finite() && v > 0.0 {
        2f64.powi(v.log2().round().clamp(-500.0, 500.0) as i32)
    } else {
        1.0
    }
}

/// Scaling of a Riccati problem: x = D x̃ (D diagonal) and X̃ = DXD = σX̂, so
/// Ã = D⁻¹AD, G̃ = σD⁻¹GD⁻¹, Q̃ = DQD/σ — the same X̂ for the CARE and the
/// DARE. D is a symplectic balancing of the Hamiltonian [A, G; Q, Aᵀ]
/// (Parlett–Reinsch on the 2n × 2n matrix, then D = √(t₁/t₂) so that the
/// similarity diag(D, D⁻¹) keeps its structure); σ equilibrates ‖G̃‖ and ‖Q̃‖.
struct Scaling {
    d: Vec<f64>,
    sigma: f64,
}

impl Scaling {
    fn new(a: &DMatrix<f64>, g: &DMatrix<f64>, q: &DMatrix<f64>) -> Self {
        let n = a.nrows();
        let mut h = DMatrix::zeros(2 * n, 2 * n);
        h.view_mut((0, 0), (n, n)).copy_from(&a.abs());
        h.view_mut((0, n), (n, n)).copy_from(&g.abs());
        h.view_mut((n, 0), (n, n)).copy_from(&q.abs());
        h.view_mut((n, n), (n, n)).copy_from(&a.transpose().abs());
        let (_, t) = balance(&h);
        let d: Vec<f64> = (0..n).map(|i| pow2((t[i] / t[n + i]).sqrt())).collect();
        let gn = DMatrix::from_fn(n, n, |i, j| g[(i, j)] / (d[i] * d[j])).norm();
        let qn = DMatrix::from_fn(n, n, |i, j| q[(i, j)] * d[i] * d[j]).norm();
        let sigma = if gn > 0.0 && qn > 0.0 {
            pow2((qn / gn).sqrt())
        } else {
            1.0
        };
        Scaling { d, sigma }
    }

    /// (Ã, G̃, Q̃).
    fn apply(
        &self,
        a: &DMatrix<f64>,
        g: &DMatrix<f64>,
        q: &DMatrix<f64>,
    ) -> (DMatrix<f64>, DMatrix<f64>, DMatrix<f64>) {
        let (d, s) = (&self.d, self.sigma);
        let n = d.len();
        (
            DMatrix::from_fn(n, n, |i, j| a[(i, j)] * d[j] / d[i]),
            DMatrix::from_fn(n, n, |i, j| g[(i, j)] * s / (d[i] * d[j])),
            DMatrix::from_fn(n, n, |i, j| q[(i, j)] * d[i] * d[j] / s),
        )
    }

    /// X = σD⁻¹X̂D⁻¹.
    fn unscale(&self, xs: &DMatrix<f64>) -> DMatrix<f64> {
        let d = &self.d;
        let n = d.len();
        DMatrix::from_fn(n, n, |i, j| xs[(i, j)] * self.sigma / (d[i] * d[j]))
    }
}

fn hamiltonian(a: &DMatrix<f64>, g: &DMatrix<f64>, q: &DMatrix<f64>) -> DMatrix<f64> {
    let n = a.nrows();
    let mut h = DMatrix::zeros(2 * n, 2 * n);
    h.view_mut((0, 0), (n, n)).copy_from(a);
    h.view_mut((0, n), (n, n)).copy_from(&(-g));
    h.view_mut((n, 0), (n, n)).copy_from(&(-q));
    h.view_mut((n, n), (n, n)).copy_from(&(-a.transpose()));
    h
}

/// The structural causes of a missing stabilising solution, named: modes of A
/// in the closed right half plane (outside the open unit disc) that G cannot
/// reach, and modes on the imaginary axis (unit circle) that Q does not see.
fn diagnose(a: &DMatrix<f64>, g: &DMatrix<f64>, q: &DMatrix<f64>, discrete: bool) -> Vec<String> {
    let n = a.nrows();
    let an = a.norm().max(f64::MIN_POSITIVE);
    let scale = an + g.norm() + q.norm();
    let mut causes = Vec::new();
    let smin = |m: DMatrix<Complex<f64>>| m.singular_values().min();
    let show = |l: Complex<f64>| format!("{:.6} + {:.6}i", l.re, l.im);
    for l in eigvals(a) {
        if l.im < 0.0 || !l.re.is_finite() {
            continue;
        }
        let (unstable, on_boundary) = if discrete {
            (l.norm() >= 1.0 - 1e-10, (l.norm() - 1.0).abs() <= 1e-8)
        } else {
            (l.re >= -1e-10 * an, l.re.abs() <= 1e-8 * an)
        };
        if !unstable {
            continue;
        }
        let shifted = a.map(|v| Complex::new(v, 0.0)) - DMatrix::<Complex<f64>>::identity(n, n) * l;
        let mut ctrb = DMatrix::zeros(n, 2 * n);
        ctrb.view_mut((0, 0), (n, n)).copy_from(&shifted);
        ctrb.view_mut((0, n), (n, n))
            .copy_from(&g.map(|v| Complex::new(v, 0.0)));
        let reach = smin(ctrb);
        if reach <= 1e-9 * scale {
            causes.push(format!(
                "(A, B) is not stabilisable: the mode λ = {} is not reachable from the input (PBH distance {reach:.1e})",
                show(l)
            ));
        }
        if on_boundary {
            let mut obsv = DMatrix::zeros(2 * n, n);
            obsv.view_mut((0, 0), (n, n)).copy_from(&shifted);
            obsv.view_mut((n, 0), (n, n))
                .copy_from(&q.map(|v| Complex::new(v, 0.0)));
            let seen = smin(obsv);
            if seen <= 1e-9 * scale {
                causes.push(format!(
                    "(Q, A) is not detectable: the mode λ = {} on the {} is not seen by Q (PBH distance {seen:.1e})",
                    show(l),
                    if discrete { "unit circle" } else { "imaginary axis" }
                ));
            }
        }
    }
    causes
}

/// The graph [I; X] of the first n columns of an ordered (complex) Schur
/// basis: X = U₂U₁⁻¹, real up to round-off.
fn graph(u: &DMatrix<Complex<f64>>, n: usize) -> Result<DMatrix<f64>, String> {
    let u1 = u.view((0, 0), (n, n)).clone_owned();
    let u2 = u.view((n, 0), (n, n)).clone_owned();
    let sv = u1.singular_values();
    let (smax, smin) = (sv.max(), sv.min());
    if smin <= 1e-14 * smax || !smin.is_finite() {
        return Err(format!(
            "the stable subspace is not a graph [I; X] (conditioning {:.1e})",
            smin / smax
        ));
    }
    // X U₁ = U₂ ⇔ U₁ᵀ Xᵀ = U₂ᵀ.
    let xt = u1
        .transpose()
        .lu()
        .solve(&u2.transpose())
        .ok_or_else(|| "U₁ is singular".to_string())?;
    Ok(symmetrise(&xt.transpose().map(|z| z.re)))
}

/// The stabilising CARE solution by the ordered Schur form of the Hamiltonian
/// (Laub 1979): the n eigenvalues with negative real part first.
fn care_schur(
    a: &DMatrix<f64>,
    g: &DMatrix<f64>,
    q: &DMatrix<f64>,
) -> Result<DMatrix<f64>, String> {
    let n = a.nrows();
    let h = hamiltonian(a, g, q);
    let (u, k, eig) = ordered_schur(&h, |l| l.re < 0.0)
        .ok_or_else(|| "the Schur form of the Hamiltonian did not converge".to_string())?;
    if k != n {
        let dist = eig.iter().map(|l| l.re.abs()).fold(f64::INFINITY, f64::min);
        return Err(format!(
            "the Hamiltonian has {k} eigenvalues in the open left half plane instead of {n} (eigenvalue on the imaginary axis at distance {dist:.1e})"
        ));
    }
    graph(&u, n)
}

/// ‖AᵀX + XA − XGX + Q‖ relative to the terms, and the residual.
fn care_residual(
    a: &DMatrix<f64>,
    g: &DMatrix<f64>,
    q: &DMatrix<f64>,
    x: &DMatrix<f64>,
) -> (f64, DMatrix<f64>) {
    let ax = a.transpose() * x;
    let xgx = x * g * x;
    let res = &ax + ax.transpose() - &xgx + q;
    let scale = ax.norm() * 2.0 + xgx.norm() + q.norm();
    (res.norm() / scale.max(f64::MIN_POSITIVE), res)
}

/// AᵀX + XA − XGX + Q against the round-off floor of its evaluation,
/// |Aᵀ||X| + |X||A| + |X||G||X| + |Q|, entry by entry.
fn care_backward(a: &DMatrix<f64>, g: &DMatrix<f64>, q: &DMatrix<f64>, x: &DMatrix<f64>) -> f64 {
    let (_, res) = care_residual(a, g, q, x);
    let ax = a.transpose().abs() * x.abs();
    let floor = &ax + ax.transpose() + x.abs() * g.abs() * x.abs() + q.abs();
    componentwise(&res, &floor)
}

/// maxᵢⱼ |Rᵢⱼ| / Fᵢⱼ (entries of F below ε·max F count as ε·max F): the
/// componentwise backward error, invariant under diagonal scaling.
fn componentwise(res: &DMatrix<f64>, floor: &DMatrix<f64>) -> f64 {
    let fmax = floor.amax().max(f64::MIN_POSITIVE);
    res.iter()
        .zip(floor.iter())
        .map(|(r, f)| r.abs() / f.max(f64::EPSILON * fmax))
        .fold(0.0, f64::max)
}

/// Newton's method on the CARE from `x`: (A − GX)ᵀΔ + Δ(A − GX) = −Res(X),
/// X ← X + Δ, while the residual falls (at most `steps` steps). Returns X,
/// its relative residual and the steps taken.
fn care_newton(
    a: &DMatrix<f64>,
    g: &DMatrix<f64>,
    q: &DMatrix<f64>,
    mut x: DMatrix<f64>,
    steps: usize,
) -> (DMatrix<f64>, f64, usize) {
    let (mut rel, mut res) = care_residual(a, g, q, &x);
    let mut taken = 0;
    for _ in 0..steps {
        if rel <= 1e-16 || !rel.is_finite() {
            break;
        }
        let acl = a - g * &x;
        let Ok(delta) = lyap_unchecked(&acl, &symmetrise(&res)) else {
            break;
        };
        let candidate = symmetrise(&(&x + delta));
        let (rel_c, res_c) = care_residual(a, g, q, &candidate);
        if rel_c.is_nan() || rel_c >= rel {
            break;
        }
        x = candidate;
        rel = rel_c;
        res = res_c;
        taken += 1;
    }
    (x, rel, taken)
}

/// The stabilising CARE solution by the matrix sign function (see the module
/// docs), or why it failed.
fn care_sign(
    a: &DMatrix<f64>,
    g: &DMatrix<f64>,
    q: &DMatrix<f64>,
) -> Result<(DMatrix<f64>, usize), String> {
    let n = a.nrows();
    let mut z = hamiltonian(a, g, q);
    let mut iterations = 0;
    let mut converged = false;
    let mut last_change = f64::INFINITY;
    while iterations < MAX_ITERATIONS {
        iterations += 1;
        let lu = z.clone().lu();
        let det = lu.determinant();
        let inv = lu
            .try_inverse()
            .ok_or_else(|| "the sign iteration met a singular matrix".to_string())?;
        // Determinant scaling while far from convergence; plain Newton after.
        let c = if det.is_finite() && det != 0.0 && iterations <= 20 {
            det.abs().powf(-1.0 / (2 * n) as f64)
        } else {
            1.0
        };
        let next = (&z * c + inv / c) * 0.5;
        if !next.iter().all(|v| v.is_finite()) {
            return Err("the sign iteration diverged".into());
        }
        let change = (&next - &z).norm();
        let size = next.norm();
        z = next;
        // Converged, or stagnating at round-off level (quadratic convergence
        // stops shrinking the change once it reaches the noise).
        if change <= 1e-13 * size || (change <= 1e-8 * size && change >= last_change) {
            converged = true;
            break;
        }
        last_change = change;
    }
    if !converged {
        return Err(format!(
            "the sign iteration did not converge in {MAX_ITERATIONS} steps"
        ));
    }
    // (W + I)[I; X] = 0: [W₁₂; W₂₂ + I] X = −[W₁₁ + I; W₂₁].
    let ident = DMatrix::<f64>::identity(n, n);
    let mut lhs = DMatrix::zeros(2 * n, n);
    lhs.view_mut((0, 0), (n, n))
        .copy_from(&z.view((0, n), (n, n)));
    lhs.view_mut((n, 0), (n, n))
        .copy_from(&(z.view((n, n), (n, n)) + &ident));
    let mut rhs = DMatrix::zeros(2 * n, n);
    rhs.view_mut((0, 0), (n, n))
        .copy_from(&(-(z.view((0, 0), (n, n)) + &ident)));
    rhs.view_mut((n, 0), (n, n))
        .copy_from(&(-z.view((n, 0), (n, n))));
    let svd = lhs.svd(true, true);
    let smax = svd.singular_values.max();
    let smin = svd.singular_values.min();
    if smin <= 1e-10 * smax {
        return Err(format!(
            "the sign function's stable subspace is not a graph [I; X] (conditioning {:.1e})",
            smin / smax
        ));
    }
    let x = svd
        .solve(&rhs, 0.0)
        .map_err(|e| format!("least squares failed: {e}"))?;
    Ok((symmetrise(&x), iterations))
}

/// DARE residual in the R-form (no R⁻¹): AᵀXA − X − AᵀXB(R + BᵀXB)⁻¹BᵀXA + Q,
/// relative to its terms; also the gain K = (R + BᵀXB)⁻¹BᵀXA.
fn dare_residual(
    a: &DMatrix<f64>,
    b: &DMatrix<f64>,
    q: &DMatrix<f64>,
    r: &DMatrix<f64>,
    x: &DMatrix<f64>,
) -> Option<(f64, DMatrix<f64>, DMatrix<f64>)> {
    let xa = x * a;
    let axa = a.transpose() * &xa;
    let bxa = b.transpose() * &xa;
    let k = (r + b.transpose() * x * b).lu().solve(&bxa)?;
    let quad = bxa.transpose() * &k;
    let res = &axa - x - &quad + q;
    let scale = axa.norm() + x.norm() + quad.norm() + q.norm();
    Some((
        res.norm() / scale.max(f64::MIN_POSITIVE),
        symmetrise(&res),
        k,
    ))
}

/// Newton's method (Hewer) on the DARE: (A − BK)ᵀΔ(A − BK) − Δ + Res(X) = 0,
/// X ← X + Δ, while the residual falls.
fn dare_newton(
    a: &DMatrix<f64>,
    b: &DMatrix<f64>,
    q: &DMatrix<f64>,
    r: &DMatrix<f64>,
    mut x: DMatrix<f64>,
    steps: usize,
) -> (DMatrix<f64>, f64, usize) {
    let Some((mut rel, mut res, mut k)) = dare_residual(a, b, q, r, &x) else {
        return (x, f64::INFINITY, 0);
    };
    let mut taken = 0;
    for _ in 0..steps {
        if rel <= 1e-16 || !rel.is_finite() {
            break;
        }
        let acl = a - b * &k;
        let Ok(delta) = dlyap_core(&acl, &res, false) else {
            break;
        };
        let candidate = symmetrise(&(&x + delta));
        let Some((rel_c, res_c, k_c)) = dare_residual(a, b, q, r, &candidate) else {
            break;
        };
        if rel_c.is_nan() || rel_c >= rel {
            break;
        }
        (x, rel, res, k) = (candidate, rel_c, res_c, k_c);
        taken += 1;
    }
    (x, rel, taken)
}

/// Structure-preserving doubling on X = AᵀX(I + GX)⁻¹A + H (module docs).
fn dare_sda(
    a: &DMatrix<f64>,
    g: &DMatrix<f64>,
    h: &DMatrix<f64>,
) -> Result<(DMatrix<f64>, usize), String> {
    let n = a.nrows();
    let ident = DMatrix::<f64>::identity(n, n);
    let mut ak = a.clone();
    let mut gk = g.clone();
    let mut hk = h.clone();
    let mut iterations = 0;
    let mut converged = false;
    let mut last_change = f64::INFINITY;
    while !converged && iterations < MAX_ITERATIONS {
        iterations += 1;
        let w = (&ident + &gk * &hk)
            .lu()
            .try_inverse()
            .ok_or_else(|| "I + G_k H_k became singular".to_string())?;
        let a_next = &ak * &w * &ak;
        let g_next = symmetrise(&(&gk + &ak * &w * &gk * ak.transpose()));
        let h_next = symmetrise(&(&hk + ak.transpose() * &hk * &w * &ak));
        if !h_next.iter().all(|v| v.is_finite()) || !g_next.iter().all(|v| v.is_finite()) {
            return Err("the doubling iteration diverged".into());
        }
        let change = (&h_next - &hk).norm();
        let size = h_next.norm().max(f64::MIN_POSITIVE);
        converged = change <= 1e-14 * size || (change <= 1e-8 * size && change >= last_change);
        last_change = change;
        ak = a_next;
        gk = g_next;
        hk = h_next;
    }
    if !converged {
        return Err(format!(
            "the doubling iteration did not converge in {MAX_ITERATIONS} steps"
        ));
    }
    Ok((hk, iterations))
}

/// The stabilising DARE solution by the ordered Schur form of the symplectic
/// matrix Z = [A + GA⁻ᵀQ, −GA⁻ᵀ; −A⁻ᵀQ, A⁻ᵀ] (Laub 1979; Z[I; X] = [I; X](I +
/// GX)⁻¹A): the n eigenvalues inside the unit circle first. Needs A
/// invertible.
fn dare_schur(
    a: &DMatrix<f64>,
    g: &DMatrix<f64>,
    q: &DMatrix<f64>,
) -> Result<DMatrix<f64>, String> {
    let n = a.nrows();
    let sv = a.singular_values();
    if sv.min() <= 1e-12 * sv.max() {
        return Err(
            "A is (nearly) singular, so the symplectic-matrix Schur method does not apply".into(),
        );
    }
    let ait = a
        .transpose()
        .lu()
        .try_inverse()
        .ok_or_else(|| "A is singular".to_string())?;
    let mut z = DMatrix::zeros(2 * n, 2 * n);
    z.view_mut((0, 0), (n, n)).copy_from(&(a + g * &ait * q));
    z.view_mut((0, n), (n, n)).copy_from(&(-(g * &ait)));
    z.view_mut((n, 0), (n, n)).copy_from(&(-(&ait * q)));
    z.view_mut((n, n), (n, n)).copy_from(&ait);
    let (u, k, eig) = ordered_schur(&z, |l| l.norm() < 1.0)
        .ok_or_else(|| "the Schur form of the symplectic matrix did not converge".to_string())?;
    if k != n {
        let dist = eig
            .iter()
            .map(|l| (l.norm() - 1.0).abs())
            .fold(f64::INFINITY, f64::min);
        return Err(format!(
            "the symplectic matrix has {k} eigenvalues inside the unit circle instead of {n} (eigenvalue on the unit circle at distance {dist:.1e})"
        ));
    }
    graph(&u, n)
}

/// Discrete algebraic Riccati equation with cross term `s` (see the
/// [module docs](self)); `r` must be positive definite.
pub fn dare(
    a: &DMatrix<f64>,
    b: &DMatrix<f64>,
    q: &DMatrix<f64>,
    r: &DMatrix<f64>,
    s: Option<&DMatrix<f64>>,
) -> Result<RiccatiSolution, LtiError> {
    let (n, _r_inv, a0, q0) = prepare_lq(a, b, q, r, s)?;
    let m = b.ncols();
    let mut reasons: Vec<String> = Vec::new();
    let fail = |reasons: &[String]| {
        let g = symmetrise(
            &(b * inverse_pd("r", r).unwrap_or_else(|_| DMatrix::zeros(m, m)) * b.transpose()),
        );
        let sc = Scaling::new(&a0, &g, &q0);
        let (a_s, g_s, q_s) = sc.apply(&a0, &g, &q0);
        let mut causes = diagnose(&a_s, &g_s, &q_s, true);
        causes.extend(reasons.iter().cloned());
        LtiError::Singular(format!(
            "DARE has no stabilising solution: {} (an unstable mode that B cannot reach or Q does not see, or a closed-loop pole on the unit circle)",
            causes.join("; ")
        ))
    };
    let (x, iterations) = if n == 0 {
        (DMatrix::zeros(0, 0), 0)
    } else {
        // Inputs scaled to a unit-diagonal R (u = E û), then the Riccati scaling
        // of (A, G, Q) with G = B̃R̃⁻¹B̃ᵀ.
        let e: Vec<f64> = (0..m).map(|i| pow2(1.0 / r[(i, i)].sqrt())).collect();
        let be = DMatrix::from_fn(n, m, |i, j| b[(i, j)] * e[j]);
        let re = DMatrix::from_fn(m, m, |i, j| r[(i, j)] * e[i] * e[j]);
        let re_inv = inverse_pd("r", &re)?;
        let g = symmetrise(&(&be * &re_inv * be.transpose()));
        let sc = Scaling::new(&a0, &g, &q0);
        let (a_s, g_s, q_s) = sc.apply(&a0, &g, &q0);
        let (d, sigma) = (&sc.d, sc.sigma);
        let b_s = DMatrix::from_fn(n, m, |i, j| be[(i, j)] / d[i]);
        let r_s = &re / sigma;
        let stabilising = |x: &DMatrix<f64>| match dare_residual(&a_s, &b_s, &q_s, &r_s, x) {
            Some((_, _, k)) => eigvals(&(&a_s - &b_s * k)).iter().all(|p| p.norm() < 1.0),
            None => false,
        };
        let mut best: Option<(DMatrix<f64>, f64, usize)> = None;
        match dare_sda(&a_s, &g_s, &q_s) {
            Ok((x, it)) => {
                let (x, rel, steps) = dare_newton(&a_s, &b_s, &q_s, &r_s, x, 6);
                if stabilising(&x) {
                    best = Some((x, rel, it + steps));
                } else {
                    reasons.push("the doubling solution is not stabilising".into());
                }
            }
            Err(why) => reasons.push(why),
        }
        if best.as_ref().is_none_or(|b| b.1 > 1e-13) {
            tracing::debug!(
                target: "nanomotion_core::lti::riccati",
                n = a_s.nrows(),
                reasons = %reasons.join("; "),
                "DARE: doubling not accurate enough; trying the ordered Schur method"
            );
            match dare_schur(&a_s, &g_s, &q_s) {
                Ok(x) => {
                    let (x, rel, steps) = dare_newton(&a_s, &b_s, &q_s, &r_s, x, 6);
                    if stabilising(&x) && best.as_ref().is_none_or(|b| rel < b.1) {
                        best = Some((x, rel, steps));
                    }
                }
                Err(why) => reasons.push(why),
            }
        }
        let Some((xs, _, it)) = best else {
            return Err(fail(&reasons));
        };
        // A last Newton step on the unscaled data.
        let (x, _, _) = dare_newton(&a0, b, &q0, r, sc.unscale(&xs), 4);
        (x, it)
    };
    // K = (R + BᵀXB)⁻¹(BᵀXA + Sᵀ), on the original (A, B, Q, R, S).
    let rbxb = r + b.transpose() * &x * b;
    let bxa_s = match s {
        Some(s) => b.transpose() * &x * a + s.transpose(),
        None => b.transpose() * &x * a,
    };
    let gain = rbxb
        .clone()
        .lu()
        .solve(&bxa_s)
        .ok_or_else(|| fail(&["R + BᵀXB is singular".to_string()]))?;
    let axa = a.transpose() * &x * a;
    let cross = bxa_s.transpose() * &gain;
    let res = &axa - &x - &cross + q;
    let scale = axa.norm() + x.norm() + cross.norm() + q.norm();
    let rel = res.norm() / scale.max(f64::MIN_POSITIVE);
    let bxa_abs = match s {
        Some(s) => b.transpose().abs() * x.abs() * a.abs() + s.transpose().abs(),
        None => b.transpose().abs() * x.abs() * a.abs(),
    };
    let rbxb_inv = rbxb
        .clone()
        .lu()
        .try_inverse()
        .unwrap_or_else(|| rbxb.clone());
    let floor = a.transpose().abs() * x.abs() * a.abs()
        + x.abs()
        + bxa_abs.transpose() * rbxb_inv.abs() * &bxa_abs
        + q.abs();
    let backward = componentwise(&res, &floor);
    if rel.is_nan() || (rel > RESIDUAL_TOL && backward > BACKWARD_TOL) {
        reasons.push(format!(
            "relative residual {rel:.2e} (backward error {backward:.2e})"
        ));
        return Err(fail(&reasons));
    }
    let poles = eigvals(&(a - b * &gain));
    let worst = poles.iter().map(|p| p.norm()).fold(0.0, f64::max);
    if worst.is_nan() || worst >= 1.0 {
        reasons.push(format!(
            "the closed loop A − BK has a pole of modulus {worst:.6}"
        ));
        return Err(fail(&reasons));
    }
    Ok(RiccatiSolution {
        x,
        gain,
        closed_loop_poles: poles,
        relative_residual: rel,
        backward_error: backward,
        iterations,
    })
}

/// AᵀX + XA + Q = 0 (unique when no two eigenvalues of A sum to 0) by
/// Bartels–Stewart: the real Schur form A = UTUᵀ, then the quasi-triangular
/// solve of TᵀY + YT = −UᵀQU block by block, X = UYUᵀ. O(n³) time, O(n²)
/// memory. [`lyap_solution`] returns X with its residual and backward error.
pub fn lyap(a: &DMatrix<f64>, q: &DMatrix<f64>) -> Result<DMatrix<f64>, LtiError> {
    let n = a.nrows();
    check_square("a", a, n)?;
    check_square("q", q, n)?;
    check_symmetric("q", q)?;
    lyap_unchecked(a, q)
}

/// [`lyap`] returning a [`LyapunovSolution`]: X with its relative residual,
/// backward error and the refinement steps taken, in the layout of the
/// Riccati solvers' [`RiccatiSolution`].
///
/// ```
/// use nanomotion_core::nalgebra::DMatrix;
/// use nanomotion_core::lti::lyap_solution;
/// let a = DMatrix::from_row_slice(2, 2, &[-1.0, 2.0, 0.0, -3.0]);
/// let sol = lyap_solution(&a, &DMatrix::identity(2, 2)).unwrap();
/// assert!(sol.relative_residual < 1e-14 && sol.backward_error < 1e-14);
/// ```
pub fn lyap_solution(a: &DMatrix<f64>, q: &DMatrix<f64>) -> Result<LyapunovSolution, LtiError> {
    let x = lyap(a, q)?;
    Ok(refine_lyapunov(a, q, x, false))
}

/// [`dlyap`] returning a [`LyapunovSolution`] (see [`lyap_solution`]).
pub fn dlyap_solution(a: &DMatrix<f64>, q: &DMatrix<f64>) -> Result<LyapunovSolution, LtiError> {
    let x = dlyap(a, q)?;
    Ok(refine_lyapunov(a, q, x, true))
}

/// Residual of AᵀX + XA + Q (or AᵀXA − X + Q): (relative residual, backward
/// error, residual).
fn lyapunov_residual(
    a: &DMatrix<f64>,
    q: &DMatrix<f64>,
    x: &DMatrix<f64>,
    discrete: bool,
) -> (f64, f64, DMatrix<f64>) {
    let (res, scale, floor) = if discrete {
        let axa = a.transpose() * x * a;
        let res = &axa - x + q;
        let scale = axa.norm() + x.norm() + q.norm();
        let floor = a.transpose().abs() * x.abs() * a.abs() + x.abs() + q.abs();
        (res, scale, floor)
    } else {
        let ax = a.transpose() * x;
        let res = &ax + ax.transpose() + q;
        let scale = 2.0 * ax.norm() + q.norm();
        let axa = a.transpose().abs() * x.abs();
        let floor = &axa + axa.transpose() + q.abs();
        (res, scale, floor)
    };
    (
        res.norm() / scale.max(f64::MIN_POSITIVE),
        componentwise(&res, &floor),
        symmetrise(&res),
    )
}

/// Iterative refinement of a Lyapunov solution: X ← X + Δ with Δ solving the
/// equation for the residual, at most twice, while the backward error is above
/// round-off and falls.
fn refine_lyapunov(
    a: &DMatrix<f64>,
    q: &DMatrix<f64>,
    mut x: DMatrix<f64>,
    discrete: bool,
) -> LyapunovSolution {
    let (mut rel, mut backward, mut res) = lyapunov_residual(a, q, &x, discrete);
    let mut iterations = 0;
    while iterations < 2 && backward > 4.0 * f64::EPSILON && backward.is_finite() {
        let delta = if discrete {
            dlyap_unchecked(a, &res)
        } else {
            lyap_unchecked(a, &res)
        };
        let Ok(delta) = delta else { break };
        let candidate = symmetrise(&(&x + delta));
        let (rel_c, backward_c, res_c) = lyapunov_residual(a, q, &candidate, discrete);
        if backward_c.is_nan() || backward_c >= backward {
            break;
        }
        (x, rel, backward, res) = (candidate, rel_c, backward_c, res_c);
        iterations += 1;
    }
    LyapunovSolution {
        x,
        relative_residual: rel,
        iterations,
        backward_error: backward,
    }
}

fn lyap_unchecked(a: &DMatrix<f64>, q: &DMatrix<f64>) -> Result<DMatrix<f64>, LtiError> {
    let singular = || {
        LtiError::Singular(
            "lyap: the Lyapunov operator is singular (eigenvalues of A with λ_i + λ_j = 0)".into(),
        )
    };
    // Balanced: A = D Ab D⁻¹ (powers of two), Y = DXD solves the equation with
    // (Ab, DQD); X = D⁻¹YD⁻¹.
    let (ab, d) = balance(a);
    let qb = DMatrix::from_fn(q.nrows(), q.ncols(), |i, j| q[(i, j)] * d[i] * d[j]);
    let rs = real_schur(&ab).ok_or_else(|| {
        LtiError::Singular("lyap: the Schur decomposition of A did not converge".into())
    })?;
    let c = -(rs.u.transpose() * &qb * &rs.u);
    let y = lyap_quasi_triangular(&rs, &c).ok_or_else(singular)?;
    let n = a.nrows();
    let yb = &rs.u * y * rs.u.transpose();
    let x = symmetrise(&DMatrix::from_fn(n, n, |i, j| yb[(i, j)] / (d[i] * d[j])));
    if x.iter().any(|v| !v.is_finite()) {
        return Err(singular());
    }
    Ok(x)
}

/// AᵀXA − X + Q = 0 (unique when no two eigenvalues of A multiply to 1) by
/// the Bartels–Stewart method for the Stein equation: real Schur form, then
/// the quasi-triangular solve of TᵀYT − Y = −UᵀQU, O(n³). [`dlyap_solution`]
/// returns X with its residual and backward error.
pub fn dlyap(a: &DMatrix<f64>, q: &DMatrix<f64>) -> Result<DMatrix<f64>, LtiError> {
    let n = a.nrows();
    check_square("a", a, n)?;
    check_square("q", q, n)?;
    check_symmetric("q", q)?;
    dlyap_unchecked(a, q)
}

fn dlyap_unchecked(a: &DMatrix<f64>, q: &DMatrix<f64>) -> Result<DMatrix<f64>, LtiError> {
    dlyap_core(a, q, true)
}

/// dlyap with or without the balancing of A (the DARE's Newton steps run on
/// data the Riccati scaling has already balanced).
fn dlyap_core(
    a: &DMatrix<f64>,
    q: &DMatrix<f64>,
    balanced: bool,
) -> Result<DMatrix<f64>, LtiError> {
    let singular = || {
        LtiError::Singular(
            "dlyap: the Stein operator is singular (eigenvalues of A with λ_i λ_j = 1)".into(),
        )
    };
    let (ab, d) = if balanced {
        balance(a)
    } else {
        (a.clone(), nalgebra::DVector::from_element(a.nrows(), 1.0))
    };
    let qb = DMatrix::from_fn(q.nrows(), q.ncols(), |i, j| q[(i, j)] * d[i] * d[j]);
    let rs = real_schur(&ab).ok_or_else(|| {
        LtiError::Singular("dlyap: the Schur decomposition of A did not converge".into())
    })?;
    let c = -(rs.u.transpose() * &qb * &rs.u);
    let y = stein_quasi_triangular(&rs, &c).ok_or_else(singular)?;
    let n = a.nrows();
    let yb = &rs.u * y * rs.u.transpose();
    let x = symmetrise(&DMatrix::from_fn(n, n, |i, j| yb[(i, j)] / (d[i] * d[j])));
    if x.iter().any(|v| !v.is_finite()) {
        return Err(singular());
    }
    Ok(x)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rng::Rng;

    fn m(r: usize, c: usize, v: &[f64]) -> DMatrix<f64> {
        DMatrix::from_row_slice(r, c, v)
    }

    #[test]
    fn scalar_care_and_dare_match_their_quadratic_formulas() {
        let cases: [(f64, f64, f64, f64); 3] = [
            (1.0, 1.0, 1.0, 1.0),
            (-2.0, 0.5, 3.0, 0.2),
            (0.0, 2.0, 1.0, 5.0),
        ];
        for &(a, b, q, r) in &cases {
            let [am, bm, qm, rm] = [a, b, q, r].map(|v| m(1, 1, &[v]));
            // CARE: 2ax − b²x²/r + q = 0, positive root.
            let want = (a * r + (a * a * r * r + b * b * q * r).sqrt()) / (b * b);
            let s = care(&am, &bm, &qm, &rm, None).unwrap();
            let close = |x: f64, want: f64| (x - want).abs() < 1e-12 * want.max(1.0);
            assert!(close(s.x[(0, 0)], want), "CARE {a} {b} {q} {r}");
            assert!(s.closed_loop_poles[0].re < 0.0);
            // DARE: x = a²x r/(r + b²x) + q ⇔ b²x² + (r − a²r − qb²)x − qr = 0.
            let (qa, qb, qc) = (b * b, r - a * a * r - q * b * b, -q * r);
            let want = (-qb + (qb * qb - 4.0 * qa * qc).sqrt()) / (2.0 * qa);
            let s = dare(&am, &bm, &qm, &rm, None).unwrap();
            assert!(close(s.x[(0, 0)], want), "DARE {a} {b} {q} {r}");
            assert!(s.closed_loop_poles[0].norm() < 1.0);
        }
    }

    #[test]
    fn lyapunov_solvers_satisfy_their_equations() {
        let a = m(3, 3, &[-1.0, 2.0, 0.0, 0.0, -3.0, 1.0, 0.5, 0.0, -2.0]);
        let q = m(3, 3, &[2.0, 0.5, 0.0, 0.5, 1.0, 0.2, 0.0, 0.2, 3.0]);
        let x = lyap(&a, &q).unwrap();
        assert!((a.transpose() * &x + &x * &a + &q).norm() < 1e-12);
        let ad = &a * 0.2 + DMatrix::identity(3, 3) * 0.3;
        let x = dlyap(&ad, &q).unwrap();
        assert!((ad.transpose() * &x * &ad - &x + &q).norm() < 1e-12);
        // dlyap is the infinite sum Σ (Aᵀ)^k Q A^k.
        let mut sum = DMatrix::zeros(3, 3);
        let mut ak = DMatrix::identity(3, 3);
        for _ in 0..400 {
            sum += ak.transpose() * &q * &ak;
            ak = &ak * &ad;
        }
        assert!((sum - x).norm() < 1e-10);
    }

    /// Kleinman's Newton iteration (each step one Lyapunov equation), an
    /// independent method for the CARE: from a stabilising K₀,
    /// (A − BK)ᵀX + X(A − BK) + Q + KᵀRK = 0, K ← R⁻¹BᵀX.
    fn kleinman(
        a: &DMatrix<f64>,
        b: &DMatrix<f64>,
        q: &DMatrix<f64>,
        r: &DMatrix<f64>,
        k0: DMatrix<f64>,
    ) -> DMatrix<f64> {
        let r_inv = r.clone().try_inverse().unwrap();
        let mut k = k0;
        let mut x = DMatrix::zeros(a.nrows(), a.nrows());
        for _ in 0..60 {
            let acl = a - b * &k;
            x = lyap(&acl, &(q + k.transpose() * r * &k)).unwrap();
            k = &r_inv * b.transpose() * &x;
        }
        x
    }

    /// Value iteration of the Riccati difference equation from X = 0, an
    /// independent method for the DARE.
    fn riccati_recursion(
        a: &DMatrix<f64>,
        b: &DMatrix<f64>,
        q: &DMatrix<f64>,
        r: &DMatrix<f64>,
    ) -> DMatrix<f64> {
        let mut x = DMatrix::zeros(a.nrows(), a.nrows());
        for _ in 0..20_000 {
            let k = (r + b.transpose() * &x * b).try_inverse().unwrap() * b.transpose() * &x * a;
            x = a.transpose() * &x * a - a.transpose() * &x * b * &k + q;
            x = symmetrise(&x);
        }
        x
    }

    #[test]
    fn random_lq_problems_agree_with_independent_iterations() {
        let mut rng = Rng::new(7);
        for case in 0..24 {
            let n = 1 + case % 5;
            let mm = 1 + case % 2;
            let a = DMatrix::from_fn(n, n, |_, _| rng.uniform_in(-1.0, 1.0));
            let b = DMatrix::from_fn(n, mm, |_, _| rng.uniform_in(-1.0, 1.0));
            let cq = DMatrix::from_fn(n, n, |_, _| rng.uniform_in(-1.0, 1.0));
            let q = &cq * cq.transpose() + DMatrix::identity(n, n) * 0.1;
            let cr = DMatrix::from_fn(mm, mm, |_, _| rng.uniform_in(-1.0, 1.0));
            let r = &cr * cr.transpose() + DMatrix::identity(mm, mm);
            let s = care(&a, &b, &q, &r, None).unwrap();
            assert!(
                s.relative_residual < 1e-13,
                "case {case}: {}",
                s.relative_residual
            );
            assert!(s.closed_loop_poles.iter().all(|p| p.re < 0.0));
            // Kleinman from the stabilising K₀ of a shifted CARE (A + αI).
            let alpha = 1.0 + a.norm();
            let k0 = care(&(&a + DMatrix::identity(n, n) * alpha), &b, &q, &r, None)
                .unwrap()
                .gain;
            let xk = kleinman(&a, &b, &q, &r, k0);
            assert!(
                (&xk - &s.x).norm() < 1e-9 * s.x.norm(),
                "case {case}: CARE vs Kleinman"
            );
            assert!(
                s.x.clone().cholesky().is_some(),
                "case {case}: X ≻ 0 with Q ≻ 0"
            );
            // Discrete: A scaled to spectral radius 1.3 (unstable, still stabilisable).
            let rho = eigvals(&a).iter().map(|p| p.norm()).fold(0.0, f64::max);
            let ad = &a * (1.3 / rho.max(1e-3));
            let sd = dare(&ad, &b, &q, &r, None).unwrap();
            assert!(
                sd.relative_residual < 1e-12,
                "case {case}: {}",
                sd.relative_residual
            );
            assert!(sd.closed_loop_poles.iter().all(|p| p.norm() < 1.0));
            let xr = riccati_recursion(&ad, &b, &q, &r);
            assert!(
                (&xr - &sd.x).norm() < 1e-8 * sd.x.norm(),
                "case {case}: DARE vs recursion"
            );
        }
    }

    #[test]
    fn double_integrator_closed_forms() {
        let a = m(2, 2, &[0.0, 1.0, 0.0, 0.0]);
        let b = m(2, 1, &[0.0, 1.0]);
        let s = care(
            &a,
            &b,
            &DMatrix::identity(2, 2),
            &DMatrix::identity(1, 1),
            None,
        )
        .unwrap();
        let r3 = 3f64.sqrt();
        assert!((&s.x - m(2, 2, &[r3, 1.0, 1.0, r3])).norm() < 1e-12);
        assert!((&s.gain - m(1, 2, &[1.0, r3])).norm() < 1e-12);
        // Closed loop s² + √3 s + 1.
        for p in &s.closed_loop_poles {
            assert!((p.norm() - 1.0).abs() < 1e-12 && (p.re + r3 / 2.0).abs() < 1e-12);
        }
    }

    #[test]
    fn cross_term_equals_the_shifted_problem() {
        let a = m(2, 2, &[0.2, 1.0, -0.5, 0.1]);
        let b = m(2, 1, &[0.0, 1.0]);
        let q = m(2, 2, &[2.0, 0.3, 0.3, 1.0]);
        let r = m(1, 1, &[0.5]);
        let s = m(2, 1, &[0.2, -0.1]);
        for discrete in [false, true] {
            let f = if discrete { dare } else { care };
            let with = f(&a, &b, &q, &r, Some(&s)).unwrap();
            // The completed square: u = v − R⁻¹Sᵀx turns (Q, S) into (Q − SR⁻¹Sᵀ, 0).
            let shifted = f(
                &(&a - &b * (&s.transpose() * 2.0)),
                &b,
                &(&q - &s * &s.transpose() * 2.0),
                &r,
                None,
            )
            .unwrap();
            assert!((&with.x - &shifted.x).norm() < 1e-10, "discrete {discrete}");
            // Same closed loop: K = K_shifted + R⁻¹Sᵀ.
            assert!((&with.gain - (&shifted.gain + &s.transpose() * 2.0)).norm() < 1e-10);
        }
    }

    #[test]
    fn indefinite_g_of_the_h_infinity_form() {
        // G = B₂B₂ᵀ − γ⁻²B₁B₁ᵀ: for γ large X → the LQ solution, and the equation
        // still has a stabilising solution for a moderate γ.
        let a = m(2, 2, &[0.0, 1.0, -1.0, -0.2]);
        let b1 = m(2, 1, &[0.0, 1.0]);
        let b2 = m(2, 1, &[0.0, 1.0]);
        let q = DMatrix::identity(2, 2);
        let lq = care(&a, &b2, &q, &DMatrix::identity(1, 1), None).unwrap();
        for gamma in [1e6, 10.0, 3.0] {
            let g = &b2 * b2.transpose() - &b1 * b1.transpose() / (gamma * gamma);
            let (x, _) = care_general(&a, &g, &q).unwrap();
            assert!((a.transpose() * &x + &x * &a - &x * &g * &x + &q).norm() < 1e-10);
            if gamma > 1e5 {
                assert!((&x - &lq.x).norm() < 1e-9);
            }
        }
        // Scalar 2ax − gx² + q = 0 with g < 0 (γ too small): the Hamiltonian
        // [a, −g; −q, −a] has eigenvalues ±√(a² + gq), imaginary for
        // a = 0.5, g = −3, q = 1: no stabilising solution, a typed error.
        let e = care_general(&m(1, 1, &[0.5]), &m(1, 1, &[-3.0]), &m(1, 1, &[1.0])).unwrap_err();
        assert!(matches!(e, LtiError::Singular(_)), "{e}");
        // With a² + gq > 0 the same sign of g has one: x = (a + √(a² + gq))/g.
        let (x, _) = care_general(&m(1, 1, &[2.0]), &m(1, 1, &[-1.0]), &m(1, 1, &[1.0])).unwrap();
        let want = (2.0 + 3f64.sqrt()) / -1.0;
        assert!((x[(0, 0)] - want).abs() < 1e-12, "{x} vs {want}");
    }

    #[test]
    fn zero_q_with_hurwitz_a_gives_exactly_zero() {
        // The Hamiltonian's eigenvalues ±0.001 sit next to the axis; X = 0 is
        // exact and stabilising.
        let a = m(2, 2, &[-0.001, 0.0, 1.0, -0.5]);
        let g = m(2, 2, &[1.0, 0.2, 0.2, -0.3]);
        let (x, it) = care_general(&a, &g, &DMatrix::zeros(2, 2)).unwrap();
        assert_eq!((x, it), (DMatrix::zeros(2, 2), 0));
        // With A unstable, Q = 0 still needs the iteration (X ≠ 0 stabilises).
        let (x, _) = care_general(&m(1, 1, &[1.0]), &m(1, 1, &[1.0]), &m(1, 1, &[0.0])).unwrap();
        assert!((x[(0, 0)] - 2.0).abs() < 1e-12, "{x}");
    }

    #[test]
    fn no_stabilising_solution_is_an_error_not_a_wrong_x() {
        // Unstable mode that B cannot reach.
        let a = m(2, 2, &[1.0, 0.0, 0.0, -1.0]);
        let b = m(2, 1, &[0.0, 1.0]);
        let q = DMatrix::identity(2, 2);
        let r = DMatrix::identity(1, 1);
        let e = care(&a, &b, &q, &r, None).unwrap_err();
        assert!(e.to_string().contains("no stabilising solution"), "{e}");
        let ad = m(2, 2, &[1.5, 0.0, 0.0, 0.5]);
        let e = dare(&ad, &b, &q, &r, None).unwrap_err();
        assert!(e.to_string().contains("no stabilising solution"), "{e}");
        // Bad input names the argument.
        let e = care(&a, &b, &q, &m(1, 1, &[-1.0]), None).unwrap_err();
        assert!(e.to_string().contains("`r`"), "{e}");
        let e = care(&a, &b, &m(2, 2, &[1.0, 2.0, 0.0, 1.0]), &r, None).unwrap_err();
        assert!(
            e.to_string().contains("`q`") && e.to_string().contains("symmetric"),
            "{e}"
        );
        let e = care(&a, &m(3, 1, &[0.0, 1.0, 0.0]), &q, &r, None).unwrap_err();
        assert!(matches!(e, LtiError::Dimension(_)), "{e}");
        let e = dare(&m(2, 2, &[f64::NAN, 0.0, 0.0, 1.0]), &b, &q, &r, None).unwrap_err();
        assert!(e.to_string().contains("`a`"), "{e}");
    }
}
