//! `hysteresis`: the Coleman–Hodgdon operator y = H(u) (Merry 2009, Sec. 6.3, (6.3)),
//! the core's [`ColemanHodgdon`] model as an effect block.

use super::check_len;
use nanomotion_core::Params;
use nanomotion_core::models::hysteresis::{ChParams, ColemanHodgdon};
use nanomotion_core::{Block, BuildContext, ParamError, Sector, Tick, Tunable, declared_block};
use serde::{Deserialize, Serialize};

/// `hysteresis`: PLF effect: Coleman–Hodgdon hysteresis dy/dt = α|u̇|(b·u − y) + c·u̇
/// (6.3), exact per sample, starts at y = b·u₀; tunable [alpha, b, c(, retrace.*)].
///
/// Dy/dt = α|u̇|(b·u − y) + c·u̇, integrated exactly per sample
/// ([`ColemanHodgdon::step`]); with `retrace` set, that parameter set is used
/// for decreasing u (asymmetric model). The state starts on the anhysteretic line at
/// the first input, y₀ = b·u₀ (b of the trace set). A non-finite input holds the
/// output.
///
/// Slope range ([`Block::sector`]): [min(2c − b, b), max(2c − b, b)] for the
/// symmetric model; with `retrace` see [`ColemanHodgdon::sector`] (none when the
/// two b differ).
///
/// [`Tunable`] vector: `[alpha, b, c]`, followed by
/// `[retrace.alpha, retrace.b, retrace.c]` when `retrace` is set.
#[derive(Debug, Clone, Serialize, Deserialize, Params)]
#[serde(deny_unknown_fields)]
#[block(type_name = "hysteresis", role = Actuator, ports = "u -> y")]
pub struct Hysteresis {
    /// α (1/\[u\]) > 0: how fast y returns to the anhysteretic line after a reversal.
    /// Table 6.2: 0.03 1/V.
    pub alpha: f64,
    /// b (\[y\]/\[u\]): slope of the anhysteretic line y = b·u.
    /// Table 6.2: ~1 µm/V.
    pub b: f64,
    /// c (\[y\]/\[u\]): slope right after a reversal (the thesis's u in (6.3)).
    /// ~0.7 µm/V.
    pub c: f64,
    /// Parameters for decreasing u (default: the same as for increasing u).
    /// {alpha, b, c} (asymmetric model).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    #[param(default_doc = "= trace")]
    pub retrace: Option<ChParams>,
    #[serde(skip)]
    h: Option<ColemanHodgdon>,
    #[serde(skip)]
    started: bool,
}

impl Hysteresis {
    /// A symmetric model with α, b, c.
    pub fn new(alpha: f64, b: f64, c: f64) -> Self {
        Self {
            alpha,
            b,
            c,
            retrace: None,
            h: None,
            started: false,
        }
    }

    /// The same model with a separate retrace set (asymmetric).
    pub fn with_retrace(mut self, retrace: ChParams) -> Self {
        self.retrace = Some(retrace);
        self
    }

    /// The trace (increasing u) parameter set.
    pub fn trace(&self) -> ChParams {
        ChParams::new(self.alpha, self.b, self.c)
    }

    fn model(trace: ChParams, retrace: Option<ChParams>) -> Result<ColemanHodgdon, ParamError> {
        trace.validate("")?;
        if let Some(r) = retrace {
            r.validate("retrace.")?;
        }
        ColemanHodgdon::new(trace, retrace.unwrap_or(trace))
    }
}

#[declared_block]
impl Block for Hysteresis {
    fn build(&mut self, _ctx: &BuildContext) -> Result<(), ParamError> {
        self.h = Some(Self::model(self.trace(), self.retrace)?);
        self.started = false;
        Ok(())
    }
    fn output(&mut self, _tick: Tick, u: &[f64], y: &mut [f64]) {
        let Some(h) = self.h.as_mut() else {
            y[0] = 0.0;
            return;
        };
        let u = u[0];
        if !u.is_finite() {
            y[0] = h.position();
            return;
        }
        if !self.started {
            h.reset(self.b * u, u);
            self.started = true;
        }
        y[0] = h.step(u);
    }
    fn sector(&self) -> Option<Sector> {
        // The model's range from its built state (y = 0 at u = 0, then y₀ = b·u₀:
        // both on the anhysteretic line).
        self.h.as_ref()?.sector()
    }
    fn tunable(&self) -> Option<&dyn Tunable> {
        Some(self)
    }
    fn tunable_mut(&mut self) -> Option<&mut dyn Tunable> {
        Some(self)
    }
}

impl Tunable for Hysteresis {
    fn param_names(&self) -> Vec<String> {
        let mut v: Vec<String> = ChParams::NAMES.iter().map(|s| s.to_string()).collect();
        if self.retrace.is_some() {
            v.extend(ChParams::NAMES.iter().map(|s| format!("retrace.{s}")));
        }
        v
    }
    fn params(&self) -> Vec<f64> {
        let mut v = self.trace().to_array().to_vec();
        if let Some(r) = self.retrace {
            v.extend(r.to_array());
        }
        v
    }
    fn set_params(&mut self, p: &[f64]) -> Result<(), ParamError> {
        if self.retrace.is_some() {
            check_len(p, 6, "[alpha, b, c, retrace.alpha, retrace.b, retrace.c]")?;
        } else {
            check_len(p, 3, "[alpha, b, c]")?;
        }
        let trace = ChParams::new(p[0], p[1], p[2]);
        let retrace = self.retrace.map(|_| ChParams::new(p[3], p[4], p[5]));
        Self::model(trace, retrace)?;
        self.alpha = trace.alpha;
        self.b = trace.b;
        self.c = trace.c;
        self.retrace = retrace;
        Ok(())
    }
}
