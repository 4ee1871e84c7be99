//! [`RealtimeRunner`]: a built [`Scheduler`] ticked on the wall clock against a
//! [`Device`].
//!
//! One tick of the loop thread:
//! 0. apply the live parameter updates waiting in their ring ([`crate::live`]:
//!    resolved and judged off the loop, applied here without look-ups);
//! 1. sleep until the absolute deadline `t0 + slot · T` (`clock_nanosleep`,
//!    `TIMER_ABSTIME`), optionally spinning the last few µs;
//! 2. [`Device::read`] into the `hw_input` signals ([`Scheduler::write`]);
//! 3. [`Scheduler::tick`] (or, with [`RtConfig::block_timing`],
//!    [`Scheduler::tick_probed`] timing each block into its own histogram);
//! 4. the `hw_output` signals into [`Device::write`];
//! 5. timing into fixed-memory histograms; an overrun (the tick ended after the
//!    next deadline) is counted and handled by the [`OverrunPolicy`].
//!
//! Nothing in 0–5 allocates, locks or makes a system call other than the sleep
//! and the device's own I/O (`tests/runner.rs`, `ticks_do_not_allocate`,
//! counts allocations over the whole loop, with live updates too). Status and
//! events leave the thread through a wait-free ring ([`rtrb`]); when it is
//! full they are dropped and counted, never waited for.

use crate::clock::{self, BadCpu, Missing, Privileges};
use crate::device::{Device, DeviceError, HW_INPUT, HW_OUTPUT};
use crate::histogram::{Histogram, Summary};
use crate::live::{LiveParam, ParamSender, ParamUpdate, live_params};
use nanomotion_core::Scheduler;
pub use nanomotion_core::graph::OverrunPolicy;
use nanomotion_core::graph::RealtimeSpec;
use nanomotion_core::scheduler::{SignalId, TickProbe};
use serde::Serialize;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};

/// How to run the loop.
#[derive(Debug, Clone, PartialEq)]
pub struct RtConfig {
    /// Scheduling class, CPU and memory locking asked for.
    pub privileges: Privileges,
    /// Run at normal priority if a privilege is refused (otherwise refuse to run).
    pub allow_soft: bool,
    /// Overrun handling.
    pub overrun: OverrunPolicy,
    /// Stop (outputs safe) when more than this many overruns happened.
    pub max_overruns: Option<u64>,
    /// Busy-wait the last `spin_ns` before each deadline (0: sleep only).
    pub spin_ns: u64,
    /// Ticks to run; `None`: the graph's remaining duration.
    pub ticks: Option<u64>,
    /// Base ticks between two status events (0: none).
    pub status_every: u64,
    /// Slots of the event ring.
    pub ring_slots: usize,
    /// Keep every hardware input and output sample ([`Recording`], for MCAP and
    /// replay), in memory allocated at build for the graph's duration.
    pub record: bool,
    /// Time every block of every tick ([`Timing::blocks`]): two clock reads per
    /// block phase, in a histogram per block allocated at build.
    pub block_timing: bool,
    /// Slots of the ring of live parameter updates into the loop
    /// ([`RealtimeRunner::param_sender`]); the loop empties it at every tick
    /// boundary.
    pub param_slots: usize,
    /// Live parameter updates one [`ParamSender`] sends at most (the
    /// recording of them is allocated at build for this many).
    pub max_param_updates: usize,
}

impl Default for RtConfig {
    /// SCHED_FIFO 80, memory locked, the CPUs held out of deep idle states
    /// (where permitted), no pinning, refuse without privilege, skip
    /// overruns without limit, no spin, the graph's duration, no recording; a
    /// status event every 100 ms of ticks ([`RealtimeRunner::new`] turns the
    /// `status_every: 0` here into the graph's rate / 10).
    fn default() -> Self {
        Self {
            privileges: Privileges {
                priority: Some(80),
                cpu: None,
                lock_memory: true,
                hold_cpu_latency: true,
            },
            allow_soft: false,
            overrun: OverrunPolicy::Skip,
            max_overruns: None,
            spin_ns: 0,
            ticks: None,
            status_every: 0,
            ring_slots: 1024,
            record: false,
            block_timing: false,
            param_slots: 64,
            max_param_updates: 4096,
        }
    }
}

impl RtConfig {
    /// The loop asked for: `privileges`, running at normal priority where one is
    /// refused if `allow_soft`, and the overrun policy and limit of `settings`
    /// (see [`RtConfig::with_settings`]); everything else as
    /// [`RtConfig::default`]. `nanomotion rt`, `nanomotion plant`, Python's
    /// `rt` and [`RtConfig::soft_catch_up`] all build their loop here.
    pub fn new(privileges: Privileges, allow_soft: bool, settings: RealtimeSpec) -> Self {
        Self {
            privileges,
            allow_soft,
            ..Self::default()
        }
        .with_settings(settings)
    }

    /// A real-time run that works on any machine (tests, examples): SCHED_FIFO
    /// 80 where permitted, normal priority where not (`allow_soft`), memory
    /// unlocked, the CPUs' idle states left alone, and late ticks caught up so
    /// that every tick runs.
    pub fn soft_catch_up() -> Self {
        Self::new(
            Privileges {
                priority: Some(80),
                cpu: None,
                lock_memory: false,
                hold_cpu_latency: false,
            },
            true,
            RealtimeSpec {
                overrun: Some(OverrunPolicy::CatchUp),
                max_overruns: None,
            },
        )
    }

    /// With the overrun policy and limit of `settings` (a graph's `realtime:`
    /// section, already [overridden](RealtimeSpec::overridden_by) by the command
    /// line's); what it leaves out keeps [`RtConfig::default`]'s value.
    pub fn with_settings(self, settings: RealtimeSpec) -> Self {
        Self {
            overrun: settings.overrun.unwrap_or_default(),
            max_overruns: settings.max_overruns,
            ..self
        }
    }
}

/// Why a run could not start or went wrong at build.
#[derive(Debug, thiserror::Error)]
pub enum RtError {
    /// A privilege was refused and soft running was not allowed.
    #[error(
        "real-time privileges missing:\n{}\n(fix: grant them as said, or pass --allow-soft to run at normal priority, without timing guarantees)",
        .0.iter().map(|m| format!("  - {m}")).collect::<Vec<_>>().join("\n")
    )]
    Privilege(Vec<Missing>),
    /// The CPU to pin to cannot be used.
    #[error(transparent)]
    Cpu(#[from] BadCpu),
    /// A graph block and the device do not match.
    #[error("block `{block}` ({kind}): {problem} (fix: {fix})")]
    Wiring {
        /// Block name.
        block: String,
        /// `hw_input` or `hw_output`.
        kind: &'static str,
        /// What does not match.
        problem: String,
        /// How to fix it.
        fix: String,
    },
    /// The device refused its configuration.
    #[error("device `{device}`: {source}")]
    Device {
        /// Device name.
        device: String,
        /// Its error.
        source: DeviceError,
    },
    /// The graph's rate cannot be run on the wall clock.
    #[error("{0}")]
    Rate(String),
    /// The loop thread could not be started or panicked.
    #[error("loop thread: {0}")]
    Thread(String),
}

/// Why the loop stopped.
#[derive(Debug, Clone, PartialEq)]
pub enum Stop {
    /// Every tick asked for ran.
    Completed,
    /// More overruns than `max_overruns`.
    MaxOverruns,
    /// The device reported an error (watchdog, I/O).
    Device(DeviceError),
    /// [`RealtimeRunner::stop_handle`] was set (Ctrl-C).
    Interrupted,
}

impl std::fmt::Display for Stop {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Self::Completed => write!(f, "completed"),
            Self::MaxOverruns => write!(f, "stopped: too many overruns"),
            Self::Device(e) => write!(f, "stopped by the device: {e}"),
            Self::Interrupted => write!(f, "interrupted"),
        }
    }
}

/// A message from the loop thread (through the ring).
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Event {
    /// Periodic status.
    Status {
        /// Ticks run so far.
        ticks: u64,
        /// Overruns so far.
        overruns: u64,
        /// Largest wake-up latency since the previous status (ns).
        worst_latency_ns: u64,
        /// Largest execution time since the previous status (ns).
        worst_execution_ns: u64,
    },
    /// A live parameter update was applied ([`crate::live`]).
    Param {
        /// The first tick computed with the new value (ticks run before it).
        tick: u64,
        /// Row of the graph's table of live parameters
        /// ([`ParamSender::path`] names it).
        param: u32,
        /// The new value.
        value: f64,
    },
    /// A tick ended after the next deadline.
    Overrun {
        /// Index of the tick (ticks run before it).
        tick: u64,
        /// How far past the next deadline it ended (ns).
        late_ns: u64,
    },
}

/// The loop's histograms (fixed memory, allocated at build).
#[derive(Debug, Clone, Default)]
pub struct Timing {
    /// Actual − planned start of each tick (ns).
    pub wakeup_latency: Histogram,
    /// Time between the starts of consecutive ticks on consecutive slots (ns);
    /// its buckets are 3 % of T wide, so jitter is in `period_jitter`.
    pub period: Histogram,
    /// |period − T| of the same pairs (ns): the jitter, at its own resolution.
    pub period_jitter: Histogram,
    /// Start of the tick to the end of [`Device::write`] (ns).
    pub execution: Histogram,
    /// Time each block (execution order, [`Scheduler::block_names`]) spent in
    /// the ticks it was due, gathering its inputs and computing (ns); empty
    /// unless [`RtConfig::block_timing`].
    pub blocks: Vec<Histogram>,
}

/// One block's execution time in a [`TimingReport`].
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct BlockTime {
    /// The block's name (inserted rate transitions start with `rt:`).
    pub name: String,
    /// Its time per tick it was due (ns): `count` is the number of those ticks.
    #[serde(flatten)]
    pub time: Summary,
}

/// Per-block execution time of the current tick, in memory allocated at build:
/// the [`TickProbe`] of a run with [`RtConfig::block_timing`].
#[derive(Debug)]
struct BlockClock {
    /// When the current phase began (ns).
    start: u64,
    /// Time of each block in this tick so far (ns).
    spent: Box<[u64]>,
    /// Whether each block was due in this tick.
    ran: Box<[bool]>,
}

impl BlockClock {
    fn new(blocks: usize) -> Self {
        Self {
            start: 0,
            spent: vec![0; blocks].into_boxed_slice(),
            ran: vec![false; blocks].into_boxed_slice(),
        }
    }

    /// Record the tick's times into `hist` (one per block) and start afresh.
    #[inline]
    fn flush(&mut self, hist: &mut [Histogram]) {
        for ((spent, ran), h) in self.spent.iter_mut().zip(self.ran.iter_mut()).zip(hist) {
            if *ran {
                h.record(*spent);
                *spent = 0;
                *ran = false;
            }
        }
    }
}

impl TickProbe for BlockClock {
    #[inline]
    fn enter(&mut self, _block: usize) {
        self.start = clock::now_ns();
    }
    #[inline]
    fn leave(&mut self, block: usize) {
        self.spent[block] += clock::now_ns().saturating_sub(self.start);
        self.ran[block] = true;
    }
}

/// What a run measured: printed, and written as `timing.json`.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct TimingReport {
    /// Base rate of the graph (Hz).
    pub rate_hz: f64,
    /// Its period (ns).
    pub period_ns: f64,
    /// Ticks run.
    pub ticks: u64,
    /// Grid slots passed (ticks run + ticks skipped).
    pub slots: u64,
    /// Ticks that ended after the next deadline.
    pub overruns: u64,
    /// Deadlines skipped under the `skip` policy.
    pub missed_ticks: u64,
    /// The overrun policy.
    pub overrun_policy: &'static str,
    /// The overrun limit (`null`: none).
    pub max_overruns: Option<u64>,
    /// Why the loop stopped, in words.
    pub stop: String,
    /// Why the loop stopped (typed; not in the JSON, which has `stop`).
    #[serde(skip)]
    pub stopped: Stop,
    /// Whether the safe state was written without error.
    pub safe_state_ok: bool,
    /// Scheduling of the loop thread as the kernel reported it (`SCHED_FIFO 80`).
    pub scheduling: String,
    /// CPU the loop was pinned to.
    pub cpu: Option<usize>,
    /// Whether `mlockall` succeeded.
    pub memory_locked: bool,
    /// Whether the CPUs were held out of deep idle states for the run
    /// ([`clock::CpuLatencyHold`]).
    pub cpu_latency_held: bool,
    /// Why they were not, when it was asked for and refused (the run goes on:
    /// it only wakes later).
    pub cpu_latency_refused: Option<Missing>,
    /// Privileges refused (the run was soft).
    pub missing_privileges: Vec<Missing>,
    /// Events the ring could not take (dropped, never waited for).
    pub events_dropped: u64,
    /// Live parameter updates applied.
    pub param_updates: u64,
    /// Transport delay the device declares (ticks).
    pub device_latency_ticks: u32,
    /// Grid origin, last deadline and last wake-up on CLOCK_MONOTONIC (ns).
    pub t0_ns: u64,
    /// The deadline of the last tick run (ns).
    pub last_deadline_ns: u64,
    /// When the last tick woke up (ns).
    pub last_wake_ns: u64,
    /// Wake-up latency (ns).
    pub wakeup_latency: Summary,
    /// Period between consecutive ticks (ns; quantiles to 3 %, min/max/mean exact).
    pub period: Summary,
    /// |period − T| (ns).
    pub period_jitter: Summary,
    /// Execution time per tick, device I/O included (ns).
    pub execution: Summary,
    /// Execution time of each block, in execution order (with
    /// [`RtConfig::block_timing`]; otherwise empty and left out of the JSON).
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub blocks: Vec<BlockTime>,
}

/// The hardware samples of a run, tick by tick: what the `hw_input` blocks
/// received and what the `hw_output` blocks sent.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Recording {
    /// Title of the graph.
    pub title: Option<String>,
    /// Base rate of the loop (Hz).
    pub rate_hz: f64,
    /// Input channels recorded (the graph's `hw_input` blocks), in order.
    pub inputs: Vec<crate::Channel>,
    /// Output channels recorded (the `hw_output` blocks), in order.
    pub outputs: Vec<crate::Channel>,
    /// Wake-up time of each tick on CLOCK_MONOTONIC (ns).
    pub t_ns: Vec<u64>,
    /// Input samples, tick-major (`ticks × inputs.len()`).
    pub input_values: Vec<f64>,
    /// Output samples, tick-major (`ticks × outputs.len()`).
    pub output_values: Vec<f64>,
    /// The graph's live parameters (`BLOCK.PARAM`): the table
    /// [`ParamChange::param`] indexes.
    pub params: Vec<String>,
    /// The live parameter updates applied, in the order applied.
    pub param_changes: Vec<ParamChange>,
}

/// A live parameter update as recorded: applied before tick `tick`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ParamChange {
    /// The first tick computed with the new value.
    pub tick: u64,
    /// Row of [`Recording::params`].
    pub param: u32,
    /// The new value.
    pub value: f64,
}

impl Recording {
    /// Ticks recorded.
    pub fn ticks(&self) -> usize {
        self.t_ns.len()
    }
}

/// Counters of one loop (no allocation).
#[derive(Debug, Clone, Default)]
struct Counters {
    ticks: u64,
    slots: u64,
    overruns: u64,
    missed: u64,
    dropped: u64,
    param_updates: u64,
    t0: u64,
    last_deadline: u64,
    last_wake: u64,
}

/// Everything the loop thread touches.
struct LoopCore<D: Device> {
    sched: Scheduler,
    device: D,
    cfg: RtConfig,
    /// (device input channel, `hw_input` signal).
    inputs: Vec<(usize, SignalId)>,
    /// (device output channel, `hw_output` signal), one per device output.
    outputs: Vec<(usize, SignalId)>,
    in_buf: Vec<f64>,
    out_buf: Vec<f64>,
    timing: Timing,
    /// Per-block timing, when asked for.
    block_clock: Option<BlockClock>,
    record: Option<Recording>,
    events: rtrb::Producer<Event>,
    /// Live parameter updates in; (block, slot) of each row of the table.
    params: rtrb::Consumer<ParamUpdate>,
    param_slots: Box<[(usize, usize)]>,
    stop: Arc<AtomicBool>,
}

/// A built graph run on the wall clock against a device.
///
/// ```no_run
/// use nanomotion_core::GraphSpec;
/// use nanomotion_rt::{NoDevice, RealtimeRunner, RtConfig};
/// let (sched, _) = GraphSpec::from_file("examples/quickstart.yaml").unwrap().build().unwrap();
/// let mut runner = RealtimeRunner::new(sched, NoDevice, RtConfig::default()).unwrap();
/// let report = runner.run(|_event| {}).unwrap();
/// println!("p99.9 wake-up latency {:?} ns", report.wakeup_latency.p999_ns);
/// ```
pub struct RealtimeRunner<D: Device> {
    core: LoopCore<D>,
    events: rtrb::Consumer<Event>,
    /// The sending end of the update ring, until [`RealtimeRunner::param_sender`]
    /// takes it.
    params: Option<rtrb::Producer<ParamUpdate>>,
}

impl<D: Device> std::fmt::Debug for RealtimeRunner<D> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("RealtimeRunner")
            .field("device", &self.core.device.name())
            .field("scheduler", &self.core.sched)
            .finish_non_exhaustive()
    }
}

/// A device without channels: the graph runs on the wall clock alone (a
/// simulated loop, e.g. to measure the machine's timing).
#[derive(Debug, Clone, Copy, Default)]
pub struct NoDevice;

impl Device for NoDevice {
    fn name(&self) -> &str {
        "none"
    }
    fn inputs(&self) -> &[crate::Channel] {
        &[]
    }
    fn outputs(&self) -> &[crate::Channel] {
        &[]
    }
    fn read(&mut self, _now_ns: u64, _inputs: &mut [f64]) -> Result<(), DeviceError> {
        Ok(())
    }
    fn write(&mut self, _now_ns: u64, _outputs: &[f64]) -> Result<(), DeviceError> {
        Ok(())
    }
}

/// Blocks as (name, unit).
pub type NamedUnits = Vec<(String, Option<String>)>;

/// The `hw_input` and `hw_output` blocks of a built graph: (name, unit) each,
/// in execution order.
pub fn hw_blocks(sched: &Scheduler) -> (NamedUnits, NamedUnits) {
    let mut ins = Vec::new();
    let mut outs = Vec::new();
    for w in sched.wiring() {
        let unit = w.outputs.first().and_then(|p| p.unit.clone());
        if w.type_name == HW_INPUT {
            ins.push((w.name, unit));
        } else if w.type_name == HW_OUTPUT {
            outs.push((w.name, unit));
        }
    }
    (ins, outs)
}

impl<D: Device> RealtimeRunner<D> {
    /// Connect `device` to the graph's `hw_input`/`hw_output` blocks by name,
    /// check units, configure the device and allocate everything the loop needs.
    pub fn new(sched: Scheduler, mut device: D, mut cfg: RtConfig) -> Result<Self, RtError> {
        let rate = sched.base_rate_hz();
        if !(rate.is_finite() && rate > 0.0 && rate <= 1.0e6) {
            return Err(RtError::Rate(format!(
                "base_rate_hz {rate} cannot run on the wall clock (fix: a rate in (0, 1 MHz])"
            )));
        }
        let (hw_in, hw_out) = hw_blocks(&sched);
        let mut inputs = Vec::new();
        for (name, unit) in &hw_in {
            let j = device.inputs().iter().position(|c| &c.name == name);
            let Some(j) = j else {
                return Err(wiring(
                    name,
                    HW_INPUT,
                    &device,
                    "no device input channel of that name",
                    device.inputs(),
                ));
            };
            check_unit(name, HW_INPUT, unit, &device.inputs()[j].unit)?;
            let id = sched.signal_id(&format!("{name}.y")).ok_or_else(|| {
                RtError::Thread(format!("signal {name}.y of a hw_input block not found"))
            })?;
            inputs.push((j, id));
        }
        let mut outputs = Vec::new();
        for (j, ch) in device.outputs().iter().enumerate() {
            let Some((name, unit)) = hw_out.iter().find(|(n, _)| n == &ch.name) else {
                return Err(RtError::Wiring {
                    block: ch.name.clone(),
                    kind: HW_OUTPUT,
                    problem: format!(
                        "device `{}` has an output channel `{}` that no hw_output block drives",
                        device.name(),
                        ch.name
                    ),
                    fix: format!(
                        "add `- {{ name: {}, type: hw_output }}` and connect the signal to drive it",
                        ch.name
                    ),
                });
            };
            check_unit(name, HW_OUTPUT, unit, &ch.unit)?;
            let id = sched.signal_id(&format!("{name}.y")).ok_or_else(|| {
                RtError::Thread(format!("signal {name}.y of a hw_output block not found"))
            })?;
            outputs.push((j, id));
        }
        for (name, _) in &hw_out {
            if !device.outputs().iter().any(|c| &c.name == name) {
                return Err(wiring(
                    name,
                    HW_OUTPUT,
                    &device,
                    "no device output channel of that name",
                    device.outputs(),
                ));
            }
        }
        device.configure(rate).map_err(|source| RtError::Device {
            device: device.name().to_string(),
            source,
        })?;
        if cfg.status_every == 0 {
            cfg.status_every = ((rate / 10.0).round() as u64).max(1);
        }
        let (producer, consumer) = rtrb::RingBuffer::new(cfg.ring_slots.max(1));
        let (param_in, param_out) = rtrb::RingBuffer::new(cfg.param_slots.max(1));
        let table = live_params(&sched);
        let in_buf = vec![0.0; device.inputs().len()];
        let out_buf = vec![0.0; device.outputs().len()];
        let record = cfg.record.then(|| {
            let n = cfg
                .ticks
                .unwrap_or(u64::MAX)
                .min(sched.ticks_total().saturating_sub(sched.ticks_done()))
                as usize;
            Recording {
                title: sched.result().title,
                rate_hz: rate,
                inputs: inputs
                    .iter()
                    .map(|&(j, _)| device.inputs()[j].clone())
                    .collect(),
                outputs: device.outputs().to_vec(),
                t_ns: Vec::with_capacity(n),
                input_values: Vec::with_capacity(n * inputs.len()),
                output_values: Vec::with_capacity(n * outputs.len()),
                params: table.iter().map(|p| p.path.clone()).collect(),
                param_changes: Vec::with_capacity(cfg.max_param_updates),
            }
        });
        let n_blocks = sched.block_names().len();
        let (block_clock, block_hists) = if cfg.block_timing {
            let hists = (0..n_blocks).map(|_| Histogram::new()).collect();
            (Some(BlockClock::new(n_blocks)), hists)
        } else {
            (None, Vec::new())
        };
        Ok(Self {
            core: LoopCore {
                sched,
                device,
                cfg,
                inputs,
                outputs,
                in_buf,
                out_buf,
                timing: Timing {
                    blocks: block_hists,
                    ..Timing::default()
                },
                block_clock,
                record,
                events: producer,
                params: param_out,
                param_slots: table.iter().map(|p| (p.block, p.slot)).collect(),
                stop: Arc::new(AtomicBool::new(false)),
            },
            events: consumer,
            params: Some(param_in),
        })
    }

    /// The sender of live parameter updates into the loop ([`crate::live`]),
    /// once: take it before [`RealtimeRunner::run`] (it may be moved to
    /// another thread). Updates sent before the run take effect at tick 0.
    pub fn param_sender(&mut self) -> Result<ParamSender, RtError> {
        let ring = self.params.take().ok_or_else(|| {
            RtError::Thread(
                "the parameter sender was already taken (fix: keep the one `param_sender()` returned; clone nothing, one sender per runner)".into(),
            )
        })?;
        Ok(ParamSender::new(
            &self.core.sched,
            ring,
            self.core.cfg.max_param_updates,
        ))
    }

    /// The graph's live parameters: row `i` is what [`Event::Param`]'s
    /// `param: i` means.
    pub fn live_params(&self) -> Vec<LiveParam> {
        live_params(&self.core.sched)
    }

    /// A flag that stops the loop at the next tick boundary (outputs safe).
    pub fn stop_handle(&self) -> Arc<AtomicBool> {
        Arc::clone(&self.core.stop)
    }

    /// Run on a new loop thread; the calling thread hands every event to
    /// `on_event` (a non-real-time consumer: printing, logging) until the loop
    /// ends. Returns the timing report; the graph's logs stay in
    /// [`RealtimeRunner::scheduler`].
    pub fn run(&mut self, mut on_event: impl FnMut(Event)) -> Result<TimingReport, RtError> {
        let core = &mut self.core;
        let events = &mut self.events;
        // The loop thread wakes this one when it ends, so that the caller
        // learns of the end (and can let the device go) at once, not at the
        // next 20 ms poll.
        let waiter = std::thread::current();
        let done = AtomicBool::new(false);
        std::thread::scope(|s| {
            let handle = std::thread::Builder::new()
                .name("nanomotion-rt".into())
                .stack_size(8 << 20)
                .spawn_scoped(s, || {
                    let r = core.run_loop();
                    done.store(true, Ordering::Release);
                    waiter.unpark();
                    r
                })
                .map_err(|e| RtError::Thread(e.to_string()))?;
            while !done.load(Ordering::Acquire) && !handle.is_finished() {
                while let Ok(e) = events.pop() {
                    on_event(e);
                }
                std::thread::park_timeout(std::time::Duration::from_millis(20));
            }
            let r = handle
                .join()
                .map_err(|_| RtError::Thread("the loop thread panicked".into()))?;
            while let Ok(e) = events.pop() {
                on_event(e);
            }
            r
        })
    }

    /// Run the loop on the calling thread (which then gets the scheduling class
    /// and affinity asked for); events stay in the ring for
    /// [`RealtimeRunner::drain_events`].
    pub fn run_here(&mut self) -> Result<TimingReport, RtError> {
        self.core.run_loop()
    }

    /// Events waiting in the ring.
    pub fn drain_events(&mut self, mut on_event: impl FnMut(Event)) {
        while let Ok(e) = self.events.pop() {
            on_event(e);
        }
    }

    /// The graph (its logs hold the run).
    pub fn scheduler(&self) -> &Scheduler {
        &self.core.sched
    }

    /// The device.
    pub fn device(&self) -> &D {
        &self.core.device
    }

    /// The histograms of the last run.
    pub fn timing(&self) -> &Timing {
        &self.core.timing
    }

    /// The hardware samples of the last run, if recording was asked for.
    pub fn recording(&self) -> Option<&Recording> {
        self.core.record.as_ref()
    }

    /// The hardware samples of the last run, taken out of the runner (to
    /// write them after the device is let go); a further run records nothing.
    pub fn take_recording(&mut self) -> Option<Recording> {
        self.core.record.take()
    }

    /// The graph and the device back.
    pub fn into_parts(self) -> (Scheduler, D) {
        (self.core.sched, self.core.device)
    }
}

fn wiring<D: Device>(
    name: &str,
    kind: &'static str,
    device: &D,
    problem: &str,
    channels: &[crate::Channel],
) -> RtError {
    let list: Vec<&str> = channels.iter().map(|c| c.name.as_str()).collect();
    RtError::Wiring {
        block: name.into(),
        kind,
        problem: format!("{problem} on device `{}`", device.name()),
        fix: if list.is_empty() {
            format!(
                "device `{}` has no such channels; remove the block or use another device",
                device.name()
            )
        } else {
            format!(
                "name the block after one of the device's channels: {}",
                list.join(", ")
            )
        },
    }
}

fn check_unit(
    name: &str,
    kind: &'static str,
    block: &Option<String>,
    device: &Option<String>,
) -> Result<(), RtError> {
    match (block, device) {
        (Some(b), Some(d)) if b != d => Err(RtError::Wiring {
            block: name.into(),
            kind,
            problem: format!("unit `{b}` but the device channel is in `{d}`"),
            fix: format!("set `unit: {d}` on the block, or scale the signal before/after it"),
        }),
        _ => Ok(()),
    }
}

impl<D: Device> LoopCore<D> {
    /// Planned start of grid slot `slot` (ns): computed from the origin every
    /// time, so rounding never accumulates.
    #[inline]
    fn deadline(t0: u64, period_ns: f64, slot: u64) -> u64 {
        t0 + (slot as f64 * period_ns).round() as u64
    }

    /// Apply one live parameter update before tick `c.ticks`: the block's
    /// own in-place setter (no allocation), then the record and the event.
    #[inline]
    fn apply(&mut self, c: &mut Counters, u: ParamUpdate) {
        let Some(&(block, slot)) = self.param_slots.get(u.param as usize) else {
            return;
        };
        if let Some(b) = self.sched.block_at_mut(block) {
            b.set_live_param(slot, u.value);
        }
        c.param_updates += 1;
        // Within the capacity reserved at build (the sender's limit).
        if let Some(r) = &mut self.record
            && r.param_changes.len() < r.param_changes.capacity()
        {
            r.param_changes.push(ParamChange {
                tick: c.ticks,
                param: u.param,
                value: u.value,
            });
        }
        let e = Event::Param {
            tick: c.ticks,
            param: u.param,
            value: u.value,
        };
        self.push(c, e);
    }

    #[inline]
    fn push(&mut self, c: &mut Counters, e: Event) {
        if self.events.push(e).is_err() {
            c.dropped += 1;
        }
    }

    /// The loop itself. Allocation-free from the first tick to the safe state
    /// (a refused privilege or a device error allocates its message).
    fn run_loop(&mut self) -> Result<TimingReport, RtError> {
        let missing = clock::acquire(&self.cfg.privileges)?;
        if !missing.is_empty() && !self.cfg.allow_soft {
            return Err(RtError::Privilege(missing));
        }
        let memory_locked = self.cfg.privileges.lock_memory
            && !missing.iter().any(|m| m.what.starts_with("mlockall"));
        // Held until this function returns, whichever way it does.
        let cpu_latency = self
            .cfg
            .privileges
            .hold_cpu_latency
            .then(clock::CpuLatencyHold::new);
        // Normal-priority threads sleep up to 50 µs past a deadline (timer
        // slack); SCHED_FIFO ones have none. Ask for 1 ns either way, so a soft
        // run is as punctual as the scheduler lets it be.
        // SAFETY: prctl with an integer argument, on the calling thread.
        unsafe { libc::prctl(libc::PR_SET_TIMERSLACK, 1 as libc::c_ulong) };
        clock::prefault_stack(256 * 1024);
        self.timing.wakeup_latency.clear();
        self.timing.period.clear();
        self.timing.period_jitter.clear();
        self.timing.execution.clear();
        self.timing.blocks.iter_mut().for_each(Histogram::clear);
        self.stop.store(false, Ordering::Relaxed);
        if let Some(r) = &mut self.record {
            r.t_ns.clear();
            r.input_values.clear();
            r.output_values.clear();
            r.param_changes.clear();
        }
        let period_ns = 1.0e9 / self.sched.base_rate_hz();
        let n = self.cfg.ticks.unwrap_or_else(|| {
            self.sched
                .ticks_total()
                .saturating_sub(self.sched.ticks_done())
        });
        let mut c = Counters {
            // Start one period (at least 1 ms) from now: the first sleep is a real one.
            t0: clock::now_ns() + (period_ns as u64).max(1_000_000),
            ..Counters::default()
        };
        let mut slot = 0u64;
        let mut prev: Option<(u64, u64)> = None; // (slot, wake)
        let (mut worst_lat, mut worst_exec) = (0u64, 0u64);
        let stop = loop {
            if c.ticks >= n {
                break Stop::Completed;
            }
            if self.stop.load(Ordering::Relaxed) {
                break Stop::Interrupted;
            }
            // Live parameter updates, at the boundary before this tick.
            while let Ok(u) = self.params.pop() {
                self.apply(&mut c, u);
            }
            let deadline = Self::deadline(c.t0, period_ns, slot);
            clock::sleep_until(deadline, self.cfg.spin_ns);
            let wake = clock::now_ns();
            let latency = wake.saturating_sub(deadline);
            self.timing.wakeup_latency.record(latency);
            if let Some((ps, pw)) = prev
                && ps + 1 == slot
            {
                let p = wake - pw;
                self.timing.period.record(p);
                self.timing
                    .period_jitter
                    .record((p as f64 - period_ns).abs().round() as u64);
            }
            prev = Some((slot, wake));
            c.last_deadline = deadline;
            c.last_wake = wake;
            if let Err(e) = self.device.read(wake, &mut self.in_buf) {
                break Stop::Device(e);
            }
            for &(j, id) in &self.inputs {
                self.sched.write(id, &self.in_buf[j..j + 1]);
            }
            match &mut self.block_clock {
                None => self.sched.tick(),
                Some(probe) => {
                    self.sched.tick_probed(probe);
                    probe.flush(&mut self.timing.blocks);
                }
            }
            for &(j, id) in &self.outputs {
                self.out_buf[j] = self.sched.read(id)[0];
            }
            // Within the capacity reserved at build: no allocation.
            if let Some(r) = &mut self.record
                && r.t_ns.len() < r.t_ns.capacity()
            {
                r.t_ns.push(wake);
                r.input_values
                    .extend(self.inputs.iter().map(|&(j, _)| self.in_buf[j]));
                r.output_values.extend_from_slice(&self.out_buf);
            }
            if let Err(e) = self.device.write(clock::now_ns(), &self.out_buf) {
                break Stop::Device(e);
            }
            let end = clock::now_ns();
            let exec = end - wake;
            self.timing.execution.record(exec);
            c.ticks += 1;
            worst_lat = worst_lat.max(latency);
            worst_exec = worst_exec.max(exec);
            let next = Self::deadline(c.t0, period_ns, slot + 1);
            if end > next {
                c.overruns += 1;
                let e = Event::Overrun {
                    tick: c.ticks - 1,
                    late_ns: end - next,
                };
                self.push(&mut c, e);
                slot = match self.cfg.overrun {
                    OverrunPolicy::CatchUp => slot + 1,
                    OverrunPolicy::Skip => {
                        // The first slot whose deadline is still ahead.
                        let mut s = ((end - c.t0) as f64 / period_ns).floor() as u64 + 1;
                        while Self::deadline(c.t0, period_ns, s) <= end {
                            s += 1;
                        }
                        c.missed += s - (slot + 1);
                        s
                    }
                };
                if self.cfg.max_overruns.is_some_and(|m| c.overruns > m) {
                    break Stop::MaxOverruns;
                }
            } else {
                slot += 1;
            }
            if c.ticks.is_multiple_of(self.cfg.status_every) {
                let e = Event::Status {
                    ticks: c.ticks,
                    overruns: c.overruns,
                    worst_latency_ns: worst_lat,
                    worst_execution_ns: worst_exec,
                };
                self.push(&mut c, e);
                worst_lat = 0;
                worst_exec = 0;
            }
        };
        c.slots = slot;
        let safe_state_ok = self.device.safe_state().is_ok();
        let (policy, prio) = clock::current_policy();
        Ok(TimingReport {
            rate_hz: self.sched.base_rate_hz(),
            period_ns,
            ticks: c.ticks,
            slots: c.slots,
            overruns: c.overruns,
            missed_ticks: c.missed,
            overrun_policy: self.cfg.overrun.as_str(),
            max_overruns: self.cfg.max_overruns,
            stop: stop.to_string(),
            safe_state_ok,
            scheduling: match policy {
                libc::SCHED_FIFO => format!("SCHED_FIFO {prio}"),
                libc::SCHED_RR => format!("SCHED_RR {prio}"),
                _ => "SCHED_OTHER (normal priority)".to_string(),
            },
            cpu: self.cfg.privileges.cpu,
            memory_locked,
            cpu_latency_held: matches!(cpu_latency, Some(Ok(_))),
            cpu_latency_refused: cpu_latency.and_then(Result::err),
            missing_privileges: missing,
            events_dropped: c.dropped,
            param_updates: c.param_updates,
            device_latency_ticks: self.device.latency_ticks(),
            t0_ns: c.t0,
            last_deadline_ns: c.last_deadline,
            last_wake_ns: c.last_wake,
            wakeup_latency: self.timing.wakeup_latency.summary(),
            period: self.timing.period.summary(),
            period_jitter: self.timing.period_jitter.summary(),
            execution: self.timing.execution.summary(),
            blocks: self
                .sched
                .block_names()
                .iter()
                .zip(&self.timing.blocks)
                .map(|(name, h)| BlockTime {
                    name: name.clone(),
                    time: h.summary(),
                })
                .collect(),
            stopped: stop,
        })
    }
}

#[cfg(test)]
mod config_tests {
    use super::*;

    /// The one constructor: privileges, soft running and the graph's settings
    /// set, everything else the default.
    #[test]
    fn new_sets_the_asked_and_keeps_the_rest() {
        let privileges = Privileges {
            priority: Some(42),
            cpu: Some(1),
            lock_memory: true,
            hold_cpu_latency: false,
        };
        let c = RtConfig::new(
            privileges,
            true,
            RealtimeSpec {
                overrun: Some(OverrunPolicy::CatchUp),
                max_overruns: Some(7),
            },
        );
        let want = RtConfig {
            privileges,
            allow_soft: true,
            overrun: OverrunPolicy::CatchUp,
            max_overruns: Some(7),
            ..RtConfig::default()
        };
        assert_eq!(c, want);
        // settings left out: skip, no limit (the defaults)
        let c = RtConfig::new(privileges, false, RealtimeSpec::default());
        assert_eq!((c.overrun, c.max_overruns), (OverrunPolicy::Skip, None));
    }

    /// `soft_catch_up` is the configuration the tests wrote out by hand before.
    #[test]
    fn soft_catch_up_is_fifo_80_soft_unlocked_catching_up() {
        let want = RtConfig {
            privileges: Privileges {
                priority: Some(80),
                cpu: None,
                lock_memory: false,
                hold_cpu_latency: false,
            },
            allow_soft: true,
            overrun: OverrunPolicy::CatchUp,
            ..RtConfig::default()
        };
        assert_eq!(RtConfig::soft_catch_up(), want);
    }
}
