//! Python exceptions for Rust errors: the message is the Rust error's `Display`
//! text unchanged (what the CLI prints after `error: `), the class says which
//! part of the library refused.
//!
//! ```text
//! NanomotionError (Exception)
//! ├── GraphError      YAML syntax or schema, block parameters, wiring, rates, non-finite run
//! ├── GateError       the stability gate refused the graph (run without allow_unproven)
//! ├── DataError       measured data files and comparisons
//! ├── AnalysisError   spectral analysis and LTI arguments
//! ├── ModelError      hysteresis / time-stamping model parameters
//! ├── DiagnoseError   the discrepancy workflow
//! └── SweepError      sweep files and sweep runs
//! ```

use pyo3::create_exception;
use pyo3::exceptions::PyException;
use pyo3::prelude::*;

create_exception!(
    _nanomotion,
    NanomotionError,
    PyException,
    "Base class of every error raised by nanomotion; the message is the Rust library's, unchanged."
);
create_exception!(
    _nanomotion,
    GraphError,
    NanomotionError,
    "A graph did not load, build or run (YAML line/column, block, port or rate in the message)."
);
create_exception!(
    _nanomotion,
    GateError,
    NanomotionError,
    "The stability gate refused the graph (unstable, unproven or out-of-bounds loop)."
);
create_exception!(
    _nanomotion,
    DataError,
    NanomotionError,
    "A measured-data file or comparison is wrong (file, row, column in the message)."
);
create_exception!(
    _nanomotion,
    AnalysisError,
    NanomotionError,
    "Bad arguments to an analysis or LTI function."
);
create_exception!(
    _nanomotion,
    ModelError,
    NanomotionError,
    "Bad parameters of a hysteresis or time-stamping model."
);
create_exception!(
    _nanomotion,
    DiagnoseError,
    NanomotionError,
    "The discrepancy workflow (diagnose) refused its inputs."
);
create_exception!(
    _nanomotion,
    SweepError,
    NanomotionError,
    "A sweep file or a sweep run failed."
);

/// `Err(Class(message))` from any displayable Rust error.
pub fn graph_err(e: impl std::fmt::Display) -> PyErr {
    GraphError::new_err(e.to_string())
}
/// See [`graph_err`].
pub fn gate_err(e: impl std::fmt::Display) -> PyErr {
    GateError::new_err(e.to_string())
}
/// See [`graph_err`].
pub fn data_err(e: impl std::fmt::Display) -> PyErr {
    DataError::new_err(e.to_string())
}
/// See [`graph_err`].
pub fn analysis_err(e: impl std::fmt::Display) -> PyErr {
    AnalysisError::new_err(e.to_string())
}
/// See [`graph_err`].
pub fn model_err(e: impl std::fmt::Display) -> PyErr {
    ModelError::new_err(e.to_string())
}
/// See [`graph_err`].
pub fn diagnose_err(e: impl std::fmt::Display) -> PyErr {
    DiagnoseError::new_err(e.to_string())
}
/// See [`graph_err`].
pub fn sweep_err(e: impl std::fmt::Display) -> PyErr {
    SweepError::new_err(e.to_string())
}

pub(crate) fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    let py = m.py();
    m.add("NanomotionError", py.get_type::<NanomotionError>())?;
    m.add("GraphError", py.get_type::<GraphError>())?;
    m.add("GateError", py.get_type::<GateError>())?;
    m.add("DataError", py.get_type::<DataError>())?;
    m.add("AnalysisError", py.get_type::<AnalysisError>())?;
    m.add("ModelError", py.get_type::<ModelError>())?;
    m.add("DiagnoseError", py.get_type::<DiagnoseError>())?;
    m.add("SweepError", py.get_type::<SweepError>())?;
    Ok(())
}
