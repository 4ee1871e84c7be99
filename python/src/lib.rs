//! # nanomotion-python
//!
//! The extension module `nanomotion._nanomotion` behind the Python package
//! `nanomotion` (pyo3, abi3 for CPython ≥ 3.11, built with maturin). It calls the
//! library — the same functions the `nanomotion` CLI calls — and never
//! re-implements them:
//!
//! - graphs ([`graph`]): load, check (the stability gate), run with overrides
//!   (dotted parameter paths, seed, duration, measured data), logged signals as
//!   numpy arrays, scores; `diagnose` (the plf discrepancy workflow);
//! - analysis ([`analysis`]): Welch PSD, cumulative PSD, H1 FRF, LTI models with
//!   frequency response, poles, H∞ norm and stability margins;
//! - models ([`models`]): Coleman–Hodgdon hysteresis (6.3), its exact inverse
//!   feed-forward (6.6) on the extended model (6.4), the time-stamping estimator
//!   (8.1)–(8.4) with the encoder of Ch. 8;
//! - the wall clock ([`rt`]): a graph run in real time as `nanomotion rt` runs
//!   it, alone or against a plant in another process (`device="shm:NAME"`),
//!   in the background with live parameter updates, with its timing report;
//! - sweeps ([`sweep`]): the pieces of `nanomotion::sweep` a distributed engine
//!   (Ray) needs, and the local rayon path.
//!
//! Rust errors become Python exceptions carrying the same message (the CLI
//! prints it after `error: `), in a hierarchy rooted at `NanomotionError`
//! ([`errors`]).

use pyo3::prelude::*;

pub mod analysis;
pub mod errors;
pub mod graph;
pub mod models;
pub mod rt;
pub mod sweep;

/// The module `nanomotion._nanomotion`.
#[pymodule]
fn _nanomotion(m: &Bound<'_, PyModule>) -> PyResult<()> {
    // typetag registers block types through the linker: reference every plugin.
    nanomotion::link_plugins();
    m.add("__version__", env!("CARGO_PKG_VERSION"))?;
    errors::register(m)?;
    graph::register(m)?;
    analysis::register(m)?;
    models::register(m)?;
    sweep::register(m)?;
    rt::register(m)?;
    Ok(())
}
