//! Discrete (and continuous) LTI toolkit.
//!
//! Models are kept as state space or cascaded second-order sections: SPEC §1 notes
//! that the Ch. 5 plant discretised at 4 kHz as one high-order polynomial transfer
//! function is too ill-conditioned to simulate from its coefficients.

use nalgebra::DMatrix;
use serde::{Deserialize, Serialize};

/// State-space model x' = A x + B u, y = C x + D u; `dt = None` for continuous
/// time (x' = dx/dt), `Some(T)` for discrete time with period T seconds
/// (x' = x[k+1]).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct StateSpace {
    /// State matrix A (n × n).
    pub a: DMatrix<f64>,
    /// Input matrix B (n × m).
    pub b: DMatrix<f64>,
    /// Output matrix C (p × n).
    pub c: DMatrix<f64>,
    /// Feed-through matrix D (p × m).
    pub d: DMatrix<f64>,
    /// Sample period in seconds, `None` for continuous time.
    pub dt: Option<f64>,
}

/// SISO transfer function num(s)/den(s) or num(z)/den(z), coefficients in
/// **descending** powers (as python-control and MATLAB write them); `dt` as for
/// [`StateSpace`].
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct TransferFunction {
    /// Numerator coefficients, highest power first.
    pub num: Vec<f64>,
    /// Denominator coefficients, highest power first.
    pub den: Vec<f64>,
    /// Sample period in seconds, `None` for continuous time.
    pub dt: Option<f64>,
}

/// One second-order section in scipy's `sos` layout `[b0, b1, b2, a0, a1, a2]`:
/// H(z) = (b0 + b1 z⁻¹ + b2 z⁻²) / (a0 + a1 z⁻¹ + a2 z⁻²). A cascade of sections is
/// a `Vec<SosSection>`.
pub type SosSection = [f64; 6];
