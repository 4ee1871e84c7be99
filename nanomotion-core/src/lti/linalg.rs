//! Dense linear-algebra and polynomial helpers of the LTI toolkit: matrix
//! exponential, balancing, eigenvalues, polynomial roots and products.
//!
//! Polynomials are `&[f64]` in **descending** powers (MATLAB/python-control order).

use super::Complex;
use nalgebra::{DMatrix, DVector};

/// Matrix exponential e^A by scaling and squaring with a Padé(3/5/7/9/13)
/// approximant (Higham 2005, the algorithm behind MATLAB's and scipy's `expm`).
///
/// # Panics
/// If `a` is not square.
pub fn expm(a: &DMatrix<f64>) -> DMatrix<f64> {
    assert!(a.is_square(), "expm: matrix must be square");
    let n = a.nrows();
    if n == 0 {
        return a.clone();
    }
    let ident = DMatrix::<f64>::identity(n, n);
    let norm1 = norm_1(a);
    if !norm1.is_finite() {
        return DMatrix::from_element(n, n, f64::NAN);
    }
    // (theta_m, Padé coefficients b_0..b_m)
    const B3: [f64; 4] = [120.0, 60.0, 12.0, 1.0];
    const B5: [f64; 6] = [30240.0, 15120.0, 3360.0, 420.0, 30.0, 1.0];
    const B7: [f64; 8] = [
        17297280.0, 8648640.0, 1995840.0, 277200.0, 25200.0, 1512.0, 56.0, 1.0,
    ];
    const B9: [f64; 10] = [
        17643225600.0,
        8821612800.0,
        2075673600.0,
        302702400.0,
        30270240.0,
        2162160.0,
        110880.0,
        3960.0,
        90.0,
        1.0,
    ];
    const B13: [f64; 14] = [
        64764752532480000.0,
        32382376266240000.0,
        7771770303897600.0,
        1187353796428800.0,
        129060195264000.0,
        10559470521600.0,
        670442572800.0,
        33522128640.0,
        1323241920.0,
        40840800.0,
        960960.0,
        16380.0,
        182.0,
        1.0,
    ];
    let small: [(f64, &[f64]); 4] = [
        (1.495585217958292e-2, &B3),
        (2.539_398_330_063_23e-1, &B5),
        (9.504178996162932e-1, &B7),
        (2.097847961257068, &B9),
    ];
    for (theta, b) in small {
        if norm1 <= theta {
            let (u, v) = pade_uv_low(a, b, &ident);
            return pade_solve(&u, &v);
        }
    }
    const THETA13: f64 = 5.371920351148152;
    let s = if norm1 > THETA13 {
        (norm1 / THETA13).log2().ceil().max(0.0) as i32
    } else {
        0
    };
    let a_s = a * 2f64.powi(-s);
    let b = &B13;
    let a2 = &a_s * &a_s;
    let a4 = &a2 * &a2;
    let a6 = &a4 * &a2;
    let u_inner = &a6 * (&a6 * b[13] + &a4 * b[11] + &a2 * b[9])
        + &a6 * b[7]
        + &a4 * b[5]
        + &a2 * b[3]
        + &ident * b[1];
    let u = &a_s * u_inner;
    let v = &a6 * (&a6 * b[12] + &a4 * b[10] + &a2 * b[8])
        + &a6 * b[6]
        + &a4 * b[4]
        + &a2 * b[2]
        + &ident * b[0];
    let mut r = pade_solve(&u, &v);
    for _ in 0..s {
        r = &r * &r;
    }
    r
}

fn pade_uv_low(a: &DMatrix<f64>, b: &[f64], ident: &DMatrix<f64>) -> (DMatrix<f64>, DMatrix<f64>) {
    let m = b.len() - 1;
    let a2 = a * a;
    let mut u_inner = ident * b[1];
    let mut v = ident * b[0];
    let mut p = ident.clone();
    let mut k = 2;
    while k <= m {
        p = &p * &a2;
        v += &p * b[k];
        if k < m {
            u_inner += &p * b[k + 1];
        }
        k += 2;
    }
    (a * u_inner, v)
}

fn pade_solve(u: &DMatrix<f64>, v: &DMatrix<f64>) -> DMatrix<f64> {
    let lhs = v - u;
    let rhs = v + u;
    lhs.lu()
        .solve(&rhs)
        .unwrap_or_else(|| DMatrix::from_element(u.nrows(), u.ncols(), f64::NAN))
}

/// Induced 1-norm (maximum absolute column sum).
pub fn norm_1(a: &DMatrix<f64>) -> f64 {
    a.column_iter()
        .map(|c| c.iter().map(|v| v.abs()).sum::<f64>())
        .fold(0.0, f64::max)
}

/// Diagonal similarity balancing (Parlett–Reinsch, powers of two, as LAPACK
/// `gebal` without permutations): returns `(T⁻¹ A T, d)` with `T = diag(d)`.
/// Eigenvalues are unchanged and their numerical computation is better
/// conditioned.
pub fn balance(a: &DMatrix<f64>) -> (DMatrix<f64>, DVector<f64>) {
    let n = a.nrows();
    let mut m = a.clone();
    let mut d = DVector::from_element(n, 1.0);
    if n < 2 {
        return (m, d);
    }
    for _sweep in 0..100 {
        let mut converged = true;
        for i in 0..n {
            let mut c = 0.0;
            let mut r = 0.0;
            for j in 0..n {
                if j != i {
                    c += m[(j, i)].abs();
                    r += m[(i, j)].abs();
                }
            }
            if c == 0.0 || r == 0.0 || !c.is_finite() || !r.is_finite() {
                continue;
            }
            let s = c + r;
            let mut f = 1.0;
            let g = r / 2.0;
            while c < g && f < 1e150 {
                f *= 2.0;
                c *= 4.0;
            }
            let g = r * 2.0;
            while c >= g && f > 1e-150 {
                f /= 2.0;
                c /= 4.0;
            }
            if (c + r) / f < 0.95 * s {
                converged = false;
                d[i] *= f;
                // A <- T^-1 A T: row i divided by f, column i multiplied by f.
                for j in 0..n {
                    m[(i, j)] /= f;
                }
                for j in 0..n {
                    m[(j, i)] *= f;
                }
            }
        }
        if converged {
            break;
        }
    }
    (m, d)
}

/// Eigenvalues of a real square matrix (complex, in no particular order).
///
/// The matrix is balanced first, then reduced by nalgebra's real Schur
/// decomposition. Returns NaNs if the QR iteration fails to converge (not observed
/// on the toolkit's matrices, but reported rather than looping forever).
pub fn eigvals(a: &DMatrix<f64>) -> Vec<Complex<f64>> {
    eigvals_by(a, schur_eigvals)
}

/// Eigenvalues of a real square matrix, as [`eigvals`] (same isolation of
/// exact eigenvalues, same balancing), by the eigenvalue-only Francis
/// double-shift QR iteration of [`hessenberg_eigvals`] instead of nalgebra's
/// full Schur decomposition: no Schur vectors and no updates outside the
/// active block, about a third of the work (`cargo bench -p nanomotion-core
/// --bench lti_numerics -- eigvals`). Same backward stability, different
/// round-off: used where only the values matter and their last bits do not
/// reach a result (the H∞ norm's Hamiltonian test, pole frequencies that
/// start a search, the frequency evaluator's near-pole test).
pub fn eigvals_fast(a: &DMatrix<f64>) -> Vec<Complex<f64>> {
    eigvals_by(a, |b| {
        let n = b.nrows();
        let h = if n > 2 {
            nalgebra::linalg::Hessenberg::new(b.clone()).unpack_h()
        } else {
            b.clone()
        };
        let mut rows: Vec<f64> = (0..n * n).map(|k| h[(k / n, k % n)]).collect();
        hessenberg_eigvals(&mut rows, n).unwrap_or_else(|| schur_eigvals(b))
    })
}

/// [`eigvals`] with the eigenvalues of the balanced active part computed by
/// `core`.
fn eigvals_by(
    a: &DMatrix<f64>,
    core: impl Fn(DMatrix<f64>) -> Vec<Complex<f64>>,
) -> Vec<Complex<f64>> {
    let n = a.nrows();
    assert!(a.is_square(), "eigvals: matrix must be square");
    if n == 0 {
        return Vec::new();
    }
    if a.iter().any(|v| !v.is_finite()) {
        return vec![Complex::new(f64::NAN, f64::NAN); n];
    }
    // Isolate eigenvalues first (LAPACK gebal's permutation step): a row or
    // column whose off-diagonal entries in the active part are exactly zero
    // gives its diagonal entry as an eigenvalue, exactly. A delay chain z⁻ᵈ is
    // nilpotent and deflates completely to d exact zeros, instead of a circle
    // of radius ε^(1/d) from the QR iteration.
    let mut active: Vec<usize> = (0..n).collect();
    let mut isolated = Vec::new();
    loop {
        let found = active.iter().position(|&i| {
            active.iter().all(|&j| j == i || a[(i, j)] == 0.0)
                || active.iter().all(|&j| j == i || a[(j, i)] == 0.0)
        });
        match found {
            Some(k) => {
                let i = active.remove(k);
                isolated.push(Complex::new(a[(i, i)], 0.0));
            }
            None => break,
        }
    }
    if active.is_empty() {
        return isolated;
    }
    if !isolated.is_empty() {
        let sub = DMatrix::from_fn(active.len(), active.len(), |r, c| a[(active[r], active[c])]);
        let mut rest = eigvals_by(&sub, core);
        isolated.append(&mut rest);
        return isolated;
    }
    let (b, _) = balance(a);
    core(b)
}

/// Eigenvalues of a balanced matrix by nalgebra's real Schur decomposition
/// (NaNs if it does not converge).
fn schur_eigvals(b: DMatrix<f64>) -> Vec<Complex<f64>> {
    let n = b.nrows();
    match nalgebra::linalg::Schur::try_new(b.clone(), f64::EPSILON, 10_000 * n.max(1)) {
        Some(s) => s.complex_eigenvalues().iter().copied().collect(),
        None => {
            // Retry with a tiny relative perturbation of the scaling (breaks
            // exceptional cycles of the shifted QR).
            let scale = 1.0 + 1e-13;
            let mut c = b;
            c[(0, 0)] *= scale;
            match nalgebra::linalg::Schur::try_new(c, f64::EPSILON * 4.0, 100_000 * n.max(1)) {
                Some(s) => s.complex_eigenvalues().iter().copied().collect(),
                None => vec![Complex::new(f64::NAN, f64::NAN); n],
            }
        }
    }
}

/// Eigenvalues of the upper Hessenberg matrix `h` (n × n, row-major; entries
/// below the subdiagonal are ignored and overwritten) by the Francis
/// double-shift QR iteration with deflation on the active block only and
/// exceptional shifts after 10 and 20 iterations without deflation (EISPACK
/// `hqr`; LAPACK `dlahqr` without the Schur form). `None` when an eigenvalue
/// takes more than 60 iterations or the values are not finite.
pub fn hessenberg_eigvals(h: &mut [f64], n: usize) -> Option<Vec<Complex<f64>>> {
    assert_eq!(h.len(), n * n, "hessenberg_eigvals: n × n row-major matrix");
    let at = |i: usize, j: usize| i * n + j;
    let sign = |a: f64, b: f64| if b >= 0.0 { a.abs() } else { -a.abs() };
    let mut out = vec![Complex::new(0.0, 0.0); n];
    for i in 2..n {
        for j in 0..i - 1 {
            h[at(i, j)] = 0.0;
        }
    }
    let mut anorm = 0.0;
    for i in 0..n {
        for j in i.saturating_sub(1)..n {
            anorm += h[at(i, j)].abs();
        }
    }
    if !anorm.is_finite() {
        return None;
    }
    // Active block rows/columns l..=nn; eigenvalues deflate off its bottom.
    let mut remaining = n;
    let mut shift = 0.0;
    while remaining > 0 {
        let nn = remaining - 1;
        let mut its = 0;
        loop {
            // The lowest negligible subdiagonal entry splits off l..=nn.
            let mut l = nn;
            while l >= 1 {
                let mut s = h[at(l - 1, l - 1)].abs() + h[at(l, l)].abs();
                if s == 0.0 {
                    s = anorm;
                }
                if h[at(l, l - 1)].abs() <= f64::EPSILON * s {
                    h[at(l, l - 1)] = 0.0;
                    break;
                }
                l -= 1;
            }
            let mut x = h[at(nn, nn)];
            if l == nn {
                out[nn] = Complex::new(x + shift, 0.0);
                remaining -= 1;
                break;
            }
            let mut y = h[at(nn - 1, nn - 1)];
            let mut w = h[at(nn, nn - 1)] * h[at(nn - 1, nn)];
            if l + 1 == nn {
                // A 2 × 2 block: its two eigenvalues.
                let p = 0.5 * (y - x);
                let q = p * p + w;
                let z = q.abs().sqrt();
                x += shift;
                if q >= 0.0 {
                    let z = p + sign(z, p);
                    let second = if z != 0.0 { x - w / z } else { x + z };
                    out[nn - 1] = Complex::new(x + z, 0.0);
                    out[nn] = Complex::new(second, 0.0);
                } else {
                    out[nn - 1] = Complex::new(x + p, -z);
                    out[nn] = Complex::new(x + p, z);
                }
                remaining -= 2;
                break;
            }
            if its == 60 {
                return None;
            }
            if its == 10 || its == 20 || its == 40 {
                // Exceptional shift.
                shift += x;
                for i in 0..=nn {
                    h[at(i, i)] -= x;
                }
                let s = h[at(nn, nn - 1)].abs() + h[at(nn - 1, nn - 2)].abs();
                x = 0.75 * s;
                y = x;
                w = -0.4375 * s * s;
            }
            its += 1;
            // Two consecutive small subdiagonal entries: start the bulge at m.
            let mut m = nn - 2;
            let (mut p, mut q, mut r);
            loop {
                let z = h[at(m, m)];
                let (rr, ss) = (x - z, y - z);
                p = (rr * ss - w) / h[at(m + 1, m)] + h[at(m, m + 1)];
                q = h[at(m + 1, m + 1)] - z - rr - ss;
                r = h[at(m + 2, m + 1)];
                let s = p.abs() + q.abs() + r.abs();
                p /= s;
                q /= s;
                r /= s;
                if m == l {
                    break;
                }
                let u = h[at(m, m - 1)].abs() * (q.abs() + r.abs());
                let v = p.abs() * (h[at(m - 1, m - 1)].abs() + z.abs() + h[at(m + 1, m + 1)].abs());
                if u <= f64::EPSILON * v {
                    break;
                }
                m -= 1;
            }
            for i in m + 2..=nn {
                h[at(i, i - 2)] = 0.0;
                if i != m + 2 {
                    h[at(i, i - 3)] = 0.0;
                }
            }
            // The double-shift QR step on rows/columns l..=nn, by 3 × 3
            // Householder reflections chasing the bulge down.
            for k in m..nn {
                let last = k + 1 == nn;
                if k != m {
                    p = h[at(k, k - 1)];
                    q = h[at(k + 1, k - 1)];
                    r = if last { 0.0 } else { h[at(k + 2, k - 1)] };
                    x = p.abs() + q.abs() + r.abs();
                    if x != 0.0 {
                        p /= x;
                        q /= x;
                        r /= x;
                    }
                }
                let s = sign((p * p + q * q + r * r).sqrt(), p);
                if s == 0.0 {
                    continue;
                }
                if k == m {
                    if l != m {
                        h[at(k, k - 1)] = -h[at(k, k - 1)];
                    }
                } else {
                    h[at(k, k - 1)] = -s * x;
                }
                p += s;
                x = p / s;
                y = q / s;
                let z = r / s;
                q /= p;
                r /= p;
                // Rows k, k + 1 (and k + 2), columns k..=nn: contiguous.
                let (row0, rest) = h[k * n..].split_at_mut(n);
                let (row1, rest) = rest.split_at_mut(n);
                let (row0, row1) = (&mut row0[k..=nn], &mut row1[k..=nn]);
                if last {
                    for (a0, a1) in row0.iter_mut().zip(row1.iter_mut()) {
                        let t = *a0 + q * *a1;
                        *a1 -= t * y;
                        *a0 -= t * x;
                    }
                } else {
                    let row2 = &mut rest[k..=nn];
                    for ((a0, a1), a2) in row0.iter_mut().zip(row1.iter_mut()).zip(row2.iter_mut())
                    {
                        let t = *a0 + q * *a1 + r * *a2;
                        *a2 -= t * z;
                        *a1 -= t * y;
                        *a0 -= t * x;
                    }
                }
                // Columns k, k + 1 (and k + 2), rows l..=min(nn, k + 3).
                let width = if last { 2 } else { 3 };
                for i in l..=nn.min(k + 3) {
                    let c = &mut h[i * n + k..i * n + k + width];
                    let mut t = x * c[0] + y * c[1];
                    if !last {
                        t += z * c[2];
                        c[2] -= t * r;
                    }
                    c[1] -= t * q;
                    c[0] -= t;
                }
            }
        }
    }
    out.iter()
        .all(|v| v.re.is_finite() && v.im.is_finite())
        .then_some(out)
}

/// Remove leading (highest-power) zero coefficients; an all-zero polynomial
/// becomes `[0.0]`.
pub fn poly_trim(p: &[f64]) -> Vec<f64> {
    match p.iter().position(|&c| c != 0.0) {
        Some(i) => p[i..].to_vec(),
        None => vec![0.0],
    }
}

/// Evaluate a real polynomial (descending powers) at a complex point (Horner).
pub fn polyval(p: &[f64], x: Complex<f64>) -> Complex<f64> {
    p.iter().fold(Complex::new(0.0, 0.0), |acc, &c| acc * x + c)
}

/// Product of two polynomials (descending powers).
pub fn polymul(a: &[f64], b: &[f64]) -> Vec<f64> {
    if a.is_empty() || b.is_empty() {
        return Vec::new();
    }
    let mut out = vec![0.0; a.len() + b.len() - 1];
    for (i, &x) in a.iter().enumerate() {
        for (j, &y) in b.iter().enumerate() {
            out[i + j] += x * y;
        }
    }
    out
}

/// Sum of two polynomials (descending powers, aligned at the constant term).
pub fn polyadd(a: &[f64], b: &[f64]) -> Vec<f64> {
    let n = a.len().max(b.len());
    let mut out = vec![0.0; n];
    for (i, &x) in a.iter().rev().enumerate() {
        out[n - 1 - i] += x;
    }
    for (i, &x) in b.iter().rev().enumerate() {
        out[n - 1 - i] += x;
    }
    out
}

/// Monic real polynomial with the given roots (complex roots must come in
/// conjugate pairs; imaginary round-off of the coefficients is dropped).
pub fn poly_from_roots(roots: &[Complex<f64>]) -> Vec<f64> {
    let mut c = vec![Complex::new(1.0, 0.0)];
    for &r in roots {
        let mut next = vec![Complex::new(0.0, 0.0); c.len() + 1];
        for (i, &ci) in c.iter().enumerate() {
            next[i] += ci;
            next[i + 1] -= ci * r;
        }
        c = next;
    }
    c.iter().map(|z| z.re).collect()
}

/// Roots of a real polynomial (descending powers) as eigenvalues of its
/// (balanced) companion matrix, like numpy's `roots`. Leading zeros are ignored;
/// trailing zeros give roots at 0.
pub fn roots(p: &[f64]) -> Vec<Complex<f64>> {
    let p = poly_trim(p);
    let n = p.len() - 1;
    if n == 0 {
        return Vec::new();
    }
    // Trailing zeros are exact roots at 0.
    let nz = p.iter().rev().take_while(|c| **c == 0.0).count();
    if nz > 0 {
        let mut r = roots(&p[..p.len() - nz]);
        r.extend(std::iter::repeat_n(Complex::new(0.0, 0.0), nz));
        return r;
    }
    // A leading coefficient much smaller than the constant term would put
    // overflowing ratios in the companion matrix (NaN eigenvalues): take the
    // roots y of the reversed polynomial instead, x = 1/y (large but finite).
    if p[0].abs() < p[n].abs() {
        let rev: Vec<f64> = p.iter().rev().copied().collect();
        return roots(&rev)
            .into_iter()
            .map(|y| {
                if y.norm() == 0.0 {
                    Complex::new(f64::INFINITY, 0.0)
                } else if y.re.abs() >= y.im.abs() {
                    // Smith's division: no underflow of |y|² for tiny y.
                    let r = y.im / y.re;
                    let d = y.re + y.im * r;
                    Complex::new(1.0 / d, -r / d)
                } else {
                    let r = y.re / y.im;
                    let d = y.re * r + y.im;
                    Complex::new(r / d, -1.0 / d)
                }
            })
            .collect();
    }
    let mut comp = DMatrix::<f64>::zeros(n, n);
    for j in 0..n {
        comp[(0, j)] = -p[j + 1] / p[0];
    }
    for i in 1..n {
        comp[(i, i - 1)] = 1.0;
    }
    eigvals(&comp)
}

/// Sort complex numbers into conjugate pairs: returns the real ones (imaginary
/// part below `tol`·(1+|z|), imaginary part zeroed) and one member (positive
/// imaginary part) of each pair.
pub fn split_conjugates(z: &[Complex<f64>], tol: f64) -> (Vec<f64>, Vec<Complex<f64>>) {
    let mut reals = Vec::new();
    let mut pos = Vec::new();
    for &v in z {
        if v.im.abs() <= tol * (1.0 + v.norm()) {
            reals.push(v.re);
        } else if v.im > 0.0 {
            pos.push(v);
        }
    }
    (reals, pos)
}

/// What a real matrix's spectrum offers [`rescale_modes`]: oscillatory modes
/// (complex pairs) and non-zero real poles (lags).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ModeKinds {
    /// At least one complex pair.
    pub oscillatory: bool,
    /// At least one real eigenvalue away from zero.
    pub lag: bool,
    /// Number of complex pole pairs (oscillatory modes).
    pub pairs: usize,
}

/// Whether an eigenvalue counts as a complex pair's member (|Im λ| above
/// round-off of |λ|).
fn is_oscillatory(l: Complex<f64>) -> bool {
    l.im.abs() > 1e-9 * l.norm()
}

/// The kinds of modes of `a` (see [`ModeKinds`]).
pub fn mode_kinds(a: &DMatrix<f64>) -> ModeKinds {
    let ev = eigvals(a);
    let scale = ev.iter().fold(0.0f64, |m, l| m.max(l.norm()));
    let pairs = ev
        .iter()
        .filter(|&&l| is_oscillatory(l) && l.im > 0.0)
        .count();
    ModeKinds {
        oscillatory: pairs > 0,
        pairs,
        lag: ev
            .iter()
            .any(|&l| !is_oscillatory(l) && l.re.abs() > 1e-9 * scale.max(f64::MIN_POSITIVE)),
    }
}

/// `a` with its modes moved in the complex plane: every complex pair
/// σ ± jω_d becomes `damping_scale`·σ ± jω_d (its decay rate, so its damping,
/// scaled; the damped frequency kept) and every real eigenvalue p becomes
/// `lag_scale`·p, the eigenvectors kept: A' = V f(Λ) V⁻¹. For a 2 × 2 block
/// with a complex pair this is A + (d − 1)·σ·I. The calibration of a plant
/// model whose damping or amplifier lag is a few per cent off. `None` when
/// `a` is not diagonalisable to working accuracy (a repeated mode, a double
/// integrator with a non-unit lag scale), when the scales are not positive and
/// finite, or on non-finite entries.
pub fn rescale_modes(a: &DMatrix<f64>, damping_scale: f64, lag_scale: f64) -> Option<DMatrix<f64>> {
    rescale_modes_each(a, damping_scale, lag_scale, &[]).map(|(a, _)| a)
}

/// The calibration of one complex pole pair after the first (see
/// [`rescale_modes_each`]): its own time scale and its own damping scale,
/// each relative to the model's.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PairScale {
    /// s_k: the pair's poles × s_k (its frequency; damping ratio kept).
    pub frequency: f64,
    /// d_k: the pair's decay rate σ × d_k (its damping ratio × d_k, about).
    pub damping: f64,
    /// g_k: the pair's residues × g_k (its share of the static gain × g_k).
    pub gain: f64,
}

impl PairScale {
    /// The pair as the model has it.
    pub const UNITY: PairScale = PairScale {
        frequency: 1.0,
        damping: 1.0,
        gain: 1.0,
    };
}

/// [`rescale_modes`], and then the 2nd, 3rd, … complex pair (ranked by
/// natural frequency |λ|) given its own scales `higher_pairs[0]`,
/// `higher_pairs[1]`, …: its decay rate × d_k besides the model's damping
/// scale (σ ± jω_d → d·d_k·σ ± jω_d), then its time scale s_k — that mode's
/// term H_k(s) of the partial fractions becomes H_k(s/s_k), its poles × s_k,
/// its damping ratio and its static contribution kept, as the model's time
/// scale does for every mode. Returns A' and the input map T (B ← T·B: the
/// mode's residues × s_k). With the model's time and damping scales this is a
/// frequency and a damping per mode: the calibration of a model whose second
/// mode is off by itself (the damping of two modes comes from different
/// dissipation — a stage's guide, a mount's rubber — and is off by different
/// factors). Pairs beyond the list, and pairs of equal |λ| (which share a
/// rank), keep their frequency and the model's damping scale.
pub fn rescale_modes_each(
    a: &DMatrix<f64>,
    damping_scale: f64,
    lag_scale: f64,
    higher_pairs: &[PairScale],
) -> Option<(DMatrix<f64>, DMatrix<f64>)> {
    let positive = |v: f64| v.is_finite() && v > 0.0;
    if !a.is_square()
        || !positive(damping_scale)
        || !positive(lag_scale)
        || !higher_pairs
            .iter()
            .all(|s| positive(s.frequency) && positive(s.damping) && positive(s.gain))
    {
        return None;
    }
    if damping_scale == 1.0
        && lag_scale == 1.0
        && higher_pairs.iter().all(|&s| s == PairScale::UNITY)
    {
        return Some((a.clone(), DMatrix::identity(a.nrows(), a.nrows())));
    }
    let n = a.nrows();
    let ev = eigvals(a);
    if ev.iter().any(|l| !l.re.is_finite() || !l.im.is_finite()) {
        return None;
    }
    // A pair's rank: how many pairs have a smaller natural frequency (the
    // conjugates share it: same |λ|, compared with a relative tolerance).
    let upper: Vec<f64> = ev
        .iter()
        .filter(|&&l| is_oscillatory(l) && l.im > 0.0)
        .map(|l| l.norm())
        .collect();
    let rank = |l: Complex<f64>| {
        let r = l.norm();
        upper.iter().filter(|&&u| u < r * (1.0 - 1e-9)).count()
    };
    // Per eigenvalue: its own scales (unity but for the higher pairs).
    let own: Vec<PairScale> = ev
        .iter()
        .map(|&l| {
            if is_oscillatory(l) {
                rank(l)
                    .checked_sub(1)
                    .and_then(|j| higher_pairs.get(j))
                    .copied()
                    .unwrap_or(PairScale::UNITY)
            } else {
                PairScale::UNITY
            }
        })
        .collect();
    let own_scale: Vec<f64> = own.iter().map(|s| s.frequency * s.gain).collect();
    let moved: Vec<Complex<f64>> = ev
        .iter()
        .zip(&own)
        .map(|(&l, s)| {
            if is_oscillatory(l) {
                Complex::new(damping_scale * s.damping * l.re, l.im) * s.frequency
            } else {
                Complex::new(lag_scale * l.re, 0.0)
            }
        })
        .collect();
    // Eigenvectors: the right singular vector of the smallest singular value
    // of (A − λI).
    let ac = a.map(|v| Complex::new(v, 0.0));
    let mut v = DMatrix::<Complex<f64>>::zeros(n, n);
    for (k, &l) in ev.iter().enumerate() {
        let shifted = &ac - DMatrix::<Complex<f64>>::identity(n, n) * l;
        let svd = shifted.svd(false, true);
        let v_t = svd.v_t?;
        let (imin, _) =
            svd.singular_values
                .iter()
                .enumerate()
                .fold(
                    (0, f64::INFINITY),
                    |b, (i, &s)| if s < b.1 { (i, s) } else { b },
                );
        for r in 0..n {
            v[(r, k)] = v_t[(imin, r)].conj();
        }
    }
    let v_inv = v.clone().try_inverse()?;
    let norm = |m: &DMatrix<Complex<f64>>| m.iter().map(|z| z.norm()).fold(0.0, f64::max);
    let condition = norm(&v) * norm(&v_inv);
    if condition.is_nan() || condition >= 1e8 {
        return None;
    }
    let lambda = DMatrix::from_diagonal(&DVector::from_vec(moved));
    let out = &v * lambda * &v_inv;
    let a_scale = a.amax().max(f64::MIN_POSITIVE);
    let input_map =
        &v * DMatrix::from_diagonal(&DVector::from_iterator(
            n,
            own_scale.iter().map(|&s| Complex::new(s, 0.0)),
        )) * &v_inv;
    let complex_part = |m: &DMatrix<Complex<f64>>, scale: f64| {
        m.iter().any(|z| z.im.is_nan() || z.im.abs() > 1e-8 * scale)
    };
    let map_scale = own_scale.iter().fold(1.0f64, |m, &s| m.max(s));
    if complex_part(&out, a_scale) || complex_part(&input_map, map_scale) {
        return None;
    }
    Some((out.map(|z| z.re), input_map.map(|z| z.re)))
}

/// The bracket a golden-section search for a maximum of `f` on [a, b]
/// leaves after `iterations` steps: `(a, b, x1, x2)`, the interval and its
/// two interior points (x1 < x2). `f` is unimodal on [a, b] for the result to
/// mean the maximum; each step shrinks the interval by 0.618 with one call.
pub fn golden_section_max(
    mut f: impl FnMut(f64) -> f64,
    a: f64,
    b: f64,
    iterations: usize,
) -> (f64, f64, f64, f64) {
    let g = 0.5 * (5f64.sqrt() - 1.0);
    let (mut a, mut b) = (a, b);
    let (mut x1, mut x2) = (b - g * (b - a), a + g * (b - a));
    let (mut f1, mut f2) = (f(x1), f(x2));
    for _ in 0..iterations {
        if f1 > f2 {
            b = x2;
            x2 = x1;
            f2 = f1;
            x1 = b - g * (b - a);
            f1 = f(x1);
        } else {
            a = x1;
            x1 = x2;
            f1 = f2;
            x2 = a + g * (b - a);
            f2 = f(x2);
        }
    }
    (a, b, x1, x2)
}

/// Complex linear solve `M X = R` for a complex square `M`.
pub fn solve_complex(
    m: DMatrix<Complex<f64>>,
    r: &DMatrix<Complex<f64>>,
) -> Option<DMatrix<Complex<f64>>> {
    m.lu().solve(r)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn close(a: &DMatrix<f64>, b: &DMatrix<f64>, tol: f64) -> bool {
        (a - b).amax() <= tol * (1.0 + b.amax())
    }

    #[test]
    fn rescale_modes_matches_the_closed_forms() {
        // A 2 × 2 block with poles σ ± jω_d: f(A) = A + (d − 1)σI; a real
        // pole p: ℓp. Mixed in one matrix behind a similarity T, the result
        // must be T · blockdiag(closed forms) · T⁻¹.
        for &(w, z, p, d, l) in &[
            (10.0, 0.05, -3.0, 1.3, 0.8),
            (2.0 * std::f64::consts::PI * 150.0, 0.01, -4000.0, 0.7, 1.1),
            (1.0, 0.5, -0.2, 1.0, 2.0),
        ] {
            let sigma = -z * w;
            let pair = DMatrix::from_row_slice(2, 2, &[0.0, 1.0, -w * w, -2.0 * z * w]);
            let pair_moved = &pair + DMatrix::identity(2, 2) * ((d - 1.0) * sigma);
            let mut blk = DMatrix::zeros(3, 3);
            let mut want_blk = DMatrix::zeros(3, 3);
            blk.view_mut((0, 0), (2, 2)).copy_from(&pair);
            want_blk.view_mut((0, 0), (2, 2)).copy_from(&pair_moved);
            blk[(2, 2)] = p;
            want_blk[(2, 2)] = l * p;
            let t = DMatrix::from_row_slice(3, 3, &[1.0, 0.3, -0.2, 0.1, 2.0, 0.5, -0.4, 0.2, 1.5]);
            let t_inv = t.clone().try_inverse().unwrap();
            let a = &t * &blk * &t_inv;
            let want = &t * &want_blk * &t_inv;
            let got = rescale_modes(&a, d, l).unwrap();
            assert!(close(&got, &want, 1e-9), "{got} vs {want}");
            assert_eq!(
                mode_kinds(&a),
                ModeKinds {
                    oscillatory: true,
                    lag: true,
                    pairs: 1
                }
            );
        }
        // Unit scales give A back exactly; a repeated mode (a Jordan block) is
        // refused; an integrator (λ = 0) is not a lag.
        let jordan = DMatrix::from_row_slice(2, 2, &[-1.0, 1.0, 0.0, -1.0]);
        assert_eq!(rescale_modes(&jordan, 1.0, 1.0), Some(jordan.clone()));
        assert_eq!(rescale_modes(&jordan, 1.0, 1.2), None);
        let free_mass = DMatrix::from_row_slice(2, 2, &[0.0, 1.0, 0.0, -2.0]);
        // 1/(s(s + 2)) with the residues kept and the pole at −2 moved to −3:
        // 1/(2s) − 1/(2(s + 3)) = 1.5/(s(s + 3)), i.e. A' = [[0, 1.5], [0, −3]]
        // with B = [0; 1], C = [1, 0].
        let moved = rescale_modes(&free_mass, 1.0, 1.5).unwrap();
        let want = DMatrix::from_row_slice(2, 2, &[0.0, 1.5, 0.0, -3.0]);
        assert!(close(&moved, &want, 1e-12), "{moved}");
        assert_eq!(
            mode_kinds(&DMatrix::from_row_slice(1, 1, &[0.0])),
            ModeKinds {
                oscillatory: false,
                lag: false,
                pairs: 0
            }
        );
        assert_eq!(rescale_modes(&free_mass, -1.0, 1.0), None);
    }

    #[test]
    fn rescale_modes_each_moves_one_pair_by_itself() {
        // Two pairs (ω 10 and 40) and a lag behind a similarity T: scaling the
        // second pair by s moves only its 2 × 2 block, A₂ → s·A₂ (both σ and
        // ω_d × s), after the damping scale, and its inputs B₂ → s·B₂ (the
        // time scale of that mode alone); the first pair and the lag follow
        // `rescale_modes`. The pair ranking follows |λ|, not the order of the
        // blocks (the faster pair is placed first).
        let pair =
            |w: f64, z: f64| DMatrix::from_row_slice(2, 2, &[0.0, 1.0, -w * w, -2.0 * z * w]);
        let (slow, fast) = (pair(10.0, 0.05), pair(40.0, 0.02));
        let (d, l, s, d2, g2) = (1.2, 0.9, 1.07, 0.8, 0.7);
        let shift_by = |m: &DMatrix<f64>, w: f64, z: f64, d: f64| {
            m + DMatrix::identity(2, 2) * ((d - 1.0) * (-z * w))
        };
        let shift = |m: &DMatrix<f64>, w: f64, z: f64| shift_by(m, w, z, d);
        let mut blk = DMatrix::zeros(5, 5);
        let mut want_blk = DMatrix::zeros(5, 5);
        blk.view_mut((0, 0), (2, 2)).copy_from(&fast);
        blk.view_mut((2, 2), (2, 2)).copy_from(&slow);
        blk[(4, 4)] = -7.0;
        want_blk
            .view_mut((0, 0), (2, 2))
            .copy_from(&(shift_by(&fast, 40.0, 0.02, d * d2) * s));
        want_blk
            .view_mut((2, 2), (2, 2))
            .copy_from(&shift(&slow, 10.0, 0.05));
        want_blk[(4, 4)] = -7.0 * l;
        let t = DMatrix::from_fn(5, 5, |i, j| {
            if i == j {
                2.0
            } else {
                0.1 * (i as f64 - 0.5 * j as f64)
            }
        });
        let t_inv = t.clone().try_inverse().unwrap();
        let a = &t * &blk * &t_inv;
        let want = &t * &want_blk * &t_inv;
        let second = PairScale {
            frequency: s,
            damping: d2,
            gain: g2,
        };
        let (got, input_map) = rescale_modes_each(&a, d, l, &[second]).unwrap();
        assert!(close(&got, &want, 1e-9), "{got} vs {want}");
        // B ← T·B scales that mode's inputs by s·g₂: its residues × s, so its
        // term H₂(s) becomes H₂(s/s₂) with its static contribution kept, and
        // then × g₂ (its own damping scale moves its poles, not its residues).
        let mut want_map = DMatrix::identity(5, 5);
        want_map.view_mut((0, 0), (2, 2)).scale_mut(s * g2);
        let want_map = &t * want_map * &t_inv;
        assert!(
            close(&input_map, &want_map, 1e-9),
            "{input_map} vs {want_map}"
        );
        assert_eq!(mode_kinds(&a).pairs, 2);
        // Unit scales everywhere give A back; a scale beyond the pairs is unused.
        assert_eq!(
            rescale_modes_each(&a, 1.0, 1.0, &[PairScale::UNITY]).map(|(m, _)| m),
            Some(a.clone())
        );
        let beyond = PairScale {
            frequency: 1.3,
            damping: 0.5,
            gain: 2.0,
        };
        let (only_first, _) = rescale_modes_each(&a, d, l, &[PairScale::UNITY, beyond]).unwrap();
        assert!(close(&only_first, &rescale_modes(&a, d, l).unwrap(), 1e-12));
        for bad in [
            (0.0, 1.0, 1.0),
            (1.0, 0.0, 1.0),
            (1.0, 1.0, -1.0),
            (1.0, f64::NAN, 1.0),
        ] {
            let bad = PairScale {
                frequency: bad.0,
                damping: bad.1,
                gain: bad.2,
            };
            assert_eq!(rescale_modes_each(&a, 1.0, 1.0, &[bad]), None);
        }
    }

    #[test]
    fn golden_section_finds_the_peak_of_a_parabola() {
        // −(x − 0.3)² on [−1, 2]: the bracket closes on 0.3 as 0.618ⁿ.
        let (a, b, x1, x2) = golden_section_max(|x| -(x - 0.3) * (x - 0.3), -1.0, 2.0, 60);
        assert!(a <= x1 && x1 <= x2 && x2 <= b);
        assert!((b - a) < 3.0 * 0.62f64.powi(60));
        assert!((0.5 * (a + b) - 0.3).abs() < 1e-10);
    }

    #[test]
    fn expm_rotation_matches_closed_form() {
        for &w in &[0.1, 1.0, 3.0, 10.0, 100.0, 1234.5] {
            let a = DMatrix::from_row_slice(2, 2, &[0.0, -w, w, 0.0]);
            let e = expm(&a);
            let r = DMatrix::from_row_slice(2, 2, &[w.cos(), -w.sin(), w.sin(), w.cos()]);
            assert!(close(&e, &r, 1e-11), "w={w}: {e} vs {r}");
        }
    }

    #[test]
    fn expm_diagonal_and_nilpotent() {
        for &s in &[1e-4, 0.01, 0.2, 0.9, 2.0, 5.0, 40.0] {
            let a = DMatrix::from_diagonal(&DVector::from_vec(vec![-s, s, 0.5 * s, 0.0]));
            let e = expm(&a);
            for i in 0..4 {
                let want = a[(i, i)].exp();
                assert!((e[(i, i)] - want).abs() <= 1e-13 * want.max(1.0), "s={s}");
            }
            // Nilpotent N (3x3 upper shift times s): e^N = I + N + N²/2.
            let n = DMatrix::from_row_slice(3, 3, &[0.0, s, 0.0, 0.0, 0.0, s, 0.0, 0.0, 0.0]);
            let want = DMatrix::identity(3, 3) + &n + &n * &n * 0.5;
            assert!(close(&expm(&n), &want, 1e-13), "s={s}");
        }
    }

    #[test]
    fn expm_agrees_with_nalgebra_and_taylor() {
        let mut rng = crate::rng::Rng::new(7);
        for trial in 0..30 {
            let n = 1 + trial % 6;
            let scale = [0.01, 0.3, 1.0, 4.0, 20.0][trial % 5];
            let a = DMatrix::from_fn(n, n, |_, _| scale * (rng.uniform() * 2.0 - 1.0));
            let e = expm(&a);
            let reference = a.exp();
            assert!(close(&e, &reference, 1e-9), "trial {trial}");
            // e^A e^-A = I (well conditioned only for moderate norms)
            if scale > 4.0 {
                continue;
            }
            let prod = &e * expm(&(-&a));
            assert!(
                close(&prod, &DMatrix::identity(n, n), 1e-8),
                "trial {trial}"
            );
        }
    }

    #[test]
    fn roots_and_poly_round_trip() {
        let r = roots(&[1.0, -6.0, 11.0, -6.0]);
        let mut re: Vec<f64> = r.iter().map(|z| z.re).collect();
        re.sort_by(|a, b| a.partial_cmp(b).unwrap());
        for (x, want) in re.iter().zip([1.0, 2.0, 3.0]) {
            assert!((x - want).abs() < 1e-10);
        }
        let z = [
            Complex::new(-0.3, 0.8),
            Complex::new(-0.3, -0.8),
            Complex::new(0.5, 0.0),
        ];
        let p = poly_from_roots(&z);
        for &zi in &z {
            assert!(polyval(&p, zi).norm() < 1e-14);
        }
        assert_eq!(polymul(&[1.0, 1.0], &[1.0, -1.0]), vec![1.0, 0.0, -1.0]);
        assert_eq!(polyadd(&[1.0, 0.0, 0.0], &[2.0, 3.0]), vec![1.0, 2.0, 3.0]);
        assert_eq!(poly_trim(&[0.0, 0.0, 2.0, 1.0]), vec![2.0, 1.0]);
    }

    /// The largest distance from an eigenvalue in `got` to its partner in
    /// `want`, paired greedily (nearest unused partner).
    fn spectrum_distance(got: &[Complex<f64>], want: &[Complex<f64>]) -> f64 {
        assert_eq!(got.len(), want.len());
        let mut used = vec![false; want.len()];
        let mut worst: f64 = 0.0;
        for g in got {
            let (k, d) = want
                .iter()
                .enumerate()
                .filter(|(k, _)| !used[*k])
                .map(|(k, w)| (k, (g - w).norm()))
                .min_by(|a, b| a.1.total_cmp(&b.1))
                .unwrap();
            used[k] = true;
            worst = worst.max(d);
        }
        worst
    }

    /// The eigenvalue-only QR iteration against closed forms: modal
    /// matrices (real poles and 2 × 2 rotation–scaling blocks with known
    /// eigenvalues, spread over six decades) behind a random orthogonal
    /// similarity, and against nalgebra's Schur form ([`eigvals`]) on random
    /// dense matrices.
    #[test]
    fn eigvals_fast_matches_closed_forms_and_the_schur_form() {
        let mut rng = crate::rng::Rng::new(2909);
        for &n in &[1usize, 2, 3, 4, 7, 16, 45, 120] {
            let mut blk = DMatrix::zeros(n, n);
            let mut want = Vec::new();
            let pairs = n / 3;
            let reals = n - 2 * pairs;
            for i in 0..reals {
                let lam = -10f64.powf(-3.0 + 6.0 * i as f64 / reals.max(2) as f64);
                blk[(i, i)] = lam;
                want.push(Complex::new(lam, 0.0));
            }
            for k in 0..pairs {
                let i = reals + 2 * k;
                let wd = 10f64.powf(-2.0 + 5.0 * k as f64 / pairs.max(2) as f64);
                let sigma = -0.05 * wd;
                blk[(i, i)] = sigma;
                blk[(i + 1, i + 1)] = sigma;
                blk[(i, i + 1)] = wd;
                blk[(i + 1, i)] = -wd;
                want.push(Complex::new(sigma, wd));
                want.push(Complex::new(sigma, -wd));
            }
            let q = DMatrix::from_fn(n, n, |_, _| rng.uniform_in(-1.0, 1.0))
                .qr()
                .q();
            let a = &q * &blk * q.transpose();
            let scale = want.iter().map(|w| w.norm()).fold(0.0, f64::max);
            let d = spectrum_distance(&eigvals_fast(&a), &want);
            assert!(d <= 1e-12 * n as f64 * scale, "modal n={n}: {d:e}");
            let dense = DMatrix::from_fn(n, n, |_, _| rng.normal());
            let d = spectrum_distance(&eigvals_fast(&dense), &eigvals(&dense));
            assert!(d <= 1e-10 * norm_1(&dense), "random n={n}: {d:e}");
        }
        // Exact cases: zero, identity (all repeated), a nilpotent delay chain.
        let z = eigvals_fast(&DMatrix::zeros(5, 5));
        assert!(z.iter().all(|v| *v == Complex::new(0.0, 0.0)));
        let i = eigvals_fast(&DMatrix::identity(6, 6));
        assert!(i.iter().all(|v| *v == Complex::new(1.0, 0.0)));
        let chain = DMatrix::from_fn(8, 8, |r, c| if r == c + 1 { 1.0 } else { 0.0 });
        assert!(eigvals_fast(&chain).iter().all(|v| v.norm() == 0.0));
        // A Hamiltonian matrix: its eigenvalues come in pairs ±λ.
        let n = 30;
        let a = DMatrix::from_fn(n, n, |_, _| rng.normal());
        let g = DMatrix::from_fn(n, n, |_, _| rng.normal());
        let g = &g * g.transpose();
        let f = DMatrix::from_fn(n, n, |_, _| rng.normal());
        let f = &f * f.transpose();
        let mut h = DMatrix::zeros(2 * n, 2 * n);
        h.view_mut((0, 0), (n, n)).copy_from(&a);
        h.view_mut((0, n), (n, n)).copy_from(&(-&g));
        h.view_mut((n, 0), (n, n)).copy_from(&(-&f));
        h.view_mut((n, n), (n, n)).copy_from(&(-a.transpose()));
        let ev = eigvals_fast(&h);
        let neg: Vec<Complex<f64>> = ev.iter().map(|v| -v).collect();
        assert!(spectrum_distance(&ev, &neg) <= 1e-9 * norm_1(&h));
        assert!(spectrum_distance(&ev, &eigvals(&h)) <= 1e-9 * norm_1(&h));
    }

    #[test]
    fn balance_preserves_eigenvalues() {
        let a = DMatrix::from_row_slice(3, 3, &[1.0, 1e6, 0.0, 1e-6, 2.0, 1e5, 0.0, 1e-5, 3.0]);
        let (b, d) = balance(&a);
        let t = DMatrix::from_diagonal(&d);
        let back = &t * &b * t.try_inverse().unwrap();
        assert!(close(&back, &a, 1e-14));
        assert!(b.amax() < a.amax());
        let mut ev: Vec<f64> = eigvals(&a).iter().map(|z| z.re).collect();
        ev.sort_by(|x, y| x.partial_cmp(y).unwrap());
        let tr: f64 = ev.iter().sum();
        assert!((tr - 6.0).abs() < 1e-9);
    }
}
