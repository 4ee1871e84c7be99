//! Issue 14: reproducers of the defects found by the independent cross-check of
//! `nanomotion_core::lti` (badly scaled Riccati problems, O(n³) Lyapunov,
//! H∞ synthesis limits, validation, delay-chain poles). Each test failed on the
//! code before the fix.

use nalgebra::DMatrix;
use nanomotion_core::lti::{C2dMethod, LtiError, StateSpace, c2d, care, dare};
use nanomotion_core::rng::Rng;
use std::f64::consts::PI;

/// ‖AᵀX + XA − (XB)R⁻¹(BᵀX) + Q‖_F relative to the sum of the terms' norms,
/// computed here from the data.
fn care_residual(
    a: &DMatrix<f64>,
    b: &DMatrix<f64>,
    q: &DMatrix<f64>,
    r: &DMatrix<f64>,
    x: &DMatrix<f64>,
) -> f64 {
    let xb = x * b;
    let quad = &xb * r.clone().try_inverse().unwrap() * xb.transpose();
    let res = a.transpose() * x + x * a - &quad + q;
    res.norm() / (2.0 * (a.transpose() * x).norm() + quad.norm() + q.norm())
}

fn dare_residual(
    a: &DMatrix<f64>,
    b: &DMatrix<f64>,
    q: &DMatrix<f64>,
    r: &DMatrix<f64>,
    x: &DMatrix<f64>,
) -> f64 {
    let axa = a.transpose() * x * a;
    let bxa = b.transpose() * x * a;
    let quad = bxa.transpose() * (r + b.transpose() * x * b).try_inverse().unwrap() * &bxa;
    let res = &axa - x - &quad + q;
    res.norm() / (axa.norm() + x.norm() + quad.norm() + q.norm())
}

/// Componentwise backward error of the CARE, computed here: maxᵢⱼ |Res|ᵢⱼ over
/// (|Aᵀ||X| + |X||A| + |X||B||R⁻¹||Bᵀ||X| + |Q|)ᵢⱼ.
fn care_backward(
    a: &DMatrix<f64>,
    b: &DMatrix<f64>,
    q: &DMatrix<f64>,
    r: &DMatrix<f64>,
    x: &DMatrix<f64>,
) -> f64 {
    let ri = r.clone().try_inverse().unwrap();
    let res = a.transpose() * x + x * a - x * b * &ri * b.transpose() * x + q;
    let (aa, xa, ba) = (a.abs(), x.abs(), b.abs());
    let floor =
        aa.transpose() * &xa + &xa * &aa + &xa * &ba * ri.abs() * ba.transpose() * &xa + q.abs();
    let fmax = floor.amax();
    res.iter()
        .zip(floor.iter())
        .map(|(r, f)| r.abs() / f.max(f64::EPSILON * fmax))
        .fold(0.0, f64::max)
}

/// The stage model: an integrator plus a 500 Hz mode with ζ = 0.01.
fn stage() -> (DMatrix<f64>, DMatrix<f64>) {
    let w = 2.0 * PI * 500.0;
    let z = 0.01;
    let a = DMatrix::from_row_slice(
        3,
        3,
        &[0.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, -w * w, -2.0 * z * w],
    );
    let b = DMatrix::from_row_slice(3, 1, &[1.0, 0.0, w * w]);
    (a, b)
}

#[test]
fn care_on_the_stage_model_with_cheap_control() {
    let (a, b) = stage();
    let q = DMatrix::identity(3, 3);
    let r = DMatrix::from_element(1, 1, 1e-6);
    let s = care(&a, &b, &q, &r, None).unwrap();
    // The terms of the equation cancel (B = [1, 0, ω²]ᵀ, R = 1e-6): the
    // normwise residual of even the exact X is ~1e-11; against the round-off
    // floor of evaluating the equation the residual is at machine precision.
    let res = care_residual(&a, &b, &q, &r, &s.x);
    assert!(res < 1e-10, "residual {res:e}");
    assert!(s.backward_error < 1e-15, "{:e}", s.backward_error);
    assert!(s.closed_loop_poles.iter().all(|p| p.re < 0.0));
    assert!(s.x.clone().cholesky().is_some(), "X ≻ 0");
}

#[test]
fn dare_on_the_zoh_stage_model_at_20_khz() {
    let (a, b) = stage();
    let sys = StateSpace::new(a, b, DMatrix::zeros(1, 3), DMatrix::zeros(1, 1), None).unwrap();
    let d = c2d(&sys, 1.0 / 20e3, C2dMethod::Zoh).unwrap();
    let q = DMatrix::identity(3, 3);
    let r = DMatrix::from_element(1, 1, 1e-6);
    let s = dare(&d.a, &d.b, &q, &r, None).unwrap();
    let res = dare_residual(&d.a, &d.b, &q, &r, &s.x);
    assert!(res < 1e-13, "residual {res:e}");
    assert!(s.closed_loop_poles.iter().all(|p| p.norm() < 1.0));
}

fn random_problem(rng: &mut Rng, n: usize, m: usize) -> [DMatrix<f64>; 3] {
    let a = DMatrix::from_fn(n, n, |_, _| rng.normal());
    let b = DMatrix::from_fn(n, m, |_, _| rng.normal());
    let c = DMatrix::from_fn(n, n, |_, _| rng.normal());
    let q = &c * c.transpose() / n as f64 + DMatrix::identity(n, n) * 1e-3;
    [a, b, q]
}

#[test]
fn random_n20_problems_with_r_1e_minus_8() {
    let mut rng = Rng::new(14);
    for case in 0..6 {
        let [a, b, q] = random_problem(&mut rng, 20, [2, 4, 20][case % 3]);
        let m = b.ncols();
        let r = DMatrix::identity(m, m) * 1e-8;
        let s = care(&a, &b, &q, &r, None).unwrap_or_else(|e| panic!("case {case}: care {e}"));
        assert!(
            s.backward_error < 1e-14,
            "case {case}: care backward error {:e}",
            s.backward_error
        );
        // Normwise the terms cancel to ~1e-6 (the equation's own round-off);
        // componentwise the residual is at machine precision.
        let be = care_backward(&a, &b, &q, &r, &s.x);
        assert!(be < 1e-13, "case {case}: care backward error {be:e}");
        assert!(s.closed_loop_poles.iter().all(|p| p.re < 0.0));
        // Discrete: the same data scaled to spectral radius 1.2.
        let rho = nanomotion_core::lti::linalg::eigvals(&a)
            .iter()
            .map(|p| p.norm())
            .fold(0.0, f64::max);
        let ad = &a * (1.2 / rho);
        let s = dare(&ad, &b, &q, &r, None).unwrap_or_else(|e| panic!("case {case}: dare {e}"));
        assert!(
            s.backward_error < 1e-14,
            "case {case}: dare backward error {:e}",
            s.backward_error
        );
        let res = dare_residual(&ad, &b, &q, &r, &s.x);
        assert!(res < 1e-8, "case {case}: dare residual {res:e}");
        assert!(s.closed_loop_poles.iter().all(|p| p.norm() < 1.0));
    }
}

#[test]
fn dare_n5_with_r_1e_minus_8_to_round_off() {
    let mut rng = Rng::new(5);
    for case in 0..10 {
        let [a, b, q] = random_problem(&mut rng, 5, 1 + case % 2);
        let m = b.ncols();
        let r = DMatrix::identity(m, m) * 1e-8;
        let s = dare(&a, &b, &q, &r, None).unwrap_or_else(|e| panic!("case {case}: {e}"));
        let res = dare_residual(&a, &b, &q, &r, &s.x);
        assert!(res < 1e-14, "case {case}: residual {res:e}");
    }
}

#[test]
fn riccati_errors_name_the_cause() {
    // Unstable mode that B cannot reach: not stabilisable.
    let a = DMatrix::from_row_slice(2, 2, &[1.0, 0.0, 0.0, -1.0]);
    let b = DMatrix::from_row_slice(2, 1, &[0.0, 1.0]);
    let q = DMatrix::identity(2, 2);
    let r = DMatrix::identity(1, 1);
    let e = care(&a, &b, &q, &r, None).unwrap_err();
    assert!(e.to_string().contains("not stabilisable"), "{e}");
    let ad = DMatrix::from_row_slice(2, 2, &[1.5, 0.0, 0.0, 0.5]);
    let e = dare(&ad, &b, &q, &r, None).unwrap_err();
    assert!(e.to_string().contains("not stabilisable"), "{e}");
    // A mode on the imaginary axis that Q does not see: not detectable, and the
    // Hamiltonian eigenvalue on the axis is reported with its distance.
    let a = DMatrix::from_row_slice(2, 2, &[0.0, 1.0, -1.0, 0.0]);
    let b = DMatrix::from_row_slice(2, 1, &[0.0, 1.0]);
    let e = care(&a, &b, &DMatrix::zeros(2, 2), &r, None).unwrap_err();
    let msg = e.to_string();
    assert!(msg.contains("not detectable"), "{msg}");
    assert!(
        msg.contains("imaginary axis") && msg.contains("distance"),
        "{msg}"
    );
    assert!(matches!(e, LtiError::Singular(_)));
}

/// A random Hurwitz matrix: shifted so that its rightmost eigenvalue is at −0.1.
fn hurwitz(rng: &mut Rng, n: usize) -> DMatrix<f64> {
    let a = DMatrix::from_fn(n, n, |_, _| rng.normal());
    let worst = nanomotion_core::lti::linalg::eigvals(&a)
        .iter()
        .map(|p| p.re)
        .fold(f64::NEG_INFINITY, f64::max);
    a - DMatrix::identity(n, n) * (worst + 0.1)
}

#[test]
fn lyapunov_is_cubic_and_care_is_refined_at_n40() {
    use nanomotion_core::lti::{dlyap, lyap};
    let mut rng = Rng::new(40);
    // n = 60 by the Kronecker form was a 3600 × 3600 LU (minutes, 100 MB).
    let n = 60;
    let a = hurwitz(&mut rng, n);
    let c = DMatrix::from_fn(n, n, |_, _| rng.normal());
    let q = &c * c.transpose();
    let t0 = std::time::Instant::now();
    let x = lyap(&a, &q).unwrap();
    let ad = &a
        * (0.9
            / nanomotion_core::lti::linalg::eigvals(&a)
                .iter()
                .map(|p| p.norm())
                .fold(0.0, f64::max));
    let xd = dlyap(&ad, &q).unwrap();
    let elapsed = t0.elapsed().as_secs_f64();
    assert!(elapsed < 2.0, "lyap + dlyap at n = 60 took {elapsed} s");
    let r = a.transpose() * &x + &x * &a + &q;
    assert!(
        r.norm() < 1e-11 * (2.0 * (&a * &x).norm() + q.norm()),
        "{:e}",
        r.norm()
    );
    let r = ad.transpose() * &xd * &ad - &xd + &q;
    assert!(
        r.norm() < 1e-11 * (2.0 * xd.norm() + q.norm()),
        "{:e}",
        r.norm()
    );
    // CARE at n = 40 is refined by Newton (it was not above n = 24).
    let b = DMatrix::from_fn(40, 3, |_, _| rng.normal());
    let a40 = DMatrix::from_fn(40, 40, |_, _| rng.normal());
    let q40 = DMatrix::identity(40, 40);
    let r3 = DMatrix::identity(3, 3);
    let s = care(&a40, &b, &q40, &r3, None).unwrap();
    assert!(s.relative_residual < 1e-9, "{:e}", s.relative_residual);
    assert!(s.backward_error < 1e-15, "{:e}", s.backward_error);
    assert!(care_backward(&a40, &b, &q40, &r3, &s.x) < 1e-13);
}

mod hinf_synthesis {
    use nalgebra::DMatrix;
    use nanomotion_core::lti::hinfsyn::{HinfSynOptions, augw, hinfsyn, lft};
    use nanomotion_core::lti::{C2dMethod, StateSpace, TransferFunction, c2d, hinfnorm};

    fn tf(num: &[f64], den: &[f64]) -> StateSpace {
        TransferFunction::new(num.to_vec(), den.to_vec(), None)
            .unwrap()
            .to_ss()
            .unwrap()
    }

    fn gain(k: f64) -> StateSpace {
        StateSpace::gain(DMatrix::from_element(1, 1, k), None)
    }

    /// The standard biproper sensitivity weight W_S = (s/M + ω)/(s + ωA):
    /// D₁₁ = 1/M ≠ 0.
    #[test]
    fn biproper_sensitivity_weight_d11_nonzero() {
        let g = tf(&[1.0], &[1.0, 0.4, 1.0]);
        let (m, w, aa) = (2.0, 0.5, 1e-3);
        let ws = tf(&[1.0 / m, w], &[1.0, w * aa]);
        let p = augw(&g, Some(&ws), Some(&gain(0.1)), None).unwrap();
        assert!(p.d[(0, 0)] != 0.0);
        let syn = hinfsyn(&p, 1, 1, &HinfSynOptions::default()).unwrap();
        // Independent check of the returned closed loop.
        let cl = lft(&p, &syn.controller, 1, 1).unwrap();
        assert!(cl.is_stable());
        let norm = hinfnorm(&cl).unwrap().norm;
        assert!(
            norm <= syn.gamma * (1.0 + 1e-6),
            "{norm} vs γ {}",
            syn.gamma
        );
        // ‖W_S S‖∞ ≥ |W_S(∞)| = 1/M since S(∞) = 1 (strictly proper G).
        assert!(syn.gamma >= 1.0 / m);
        // Better than a PI on the same weights, and the bracket is tight.
        let pi = lft(&p, &tf(&[0.3, 0.1], &[1.0, 0.0]), 1, 1).unwrap();
        assert!(norm < hinfnorm(&pi).unwrap().norm);
        assert!(syn.gamma - syn.gamma_infeasible <= 1e-4 * syn.gamma);
        // D₁₁ with γ below ‖D₁₁‖ is infeasible: the lower end never passes 1/M.
        assert!(syn.gamma_infeasible >= 1.0 / m * (1.0 - 1e-12));
    }

    fn coupled_plant() -> StateSpace {
        let a = DMatrix::from_row_slice(
            4,
            4,
            &[
                0.0, 1.0, 0.0, 0.0, -1.0, -0.1, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, -1.2, -0.1,
            ],
        );
        let b = DMatrix::from_row_slice(4, 2, &[0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0]);
        let c = DMatrix::from_row_slice(2, 4, &[1.0, 0.0, 0.05, 0.0, -0.03, 0.0, 1.0, 0.0]);
        let g = StateSpace::new(a, b, c, DMatrix::zeros(2, 2), None).unwrap();
        let w1 = StateSpace::new(
            DMatrix::identity(2, 2) * -0.001,
            DMatrix::identity(2, 2),
            DMatrix::identity(2, 2) * 0.5,
            DMatrix::zeros(2, 2),
            None,
        )
        .unwrap();
        let w2 = StateSpace::gain(DMatrix::identity(2, 2) * 0.3, None);
        augw(&g, Some(&w1), Some(&w2), None).unwrap()
    }

    #[test]
    fn mimo_biproper_weight_with_d11_nonzero() {
        // The coupled 2×2 plant with W1 = (s/2 + 0.5)/(s + 0.0005)·I.
        let p0 = coupled_plant();
        let g = StateSpace::new(
            p0.a.view((0, 0), (4, 4)).clone_owned(),
            p0.b.view((0, 2), (4, 2)).clone_owned(),
            -p0.c.view((4, 0), (2, 4)).clone_owned(),
            DMatrix::zeros(2, 2),
            None,
        )
        .unwrap();
        let w1 = StateSpace::new(
            DMatrix::identity(2, 2) * -0.0005,
            DMatrix::identity(2, 2),
            DMatrix::identity(2, 2) * (0.5 - 0.0005 * 0.5),
            DMatrix::identity(2, 2) * 0.5,
            None,
        )
        .unwrap();
        let w2 = StateSpace::gain(DMatrix::identity(2, 2) * 0.3, None);
        let p = augw(&g, Some(&w1), Some(&w2), None).unwrap();
        assert!(p.d[(0, 0)] == 0.5 && p.d[(1, 1)] == 0.5);
        let syn = hinfsyn(&p, 2, 2, &HinfSynOptions::default()).unwrap();
        let cl = lft(&p, &syn.controller, 2, 2).unwrap();
        let norm = hinfnorm(&cl).unwrap().norm;
        assert!(norm <= syn.gamma * (1.0 + 1e-6), "{norm} vs {}", syn.gamma);
        assert!(syn.gamma >= 0.5, "‖W1(∞)S(∞)‖ = 0.5 is a lower bound");
    }

    #[test]
    fn tight_tolerance_returns_the_best_verified_controller() {
        let p = coupled_plant();
        let opts = HinfSynOptions {
            gamma_rel_tol: 1e-8,
            ..Default::default()
        };
        let syn = hinfsyn(&p, 2, 2, &opts).unwrap();
        let norm = hinfnorm(&lft(&p, &syn.controller, 2, 2).unwrap())
            .unwrap()
            .norm;
        assert!(norm <= syn.gamma * (1.0 + 1e-6));
        let loose = hinfsyn(&p, 2, 2, &HinfSynOptions::default()).unwrap();
        assert!(syn.gamma <= loose.gamma * (1.0 + 1e-9));
    }

    #[test]
    fn discrete_plants_by_the_exact_bilinear_map() {
        let g = tf(&[1.0], &[1.0, 0.4, 1.0]);
        let w1 = tf(&[1.0], &[1.0, 0.001]);
        let pc = augw(&g, Some(&w1), Some(&gain(0.5)), None).unwrap();
        let dt = 0.05;
        let pd = c2d(&pc, dt, C2dMethod::TUSTIN).unwrap();
        let opts = HinfSynOptions {
            gamma_rel_tol: 1e-6,
            ..Default::default()
        };
        let sc = hinfsyn(&pc, 1, 1, &opts).unwrap();
        let sd = hinfsyn(&pd, 1, 1, &opts).unwrap();
        assert_eq!(sd.controller.dt, Some(dt));
        let cl = lft(&pd, &sd.controller, 1, 1).unwrap();
        assert!(cl.is_stable());
        let norm = hinfnorm(&cl).unwrap().norm;
        assert!(norm <= sd.gamma * (1.0 + 1e-6), "{norm} vs {}", sd.gamma);
        // Tustin is the bilinear map (with a frequency scaling), which
        // preserves the H∞ norm exactly: the same optimal γ.
        assert!(
            (sd.gamma - sc.gamma).abs() <= 2e-6 * sc.gamma,
            "{} vs {}",
            sd.gamma,
            sc.gamma
        );
    }

    #[test]
    fn gamma_bracket_does_not_depend_on_gamma_one() {
        let g = tf(&[1.0], &[1.0, 0.4, 1.0]);
        let w1 = tf(&[1.0], &[1.0, 0.001]);
        let base = hinfsyn(
            &augw(&g, Some(&w1), Some(&gain(0.5)), None).unwrap(),
            1,
            1,
            &HinfSynOptions::default(),
        )
        .unwrap();
        for k in [1e-10, 1e10] {
            // z scaled by k: γ scales by k.
            let p = augw(&g, Some(&w1.scaled(k)), Some(&gain(0.5 * k)), None).unwrap();
            let syn = hinfsyn(&p, 1, 1, &HinfSynOptions::default()).unwrap();
            assert!(
                (syn.gamma / k - base.gamma).abs() <= 2e-4 * base.gamma,
                "k = {k}: {} vs {}",
                syn.gamma / k,
                base.gamma
            );
        }
    }
}

#[test]
fn delay_chain_poles_are_exactly_zero() {
    use nanomotion_core::lti::{delay, series};
    for d in [1usize, 3, 8, 20] {
        let z = delay(d, 1e-3);
        let p = z.poles();
        assert_eq!(p.len(), d);
        assert!(p.iter().all(|l| l.norm() == 0.0), "d = {d}: {p:?}");
        // A plant behind the delay keeps its own poles; the delay's are exact.
        let g = StateSpace::new(
            DMatrix::from_row_slice(2, 2, &[0.5, 0.2, -0.3, 0.7]),
            DMatrix::from_row_slice(2, 1, &[1.0, 0.0]),
            DMatrix::from_row_slice(1, 2, &[1.0, 1.0]),
            DMatrix::zeros(1, 1),
            Some(1e-3),
        )
        .unwrap();
        let s = series(&z, &g).unwrap();
        let zeros = s.poles().iter().filter(|l| l.norm() == 0.0).count();
        assert_eq!(zeros, d, "d = {d}: {:?}", s.poles());
    }
}

mod validation {
    use nalgebra::DMatrix;
    use nanomotion_core::lti::{
        C2dMethod, Complex, LtiError, StateSpace, TransferFunction, c2d, zpk_checked,
    };

    #[test]
    fn state_space_rejects_non_finite_entries() {
        let ok = |v: f64| {
            StateSpace::new(
                DMatrix::from_element(1, 1, v),
                DMatrix::from_element(1, 1, 1.0),
                DMatrix::from_element(1, 1, 1.0),
                DMatrix::zeros(1, 1),
                None,
            )
        };
        assert!(ok(-1.0).is_ok());
        for bad in [f64::NAN, f64::INFINITY, f64::NEG_INFINITY] {
            let e = ok(bad).unwrap_err();
            assert!(matches!(e, LtiError::Parameter { name: "a", .. }), "{e}");
        }
        let e = StateSpace::new(
            DMatrix::zeros(2, 2),
            DMatrix::zeros(3, 1),
            DMatrix::zeros(1, 2),
            DMatrix::zeros(1, 1),
            None,
        )
        .unwrap_err();
        assert!(matches!(e, LtiError::Dimension(_)));
    }

    #[test]
    fn hand_built_inconsistent_models_are_typed_errors_not_panics() {
        use nanomotion_core::lti::{feedback, hinfnorm, series, ss2tf};
        let good = StateSpace::new(
            DMatrix::from_element(1, 1, -1.0),
            DMatrix::from_element(1, 1, 1.0),
            DMatrix::from_element(1, 1, 1.0),
            DMatrix::zeros(1, 1),
            None,
        )
        .unwrap();
        let mut bad = good.clone();
        bad.b = DMatrix::zeros(3, 1); // 3 rows for 1 state
        assert!(matches!(bad.validate(), Err(LtiError::Dimension(_))));
        assert!(matches!(hinfnorm(&bad), Err(LtiError::Dimension(_))));
        assert!(matches!(
            c2d(&bad, 0.1, C2dMethod::Zoh),
            Err(LtiError::Dimension(_))
        ));
        assert!(matches!(series(&good, &bad), Err(LtiError::Dimension(_))));
        assert!(matches!(
            feedback(&bad, &good, -1.0),
            Err(LtiError::Dimension(_))
        ));
        assert!(matches!(ss2tf(&bad), Err(LtiError::Dimension(_))));
        let mut nan = good.clone();
        nan.a[(0, 0)] = f64::NAN;
        assert!(matches!(
            hinfnorm(&nan),
            Err(LtiError::Parameter { name: "a", .. })
        ));
        assert!(c2d(&nan, 0.1, C2dMethod::Zoh).is_err());
    }

    #[test]
    fn zpk_checked_refuses_an_unpaired_complex_root() {
        let z = [Complex::new(-1.0, 2.0)];
        let e = zpk_checked(&[], &z, 1.0, None).unwrap_err();
        assert!(e.to_string().contains("conjugate"), "{e}");
        let pair = [Complex::new(-1.0, 2.0), Complex::new(-1.0, -2.0)];
        let tf = zpk_checked(&[Complex::new(-3.0, 0.0)], &pair, 2.0, None).unwrap();
        assert_eq!(tf.num, vec![2.0, 6.0]);
        assert!((tf.den[1] - 2.0).abs() < 1e-15 && (tf.den[2] - 5.0).abs() < 1e-15);
    }

    #[test]
    fn zoh_overflow_is_an_error_not_inf() {
        let sys = StateSpace::new(
            DMatrix::from_element(1, 1, 1e4),
            DMatrix::from_element(1, 1, 1.0),
            DMatrix::from_element(1, 1, 1.0),
            DMatrix::zeros(1, 1),
            None,
        )
        .unwrap();
        let e = c2d(&sys, 1.0, C2dMethod::Zoh).unwrap_err();
        assert!(e.to_string().contains("overflows"), "{e}");
        assert!(c2d(&sys, 1e-5, C2dMethod::Zoh).is_ok());
    }

    #[test]
    fn poles_with_a_tiny_leading_coefficient_are_not_nan() {
        // ε s² + 3 s + 2: roots ≈ −2/3 and −3/ε.
        let eps = 1e-300;
        let tf = TransferFunction::new(vec![1.0], vec![eps, 3.0, 2.0], None).unwrap();
        let p = tf.poles();
        assert!(p.iter().all(|z| !z.re.is_nan() && !z.im.is_nan()), "{p:?}");
        assert!(p.iter().any(|z| (z.re + 2.0 / 3.0).abs() < 1e-12), "{p:?}");
    }

    #[test]
    fn siso_helpers_on_mimo_are_errors() {
        let sys = StateSpace::gain(DMatrix::identity(2, 2), None);
        assert!(matches!(
            sys.try_freqresp_siso(&[1.0]),
            Err(LtiError::Dimension(_))
        ));
        assert!(sys.try_bode(&[1.0]).is_err());
        let siso = StateSpace::gain(DMatrix::from_element(1, 1, 2.0), None);
        assert_eq!(
            siso.try_freqresp_siso(&[1.0]).unwrap()[0],
            Complex::new(2.0, 0.0)
        );
    }
}
