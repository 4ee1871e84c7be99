//! Parameter studies from Python: the pieces of `nanomotion::sweep` that an
//! engine needs — plan, pending runs, one chunk of runs → rows, the row store,
//! the table — so that `nanomotion.sweep(..., engine="ray")` can run chunks as
//! Ray tasks and gather them into the same files `nanomotion sweep` writes, and
//! `engine="local"` is `run_study` itself (rayon). Rows cross the boundary as
//! JSON (`Row` is serde), which is also what Ray ships between processes.

use crate::errors::sweep_err;
use nanomotion::sweep::{self, Row, RowStore, RunOptions, Study};
use pyo3::prelude::*;
use pyo3::types::PyDict;
use std::path::{Path, PathBuf};

fn study(path: &Path) -> PyResult<Study> {
    Study::from_file(path).map_err(sweep_err)
}

fn summary_dict<'py>(py: Python<'py>, s: &sweep::Summary) -> PyResult<Bound<'py, PyDict>> {
    let d = PyDict::new(py);
    d.set_item("planned", s.planned)?;
    d.set_item("resumed", s.resumed)?;
    d.set_item("computed", s.computed)?;
    d.set_item("failed", s.failed)?;
    d.set_item(
        "files",
        s.files
            .iter()
            .map(|f| f.display().to_string())
            .collect::<Vec<_>>(),
    )?;
    d.set_item("wall_s", s.wall_s)?;
    Ok(d)
}

/// The study's deterministic plan as JSON (`plan.json`).
#[pyfunction]
fn sweep_plan(path: PathBuf) -> PyResult<String> {
    let plan = study(&path)?.plan();
    serde_json::to_string(&plan).map_err(sweep_err)
}

/// Open (or create) the row store in `out` and return (planned runs, the
/// indices not finished yet, the plan's hash). `restart` discards finished rows.
#[pyfunction]
#[pyo3(signature = (path, out, restart=false))]
fn sweep_pending(
    path: PathBuf,
    out: PathBuf,
    restart: bool,
) -> PyResult<(usize, Vec<usize>, String)> {
    let s = study(&path)?;
    let plan = s.plan();
    let (_store, done) = RowStore::open(&out, &plan, restart).map_err(sweep_err)?;
    let mut finished = vec![false; plan.len()];
    for r in &done {
        finished[r.index] = true;
    }
    let todo = (0..plan.len()).filter(|&i| !finished[i]).collect();
    Ok((plan.len(), todo, plan.study_hash))
}

/// Run the plan's runs `indices` in this process on `jobs` threads (0: all
/// cores) and return their rows as a JSON list. This is the body of a Ray task.
#[pyfunction]
#[pyo3(signature = (path, indices, jobs=1))]
fn sweep_run_chunk(
    py: Python<'_>,
    path: PathBuf,
    indices: Vec<usize>,
    jobs: usize,
) -> PyResult<String> {
    let s = study(&path)?;
    let plan = s.plan();
    let rows = py.detach(move || s.run_chunk(&plan, &indices, jobs, |_| {}));
    serde_json::to_string(&rows).map_err(sweep_err)
}

/// Append rows (a JSON list from [`sweep_run_chunk`]) to the store in `out`;
/// rows of another plan are refused. Returns how many were appended.
#[pyfunction]
fn sweep_append(path: PathBuf, out: PathBuf, rows_json: &str) -> PyResult<usize> {
    let s = study(&path)?;
    let plan = s.plan();
    let rows: Vec<Row> = serde_json::from_str(rows_json).map_err(sweep_err)?;
    let (store, _) = RowStore::open(&out, &plan, false).map_err(sweep_err)?;
    for r in &rows {
        if r.study != plan.study_hash {
            return Err(sweep_err(format!(
                "a row of plan {} was returned for plan {} (the study or its graph changed while it ran: run it again)",
                r.study, plan.study_hash
            )));
        }
        store.append(r).map_err(sweep_err)?;
    }
    Ok(rows.len())
}

/// Write `results.csv`, `results.parquet`, `plan.json` and the plots from the
/// finished rows in `out`; returns the summary (`computed` is 0: the rows were
/// computed by the engine).
#[pyfunction]
fn sweep_write<'py>(py: Python<'py>, path: PathBuf, out: PathBuf) -> PyResult<Bound<'py, PyDict>> {
    let s = study(&path)?;
    let plan = s.plan();
    let (_store, rows) = RowStore::open(&out, &plan, false).map_err(sweep_err)?;
    let files = sweep::write_results(&out, &s, &plan, &rows).map_err(sweep_err)?;
    let summary = sweep::Summary {
        planned: plan.len(),
        resumed: rows.len(),
        computed: 0,
        failed: rows.iter().filter(|r| r.error.is_some()).count(),
        files,
        wall_s: 0.0,
    };
    summary_dict(py, &summary)
}

/// The lock of a sweep's output folder held by a Python engine for the whole
/// study (the CLI's `FolderLock`): a second sweep into the same folder — from
/// the CLI, `engine="local"` or another Ray driver — is refused while it is
/// held. A context manager; released on `release()`, on leaving the `with`
/// block, or when collected.
#[pyclass(name = "SweepLock", module = "nanomotion._nanomotion")]
struct SweepLock {
    lock: Option<nanomotion::output::FolderLock>,
}

#[pymethods]
impl SweepLock {
    /// Release the lock (idempotent).
    fn release(&mut self) {
        self.lock.take();
    }
    /// Whether the lock is still held.
    #[getter]
    fn held(&self) -> bool {
        self.lock.is_some()
    }
    fn __enter__(slf: PyRef<'_, Self>) -> PyRef<'_, Self> {
        slf
    }
    #[pyo3(signature = (*_exc))]
    fn __exit__(&mut self, _exc: &Bound<'_, pyo3::types::PyTuple>) -> bool {
        self.release();
        false
    }
}

/// Lock the output folder `out` of a sweep (created if missing) as
/// `nanomotion sweep` does: a folder of the user's that is not a sweep's is
/// refused, and so is a folder another sweep is writing.
#[pyfunction]
fn sweep_lock(out: PathBuf) -> PyResult<SweepLock> {
    nanomotion::output::refuse_foreign(&out, &[sweep::ROWS_FILE], "empty it").map_err(sweep_err)?;
    let lock = nanomotion::output::FolderLock::acquire(&out).map_err(sweep_err)?;
    Ok(SweepLock { lock: Some(lock) })
}

/// `nanomotion sweep` in-process: plan, resume, run the rest on `jobs` rayon
/// threads (0: all cores), write the table and plots.
#[pyfunction]
#[pyo3(signature = (path, out, jobs=0, restart=false, limit=None))]
fn sweep_local<'py>(
    py: Python<'py>,
    path: PathBuf,
    out: PathBuf,
    jobs: usize,
    restart: bool,
    limit: Option<usize>,
) -> PyResult<Bound<'py, PyDict>> {
    let s = study(&path)?;
    let opts = RunOptions {
        jobs,
        restart,
        limit,
        progress: false,
    };
    let summary = py
        .detach(move || sweep::run_study(&s, &out, &opts).map_err(|e| e.to_string()))
        .map_err(sweep_err)?;
    summary_dict(py, &summary)
}

pub(crate) fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_function(wrap_pyfunction!(sweep_plan, m)?)?;
    m.add_function(wrap_pyfunction!(sweep_pending, m)?)?;
    m.add_function(wrap_pyfunction!(sweep_run_chunk, m)?)?;
    m.add_function(wrap_pyfunction!(sweep_append, m)?)?;
    m.add_function(wrap_pyfunction!(sweep_write, m)?)?;
    m.add_function(wrap_pyfunction!(sweep_local, m)?)?;
    m.add_function(wrap_pyfunction!(sweep_lock, m)?)?;
    m.add_class::<SweepLock>()?;
    Ok(())
}
