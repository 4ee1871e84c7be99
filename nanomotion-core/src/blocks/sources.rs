//! Signal sources: references, disturbances and noise. All implement
//! [`Source`] (a function of time, or a seeded random stream) and have no inputs;
//! each block plays its `Source` (`#[declared_block]` writes its `output`).
//!
//! | type | outputs | what |
//! |---|---|---|
//! | `constant` | `y[width]` | a constant |
//! | `step` | `y` | `initial` before `time_s`, `final` from then on |
//! | `constant_velocity` | `y`, `v` | ramp from `initial_m` at `start_s` with `velocity_m_s` |
//! | `sinusoid` | `y` | offset + A sin(2π f t + φ) |
//! | `triangular_scan` | `y` | AFM raster line scan, triangle of amplitude A |
//! | `point_to_point` | `y`, `v`, `a` | smooth move: third-order (jerk-limited), minimum-jerk or cycloidal |
//! | `white_noise` | `y[width]` | seeded Gaussian white noise, by `std` or one-sided `psd` |
//!
//! Times compare with a tolerance of [`TIME_TOL_S`] so that an event at t = k·T
//! happens at sample k even though k·T is rounded.
//!
//! ```
//! use nanomotion_core::Source;
//! use nanomotion_core::blocks::sources::PointToPoint;
//! // 10 µm move, v ≤ 1 mm/s, a ≤ 0.1 m/s², j ≤ 100 m/s³ (third order).
//! let mut p = PointToPoint::third_order(0.0, 10e-6, 1e-3, 0.1, 100.0).unwrap();
//! let mut y = [0.0; 3];
//! p.sample(1.0, &mut y);
//! assert_eq!(y, [10e-6, 0.0, 0.0]);
//! ```

use crate::block::check;
use crate::doc::Params;
use crate::rng::Rng;
use crate::{Block, BuildContext, ParamError, Source, declared_block};
use serde::{Deserialize, Serialize};
use std::f64::consts::{PI, TAU};

/// Tolerance (s) when comparing a sample time with an event time: 1 ps, far below
/// any sample period, far above the rounding of k·T.
pub const TIME_TOL_S: f64 = 1e-12;

fn one() -> usize {
    1
}

fn zero() -> f64 {
    0.0
}

// ---------------------------------------------------------------------------------
// constant
// ---------------------------------------------------------------------------------

/// `constant`: y = value on every channel.
#[derive(Debug, Clone, Serialize, Deserialize, Params)]
#[serde(deny_unknown_fields)]
#[block(type_name = "constant", role = Source, ports = "-> y[width]")]
pub struct Constant {
    /// The value (unit of the signal).
    #[param(finite)]
    pub value: f64,
    /// Output width.
    #[serde(default = "one")]
    #[param(width)]
    pub width: usize,
}

impl Constant {
    /// A scalar constant.
    pub fn new(value: f64) -> Self {
        Self { value, width: 1 }
    }
}

impl Source for Constant {
    fn sample(&mut self, _t: f64, y: &mut [f64]) {
        y.fill(self.value);
    }
}

#[declared_block]
impl Block for Constant {}

// ---------------------------------------------------------------------------------
// step
// ---------------------------------------------------------------------------------

/// `step`: y = `initial` for t < `time_s`, `final` for t ≥ `time_s`.
#[derive(Debug, Clone, Serialize, Deserialize, Params)]
#[serde(deny_unknown_fields)]
#[block(type_name = "step", role = Source, ports = "-> y")]
pub struct Step {
    /// Time of the step (s).
    #[serde(default = "zero")]
    #[param(finite)]
    pub time_s: f64,
    /// Value before the step.
    #[serde(default = "zero")]
    #[param(finite)]
    pub initial: f64,
    /// Value from the step on (YAML `final`).
    #[serde(rename = "final")]
    #[param(finite)]
    pub final_value: f64,
}

impl Step {
    /// A step from `initial` to `final_value` at `time_s`.
    pub fn new(time_s: f64, initial: f64, final_value: f64) -> Self {
        Self {
            time_s,
            initial,
            final_value,
        }
    }
}

impl Source for Step {
    fn sample(&mut self, t: f64, y: &mut [f64]) {
        y[0] = if t >= self.time_s - TIME_TOL_S {
            self.final_value
        } else {
            self.initial
        };
    }
}

#[declared_block]
impl Block for Step {}

// ---------------------------------------------------------------------------------
// constant_velocity
// ---------------------------------------------------------------------------------

/// `constant_velocity`: a ramp r(t) = initial_m + velocity_m_s·max(0, t − start_s),
/// the constant-velocity reference of Ch. 2 and 5 (e.g. 10 µm/s). Outputs position
/// `y` (m) and velocity `v` (m/s), e.g. for the amplitude/phase feed-forward
/// (2.11)–(2.12) that needs ṙ.
#[derive(Debug, Clone, Serialize, Deserialize, Params)]
#[serde(deny_unknown_fields)]
#[block(type_name = "constant_velocity", role = Source, ports = "-> y (m), v (m/s)")]
pub struct ConstantVelocity {
    /// Velocity ṙ after the start (m/s).
    #[param(finite)]
    pub velocity_m_s: f64,
    /// Time at which the motion starts (s).
    #[serde(default = "zero")]
    #[param(finite)]
    pub start_s: f64,
    /// Position before the start (m).
    #[serde(default = "zero")]
    #[param(finite)]
    pub initial_m: f64,
}

impl ConstantVelocity {
    /// A ramp with `velocity_m_s` starting at t = 0 from 0.
    pub fn new(velocity_m_s: f64) -> Self {
        Self {
            velocity_m_s,
            start_s: 0.0,
            initial_m: 0.0,
        }
    }
}

impl Source for ConstantVelocity {
    /// y = [r(t), ṙ(t)].
    fn sample(&mut self, t: f64, y: &mut [f64]) {
        let tau = t - self.start_s;
        if tau > 0.0 {
            y[0] = self.initial_m + self.velocity_m_s * tau;
            y[1] = self.velocity_m_s;
        } else {
            y[0] = self.initial_m;
            y[1] = if tau > -TIME_TOL_S {
                self.velocity_m_s
            } else {
                0.0
            };
        }
    }
}

#[declared_block]
impl Block for ConstantVelocity {}

// ---------------------------------------------------------------------------------
// sinusoid
// ---------------------------------------------------------------------------------

/// `sinusoid`: y = offset + amplitude·sin(2π·frequency_hz·t + phase_rad).
#[derive(Debug, Clone, Serialize, Deserialize, Params)]
#[serde(deny_unknown_fields)]
#[block(type_name = "sinusoid", role = Source, ports = "-> y")]
pub struct Sinusoid {
    /// Amplitude (unit of the signal).
    #[param(non_negative)]
    pub amplitude: f64,
    /// Frequency f (Hz).
    #[param(non_negative)]
    pub frequency_hz: f64,
    /// Phase φ at t = 0 (rad).
    #[serde(default = "zero")]
    #[param(finite)]
    pub phase_rad: f64,
    /// Offset added (unit of the signal).
    #[serde(default = "zero")]
    #[param(finite)]
    pub offset: f64,
}

impl Sinusoid {
    /// A sine of `amplitude` and `frequency_hz`, zero phase and offset.
    pub fn new(amplitude: f64, frequency_hz: f64) -> Self {
        Self {
            amplitude,
            frequency_hz,
            phase_rad: 0.0,
            offset: 0.0,
        }
    }
}

impl Source for Sinusoid {
    fn sample(&mut self, t: f64, y: &mut [f64]) {
        y[0] = self.offset + self.amplitude * (TAU * self.frequency_hz * t + self.phase_rad).sin();
    }
}

#[declared_block]
impl Block for Sinusoid {}

// ---------------------------------------------------------------------------------
// triangular_scan
// ---------------------------------------------------------------------------------

/// `triangular_scan`: the triangular set-point of the fast axis of an AFM raster
/// line scan (Ch. 6–7): trace and retrace at constant speed 4·A·f between
/// offset − A and offset + A.
///
/// With p = frac(f·t): y = offset + A·4p for p < ¼, A·(2 − 4p) for ¼ ≤ p < ¾,
/// A·(4p − 4) after — zero at t = 0 rising, +A at T/4, zero at T/2, −A at 3T/4
/// (T = 1/f), like a sine of the same frequency.
#[derive(Debug, Clone, Serialize, Deserialize, Params)]
#[serde(deny_unknown_fields)]
#[block(type_name = "triangular_scan", role = Source, ports = "-> y (m)")]
pub struct TriangularScan {
    /// Amplitude A (m): the scan covers [offset − A, offset + A], a line of 2A.
    #[param(non_negative)]
    pub amplitude: f64,
    /// Line frequency f (Hz): one trace and one retrace per period.
    #[param(non_negative)]
    pub frequency_hz: f64,
    /// Centre of the scan (m).
    #[serde(default = "zero")]
    #[param(finite)]
    pub offset: f64,
}

impl TriangularScan {
    /// A scan of `amplitude` (m) at `frequency_hz` around 0.
    pub fn new(amplitude: f64, frequency_hz: f64) -> Self {
        Self {
            amplitude,
            frequency_hz,
            offset: 0.0,
        }
    }
}

impl Source for TriangularScan {
    fn sample(&mut self, t: f64, y: &mut [f64]) {
        let x = self.frequency_hz * t;
        let p = x - x.floor();
        let shape = if p < 0.25 {
            4.0 * p
        } else if p < 0.75 {
            2.0 - 4.0 * p
        } else {
            4.0 * p - 4.0
        };
        y[0] = self.offset + self.amplitude * shape;
    }
}

#[declared_block]
impl Block for TriangularScan {}

// ---------------------------------------------------------------------------------
// point_to_point
// ---------------------------------------------------------------------------------

/// Shape of a [`PointToPoint`] move.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, Params)]
#[serde(rename_all = "snake_case")]
pub enum P2pProfile {
    /// Third-order (jerk-limited, "S-curve") profile: up to seven phases of
    /// constant jerk ±j_max / 0, the fastest move under |v| ≤ v_max, |a| ≤ a_max,
    /// |j| ≤ j_max (Lambrechts, Boerlage & Steinbuch, *Control Eng. Practice*
    /// 13(2), 2005). Needs `j_max_m_s3`; `v_max_m_s`, `a_max_m_s2` optional.
    ThirdOrder,
    /// Minimum-jerk quintic x = x₀ + D(10s³ − 15s⁴ + 6s⁵), s = τ/T: zero velocity
    /// and acceleration at both ends.
    MinimumJerk,
    /// Cycloidal x = x₀ + D(s − sin(2πs)/(2π)): zero velocity and acceleration at
    /// both ends, sinusoidal acceleration.
    Cycloidal,
}

fn third_order() -> P2pProfile {
    P2pProfile::ThirdOrder
}

/// One phase of constant jerk: starts at `t0` (relative to the move start) in
/// state (x, v, a).
#[derive(Debug, Clone, Copy, Default, PartialEq)]
struct JerkPhase {
    t0: f64,
    x: f64,
    v: f64,
    a: f64,
    j: f64,
}

/// The planned move, derived in `build` (or by the constructors).
#[derive(Debug, Clone, Copy, Default, PartialEq)]
struct Plan {
    /// Move duration (s).
    t_end: f64,
    /// Third order: the seven phases (for D ≥ 0; `sign` flips them).
    phases: [JerkPhase; 7],
    /// +1 or −1: direction of the move.
    sign: f64,
}

/// `point_to_point`: a smooth move from `start_m` to `target_m` beginning at
/// `begin_s`. Outputs position `y` (m), velocity `v` (m/s) and acceleration
/// `a` (m/s²), all exactly consistent (v and a are the analytic derivatives of y).
/// Before `begin_s` it holds `start_m`; after the move it outputs `target_m`
/// exactly.
///
/// - `third_order`: fastest jerk-limited move under the given limits;
/// - `minimum_jerk`, `cycloidal`: over `duration_s` if given, otherwise over the
///   shortest duration that respects every given limit (peaks: minimum jerk
///   v = 1.875 D/T, a = 5.774 D/T², j = 60 D/T³; cycloidal v = 2 D/T,
///   a = 2π D/T², j = 4π² D/T³).
#[derive(Debug, Clone, Serialize, Deserialize, Params)]
#[serde(deny_unknown_fields)]
#[block(type_name = "point_to_point", role = Source, ports = "-> y (m), v (m/s), a (m/s²)")]
pub struct PointToPoint {
    /// Start position (m).
    #[serde(default = "zero")]
    #[param(finite)]
    pub start_m: f64,
    /// Target position (m).
    #[param(finite)]
    pub target_m: f64,
    /// Time at which the move begins (s).
    #[serde(default = "zero")]
    #[param(finite)]
    pub begin_s: f64,
    /// Profile shape.
    #[serde(default = "third_order")]
    pub profile: P2pProfile,
    /// Duration of a `minimum_jerk` or `cycloidal` move (s); `minimum_jerk`/`cycloidal`
    /// only.
    #[serde(default)]
    pub duration_s: Option<f64>,
    /// Velocity limit (m/s).
    #[serde(default)]
    pub v_max_m_s: Option<f64>,
    /// Acceleration limit (m/s²).
    #[serde(default)]
    pub a_max_m_s2: Option<f64>,
    /// Jerk limit (m/s³); required for `third_order`.
    #[serde(default)]
    pub j_max_m_s3: Option<f64>,
    #[serde(skip)]
    plan: Plan,
}

impl PointToPoint {
    fn unplanned(start_m: f64, target_m: f64, profile: P2pProfile) -> Self {
        Self {
            start_m,
            target_m,
            begin_s: 0.0,
            profile,
            duration_s: None,
            v_max_m_s: None,
            a_max_m_s2: None,
            j_max_m_s3: None,
            plan: Plan::default(),
        }
    }

    /// The fastest jerk-limited move from `start_m` to `target_m` at t = 0 (use
    /// `f64::INFINITY` for an absent velocity or acceleration limit).
    pub fn third_order(
        start_m: f64,
        target_m: f64,
        v_max_m_s: f64,
        a_max_m_s2: f64,
        j_max_m_s3: f64,
    ) -> Result<Self, ParamError> {
        let mut p = Self::unplanned(start_m, target_m, P2pProfile::ThirdOrder);
        p.v_max_m_s = v_max_m_s.is_finite().then_some(v_max_m_s);
        p.a_max_m_s2 = a_max_m_s2.is_finite().then_some(a_max_m_s2);
        p.j_max_m_s3 = Some(j_max_m_s3);
        p.plan()?;
        Ok(p)
    }

    /// A `minimum_jerk` or `cycloidal` move over `duration_s` starting at t = 0.
    pub fn timed(
        profile: P2pProfile,
        start_m: f64,
        target_m: f64,
        duration_s: f64,
    ) -> Result<Self, ParamError> {
        let mut p = Self::unplanned(start_m, target_m, profile);
        p.duration_s = Some(duration_s);
        p.plan()?;
        Ok(p)
    }

    /// Duration of the move (s), valid once planned.
    pub fn duration(&self) -> f64 {
        self.plan.t_end
    }

    /// Validate the parameters and plan the move.
    fn plan(&mut self) -> Result<(), ParamError> {
        self.check_params()?;
        for (field, v) in [
            ("duration_s", self.duration_s),
            ("v_max_m_s", self.v_max_m_s),
            ("a_max_m_s2", self.a_max_m_s2),
            ("j_max_m_s3", self.j_max_m_s3),
        ] {
            if let Some(v) = v {
                check::positive(field, v)?;
            }
        }
        let d = self.target_m - self.start_m;
        let dist = d.abs();
        let inf = f64::INFINITY;
        let (vm, am) = (
            self.v_max_m_s.unwrap_or(inf),
            self.a_max_m_s2.unwrap_or(inf),
        );
        let mut plan = Plan {
            sign: if d < 0.0 { -1.0 } else { 1.0 },
            ..Plan::default()
        };
        match self.profile {
            P2pProfile::ThirdOrder => {
                if self.duration_s.is_some() {
                    return Err(ParamError::new(
                        "duration_s",
                        "is given for a third_order profile, whose duration follows from the limits",
                        "remove duration_s, or use profile: minimum_jerk or cycloidal",
                    ));
                }
                let Some(jm) = self.j_max_m_s3 else {
                    return Err(ParamError::new(
                        "j_max_m_s3",
                        "is missing; a third_order profile needs a jerk limit",
                        "give j_max_m_s3 (and optionally v_max_m_s, a_max_m_s2)",
                    ));
                };
                plan_third_order(&mut plan, dist, vm, am, jm);
            }
            P2pProfile::MinimumJerk | P2pProfile::Cycloidal => {
                // Peak |v|, |a|, |j| per unit distance for T = 1.
                let (cv, ca, cj) = match self.profile {
                    P2pProfile::MinimumJerk => (1.875, 10.0 / 3f64.sqrt(), 60.0),
                    _ => (2.0, TAU, 4.0 * PI * PI),
                };
                let limited = [self.v_max_m_s, self.a_max_m_s2, self.j_max_m_s3];
                plan.t_end = match (self.duration_s, limited.iter().any(Option::is_some)) {
                    (Some(t), false) => t,
                    (None, true) => {
                        let jm = self.j_max_m_s3.unwrap_or(inf);
                        (cv * dist / vm)
                            .max((ca * dist / am).sqrt())
                            .max((cj * dist / jm).cbrt())
                    }
                    _ => {
                        return Err(ParamError::new(
                            "duration_s",
                            "a minimum_jerk/cycloidal move needs either duration_s or limits, not both",
                            "give duration_s alone, or v_max_m_s / a_max_m_s2 / j_max_m_s3 alone",
                        ));
                    }
                };
            }
        }
        self.plan = plan;
        Ok(())
    }

    /// Position, velocity, acceleration and jerk at time `t` (s).
    pub fn evaluate(&self, t: f64) -> [f64; 4] {
        let tau = t - self.begin_s;
        let p = &self.plan;
        let d = self.target_m - self.start_m;
        if tau <= 0.0 || p.t_end <= 0.0 {
            return [
                if tau <= 0.0 {
                    self.start_m
                } else {
                    self.target_m
                },
                0.0,
                0.0,
                0.0,
            ];
        }
        if tau >= p.t_end {
            return [self.target_m, 0.0, 0.0, 0.0];
        }
        let big_t = p.t_end;
        let s = tau / big_t;
        let (x, v, a, j) = match self.profile {
            P2pProfile::ThirdOrder => {
                let ph = p
                    .phases
                    .iter()
                    .rev()
                    .find(|ph| tau >= ph.t0)
                    .unwrap_or(&p.phases[0]);
                let h = tau - ph.t0;
                let x = ph.x + h * (ph.v + h * (ph.a / 2.0 + h * ph.j / 6.0));
                let v = ph.v + h * (ph.a + h * ph.j / 2.0);
                let a = ph.a + h * ph.j;
                let sg = p.sign;
                (sg * x, sg * v, sg * a, sg * ph.j)
            }
            P2pProfile::MinimumJerk => {
                let s2 = s * s;
                (
                    d * s2 * s * (10.0 - 15.0 * s + 6.0 * s2),
                    d / big_t * 30.0 * s2 * (1.0 - s) * (1.0 - s),
                    d / (big_t * big_t) * 60.0 * s * (1.0 - s) * (1.0 - 2.0 * s),
                    d / (big_t * big_t * big_t) * 60.0 * (1.0 - 6.0 * s + 6.0 * s2),
                )
            }
            P2pProfile::Cycloidal => {
                let (sn, cs) = (TAU * s).sin_cos();
                (
                    d * (s - sn / TAU),
                    d / big_t * (1.0 - cs),
                    d / (big_t * big_t) * TAU * sn,
                    d / (big_t * big_t * big_t) * TAU * TAU * cs,
                )
            }
        };
        [self.start_m + x, v, a, j]
    }
}

/// Plan the fastest symmetric jerk-limited move over `dist` ≥ 0: phases of
/// durations [t_j, t_a, t_j, t_v, t_j, t_a, t_j] with jerk [j, 0, −j, 0, −j, 0, j].
///
/// t_j = min(∛(D/2j), √(v/j), a/j); the peak acceleration is â = j·t_j;
/// t_a = max(0, min(v/â − t_j, (−3t_j + √(t_j² + 4D/â))/2)); the peak velocity
/// is v̂ = â(t_j + t_a) and t_v = D/v̂ − (2t_j + t_a).
fn plan_third_order(plan: &mut Plan, dist: f64, vm: f64, am: f64, jm: f64) {
    if dist == 0.0 {
        plan.t_end = 0.0;
        return;
    }
    let tj = (dist / (2.0 * jm))
        .cbrt()
        .min((vm / jm).sqrt())
        .min(am / jm);
    let a_pk = jm * tj;
    let ta = (vm / a_pk - tj)
        .min((-3.0 * tj + (tj * tj + 4.0 * dist / a_pk).sqrt()) / 2.0)
        .max(0.0);
    let v_pk = a_pk * (tj + ta);
    let tv = (dist / v_pk - (2.0 * tj + ta)).max(0.0);
    let durations = [tj, ta, tj, tv, tj, ta, tj];
    let jerks = [jm, 0.0, -jm, 0.0, -jm, 0.0, jm];
    let (mut t, mut x, mut v, mut a) = (0.0, 0.0, 0.0, 0.0);
    for i in 0..7 {
        let (h, j) = (durations[i], jerks[i]);
        plan.phases[i] = JerkPhase { t0: t, x, v, a, j };
        x += h * (v + h * (a / 2.0 + h * j / 6.0));
        v += h * (a + h * j / 2.0);
        a += h * j;
        t += h;
    }
    plan.t_end = t;
}

impl Source for PointToPoint {
    /// y = [position, velocity, acceleration].
    fn sample(&mut self, t: f64, y: &mut [f64]) {
        let e = self.evaluate(t);
        y[..3].copy_from_slice(&e[..3]);
    }
}

#[declared_block]
impl Block for PointToPoint {
    fn build(&mut self, _ctx: &BuildContext) -> Result<(), ParamError> {
        self.plan()
    }
}

// ---------------------------------------------------------------------------------
// white_noise
// ---------------------------------------------------------------------------------

fn placeholder_rng() -> Rng {
    Rng::new(0)
}

/// `white_noise`: independent Gaussian samples N(mean, σ²) on each of `width`
/// channels, from the block's seeded stream ([`BuildContext::seed`]): the same seed
/// gives the same bits, after every rebuild.
///
/// Give either `std` (σ per sample) or `psd`, the **one-sided** power spectral
/// density S (unit²/Hz) of the sampled noise, flat from 0 to the Nyquist frequency:
/// σ = √(S·f_s/2), so that ∫₀^{f_s/2} S df = σ² (the end value of the cumulative
/// PSD is the variance).
#[derive(Debug, Clone, Serialize, Deserialize, Params)]
#[serde(deny_unknown_fields)]
#[block(type_name = "white_noise", role = Source, ports = "-> y[width]")]
pub struct WhiteNoise {
    /// Standard deviation σ per sample (unit of the signal).
    #[serde(default)]
    pub std: Option<f64>,
    /// One-sided PSD S (unit²/Hz), alternative to `std`: σ = √(S·f_s/2).
    #[serde(default)]
    pub psd: Option<f64>,
    /// Mean (unit of the signal).
    #[serde(default = "zero")]
    #[param(finite)]
    pub mean: f64,
    /// Number of independent channels.
    #[serde(default = "one")]
    #[param(width)]
    pub width: usize,
    #[serde(skip)]
    sigma: f64,
    #[serde(skip, default = "placeholder_rng")]
    rng: Rng,
}

impl WhiteNoise {
    /// Noise of standard deviation `std` on `width` channels, seeded with `seed`
    /// (ready to use without [`Block::build`]).
    pub fn with_std(std: f64, width: usize, seed: u64) -> Self {
        Self {
            std: Some(std),
            psd: None,
            mean: 0.0,
            width,
            sigma: std,
            rng: Rng::new(seed),
        }
    }

    /// The σ that `std` or `psd` gives at sample period `dt` (s).
    fn sigma_for(&self, dt: f64) -> Result<f64, ParamError> {
        match (self.std, self.psd) {
            (Some(s), None) => check::non_negative("std", s).map(|_| s),
            (None, Some(p)) => {
                check::non_negative("psd", p)?;
                Ok((p / (2.0 * dt)).sqrt())
            }
            (Some(_), Some(_)) => Err(ParamError::new(
                "psd",
                "is given together with std",
                "give std or psd, not both",
            )),
            (None, None) => Err(ParamError::new(
                "std",
                "is missing",
                "give std (per sample) or psd (unit²/Hz)",
            )),
        }
    }
}

impl Source for WhiteNoise {
    fn sample(&mut self, _t: f64, y: &mut [f64]) {
        for yi in y.iter_mut() {
            *yi = self.mean + self.sigma * self.rng.normal();
        }
    }
}

#[declared_block]
impl Block for WhiteNoise {
    fn build(&mut self, ctx: &BuildContext) -> Result<(), ParamError> {
        self.check_params()?;
        self.sigma = self.sigma_for(ctx.dt)?;
        self.rng = Rng::new(ctx.seed);
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::Tick;

    const DT: f64 = 1e-4;

    fn built(text: &str, seed: u64) -> Box<dyn Block> {
        let mut b: Box<dyn Block> = crate::yaml::from_str(text, "test").unwrap();
        b.build(&BuildContext::new("src", DT, seed)).unwrap();
        b
    }

    fn run(b: &mut dyn Block, k: u64) -> Vec<f64> {
        let w: usize = b.outputs().iter().map(|p| p.width).sum();
        let mut y = vec![0.0; w];
        b.output(Tick::new(k, DT), &[], &mut y);
        y
    }

    fn build_err(text: &str) -> String {
        let mut b: Box<dyn Block> = crate::yaml::from_str(text, "test").unwrap();
        b.build(&BuildContext::new("src", DT, 0)).unwrap_err().field
    }

    #[test]
    fn constant_and_step_values() {
        let mut c = built("type: constant\nvalue: 2.5\nwidth: 2\n", 0);
        assert_eq!(run(c.as_mut(), 7), vec![2.5, 2.5]);
        // Step at 0.1 s = sample 1000 exactly, despite the rounding of 1000·1e-4.
        let mut s = built("type: step\ntime_s: 0.1\ninitial: -1\nfinal: 3\n", 0);
        assert_eq!(run(s.as_mut(), 999), vec![-1.0]);
        assert_eq!(run(s.as_mut(), 1000), vec![3.0]);
        assert_eq!(build_err("type: step\nfinal: .nan\n"), "final");
        assert_eq!(build_err("type: constant\nvalue: .inf\n"), "value");
    }

    #[test]
    fn constant_velocity_is_a_ramp_after_start() {
        let mut r = ConstantVelocity {
            velocity_m_s: 10e-6,
            start_s: 0.5,
            initial_m: 1e-6,
        };
        let mut y = [0.0; 2];
        r.sample(0.25, &mut y);
        assert_eq!(y, [1e-6, 0.0]);
        r.sample(1.5, &mut y);
        assert!((y[0] - 11e-6).abs() < 1e-18);
        assert_eq!(y[1], 10e-6);
        assert_eq!(
            build_err("type: constant_velocity\nvelocity_m_s: .nan\n"),
            "velocity_m_s"
        );
    }

    #[test]
    fn sinusoid_closed_form() {
        let mut s = Sinusoid {
            amplitude: 2.0,
            frequency_hz: 5.0,
            phase_rad: PI / 2.0,
            offset: 1.0,
        };
        let mut y = [0.0];
        for t in [0.0, 0.01, 0.05, 0.1, 0.123] {
            s.sample(t, &mut y);
            assert!(
                (y[0] - (1.0 + 2.0 * (TAU * 5.0 * t).cos())).abs() < 1e-12,
                "t = {t}"
            );
        }
        assert_eq!(
            build_err("type: sinusoid\namplitude: -1\nfrequency_hz: 1\n"),
            "amplitude"
        );
        assert_eq!(
            build_err("type: sinusoid\namplitude: 1\nfrequency_hz: -1\n"),
            "frequency_hz"
        );
    }

    #[test]
    fn triangular_scan_peaks_zero_crossings_and_speed() {
        let (a, f) = (50e-6, 2.0); // 100 µm line at 2 Hz: T = 0.5 s
        let mut s = TriangularScan::new(a, f);
        let mut y = [0.0];
        let at = |s: &mut TriangularScan, t: f64| {
            let mut y = [0.0];
            s.sample(t, &mut y);
            y[0]
        };
        for k in 0..6 {
            let t0 = k as f64 * 0.25; // zero crossings every T/2
            assert!(at(&mut s, t0).abs() < 1e-18, "zero at {t0}");
            let peak = if k % 2 == 0 { a } else { -a }; // peaks at T/4 + k·T/2
            assert!(
                (at(&mut s, t0 + 0.125) - peak).abs() < 1e-18,
                "peak at {}",
                t0 + 0.125
            );
        }
        // Constant speed 4·A·f on the trace and the retrace; never beyond ±A.
        let speed = 4.0 * a * f;
        for k in 0..2000 {
            let t = k as f64 * 1e-3;
            s.sample(t, &mut y);
            assert!(y[0].abs() <= a * (1.0 + 1e-12));
            let slope = (at(&mut s, t + 1e-3) - y[0]) / 1e-3;
            // Away from the turning points the slope is ±4Af.
            let p = (f * t).fract();
            if (p - 0.25).abs() > 0.003 && (p - 0.75).abs() > 0.003 {
                assert!(
                    (slope.abs() - speed).abs() < 1e-9 * speed,
                    "t = {t}: slope {slope}"
                );
            }
        }
    }

    /// Checks a planned move: limits respected, v = dx/dt and a = dv/dt (central
    /// differences, tolerances relative to the move's own peaks), exact arrival.
    fn assert_profile_consistent(p: &PointToPoint, limits: [f64; 3]) {
        let (t0, t_end) = (p.begin_s, p.begin_s + p.duration());
        let n = 4000;
        let grid: Vec<f64> = (0..=n)
            .map(|i| t0 + p.duration() * i as f64 / n as f64)
            .collect();
        let peak = |k: usize| {
            grid.iter()
                .map(|&t| p.evaluate(t)[k].abs())
                .fold(0.0, f64::max)
        };
        let (v_pk, a_pk, j_pk) = (peak(1), peak(2), peak(3));
        assert!(v_pk > 0.0 && a_pk > 0.0 && j_pk > 0.0);
        assert!(
            v_pk <= limits[0] * (1.0 + 1e-9),
            "peak v {v_pk} > {}",
            limits[0]
        );
        assert!(
            a_pk <= limits[1] * (1.0 + 1e-9),
            "peak a {a_pk} > {}",
            limits[1]
        );
        assert!(
            j_pk <= limits[2] * (1.0 + 1e-9),
            "peak j {j_pk} > {}",
            limits[2]
        );
        let h = p.duration() * 1e-5;
        for &t in &grid {
            if t - h <= t0 || t + h >= t_end {
                continue;
            }
            let [_, v, a, _] = p.evaluate(t);
            let [xm, vm, am, _] = p.evaluate(t - h);
            let [xp, vp, ap, _] = p.evaluate(t + h);
            // Central differences are exact to O(h²) where jerk is constant and
            // O(h·Δj) across a jerk switch.
            assert!(
                ((xp - xm) / (2.0 * h) - v).abs() < 1e-6 * v_pk,
                "dx/dt at t = {t}"
            );
            assert!(
                ((vp - vm) / (2.0 * h) - a).abs() < 2.0 * h * j_pk + 1e-6 * a_pk,
                "dv/dt at t = {t}"
            );
            assert!(
                (ap - am).abs() / (2.0 * h) <= j_pk * (1.0 + 1e-6),
                "|da/dt| ≤ j at t = {t}"
            );
        }
        // Exactly at the target at and after the end, at rest.
        assert_eq!(p.evaluate(t_end), [p.target_m, 0.0, 0.0, 0.0]);
        assert_eq!(p.evaluate(t_end + 1.0), [p.target_m, 0.0, 0.0, 0.0]);
        // Continuous arrival: just before the end it is within rounding of target.
        let [x, v, a, _] = p.evaluate(t_end - 1e-9 * p.duration());
        let d = (p.target_m - p.start_m).abs();
        assert!((x - p.target_m).abs() < 1e-9 * d, "x(T-) = {x}");
        assert!(
            v.abs() < 1e-6 * v_pk && a.abs() < 1e-6 * a_pk,
            "v(T-) = {v}, a(T-) = {a}"
        );
        assert_eq!(p.evaluate(t0 - 1e-3)[0], p.start_m);
        assert_eq!(p.evaluate(t0), [p.start_m, 0.0, 0.0, 0.0]);
    }

    #[test]
    fn third_order_with_all_limits_active_has_closed_form_duration() {
        // D = 1 mm, v = 10 mm/s, a = 0.5 m/s², j = 100 m/s³: all limits reached, the
        // classic duration is T = D/v + v/a + a/j.
        let (d, vm, am, jm) = (1e-3, 1e-2, 0.5, 100.0);
        let p = PointToPoint::third_order(0.0, d, vm, am, jm).unwrap();
        let t = d / vm + vm / am + am / jm;
        assert!((p.duration() - t).abs() < 1e-12, "{} vs {t}", p.duration());
        assert_profile_consistent(&p, [vm, am, jm]);
        // Peak velocity and acceleration are reached.
        let [_, v_mid, _, _] = p.evaluate(t / 2.0);
        assert!((v_mid - vm).abs() < 1e-12);
        let [_, _, a_pk, _] = p.evaluate(am / jm + 0.5 * (vm / am - am / jm));
        assert!((a_pk - am).abs() < 1e-9);
    }

    #[test]
    fn third_order_short_moves_and_negative_direction() {
        // Short move: only the jerk limit matters, T = 4·∛(D/2j).
        let (d, jm) = (1e-9, 100.0);
        let p = PointToPoint::third_order(5e-6, 5e-6 - d, 1.0, 1e3, jm).unwrap();
        assert!((p.duration() - 4.0 * (d / (2.0 * jm)).cbrt()).abs() < 1e-15);
        assert_profile_consistent(&p, [1.0, 1e3, jm]);
        assert!(p.evaluate(p.duration() / 2.0)[1] < 0.0, "moves down");
        // Acceleration-limited, no constant-velocity phase.
        let p = PointToPoint::third_order(0.0, 1e-4, f64::INFINITY, 0.05, 10.0).unwrap();
        assert_profile_consistent(&p, [f64::INFINITY, 0.05, 10.0]);
        // Zero-length move: holds.
        let p = PointToPoint::third_order(1.0, 1.0, 1.0, 1.0, 1.0).unwrap();
        assert_eq!(p.evaluate(0.5), [1.0, 0.0, 0.0, 0.0]);
    }

    #[test]
    fn minimum_jerk_and_cycloidal_closed_forms() {
        let (d, t) = (4e-6, 0.2);
        let p = PointToPoint::timed(P2pProfile::MinimumJerk, 0.0, d, t).unwrap();
        let [x, v, _, _] = p.evaluate(t / 2.0);
        assert!((x - d / 2.0).abs() < 1e-18);
        assert!((v - 1.875 * d / t).abs() < 1e-15);
        assert_profile_consistent(
            &p,
            [1.875 * d / t, 5.7736 * d / (t * t), 60.0 * d / t.powi(3)],
        );
        let c = PointToPoint::timed(P2pProfile::Cycloidal, 0.0, d, t).unwrap();
        assert!((c.evaluate(t / 2.0)[1] - 2.0 * d / t).abs() < 1e-15);
        assert!((c.evaluate(t / 4.0)[2] - TAU * d / (t * t)).abs() < 1e-12);
        assert_profile_consistent(
            &c,
            [
                2.0 * d / t,
                TAU * d / (t * t),
                4.0 * PI * PI * d / t.powi(3),
            ],
        );
    }

    #[test]
    fn minimum_jerk_duration_from_limits_and_yaml() {
        let text = "type: point_to_point\ntarget_m: 2.0e-6\nbegin_s: 0.01\nprofile: minimum_jerk\nv_max_m_s: 1.875e-4\na_max_m_s2: 1.0\n";
        let mut b = built(text, 0);
        let y = run(b.as_mut(), 0);
        assert_eq!(y, vec![0.0, 0.0, 0.0]);
        // Velocity-limited here: T = 1.875 D / v_max = 20 ms, peak v = v_max at
        // mid-move (t = 20 ms = sample 200), where x = D/2.
        let y = run(b.as_mut(), 200);
        assert!((y[0] - 1e-6).abs() < 1e-18, "{y:?}");
        assert!((y[1] - 1.875e-4).abs() < 1e-15, "{y:?}");
        assert!(y[2].abs() < 1e-12, "{y:?}");
        let y = run(b.as_mut(), 600);
        assert_eq!(y, vec![2e-6, 0.0, 0.0]);
        assert_eq!(
            build_err("type: point_to_point\ntarget_m: 1\nprofile: cycloidal\n"),
            "duration_s"
        );
        assert_eq!(
            build_err("type: point_to_point\ntarget_m: 1\n"),
            "j_max_m_s3"
        );
        assert_eq!(
            build_err("type: point_to_point\ntarget_m: 1\nj_max_m_s3: -1\n"),
            "j_max_m_s3"
        );
        assert_eq!(
            build_err("type: point_to_point\ntarget_m: 1\nj_max_m_s3: 1\nduration_s: 1\n"),
            "duration_s"
        );
    }

    #[test]
    fn white_noise_moments_and_psd() {
        let n = 100_000;
        let mut b = built("type: white_noise\nstd: 2.0\nmean: 1.0\nwidth: 2\n", 5);
        let (mut s, mut s2, mut cross) = ([0.0; 2], [0.0; 2], 0.0);
        for k in 0..n {
            let y = run(b.as_mut(), k);
            for i in 0..2 {
                s[i] += y[i];
                s2[i] += y[i] * y[i];
            }
            cross += (y[0] - 1.0) * (y[1] - 1.0);
        }
        for i in 0..2 {
            let mean = s[i] / n as f64;
            let var = s2[i] / n as f64 - mean * mean;
            // Standard errors: σ/√n = 0.0063 (mean), σ²·√(2/n) = 0.018 (variance).
            assert!((mean - 1.0).abs() < 0.03, "mean {mean}");
            assert!((var - 4.0).abs() < 0.08, "var {var}");
        }
        assert!((cross / n as f64).abs() < 0.08, "channels independent");
        // psd: σ² = S·f_s/2 = 1e-6 · 10 kHz / 2 = 5e-3.
        let mut p = built("type: white_noise\npsd: 1.0e-6\n", 1);
        let var = (0..n).map(|k| run(p.as_mut(), k)[0].powi(2)).sum::<f64>() / n as f64;
        assert!((var - 5e-3).abs() < 5e-3 * 0.03, "var {var}");
        assert_eq!(build_err("type: white_noise\n"), "std");
        assert_eq!(build_err("type: white_noise\nstd: 1\npsd: 1\n"), "psd");
        assert_eq!(build_err("type: white_noise\nstd: -1\n"), "std");
    }

    #[test]
    fn white_noise_is_deterministic_across_rebuilds() {
        let draw = |b: &mut dyn Block| {
            (0..100)
                .map(|k| run(b, k)[0].to_bits())
                .collect::<Vec<u64>>()
        };
        let mut b = built("type: white_noise\nstd: 1.0\n", 42);
        let first = draw(b.as_mut());
        b.build(&BuildContext::new("src", DT, 42)).unwrap();
        assert_eq!(draw(b.as_mut()), first, "rebuild restarts the stream");
        let mut c = built("type: white_noise\nstd: 1.0\n", 42);
        assert_eq!(draw(c.as_mut()), first, "same seed, same bits");
        let mut d = built("type: white_noise\nstd: 1.0\n", 43);
        assert_ne!(draw(d.as_mut()), first);
        // The plain-Rust constructor draws the same stream as the block.
        let mut w = WhiteNoise::with_std(1.0, 1, 42);
        let mut y = [0.0];
        let plain: Vec<u64> = (0..100)
            .map(|k| {
                w.sample(k as f64 * DT, &mut y);
                y[0].to_bits()
            })
            .collect();
        assert_eq!(plain, first);
    }

    #[test]
    fn ticks_do_not_allocate() {
        let texts = [
            "type: constant\nvalue: 1\n",
            "type: step\nfinal: 1\n",
            "type: constant_velocity\nvelocity_m_s: 1\n",
            "type: sinusoid\namplitude: 1\nfrequency_hz: 3\n",
            "type: triangular_scan\namplitude: 1\nfrequency_hz: 3\n",
            "type: point_to_point\ntarget_m: 1\nv_max_m_s: 10\na_max_m_s2: 100\nj_max_m_s3: 1000\n",
            "type: white_noise\nstd: 1\nwidth: 3\n",
        ];
        for text in texts {
            let mut b = built(text, 3);
            let w: usize = b.outputs().iter().map(|p| p.width).sum();
            let mut y = vec![0.0; w];
            let info = allocation_counter::measure(|| {
                for k in 0..1000 {
                    b.output(Tick::new(k, DT), &[], &mut y);
                }
            });
            assert_eq!(info.count_total, 0, "{text}");
            assert!(y.iter().all(|v| v.is_finite()));
        }
    }
}
