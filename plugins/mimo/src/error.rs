//! Errors of the MIMO toolkit: typed, naming the parameter and the fix.

use nanomotion_core::ParamError;
use nanomotion_core::analysis::AnalysisError;
use nanomotion_core::lti::LtiError;
use thiserror::Error;

/// What can go wrong in design, analysis or configuration.
#[derive(Debug, Clone, PartialEq, Error)]
pub enum MimoError {
    /// A bad parameter (name, what is wrong, how to fix it).
    #[error("`{name}`: {problem} ({fix})")]
    Param {
        /// Parameter name (a path such as `weights.axes[2].f_s1_hz`).
        name: String,
        /// What is wrong.
        problem: String,
        /// How to fix it.
        fix: String,
    },
    /// An LTI operation failed (synthesis, norms, discretisation).
    #[error("{context}: {source}")]
    Lti {
        /// What was being done.
        context: String,
        /// The toolkit's error.
        source: LtiError,
    },
    /// A frequency-domain analysis failed.
    #[error("{context}: {source}")]
    Analysis {
        /// What was being done.
        context: String,
        /// The toolkit's error.
        source: AnalysisError,
    },
}

impl MimoError {
    /// A parameter error.
    pub fn param(
        name: impl Into<String>,
        problem: impl Into<String>,
        fix: impl Into<String>,
    ) -> Self {
        MimoError::Param {
            name: name.into(),
            problem: problem.into(),
            fix: fix.into(),
        }
    }

    /// An LTI error with its context.
    pub fn lti(context: impl Into<String>) -> impl FnOnce(LtiError) -> Self {
        let context = context.into();
        move |source| MimoError::Lti { context, source }
    }
}

impl From<MimoError> for ParamError {
    fn from(e: MimoError) -> Self {
        match e {
            MimoError::Param { name, problem, fix } => ParamError::new(name, problem, fix),
            other => ParamError::new("model", other.to_string(), "check the controller matrices"),
        }
    }
}

/// Check that `v` is finite and positive.
pub(crate) fn positive(name: &str, v: f64) -> Result<(), MimoError> {
    if v.is_finite() && v > 0.0 {
        Ok(())
    } else {
        Err(MimoError::param(
            name,
            format!("is {v}, must be finite and > 0"),
            "give a positive number",
        ))
    }
}

/// Largest magnitude of a gain, weight or coupling in a synthesis config (and
/// smallest of a positive weight: 1/this): 10¹². Beyond it the H∞ problem's
/// numbers (γ, γ², the Riccati solutions) leave the range f64 resolves, and
/// the synthesis could not end (audit D7: `k_s: 1e200` hung).
pub const MAX_MAGNITUDE: f64 = 1e12;

/// Check that `v` is a positive number in [1/[`MAX_MAGNITUDE`], [`MAX_MAGNITUDE`]].
pub(crate) fn weight(name: &str, v: f64) -> Result<(), MimoError> {
    positive(name, v)?;
    if (1.0 / MAX_MAGNITUDE..=MAX_MAGNITUDE).contains(&v) {
        Ok(())
    } else {
        Err(MimoError::param(
            name,
            format!(
                "is {v:e}, outside [{:e}, {MAX_MAGNITUDE:e}]",
                1.0 / MAX_MAGNITUDE
            ),
            "give a weight within 12 decades of 1 (rescale the plant's units if its numbers are that large)",
        ))
    }
}

/// Check that `v` is finite and |v| ≤ [`MAX_MAGNITUDE`].
pub(crate) fn magnitude(name: &str, v: f64) -> Result<(), MimoError> {
    finite(name, v)?;
    if v.abs() <= MAX_MAGNITUDE {
        Ok(())
    } else {
        Err(MimoError::param(
            name,
            format!("is {v:e}, larger in magnitude than {MAX_MAGNITUDE:e}"),
            "rescale the plant's units (e.g. µm instead of nm) so its gains stay within 10¹²",
        ))
    }
}

/// Check that `v` is finite.
pub(crate) fn finite(name: &str, v: f64) -> Result<(), MimoError> {
    if v.is_finite() {
        Ok(())
    } else {
        Err(MimoError::param(
            name,
            format!("is {v}"),
            "give a finite number",
        ))
    }
}
