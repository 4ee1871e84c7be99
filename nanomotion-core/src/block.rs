//! The [`Block`] trait: the unit a graph is made of.
//!
//! A block has input and output ports carrying `f64` vectors, runs at a fixed rate
//! (an integer divisor of the graph's base rate), and is stepped in two phases per
//! sample:
//!
//! 1. [`Block::output`] — in topological order. A block *with* direct feed-through
//!    reads its inputs of this sample and writes its outputs (and may update its
//!    state here). A block *without* direct feed-through writes its outputs from its
//!    state only and must not depend on `u`.
//! 2. [`Block::update`] — called only for blocks without direct feed-through, after
//!    every block's outputs of this sample exist: advance the state with this sample's
//!    inputs.
//!
//! Life cycle (after copper-rs): deserialise (YAML or plain Rust constructor) →
//! [`Block::build`] (validate parameters, preallocate, derive coefficients from the
//! sample time) → ticks. Everything that allocates, looks up or validates belongs in
//! `build`; `output`/`update` are the real-time path and must not allocate, lock, do
//! I/O or look up strings.
//!
//! # Writing a block
//!
//! **Declared (every block of this workspace).** The parameter struct derives
//! [`Params`](crate::doc::Params) and says, once, in `#[block(type_name = "…", role
//! = …, ports = "…")]` what the block is called in a graph file, the role it plays
//! and its ports; `#[param(…)]` bounds on its fields are its validation (see
//! [`crate::doc`]). `#[declared_block]` on the `impl Block` then registers the type
//! with `typetag` under that name and writes what the impl leaves out:
//! `inputs`/`outputs` from `ports` when that string is a declaration
//! ([`DeclaredPorts`]: `name[width] (unit) [scheduling]`, widths a number, a
//! `usize` field or a list's sum, units SI symbols; an output `name[width]
//! [unit of u]` is in the unit of input `u`; a port `… if flag` exists when a
//! `bool` field is true, a group `in{i}[width] for i in 0..count` repeats; see
//! [`crate::doc`]), `role` from `role` ([`DeclaredBlock`]), and
//! `build` as the declared checks (`check_params()`, then `check_at_rate(ctx.dt)`),
//! and, for a block that writes no `output`, its [`Source`](crate::Source):
//! `sample` at the tick's time.
//! A block writes itself only what the declaration cannot say: its `output`, and
//! ports those forms cannot say (a width computed from several fields), a
//! `build` that prepares more than checks.
//!
//! ```
//! use nanomotion_core::{Block, BuildContext, Params, Role, Tick, declared_block};
//! use serde::{Deserialize, Serialize};
//!
//! /// `doc_scaler`: y = k·u.
//! #[derive(Debug, Clone, Serialize, Deserialize, Params)]
//! #[serde(deny_unknown_fields)]
//! #[block(type_name = "doc_scaler", role = Math, ports = "u (m), phase [scheduling] -> y (m)")]
//! struct Scaler {
//!     /// Gain k.
//!     #[param(finite)]
//!     k: f64,
//! }
//!
//! #[declared_block]
//! impl Block for Scaler {
//!     fn output(&mut self, _t: Tick, u: &[f64], y: &mut [f64]) { y[0] = self.k * u[0]; }
//! }
//!
//! let mut b = Scaler { k: f64::NAN };
//! let e = b.build(&BuildContext::new("s", 1e-3, 0)).unwrap_err();
//! assert_eq!(e.field, "k");
//! let mut b: Box<dyn Block> = nanomotion_core::yaml::from_str("type: doc_scaler\nk: 2\n", "doc").unwrap();
//! b.build(&BuildContext::new("s", 1e-3, 0)).unwrap();
//! let ins = b.inputs();
//! assert_eq!((ins[0].unit.as_deref(), ins[1].scheduling), (Some("m"), true));
//! assert_eq!(b.role(), Role::Math);
//! let mut y = [0.0];
//! b.output(Tick::new(0, 1e-3), &[3.0, 0.5], &mut y);
//! assert_eq!(y[0], 6.0);
//! ```
//!
//! **By hand (a third-party block that wants no declaration).** `Block` is an
//! ordinary trait object registered with `typetag`: implement it directly under
//! `#[typetag::serde(name = "…")]`, writing the ports, the validation and (if not
//! [`Role::Math`]) the role yourself. Such a block runs and is checked like any
//! other; `nanomotion blocks` and `nanomotion schema` list it only if it also
//! registers a [`BlockDoc`] (the derive does that, or
//! [`submit_block_doc!`](crate::submit_block_doc)).
//!
//! ```
//! use nanomotion_core::{Block, BuildContext, ParamError, Port, Tick};
//! use serde::{Deserialize, Serialize};
//!
//! /// y = k·u
//! #[derive(Debug, Clone, Serialize, Deserialize)]
//! #[serde(deny_unknown_fields)]
//! struct Doubler { k: f64 }
//!
//! #[typetag::serde(name = "doc_doubler")]
//! impl Block for Doubler {
//!     fn inputs(&self) -> Vec<Port> { vec![Port::new("u", 1)] }
//!     fn outputs(&self) -> Vec<Port> { vec![Port::new("y", 1)] }
//!     fn build(&mut self, _ctx: &BuildContext) -> Result<(), ParamError> {
//!         nanomotion_core::block::check::finite("k", self.k)
//!     }
//!     fn output(&mut self, _t: Tick, u: &[f64], y: &mut [f64]) { y[0] = self.k * u[0]; }
//! }
//!
//! let mut b = Doubler { k: 2.0 };
//! b.build(&BuildContext::new("d", 1e-3, 0)).unwrap();
//! let mut y = [0.0];
//! b.output(Tick::new(0, 1e-3), &[3.0], &mut y);
//! assert_eq!(y[0], 6.0);
//! ```

use crate::error::ParamError;
use crate::lti::StateSpace;
use std::fmt::Debug;

/// A named port of fixed width.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Port {
    /// Port name, as used in `block.port` references.
    pub name: String,
    /// Number of `f64` values the port carries.
    pub width: usize,
    /// Unit of an output's values in SI (`m`, `m/s`, `V`, `Hz`, `N`, `count`), if
    /// known; shown in CSV headers, `metrics.json` and plot axes. A graph's
    /// `units:` section sets or overrides it per signal.
    pub unit: Option<String>,
    /// For outputs in the unit of an input (sums, limiters, delays, rate
    /// transitions): the index of that input. Resolved when the graph is built.
    pub unit_from_input: Option<usize>,
    /// For inputs: a **scheduling input** — the variable the block's behaviour is
    /// scheduled on (the signal a repetitive disturbance is periodic in, e.g. a
    /// DVRC's leg angle α, thesis Sec. 5.3), not a signal path. The stability
    /// gate ([`crate::gate`]) does not linearise through it: it cuts the
    /// connection into it when it finds and assembles a feedback loop, so the
    /// loop is judged with the scheduling variable frozen, and the block's own
    /// criterion must cover its variation (for a DVRC, (5.9) over the delay
    /// range \[m, M\] that α's variation sweeps N_k through).
    pub scheduling: bool,
}

impl Port {
    /// A port named `name` carrying `width` values.
    pub fn new(name: impl Into<String>, width: usize) -> Self {
        Self {
            name: name.into(),
            width,
            unit: None,
            unit_from_input: None,
            scheduling: false,
        }
    }
    /// This output carries values in `unit` (SI, e.g. `m`).
    pub fn with_unit(mut self, unit: &str) -> Self {
        self.unit = Some(unit.to_string());
        self
    }
    /// This output carries values in the unit of input `index`.
    pub fn unit_of_input(mut self, index: usize) -> Self {
        self.unit_from_input = Some(index);
        self
    }
    /// This input is a scheduling input ([`Port::scheduling`]): the gate judges
    /// loops through the block with it frozen.
    pub fn scheduling_input(mut self) -> Self {
        self.scheduling = true;
        self
    }
}

/// Timing of one step of a block, at the block's own rate.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Tick {
    /// Index of this sample at the block's rate (0, 1, 2, ...).
    pub k: u64,
    /// Time of this sample in seconds (k·dt).
    pub t: f64,
    /// The block's sample period in seconds.
    pub dt: f64,
}

impl Tick {
    /// Tick `k` of a block with period `dt`.
    pub fn new(k: u64, dt: f64) -> Self {
        Self {
            k,
            t: k as f64 * dt,
            dt,
        }
    }
}

/// What a block learns when it is built.
#[derive(Debug, Clone)]
pub struct BuildContext {
    /// The block's instance name in the graph (for messages).
    pub name: String,
    /// The block's sample period in seconds.
    pub dt: f64,
    /// A seed for this block's random numbers, derived from the graph seed and the
    /// block name: same graph, same seed, same bits.
    pub seed: u64,
    /// Measured data attached to the graph (`nanomotion run --data`,
    /// [`GraphSpec::build_with_data`](crate::graph::GraphSpec::build_with_data)),
    /// for blocks that play recorded signals.
    pub data: Option<std::sync::Arc<dyn MeasuredData>>,
    /// The folder relative file names in parameters resolve against (the graph
    /// file's folder); `None`: the working directory.
    pub base_dir: Option<std::path::PathBuf>,
    /// Build for checking without measured data (`nanomotion check` without
    /// `--data`): blocks that play data (`data_column`) play a placeholder 0
    /// instead of refusing, so wiring and loops can be checked.
    pub placeholder_data: bool,
}

impl BuildContext {
    /// A context for block `name` with period `dt` (s) and seed `seed`, without data.
    pub fn new(name: impl Into<String>, dt: f64, seed: u64) -> Self {
        Self {
            name: name.into(),
            dt,
            seed,
            data: None,
            base_dir: None,
            placeholder_data: false,
        }
    }

    /// The same context with a folder for relative file names.
    pub fn with_base_dir(mut self, dir: Option<std::path::PathBuf>) -> Self {
        self.base_dir = dir;
        self
    }

    /// `path` as given if absolute, else relative to [`BuildContext::base_dir`].
    pub fn resolve(&self, path: &str) -> std::path::PathBuf {
        let p = std::path::Path::new(path);
        match &self.base_dir {
            Some(dir) if p.is_relative() => dir.join(p),
            _ => p.to_path_buf(),
        }
    }

    /// The same context with measured data attached.
    pub fn with_data(mut self, data: Option<std::sync::Arc<dyn MeasuredData>>) -> Self {
        self.data = data;
        self
    }
}

/// Measured data as blocks and the graph compiler see it: named columns of
/// equal length sampled at one rate. The data layer's
/// [`Dataset`](crate::data::Dataset) implements it; the block contract needs no
/// more than this, so it does not depend on how data are read.
pub trait MeasuredData: Send + Sync + Debug {
    /// Where the data came from (file name), for messages.
    fn origin(&self) -> &str;
    /// Sample rate (Hz).
    fn rate_hz(&self) -> f64;
    /// Number of samples per column.
    fn len(&self) -> usize;
    /// Whether there are no samples.
    fn is_empty(&self) -> bool {
        self.len() == 0
    }
    /// Duration len / rate (s).
    fn duration_s(&self) -> f64;
    /// Column names, in file order.
    fn names(&self) -> &[String];
    /// The samples of column `name`, if it exists.
    fn column(&self, name: &str) -> Option<&[f64]>;
}

/// A block whose parameters can be read and changed as one vector between runs,
/// without rebuilding the graph: what identification and the discrepancy workflow
/// fit. After [`Tunable::set_params`] the caller rebuilds the block
/// ([`Scheduler::reset`](crate::scheduler::Scheduler::reset) does) so that derived
/// coefficients follow.
pub trait Tunable {
    /// Names of the parameters, in vector order (as spelled in YAML).
    fn param_names(&self) -> Vec<String>;
    /// The parameter vector.
    fn params(&self) -> Vec<f64>;
    /// Set the parameter vector; errors name the field and leave the block unchanged.
    fn set_params(&mut self, p: &[f64]) -> Result<(), ParamError>;
}

/// A block of a controller graph. See the [module documentation](self).
#[typetag::serde(tag = "type")]
pub trait Block: Send + Debug {
    /// Input ports, in the order their values are concatenated in `u`.
    /// Valid after [`Block::build`].
    fn inputs(&self) -> Vec<Port> {
        Vec::new()
    }
    /// Output ports, in the order their values are concatenated in `y`.
    /// Valid after [`Block::build`].
    fn outputs(&self) -> Vec<Port>;
    /// Whether any output depends on the input of the same sample. Blocks without
    /// feed-through break algebraic loops and get [`Block::update`] calls.
    fn direct_feedthrough(&self) -> bool {
        true
    }
    /// Validate parameters and prepare for running at period `ctx.dt`.
    /// Called once before the first tick; may be called again to restart from the
    /// initial state.
    fn build(&mut self, ctx: &BuildContext) -> Result<(), ParamError> {
        let _ = ctx;
        Ok(())
    }
    /// Phase 1 of a step: write the outputs `y` of sample `tick`.
    ///
    /// **A block with direct feed-through** ([`Block::direct_feedthrough`] true, the
    /// default) gets no [`Block::update`] call: it must advance its own state here,
    /// after computing `y` from `u` (e.g. `y = C x + D u; x = A x + B u`). The
    /// scheduler calls `output` exactly once per sample of the block's rate, so this
    /// is safe.
    fn output(&mut self, tick: Tick, u: &[f64], y: &mut [f64]);
    /// Phase 2 of a step (blocks **without** feed-through only): advance the state
    /// with the inputs `u` of sample `tick`. Never called for feed-through blocks
    /// (see [`Block::output`]).
    fn update(&mut self, tick: Tick, u: &[f64]) {
        let _ = (tick, u);
    }
    /// The block's discrete-time LTI model at its own rate (from all inputs to all
    /// outputs, ports concatenated), if it is linear time-invariant. Valid after
    /// [`Block::build`]. Lets tools analyse loops before a graph runs.
    fn lti(&self) -> Option<StateSpace> {
        None
    }
    /// The linear model(s) a loop through this block is *judged on* when the block
    /// is not exactly LTI (a saturation: gain 1; a quantiser: gain 1; a plant:
    /// its model at the operating point; a gain-scheduled controller: one model
    /// per schedule point). The stability gate ([`crate::gate`]) uses this before
    /// [`Block::lti`] and says in its report that the loop was judged on a
    /// linearisation. `None`: use [`Block::lti`] (or, if that is `None` too, the
    /// block cannot be linearised and its loops are "unproven").
    fn linearisation(&self) -> Option<Linearisation> {
        None
    }
    /// The block's *incremental sector* (slope range), if its input–output map
    /// has one: see [`Sector`]. The stability gate ([`crate::gate`]) uses it for
    /// a block with neither [`Block::linearisation`] nor [`Block::lti`]: the loop
    /// is judged at the centre slope and proven for every slope history in the
    /// range by the circle criterion. Valid after [`Block::build`] (the range may
    /// depend on the built state). `None` (the default): no such bound is known,
    /// and the block's loops stay "unproven".
    fn sector(&self) -> Option<Sector> {
        None
    }
    /// For learning blocks (repetitive control and its variants): the filters and
    /// delay range the stability gate ([`crate::gate`]) needs to evaluate the
    /// convergence criteria (5.5)/(5.9) with the T of the loop the block is in.
    /// The gate then analyses the loop with the block's output set to zero and
    /// checks the criterion on top. Valid after [`Block::build`].
    fn learning(&self) -> Option<crate::learning::LearningModel> {
        None
    }
    /// Heap memory (bytes) the block holds after [`Block::build`] beyond its ports:
    /// delay lines, memories, tables. The graph compiler adds these up with the
    /// signal and log buffers and refuses a graph above
    /// [`MAX_GRAPH_BYTES`](crate::graph::MAX_GRAPH_BYTES). Blocks whose state is a
    /// few numbers keep the default 0.
    fn memory_bytes(&self) -> usize {
        0
    }
    /// The heap memory [`Block::build`] will allocate at sample period `dt` (s),
    /// from the parameters alone (before it is built), and the field that sets
    /// it: the graph compiler adds
    /// these up and refuses a graph above
    /// [`MAX_GRAPH_BYTES`](crate::graph::MAX_GRAPH_BYTES) before any block
    /// allocates anything. Blocks with large buffers (delay lines, memories)
    /// implement it; the default is `("", 0)`.
    fn planned_bytes(&self, dt: f64) -> (&'static str, usize) {
        let _ = dt;
        ("", 0)
    }
    /// The role the block plays.
    fn role(&self) -> Role {
        Role::Math
    }
    /// The block's fittable parameters, if it has any (see [`Tunable`]).
    fn tunable(&self) -> Option<&dyn Tunable> {
        None
    }
    /// Mutable access to the block's fittable parameters.
    fn tunable_mut(&mut self) -> Option<&mut dyn Tunable> {
        None
    }
    /// Names (as spelled in YAML) of the parameters that may change while the
    /// graph runs, between two ticks, **keeping the block's state** (an
    /// integrator keeps its value when a gain changes): slot `i` of
    /// [`Block::set_live_param`] is `live_params()[i]`. The default: none.
    /// A block with a `#[block(…)]` declares them there (`live = "kp,
    /// zero_hz"`, [`DeclaredBlock::LIVE_PARAMS`]) and [`declared_block`]
    /// writes this method.
    /// `nanomotion rt` applies such changes from the terminal
    /// (`set ctrl.kp=1.2`), see `nanomotion-rt`'s `ParamSender`.
    fn live_params(&self) -> &'static [&'static str] {
        &[]
    }
    /// Set live parameter `slot` (an index into [`Block::live_params`]) to
    /// `value` between two ticks and re-derive what depends on it, keeping the
    /// state. **Real-time path**: must not allocate, lock or look up strings.
    /// The caller has validated the value beforehand, by building a copy of
    /// the block with it ([`Block::build`] gives the block's own message for a
    /// bad value); a slot out of range is ignored.
    fn set_live_param(&mut self, slot: usize, value: f64) {
        let _ = (slot, value);
    }
}

/// What [`Block::linearisation`] returns: the model(s) the block is judged on and
/// why they are not exact.
#[derive(Debug, Clone, PartialEq)]
pub struct Linearisation {
    /// One model per operating/schedule point, each with a label (e.g.
    /// `"K = 2.5"`); discrete at the block's rate, inputs and outputs as for
    /// [`Block::lti`]. At least one.
    pub points: Vec<(String, StateSpace)>,
    /// What the linearisation leaves out, e.g. `"output limits ignored (gain 1
    /// inside [-2000, 2000])"`.
    pub note: String,
}

impl Linearisation {
    /// A single model with a note.
    pub fn single(model: StateSpace, note: impl Into<String>) -> Self {
        Self {
            points: vec![(String::new(), model)],
            note: note.into(),
        }
    }
}

/// What [`Block::sector`] returns: an **incremental sector** (slope range)
/// `[lower, upper]` of a square block (total input width = total output width,
/// ports concatenated, channel i of the output paired with channel i of the
/// input).
///
/// **The promise.** For any two successive samples k−1, k of the block's rate and
/// every channel i, with finite inputs,
///
/// ```text
/// y_i[k] − y_i[k−1] = s · (u_i[k] − u_i[k−1])   for some s ∈ [lower, upper]
/// ```
///
/// (s may depend on the channel, the sample and the block's state; when the input
/// does not move the output does not move). It must hold from the block's built
/// state on, for every finite input sequence — a bound that holds only for
/// bounded inputs or from some states is not a sector.
///
/// **Why increments.** Write s_k for the slope of sample k. If the rest of the
/// loop is LTI (reference and disturbances constant), the increments
/// Δx(k) = x(k) − x(k−1) of every signal satisfy the same LTI loop with the block
/// replaced by the time-varying gain s_k ∈ [lower, upper]: its memory (a
/// hysteresis loop, the play of a backlash) is in s_k. If that time-varying loop
/// is stable for every slope history (the gate proves it with the circle
/// criterion, see [`crate::gate`]), the increments decay exponentially and the
/// loop settles, whatever the block's memory; equilibria need no separate proof.
/// A sector on values (y/u ∈ [a, b]) would not do: hysteresis and backlash
/// have none (y ≠ 0 at u = 0).
#[derive(Debug, Clone, PartialEq)]
pub struct Sector {
    /// Smallest slope (finite).
    pub lower: f64,
    /// Largest slope (finite, ≥ `lower`).
    pub upper: f64,
    /// Where the range comes from, e.g. `"Coleman–Hodgdon: slopes between 2c − b and
    /// b"` (shown in the gate's report).
    pub note: String,
}

impl Sector {
    /// The range `[lower, upper]` with a note.
    pub fn new(lower: f64, upper: f64, note: impl Into<String>) -> Self {
        Self {
            lower,
            upper,
            note: note.into(),
        }
    }
    /// The centre slope k0 = (lower + upper)/2: the gain the loop is judged at.
    pub fn centre(&self) -> f64 {
        0.5 * (self.lower + self.upper)
    }
    /// The radius r = (upper − lower)/2: how far a slope may be from the centre.
    pub fn radius(&self) -> f64 {
        0.5 * (self.upper - self.lower)
    }
    /// Whether `s` lies in the range, with a relative tolerance `tol` of the
    /// range's scale (for tests of blocks against their declared range).
    pub fn contains(&self, s: f64, tol: f64) -> bool {
        let scale = self
            .lower
            .abs()
            .max(self.upper.abs())
            .max(f64::MIN_POSITIVE);
        s >= self.lower - tol * scale && s <= self.upper + tol * scale
    }
}

pub use crate::doc::{BlockDoc, ParamDoc, Role, block_docs};

/// Completes an `impl Block for T` from `T`'s `#[block(…)]` (module
/// documentation): the typetag registration under the declared `type_name`,
/// `live_params` from the declared `live`, and `inputs`/`outputs`, `role` and
/// `build` where the impl leaves them out.
pub use nanomotion_derive::declared_block;

/// What a block's `#[block(type_name = "…", role = …, ports = "…", live =
/// "…")]` declares, implemented by `#[derive(Params)]`; [`declared_block`]
/// reads it.
pub trait DeclaredBlock {
    /// The block's `type:` in a graph file (its typetag name).
    const TYPE_NAME: &'static str;
    /// The role the block plays ([`Block::role`]).
    const ROLE: Role;
    /// The parameters that may change while the graph runs
    /// ([`Block::live_params`], in slot order; `live = "kp, zero_hz"`), none
    /// when `live` is left out. The one declaration of them: the block's
    /// `live_params`, its [`BlockDoc::live`] (`nanomotion blocks`) and
    /// [`live_params_by_type`](crate::doc::live_params_by_type) read it.
    const LIVE_PARAMS: &'static [&'static str];
}

/// The ports a block's `#[block(ports = "…")]` declares, implemented by
/// `#[derive(Params)]` when the string is a declaration (`name[width] (unit)
/// [scheduling]`, see [`crate::doc`]) rather than a description; [`declared_block`]
/// makes them [`Block::inputs`] and [`Block::outputs`].
#[diagnostic::on_unimplemented(
    message = "the `ports` of `{Self}`'s #[block(…)] describe its ports but do not declare them",
    note = "write `fn inputs` and `fn outputs` in its `impl Block`, or make `ports` a declaration: `name[width] (unit) [scheduling], … -> …` (widths: numbers or usize fields; units: SI symbols)"
)]
pub trait DeclaredPorts: DeclaredBlock {
    /// The declared inputs, in order.
    fn declared_inputs(&self) -> Vec<Port>;
    /// The declared outputs, in order.
    fn declared_outputs(&self) -> Vec<Port>;
}

/// All block types registered with `typetag` (every linked crate), sorted.
///
/// typetag does not expose its registry, so this asks it: deserialising an unknown
/// tag makes it list the known ones.
pub fn registered_types() -> Vec<String> {
    let probe = "type: no_such_block_zz\n";
    match crate::yaml::from_str::<Box<dyn Block>>(probe, "probe") {
        Ok(_) => Vec::new(),
        Err(e) => parse_expected_list(&e.to_string()),
    }
}

/// Parse serde's "expected one of `a`, `b`" list out of an error message.
pub(crate) fn parse_expected_list(msg: &str) -> Vec<String> {
    let Some(pos) = msg.find("expected one of") else {
        return Vec::new();
    };
    let rest = &msg[pos + "expected one of".len()..];
    let mut line = rest.lines().next().unwrap_or("");
    if let Some(at) = line.find(" at line ") {
        line = &line[..at];
    }
    let mut v: Vec<String> = line
        .split(',')
        .map(|s| s.trim().trim_matches('`').trim().to_string())
        .filter(|s| !s.is_empty())
        .collect();
    v.sort();
    v.dedup();
    v
}

/// Parameter validation helpers for [`Block::build`]; each returns a
/// [`ParamError`] naming the field and the fix.
pub mod check {
    use crate::error::ParamError;

    /// `value` must be finite.
    pub fn finite(field: &str, value: f64) -> Result<(), ParamError> {
        if value.is_finite() {
            Ok(())
        } else {
            Err(ParamError::new(
                field,
                format!("is {value}, not a finite number"),
                "give a finite number",
            ))
        }
    }
    /// Every element of `values` must be finite.
    pub fn all_finite(field: &str, values: &[f64]) -> Result<(), ParamError> {
        match values.iter().position(|v| !v.is_finite()) {
            None => Ok(()),
            Some(i) => Err(ParamError::new(
                format!("{field}[{i}]"),
                format!("is {}, not a finite number", values[i]),
                "give finite numbers",
            )),
        }
    }
    /// `value` must be finite and > 0.
    pub fn positive(field: &str, value: f64) -> Result<(), ParamError> {
        finite(field, value)?;
        if value > 0.0 {
            Ok(())
        } else {
            Err(ParamError::new(
                field,
                format!("is {value}, must be > 0"),
                "give a positive value",
            ))
        }
    }
    /// `value` must be finite and ≥ 0.
    pub fn non_negative(field: &str, value: f64) -> Result<(), ParamError> {
        finite(field, value)?;
        if value >= 0.0 {
            Ok(())
        } else {
            Err(ParamError::new(
                field,
                format!("is {value}, must be ≥ 0"),
                "give a non-negative value",
            ))
        }
    }
    /// `value` must be finite and in `[lo, hi]`.
    pub fn in_range(field: &str, value: f64, lo: f64, hi: f64) -> Result<(), ParamError> {
        finite(field, value)?;
        if (lo..=hi).contains(&value) {
            Ok(())
        } else {
            Err(ParamError::new(
                field,
                format!("is {value}, outside [{lo}, {hi}]"),
                format!("give a value in [{lo}, {hi}]"),
            ))
        }
    }
    // One end of an interval: declared in `doc` (the derive's schema reads it;
    // `doc` is below `block`), used here by the checks.
    pub use crate::doc::Limit;

    /// The interval in words: `> 0`, `≤ 1`, `(0, 1]`; the bracket or operator
    /// says whether an end is included.
    fn interval<T: std::fmt::Display>(lo: Option<Limit<T>>, hi: Option<Limit<T>>) -> String {
        match (lo, hi) {
            (Some(lo), Some(hi)) => {
                let (a, l) = match lo {
                    Limit::Inclusive(x) => ('[', x),
                    Limit::Exclusive(x) => ('(', x),
                };
                let (b, h) = match hi {
                    Limit::Inclusive(x) => (']', x),
                    Limit::Exclusive(x) => (')', x),
                };
                format!("in {a}{l}, {h}{b}")
            }
            (Some(Limit::Inclusive(x)), None) => format!("≥ {x}"),
            (Some(Limit::Exclusive(x)), None) => format!("> {x}"),
            (None, Some(Limit::Inclusive(x))) => format!("≤ {x}"),
            (None, Some(Limit::Exclusive(x))) => format!("< {x}"),
            (None, None) => "any value".into(),
        }
    }

    /// `value` must be finite and within `lo` and `hi`, each end inclusive or
    /// exclusive, either left out (`> 0`, `in (0, 1]`, `≤ 1`). Two inclusive
    /// ends give exactly [`in_range`]'s message.
    pub fn between(
        field: &str,
        value: f64,
        lo: Option<Limit<f64>>,
        hi: Option<Limit<f64>>,
    ) -> Result<(), ParamError> {
        if let (Some(Limit::Inclusive(l)), Some(Limit::Inclusive(h))) = (lo, hi) {
            return in_range(field, value, l, h);
        }
        finite(field, value)?;
        if admits(value, lo, hi) {
            return Ok(());
        }
        let words = interval(lo, hi);
        let problem = match (lo, hi) {
            (Some(_), Some(_)) => format!("is {value}, not {words}"),
            _ => format!("is {value}, must be {words}"),
        };
        Err(ParamError::new(
            field,
            problem,
            format!("give a value {words}"),
        ))
    }

    /// A whole number (a count, an order, an iteration cap) within `lo` and
    /// `hi`, each end inclusive or exclusive, either left out. The interval is
    /// said as the whole numbers it holds (`> 0` is `≥ 1`); two ends give
    /// [`size`]'s message, so a `usize` and a `u32` count read the same.
    pub fn whole(
        field: &str,
        value: i128,
        lo: Option<Limit<i128>>,
        hi: Option<Limit<i128>>,
    ) -> Result<(), ParamError> {
        let (lo, hi) = whole_ends(lo, hi);
        if lo.is_none_or(|l| value >= l) && hi.is_none_or(|h| value <= h) {
            return Ok(());
        }
        let (problem, fix) = match (lo, hi) {
            (Some(l), Some(h)) => (
                format!("is {value}, outside the allowed range [{l}, {h}]"),
                format!("give a whole number in [{l}, {h}]"),
            ),
            (Some(l), None) => (
                format!("is {value}, must be ≥ {l}"),
                format!("give a whole number ≥ {l}"),
            ),
            (None, Some(h)) => (
                format!("is {value}, must be ≤ {h}"),
                format!("give a whole number ≤ {h}"),
            ),
            (None, None) => unreachable!("no bound refuses nothing"),
        };
        Err(ParamError::new(field, problem, fix))
    }

    /// `lo` must be ≤ `hi` (both finite).
    pub fn ordered(field_lo: &str, lo: f64, field_hi: &str, hi: f64) -> Result<(), ParamError> {
        finite(field_lo, lo)?;
        finite(field_hi, hi)?;
        if lo <= hi {
            Ok(())
        } else {
            Err(ParamError::new(
                field_lo,
                format!("{field_lo} = {lo} is larger than {field_hi} = {hi}"),
                format!("make {field_lo} ≤ {field_hi}"),
            ))
        }
    }
    // Intervals (whether a value lies in one, its whole-number ends) and a
    // list's length in words: declared in `doc` beside `Limit` (the schema
    // uses them too), used here by the checks.
    use crate::doc::{admits, entries_of, entries_words, whole_ends};

    /// A list of `n` entries whose count must be within `lo` and `hi` (each end
    /// inclusive or exclusive, either left out): `#[param(len(…))]`.
    pub fn entries(
        field: &str,
        n: usize,
        lo: Option<Limit<i128>>,
        hi: Option<Limit<i128>>,
    ) -> Result<(), ParamError> {
        let count = n as i128;
        if admits(count, lo, hi) {
            return Ok(());
        }
        let words = entries_words(lo, hi).unwrap_or_default();
        let problem = if n == 0 {
            "is empty".to_string()
        } else {
            format!("has {}, must have {words}", entries_of(count))
        };
        Err(ParamError::new(field, problem, format!("give {words}")))
    }

    /// A list of numbers, each above the one before (breakpoints, sample
    /// times): `#[param(increasing)]`. The error names the first entry that
    /// is not (`x[2]`).
    pub fn increasing(field: &str, values: &[f64]) -> Result<(), ParamError> {
        match (1..values.len())
            .find(|&j| values[j].partial_cmp(&values[j - 1]) != Some(std::cmp::Ordering::Greater))
        {
            None => Ok(()),
            Some(j) => Err(ParamError::new(
                format!("{field}[{j}]"),
                format!(
                    "is {}, not above the entry before it, {}",
                    values[j],
                    values[j - 1]
                ),
                "sort the entries strictly increasing",
            )),
        }
    }

    /// Two lists that pair entry by entry (breakpoints and their values) hold
    /// as many entries: `#[param(same_len = other)]`.
    pub fn same_len(field: &str, n: usize, other: &str, m: usize) -> Result<(), ParamError> {
        if n == m {
            Ok(())
        } else {
            Err(ParamError::new(
                field,
                format!(
                    "has {}, {other} has {}",
                    entries_of(n as i128),
                    entries_of(m as i128)
                ),
                format!("give as many entries in {field} as in {other}, one per pair"),
            ))
        }
    }

    /// A frequency `f_hz` (Hz, its own bounds checked before) below the Nyquist
    /// frequency of the block's period `dt`: `#[param(below_nyquist)]`.
    pub fn below_nyquist(field: &str, f_hz: f64, dt: f64) -> Result<(), ParamError> {
        let nyq = 0.5 / dt;
        if f_hz < nyq {
            Ok(())
        } else {
            Err(ParamError::new(
                field,
                format!(
                    "{f_hz} Hz is not below the Nyquist frequency {nyq} Hz of the block's rate"
                ),
                "lower the frequency or raise the block's rate",
            ))
        }
    }

    /// `value` must be ≥ 1.
    pub fn at_least_one(field: &str, value: usize) -> Result<(), ParamError> {
        if value >= 1 {
            Ok(())
        } else {
            Err(ParamError::new(field, "is 0", "give at least 1"))
        }
    }

    /// A size (count of things a block allocates or loops over) must be in
    /// `[lo, hi]`. Every size parameter of every block goes through this (or
    /// [`width`], [`buffer`]) before anything is allocated, so a huge value in a
    /// graph file is an error naming the field, never an allocation abort.
    pub fn size(field: &str, value: usize, lo: usize, hi: usize) -> Result<(), ParamError> {
        if (lo..=hi).contains(&value) {
            Ok(())
        } else {
            Err(ParamError::new(
                field,
                format!("is {value}, outside the allowed range [{lo}, {hi}]"),
                format!("give a whole number in [{lo}, {hi}]"),
            ))
        }
    }

    /// A port or channel width: `1 ..= MAX_WIDTH`.
    pub fn width(field: &str, value: usize) -> Result<(), ParamError> {
        size(field, value, 1, super::MAX_WIDTH)
    }

    /// A buffer of `samples` samples of `width` values each (delay lines,
    /// repetitive-control memories): `samples` in `[lo, MAX_BUFFER_VALUES]` and
    /// `samples · width ≤ MAX_BUFFER_VALUES`.
    pub fn buffer(field: &str, samples: usize, lo: usize, width: usize) -> Result<(), ParamError> {
        size(field, samples, lo, super::MAX_BUFFER_VALUES)?;
        match samples.checked_mul(width.max(1)) {
            Some(v) if v <= super::MAX_BUFFER_VALUES => Ok(()),
            _ => Err(ParamError::new(
                field,
                format!(
                    "{samples} samples × width {width} is more than {} buffered values ({} MiB)",
                    super::MAX_BUFFER_VALUES,
                    (super::MAX_BUFFER_VALUES * 8) >> 20
                ),
                "give a shorter buffer or fewer channels",
            )),
        }
    }

    /// A duration in seconds that a block turns into a number of samples at
    /// period `dt`: finite, ≥ 0, and at most `max_samples` samples. Returns the
    /// number of samples (rounded to the nearest; exact multiples are the caller's
    /// business).
    pub fn samples_of(
        field: &str,
        seconds: f64,
        dt: f64,
        max_samples: usize,
    ) -> Result<usize, ParamError> {
        non_negative(field, seconds)?;
        let n = (seconds / dt).round();
        if n.is_finite() && n <= max_samples as f64 {
            Ok(n as usize)
        } else {
            Err(ParamError::new(
                field,
                format!(
                    "{seconds} s is {n:e} samples at the block period {dt} s, more than {max_samples}"
                ),
                format!("give at most {} s", max_samples as f64 * dt),
            ))
        }
    }
}

/// Largest width of a port (values per sample), and of the channel count of any
/// block (`width`, `widths[i]`): 1024. Checked by every block's `build` and again
/// by the graph compiler for every port of every block.
pub const MAX_WIDTH: usize = 1024;

/// Largest number of `f64` values one block may buffer (delay lines, repetitive
/// memories, FIR taps): 2^24 = 16 777 216 values, 128 MiB.
pub const MAX_BUFFER_VALUES: usize = 1 << 24;

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn expected_list_is_parsed() {
        let v = parse_expected_list("unknown variant `x`, expected one of `b`, `a`, `c` at line 1");
        assert_eq!(v, vec!["a", "b", "c"]);
        let v = parse_expected_list("unknown variant `x`, expected one of b, a");
        assert_eq!(v, vec!["a", "b"]);
    }

    #[test]
    fn checks_name_field_and_fix() {
        let e = check::positive("mass_kg", -1.0).unwrap_err();
        assert_eq!(e.field, "mass_kg");
        assert!(e.to_string().contains("> 0"));
        assert!(check::finite("k", f64::NAN).is_err());
        assert!(check::in_range("q", 0.5, 0.0, 1.0).is_ok());
        assert!(check::in_range("q", 1.5, 0.0, 1.0).is_err());
        assert_eq!(
            check::all_finite("num", &[1.0, f64::INFINITY])
                .unwrap_err()
                .field,
            "num[1]"
        );
    }
}
