//! The schema of a graph file ([`GraphSpec`] and its parts), the limits a graph
//! must keep, and the builder methods for graphs written in Rust. Reading YAML is
//! in `load.rs`, compiling to a [`Scheduler`](crate::scheduler::Scheduler) in
//! `compile.rs`.

use crate::Params;
use crate::block::Block;
use crate::require::Require;
use crate::scheduler::Scheduler;
use serde::{Deserialize, Serialize};
use serde_json::{Value, json};

/// One block of a graph: instance name, optional rate, and the block itself
/// (its `type:` and parameters, flattened into the same YAML map).
///
/// Its `name` and `rate_hz` are the keys every entry of a graph's `blocks:` has
/// besides the block's own (`nanomotion schema` takes them from here).
#[derive(Debug, Serialize, Deserialize, Params)]
pub struct BlockSpec {
    /// Unique instance name: ASCII letters, digits, `_`, `-` (no `.`, which separates
    /// block and port, and no `:`, reserved for inserted blocks).
    #[param(schema = "block_name_schema")]
    pub name: String,
    /// Rate in Hz; must divide the base rate. Default: the base rate.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    #[param(schema = "rate_schema")]
    pub rate_hz: Option<f64>,
    /// The block: `type:` tag and its parameters.
    #[serde(flatten)]
    pub block: Box<dyn Block>,
}

/// A connection from an output port to an input port (`block.port`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, Params)]
#[serde(deny_unknown_fields)]
pub struct Connection {
    /// Source, `block.port` of an output.
    #[param(schema = "signal_schema")]
    pub from: String,
    /// Destination, `block.port` of an input.
    #[param(schema = "signal_schema")]
    pub to: String,
}

/// An error signal to score (rms, max, ... after the run).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, Params)]
#[serde(deny_unknown_fields)]
pub struct ScoreSpec {
    /// The signal, `block.port` of an output.
    #[param(schema = "signal_schema")]
    pub signal: String,
    /// Ignore samples before this time (s), to skip start-up transients.
    #[serde(default)]
    #[param(schema = "seconds_schema")]
    pub from_s: f64,
}

/// A model output paired with a measured column (`nanomotion run --data`,
/// `nanomotion diagnose`): the residual is `measured − model`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, Params)]
#[serde(deny_unknown_fields)]
pub struct CompareSpec {
    /// The model signal, `block.port` of an output of width 1.
    #[param(schema = "signal_schema")]
    pub signal: String,
    /// The measured column of the data file.
    pub column: String,
}

/// What to do when a tick on the wall clock ends after the next deadline
/// (`realtime: { overrun: … }`, `nanomotion rt --overrun`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum OverrunPolicy {
    /// Drop the ticks whose deadlines have passed and go on at the next deadline
    /// still ahead: the loop stays on its grid, the graph's time falls behind the
    /// wall clock by the skipped ticks (counted as missed ticks).
    #[default]
    Skip,
    /// Run the late ticks back to back, without sleeping, until the loop is on
    /// its grid again: no tick is lost, some run late.
    CatchUp,
}

impl std::str::FromStr for OverrunPolicy {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        match s {
            "skip" => Ok(Self::Skip),
            "catch-up" => Ok(Self::CatchUp),
            _ => Err(format!(
                "unknown overrun policy `{s}` (fix: `skip` or `catch-up`)"
            )),
        }
    }
}

impl OverrunPolicy {
    /// The spelling in YAML, on the command line and in JSON.
    pub fn as_str(self) -> &'static str {
        match self {
            Self::Skip => "skip",
            Self::CatchUp => "catch-up",
        }
    }
}

impl Serialize for OverrunPolicy {
    fn serialize<S: serde::Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        s.serialize_str(self.as_str())
    }
}

/// Read through [`FromStr`](std::str::FromStr), so that a bad value gets its
/// own message and fix (not the block-type hint of an unknown `type:`).
impl<'de> Deserialize<'de> for OverrunPolicy {
    fn deserialize<D: serde::Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        let s = String::deserialize(d)?;
        s.parse().map_err(serde::de::Error::custom)
    }
}

/// The `realtime:` section of a graph: how it runs on the wall clock. Every
/// field is optional; the command line's `--overrun` and `--max-overruns`
/// replace the graph's.
///
/// ```yaml
/// realtime:
///   overrun: catch-up     # or skip (the default)
///   max_overruns: 0       # stop, outputs safe, at the first overrun
/// ```
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize, Params)]
#[serde(deny_unknown_fields)]
pub struct RealtimeSpec {
    /// What to do when a tick ends after the next deadline: `skip` the missed
    /// deadlines (stay on the grid) or `catch-up` (run the late ticks back to
    /// back).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    #[param(schema = "overrun_schema")]
    pub overrun: Option<OverrunPolicy>,
    /// Stop the loop (outputs to their safe values) after more than this many
    /// overruns; absent: never.
    #[serde(
        default,
        skip_serializing_if = "Option::is_none",
        deserialize_with = "max_overruns"
    )]
    #[param(schema = "count_schema")]
    pub max_overruns: Option<u64>,
}

/// `max_overruns`: a whole number ≥ 0, or a message naming the field and the fix.
fn max_overruns<'de, D: serde::Deserializer<'de>>(d: D) -> Result<Option<u64>, D::Error> {
    struct Count;
    const FIX: &str = "max_overruns must be a whole number ≥ 0 (fix: e.g. `max_overruns: 0` to stop at the first overrun, or leave it out for no limit)";
    impl serde::de::Visitor<'_> for Count {
        type Value = Option<u64>;
        fn expecting(&self, f: &mut std::fmt::Formatter) -> std::fmt::Result {
            f.write_str(FIX)
        }
        fn visit_u64<E: serde::de::Error>(self, v: u64) -> Result<Self::Value, E> {
            Ok(Some(v))
        }
        fn visit_i64<E: serde::de::Error>(self, v: i64) -> Result<Self::Value, E> {
            u64::try_from(v)
                .map(Some)
                .map_err(|_| E::custom(format!("{v}: {FIX}")))
        }
        fn visit_f64<E: serde::de::Error>(self, v: f64) -> Result<Self::Value, E> {
            Err(E::custom(format!("{v}: {FIX}")))
        }
        fn visit_str<E: serde::de::Error>(self, v: &str) -> Result<Self::Value, E> {
            Err(E::custom(format!("`{v}`: {FIX}")))
        }
    }
    d.deserialize_any(Count)
}

impl RealtimeSpec {
    /// These settings, each replaced by `over`'s where `over` has one (the
    /// command line over the graph file).
    pub fn overridden_by(self, over: RealtimeSpec) -> RealtimeSpec {
        RealtimeSpec {
            overrun: over.overrun.or(self.overrun),
            max_overruns: over.max_overruns.or(self.max_overruns),
        }
    }
}

/// A whole graph as written in YAML. Its fields (names, docs, defaults, which are
/// required, no others allowed) are the graph-level part of `nanomotion schema`
/// ([`graph_schema`](crate::graph::graph_schema)).
#[derive(Debug, Serialize, Deserialize, Params)]
#[serde(deny_unknown_fields)]
pub struct GraphSpec {
    /// Optional title, shown in reports and plots.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    #[param(schema = "title_schema")]
    pub title: Option<String>,
    /// Base tick rate (Hz): every block's rate must divide it.
    #[param(schema = "rate_schema")]
    pub base_rate_hz: f64,
    /// Simulated duration (s). May be left out of a graph that reads measured
    /// data ([`GraphSpec::reads_data`]): it is then the data's length. Left out,
    /// it reads as NaN until the graph is built with its data.
    #[serde(
        default = "duration_from_data",
        skip_serializing_if = "duration_absent"
    )]
    #[param(schema = "seconds_schema")]
    pub duration_s: f64,
    /// Seed of all random blocks (each block derives its own stream from it and its
    /// name).
    #[serde(default)]
    pub seed: u64,
    /// Reject connections between different rates instead of inserting rate
    /// transitions.
    #[serde(default)]
    pub strict_rates: bool,
    /// The blocks.
    #[param(schema = "block_entries_schema")]
    pub blocks: Vec<BlockSpec>,
    /// The connections.
    #[serde(default)]
    pub connections: Vec<Connection>,
    /// Output ports to record (`block.port`).
    #[serde(default)]
    #[param(schema = "signals_schema")]
    pub log: Vec<String>,
    /// Error signals to score.
    #[serde(default)]
    pub score: Vec<ScoreSpec>,
    /// Model outputs to compare with measured columns (needs data: `--data`).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub compare: Vec<CompareSpec>,
    /// Stability requirements on the feedback loops (`require:`), checked by the
    /// stability gate ([`crate::gate`]) before the graph runs.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub require: Option<Require>,
    /// How the graph runs on the wall clock (`nanomotion rt`, `nanomotion
    /// plant`, the `nanomotion-rt` crate); a simulation ignores it.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub realtime: Option<RealtimeSpec>,
    /// Where each connection is in the file (origin, 1-based lines), when it
    /// was read from YAML in block style; connection errors then name the line.
    #[serde(skip)]
    pub connection_lines: Option<(String, Vec<usize>)>,
    /// Units of signals (`block.port: unit`), setting or overriding what the
    /// blocks declare; shown in CSV headers, `metrics.json` and plots.
    #[serde(default, skip_serializing_if = "std::collections::BTreeMap::is_empty")]
    #[param(schema = "units_schema")]
    pub units: std::collections::BTreeMap<String, String>,
    /// The folder relative file names in block parameters (`calibration_file`)
    /// are resolved against: the graph file's folder when read with
    /// [`GraphSpec::from_file`], else the working directory. Not part of the YAML.
    #[serde(skip)]
    pub base_dir: Option<std::path::PathBuf>,
}

/// `duration_s` left out: NaN until the data's length replaces it.
fn duration_from_data() -> f64 {
    f64::NAN
}

fn duration_absent(d: &f64) -> bool {
    d.is_nan()
}

/// What the loader did on its own initiative, for the user to see.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct BuildReport {
    /// Rate transitions inserted between blocks of different rates, one line each.
    pub rate_transitions: Vec<String>,
    /// Execution order (block names) of the output phase.
    pub order: Vec<String>,
}

/// Alias kept for readability: a built graph is a [`Scheduler`].
pub type Graph = Scheduler;

/// Maximum number of base ticks a graph may ask for (keeps memory and time sane).
pub const MAX_TICKS: f64 = 2.0e9;

/// Lowest base rate and block rate (Hz): 1 mHz.
pub const MIN_RATE_HZ: f64 = 1e-3;
/// Highest base rate (Hz): 1 GHz.
pub const MAX_RATE_HZ: f64 = 1e9;

/// Base ticks a streamed log holds between two hand-overs to the sink
/// ([`GraphSpec::build_streamed`]): 2^16. A log of width w at period p keeps
/// ⌈2^16 / p⌉ · w values (at most 512 KiB per value of width).
pub const LOG_CHUNK_TICKS: u64 = 1 << 16;

/// Most memory a built graph may hold, estimated at build (bytes): 4 GiB. The
/// estimate adds the signal and input buffers, every log (samples × width × 8
/// bytes, reserved for the whole run, or for [`LOG_CHUNK_TICKS`] when streamed)
/// and each block's
/// [`Block::memory_bytes`]; a graph above it is refused with the breakdown.
pub const MAX_GRAPH_BYTES: usize = 4 << 30;

/// Longest block name, in characters (ASCII).
pub const MAX_BLOCK_NAME_CHARS: usize = 100;

/// Longest `title`, in characters.
pub const MAX_TITLE_CHARS: usize = 200;

/// Longest unit of a signal (`units:`), in characters.
pub const MAX_UNIT_CHARS: usize = 32;

// JSON Schemas of the graph-level fields whose form or bounds are the limits
// above (`#[param(schema = …)]`); the compiler checks the same constants with
// messages that name the file's context.

fn count_schema() -> Value {
    json!({ "type": "integer", "minimum": 0 })
}
fn overrun_schema() -> Value {
    json!({ "enum": [OverrunPolicy::Skip.as_str(), OverrunPolicy::CatchUp.as_str()] })
}
fn rate_schema() -> Value {
    json!({ "type": "number", "minimum": MIN_RATE_HZ, "maximum": MAX_RATE_HZ })
}

fn seconds_schema() -> Value {
    json!({ "type": "number", "minimum": 0 })
}

fn title_schema() -> Value {
    json!({ "type": "string", "maxLength": MAX_TITLE_CHARS })
}

fn block_name_schema() -> Value {
    json!({ "type": "string", "pattern": format!("^[A-Za-z0-9_-]{{1,{MAX_BLOCK_NAME_CHARS}}}$") })
}

fn signal_schema() -> Value {
    json!({ "type": "string", "pattern": "^[^.]+\\.[^.]+$", "description": "`block.port`" })
}

fn signals_schema() -> Value {
    json!({ "type": "array", "items": signal_schema() })
}

/// Each entry is a block of any registered type, or `- include: FILE`
/// (`definitions/block_entry` of [`graph_schema`](crate::graph::graph_schema)).
fn block_entries_schema() -> Value {
    json!({ "type": "array", "items": { "$ref": "#/definitions/block_entry" } })
}

fn units_schema() -> Value {
    json!({
        "type": "object",
        "description": "unit of a signal, `block.port: unit`",
        "additionalProperties": { "type": "string", "minLength": 1, "maxLength": MAX_UNIT_CHARS },
    })
}

impl GraphSpec {
    /// An empty graph at `base_rate_hz` running for `duration_s`, for building graphs
    /// from Rust.
    pub fn new(base_rate_hz: f64, duration_s: f64) -> Self {
        Self {
            title: None,
            base_rate_hz,
            duration_s,
            seed: 0,
            strict_rates: false,
            blocks: Vec::new(),
            connections: Vec::new(),
            log: Vec::new(),
            score: Vec::new(),
            compare: Vec::new(),
            require: None,
            realtime: None,
            units: std::collections::BTreeMap::new(),
            connection_lines: None,
            base_dir: None,
        }
    }

    /// Score error signal `signal` (`block.port`), ignoring samples before
    /// `from_s` seconds.
    pub fn score(&mut self, signal: &str, from_s: f64) -> &mut Self {
        self.score.push(ScoreSpec {
            signal: signal.to_string(),
            from_s,
        });
        self
    }

    /// Add a block running at the base rate.
    pub fn add(&mut self, name: &str, block: impl Block + 'static) -> &mut Self {
        self.blocks.push(BlockSpec {
            name: name.to_string(),
            rate_hz: None,
            block: Box::new(block),
        });
        self
    }

    /// Add a block running at `rate_hz`.
    pub fn add_at(&mut self, name: &str, rate_hz: f64, block: impl Block + 'static) -> &mut Self {
        self.blocks.push(BlockSpec {
            name: name.to_string(),
            rate_hz: Some(rate_hz),
            block: Box::new(block),
        });
        self
    }

    /// Connect output `from` (`block.port`) to input `to`.
    pub fn connect(&mut self, from: &str, to: &str) -> &mut Self {
        self.connections.push(Connection {
            from: from.to_string(),
            to: to.to_string(),
        });
        self
    }

    /// Record output `signal` (`block.port`).
    pub fn log(&mut self, signal: &str) -> &mut Self {
        self.log.push(signal.to_string());
        self
    }

    /// Whether the graph reads measured data: it has a `data_column` block or a
    /// `compare:` entry. Data given to a graph that does not would only change
    /// its duration.
    pub fn reads_data(&self) -> bool {
        !self.compare.is_empty()
            || self
                .blocks
                .iter()
                .any(|b| b.block.typetag_name() == "data_column")
    }
}

/// Largest graph file [`GraphSpec::from_file`] reads: 64 MiB.
pub const MAX_GRAPH_FILE_BYTES: u64 = 64 << 20;

/// The documented block-name rule: non-empty, ASCII letters, digits, `_` and `-`
/// only (`.` separates block and port; `:` is reserved for inserted blocks such as
/// rate transitions, so they can never collide with a user's block).
pub fn valid_block_name(name: &str) -> bool {
    !name.is_empty()
        && name.len() <= MAX_BLOCK_NAME_CHARS
        && name
            .chars()
            .all(|c| c.is_ascii_alphanumeric() || c == '_' || c == '-')
}
