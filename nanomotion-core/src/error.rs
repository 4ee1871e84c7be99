//! Typed errors. Every error names the place (block, field, line/column where the
//! YAML parser gives them) and says how to fix it.

use thiserror::Error;

/// A block parameter that fails validation when the block is built.
#[derive(Debug, Clone, PartialEq, Error)]
#[error("field `{field}`: {problem} (fix: {fix})")]
pub struct ParamError {
    /// Name of the offending field, as spelled in YAML (`kp`, `mass_kg`, ...).
    pub field: String,
    /// What is wrong with it.
    pub problem: String,
    /// How to fix it.
    pub fix: String,
}

impl ParamError {
    /// A new parameter error.
    pub fn new(
        field: impl Into<String>,
        problem: impl Into<String>,
        fix: impl Into<String>,
    ) -> Self {
        Self {
            field: field.into(),
            problem: problem.into(),
            fix: fix.into(),
        }
    }
}

/// Everything that can go wrong between a YAML file and a running graph.
///
/// Connection `index` fields are 0-based positions in `connections`; messages
/// count from 1 ("connection 1" is the first entry), as a reader of the file does.
#[derive(Debug, Error)]
pub enum GraphError {
    /// An error about one entry of the file, with where it is.
    #[error("{origin}: line {line}: {source}")]
    At {
        /// The graph file.
        origin: String,
        /// Line of the entry (1-based).
        line: usize,
        /// The error.
        #[source]
        source: Box<GraphError>,
    },
    /// The YAML did not parse or did not match the graph schema (unknown field,
    /// wrong type, unknown block type, ...). The message carries line and column.
    #[error("{origin}: {message}")]
    Parse { origin: String, message: String },
    /// A block's parameters are invalid.
    #[error("block `{block}` (type `{type_name}`): {source}")]
    Param {
        block: String,
        type_name: String,
        #[source]
        source: ParamError,
    },
    /// Two blocks share a name.
    #[error("duplicate block name `{name}`: block names must be unique (rename one of them)")]
    DuplicateName { name: String },
    /// A connection names a block that does not exist.
    #[error("connection {n} (`{reference}`): unknown block `{block}`{hint}", n = .index + 1)]
    UnknownBlock {
        index: usize,
        reference: String,
        block: String,
        hint: String,
    },
    /// A connection names a port the block does not have.
    #[error(
        "connection {n} (`{reference}`): block `{block}` has no {direction} port `{port}`; its {direction} ports are: {known}",
        n = .index + 1
    )]
    UnknownPort {
        index: usize,
        reference: String,
        block: String,
        port: String,
        direction: &'static str,
        known: String,
    },
    /// A port reference is not of the form `block.port`.
    #[error("connection {n}: `{reference}` is not a port reference; write it as `block.port`", n = .index + 1)]
    BadReference { index: usize, reference: String },
    /// The two ends of a connection have different widths.
    #[error(
        "connection {n} (`{from}` -> `{to}`): width mismatch, `{from}` carries {from_width} values but `{to}` expects {to_width}",
        n = .index + 1
    )]
    WidthMismatch {
        index: usize,
        from: String,
        to: String,
        from_width: usize,
        to_width: usize,
    },
    /// An input port is fed by nothing.
    #[error("input `{block}.{port}` is not connected: add a connection `to: {block}.{port}`")]
    Unconnected { block: String, port: String },
    /// An input port is fed twice.
    #[error(
        "input `{to}` is connected twice (connections {a} and {b}); an input takes exactly one source, use a `sum` block to add signals",
        a = .first + 1,
        b = .second + 1
    )]
    DoubleConnection {
        to: String,
        first: usize,
        second: usize,
    },
    /// A block's rate is not an integer divisor of the base rate.
    #[error(
        "block `{block}`: rate {rate_hz} Hz is not an integer divisor of the base rate {base_rate_hz} Hz (fix: choose base_rate_hz / k for an integer k)"
    )]
    BadRate {
        block: String,
        rate_hz: f64,
        base_rate_hz: f64,
    },
    /// Connecting blocks of different rates while the graph asked for strict rates.
    #[error(
        "connection {n} (`{from}` -> `{to}`): rates differ ({from_hz} Hz -> {to_hz} Hz) and `strict_rates: true` forbids implicit rate transitions; insert a `rate_transition` block or give both blocks the same rate",
        n = .index + 1
    )]
    RateMismatch {
        index: usize,
        from: String,
        to: String,
        from_hz: f64,
        to_hz: f64,
    },
    /// A cycle of blocks with direct feed-through.
    #[error(
        "algebraic loop: {cycle}; break it with a block without direct feed-through (e.g. `delay` with d: 1, or a plant)"
    )]
    AlgebraicLoop { cycle: String },
    /// A graph-level setting is invalid.
    #[error("graph setting `{field}`: {problem} (fix: {fix})")]
    Setting {
        field: String,
        problem: String,
        fix: String,
    },
    /// A logged or scored signal does not exist.
    #[error("{section} entry `{reference}`: {problem}")]
    BadSignal {
        section: &'static str,
        reference: String,
        problem: String,
    },
    /// A block produced a non-finite output (found by
    /// [`Scheduler::check_finite`](crate::scheduler::Scheduler::check_finite)).
    #[error(
        "block `{block}` (type `{type_name}`) produced a non-finite output ({value} in `{block}.{port}`) at base tick {tick} (t = {t_s} s), the first in the run (fix: check its parameters and inputs; an unstable loop diverges, see its gains and sample rate)"
    )]
    NonFinite {
        block: String,
        type_name: String,
        port: String,
        value: f64,
        tick: u64,
        t_s: f64,
    },
    /// A non-finite value was seen but replaying the run from the start did not
    /// produce it again.
    #[error(
        "a non-finite value appeared by base tick {tick} ({place}), but replaying the run from its initial state did not reproduce it (fix: reset the scheduler before running, and do not change blocks during a run)"
    )]
    NonFiniteNotReproduced { tick: u64, place: String },
    /// The file could not be read.
    #[error("cannot read `{path}`: {source}")]
    Io {
        path: String,
        #[source]
        source: std::io::Error,
    },
    /// A parameter override (`--set PATH=VALUE`, a sweep parameter) names a path
    /// that does not exist, gives a value of the wrong type, or a value the graph
    /// rejects (see [`crate::overrides`]).
    #[error("override `{path}`: {problem} (fix: {fix})")]
    Override {
        /// The dotted path as written.
        path: String,
        /// What is wrong.
        problem: String,
        /// How to fix it.
        fix: String,
    },
}

impl GraphError {
    /// The error itself, without the file location an [`GraphError::At`] adds.
    pub fn root(&self) -> &GraphError {
        match self {
            GraphError::At { source, .. } => source.root(),
            e => e,
        }
    }
}
