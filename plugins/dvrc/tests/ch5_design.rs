//! Sec. 5.5.3 on the fitted walking-piezo model (5.31): the Q design for a fixed
//! delay and for the thesis's worst-case spread M − m = 180 (bound −22.6 dB).
//! Same computation as `examples/ch5_design.rs`.

use dvrc::Filter;
use dvrc::stability::{design_q_cutoff, rc_criterion};
use nanomotion_core::LearningFilter;
use nanomotion_core::blocks::control::Pi;
use nanomotion_core::lti::{StateSpace, feedback, series, zpetc_ss};
use walking_piezo::FittedStageParams;

const DT: f64 = 1.0 / 4000.0;

#[test]
fn ch5_q_design_for_fixed_and_varying_delay() {
    let p = FittedStageParams::default();
    let g = p.discrete(DT).unwrap();
    let kp = 2.0 * std::f64::consts::PI * 50.0 / p.gain_m_per_cycle;
    let k = Pi::new(kp, 5.0, DT).unwrap().as_pid().state_space();
    let one = StateSpace::gain(nalgebra::DMatrix::from_element(1, 1, 1.0), Some(DT));
    let t = feedback(&series(&k, &g).unwrap(), &one, -1.0).unwrap();
    assert!(t.is_stable());
    let z = zpetc_ss(&t).unwrap();
    let l = Filter::from_ss(z.to_ss().unwrap(), z.preview).unwrap();
    // 3 samples plant delay + relative degree + unstable zeros.
    assert!(l.preview_samples() >= 4, "{}", l.preview_samples());
    // Fixed N: (5.5) holds already without Q (our L inverts the model itself).
    let c0 = rc_criterion(&t, &l, &Filter::identity(DT), 600, 600).unwrap();
    assert!(c0.holds() && c0.hinf > 0.3, "{c0}");
    // M − m = 180: Q must cut off well below Nyquist.
    let d = design_q_cutoff(&t, &l, 101, 180, 0.05).unwrap();
    assert!(
        d.cutoff_hz > 100.0 && d.cutoff_hz < 1000.0,
        "{}",
        d.cutoff_hz
    );
    assert!((20.0 * d.criterion.bound.log10() + 22.58).abs() < 0.01);
    assert!(d.criterion.holds(), "{}", d.criterion);
    // The exact norm is below the bound, and not by much (the design is tight).
    let q = Filter::fir(d.taps.clone(), 50, DT);
    let c = rc_criterion(&t, &l, &q, 600, 780).unwrap();
    assert!(c.margin_db() > 0.0 && c.margin_db() < 2.0, "{c}");
    // A 20 % higher cut-off breaks (5.9): the criterion bites.
    let q_hi = Filter::fir(
        nanomotion_core::lti::fir_lowpass(101, 1.2 * d.cutoff_hz, DT).unwrap(),
        50,
        DT,
    );
    assert!(!rc_criterion(&t, &l, &q_hi, 600, 780).unwrap().holds());
}
