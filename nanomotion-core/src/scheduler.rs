//! The multi-rate scheduler: runs a compiled graph tick by tick.
//!
//! Everything is resolved when the graph is built ([`crate::graph::GraphSpec::build`]):
//! execution order, each block's period in base ticks, where each output lives in
//! one flat signal buffer, and a list of copies ("gathers") that assemble each
//! block's inputs into a contiguous slice. A tick is then two passes over arrays of
//! indices: no heap allocation, no string or hash look-up, no locking, no I/O
//! (`tests/scheduler.rs::ticks_do_not_allocate` counts allocations over 10 000
//! ticks to prove it).
//!
//! Per base tick `k`:
//! 1. output phase, in topological order: every block whose period divides `k`
//!    gathers its inputs (blocks with feed-through only) and writes its outputs;
//! 2. update phase: every due block without feed-through gathers its inputs (now
//!    all of this sample) and advances its state;
//! 3. logging: due log channels append to preallocated buffers.
//!
//! Logs are kept whole (reserved for the whole run at build) or, for a graph
//! built with [`GraphSpec::build_streamed`](crate::graph::GraphSpec::build_streamed),
//! streamed: each log holds one chunk of [`LOG_CHUNK_TICKS`](crate::graph::LOG_CHUNK_TICKS)
//! base ticks, and [`Scheduler::run_streamed`] hands every chunk to a sink (e.g.
//! a CSV writer) between ticks and computes the scores online, so memory does
//! not grow with the duration.
//!
//! Multi-rate: a block at rate f runs on every (f_base / f)-th base tick; its
//! outputs hold in between. Connections between different rates go through
//! explicit [`RateTransition`] blocks that the loader inserts and reports (or
//! rejects with `strict_rates: true`). [`Scheduler::tick`] folds a transition
//! that only its consumer reads into the consumer's input (the consumer reads
//! the source, the same value); [`Scheduler::tick_probed`] runs it as a block.

use crate::block::{Block, BuildContext, Port, Tick};
use crate::error::{GraphError, ParamError};
use crate::lti::StateSpace;
use serde::{Deserialize, Serialize};
use std::ops::Range;

/// One block's place in the tick loop.
#[derive(Debug, Clone)]
pub(crate) struct Node {
    /// Period in base ticks.
    pub period: u64,
    /// Index of its [`Rate`] (set by [`Scheduler::new_internal`]).
    pub rate: usize,
    pub dt: f64,
    pub inputs: Range<usize>,
    pub outputs: Range<usize>,
    pub gathers: Range<usize>,
    pub feedthrough: bool,
    /// An inserted [`RateTransition`]: the tick copies its one gathered input
    /// straight to its output (the block is not called; same values), or
    /// folds it into its consumer's input (see [`Scheduler::tick`]).
    pub transition: bool,
}

/// The blocks of one period (and sample time): when they are due, and the
/// [`Tick`] they get. Due blocks are found per rate, not per block, and a tick
/// on which only the base rate is due runs just the base-rate blocks.
#[derive(Debug, Clone)]
struct Rate {
    /// Period in base ticks.
    period: u64,
    /// Period in seconds (the blocks' `Tick::dt`).
    dt: f64,
    /// Base tick on which its blocks are next due.
    next: u64,
    /// Samples of this rate begun so far.
    done: u64,
    /// Whether its blocks are due on the current tick.
    due: bool,
    /// The current sample of its blocks (when due).
    tick: Tick,
}

impl Rate {
    /// Begin the next sample: its `Tick` (`k·dt` with `k` converted through
    /// `i64`, one instruction instead of `u64`'s several; the same value below
    /// 2⁶³ ticks), and when it is due next.
    /// Returns the new `Tick` (what the single-rate path hands every block,
    /// from registers rather than read back from `self.tick`).
    #[inline(always)]
    fn begin_sample(&mut self) -> Tick {
        self.tick = Tick {
            k: self.done,
            t: self.done as i64 as f64 * self.dt,
            dt: self.dt,
        };
        self.done += 1;
        self.next += self.period;
        self.tick
    }

    fn restart(&mut self) {
        self.next = 0;
        self.done = 0;
        self.due = false;
        self.tick = Tick::new(0, self.dt);
    }
}

/// What one [`Step`] of a tick does.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum StepKind {
    /// An inserted rate transition: copy its source's `len` values (its one
    /// gather) to its output; the block is not called.
    Hold,
    /// Output phase of a block with feed-through: gather its inputs, compute.
    Output,
    /// Output phase of a block with feed-through whose inputs are one
    /// contiguous run of the signal buffer (one gather): the block reads them
    /// there, nothing is copied.
    OutputDirect,
    /// Output phase of a block without feed-through: no gathering (its input
    /// buffer holds what its last update gathered, as always).
    OutputHeld,
    /// Update phase (no feed-through): gather, advance.
    Update,
}

/// One block's phase in a tick, with all it needs inline (compiled at build
/// from its [`Node`]).
#[derive(Debug, Clone, Copy)]
struct Step {
    kind: StepKind,
    /// Execution index of the block.
    block: usize,
    /// Index of its [`Rate`].
    rate: usize,
    /// Its gathers in the program's gather list.
    gathers: (usize, usize),
    /// Its input range in the input buffer.
    inputs: (usize, usize),
    /// Its output range in the signal buffer.
    outputs: (usize, usize),
}

/// The steps of the ticks on which only the base rate is due (`fast`, no
/// rate checked) and of the others (`full`, each step run if its rate is
/// due): output phase in execution order, then the update phase; with the
/// gather list the steps index.
#[derive(Debug, Clone, Default)]
struct Program {
    fast: Vec<Step>,
    full: Vec<Step>,
    gathers: Vec<Gather>,
}

/// Copy `len` values from the signal buffer at `src` to the input buffer at `dst`.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Gather {
    pub src: usize,
    pub dst: usize,
    pub len: usize,
}

/// A recorded signal.
#[derive(Debug, Clone)]
pub(crate) struct LogChannel {
    pub name: String,
    /// Base ticks until the next sample is recorded.
    pub countdown: u64,
    pub offset: usize,
    pub width: usize,
    pub period: u64,
    pub rate_hz: f64,
    pub data: Vec<f64>,
    /// Unit of the values, if known.
    pub unit: Option<String>,
    /// Samples of the whole run.
    pub total_samples: u64,
    /// Samples already handed to a sink (streamed runs) before `data[0]`.
    pub streamed: u64,
    /// Samples that found no room (a streamed log stepped past its chunk
    /// without [`Scheduler::run_streamed`]); never written, counted.
    pub dropped: u64,
}

/// A scored signal: index of its log channel, the settle time and (for
/// streamed runs) the online sums of each element.
#[derive(Debug, Clone)]
pub(crate) struct ScoreChannel {
    pub channel: usize,
    pub from_s: f64,
    /// First scored sample (`from_s` in samples).
    pub first: u64,
    pub acc: Vec<ScoreAcc>,
}

/// Online sums of one scored element, accumulated in sample order (the same
/// order as the whole-log formulas, so the results agree bit for bit).
#[derive(Debug, Clone, Copy, Default)]
pub(crate) struct ScoreAcc {
    n: usize,
    sum: f64,
    sum_sq: f64,
    max_abs: f64,
}

impl ScoreAcc {
    fn add(&mut self, x: f64) {
        self.n += 1;
        self.sum += x;
        self.sum_sq += x * x;
        self.max_abs = self.max_abs.max(x.abs());
    }
    /// (rms, max_abs, mean), NaN without samples.
    fn finish(&self) -> (f64, f64, f64) {
        if self.n == 0 {
            return (f64::NAN, f64::NAN, f64::NAN);
        }
        let n = self.n as f64;
        ((self.sum_sq / n).sqrt(), self.max_abs, self.sum / n)
    }
}

/// Samples of one log handed to a [`Scheduler::run_streamed`] sink.
#[derive(Debug, Clone, Copy)]
pub struct LogChunk<'a> {
    /// `block.port`.
    pub name: &'a str,
    /// Sample rate of the log (Hz).
    pub rate_hz: f64,
    /// Values per sample.
    pub width: usize,
    /// Index (in the whole run) of the first sample in `data`.
    pub start_sample: u64,
    /// Samples of the whole run (known in advance).
    pub total_samples: u64,
    /// Unit of the values, if known.
    pub unit: Option<&'a str>,
    /// New samples, row-major (`data.len() / width` of them; may be none).
    pub data: &'a [f64],
}

/// Everything the graph compiler hands to the scheduler.
pub(crate) struct Parts {
    pub title: Option<String>,
    pub base_rate_hz: f64,
    pub n_ticks: u64,
    pub blocks: Vec<Box<dyn Block>>,
    pub nodes: Vec<Node>,
    pub gathers: Vec<Gather>,
    pub signal_len: usize,
    pub input_len: usize,
    pub ctxs: Vec<BuildContext>,
    pub names: Vec<String>,
    pub type_names: Vec<String>,
    pub ports: Vec<(Vec<Port>, Vec<Port>, Vec<usize>)>,
    pub logs: Vec<LogChannel>,
    pub scores: Vec<ScoreChannel>,
    /// `(signal, measured column, log channel)` of each `compare:` entry.
    pub compares: Vec<(String, String, usize)>,
    pub rate_transitions: Vec<String>,
    /// Base ticks per log chunk when logs are streamed (`None`: whole logs).
    pub chunk_ticks: Option<u64>,
}

/// Told where each block's work in a tick begins and ends
/// ([`Scheduler::tick_probed`]): `enter(i)` before block `i` (execution order,
/// as in [`Scheduler::block_names`]) gathers its inputs and computes, `leave(i)`
/// after — once for its output phase and, for a block without feed-through,
/// once more for its update phase. Called on the ticking thread: an
/// implementation must not allocate, lock or block.
pub trait TickProbe {
    /// Block `block` starts a phase.
    fn enter(&mut self, block: usize);
    /// Block `block` ends it.
    fn leave(&mut self, block: usize);
}

/// No probe: what [`Scheduler::tick`] uses (both calls compile to nothing).
impl TickProbe for () {
    #[inline(always)]
    fn enter(&mut self, _block: usize) {}
    #[inline(always)]
    fn leave(&mut self, _block: usize) {}
}

/// A handle to an output signal, resolved once with [`Scheduler::signal_id`] and
/// read every tick with [`Scheduler::read`] without any look-up.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct SignalId {
    offset: usize,
    width: usize,
}

/// A recorded signal after a run.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct SignalLog {
    /// `block.port`.
    pub name: String,
    /// Sample rate of the log (the source block's rate), Hz.
    pub rate_hz: f64,
    /// Values per sample.
    pub width: usize,
    /// Unit of the values, if known (SI, e.g. `m`).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub unit: Option<String>,
    /// Samples, row-major: `data[i * width + j]` is element j of sample i, taken at
    /// t = i / rate_hz.
    pub data: Vec<f64>,
}

impl SignalLog {
    /// Number of samples.
    pub fn len(&self) -> usize {
        self.data.len().checked_div(self.width).unwrap_or(0)
    }
    /// Whether no sample was recorded.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }
    /// Element `j` of every sample.
    pub fn column(&self, j: usize) -> Vec<f64> {
        self.data
            .iter()
            .skip(j)
            .step_by(self.width.max(1))
            .copied()
            .collect()
    }
    /// Sample times (s).
    pub fn times(&self) -> Vec<f64> {
        (0..self.len()).map(|i| i as f64 / self.rate_hz).collect()
    }
}

/// Scores of one error signal (each element of a vector signal separately).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Score {
    /// `block.port`, with `[j]` for element j of a vector signal.
    pub signal: String,
    /// Samples before this time (s) were ignored.
    pub from_s: f64,
    /// Unit of rms, max_abs and mean, if known.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub unit: Option<String>,
    /// Root mean square.
    pub rms: f64,
    /// Largest absolute value.
    pub max_abs: f64,
    /// Mean.
    pub mean: f64,
    /// Number of samples scored.
    pub samples: usize,
}

/// What a run produced.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct RunResult {
    /// Title of the graph, if it had one.
    pub title: Option<String>,
    /// Simulated time (s).
    pub duration_s: f64,
    /// Recorded signals, in the order they were asked for (logs first, then scored
    /// signals not already logged).
    pub logs: Vec<SignalLog>,
    /// Scores of the `score:` signals.
    pub scores: Vec<Score>,
}

/// A compiled graph, ready to tick. Build one with
/// [`GraphSpec::build`](crate::graph::GraphSpec::build).
pub struct Scheduler {
    title: Option<String>,
    base_rate_hz: f64,
    n_ticks: u64,
    k: u64,
    blocks: Vec<Box<dyn Block>>,
    nodes: Vec<Node>,
    gathers: Vec<Gather>,
    signals: Vec<f64>,
    inputs: Vec<f64>,
    ctxs: Vec<BuildContext>,
    names: Vec<String>,
    type_names: Vec<String>,
    ports: Vec<(Vec<Port>, Vec<Port>, Vec<usize>)>,
    logs: Vec<LogChannel>,
    scores: Vec<ScoreChannel>,
    compares: Vec<(String, String, usize)>,
    rate_transitions: Vec<String>,
    /// One entry per distinct period (and sample time), those of period 1
    /// (the base rate) first.
    rates: Vec<Rate>,
    /// How many of `rates` have period 1.
    n_base: usize,
    /// The base tick on which a slower rate is next due (`u64::MAX`: none).
    next_slow: u64,
    /// What [`Scheduler::tick`] runs: inserted rate transitions folded into
    /// their consumers' inputs where they can be.
    folded: Program,
    /// What [`Scheduler::tick_probed`] runs: every block as written in the
    /// execution order, transitions included.
    plain: Program,
    /// The first non-finite output, once located: (execution index, output
    /// offset, base tick, value).
    non_finite: Option<(usize, usize, u64, f64)>,
    /// Base ticks done when a chunk check of [`Scheduler::run`] first saw a
    /// non-finite output (not yet located).
    seen_non_finite: Option<u64>,
    /// Base ticks per log chunk when logs are streamed (`None`: whole logs).
    chunk_ticks: Option<u64>,
}

impl std::fmt::Debug for Scheduler {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Scheduler")
            .field("base_rate_hz", &self.base_rate_hz)
            .field("blocks", &self.names)
            .field("k", &self.k)
            .finish_non_exhaustive()
    }
}

impl Scheduler {
    pub(crate) fn new_internal(mut p: Parts) -> Self {
        // One rate per (period, dt), the base-rate ones first.
        let mut rates: Vec<Rate> = Vec::new();
        let mut rate_of = std::collections::HashMap::new();
        let base_first = p
            .nodes
            .iter()
            .filter(|n| n.period == 1)
            .chain(p.nodes.iter().filter(|n| n.period != 1));
        for node in base_first {
            rate_of
                .entry((node.period, node.dt.to_bits()))
                .or_insert_with(|| {
                    rates.push(Rate {
                        period: node.period,
                        dt: node.dt,
                        next: 0,
                        done: 0,
                        due: false,
                        tick: Tick::new(0, node.dt),
                    });
                    rates.len() - 1
                });
        }
        for node in &mut p.nodes {
            node.rate = rate_of[&(node.period, node.dt.to_bits())];
        }
        let n_base = rates.iter().filter(|r| r.period == 1).count();
        let producer = producers(&p.nodes, p.signal_len);
        let plain = Program::compile(&p.nodes, &p.gathers, &[], &producer);
        let fold = foldable_transitions(&p.nodes, &p.gathers, &p.logs, &producer);
        let folded = Program::compile(&p.nodes, &p.gathers, &fold, &producer);
        let mut s = Self {
            title: p.title,
            base_rate_hz: p.base_rate_hz,
            n_ticks: p.n_ticks,
            k: 0,
            blocks: p.blocks,
            nodes: p.nodes,
            gathers: p.gathers,
            signals: vec![0.0; p.signal_len],
            inputs: vec![0.0; p.input_len],
            ctxs: p.ctxs,
            names: p.names,
            type_names: p.type_names,
            ports: p.ports,
            logs: p.logs,
            scores: p.scores,
            compares: p.compares,
            rate_transitions: p.rate_transitions,
            rates,
            n_base,
            next_slow: u64::MAX,
            folded,
            plain,
            non_finite: None,
            seen_non_finite: None,
            chunk_ticks: p.chunk_ticks,
        };
        s.restart_rates();
        s
    }

    /// Every rate due on base tick 0, none begun.
    fn restart_rates(&mut self) {
        self.rates.iter_mut().for_each(Rate::restart);
        self.next_slow = if self.rates.len() > self.n_base {
            0
        } else {
            u64::MAX
        };
    }

    /// One base tick: output phase, update phase, logging. Allocation-free.
    ///
    /// Due blocks are found per rate (one comparison per tick when only the
    /// base rate is due); inputs are gathered by copies whose indices were
    /// resolved at build time, or read in place when they are one contiguous
    /// run of the signal buffer. An inserted rate transition whose output only
    /// its consumer reads (not logged) is folded into the consumer: the
    /// consumer reads the transition's source directly — the same value, as
    /// the transition runs at its consumer's rate and would have copied the
    /// source on this very tick before the consumer read it — so the
    /// transition's own output signal is not written by `tick` (it is by
    /// [`Scheduler::tick_probed`], which runs every block as built).
    #[inline]
    pub fn tick(&mut self) {
        self.tick_with(&mut (), true);
    }

    /// [`Scheduler::tick`] with `probe` told when each due block starts and
    /// ends its output phase and its update phase (input gathering included),
    /// e.g. to time every block. Every block runs as built: inserted rate
    /// transitions are not folded (each is timed as its own block, and writes
    /// its output signal); the values are the same as `tick`'s.
    #[inline]
    pub fn tick_probed<P: TickProbe>(&mut self, probe: &mut P) {
        self.tick_with(probe, false);
    }

    #[inline(always)]
    fn tick_with<P: TickProbe>(&mut self, probe: &mut P, folded: bool) {
        let k = self.k;
        let only_base = k != self.next_slow;
        // The one sample every step of this tick gets, when only one rate is
        // due (the common single-rate graph): read once here instead of from
        // `rates` per step.
        let mut single: Option<Tick> = None;
        if only_base {
            // Only the base rate is due: begin its sample.
            if let [rate] = &mut self.rates[..self.n_base] {
                single = Some(rate.begin_sample());
            } else {
                for rate in self.rates[..self.n_base].iter_mut() {
                    rate.begin_sample();
                }
            }
        } else {
            let mut next_slow = u64::MAX;
            for rate in self.rates.iter_mut() {
                rate.due = rate.next == k;
                if rate.due {
                    rate.begin_sample();
                }
                if rate.period > 1 {
                    next_slow = next_slow.min(rate.next);
                }
            }
            self.next_slow = next_slow;
        }
        let Self {
            blocks,
            rates,
            signals,
            inputs,
            logs,
            folded: folded_program,
            plain,
            ..
        } = self;
        let program = if folded { folded_program } else { plain };
        let mut run = Run {
            blocks,
            rates,
            gathers: &program.gathers,
            signals,
            inputs,
            probe,
        };
        // Phase 1: outputs of the due blocks in topological order; phase 2:
        // state updates of due blocks without feed-through, with this
        // sample's inputs (all outputs of this sample exist now). On a tick
        // with only the base rate due, the fast program holds just its blocks.
        let rates = run.rates;
        if let Some(tick) = single {
            for step in &program.fast {
                run.step(step, tick);
            }
        } else if only_base {
            for step in &program.fast {
                run.step(step, rates[step.rate].tick);
            }
        } else {
            for step in &program.full {
                let rate = &rates[step.rate];
                if rate.due {
                    run.step(step, rate.tick);
                }
            }
        }
        // Phase 3: logging into preallocated buffers (capacity reserved at build).
        for log in logs.iter_mut() {
            if log.countdown != 0 {
                log.countdown -= 1;
                continue;
            }
            log.countdown = log.period - 1;
            if log.data.len() + log.width <= log.data.capacity() {
                log.data
                    .extend_from_slice(&signals[log.offset..log.offset + log.width]);
            } else {
                log.dropped += 1;
            }
        }
        self.k += 1;
    }

    /// Run `n` base ticks.
    pub fn step_n(&mut self, n: u64) {
        for _ in 0..n {
            self.tick();
        }
    }

    /// Run the whole duration from the current state, calling `progress` with the
    /// fraction done (0..=1) about a hundred times, and return the logs and scores.
    ///
    /// On a streamed graph ([`GraphSpec::build_streamed`](crate::graph::GraphSpec::build_streamed))
    /// this is [`Scheduler::run_streamed`] with a sink that discards the samples:
    /// the scores are computed, the returned logs are empty.
    pub fn run(&mut self, mut progress: impl FnMut(f64)) -> RunResult {
        if self.chunk_ticks.is_some() {
            let r: Result<RunResult, std::convert::Infallible> =
                self.run_chunked(&mut |_| Ok(()), &mut progress);
            return r.unwrap_or_else(|e| match e {});
        }
        self.run_whole(&mut progress)
    }

    /// [`Scheduler::run`] with whole logs.
    fn run_whole(&mut self, progress: &mut dyn FnMut(f64)) -> RunResult {
        let remaining = self.n_ticks.saturating_sub(self.k);
        let chunk = (self.n_ticks / 100).max(1);
        let mut done = 0;
        while done < remaining {
            let n = chunk.min(remaining - done);
            self.step_n(n);
            done += n;
            // Chunk check (about 100 per run, O(signals) each): remembers that a
            // non-finite value exists, for `check_finite` to locate exactly.
            if self.seen_non_finite.is_none() && self.first_non_finite_output().is_some() {
                self.seen_non_finite = Some(self.k);
            }
            progress(self.k as f64 / self.n_ticks.max(1) as f64);
        }
        self.result()
    }

    /// Whether logs are streamed (built with
    /// [`GraphSpec::build_streamed`](crate::graph::GraphSpec::build_streamed)).
    pub fn is_streamed(&self) -> bool {
        self.chunk_ticks.is_some()
    }

    /// Bytes reserved for logs now (their capacity): the whole run's samples
    /// for whole logs, one chunk for streamed logs.
    pub fn log_capacity_bytes(&self) -> usize {
        self.logs.iter().map(|l| l.data.capacity() * 8).sum()
    }

    /// Run the whole duration from the current state with streamed logs: after
    /// every chunk of at most [`LOG_CHUNK_TICKS`](crate::graph::LOG_CHUNK_TICKS)
    /// base ticks (and about a hundred times per run, for `progress`), `sink`
    /// gets the new samples of every log (one [`LogChunk`] per log, in log order)
    /// and the log buffers are emptied for the next chunk; the scores are summed
    /// online (same values as [`Scheduler::result`] on whole logs). Ticks stay
    /// allocation-free; memory does not depend on the duration. Non-finite
    /// samples are noticed in each chunk for [`Scheduler::check_finite`].
    ///
    /// The returned [`RunResult`] has the scores and no log samples. A sink error
    /// stops the run and is returned. On a graph with whole logs this runs like
    /// [`Scheduler::run`] and hands each log over once, at the end.
    pub fn run_streamed<E>(
        &mut self,
        mut sink: impl FnMut(&[LogChunk<'_>]) -> Result<(), E>,
        mut progress: impl FnMut(f64),
    ) -> Result<RunResult, E> {
        if self.chunk_ticks.is_some() {
            return self.run_chunked(&mut sink, &mut progress);
        }
        {
            let result = self.run_whole(&mut progress);
            let chunks: Vec<LogChunk<'_>> = self
                .logs
                .iter()
                .map(|l| LogChunk {
                    name: &l.name,
                    rate_hz: l.rate_hz,
                    width: l.width,
                    start_sample: 0,
                    total_samples: l.total_samples,
                    unit: l.unit.as_deref(),
                    data: &l.data,
                })
                .collect();
            sink(&chunks)?;
            Ok(result)
        }
    }

    /// [`Scheduler::run_streamed`] on a streamed graph.
    fn run_chunked<E>(
        &mut self,
        sink: &mut dyn FnMut(&[LogChunk<'_>]) -> Result<(), E>,
        progress: &mut dyn FnMut(f64),
    ) -> Result<RunResult, E> {
        let chunk_ticks = self.chunk_ticks.unwrap_or(u64::MAX);
        let remaining = self.n_ticks.saturating_sub(self.k);
        let step = (self.n_ticks / 100).clamp(1, chunk_ticks.max(1));
        let mut done = 0;
        while done < remaining {
            let n = step.min(remaining - done);
            self.step_n(n);
            done += n;
            if self.seen_non_finite.is_none() && self.first_non_finite_output().is_some() {
                self.seen_non_finite = Some(self.k);
            }
            self.fold_scores();
            if self.seen_non_finite.is_none() {
                self.seen_non_finite = self.first_non_finite_log_tick();
            }
            // One small Vec per chunk (outside the ticks).
            let chunks: Vec<LogChunk<'_>> = self
                .logs
                .iter()
                .map(|l| LogChunk {
                    name: &l.name,
                    rate_hz: l.rate_hz,
                    width: l.width,
                    start_sample: l.streamed,
                    total_samples: l.total_samples,
                    unit: l.unit.as_deref(),
                    data: &l.data,
                })
                .collect();
            sink(&chunks)?;
            for l in &mut self.logs {
                l.streamed += (l.data.len() / l.width.max(1)) as u64;
                l.data.clear();
            }
            progress(self.k as f64 / self.n_ticks.max(1) as f64);
        }
        let mut result = self.result();
        result.logs.iter_mut().for_each(|l| l.data = Vec::new());
        Ok(result)
    }

    /// Add the samples now in the logs to the online score sums (streamed runs).
    fn fold_scores(&mut self) {
        for s in &mut self.scores {
            let l = &self.logs[s.channel];
            let w = l.width.max(1);
            let skip = s.first.saturating_sub(l.streamed) as usize;
            for row in l.data.chunks_exact(w).skip(skip) {
                for (a, &x) in s.acc.iter_mut().zip(row) {
                    a.add(x);
                }
            }
        }
    }

    /// Logs and scores of what has run so far.
    pub fn result(&self) -> RunResult {
        for l in self.logs.iter().filter(|l| l.dropped > 0) {
            tracing::warn!(
                target: "nanomotion_core::scheduler",
                log = %l.name,
                dropped = l.dropped,
                "a streamed log was stepped past its chunk outside run_streamed; these samples were not recorded"
            );
        }
        let logs: Vec<SignalLog> = self
            .logs
            .iter()
            .map(|l| SignalLog {
                name: l.name.clone(),
                rate_hz: l.rate_hz,
                width: l.width,
                unit: l.unit.clone(),
                data: l.data.clone(),
            })
            .collect();
        let mut scores = Vec::new();
        for s in &self.scores {
            let log = &logs[s.channel];
            if self.chunk_ticks.is_some() {
                for (j, a) in s.acc.iter().enumerate() {
                    let (rms, max_abs, mean) = a.finish();
                    scores.push(Score {
                        signal: if log.width == 1 {
                            log.name.clone()
                        } else {
                            format!("{}[{j}]", log.name)
                        },
                        from_s: s.from_s,
                        unit: log.unit.clone(),
                        rms,
                        max_abs,
                        mean,
                        samples: a.n,
                    });
                }
                continue;
            }
            let first = (s.from_s * log.rate_hz - 1e-9).ceil().max(0.0) as usize;
            for j in 0..log.width {
                let col: Vec<f64> = log.column(j).into_iter().skip(first).collect();
                let n = col.len();
                let (rms, max_abs, mean) = if n == 0 {
                    (f64::NAN, f64::NAN, f64::NAN)
                } else {
                    (
                        (col.iter().map(|x| x * x).sum::<f64>() / n as f64).sqrt(),
                        col.iter().fold(0.0f64, |m, x| m.max(x.abs())),
                        col.iter().sum::<f64>() / n as f64,
                    )
                };
                let signal = if log.width == 1 {
                    log.name.clone()
                } else {
                    format!("{}[{j}]", log.name)
                };
                scores.push(Score {
                    signal,
                    from_s: s.from_s,
                    unit: log.unit.clone(),
                    rms,
                    max_abs,
                    mean,
                    samples: n,
                });
            }
        }
        RunResult {
            title: self.title.clone(),
            duration_s: self.k as f64 / self.base_rate_hz,
            logs,
            scores,
        }
    }

    /// Check that the run so far produced only finite values; otherwise name the
    /// block, port and base tick of the *first* non-finite output.
    ///
    /// How (issue 13, item 8): nothing is checked inside [`Scheduler::tick`], so the
    /// real-time path costs what the bench measures. Instead non-finite values are
    /// *detected* cheaply — [`Scheduler::run`] checks every output after each of its
    /// ~100 chunks, and this method checks the current outputs and scans every
    /// log once (a transient `inf` that recovers still sits in the log and would
    /// reach the CSV) — and then *located* exactly by replaying from the initial
    /// state ([`Scheduler::reset`] replays bit for bit) with every block's outputs
    /// checked after every tick, up to the tick where the value was seen. In
    /// execution order the producer comes before every block it feeds, so the first
    /// non-finite output of the first bad tick is its producer's. A failed check
    /// thus costs at most one more run; a passing one costs a scan of the logs.
    /// Not detected: a non-finite value in an unlogged signal that recovers before
    /// the next chunk boundary and leaves no trace in any logged or final output.
    ///
    /// After an error the scheduler stands at the located tick (its logs hold the
    /// replay up to there); call [`Scheduler::reset`] to start over.
    pub fn check_finite(&mut self) -> Result<(), GraphError> {
        if self.non_finite.is_none() {
            let seen = self
                .seen_non_finite
                .or_else(|| self.first_non_finite_output().map(|_| self.k))
                .or_else(|| self.first_non_finite_log_tick());
            if let Some(seen) = seen {
                tracing::debug!(
                    target: "nanomotion_core::scheduler",
                    seen,
                    "non-finite value detected; replaying to locate it"
                );
                self.locate_non_finite(seen)?;
            }
        }
        match self.non_finite {
            None => Ok(()),
            Some((i, offset, tick, value)) => {
                let (_, outs, offs) = &self.ports[i];
                let port = offs
                    .iter()
                    .zip(outs)
                    .find(|(o, p)| (**o..**o + p.width).contains(&offset))
                    .map(|(o, p)| {
                        if p.width == 1 {
                            p.name.clone()
                        } else {
                            format!("{}[{}]", p.name, offset - o)
                        }
                    })
                    .unwrap_or_default();
                Err(GraphError::NonFinite {
                    block: self.names[i].clone(),
                    type_name: self.type_names[i].clone(),
                    port,
                    value,
                    tick,
                    t_s: tick as f64 / self.base_rate_hz,
                })
            }
        }
    }

    /// The first block (execution order) with a non-finite output now:
    /// (execution index, offset in the signal buffer).
    fn first_non_finite_output(&self) -> Option<(usize, usize)> {
        self.nodes.iter().enumerate().find_map(|(i, node)| {
            let r = node.outputs.clone();
            self.signals[r.clone()]
                .iter()
                .position(|v| !v.is_finite())
                .map(|j| (i, r.start + j))
        })
    }

    /// Ticks done when the earliest non-finite logged sample was recorded.
    fn first_non_finite_log_tick(&self) -> Option<u64> {
        self.logs
            .iter()
            .filter_map(|l| {
                let i = l.data.iter().position(|v| !v.is_finite())? / l.width.max(1);
                Some((l.streamed + i as u64) * l.period + 1)
            })
            .min()
    }

    /// Replay from the initial state until the first non-finite output, at most
    /// `seen` ticks (where it was detected) — or the ticks done so far.
    fn locate_non_finite(&mut self, seen: u64) -> Result<(), GraphError> {
        let end = seen.max(1).min(self.k.max(1));
        self.reset()?;
        while self.k < end {
            self.tick();
            if let Some((i, offset)) = self.first_non_finite_output() {
                self.non_finite = Some((i, offset, self.k - 1, self.signals[offset]));
                tracing::warn!(
                    target: "nanomotion_core::scheduler",
                    block = %self.names[i],
                    tick = self.k - 1,
                    "first non-finite output located by replay"
                );
                return Ok(());
            }
        }
        Err(GraphError::NonFiniteNotReproduced {
            tick: seen,
            place: "during the run".into(),
        })
    }

    /// Restart from the initial state: every block is built again with the same
    /// context (same seeds), logs are cleared. Same graph, same bits.
    pub fn reset(&mut self) -> Result<(), GraphError> {
        for (i, b) in self.blocks.iter_mut().enumerate() {
            b.build(&self.ctxs[i])
                .map_err(|source: ParamError| GraphError::Param {
                    block: self.names[i].clone(),
                    type_name: self.type_names[i].clone(),
                    source,
                })?;
        }
        self.restart_rates();
        self.signals.iter_mut().for_each(|v| *v = 0.0);
        self.inputs.iter_mut().for_each(|v| *v = 0.0);
        for l in &mut self.logs {
            l.data.clear();
            l.countdown = 0;
            l.streamed = 0;
            l.dropped = 0;
        }
        for s in &mut self.scores {
            s.acc.iter_mut().for_each(|a| *a = ScoreAcc::default());
        }
        self.k = 0;
        self.non_finite = None;
        self.seen_non_finite = None;
        Ok(())
    }

    /// The `score:` entries: `(log name, from_s)` in graph order.
    pub fn score_signals(&self) -> Vec<(String, f64)> {
        self.scores
            .iter()
            .map(|s| (self.logs[s.channel].name.clone(), s.from_s))
            .collect()
    }

    /// The `compare:` entries: `(signal, measured column)` in graph order.
    pub fn compares(&self) -> impl Iterator<Item = (&str, &str)> {
        self.compares
            .iter()
            .map(|(s, c, _)| (s.as_str(), c.as_str()))
    }

    /// The samples recorded so far of the `i`-th `compare:` signal and their rate
    /// (Hz), without copying.
    pub fn compare_log(&self, i: usize) -> Option<(&[f64], f64)> {
        let (_, _, ch) = self.compares.get(i)?;
        let l = &self.logs[*ch];
        Some((&l.data, l.rate_hz))
    }

    /// The samples recorded so far of log channel `name` (`block.port`), their
    /// width and rate (Hz), without copying.
    pub fn log_view(&self, name: &str) -> Option<(&[f64], usize, f64)> {
        let l = self.logs.iter().find(|l| l.name == name)?;
        Some((&l.data, l.width, l.rate_hz))
    }

    /// Index of block `name` in execution order (resolve once, then use
    /// [`Scheduler::block_at_mut`] without look-ups).
    pub fn block_index(&self, name: &str) -> Option<usize> {
        self.names.iter().position(|n| n == name)
    }

    /// The block at execution index `i`, mutable (to change a [`Tunable`](crate::block::Tunable)
    /// block's parameters between runs; call [`Scheduler::reset`] afterwards).
    pub fn block_at_mut(&mut self, i: usize) -> Option<&mut dyn Block> {
        Some(self.blocks.get_mut(i)?.as_mut())
    }

    /// The context block `i` (execution order) was built with: what building a
    /// copy of it needs (to validate a parameter change off the real-time
    /// path, as `nanomotion-rt`'s live updates do).
    pub fn build_context(&self, i: usize) -> Option<&BuildContext> {
        self.ctxs.get(i)
    }

    /// The block called `name`, mutable.
    pub fn block_mut(&mut self, name: &str) -> Option<&mut dyn Block> {
        let i = self.block_index(name)?;
        self.block_at_mut(i)
    }

    /// Resolve `block.port` to a handle for [`Scheduler::read`].
    pub fn signal_id(&self, reference: &str) -> Option<SignalId> {
        let (b, port) = reference.split_once('.')?;
        let bi = self.names.iter().position(|n| n == b)?;
        let (_, outs, offs) = &self.ports[bi];
        let pi = outs.iter().position(|o| o.name == port)?;
        Some(SignalId {
            offset: offs[pi],
            width: outs[pi].width,
        })
    }

    /// The current value of a signal.
    #[inline]
    pub fn read(&self, id: SignalId) -> &[f64] {
        &self.signals[id.offset..id.offset + id.width]
    }

    /// Set a signal between ticks, without any look-up: for an output that its
    /// block holds and the outside world fills (the `hw_input` block of
    /// `nanomotion-rt` gets a device's samples this way before each tick). A
    /// block that computes this output overwrites it on its next due tick.
    #[inline]
    pub fn write(&mut self, id: SignalId, values: &[f64]) {
        self.signals[id.offset..id.offset + id.width].copy_from_slice(values);
    }

    /// Base ticks run so far.
    pub fn ticks_done(&self) -> u64 {
        self.k
    }
    /// Base ticks of the whole run.
    pub fn ticks_total(&self) -> u64 {
        self.n_ticks
    }
    /// Base rate (Hz).
    pub fn base_rate_hz(&self) -> f64 {
        self.base_rate_hz
    }
    /// Simulated time so far (s).
    pub fn time_s(&self) -> f64 {
        self.k as f64 / self.base_rate_hz
    }
    /// Block names in execution order.
    pub fn block_names(&self) -> &[String] {
        &self.names
    }
    /// Rate transitions the loader inserted, one line each.
    pub fn rate_transitions(&self) -> &[String] {
        &self.rate_transitions
    }
    /// The block called `name`.
    pub fn block(&self, name: &str) -> Option<&dyn Block> {
        let i = self.names.iter().position(|n| n == name)?;
        Some(self.blocks[i].as_ref())
    }
    /// The discrete LTI model of block `name`, if it is LTI.
    pub fn lti_of(&self, name: &str) -> Option<StateSpace> {
        self.block(name)?.lti()
    }
    /// How every block is wired, in execution order: what analyses of the built
    /// graph need (the stability gate, [`crate::gate`], finds loops with it).
    pub fn wiring(&self) -> Vec<BlockWiring> {
        // Output offset -> (block, output port); ports have width >= 1, so the
        // offsets are distinct.
        let mut at = std::collections::HashMap::new();
        for (j, (_, outs, offs)) in self.ports.iter().enumerate() {
            for (pi, (o, &off)) in outs.iter().zip(offs).enumerate() {
                if o.width > 0 {
                    at.insert(off, (j, pi));
                }
            }
        }
        self.names
            .iter()
            .enumerate()
            .map(|(i, name)| {
                let (ins, outs, _) = &self.ports[i];
                let node = &self.nodes[i];
                BlockWiring {
                    name: name.clone(),
                    type_name: self.type_names[i].clone(),
                    period: node.period,
                    dt: node.dt,
                    inputs: ins.clone(),
                    outputs: outs.clone(),
                    sources: self.gathers[node.gathers.clone()]
                        .iter()
                        .map(|g| at.get(&g.src).copied().unwrap_or((usize::MAX, 0)))
                        .collect(),
                    feedthrough: node.feedthrough,
                }
            })
            .collect()
    }
    /// The block at execution index `i` (see [`Scheduler::wiring`]).
    pub fn block_at(&self, i: usize) -> Option<&dyn Block> {
        self.blocks.get(i).map(|b| b.as_ref())
    }
    /// One line per block: name, type, role, rate, ports.
    pub fn describe(&self) -> Vec<String> {
        self.names
            .iter()
            .enumerate()
            .map(|(i, n)| {
                let (ins, outs, _) = &self.ports[i];
                let fmt = |ps: &[Port]| {
                    ps.iter()
                        .map(|p| format!("{}[{}]", p.name, p.width))
                        .collect::<Vec<_>>()
                        .join(", ")
                };
                format!(
                    "{n} ({}, {}) at {} Hz: in ({}) -> out ({}){}",
                    self.type_names[i],
                    self.blocks[i].role().as_str(),
                    1.0 / self.nodes[i].dt,
                    fmt(ins),
                    fmt(outs),
                    if self.nodes[i].feedthrough {
                        ""
                    } else {
                        ", no feed-through"
                    }
                )
            })
            .collect()
    }
}

/// How one block of a built graph is wired ([`Scheduler::wiring`]).
#[derive(Debug, Clone, PartialEq)]
pub struct BlockWiring {
    /// Instance name (inserted rate transitions start with `rt:`).
    pub name: String,
    /// The `type:` tag.
    pub type_name: String,
    /// Period in base ticks.
    pub period: u64,
    /// Period in seconds.
    pub dt: f64,
    /// Input ports.
    pub inputs: Vec<Port>,
    /// Output ports.
    pub outputs: Vec<Port>,
    /// For each input port: (execution index of the source block, index of its
    /// output port).
    pub sources: Vec<(usize, usize)>,
    /// Whether the block has direct feed-through.
    pub feedthrough: bool,
}

/// What one tick works on.
struct Run<'a, P> {
    blocks: &'a mut [Box<dyn Block>],
    rates: &'a [Rate],
    gathers: &'a [Gather],
    signals: &'a mut [f64],
    inputs: &'a mut [f64],
    probe: &'a mut P,
}

impl<P: TickProbe> Run<'_, P> {
    /// One due block's phase, at sample `tick` of its rate.
    #[inline(always)]
    fn step(&mut self, s: &Step, tick: Tick) {
        let (g0, g1) = s.gathers;
        let (i0, i1) = s.inputs;
        let (o0, o1) = s.outputs;
        self.probe.enter(s.block);
        match s.kind {
            StepKind::Hold => {
                let g = self.gathers[g0];
                hold(self.signals, g.src, o0, g.len);
            }
            StepKind::Output => {
                gather(&self.gathers[g0..g1], self.signals, self.inputs);
                self.blocks[s.block].output(tick, &self.inputs[i0..i1], &mut self.signals[o0..o1]);
            }
            StepKind::OutputDirect => {
                let g = self.gathers[g0];
                let (u, y) = disjoint(self.signals, g.src..g.src + g.len, o0..o1);
                self.blocks[s.block].output(tick, u, y);
            }
            StepKind::OutputHeld => {
                self.blocks[s.block].output(tick, &self.inputs[i0..i1], &mut self.signals[o0..o1]);
            }
            StepKind::Update => {
                gather(&self.gathers[g0..g1], self.signals, self.inputs);
                self.blocks[s.block].update(tick, &self.inputs[i0..i1]);
            }
        }
        self.probe.leave(s.block);
    }
}

/// `signals[input]` to read and `signals[output]` to write, two disjoint
/// ranges (a block's input is another block's output: a block feeding itself
/// through feed-through is an algebraic loop, rejected at build).
#[inline(always)]
fn disjoint(
    signals: &mut [f64],
    input: Range<usize>,
    output: Range<usize>,
) -> (&[f64], &mut [f64]) {
    if input.end <= output.start {
        let (a, b) = signals.split_at_mut(output.start);
        (&a[input], &mut b[..output.end - output.start])
    } else {
        let (a, b) = signals.split_at_mut(input.start);
        (&b[..input.end - input.start], &mut a[output])
    }
}

impl Program {
    /// The steps of `nodes`, with the transitions marked in `fold` folded into
    /// their consumers: the consumers' gathers read the transition's source.
    fn compile(nodes: &[Node], gathers: &[Gather], fold: &[bool], producer: &[usize]) -> Self {
        let mut program = Program {
            gathers: gathers.to_vec(),
            ..Program::default()
        };
        for g in program.gathers.iter_mut() {
            if let Some(&t) = producer.get(g.src)
                && fold.get(t) == Some(&true)
            {
                let node = &nodes[t];
                g.src = gathers[node.gathers.start].src + (g.src - node.outputs.start);
            }
        }
        let step = |i: usize, kind: StepKind| {
            let n = &nodes[i];
            Step {
                kind,
                block: i,
                rate: n.rate,
                gathers: (n.gathers.start, n.gathers.end),
                inputs: (n.inputs.start, n.inputs.end),
                outputs: (n.outputs.start, n.outputs.end),
            }
        };
        let mut outputs = Vec::new();
        let mut updates = Vec::new();
        for (i, n) in nodes.iter().enumerate() {
            if fold.get(i) == Some(&true) {
                continue;
            }
            let kind = if n.transition {
                StepKind::Hold
            } else if !n.feedthrough {
                StepKind::OutputHeld
            } else if n.gathers.len() == 1 && program.gathers[n.gathers.start].len == n.inputs.len()
            {
                StepKind::OutputDirect
            } else {
                StepKind::Output
            };
            outputs.push(step(i, kind));
            if !n.feedthrough {
                updates.push(step(i, StepKind::Update));
            }
        }
        program.full = outputs.into_iter().chain(updates).collect();
        program.fast = program
            .full
            .iter()
            .filter(|s| nodes[s.block].period == 1)
            .copied()
            .collect();
        program
    }
}

/// For each offset of the signal buffer, the execution index of the block
/// whose output it is.
fn producers(nodes: &[Node], signal_len: usize) -> Vec<usize> {
    let mut producer = vec![usize::MAX; signal_len];
    for (i, n) in nodes.iter().enumerate() {
        producer[n.outputs.clone()].iter_mut().for_each(|p| *p = i);
    }
    producer
}

/// Which inserted rate transitions a tick can skip: those whose output is
/// read only by blocks at the transition's own rate (its consumer) and is not
/// logged, and whose source is not itself a transition. Such a consumer can
/// read the source directly: the transition, due on the same ticks, would
/// have copied the source's current value before the consumer reads it (a
/// consumer with feed-through comes after it in execution order; one without
/// reads in the update phase, after every output). Linear in the graph.
fn foldable_transitions(
    nodes: &[Node],
    gathers: &[Gather],
    logs: &[LogChannel],
    producer: &[usize],
) -> Vec<bool> {
    let of = |offset: usize| producer.get(offset).copied().filter(|&p| p < nodes.len());
    let mut fold: Vec<bool> = nodes
        .iter()
        .map(|t| {
            t.transition
                && t.gathers.len() == 1
                && of(gathers[t.gathers.start].src).is_some_and(|s| !nodes[s].transition)
        })
        .collect();
    for l in logs {
        for offset in l.offset..l.offset + l.width {
            if let Some(p) = of(offset) {
                fold[p] = false;
            }
        }
    }
    for (reader, n) in nodes.iter().enumerate() {
        for g in &gathers[n.gathers.clone()] {
            if let Some(p) = of(g.src)
                && nodes[p].period != nodes[reader].period
            {
                fold[p] = false;
            }
        }
    }
    fold
}

/// A rate transition's work: its source's `len` values copied to its output.
#[inline(always)]
fn hold(signals: &mut [f64], src: usize, dst: usize, len: usize) {
    if len == 1 {
        signals[dst] = signals[src];
    } else {
        signals.copy_within(src..src + len, dst);
    }
}

/// Copy each gather's source values into the input buffer.
#[inline(always)]
fn gather(list: &[Gather], signals: &[f64], inputs: &mut [f64]) {
    for g in list {
        if g.len == 1 {
            inputs[g.dst] = signals[g.src];
        } else {
            inputs[g.dst..g.dst + g.len].copy_from_slice(&signals[g.src..g.src + g.len]);
        }
    }
}

/// Prefix of the names of inserted rate transitions. It contains `:`, which user
/// block names may not contain, so an inserted name can never be a user's name.
pub const RATE_TRANSITION_PREFIX: &str = "rt:";

/// Copies its input at its own rate: zero-order hold to a faster rate,
/// sampling to a slower one (inserted automatically between rates).
///
/// Running at a faster rate than its source it is a zero-order hold; at a
/// slower rate, a decimator (plain sampling: filter first if aliasing matters).
/// The loader inserts one for every connection between different rates and
/// reports it.
#[derive(Debug, Clone, Serialize, Deserialize, crate::doc::Params)]
#[serde(deny_unknown_fields)]
#[block(type_name = "rate_transition", role = Math, ports = "u[width] -> y[width] [unit of u]")]
pub struct RateTransition {
    /// Number of values carried.
    #[param(width)]
    pub width: usize,
}

impl RateTransition {
    /// A transition carrying `width` values.
    pub fn new(width: usize) -> Self {
        Self { width }
    }
}

#[crate::block::declared_block]
impl Block for RateTransition {
    fn output(&mut self, _tick: Tick, u: &[f64], y: &mut [f64]) {
        y.copy_from_slice(u);
    }
}
