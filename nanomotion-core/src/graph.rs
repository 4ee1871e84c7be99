//! YAML controller graphs: the schema ([`GraphSpec`]), loading with located errors,
//! and compilation into a [`Scheduler`].
//!
//! The format is documented in `docs/graph-format.md`. In short:
//!
//! ```
//! use nanomotion_core::graph::GraphSpec;
//! let yaml = r#"
//! base_rate_hz: 1000
//! duration_s: 0.01
//! seed: 1
//! blocks:
//!   - { name: src, type: graph_doc_const, value: 2.0 }
//! log: [src.y]
//! "#;
//! # use nanomotion_core::{Block, Port, Tick};
//! # #[derive(Debug, serde::Serialize, serde::Deserialize)]
//! # struct C { value: f64 }
//! # #[typetag::serde(name = "graph_doc_const")]
//! # impl Block for C {
//! #     fn outputs(&self) -> Vec<Port> { vec![Port::new("y", 1)] }
//! #     fn output(&mut self, _t: Tick, _u: &[f64], y: &mut [f64]) { y[0] = self.value; }
//! # }
//! let spec = GraphSpec::from_yaml(yaml, "doc.yaml").unwrap();
//! let (mut sched, _report) = spec.build().unwrap();
//! let result = sched.run(|_| {});
//! assert_eq!(result.logs[0].data, vec![2.0; 10]);
//! ```

use crate::block::{Block, BuildContext, Port};
use crate::error::GraphError;
use crate::rng::derive_seed;
use crate::scheduler::{Gather, LogChannel, Node, Scheduler, ScoreChannel};
use serde::{Deserialize, Serialize};
use std::fmt::Write as _;

/// One block of a graph: instance name, optional rate, and the block itself
/// (its `type:` and parameters, flattened into the same YAML map).
#[derive(Debug, Serialize, Deserialize)]
pub struct BlockSpec {
    /// Unique instance name: ASCII letters, digits, `_`, `-` (no `.`, which separates
    /// block and port, and no `:`, reserved for inserted blocks).
    pub name: String,
    /// Rate in Hz; must divide the base rate. Default: the base rate.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub rate_hz: Option<f64>,
    /// The block: `type:` tag and its parameters.
    #[serde(flatten)]
    pub block: Box<dyn Block>,
}

/// A connection from an output port to an input port (`block.port`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Connection {
    /// Source, `block.port` of an output.
    pub from: String,
    /// Destination, `block.port` of an input.
    pub to: String,
}

/// An error signal to score (rms, max, ... after the run).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ScoreSpec {
    /// The signal, `block.port` of an output.
    pub signal: String,
    /// Ignore samples before this time (s), to skip start-up transients.
    #[serde(default)]
    pub from_s: f64,
}

/// A model output paired with a measured column (`nanomotion run --data`,
/// `nanomotion diagnose`): the residual is `measured − model`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CompareSpec {
    /// The model signal, `block.port` of an output of width 1.
    pub signal: String,
    /// The measured column of the data file.
    pub column: String,
}

/// A whole graph as written in YAML.
#[derive(Debug, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct GraphSpec {
    /// Optional title, shown in reports and plots.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub title: Option<String>,
    /// Base tick rate (Hz): every block's rate must divide it.
    pub base_rate_hz: f64,
    /// Simulated duration (s). May be left out of a graph that reads measured
    /// data ([`GraphSpec::reads_data`]): it is then the data's length. Left out,
    /// it reads as NaN until the graph is built with its data.
    #[serde(
        default = "duration_from_data",
        skip_serializing_if = "duration_absent"
    )]
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
    pub blocks: Vec<BlockSpec>,
    /// The connections.
    #[serde(default)]
    pub connections: Vec<Connection>,
    /// Output ports to record (`block.port`).
    #[serde(default)]
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
    pub require: Option<crate::gate::Require>,
    /// Where each connection is in the file (origin, 1-based lines), when it
    /// was read from YAML in block style; connection errors then name the line.
    #[serde(skip)]
    pub connection_lines: Option<(String, Vec<usize>)>,
    /// Units of signals (`block.port: unit`), setting or overriding what the
    /// blocks declare; shown in CSV headers, `metrics.json` and plots.
    #[serde(default, skip_serializing_if = "std::collections::BTreeMap::is_empty")]
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

/// Prefix of the names of inserted rate transitions. It contains `:`, which user
/// block names may not contain, so an inserted name can never be a user's name.
pub const RATE_TRANSITION_PREFIX: &str = "rt:";

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

    /// Parse a graph from YAML text; `origin` (file name) prefixes errors.
    /// `- include: FILE` entries ([`crate::include`]) resolve against the
    /// working directory here, against the file's folder in [`GraphSpec::from_file`].
    pub fn from_yaml(text: &str, origin: &str) -> Result<Self, GraphError> {
        Self::from_yaml_in(text, origin, std::path::Path::new("."), Vec::new())
    }

    /// [`GraphSpec::from_yaml`] with includes resolved against `base`.
    /// `stack`: the file itself (for the include-cycle check), when known.
    fn from_yaml_in(
        text: &str,
        origin: &str,
        base: &std::path::Path,
        mut stack: Vec<std::path::PathBuf>,
    ) -> Result<Self, GraphError> {
        if crate::include::has_includes(text) {
            let expanded = crate::include::expand(text, origin, base, &mut stack)?;
            let mut spec = Self::from_yaml_in(&expanded, origin, base, Vec::new())?;
            // Connection lines from the file as written (not the expanded text).
            let lines = connection_lines(text);
            spec.connection_lines =
                (lines.len() == spec.connections.len()).then(|| (origin.to_string(), lines));
            return Ok(spec);
        }
        let mut spec =
            crate::yaml::from_str::<GraphSpec>(text, origin).map_err(add_type_suggestion)?;
        let lines = connection_lines(text);
        if lines.len() == spec.connections.len() {
            spec.connection_lines = Some((origin.to_string(), lines));
        }
        Ok(spec)
    }

    /// Read and parse a graph file (at most [`MAX_GRAPH_FILE_BYTES`]). Relative
    /// file names in block parameters will resolve against its folder.
    pub fn from_file(path: impl AsRef<std::path::Path>) -> Result<Self, GraphError> {
        let path = path.as_ref();
        let text =
            read_text_capped(path, MAX_GRAPH_FILE_BYTES).map_err(|source| GraphError::Io {
                path: path.display().to_string(),
                source,
            })?;
        let base = path
            .parent()
            .filter(|p| !p.as_os_str().is_empty())
            .map_or_else(
                || std::path::PathBuf::from("."),
                std::path::Path::to_path_buf,
            );
        let root = path.canonicalize().unwrap_or_else(|_| path.to_path_buf());
        let mut spec = Self::from_yaml_in(&text, &path.display().to_string(), &base, vec![root])?;
        spec.base_dir = Some(base);
        Ok(spec)
    }

    /// Validate the graph, build every block, resolve ports, rates and order, and
    /// return the ready-to-run scheduler with a report of what was inserted.
    pub fn build(self) -> Result<(Scheduler, BuildReport), GraphError> {
        compile(self, None, None)
    }

    /// [`GraphSpec::build`] for a run whose logs are streamed: each log keeps
    /// room for [`LOG_CHUNK_TICKS`] base ticks only (not the whole run), and
    /// [`Scheduler::run_streamed`] hands the recorded samples to a sink chunk by
    /// chunk, so the run's memory is bounded and independent of `duration_s`.
    /// The memory estimate ([`MAX_GRAPH_BYTES`]) then counts one chunk per log.
    /// `data`: measured data for `data_column` blocks, as in
    /// [`GraphSpec::build_with_data`] (`compare:` needs whole logs: use that).
    pub fn build_streamed(
        self,
        data: Option<std::sync::Arc<crate::data::Dataset>>,
    ) -> Result<(Scheduler, BuildReport), GraphError> {
        compile(self, data, Some(LOG_CHUNK_TICKS))
    }

    /// [`GraphSpec::build`] with measured data attached: blocks that play recorded
    /// signals (`data_column`) read it when they are built. A graph without
    /// `duration_s` runs for the data's length.
    pub fn build_with_data(
        self,
        data: std::sync::Arc<crate::data::Dataset>,
    ) -> Result<(Scheduler, BuildReport), GraphError> {
        compile(self, Some(data), None)
    }

    /// [`GraphSpec::build`] of a graph that reads measured data, without the data,
    /// to check it (`nanomotion check` without `--data`): `data_column` blocks play
    /// a placeholder 0, so names, ports, rates, order and loops are checked; the
    /// columns and the data's rate are not. A graph without `duration_s` gets 0 s.
    pub fn build_without_data(self) -> Result<(Scheduler, BuildReport), GraphError> {
        compile_with(self, None, None, true)
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

/// Read a UTF-8 text file of at most `max_bytes` bytes through a bounded reader
/// (so `/dev/zero` or a huge file is an error, not an endless read).
pub fn read_text_capped(path: &std::path::Path, max_bytes: u64) -> std::io::Result<String> {
    use std::io::Read as _;
    let file = std::fs::File::open(path)?;
    let mut bytes = Vec::new();
    file.take(max_bytes + 1).read_to_end(&mut bytes)?;
    if bytes.len() as u64 > max_bytes {
        return Err(std::io::Error::new(
            std::io::ErrorKind::InvalidData,
            format!("larger than {} MiB; is it the right file?", max_bytes >> 20),
        ));
    }
    String::from_utf8(bytes).map_err(|e| {
        std::io::Error::new(
            std::io::ErrorKind::InvalidData,
            format!("not UTF-8 text ({e})"),
        )
    })
}

/// Add "did you mean" to unknown-type errors.
fn add_type_suggestion(e: GraphError) -> GraphError {
    let GraphError::Parse {
        origin,
        mut message,
    } = e
    else {
        return e;
    };
    if let Some(pos) = message.find("unknown variant `") {
        let rest = &message[pos + "unknown variant `".len()..];
        if let Some(end) = rest.find('`') {
            let bad = rest[..end].to_string();
            let known = crate::block::parse_expected_list(&message);
            if let Some(best) = nearest(&bad, known.iter().map(String::as_str)) {
                message = format!(
                    "{message}\nhint: unknown block type `{bad}`; did you mean `{best}`? (`nanomotion blocks` lists all types)"
                );
            } else {
                message = format!(
                    "{message}\nhint: unknown block type `{bad}` (`nanomotion blocks` lists all types)"
                );
            }
        }
    }
    GraphError::Parse { origin, message }
}

/// Where an unknown field is: (0-based line, 1-based column, what the parser
/// said without its locations), searching from the reported line on.
fn unknown_field_site(
    message: &str,
    text: &str,
    first_line: usize,
) -> Option<(usize, usize, String)> {
    let pos = message.find("unknown field `")?;
    let rest = &message[pos + "unknown field `".len()..];
    let field = &rest[..rest.find('`')?];
    let is_key_on = |line: &str| {
        line.match_indices(&format!("{field}:")).any(|(i, _)| {
            i == 0
                || line[..i]
                    .chars()
                    .next_back()
                    .is_some_and(|c| c == ' ' || c == '{' || c == ',' || c == '-' || c == '\t')
        })
    };
    let (n, line) = text
        .lines()
        .enumerate()
        .skip(first_line.saturating_sub(1))
        .find(|(_, l)| is_key_on(l))?;
    let first = message.lines().next().unwrap_or("");
    let what = first[first.find("unknown field `").unwrap_or(0)..]
        .split(" at line ")
        .next()
        .unwrap_or("")
        .to_string();
    let column = line
        .match_indices(&format!("{field}:"))
        .map(|(i, _)| i + 1)
        .next()
        .unwrap_or(1);
    Some((n, column, what))
}

/// Where a value of the wrong type is (audit D21): inside a block the parser
/// reports the entry's first line and the line after it, not the field; the
/// field is the key between them whose value is the one the parser quotes
/// (`invalid type: string "fast", expected f64`). Returns (0-based line,
/// 1-based column of the key, the message naming the field).
fn bad_value_site(message: &str, text: &str, first_line: usize) -> Option<(usize, usize, String)> {
    let first = message.lines().next()?;
    let from = first.find("invalid type: ")?;
    let mut parts = first[from..].split(" at line ");
    let what = parts.next()?;
    let last_line = parts
        .next()
        .and_then(|r| r.split(|c: char| !c.is_ascii_digit()).next())
        .and_then(|n| n.parse::<usize>().ok())
        .filter(|&l| l >= first_line)
        .unwrap_or(usize::MAX);
    let unexpected = &what["invalid type: ".len()..];
    let value = match unexpected.strip_prefix("string \"") {
        Some(r) => r.split('"').next()?,
        None => unexpected.split('`').nth(1)?,
    };
    for (n, line) in text
        .lines()
        .enumerate()
        .skip(first_line.saturating_sub(1))
        .take(last_line.saturating_sub(first_line.saturating_sub(1)))
    {
        for (i, _) in line.match_indices(':') {
            let key_start = line[..i]
                .rfind(|c: char| !(c.is_ascii_alphanumeric() || c == '_'))
                .map_or(0, |k| k + 1);
            let key = &line[key_start..i];
            let token = line[i + 1..]
                .split([',', '}', '#'])
                .next()
                .unwrap_or("")
                .trim()
                .trim_matches(|c| c == '"' || c == '\'');
            if !key.is_empty() && token == value {
                return Some((n, key_start + 1, format!("field `{key}`: {what}")));
            }
        }
    }
    None
}

/// Inside a block, the parser (typetag buffers the block's map) reports an
/// unknown field or a value of the wrong type at the block's first line and "at
/// line" of its last field. Find the line that really holds the key and say so,
/// naming the field, with the text of that line.
pub(crate) fn locate_field(e: GraphError, text: &str) -> GraphError {
    let GraphError::Parse {
        origin,
        mut message,
    } = e
    else {
        return e;
    };
    // The reported line: "line N column M" at the start of the message.
    let first_line = message
        .strip_prefix("line ")
        .and_then(|r| r.split_whitespace().next())
        .and_then(|n| n.parse::<usize>().ok())
        .unwrap_or(1);
    let Some((n, column, what)) = unknown_field_site(&message, text, first_line)
        .or_else(|| bad_value_site(&message, text, first_line))
    else {
        return GraphError::Parse { origin, message };
    };
    // The message rebuilt at the typo's own line, with the lines around it.
    let lines: Vec<&str> = text.lines().collect();
    let width = (n + 2).to_string().len();
    let mut out = format!(
        "line {} column {column}: {what}\n{:width$}--> {origin}:{}:{column}\n{:width$} |\n",
        n + 1,
        "",
        n + 1,
        ""
    );
    let from = n.saturating_sub(1);
    for (k, l) in lines.iter().enumerate().take(n + 1).skip(from) {
        out.push_str(&format!("{:>width$} | {l}\n", k + 1));
    }
    out.push_str(&format!(
        "{:width$} | {}^ {what}\n",
        "",
        " ".repeat(column - 1)
    ));
    if let Some(next) = lines.get(n + 1) {
        out.push_str(&format!("{:>width$} | {next}\n", n + 2));
    }
    out.push_str(&format!("{:width$} |", ""));
    message = out;
    GraphError::Parse { origin, message }
}

/// 1-based lines of the entries of a block-style top-level `connections:` list
/// (`- ` items at its first indentation); empty for a flow-style list.
fn connection_lines(text: &str) -> Vec<usize> {
    let mut out = Vec::new();
    let mut inside = false;
    let mut indent: Option<usize> = None;
    for (n, line) in text.lines().enumerate() {
        let trimmed = line.trim_start();
        if trimmed.is_empty() || trimmed.starts_with('#') {
            continue;
        }
        let ind = line.len() - trimmed.len();
        if ind == 0 {
            inside = trimmed.starts_with("connections:")
                && trimmed["connections:".len()..]
                    .trim_start()
                    .split('#')
                    .next()
                    == Some("");
            continue;
        }
        if inside && trimmed.starts_with('-') && *indent.get_or_insert(ind) == ind {
            out.push(n + 1);
        }
    }
    out
}

/// Levenshtein distance in characters (for "did you mean" suggestions).
pub fn edit_distance(a: &str, b: &str) -> usize {
    let b: Vec<char> = b.chars().collect();
    let mut prev: Vec<usize> = (0..=b.len()).collect();
    for (i, ca) in a.chars().enumerate() {
        let mut cur = vec![i + 1; b.len() + 1];
        for (j, cb) in b.iter().enumerate() {
            let sub = prev[j] + usize::from(ca != *cb);
            cur[j + 1] = sub.min(prev[j + 1] + 1).min(cur[j] + 1);
        }
        prev = cur;
    }
    prev[b.len()]
}

/// Longest word (bytes) "did you mean" compares: the edit distance costs the
/// product of the two lengths, and a name this long is no typo of a short one.
pub const MAX_SUGGEST_BYTES: usize = 64;

/// Whether `candidate` is near enough to `word` to suggest it ("did you mean").
/// Words longer than [`MAX_SUGGEST_BYTES`] are never compared (audit D8: the
/// comparison was quadratic in the length of a 160 000-character name).
pub fn is_near(word: &str, candidate: &str) -> bool {
    word.len() <= MAX_SUGGEST_BYTES
        && candidate.len() <= MAX_SUGGEST_BYTES
        && edit_distance(word, candidate) <= (candidate.len().max(word.len()) / 2).max(2)
}

/// The candidate nearest to `word`, if it is reasonably near.
pub(crate) fn nearest<'a>(
    word: &str,
    candidates: impl Iterator<Item = &'a str>,
) -> Option<&'a str> {
    candidates
        .filter(|c| is_near(word, c))
        .map(|c| (edit_distance(word, c), c))
        .min_by_key(|(d, _)| *d)
        .map(|(_, c)| c)
}

/// A block while compiling.
struct Pending {
    name: String,
    type_name: String,
    block: Box<dyn Block>,
    period: u64,
    rate_hz: f64,
    ctx: BuildContext,
    inputs: Vec<Port>,
    outputs: Vec<Port>,
    feedthrough: bool,
    /// For each input port, the (block index, output port index) feeding it.
    sources: Vec<Option<(usize, usize, usize)>>, // (block, port, connection index)
}

fn setting(field: &str, problem: impl Into<String>, fix: impl Into<String>) -> GraphError {
    GraphError::Setting {
        field: field.into(),
        problem: problem.into(),
        fix: fix.into(),
    }
}

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

fn bytes_text(b: f64) -> String {
    if b >= (1u64 << 30) as f64 {
        format!("{:.1} GiB", b / (1u64 << 30) as f64)
    } else {
        format!("{:.1} MiB", b / (1u64 << 20) as f64)
    }
}

fn compile(
    spec: GraphSpec,
    data: Option<std::sync::Arc<crate::data::Dataset>>,
    chunk_ticks: Option<u64>,
) -> Result<(Scheduler, BuildReport), GraphError> {
    compile_with(spec, data, chunk_ticks, false)
}

fn compile_with(
    spec: GraphSpec,
    data: Option<std::sync::Arc<crate::data::Dataset>>,
    chunk_ticks: Option<u64>,
    placeholder_data: bool,
) -> Result<(Scheduler, BuildReport), GraphError> {
    let GraphSpec {
        title,
        base_rate_hz,
        duration_s,
        seed,
        strict_rates,
        blocks,
        connections,
        log,
        score,
        compare,
        require: _,
        units,
        connection_lines,
        base_dir,
    } = spec;
    if !(MIN_RATE_HZ..=MAX_RATE_HZ).contains(&base_rate_hz) {
        return Err(setting(
            "base_rate_hz",
            format!("is {base_rate_hz}, outside [{MIN_RATE_HZ}, {MAX_RATE_HZ:e}] Hz"),
            "give a positive rate in Hz, e.g. 4000",
        ));
    }
    if let Some(t) = &title {
        if let Some(c) = t.chars().find(|c| c.is_control()) {
            return Err(setting(
                "title",
                format!("contains the control character U+{:04X}", c as u32),
                "remove it (titles go into SVG and JSON files; write plain text on one line)",
            ));
        }
        if t.chars().count() > MAX_TITLE_CHARS {
            return Err(setting(
                "title",
                format!("has {} characters", t.chars().count()),
                format!("shorten it to at most {MAX_TITLE_CHARS} characters"),
            ));
        }
    }
    let duration_s = match (&data, placeholder_data) {
        (_, _) if !duration_s.is_nan() => duration_s,
        (Some(d), _) => d.duration_s(),
        (None, true) => 0.0,
        (None, false) => {
            return Err(setting(
                "duration_s",
                "is missing (or NaN)",
                "give the duration in seconds (`duration_s: 2.0`); a graph that reads measured data may leave it out and run with the data (`--data FILE`), whose length it then takes",
            ));
        }
    };
    if !(duration_s.is_finite() && duration_s >= 0.0) {
        return Err(setting(
            "duration_s",
            format!("is {duration_s}"),
            "give a non-negative duration in seconds",
        ));
    }
    let n_ticks_f = (duration_s * base_rate_hz).round();
    if n_ticks_f > MAX_TICKS {
        return Err(setting(
            "duration_s",
            format!(
                "{duration_s} s at {base_rate_hz} Hz is {n_ticks_f:e} ticks, more than {MAX_TICKS:e}"
            ),
            "shorten the run or lower the base rate",
        ));
    }
    if let Some(d) = &data {
        let run_s = n_ticks_f / base_rate_hz;
        let data_s = d.duration_s();
        if run_s > data_s * (1.0 + 1e-9) {
            return Err(setting(
                "duration_s",
                format!(
                    "the run lasts {run_s} s but the data {} lasts only {data_s} s ({} samples at {} Hz)",
                    d.origin(),
                    d.len(),
                    d.rate_hz()
                ),
                format!(
                    "run at most {data_s} s (`--duration {data_s}`, or leave it out to use the data's length)"
                ),
            ));
        }
    }
    if blocks.is_empty() {
        return Err(setting("blocks", "is empty", "add at least one block"));
    }
    let base_dt = 1.0 / base_rate_hz;

    // 0. The blocks' buffers, from their parameters, before any is allocated
    // (a block whose own size is out of range is left to its build's message).
    let mut planned = 0usize;
    for b in &blocks {
        let (field, bytes) = b
            .block
            .planned_bytes(1.0 / b.rate_hz.unwrap_or(base_rate_hz));
        if bytes > MAX_GRAPH_BYTES {
            continue;
        }
        planned = planned.saturating_add(bytes);
        if planned > MAX_GRAPH_BYTES {
            return Err(GraphError::Param {
                block: b.name.clone(),
                type_name: b.block.typetag_name().to_string(),
                source: crate::ParamError::new(
                    field,
                    format!(
                        "the blocks up to this one need {} of buffers, more than the {} a graph may use (checked before anything is allocated)",
                        bytes_text(planned as f64),
                        bytes_text(MAX_GRAPH_BYTES as f64)
                    ),
                    format!(
                        "lower `{field}` here or in the blocks before, or use fewer such blocks"
                    ),
                ),
            });
        }
    }

    // 1. Names, rates, build.
    let mut pending: Vec<Pending> = Vec::with_capacity(blocks.len());
    let mut block_bytes = 0usize;
    for b in blocks {
        if !valid_block_name(&b.name) {
            return Err(setting(
                "blocks.name",
                if b.name.len() > MAX_BLOCK_NAME_CHARS {
                    format!(
                        "`{}…` has {} characters, more than {MAX_BLOCK_NAME_CHARS}",
                        b.name.chars().take(20).collect::<String>().escape_debug(),
                        b.name.chars().count()
                    )
                } else {
                    format!("`{}` is not a valid block name", b.name.escape_debug())
                },
                format!(
                    "use at most {MAX_BLOCK_NAME_CHARS} ASCII letters, digits, `_` and `-` (`.` separates block and port; `:` is reserved for blocks the loader inserts, such as rate transitions)"
                ),
            ));
        }
        if pending.iter().any(|p| p.name == b.name) {
            return Err(GraphError::DuplicateName { name: b.name });
        }
        let rate_hz = b.rate_hz.unwrap_or(base_rate_hz);
        let ratio = base_rate_hz / rate_hz;
        let period = ratio.round();
        if !(rate_hz.is_finite() && rate_hz >= MIN_RATE_HZ && (1.0..=MAX_TICKS).contains(&period))
            || (ratio - period).abs() > 1e-9 * ratio
        {
            return Err(GraphError::BadRate {
                block: b.name,
                rate_hz,
                base_rate_hz,
            });
        }
        let period = period as u64;
        let dt = period as f64 * base_dt;
        let type_name = b.block.typetag_name().to_string();
        let mut block = b.block;
        let ctx = BuildContext::new(b.name.clone(), dt, derive_seed(seed, &b.name))
            .with_data(data.clone())
            .with_base_dir(base_dir.clone());
        let ctx = BuildContext {
            placeholder_data,
            ..ctx
        };
        block.build(&ctx).map_err(|source| GraphError::Param {
            block: b.name.clone(),
            type_name: type_name.clone(),
            source,
        })?;
        let inputs = block.inputs();
        let outputs = block.outputs();
        // Every port of every block (plugins too) within the width bound.
        for (dir, ports) in [("input", &inputs), ("output", &outputs)] {
            for port in ports.iter() {
                if port.width > crate::block::MAX_WIDTH {
                    return Err(GraphError::Param {
                        block: b.name.clone(),
                        type_name: type_name.clone(),
                        source: crate::ParamError::new(
                            format!("{dir} port `{}`", port.name),
                            format!(
                                "is {} values wide, more than {}",
                                port.width,
                                crate::block::MAX_WIDTH
                            ),
                            "give the block fewer channels",
                        ),
                    });
                }
            }
        }
        block_bytes = block_bytes.saturating_add(block.memory_bytes());
        if block_bytes > MAX_GRAPH_BYTES {
            return Err(setting(
                "blocks",
                format!(
                    "the blocks up to `{}` hold {} of buffers, more than the {} a graph may use",
                    b.name,
                    bytes_text(block_bytes as f64),
                    bytes_text(MAX_GRAPH_BYTES as f64)
                ),
                "shorten delays and repetitive memories, or use fewer channels",
            ));
        }
        let feedthrough = block.direct_feedthrough();
        pending.push(Pending {
            sources: vec![None; inputs.len()],
            name: b.name,
            type_name,
            block,
            period,
            rate_hz,
            ctx,
            inputs,
            outputs,
            feedthrough,
        });
    }

    // 2. Connections (an error names the entry's line when it is known).
    let mut report = BuildReport::default();
    let at = |index: usize| {
        move |e: GraphError| match &connection_lines {
            Some((origin, lines)) if index < lines.len() => GraphError::At {
                origin: origin.clone(),
                line: lines[index],
                source: Box::new(e),
            },
            _ => e,
        }
    };
    let mut current = 0;
    let mut connect = || -> Result<(), GraphError> {
        for (index, c) in connections.iter().enumerate() {
            current = index;
            let (sb, sp) = resolve(&pending, &c.from, index, Direction::Output)?;
            let (db, dp) = resolve(&pending, &c.to, index, Direction::Input)?;
            let fw = pending[sb].outputs[sp].width;
            let tw = pending[db].inputs[dp].width;
            if fw != tw {
                return Err(GraphError::WidthMismatch {
                    index,
                    from: c.from.clone(),
                    to: c.to.clone(),
                    from_width: fw,
                    to_width: tw,
                });
            }
            if let Some((_, _, first)) = pending[db].sources[dp] {
                return Err(GraphError::DoubleConnection {
                    to: c.to.clone(),
                    first,
                    second: index,
                });
            }
            let (src_block, src_port) = if pending[sb].period != pending[db].period {
                let (from_hz, to_hz) = (pending[sb].rate_hz, pending[db].rate_hz);
                if strict_rates {
                    return Err(GraphError::RateMismatch {
                        index,
                        from: c.from.clone(),
                        to: c.to.clone(),
                        from_hz,
                        to_hz,
                    });
                }
                // Insert an explicit rate transition running at the destination's rate.
                let kind = if to_hz > from_hz {
                    "zero-order hold"
                } else {
                    "decimation (sampling, no anti-alias filter)"
                };
                // `:` cannot appear in a user's name, so this cannot collide with one.
                let name = format!(
                    "{RATE_TRANSITION_PREFIX}{}:{}",
                    c.from.replace('.', ":"),
                    pending[db].name
                );
                let note = format!(
                    "`{}` -> `{}`: {kind} {from_hz} Hz -> {to_hz} Hz, inserted as block `{name}`",
                    c.from, c.to
                );
                tracing::info!(target: "nanomotion_core::graph", "rate transition {note}");
                report.rate_transitions.push(note);
                let idx = match pending.iter().position(|p| p.name == name) {
                    Some(i) => i,
                    None => {
                        let mut block: Box<dyn Block> =
                            Box::new(crate::scheduler::RateTransition::new(fw));
                        let ctx = BuildContext::new(name.clone(), pending[db].ctx.dt, 0);
                        block.build(&ctx).map_err(|source| GraphError::Param {
                            block: name.clone(),
                            type_name: "rate_transition".into(),
                            source,
                        })?;
                        pending.push(Pending {
                            sources: vec![Some((sb, sp, index))],
                            name: name.clone(),
                            type_name: "rate_transition".into(),
                            inputs: block.inputs(),
                            outputs: block.outputs(),
                            feedthrough: true,
                            block,
                            period: pending[db].period,
                            rate_hz: to_hz,
                            ctx,
                        });
                        pending.len() - 1
                    }
                };
                (idx, 0)
            } else {
                (sb, sp)
            };
            pending[db].sources[dp] = Some((src_block, src_port, index));
        }
        Ok(())
    };
    connect().map_err(|e| at(current)(e))?;
    for p in &pending {
        for (i, s) in p.sources.iter().enumerate() {
            if s.is_none() {
                return Err(GraphError::Unconnected {
                    block: p.name.clone(),
                    port: p.inputs[i].name.clone(),
                });
            }
        }
    }

    // 3. Order: Kahn's algorithm on the feed-through dependencies, stable in the
    //    order blocks were written.
    let n = pending.len();
    let mut indegree = vec![0usize; n];
    let mut dependents: Vec<Vec<usize>> = vec![Vec::new(); n];
    for (d, p) in pending.iter().enumerate() {
        if !p.feedthrough {
            continue;
        }
        for &(s, _, _) in p.sources.iter().flatten() {
            indegree[d] += 1;
            dependents[s].push(d);
        }
    }
    let mut order = Vec::with_capacity(n);
    let mut ready: std::collections::BTreeSet<usize> =
        (0..n).filter(|&i| indegree[i] == 0).collect();
    while let Some(i) = ready.pop_first() {
        order.push(i);
        for &d in &dependents[i] {
            indegree[d] -= 1;
            if indegree[d] == 0 {
                ready.insert(d);
            }
        }
    }
    if order.len() < n {
        return Err(GraphError::AlgebraicLoop {
            cycle: find_cycle(&pending, &indegree),
        });
    }

    // 4. Buffers: outputs laid out in execution order, inputs gathered per block.
    let mut out_offsets: Vec<Vec<usize>> = vec![Vec::new(); n];
    let mut signal_len = 0usize;
    for &i in &order {
        for port in &pending[i].outputs {
            out_offsets[i].push(signal_len);
            signal_len += port.width;
        }
    }
    let mut nodes = Vec::with_capacity(n);
    let mut gathers = Vec::new();
    let mut input_len = 0usize;
    let mut ctxs = Vec::with_capacity(n);
    let mut names = Vec::with_capacity(n);
    let mut type_names = Vec::with_capacity(n);
    let mut position = vec![0usize; n];
    for (pos, &i) in order.iter().enumerate() {
        position[i] = pos;
    }
    let mut slots: Vec<Option<Box<dyn Block>>> = Vec::with_capacity(n);
    let mut port_tables = Vec::with_capacity(n);
    for p in pending.iter_mut() {
        slots.push(Some(std::mem::replace(
            &mut p.block,
            Box::new(crate::scheduler::RateTransition::new(0)),
        )));
    }
    // Units: the graph's `units:` section over what the blocks declare.
    for (reference, unit) in &units {
        let bad = |problem: String| GraphError::BadSignal {
            section: "units",
            reference: reference.clone(),
            problem,
        };
        let (b, port) = reference
            .split_once('.')
            .ok_or_else(|| bad("write signals as `block.port`".into()))?;
        let Some(p) = pending.iter_mut().find(|p| p.name == b) else {
            return Err(bad(format!("there is no block `{b}`")));
        };
        let Some(o) = p.outputs.iter_mut().find(|o| o.name == port) else {
            return Err(bad(format!("block `{b}` has no output `{port}`")));
        };
        if unit.is_empty() || unit.len() > 32 || unit.chars().any(char::is_control) {
            return Err(bad(format!(
                "unit `{}` must be 1 to 32 printable characters (e.g. m, m/s, V)",
                unit.escape_debug()
            )));
        }
        o.unit = Some(unit.clone());
    }
    // Then units taken from an input's source (repeat until settled: chains of
    // pass-through blocks in any order, loops included).
    for _ in 0..n.max(1) {
        let mut changed = false;
        for i in 0..n {
            for o in 0..pending[i].outputs.len() {
                if pending[i].outputs[o].unit.is_some() {
                    continue;
                }
                let Some(k) = pending[i].outputs[o].unit_from_input else {
                    continue;
                };
                let Some(Some((s, sp, _))) = pending[i].sources.get(k).copied() else {
                    continue;
                };
                if let Some(u) = pending[s].outputs[sp].unit.clone() {
                    pending[i].outputs[o].unit = Some(u);
                    changed = true;
                }
            }
        }
        if !changed {
            break;
        }
    }
    let mut block_list: Vec<Box<dyn Block>> = Vec::with_capacity(n);
    for &i in &order {
        let p = &pending[i];
        let in_start = input_len;
        let g_start = gathers.len();
        for (k, port) in p.inputs.iter().enumerate() {
            let (s, sp, _) = p.sources[k].expect("checked above");
            gathers.push(Gather {
                src: out_offsets[s][sp],
                dst: input_len,
                len: port.width,
            });
            input_len += port.width;
        }
        let out_start = out_offsets[i].first().copied().unwrap_or(0);
        let out_len: usize = p.outputs.iter().map(|o| o.width).sum();
        nodes.push(Node {
            period: p.period,
            countdown: 0,
            due: false,
            dt: p.ctx.dt,
            k_local: 0,
            inputs: in_start..input_len,
            outputs: out_start..out_start + out_len,
            gathers: g_start..gathers.len(),
            feedthrough: p.feedthrough,
        });
        block_list.push(slots[i].take().expect("each block taken once"));
        ctxs.push(p.ctx.clone());
        names.push(p.name.clone());
        type_names.push(p.type_name.clone());
        port_tables.push((p.inputs.clone(), p.outputs.clone(), out_offsets[i].clone()));
        report.order.push(p.name.clone());
    }

    // 5. Logs and scores.
    let n_ticks = n_ticks_f as u64;
    let lookup = |reference: &str,
                  section: &'static str|
     -> Result<(usize, usize, usize, Option<String>), GraphError> {
        let bad = |problem: String| GraphError::BadSignal {
            section,
            reference: reference.to_string(),
            problem,
        };
        let (b, port) = reference
            .split_once('.')
            .ok_or_else(|| bad("write signals as `block.port`".into()))?;
        let Some(bi) = names.iter().position(|n| n == b) else {
            let hint = nearest(b, names.iter().map(String::as_str))
                .map(|s| format!("; did you mean `{s}`?"))
                .unwrap_or_default();
            return Err(bad(format!("no block named `{b}`{hint}")));
        };
        let (_, outs, offs) = &port_tables[bi];
        let Some(pi) = outs.iter().position(|o| o.name == port) else {
            let known: Vec<&str> = outs.iter().map(|o| o.name.as_str()).collect();
            return Err(bad(format!(
                "block `{b}` has no output `{port}`; its outputs are: {}",
                known.join(", ")
            )));
        };
        Ok((bi, offs[pi], outs[pi].width, outs[pi].unit.clone()))
    };
    let mut logs: Vec<LogChannel> = Vec::new();
    // Memory estimate, checked before each log buffer is reserved.
    let mut graph_bytes = (signal_len + input_len)
        .saturating_mul(8)
        .saturating_add(block_bytes);
    let mut log_bytes = 0usize;
    let add_log = |reference: &str,
                   section: &'static str,
                   logs: &mut Vec<LogChannel>,
                   graph_bytes: &mut usize,
                   log_bytes: &mut usize|
     -> Result<usize, GraphError> {
        if let Some(i) = logs.iter().position(|l| l.name == reference) {
            return Ok(i);
        }
        let (bi, offset, width, unit) = lookup(reference, section)?;
        let period = nodes[bi].period;
        let total_samples = n_ticks.div_ceil(period);
        // Samples kept in memory: the whole run, or one chunk when streamed.
        let samples =
            chunk_ticks.map_or(total_samples, |c| c.min(n_ticks).div_ceil(period)) as usize;
        let bytes = samples.saturating_mul(width).saturating_mul(8);
        *graph_bytes = graph_bytes.saturating_add(bytes);
        *log_bytes = log_bytes.saturating_add(bytes);
        if *graph_bytes > MAX_GRAPH_BYTES {
            return Err(setting(
                "log",
                format!(
                    "recording `{reference}` ({samples} samples × {width} values) brings the graph to about {} ({} of it logs, which are kept in memory for the whole run unless streamed), more than the {} limit",
                    bytes_text(*graph_bytes as f64),
                    bytes_text(*log_bytes as f64),
                    bytes_text(MAX_GRAPH_BYTES as f64)
                ),
                "log and score fewer signals, shorten duration_s, or give the logged blocks a lower rate_hz (`nanomotion run` streams logs to disk when the graph has no `compare:`; from Rust use GraphSpec::build_streamed)",
            ));
        }
        logs.push(LogChannel {
            name: reference.to_string(),
            countdown: 0,
            offset,
            width,
            period,
            rate_hz: base_rate_hz / period as f64,
            data: Vec::with_capacity(samples * width),
            unit,
            total_samples,
            streamed: 0,
            dropped: 0,
        });
        Ok(logs.len() - 1)
    };
    for l in &log {
        add_log(l, "log", &mut logs, &mut graph_bytes, &mut log_bytes)?;
    }
    let mut scores = Vec::new();
    for s in &score {
        if !(s.from_s.is_finite() && s.from_s >= 0.0) {
            return Err(GraphError::BadSignal {
                section: "score",
                reference: s.signal.clone(),
                problem: format!(
                    "from_s is {}; give a non-negative time in seconds",
                    s.from_s
                ),
            });
        }
        let channel = add_log(
            &s.signal,
            "score",
            &mut logs,
            &mut graph_bytes,
            &mut log_bytes,
        )?;
        let l = &logs[channel];
        let samples = n_ticks.div_ceil(l.period);
        let first = (s.from_s * l.rate_hz - 1e-9).ceil().max(0.0);
        if n_ticks > 0 && first >= samples as f64 {
            return Err(GraphError::BadSignal {
                section: "score",
                reference: s.signal.clone(),
                problem: format!(
                    "from_s is {} s but the run records only {} s of it ({samples} samples at {} Hz), so nothing would be scored; give from_s below {} s or run longer",
                    s.from_s,
                    n_ticks as f64 / base_rate_hz,
                    l.rate_hz,
                    (samples as f64 - 1.0).max(0.0) / l.rate_hz
                ),
            });
        }
        scores.push(ScoreChannel {
            channel,
            from_s: s.from_s,
            first: first as u64,
            acc: vec![crate::scheduler::ScoreAcc::default(); l.width],
        });
    }

    let mut compares = Vec::new();
    for c in &compare {
        let channel = add_log(
            &c.signal,
            "compare",
            &mut logs,
            &mut graph_bytes,
            &mut log_bytes,
        )?;
        compares.push((c.signal.clone(), c.column.clone(), channel));
    }

    tracing::debug!(
        target: "nanomotion_core::graph",
        blocks = block_list.len(),
        ticks = n_ticks,
        memory_bytes = graph_bytes,
        log_bytes,
        "graph built; execution order: {}",
        report.order.join(", ")
    );
    let sched = Scheduler::new_internal(crate::scheduler::Parts {
        title,
        base_rate_hz,
        n_ticks,
        blocks: block_list,
        nodes,
        gathers,
        signal_len,
        input_len,
        ctxs,
        names,
        type_names,
        ports: port_tables,
        logs,
        scores,
        compares,
        rate_transitions: report.rate_transitions.clone(),
        chunk_ticks,
    });
    Ok((sched, report))
}

#[derive(Clone, Copy, PartialEq)]
enum Direction {
    Input,
    Output,
}

fn resolve(
    pending: &[Pending],
    reference: &str,
    index: usize,
    dir: Direction,
) -> Result<(usize, usize), GraphError> {
    let (b, port) = reference
        .split_once('.')
        .ok_or_else(|| GraphError::BadReference {
            index,
            reference: reference.to_string(),
        })?;
    let Some(bi) = pending.iter().position(|p| p.name == b) else {
        let mut hint = nearest(b, pending.iter().map(|p| p.name.as_str()))
            .map(|s| format!("; did you mean `{s}`?"))
            .unwrap_or_default();
        let names: Vec<&str> = pending
            .iter()
            .map(|p| p.name.as_str())
            .filter(|n| !n.contains(':'))
            .collect();
        let shown = names
            .iter()
            .take(20)
            .copied()
            .collect::<Vec<_>>()
            .join(", ");
        let more = if names.len() > 20 {
            format!(", ... ({} in all)", names.len())
        } else {
            String::new()
        };
        let _ = write!(hint, "; known blocks: {shown}{more}");
        return Err(GraphError::UnknownBlock {
            index,
            reference: reference.to_string(),
            block: b.to_string(),
            hint,
        });
    };
    let ports = match dir {
        Direction::Input => &pending[bi].inputs,
        Direction::Output => &pending[bi].outputs,
    };
    match ports.iter().position(|p| p.name == port) {
        Some(pi) => Ok((bi, pi)),
        None => {
            let mut known = String::new();
            for (i, p) in ports.iter().enumerate() {
                let _ = write!(
                    known,
                    "{}{} (width {})",
                    if i > 0 { ", " } else { "" },
                    p.name,
                    p.width
                );
            }
            if known.is_empty() {
                known.push_str("(none)");
            }
            Err(GraphError::UnknownPort {
                index,
                reference: reference.to_string(),
                block: b.to_string(),
                port: port.to_string(),
                direction: if dir == Direction::Input {
                    "input"
                } else {
                    "output"
                },
                known,
            })
        }
    }
}

/// A cycle among the blocks left with positive in-degree, as `a -> b -> a`.
fn find_cycle(pending: &[Pending], indegree: &[usize]) -> String {
    // Follow feed-through sources backwards from any blocked node until a repeat.
    let start = indegree.iter().position(|&d| d > 0).unwrap_or(0);
    let mut path = vec![start];
    let mut cur = start;
    loop {
        let next = pending[cur]
            .sources
            .iter()
            .flatten()
            .map(|&(s, _, _)| s)
            .find(|&s| indegree[s] > 0 && pending[s].feedthrough);
        let Some(next) = next else { break };
        if let Some(pos) = path.iter().position(|&p| p == next) {
            let mut cycle: Vec<&str> = path[pos..]
                .iter()
                .rev()
                .map(|&i| pending[i].name.as_str())
                .collect();
            cycle.push(cycle[0]);
            return cycle.join(" -> ");
        }
        path.push(next);
        cur = next;
    }
    path.iter()
        .map(|&i| pending[i].name.as_str())
        .collect::<Vec<_>>()
        .join(" <- ")
}

#[cfg(test)]
mod tests {
    /// Audit D8: a 160 000-character block name and a reference to another one
    /// made "did you mean" run for minutes (quadratic edit distance).
    #[test]
    fn long_names_are_refused_at_once() {
        let n = 160_000;
        let (a, b) = ("a".repeat(n), "b".repeat(n));
        let text = format!(
            "base_rate_hz: 1000\nduration_s: 1\nblocks:\n  - {{ name: {a}, type: gain, k: 1.0 }}\n  - {{ name: c, type: constant, value: 1.0 }}\nconnections:\n  - {{ from: {b}.y, to: {a}.u }}\n"
        );
        let start = std::time::Instant::now();
        let e = super::GraphSpec::from_yaml(&text, "longname.yaml")
            .unwrap()
            .build()
            .err()
            .unwrap()
            .to_string();
        assert!(start.elapsed().as_secs_f64() < 2.0, "{:?}", start.elapsed());
        assert!(e.contains("160000 characters, more than 100"), "{e}");
        assert!(!super::is_near(&a, &b) && super::is_near("gian", "gain"));
        let start = std::time::Instant::now();
        assert_eq!(super::nearest(&a, [b.as_str()].into_iter()), None);
        assert!(start.elapsed().as_secs_f64() < 0.1);
    }
    /// Audit D21: a wrong-type value inside a block named neither the field nor
    /// its line (the parser pointed at the entry's first line and the next one).
    #[test]
    fn a_wrong_type_value_names_its_field_and_line() {
        let text = "base_rate_hz: 4000\nduration_s: 0.1\nblocks:\n  - name: w\n    type: walking_waveform\n  - name: s\n    type: walking_piezo_stage\n    stage_mass_kg: 0.428\n    preload_n: 55.0\n    mu: 0.2\n    mu_pair_rel: 0.1\n    mu_spatial_rel: 0.1\n    substeps: 2\n    tol_n: fast\n    max_iter: 200\nconnections:\n  - { from: w.u, to: s.u }\n";
        // The core has no walking stage: a core block shows the same.
        let text = text
            .replace("walking_waveform", "constant\n    value: 1.0")
            .replace(
                "type: walking_piezo_stage\n    stage_mass_kg: 0.428\n    preload_n: 55.0\n    mu: 0.2\n    mu_pair_rel: 0.1\n    mu_spatial_rel: 0.1\n    substeps: 2\n    tol_n: fast\n    max_iter: 200",
                "type: pid\n    kp: 1.0\n    ki: 2.0\n    kd: fast\n    derivative_cutoff_hz: 100.0",
            )
            .replace("w.u, to: s.u", "w.y, to: s.e");
        let e = super::GraphSpec::from_yaml(&text, "typeerr.yaml")
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("line 11 column 5: field `kd`: invalid type: string \"fast\""),
            "{e}"
        );
        assert!(e.contains("11 |     kd: fast"), "{e}");
        // Flow style: the key on its own line too.
        let flow = "base_rate_hz: 10\nduration_s: 1\nblocks:\n  - { name: c, type: constant, value: 1.0 }\n  - { name: g, type: gain,\n      k: NaN }\n";
        let e = super::GraphSpec::from_yaml(flow, "f.yaml")
            .unwrap_err()
            .to_string();
        assert!(e.contains("line 6 column 7: field `k`"), "{e}");
    }

    use super::*;

    #[test]
    fn edit_distance_and_nearest() {
        assert_eq!(edit_distance("gain", "gian"), 2);
        assert_eq!(edit_distance("", "abc"), 3);
        assert_eq!(edit_distance("kitten", "sitting"), 3);
        assert_eq!(
            nearest("gian", ["gain", "sum", "pid"].into_iter()),
            Some("gain")
        );
        assert_eq!(nearest("zzzzzzzz", ["gain", "sum"].into_iter()), None);
    }
}
