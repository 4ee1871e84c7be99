//! `drift`: an offset that changes slowly with time.

use super::{MAX_MAGNITUDE, check_bounded, check_len};
use nanomotion_core::Params;
use nanomotion_core::{Block, BuildContext, ParamError, Tick, Tunable, declared_block};
use serde::{Deserialize, Serialize};

/// `drift`: PLF effect: y = u + offset + rate·t + curvature·t²; tunable [offset, rate,
/// curvature].
///
/// Y = u + offset + rate·t + curvature·t², t the tick time (s) — e.g. a
/// thermal drift of a sensor or a slowly moving zero of an amplifier.
///
/// [`Tunable`] vector: `[offset, rate, curvature]`.
#[derive(Debug, Clone, Serialize, Deserialize, Params)]
#[serde(deny_unknown_fields)]
#[block(type_name = "drift", role = Source, ports = "u -> y")]
pub struct Drift {
    /// Offset (\[u\]), default 0.
    #[serde(default)]
    pub offset: f64,
    /// Rate (\[u\]/s), default 0.
    #[serde(default)]
    pub rate: f64,
    /// Curvature (\[u\]/s²), default 0.
    #[serde(default)]
    pub curvature: f64,
}

impl Drift {
    /// y = u + offset + rate·t + curvature·t².
    pub fn new(offset: f64, rate: f64, curvature: f64) -> Self {
        Self {
            offset,
            rate,
            curvature,
        }
    }

    /// The drift at time `t` (s).
    pub fn at(&self, t: f64) -> f64 {
        self.offset + (self.rate + self.curvature * t) * t
    }

    fn check(p: [f64; 3]) -> Result<(), ParamError> {
        check_bounded("offset", p[0], MAX_MAGNITUDE)?;
        check_bounded("rate", p[1], MAX_MAGNITUDE)?;
        check_bounded("curvature", p[2], MAX_MAGNITUDE)
    }
}

#[declared_block]
impl Block for Drift {
    fn build(&mut self, _ctx: &BuildContext) -> Result<(), ParamError> {
        Self::check([self.offset, self.rate, self.curvature])
    }
    fn output(&mut self, tick: Tick, u: &[f64], y: &mut [f64]) {
        y[0] = u[0] + self.at(tick.t);
    }
    fn tunable(&self) -> Option<&dyn Tunable> {
        Some(self)
    }
    fn tunable_mut(&mut self) -> Option<&mut dyn Tunable> {
        Some(self)
    }
}

impl Tunable for Drift {
    fn param_names(&self) -> Vec<String> {
        ["offset", "rate", "curvature"].map(String::from).to_vec()
    }
    fn params(&self) -> Vec<f64> {
        vec![self.offset, self.rate, self.curvature]
    }
    fn set_params(&mut self, p: &[f64]) -> Result<(), ParamError> {
        check_len(p, 3, "[offset, rate, curvature]")?;
        Self::check([p[0], p[1], p[2]])?;
        self.offset = p[0];
        self.rate = p[1];
        self.curvature = p[2];
        Ok(())
    }
}
