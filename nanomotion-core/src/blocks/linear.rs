//! Linear time-invariant blocks: `transfer_function`, `state_space`, `low_pass`,
//! `notch`, `lead_lag` and `delay`.
//!
//! Every block is realised as a discrete state-space model at the block's own rate
//! (built in [`Block::build`], from a cascade of first/second-order sections
//! where it starts from a transfer function — never as one high-order polynomial
//! difference equation, see SPEC §1) and stepped by an allocation-free
//! [`SsStepper`]. The filters (`low_pass`, `notch`, `lead_lag`) are designed
//! as closed-form second-order sections realised in direct form II transposed,
//! and re-designed in place, states kept, when a corner changes while the loop
//! runs ([`Block::set_live_param`]). Filters act channel by channel on an
//! input of width `width` (default 1). Input port `u`, output port `y`.
//! [`Block::lti`] returns the exact discrete model that is simulated.

use crate::block::{BuildContext, Port, Tick, check};
use crate::doc::Params;
use crate::error::ParamError;
use crate::lti::{self, C2dMethod, LtiError, SosSection, SsStepper, StateSpace, TransferFunction};
use crate::{Block, Controller, declared_block};
use nalgebra::DMatrix;
use serde::{Deserialize, Serialize};
use std::f64::consts::PI;

/// Discretisation of a continuous model in a block (YAML `tustin` or `zoh`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, Params)]
#[serde(rename_all = "snake_case")]
pub enum Discretisation {
    /// Bilinear (Tustin) transform, optionally pre-warped (`prewarp_hz`):
    /// preserves stability and the frequency axis shape; for controllers and
    /// filters.
    Tustin,
    /// Zero-order hold: exact for inputs held over the sample; for plants.
    Zoh,
}

fn one() -> usize {
    1
}

fn lti_to_param(field: &str, e: LtiError) -> ParamError {
    ParamError::new(field, e.to_string(), "check the model coefficients")
}

/// Runtime of a linear block: one discrete SISO (or one MIMO) model, one stepper
/// per channel.
#[derive(Debug, Clone)]
struct LinearCore {
    /// The discrete model of one channel (or the MIMO model).
    model: StateSpace,
    /// One stepper per channel.
    steppers: Vec<SsStepper>,
    /// Inputs and outputs per channel.
    m: usize,
    p: usize,
    feedthrough: bool,
}

impl LinearCore {
    fn new(model: StateSpace, channels: usize) -> Result<Self, LtiError> {
        let s = SsStepper::new(&model)?;
        Ok(Self {
            m: model.ninputs(),
            p: model.noutputs(),
            feedthrough: model.has_feedthrough(),
            steppers: vec![s; channels],
            model,
        })
    }

    /// Phase 1. With feed-through the state is also advanced here (the scheduler
    /// calls `update` only for blocks without feed-through).
    #[inline(always)]
    fn output(&mut self, u: &[f64], y: &mut [f64]) {
        if let [s] = self.steppers.as_mut_slice() {
            // One channel: its input and output are the whole `u` and `y`.
            if self.feedthrough {
                s.step(u, y);
            } else {
                s.output(&[], y);
            }
            return;
        }
        self.output_channels(u, y);
    }

    /// [`LinearCore::output`] of several channels (out of line: the
    /// one-channel case is what the blocks inline).
    #[inline(never)]
    fn output_channels(&mut self, u: &[f64], y: &mut [f64]) {
        let (m, p) = (self.m, self.p);
        for (i, s) in self.steppers.iter_mut().enumerate() {
            let yi = &mut y[i * p..(i + 1) * p];
            if self.feedthrough {
                s.step(&u[i * m..(i + 1) * m], yi);
            } else {
                s.output(&[], yi);
            }
        }
    }

    /// Phase 2 (no feed-through only).
    #[inline(always)]
    fn update(&mut self, u: &[f64]) {
        if self.feedthrough {
            return;
        }
        if let [s] = self.steppers.as_mut_slice() {
            s.update(u);
            return;
        }
        self.update_channels(u);
    }

    /// [`LinearCore::update`] of several channels.
    #[inline(never)]
    fn update_channels(&mut self, u: &[f64]) {
        let m = self.m;
        for (i, s) in self.steppers.iter_mut().enumerate() {
            s.update(&u[i * m..(i + 1) * m]);
        }
    }

    fn reset(&mut self) {
        for s in &mut self.steppers {
            s.reset();
        }
    }

    /// Take the coefficients of the cascade `sos` (the structure it was built
    /// with: [`lti::sos_realise_into`]), every channel's delay lines kept. No
    /// allocation unless it refuses; on a refusal of the model the core is
    /// unchanged, on one of a stepper (a cascade that would gain feed-through)
    /// the model has changed and the caller re-applies the cascade it had.
    fn retune(&mut self, sos: &[SosSection]) -> Result<(), LtiError> {
        lti::sos_realise_into(sos, &mut self.model)?;
        for s in &mut self.steppers {
            s.set_coefficients(&self.model)?;
        }
        Ok(())
    }

    /// The model of all channels (block diagonal).
    fn lti(&self) -> StateSpace {
        if self.steppers.len() == 1 {
            return self.model.clone();
        }
        lti::append(&vec![self.model.clone(); self.steppers.len()])
            .unwrap_or_else(|_| self.model.clone())
    }
}

/// Parse a row-major matrix given as a list of rows.
fn matrix_from_rows(
    field: &str,
    rows: &[Vec<f64>],
    nrows: usize,
    ncols: usize,
) -> Result<DMatrix<f64>, ParamError> {
    if rows.len() != nrows && !((nrows == 0 || ncols == 0) && rows.iter().all(|r| r.is_empty())) {
        return Err(ParamError::new(
            field,
            format!("has {} rows, expected {nrows}", rows.len()),
            format!("give {nrows} rows of {ncols} numbers each"),
        ));
    }
    let mut m = DMatrix::zeros(nrows, ncols);
    for (i, r) in rows.iter().enumerate().take(nrows) {
        if r.len() != ncols {
            return Err(ParamError::new(
                format!("{field}[{i}]"),
                format!("has {} entries, expected {ncols}", r.len()),
                format!("give {ncols} numbers per row of `{field}`"),
            ));
        }
        check::all_finite(&format!("{field}[{i}]"), r)?;
        for (j, v) in r.iter().enumerate() {
            m[(i, j)] = *v;
        }
    }
    Ok(m)
}

/// Resolve the continuous-time discretisation fields.
fn c2d_method(
    discrete: bool,
    discretisation: Option<Discretisation>,
    prewarp_hz: Option<f64>,
    dt: f64,
) -> Result<Option<C2dMethod>, ParamError> {
    if discrete {
        if discretisation.is_some() {
            return Err(ParamError::new(
                "discretisation",
                "is given but the model is already discrete (`discrete: true`)",
                "remove `discretisation`, or set `discrete: false` for a continuous model",
            ));
        }
        if prewarp_hz.is_some() {
            return Err(ParamError::new(
                "prewarp_hz",
                "is given for a discrete model",
                "remove `prewarp_hz`",
            ));
        }
        return Ok(None);
    }
    let Some(method) = discretisation else {
        return Err(ParamError::new(
            "discretisation",
            "is missing for a continuous model",
            "add `discretisation: tustin` (controllers, filters) or `discretisation: zoh` (plants), or `discrete: true` if the coefficients are in z",
        ));
    };
    if let Some(f) = prewarp_hz {
        // > 0 is declared on the field (`#[param(positive)]`); below Nyquist is
        // checked here rather than by `below_nyquist` because it applies only
        // once the model is known to be continuous (the errors above come first)
        check::below_nyquist("prewarp_hz", f, dt)?;
    }
    match method {
        Discretisation::Zoh => {
            if prewarp_hz.is_some() {
                return Err(ParamError::new(
                    "prewarp_hz",
                    "only applies to `discretisation: tustin`",
                    "remove `prewarp_hz` or use tustin",
                ));
            }
            Ok(Some(C2dMethod::Zoh))
        }
        Discretisation::Tustin => Ok(Some(C2dMethod::Tustin { prewarp_hz })),
    }
}

macro_rules! core_steps {
    () => {
        fn output(&mut self, _tick: Tick, u: &[f64], y: &mut [f64]) {
            if let Some(c) = self.core.as_mut() {
                c.output(u, y);
            }
        }
        fn update(&mut self, _tick: Tick, u: &[f64]) {
            if let Some(c) = self.core.as_mut() {
                c.update(u);
            }
        }
        fn lti(&self) -> Option<StateSpace> {
            self.core.as_ref().map(|c| c.lti())
        }
    };
}

/// Most second-order sections of a filter block: a `low_pass` of
/// [`MAX_LOW_PASS_ORDER`].
const MAX_SECTIONS: usize = MAX_LOW_PASS_ORDER.div_ceil(2);

/// A filter block realised as a cascade of second-order sections in direct
/// form II transposed (`low_pass`, `notch`, `lead_lag`). Its
/// [`design`](SectionFilter::design) is the one function both
/// [`Block::build`] and a live change call: the block's own checks, then the
/// closed-form discrete sections.
trait SectionFilter {
    /// The block's checks at period `dt` (s), then its sections written into
    /// `out`; their number. Allocation-free unless it refuses.
    fn design(&self, dt: f64, out: &mut [SosSection]) -> Result<usize, ParamError>;
    /// The parameter behind live slot `slot` ([`Block::live_params`]).
    fn live_slot(&mut self, slot: usize) -> Option<&mut f64>;
    /// The running core (after [`Block::build`]).
    fn core_mut(&mut self) -> Option<&mut LinearCore>;
    /// Number of channels.
    fn channels(&self) -> usize;

    /// The core of the design at period `dt` (s): [`Block::build`].
    fn build_core(&self, dt: f64) -> Result<LinearCore, ParamError> {
        let mut sos = [[0.0; 6]; MAX_SECTIONS];
        let n = self.design(dt, &mut sos)?;
        let model = lti::sos2ss(&sos[..n], dt).map_err(|e| lti_to_param("order", e))?;
        LinearCore::new(model, self.channels()).map_err(|e| lti_to_param("order", e))
    }

    /// The running core re-designed from the parameters as they are, its
    /// delay lines kept. Allocation-free unless it refuses.
    fn redesign(&mut self) -> Result<(), ParamError> {
        let Some(dt) = self.core_mut().and_then(|c| c.model.dt) else {
            return Ok(()); // not built: `build` designs it
        };
        let mut sos = [[0.0; 6]; MAX_SECTIONS];
        let n = self.design(dt, &mut sos)?;
        if let Some(core) = self.core_mut() {
            core.retune(&sos[..n])
                .map_err(|e| lti_to_param("order", e))?;
        }
        Ok(())
    }

    /// [`Block::set_live_param`]: live parameter `slot` to `value` and the
    /// sections re-designed, the delay lines kept; a value the design
    /// refuses leaves the block as it was (the sender refuses it first,
    /// building a copy of the block with it).
    fn set_live(&mut self, slot: usize, value: f64) {
        let Some(old) = self.live_slot(slot).map(|p| std::mem::replace(p, value)) else {
            return;
        };
        if self.redesign().is_err() {
            if let Some(p) = self.live_slot(slot) {
                *p = old;
            }
            // The design it ran with, which passed before.
            let _ = self.redesign();
        }
    }
}

macro_rules! controller_impl {
    ($t:ty) => {
        impl Controller for $t {
            /// One sample of the filter (call [`Block::build`] first).
            fn control(&mut self, e: &[f64], u: &mut [f64]) {
                if let Some(c) = self.core.as_mut() {
                    c.output(e, u);
                    c.update(e);
                }
            }
            fn reset(&mut self) {
                if let Some(c) = self.core.as_mut() {
                    c.reset();
                }
            }
        }
    };
}

// ---------------------------------------------------------------------------
// transfer_function

/// `transfer_function`: a SISO transfer function num/den, continuous in s
/// (discretised at the block's rate by Tustin or ZOH) or discrete in z
/// (`discrete: true`), applied to each of `width` channels, realised as a series
/// cascade of first/second-order sections built from the poles and zeros, in
/// state space.
#[derive(Debug, Clone, Serialize, Deserialize, Params)]
#[serde(deny_unknown_fields)]
#[block(type_name = "transfer_function", role = Math, ports = "u[width] -> y[width]")]
pub struct TransferFunctionBlock {
    /// Numerator coefficients, highest power of s (or z) first.
    #[param(len(1, MAX_TF_ORDER + 1), finite, hint = "highest power first")]
    pub num: Vec<f64>,
    /// Denominator coefficients, highest power of s (or z) first.
    #[param(len(1, MAX_TF_ORDER + 1), finite, hint = "highest power first")]
    pub den: Vec<f64>,
    /// `true` if `num`/`den` are in z at the block's rate (else in s).
    #[serde(default)]
    pub discrete: bool,
    /// `tustin` or `zoh`; required for a continuous model.
    #[serde(default)]
    pub discretisation: Option<Discretisation>,
    /// Tustin pre-warp frequency (Hz), where the discrete response matches the
    /// continuous one exactly.
    #[serde(default)]
    #[param(positive)]
    pub prewarp_hz: Option<f64>,
    /// Number of independent channels.
    #[serde(default = "one")]
    #[param(width)]
    pub width: usize,
    #[serde(skip)]
    core: Option<LinearCore>,
}

impl TransferFunctionBlock {
    /// A continuous transfer function num(s)/den(s) discretised by `method`.
    pub fn continuous(num: Vec<f64>, den: Vec<f64>, method: Discretisation) -> Self {
        Self {
            num,
            den,
            discrete: false,
            discretisation: Some(method),
            prewarp_hz: None,
            width: 1,
            core: None,
        }
    }
    /// A discrete transfer function num(z)/den(z) at the block's rate.
    pub fn discrete(num: Vec<f64>, den: Vec<f64>) -> Self {
        Self {
            num,
            den,
            discrete: true,
            discretisation: None,
            prewarp_hz: None,
            width: 1,
            core: None,
        }
    }
}

/// Highest order of a `transfer_function` (coefficients per polynomial: 65). Its
/// roots are found by a dense eigenvalue problem at build; higher orders are
/// numerically meaningless as polynomials (write them as `state_space` or
/// cascades).
pub const MAX_TF_ORDER: usize = 64;

/// Most states of a `state_space` block: 256 (its stepper is a dense
/// matrix–vector product per tick, and discretisation a dense exponential).
pub const MAX_SS_STATES: usize = 256;

#[declared_block]
impl Block for TransferFunctionBlock {
    core_steps!();

    fn direct_feedthrough(&self) -> bool {
        match &self.core {
            Some(c) => c.feedthrough,
            None => {
                // Before build: Tustin makes any model biproper; otherwise equal degrees.
                let n = lti::linalg::poly_trim(&self.num).len();
                let d = lti::linalg::poly_trim(&self.den).len();
                n == d || (!self.discrete && self.discretisation != Some(Discretisation::Zoh))
            }
        }
    }

    fn build(&mut self, ctx: &BuildContext) -> Result<(), ParamError> {
        self.check_params()?;
        if self.den.iter().all(|&v| v == 0.0) {
            return Err(ParamError::new(
                "den",
                "is zero",
                "give the denominator coefficients, highest power first",
            ));
        }
        let method = c2d_method(self.discrete, self.discretisation, self.prewarp_hz, ctx.dt)?;
        let dt = if self.discrete { Some(ctx.dt) } else { None };
        let tf =
            TransferFunction::new(self.num.clone(), self.den.clone(), dt).map_err(|e| match e {
                LtiError::Improper { num, den } => ParamError::new(
                    "num",
                    format!(
                        "numerator degree {num} exceeds denominator degree {den} (not realisable)"
                    ),
                    "add poles (e.g. a roll-off) so that deg num ≤ deg den",
                ),
                other => lti_to_param("den", other),
            })?;
        let cascade = tf.to_ss_cascade().map_err(|e| lti_to_param("den", e))?;
        let model = match method {
            None => cascade,
            Some(m) => lti::c2d(&cascade, ctx.dt, m).map_err(|e| lti_to_param("prewarp_hz", e))?,
        };
        self.core = Some(LinearCore::new(model, self.width).map_err(|e| lti_to_param("den", e))?);
        Ok(())
    }
}
controller_impl!(TransferFunctionBlock);

// ---------------------------------------------------------------------------
// state_space

/// `state_space`: a MIMO state-space model x' = A x + B u, y = C x + D u, with the
/// matrices (A, B, C, D) given **row-major** as lists of rows; continuous
/// (discretised at the block's rate by tustin or zoh) or discrete
/// (`discrete: true`).
#[derive(Debug, Clone, Serialize, Deserialize, Params)]
#[serde(deny_unknown_fields)]
#[block(type_name = "state_space", role = Math, ports = "u[m] -> y[p]")]
pub struct StateSpaceBlock {
    /// A (n × n), list of n rows; at most 256 states.
    pub a: Vec<Vec<f64>>,
    /// B (n × m), list of n rows.
    pub b: Vec<Vec<f64>>,
    /// C (p × n), list of p rows.
    pub c: Vec<Vec<f64>>,
    /// D (p × m), list of p rows.
    #[serde(default)]
    #[param(default_doc = "zero (p × m)")]
    pub d: Vec<Vec<f64>>,
    /// `true` if the model is already discrete at the block's rate.
    #[serde(default)]
    pub discrete: bool,
    /// `tustin` or `zoh`; required for a continuous model.
    #[serde(default)]
    pub discretisation: Option<Discretisation>,
    /// Tustin pre-warp frequency (Hz).
    #[serde(default)]
    #[param(positive)]
    pub prewarp_hz: Option<f64>,
    /// Calibration gain g on the input: B, D ← g·B, g·D. Fitted by
    /// `nanomotion diagnose`'s nominal calibration (see [`crate::Tunable`]).
    #[serde(default = "unity", skip_serializing_if = "is_unity")]
    #[param(positive)]
    pub gain: f64,
    /// Calibration time scale λ of a continuous model: A, B ← λA, λB, i.e.
    /// G(s) ← G(s/λ) — every mode's frequency × λ, damping ratios and static
    /// gain unchanged (must stay 1 for a discrete model).
    #[serde(default = "unity", skip_serializing_if = "is_unity")]
    #[param(positive)]
    pub frequency_scale: f64,
    /// Calibration damping scale d of a continuous model: every complex pole
    /// pair σ ± jω_d moves to d·σ ± jω_d (decay rate, so damping ratio, × d;
    /// eigenvectors and residues kept, see `lti::linalg::rescale_modes`)
    /// (must stay 1 for a discrete model).
    #[serde(default = "unity", skip_serializing_if = "is_unity")]
    #[param(positive)]
    pub damping_scale: f64,
    /// Calibration lag scale ℓ of a continuous model: every real pole p moves
    /// to ℓ·p (an amplifier's or sensor's lag × 1/ℓ; eigenvectors and residues
    /// kept) (must stay 1 for a discrete model).
    #[serde(default = "unity", skip_serializing_if = "is_unity")]
    #[param(positive)]
    pub lag_scale: f64,
    /// Calibration frequency scales of the 2nd, 3rd and 4th complex pole pair
    /// (ranked by natural frequency) of a continuous model, each relative to
    /// the time scale: that mode's own time scale — its poles × the scale,
    /// damping ratio and static contribution kept (see
    /// `lti::linalg::rescale_modes_each`); missing entries are 1 (must stay 1
    /// for a discrete model).
    #[serde(default, skip_serializing_if = "all_unity")]
    #[param(positive)]
    pub mode_frequency_scales: Vec<f64>,
    /// Calibration damping scales of the 2nd, 3rd and 4th complex pole pair
    /// (ranked by natural frequency) of a continuous model, each relative to
    /// the damping scale: that mode's own decay rate × the scale (see
    /// `lti::linalg::rescale_modes_each`); missing entries are 1 (must stay 1
    /// for a discrete model).
    #[serde(default, skip_serializing_if = "all_unity")]
    #[param(positive)]
    pub mode_damping_scales: Vec<f64>,
    /// Calibration gain scales of the 2nd, 3rd and 4th complex pole pair
    /// (ranked by natural frequency) of a continuous model, each relative to
    /// the gain: that mode's residues × the scale, its share of the static
    /// gain with them (see `lti::linalg::rescale_modes_each`); missing entries
    /// are 1 (must stay 1 for a discrete model).
    #[serde(default, skip_serializing_if = "all_unity")]
    #[param(positive)]
    pub mode_gain_scales: Vec<f64>,
    #[serde(skip)]
    core: Option<LinearCore>,
    /// The sample period the block was built for (re-realised by `set_params`).
    #[serde(skip)]
    built_dt: Option<f64>,
}

fn unity() -> f64 {
    1.0
}

fn is_unity(v: &f64) -> bool {
    *v == 1.0
}

fn all_unity(v: &[f64]) -> bool {
    v.iter().all(is_unity)
}

/// The calibration names of the pairs after the first that carry their own
/// frequency scale (`mode_frequency_scales`, in order): at most three, since
/// modes far above the first are weakly seen in a record and each scale
/// costs the fit runs and the score a parameter.
const MODE_SCALE_NAMES: [&str; 3] = [
    "mode_2_frequency_scale",
    "mode_3_frequency_scale",
    "mode_4_frequency_scale",
];

/// The same pairs' own damping scales (`mode_damping_scales`, in order).
const MODE_DAMPING_NAMES: [&str; 3] = [
    "mode_2_damping_scale",
    "mode_3_damping_scale",
    "mode_4_damping_scale",
];

/// The same pairs' own gain scales (`mode_gain_scales`, in order).
const MODE_GAIN_NAMES: [&str; 3] = [
    "mode_2_gain_scale",
    "mode_3_gain_scale",
    "mode_4_gain_scale",
];

impl StateSpaceBlock {
    /// A block running the model `sys` (continuous models are discretised with
    /// `method` at build time; ignored for discrete models). A discrete `sys` must
    /// have the block's sample period.
    pub fn from_model(sys: &StateSpace, method: Option<Discretisation>) -> Self {
        let rows = |m: &DMatrix<f64>| {
            (0..m.nrows())
                .map(|i| m.row(i).iter().copied().collect())
                .collect()
        };
        Self {
            a: rows(&sys.a),
            b: rows(&sys.b),
            c: rows(&sys.c),
            d: rows(&sys.d),
            discrete: sys.dt.is_some(),
            discretisation: if sys.dt.is_some() { None } else { method },
            prewarp_hz: None,
            gain: 1.0,
            frequency_scale: 1.0,
            damping_scale: 1.0,
            lag_scale: 1.0,
            mode_frequency_scales: Vec::new(),
            mode_damping_scales: Vec::new(),
            mode_gain_scales: Vec::new(),
            core: None,
            built_dt: None,
        }
    }

    /// Check the matrices and the calibration, discretise at `dt` and set up the
    /// stepper (what `build` and `set_params` share).
    fn realise(&mut self, dt: f64) -> Result<(), ParamError> {
        let (n, m, p) = self.dims();
        check::size("a (states)", n, 0, MAX_SS_STATES)?;
        check::width("b (inputs)", m.max(1))?;
        check::width("c (outputs)", p.max(1))?;
        if m == 0 || p == 0 {
            return Err(ParamError::new(
                if n > 0 { "b" } else { "d" },
                "gives no inputs or no outputs",
                "give B (n×m) and C (p×n) with m, p ≥ 1 (or D for a static gain)",
            ));
        }
        self.check_params()?;
        let mode_scales = (self.mode_frequency_scales.iter())
            .map(|&v| ("mode_frequency_scales", v))
            .chain((self.mode_damping_scales.iter()).map(|&v| ("mode_damping_scales", v)))
            .chain((self.mode_gain_scales.iter()).map(|&v| ("mode_gain_scales", v)));
        for (name, v) in self.continuous_scales().into_iter().chain(mode_scales) {
            if self.discrete && v != 1.0 {
                return Err(ParamError::new(
                    name,
                    format!("is {v} on a discrete model"),
                    "remove it (a time, damping or lag scale applies to a continuous model only)",
                ));
            }
        }
        let lambda = self.frequency_scale;
        let a_raw = matrix_from_rows("a", &self.a, n, n)?;
        let pairs = self.pair_scales();
        let (a, input_map) =
            lti::linalg::rescale_modes_each(&a_raw, self.damping_scale, self.lag_scale, &pairs)
                .ok_or_else(|| {
                    ParamError::new(
                        "damping_scale",
                        "A's modes cannot be moved (a repeated mode: A is not diagonalisable)",
                        "keep damping_scale, lag_scale and the mode scales at 1 for this model",
                    )
                })?;
        let a = a * lambda;
        let b = input_map * matrix_from_rows("b", &self.b, n, m)? * (lambda * self.gain);
        let c = matrix_from_rows("c", &self.c, p, n)?;
        let d = if self.d.is_empty() {
            DMatrix::zeros(p, m)
        } else {
            matrix_from_rows("d", &self.d, p, m)? * self.gain
        };
        let method = c2d_method(self.discrete, self.discretisation, self.prewarp_hz, dt)?;
        let sys = StateSpace::new(a, b, c, d, if self.discrete { Some(dt) } else { None })
            .map_err(|e| lti_to_param("a", e))?;
        let model = match method {
            None => sys,
            Some(mth) => lti::c2d(&sys, dt, mth).map_err(|e| lti_to_param("a", e))?,
        };
        if model.a.iter().chain(model.b.iter()).any(|v| !v.is_finite()) {
            return Err(ParamError::new(
                "a",
                "discretisation gave non-finite matrices",
                "check A for poles at s = 2/T (Tustin)",
            ));
        }
        self.core = Some(LinearCore::new(model, 1).map_err(|e| lti_to_param("a", e))?);
        self.built_dt = Some(dt);
        Ok(())
    }

    /// The calibration scales of a continuous model, by field name.
    fn continuous_scales(&self) -> [(&'static str, f64); 3] {
        [
            ("frequency_scale", self.frequency_scale),
            ("damping_scale", self.damping_scale),
            ("lag_scale", self.lag_scale),
        ]
    }

    /// The pairs after the first, each with its own scales (1 where none is
    /// given).
    fn pair_scales(&self) -> Vec<lti::linalg::PairScale> {
        let n = (self.mode_frequency_scales.len())
            .max(self.mode_damping_scales.len())
            .max(self.mode_gain_scales.len());
        let at = |v: &[f64], j: usize| v.get(j).copied().unwrap_or(1.0);
        (0..n)
            .map(|j| lti::linalg::PairScale {
                frequency: at(&self.mode_frequency_scales, j),
                damping: at(&self.mode_damping_scales, j),
                gain: at(&self.mode_gain_scales, j),
            })
            .collect()
    }

    /// The calibration parameters this model offers: the gain always; the
    /// time scale of a continuous model; its damping scale when it has a
    /// complex pole pair; its lag scale when it has real poles beside
    /// complex ones (with real poles alone the time scale moves them); a
    /// frequency scale for each pair after the first (up to the fourth), then
    /// a damping scale for each of them.
    fn calibration_names(&self) -> Vec<&'static str> {
        let mut v = vec!["gain"];
        if self.discrete {
            return v;
        }
        v.push("frequency_scale");
        let n = self.a.len();
        if let Ok(a) = matrix_from_rows("a", &self.a, n, n) {
            let kinds = lti::linalg::mode_kinds(&a);
            if kinds.oscillatory {
                v.push("damping_scale");
                if kinds.lag {
                    v.push("lag_scale");
                }
                let higher = kinds.pairs.saturating_sub(1).min(MODE_SCALE_NAMES.len());
                v.extend_from_slice(&MODE_SCALE_NAMES[..higher]);
                v.extend_from_slice(&MODE_DAMPING_NAMES[..higher]);
                v.extend_from_slice(&MODE_GAIN_NAMES[..higher]);
            }
        }
        v
    }

    fn calibration_slot(&mut self, name: &str) -> &mut f64 {
        for (names, scales) in [
            (&MODE_SCALE_NAMES, &mut self.mode_frequency_scales),
            (&MODE_DAMPING_NAMES, &mut self.mode_damping_scales),
            (&MODE_GAIN_NAMES, &mut self.mode_gain_scales),
        ] {
            if let Some(j) = names.iter().position(|&n| n == name) {
                if scales.len() <= j {
                    scales.resize(j + 1, 1.0);
                }
                return &mut scales[j];
            }
        }
        match name {
            "frequency_scale" => &mut self.frequency_scale,
            "damping_scale" => &mut self.damping_scale,
            "lag_scale" => &mut self.lag_scale,
            _ => &mut self.gain,
        }
    }

    fn dims(&self) -> (usize, usize, usize) {
        let n = self.a.len();
        let m = if n > 0 {
            self.b.first().map_or(0, |r| r.len())
        } else {
            self.d.first().map_or(0, |r| r.len())
        };
        let p = if n > 0 { self.c.len() } else { self.d.len() };
        (n, m, p)
    }
}

#[declared_block]
impl Block for StateSpaceBlock {
    fn inputs(&self) -> Vec<Port> {
        vec![Port::new("u", self.dims().1)]
    }
    fn outputs(&self) -> Vec<Port> {
        vec![Port::new("y", self.dims().2)]
    }
    core_steps!();

    fn direct_feedthrough(&self) -> bool {
        match &self.core {
            Some(c) => c.feedthrough,
            None => {
                self.d.iter().flatten().any(|&v| v != 0.0)
                    || (!self.discrete && self.discretisation != Some(Discretisation::Zoh))
            }
        }
    }

    fn build(&mut self, ctx: &BuildContext) -> Result<(), ParamError> {
        self.realise(ctx.dt)
    }

    fn tunable(&self) -> Option<&dyn crate::Tunable> {
        Some(self)
    }
    fn tunable_mut(&mut self) -> Option<&mut dyn crate::Tunable> {
        Some(self)
    }
}
controller_impl!(StateSpaceBlock);

/// The calibration of a plant model: `[gain]` for a discrete model; for a
/// continuous one `[gain, frequency_scale]`, then `damping_scale` when it has
/// a complex pole pair, `lag_scale` when it also has real poles,
/// `mode_K_frequency_scale` for its pairs K = 2…4 and then
/// `mode_K_damping_scale` for the same pairs (see the fields). A built block is re-realised at once (outside any tick: it
/// allocates).
impl crate::Tunable for StateSpaceBlock {
    fn param_names(&self) -> Vec<String> {
        self.calibration_names()
            .into_iter()
            .map(String::from)
            .collect()
    }
    fn params(&self) -> Vec<f64> {
        let mode = |names: &[&str; 3], scales: &[f64], n: &str| {
            let j = names.iter().position(|&m| m == n)?;
            Some(scales.get(j).copied().unwrap_or(1.0))
        };
        let value = |n: &str| {
            mode(&MODE_SCALE_NAMES, &self.mode_frequency_scales, n)
                .or_else(|| mode(&MODE_DAMPING_NAMES, &self.mode_damping_scales, n))
                .or_else(|| mode(&MODE_GAIN_NAMES, &self.mode_gain_scales, n))
                .unwrap_or_else(|| {
                    self.continuous_scales()
                        .iter()
                        .find(|(name, _)| *name == n)
                        .map_or(self.gain, |(_, v)| *v)
                })
        };
        self.calibration_names().into_iter().map(value).collect()
    }
    fn set_params(&mut self, p: &[f64]) -> Result<(), ParamError> {
        let names = self.calibration_names();
        if p.len() != names.len() {
            return Err(ParamError::new(
                "params",
                format!("{} values given", p.len()),
                format!("give [{}]", names.join(", ")),
            ));
        }
        let old: Vec<f64> = names.iter().map(|n| *self.calibration_slot(n)).collect();
        for (n, &v) in names.iter().zip(p) {
            *self.calibration_slot(n) = v;
        }
        let result = match self.built_dt {
            Some(dt) => self.realise(dt),
            None => self.check_params(),
        };
        if result.is_err() {
            for (n, &v) in names.iter().zip(&old) {
                *self.calibration_slot(n) = v;
            }
            if let Some(dt) = self.built_dt {
                self.realise(dt)?;
            }
        }
        result
    }
}

// ---------------------------------------------------------------------------
// low_pass

fn default_order() -> usize {
    2
}

/// `low_pass`: digital Butterworth low-pass of order `order` with −3 dB
/// frequency `cutoff_hz` (pre-warped bilinear design, unity DC gain,
/// [`lti::butter_lowpass_into`]), per channel, run as a cascade of
/// second-order sections in direct form II transposed.
///
/// `cutoff_hz` can change while the loop runs (`set lp.cutoff_hz=…`,
/// [`Block::live_params`]): the sections are re-designed in place by the
/// build's own checks and design, and every section keeps its delay line
/// (z₀, z₁). For one section (order ≤ 2) the output at the tick of the
/// change moves by (b₀′ − b₀)·u\[k\] (y = z₀ + b₀u), the state then evolves
/// under the new filter; a longer cascade also carries the change of the
/// later sections' b₀ on the earlier sections' outputs.
#[derive(Debug, Clone, Serialize, Deserialize, Params)]
#[serde(deny_unknown_fields)]
#[block(type_name = "low_pass", role = Math, ports = "u[width] -> y[width] [unit of u]", live = "cutoff_hz")]
pub struct LowPass {
    /// −3 dB frequency f_c in Hz.
    #[param(positive, below_nyquist)]
    pub cutoff_hz: f64,
    /// Filter order n.
    #[serde(default = "default_order")]
    #[param(size(1, MAX_LOW_PASS_ORDER))]
    pub order: usize,
    /// Number of independent channels.
    #[serde(default = "one")]
    #[param(width)]
    pub width: usize,
    #[serde(skip)]
    core: Option<LinearCore>,
}

impl LowPass {
    /// A Butterworth low-pass of `order` with cutoff `cutoff_hz` (Hz).
    pub fn new(order: usize, cutoff_hz: f64) -> Self {
        Self {
            cutoff_hz,
            order,
            width: 1,
            core: None,
        }
    }
}

/// Highest `low_pass` order: 16. Butterworth designs above that are numerically
/// poor and slow to build, and no loop in the thesis needs more than 4.
pub const MAX_LOW_PASS_ORDER: usize = 16;

#[declared_block]
impl Block for LowPass {
    core_steps!();

    fn build(&mut self, ctx: &BuildContext) -> Result<(), ParamError> {
        self.core = Some(self.build_core(ctx.dt)?);
        Ok(())
    }
    fn set_live_param(&mut self, slot: usize, value: f64) {
        self.set_live(slot, value);
    }
}

impl SectionFilter for LowPass {
    fn design(&self, dt: f64, out: &mut [SosSection]) -> Result<usize, ParamError> {
        self.check_params()?;
        self.check_at_rate(dt)?;
        lti::butter_lowpass_into(self.order, self.cutoff_hz, dt, out)
            .map_err(|e| lti_to_param("cutoff_hz", e))
    }
    fn live_slot(&mut self, slot: usize) -> Option<&mut f64> {
        (slot == 0).then_some(&mut self.cutoff_hz)
    }
    fn core_mut(&mut self) -> Option<&mut LinearCore> {
        self.core.as_mut()
    }
    fn channels(&self) -> usize {
        self.width
    }
}
controller_impl!(LowPass);

// ---------------------------------------------------------------------------
// notch

fn default_notch_damping() -> f64 {
    0.1
}

/// `notch`: second-order notch
/// N(s) = (s² + 2·depth·ζ·ω₀ s + ω₀²)/(s² + 2ζω₀ s + ω₀²), ω₀ = 2π·centre_hz,
/// discretised by Tustin pre-warped at the centre ([`lti::tustin_section`]) so
/// that the discrete gain at `centre_hz` is exactly `depth` and the DC gain is
/// 1. Per channel, one second-order section in direct form II transposed.
///
/// `centre_hz`, `damping` and `depth` can change while the loop runs
/// ([`Block::live_params`]): the section is re-designed in place by the
/// build's own checks and design, its delay line (z₀, z₁) kept, so the output
/// at the tick of the change moves by (b₀′ − b₀)·u\[k\] (y = z₀ + b₀u) and
/// the state then evolves under the new notch.
#[derive(Debug, Clone, Serialize, Deserialize, Params)]
#[serde(deny_unknown_fields)]
#[block(type_name = "notch", role = Math, ports = "u[width] -> y[width] [unit of u]", live = "centre_hz, damping, depth")]
pub struct Notch {
    /// Centre frequency f₀ in Hz.
    #[param(positive, below_nyquist)]
    pub centre_hz: f64,
    /// Damping ζ of the poles: the −3 dB width of a deep notch is about
    /// 2ζ·f₀ Hz.
    #[serde(default = "default_notch_damping")]
    #[param(positive)]
    pub damping: f64,
    /// Gain at the centre frequency: 0 removes f₀ completely (full notch), 0.1
    /// is −20 dB; > 1 gives a peak instead.
    #[serde(default)]
    #[param(non_negative)]
    pub depth: f64,
    /// Number of independent channels.
    #[serde(default = "one")]
    #[param(width)]
    pub width: usize,
    #[serde(skip)]
    core: Option<LinearCore>,
}

impl Notch {
    /// A notch at `centre_hz` (Hz) with pole damping `damping` and centre gain
    /// `depth`.
    pub fn new(centre_hz: f64, damping: f64, depth: f64) -> Self {
        Self {
            centre_hz,
            damping,
            depth,
            width: 1,
            core: None,
        }
    }

    /// The continuous prototype N(s): numerator and denominator, highest
    /// power of s first.
    fn prototype(&self) -> ([f64; 3], [f64; 3]) {
        let w = 2.0 * PI * self.centre_hz;
        (
            [1.0, 2.0 * self.depth * self.damping * w, w * w],
            [1.0, 2.0 * self.damping * w, w * w],
        )
    }

    /// The continuous prototype N(s).
    pub fn continuous_model(&self) -> TransferFunction {
        let (num, den) = self.prototype();
        TransferFunction {
            num: num.to_vec(),
            den: den.to_vec(),
            dt: None,
        }
    }
}

#[declared_block]
impl Block for Notch {
    core_steps!();

    fn build(&mut self, ctx: &BuildContext) -> Result<(), ParamError> {
        self.core = Some(self.build_core(ctx.dt)?);
        Ok(())
    }
    fn set_live_param(&mut self, slot: usize, value: f64) {
        self.set_live(slot, value);
    }
}

impl SectionFilter for Notch {
    fn design(&self, dt: f64, out: &mut [SosSection]) -> Result<usize, ParamError> {
        self.check_params()?;
        self.check_at_rate(dt)?;
        let (num, den) = self.prototype();
        out[0] = lti::tustin_section(num, den, dt, Some(self.centre_hz))
            .map_err(|e| lti_to_param("centre_hz", e))?;
        Ok(1)
    }
    fn live_slot(&mut self, slot: usize) -> Option<&mut f64> {
        match slot {
            0 => Some(&mut self.centre_hz),
            1 => Some(&mut self.damping),
            2 => Some(&mut self.depth),
            _ => None,
        }
    }
    fn core_mut(&mut self) -> Option<&mut LinearCore> {
        self.core.as_mut()
    }
    fn channels(&self) -> usize {
        self.width
    }
}
controller_impl!(Notch);

// ---------------------------------------------------------------------------
// lead_lag

fn default_gain() -> f64 {
    1.0
}

/// `lead_lag`: C(s) = gain·(1 + s/ω_z)/(1 + s/ω_p), ω_z = 2π·zero_hz,
/// ω_p = 2π·pole_hz (a lead for zero_hz < pole_hz, a lag otherwise), discretised
/// by Tustin pre-warped at `prewarp_hz` (default: the geometric mean
/// √(zero_hz·pole_hz), where a lead's phase peaks, if that is below Nyquist;
/// otherwise plain Tustin; [`lti::tustin_section`]). DC gain `gain`. Per
/// channel, one first-order section in direct form II transposed.
///
/// `zero_hz` and `pole_hz` can change while the loop runs
/// ([`Block::live_params`]; the default pre-warp frequency follows them): the
/// section is re-designed in place by the build's own checks and design, its
/// delay line z₀ kept, so the output at the tick of the change moves by
/// (b₀′ − b₀)·u\[k\] (y = z₀ + b₀u).
#[derive(Debug, Clone, Serialize, Deserialize, Params)]
#[serde(deny_unknown_fields)]
#[block(type_name = "lead_lag", role = Controller, ports = "u[width] -> y[width]", live = "zero_hz, pole_hz")]
pub struct LeadLag {
    /// Zero frequency (Hz).
    #[param(positive)]
    pub zero_hz: f64,
    /// Pole frequency (Hz).
    #[param(positive)]
    pub pole_hz: f64,
    /// DC gain (-).
    #[serde(default = "default_gain")]
    #[param(finite)]
    pub gain: f64,
    /// Tustin pre-warp frequency (Hz).
    #[serde(default)]
    #[param(
        positive,
        below_nyquist,
        default_doc = "√(zero_hz·pole_hz) if below Nyquist, else plain Tustin"
    )]
    pub prewarp_hz: Option<f64>,
    /// Number of independent channels.
    #[serde(default = "one")]
    #[param(width)]
    pub width: usize,
    #[serde(skip)]
    core: Option<LinearCore>,
}

impl LeadLag {
    /// A lead/lag with zero and pole at `zero_hz`, `pole_hz` (Hz) and DC gain
    /// `gain`.
    pub fn new(zero_hz: f64, pole_hz: f64, gain: f64) -> Self {
        Self {
            zero_hz,
            pole_hz,
            gain,
            prewarp_hz: None,
            width: 1,
            core: None,
        }
    }

    /// The continuous prototype C(s): numerator and denominator, highest
    /// power of s first (a first-order section: no s²).
    fn prototype(&self) -> ([f64; 3], [f64; 3]) {
        let wz = 2.0 * PI * self.zero_hz;
        let wp = 2.0 * PI * self.pole_hz;
        ([0.0, self.gain / wz, self.gain], [0.0, 1.0 / wp, 1.0])
    }

    /// The continuous prototype C(s).
    pub fn continuous_model(&self) -> TransferFunction {
        let (num, den) = self.prototype();
        TransferFunction {
            num: num[1..].to_vec(),
            den: den[1..].to_vec(),
            dt: None,
        }
    }

    /// The pre-warp frequency actually used at period `dt` (s).
    pub fn effective_prewarp_hz(&self, dt: f64) -> Option<f64> {
        self.prewarp_hz.or_else(|| {
            let f = (self.zero_hz * self.pole_hz).sqrt();
            (f < 0.5 / dt).then_some(f)
        })
    }
}

#[declared_block]
impl Block for LeadLag {
    core_steps!();

    fn build(&mut self, ctx: &BuildContext) -> Result<(), ParamError> {
        self.core = Some(self.build_core(ctx.dt)?);
        Ok(())
    }
    fn set_live_param(&mut self, slot: usize, value: f64) {
        self.set_live(slot, value);
    }
}

impl SectionFilter for LeadLag {
    fn design(&self, dt: f64, out: &mut [SosSection]) -> Result<usize, ParamError> {
        self.check_params()?;
        self.check_at_rate(dt)?;
        let (num, den) = self.prototype();
        out[0] = lti::tustin_section(num, den, dt, self.effective_prewarp_hz(dt))
            .map_err(|e| lti_to_param("pole_hz", e))?;
        Ok(1)
    }
    fn live_slot(&mut self, slot: usize) -> Option<&mut f64> {
        match slot {
            0 => Some(&mut self.zero_hz),
            1 => Some(&mut self.pole_hz),
            _ => None,
        }
    }
    fn core_mut(&mut self) -> Option<&mut LinearCore> {
        self.core.as_mut()
    }
    fn channels(&self) -> usize {
        self.width
    }
}
controller_impl!(LeadLag);

// ---------------------------------------------------------------------------
// delay

/// `delay`: pure delay y\[k\] = u\[k − d\] of `d` samples (z^-d) per channel, run as a
/// ring buffer (O(1) per sample for any d). No direct feed-through for d ≥ 1, so
/// it breaks algebraic loops.
#[derive(Debug, Clone, Serialize, Deserialize, Params)]
#[serde(deny_unknown_fields)]
#[block(type_name = "delay", role = Math, ports = "u[width] -> y[width] [unit of u]")]
pub struct Delay {
    /// Delay d in samples of the block's rate; d · width ≤ 2^24.
    pub d: usize,
    /// Number of independent channels.
    #[serde(default = "one")]
    #[param(width)]
    pub width: usize,
    #[serde(skip)]
    buf: Vec<f64>,
    #[serde(skip)]
    head: usize,
    #[serde(skip)]
    dt: f64,
}

impl Delay {
    /// A delay of `d` samples.
    pub fn new(d: usize) -> Self {
        Self {
            d,
            width: 1,
            buf: Vec::new(),
            head: 0,
            dt: 0.0,
        }
    }
}

/// Largest `d · width` for which a `delay` block reports a (dense) LTI model.
pub const MAX_DENSE_DELAY_STATES: usize = 512;

#[declared_block]
impl Block for Delay {
    fn direct_feedthrough(&self) -> bool {
        self.d == 0
    }

    fn memory_bytes(&self) -> usize {
        self.buf.len() * std::mem::size_of::<f64>()
    }

    fn planned_bytes(&self, _dt: f64) -> (&'static str, usize) {
        let values = self.d.saturating_mul(self.width);
        ("d", values.saturating_mul(std::mem::size_of::<f64>()))
    }

    fn build(&mut self, ctx: &BuildContext) -> Result<(), ParamError> {
        self.check_params()?;
        check::buffer("d", self.d, 0, self.width)?;
        self.buf = vec![0.0; self.d * self.width];
        self.head = 0;
        self.dt = ctx.dt;
        Ok(())
    }

    fn output(&mut self, _tick: Tick, u: &[f64], y: &mut [f64]) {
        let w = self.width;
        if self.d == 0 {
            y[..w].copy_from_slice(&u[..w]);
        } else {
            y[..w].copy_from_slice(&self.buf[self.head * w..(self.head + 1) * w]);
        }
    }

    fn update(&mut self, _tick: Tick, u: &[f64]) {
        if self.d == 0 {
            return;
        }
        let w = self.width;
        self.buf[self.head * w..(self.head + 1) * w].copy_from_slice(&u[..w]);
        self.head += 1;
        if self.head == self.d {
            self.head = 0;
        }
    }

    /// The dense shift-register model, for delays of at most
    /// [`MAX_DENSE_DELAY_STATES`] states in all (a longer delay has no LTI model
    /// here: its dense matrices would be quadratic in `d`).
    fn lti(&self) -> Option<StateSpace> {
        if self.dt <= 0.0 || self.d.saturating_mul(self.width) > MAX_DENSE_DELAY_STATES {
            return None;
        }
        lti::append(&vec![lti::delay(self.d, self.dt); self.width]).ok()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::lti::Complex;

    const DT: f64 = 1.0 / 4000.0;

    fn yaml(text: &str) -> Box<dyn Block> {
        crate::yaml::from_str::<Box<dyn Block>>(text, "test").unwrap()
    }

    fn built(text: &str) -> Box<dyn Block> {
        let mut b = yaml(text);
        b.build(&BuildContext::new("b", DT, 0)).unwrap();
        b
    }

    fn build_err(text: &str) -> ParamError {
        let mut b = yaml(text);
        b.build(&BuildContext::new("b", DT, 0)).unwrap_err()
    }

    /// Drive a (single-channel-width) block with `u` per sample, the way the
    /// scheduler does; returns the first output.
    fn run(b: &mut dyn Block, u: &[Vec<f64>]) -> Vec<Vec<f64>> {
        let p: usize = b.outputs().iter().map(|p| p.width).sum();
        let ft = b.direct_feedthrough();
        u.iter()
            .enumerate()
            .map(|(k, uk)| {
                let mut y = vec![0.0; p];
                let t = Tick::new(k as u64, DT);
                b.output(t, uk, &mut y);
                if !ft {
                    b.update(t, uk);
                }
                y
            })
            .collect()
    }

    fn run_siso(b: &mut dyn Block, u: &[f64]) -> Vec<f64> {
        run(b, &u.iter().map(|&v| vec![v]).collect::<Vec<_>>())
            .into_iter()
            .map(|y| y[0])
            .collect()
    }

    /// Amplitude and phase of the steady-state response to a sine at `f_hz`, by
    /// simulation and projection on the last whole periods.
    fn sine_response(b: &mut dyn Block, f_hz: f64, n: usize) -> Complex<f64> {
        let w = 2.0 * PI * f_hz;
        let u: Vec<f64> = (0..n).map(|k| (w * k as f64 * DT).sin()).collect();
        let y = run_siso(b, &u);
        let start = n / 2;
        let (mut s, mut c) = (0.0, 0.0);
        for (k, yk) in y.iter().enumerate().skip(start) {
            let ph = w * k as f64 * DT;
            s += yk * ph.sin();
            c += yk * ph.cos();
        }
        let m = (n - start) as f64 / 2.0;
        Complex::new(s / m, c / m)
    }

    fn assert_model_matches_simulation(b: &mut dyn Block, freqs: &[f64]) {
        let model = b.lti().unwrap();
        assert_eq!(model.dt, Some(DT));
        assert_eq!(model.has_feedthrough(), b.direct_feedthrough());
        for &f in freqs {
            // 4000 samples at 4 kHz: integer periods for integer f.
            let got = sine_response(b, f, 8000);
            let want = model.freqresp_siso_at(2.0 * PI * f);
            assert!(
                (got - want).norm() < 2e-3 * want.norm().max(1e-3),
                "f = {f}: sim {got} model {want}"
            );
        }
    }

    #[test]
    fn low_pass_matches_butterworth_closed_form() {
        let mut b = built("type: low_pass\ncutoff_hz: 200\norder: 4\n");
        assert!(b.direct_feedthrough());
        let model = b.lti().unwrap();
        for &f in &[0.0, 50.0, 200.0, 600.0] {
            let r = (PI * f * DT).tan() / (PI * 200.0 * DT).tan();
            let want = 1.0 / (1.0 + r.powi(8)).sqrt();
            assert!((model.freqresp_siso_at(2.0 * PI * f).norm() - want).abs() < 1e-12);
        }
        b.build(&BuildContext::new("b", DT, 0)).unwrap();
        assert_model_matches_simulation(b.as_mut(), &[10.0, 200.0, 500.0]);
        // Step response settles at the DC gain 1.
        b.build(&BuildContext::new("b", DT, 0)).unwrap();
        let y = run_siso(b.as_mut(), &[1.0; 400]);
        assert!((y[399] - 1.0).abs() < 1e-9);
        assert_eq!(
            build_err("type: low_pass\ncutoff_hz: 2500\n").field,
            "cutoff_hz"
        );
        assert_eq!(
            build_err("type: low_pass\ncutoff_hz: 20\norder: 0\n").field,
            "order"
        );
    }

    #[test]
    fn notch_has_exact_depth_at_centre() {
        let mut b = built("type: notch\ncentre_hz: 527\ndamping: 0.1\ndepth: 0.1\n");
        let model = b.lti().unwrap();
        let g0 = model.freqresp_siso_at(2.0 * PI * 527.0);
        assert!((g0 - Complex::new(0.1, 0.0)).norm() < 1e-10, "{g0}");
        assert!((model.dcgain()[(0, 0)].re - 1.0).abs() < 1e-12);
        b.build(&BuildContext::new("b", DT, 0)).unwrap();
        assert_model_matches_simulation(b.as_mut(), &[100.0, 527.0, 1000.0]);
        assert_eq!(
            build_err("type: notch\ncentre_hz: 100\ndamping: -1\n").field,
            "damping"
        );
        assert_eq!(
            build_err("type: notch\ncentre_hz: 100\ndepth: -1\n").field,
            "depth"
        );
    }

    #[test]
    fn lead_lag_gains_and_phase_peak() {
        let mut b = built("type: lead_lag\nzero_hz: 50\npole_hz: 450\ngain: 2\n");
        let model = b.lti().unwrap();
        assert!((model.dcgain()[(0, 0)].re - 2.0).abs() < 1e-12);
        // Pre-warped at √(50·450) = 150 Hz: equals the continuous response there.
        let ll = LeadLag::new(50.0, 450.0, 2.0);
        let w = 2.0 * PI * 150.0;
        let want = ll.continuous_model().eval(Complex::new(0.0, w));
        assert!((model.freqresp_siso_at(w) - want).norm() < 1e-10);
        // Maximum phase lead asin((9 − 1)/(9 + 1)).
        assert!((want.arg() - (0.8f64).asin()).abs() < 1e-12);
        b.build(&BuildContext::new("b", DT, 0)).unwrap();
        assert_model_matches_simulation(b.as_mut(), &[20.0, 150.0, 900.0]);
    }

    #[test]
    fn delay_shifts_and_has_no_feedthrough() {
        let mut b = built("type: delay\nd: 3\nwidth: 2\n");
        assert!(!b.direct_feedthrough());
        let u: Vec<Vec<f64>> = (0..10).map(|k| vec![k as f64, -(k as f64)]).collect();
        let y = run(b.as_mut(), &u);
        for (k, yk) in y.iter().enumerate() {
            let want = if k >= 3 { (k - 3) as f64 } else { 0.0 };
            assert_eq!(*yk, vec![want, -want]);
        }
        let model = b.lti().unwrap();
        assert_eq!(
            (model.ninputs(), model.noutputs(), model.nstates()),
            (2, 2, 6)
        );
        let mut d0 = built("type: delay\nd: 0\n");
        assert!(d0.direct_feedthrough());
        assert_eq!(run_siso(d0.as_mut(), &[1.0, 2.0]), vec![1.0, 2.0]);
        let mut d1 = built("type: delay\nd: 1\n");
        assert_model_matches_simulation(d1.as_mut(), &[100.0, 1000.0]);
    }

    #[test]
    fn transfer_function_zoh_step_is_sampled_continuous_step() {
        // 1/(τ s + 1), τ = 2 ms: ZOH step response 1 − e^{−kT/τ} exactly.
        let mut b =
            built("type: transfer_function\nnum: [1]\nden: [0.002, 1]\ndiscretisation: zoh\n");
        assert!(!b.direct_feedthrough());
        let y = run_siso(b.as_mut(), &[1.0; 50]);
        for (k, yk) in y.iter().enumerate() {
            let want = 1.0 - (-(k as f64) * DT / 0.002).exp();
            assert!((yk - want).abs() < 1e-14, "k={k}");
        }
    }

    #[test]
    fn transfer_function_tustin_and_discrete() {
        // Lightly damped resonance, Tustin pre-warped at the resonance.
        let w0: f64 = 2.0 * PI * 527.0;
        let text = format!(
            "type: transfer_function\nnum: [{}]\nden: [1, {}, {}]\ndiscretisation: tustin\nprewarp_hz: 527\n",
            w0 * w0,
            2.0 * 0.02 * w0,
            w0 * w0
        );
        let mut b = built(&text);
        assert!(b.direct_feedthrough());
        let g = b.lti().unwrap().freqresp_siso_at(w0);
        assert!((g - Complex::new(0.0, -25.0)).norm() < 1e-8, "{g}");
        b.build(&BuildContext::new("b", DT, 0)).unwrap();
        assert_model_matches_simulation(b.as_mut(), &[100.0, 700.0]);
        // Discrete: y[k] = 0.5 y[k−1] + u[k−1] ⇔ 1/(z − 0.5).
        let mut d =
            built("type: transfer_function\nnum: [1]\nden: [1, -0.5]\ndiscrete: true\nwidth: 2\n");
        assert!(!d.direct_feedthrough());
        let y = run(d.as_mut(), &vec![vec![1.0, 2.0]; 4]);
        assert_eq!(y[0], vec![0.0, 0.0]);
        assert_eq!(y[1], vec![1.0, 2.0]);
        assert_eq!(y[3], vec![1.75, 3.5]);
        assert_eq!(d.lti().unwrap().ninputs(), 2);
        // Errors name the field.
        assert_eq!(
            build_err("type: transfer_function\nnum: [1]\nden: [1, 1]\n").field,
            "discretisation"
        );
        assert_eq!(
            build_err(
                "type: transfer_function\nnum: [1, 0, 0]\nden: [1, 1]\ndiscretisation: zoh\n"
            )
            .field,
            "num"
        );
        assert_eq!(
            build_err("type: transfer_function\nnum: [1]\nden: [0]\ndiscrete: true\n").field,
            "den"
        );
        assert_eq!(
            build_err("type: transfer_function\nnum: [1]\nden: [1, 1]\ndiscrete: true\ndiscretisation: zoh\n").field,
            "discretisation"
        );
        assert!(
            crate::yaml::from_str::<Box<dyn Block>>(
                "type: transfer_function\nnum: [1]\nden: [1]\nbogus: 1\n",
                "t"
            )
            .is_err()
        );
    }

    #[test]
    fn state_space_is_row_major_and_matches_model() {
        // Mass-spring-damper x'' = −4 x − 0.4 x' + u: A = [[0, 1], [−4, −0.4]].
        let text = "type: state_space\na: [[0, 1], [-4, -0.4]]\nb: [[0], [1]]\nc: [[1, 0], [0, 1]]\ndiscretisation: zoh\n";
        let mut b = built(text);
        assert_eq!(b.inputs()[0].width, 1);
        assert_eq!(b.outputs()[0].width, 2);
        assert!(!b.direct_feedthrough());
        let model = b.lti().unwrap();
        let cont = StateSpace::new(
            DMatrix::from_row_slice(2, 2, &[0.0, 1.0, -4.0, -0.4]),
            DMatrix::from_row_slice(2, 1, &[0.0, 1.0]),
            DMatrix::identity(2, 2),
            DMatrix::zeros(2, 1),
            None,
        )
        .unwrap();
        let want = cont.c2d(DT, C2dMethod::Zoh).unwrap();
        assert!((&model.a - &want.a).amax() < 1e-15);
        let y = run(b.as_mut(), &vec![vec![1.0]; 3]);
        assert_eq!(y[0], vec![0.0, 0.0]);
        assert!((y[1][1] - want.b[(1, 0)]).abs() < 1e-18);
        // Discrete static gain with D only.
        let mut g = built("type: state_space\na: []\nb: []\nc: []\nd: [[2, 3]]\ndiscrete: true\n");
        assert_eq!(g.inputs()[0].width, 2);
        assert!(g.direct_feedthrough());
        assert_eq!(run(g.as_mut(), &[vec![1.0, 1.0]])[0], vec![5.0]);
        assert_eq!(
            build_err("type: state_space\na: [[0, 1]]\nb: [[1]]\nc: [[1]]\ndiscrete: true\n").field,
            "a[0]"
        );
        assert_eq!(
            build_err(
                "type: state_space\na: [[0]]\nb: [[1]]\nc: [[1]]\nd: [[1, 2]]\ndiscrete: true\n"
            )
            .field,
            "d[0]"
        );
        let from = StateSpaceBlock::from_model(&want, None);
        let mut fb: Box<dyn Block> = Box::new(from);
        fb.build(&BuildContext::new("b", DT, 0)).unwrap();
        assert_eq!(fb.lti().unwrap(), want);
    }

    #[test]
    fn ticks_do_not_allocate() {
        let texts = [
            "type: low_pass\ncutoff_hz: 200\norder: 5\nwidth: 3\n",
            "type: notch\ncentre_hz: 527\n",
            "type: lead_lag\nzero_hz: 50\npole_hz: 450\n",
            "type: delay\nd: 7\nwidth: 2\n",
            "type: transfer_function\nnum: [1, 2]\nden: [1, 3, 5]\ndiscretisation: zoh\n",
            "type: state_space\na: [[0, 1], [-4, -0.4]]\nb: [[0], [1]]\nc: [[1, 0], [0, 1]]\nd: [[0], [1]]\ndiscretisation: tustin\n",
        ];
        for text in texts {
            let mut b = built(text);
            let m: usize = b.inputs().iter().map(|p| p.width).sum();
            let p: usize = b.outputs().iter().map(|p| p.width).sum();
            let u = vec![1.0; m];
            let mut y = vec![0.0; p];
            let ft = b.direct_feedthrough();
            let info = allocation_counter::measure(|| {
                for k in 0..100 {
                    let t = Tick::new(k, DT);
                    b.output(t, &u, &mut y);
                    if !ft {
                        b.update(t, &u);
                    }
                }
            });
            assert_eq!(info.count_total, 0, "{text}");
        }
    }

    /// One sample of a second-order section [b₀, b₁, b₂, 1, a₁, a₂] in direct
    /// form II transposed (scipy `sosfilt`), written out.
    fn df2t(s: [f64; 6], z: &mut [f64; 2], u: f64) -> f64 {
        let y = s[0] * u + z[0];
        z[0] = s[1] * u - s[4] * y + z[1];
        z[1] = s[2] * u - s[5] * y;
        y
    }

    /// The 2nd-order digital Butterworth low-pass at `fc` (Hz), period DT, in
    /// the textbook closed form: K = tan(π f_c T),
    /// b = K²·[1, 2, 1]/(1 + √2K + K²), a = [1, 2(K² − 1), 1 − √2K + K²]/(…).
    fn butterworth2(fc: f64) -> [f64; 6] {
        let k = (PI * fc * DT).tan();
        let n = 1.0 + 2f64.sqrt() * k + k * k;
        let b0 = k * k / n;
        let a1 = 2.0 * (k * k - 1.0) / n;
        let a2 = (1.0 - 2f64.sqrt() * k + k * k) / n;
        [b0, 2.0 * b0, b0, 1.0, a1, a2]
    }

    #[test]
    fn a_live_cutoff_change_runs_on_as_the_closed_form_butterworth_from_the_same_delay_line() {
        let (f1, f2) = (200.0, 60.0);
        let mut lp = LowPass::new(2, f1);
        lp.build(&BuildContext::new("lp", DT, 0)).unwrap();
        assert_eq!(lp.live_params(), ["cutoff_hz"]);
        let mut rng = crate::rng::Rng::new(27);
        let mut z = [0.0; 2];
        let mut y = [0.0];
        let mut step = |lp: &mut LowPass, z: &mut [f64; 2], s: [f64; 6], u: f64| {
            lp.output(Tick::new(0, DT), &[u], &mut y);
            let want = df2t(s, z, u);
            assert!(
                (y[0] - want).abs() <= 1e-13 * want.abs().max(1.0),
                "{} {want}",
                y[0]
            );
            // The block's state is the section's delay line.
            let x = lp.core.as_ref().unwrap().steppers[0].state();
            assert!((x[0] - z[0]).abs() < 1e-13 && (x[1] - z[1]).abs() < 1e-13);
            y[0]
        };
        for _ in 0..300 {
            step(&mut lp, &mut z, butterworth2(f1), rng.normal());
        }
        let before = lp.clone();
        lp.set_live_param(0, f2);
        assert_eq!(lp.cutoff_hz, f2);
        // The first output moves by (b₀′ − b₀)·u (y = z₀ + b₀u), then the
        // new filter runs on from the same delay line.
        let u = rng.normal();
        let mut old = before.clone();
        let mut y_old = [0.0];
        old.output(Tick::new(0, DT), &[u], &mut y_old);
        let y_new = step(&mut lp, &mut z, butterworth2(f2), u);
        let db0 = butterworth2(f2)[0] - butterworth2(f1)[0];
        assert!(
            (y_new - y_old[0] - db0 * u).abs() < 1e-15,
            "{y_new} {y_old:?}"
        );
        for _ in 0..300 {
            step(&mut lp, &mut z, butterworth2(f2), rng.normal());
        }
        // At a steady input u₀ the bump is (b₀′ − b₀)·u₀, the decay the new filter's.
        let mut steady = LowPass::new(2, f1);
        steady.build(&BuildContext::new("lp", DT, 0)).unwrap();
        let mut y = [0.0];
        for _ in 0..4000 {
            steady.output(Tick::new(0, DT), &[1.0], &mut y);
        }
        assert!((y[0] - 1.0).abs() < 1e-12);
        steady.set_live_param(0, f2);
        steady.output(Tick::new(0, DT), &[1.0], &mut y);
        assert!((y[0] - (1.0 + db0)).abs() < 1e-12, "{}", y[0]);
        // … and the new filter, of unity DC gain, brings it back to u₀.
        for _ in 0..4000 {
            steady.output(Tick::new(0, DT), &[1.0], &mut y);
        }
        assert!((y[0] - 1.0).abs() < 1e-12, "{}", y[0]);
    }

    /// `live`, built, driven by noise, then live parameter `slot` set to
    /// `value`; `fresh`, built with that value, started from `live`'s state at
    /// the change: from then on the two give the same samples, to the bit, and
    /// `live`'s model is `fresh`'s; for one section the change moved the
    /// output by (D′ − D)·u.
    fn runs_on_as_built_fresh<T: Block + SectionFilter + Clone>(
        mut live: T,
        mut fresh: T,
        slot: usize,
        value: f64,
    ) {
        let ctx = BuildContext::new("f", DT, 0);
        live.build(&ctx).unwrap();
        fresh.build(&ctx).unwrap();
        let m: usize = live.inputs().iter().map(|p| p.width).sum();
        let mut rng = crate::rng::Rng::new(slot as u64 + 1);
        let mut noise = |n: usize| -> Vec<Vec<f64>> {
            (0..n)
                .map(|_| (0..m).map(|_| rng.normal()).collect())
                .collect()
        };
        run(&mut live, &noise(250));
        let before = live.clone();
        let d_before = live.lti().unwrap().d[(0, 0)];
        live.set_live_param(slot, value);
        let d_after = fresh.lti().unwrap().d[(0, 0)];
        assert_eq!(live.lti(), fresh.lti());
        let states: Vec<Vec<f64>> = live
            .core_mut()
            .unwrap()
            .steppers
            .iter()
            .map(|s| s.state().to_vec())
            .collect();
        for (s, x) in fresh.core_mut().unwrap().steppers.iter_mut().zip(&states) {
            s.set_state(x);
        }
        let u = noise(250);
        let (y_live, y_fresh) = (run(&mut live, &u), run(&mut fresh, &u));
        assert_eq!(y_live, y_fresh);
        // One section (y = z₀ + b₀v): the output moved by (D′ − D)·u at the
        // change; a cascade's C moves too.
        if live.lti().unwrap().nstates() <= 2 {
            let y_old = run(&mut before.clone(), &u[..1]);
            for ((a, b), u) in y_live[0].iter().zip(&y_old[0]).zip(&u[0]) {
                assert!((a - b - (d_after - d_before) * u).abs() < 1e-14, "{a} {b}");
            }
        }
        assert_ne!(d_after, d_before);
    }

    #[test]
    fn a_live_corner_change_runs_on_as_the_filter_built_with_it_from_the_same_state() {
        let mut lp = LowPass::new(5, 300.0);
        lp.width = 3;
        let mut lp2 = LowPass::new(5, 90.0);
        lp2.width = 3;
        runs_on_as_built_fresh(lp, lp2, 0, 90.0);
        let notch = || Notch::new(527.0, 0.1, 0.1);
        for (slot, value) in [(0, 611.0), (1, 0.25), (2, 0.02)] {
            let mut f = notch();
            *f.live_slot(slot).unwrap() = value;
            runs_on_as_built_fresh(notch(), f, slot, value);
        }
        let ll = || LeadLag::new(50.0, 450.0, 2.0);
        for (slot, value) in [(0, 80.0), (1, 3000.0)] {
            let mut f = ll();
            *f.live_slot(slot).unwrap() = value;
            runs_on_as_built_fresh(ll(), f, slot, value);
        }
    }

    #[test]
    fn live_corners_give_the_tustin_image_of_the_new_prototype() {
        // Tustin with scale k maps the unit circle onto the imaginary axis:
        // H(e^{jωT}) = N(j·k·tan(ωT/2)) at every ω, k = ω_w/tan(ω_wT/2)
        // pre-warped at ω_w (2/T without). Checked on the model after the change.
        let image = |b: &dyn Block, proto: &TransferFunction, prewarp_hz: Option<f64>| {
            let model = b.lti().unwrap();
            let k = prewarp_hz.map_or(2.0 / DT, |f| {
                let w = 2.0 * PI * f;
                w / (w * DT / 2.0).tan()
            });
            for f in [0.0, 3.0, 50.0, 333.0, 611.0, 1200.0, 1990.0] {
                let w = 2.0 * PI * f;
                let want = proto.eval(Complex::new(0.0, k * (w * DT / 2.0).tan()));
                let got = model.freqresp_siso_at(w);
                assert!(
                    (got - want).norm() < 1e-11 * want.norm().max(1.0),
                    "{f} Hz: {got} {want}"
                );
            }
        };
        let mut n = Notch::new(527.0, 0.1, 0.1);
        n.build(&BuildContext::new("n", DT, 0)).unwrap();
        n.set_live_param(0, 611.0);
        n.set_live_param(1, 0.3);
        n.set_live_param(2, 0.05);
        let w0 = 2.0 * PI * 611.0;
        let proto = TransferFunction {
            num: vec![1.0, 2.0 * 0.05 * 0.3 * w0, w0 * w0],
            den: vec![1.0, 2.0 * 0.3 * w0, w0 * w0],
            dt: None,
        };
        image(&n, &proto, Some(611.0));
        // Depth exactly at the new centre, unity DC gain.
        let g = n.lti().unwrap().freqresp_siso_at(w0);
        assert!((g - Complex::new(0.05, 0.0)).norm() < 1e-12, "{g}");
        let mut ll = LeadLag::new(50.0, 450.0, 2.0);
        ll.build(&BuildContext::new("l", DT, 0)).unwrap();
        ll.set_live_param(0, 20.0);
        ll.set_live_param(1, 900.0);
        let (wz, wp) = (2.0 * PI * 20.0, 2.0 * PI * 900.0);
        let proto = TransferFunction {
            num: vec![2.0 / wz, 2.0],
            den: vec![1.0 / wp, 1.0],
            dt: None,
        };
        // The default pre-warp follows the corners: √(20·900) = 134.16 Hz.
        image(&ll, &proto, Some((20.0f64 * 900.0).sqrt()));
        // A pole at 1 MHz: the geometric mean √(20·10⁶) ≈ 4.5 kHz is above
        // Nyquist, so plain Tustin.
        ll.set_live_param(1, 1.0e6);
        let proto = TransferFunction {
            num: vec![2.0 / wz, 2.0],
            den: vec![1.0 / (2.0 * PI * 1.0e6), 1.0],
            dt: None,
        };
        image(&ll, &proto, None);
        // The low-pass after a change: the digital Butterworth magnitude
        // 1/√(1 + (tan(πfT)/tan(πf_cT))^{2n}).
        let mut lp = LowPass::new(4, 200.0);
        lp.build(&BuildContext::new("lp", DT, 0)).unwrap();
        lp.set_live_param(0, 750.0);
        let model = lp.lti().unwrap();
        for f in [0.0, 50.0, 750.0, 1500.0] {
            let r = (PI * f * DT).tan() / (PI * 750.0 * DT).tan();
            let want = 1.0 / (1.0 + r.powi(8)).sqrt();
            assert!((model.freqresp_siso_at(2.0 * PI * f).norm() - want).abs() < 1e-12);
        }
    }

    /// `b`, built and run a little, given `bad` for live parameter `slot`:
    /// its parameters, model and state stay as they were, and a copy built
    /// with the value is refused naming the parameter.
    fn refuses_live<T: Block + Clone + Serialize>(mut b: T, slot: usize, bad: f64) {
        b.build(&BuildContext::new("b", DT, 0)).unwrap();
        run(&mut b, &[vec![1.0], vec![-0.5]]);
        let before = b.clone();
        let params = serde_json::to_value(&b).unwrap();
        b.set_live_param(slot, bad);
        assert_eq!(serde_json::to_value(&b).unwrap(), params);
        assert_eq!(b.lti(), before.lti());
        let u = [vec![0.3], vec![0.7]];
        assert_eq!(run(&mut b, &u), run(&mut before.clone(), &u));
        if bad.is_finite() {
            let field = b.live_params()[slot];
            let mut p = params;
            p[field] = serde_json::json!(bad);
            p["type"] = serde_json::json!(b.typetag_name());
            let mut copy: Box<dyn Block> = serde_json::from_value(p).unwrap();
            let e = copy.build(&BuildContext::new("b", DT, 0)).unwrap_err();
            assert_eq!(e.field, field, "{e}");
        }
    }

    #[test]
    fn a_corner_the_build_refuses_leaves_the_running_filter_as_it_was() {
        // The sender refuses such a value first (it builds a copy of the block
        // with it: `Block::build`'s checks and message); given one anyway, the
        // block keeps its parameters, model and state.
        for bad in [2000.0, 2500.0, 0.0, -1.0, f64::NAN] {
            refuses_live(LowPass::new(3, 200.0), 0, bad);
            refuses_live(Notch::new(527.0, 0.1, 0.1), 0, bad);
        }
        refuses_live(Notch::new(527.0, 0.1, 0.1), 1, -0.1);
        refuses_live(Notch::new(527.0, 0.1, 0.1), 1, 0.0);
        refuses_live(Notch::new(527.0, 0.1, 0.1), 2, -1.0);
        for bad in [0.0, -3.0, f64::INFINITY] {
            refuses_live(LeadLag::new(50.0, 450.0, 2.0), 0, bad);
            refuses_live(LeadLag::new(50.0, 450.0, 2.0), 1, bad);
        }
    }

    #[test]
    fn a_live_corner_change_does_not_allocate() {
        let mut lp = LowPass::new(MAX_LOW_PASS_ORDER, 200.0);
        lp.width = 3;
        let mut lp5 = LowPass::new(5, 200.0);
        lp5.width = 2;
        let blocks: [(Box<dyn Block>, &[f64]); 4] = [
            (Box::new(lp), &[150.0]),
            (Box::new(lp5), &[40.0]),
            (Box::new(Notch::new(527.0, 0.1, 0.1)), &[600.0, 0.2, 0.3]),
            (Box::new(LeadLag::new(50.0, 450.0, 2.0)), &[70.0, 5000.0]),
        ];
        for (mut b, values) in blocks {
            b.build(&BuildContext::new("b", DT, 0)).unwrap();
            let model = b.lti();
            let info = allocation_counter::measure(|| {
                for (slot, v) in values.iter().enumerate() {
                    b.set_live_param(slot, *v);
                }
            });
            assert_eq!(info.count_total, 0, "{}", b.typetag_name());
            assert_ne!(b.lti(), model);
        }
    }

    #[test]
    fn controller_trait_runs_the_filter() {
        let mut ll = LeadLag::new(10.0, 100.0, 3.0);
        ll.build(&BuildContext::new("c", DT, 0)).unwrap();
        let mut u = [0.0];
        for _ in 0..4000 {
            ll.control(&[1.0], &mut u);
        }
        assert!((u[0] - 3.0).abs() < 1e-9);
        Controller::reset(&mut ll);
        ll.control(&[0.0], &mut u);
        assert_eq!(u[0], 0.0);
    }
}
