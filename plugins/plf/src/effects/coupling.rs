//! `axis_coupling`: static cross-talk from other axes.

use super::{MAX_MAGNITUDE, check_bounded, check_len};
use nalgebra::DMatrix;
use nanomotion_core::Params;
use nanomotion_core::lti::StateSpace;
use nanomotion_core::{Block, BuildContext, ParamError, Port, Tick, Tunable, declared_block};
use serde::{Deserialize, Serialize};

/// Most coupled signals of an `axis_coupling`.
pub const MAX_COUPLED: usize = 8;

/// `axis_coupling`: PLF effect: y = u + Σ_j c_j·s_j (static cross-axis coupling), LTI;
/// tunable [coupling..].
///
/// Y = u + Σ_j c_j·s_j, with port `s` of width n = len(coupling),
/// 1 ≤ n ≤ [`MAX_COUPLED`]: the static coupling of other axes into this one (the
/// off-diagonal terms of the AFM stage's coupling matrix, Sec. 6.2). Linear:
/// [`Block::lti`] is the gain [1, c_1, ..., c_n] from [u; s] to y.
///
/// [`Tunable`] vector: `[coupling[0..n]]`.
#[derive(Debug, Clone, Serialize, Deserialize, Params)]
#[serde(deny_unknown_fields)]
#[block(type_name = "axis_coupling", role = Plant, ports = "u, s[n] -> y")]
pub struct AxisCoupling {
    /// c_1..c_n (\[u\]/\[s\]); n is the width of port `s`.
    #[param(len(1, MAX_COUPLED))]
    pub coupling: Vec<f64>,
    #[serde(skip)]
    dt: Option<f64>,
}

impl AxisCoupling {
    /// Coupling gains c_1..c_n.
    pub fn new(coupling: Vec<f64>) -> Self {
        Self { coupling, dt: None }
    }

    /// The gains' magnitudes (their count is declared).
    fn check(c: &[f64]) -> Result<(), ParamError> {
        for (i, v) in c.iter().enumerate() {
            check_bounded(&format!("coupling[{i}]"), *v, MAX_MAGNITUDE)?;
        }
        Ok(())
    }
}

#[declared_block]
impl Block for AxisCoupling {
    fn inputs(&self) -> Vec<Port> {
        vec![Port::new("u", 1), Port::new("s", self.coupling.len())]
    }
    fn outputs(&self) -> Vec<Port> {
        vec![Port::new("y", 1)]
    }
    fn build(&mut self, ctx: &BuildContext) -> Result<(), ParamError> {
        self.check_params()?;
        Self::check(&self.coupling)?;
        nanomotion_core::block::check::positive("dt", ctx.dt)?;
        self.dt = Some(ctx.dt);
        Ok(())
    }
    fn output(&mut self, _tick: Tick, u: &[f64], y: &mut [f64]) {
        let mut out = u[0];
        for (c, s) in self.coupling.iter().zip(&u[1..]) {
            out += c * s;
        }
        y[0] = out;
    }
    fn lti(&self) -> Option<StateSpace> {
        let n = self.coupling.len();
        let mut d = DMatrix::zeros(1, n + 1);
        d[(0, 0)] = 1.0;
        for (j, c) in self.coupling.iter().enumerate() {
            d[(0, j + 1)] = *c;
        }
        Some(StateSpace::gain(d, self.dt))
    }
    fn tunable(&self) -> Option<&dyn Tunable> {
        Some(self)
    }
    fn tunable_mut(&mut self) -> Option<&mut dyn Tunable> {
        Some(self)
    }
}

impl Tunable for AxisCoupling {
    fn param_names(&self) -> Vec<String> {
        (0..self.coupling.len())
            .map(|i| format!("coupling[{i}]"))
            .collect()
    }
    fn params(&self) -> Vec<f64> {
        self.coupling.clone()
    }
    fn set_params(&mut self, p: &[f64]) -> Result<(), ParamError> {
        check_len(p, self.coupling.len(), "[coupling[0..n]]")?;
        Self::check(p)?;
        self.coupling.copy_from_slice(p);
        Ok(())
    }
}
