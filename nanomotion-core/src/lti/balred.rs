//! Balanced truncation (Moore 1981; square-root method of Tombs & Postlethwaite
//! 1987) with Hankel singular values and the H∞ error bound
//! ‖G − G_r‖∞ ≤ 2 Σ_{i>r} σ_i (Glover 1984, Enns 1984), for continuous models.
//!
//! An unstable model is first split additively, G = G_s + G_u, with G_s holding
//! the poles in the open left half plane (ordered Schur form and a Sylvester
//! equation); only G_s is reduced and G_u is kept whole (MATLAB `balred` does
//! the same), so the bound holds for the error of the whole model.
//!
//! ```
//! use nalgebra::DMatrix;
//! use nanomotion_core::lti::{StateSpace, hinfnorm};
//! use nanomotion_core::lti::balred::balanced_truncation;
//! // Three first-order lags 1/(s+1) + 0.1/(s+10) + 0.001/(s+100).
//! let a = DMatrix::from_diagonal(&nalgebra::DVector::from_vec(vec![-1.0, -10.0, -100.0]));
//! let b = DMatrix::from_column_slice(3, 1, &[1.0, 1.0, 1.0]);
//! let c = DMatrix::from_row_slice(1, 3, &[1.0, 0.1, 0.001]);
//! let g = StateSpace::new(a, b, c, DMatrix::zeros(1, 1), None).unwrap();
//! let red = balanced_truncation(&g, 1).unwrap();
//! let err = hinfnorm(&nanomotion_core::lti::parallel(&g, &red.reduced.scaled(-1.0)).unwrap()).unwrap().norm;
//! assert!(err <= red.error_bound * (1.0 + 1e-9));
//! assert!(err >= red.hankel_singular_values[1] * (1.0 - 1e-9));
//! ```

use super::schur::ordered_schur;
use super::{LtiError, StateSpace, lyap};
use nalgebra::DMatrix;

/// Result of [`balanced_truncation`].
#[derive(Debug, Clone, PartialEq)]
pub struct BalancedTruncation {
    /// The reduced model: the kept balanced states of the stable part, plus the
    /// whole unstable part (if any).
    pub reduced: StateSpace,
    /// Hankel singular values of the stable part, largest first.
    pub hankel_singular_values: Vec<f64>,
    /// Number of states of the unstable part (kept whole; with an offset, also
    /// the poles with Re ≥ −offset).
    pub unstable_states: usize,
    /// 2 Σ_{i>r} σ_i: a bound on ‖G − G_r‖∞.
    pub error_bound: f64,
}

/// G = G_s + G_u: the stable part (poles with Re < 0) and the rest. Returns
/// (G_s, G_u); the direct term goes to G_s.
pub fn stable_unstable_split(sys: &StateSpace) -> Result<(StateSpace, StateSpace), LtiError> {
    split_at(sys, 0.0)
}

/// [`stable_unstable_split`] with the border at Re = −`offset` (≥ 0): poles with
/// Re ≥ −offset go to the second part. An offset keeps near-integrators (such as
/// the 2π·10⁻⁶ rad/s poles of the thesis's W_S, which make the Gramians
/// ill-conditioned) out of the balanced part (MATLAB `balred`'s `Offset`).
pub fn split_at(sys: &StateSpace, offset: f64) -> Result<(StateSpace, StateSpace), LtiError> {
    if !(offset >= 0.0 && offset.is_finite()) {
        return Err(LtiError::param("offset", "must be finite and ≥ 0"));
    }
    sys.validate()?;
    if sys.dt.is_some() {
        return Err(LtiError::Domain(
            "the stable/unstable split is for continuous models".into(),
        ));
    }
    let n = sys.nstates();
    let (q, ns) = real_stable_basis(&sys.a, offset)?;
    let at = q.transpose() * &sys.a * &q;
    let bt = q.transpose() * &sys.b;
    let ct = &sys.c * &q;
    let nu = n - ns;
    let a11 = at.view((0, 0), (ns, ns)).clone_owned();
    let a12 = at.view((0, ns), (ns, nu)).clone_owned();
    let a22 = at.view((ns, ns), (nu, nu)).clone_owned();
    // Decouple by S = [I X; 0 I] with A11 X − X A22 + A12 = 0: S⁻¹ÃS is block
    // diagonal, B ← [B₁ − X B₂; B₂], C ← [C₁, C₂ + C₁ X].
    let x = sylvester(&a11, &a22, &a12)?;
    let b1 = bt.view((0, 0), (ns, sys.ninputs())).clone_owned();
    let b2 = bt.view((ns, 0), (nu, sys.ninputs())).clone_owned();
    let c1 = ct.view((0, 0), (sys.noutputs(), ns)).clone_owned();
    let c2 = ct.view((0, ns), (sys.noutputs(), nu)).clone_owned();
    let stable = StateSpace {
        a: a11,
        b: &b1 - &x * &b2,
        c: c1.clone(),
        d: sys.d.clone(),
        dt: None,
    };
    let unstable = StateSpace {
        a: a22,
        b: b2,
        c: &c2 + &c1 * &x,
        d: DMatrix::zeros(sys.noutputs(), sys.ninputs()),
        dt: None,
    };
    Ok((stable, unstable))
}

/// An orthogonal Q whose first `ns` columns span the invariant subspace of A's
/// eigenvalues with Re < 0.
fn real_stable_basis(a: &DMatrix<f64>, offset: f64) -> Result<(DMatrix<f64>, usize), LtiError> {
    let n = a.nrows();
    if n == 0 {
        return Ok((DMatrix::zeros(0, 0), 0));
    }
    let (u, ns, _) = ordered_schur(a, |l| l.re < -offset)
        .ok_or_else(|| LtiError::Singular("Schur form of A did not converge".into()))?;
    // The subspace is real (conjugate-closed); a real orthonormal basis of it
    // from the real and imaginary parts of the complex basis, completed to an
    // orthogonal matrix by a full QR of [basis | I].
    let mut m = DMatrix::zeros(n, 2 * ns + n);
    for j in 0..ns {
        for i in 0..n {
            m[(i, 2 * j)] = u[(i, j)].re;
            m[(i, 2 * j + 1)] = u[(i, j)].im;
        }
    }
    let svd = m.columns(0, 2 * ns).clone_owned().svd(true, false);
    let us = svd
        .u
        .ok_or_else(|| LtiError::Singular("SVD of the stable basis failed".into()))?;
    let mut q = DMatrix::zeros(n, n);
    if ns > 0 {
        q.columns_mut(0, ns).copy_from(&us.columns(0, ns));
    }
    // Complete by Gram–Schmidt against the unit vectors (twice for stability).
    let mut k = ns;
    for e in 0..n {
        if k == n {
            break;
        }
        let mut v = nalgebra::DVector::<f64>::zeros(n);
        v[e] = 1.0;
        for _ in 0..2 {
            for j in 0..k {
                let p = q.column(j).dot(&v);
                v -= q.column(j) * p;
            }
        }
        let nv = v.norm();
        if nv > 1e-8 {
            q.column_mut(k).copy_from(&(v / nv));
            k += 1;
        }
    }
    if k != n {
        return Err(LtiError::Singular(
            "could not complete the stable basis".into(),
        ));
    }
    Ok((q, ns))
}

/// X with A X − X B + C = 0 (Kronecker form; A and B without common
/// eigenvalues). Small problems only (≤ 4096 unknowns).
fn sylvester(
    a: &DMatrix<f64>,
    b: &DMatrix<f64>,
    c: &DMatrix<f64>,
) -> Result<DMatrix<f64>, LtiError> {
    let (m, n) = (a.nrows(), b.nrows());
    if m == 0 || n == 0 {
        return Ok(DMatrix::zeros(m, n));
    }
    if m * n > 4096 {
        return Err(LtiError::Dimension(format!(
            "stable/unstable split of {m} + {n} states is too large for the direct solve"
        )));
    }
    // vec(A X − X B) = (I ⊗ A − Bᵀ ⊗ I) vec(X).
    let mut k = DMatrix::zeros(m * n, m * n);
    for j in 0..n {
        for i in 0..m {
            let row = j * m + i;
            for p in 0..m {
                k[(row, j * m + p)] += a[(i, p)];
            }
            for q in 0..n {
                k[(row, q * m + i)] -= b[(q, j)];
            }
        }
    }
    let rhs = nalgebra::DVector::from_iterator(m * n, (-c).iter().copied());
    let x = k.lu().solve(&rhs).ok_or_else(|| {
        LtiError::Singular("stable and unstable parts share an eigenvalue".into())
    })?;
    Ok(DMatrix::from_column_slice(m, n, x.as_slice()))
}

/// Symmetric PSD factor L with M = L Lᵀ (eigen-decomposition, negative
/// round-off eigenvalues clipped to 0).
fn psd_factor(m: &DMatrix<f64>) -> DMatrix<f64> {
    let e = ((m + m.transpose()) * 0.5).symmetric_eigen();
    let d = e.eigenvalues.map(|v| v.max(0.0).sqrt());
    &e.eigenvectors * DMatrix::from_diagonal(&d)
}

/// Hankel singular values of a stable continuous model, largest first.
pub fn hankel_singular_values(sys: &StateSpace) -> Result<Vec<f64>, LtiError> {
    Ok(square_root(sys)?.0)
}

type SquareRoot = (Vec<f64>, DMatrix<f64>, DMatrix<f64>);

/// σ_i and the balancing projections: T (n × n) and its inverse rows Ti, such
/// that Ti A T is balanced (only the rows/columns of σ_i > 0 are meaningful).
fn square_root(sys: &StateSpace) -> Result<SquareRoot, LtiError> {
    sys.validate()?;
    if sys.dt.is_some() {
        return Err(LtiError::Domain(
            "balanced truncation here is for continuous models (map a discrete one with the bilinear transform first)".into(),
        ));
    }
    if !sys.is_stable() {
        return Err(LtiError::Unstable(
            "Hankel singular values need a stable model (split it first)".into(),
        ));
    }
    // A P + P Aᵀ + B Bᵀ = 0 and Aᵀ Q + Q A + Cᵀ C = 0 (lyap solves AᵀX + XA + Q = 0).
    let p = lyap(&sys.a.transpose(), &(&sys.b * sys.b.transpose()))?;
    let q = lyap(&sys.a, &(sys.c.transpose() * &sys.c))?;
    let lc = psd_factor(&p);
    let lo = psd_factor(&q);
    let svd = (lo.transpose() * &lc).svd(true, true);
    let (u, vt) = match (svd.u, svd.v_t) {
        (Some(u), Some(vt)) => (u, vt),
        _ => return Err(LtiError::Singular("SVD of Loᵀ Lc failed".into())),
    };
    let mut idx: Vec<usize> = (0..svd.singular_values.len()).collect();
    idx.sort_by(|&i, &j| svd.singular_values[j].total_cmp(&svd.singular_values[i]));
    let sv: Vec<f64> = idx.iter().map(|&i| svd.singular_values[i]).collect();
    let n = sys.nstates();
    let mut t = DMatrix::zeros(n, n);
    let mut ti = DMatrix::zeros(n, n);
    for (k, &i) in idx.iter().enumerate() {
        let s = sv[k];
        if s <= 0.0 {
            continue;
        }
        let w = 1.0 / s.sqrt();
        t.column_mut(k)
            .copy_from(&(&lc * vt.row(i).transpose() * w));
        ti.row_mut(k)
            .copy_from(&(u.column(i).transpose() * lo.transpose() * w));
    }
    Ok((sv, t, ti))
}

/// Balanced truncation of `sys` to `order` states (see the [module docs](self)).
/// `order` must be at least the number of unstable states; the kept stable
/// states must have σ_r > 0.
pub fn balanced_truncation(sys: &StateSpace, order: usize) -> Result<BalancedTruncation, LtiError> {
    balanced_truncation_offset(sys, order, 0.0)
}

/// [`balanced_truncation`] keeping every pole with Re ≥ −`offset` whole (see
/// [`split_at`]); the bound is then on the error of the part that was balanced,
/// which is the error of the whole model.
pub fn balanced_truncation_offset(
    sys: &StateSpace,
    order: usize,
    offset: f64,
) -> Result<BalancedTruncation, LtiError> {
    sys.validate()?;
    let (stable, unstable) = split_at(sys, offset)?;
    let nu = unstable.nstates();
    if order < nu {
        return Err(LtiError::param(
            "order",
            format!("the model has {nu} unstable states, which are kept: ask for at least {nu}"),
        ));
    }
    if order > sys.nstates() {
        return Err(LtiError::param(
            "order",
            format!("is above the model's {} states", sys.nstates()),
        ));
    }
    let r = order - nu;
    let (sv, t, ti) = square_root(&stable)?;
    if r > 0 && sv[r - 1] <= 0.0 {
        return Err(LtiError::param(
            "order",
            "keeps states with zero Hankel singular value (uncontrollable or unobservable): ask for fewer",
        ));
    }
    let tr = t.columns(0, r).clone_owned();
    let tir = ti.rows(0, r).clone_owned();
    let reduced_stable = StateSpace {
        a: &tir * &stable.a * &tr,
        b: &tir * &stable.b,
        c: &stable.c * &tr,
        d: stable.d.clone(),
        dt: None,
    };
    let reduced = if nu == 0 {
        reduced_stable
    } else {
        super::parallel(&reduced_stable, &unstable)?
    };
    let error_bound = 2.0 * sv.iter().skip(r).sum::<f64>();
    Ok(BalancedTruncation {
        reduced,
        hankel_singular_values: sv,
        unstable_states: nu,
        error_bound,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::lti::{Complex, hinfnorm, parallel};

    fn random_stable(n: usize, m: usize, p: usize, seed: u64) -> StateSpace {
        let mut rng = crate::rng::Rng::new(seed);
        let mut a = DMatrix::from_fn(n, n, |_, _| rng.normal());
        // Shift to make it stable.
        let shift = crate::lti::linalg::eigvals(&a)
            .iter()
            .map(|l| l.re)
            .fold(f64::NEG_INFINITY, f64::max);
        for i in 0..n {
            a[(i, i)] -= shift + 0.5;
        }
        let b = DMatrix::from_fn(n, m, |_, _| rng.normal());
        let c = DMatrix::from_fn(p, n, |_, _| rng.normal());
        let d = DMatrix::from_fn(p, m, |_, _| rng.normal());
        StateSpace::new(a, b, c, d, None).unwrap()
    }

    #[test]
    fn error_lies_between_sigma_next_and_twice_the_tail() {
        for seed in 0..4 {
            let g = random_stable(8, 2, 3, seed);
            for r in [1, 3, 5] {
                let red = balanced_truncation(&g, r).unwrap();
                let err = hinfnorm(&parallel(&g, &red.reduced.scaled(-1.0)).unwrap())
                    .unwrap()
                    .norm;
                let s = &red.hankel_singular_values;
                assert!(
                    err <= red.error_bound * (1.0 + 1e-7),
                    "{err} > {}",
                    red.error_bound
                );
                assert!(err >= s[r] * (1.0 - 1e-7), "{err} < σ_{} = {}", r + 1, s[r]);
                assert!(red.reduced.is_stable());
            }
        }
    }

    #[test]
    fn hankel_values_are_invariant_and_match_a_first_order_closed_form() {
        // 1/(s + a): P = 1/(2a), Q = 1/(2a), σ = 1/(2a).
        let g = StateSpace::new(
            DMatrix::from_element(1, 1, -3.0),
            DMatrix::from_element(1, 1, 1.0),
            DMatrix::from_element(1, 1, 1.0),
            DMatrix::zeros(1, 1),
            None,
        )
        .unwrap();
        let s = hankel_singular_values(&g).unwrap();
        assert!((s[0] - 1.0 / 6.0).abs() < 1e-14);
        // A similarity transform leaves them unchanged.
        let g = random_stable(5, 1, 2, 9);
        let t = DMatrix::from_fn(5, 5, |i, j| {
            if i == j {
                2.0
            } else {
                0.1 * (i + 2 * j) as f64
            }
        });
        let ti = t.clone().try_inverse().unwrap();
        let g2 =
            StateSpace::new(&ti * &g.a * &t, &ti * &g.b, &g.c * &t, g.d.clone(), None).unwrap();
        let (s1, s2) = (
            hankel_singular_values(&g).unwrap(),
            hankel_singular_values(&g2).unwrap(),
        );
        for (a, b) in s1.iter().zip(&s2) {
            assert!((a - b).abs() < 1e-9 * s1[0], "{a} vs {b}");
        }
    }

    #[test]
    fn unstable_part_is_kept_and_the_split_adds_up() {
        let mut g = random_stable(6, 1, 1, 3);
        g.a[(0, 0)] += 40.0; // makes one (or more) pole unstable
        let (gs, gu) = stable_unstable_split(&g).unwrap();
        assert!(gs.is_stable());
        assert!(gu.poles().iter().all(|l| l.re >= 0.0));
        for w in [0.1, 1.0, 10.0] {
            let s = Complex::new(0.0, w);
            let sum = gs.evalfr(s)[(0, 0)] + gu.evalfr(s)[(0, 0)];
            let want = g.evalfr(s)[(0, 0)];
            assert!((sum - want).norm() < 1e-8 * want.norm().max(1.0));
        }
        let nu = gu.nstates();
        let red = balanced_truncation(&g, nu + 1).unwrap();
        assert_eq!(red.unstable_states, nu);
        assert_eq!(red.reduced.nstates(), nu + 1);
        assert!(balanced_truncation(&g, nu.saturating_sub(1)).is_err() || nu == 0);
    }
}
