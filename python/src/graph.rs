//! Graphs from Python: load, check (the stability gate), run, diagnose.
//!
//! Every function takes the graph either as a file path (relative parameter
//! files then resolve against the graph's folder, as for the CLI) or as YAML
//! text with an origin name for messages. Runs keep whole logs (numpy arrays);
//! they follow `nanomotion run` step by step: seed, data (duration from the
//! data unless given), build, stability gate, run, non-finite check,
//! comparisons with the data.

use crate::errors::{data_err, diagnose_err, gate_err, graph_err};
use nanomotion::core::data::Dataset;
use nanomotion::core::gate::{self, FrontEnd, GateReport, Require};
use nanomotion::core::graph::GraphSpec;
use nanomotion::core::overrides::Override;
use numpy::ndarray::Array2;
use numpy::{PyArray1, PyArray2};
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyList};
use std::path::PathBuf;
use std::sync::Arc;

/// The graph from a file or from text, with dotted-path overrides applied
/// (`(path, value as YAML/JSON text)`, e.g. `("blocks.pi.kp", "2.0")`; see
/// `nanomotion_core::overrides`).
pub fn load_spec(
    path: Option<PathBuf>,
    text: Option<&str>,
    origin: &str,
    overrides: &[(String, String)],
) -> PyResult<GraphSpec> {
    let set = overrides
        .iter()
        .map(|(p, v)| Override::parse_value(p, v).map_err(graph_err))
        .collect::<PyResult<Vec<_>>>()?;
    match (path, text) {
        (Some(p), None) => GraphSpec::from_file_with_overrides(&p, &set).map_err(graph_err),
        (None, Some(t)) => GraphSpec::from_yaml_with_overrides(t, origin, &set).map_err(graph_err),
        _ => Err(graph_err(
            "give a graph either as a file path or as YAML text, not both or neither",
        )),
    }
}

/// Measured data from one or more files (merged, as `nanomotion run --data A --data B`).
fn load_data(files: &[PathBuf], rate_hz: Option<f64>) -> PyResult<Option<Arc<Dataset>>> {
    let mut merged: Option<Dataset> = None;
    for path in files {
        let d = Dataset::from_file_with_rate(path, rate_hz).map_err(data_err)?;
        merged = Some(match merged {
            None => d,
            Some(m) => m.merge(d).map_err(data_err)?,
        });
    }
    Ok(merged.map(Arc::new))
}

pub(crate) fn analyse(sched: &nanomotion::Scheduler, require: Option<&Require>) -> GateReport {
    let default = Require::default();
    gate::analyse(sched, require.unwrap_or(&default))
}

/// `nanomotion check`: build the graph and analyse every feedback loop.
/// Returns `{passes, report, failures, allowed, order, rate_transitions,
/// base_rate_hz, ticks}`; `report` is the table `nanomotion check` prints.
#[pyfunction]
#[pyo3(signature = (path=None, text=None, origin="<string>", overrides=Vec::new()))]
fn check_graph<'py>(
    py: Python<'py>,
    path: Option<PathBuf>,
    text: Option<&str>,
    origin: &str,
    overrides: Vec<(String, String)>,
) -> PyResult<Bound<'py, PyDict>> {
    let spec = load_spec(path, text, origin, &overrides)?;
    let require = spec.require.clone();
    let (sched, report) = spec.build().map_err(graph_err)?;
    let gate = analyse(&sched, require.as_ref());
    let d = PyDict::new(py);
    d.set_item("passes", gate.passes())?;
    d.set_item("report", gate.to_string().trim_end())?;
    d.set_item("failures", gate.failures())?;
    d.set_item("allowed", gate.allowed())?;
    d.set_item("order", sched.describe())?;
    d.set_item("rate_transitions", report.rate_transitions)?;
    d.set_item("base_rate_hz", sched.base_rate_hz())?;
    d.set_item("ticks", sched.ticks_total())?;
    Ok(d)
}

/// What the gate lets through, or the refusal (`nanomotion run`'s rule, from
/// the library, with the Python spelling of the escape hatch).
pub(crate) fn gate_before_run(report: &GateReport, allow: bool) -> PyResult<Vec<String>> {
    report
        .before_run(allow, &FrontEnd::PYTHON)
        .map_err(gate_err)
}

/// Options of a run besides the graph.
pub struct RunOptions {
    pub seed: Option<u64>,
    pub duration: Option<f64>,
    pub data: Vec<PathBuf>,
    pub data_rate: Option<f64>,
    pub allow_unproven: bool,
}

/// A finished run, before conversion to Python objects.
pub struct Finished {
    pub result: nanomotion::core::scheduler::RunResult,
    pub comparisons: Vec<nanomotion::core::data::Comparison>,
    pub gate_lines: Vec<String>,
    pub wall_s: f64,
}

/// Run a loaded graph as `nanomotion run` does, keeping whole logs. Releases
/// the GIL while simulating.
pub fn run_spec(py: Python<'_>, mut spec: GraphSpec, o: RunOptions) -> PyResult<Finished> {
    if let Some(s) = o.seed {
        spec.seed = s;
    }
    let data = load_data(&o.data, o.data_rate)?;
    if data.is_some() && !spec.reads_data() {
        return Err(data_err(
            "data was given, but the graph reads no data (no `data_column` block, no `compare:` entry), so it would only change the duration (fix: drop data=, or play a column with a `data_column` block / compare an output with `compare:`)".to_string(),
        ));
    }
    if data.is_none() && !spec.compare.is_empty() {
        return Err(data_err(format!(
            "the graph compares {} signal(s) with measured data (`compare:`), but no data was given (fix: run with data=\"FILE\")",
            spec.compare.len()
        )));
    }
    match (o.duration, &data) {
        (Some(d), _) => spec.duration_s = d,
        (None, Some(d)) => spec.duration_s = d.duration_s(),
        (None, None) => {}
    }
    let require = spec.require.clone();
    let (mut sched, _report) = match &data {
        Some(d) => spec.build_with_data(d.clone()),
        None => spec.build(),
    }
    .map_err(graph_err)?;
    let gate_lines = gate_before_run(&analyse(&sched, require.as_ref()), o.allow_unproven)?;
    let start = std::time::Instant::now();
    let (result, comparisons) = py
        .detach(|| -> Result<_, String> {
            let result = sched.run(|_| {});
            sched.check_finite().map_err(|e| e.to_string())?;
            let comparisons = match &data {
                Some(d) => nanomotion::core::data::compare(&sched, d).map_err(|e| e.to_string())?,
                None => Vec::new(),
            };
            Ok((result, comparisons))
        })
        .map_err(graph_err)?;
    Ok(Finished {
        result,
        comparisons,
        gate_lines,
        wall_s: start.elapsed().as_secs_f64(),
    })
}

/// The run as a dict: `title`, `duration_s`, `wall_s`, `signals` (name → numpy
/// array, shape (N,) or (N, width)), `rates_hz`, `units`, `scores` (signal →
/// dict of rms, max_abs, mean, from_s, samples, unit), `comparisons` (list of
/// dicts), `stability_gate` (lines).
pub fn finished_to_py<'py>(py: Python<'py>, f: Finished) -> PyResult<Bound<'py, PyDict>> {
    let d = PyDict::new(py);
    d.set_item("title", f.result.title.clone())?;
    d.set_item("duration_s", f.result.duration_s)?;
    d.set_item("wall_s", f.wall_s)?;
    let signals = PyDict::new(py);
    let rates = PyDict::new(py);
    let units = PyDict::new(py);
    for log in f.result.logs {
        let n = log.len();
        if log.width == 1 {
            signals.set_item(&log.name, PyArray1::from_vec(py, log.data))?;
        } else {
            let a = Array2::from_shape_vec((n, log.width), log.data)
                .map_err(|e| graph_err(format!("log `{}`: {e}", log.name)))?;
            signals.set_item(&log.name, PyArray2::from_owned_array(py, a))?;
        }
        rates.set_item(&log.name, log.rate_hz)?;
        units.set_item(&log.name, log.unit)?;
    }
    d.set_item("signals", signals)?;
    d.set_item("rates_hz", rates)?;
    d.set_item("units", units)?;
    let scores = PyDict::new(py);
    for s in &f.result.scores {
        let e = PyDict::new(py);
        e.set_item("rms", s.rms)?;
        e.set_item("max_abs", s.max_abs)?;
        e.set_item("mean", s.mean)?;
        e.set_item("from_s", s.from_s)?;
        e.set_item("samples", s.samples)?;
        e.set_item("unit", s.unit.clone())?;
        scores.set_item(&s.signal, e)?;
    }
    d.set_item("scores", scores)?;
    let comparisons = PyList::empty(py);
    for c in &f.comparisons {
        let e = PyDict::new(py);
        e.set_item("signal", &c.signal)?;
        e.set_item("column", &c.column)?;
        e.set_item("samples", c.samples)?;
        e.set_item("rate_hz", c.rate_hz)?;
        e.set_item("rms", c.rms)?;
        e.set_item("max_abs", c.max_abs)?;
        e.set_item("fit_percent", c.fit_percent)?;
        comparisons.append(e)?;
    }
    d.set_item("comparisons", comparisons)?;
    d.set_item("stability_gate", f.gate_lines)?;
    Ok(d)
}

/// `nanomotion run` without files: see [`run_spec`] and [`finished_to_py`].
#[pyfunction]
#[pyo3(signature = (path=None, text=None, origin="<string>", overrides=Vec::new(), seed=None, duration=None, data=Vec::new(), data_rate=None, allow_unproven=false))]
#[allow(clippy::too_many_arguments)]
fn run_graph<'py>(
    py: Python<'py>,
    path: Option<PathBuf>,
    text: Option<&str>,
    origin: &str,
    overrides: Vec<(String, String)>,
    seed: Option<u64>,
    duration: Option<f64>,
    data: Vec<PathBuf>,
    data_rate: Option<f64>,
    allow_unproven: bool,
) -> PyResult<Bound<'py, PyDict>> {
    let spec = load_spec(path, text, origin, &overrides)?;
    let f = run_spec(
        py,
        spec,
        RunOptions {
            seed,
            duration,
            data,
            data_rate,
            allow_unproven,
        },
    )?;
    finished_to_py(py, f)
}

/// The graph's header as a dict (title, base_rate_hz, duration_s, seed, blocks
/// as a list of (name, type), log, score signals): a cheap validity check of the
/// YAML schema without building.
#[pyfunction]
#[pyo3(signature = (path=None, text=None, origin="<string>", overrides=Vec::new()))]
fn load_graph<'py>(
    py: Python<'py>,
    path: Option<PathBuf>,
    text: Option<&str>,
    origin: &str,
    overrides: Vec<(String, String)>,
) -> PyResult<Bound<'py, PyDict>> {
    let spec = load_spec(path, text, origin, &overrides)?;
    let d = PyDict::new(py);
    d.set_item("title", spec.title.clone())?;
    d.set_item("base_rate_hz", spec.base_rate_hz)?;
    d.set_item("duration_s", spec.duration_s)?;
    d.set_item("seed", spec.seed)?;
    let json = serde_json::to_value(&spec).map_err(graph_err)?;
    let blocks: Vec<(String, String)> = json["blocks"]
        .as_array()
        .map(|bs| {
            bs.iter()
                .map(|b| {
                    (
                        b["name"].as_str().unwrap_or_default().to_string(),
                        b["type"].as_str().unwrap_or_default().to_string(),
                    )
                })
                .collect()
        })
        .unwrap_or_default();
    d.set_item("blocks", blocks)?;
    d.set_item("log", spec.log.clone())?;
    d.set_item(
        "score",
        spec.score
            .iter()
            .map(|s| s.signal.clone())
            .collect::<Vec<_>>(),
    )?;
    Ok(d)
}

/// `nanomotion diagnose` without files: the report as JSON text (the CLI's
/// `report.json`) and the augmented graph as YAML (`model_augmented.yaml`),
/// or None when no effect was found.
#[pyfunction]
#[pyo3(signature = (model, data, max_effects=3, holdout=0.3, seed=None, effects=Vec::new(), validation=Vec::new(), phase=None))]
#[allow(clippy::too_many_arguments)]
fn diagnose_graph(
    py: Python<'_>,
    model: PathBuf,
    data: PathBuf,
    max_effects: usize,
    holdout: f64,
    seed: Option<u64>,
    effects: Vec<String>,
    validation: Vec<PathBuf>,
    phase: Option<String>,
) -> PyResult<(String, Option<String>)> {
    let spec = GraphSpec::from_file(&model).map_err(graph_err)?;
    let mut records = vec![Dataset::from_file(&data).map_err(data_err)?];
    for v in &validation {
        records.push(Dataset::from_file(v).map_err(data_err)?);
    }
    let opts = nanomotion::plf::diagnose::Options {
        max_effects,
        holdout,
        seed,
        effects,
        phase,
        ..Default::default()
    };
    let report = py
        .detach(move || {
            nanomotion::plf::diagnose::diagnose_records(&spec, &records, &opts, &mut |_, _| {})
        })
        .map_err(diagnose_err)?;
    let json = serde_json::to_string(&report).map_err(diagnose_err)?;
    let yaml = match &report.augmented {
        Some(s) => Some(nanomotion::core::yaml::to_string(s).map_err(diagnose_err)?),
        None => None,
    };
    Ok((json, yaml))
}

/// `nanomotion compensate` without files: the report as JSON text (the CLI's
/// `report.json`) and the compensated graph as YAML (`compensated.yaml`).
#[pyfunction]
#[pyo3(signature = (augmented, controller, report=None, reference=None, keep=false, measured_alpha=Vec::new(), delay_margin=None))]
#[allow(clippy::too_many_arguments)]
fn compensate_graph(
    py: Python<'_>,
    augmented: PathBuf,
    controller: PathBuf,
    report: Option<PathBuf>,
    reference: Option<PathBuf>,
    keep: bool,
    measured_alpha: Vec<String>,
    delay_margin: Option<f64>,
) -> PyResult<(String, String)> {
    use nanomotion::compensate::{MeasuredSignal, Options, compensate, named};
    let aug = GraphSpec::from_file(&augmented).map_err(graph_err)?;
    let ctl = GraphSpec::from_file(&controller).map_err(graph_err)?;
    let read = |p: &PathBuf| {
        std::fs::read_to_string(p)
            .map_err(|e| diagnose_err(format!("{}: cannot read it ({e})", p.display())))
    };
    let report = report.or_else(|| {
        let beside = augmented.with_file_name("report.json");
        beside.is_file().then_some(beside)
    });
    let effects = match &report {
        Some(p) => {
            named::from_report_json(&read(p)?, &p.display().to_string()).map_err(diagnose_err)?
        }
        None => named::from_graph(&aug),
    };
    let reference = match &reference {
        Some(p) => Some(
            nanomotion::core::yaml::from_str::<serde_json::Value>(
                &read(p)?,
                &p.display().to_string(),
            )
            .map_err(graph_err)?,
        ),
        None => None,
    };
    let measured = measured_alpha
        .iter()
        .map(|m| MeasuredSignal::from_file_column(m).map_err(diagnose_err))
        .collect::<PyResult<Vec<_>>>()?;
    let opts = Options {
        keep,
        reference,
        delay_margin,
        measured,
        augmented_name: augmented.display().to_string(),
        controller_name: controller.display().to_string(),
        ..Options::default()
    };
    let out = py
        .detach(move || compensate(&aug, &ctl, &effects, &opts))
        .map_err(diagnose_err)?;
    let json = serde_json::to_string(&out.report).map_err(diagnose_err)?;
    let yaml = nanomotion::core::yaml::to_string(&out.compensated).map_err(diagnose_err)?;
    Ok((json, yaml))
}

pub(crate) fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_function(wrap_pyfunction!(load_graph, m)?)?;
    m.add_function(wrap_pyfunction!(check_graph, m)?)?;
    m.add_function(wrap_pyfunction!(run_graph, m)?)?;
    m.add_function(wrap_pyfunction!(diagnose_graph, m)?)?;
    m.add_function(wrap_pyfunction!(compensate_graph, m)?)?;
    Ok(())
}
