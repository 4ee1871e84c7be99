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
//! - [`lyap`] (AᵀX + XA + Q = 0) and [`dlyap`] (AᵀXA − X + Q = 0), by the
//!   Kronecker form, for small n.
//!
//! # Methods
//!
//! **CARE: matrix sign function** (Roberts 1971; determinant scaling, Byers 1987).
//! The Hamiltonian H = [A, −G; −Q, −Aᵀ] has no eigenvalue on the imaginary axis
//! exactly when a stabilising solution can exist; Z ← (cZ + (cZ)⁻¹)/2 with
//! c = |det Z|^(−1/2n) converges quadratically to W = sign(H), and the stable
//! invariant subspace [I; X] satisfies (W + I)[I; X] = 0, i.e.
//! [W₁₂; W₂₂ + I] X = −[W₁₁ + I; W₂₁], solved by least squares. Only LU and QR
//! are needed (nalgebra has no ordered Schur form).
//!
//! **DARE: structure-preserving doubling** (SDA; Chu, Fan, Lin & Wang 2004) on
//! X = AᵀX(I + GX)⁻¹A + H, G = BR⁻¹Bᵀ, H = Q (after removing S):
//! A ← A(I + GH)⁻¹A, G ← G + A(I + GH)⁻¹GAᵀ, H ← H + AᵀH(I + GH)⁻¹A; H → X
//! quadratically.
//!
//! Every answer is **checked independently of the method** before it is returned:
//! the residual of the equation itself (relative to the size of its terms) and
//! the eigenvalues of the closed loop. An equation without a stabilising
//! solution (an uncontrollable unstable mode, a Hamiltonian eigenvalue on the
//! axis) is a [`LtiError::Singular`] naming what failed, never a wrong X.
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

use super::linalg::eigvals;
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
    /// Sign-function or doubling iterations used.
    pub iterations: usize,
}

/// Largest accepted relative residual before a solution is refused.
const RESIDUAL_TOL: f64 = 1e-8;
const MAX_ITERATIONS: usize = 100;
/// Largest state dimension for the Newton refinement of the CARE (Kronecker
/// Lyapunov solves of size n²).
const REFINE_MAX_N: usize = 24;

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
    Ok(RiccatiSolution {
        closed_loop_poles: eigvals(&acl),
        relative_residual: res.norm() / scale.max(f64::MIN_POSITIVE),
        x,
        gain,
        iterations,
    })
}

/// AᵀX + XA − XGX + Q = 0 for symmetric G, Q (either may be indefinite): the
/// stabilising X (A − GX Hurwitz) by the matrix sign function. Returns X and
/// the iterations used.
pub fn care_general(
    a: &DMatrix<f64>,
    g: &DMatrix<f64>,
    q: &DMatrix<f64>,
) -> Result<(DMatrix<f64>, usize), LtiError> {
    let n = a.nrows();
    check_square("a", a, n)?;
    check_square("g", g, n)?;
    check_square("q", q, n)?;
    check_symmetric("g", g)?;
    check_symmetric("q", q)?;
    if n == 0 {
        return Ok((DMatrix::zeros(0, 0), 0));
    }
    // Q = 0 with A Hurwitz: X = 0 is the stabilising solution, exactly (A − G·0 =
    // A). The sign iteration would return round-off instead, which no relative
    // residual can judge (every term of the equation is then round-off too).
    // This is the Y equation of every mixed-sensitivity H∞ problem with y = e.
    let data = a.norm() + g.norm();
    if q.iter().all(|v| v.abs() <= f64::EPSILON * data) && eigvals(a).iter().all(|l| l.re < 0.0) {
        return Ok((DMatrix::zeros(n, n), 0));
    }
    // Hamiltonian H = [A, −G; −Q, −Aᵀ].
    let mut z = DMatrix::zeros(2 * n, 2 * n);
    z.view_mut((0, 0), (n, n)).copy_from(a);
    z.view_mut((0, n), (n, n)).copy_from(&(-g));
    z.view_mut((n, 0), (n, n)).copy_from(&(-q));
    z.view_mut((n, n), (n, n)).copy_from(&(-a.transpose()));
    let no_solution = |why: String| {
        LtiError::Singular(format!(
            "CARE has no stabilising solution: {why} (the Hamiltonian has an eigenvalue on or near the imaginary axis: an unstable mode that G cannot reach or Q does not see)"
        ))
    };
    let mut iterations = 0;
    let mut converged = false;
    let mut last_change = f64::INFINITY;
    while iterations < MAX_ITERATIONS {
        iterations += 1;
        let lu = z.clone().lu();
        let det = lu.determinant();
        let inv = lu
            .try_inverse()
            .ok_or_else(|| no_solution("the sign iteration met a singular matrix".into()))?;
        // Determinant scaling while far from convergence; plain Newton after.
        let c = if det.is_finite() && det != 0.0 && iterations <= 20 {
            det.abs().powf(-1.0 / (2 * n) as f64)
        } else {
            1.0
        };
        let next = (&z * c + inv / c) * 0.5;
        if !next.iter().all(|v| v.is_finite()) {
            return Err(no_solution("the sign iteration diverged".into()));
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
        return Err(no_solution(format!(
            "the sign iteration did not converge in {MAX_ITERATIONS} steps"
        )));
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
        return Err(no_solution(format!(
            "the stable subspace is not a graph [I; X] (conditioning {:.1e})",
            smin / smax
        )));
    }
    let x = svd
        .solve(&rhs, 0.0)
        .map_err(|e| no_solution(format!("least squares failed: {e}")))?;
    let mut x = symmetrise(&x);
    // Independent checks: residual and closed-loop stability.
    let residual = |x: &DMatrix<f64>| {
        let res = a.transpose() * x + x * a - x * g * x + q;
        let scale = (a.transpose() * x).norm() * 2.0 + (x * g * x).norm() + q.norm();
        (res.norm() / scale.max(f64::MIN_POSITIVE), res)
    };
    let (mut rel, mut res) = residual(&x);
    // Newton refinement (the sign function loses digits when the Hamiltonian's
    // eigenvalues are spread): (A − GX)ᵀΔ + Δ(A − GX) = −Res(X), X ← X + Δ,
    // while it helps. Kronecker Lyapunov solves, so only for n ≤ 24.
    if n <= REFINE_MAX_N {
        for _ in 0..3 {
            if rel <= 1e-15 {
                break;
            }
            let acl = a - g * &x;
            let Ok(delta) = lyap(&acl, &symmetrise(&res)) else {
                break;
            };
            let candidate = symmetrise(&(&x + delta));
            let (rel_c, res_c) = residual(&candidate);
            if rel_c.is_nan() || rel_c >= rel {
                break;
            }
            x = candidate;
            rel = rel_c;
            res = res_c;
        }
    }
    if rel.is_nan() || rel > RESIDUAL_TOL {
        return Err(no_solution(format!("relative residual {rel:.2e}")));
    }
    let worst = eigvals(&(a - g * &x))
        .iter()
        .map(|p| p.re)
        .fold(f64::NEG_INFINITY, f64::max);
    if worst.is_nan() || worst >= 0.0 {
        return Err(no_solution(format!(
            "the closed loop A − GX has an eigenvalue with real part {worst:.3e}"
        )));
    }
    Ok((x, iterations))
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
    let (n, r_inv, a0, q0) = prepare_lq(a, b, q, r, s)?;
    let no_solution = |why: String| {
        LtiError::Singular(format!(
            "DARE has no stabilising solution: {why} (an unstable mode that B cannot reach or Q does not see, or a closed-loop pole on the unit circle)"
        ))
    };
    let ident = DMatrix::<f64>::identity(n, n);
    let mut ak = a0.clone();
    let mut gk = symmetrise(&(b * &r_inv * b.transpose()));
    let mut hk = q0.clone();
    let mut iterations = 0;
    let mut converged = n == 0;
    let mut last_change = f64::INFINITY;
    while !converged && iterations < MAX_ITERATIONS {
        iterations += 1;
        let w = (&ident + &gk * &hk)
            .lu()
            .try_inverse()
            .ok_or_else(|| no_solution("I + G_k H_k became singular".into()))?;
        let a_next = &ak * &w * &ak;
        let g_next = symmetrise(&(&gk + &ak * &w * &gk * ak.transpose()));
        let h_next = symmetrise(&(&hk + ak.transpose() * &hk * &w * &ak));
        if !h_next.iter().all(|v| v.is_finite()) || !g_next.iter().all(|v| v.is_finite()) {
            return Err(no_solution("the doubling iteration diverged".into()));
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
        return Err(no_solution(format!(
            "the doubling iteration did not converge in {MAX_ITERATIONS} steps"
        )));
    }
    let x = hk;
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
        .ok_or_else(|| no_solution("R + BᵀXB is singular".into()))?;
    let axa = a.transpose() * &x * a;
    let cross = bxa_s.transpose() * &gain;
    let res = &axa - &x - &cross + q;
    let scale = axa.norm() + x.norm() + cross.norm() + q.norm();
    let rel = res.norm() / scale.max(f64::MIN_POSITIVE);
    if rel.is_nan() || rel > RESIDUAL_TOL {
        return Err(no_solution(format!("relative residual {rel:.2e}")));
    }
    let poles = eigvals(&(a - b * &gain));
    let worst = poles.iter().map(|p| p.norm()).fold(0.0, f64::max);
    if worst.is_nan() || worst >= 1.0 {
        return Err(no_solution(format!(
            "the closed loop A − BK has a pole of modulus {worst:.6}"
        )));
    }
    Ok(RiccatiSolution {
        x,
        gain,
        closed_loop_poles: poles,
        relative_residual: rel,
        iterations,
    })
}

/// Solve Σ_i L_i X R_i = −Q for X by the Kronecker form (column-major vec):
/// (Σ R_iᵀ ⊗ L_i) vec X = −vec Q.
fn kronecker_solve(
    terms: &[(DMatrix<f64>, DMatrix<f64>)],
    q: &DMatrix<f64>,
    what: &str,
) -> Result<DMatrix<f64>, LtiError> {
    let n = q.nrows();
    let mut k = DMatrix::zeros(n * n, n * n);
    for (l, r) in terms {
        // (Rᵀ ⊗ L)[(j·n + i), (c·n + a)] = R[c, j]·L[i, a].
        for j in 0..n {
            for c in 0..n {
                let rcj = r[(c, j)];
                if rcj == 0.0 {
                    continue;
                }
                for i in 0..n {
                    for a in 0..n {
                        k[(j * n + i, c * n + a)] += rcj * l[(i, a)];
                    }
                }
            }
        }
    }
    let rhs = DMatrix::from_column_slice(n * n, 1, (-q).as_slice());
    let v = k.lu().solve(&rhs).ok_or_else(|| {
        LtiError::Singular(format!(
            "{what}: the Lyapunov operator is singular (eigenvalues of A with λ_i + λ_j = 0, or λ_i λ_j = 1 in discrete time)"
        ))
    })?;
    Ok(symmetrise(&DMatrix::from_column_slice(n, n, v.as_slice())))
}

/// AᵀX + XA + Q = 0 (unique when no two eigenvalues of A sum to 0); Kronecker
/// form, O(n⁶): for n up to a few tens.
pub fn lyap(a: &DMatrix<f64>, q: &DMatrix<f64>) -> Result<DMatrix<f64>, LtiError> {
    let n = a.nrows();
    check_square("a", a, n)?;
    check_square("q", q, n)?;
    check_symmetric("q", q)?;
    let i = DMatrix::identity(n, n);
    kronecker_solve(&[(a.transpose(), i.clone()), (i, a.clone())], q, "lyap")
}

/// AᵀXA − X + Q = 0 (unique when no two eigenvalues of A multiply to 1);
/// Kronecker form, for n up to a few tens.
pub fn dlyap(a: &DMatrix<f64>, q: &DMatrix<f64>) -> Result<DMatrix<f64>, LtiError> {
    let n = a.nrows();
    check_square("a", a, n)?;
    check_square("q", q, n)?;
    check_symmetric("q", q)?;
    let i = DMatrix::identity(n, n);
    kronecker_solve(&[(a.transpose(), a.clone()), (-&i, i)], q, "dlyap")
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
