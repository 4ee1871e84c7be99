//! Compiling a [`GraphSpec`] into a [`Scheduler`], once, before the first tick.
//! The phases, in the order [`compile`] runs them (each refuses with a
//! [`GraphError`] naming the place and the fix):
//!
//! 1. [`run_length`]: the settings — base rate, title, duration (the data's
//!    length when left out) — give the number of base ticks;
//! 2. [`check_planned_memory`]: at least one block, and the blocks' buffers
//!    from their parameters, before anything is allocated;
//! 3. [`build_blocks`]: names, rates, [`Block::build`], port widths, the memory
//!    the built blocks hold;
//! 4. [`connect`]: every connection resolved and its widths matched, a rate
//!    transition inserted between different rates, every input connected;
//! 5. [`execution_order`]: Kahn's algorithm on the feed-through edges
//!    (algebraic loops refused);
//! 6. [`assign_units`]: the graph's `units:` over what the blocks declare, then
//!    units passed on from inputs;
//! 7. [`lay_out`]: outputs in one flat buffer in execution order, each block's
//!    inputs as a list of copies;
//! 8. [`Recorder::record`]: logs, scores and compares, with the memory estimate
//!    checked before each log is reserved; then the [`Scheduler`] is assembled.
//!
//! [`compile`] itself only passes each phase's result to the next.

use super::load::nearest;
use super::spec::{
    BlockSpec, BuildReport, CompareSpec, Connection, GraphSpec, LOG_CHUNK_TICKS,
    MAX_BLOCK_NAME_CHARS, MAX_GRAPH_BYTES, MAX_RATE_HZ, MAX_TICKS, MAX_TITLE_CHARS, MAX_UNIT_CHARS,
    MIN_RATE_HZ, ScoreSpec, valid_block_name,
};
use crate::block::{Block, BuildContext, MeasuredData, Port};
use crate::error::GraphError;
use crate::rng::derive_seed;
use crate::scheduler::{
    Gather, LogChannel, Node, Parts, RATE_TRANSITION_PREFIX, RateTransition, Scheduler, ScoreAcc,
    ScoreChannel,
};
use std::collections::{BTreeMap, HashMap};
use std::fmt::Write as _;
use std::sync::Arc;

/// Measured data a graph is built with, if any.
type Data = Option<Arc<dyn MeasuredData>>;

impl GraphSpec {
    /// Validate the graph, build every block, resolve ports, rates and order, and
    /// return the ready-to-run scheduler with a report of what was inserted.
    pub fn build(self) -> Result<(Scheduler, BuildReport), GraphError> {
        compile(self, None, None, false)
    }

    /// [`GraphSpec::build`] for a run whose logs are streamed: each log keeps
    /// room for [`LOG_CHUNK_TICKS`] base ticks only (not the whole run), and
    /// [`Scheduler::run_streamed`] hands the recorded samples to a sink chunk by
    /// chunk, so the run's memory is bounded and independent of `duration_s`.
    /// The memory estimate ([`MAX_GRAPH_BYTES`]) then counts one chunk per log.
    /// `data`: measured data for `data_column` blocks, as in
    /// [`GraphSpec::build_with_data`] (`compare:` needs whole logs: use that).
    pub fn build_streamed(self, data: Data) -> Result<(Scheduler, BuildReport), GraphError> {
        compile(self, data, Some(LOG_CHUNK_TICKS), false)
    }

    /// [`GraphSpec::build`] with measured data attached (a
    /// [`Dataset`](crate::data::Dataset), or anything else that is
    /// [`MeasuredData`]): blocks that play recorded signals (`data_column`) read
    /// it when they are built. A graph without `duration_s` runs for the data's
    /// length.
    pub fn build_with_data(
        self,
        data: Arc<dyn MeasuredData>,
    ) -> Result<(Scheduler, BuildReport), GraphError> {
        compile(self, Some(data), None, false)
    }

    /// [`GraphSpec::build`] of a graph that reads measured data, without the data,
    /// to check it (`nanomotion check` without `--data`): `data_column` blocks play
    /// a placeholder 0, so names, ports, rates, order and loops are checked; the
    /// columns and the data's rate are not. A graph without `duration_s` gets 0 s.
    pub fn build_without_data(self) -> Result<(Scheduler, BuildReport), GraphError> {
        compile(self, None, None, true)
    }
}

/// Block name → index in the blocks being compiled: built once, so each look-up
/// of a connection, unit or log is O(1) and the whole build O(N log N) in the
/// number of blocks (it was a linear search per look-up, O(N²)).
type NameIndex = HashMap<String, usize>;

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

fn bytes_text(b: f64) -> String {
    if b >= (1u64 << 30) as f64 {
        format!("{:.1} GiB", b / (1u64 << 30) as f64)
    } else {
        format!("{:.1} MiB", b / (1u64 << 20) as f64)
    }
}

/// The whole compilation, phase by phase (see the module documentation).
fn compile(
    spec: GraphSpec,
    data: Data,
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
        realtime: _,
        units,
        connection_lines,
        base_dir,
    } = spec;
    // 1. settings
    let n_ticks = run_length(
        base_rate_hz,
        title.as_deref(),
        duration_s,
        data.as_deref(),
        placeholder_data,
    )?;
    // 2. the blocks' planned memory
    check_planned_memory(&blocks, base_rate_hz)?;
    // 3. names, rates, build
    let (mut pending, mut index, block_bytes) = build_blocks(
        blocks,
        base_rate_hz,
        seed,
        &data,
        &base_dir,
        placeholder_data,
    )?;
    let mut report = BuildReport::default();
    // 4. connections and rate transitions
    connect(
        &mut pending,
        &mut index,
        &connections,
        strict_rates,
        connection_lines.as_ref(),
        &mut report,
    )?;
    // 5. execution order
    let order = execution_order(&pending)?;
    // 6. units
    assign_units(&mut pending, &index, &units)?;
    // 7. buffers
    let layout = lay_out(pending, &order, &mut report);
    // 8. recorded signals
    let rec = Recorder::new(&layout, base_rate_hz, n_ticks, chunk_ticks, block_bytes);
    let Recorded {
        logs,
        scores,
        compares,
        graph_bytes,
        log_bytes,
    } = rec.record(&log, &score, &compare)?;

    tracing::debug!(
        target: "nanomotion_core::graph",
        blocks = layout.blocks.len(),
        ticks = n_ticks,
        memory_bytes = graph_bytes,
        log_bytes,
        "graph built; execution order: {}",
        report.order.join(", ")
    );
    let sched = Scheduler::new_internal(Parts {
        title,
        base_rate_hz,
        n_ticks,
        blocks: layout.blocks,
        nodes: layout.nodes,
        gathers: layout.gathers,
        signal_len: layout.signal_len,
        input_len: layout.input_len,
        ctxs: layout.ctxs,
        names: layout.names,
        type_names: layout.type_names,
        ports: layout.ports,
        logs,
        scores,
        compares,
        rate_transitions: report.rate_transitions.clone(),
        chunk_ticks,
    });
    Ok((sched, report))
}

/// Phase 1: the graph's settings. Returns the number of base ticks of the run.
fn run_length(
    base_rate_hz: f64,
    title: Option<&str>,
    duration_s: f64,
    data: Option<&dyn MeasuredData>,
    placeholder_data: bool,
) -> Result<u64, GraphError> {
    if !(MIN_RATE_HZ..=MAX_RATE_HZ).contains(&base_rate_hz) {
        return Err(setting(
            "base_rate_hz",
            format!("is {base_rate_hz}, outside [{MIN_RATE_HZ}, {MAX_RATE_HZ:e}] Hz"),
            "give a positive rate in Hz, e.g. 4000",
        ));
    }
    if let Some(t) = title {
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
    let duration_s = match (data, placeholder_data) {
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
    if let Some(d) = data {
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
    Ok(n_ticks_f as u64)
}

/// Phase 2: at least one block, and the blocks' buffers, from their
/// parameters, before any is allocated (a block whose own size is out of range
/// is left to its build's message).
fn check_planned_memory(blocks: &[BlockSpec], base_rate_hz: f64) -> Result<(), GraphError> {
    if blocks.is_empty() {
        return Err(setting("blocks", "is empty", "add at least one block"));
    }
    let mut planned = 0usize;
    for b in blocks {
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
    Ok(())
}

/// Phase 3: names, rates, build. Returns the built blocks, their name index and
/// the heap memory they hold.
fn build_blocks(
    blocks: Vec<BlockSpec>,
    base_rate_hz: f64,
    seed: u64,
    data: &Data,
    base_dir: &Option<std::path::PathBuf>,
    placeholder_data: bool,
) -> Result<(Vec<Pending>, NameIndex, usize), GraphError> {
    let base_dt = 1.0 / base_rate_hz;
    let mut pending: Vec<Pending> = Vec::with_capacity(blocks.len());
    let mut index = NameIndex::with_capacity(blocks.len());
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
        if index.contains_key(&b.name) {
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
        index.insert(b.name.clone(), pending.len());
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
    Ok((pending, index, block_bytes))
}

/// Phase 4: the connections (an error names the entry's line when it is known),
/// then every input must have a source.
fn connect(
    pending: &mut Vec<Pending>,
    index: &mut NameIndex,
    connections: &[Connection],
    strict_rates: bool,
    lines: Option<&(String, Vec<usize>)>,
    report: &mut BuildReport,
) -> Result<(), GraphError> {
    for (k, c) in connections.iter().enumerate() {
        connect_one(pending, index, k, c, strict_rates, report).map_err(|e| match lines {
            Some((origin, lines)) if k < lines.len() => GraphError::At {
                origin: origin.clone(),
                line: lines[k],
                source: Box::new(e),
            },
            _ => e,
        })?;
    }
    for p in pending.iter() {
        for (i, s) in p.sources.iter().enumerate() {
            if s.is_none() {
                return Err(GraphError::Unconnected {
                    block: p.name.clone(),
                    port: p.inputs[i].name.clone(),
                });
            }
        }
    }
    Ok(())
}

/// Connection `index`: ports resolved, widths equal, the input free; between
/// different rates through a rate transition.
fn connect_one(
    pending: &mut Vec<Pending>,
    names: &mut NameIndex,
    index: usize,
    c: &Connection,
    strict_rates: bool,
    report: &mut BuildReport,
) -> Result<(), GraphError> {
    let (sb, sp) = resolve(pending, names, &c.from, index, Direction::Output)?;
    let (db, dp) = resolve(pending, names, &c.to, index, Direction::Input)?;
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
        if strict_rates {
            return Err(GraphError::RateMismatch {
                index,
                from: c.from.clone(),
                to: c.to.clone(),
                from_hz: pending[sb].rate_hz,
                to_hz: pending[db].rate_hz,
            });
        }
        (
            rate_transition(pending, names, (sb, sp), db, index, c, report)?,
            0,
        )
    } else {
        (sb, sp)
    };
    pending[db].sources[dp] = Some((src_block, src_port, index));
    Ok(())
}

/// The explicit rate transition between output `source` and block `db` (at
/// `db`'s rate), inserted once per source and destination block and reported.
/// Returns its index.
fn rate_transition(
    pending: &mut Vec<Pending>,
    names: &mut NameIndex,
    (sb, sp): (usize, usize),
    db: usize,
    index: usize,
    c: &Connection,
    report: &mut BuildReport,
) -> Result<usize, GraphError> {
    let (from_hz, to_hz) = (pending[sb].rate_hz, pending[db].rate_hz);
    let fw = pending[sb].outputs[sp].width;
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
    if let Some(&i) = names.get(&name) {
        return Ok(i);
    }
    let mut block: Box<dyn Block> = Box::new(RateTransition::new(fw));
    let ctx = BuildContext::new(name.clone(), pending[db].ctx.dt, 0);
    block.build(&ctx).map_err(|source| GraphError::Param {
        block: name.clone(),
        type_name: "rate_transition".into(),
        source,
    })?;
    names.insert(name.clone(), pending.len());
    pending.push(Pending {
        sources: vec![Some((sb, sp, index))],
        name,
        type_name: "rate_transition".into(),
        inputs: block.inputs(),
        outputs: block.outputs(),
        feedthrough: true,
        block,
        period: pending[db].period,
        rate_hz: to_hz,
        ctx,
    });
    Ok(pending.len() - 1)
}

/// Phase 5: the execution order of the output phase, by Kahn's algorithm on the
/// feed-through dependencies, stable in the order blocks were written.
fn execution_order(pending: &[Pending]) -> Result<Vec<usize>, GraphError> {
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
            cycle: find_cycle(pending, &indegree),
        });
    }
    Ok(order)
}

/// Phase 6: units — the graph's `units:` section over what the blocks declare,
/// then units taken from an input's source.
fn assign_units(
    pending: &mut [Pending],
    index: &NameIndex,
    units: &BTreeMap<String, String>,
) -> Result<(), GraphError> {
    for (reference, unit) in units {
        let bad = |problem: String| GraphError::BadSignal {
            section: "units",
            reference: reference.clone(),
            problem,
        };
        let (b, port) = reference
            .split_once('.')
            .ok_or_else(|| bad("write signals as `block.port`".into()))?;
        let Some(p) = index.get(b).map(|&i| &mut pending[i]) else {
            return Err(bad(format!("there is no block `{b}`")));
        };
        let Some(o) = p.outputs.iter_mut().find(|o| o.name == port) else {
            return Err(bad(format!("block `{b}` has no output `{port}`")));
        };
        if unit.is_empty() || unit.len() > MAX_UNIT_CHARS || unit.chars().any(char::is_control) {
            return Err(bad(format!(
                "unit `{}` must be 1 to {MAX_UNIT_CHARS} printable characters (e.g. m, m/s, V)",
                unit.escape_debug()
            )));
        }
        o.unit = Some(unit.clone());
    }
    // Each output without a unit that takes its input's unit waits on that
    // input's source; from every output with a unit, pass it on along these
    // waits (chains of pass-through blocks in any order, loops included; each
    // output is visited once).
    let mut waiting: HashMap<(usize, usize), Vec<(usize, usize)>> = HashMap::new();
    let mut ready: Vec<(usize, usize)> = Vec::new();
    for (i, p) in pending.iter().enumerate() {
        for (o, port) in p.outputs.iter().enumerate() {
            if port.unit.is_some() {
                ready.push((i, o));
            } else if let Some(k) = port.unit_from_input
                && let Some(Some((s, sp, _))) = p.sources.get(k).copied()
            {
                waiting.entry((s, sp)).or_default().push((i, o));
            }
        }
    }
    while let Some((s, sp)) = ready.pop() {
        let Some(takers) = waiting.remove(&(s, sp)) else {
            continue;
        };
        let unit = pending[s].outputs[sp].unit.clone();
        for (i, o) in takers {
            pending[i].outputs[o].unit = unit.clone();
            ready.push((i, o));
        }
    }
    Ok(())
}

/// The blocks in execution order with their buffers laid out.
struct Layout {
    blocks: Vec<Box<dyn Block>>,
    nodes: Vec<Node>,
    gathers: Vec<Gather>,
    signal_len: usize,
    input_len: usize,
    ctxs: Vec<BuildContext>,
    names: Vec<String>,
    type_names: Vec<String>,
    /// Per block: inputs, outputs, and each output's offset in the signals.
    ports: Vec<(Vec<Port>, Vec<Port>, Vec<usize>)>,
}

/// Phase 7: buffers — outputs laid out in execution order in one flat buffer,
/// inputs gathered per block by a list of copies.
fn lay_out(mut pending: Vec<Pending>, order: &[usize], report: &mut BuildReport) -> Layout {
    let n = pending.len();
    let mut out_offsets: Vec<Vec<usize>> = vec![Vec::new(); n];
    let mut signal_len = 0usize;
    for &i in order {
        for port in &pending[i].outputs {
            out_offsets[i].push(signal_len);
            signal_len += port.width;
        }
    }
    let mut slots: Vec<Option<Box<dyn Block>>> = pending
        .iter_mut()
        .map(|p| {
            Some(std::mem::replace(
                &mut p.block,
                Box::new(RateTransition::new(0)),
            ))
        })
        .collect();
    let mut l = Layout {
        blocks: Vec::with_capacity(n),
        nodes: Vec::with_capacity(n),
        gathers: Vec::new(),
        signal_len,
        input_len: 0,
        ctxs: Vec::with_capacity(n),
        names: Vec::with_capacity(n),
        type_names: Vec::with_capacity(n),
        ports: Vec::with_capacity(n),
    };
    for &i in order {
        let p = &pending[i];
        let in_start = l.input_len;
        let g_start = l.gathers.len();
        for (k, port) in p.inputs.iter().enumerate() {
            let (s, sp, _) = p.sources[k].expect("checked above");
            l.gathers.push(Gather {
                src: out_offsets[s][sp],
                dst: l.input_len,
                len: port.width,
            });
            l.input_len += port.width;
        }
        let out_start = out_offsets[i].first().copied().unwrap_or(0);
        let out_len: usize = p.outputs.iter().map(|o| o.width).sum();
        l.nodes.push(Node {
            period: p.period,
            rate: 0,
            dt: p.ctx.dt,
            inputs: in_start..l.input_len,
            outputs: out_start..out_start + out_len,
            gathers: g_start..l.gathers.len(),
            feedthrough: p.feedthrough,
            transition: p.name.starts_with(RATE_TRANSITION_PREFIX),
        });
        l.blocks
            .push(slots[i].take().expect("each block taken once"));
        l.ctxs.push(p.ctx.clone());
        l.names.push(p.name.clone());
        l.type_names.push(p.type_name.clone());
        l.ports
            .push((p.inputs.clone(), p.outputs.clone(), out_offsets[i].clone()));
        report.order.push(p.name.clone());
    }
    l
}

/// Phase 8: the recorded signals (logs, and the logs behind scores and
/// compares), each checked against the memory estimate before its buffer is
/// reserved.
struct Recorder<'a> {
    layout: &'a Layout,
    /// Block name → index in `layout`.
    names: HashMap<&'a str, usize>,
    /// Signal reference → index in `logs`.
    log_index: HashMap<String, usize>,
    base_rate_hz: f64,
    n_ticks: u64,
    chunk_ticks: Option<u64>,
    logs: Vec<LogChannel>,
    /// Memory estimate so far: signals, inputs, blocks, logs (bytes).
    graph_bytes: usize,
    log_bytes: usize,
}

/// What phase 8 gives the scheduler: the recorded channels, the scores and
/// compares reading them, and the memory estimate.
struct Recorded {
    logs: Vec<LogChannel>,
    scores: Vec<ScoreChannel>,
    /// (signal, data column, log channel).
    compares: Vec<(String, String, usize)>,
    /// Memory estimate of the whole graph: signals, inputs, blocks, logs (bytes).
    graph_bytes: usize,
    log_bytes: usize,
}

impl<'a> Recorder<'a> {
    fn new(
        layout: &'a Layout,
        base_rate_hz: f64,
        n_ticks: u64,
        chunk_ticks: Option<u64>,
        block_bytes: usize,
    ) -> Self {
        Self {
            layout,
            names: layout
                .names
                .iter()
                .enumerate()
                .map(|(i, n)| (n.as_str(), i))
                .collect(),
            log_index: HashMap::new(),
            base_rate_hz,
            n_ticks,
            chunk_ticks,
            logs: Vec::new(),
            graph_bytes: (layout.signal_len + layout.input_len)
                .saturating_mul(8)
                .saturating_add(block_bytes),
            log_bytes: 0,
        }
    }

    /// (block, offset, width, unit) of output `reference` (`block.port`).
    fn lookup(
        &self,
        reference: &str,
        section: &'static str,
    ) -> Result<(usize, usize, usize, Option<String>), GraphError> {
        let bad = |problem: String| GraphError::BadSignal {
            section,
            reference: reference.to_string(),
            problem,
        };
        let (b, port) = reference
            .split_once('.')
            .ok_or_else(|| bad("write signals as `block.port`".into()))?;
        let names = &self.layout.names;
        let Some(&bi) = self.names.get(b) else {
            let hint = nearest(b, names.iter().map(String::as_str))
                .map(|s| format!("; did you mean `{s}`?"))
                .unwrap_or_default();
            return Err(bad(format!("no block named `{b}`{hint}")));
        };
        let (_, outs, offs) = &self.layout.ports[bi];
        let Some(pi) = outs.iter().position(|o| o.name == port) else {
            let known: Vec<&str> = outs.iter().map(|o| o.name.as_str()).collect();
            return Err(bad(format!(
                "block `{b}` has no output `{port}`; its outputs are: {}",
                known.join(", ")
            )));
        };
        Ok((bi, offs[pi], outs[pi].width, outs[pi].unit.clone()))
    }

    /// The log of `reference`, added if new. Returns its index.
    fn channel(&mut self, reference: &str, section: &'static str) -> Result<usize, GraphError> {
        if let Some(&i) = self.log_index.get(reference) {
            return Ok(i);
        }
        let (bi, offset, width, unit) = self.lookup(reference, section)?;
        let n_ticks = self.n_ticks;
        let period = self.layout.nodes[bi].period;
        let total_samples = n_ticks.div_ceil(period);
        // Samples kept in memory: the whole run, or one chunk when streamed.
        let samples =
            self.chunk_ticks
                .map_or(total_samples, |c| c.min(n_ticks).div_ceil(period)) as usize;
        let bytes = samples.saturating_mul(width).saturating_mul(8);
        self.graph_bytes = self.graph_bytes.saturating_add(bytes);
        self.log_bytes = self.log_bytes.saturating_add(bytes);
        if self.graph_bytes > MAX_GRAPH_BYTES {
            return Err(setting(
                "log",
                format!(
                    "recording `{reference}` ({samples} samples × {width} values) brings the graph to about {} ({} of it logs, which are kept in memory for the whole run unless streamed), more than the {} limit",
                    bytes_text(self.graph_bytes as f64),
                    bytes_text(self.log_bytes as f64),
                    bytes_text(MAX_GRAPH_BYTES as f64)
                ),
                "log and score fewer signals, shorten duration_s, or give the logged blocks a lower rate_hz (`nanomotion run` streams logs to disk when the graph has no `compare:`; from Rust use GraphSpec::build_streamed)",
            ));
        }
        self.log_index
            .insert(reference.to_string(), self.logs.len());
        self.logs.push(LogChannel {
            name: reference.to_string(),
            countdown: 0,
            offset,
            width,
            period,
            rate_hz: self.base_rate_hz / period as f64,
            data: Vec::with_capacity(samples * width),
            unit,
            total_samples,
            streamed: 0,
            dropped: 0,
        });
        Ok(self.logs.len() - 1)
    }

    /// Record the graph's `log:`, `score:` and `compare:` signals, in that
    /// order (a signal named twice is recorded once).
    fn record(
        mut self,
        log: &[String],
        score: &[ScoreSpec],
        compare: &[CompareSpec],
    ) -> Result<Recorded, GraphError> {
        for l in log {
            self.channel(l, "log")?;
        }
        let mut scores = Vec::new();
        for s in score {
            scores.push(self.score(s)?);
        }
        let mut compares = Vec::new();
        for c in compare {
            let channel = self.channel(&c.signal, "compare")?;
            compares.push((c.signal.clone(), c.column.clone(), channel));
        }
        Ok(Recorded {
            logs: self.logs,
            scores,
            compares,
            graph_bytes: self.graph_bytes,
            log_bytes: self.log_bytes,
        })
    }

    /// The score of `s`: its log, and the first sample at or after `from_s`.
    fn score(&mut self, s: &ScoreSpec) -> Result<ScoreChannel, GraphError> {
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
        let channel = self.channel(&s.signal, "score")?;
        let n_ticks = self.n_ticks;
        let l = &self.logs[channel];
        let samples = n_ticks.div_ceil(l.period);
        let first = (s.from_s * l.rate_hz - 1e-9).ceil().max(0.0);
        if n_ticks > 0 && first >= samples as f64 {
            return Err(GraphError::BadSignal {
                section: "score",
                reference: s.signal.clone(),
                problem: format!(
                    "from_s is {} s but the run records only {} s of it ({samples} samples at {} Hz), so nothing would be scored; give from_s below {} s or run longer",
                    s.from_s,
                    n_ticks as f64 / self.base_rate_hz,
                    l.rate_hz,
                    (samples as f64 - 1.0).max(0.0) / l.rate_hz
                ),
            });
        }
        Ok(ScoreChannel {
            channel,
            from_s: s.from_s,
            first: first as u64,
            acc: vec![ScoreAcc::default(); l.width],
        })
    }
}

#[derive(Clone, Copy, PartialEq)]
enum Direction {
    Input,
    Output,
}

fn resolve(
    pending: &[Pending],
    names: &NameIndex,
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
    let Some(&bi) = names.get(b) else {
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
    // Position of each block on `path` (usize::MAX: not on it).
    let mut on_path = vec![usize::MAX; pending.len()];
    on_path[start] = 0;
    let mut cur = start;
    loop {
        let next = pending[cur]
            .sources
            .iter()
            .flatten()
            .map(|&(s, _, _)| s)
            .find(|&s| indegree[s] > 0 && pending[s].feedthrough);
        let Some(next) = next else { break };
        if on_path[next] != usize::MAX {
            let pos = on_path[next];
            let mut cycle: Vec<&str> = path[pos..]
                .iter()
                .rev()
                .map(|&i| pending[i].name.as_str())
                .collect();
            cycle.push(cycle[0]);
            return cycle.join(" -> ");
        }
        on_path[next] = path.len();
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
    use super::*;

    /// Issue #29: the build of a generated chain was quadratic in the number
    /// of blocks (a linear name search per connection, unit and log; the
    /// unit pass swept every block once per block of a chain written back to
    /// front). 20 000 `delay` blocks written back to front (240 000 YAML
    /// values, under the parser's budget of 250 000): order, wiring, the unit
    /// passed along the whole chain, and the errors that name blocks.
    #[test]
    fn a_chain_of_20000_blocks_builds_with_its_unit_passed_along() {
        let n = 20_000;
        let mut yaml = String::from("base_rate_hz: 1000\nduration_s: 0.002\nblocks:\n");
        for i in (1..n).rev() {
            let _ = writeln!(yaml, "  - {{ name: b{i}, type: delay, d: 1 }}");
        }
        yaml.push_str("  - { name: b0, type: constant, value: 2.0 }\nconnections:\n");
        for i in 1..n {
            let _ = writeln!(yaml, "  - {{ from: b{}.y, to: b{i}.u }}", i - 1);
        }
        let _ = writeln!(yaml, "units: {{ b0.y: m }}\nlog: [b{}.y]", n - 1);
        let spec = GraphSpec::from_yaml(&yaml, "chain.yaml").unwrap();
        let (sched, report) = spec.build().unwrap();
        // Execution order is the order written (a delay has no feed-through).
        assert_eq!(report.order.len(), n);
        assert_eq!(report.order[0], format!("b{}", n - 1));
        assert_eq!(report.order[n - 1], "b0");
        let wiring = sched.wiring();
        assert!(
            wiring
                .iter()
                .all(|w| w.outputs[0].unit.as_deref() == Some("m"))
        );
        // Block i reads block i − 1.
        let at = |name: &str| wiring.iter().position(|w| w.name == name).unwrap();
        assert_eq!(wiring[at("b7")].sources, vec![(at("b6"), 0)]);
        // A duplicate name and an unknown one are still found, by name.
        let dup = yaml.replace("name: b17,", "name: b16,");
        let e = GraphSpec::from_yaml(&dup, "dup.yaml")
            .unwrap()
            .build()
            .err()
            .unwrap();
        assert!(
            matches!(e, GraphError::DuplicateName { ref name } if name == "b16"),
            "{e}"
        );
        let unknown = yaml.replace("from: b16.y", "from: b16x.y");
        let e = GraphSpec::from_yaml(&unknown, "unknown.yaml")
            .unwrap()
            .build()
            .err()
            .unwrap()
            .to_string();
        assert!(e.contains("b16x") && e.contains("did you mean"), "{e}");
    }
}
