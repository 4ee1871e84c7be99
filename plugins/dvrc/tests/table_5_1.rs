//! Issue 7 item 5 / issue 18 item 3, reduced: the Table 5.1-style experiment on
//! the linear fitted stage with a take-over velocity dip periodic in α (see
//! `examples/table_5_1.rs` for the full table and docs/repetitive-control.md for
//! the discussion).

use nanomotion::experiments::table51::*;

#[test]
fn uniform_alpha_rc_equals_dvrc_varying_rate_dvrc_adapts() {
    let s = setup();
    let constant = Velocity::Constant(1e-4);
    let varying = Velocity::Sinusoidal {
        v0: 1e-5,
        a: 0.5,
        f_hz: 0.1,
    };
    let (_, _, m1, mm1) = delay_range_dip(&s, constant, 56);
    let (_, _, m2, mm2) = delay_range_dip(&s, varying, 56);
    let (q, fc) = q_for(&s, (mm1 - m1).max(mm2 - m2));
    assert!(fc > 50.0 && fc < 1000.0, "{fc}");
    // 0.1 mm/s: the stage walks c(1 − mean δ) per α cycle.
    let n = (s.c_m_per_cycle * (1.0 - dip_mean()) / 1e-4 / DT).round() as usize;
    let none = run(&s, &q, constant, Rc::None, 6.0).0;
    let (rc, n_rc) = run(&s, &q, constant, Rc::Standard, 6.0);
    let (dv, n_dv) = run(&s, &q, constant, Rc::Dvrc, 6.0);
    assert!(none > 1e-9, "{none}");
    // The dip's harmonics above Q's cut-off (≈ 210 Hz; 2f_α = 27 Hz here) are not
    // learned: RC removes most, not all of it.
    assert!(rc < 0.2 * none && dv < 0.2 * none, "{none} {rc} {dv}");
    assert_eq!(n_rc, (n, n));
    assert!(
        n_dv.0 + 1 >= n && n_dv.1 <= n + 1,
        "α advances uniformly: N_k within one sample of {n}: {n_dv:?}"
    );
    assert!((rc - dv).abs() <= 0.2 * rc, "{rc} vs {dv}");
    // Sinusoidal velocity: N_k follows the rate over a factor ~3.
    let (dvv, seen) = run(&s, &q, varying, Rc::Dvrc, 40.0);
    let rcv = run(&s, &q, varying, Rc::Standard, 40.0).0;
    assert!(seen.0 < 2200 && seen.1 > 5200, "{seen:?}");
    assert!(dvv < rcv, "DVRC {dvv} vs RC {rcv}");
}

/// The α-synchronous average splits a signal that is periodic in α plus a
/// non-periodic part into the two (independent check: a sine in α and a sine in
/// t at an incommensurate frequency).
#[test]
fn alpha_periodic_split_separates_periodic_and_other_parts() {
    let n = 200_000;
    let alpha: Vec<f64> = (0..n).map(|k| k as f64 * 0.01).collect();
    let e: Vec<f64> = alpha
        .iter()
        .enumerate()
        .map(|(k, a)| 3.0 * (2.0 * a).sin() + 4.0 * (k as f64 * 0.0123 * std::f64::consts::E).sin())
        .collect();
    let (tot, per, rest) = alpha_periodic_split(&e, &alpha, 256);
    let r2 = std::f64::consts::FRAC_1_SQRT_2;
    assert!((per - 3.0 * r2).abs() < 0.05, "{per}");
    assert!((rest - 4.0 * r2).abs() < 0.05, "{rest}");
    assert!((tot * tot - per * per - rest * rest).abs() < 1e-9);
}
