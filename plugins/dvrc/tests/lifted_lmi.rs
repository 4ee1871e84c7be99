//! The lifted LMI check (5.16) (`stability::lifted_lmi_check`) against the other,
//! independent tests of the same lifted system (5.13)–(5.15):
//!
//! - consistency with the joint-spectral-radius branch and bound (`lifted_check`)
//!   and with the small-gain criterion (5.9) on seeded random cases: LMI feasible
//!   ⇒ the certificate bounds the JSR below 1 and no destabilising product exists;
//!   a destabilising product ⇒ LMI infeasible; (5.9) ⇒ LMI feasible (the
//!   small-gain Lyapunov function of Theorem 4 is a special case of (5.16));
//! - "less conservative": cases where (5.9) fails and (5.16) proves stability,
//!   computed (an abstract H and a whole RC loop through `rc-check`);
//! - m = M: (5.16) is one Lyapunov LMI, feasible ⇔ ρ(Λ(m)) < 1;
//! - every certificate re-verified here by eigenvalues of P_i − Λ(i)ᵀP_jΛ(i).

mod support;
use dvrc::check::{LiftedLmiOutcome, rc_check_graph};
use dvrc::stability::{
    LIFTED_LMI_MAX_UNKNOWNS, LiftedLmi, LiftedLmiOptions, LiftedVerdict, LmiForm, lifted_check,
    lifted_lmi_check, lifted_lmi_unknowns, lifted_matrix, simulate_delay_loop,
};
use nalgebra::DMatrix;
use nanomotion_core::GraphSpec;
use nanomotion_core::lti::lmi::LmiStatus;
use nanomotion_core::lti::{StateSpace, hinfnorm};
use nanomotion_core::rng::Rng;
use support::spectral_radius;

const DT: f64 = 1e-3;

fn resonant_h(r: f64, th: f64, norm: f64) -> StateSpace {
    support::resonant_h(r, th, norm, DT)
}

/// H(z) = c z⁻¹ (one state).
fn gain_h(c: f64) -> StateSpace {
    let m = |v: f64| DMatrix::from_element(1, 1, v);
    StateSpace::new(m(0.0), m(1.0), m(c), m(0.0), Some(DT)).unwrap()
}

fn min_eig(m: &DMatrix<f64>) -> f64 {
    ((m + m.transpose()) * 0.5)
        .symmetric_eigenvalues()
        .iter()
        .copied()
        .fold(f64::INFINITY, f64::min)
}

/// Re-verify a certificate from scratch: min over i, j of λ_min(P_i) and
/// λ_min(P_i − Λ(i)ᵀP_jΛ(i)).
fn verify(h: &StateSpace, n_min: usize, n_max: usize, r: &LiftedLmi) -> f64 {
    let mut worst = f64::INFINITY;
    for (i, pi) in r.p.iter().enumerate() {
        let lam = lifted_matrix(h, n_min + i, n_max);
        worst = worst.min(min_eig(pi));
        for pj in &r.p {
            worst = worst.min(min_eig(&(pi - lam.transpose() * pj * &lam)));
        }
    }
    worst
}

fn lmi(h: &StateSpace, n_min: usize, n_max: usize) -> LiftedLmi {
    lifted_lmi_check(h, n_min, n_max, &LiftedLmiOptions::default()).unwrap()
}

#[test]
fn lmi_is_consistent_with_the_jsr_branch_and_bound_and_with_5_9() {
    let mut rng = Rng::new(0x516_0001);
    let (mut feasible, mut infeasible, mut bb_stable, mut bb_unstable) = (0, 0, 0, 0);
    for case in 0..24 {
        let r = rng.uniform_in(0.3, 0.9);
        let th = rng.uniform_in(0.2, 2.8);
        let norm = rng.uniform_in(0.3, 1.2);
        let m = 1 + case % 3;
        let spread = (case / 3) % 4;
        let mm = m + spread;
        let h = resonant_h(r, th, norm);
        let res = lmi(&h, m, mm);
        let bb = lifted_check(&h, m, mm, 5_000);
        let small_gain = norm < 1.0 / ((spread + 1) as f64).sqrt();
        let what = format!("case {case}: r {r:.3}, θ {th:.3}, ‖H‖ {norm:.3}, N ∈ [{m}, {mm}]");
        if small_gain {
            // The Lyapunov function of Theorem 4 / Corollary 7 is a common P.
            assert!(res.feasible(), "{what}: (5.9) holds but {res}");
        }
        if res.feasible() {
            feasible += 1;
            assert!(verify(&h, m, mm, &res) > 0.0, "{what}");
            let jsr = res.jsr_upper.unwrap();
            assert!(jsr < 1.0, "{what}: {jsr}");
            // No product of Λ's can have a spectral radius above the bound.
            assert!(bb.rho_lower <= jsr + 1e-9, "{what}: {bb} vs {jsr}");
            assert!(
                !matches!(bb.verdict, LiftedVerdict::Unstable { .. }),
                "{what}"
            );
            if bb.verdict == LiftedVerdict::Stable {
                bb_stable += 1;
            }
        } else {
            infeasible += 1;
            assert_eq!(res.status, LmiStatus::InfeasibleWithinTolerance, "{what}");
        }
        if let LiftedVerdict::Unstable { sequence } = &bb.verdict {
            bb_unstable += 1;
            assert!(!res.feasible(), "{what}: destabilising {sequence:?}");
        }
    }
    assert!(
        feasible >= 6 && infeasible >= 3,
        "{feasible} / {infeasible}"
    );
    assert!(
        bb_stable >= 3 && bb_unstable >= 1,
        "{bb_stable} / {bb_unstable}"
    );
}

#[test]
fn lmi_proves_stability_where_5_9_fails() {
    // ‖H‖∞ = 0.9, delays N ∈ [1, 3]: (5.9) needs ‖H‖∞ < 1/√3 = 0.577.
    let h = resonant_h(0.8, 1.0, 0.9);
    let hinf = hinfnorm(&h).unwrap().norm;
    assert!((hinf - 0.9).abs() < 1e-9);
    assert!(hinf >= 1.0 / 3f64.sqrt(), "(5.9) would hold");
    let res = lmi(&h, 1, 3);
    assert_eq!(res.status, LmiStatus::Feasible, "{res}");
    assert!(res.margin > 0.0 && verify(&h, 1, 3, &res) > 0.0);
    assert!(res.jsr_upper.unwrap() < 1.0);
    assert_eq!((res.dim, res.n_delays, res.unknowns), (5, 3, 45));
    // The literal block form of (5.16) gives the same answer.
    let block = lifted_lmi_check(
        &h,
        1,
        3,
        &LiftedLmiOptions {
            form: LmiForm::Block,
            ..Default::default()
        },
    )
    .unwrap();
    assert_eq!(block.status, LmiStatus::Feasible, "{block}");
    assert!(verify(&h, 1, 3, &block) > 0.0);
    // Random delay sequences in [1, 3] all decay.
    let mut rng = Rng::new(7);
    for _ in 0..8 {
        let len = 600;
        let delays: Vec<usize> = (0..len)
            .map(|_| 1 + (rng.next_u64() % 3) as usize)
            .collect();
        let mut d = vec![0.0; len];
        d[0] = 1.0;
        let (q, _) = simulate_delay_loop(&h, &delays, &d);
        let late = q[len - 50..].iter().map(|x| x.abs()).fold(0.0, f64::max);
        assert!(late < 1e-3, "{late}");
    }
    // H = c z⁻¹ with delays in [1, 2]: (5.9) needs |c| < 0.707; (5.16) proves
    // c = 0.8 (not c = −0.8: the quadratic Lyapunov functions of (5.16) are
    // not sign-symmetric here, although |q| ≤ |c| max |q_past| shows that any
    // |c| < 1 is stable).
    let res = lmi(&gain_h(0.8), 1, 2);
    assert_eq!(res.status, LmiStatus::Feasible, "{res}");
    assert!(verify(&gain_h(0.8), 1, 2, &res) > 0.0);
    assert!(!lmi(&gain_h(-0.8), 1, 2).feasible());
}

/// A DVRC loop whose learning filter inverts a model with 5× the true gain:
/// T = 0.2/(z − 0.8), L = ZPETC of 1/(z − 0.8) (preview 1), Q = 1, so
/// H = Q(z⁻¹ − T L_c) = 0.8 z⁻¹. With N_k ∈ [2, 3] (delay block 1 or 2),
/// (5.9) needs ‖H‖∞ < 1/√2.
const GAIN_LOOP: &str = r#"
base_rate_hz: 1000
duration_s: 0.1
blocks:
  - name: rc
    type: dvrc
    n_min: 2
    n_max: 3
    learning: {kind: zpetc, num: [1.0], den: [1.0, -0.8]}
    robustness: {kind: identity}
    t_model: {num: [0.2], den: [1.0, -0.8]}
connections: []
"#;

#[test]
fn rc_check_reports_the_lmi_and_accepts_what_only_it_proves() {
    let spec = GraphSpec::from_yaml(GAIN_LOOP, "gain_loop").unwrap();
    let report = rc_check_graph(&spec);
    let b = &report.blocks[0];
    let c = b.criterion.as_ref().unwrap();
    assert!((c.hinf - 0.8).abs() < 1e-6, "{c}");
    assert!(!c.holds() && !b.small_gain_holds());
    let Some(LiftedLmiOutcome::Solved(res)) = &b.lifted_lmi else {
        panic!("LMI not run: {report}");
    };
    assert!(res.feasible(), "{report}");
    assert!(b.lifted_proves() && b.holds() && report.all_hold());
    let text = report.to_string();
    assert!(text.contains("lifted LMIs (5.16)"), "{text}");
    assert!(
        text.contains("although the small-gain criterion fails"),
        "{text}"
    );
    // With a 10× model error H = 0.9 z⁻¹ over N_k ∈ [2, 5]: neither (5.9) nor the
    // LMI proves anything and rc-check says so.
    let worse = GAIN_LOOP
        .replace("n_max: 3", "n_max: 5")
        .replace("num: [0.2]", "num: [0.1]");
    let report = rc_check_graph(&GraphSpec::from_yaml(&worse, "worse").unwrap());
    let b = &report.blocks[0];
    assert!(!b.holds() && !report.all_hold(), "{report}");
    assert!(report.to_string().contains("infeasible"), "{report}");
}

#[test]
fn rc_check_says_when_the_lmi_is_too_large() {
    let yaml = std::fs::read_to_string(concat!(env!("CARGO_MANIFEST_DIR"), "/graphs/rc_dvrc.yaml"))
        .unwrap();
    let report = rc_check_graph(&GraphSpec::from_yaml(&yaml, "rc_dvrc").unwrap());
    let b = &report.blocks[0];
    let Some(LiftedLmiOutcome::Skipped {
        dim,
        n_delays,
        unknowns,
        limit,
    }) = &b.lifted_lmi
    else {
        panic!("{report}");
    };
    assert_eq!(*limit, LIFTED_LMI_MAX_UNKNOWNS);
    assert_eq!(*n_delays, 101);
    assert_eq!(*unknowns, n_delays * dim * (dim + 1) / 2);
    let text = report.to_string();
    assert!(
        text.contains("lifted LMIs (5.16) skipped: too large") && text.contains("limit 600"),
        "{text}"
    );
    assert!(
        text.contains("joint-spectral-radius check skipped"),
        "{text}"
    );
    assert!(report.all_hold(), "(5.9) still holds: {text}");
}

#[test]
fn fixed_delay_reduces_to_a_lyapunov_test() {
    // m = M: one P and one LMI P − Λ(m)ᵀPΛ(m) ≻ 0, feasible ⇔ ρ(Λ(m)) < 1.
    let mut rng = Rng::new(0x516_0002);
    let (mut stable, mut unstable) = (0, 0);
    for _ in 0..40 {
        let h = resonant_h(
            rng.uniform_in(0.2, 0.95),
            rng.uniform_in(0.1, 3.0),
            rng.uniform_in(0.3, 2.5),
        );
        let n = 1 + (rng.next_u64() % 5) as usize;
        let rho = spectral_radius(&lifted_matrix(&h, n, n));
        if (rho - 1.0).abs() < 2e-3 {
            continue;
        }
        let res = lmi(&h, n, n);
        assert_eq!((res.n_delays, res.n_lmis), (1, 2));
        if rho < 1.0 {
            stable += 1;
            assert_eq!(res.status, LmiStatus::Feasible, "ρ = {rho}: {res}");
            assert!(verify(&h, n, n, &res) > 0.0);
            // The certificate's bound is ≥ ρ (it is an induced norm).
            assert!(res.jsr_upper.unwrap() >= rho - 1e-9);
        } else {
            unstable += 1;
            assert_eq!(
                res.status,
                LmiStatus::InfeasibleWithinTolerance,
                "ρ = {rho}: {res}"
            );
        }
    }
    assert!(stable >= 8 && unstable >= 8, "{stable} / {unstable}");
}

#[test]
fn destabilising_sequence_means_infeasible_lmis() {
    // The documented counterexample: ‖H‖∞ = 0.9, N ∈ [1, 5]; the JSR check finds
    // a periodic sequence with ρ > 1, so no Lyapunov function can exist.
    let h = resonant_h(0.8, 1.0, 0.9);
    let bb = lifted_check(&h, 1, 5, 20_000);
    assert!(matches!(bb.verdict, LiftedVerdict::Unstable { .. }));
    let res = lmi(&h, 1, 5);
    assert_eq!(res.status, LmiStatus::InfeasibleWithinTolerance, "{res}");
    assert!(res.jsr_upper.is_none());
    assert!(res.to_string().contains("not proved"));
}

#[test]
fn bad_input_gives_errors_not_panics() {
    let h = resonant_h(0.8, 1.0, 0.5);
    let o = LiftedLmiOptions::default();
    assert!(lifted_lmi_check(&h, 0, 3, &o).is_err());
    assert!(lifted_lmi_check(&h, 3, 2, &o).is_err());
    let mut cont = h.clone();
    cont.dt = None;
    assert!(lifted_lmi_check(&cont, 1, 2, &o).is_err());
    let mut nan = h.clone();
    nan.a[(0, 0)] = f64::NAN;
    assert!(lifted_lmi_check(&nan, 1, 2, &o).is_err());
    let mimo = StateSpace::new(
        DMatrix::zeros(1, 1),
        DMatrix::zeros(1, 2),
        DMatrix::zeros(1, 1),
        DMatrix::zeros(1, 2),
        Some(DT),
    )
    .unwrap();
    assert!(lifted_lmi_check(&mimo, 1, 2, &o).is_err());
    // Too large: the error names the size and the limit.
    let e = lifted_lmi_check(&h, 10, 40, &o).unwrap_err().to_string();
    let u = lifted_lmi_unknowns(2, 10, 40);
    assert!(e.contains(&u.to_string()) && e.contains("limit 600"), "{e}");
    assert_eq!(lifted_lmi_unknowns(2, 1, 3), 3 * 15);
    assert_eq!(lifted_lmi_unknowns(usize::MAX, 1, usize::MAX), usize::MAX);
}

#[test]
fn lmi_thresholds_documented_in_repetitive_control_md() {
    // (H, m, M, largest ‖H‖∞ for which (5.16) is feasible, found by bisection).
    type Row<'a> = (&'a dyn Fn(f64) -> StateSpace, usize, usize, f64);
    let res_08 = |g| resonant_h(0.8, 1.0, g);
    let res_09 = |g| resonant_h(0.9, 2.0, g);
    let rows: [Row; 6] = [
        (&res_08, 1, 3, 0.9998),
        (&res_08, 1, 5, 0.795),
        (&res_08, 4, 7, 0.736),
        (&res_09, 1, 5, 0.834),
        (&gain_h, 1, 2, 0.881),
        (&gain_h, 1, 4, 0.646),
    ];
    for (h, m, mm, max) in rows {
        let bound = 1.0 / ((mm - m + 1) as f64).sqrt();
        assert!(max > bound + 0.1);
        let below = lmi(&h(max - 0.015), m, mm);
        assert!(below.feasible(), "[{m}, {mm}] at {}: {below}", max - 0.015);
        if max + 0.015 < 1.0 {
            let above = lmi(&h(max + 0.015), m, mm);
            assert!(!above.feasible(), "[{m}, {mm}] at {}: {above}", max + 0.015);
        }
    }
}
