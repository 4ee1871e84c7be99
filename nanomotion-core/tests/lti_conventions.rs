//! Issue 14, items 4 (remainder) and 5: one convention across the LTI toolkit.
//!
//! - every public function taking a `StateSpace` gives a typed error (fallible
//!   ones) or a NaN / "not stable" answer (infallible ones) on a hand-built
//!   model with inconsistent sizes, non-finite entries or a bad `dt`, never a
//!   panic inside nalgebra; deserialisation refuses such models;
//! - frequencies: the Tustin pre-warp can be given in rad/s like every
//!   frequency grid;
//! - solution structs with residual, backward error and iterations for
//!   `care_general`, `lyap` and `dlyap`;
//! - models built without a nalgebra dependency: the re-export and the
//!   slice/row constructors with typed errors for ragged rows.

use nanomotion_core::lti::hinfsyn::{HinfSynOptions, augw, hinfsyn, lft};
use nanomotion_core::lti::{
    C2dMethod, Complex, LtiError, SsStepper, StateSpace, TransferFunction, append, c2d,
    care_general, care_general_solution, dlyap, dlyap_solution, feedback, hinfnorm, impulse, lsim,
    lsim_siso, lyap, lyap_solution, parallel, series, ss2sos, ss2tf, stability_margins,
    step_response, zpetc_ss,
};
// No `use nalgebra`: the matrices come through the core's re-export.
use nanomotion_core::nalgebra::DMatrix;
use nanomotion_core::rng::Rng;
use std::f64::consts::PI;

fn good(dt: Option<f64>) -> StateSpace {
    let a = match dt {
        None => vec![vec![-1.0, 0.5], vec![0.0, -2.0]],
        Some(_) => vec![vec![0.5, 0.1], vec![0.0, 0.3]],
    };
    StateSpace::from_rows(&a, &[[1.0], [1.0]], &[[1.0, 0.0]], &[[0.0]], dt).unwrap()
}

/// Each way of breaking a model by setting its public fields, continuous and
/// discrete: (description, model).
fn inconsistent_models() -> Vec<(String, StateSpace)> {
    let mut out = Vec::new();
    for dt in [None, Some(1e-3)] {
        let g = good(dt);
        let mut cases: Vec<(&str, StateSpace)> = Vec::new();
        let mut m = g.clone();
        m.a = DMatrix::zeros(2, 3);
        cases.push(("A not square", m));
        let mut m = g.clone();
        m.a = DMatrix::from_element(3, 3, -0.1);
        cases.push(("A larger than B and C", m));
        let mut m = g.clone();
        m.b = DMatrix::zeros(3, 1);
        cases.push(("B rows ≠ n", m));
        let mut m = g.clone();
        m.b = DMatrix::zeros(0, 1);
        cases.push(("B without rows", m));
        let mut m = g.clone();
        m.c = DMatrix::zeros(1, 5);
        cases.push(("C columns ≠ n", m));
        let mut m = g.clone();
        m.d = DMatrix::zeros(2, 1);
        cases.push(("D rows ≠ p", m));
        let mut m = g.clone();
        m.d = DMatrix::zeros(1, 3);
        cases.push(("D columns ≠ m", m));
        let mut m = g.clone();
        m.c = DMatrix::zeros(0, 2);
        cases.push(("C without rows, D 1×1", m));
        let mut m = g.clone();
        m.a[(0, 1)] = f64::NAN;
        cases.push(("NaN in A", m));
        let mut m = g.clone();
        m.b[(1, 0)] = f64::INFINITY;
        cases.push(("inf in B", m));
        let mut m = g.clone();
        m.d[(0, 0)] = f64::NEG_INFINITY;
        cases.push(("-inf in D", m));
        if dt.is_some() {
            for bad in [0.0, -1e-3, f64::NAN, f64::INFINITY] {
                let mut m = g.clone();
                m.dt = Some(bad);
                out.push((format!("dt = {bad}"), m));
            }
        }
        for (what, m) in cases {
            out.push((
                format!(
                    "{what} ({})",
                    if dt.is_some() {
                        "discrete"
                    } else {
                        "continuous"
                    }
                ),
                m,
            ));
        }
    }
    out
}

fn all_nan(m: &DMatrix<Complex<f64>>) -> bool {
    m.iter().all(|z| z.re.is_nan() && z.im.is_nan())
}

/// Every public LTI function that takes a `StateSpace`, on every inconsistent
/// shape: the fallible ones return `Err`, the infallible ones return NaN (or
/// "not stable", or the model unchanged), and nothing panics.
#[test]
fn every_public_function_on_an_inconsistent_model_is_an_error_not_a_panic() {
    let w = [0.0, 1.0, 10.0];
    let opts = HinfSynOptions::default();
    for (what, bad) in inconsistent_models() {
        let good = good(bad.dt.filter(|t| t.is_finite() && *t > 0.0));
        let e = |r: bool, f: &str| assert!(r, "{what}: {f} did not return an error");
        // Checks and accessors.
        e(bad.validate().is_err(), "validate");
        let _ = (bad.nstates(), bad.ninputs(), bad.noutputs(), bad.is_siso());
        let _ = (
            bad.is_discrete(),
            bad.has_feedthrough(),
            bad.frequency_point(1.0),
        );
        // Infallible queries: NaN, not stable, unchanged.
        e(bad.try_poles().is_err(), "try_poles");
        assert!(
            bad.poles().iter().all(|p| p.re.is_nan()),
            "{what}: poles {:?}",
            bad.poles()
        );
        assert!(!bad.is_stable(), "{what}: is_stable");
        e(
            bad.try_evalfr(Complex::new(0.0, 1.0)).is_err(),
            "try_evalfr",
        );
        assert!(
            all_nan(&bad.evalfr(Complex::new(0.0, 1.0))),
            "{what}: evalfr"
        );
        e(bad.try_freqresp(&w).is_err(), "try_freqresp");
        assert!(bad.freqresp(&w).iter().all(all_nan), "{what}: freqresp");
        assert!(
            bad.freqresp_siso_at(1.0).re.is_nan(),
            "{what}: freqresp_siso_at"
        );
        assert!(
            bad.freqresp_siso(&w).iter().all(|z| z.re.is_nan()),
            "{what}: freqresp_siso"
        );
        e(bad.try_freqresp_siso(&w).is_err(), "try_freqresp_siso");
        e(bad.try_bode(&w).is_err(), "try_bode");
        let (mag, _) = bad.bode(&w);
        assert!(mag.iter().all(|v| v.is_nan()), "{what}: bode");
        e(bad.try_dcgain().is_err(), "try_dcgain");
        assert!(all_nan(&bad.dcgain()), "{what}: dcgain");
        let bal = bad.balanced();
        assert!(
            bal.validate().is_err()
                && bal.a.shape() == bad.a.shape()
                && bal.b.shape() == bad.b.shape(),
            "{what}: balanced"
        );
        assert!(bad.scaled(2.0).validate().is_err(), "{what}: scaled");
        // Fallible operations: typed errors.
        e(bad.with_input_delay(2).is_err(), "with_input_delay");
        e(bad.with_output_delay(2).is_err(), "with_output_delay");
        e(bad.to_tf().is_err(), "to_tf");
        e(ss2tf(&bad).is_err(), "ss2tf");
        e(ss2sos(&bad).is_err(), "ss2sos");
        e(zpetc_ss(&bad).is_err(), "zpetc_ss");
        for method in [C2dMethod::Zoh, C2dMethod::TUSTIN] {
            e(c2d(&bad, 1e-3, method).is_err(), "c2d");
            e(bad.c2d(1e-3, method).is_err(), "StateSpace::c2d");
        }
        e(series(&bad, &good).is_err(), "series(bad, good)");
        e(series(&good, &bad).is_err(), "series(good, bad)");
        e(parallel(&bad, &good).is_err(), "parallel(bad, good)");
        e(parallel(&good, &bad).is_err(), "parallel(good, bad)");
        e(feedback(&bad, &good, -1.0).is_err(), "feedback(bad, good)");
        e(feedback(&good, &bad, -1.0).is_err(), "feedback(good, bad)");
        e(append(&[good.clone(), bad.clone()]).is_err(), "append");
        e(append(std::slice::from_ref(&bad)).is_err(), "append(bad)");
        e(hinfnorm(&bad).is_err(), "hinfnorm");
        e(stability_margins(&bad).is_err(), "stability_margins");
        e(hinfsyn(&bad, 1, 1, &opts).is_err(), "hinfsyn");
        e(lft(&bad, &good, 1, 1).is_err(), "lft(bad, good)");
        e(lft(&good, &bad, 1, 1).is_err(), "lft(good, bad)");
        e(
            augw(&bad, Some(&good), None, None).is_err(),
            "augw(g = bad)",
        );
        e(
            augw(&good, Some(&bad), None, None).is_err(),
            "augw(w1 = bad)",
        );
        e(
            augw(&good, None, Some(&bad), None).is_err(),
            "augw(w2 = bad)",
        );
        e(
            augw(&good, None, None, Some(&bad)).is_err(),
            "augw(w3 = bad)",
        );
        e(SsStepper::new(&bad).is_err(), "SsStepper::new");
        e(
            lsim(&bad, &DMatrix::zeros(4, bad.ninputs()), None).is_err(),
            "lsim",
        );
        e(lsim_siso(&bad, &[1.0, 0.0]).is_err(), "lsim_siso");
        e(step_response(&bad, 4).is_err(), "step_response");
        e(impulse(&bad, 4).is_err(), "impulse");
    }
}

/// Models read from files pass the checks of `StateSpace::new`.
#[test]
fn deserialising_an_inconsistent_model_is_an_error() {
    let g = good(Some(1e-3));
    let json = serde_json::to_string(&g).unwrap();
    let back: StateSpace = serde_json::from_str(&json).unwrap();
    assert_eq!(back, g);
    let mut bad = g.clone();
    bad.b = DMatrix::zeros(3, 1);
    let json = serde_json::to_string(&bad).unwrap();
    let e = serde_json::from_str::<StateSpace>(&json).unwrap_err();
    assert!(e.to_string().contains("dimension mismatch"), "{e}");
    let mut bad = g.clone();
    bad.dt = Some(-1.0);
    let json = serde_json::to_string(&bad).unwrap();
    assert!(serde_json::from_str::<StateSpace>(&json).is_err());
}

/// A model without outputs has no (0, 0) channel: `lsim_siso` said so by
/// panicking (index out of bounds) before; a model without inputs still
/// simulates.
#[test]
fn lsim_siso_without_outputs_is_an_error() {
    let no_out = StateSpace::new(
        DMatrix::from_element(1, 1, 0.5),
        DMatrix::from_element(1, 1, 1.0),
        DMatrix::zeros(0, 1),
        DMatrix::zeros(0, 1),
        Some(1.0),
    )
    .unwrap();
    assert!(matches!(
        lsim_siso(&no_out, &[1.0]),
        Err(LtiError::Dimension(_))
    ));
    assert!(no_out.freqresp_siso_at(1.0).re.is_nan());
    let no_in = StateSpace::new(
        DMatrix::from_element(1, 1, 0.5),
        DMatrix::zeros(1, 0),
        DMatrix::from_element(1, 1, 1.0),
        DMatrix::zeros(1, 0),
        Some(1.0),
    )
    .unwrap();
    assert_eq!(lsim_siso(&no_in, &[1.0, 2.0]).unwrap(), vec![0.0, 0.0]);
}

/// The Tustin pre-warp is in Hz (`prewarp_hz`); the rad/s constructor gives
/// the same discretisation, exact at ω₀ in rad/s like every frequency grid.
#[test]
fn tustin_prewarp_in_rad_s_matches_the_hz_variant() {
    let dt = 1.0 / 4000.0;
    // Lightly damped resonance at 600 Hz.
    let w_n = 2.0 * PI * 600.0;
    let g =
        TransferFunction::from_slices(&[w_n * w_n], &[1.0, 0.04 * w_n, w_n * w_n], None).unwrap();
    let w0 = 2.0 * PI * 1500.0; // rad/s
    let by_rad = g.c2d(dt, C2dMethod::tustin_prewarp_rad_s(w0)).unwrap();
    let by_hz = g
        .c2d(
            dt,
            C2dMethod::Tustin {
                prewarp_hz: Some(1500.0),
            },
        )
        .unwrap();
    let by_hz2 = g.c2d(dt, C2dMethod::tustin_prewarp_hz(1500.0)).unwrap();
    assert_eq!(by_hz, by_hz2);
    assert!((&by_rad.a - &by_hz.a).norm() < 1e-13 * by_hz.a.norm());
    assert!((&by_rad.d - &by_hz.d).norm() < 1e-13 * by_hz.d.norm().max(1.0));
    let (gc, gd) = (g.freqresp(&[w0])[0], by_rad.freqresp_siso(&[w0])[0]);
    assert!((gc - gd).norm() < 1e-11 * gc.norm(), "{gc} vs {gd}");
    // Plain Tustin is off at 1500 Hz by the frequency warping.
    let plain = g.c2d(dt, C2dMethod::TUSTIN).unwrap();
    assert!((plain.freqresp_siso(&[w0])[0] - gc).norm() > 1e-3 * gc.norm());
    let w0_back = C2dMethod::tustin_prewarp_rad_s(w0).prewarp_rad_s().unwrap();
    assert!((w0_back - w0).abs() <= 4.0 * f64::EPSILON * w0);
    assert_eq!(C2dMethod::Zoh.prewarp_rad_s(), None);
    assert_eq!(C2dMethod::TUSTIN.prewarp_rad_s(), None);
    // Above Nyquist (π/T rad/s) is an error naming both units.
    let e = g
        .c2d(dt, C2dMethod::tustin_prewarp_rad_s(1.01 * PI / dt))
        .unwrap_err();
    assert!(
        e.to_string().contains("rad/s") && e.to_string().contains("Hz"),
        "{e}"
    );
}

fn hurwitz(rng: &mut Rng, n: usize, scale: &[f64]) -> DMatrix<f64> {
    let a = DMatrix::from_fn(n, n, |_, _| rng.normal());
    let worst = nanomotion_core::lti::linalg::eigvals(&a)
        .iter()
        .map(|p| p.re)
        .fold(f64::NEG_INFINITY, f64::max);
    let a = a - DMatrix::identity(n, n) * (worst + 0.5);
    // Diagonal similarity: same eigenvalues, badly scaled entries.
    DMatrix::from_fn(n, n, |i, j| a[(i, j)] * scale[i] / scale[j])
}

/// `care_general_solution`, `lyap_solution` and `dlyap_solution` return the
/// same X as the tuple/matrix functions with residual, backward error and
/// iterations, like `care`/`dare`'s `RiccatiSolution`.
#[test]
fn solution_structs_for_care_general_lyap_and_dlyap() {
    let mut rng = Rng::new(5);
    for case in 0..12 {
        let n = 2 + case % 7;
        let scale: Vec<f64> = (0..n)
            .map(|i| {
                if case % 3 == 0 {
                    10f64.powi(i as i32 % 4 - 2)
                } else {
                    1.0
                }
            })
            .collect();
        let a = hurwitz(&mut rng, n, &scale);
        let c = DMatrix::from_fn(n, n, |_, _| rng.normal());
        let q = &c * c.transpose() + DMatrix::identity(n, n);
        // Lyapunov: AᵀX + XA + Q = 0.
        let sol = lyap_solution(&a, &q).unwrap();
        let x = lyap(&a, &q).unwrap();
        assert!((&sol.x - &x).norm() <= 1e-10 * x.norm(), "case {case}");
        let res = a.transpose() * &sol.x + &sol.x * &a + &q;
        let rel = res.norm() / (2.0 * (a.transpose() * &sol.x).norm() + q.norm());
        assert!(
            (sol.relative_residual - rel).abs() <= 1e-3 * rel + 1e-18,
            "case {case}"
        );
        assert!(
            sol.relative_residual < 1e-13,
            "case {case}: {:e}",
            sol.relative_residual
        );
        assert!(
            sol.backward_error < 1e-13,
            "case {case}: {:e}",
            sol.backward_error
        );
        assert!(sol.iterations <= 2);
        // Stein: AᵀXA − X + Q = 0 with ρ(A) = 0.9.
        let rho = nanomotion_core::lti::linalg::eigvals(&a)
            .iter()
            .map(|p| p.norm())
            .fold(0.0, f64::max);
        let ad = &a * (0.9 / rho);
        let sol = dlyap_solution(&ad, &q).unwrap();
        let x = dlyap(&ad, &q).unwrap();
        assert!((&sol.x - &x).norm() <= 1e-10 * x.norm(), "case {case}");
        let res = ad.transpose() * &sol.x * &ad - &sol.x + &q;
        assert!(
            res.norm() < 1e-12 * (sol.x.norm() + q.norm()),
            "case {case}"
        );
        assert!(
            sol.relative_residual < 1e-13,
            "case {case}: {:e}",
            sol.relative_residual
        );
        assert!(
            sol.backward_error < 1e-13,
            "case {case}: {:e}",
            sol.backward_error
        );
        // General CARE: an indefinite G of the H∞ form (γ = 100) on the
        // well-scaled problems, G = B₂B₂ᵀ on the badly scaled ones (a
        // stabilising solution then exists for sure: A Hurwitz, Q ≻ 0).
        let b2 = DMatrix::from_fn(n, 1, |_, _| rng.normal());
        let b1 = DMatrix::from_fn(n, 1, |_, _| rng.normal());
        let g = if case % 3 == 0 {
            &b2 * b2.transpose()
        } else {
            &b2 * b2.transpose() - &b1 * b1.transpose() * 1e-4
        };
        let sol = care_general_solution(&a, &g, &q).unwrap();
        let (x, it) = care_general(&a, &g, &q).unwrap();
        assert_eq!((&sol.x, sol.iterations), (&x, it), "case {case}");
        let res = a.transpose() * &x + &x * &a - &x * &g * &x + &q;
        let scale = 2.0 * (a.transpose() * &x).norm() + (&x * &g * &x).norm() + q.norm();
        assert!(
            (sol.relative_residual - res.norm() / scale).abs()
                <= 1e-3 * sol.relative_residual + 1e-18
        );
        assert!(
            sol.relative_residual < 1e-12,
            "case {case}: {:e}",
            sol.relative_residual
        );
        assert!(
            sol.backward_error < 1e-12,
            "case {case}: {:e}",
            sol.backward_error
        );
        assert_eq!(sol.closed_loop_poles.len(), n);
        assert!(sol.closed_loop_poles.iter().all(|p| p.re < 0.0));
    }
    // Errors stay typed.
    let one = DMatrix::from_element(1, 1, 1.0);
    assert!(matches!(
        lyap_solution(&DMatrix::zeros(2, 3), &one),
        Err(LtiError::Dimension(_))
    ));
    assert!(matches!(
        lyap_solution(&DMatrix::zeros(1, 1), &one),
        Err(LtiError::Singular(_))
    ));
    assert!(matches!(
        dlyap_solution(&one, &one),
        Err(LtiError::Singular(_))
    ));
    assert!(care_general_solution(&(&one * 0.5), &(-&one * 3.0), &one).is_err());
}

/// Systems from plain rows: `Vec<Vec<f64>>`, `&[&[f64]]` and arrays give the
/// same model as `StateSpace::new`; ragged rows are a typed error naming the
/// matrix and row; sizes that do not fit are a dimension error.
#[test]
fn state_space_and_transfer_function_from_plain_rows() {
    let a = vec![vec![0.0, 1.0], vec![-4.0, -0.4]];
    let b = vec![vec![0.0], vec![1.0]];
    let c = vec![vec![1.0, 0.0]];
    let d = vec![vec![0.5]];
    let from_vecs = StateSpace::from_rows(&a, &b, &c, &d, Some(0.01)).unwrap();
    let a_sl: [&[f64]; 2] = [&[0.0, 1.0], &[-4.0, -0.4]];
    let from_slices = StateSpace::from_rows(
        &a_sl,
        &[&[0.0][..], &[1.0]],
        &[&[1.0, 0.0][..]],
        &[&[0.5][..]],
        Some(0.01),
    )
    .unwrap();
    let from_arrays = StateSpace::from_rows(
        &[[0.0, 1.0], [-4.0, -0.4]],
        &[[0.0], [1.0]],
        &[[1.0, 0.0]],
        &[[0.5]],
        Some(0.01),
    )
    .unwrap();
    let want = StateSpace::new(
        DMatrix::from_row_slice(2, 2, &[0.0, 1.0, -4.0, -0.4]),
        DMatrix::from_row_slice(2, 1, &[0.0, 1.0]),
        DMatrix::from_row_slice(1, 2, &[1.0, 0.0]),
        DMatrix::from_element(1, 1, 0.5),
        Some(0.01),
    )
    .unwrap();
    assert_eq!(from_vecs, want);
    assert_eq!(from_slices, want);
    assert_eq!(from_arrays, want);
    // Empty D is the zero matrix of the right shape (2 outputs × 1 input here).
    let z =
        StateSpace::from_rows(&a, &b, &[[1.0, 0.0], [0.0, 1.0]], &[] as &[[f64; 1]], None).unwrap();
    assert_eq!(z.d, DMatrix::zeros(2, 1));
    // Static gain: no states, sizes from D.
    let k = StateSpace::from_rows(
        &[] as &[[f64; 0]],
        &[] as &[[f64; 2]],
        &[] as &[[f64; 0]],
        &[[1.0, 2.0]],
        None,
    )
    .unwrap();
    assert_eq!(
        k,
        StateSpace::gain(DMatrix::from_row_slice(1, 2, &[1.0, 2.0]), None)
    );
    // Ragged rows, each matrix.
    let ragged = vec![vec![1.0, 0.0], vec![0.0]];
    let cases = [
        (StateSpace::from_rows(&ragged, &b, &c, &d, None), "a"),
        (
            StateSpace::from_rows(&a, &[vec![0.0], vec![1.0, 2.0]], &c, &d, None),
            "b",
        ),
        (
            StateSpace::from_rows(&a, &b, &[vec![1.0, 0.0], vec![1.0]], &d, None),
            "c",
        ),
        (
            StateSpace::from_rows(&a, &b, &c, &[vec![0.5], vec![]], None),
            "d",
        ),
    ];
    for (r, name) in cases {
        match r {
            Err(LtiError::RaggedRows {
                matrix,
                row: 1,
                len,
                expected,
            }) => {
                assert_eq!(matrix, name);
                assert_ne!(len, expected);
            }
            other => panic!("{name}: {other:?}"),
        }
    }
    let e = StateSpace::from_rows(&ragged, &b, &c, &d, None).unwrap_err();
    assert!(
        e.to_string().contains("`a`") && e.to_string().contains("row 1"),
        "{e}"
    );
    // Rectangular but not fitting: dimension errors; non-finite: parameter error.
    assert!(matches!(
        StateSpace::from_rows(&[[0.0, 1.0, 2.0], [0.0, 0.0, 1.0]], &b, &c, &d, None),
        Err(LtiError::Dimension(_))
    ));
    assert!(matches!(
        StateSpace::from_rows(&a, &[[0.0], [1.0], [2.0]], &c, &d, None),
        Err(LtiError::Dimension(_))
    ));
    assert!(matches!(
        StateSpace::from_rows(&a, &b, &c, &[[0.5, 0.0]], None),
        Err(LtiError::Dimension(_))
    ));
    assert!(matches!(
        StateSpace::from_rows(&[[f64::NAN, 1.0], [0.0, 0.0]], &b, &c, &d, None),
        Err(LtiError::Parameter { name: "a", .. })
    ));
    // Transfer functions from slices and arrays.
    let tf = TransferFunction::from_slices(&[1.0, 2.0], &[1.0, 3.0, 2.0], Some(0.1)).unwrap();
    assert_eq!(
        tf,
        TransferFunction::new(vec![1.0, 2.0], vec![1.0, 3.0, 2.0], Some(0.1)).unwrap()
    );
    assert!(matches!(
        TransferFunction::from_slices(&[1.0, 0.0, 0.0], &[1.0, 1.0], None),
        Err(LtiError::Improper { num: 2, den: 1 })
    ));
    assert!(TransferFunction::from_slices(&[1.0], &[0.0], None).is_err());
}
