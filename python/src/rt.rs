//! `nanomotion rt` from Python: a graph on the wall clock (no device: the loop
//! closes inside the graph), judged by the stability gate first, with the
//! timing report of `timing.json`. Live parameter updates and devices are the
//! command line's and Rust's for now (docs/realtime.md).

use crate::errors::graph_err;
use crate::graph::{Finished, finished_to_py, gate_before_run, load_spec};
use nanomotion::core::graph::{OverrunPolicy, RealtimeSpec};
use nanomotion::rt::clock::Privileges;
use nanomotion::rt::{NoDevice, RealtimeRunner, RtConfig};
use pyo3::prelude::*;
use pyo3::types::PyDict;
use std::path::PathBuf;

/// Run a graph on the wall clock as `nanomotion rt GRAPH` does (without
/// files): built, judged by the stability gate (refused unless
/// `allow_unproven`), then ticked at its base rate by a SCHED_FIFO thread
/// (`priority`, pinned to `cpu`; `allow_soft`: at normal priority where that
/// is refused), the CPUs held out of deep idle states unless
/// `allow_idle_states`, late ticks skipped or caught up (`overrun`, default
/// the graph's `realtime:`), stopped after `max_overruns`. Releases the GIL
/// while the loop runs. Returns the run's dict (as `run_graph`) and the timing
/// report as JSON (`timing.json`'s text).
#[pyfunction]
#[pyo3(signature = (path=None, text=None, origin="<string>", overrides=Vec::new(), duration=None, allow_unproven=false, allow_soft=false, priority=80, cpu=None, overrun=None, max_overruns=None, allow_idle_states=false))]
#[allow(clippy::too_many_arguments)]
fn rt_graph<'py>(
    py: Python<'py>,
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
) -> PyResult<(Bound<'py, PyDict>, String)> {
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
    let mut spec = load_spec(path, text, origin, &overrides)?;
    if let Some(d) = duration {
        spec.duration_s = d;
    }
    let require = spec.require.clone();
    let settings = spec.realtime.unwrap_or_default();
    let (sched, _) = spec.build().map_err(graph_err)?;
    let gate_lines = gate_before_run(
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
    let mut runner = RealtimeRunner::new(sched, NoDevice, cfg).map_err(graph_err)?;
    let start = std::time::Instant::now();
    let report = py.detach(|| runner.run(|_| {})).map_err(graph_err)?;
    let wall_s = start.elapsed().as_secs_f64();
    let (sched, _) = runner.into_parts();
    let timing = serde_json::to_string(&report).map_err(graph_err)?;
    let run = finished_to_py(
        py,
        Finished {
            result: sched.result(),
            comparisons: Vec::new(),
            gate_lines,
            wall_s,
        },
    )?;
    Ok((run, timing))
}

pub(crate) fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_function(wrap_pyfunction!(rt_graph, m)?)?;
    Ok(())
}
