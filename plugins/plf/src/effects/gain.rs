//! `position_dependent_gain`: a gain that varies polynomially with a scheduling
//! signal.

use super::{MAX_MAGNITUDE, check_bounded, check_len};
use nanomotion_core::Params;
use nanomotion_core::{Block, BuildContext, ParamError, Port, Tick, Tunable, declared_block};
use serde::{Deserialize, Serialize};

/// Highest polynomial order of a `position_dependent_gain`.
pub const MAX_ORDER: usize = 8;

/// Where the scheduling variable comes from.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize, Params)]
#[serde(rename_all = "snake_case")]
pub enum GainVariable {
    /// The signal on port `s` (usually the plant's position).
    #[default]
    Signal,
    /// The input itself (s = u; no port `s`): an amplitude-dependent gain.
    Input,
}

fn one() -> f64 {
    1.0
}

/// `position_dependent_gain`: PLF effect: y = u·(1 + g0 + Σ g_i ((s −
/// center)/scale)^i), s from port s or s = u; tunable [coeffs.., g0].
///
/// ```text
/// y = u·(1 + g_0 + Σ_{i=1..n} g_i·((s − center)/scale)^i)
/// ```
///
/// with s from port `s` (`variable: signal`, default) or s = u (`variable: input`).
/// 1 ≤ n ≤ [`MAX_ORDER`]. Evaluated by Horner's rule. g_0 (`g0`, default 0) is a
/// constant relative gain error: a nominal model's gain is rarely exact, and with
/// the polynomial centred on the record's mean position a gain that varies
/// linearly about another point needs it.
///
/// [`Tunable`] vector: `[coeffs[0..n], g0]` (g_1..g_n, then g_0).
#[derive(Debug, Clone, Serialize, Deserialize, Params)]
#[serde(deny_unknown_fields)]
#[block(type_name = "position_dependent_gain", role = Plant, ports = "u (, s) -> y")]
pub struct PositionDependentGain {
    /// `signal` (default, port `s`) or `input`.
    #[serde(default)]
    #[param(default_doc = "signal")]
    pub variable: GainVariable,
    /// Centre of the polynomial (unit of s), default 0.
    #[serde(default)]
    pub center: f64,
    /// Scale (unit of s), default 1: the polynomial is in (s − center)/scale.
    #[serde(default = "one")]
    #[param(positive)]
    pub scale: f64,
    /// g_1..g_n (dimensionless).
    #[param(len(1, MAX_ORDER))]
    pub coeffs: Vec<f64>,
    /// g_0: constant relative gain error (dimensionless), default 0.
    #[serde(default)]
    pub g0: f64,
}

impl PositionDependentGain {
    /// A gain scheduled on port `s`.
    pub fn new(center: f64, scale: f64, coeffs: Vec<f64>) -> Self {
        Self {
            variable: GainVariable::Signal,
            center,
            scale,
            coeffs,
            g0: 0.0,
        }
    }

    /// The relative gain 1 + g_0 + Σ g_i x^i at scheduling value `s`.
    pub fn gain(&self, s: f64) -> f64 {
        let x = (s - self.center) / self.scale;
        let mut acc = 0.0;
        for g in self.coeffs.iter().rev() {
            acc = (acc + g) * x;
        }
        1.0 + self.g0 + acc
    }

    /// The coefficients' magnitudes (their count is declared).
    fn check_coeffs(c: &[f64]) -> Result<(), ParamError> {
        for (i, g) in c.iter().enumerate() {
            check_bounded(&format!("coeffs[{i}]"), *g, MAX_MAGNITUDE)?;
        }
        Ok(())
    }
}

#[declared_block]
impl Block for PositionDependentGain {
    fn inputs(&self) -> Vec<Port> {
        match self.variable {
            GainVariable::Signal => vec![Port::new("u", 1), Port::new("s", 1)],
            GainVariable::Input => vec![Port::new("u", 1)],
        }
    }
    fn outputs(&self) -> Vec<Port> {
        vec![Port::new("y", 1)]
    }
    fn build(&mut self, _ctx: &BuildContext) -> Result<(), ParamError> {
        // scale > 0 and 1 to 8 coefficients: declared
        self.check_params()?;
        check_bounded("center", self.center, MAX_MAGNITUDE)?;
        check_bounded("g0", self.g0, MAX_MAGNITUDE)?;
        Self::check_coeffs(&self.coeffs)
    }
    fn output(&mut self, _tick: Tick, u: &[f64], y: &mut [f64]) {
        let s = match self.variable {
            GainVariable::Signal => u[1],
            GainVariable::Input => u[0],
        };
        y[0] = u[0] * self.gain(s);
    }
    fn tunable(&self) -> Option<&dyn Tunable> {
        Some(self)
    }
    fn tunable_mut(&mut self) -> Option<&mut dyn Tunable> {
        Some(self)
    }
}

impl Tunable for PositionDependentGain {
    fn param_names(&self) -> Vec<String> {
        (0..self.coeffs.len())
            .map(|i| format!("coeffs[{i}]"))
            .chain(std::iter::once("g0".to_string()))
            .collect()
    }
    fn params(&self) -> Vec<f64> {
        let mut p = self.coeffs.clone();
        p.push(self.g0);
        p
    }
    fn set_params(&mut self, p: &[f64]) -> Result<(), ParamError> {
        let n = self.coeffs.len();
        check_len(p, n + 1, "[coeffs[0..n], g0]")?;
        Self::check_coeffs(&p[..n])?;
        check_bounded("g0", p[n], MAX_MAGNITUDE)?;
        self.coeffs.copy_from_slice(&p[..n]);
        self.g0 = p[n];
        Ok(())
    }
}
