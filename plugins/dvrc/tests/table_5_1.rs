//! Issue 7 item 5, reduced: the Table 5.1-style experiment on the linear fitted
//! stage with a ripple periodic in α (see `examples/table_5_1.rs` for the full
//! table and docs/repetitive-control.md for the discussion).

mod common;
use common::table51::*;

#[test]
fn uniform_alpha_rc_equals_dvrc_varying_rate_dvrc_adapts() {
    let s = setup();
    let constant = Velocity::Constant(1e-4);
    let varying = Velocity::Sinusoidal {
        v0: 1e-5,
        a: 0.5,
        f_hz: 0.1,
    };
    let (_, _, m1, mm1) = delay_range(&s, constant, 56);
    let (_, _, m2, mm2) = delay_range(&s, varying, 56);
    let (q, fc) = q_for(&s, (mm1 - m1).max(mm2 - m2));
    assert!(fc > 50.0 && fc < 1000.0, "{fc}");
    // 0.1 mm/s: ripple fundamental 12.6 Hz, N = 316 samples.
    let none = run(&s, &q, constant, Rc::None, 6.0).0;
    let (rc, n_rc) = run(&s, &q, constant, Rc::Standard, 6.0);
    let (dv, n_dv) = run(&s, &q, constant, Rc::Dvrc, 6.0);
    assert!(none > 1e-9, "{none}");
    assert!(rc < 0.05 * none && dv < 0.05 * none, "{none} {rc} {dv}");
    assert_eq!(n_rc, (316, 316));
    assert_eq!(n_dv, (316, 316), "α advances uniformly: N_k constant");
    assert!((rc - dv).abs() <= 0.05 * rc, "{rc} vs {dv}");
    // Sinusoidal velocity: N_k follows the rate over a factor ~3.
    let (dvv, seen) = run(&s, &q, varying, Rc::Dvrc, 40.0);
    let rcv = run(&s, &q, varying, Rc::Standard, 40.0).0;
    assert!(seen.0 < 2300 && seen.1 > 5500, "{seen:?}");
    assert!(dvv < rcv, "DVRC {dvv} vs RC {rcv}");
}
