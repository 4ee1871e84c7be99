//! Typed errors of the AFM-stage crate.

use thiserror::Error;

/// Everything that can go wrong in the hysteresis models, their inversion and
/// identification. Every variant names the offending quantity and how to fix it.
#[derive(Debug, Clone, PartialEq, Error)]
pub enum AfmError {
    /// A model parameter is non-finite or out of its range.
    #[error("parameter `{name}`: {problem}")]
    Parameter {
        /// Parameter name (thesis symbol in the docs).
        name: String,
        /// What is wrong and how to fix it.
        problem: String,
    },
    /// The voltage range V_R = V_M − V_m is zero or negative.
    #[error("voltage range V_R = V_M − V_m = {v_r} V: it must be > 0 (give V_M > V_m)")]
    ZeroRange {
        /// The offending range (V).
        v_r: f64,
    },
    /// A position outside the range the inverse model covers.
    #[error(
        "position {x} outside the invertible range [{lo}, {hi}] of the {branch} branch: restrict the reference or widen the voltage range"
    )]
    OutOfRange {
        /// Requested position (unit of the model, µm by default).
        x: f64,
        /// Lowest reachable position.
        lo: f64,
        /// Highest reachable position.
        hi: f64,
        /// `trace` or `retrace`.
        branch: &'static str,
    },
    /// The branch is not strictly increasing on [V_m, V_M], so it has no inverse.
    #[error(
        "the {branch} branch is not strictly increasing on [{v_m}, {v_max}] V (slope {slope} at {at} V): the model has no inverse there"
    )]
    NotMonotone {
        /// `trace` or `retrace`.
        branch: &'static str,
        /// Lower voltage V_m.
        v_m: f64,
        /// Upper voltage V_M.
        v_max: f64,
        /// Slope dx/dV found (≤ 0).
        slope: f64,
        /// Voltage where it was found.
        at: f64,
    },
    /// Identification data that cannot be used (too short, non-monotone, NaN).
    #[error("identification data, {what}: {problem}")]
    Data {
        /// Which curve or sample.
        what: String,
        /// What is wrong.
        problem: String,
    },
    /// A data file that cannot be read or parsed.
    #[error("{file}:{line}: {problem}")]
    File {
        /// Path of the file.
        file: String,
        /// 1-based line (0 when the whole file is concerned).
        line: usize,
        /// What is wrong.
        problem: String,
    },
    /// The nonlinear least-squares fit failed.
    #[error("fit failed: {0}")]
    Fit(String),
}

impl AfmError {
    pub(crate) fn param(name: impl Into<String>, problem: impl Into<String>) -> Self {
        AfmError::Parameter {
            name: name.into(),
            problem: problem.into(),
        }
    }
}

/// `value` must be finite.
pub(crate) fn finite(name: &str, value: f64) -> Result<(), AfmError> {
    if value.is_finite() {
        Ok(())
    } else {
        Err(AfmError::param(
            name,
            format!("is {value}, give a finite number"),
        ))
    }
}

/// `value` must be finite and > 0.
pub(crate) fn positive(name: &str, value: f64) -> Result<(), AfmError> {
    finite(name, value)?;
    if value > 0.0 {
        Ok(())
    } else {
        Err(AfmError::param(name, format!("is {value}, must be > 0")))
    }
}

/// Convert to the core's [`nanomotion_core::ParamError`] for `Block::build`.
impl From<AfmError> for nanomotion_core::ParamError {
    fn from(e: AfmError) -> Self {
        match e {
            AfmError::Parameter { name, problem } => {
                nanomotion_core::ParamError::new(name, problem, "see the block documentation")
            }
            other => nanomotion_core::ParamError::new(
                "parameters",
                other.to_string(),
                "adjust the parameters",
            ),
        }
    }
}

/// The core's validation errors (e.g. of the shared Coleman–Hodgdon model) as
/// [`AfmError::Parameter`].
impl From<nanomotion_core::ParamError> for AfmError {
    fn from(e: nanomotion_core::ParamError) -> Self {
        AfmError::Parameter {
            name: e.field,
            problem: format!("{} (fix: {})", e.problem, e.fix),
        }
    }
}
