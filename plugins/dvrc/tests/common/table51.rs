//! Table 5.1-style experiment on the *linear* fitted stage (5.31) with a ripple
//! periodic in the leg angle (Fig. 5.6(b)): x_s = G(z) f_α + d(α), α = 2π ∫ f_α dt.
//! Shared by `tests/table_5_1.rs` and `examples/table_5_1.rs`.
#![allow(dead_code)]

use dvrc::filters::Filter;
use dvrc::rc::MemoryLoop;
use dvrc::stability::{design_q_cutoff, rc_criterion};
use nanomotion_core::blocks::control::Pi;
use nanomotion_core::lti::{SsStepper, StateSpace, feedback, series, zpetc_ss};
use nanomotion_core::{Controller, LearningFilter};
use std::f64::consts::TAU;
use walking_piezo::FittedStageParams;

pub const DT: f64 = 1.0 / 4000.0;

/// The ripple d(α) (m): our choice, harmonics 1, 2 and 4 of the leg angle.
pub fn ripple(alpha: f64) -> f64 {
    5e-9 * alpha.sin() + 2e-9 * (2.0 * alpha + 0.7).sin() + 1e-9 * (4.0 * alpha + 1.3).sin()
}

/// Which controller adds to the PI loop.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Rc {
    None,
    Standard,
    HighOrder,
    Dvrc,
}

pub struct Setup {
    pub g: StateSpace,
    pub kp: f64,
    pub t: StateSpace,
    pub l: Filter,
    pub c_m_per_cycle: f64,
}

pub fn setup() -> Setup {
    let p = FittedStageParams::default();
    let g = p.discrete(DT).unwrap();
    let kp = TAU * 50.0 / p.gain_m_per_cycle;
    let k = Pi::new(kp, 5.0, DT).unwrap().as_pid().state_space();
    let one = StateSpace::gain(nalgebra::DMatrix::from_element(1, 1, 1.0), Some(DT));
    let t = feedback(&series(&k, &g).unwrap(), &one, -1.0).unwrap();
    let z = zpetc_ss(&t).unwrap();
    let l = Filter::from_ss(z.to_ss().unwrap(), z.preview).unwrap();
    Setup {
        g,
        kp,
        t,
        l,
        c_m_per_cycle: p.gain_m_per_cycle,
    }
}

/// Velocity profile (m/s) at time t.
#[derive(Debug, Clone, Copy)]
pub enum Velocity {
    Constant(f64),
    /// v0·(1 + a·sin(2π f t))
    Sinusoidal {
        v0: f64,
        a: f64,
        f_hz: f64,
    },
}

impl Velocity {
    pub fn position(&self, t: f64) -> f64 {
        match *self {
            Velocity::Constant(v) => v * t,
            Velocity::Sinusoidal { v0, a, f_hz } => {
                v0 * (t + a * (1.0 - (TAU * f_hz * t).cos()) / (TAU * f_hz))
            }
        }
    }
    pub fn range(&self) -> (f64, f64) {
        match *self {
            Velocity::Constant(v) => (v, v),
            Velocity::Sinusoidal { v0, a, .. } => (v0 * (1.0 - a), v0 * (1.0 + a)),
        }
    }
}

/// Periods j of α per memory-loop period so that N ≥ `n_needed` at the highest
/// speed, and [m, M] (samples) for the velocity profile (±10 % margin).
pub fn delay_range(s: &Setup, v: Velocity, n_needed: usize) -> (usize, f64, usize, usize) {
    let (vmin, vmax) = v.range();
    let n_of = |vel: f64| s.c_m_per_cycle / vel / DT; // samples per α period
    let j = ((n_needed as f64 / n_of(vmax)).ceil() as usize).max(1);
    let m = (0.9 * j as f64 * n_of(vmax)).floor() as usize;
    let mm = (1.1 * j as f64 * n_of(vmin)).ceil() as usize;
    (
        j,
        j as f64 * n_of(0.5 * (vmin + vmax)),
        m.max(n_needed),
        mm.max(n_needed + 1),
    )
}

/// The Q used by all three RC variants: 101 taps, designed for `spread`.
pub fn q_for(s: &Setup, spread: usize) -> (Filter, f64) {
    let d = design_q_cutoff(&s.t, &s.l, 101, spread, 0.05).unwrap();
    (Filter::fir(d.taps, 50, DT), d.cutoff_hz)
}

/// Run one experiment; returns (rms error over the last quarter (m), the N range seen).
pub fn run(
    s: &Setup,
    q: &Filter,
    v: Velocity,
    which: Rc,
    duration_s: f64,
) -> (f64, (usize, usize)) {
    run_with(s, q, v, which, duration_s, 1.0)
}

/// [`run`] with the ripple scaled by `ripple_gain` (0: the reference-induced floor).
pub fn run_with(
    s: &Setup,
    q: &Filter,
    v: Velocity,
    which: Rc,
    duration_s: f64,
    ripple_gain: f64,
) -> (f64, (usize, usize)) {
    run_loop(s, s, q, v, which, duration_s, ripple_gain)
}

/// [`run`] with the plant of `plant` (its `g`; N from its `c_m_per_cycle`) and
/// the PI, L of `design`: the loop with a model mismatch.
pub fn run_mixed(
    plant: &Setup,
    design: &Setup,
    q: &Filter,
    v: Velocity,
    which: Rc,
    duration_s: f64,
) -> (f64, (usize, usize)) {
    run_loop(plant, design, q, v, which, duration_s, 1.0)
}

/// The loop of [`run_with`] and [`run_mixed`]: plant `plant.g`, PI and RC of
/// `design`, ripple scaled by `ripple_gain`.
fn run_loop(
    plant: &Setup,
    design: &Setup,
    q: &Filter,
    v: Velocity,
    which: Rc,
    duration_s: f64,
    ripple_gain: f64,
) -> (f64, (usize, usize)) {
    let comp = design.l.preview_samples() + q.preview_samples();
    let (j, n_mean, m, mm) = delay_range(plant, v, comp + 1);
    let n_fixed = n_mean.round() as usize;
    let mut g = SsStepper::new(&plant.g).unwrap();
    let mut pi = Pi::new(design.kp, 5.0, DT).unwrap();
    let mut rc = RcUnderTest::new(design, q, which, j, n_fixed, m, mm);
    let steps = (duration_s / DT) as usize;
    let mut alpha = 0.0;
    let mut y = [0.0];
    let mut u = [0.0];
    let mut sq = 0.0;
    let mut cnt = 0usize;
    let mut seen = (usize::MAX, 0usize);
    for k in 0..steps {
        g.output(&[], &mut y);
        let e = v.position(k as f64 * DT) - (y[0] + ripple_gain * ripple(alpha));
        let (nk, w) = rc.output(alpha);
        pi.control(&[e + w], &mut u);
        rc.learn(e);
        g.update(&u);
        alpha += TAU * u[0] * DT;
        if k >= steps * 3 / 4 {
            sq += e * e;
            cnt += 1;
            seen = (seen.0.min(nk), seen.1.max(nk));
        }
    }
    ((sq / cnt as f64).sqrt(), seen)
}

/// The criterion for the DVRC range actually used.
pub fn criterion_text(s: &Setup, q: &Filter, m: usize, mm: usize) -> String {
    rc_criterion(&s.t, &s.l, q, m, mm).unwrap().to_string()
}

/// The repetitive controller of one Table 5.1 run: the memory loop configured for
/// `which`, and the α-based delay estimate used by DVRC. Shared by the linear and
/// nonlinear harnesses so both run exactly the same RC.
pub struct RcUnderTest {
    which: Rc,
    ml: MemoryLoop,
    est: dvrc::AlphaDelay,
    n_fixed: usize,
}

impl RcUnderTest {
    /// `j` periods of α per repetition, fixed delay `n_fixed`, DVRC range [m, mm].
    pub fn new(
        s: &Setup,
        q: &Filter,
        which: Rc,
        j: usize,
        n_fixed: usize,
        m: usize,
        mm: usize,
    ) -> Self {
        let (weights, n_period, lo, hi) = match which {
            Rc::HighOrder => (vec![2.0, -1.0], n_fixed, n_fixed, n_fixed),
            Rc::Dvrc => (vec![1.0], 0, m, mm),
            _ => (vec![1.0], 0, n_fixed, n_fixed),
        };
        let ml = MemoryLoop::new(s.l.clone(), q.clone(), weights, n_period, lo, hi).unwrap();
        let est = dvrc::AlphaDelay::new(j as f64 * TAU, m, mm, n_fixed.clamp(m, mm));
        Self {
            which,
            ml,
            est,
            n_fixed,
        }
    }

    /// Phase 1 of a sample: the delay N_k used and the RC output w_k.
    pub fn output(&mut self, alpha: f64) -> (usize, f64) {
        let nk = match self.which {
            Rc::Dvrc => self.est.next(alpha),
            _ => self.n_fixed,
        };
        let w = if self.which == Rc::None {
            0.0
        } else {
            self.ml.output(nk)
        };
        (nk, w)
    }

    /// Phase 2: learn from the error of the same sample.
    pub fn learn(&mut self, e: f64) {
        if self.which != Rc::None {
            self.ml.update(e);
        }
    }
}
