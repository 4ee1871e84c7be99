//! Table 5.1-style experiment on the *linear* fitted stage (5.31) with a ripple
//! periodic in the leg angle (Fig. 5.6(b)): x_s = G(z) f_α + d(α), α = 2π ∫ f_α dt.
//! Run by the dvrc plugin's `tests/table_5_1.rs` and `examples/table_5_1.rs`, and by
//! `nanomotion reproduce table_5_1`.

use dvrc::filters::Filter;
use dvrc::rc::MemoryLoop;
use dvrc::stability::{design_q_cutoff, rc_criterion};
use nanomotion_core::blocks::control::Pi;
use nanomotion_core::lti::{SsStepper, StateSpace, feedback, series, zpetc_ss};
use nanomotion_core::{Controller, LearningFilter};
use std::f64::consts::TAU;
use walking_piezo::FittedStageParams;

pub const DT: f64 = 1.0 / 4000.0;

/// The former output ripple d(α) (m): harmonics 1, 2 and 4 of the leg angle, added
/// to the position. The 50 Hz PI already removes it at low speed (0.066 nm left at
/// 10 µm/s), so it is kept only as [`Disturbance::Ripple`] for comparison.
pub fn ripple(alpha: f64) -> f64 {
    5e-9 * alpha.sin() + 2e-9 * (2.0 * alpha + 0.7).sin() + 1e-9 * (4.0 * alpha + 1.3).sin()
}

/// Depth of the take-over velocity dip (fraction of the drive velocity lost at the
/// centre of a take-over).
pub const DIP_DEPTH: f64 = 0.5;
/// Half-width of a dip in leg angle (rad): a take-over lasts 2·π/8 of a cycle.
pub const DIP_HALF_WIDTH_RAD: f64 = std::f64::consts::PI / 8.0;

/// The α-periodic velocity dip δ(α) ∈ [0, DIP_DEPTH]: at each of the two take-overs
/// per cycle (α ≡ 0 and π mod 2π, the pairs alternate) the stage moves slower,
/// raised-cosine shaped over ±[`DIP_HALF_WIDTH_RAD`]. The plant sees f_α(1 − δ(α))
/// while α advances with f_α: an input disturbance periodic in α whose position
/// error is not removed by the PI as the output ripple is (our choice of shape and
/// depth: the thesis gives no g_nlin).
pub fn velocity_dip(alpha: f64) -> f64 {
    let phase = alpha.rem_euclid(std::f64::consts::PI);
    let d = phase.min(std::f64::consts::PI - phase); // distance to the nearest take-over
    if d >= DIP_HALF_WIDTH_RAD {
        0.0
    } else {
        DIP_DEPTH * 0.5 * (1.0 + (std::f64::consts::PI * d / DIP_HALF_WIDTH_RAD).cos())
    }
}

/// The disturbance periodic in α of a Table 5.1 run on the linear stage.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Disturbance {
    /// The take-over velocity dip [`velocity_dip`] (default).
    VelocityDip,
    /// The output ripple [`ripple`] of the previous revision.
    Ripple,
}

/// Which controller adds to the PI loop.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Rc {
    None,
    Standard,
    HighOrder,
    Dvrc,
}

#[derive(Debug, Clone)]
pub struct Setup {
    pub g: StateSpace,
    pub kp: f64,
    pub t: StateSpace,
    pub l: Filter,
    pub c_m_per_cycle: f64,
}

/// The real stage's step per α cycle in Ch. 5 (m): Sec. 5.5.2 finds the error's
/// base frequency at 10 µm/s to be 1.98 Hz, so the stage walked
/// 10 µm/s / 1.98 Hz = 5.05 µm per cycle (issue 18 item 2; docs/walking-piezo.md,
/// "Step per drive cycle").
pub const CH5_STEP_M: f64 = 1e-5 / 1.98;

/// The nominal design: (5.31) with its default gain (Ch. 2's c = 7.91 µm per
/// cycle, (5.31)'s own c is lost) and 3 samples of delay.
pub fn setup() -> Setup {
    setup_with_c(FittedStageParams::default().gain_m_per_cycle)
}

/// (5.31) with the step per cycle `c` (m), its PI (50 Hz), T and L = ZPETC of T.
pub fn setup_with_c(c: f64) -> Setup {
    let p = FittedStageParams {
        gain_m_per_cycle: c,
        ..FittedStageParams::default()
    };
    let g = p.discrete(DT).unwrap();
    let kp = TAU * 50.0 / p.gain_m_per_cycle;
    let k = Pi::new(kp, 5.0, DT).unwrap().as_pid().state_space();
    let one = StateSpace::gain(
        nanomotion_core::nalgebra::DMatrix::from_element(1, 1, 1.0),
        Some(DT),
    );
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
    delay_range_for(s.c_m_per_cycle, v, n_needed)
}

/// Mean of [`velocity_dip`] over a cycle: DIP_DEPTH·w/π (a raised cosine of
/// half-width w per half cycle).
pub fn dip_mean() -> f64 {
    DIP_DEPTH * DIP_HALF_WIDTH_RAD / std::f64::consts::PI
}

/// [`delay_range`] for the loop with the velocity dip: the stage walks
/// c·(1 − mean δ) per α cycle, so the loop drives f_α faster and N is shorter.
pub fn delay_range_dip(s: &Setup, v: Velocity, n_needed: usize) -> (usize, f64, usize, usize) {
    delay_range_for(s.c_m_per_cycle * (1.0 - dip_mean()), v, n_needed)
}

fn delay_range_for(c: f64, v: Velocity, n_needed: usize) -> (usize, f64, usize, usize) {
    let (vmin, vmax) = v.range();
    let n_of = |vel: f64| c / vel / DT; // samples per α period
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
    run_loop(
        s,
        s,
        q,
        v,
        which,
        duration_s,
        ripple_gain,
        Disturbance::VelocityDip,
    )
    .summary()
}

/// [`run_with`] with the disturbance `dist`, returning the whole record.
#[allow(clippy::too_many_arguments)]
pub fn run_record(
    s: &Setup,
    q: &Filter,
    v: Velocity,
    which: Rc,
    duration_s: f64,
    gain: f64,
    dist: Disturbance,
) -> RunRecord {
    run_loop(s, s, q, v, which, duration_s, gain, dist)
}

/// The last quarter of a run: errors e_k (m), leg angles α_k (rad) and the delays
/// N_k used.
#[derive(Debug, Clone, Default)]
pub struct RunRecord {
    pub e: Vec<f64>,
    pub alpha: Vec<f64>,
    pub n: Vec<usize>,
}

impl RunRecord {
    /// rms of e.
    pub fn rms(&self) -> f64 {
        (self.e.iter().map(|e| e * e).sum::<f64>() / self.e.len().max(1) as f64).sqrt()
    }
    /// (rms, (min N_k, max N_k)).
    pub fn summary(&self) -> (f64, (usize, usize)) {
        let lo = self.n.iter().copied().min().unwrap_or(0);
        let hi = self.n.iter().copied().max().unwrap_or(0);
        (self.rms(), (lo, hi))
    }
    /// Split e into its α-periodic part (the α-synchronous average over `bins`
    /// bins of α mod 2π) and the rest: (rms e, rms periodic, rms rest).
    pub fn periodic_split(&self, bins: usize) -> (f64, f64, f64) {
        alpha_periodic_split(&self.e, &self.alpha, bins)
    }
}

/// Split the rms of `e` into the part periodic in α (the α-synchronous average:
/// mean of e over `bins` bins of α mod 2π, the content any RC in α could remove)
/// and the rest. Returns (total, periodic, rest) rms.
pub fn alpha_periodic_split(e: &[f64], alpha: &[f64], bins: usize) -> (f64, f64, f64) {
    let mut sum = vec![0.0; bins];
    let mut cnt = vec![0usize; bins];
    let bin = |a: f64| (((a.rem_euclid(TAU)) / TAU * bins as f64) as usize).min(bins - 1);
    for (&x, &a) in e.iter().zip(alpha) {
        let b = bin(a);
        sum[b] += x;
        cnt[b] += 1;
    }
    let n = e.len() as f64;
    let total = (e.iter().map(|x| x * x).sum::<f64>() / n).sqrt();
    let periodic = (alpha
        .iter()
        .map(|&a| {
            let b = bin(a);
            let m = sum[b] / cnt[b] as f64;
            m * m
        })
        .sum::<f64>()
        / n)
        .sqrt();
    let rest = (total * total - periodic * periodic).max(0.0).sqrt();
    (total, periodic, rest)
}

/// [`run`] with the plant of `plant` (its `g`; N from its `c_m_per_cycle`) and
/// the PI, L of `design`: the loop with a model mismatch (output ripple, as in
/// the documented high-order RC divergence experiment).
pub fn run_mixed(
    plant: &Setup,
    design: &Setup,
    q: &Filter,
    v: Velocity,
    which: Rc,
    duration_s: f64,
) -> (f64, (usize, usize)) {
    run_loop(
        plant,
        design,
        q,
        v,
        which,
        duration_s,
        1.0,
        Disturbance::Ripple,
    )
    .summary()
}

/// The loop of [`run_with`] and [`run_mixed`]: plant `plant.g`, PI and RC of
/// `design`, disturbance `dist` scaled by `gain`.
#[allow(clippy::too_many_arguments)]
fn run_loop(
    plant: &Setup,
    design: &Setup,
    q: &Filter,
    v: Velocity,
    which: Rc,
    duration_s: f64,
    gain: f64,
    dist: Disturbance,
) -> RunRecord {
    let comp = design.l.preview_samples() + q.preview_samples();
    let (j, n_mean, m, mm) = match dist {
        Disturbance::Ripple => delay_range(plant, v, comp + 1),
        Disturbance::VelocityDip => delay_range_dip(plant, v, comp + 1),
    };
    let n_fixed = n_mean.round() as usize;
    let mut g = SsStepper::new(&plant.g).unwrap();
    let mut pi = Pi::new(design.kp, 5.0, DT).unwrap();
    let mut rc = RcUnderTest::new(design, q, which, j, n_fixed, m, mm);
    let steps = (duration_s / DT) as usize;
    let mut alpha = 0.0;
    let mut y = [0.0];
    let mut u = [0.0];
    let mut rec = RunRecord::default();
    for k in 0..steps {
        g.output(&[], &mut y);
        let d_out = match dist {
            Disturbance::Ripple => gain * ripple(alpha),
            Disturbance::VelocityDip => 0.0,
        };
        let e = v.position(k as f64 * DT) - (y[0] + d_out);
        let (nk, w) = rc.output(alpha);
        pi.control(&[e + w], &mut u);
        rc.learn(e);
        // The stage advances with f_α(1 − δ(α)); α with f_α.
        let u_plant = match dist {
            Disturbance::Ripple => u[0],
            Disturbance::VelocityDip => u[0] * (1.0 - gain * velocity_dip(alpha)),
        };
        g.update(&[u_plant]);
        if k >= steps * 3 / 4 {
            rec.e.push(e);
            rec.alpha.push(alpha);
            rec.n.push(nk);
        }
        alpha += TAU * u[0] * DT;
    }
    rec
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

/// One reference of the linear Table 5.1.
#[derive(Debug, Clone)]
pub struct LinearRow {
    /// e.g. "10 µm/s".
    pub name: &'static str,
    /// The reference velocity.
    pub velocity: Velocity,
    /// Run length (s).
    pub duration_s: f64,
    /// DVRC's window [m, M] (samples).
    pub m: usize,
    /// Upper end of the window.
    pub mm: usize,
    /// rms error over the last quarter (m), no RC and no disturbance (the
    /// reference-induced floor).
    pub floor: f64,
    /// rms error (m) for none, RC, high-order RC, DVRC.
    pub rms: [f64; 4],
    /// (total, α-periodic, rest) rms (m) for none, RC, high-order RC, DVRC.
    pub split: [(f64, f64, f64); 4],
    /// Smallest and largest N_k DVRC used.
    pub dvrc_n: (usize, usize),
}

/// The linear Table 5.1 (velocity dip).
#[derive(Debug, Clone)]
pub struct LinearTable {
    /// Q cut-off (Hz) and the spread M − m it was designed for.
    pub q_cutoff_hz: f64,
    /// Largest M − m over the references.
    pub spread: usize,
    /// One row per reference.
    pub rows: Vec<LinearRow>,
    /// 10 µm/s with the former output ripple instead of the dip: none, RC,
    /// high-order RC, DVRC rms (m).
    pub ripple_10um: [f64; 4],
    /// (5.9) on the worst spread, as text.
    pub criterion: String,
    /// High-order RC on the sinusoidal velocity for growing run lengths:
    /// (run length (s), rms over its last 10 s = one velocity period (m)) —
    /// whether its error grows without bound (full mode only).
    pub high_order_growth: Vec<(f64, f64)>,
    /// The same for no RC (the reference).
    pub none_growth: Vec<(f64, f64)>,
}

/// The references of the table and their run lengths (s); `quick` quarters them.
pub fn linear_profiles(quick: bool) -> Vec<(&'static str, Velocity, f64)> {
    let k = if quick { 0.25 } else { 1.0 };
    vec![
        ("1 µm/s", Velocity::Constant(1e-6), 120.0 * k),
        ("10 µm/s", Velocity::Constant(1e-5), 40.0 * k),
        ("0.1 mm/s", Velocity::Constant(1e-4), 20.0 * k),
        ("1 mm/s", Velocity::Constant(1e-3), 20.0 * k),
        (
            "10 µm/s·(1 + 0.5 sin 0.2πt)",
            Velocity::Sinusoidal {
                v0: 1e-5,
                a: 0.5,
                f_hz: 0.1,
            },
            80.0 * k,
        ),
    ]
}

/// The linear Table 5.1: every reference of [`linear_profiles`] with the velocity
/// dip, none / RC / high-order RC / DVRC, one Q designed for the largest spread.
pub fn linear_table(quick: bool) -> LinearTable {
    // The plant walks the thesis's Ch. 5 step per cycle.
    let s = setup_with_c(CH5_STEP_M);
    let profiles = linear_profiles(quick);
    // q + l + 1 = 56 samples minimum delay.
    let comp = 56;
    let spread = profiles
        .iter()
        .map(|(_, v, _)| {
            let (_, _, m, mm) = delay_range_dip(&s, *v, comp);
            mm - m
        })
        .max()
        .unwrap_or(0);
    let (q, fc) = q_for(&s, spread);
    let which = [Rc::None, Rc::Standard, Rc::HighOrder, Rc::Dvrc];
    let rows = profiles
        .iter()
        .map(|&(name, v, dur)| {
            let (_, _, m, mm) = delay_range_dip(&s, v, comp);
            let floor = run_with(&s, &q, v, Rc::None, dur, 0.0).0;
            let recs: Vec<RunRecord> = which
                .iter()
                .map(|&w| run_record(&s, &q, v, w, dur, 1.0, Disturbance::VelocityDip))
                .collect();
            LinearRow {
                name,
                velocity: v,
                duration_s: dur,
                m,
                mm,
                floor,
                rms: [0, 1, 2, 3].map(|i| recs[i].rms()),
                split: [0, 1, 2, 3].map(|i| recs[i].periodic_split(256)),
                dvrc_n: recs[3].summary().1,
            }
        })
        .collect();
    let dur10 = if quick { 10.0 } else { 40.0 };
    let ripple_10um = which.map(|w| {
        run_record(
            &s,
            &q,
            Velocity::Constant(1e-5),
            w,
            dur10,
            1.0,
            Disturbance::Ripple,
        )
        .rms()
    });
    let sinus = Velocity::Sinusoidal {
        v0: 1e-5,
        a: 0.5,
        f_hz: 0.1,
    };
    let growth = |w: Rc| -> Vec<(f64, f64)> {
        if quick {
            return Vec::new();
        }
        [40.0, 80.0, 160.0, 320.0]
            .map(|dur| {
                let r = run_record(&s, &q, sinus, w, dur, 1.0, Disturbance::VelocityDip);
                let last = &r.e[r.e.len() - (10.0 / DT) as usize..];
                let rms = (last.iter().map(|e| e * e).sum::<f64>() / last.len() as f64).sqrt();
                (dur, rms)
            })
            .to_vec()
    };
    LinearTable {
        q_cutoff_hz: fc,
        spread,
        rows,
        ripple_10um,
        criterion: criterion_text(&s, &q, comp, comp + spread),
        high_order_growth: growth(Rc::HighOrder),
        none_growth: growth(Rc::None),
    }
}
