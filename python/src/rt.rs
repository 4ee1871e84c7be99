//! `nanomotion rt` from Python: a graph on the wall clock, judged by the
//! stability gate first, alone (the loop closes inside the graph) or against a
//! device (`device="shm:NAME"`: a plant served by `nanomotion plant --serve
//! NAME`), in the background with live parameter updates (`RtRun::set`,
//! the library's `ParamSender`: the same resolution, judgement and refusal
//! texts as `set BLOCK.PARAM=VALUE` on the CLI's standard input), ending with
//! the run's logs and the timing report of `timing.json`.

use crate::errors::{gate_err, graph_err};
use crate::graph::{Finished, finished_to_py, gate_before_run, load_spec};
use nanomotion::core::Scheduler;
use nanomotion::core::gate::FrontEnd;
use nanomotion::core::graph::{OverrunPolicy, RealtimeSpec};
use nanomotion::rt::clock::Privileges;
use nanomotion::rt::through::{ThroughError, before_run_through};
use nanomotion::rt::{
    ConnectError, Device, Event, LiveError, NoDevice, ParamSender, RealtimeRunner, RtConfig,
    RtError, ShmDevice, TimingReport,
};
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyList, PyString};
use std::path::PathBuf;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex, MutexGuard};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

/// What the loop reported so far, kept by the thread that reads its events
/// (never the loop thread itself).
#[derive(Debug, Default)]
struct Progress {
    ticks: u64,
    overruns: u64,
    worst_latency_ns: u64,
    worst_execution_ns: u64,
    /// (first tick computed with it, row of the live parameter, value).
    updates: Vec<(u64, u32, f64)>,
    /// The loop has ended (or never started).
    ended: bool,
}

impl Progress {
    fn on(&mut self, e: Event) {
        match e {
            Event::Status {
                ticks,
                overruns,
                worst_latency_ns,
                worst_execution_ns,
            } => {
                self.ticks = ticks;
                self.overruns = overruns;
                self.worst_latency_ns = self.worst_latency_ns.max(worst_latency_ns);
                self.worst_execution_ns = self.worst_execution_ns.max(worst_execution_ns);
            }
            Event::Param { tick, param, value } => self.updates.push((tick, param, value)),
            Event::Overrun { .. } => {}
        }
    }
}

/// A finished loop: the timing report, the graph (its logs) and the wall time.
struct Outcome {
    report: TimingReport,
    sched: Scheduler,
    wall_s: f64,
}

/// The run's dict and the timing report as JSON.
type RunAndTiming = (Py<PyDict>, String);

/// The lock's content, also after a panic elsewhere (nothing here leaves a
/// value half-written).
fn lock<T>(m: &Mutex<T>) -> MutexGuard<'_, T> {
    m.lock().unwrap_or_else(|e| e.into_inner())
}

/// A loop running in the background (`nanomotion.rt_start`): change live
/// parameters with `RtRun::set`, watch it with `RtRun::status`, end it
/// with `RtRun::stop` or `RtRun::wait`.
#[pyclass(module = "nanomotion._nanomotion")]
pub struct RtRun {
    rate_hz: f64,
    device: String,
    /// `BLOCK.PARAM` of each row of the graph's table of live parameters.
    params: Vec<String>,
    gate_lines: Vec<String>,
    stop: Arc<AtomicBool>,
    progress: Arc<Mutex<Progress>>,
    sender: Mutex<ParamSender>,
    thread: Mutex<Option<JoinHandle<Result<Outcome, RtError>>>>,
    /// What `wait`/`stop` returned, for the next call.
    result: Mutex<Option<PyResult<RunAndTiming>>>,
}

impl Drop for RtRun {
    /// A handle dropped while its loop runs stops the loop (outputs safe)
    /// and waits for it: no loop outlives its handle.
    fn drop(&mut self) {
        if let Some(h) = lock(&self.thread).take() {
            self.stop.store(true, Ordering::Relaxed);
            let _ = h.join();
        }
    }
}

/// Run `runner` on threads of its own: the loop thread and one that hands its
/// events to `progress`.
fn launch<D: Device + 'static>(
    mut runner: RealtimeRunner<D>,
    progress: Arc<Mutex<Progress>>,
) -> PyResult<JoinHandle<Result<Outcome, RtError>>> {
    std::thread::Builder::new()
        .name("nanomotion-rt-events".into())
        .spawn(move || {
            let start = Instant::now();
            let report = runner.run(|e| lock(&progress).on(e));
            let wall_s = start.elapsed().as_secs_f64();
            lock(&progress).ended = true;
            let (sched, device) = runner.into_parts();
            // Let the device go at once: the plant sees the end now.
            drop(device);
            Ok(Outcome {
                report: report?,
                sched,
                wall_s,
            })
        })
        .map_err(|e| graph_err(format!("the loop's thread could not start: {e}")))
}

/// Start a graph on the wall clock as `nanomotion rt GRAPH [--device
/// shm:NAME]` does (without files), in the background: built, judged by the
/// stability gate (refused unless `allow_unproven`), connected to `device`
/// (`"shm:NAME"`, waiting up to `connect_timeout` s for the plant; stopped by
/// a watchdog after `watchdog_ms` of silence; the loop through it judged by
/// the gate with the plant's graph and the device's latency), then ticked at
/// its base rate by
/// a SCHED_FIFO thread (`priority`, pinned to `cpu`; `allow_soft`: at normal
/// priority where that is refused), the CPUs held out of deep idle states
/// unless `allow_idle_states`, late ticks skipped or caught up (`overrun`,
/// default the graph's `realtime:`), stopped after `max_overruns`. Live
/// parameter updates are judged by the block's validation and the stability
/// gate on a second build of the graph, as the CLI's are.
#[pyfunction]
#[pyo3(signature = (path=None, text=None, origin="<string>", overrides=Vec::new(), duration=None, allow_unproven=false, allow_soft=false, priority=80, cpu=None, overrun=None, max_overruns=None, allow_idle_states=false, device=None, connect_timeout=10.0, watchdog_ms=50.0))]
#[allow(clippy::too_many_arguments)]
fn rt_start(
    py: Python<'_>,
    path: Option<PathBuf>,
    text: Option<&str>,
    origin: &str,
    overrides: Vec<(String, String)>,
    duration: Option<f64>,
    allow_unproven: bool,
    allow_soft: bool,
    priority: u8,
    cpu: Option<usize>,
    overrun: Option<&str>,
    max_overruns: Option<u64>,
    allow_idle_states: bool,
    device: Option<&str>,
    connect_timeout: f64,
    watchdog_ms: f64,
) -> PyResult<RtRun> {
    if !(1..=99).contains(&priority) {
        return Err(graph_err(format!(
            "priority={priority}: SCHED_FIFO priorities are 1–99 (fix: e.g. priority=80)"
        )));
    }
    let overrun = overrun
        .map(|o| {
            serde_json::from_value::<OverrunPolicy>(serde_json::Value::String(o.into())).map_err(
                |_| {
                    graph_err(format!(
                        "overrun={o:?}: not a policy (fix: \"skip\" or \"catch-up\")"
                    ))
                },
            )
        })
        .transpose()?;
    let load = || {
        load_spec(path.clone(), text, origin, &overrides).map(|mut spec| {
            if let Some(d) = duration {
                spec.duration_s = d;
            }
            spec
        })
    };
    let spec = load()?;
    let require = spec.require.clone();
    let settings = spec.realtime.unwrap_or_default();
    let (sched, _) = spec.build().map_err(graph_err)?;
    let mut gate_lines = gate_before_run(
        &crate::graph::analyse(&sched, require.as_ref()),
        allow_unproven,
    )?;
    let cfg = RtConfig::new(
        Privileges {
            priority: Some(priority),
            cpu,
            lock_memory: true,
            hold_cpu_latency: !allow_idle_states,
        },
        allow_soft,
        settings.overridden_by(RealtimeSpec {
            overrun,
            max_overruns,
        }),
    );
    let rate_hz = sched.base_rate_hz();
    let progress = Arc::new(Mutex::new(Progress::default()));
    // The runner, the sender of its live updates judged by the gate on a
    // second build (joined with the device's plant when it has one), the
    // loop's thread.
    macro_rules! start {
        ($dev:expr) => {{
            let mut runner = RealtimeRunner::new(sched, $dev, cfg).map_err(graph_err)?;
            let sender = runner
                .param_sender()
                .map_err(graph_err)?
                .gated_through(load()?, runner.device())
                .map_err(graph_err)?;
            let stop = runner.stop_handle();
            let name = runner.device().name().to_string();
            let thread = launch(runner, Arc::clone(&progress))?;
            (sender, stop, name, thread)
        }};
    }
    let (sender, stop, device, thread) = match device {
        None => start!(NoDevice),
        Some(d) => {
            let dev = py
                .detach(|| ShmDevice::connect_named(d, connect_timeout, watchdog_ms))
                .map_err(|e| match e {
                    ConnectError::ConnectTimeout(_) => graph_err(format!("connect_timeout: {e}")),
                    ConnectError::Watchdog(_) => graph_err(format!("watchdog_ms: {e}")),
                    _ => graph_err(e),
                })?;
            // The loop closes through the device: the gate judges it with the
            // plant's graph and the device's latency, before it runs.
            let through = before_run_through(load()?, &dev, allow_unproven, &FrontEnd::PYTHON)
                .map_err(|e| match e {
                    ThroughError::Refused(_) => gate_err(e),
                    _ => graph_err(format!("device `{}`: {e}", dev.name())),
                })?;
            gate_lines.extend(through);
            start!(dev)
        }
    };
    Ok(RtRun {
        rate_hz,
        device,
        params: sender.params().iter().map(|p| p.path.clone()).collect(),
        gate_lines,
        stop,
        progress,
        sender: Mutex::new(sender),
        thread: Mutex::new(Some(thread)),
        result: Mutex::new(None),
    })
}

/// A refused update as a Python exception: the gate's refusal is a
/// `GateError`, every other one a `GraphError`; the text is the library's.
fn live_err(e: LiveError) -> PyErr {
    match e {
        LiveError::Gate { .. } => gate_err(e),
        _ => graph_err(e),
    }
}

impl RtRun {
    /// Wait for the loop's end (stopping it first if `stop`), then the run's
    /// dict and the timing report as JSON; the same on every later call.
    fn finish<'py>(&self, py: Python<'py>, stop: bool) -> PyResult<(Bound<'py, PyDict>, String)> {
        let handle = lock(&self.thread).take();
        if let Some(handle) = handle {
            let mut interrupted = None;
            while !handle.is_finished() {
                if stop {
                    // Again on every turn: a loop that had not begun yet
                    // clears the flag when it does.
                    self.stop.store(true, Ordering::Relaxed);
                }
                py.detach(|| std::thread::sleep(Duration::from_millis(5)));
                if let Err(e) = py.check_signals() {
                    // Ctrl-C: stop the loop (outputs safe) and keep its run.
                    self.stop.store(true, Ordering::Relaxed);
                    interrupted = Some(e);
                }
            }
            let joined = py.detach(|| handle.join());
            let result = match joined {
                Err(_) => Err(graph_err("the loop's thread panicked")),
                Ok(Err(e)) => Err(graph_err(e)),
                Ok(Ok(o)) => self.to_py(py, o),
            };
            *lock(&self.result) = Some(result);
            if let Some(e) = interrupted {
                return Err(e);
            }
        }
        match lock(&self.result).as_ref() {
            Some(Ok((run, timing))) => Ok((run.bind(py).clone(), timing.clone())),
            Some(Err(e)) => Err(e.clone_ref(py)),
            None => Err(graph_err(
                "the run is being waited for on another thread (fix: wait on one thread)",
            )),
        }
    }

    fn to_py(&self, py: Python<'_>, o: Outcome) -> PyResult<RunAndTiming> {
        let timing = serde_json::to_string(&o.report).map_err(graph_err)?;
        let run = finished_to_py(
            py,
            Finished {
                result: o.sched.result(),
                comparisons: Vec::new(),
                gate_lines: self.gate_lines.clone(),
                wall_s: o.wall_s,
            },
        )?;
        Ok((run.unbind(), timing))
    }
}

#[pymethods]
impl RtRun {
    /// Set live parameter `path` (`"pi.kp"` or `"blocks.pi.kp"`) to `value`
    /// (a number, or the text of one as in `set pi.kp=4e7`) at the loop's next
    /// tick boundary. Judged before it is sent, as the CLI's `set` lines are:
    /// a path that names no live parameter, a value the block refuses
    /// (`GraphError`) or one that makes a passing loop fail the stability gate
    /// (`GateError`) raises, naming the parameter and the fix, and never
    /// reaches the loop. `status()["updates"]` gives the tick it took effect at.
    fn set(&self, py: Python<'_>, path: &str, value: &Bound<'_, PyAny>) -> PyResult<()> {
        // A number is sent as it is; anything else as the text of a `set`
        // line, which the library reads (and refuses when it is not a number).
        let number = if value.is_instance_of::<pyo3::types::PyBool>() {
            None
        } else {
            value.extract::<f64>().ok()
        };
        let line = match number {
            Some(_) => String::new(),
            None if value.is_instance_of::<PyString>() => format!("{path}={value}"),
            None => format!("{path}={}", value.repr()?),
        };
        let sender = &self.sender;
        py.detach(|| {
            let mut s = lock(sender);
            match number {
                Some(v) => s.set(path, v),
                None => s.set_text(&line).map(|_| ()),
            }
        })
        .map_err(live_err)
    }

    /// The graph's live parameters (`BLOCK.PARAM`).
    #[getter]
    fn live_params(&self) -> Vec<String> {
        self.params.clone()
    }

    /// The device's name (`none`, `shm:NAME`).
    #[getter]
    fn device(&self) -> String {
        self.device.clone()
    }

    /// Whether the loop still runs.
    #[getter]
    fn running(&self) -> bool {
        !lock(&self.progress).ended
    }

    /// The loop so far: `running`, `ticks` and `t_s` (at the last status,
    /// every 0.1 s of ticks), `overruns`, the worst wake-up latency and
    /// execution time so far (ns), and `updates`: every live update applied,
    /// as `{path, value, tick, t_s}` (`tick`: the first tick computed with
    /// the value).
    fn status<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        let p = lock(&self.progress);
        let running = !p.ended;
        let d = PyDict::new(py);
        d.set_item("running", running)?;
        d.set_item("device", &self.device)?;
        d.set_item("ticks", p.ticks)?;
        d.set_item("t_s", p.ticks as f64 / self.rate_hz)?;
        d.set_item("overruns", p.overruns)?;
        d.set_item("worst_wakeup_latency_ns", p.worst_latency_ns)?;
        d.set_item("worst_execution_ns", p.worst_execution_ns)?;
        let updates = PyList::empty(py);
        for &(tick, param, value) in &p.updates {
            let u = PyDict::new(py);
            u.set_item(
                "path",
                self.params.get(param as usize).map_or("?", String::as_str),
            )?;
            u.set_item("value", value)?;
            u.set_item("tick", tick)?;
            u.set_item("t_s", tick as f64 / self.rate_hz)?;
            updates.append(u)?;
        }
        d.set_item("updates", updates)?;
        Ok(d)
    }

    /// Wait until the loop has run its ticks (releasing the GIL; Ctrl-C stops
    /// it, outputs safe). Returns the run's dict and the timing report as
    /// JSON (`timing.json`'s text); the same on every later call.
    fn wait<'py>(&self, py: Python<'py>) -> PyResult<(Bound<'py, PyDict>, String)> {
        self.finish(py, false)
    }

    /// Stop the loop at its next tick boundary (the device's outputs put in
    /// their safe state), then as `RtRun::wait`.
    fn stop<'py>(&self, py: Python<'py>) -> PyResult<(Bound<'py, PyDict>, String)> {
        self.finish(py, true)
    }
}

pub(crate) fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_class::<RtRun>()?;
    m.add_function(wrap_pyfunction!(rt_start, m)?)?;
    Ok(())
}
