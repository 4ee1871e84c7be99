//! Cross-check of the dense LTI numerics against independent computations on
//! seeded random problems (issue 14): ≥ 100 problems per function, sizes up to
//! 40, a quarter of them badly scaled by a diagonal similarity with entries
//! 10^±3.
//!
//! - `lyap`/`dlyap`: the Kronecker linear solve (n ≤ 10) and the residual;
//! - `care`: Kleinman's Newton iteration with Kronecker Lyapunov solves
//!   (n ≤ 8), the componentwise backward error computed here, closed-loop
//!   stability;
//! - `dare`: the Riccati difference recursion from X = 0 (n ≤ 6), the
//!   backward error, closed-loop stability;
//! - `hinfnorm`: a dense logarithmic frequency grid (the norm must dominate it)
//!   and σ̄ at the returned peak frequency (the norm must be attained).

use nalgebra::{Complex, DMatrix};
use nanomotion_core::lti::linalg::eigvals;
use nanomotion_core::lti::{StateSpace, care, dare, dlyap, hinfnorm, lyap};
use nanomotion_core::rng::Rng;

const SIZES: [usize; 10] = [1, 2, 3, 4, 6, 8, 10, 16, 25, 40];
const CASES: usize = 100;
const SCALE_DECADES: f64 = 3.0;

fn randn(rng: &mut Rng, r: usize, c: usize) -> DMatrix<f64> {
    DMatrix::from_fn(r, c, |_, _| rng.normal())
}

/// Diagonal scaling T (entries 10^u, u ∈ [−3, 3]) for every fourth case, else I.
fn scaling(rng: &mut Rng, n: usize, case: usize) -> Vec<f64> {
    (0..n)
        .map(|_| {
            if case % 4 == 3 {
                10f64.powf(rng.uniform_in(-SCALE_DECADES, SCALE_DECADES))
            } else {
                1.0
            }
        })
        .collect()
}

/// T⁻¹AT.
fn similar(a: &DMatrix<f64>, t: &[f64]) -> DMatrix<f64> {
    DMatrix::from_fn(a.nrows(), a.ncols(), |i, j| a[(i, j)] * t[j] / t[i])
}

/// TᵀQT for symmetric Q (the Q of the transformed problem).
fn congruent(q: &DMatrix<f64>, t: &[f64]) -> DMatrix<f64> {
    DMatrix::from_fn(q.nrows(), q.ncols(), |i, j| q[(i, j)] * t[i] * t[j])
}

/// T⁻¹XT⁻¹: the solution of the unscaled problem.
fn unscale(x: &DMatrix<f64>, t: &[f64]) -> DMatrix<f64> {
    DMatrix::from_fn(x.nrows(), x.ncols(), |i, j| x[(i, j)] / (t[i] * t[j]))
}

fn spectral_abscissa(a: &DMatrix<f64>) -> f64 {
    eigvals(a)
        .iter()
        .map(|l| l.re)
        .fold(f64::NEG_INFINITY, f64::max)
}

fn spectral_radius(a: &DMatrix<f64>) -> f64 {
    eigvals(a).iter().map(|l| l.norm()).fold(0.0, f64::max)
}

/// Σ Lᵢ X Rᵢ = −Q by the Kronecker form (the pre-issue-14 algorithm).
fn kronecker(terms: &[(DMatrix<f64>, DMatrix<f64>)], q: &DMatrix<f64>) -> DMatrix<f64> {
    let n = q.nrows();
    let mut k = DMatrix::zeros(n * n, n * n);
    for (l, r) in terms {
        k += r.transpose().kronecker(l);
    }
    let rhs = DMatrix::from_column_slice(n * n, 1, (-q).as_slice());
    let v = k.lu().solve(&rhs).unwrap();
    DMatrix::from_column_slice(n, n, v.as_slice())
}

fn kron_lyap(a: &DMatrix<f64>, q: &DMatrix<f64>) -> DMatrix<f64> {
    let i = DMatrix::identity(a.nrows(), a.nrows());
    kronecker(&[(a.transpose(), i.clone()), (i, a.clone())], q)
}

fn kron_dlyap(a: &DMatrix<f64>, q: &DMatrix<f64>) -> DMatrix<f64> {
    let i = DMatrix::identity(a.nrows(), a.nrows());
    kronecker(&[(a.transpose(), a.clone()), (-&i, i)], q)
}

/// maxᵢⱼ |R|ᵢⱼ / Fᵢⱼ (floor entries below ε·max F count as ε·max F).
fn componentwise(res: &DMatrix<f64>, floor: &DMatrix<f64>) -> f64 {
    let fmax = floor.amax();
    res.iter()
        .zip(floor.iter())
        .map(|(r, f)| r.abs() / f.max(f64::EPSILON * fmax))
        .fold(0.0, f64::max)
}

fn problem(rng: &mut Rng, case: usize) -> (usize, Vec<f64>) {
    let n = SIZES[case % SIZES.len()];
    let t = scaling(rng, n, case);
    (n, t)
}

#[test]
fn lyap_and_dlyap_against_kronecker_and_residual() {
    let mut rng = Rng::new(101);
    for case in 0..CASES {
        let (n, t) = problem(&mut rng, case);
        let a0 = randn(&mut rng, n, n);
        let a0 = &a0 - DMatrix::identity(n, n) * (spectral_abscissa(&a0) + 0.2);
        let c = randn(&mut rng, n, n);
        let q0 = &c * c.transpose();
        let (a, q) = (similar(&a0, &t), congruent(&q0, &t));
        let x = lyap(&a, &q).unwrap();
        // The residual of the unscaled equation for X₀ = T⁻¹XT⁻¹.
        let x0 = unscale(&x, &t);
        let ax = a0.transpose() * &x0;
        let res = &ax + ax.transpose() + &q0;
        let rel = res.norm() / (2.0 * ax.norm() + q0.norm());
        assert!(rel < 1e-12, "case {case} (n = {n}): lyap residual {rel:e}");
        if n <= 10 {
            let xk = kron_lyap(&a, &q);
            assert!(
                (&xk - &x).norm() <= 1e-8 * xk.norm(),
                "case {case}: lyap vs Kronecker"
            );
        }
        // Discrete: spectral radius 0.95.
        let rho = 0.95 / spectral_radius(&a);
        let ad = &a * rho;
        let x = dlyap(&ad, &q).unwrap();
        let (ad0, x0) = (&a0 * rho, unscale(&x, &t));
        let axa = ad0.transpose() * &x0 * &ad0;
        let res = &axa - &x0 + &q0;
        let rel = res.norm() / (axa.norm() + x0.norm() + q0.norm());
        assert!(rel < 1e-12, "case {case} (n = {n}): dlyap residual {rel:e}");
        if n <= 10 {
            let xk = kron_dlyap(&ad, &q);
            assert!(
                (&xk - &x).norm() <= 1e-8 * xk.norm(),
                "case {case}: dlyap vs Kronecker"
            );
        }
    }
}

fn care_backward(
    a: &DMatrix<f64>,
    b: &DMatrix<f64>,
    q: &DMatrix<f64>,
    r: &DMatrix<f64>,
    x: &DMatrix<f64>,
) -> f64 {
    let ri = r.clone().try_inverse().unwrap();
    let res = a.transpose() * x + x * a - x * b * &ri * b.transpose() * x + q;
    let fa = a.transpose().abs() * x.abs();
    let xb = x.abs() * b.abs();
    componentwise(
        &res,
        &(&fa + fa.transpose() + &xb * ri.abs() * xb.transpose() + q.abs()),
    )
}

fn dare_backward(
    a: &DMatrix<f64>,
    b: &DMatrix<f64>,
    q: &DMatrix<f64>,
    r: &DMatrix<f64>,
    x: &DMatrix<f64>,
) -> f64 {
    let s = (r + b.transpose() * x * b).try_inverse().unwrap();
    let bxa = b.transpose() * x * a;
    let res = a.transpose() * x * a - x - bxa.transpose() * &s * &bxa + q;
    let bxa_abs = b.transpose().abs() * x.abs() * a.abs();
    let floor = a.transpose().abs() * x.abs() * a.abs()
        + x.abs()
        + bxa_abs.transpose() * s.abs() * &bxa_abs
        + q.abs();
    componentwise(&res, &floor)
}

/// (A, B, Q, R) with m inputs; R = 10^k·I with k ∈ {0, −4, −8} cycling.
fn lq_problem(rng: &mut Rng, case: usize) -> [DMatrix<f64>; 4] {
    let (n, t) = problem(rng, case);
    // Up to n/4 inputs: random systems with 2 inputs and 40 states are
    // numerically uncontrollable (PBH distances ~1e-5), which the solvers
    // report as such instead of returning an X.
    let m = (1 + case % 3).max(n / 4).min(n.max(1));
    let a = randn(rng, n, n);
    let b = randn(rng, n, m);
    let c = randn(rng, n, n);
    let q = &c * c.transpose() / n as f64 + DMatrix::identity(n, n) * 0.1;
    let r = DMatrix::identity(m, m) * [1.0, 1e-4, 1e-8][case % 3];
    // x = T x̃: Ã = T⁻¹AT, B̃ = T⁻¹B, Q̃ = TQT.
    let bt = DMatrix::from_fn(n, m, |i, j| b[(i, j)] / t[i]);
    [similar(&a, &t), bt, congruent(&q, &t), r]
}

/// Kleinman's iteration with Kronecker Lyapunov solves from a stabilising gain.
fn kleinman(
    a: &DMatrix<f64>,
    b: &DMatrix<f64>,
    q: &DMatrix<f64>,
    r: &DMatrix<f64>,
    k0: DMatrix<f64>,
) -> DMatrix<f64> {
    let ri = r.clone().try_inverse().unwrap();
    let mut k = k0;
    let mut x = DMatrix::zeros(a.nrows(), a.nrows());
    for _ in 0..40 {
        let acl = a - b * &k;
        let xn = kron_lyap(&acl, &(q + k.transpose() * r * &k));
        let xn = (&xn + xn.transpose()) * 0.5;
        let done = (&xn - &x).norm() <= 1e-15 * xn.norm();
        x = xn;
        k = &ri * b.transpose() * &x;
        if done {
            break;
        }
    }
    x
}

#[test]
fn care_against_kleinman_and_backward_error() {
    let mut rng = Rng::new(202);
    for case in 0..CASES {
        let [a, b, q, r] = lq_problem(&mut rng, case);
        let n = a.nrows();
        let s = care(&a, &b, &q, &r, None).unwrap_or_else(|e| panic!("case {case} (n = {n}): {e}"));
        let be = care_backward(&a, &b, &q, &r, &s.x);
        assert!(be < 1e-12, "case {case} (n = {n}): backward error {be:e}");
        assert!(
            s.closed_loop_poles.iter().all(|p| p.re < 0.0),
            "case {case}"
        );
        if n <= 8 && case % 4 != 3 && r[(0, 0)] >= 1e-4 {
            // Kleinman from a perturbed stabilising gain: it converges to the
            // unique stabilising solution from any stabilising K₀.
            let k0 = &s.gain * 1.1;
            assert!(eigvals(&(&a - &b * &k0)).iter().all(|p| p.re < 0.0));
            let xk = kleinman(&a, &b, &q, &r, k0);
            assert!(
                (&xk - &s.x).norm() <= 1e-7 * s.x.norm(),
                "case {case}: CARE vs Kleinman {:e}",
                (&xk - &s.x).norm() / s.x.norm()
            );
        }
    }
}

#[test]
fn dare_against_recursion_and_backward_error() {
    let mut rng = Rng::new(303);
    for case in 0..CASES {
        let [a, b, q, r] = lq_problem(&mut rng, case);
        let n = a.nrows();
        let ad = &a * (1.1 / spectral_radius(&a));
        let s =
            dare(&ad, &b, &q, &r, None).unwrap_or_else(|e| panic!("case {case} (n = {n}): {e}"));
        let be = dare_backward(&ad, &b, &q, &r, &s.x);
        assert!(be < 1e-12, "case {case} (n = {n}): backward error {be:e}");
        assert!(
            s.closed_loop_poles.iter().all(|p| p.norm() < 1.0),
            "case {case}"
        );
        if n <= 6 && case % 4 != 3 && r[(0, 0)] >= 1e-4 {
            let mut x = DMatrix::zeros(n, n);
            for _ in 0..5000 {
                let k = (&r + b.transpose() * &x * &b).try_inverse().unwrap()
                    * b.transpose()
                    * &x
                    * &ad;
                let xn = ad.transpose() * &x * &ad - ad.transpose() * &x * &b * &k + &q;
                x = (&xn + xn.transpose()) * 0.5;
            }
            assert!(
                (&x - &s.x).norm() <= 1e-7 * s.x.norm(),
                "case {case}: DARE vs recursion {:e}",
                (&x - &s.x).norm() / s.x.norm()
            );
        }
    }
}

#[test]
fn hinfnorm_against_a_dense_grid_and_its_own_peak() {
    let mut rng = Rng::new(404);
    for case in 0..CASES {
        let (n, t) = problem(&mut rng, case);
        let (p, m) = (1 + case % 2, 1 + (case / 2) % 2);
        let a = randn(&mut rng, n, n);
        let a = &a - DMatrix::identity(n, n) * (spectral_abscissa(&a) + 0.05);
        let b = randn(&mut rng, n, m);
        let c = randn(&mut rng, p, n);
        let d = if case % 3 == 0 {
            randn(&mut rng, p, m)
        } else {
            DMatrix::zeros(p, m)
        };
        let bt = DMatrix::from_fn(n, m, |i, j| b[(i, j)] / t[i]);
        let ct = DMatrix::from_fn(p, n, |i, j| c[(i, j)] * t[j]);
        let sys = StateSpace::new(similar(&a, &t), bt, ct, d, None).unwrap();
        let h = hinfnorm(&sys).unwrap();
        let sigma = |w: f64| {
            let g = if w.is_infinite() {
                sys.d.map(|v| Complex::new(v, 0.0))
            } else {
                sys.evalfr(Complex::new(0.0, w))
            };
            g.singular_values().max()
        };
        // Attained at the returned frequency.
        let at_peak = sigma(h.peak_rad_s);
        assert!(
            (at_peak - h.norm).abs() <= 1e-9 * h.norm,
            "case {case}: σ̄ at the peak {at_peak} vs {}",
            h.norm
        );
        // Dominates a dense grid over the spectrum's range.
        let mags: Vec<f64> = eigvals(&sys.a).iter().map(|l| l.norm()).collect();
        let lo = mags.iter().copied().fold(f64::INFINITY, f64::min) / 100.0;
        let hi = mags.iter().copied().fold(0.0, f64::max) * 100.0;
        let grid = (0..=2000)
            .map(|i| sigma(lo * (hi / lo).powf(i as f64 / 2000.0)))
            .fold(sigma(0.0), f64::max);
        assert!(
            h.norm >= grid * (1.0 - 1e-9),
            "case {case} (n = {n}): {} below the grid's {grid}",
            h.norm
        );
    }
}
