//! `backlash`: the play operator.

use super::{MAX_MAGNITUDE, check_bounded, check_len};
use nanomotion_core::Params;
use nanomotion_core::block::check;
use nanomotion_core::{Block, BuildContext, ParamError, Sector, Tick, Tunable, declared_block};
use serde::{Deserialize, Serialize};

/// `backlash`: PLF effect: play operator of width w: y moves only once u is w/2 past
/// it, y₀ = u₀; tunable `width`.
///
/// Play operator of width w ≥ 0. The output follows the input only
/// after the input has moved w/2 past it:
///
/// ```text
/// u − y > w/2  ⇒  y = u − w/2
/// y − u > w/2  ⇒  y = u + w/2
/// otherwise y unchanged
/// ```
///
/// starting at y = u₀ (the first input). A non-finite input passes through without
/// changing the state.
///
/// Slope range ([`Block::sector`]) [0, 1]: between two samples y moves in the
/// direction of u by at most as much as u (0 inside the play, 1 when pushed).
///
/// [`Tunable`] vector: `[width]`.
#[derive(Debug, Clone, Serialize, Deserialize, Params)]
#[serde(deny_unknown_fields)]
#[block(type_name = "backlash", role = Plant, ports = "u -> y")]
pub struct Backlash {
    /// Total play w (unit of u), ≥ 0.
    pub width: f64,
    #[serde(skip)]
    y: Option<f64>,
}

impl Backlash {
    /// Play of total width `width`.
    pub fn new(width: f64) -> Self {
        Self { width, y: None }
    }

    fn check(w: f64) -> Result<(), ParamError> {
        check::non_negative("width", w)?;
        check_bounded("width", w, MAX_MAGNITUDE)
    }
}

#[declared_block]
impl Block for Backlash {
    fn build(&mut self, _ctx: &BuildContext) -> Result<(), ParamError> {
        Self::check(self.width)?;
        self.y = None;
        Ok(())
    }
    fn output(&mut self, _tick: Tick, u: &[f64], y: &mut [f64]) {
        let u = u[0];
        if !u.is_finite() {
            y[0] = u;
            return;
        }
        let h = 0.5 * self.width;
        let mut out = self.y.unwrap_or(u);
        if u - out > h {
            out = u - h;
        } else if out - u > h {
            out = u + h;
        }
        self.y = Some(out);
        y[0] = out;
    }
    fn sector(&self) -> Option<Sector> {
        // y moves only by the part of u's move beyond the play, in u's direction.
        Some(Sector::new(
            0.0,
            1.0,
            "backlash: 0 inside the play, 1 when pushed",
        ))
    }
    fn tunable(&self) -> Option<&dyn Tunable> {
        Some(self)
    }
    fn tunable_mut(&mut self) -> Option<&mut dyn Tunable> {
        Some(self)
    }
}

impl Tunable for Backlash {
    fn param_names(&self) -> Vec<String> {
        vec!["width".into()]
    }
    fn params(&self) -> Vec<f64> {
        vec![self.width]
    }
    fn set_params(&mut self, p: &[f64]) -> Result<(), ParamError> {
        check_len(p, 1, "[width]")?;
        Self::check(p[0])?;
        self.width = p[0];
        Ok(())
    }
}
