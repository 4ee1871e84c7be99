//! Linear plant models of the walking piezo stage, input drive frequency f_α (Hz),
//! output stage position x_s (m):
//!
//! - [`LinearStage`]: the first-principles model (2.3)–(2.7) of Ch. 2,
//!   P(s) = c(bs + k) / (s(Ms² + bs + k)), realised as the states
//!   (x_p, x_s, ẋ_s) of the mass–spring–damper of Fig. 2.7 driven by the leg
//!   position x_p = c·α/2π (2.5);
//! - [`FittedStage`]: the model (5.31) fitted in Ch. 5, an integrator, a resonance,
//!   an anti-resonance and a second resonance, plus a delay of three samples at
//!   4 kHz, realised as a cascade of second-order sections (never as one
//!   high-order polynomial, SPEC §1).
//!
//! Both are discretised exactly (zero-order hold) at the block's period with
//! `nanomotion_core::lti::c2d` and stepped without allocation.

use nalgebra::DMatrix;
use nanomotion_core::Params;
use nanomotion_core::block::check;
use nanomotion_core::lti::{C2dMethod, LtiError, SsStepper, StateSpace, series};
use nanomotion_core::{Block, BuildContext, ParamError, Plant, Tick, declared_block};
use serde::{Deserialize, Serialize};
use std::f64::consts::PI;

fn lti_to_param(field: &str, e: LtiError) -> ParamError {
    ParamError::new(
        field,
        format!("the model cannot be discretised: {e}"),
        "check the model parameters and the block rate",
    )
}

// ---------------------------------------------------------------------------
// (2.3)–(2.7)
// ---------------------------------------------------------------------------

/// Parameters of the Ch. 2 linear model (2.7). Defaults are the thesis's values.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, Params)]
#[serde(default, deny_unknown_fields)]
pub struct LinearStageParams {
    /// Stage mass M (kg); thesis: 0.255 kg.
    #[param(positive)]
    pub mass_kg: f64,
    /// Resonance f_res (Hz) giving the stiffness k = 4π²M f_res²; thesis: 575 Hz.
    #[param(positive)]
    pub f_res_hz: f64,
    /// Damping b (N·s/m) of the rubber casting; thesis: 16 N·s/m.
    #[param(non_negative)]
    pub damping_ns_m: f64,
    /// Motor constant c (m per cycle of α), the leg travel per waveform period
    /// (2.5). From (2.8), |P| = −138 dB (m/Hz) at 10 Hz: c = 2π·10·10^(−138/20)
    /// = 7.91 µm.
    #[param(finite)]
    pub motor_constant_m: f64,
}

impl Default for LinearStageParams {
    /// The thesis's values (a graph file may leave any field out).
    fn default() -> Self {
        Self {
            mass_kg: 0.255,
            f_res_hz: 575.0,
            damping_ns_m: 16.0,
            motor_constant_m: 2.0 * PI * 10.0 * 10f64.powf(-138.0 / 20.0),
        }
    }
}

impl LinearStageParams {
    /// Check that every parameter is physical.
    pub fn validate(&self) -> Result<(), ParamError> {
        self.check_params()?;
        if self.motor_constant_m == 0.0 {
            return Err(ParamError::new(
                "motor_constant_m",
                "is 0: the stage would never move",
                "give the leg travel per cycle, e.g. 7.91e-6",
            ));
        }
        Ok(())
    }

    /// Stiffness k = 4π²M f_res² (N/m).
    pub fn stiffness_n_m(&self) -> f64 {
        4.0 * PI * PI * self.mass_kg * self.f_res_hz * self.f_res_hz
    }

    /// The continuous model (2.7) with states (x_p, x_s, ẋ_s), input f_α (Hz),
    /// outputs (x_s, ẋ_s).
    pub fn continuous(&self) -> StateSpace {
        let (m, b, c, k) = (
            self.mass_kg,
            self.damping_ns_m,
            self.motor_constant_m,
            self.stiffness_n_m(),
        );
        let a =
            DMatrix::from_row_slice(3, 3, &[0.0, 0.0, 0.0, 0.0, 0.0, 1.0, k / m, -k / m, -b / m]);
        let bm = DMatrix::from_row_slice(3, 1, &[c, 0.0, b * c / m]);
        let cm = DMatrix::from_row_slice(2, 3, &[0.0, 1.0, 0.0, 0.0, 0.0, 1.0]);
        StateSpace {
            a,
            b: bm,
            c: cm,
            d: DMatrix::zeros(2, 1),
            dt: None,
        }
    }

    /// P(s) of (2.7) evaluated at s (closed form), from f_α (Hz) to x_s (m).
    pub fn transfer_at(&self, s: nalgebra::Complex<f64>) -> nalgebra::Complex<f64> {
        let (m, b, c, k) = (
            self.mass_kg,
            self.damping_ns_m,
            self.motor_constant_m,
            self.stiffness_n_m(),
        );
        (s * b + k) * c / (s * (s * s * m + s * b + k))
    }
}

/// The Ch. 2 linear stage (2.7), discretised by zero-order hold at period `dt`.
///
/// ```
/// use walking_piezo::{LinearStage, LinearStageParams};
/// use nanomotion_core::Plant;
/// let p = LinearStageParams::default();
/// let mut stage = LinearStage::new(p.clone(), 1.0 / 4000.0).unwrap();
/// // 1 s at f_α = 10 Hz: ten cycles of c ≈ 7.9 µm, minus the small spring lag.
/// for _ in 0..4000 { stage.advance(&[10.0]); }
/// let mut y = [0.0; 2];
/// stage.plant_output(&mut y);
/// assert!((y[0] - 10.0 * p.motor_constant_m).abs() < 1e-8);
/// ```
#[derive(Debug, Clone)]
pub struct LinearStage {
    params: LinearStageParams,
    discrete: StateSpace,
    stepper: SsStepper,
}

impl LinearStage {
    /// Validate `params` and discretise at `dt` (s).
    pub fn new(params: LinearStageParams, dt: f64) -> Result<Self, ParamError> {
        params.validate()?;
        check::positive("dt", dt)?;
        let discrete = params
            .continuous()
            .c2d(dt, C2dMethod::Zoh)
            .map_err(|e| lti_to_param("f_res_hz", e))?;
        let stepper = SsStepper::new(&discrete).map_err(|e| lti_to_param("f_res_hz", e))?;
        Ok(Self {
            params,
            discrete,
            stepper,
        })
    }
    /// The parameters.
    pub fn params(&self) -> &LinearStageParams {
        &self.params
    }
    /// The discrete model (input f_α, outputs x_s, ẋ_s).
    pub fn discrete(&self) -> &StateSpace {
        &self.discrete
    }
    /// Back to rest at x = 0.
    pub fn reset(&mut self) {
        self.stepper.reset();
    }
}

impl Plant for LinearStage {
    /// `y = [x_s (m), ẋ_s (m/s)]`.
    fn plant_output(&self, y: &mut [f64]) {
        // Strictly proper (D = 0): y = C x, the input slice is not read.
        self.stepper.output(&[0.0], y);
    }
    /// `u = [f_α (Hz)]`; a non-finite input is ignored (state held) — use the
    /// block's `faults` output to see it.
    fn advance(&mut self, u: &[f64]) {
        if u[0].is_finite() {
            self.stepper.update(u);
        }
    }
}

/// `walking_piezo_linear`: walking piezo stage, linear model (2.7) P(s) =
/// c(bs+k)/(s(Ms²+bs+k)), ZOH-discretised.
///
/// Graph block `walking_piezo_linear`: the model (2.7), f_α (Hz) → x_s (m), ẋ_s (m/s).
#[derive(Debug, Clone, Default, Serialize, Deserialize, Params)]
#[serde(transparent)]
#[block(type_name = "walking_piezo_linear", role = Plant, ports = "f_alpha[1] (Hz) -> x_s[1] (m), v_s[1] (m/s), faults[1] (count) \"of non-finite inputs\"")]
pub struct LinearStageBlock {
    /// The parameters.
    pub params: LinearStageParams,
    #[serde(skip)]
    sim: Option<LinearStage>,
    #[serde(skip)]
    faults: u64,
}

impl LinearStageBlock {
    /// A block with these parameters (build it before stepping).
    pub fn new(params: LinearStageParams) -> Self {
        Self {
            params,
            sim: None,
            faults: 0,
        }
    }
}

#[declared_block]
impl Block for LinearStageBlock {
    fn direct_feedthrough(&self) -> bool {
        false
    }
    fn build(&mut self, ctx: &BuildContext) -> Result<(), ParamError> {
        self.sim = Some(LinearStage::new(self.params.clone(), ctx.dt)?);
        self.faults = 0;
        Ok(())
    }
    fn output(&mut self, _tick: Tick, _u: &[f64], y: &mut [f64]) {
        if let Some(s) = &self.sim {
            s.plant_output(&mut y[..2]);
        }
        y[2] = self.faults as f64;
    }
    fn update(&mut self, _tick: Tick, u: &[f64]) {
        if !u[0].is_finite() {
            self.faults += 1;
        }
        if let Some(s) = &mut self.sim {
            s.advance(u);
        }
    }
    fn lti(&self) -> Option<StateSpace> {
        let d = self.sim.as_ref()?.discrete.clone();
        // Append the `faults` output as a zero row so ports and model agree.
        let n = d.nstates();
        let mut c = DMatrix::zeros(3, n);
        c.view_mut((0, 0), (2, n)).copy_from(&d.c);
        Some(StateSpace {
            c,
            d: DMatrix::zeros(3, 1),
            ..d
        })
    }
}

// ---------------------------------------------------------------------------
// (2.3) with the voltages and the switching between the pairs
// ---------------------------------------------------------------------------

/// Parameters of the switched model (2.3): the mass–spring–damper of Fig. 2.7
/// driven by the leg pair that is higher (y_p1 ≥ y_p2: pair 1), with leg positions
/// from the voltages by (4.2).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, Params)]
#[serde(default, deny_unknown_fields)]
pub struct SwitchedStageParams {
    /// Stage mass M (kg); thesis: 0.255 kg.
    pub mass_kg: f64,
    /// Resonance f_res (Hz), k = 4π²M f_res²; thesis: 575 Hz.
    pub f_res_hz: f64,
    /// Damping b (N·s/m); thesis: 16 N·s/m.
    pub damping_ns_m: f64,
    /// Bending coefficients c_x1..c_x4 (m/V).
    pub c_x_m_v: [f64; 4],
    /// Extension coefficients c_y1..c_y4 (m/V).
    pub c_y_m_v: [f64; 4],
}

impl Default for SwitchedStageParams {
    /// The linear model's mass, resonance and damping, the Ch. 5 motor's
    /// coefficients (a graph file may leave any field out).
    fn default() -> Self {
        let lin = LinearStageParams::default();
        Self {
            mass_kg: lin.mass_kg,
            f_res_hz: lin.f_res_hz,
            damping_ns_m: lin.damping_ns_m,
            c_x_m_v: [crate::kinematics::C_X_M_PER_V; 4],
            c_y_m_v: [crate::kinematics::C_Y_M_PER_V; 4],
        }
    }
}

/// The switched linear model (2.3): M ẍ_s = k(X_p − x_s) + b(Ẋ_p − ẋ_s), with the
/// drive position X_p that of the higher pair.
///
/// Read literally, (2.3) ties the stage to the bounded leg position and cannot
/// walk; here, as the walking principle requires, the pair that takes over grips
/// the stage where the previous one left it: X_p = offset + x_p,active with the
/// offset re-referenced at each take-over so that X_p is continuous. The model
/// from X_p to x_s, (bs + k)/(Ms² + bs + k) (2.4), is ZOH-discretised in state
/// space.
///
/// ```
/// use walking_piezo::{SwitchedStage, SwitchedStageParams, SinusoidalWaveform};
/// use nanomotion_core::Plant;
/// let dt = 1e-4;
/// let mut s = SwitchedStage::new(SwitchedStageParams::default(), dt).unwrap();
/// let w = SinusoidalWaveform { f_alpha_hz: 1.0, ..Default::default() };
/// for k in 0..10_000 { s.advance(&w.voltages(w.alpha(k as f64 * dt))); }
/// let mut y = [0.0; 3];
/// s.plant_output(&mut y);
/// // One cycle: both pairs sweep their stroke 2·c_x·A/√2 in contact.
/// let per_cycle = 2.0 * 2f64.sqrt() * 64.5e-9 * 46.0;
/// assert!((y[0] - per_cycle).abs() < 0.02 * per_cycle);
/// ```
#[derive(Debug, Clone)]
pub struct SwitchedStage {
    params: SwitchedStageParams,
    kin: crate::kinematics::LegKinematics,
    stepper: SsStepper,
    pair: usize,
    offset: f64,
    x_p: f64,
    started: bool,
}

impl SwitchedStage {
    /// Validate and discretise at `dt` (s).
    pub fn new(params: SwitchedStageParams, dt: f64) -> Result<Self, ParamError> {
        check::positive("mass_kg", params.mass_kg)?;
        check::positive("f_res_hz", params.f_res_hz)?;
        check::non_negative("damping_ns_m", params.damping_ns_m)?;
        check::positive("dt", dt)?;
        let kin = crate::kinematics::LegKinematics {
            c_x_m_v: params.c_x_m_v,
            c_y_m_v: params.c_y_m_v,
        };
        kin.validate()?;
        let (m, b) = (params.mass_kg, params.damping_ns_m);
        let k = 4.0 * PI * PI * m * params.f_res_hz * params.f_res_hz;
        // z'' = (X_p − b z' − k z)/M, x_s = k z + b z'.
        let sys = StateSpace {
            a: DMatrix::from_row_slice(2, 2, &[0.0, 1.0, -k / m, -b / m]),
            b: DMatrix::from_row_slice(2, 1, &[0.0, 1.0 / m]),
            c: DMatrix::from_row_slice(1, 2, &[k, b]),
            d: DMatrix::zeros(1, 1),
            dt: None,
        };
        let d = sys
            .c2d(dt, C2dMethod::Zoh)
            .map_err(|e| lti_to_param("f_res_hz", e))?;
        Ok(Self {
            params,
            kin,
            stepper: SsStepper::new(&d).map_err(|e| lti_to_param("f_res_hz", e))?,
            pair: 0,
            offset: 0.0,
            x_p: 0.0,
            started: false,
        })
    }
    /// The parameters.
    pub fn params(&self) -> &SwitchedStageParams {
        &self.params
    }
    /// The driving pair (0 or 1) of the last step.
    pub fn pair(&self) -> usize {
        self.pair
    }
}

impl Plant for SwitchedStage {
    /// `y = [x_s (m), X_p (m), driving pair (1 or 2)]`.
    fn plant_output(&self, y: &mut [f64]) {
        self.stepper.output(&[0.0], &mut y[..1]);
        y[1] = self.x_p;
        y[2] = (self.pair + 1) as f64;
    }
    /// `u = [u1, u2, u3, u4]` (V); a non-finite input is ignored (state held).
    fn advance(&mut self, u: &[f64]) {
        if !u[..4].iter().all(|v| v.is_finite()) {
            return;
        }
        let t = self.kin.tips(&[u[0], u[1], u[2], u[3]]);
        let pair = if t.y[0] >= t.y[1] { 0 } else { 1 };
        if !self.started {
            self.started = true;
            self.pair = pair;
            self.offset = -t.x[pair];
        } else if pair != self.pair {
            // Take-over: the new pair grips the stage where the old one left it.
            self.offset = self.x_p - t.x[pair];
            self.pair = pair;
        }
        self.x_p = self.offset + t.x[pair];
        self.stepper.update(&[self.x_p]);
    }
}

/// `walking_piezo_switched`: walking piezo stage, switched linear model (2.3): the
/// higher leg pair drives a mass-spring-damper.
///
/// Graph block `walking_piezo_switched`: the switched linear model (2.3),
/// u (4, V) → x_s (m), x_p (m), pair (1 or 2).
#[derive(Debug, Clone, Default, Serialize, Deserialize, Params)]
#[serde(transparent)]
#[block(type_name = "walking_piezo_switched", role = Plant, ports = "u[4] (V) -> x_s[1] (m), x_p[1] (m), pair[1] \"1 or 2\", faults[1]")]
pub struct SwitchedStageBlock {
    /// The parameters.
    pub params: SwitchedStageParams,
    #[serde(skip)]
    sim: Option<SwitchedStage>,
    #[serde(skip)]
    faults: u64,
}

#[declared_block]
impl Block for SwitchedStageBlock {
    fn direct_feedthrough(&self) -> bool {
        false
    }
    fn build(&mut self, ctx: &BuildContext) -> Result<(), ParamError> {
        self.sim = Some(SwitchedStage::new(self.params.clone(), ctx.dt)?);
        self.faults = 0;
        Ok(())
    }
    fn output(&mut self, _tick: Tick, _u: &[f64], y: &mut [f64]) {
        if let Some(s) = &self.sim {
            s.plant_output(&mut y[..3]);
        }
        y[3] = self.faults as f64;
    }
    fn update(&mut self, _tick: Tick, u: &[f64]) {
        if !u.iter().all(|v| v.is_finite()) {
            self.faults += 1;
        }
        if let Some(s) = &mut self.sim {
            s.advance(u);
        }
    }
}

// ---------------------------------------------------------------------------
// (5.31)
// ---------------------------------------------------------------------------

/// Parameters of the Ch. 5 fitted model (5.31)
///
/// G(s) = (c/s) · (ω_p1²ω_p2²/ω_z1²) · (s² + b_z1 ω_z1 s + ω_z1²) /
///        ((s² + b_p1 ω_p1 s + ω_p1²)(s² + b_p2 ω_p2 s + ω_p2²)) · e^{−s·delay},
///
/// ω = 2πf, normalised so that G(s) → c/s at low frequency (c in m per cycle of α,
/// the thesis's value of c is lost in the text, so the default is the Ch. 2 value).
/// The b's are the thesis's "2ζ" coefficients; their printed values lost their
/// zeros and are read as 0.33, 0.2 and 0.175.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, Params)]
#[serde(default, deny_unknown_fields)]
pub struct FittedStageParams {
    /// Low-frequency gain c (m per cycle): G(s) ≈ c/s.
    #[param(finite)]
    pub gain_m_per_cycle: f64,
    /// First resonance f_p1 (Hz); thesis: 527 Hz.
    #[param(positive)]
    pub f_p1_hz: f64,
    /// Damping coefficient b_p1 (= 2ζ) of the first resonance.
    #[param(positive)]
    pub b_p1: f64,
    /// Anti-resonance f_z1 (Hz); thesis: 624 Hz.
    #[param(positive)]
    pub f_z1_hz: f64,
    /// Damping coefficient b_z1 (= 2ζ) of the anti-resonance.
    #[param(non_negative)]
    pub b_z1: f64,
    /// Second resonance f_p2 (Hz); thesis: 650 Hz.
    #[param(positive)]
    pub f_p2_hz: f64,
    /// Damping coefficient b_p2 (= 2ζ) of the second resonance.
    #[param(positive)]
    pub b_p2: f64,
    /// Pure delay (s), an integer number of block periods; thesis: three samples
    /// at 4 kHz = 0.75 ms.
    /// At most 2^24 periods (a ring buffer; the LTI model carries it as states up to 512).
    #[param(non_negative)]
    pub delay_s: f64,
}

impl Default for FittedStageParams {
    /// The thesis's values, the gain the linear model's motor constant (a
    /// graph file may leave any field out).
    fn default() -> Self {
        Self {
            gain_m_per_cycle: LinearStageParams::default().motor_constant_m,
            f_p1_hz: 527.0,
            b_p1: 0.33,
            f_z1_hz: 624.0,
            b_z1: 0.2,
            f_p2_hz: 650.0,
            b_p2: 0.175,
            delay_s: 3.0 / 4000.0,
        }
    }
}

/// A second-order section (s² + b ω s + ω²) as a tuple of coefficients.
fn quad(f_hz: f64, b: f64) -> (f64, f64) {
    let w = 2.0 * PI * f_hz;
    (b * w, w * w)
}

impl FittedStageParams {
    /// Check that every parameter is physical.
    pub fn validate(&self) -> Result<(), ParamError> {
        self.check_params()?;
        if self.gain_m_per_cycle == 0.0 {
            return Err(ParamError::new(
                "gain_m_per_cycle",
                "is 0",
                "give the stage travel per cycle of α (m)",
            ));
        }
        Ok(())
    }

    /// The continuous delay-free part as a cascade integrator → (zero/pole section)
    /// → (pole section), input f_α (Hz), output x_s (m).
    pub fn continuous(&self) -> Result<StateSpace, LtiError> {
        let c = self.gain_m_per_cycle;
        let (az1, az0) = quad(self.f_z1_hz, self.b_z1);
        let (ap1_1, ap1_0) = quad(self.f_p1_hz, self.b_p1);
        let (ap2_1, ap2_0) = quad(self.f_p2_hz, self.b_p2);
        let integ = StateSpace::new(
            DMatrix::zeros(1, 1),
            DMatrix::from_element(1, 1, c),
            DMatrix::from_element(1, 1, 1.0),
            DMatrix::zeros(1, 1),
            None,
        )?;
        // (s² + az1 s + az0)/(s² + ap1_1 s + ap1_0) = 1 + ((az1−ap1_1)s + (az0−ap1_0))/(...):
        // controllable canonical form.
        let sec1 = StateSpace::new(
            DMatrix::from_row_slice(2, 2, &[0.0, 1.0, -ap1_0, -ap1_1]),
            DMatrix::from_row_slice(2, 1, &[0.0, 1.0]),
            DMatrix::from_row_slice(1, 2, &[az0 - ap1_0, az1 - ap1_1]),
            DMatrix::from_element(1, 1, 1.0),
            None,
        )?;
        // gain · 1/(s² + ap2_1 s + ap2_0), gain = ω_p1²ω_p2²/ω_z1² (unit DC gain overall).
        let g = ap1_0 * ap2_0 / az0;
        let sec2 = StateSpace::new(
            DMatrix::from_row_slice(2, 2, &[0.0, 1.0, -ap2_0, -ap2_1]),
            DMatrix::from_row_slice(2, 1, &[0.0, 1.0]),
            DMatrix::from_row_slice(1, 2, &[g, 0.0]),
            DMatrix::zeros(1, 1),
            None,
        )?;
        series(&series(&integ, &sec1)?, &sec2)
    }

    /// G(s) of (5.31) without the delay, evaluated at s (closed form).
    pub fn transfer_at(&self, s: nalgebra::Complex<f64>) -> nalgebra::Complex<f64> {
        let (az1, az0) = quad(self.f_z1_hz, self.b_z1);
        let (ap1_1, ap1_0) = quad(self.f_p1_hz, self.b_p1);
        let (ap2_1, ap2_0) = quad(self.f_p2_hz, self.b_p2);
        let num = (s * s + s * az1 + az0) * (ap1_0 * ap2_0 / az0) * self.gain_m_per_cycle;
        num / (s * (s * s + s * ap1_1 + ap1_0) * (s * s + s * ap2_1 + ap2_0))
    }

    /// The delay in samples at period `dt`, if it is an integer number of periods
    /// and at most [`MAX_FITTED_DELAY_SAMPLES`].
    pub fn delay_samples(&self, dt: f64) -> Result<usize, ParamError> {
        check::non_negative("delay_s", self.delay_s)?;
        let n = self.delay_s / dt;
        let rounded = n.round();
        if rounded.is_nan() || rounded > MAX_FITTED_DELAY_SAMPLES as f64 {
            return Err(ParamError::new(
                "delay_s",
                format!(
                    "{} s is {n:.4e} periods of {dt} s, more than {MAX_FITTED_DELAY_SAMPLES} (the delay's ring buffer would exceed 128 MiB)",
                    self.delay_s
                ),
                format!("give at most {} s", MAX_FITTED_DELAY_SAMPLES as f64 * dt),
            ));
        }
        if (n - rounded).abs() > 1e-6 * n.max(1.0) {
            return Err(ParamError::new(
                "delay_s",
                format!(
                    "{} s is {n:.4} periods of {dt} s, not an integer number",
                    self.delay_s
                ),
                "give a multiple of the block period (e.g. 0.00075 at 4 kHz)",
            ));
        }
        Ok(rounded as usize)
    }

    /// The discrete delay-free model at period `dt` (ZOH of the cascade).
    pub fn discrete_delay_free(&self, dt: f64) -> Result<StateSpace, ParamError> {
        self.validate()?;
        check::positive("dt", dt)?;
        let sys = self.continuous().map_err(|e| lti_to_param("f_p1_hz", e))?;
        sys.c2d(dt, C2dMethod::Zoh)
            .map_err(|e| lti_to_param("f_p1_hz", e))
    }

    /// The discrete model at period `dt`: ZOH of the cascade, then the delay as
    /// states z^-d (for analyses; the simulation uses a ring buffer). Refused for
    /// delays above [`MAX_FITTED_DELAY_MODEL_SAMPLES`] (a dense model of
    /// thousands of delay states would cost seconds and gigabytes).
    pub fn discrete(&self, dt: f64) -> Result<StateSpace, ParamError> {
        let d = self.discrete_delay_free(dt)?;
        let nd = self.delay_samples(dt)?;
        if nd > MAX_FITTED_DELAY_MODEL_SAMPLES {
            return Err(ParamError::new(
                "delay_s",
                format!(
                    "is {nd} samples; a state-space model has delay states only up to {MAX_FITTED_DELAY_MODEL_SAMPLES}"
                ),
                "analyse the delay-free model (discrete_delay_free) with the delay as e^{-jωd·dt}",
            ));
        }
        if nd == 0 {
            Ok(d)
        } else {
            d.with_output_delay(nd)
                .map_err(|e| lti_to_param("delay_s", e))
        }
    }
}

/// Longest pure delay of `walking_piezo_fitted`, in samples of its period:
/// 2^24 (the per-block buffer bound, 128 MiB). The delay is simulated by a
/// ring buffer, so building costs O(1) and a tick O(1) whatever its length.
pub const MAX_FITTED_DELAY_SAMPLES: usize = nanomotion_core::block::MAX_BUFFER_VALUES;

/// Longest delay of `walking_piezo_fitted` that its LTI model
/// ([`Block::lti`], for analyses) carries as states: 512 samples (as for the
/// core `delay` block). Longer delays simulate normally but report no LTI model.
pub const MAX_FITTED_DELAY_MODEL_SAMPLES: usize = 512;

/// The Ch. 5 fitted stage (5.31), discretised at period `dt`: the delay-free
/// model stepped in state space, its output delayed by a ring buffer of
/// `delay_s / dt` samples.
///
/// ```
/// use walking_piezo::{FittedStage, FittedStageParams};
/// use nanomotion_core::Plant;
/// let mut g = FittedStage::new(FittedStageParams::default(), 1.0 / 4000.0).unwrap();
/// assert_eq!(g.delay_samples(), 3);
/// for _ in 0..4000 { g.advance(&[10.0]); }
/// let mut y = [0.0];
/// g.plant_output(&mut y);
/// assert!((y[0] - 10.0 * FittedStageParams::default().gain_m_per_cycle).abs() < 2e-7);
/// ```
#[derive(Debug, Clone)]
pub struct FittedStage {
    params: FittedStageParams,
    /// The model with delay states, when the delay is short enough to carry them.
    discrete: Option<StateSpace>,
    delay: usize,
    stepper: SsStepper,
    /// Past outputs of the delay-free model: `ring[head]` is y[k − delay].
    ring: Vec<f64>,
    head: usize,
}

impl FittedStage {
    /// Validate and discretise at `dt` (s).
    pub fn new(params: FittedStageParams, dt: f64) -> Result<Self, ParamError> {
        let free = params.discrete_delay_free(dt)?;
        let delay = params.delay_samples(dt)?;
        let discrete = if delay <= MAX_FITTED_DELAY_MODEL_SAMPLES {
            Some(params.discrete(dt)?)
        } else {
            None
        };
        let stepper = SsStepper::new(&free).map_err(|e| lti_to_param("f_p1_hz", e))?;
        Ok(Self {
            params,
            discrete,
            delay,
            stepper,
            ring: vec![0.0; delay],
            head: 0,
        })
    }
    /// The parameters.
    pub fn params(&self) -> &FittedStageParams {
        &self.params
    }
    /// The discrete model including the delay states (none for delays above
    /// [`MAX_FITTED_DELAY_MODEL_SAMPLES`]).
    pub fn discrete(&self) -> Option<&StateSpace> {
        self.discrete.as_ref()
    }
    /// The delay in samples.
    pub fn delay_samples(&self) -> usize {
        self.delay
    }
    /// Bytes held by the delay line.
    pub fn memory_bytes(&self) -> usize {
        self.ring.len() * 8
    }
    /// Back to rest.
    pub fn reset(&mut self) {
        self.stepper.reset();
        self.ring.iter_mut().for_each(|v| *v = 0.0);
        self.head = 0;
    }
}

impl Plant for FittedStage {
    /// `y = [x_s (m)]`.
    fn plant_output(&self, y: &mut [f64]) {
        if self.delay == 0 {
            // Strictly proper (D = 0): y = C x, the input slice is not read.
            self.stepper.output(&[0.0], y);
        } else {
            y[0] = self.ring[self.head];
        }
    }
    /// `u = [f_α (Hz)]`; a non-finite input is ignored (state held, the delay
    /// line moves on).
    fn advance(&mut self, u: &[f64]) {
        if self.delay > 0 {
            let mut y = [0.0];
            self.stepper.output(&[0.0], &mut y);
            self.ring[self.head] = y[0];
            self.head = if self.head + 1 == self.delay {
                0
            } else {
                self.head + 1
            };
        }
        if u[0].is_finite() {
            self.stepper.update(u);
        }
    }
}

/// `walking_piezo_fitted`: walking piezo stage, Ch. 5 fitted model (5.31): integrator,
/// 527 Hz resonance, 624 Hz anti-resonance, 650 Hz resonance, 3-sample delay.
///
/// Graph block `walking_piezo_fitted`: the Ch. 5 model (5.31), f_α (Hz) → x_s (m).
#[derive(Debug, Clone, Default, Serialize, Deserialize, Params)]
#[serde(transparent)]
#[block(type_name = "walking_piezo_fitted", role = Plant, ports = "f_alpha[1] (Hz) -> x_s[1] (m), faults[1] (count) \"of non-finite inputs\"")]
pub struct FittedStageBlock {
    /// The parameters.
    pub params: FittedStageParams,
    #[serde(skip)]
    sim: Option<FittedStage>,
    #[serde(skip)]
    faults: u64,
}

impl FittedStageBlock {
    /// A block with these parameters (build it before stepping).
    pub fn new(params: FittedStageParams) -> Self {
        Self {
            params,
            sim: None,
            faults: 0,
        }
    }
}

#[declared_block]
impl Block for FittedStageBlock {
    fn direct_feedthrough(&self) -> bool {
        false
    }
    fn build(&mut self, ctx: &BuildContext) -> Result<(), ParamError> {
        self.sim = Some(FittedStage::new(self.params.clone(), ctx.dt)?);
        self.faults = 0;
        Ok(())
    }
    fn output(&mut self, _tick: Tick, _u: &[f64], y: &mut [f64]) {
        if let Some(s) = &self.sim {
            s.plant_output(&mut y[..1]);
        }
        y[1] = self.faults as f64;
    }
    fn update(&mut self, _tick: Tick, u: &[f64]) {
        if !u[0].is_finite() {
            self.faults += 1;
        }
        if let Some(s) = &mut self.sim {
            s.advance(u);
        }
    }
    fn memory_bytes(&self) -> usize {
        self.sim.as_ref().map_or(0, FittedStage::memory_bytes)
    }
    fn planned_bytes(&self, dt: f64) -> (&'static str, usize) {
        let samples = (self.params.delay_s / dt).round();
        let bytes = if samples.is_finite() && samples >= 0.0 {
            (samples.min(usize::MAX as f64 / 16.0) as usize + 1).saturating_mul(8)
        } else {
            0
        };
        ("delay_s", bytes)
    }
    fn lti(&self) -> Option<StateSpace> {
        let d = self.sim.as_ref()?.discrete.clone()?;
        let n = d.nstates();
        let mut c = DMatrix::zeros(2, n);
        c.view_mut((0, 0), (1, n)).copy_from(&d.c);
        Some(StateSpace {
            c,
            d: DMatrix::zeros(2, 1),
            ..d
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::Complex;

    #[test]
    fn linear_discrete_matches_closed_form_frequency_response() {
        let p = LinearStageParams::default();
        let dt = 1.0 / 40_000.0;
        let s = LinearStage::new(p.clone(), dt).unwrap();
        for f in [1.0, 10.0, 100.0, 575.0, 1000.0] {
            let w = 2.0 * PI * f;
            let gd = s.discrete().freqresp_siso_at(w);
            let gc = p.transfer_at(Complex::new(0.0, w));
            // ZOH adds a half-sample delay: compare after removing e^{-jωT/2} and
            // allowing the (ωT)² amplitude error of the hold.
            let corr = gd * Complex::from_polar(1.0, w * dt / 2.0);
            let rel = (corr - gc).norm() / gc.norm();
            assert!(
                rel < 2.0 * (w * dt).powi(2) + 1e-9,
                "f = {f}: rel err {rel}"
            );
        }
    }

    #[test]
    fn linear_constant_frequency_gives_velocity_c_f_and_spring_lag() {
        // Ramp input x_p = c f t: steady-state lag of (2.4) is b/k·ẋ_p − ... For
        // X_s/X_p = (bs+k)/(Ms²+bs+k), the ramp error X_p − X_s → (M s²)/(...)·ramp
        // tends to 0 (type-2 behaviour of a unity-DC, matched-first-order system):
        // (Ms²)/(Ms²+bs+k)·v/s² → M v/k·s → 0. So x_s(t) − c f t → 0.
        let p = LinearStageParams::default();
        let dt = 1.0 / 4000.0;
        let mut s = LinearStage::new(p.clone(), dt).unwrap();
        let f = 25.0;
        let n = 8000;
        for _ in 0..n {
            s.advance(&[f]);
        }
        let mut y = [0.0; 2];
        s.plant_output(&mut y);
        let t = n as f64 * dt;
        assert!(
            (y[0] - p.motor_constant_m * f * t).abs() < 1e-12 + 1e-6 * y[0].abs(),
            "{y:?}"
        );
        assert!((y[1] - p.motor_constant_m * f).abs() < 1e-9, "{y:?}");
    }

    #[test]
    fn fitted_is_integrator_at_low_frequency_and_has_the_resonances() {
        let p = FittedStageParams::default();
        let w = 2.0 * PI * 1.0;
        let g = p.transfer_at(Complex::new(0.0, w));
        let expect = p.gain_m_per_cycle / w;
        assert!((g.norm() - expect).abs() / expect < 1e-3);
        // The continuous realisation equals the closed form everywhere.
        let sys = p.continuous().unwrap();
        for f in [5.0, 527.0, 600.0, 624.0, 650.0, 1500.0] {
            let w = 2.0 * PI * f;
            let a = sys.freqresp_siso_at(w);
            let b = p.transfer_at(Complex::new(0.0, w));
            assert!((a - b).norm() / b.norm() < 1e-9, "f = {f}");
        }
        // Poles at the given resonances.
        let mut wn: Vec<f64> = sys
            .poles()
            .iter()
            .map(|z| z.norm() / (2.0 * PI))
            .filter(|f| *f > 1.0)
            .collect();
        wn.sort_by(f64::total_cmp);
        assert!(
            (wn[0] - 527.0).abs() < 1e-6 && (wn[2] - 650.0).abs() < 1e-6,
            "{wn:?}"
        );
    }

    #[test]
    fn fitted_discrete_has_the_delay_and_matches_continuous() {
        let p = FittedStageParams::default();
        let dt = 1.0 / 4000.0;
        let d = p.discrete(dt).unwrap();
        assert_eq!(d.nstates(), 5 + 3);
        for f in [1.0, 10.0, 100.0, 400.0] {
            let w = 2.0 * PI * f;
            let gd = d.freqresp_siso_at(w) * Complex::from_polar(1.0, w * dt * 3.5);
            let gc = p.transfer_at(Complex::new(0.0, w));
            let rel = (gd - gc).norm() / gc.norm();
            assert!(rel < 3.0 * (w * dt).powi(2) + 1e-9, "f = {f}: {rel}");
        }
        // Impulse: the first three outputs after a unit pulse are exactly zero.
        let mut g = FittedStage::new(p.clone(), dt).unwrap();
        let mut y = [0.0];
        g.advance(&[1.0]);
        for _ in 0..3 {
            g.plant_output(&mut y);
            assert_eq!(y[0], 0.0);
            g.advance(&[0.0]);
        }
        g.plant_output(&mut y);
        assert!(y[0] > 0.0);
        // A delay that is not a whole number of samples is refused by name.
        let bad = FittedStageParams { delay_s: 1e-4, ..p };
        assert_eq!(bad.discrete(dt).unwrap_err().field, "delay_s");
    }

    #[test]
    fn a_long_fitted_delay_is_a_ring_buffer_with_the_output_delayed_exactly() {
        // Issue 13 item 4: 3 s at 4 kHz (12 000 samples) used to build a dense
        // 12 005-state model (61 s, 2.3 GB). Now: the delay-free model and a ring.
        let dt = 1.0 / 4000.0;
        let nd = 12_000;
        let long = FittedStageParams {
            delay_s: 3.0,
            ..Default::default()
        };
        let free = FittedStageParams {
            delay_s: 0.0,
            ..Default::default()
        };
        let info = allocation_counter::measure(|| {
            let g = FittedStage::new(long.clone(), dt).unwrap();
            assert_eq!(g.delay_samples(), nd);
            assert!(g.discrete().is_none());
        });
        // The ring (96 kB) and a few small matrices, not (n + 12 000)² values.
        assert!(info.bytes_max < 1 << 20, "{} bytes", info.bytes_max);
        let mut a = FittedStage::new(long.clone(), dt).unwrap();
        let mut b = FittedStage::new(free, dt).unwrap();
        let mut ya = Vec::new();
        let mut yb = Vec::new();
        let mut y = [0.0];
        for k in 0..nd + 3000 {
            let u = [if k < 2000 {
                10.0
            } else {
                -3.0 + (k % 7) as f64
            }];
            a.plant_output(&mut y);
            ya.push(y[0]);
            b.plant_output(&mut y);
            yb.push(y[0]);
            a.advance(&u);
            b.advance(&u);
        }
        assert!(ya[..nd].iter().all(|&v| v == 0.0));
        assert_eq!(&ya[nd..], &yb[..3000], "delayed bit for bit");
        assert!(yb[2999] != 0.0);
        // The short thesis delay keeps its LTI model, equal to the ring's output.
        let g = FittedStage::new(FittedStageParams::default(), dt).unwrap();
        assert_eq!(g.discrete().unwrap().nstates(), 5 + 3);
        // The block reports its ring to the memory estimate and no LTI model.
        let mut blk = FittedStageBlock::new(long.clone());
        blk.build(&BuildContext::new("g", dt, 0)).unwrap();
        assert_eq!(blk.memory_bytes(), nd * 8);
        assert!(blk.lti().is_none());
        // Above the bound: a ParamError naming delay_s, not an allocation.
        let huge = FittedStageParams {
            delay_s: (MAX_FITTED_DELAY_SAMPLES + 1) as f64 * dt,
            ..Default::default()
        };
        assert_eq!(FittedStage::new(huge, dt).unwrap_err().field, "delay_s");
    }

    #[test]
    fn the_ring_delay_equals_the_dense_delay_model() {
        let dt = 1.0 / 4000.0;
        let p = FittedStageParams {
            delay_s: 40.0 * dt,
            ..Default::default()
        };
        let mut g = FittedStage::new(p.clone(), dt).unwrap();
        let dense = p.discrete(dt).unwrap();
        assert_eq!(dense.nstates(), 45);
        let mut st = SsStepper::new(&dense).unwrap();
        let (mut y1, mut y2) = ([0.0], [0.0]);
        for k in 0..500 {
            let u = [((k * 37) % 11) as f64 - 5.0];
            g.plant_output(&mut y1);
            st.output(&[0.0], &mut y2);
            assert!(
                (y1[0] - y2[0]).abs() <= 1e-12 * y2[0].abs().max(1e-9),
                "k = {k}: {} vs {}",
                y1[0],
                y2[0]
            );
            g.advance(&u);
            st.update(&u);
        }
    }

    #[test]
    fn bad_parameters_are_refused_by_name() {
        let p = LinearStageParams {
            mass_kg: -1.0,
            ..Default::default()
        };
        assert_eq!(LinearStage::new(p, 1e-3).unwrap_err().field, "mass_kg");
        let p = LinearStageParams {
            damping_ns_m: f64::NAN,
            ..Default::default()
        };
        assert_eq!(LinearStage::new(p, 1e-3).unwrap_err().field, "damping_ns_m");
        assert_eq!(
            LinearStage::new(LinearStageParams::default(), 0.0)
                .unwrap_err()
                .field,
            "dt"
        );
        let p = FittedStageParams {
            f_p2_hz: 0.0,
            ..Default::default()
        };
        assert_eq!(FittedStage::new(p, 1e-3).unwrap_err().field, "f_p2_hz");
        // every bound declared on FittedStageParams, refused by name
        let fitted = |f: &dyn Fn(&mut FittedStageParams)| {
            let mut p = FittedStageParams::default();
            f(&mut p);
            FittedStage::new(p, 1e-3).unwrap_err().field
        };
        assert_eq!(
            fitted(&|p| p.gain_m_per_cycle = f64::NAN),
            "gain_m_per_cycle"
        );
        assert_eq!(fitted(&|p| p.gain_m_per_cycle = 0.0), "gain_m_per_cycle");
        assert_eq!(fitted(&|p| p.b_p1 = 0.0), "b_p1");
        assert_eq!(fitted(&|p| p.b_z1 = -0.1), "b_z1");
        assert_eq!(fitted(&|p| p.f_z1_hz = -1.0), "f_z1_hz");
        assert_eq!(fitted(&|p| p.delay_s = -1e-3), "delay_s");
        // the same declaration is the schema's bound
        let docs = FittedStageParams::param_docs();
        let schema = |n: &str| docs.iter().find(|d| d.name == n).unwrap().schema.clone();
        assert_eq!(schema("f_p1_hz")["exclusiveMinimum"], 0);
        assert_eq!(schema("b_z1")["minimum"], 0);
        assert_eq!(schema("delay_s")["minimum"], 0);
    }

    #[test]
    fn block_runs_and_reports_non_finite_input() {
        let mut b = LinearStageBlock::default();
        b.build(&BuildContext::new("lin", 2.5e-4, 0)).unwrap();
        let mut y = [0.0; 3];
        b.update(Tick::new(0, 2.5e-4), &[f64::NAN]);
        b.output(Tick::new(1, 2.5e-4), &[], &mut y);
        assert_eq!(y, [0.0, 0.0, 1.0]);
        let l = b.lti().unwrap();
        assert_eq!((l.noutputs(), l.ninputs()), (3, 1));
        assert!(!b.direct_feedthrough());
    }

    #[test]
    fn switched_model_walks_with_the_motor_constant_of_2_5() {
        // Quasi-static walking: the stage advances 2·(c_x A √2) per cycle, which is
        // the motor constant c of (2.5); so the switched model (2.3) and the
        // frequency model (2.7) agree at low frequency.
        let dt = 1e-4;
        let mut s = SwitchedStage::new(SwitchedStageParams::default(), dt).unwrap();
        let w = crate::SinusoidalWaveform {
            f_alpha_hz: 2.0,
            ..Default::default()
        };
        let c = 2.0 * 2f64.sqrt() * crate::kinematics::C_X_M_PER_V * w.amplitude_v;
        let lin = LinearStageParams {
            motor_constant_m: c,
            ..Default::default()
        };
        let mut l = LinearStage::new(lin, dt).unwrap();
        let n = 20_000; // 4 cycles
        let mut switches = 0;
        let mut last = None;
        for k in 0..n {
            s.advance(&w.voltages(w.alpha(k as f64 * dt)));
            l.advance(&[w.f_alpha_hz]);
            if last.is_some_and(|p| p != s.pair()) {
                switches += 1;
            }
            last = Some(s.pair());
        }
        let (mut ys, mut yl) = ([0.0; 3], [0.0; 2]);
        s.plant_output(&mut ys);
        l.plant_output(&mut yl);
        assert_eq!(switches, 8);
        // Within one stroke (the stepwise motion oscillates about the ramp).
        assert!((ys[0] - yl[0]).abs() < c / 2.0, "{} vs {}", ys[0], yl[0]);
        assert!((ys[0] - 4.0 * c).abs() < 0.6 * c);
    }
}
