//! Sec. 5.5.3 on the fitted walking-piezo model (5.31): PI feedback with a 50 Hz
//! bandwidth at 4 kHz, L = ZPETC of T, and the linear-phase Q (101 taps) chosen by
//! `design_q_cutoff` for a fixed delay (criterion (5.5)) and for the thesis's
//! worst-case delay spread M − m = 180 (criterion (5.9), bound −22.6 dB).
//!
//! Run: `cargo run --release -p nanomotion-dvrc --example ch5_design`

use dvrc::Filter;
use dvrc::stability::{criterion_curve, design_q_cutoff, rc_criterion};
use nanomotion_core::blocks::control::Pi;
use nanomotion_core::lti::{StateSpace, feedback, series, zpetc_ss};
use walking_piezo::FittedStageParams;

const DT: f64 = 1.0 / 4000.0;

/// T(z) of the Ch. 5 loop and its ZPETC learning filter.
pub fn ch5_loop() -> (StateSpace, Filter) {
    let p = FittedStageParams::default();
    let g = p.discrete(DT).expect("fitted model");
    // PI (thesis: zero at f_zc, 50 Hz bandwidth): k·(s + 2π f_zc)/s with
    // |G K| = 1 at 50 Hz, G ≈ c/s there.
    let f_bw = 50.0;
    let kp = 2.0 * std::f64::consts::PI * f_bw / p.gain_m_per_cycle;
    let k = Pi::new(kp, 5.0, DT).expect("PI").as_pid().state_space();
    let one = StateSpace::gain(nalgebra::DMatrix::from_element(1, 1, 1.0), Some(DT));
    let t = feedback(&series(&k, &g).unwrap(), &one, -1.0).unwrap();
    let z = zpetc_ss(&t).expect("ZPETC of T");
    let l = Filter::from_ss(z.to_ss().unwrap(), z.preview).unwrap();
    (t, l)
}

fn main() {
    let (t, l) = ch5_loop();
    println!(
        "T stable: {}, ZPETC preview l = {}",
        t.is_stable(),
        nanomotion_core::LearningFilter::preview_samples(&l)
    );
    let f: Vec<f64> = (1..200).map(|i| i as f64 * 10.0).collect();
    let no_q = criterion_curve(&t, &l, &Filter::identity(DT), &f);
    let worst = f
        .iter()
        .zip(&no_q)
        .fold((0.0, 0.0), |a, (&fi, &v)| if v > a.1 { (fi, v) } else { a });
    println!(
        "without Q: max |1 − T L z^l| = {:.3} at {:.0} Hz",
        worst.1, worst.0
    );
    for spread in [0usize, 180] {
        let d = design_q_cutoff(&t, &l, 101, spread, 0.05).expect("design");
        let q = Filter::fir(d.taps.clone(), 50, DT);
        let c = rc_criterion(&t, &l, &q, 600, 600 + spread).unwrap();
        println!("M − m = {spread:3}: Q cut-off {:.1} Hz; {c}", d.cutoff_hz);
    }
}
