//! Table 5.1-style experiment (issue 7 item 5) on the *nonlinear* walking piezo
//! stage: `WaveformDriver` (asymmetric waveforms, q = 1/3) → `WalkingPiezoStage`
//! (10 sub-steps of 25 µs inside the 4 kHz loop, seeded μ variation with unequal
//! pairs), PI on f_α designed on the fitted linear model (5.31), the RC memory loop
//! with L = ZPETC of the linear T and a 101-tap FIR Q, DVRC driven by the driver's
//! α. No ripple is added: the error is what the stepping of the model produces.
//! Shared by `tests/table_5_1_nonlinear.rs` and `examples/table_5_1_nonlinear.rs`.
#![allow(dead_code)]

use super::table51::{Rc, RcUnderTest, Setup, Velocity};
use dvrc::filters::Filter;
use dvrc::stability::design_q_cutoff;
use nanomotion_core::blocks::control::Pi;
use nanomotion_core::lti::{Margins, series, stability_margins};
use nanomotion_core::{Controller, LearningFilter};
use walking_piezo::driver::{DriverParams, WaveformDriver, WaveformShape};
use walking_piezo::{StageParams, WalkingPiezoStage};

pub const DT: f64 = super::table51::DT;
/// Seed of the stage's friction variation.
pub const SEED: u64 = 7;

/// Margins of the PI (k_p from `setup`, zero 5 Hz) on the fitted linear model.
pub fn margins(s: &Setup) -> Margins {
    let k = Pi::new(s.kp, 5.0, DT).unwrap().as_pid().state_space();
    stability_margins(&series(&k, &s.g).unwrap()).unwrap()
}

pub fn stage_params() -> StageParams {
    StageParams {
        substeps: 10,
        ..StageParams::default()
    }
}

pub fn driver() -> WaveformDriver {
    WaveformDriver::new(
        DriverParams {
            shape: WaveformShape::Asymmetric {
                overlap_q: 1.0 / 3.0,
            },
            ..Default::default()
        },
        DT,
    )
    .unwrap()
}

/// Open-loop step per α cycle (m) of the nonlinear stage with this driver at
/// `f_alpha_hz` (after one run-in cycle, over `cycles` cycles).
pub fn step_per_cycle(f_alpha_hz: f64, cycles: usize) -> f64 {
    step_per_cycle_on(&stage_params(), f_alpha_hz, cycles)
}

/// [`step_per_cycle`] for other stage parameters.
pub fn step_per_cycle_on(p: &StageParams, f_alpha_hz: f64, cycles: usize) -> f64 {
    let mut d = driver();
    let mut st = WalkingPiezoStage::new(p.clone(), DT, SEED).unwrap();
    let per = (1.0 / (f_alpha_hz * DT)).round() as usize;
    let mut x0 = 0.0;
    for k in 0..per * (cycles + 1) {
        if k == per {
            x0 = st.signals().x_s;
        }
        let (u, _) = d.try_drive(f_alpha_hz, None, None).unwrap();
        let _ = st.step(&u, 0.0);
    }
    (st.signals().x_s - x0) / cycles as f64
}

/// Periods j of α per memory-loop period (N ≥ `n_needed` at the highest speed),
/// the nominal N, and [m, M] with a relative `margin` for irregular stepping.
pub fn delay_range(
    step_m: f64,
    v: Velocity,
    n_needed: usize,
    margin: f64,
) -> (usize, f64, usize, usize) {
    let (vmin, vmax) = v.range();
    let n_of = |vel: f64| step_m / vel / DT;
    let j = ((n_needed as f64 / n_of(vmax)).ceil() as usize).max(1);
    let m = ((1.0 - margin) * j as f64 * n_of(vmax)).floor() as usize;
    let mm = ((1.0 + margin) * j as f64 * n_of(vmin)).ceil() as usize;
    (
        j,
        j as f64 * n_of(0.5 * (vmin + vmax)),
        m.max(n_needed),
        mm.max(n_needed + 1),
    )
}

pub fn q_for(s: &Setup, spread: usize) -> (Filter, f64) {
    let d = design_q_cutoff(&s.t, &s.l, 101, spread, 0.05).unwrap();
    (Filter::fir(d.taps, 50, DT), d.cutoff_hz)
}

/// Result of one run.
#[derive(Debug, Clone, Copy)]
pub struct Outcome {
    /// rms error over the last quarter (m).
    pub rms: f64,
    /// N_k range seen over the last quarter.
    pub seen: (usize, usize),
    /// Fixed-point iterations that hit the cap (whole run).
    pub nonconverged: u64,
}

/// Run one experiment of `duration_s` on the nonlinear stage.
pub fn run(
    s: &Setup,
    q: &Filter,
    step_m: f64,
    margin: f64,
    v: Velocity,
    which: Rc,
    duration_s: f64,
) -> Outcome {
    run_on(&stage_params(), s, q, step_m, margin, v, which, duration_s)
}

/// [`run`] on a stage with parameters `p`.
#[allow(clippy::too_many_arguments)]
pub fn run_on(
    p: &StageParams,
    s: &Setup,
    q: &Filter,
    step_m: f64,
    margin: f64,
    v: Velocity,
    which: Rc,
    duration_s: f64,
) -> Outcome {
    let comp = s.l.preview_samples() + q.preview_samples();
    let (j, n_mean, m, mm) = delay_range(step_m, v, comp + 1, margin);
    let n_fixed = n_mean.round() as usize;
    let mut stage = WalkingPiezoStage::new(p.clone(), DT, SEED).unwrap();
    let mut drv = driver();
    let mut pi = Pi::new(s.kp, 5.0, DT).unwrap();
    let mut rc = RcUnderTest::new(s, q, which, j, n_fixed, m, mm);
    let steps = (duration_s / DT) as usize;
    let mut u = [0.0];
    let mut sq = 0.0;
    let mut cnt = 0usize;
    let mut seen = (usize::MAX, 0usize);
    for k in 0..steps {
        let t = k as f64 * DT;
        let e = v.position(t) - stage.signals().x_s;
        // α of this sample (the driver integrates f_α after output).
        let alpha = drv.alpha();
        let (nk, w) = rc.output(alpha);
        pi.control(&[e + w], &mut u);
        rc.learn(e);
        let (volts, _) = drv.try_drive(u[0], None, None).unwrap();
        let _ = stage.step(&volts, 0.0);
        if k >= steps * 3 / 4 {
            sq += e * e;
            cnt += 1;
            seen = (seen.0.min(nk), seen.1.max(nk));
        }
    }
    Outcome {
        rms: (sq / cnt as f64).sqrt(),
        seen,
        nonconverged: stage.counters().nonconverged,
    }
}

/// T(z) of the PI loop on the fitted linear model with its gain c replaced by
/// `c_m_per_cycle` (e.g. the nonlinear stage's measured step per cycle): for
/// checking the criteria against the plant the loop actually runs on.
pub fn t_with_gain(s: &Setup, c_m_per_cycle: f64) -> nanomotion_core::lti::StateSpace {
    use nanomotion_core::lti::{StateSpace, feedback};
    let p = walking_piezo::FittedStageParams {
        gain_m_per_cycle: c_m_per_cycle,
        ..Default::default()
    };
    let g = p.discrete(DT).unwrap();
    let k = Pi::new(s.kp, 5.0, DT).unwrap().as_pid().state_space();
    let one = StateSpace::gain(nalgebra::DMatrix::from_element(1, 1, 1.0), Some(DT));
    feedback(&series(&k, &g).unwrap(), &one, -1.0).unwrap()
}
