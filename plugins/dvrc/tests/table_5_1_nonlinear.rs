//! Issue 7 item 5 on the nonlinear walking piezo stage, reduced to short runs:
//! only robust shapes are asserted (see `examples/table_5_1_nonlinear.rs` for the
//! full table and docs/repetitive-control.md for the discussion).

mod common;
use common::table51::{Rc, Velocity, setup};
use common::table51_nonlinear::*;

#[test]
fn nonlinear_stage_dvrc_beats_no_rc_and_fixed_n_rc_on_varying_velocity() {
    let s = setup();
    // The 50 Hz PI is stable with margins on the fitted linear model.
    let mg = margins(&s);
    assert!(mg.phase_margin_deg > 45.0, "{mg:?}");
    assert!(mg.gain_margin > 2.0, "{mg:?}");
    let margin = 0.25;
    let step = step_per_cycle(1.0, 2);
    // The nonlinear stage walks ~10 % less per cycle than the linear model's c.
    assert!(
        step > 0.5 * s.c_m_per_cycle && step < s.c_m_per_cycle,
        "{step:e}"
    );
    let varying = Velocity::Sinusoidal {
        v0: 1e-5,
        a: 0.5,
        f_hz: 0.1,
    };
    let (_, _, m, mm) = delay_range(step, varying, 56, margin);
    let (q, fc) = q_for(&s, mm - m);
    assert!(fc > 50.0 && fc < 1000.0, "{fc}");
    for (v, dur) in [(1e-6, 40.0), (1e-5, 15.0), (1e-4, 5.0), (1e-3, 3.0)] {
        let v = Velocity::Constant(v);
        let none = run(&s, &q, step, margin, v, Rc::None, dur);
        let dv = run(&s, &q, step, margin, v, Rc::Dvrc, dur);
        assert!(none.rms > 1e-11, "{v:?}: {none:?}");
        assert!(dv.rms <= none.rms, "{v:?}: DVRC {dv:?} vs none {none:?}");
    }
    let none = run(&s, &q, step, margin, varying, Rc::None, 40.0);
    let rc = run(&s, &q, step, margin, varying, Rc::Standard, 40.0);
    let dv = run(&s, &q, step, margin, varying, Rc::Dvrc, 40.0);
    // N_k follows the rate (v ∈ [5, 15] µm/s).
    assert!(dv.seen.1 > 2 * dv.seen.0, "{:?}", dv.seen);
    assert!(dv.rms < rc.rms, "DVRC {dv:?} vs RC {rc:?}");
    assert!(dv.rms < none.rms, "DVRC {dv:?} vs none {none:?}");
}
