//! `friction`: a lumped Coulomb + Stribeck + viscous friction force computed from a
//! position signal.

use super::{MAX_MAGNITUDE, check_bounded, check_len};
use nanomotion_core::Params;
use nanomotion_core::block::check;
use nanomotion_core::{Block, BuildContext, ParamError, Port, Tick, Tunable, declared_block};
use serde::{Deserialize, Serialize};

/// `friction`: PLF effect: friction force from a position, y = −tanh(v/v_eps)(F_C + F_S
/// e^{−(v/v_S)²}) − F_v v, v = Δu/dt; add it to a plant's force input; tunable
/// [coulomb, stribeck, v_stribeck, viscous].
///
/// Input `u` is a position; the velocity is the backward difference
/// v = (u_k − u_{k−1})/dt (v = 0 at the first tick), and the output is the force
///
/// ```text
/// y = −sgn_ε(v)·(F_C + F_S·e^{−(v/v_S)²}) − F_v·v,    sgn_ε(v) = tanh(v/v_ε)
/// ```
///
/// It is meant to be added to a plant's force input (the workflow inserts a sum
/// block: force = command + friction(position)). The walking-piezo plugin's
/// friction (Sec. 4.3) is a different model: a set-valued contact law between the
/// legs and the drive rod, solved inside that plant's own time-stepping scheme, not
/// a signal-level force; that is why this smooth, lumped model is separate.
///
/// [`Tunable`] vector: `[coulomb, stribeck, v_stribeck, viscous]`.
#[derive(Debug, Clone, Serialize, Deserialize, Params)]
#[serde(deny_unknown_fields)]
#[block(type_name = "friction", role = Plant, ports = "u (position) -> y (force)")]
pub struct Friction {
    /// Coulomb level F_C ≥ 0 (force unit, e.g. N).
    pub coulomb: f64,
    /// Stribeck excess F_S ≥ 0 (force unit): static minus Coulomb friction.
    #[serde(default)]
    pub stribeck: f64,
    /// Stribeck velocity v_S > 0 (\[u\]/s).
    pub v_stribeck: f64,
    /// Viscous coefficient F_v (force per \[u\]/s).
    #[serde(default)]
    pub viscous: f64,
    /// Smoothing velocity v_ε > 0 (\[u\]/s) of the sign function.
    pub v_eps: f64,
    #[serde(skip)]
    prev: Option<f64>,
}

impl Friction {
    /// Coulomb level, Stribeck excess and velocity, smoothing velocity; no viscous term.
    pub fn new(coulomb: f64, stribeck: f64, v_stribeck: f64, v_eps: f64) -> Self {
        Self {
            coulomb,
            stribeck,
            v_stribeck,
            viscous: 0.0,
            v_eps,
            prev: None,
        }
    }

    /// The force at velocity `v` (\[u\]/s).
    pub fn force(&self, v: f64) -> f64 {
        let r = v / self.v_stribeck;
        -(v / self.v_eps).tanh() * (self.coulomb + self.stribeck * (-r * r).exp())
            - self.viscous * v
    }

    fn check(p: [f64; 4], v_eps: f64) -> Result<(), ParamError> {
        check::non_negative("coulomb", p[0])?;
        check_bounded("coulomb", p[0], MAX_MAGNITUDE)?;
        check::non_negative("stribeck", p[1])?;
        check_bounded("stribeck", p[1], MAX_MAGNITUDE)?;
        check::positive("v_stribeck", p[2])?;
        check_bounded("viscous", p[3], MAX_MAGNITUDE)?;
        check::positive("v_eps", v_eps)
    }
}

#[declared_block]
impl Block for Friction {
    fn inputs(&self) -> Vec<Port> {
        vec![Port::new("u", 1)]
    }
    fn outputs(&self) -> Vec<Port> {
        vec![Port::new("y", 1)]
    }
    fn build(&mut self, ctx: &BuildContext) -> Result<(), ParamError> {
        Self::check(
            [self.coulomb, self.stribeck, self.v_stribeck, self.viscous],
            self.v_eps,
        )?;
        check::positive("dt", ctx.dt)?;
        self.prev = None;
        Ok(())
    }
    fn output(&mut self, tick: Tick, u: &[f64], y: &mut [f64]) {
        let x = u[0];
        let v = match self.prev {
            Some(p) => (x - p) / tick.dt,
            None => 0.0,
        };
        self.prev = Some(x);
        y[0] = self.force(v);
    }
    fn tunable(&self) -> Option<&dyn Tunable> {
        Some(self)
    }
    fn tunable_mut(&mut self) -> Option<&mut dyn Tunable> {
        Some(self)
    }
}

impl Tunable for Friction {
    fn param_names(&self) -> Vec<String> {
        ["coulomb", "stribeck", "v_stribeck", "viscous"]
            .map(String::from)
            .to_vec()
    }
    fn params(&self) -> Vec<f64> {
        vec![self.coulomb, self.stribeck, self.v_stribeck, self.viscous]
    }
    fn set_params(&mut self, p: &[f64]) -> Result<(), ParamError> {
        check_len(p, 4, "[coulomb, stribeck, v_stribeck, viscous]")?;
        Self::check([p[0], p[1], p[2], p[3]], self.v_eps)?;
        self.coulomb = p[0];
        self.stribeck = p[1];
        self.v_stribeck = p[2];
        self.viscous = p[3];
        Ok(())
    }
}
