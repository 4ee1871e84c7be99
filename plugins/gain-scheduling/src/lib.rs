//! # nanomotion-gain-scheduling
//!
//! Generic **gain scheduling** after R.J.E. Merry, *Performance-driven control of
//! nano-motion systems* (TU/e 2009), Sec. 2.4.3 and 2.5.1: a controller whose gain
//! is multiplied by a factor depending on the operating point,
//!
//! K(σ) = K_1(σ_1)·K_2(σ_2)·…   — (2.13) K(A, φ̄) = K_A(A)·K_φ(φ̄) for the walking piezo,
//!
//! with each factor an interpolation table (linear or on a dB scale) or the thesis's
//! fitted law, a first-order power series on a dB scale,
//! K_i(σ) = 10^((a σ^b + c)/20) ([`fit_power_db`] fits it by least squares through
//! gains identified at operating points).
//!
//! It works with **any controller** and any number of scheduling variables:
//!
//! - from Rust, [`Scheduled`] wraps any [`nanomotion_core::Controller`];
//! - in graphs, block `gain_scheduled` wraps any inner block given inline
//!   (`controller: {type: pi, kp: …, zero_hz: …}`) and adds an input `sigma`
//!   (one value per factor) and an output `gain`.
//!
//! **Where the gain goes, and why.** By default the gain multiplies the controller
//! *input* (`placement: input`): u = C(K·e). For a constant K this equals K·C(e)
//! (C linear), so the loop gain is scaled exactly as (2.13) asks; when K changes,
//! the states of C (the integrator of a PI, which holds the f_α of a constant
//! velocity) are untouched and only the direct part moves, by D·ΔK·e with e small
//! near the operating point: the change is **bumpless**. Multiplying the *output*
//! (`placement: output`, u = K·C(e)) scales the integrator's stored action too and
//! kicks the plant by ΔK·u at every gain change; it is offered for controllers that
//! are not linear in their input, and the tests show the difference.
//!
//! ```
//! use gain_scheduling::{GainLaw, GainSchedule, Placement, Scheduled};
//! use nanomotion_core::Controller;
//! struct P(f64);
//! impl Controller for P {
//!     fn control(&mut self, e: &[f64], u: &mut [f64]) { u[0] = self.0 * e[0]; }
//!     fn reset(&mut self) {}
//! }
//! // K(σ) = 10^((−20 σ^1 + 20)/20): 0 dB at σ = 1, +20 dB at σ = 0.
//! let law = GainLaw::PowerDb { a: -20.0, b: 1.0, c: 20.0 };
//! let mut c = Scheduled::new(P(2.0), GainSchedule::new(vec![law]).unwrap(), Placement::Input);
//! let mut u = [0.0];
//! c.control(&[1.0], &[0.0], &mut u);
//! assert!((u[0] - 20.0).abs() < 1e-9);
//! ```

use nanomotion_core::Params;
use nanomotion_core::{Block, BuildContext, Controller, ParamError, Port, Tick, declared_block};
use serde::{Deserialize, Serialize};
use thiserror::Error;

// ---------------------------------------------------------------------------
// Laws
// ---------------------------------------------------------------------------

/// One factor K_i(σ_i) of the schedule (YAML: `{kind: power_db, a: …, b: …, c: …}`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, Params)]
#[serde(tag = "kind", rename_all = "snake_case", deny_unknown_fields)]
pub enum GainLaw {
    /// A fixed factor.
    Constant {
        /// K (dimensionless).
        #[param(positive)]
        gain: f64,
    },
    /// Linear interpolation of K through (x_j, K_j), constant beyond the ends.
    Table {
        /// Breakpoints σ_j (unit of the scheduling variable).
        #[param(len(>= 1), finite, increasing, same_len = gain)]
        x: Vec<f64>,
        /// Gains K_j at the breakpoints.
        #[param(positive, hint = "or use table_db")]
        gain: Vec<f64>,
    },
    /// Linear interpolation on a dB scale through (x_j, 20 log10 K_j).
    TableDb {
        /// Breakpoints σ_j.
        #[param(len(>= 1), finite, increasing, same_len = gain_db)]
        x: Vec<f64>,
        /// Gains in dB at the breakpoints.
        #[param(finite)]
        gain_db: Vec<f64>,
    },
    /// First-order power series on a dB scale: K(σ) = 10^((a σ^b + c)/20), σ > 0
    /// (smaller σ are clamped to 1e-12). Thesis Sec. 2.5.1.
    PowerDb {
        /// a (dB per unit^b).
        #[param(finite)]
        a: f64,
        /// Exponent b.
        #[param(finite)]
        b: f64,
        /// Offset c (dB).
        #[param(finite)]
        c: f64,
    },
}

fn interp(x: &[f64], y: &[f64], s: f64) -> f64 {
    let n = x.len();
    if s <= x[0] {
        return y[0];
    }
    if s >= x[n - 1] {
        return y[n - 1];
    }
    // Binary search: no allocation.
    let j = x.partition_point(|&v| v <= s).max(1);
    let t = (s - x[j - 1]) / (x[j] - x[j - 1]);
    y[j - 1] + t * (y[j] - y[j - 1])
}

impl GainLaw {
    /// K at scheduling value `sigma`. A non-finite σ gives the value at the nearest
    /// end of a table, and for the power law the value at σ = 1e-12.
    pub fn gain(&self, sigma: f64) -> f64 {
        match self {
            GainLaw::Constant { gain } => *gain,
            GainLaw::Table { x, gain } => {
                interp(x, gain, if sigma.is_nan() { x[0] } else { sigma })
            }
            GainLaw::TableDb { x, gain_db } => {
                10f64.powf(interp(x, gain_db, if sigma.is_nan() { x[0] } else { sigma }) / 20.0)
            }
            GainLaw::PowerDb { a, b, c } => {
                let s = if sigma.is_finite() {
                    sigma.max(1e-12)
                } else {
                    1e-12
                };
                10f64.powf((a * s.powf(*b) + c) / 20.0)
            }
        }
    }

    /// Check the law (its declared bounds); `field` names it in errors (e.g.
    /// `schedule[1]`).
    pub fn validate(&self, field: &str) -> Result<(), ParamError> {
        nanomotion_core::doc::within(field, self.check_params())
    }
}

/// The product K(σ) = Π K_i(σ_i) (2.13), one factor per scheduling variable.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, Params)]
#[serde(transparent)]
pub struct GainSchedule {
    /// The factors.
    #[param(len(>= 1), nested)]
    pub laws: Vec<GainLaw>,
}

impl GainSchedule {
    /// A validated schedule with at least one factor.
    pub fn new(laws: Vec<GainLaw>) -> Result<Self, ParamError> {
        let s = Self { laws };
        s.validate()?;
        Ok(s)
    }
    /// Check the declared bounds: at least one factor, each factor's own
    /// (errors named as the block's field: `schedule[1].x[2]`).
    pub fn validate(&self) -> Result<(), ParamError> {
        nanomotion_core::doc::within("schedule", self.check_params())
    }
    /// Number of scheduling variables.
    pub fn len(&self) -> usize {
        self.laws.len()
    }
    /// Whether there are no factors (never, once validated).
    pub fn is_empty(&self) -> bool {
        self.laws.is_empty()
    }
    /// K(σ); `sigma` has one value per factor.
    pub fn gain(&self, sigma: &[f64]) -> f64 {
        self.laws
            .iter()
            .zip(sigma)
            .map(|(l, &s)| l.gain(s))
            .product()
    }
}

/// Where the scheduled gain multiplies the controller (see the crate doc).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize, Params)]
#[serde(rename_all = "snake_case")]
pub enum Placement {
    /// u = C(K·e): bumpless for linear controllers (default).
    #[default]
    Input,
    /// u = K·C(e): jumps by ΔK·u when K changes.
    Output,
}

// ---------------------------------------------------------------------------
// Rust API
// ---------------------------------------------------------------------------

/// Any [`Controller`] with a gain schedule. Single-input controllers need no
/// allocation; the input is scaled in a stack buffer of up to 16 values.
#[derive(Debug, Clone)]
pub struct Scheduled<C> {
    /// The inner controller.
    pub inner: C,
    /// K(σ).
    pub schedule: GainSchedule,
    /// Where K acts.
    pub placement: Placement,
    gain: f64,
}

impl<C: Controller> Scheduled<C> {
    /// Wrap `inner`.
    pub fn new(inner: C, schedule: GainSchedule, placement: Placement) -> Self {
        Self {
            inner,
            schedule,
            placement,
            gain: 1.0,
        }
    }
    /// The gain of the last sample.
    pub fn gain(&self) -> f64 {
        self.gain
    }
    /// One sample with scheduling values `sigma` (one per factor). `e` has at most
    /// 16 values.
    pub fn control(&mut self, e: &[f64], sigma: &[f64], u: &mut [f64]) {
        let k = self.schedule.gain(sigma);
        self.gain = k;
        match self.placement {
            Placement::Input => {
                let mut buf = [0.0; 16];
                let n = e.len().min(16);
                for (b, &v) in buf[..n].iter_mut().zip(e) {
                    *b = k * v;
                }
                self.inner.control(&buf[..n], u);
            }
            Placement::Output => {
                self.inner.control(e, u);
                u.iter_mut().for_each(|v| *v *= k);
            }
        }
    }
    /// Reset the inner controller.
    pub fn reset(&mut self) {
        self.inner.reset();
        self.gain = 1.0;
    }
}

// ---------------------------------------------------------------------------
// Fit
// ---------------------------------------------------------------------------

/// Why a fit failed.
#[derive(Debug, Clone, PartialEq, Error)]
pub enum FitError {
    /// Fewer than 3 points, or lengths differ.
    #[error(
        "need at least 3 (σ, gain) pairs of equal length, got {sigma} σ and {gain} gains (fix: identify more operating points)"
    )]
    TooFewPoints {
        /// Number of σ.
        sigma: usize,
        /// Number of gains.
        gain: usize,
    },
    /// σ must be positive and finite for σ^b, gains finite.
    #[error(
        "point {index}: σ = {sigma}, gain = {gain_db} dB; σ must be > 0 and both finite (fix: use positive scheduling values)"
    )]
    BadPoint {
        /// Index.
        index: usize,
        /// σ.
        sigma: f64,
        /// Gain (dB).
        gain_db: f64,
    },
}

/// Least-squares fit of the first-order power series on a dB scale
/// g(σ) = a σ^b + c (dB) through `(sigma[j], gain_db[j])` (Sec. 2.5.1): for each b
/// the fit is linear in (a, c); b is found by a grid over [−4, 4] then golden-section
/// refinement. Returns the law and the rms residual (dB).
///
/// ```
/// use gain_scheduling::{GainLaw, fit_power_db};
/// let s = [23.0f64, 30.0, 38.0, 46.0];
/// let g: Vec<f64> = s.iter().map(|x| -3.0 * x.powf(0.7) + 29.0).collect();
/// let (law, rms) = fit_power_db(&s, &g).unwrap();
/// let GainLaw::PowerDb { a, b, c } = law else { unreachable!() };
/// assert!((a + 3.0).abs() < 1e-5 && (b - 0.7).abs() < 1e-6 && (c - 29.0).abs() < 1e-4 && rms < 1e-8);
/// ```
pub fn fit_power_db(sigma: &[f64], gain_db: &[f64]) -> Result<(GainLaw, f64), FitError> {
    if sigma.len() < 3 || sigma.len() != gain_db.len() {
        return Err(FitError::TooFewPoints {
            sigma: sigma.len(),
            gain: gain_db.len(),
        });
    }
    for (index, (&s, &g)) in sigma.iter().zip(gain_db).enumerate() {
        if !(s.is_finite() && s > 0.0 && g.is_finite()) {
            return Err(FitError::BadPoint {
                index,
                sigma: s,
                gain_db: g,
            });
        }
    }
    // Normalise σ by its largest value for conditioning: a σ^b = (a s_max^b)(σ/s_max)^b.
    let smax = sigma.iter().copied().fold(0.0, f64::max);
    let lin = |b: f64| -> (f64, f64, f64) {
        // Regress g on [x, 1] with x = (σ/smax)^b.
        let n = sigma.len() as f64;
        let xs = sigma.iter().map(|s| (s / smax).powf(b));
        let (mut sx, mut sxx, mut sy, mut sxy) = (0.0, 0.0, 0.0, 0.0);
        for (x, &y) in xs.zip(gain_db) {
            sx += x;
            sxx += x * x;
            sy += y;
            sxy += x * y;
        }
        let det = n * sxx - sx * sx;
        let (a, c) = if det.abs() < 1e-300 {
            (0.0, sy / n)
        } else {
            ((n * sxy - sx * sy) / det, (sxx * sy - sx * sxy) / det)
        };
        let sse: f64 = sigma
            .iter()
            .zip(gain_db)
            .map(|(s, y)| (a * (s / smax).powf(b) + c - y).powi(2))
            .sum();
        (a, c, sse)
    };
    let mut best_b = 1.0;
    let mut best = f64::INFINITY;
    for i in 0..=800 {
        let b = -4.0 + 0.01 * i as f64;
        if b.abs() < 1e-9 {
            continue;
        }
        let sse = lin(b).2;
        if sse < best {
            best = sse;
            best_b = b;
        }
    }
    // Golden section on [b − 0.01, b + 0.01].
    let (mut lo, mut hi) = (best_b - 0.01, best_b + 0.01);
    let g = 0.5 * (5f64.sqrt() - 1.0);
    for _ in 0..100 {
        let m1 = hi - g * (hi - lo);
        let m2 = lo + g * (hi - lo);
        if lin(m1).2 < lin(m2).2 {
            hi = m2;
        } else {
            lo = m1;
        }
    }
    let b = 0.5 * (lo + hi);
    let (a_n, c, sse) = lin(b);
    let law = GainLaw::PowerDb {
        a: a_n / smax.powf(b),
        b,
        c,
    };
    Ok((law, (sse / sigma.len() as f64).sqrt()))
}

// ---------------------------------------------------------------------------
// Graph block
// ---------------------------------------------------------------------------

/// `gain_scheduled`: gain scheduling (2.13): any inner block with K(σ) = Π K_i(σ_i)
/// from tables or fitted dB power laws, bumpless at the input.
///
/// Graph block `gain_scheduled`: any inner block with a gain schedule.
///
/// With `placement: input` every inner input is multiplied by K (the inner block
/// should be linear in its inputs: a controller on the error e).
///
/// ```yaml
/// type: gain_scheduled
/// controller: {type: pi, kp: 7.67e6, zero_hz: 2.68}
/// schedule:
///   - {kind: power_db, a: -30.0, b: 0.5, c: 203.5}
///   - {kind: table, x: [0.785, 1.571], gain: [2.0, 1.0]}
/// ```
#[derive(Debug, Serialize, Deserialize, Params)]
#[serde(deny_unknown_fields)]
#[block(type_name = "gain_scheduled", role = Controller, ports = "<inner inputs>, sigma[n] \"one value per factor of schedule\" [scheduling] -> <inner outputs>, gain \"K(σ)\"")]
pub struct GainScheduledBlock {
    /// The inner block (any registered type), e.g. `{type: pi, kp: 1, zero_hz: 2}`.
    pub controller: Box<dyn Block>,
    /// One factor K_i(σ_i) per scheduling variable; K = Π K_i (2.13);
    /// `power_db`: K = 10^((aσ^b + c)/20).
    #[param(nested)]
    pub schedule: GainSchedule,
    /// `input` (default, bumpless) or `output`.
    /// `input`: u = C(K·e); `output`: u = K·C(e).
    #[serde(default)]
    #[param(default_doc = "input")]
    pub placement: Placement,
    #[serde(skip)]
    n_in: usize,
    #[serde(skip)]
    n_out: usize,
    #[serde(skip)]
    scratch: Vec<f64>,
    #[serde(skip)]
    gain: f64,
    #[serde(skip)]
    inner_feedthrough: bool,
}

impl GainScheduledBlock {
    /// Wrap `controller` (build it before stepping).
    pub fn new(controller: Box<dyn Block>, schedule: GainSchedule, placement: Placement) -> Self {
        Self {
            controller,
            schedule,
            placement,
            n_in: 0,
            n_out: 0,
            scratch: Vec::new(),
            gain: 1.0,
            inner_feedthrough: true,
        }
    }

    fn scaled_input(&mut self, u: &[f64]) {
        let k = self.schedule.gain(&u[self.n_in..]);
        self.gain = k;
        let f = if self.placement == Placement::Input {
            k
        } else {
            1.0
        };
        for (s, &v) in self.scratch.iter_mut().zip(&u[..self.n_in]) {
            *s = f * v;
        }
    }
}

#[declared_block]
impl Block for GainScheduledBlock {
    fn inputs(&self) -> Vec<Port> {
        let mut v = self.controller.inputs();
        v.push(Port::new("sigma", self.schedule.len()).scheduling_input());
        v
    }
    fn outputs(&self) -> Vec<Port> {
        let mut v = self.controller.outputs();
        v.push(Port::new("gain", 1));
        v
    }
    fn direct_feedthrough(&self) -> bool {
        // The `gain` output depends on σ of the same sample.
        true
    }
    fn build(&mut self, ctx: &BuildContext) -> Result<(), ParamError> {
        self.check_params()?;
        self.controller.build(ctx).map_err(|e| ParamError {
            field: format!("controller.{}", e.field),
            ..e
        })?;
        self.n_in = self.controller.inputs().iter().map(|p| p.width).sum();
        self.n_out = self.controller.outputs().iter().map(|p| p.width).sum();
        self.scratch = vec![0.0; self.n_in];
        self.gain = 1.0;
        self.inner_feedthrough = self.controller.direct_feedthrough();
        Ok(())
    }
    fn output(&mut self, tick: Tick, u: &[f64], y: &mut [f64]) {
        self.scaled_input(u);
        let n_out = self.n_out;
        self.controller.output(tick, &self.scratch, &mut y[..n_out]);
        if !self.inner_feedthrough {
            // The wrapper is always feed-through (its `gain` output depends on σ),
            // so the scheduler never calls our `update`: advance an inner block
            // without feed-through here, after its output of this sample.
            self.controller.update(tick, &self.scratch);
        }
        if self.placement == Placement::Output {
            y[..n_out].iter_mut().for_each(|v| *v *= self.gain);
        }
        y[n_out] = self.gain;
    }
    /// For the stability gate: the inner controller's model times K at every
    /// schedule point — the gains at the table breakpoints (piecewise-linear
    /// laws, in K or in dB, take their extremes there) and constants; K = Π K_i
    /// over every combination (at most 64). The `sigma` input and `gain` output
    /// do not enter the linear model (K is frozen at each point). A `power_db`
    /// law is continuous with no points to check: no linearisation (unproven).
    fn linearisation(&self) -> Option<nanomotion_core::Linearisation> {
        let (inner, inner_note) = match self.controller.linearisation() {
            Some(l) => (l.points.into_iter().next()?.1, Some(l.note)),
            None => (self.controller.lti()?, None),
        };
        let mut gains = vec![1.0];
        for law in &self.schedule.laws {
            let ks: Vec<f64> = match law {
                GainLaw::Constant { gain } => vec![*gain],
                GainLaw::Table { gain, .. } => gain.clone(),
                GainLaw::TableDb { gain_db, .. } => {
                    gain_db.iter().map(|g| 10f64.powf(g / 20.0)).collect()
                }
                GainLaw::PowerDb { .. } => return None,
            };
            gains = gains
                .iter()
                .flat_map(|g| ks.iter().map(move |k| g * k))
                .take(64)
                .collect();
        }
        let (n_sigma, n_in, n_out) = (self.schedule.len(), inner.ninputs(), inner.noutputs());
        let points = gains
            .into_iter()
            .map(|k| {
                let mut m = inner.clone();
                // Input placement scales B and D (C(K e)); output scales C and D.
                if self.placement == Placement::Input {
                    m.b *= k;
                } else {
                    m.c *= k;
                }
                m.d *= k;
                let mut b = nanomotion_core::nalgebra::DMatrix::zeros(m.nstates(), n_in + n_sigma);
                b.columns_mut(0, n_in).copy_from(&m.b);
                let mut c = nanomotion_core::nalgebra::DMatrix::zeros(n_out + 1, m.nstates());
                c.rows_mut(0, n_out).copy_from(&m.c);
                let mut d = nanomotion_core::nalgebra::DMatrix::zeros(n_out + 1, n_in + n_sigma);
                d.view_mut((0, 0), (n_out, n_in)).copy_from(&m.d);
                m.b = b;
                m.c = c;
                m.d = d;
                (format!("K = {k:.4}"), m)
            })
            .collect();
        let mut note =
            "gain-scheduled controller judged at each schedule point (K frozen)".to_string();
        if let Some(n) = inner_note {
            note = format!("{note}; inner controller: {n}");
        }
        Some(nanomotion_core::Linearisation { points, note })
    }
}
