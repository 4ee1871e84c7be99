//! The LMI solver (`nanomotion_core::lti::lmi`) against independent computations:
//!
//! - discrete Lyapunov LMIs on seeded random matrices with spectral radius just
//!   below and just above 1, against the closed-form solution of the Lyapunov
//!   equation (Kronecker linear solve) and the eigenvalues;
//! - common / switching-dependent Lyapunov functions of matrix pairs whose answer
//!   is known: a nilpotent pair with JSR = a, a triangular pair, and the pair of
//!   Ahmadi, Jungers, Parrilo & Roozbehani (SIAM J. Control Optim. 2014) that is
//!   stable under arbitrary switching without a common quadratic Lyapunov
//!   function (the non-existence proved by a verified dual certificate);
//! - every certificate re-checked by eigenvalues built here from the data;
//! - proptest: a "feasible" answer always satisfies every LMI; bad input gives
//!   typed errors, never a panic.

use nalgebra::DMatrix;
use nanomotion_core::lti::linalg::eigvals;
use nanomotion_core::lti::lmi::{
    LmiConstraint, LmiError, LmiOptions, LmiProblem, LmiSolution, LmiStatus,
};
use nanomotion_core::rng::Rng;
use proptest::prelude::*;

fn rho(a: &DMatrix<f64>) -> f64 {
    eigvals(a).iter().map(|z| z.norm()).fold(0.0, f64::max)
}

fn min_eig(m: &DMatrix<f64>) -> f64 {
    let s = (m + m.transpose()) * 0.5;
    s.symmetric_eigenvalues()
        .iter()
        .copied()
        .fold(f64::INFINITY, f64::min)
}

fn random_matrix(rng: &mut Rng, n: usize) -> DMatrix<f64> {
    DMatrix::from_fn(n, n, |_, _| rng.normal())
}

/// Closed form: P with P − AᵀPA = Q, from (I − Aᵀ⊗Aᵀ) vec P = vec Q.
fn dlyap(a: &DMatrix<f64>, q: &DMatrix<f64>) -> DMatrix<f64> {
    let n = a.nrows();
    let at = a.transpose();
    let k = at.kronecker(&at);
    let m = DMatrix::<f64>::identity(n * n, n * n) - k;
    let rhs = nalgebra::DVector::from_column_slice(q.as_slice());
    let v = m
        .lu()
        .solve(&rhs)
        .expect("no eigenvalue pair with λ_i λ_j = 1");
    let p = DMatrix::from_column_slice(n, n, v.as_slice());
    (&p + p.transpose()) * 0.5
}

/// find P: P ≻ 0, P − AᵢᵀPAᵢ ≻ 0 for every Aᵢ (common quadratic Lyapunov function).
fn cqlf_problem(mats: &[DMatrix<f64>]) -> LmiProblem {
    let n = mats[0].nrows();
    let mut lmi = LmiProblem::new();
    let p = lmi.variable("P", n).unwrap();
    let mut c = LmiConstraint::new("P ≻ 0", n);
    c.var(p, 1.0).unwrap();
    lmi.add(c).unwrap();
    for (i, a) in mats.iter().enumerate() {
        let mut c = LmiConstraint::new(format!("P − A{i}ᵀPA{i} ≻ 0"), n);
        c.var(p, 1.0).unwrap().congruence(p, a, -1.0).unwrap();
        lmi.add(c).unwrap();
    }
    lmi
}

/// Switching-dependent Lyapunov function V = ξᵀP_{σ}ξ (the form of the thesis's
/// (5.16)): P_i ≻ 0, P_i − AᵢᵀP_jAᵢ ≻ 0 for all i, j; `block` uses the 2×2-block
/// form [P_i, AᵢᵀP_j; P_jAᵢ, P_j] ≻ 0 instead of the Schur complement.
fn pdlf_problem(mats: &[DMatrix<f64>], block: bool) -> LmiProblem {
    let n = mats[0].nrows();
    let mut lmi = LmiProblem::new();
    let ps: Vec<_> = (0..mats.len())
        .map(|i| lmi.variable(format!("P{i}"), n).unwrap())
        .collect();
    let e1 = DMatrix::<f64>::identity(n, n).resize_horizontally(2 * n, 0.0);
    let mut e2 = DMatrix::<f64>::zeros(n, 2 * n);
    e2.view_mut((0, n), (n, n)).fill_with_identity();
    for &p in &ps {
        let mut c = LmiConstraint::new("P ≻ 0", n);
        c.var(p, 1.0).unwrap();
        lmi.add(c).unwrap();
    }
    for (i, a) in mats.iter().enumerate() {
        for &pj in &ps {
            if block {
                let mut c = LmiConstraint::new("block", 2 * n);
                c.congruence(ps[i], &e1, 1.0)
                    .unwrap()
                    .congruence(pj, &e2, 1.0)
                    .unwrap()
                    .sym_product(pj, &e2, &(a * &e1), 1.0)
                    .unwrap();
                lmi.add(c).unwrap();
            } else {
                let mut c = LmiConstraint::new("dec", n);
                c.var(ps[i], 1.0).unwrap().congruence(pj, a, -1.0).unwrap();
                lmi.add(c).unwrap();
            }
        }
    }
    lmi
}

/// Independent check of a CQLF certificate.
fn check_cqlf(mats: &[DMatrix<f64>], p: &DMatrix<f64>) -> f64 {
    let mut m = min_eig(p);
    for a in mats {
        m = m.min(min_eig(&(p - a.transpose() * p * a)));
    }
    m
}

/// Independent check of a switching-dependent certificate.
fn check_pdlf(mats: &[DMatrix<f64>], ps: &[DMatrix<f64>]) -> f64 {
    let mut m = f64::INFINITY;
    for (i, a) in mats.iter().enumerate() {
        m = m.min(min_eig(&ps[i]));
        for pj in ps {
            m = m.min(min_eig(&(&ps[i] - a.transpose() * pj * a)));
        }
    }
    m
}

fn solve(lmi: &LmiProblem) -> LmiSolution {
    lmi.solve(&LmiOptions::default()).unwrap()
}

#[test]
fn lyapunov_lmi_matches_spectral_radius_and_closed_form() {
    let mut rng = Rng::new(0x5EED_0001);
    let mut steps = Vec::new();
    for case in 0..20 {
        let n = 2 + case % 5;
        let b = random_matrix(&mut rng, n);
        for target in [0.98, 0.995, 1.005, 1.02] {
            let a = &b * (target / rho(&b));
            let r = rho(&a);
            let stable = r < 1.0;
            // Closed form with Q = I: positive definite ⇔ ρ < 1 (Lyapunov).
            let p_cf = dlyap(&a, &DMatrix::identity(n, n));
            assert_eq!(min_eig(&p_cf) > 0.0, stable, "closed form, ρ = {r}");
            let lmi = cqlf_problem(std::slice::from_ref(&a));
            let sol = solve(&lmi);
            steps.push(sol.newton_steps);
            if stable {
                assert_eq!(sol.status, LmiStatus::Feasible, "n = {n}, ρ = {r}: {sol:?}");
                let p = &sol.variables[0];
                let m = check_cqlf(std::slice::from_ref(&a), p);
                assert!(m > 0.0, "certificate fails: {m}");
                assert!(
                    (m - sol.margin).abs() <= 1e-9 * p.norm(),
                    "{m} vs {}",
                    sol.margin
                );
                // Any certificate is the Lyapunov solution for its own Q: the
                // closed form with Q = P − AᵀPA reproduces P.
                let q = p - a.transpose() * p * &a;
                let back = dlyap(&a, &q);
                assert!(
                    (&back - p).norm() <= 1e-7 * p.norm() * (1.0 / (1.0 - r)),
                    "P vs closed form: {}",
                    (&back - p).norm()
                );
            } else {
                assert_eq!(
                    sol.status,
                    LmiStatus::InfeasibleWithinTolerance,
                    "n = {n}, ρ = {r}: {sol:?}"
                );
                assert!(sol.t_upper < 1e-8, "{sol:?}");
                assert!(
                    sol.margin <= 0.0
                        || check_cqlf(std::slice::from_ref(&a), &sol.variables[0]) <= 0.0
                );
            }
        }
    }
    let max = steps.iter().max().unwrap();
    assert!(*max < 200, "Newton steps {steps:?}");
}

#[test]
fn nilpotent_pair_has_a_cqlf_iff_a_below_one() {
    // A1 = [0 a; 0 0], A2 = A1ᵀ: each nilpotent, A1A2 = diag(a², 0), so the JSR is
    // ≥ a; ‖Aᵢ‖₂ = a gives ≤ a. For a < 1, P = I works; for a > 1 the switched
    // system is unstable, so no Lyapunov function of any kind exists.
    for (a, feasible) in [(0.95, true), (0.999, true), (1.001, false), (1.05, false)] {
        let a1 = DMatrix::from_row_slice(2, 2, &[0.0, a, 0.0, 0.0]);
        let mats = [a1.clone(), a1.transpose()];
        assert!((rho(&(&mats[0] * &mats[1])).sqrt() - a).abs() < 1e-12);
        for lmi in [cqlf_problem(&mats), pdlf_problem(&mats, false)] {
            let sol = solve(&lmi);
            if feasible {
                assert_eq!(sol.status, LmiStatus::Feasible, "a = {a}");
                assert!(
                    lmi.min_eigenvalues(&sol.variables)
                        .unwrap()
                        .iter()
                        .all(|&e| e > 0.0)
                );
            } else {
                assert_eq!(sol.status, LmiStatus::InfeasibleWithinTolerance, "a = {a}");
            }
        }
    }
}

#[test]
fn triangular_pair_has_a_cqlf() {
    // Simultaneously upper-triangular Schur matrices always share a quadratic
    // Lyapunov function (P = diag(1, δ⁻²)-type scaling makes the off-diagonal
    // entries small), even with large off-diagonal terms.
    let a1 = DMatrix::from_row_slice(3, 3, &[0.9, 5.0, -2.0, 0.0, 0.8, 4.0, 0.0, 0.0, -0.7]);
    let a2 = DMatrix::from_row_slice(3, 3, &[-0.95, -3.0, 1.0, 0.0, 0.6, -6.0, 0.0, 0.0, 0.9]);
    let mats = [a1, a2];
    let sol = solve(&cqlf_problem(&mats));
    assert_eq!(sol.status, LmiStatus::Feasible, "{sol:?}");
    assert!(check_cqlf(&mats, &sol.variables[0]) > 0.0);
    // Raising one diagonal entry above 1 makes A1 itself unstable.
    let mut bad = mats.clone();
    bad[0][(2, 2)] = -1.01;
    let sol = solve(&cqlf_problem(&bad));
    assert_eq!(sol.status, LmiStatus::InfeasibleWithinTolerance);
}

#[test]
fn switching_stable_pair_without_common_quadratic_lyapunov_function() {
    // Ahmadi, Jungers, Parrilo & Roozbehani (2014): A1 = [−1 −1; −4 0],
    // A2 = [3 3; −2 1], JSR ≈ 3.917. Scaled by 1/3.95 the JSR is < 1 (proved
    // below by a switching-dependent Lyapunov function, the form of (5.16)), but
    // no common quadratic Lyapunov function exists (proved by a dual certificate).
    let a1 = DMatrix::from_row_slice(2, 2, &[-1.0, -1.0, -4.0, 0.0]);
    let a2 = DMatrix::from_row_slice(2, 2, &[3.0, 3.0, -2.0, 1.0]);
    // Lower bound on the JSR from all products up to length 10.
    let mut lb: f64 = 0.0;
    for k in 1..=10usize {
        for code in 0..(1u32 << k) {
            let mut p = DMatrix::<f64>::identity(2, 2);
            for b in 0..k {
                p = if (code >> b) & 1 == 1 {
                    &a1 * &p
                } else {
                    &a2 * &p
                };
            }
            lb = lb.max(rho(&p).powf(1.0 / k as f64));
        }
    }
    assert!(lb > 3.917 && lb < 3.95, "JSR lower bound {lb}");
    let r = 3.95;
    let mats = [&a1 / r, &a2 / r];
    // Switching-dependent Lyapunov function, Schur-complement and block forms.
    for block in [false, true] {
        let sol = solve(&pdlf_problem(&mats, block));
        assert_eq!(sol.status, LmiStatus::Feasible, "block {block}: {sol:?}");
        assert!(check_pdlf(&mats, &sol.variables) > 0.0);
    }
    // No CQLF: the solver says so...
    let sol = solve(&cqlf_problem(&mats));
    assert_eq!(sol.status, LmiStatus::InfeasibleWithinTolerance, "{sol:?}");
    // ...and a dual certificate proves it: Z1, Z2 ≻ 0 with
    // Σ (AᵢZᵢAᵢᵀ − Zᵢ) ≻ 0. If P were a CQLF, 0 < tr(P Σ(AᵢZᵢAᵢᵀ − Zᵢ)) =
    // Σ tr((AᵢᵀPAᵢ − P)Zᵢ) < 0.
    let mut dual = LmiProblem::new();
    let z: Vec<_> = (0..2)
        .map(|i| dual.variable(format!("Z{i}"), 2).unwrap())
        .collect();
    let mut sum = LmiConstraint::new("Σ AZAᵀ − Z", 2);
    for i in 0..2 {
        let mut c = LmiConstraint::new("Z ≻ 0", 2);
        c.var(z[i], 1.0).unwrap();
        dual.add(c).unwrap();
        sum.congruence(z[i], &mats[i].transpose(), 1.0)
            .unwrap()
            .var(z[i], -1.0)
            .unwrap();
    }
    dual.add(sum).unwrap();
    let d = solve(&dual);
    assert_eq!(d.status, LmiStatus::Feasible, "{d:?}");
    let zs = &d.variables;
    let mut s = DMatrix::<f64>::zeros(2, 2);
    for i in 0..2 {
        assert!(min_eig(&zs[i]) > 0.0);
        s += &mats[i] * &zs[i] * mats[i].transpose() - &zs[i];
    }
    assert!(min_eig(&s) > 0.0);
    // Scaled by 1/4.05 a CQLF exists (the ellipsoidal bound lies in (3.95, 4.05)).
    let mats = [&a1 / 4.05, &a2 / 4.05];
    let sol = solve(&cqlf_problem(&mats));
    assert_eq!(sol.status, LmiStatus::Feasible);
    assert!(check_cqlf(&mats, &sol.variables[0]) > 0.0);
}

#[test]
fn optimising_the_margin_gives_a_better_certificate() {
    let a = DMatrix::from_row_slice(2, 2, &[0.5, 1.0, -0.3, 0.7]);
    let lmi = cqlf_problem(std::slice::from_ref(&a));
    let first = solve(&lmi);
    let best = lmi
        .solve(&LmiOptions {
            stop_at_first_feasible: false,
            ..Default::default()
        })
        .unwrap();
    assert_eq!(best.status, LmiStatus::Feasible);
    assert!(
        best.margin >= first.margin,
        "{} < {}",
        best.margin,
        first.margin
    );
    assert!(best.t_upper - best.t <= 1e-3 * best.t + 1e-9);
    assert!(check_cqlf(std::slice::from_ref(&a), &best.variables[0]) > 0.0);
}

#[test]
fn inhomogeneous_problems_can_be_proved_infeasible() {
    // x ≻ 0 and 1 − x ≻ 0 (1×1): feasible; x − 2 ≻ 0 and 1 − x ≻ 0: infeasible
    // for every x (t* = −1/2 on the unnormalised problem).
    let mut lmi = LmiProblem::new();
    let x = lmi.variable("x", 1).unwrap();
    let mut c1 = LmiConstraint::new("x − 2", 1);
    c1.var(x, 1.0).unwrap().identity(-2.0).unwrap();
    let mut c2 = LmiConstraint::new("1 − x", 1);
    c2.var(x, -1.0).unwrap().identity(1.0).unwrap();
    lmi.add(c1).unwrap();
    lmi.add(c2).unwrap();
    let opts = LmiOptions {
        bound: 10.0,
        ..Default::default()
    };
    let sol = lmi.solve(&opts).unwrap();
    assert_eq!(sol.status, LmiStatus::Infeasible, "{sol:?}");
    assert!(sol.t_upper < 0.0);
    // x ∈ (0.5, 0.75) with a constant matrix block: diag(x − 0.5, 0.75 − x) ≻ 0.
    let mut lmi = LmiProblem::new();
    let x = lmi.variable("x", 1).unwrap();
    let mut c = LmiConstraint::new("box", 2);
    let sel1 = DMatrix::from_row_slice(1, 2, &[1.0, 0.0]);
    let sel2 = DMatrix::from_row_slice(1, 2, &[0.0, 1.0]);
    c.congruence(x, &sel1, 1.0)
        .unwrap()
        .congruence(x, &sel2, -1.0)
        .unwrap()
        .constant(&DMatrix::from_row_slice(2, 2, &[-0.5, 0.0, 0.0, 0.75]))
        .unwrap();
    lmi.add(c).unwrap();
    let sol = lmi.solve(&opts).unwrap();
    assert_eq!(sol.status, LmiStatus::Feasible);
    let v = sol.variables[0][(0, 0)];
    assert!(v > 0.5 && v < 0.75, "{v}");
}

#[test]
fn bad_input_gives_typed_errors() {
    let mut lmi = LmiProblem::new();
    assert!(matches!(lmi.variable("empty", 0), Err(LmiError::Empty(_))));
    let p = lmi.variable("P", 2).unwrap();
    let mut c = LmiConstraint::new("c", 2);
    assert!(matches!(c.var(p, f64::NAN), Err(LmiError::NonFinite(_))));
    let mut bad = DMatrix::<f64>::identity(2, 2);
    bad[(0, 1)] = f64::INFINITY;
    assert!(matches!(
        c.congruence(p, &bad, 1.0),
        Err(LmiError::NonFinite(_))
    ));
    assert!(matches!(
        c.congruence(p, &DMatrix::identity(2, 3), 1.0),
        Err(LmiError::Dimension { .. })
    ));
    assert!(matches!(
        c.constant(&DMatrix::from_row_slice(2, 2, &[1.0, 2.0, 0.0, 1.0])),
        Err(LmiError::NotSymmetric(_))
    ));
    assert!(matches!(
        c.sym_product(p, &DMatrix::identity(2, 2), &DMatrix::identity(3, 2), 1.0),
        Err(LmiError::Dimension { .. })
    ));
    // Term matrix with 3 rows for a 2×2 variable: caught when added.
    let mut c3 = LmiConstraint::new("rows", 2);
    c3.congruence(p, &DMatrix::identity(3, 2), 1.0).unwrap();
    assert!(matches!(lmi.add(c3), Err(LmiError::Dimension { .. })));
    // A variable of another problem.
    let mut other = LmiProblem::new();
    let _ = other.variable("a", 1).unwrap();
    let q = other.variable("b", 1).unwrap();
    let mut c4 = LmiConstraint::new("foreign", 1);
    c4.var(q, 1.0).unwrap();
    assert!(matches!(lmi.add(c4), Err(LmiError::UnknownVariable(1))));
    assert!(matches!(
        lmi.add(LmiConstraint::new("zero", 0)),
        Err(LmiError::Empty(_))
    ));
    assert!(matches!(
        lmi.solve(&LmiOptions::default()),
        Err(LmiError::Empty(_))
    ));
    let mut ok = LmiConstraint::new("P", 2);
    ok.var(p, 1.0).unwrap();
    lmi.add(ok).unwrap();
    for opts in [
        LmiOptions {
            bound: f64::NAN,
            ..Default::default()
        },
        LmiOptions {
            gap_tol: -1.0,
            ..Default::default()
        },
    ] {
        assert!(matches!(lmi.solve(&opts), Err(LmiError::Option { .. })));
    }
    assert!(matches!(
        lmi.solve(&LmiOptions {
            max_unknowns: 2,
            ..Default::default()
        }),
        Err(LmiError::TooLarge {
            unknowns: 3,
            limit: 2
        })
    ));
    assert!(matches!(
        lmi.min_eigenvalues(&[DMatrix::identity(3, 3)]),
        Err(LmiError::Dimension { .. })
    ));
    assert!(matches!(
        lmi.min_eigenvalues(&[]),
        Err(LmiError::Dimension { .. })
    ));
    let sol = lmi.solve(&LmiOptions::default()).unwrap();
    assert_eq!(sol.status, LmiStatus::Feasible);
    // Absurd sizes: errors, no allocation, no overflow.
    let mut huge = LmiConstraint::new("huge", 1 << 40);
    assert!(matches!(
        huge.identity(1.0),
        Err(LmiError::Dimension { .. })
    ));
    assert!(matches!(lmi.add(huge), Err(LmiError::Dimension { .. })));
    let _ = lmi.variable("H", usize::MAX / 2).unwrap();
    assert!(lmi.unknowns() >= usize::MAX / 2);
    assert!(matches!(
        lmi.solve(&LmiOptions::default()),
        Err(LmiError::TooLarge { .. })
    ));
}

/// One random term: (variable, kind, matrices, coefficient).
#[derive(Debug, Clone)]
enum TermSpec {
    Cong(usize, DMatrix<f64>, f64),
    Sym(usize, DMatrix<f64>, DMatrix<f64>, f64),
}

fn mat(n: usize, m: usize, v: &[f64]) -> DMatrix<f64> {
    DMatrix::from_fn(n, m, |i, j| v[(i * m + j) % v.len()])
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 64, ..ProptestConfig::default() })]

    /// Whatever the solver calls feasible really satisfies every LMI, checked by
    /// building F_k(X) here from the same data.
    #[test]
    fn feasible_answers_satisfy_every_lmi(
        sizes in proptest::collection::vec(1usize..=3, 1..=2),
        ncons in 1usize..=3,
        dims in proptest::collection::vec(1usize..=4, 3),
        vals in proptest::collection::vec(-2.0f64..2.0, 48),
        shifts in proptest::collection::vec(-1.0f64..2.0, 3),
        kinds in proptest::collection::vec(0usize..4, 9),
        bound in prop_oneof![Just(1.0), Just(10.0)],
    ) {
        let mut lmi = LmiProblem::new();
        let vars: Vec<_> = sizes.iter().enumerate().map(|(i, &n)| lmi.variable(format!("X{i}"), n).unwrap()).collect();
        let mut specs: Vec<(usize, f64, Vec<TermSpec>)> = Vec::new();
        let mut off = 0usize;
        let mut next = |n: usize, m: usize| { let v = vals[off % 48..].iter().chain(vals.iter()).copied().take(n * m).collect::<Vec<_>>(); off += 7; mat(n, m, &v) };
        for k in 0..ncons {
            let d = dims[k];
            let mut c = LmiConstraint::new(format!("F{k}"), d);
            c.identity(shifts[k]).unwrap();
            let mut terms = Vec::new();
            for t in 0..3 {
                let kind = kinds[3 * k + t];
                let v = (k + t) % vars.len();
                let n = sizes[v];
                let coef = if kind % 2 == 0 { 1.0 } else { -0.5 };
                if kind < 3 {
                    let a = next(n, d);
                    c.congruence(vars[v], &a, coef).unwrap();
                    terms.push(TermSpec::Cong(v, a, coef));
                } else {
                    let l = next(n, d);
                    let r = next(n, d);
                    c.sym_product(vars[v], &l, &r, coef).unwrap();
                    terms.push(TermSpec::Sym(v, l, r, coef));
                }
            }
            lmi.add(c).unwrap();
            specs.push((d, shifts[k], terms));
        }
        let sol = lmi.solve(&LmiOptions { bound, ..Default::default() }).unwrap();
        prop_assert!(sol.t.is_finite() && !sol.margin.is_nan());
        prop_assert!(sol.min_eigs.iter().all(|e| !e.is_nan()));
        if sol.status == LmiStatus::Feasible {
            let xs = &sol.variables;
            for x in xs {
                prop_assert!((x - x.transpose()).amax() == 0.0);
                prop_assert!(min_eig(&(DMatrix::identity(x.nrows(), x.nrows()) * bound - x)) > -1e-12);
            }
            for (d, shift, terms) in &specs {
                let mut f = DMatrix::<f64>::identity(*d, *d) * *shift;
                for t in terms {
                    match t {
                        TermSpec::Cong(v, a, c) => f += a.transpose() * &xs[*v] * a * *c,
                        TermSpec::Sym(v, l, r, c) => {
                            let m = l.transpose() * &xs[*v] * r;
                            f += (&m + m.transpose()) * *c;
                        }
                    }
                }
                prop_assert!(min_eig(&f) > 0.0, "λ_min = {}", min_eig(&f));
            }
            prop_assert!(sol.margin > 0.0);
        } else {
            // Not feasible: the constant-only point X = 0 is not better than the
            // reported upper bound (a consistency check of the bound).
            let zero: Vec<_> = sizes.iter().map(|&n| DMatrix::<f64>::zeros(n, n)).collect();
            let e0 = lmi.min_eigenvalues(&zero).unwrap();
            prop_assert!(e0.iter().any(|&e| e <= 1e-9), "X = 0 is feasible: {e0:?}, {sol:?}");
        }
    }

    /// Random (possibly inconsistent) sizes and values never panic.
    #[test]
    fn arbitrary_input_never_panics(
        nvar in 0usize..3,
        dim in 0usize..4,
        rows in 0usize..4,
        cols in 0usize..4,
        v in prop_oneof![Just(f64::NAN), Just(f64::INFINITY), -1e3f64..1e3],
    ) {
        let mut lmi = LmiProblem::new();
        let vars: Vec<_> = (0..nvar).filter_map(|i| lmi.variable(format!("X{i}"), i + 1).ok()).collect();
        let mut c = LmiConstraint::new("c", dim);
        let a = DMatrix::from_element(rows, cols, v);
        for x in &vars {
            let _ = c.congruence(*x, &a, 1.0);
            let _ = c.sym_product(*x, &a, &a, v);
            let _ = c.var(*x, 1.0);
        }
        let _ = c.constant(&DMatrix::from_element(dim, dim, v));
        let _ = lmi.add(c);
        if let Ok(sol) = lmi.solve(&LmiOptions::default()) {
            prop_assert!(!sol.t.is_nan() && !sol.margin.is_nan());
        }
    }
}
