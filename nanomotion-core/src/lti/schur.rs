//! Schur-form kernels of the Riccati and Lyapunov solvers:
//!
//! - the real Schur form A = U T Uᵀ (nalgebra's QR algorithm) with its 1×1/2×2
//!   diagonal blocks;
//! - Bartels–Stewart: the quasi-triangular Lyapunov (TᵀY + YT = C) and Stein
//!   (TᵀYT − Y = C) solves, block by block, O(n³);
//! - an **ordered** Schur basis of an invariant subspace: the real Schur form is
//!   turned into a complex (triangular) Schur form by one unitary 2×2 rotation
//!   per complex-pair block, then the selected eigenvalues are moved to the
//!   top by unitary swaps of adjacent diagonal entries (the complex analogue of
//!   LAPACK's `trexc`; every swap is a Givens rotation, so the basis stays
//!   orthonormal to round-off).

use super::Complex;
use nalgebra::DMatrix;

type C64 = Complex<f64>;

/// A = U T Uᵀ with T upper quasi-triangular; `blocks` lists the diagonal
/// blocks as (first index, size ∈ {1, 2}).
pub(crate) struct RealSchur {
    pub u: DMatrix<f64>,
    pub t: DMatrix<f64>,
    pub blocks: Vec<(usize, usize)>,
}

/// The real Schur form of a finite square matrix, or `None` if the QR
/// iteration fails.
pub(crate) fn real_schur(a: &DMatrix<f64>) -> Option<RealSchur> {
    let n = a.nrows();
    if a.iter().any(|v| !v.is_finite()) {
        return None;
    }
    if n == 0 {
        return Some(RealSchur {
            u: DMatrix::zeros(0, 0),
            t: DMatrix::zeros(0, 0),
            blocks: Vec::new(),
        });
    }
    let s = nalgebra::linalg::Schur::try_new(a.clone(), f64::EPSILON, 10_000 * n)?;
    let (u, mut t) = s.unpack();
    let mut blocks = Vec::new();
    let mut i = 0;
    while i < n {
        if i + 1 < n && t[(i + 1, i)] != 0.0 {
            blocks.push((i, 2));
            i += 2;
        } else {
            blocks.push((i, 1));
            i += 1;
        }
    }
    // Exact zeros below the block diagonal.
    for &(s0, sz) in &blocks {
        for j in s0..s0 + sz {
            for r in (s0 + sz)..n {
                t[(r, j)] = 0.0;
            }
        }
    }
    if t.iter().chain(u.iter()).any(|v| !v.is_finite()) {
        return None;
    }
    Some(RealSchur { u, t, blocks })
}

/// Solves the ≤ 4×4 Kronecker system of one block pair.
fn small_solve(k: DMatrix<f64>, f: &DMatrix<f64>) -> Option<DMatrix<f64>> {
    let (p, r) = f.shape();
    let rhs = DMatrix::from_column_slice(p * r, 1, f.as_slice());
    let v = k.lu().solve(&rhs)?;
    if v.iter().any(|x| !x.is_finite()) {
        return None;
    }
    Some(DMatrix::from_column_slice(p, r, v.as_slice()))
}

/// TᵀY + YT = C for the quasi-triangular T of a real Schur form (block
/// forward substitution). `None` when the operator is singular (two
/// eigenvalues of T sum to 0).
pub(crate) fn lyap_quasi_triangular(rs: &RealSchur, c: &DMatrix<f64>) -> Option<DMatrix<f64>> {
    let t = &rs.t;
    let n = t.nrows();
    let mut y = DMatrix::<f64>::zeros(n, n);
    let tol = f64::EPSILON * t.norm().max(f64::MIN_POSITIVE);
    for &(sk, bk) in &rs.blocks {
        for &(sl, bl) in &rs.blocks {
            // F = C_kl − Σ_{i<k} T_ikᵀ Y_il − Σ_{j<l} Y_kj T_jl.
            let mut f = c.view((sk, sl), (bk, bl)).clone_owned();
            if sk > 0 {
                f -= t.view((0, sk), (sk, bk)).transpose() * y.view((0, sl), (sk, bl));
            }
            if sl > 0 {
                f -= y.view((sk, 0), (bk, sl)) * t.view((0, sl), (sl, bl));
            }
            // T_kkᵀ Y + Y T_ll = F: (I ⊗ T_kkᵀ + T_llᵀ ⊗ I) vec Y = vec F.
            let tkk_t = t.view((sk, sk), (bk, bk)).transpose();
            let tll = t.view((sl, sl), (bl, bl));
            let mut k = tll.transpose().kronecker(&DMatrix::<f64>::identity(bk, bk));
            k += DMatrix::<f64>::identity(bl, bl).kronecker(&tkk_t);
            if k.iter().all(|v| v.abs() <= tol) {
                return None;
            }
            let blk = small_solve(k, &f)?;
            y.view_mut((sk, sl), (bk, bl)).copy_from(&blk);
        }
    }
    Some(y)
}

/// TᵀYT − Y = C for the quasi-triangular T of a real Schur form, O(n³).
/// `None` when the operator is singular (two eigenvalues multiply to 1).
pub(crate) fn stein_quasi_triangular(rs: &RealSchur, c: &DMatrix<f64>) -> Option<DMatrix<f64>> {
    let t = &rs.t;
    let n = t.nrows();
    let mut y = DMatrix::<f64>::zeros(n, n);
    for &(sl, bl) in &rs.blocks {
        let tll = t.view((sl, sl), (bl, bl)).clone_owned();
        // V_i = Σ_{j<l} Y_ij T_jl for every row block i (n × bl).
        let v = if sl > 0 {
            y.view((0, 0), (n, sl)) * t.view((0, sl), (sl, bl))
        } else {
            DMatrix::zeros(n, bl)
        };
        // W_i = V_i + Y_il T_ll for the row blocks already solved.
        let mut w = DMatrix::<f64>::zeros(n, bl);
        for &(sk, bk) in &rs.blocks {
            // Σ_{i≤k, j≤l} T_ikᵀ Y_ij T_jl − Y_kl = C_kl; the unknown sits in
            // T_kkᵀ Y_kl T_ll − Y_kl.
            let tkk_t = t.view((sk, sk), (bk, bk)).transpose();
            let mut f = c.view((sk, sl), (bk, bl)).clone_owned();
            if sk > 0 {
                f -= t.view((0, sk), (sk, bk)).transpose() * w.view((0, 0), (sk, bl));
            }
            f -= &tkk_t * v.view((sk, 0), (bk, bl));
            let k = tll.transpose().kronecker(&tkk_t) - DMatrix::<f64>::identity(bk * bl, bk * bl);
            let blk = small_solve(k, &f)?;
            y.view_mut((sk, sl), (bk, bl)).copy_from(&blk);
            let wk = v.view((sk, 0), (bk, bl)) + &blk * &tll;
            w.view_mut((sk, 0), (bk, bl)).copy_from(&wk);
        }
    }
    Some(y)
}

/// Unitary rotation G = [x̂, x̂⊥] (first column x/‖x‖) applied as
/// T ← Gᴴ T G on rows/columns (k, k+1), and U ← U G.
fn rotate(t: &mut DMatrix<C64>, u: &mut DMatrix<C64>, k: usize, x0: C64, x1: C64) {
    let nx = (x0.norm_sqr() + x1.norm_sqr()).sqrt();
    if nx == 0.0 || !nx.is_finite() {
        return;
    }
    let (c, s) = (x0 / nx, x1 / nx);
    let n = t.nrows();
    for j in 0..n {
        let (a, b) = (t[(k, j)], t[(k + 1, j)]);
        t[(k, j)] = c.conj() * a + s.conj() * b;
        t[(k + 1, j)] = -s * a + c * b;
    }
    for i in 0..n {
        let (a, b) = (t[(i, k)], t[(i, k + 1)]);
        t[(i, k)] = a * c + b * s;
        t[(i, k + 1)] = -a * s.conj() + b * c.conj();
    }
    for i in 0..u.nrows() {
        let (a, b) = (u[(i, k)], u[(i, k + 1)]);
        u[(i, k)] = a * c + b * s;
        u[(i, k + 1)] = -a * s.conj() + b * c.conj();
    }
}

/// An orthonormal (complex) basis whose first `k` columns span the invariant
/// subspace of `h` belonging to the eigenvalues where `select` is true, with
/// all eigenvalues in their new order. `None` if the Schur form fails.
pub(crate) fn ordered_schur(
    h: &DMatrix<f64>,
    select: impl Fn(C64) -> bool,
) -> Option<(DMatrix<C64>, usize, Vec<C64>)> {
    let rs = real_schur(h)?;
    let n = h.nrows();
    let mut t = rs.t.map(|v| C64::new(v, 0.0));
    let mut u = rs.u.map(|v| C64::new(v, 0.0));
    // Complex Schur form: triangularise each 2×2 block with its eigenvector.
    for &(s0, sz) in &rs.blocks {
        if sz != 2 {
            continue;
        }
        let (a, b, c, d) = (
            t[(s0, s0)],
            t[(s0, s0 + 1)],
            t[(s0 + 1, s0)],
            t[(s0 + 1, s0 + 1)],
        );
        let half = (a - d) * 0.5;
        let lam = (a + d) * 0.5 + (half * half + b * c).sqrt();
        let (v1, v2) = ((b, lam - a), (lam - d, c));
        let (x0, x1) = if v1.0.norm() + v1.1.norm() >= v2.0.norm() + v2.1.norm() {
            v1
        } else {
            v2
        };
        rotate(&mut t, &mut u, s0, x0, x1);
        t[(s0 + 1, s0)] = C64::new(0.0, 0.0);
    }
    // Move the selected eigenvalues to the top, keeping their relative order.
    let mut top = 0;
    for p in 0..n {
        if !select(t[(p, p)]) {
            continue;
        }
        let mut k = p;
        while k > top {
            let (t11, t22, t12) = (t[(k - 1, k - 1)], t[(k, k)], t[(k - 1, k)]);
            rotate(&mut t, &mut u, k - 1, t12, t22 - t11);
            t[(k, k - 1)] = C64::new(0.0, 0.0);
            t[(k - 1, k - 1)] = t22;
            t[(k, k)] = t11;
            k -= 1;
        }
        top += 1;
    }
    let eig = (0..n).map(|i| t[(i, i)]).collect();
    Some((u, top, eig))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rng::Rng;

    #[test]
    fn quasi_triangular_solves_and_reordering() {
        let mut rng = Rng::new(3);
        for n in [1, 2, 5, 9] {
            let a = DMatrix::from_fn(n, n, |_, _| rng.normal());
            let rs = real_schur(&a).unwrap();
            assert!((&rs.u * &rs.t * rs.u.transpose() - &a).norm() < 1e-12 * a.norm());
            let c = DMatrix::from_fn(n, n, |_, _| rng.normal());
            let y = lyap_quasi_triangular(&rs, &c).unwrap();
            assert!((rs.t.transpose() * &y + &y * &rs.t - &c).norm() < 1e-10 * c.norm());
            let y = stein_quasi_triangular(&rs, &c).unwrap();
            let r = rs.t.transpose() * &y * &rs.t - &y - &c;
            assert!(r.norm() < 1e-9 * c.norm() * (1.0 + y.norm()), "{n}");
            // Ordered basis: the first k columns are invariant.
            let (u, k, eig) = ordered_schur(&a, |z| z.re < 0.0).unwrap();
            assert_eq!(k, eig.iter().filter(|z| z.re < 0.0).count());
            assert!(eig[..k].iter().all(|z| z.re < 0.0));
            let ac = a.map(|v| C64::new(v, 0.0));
            let uh = u.adjoint();
            let tt = &uh * &ac * &u;
            for j in 0..k {
                for i in k..n {
                    assert!(tt[(i, j)].norm() < 1e-11 * a.norm(), "{n}: {i},{j}");
                }
            }
            assert!((&uh * &u - DMatrix::<C64>::identity(n, n)).norm() < 1e-12);
        }
    }
}
