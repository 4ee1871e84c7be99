//! `backlash_inverse`: the inverse of the play operator, placed before the
//! actuator so that the backlash the diagnosis named cancels.
//!
//! The plf `backlash` block (play of width w, starting at y = u₀) follows its
//! input only once the input has moved w/2 past its output. Its exact inverse
//! for a wanted output w_k: start at u₀ = w₀; then u = w + w/2 while the wanted
//! output rises, u = w − w/2 while it falls, and the last u while it holds — a
//! jump of the full width at every reversal. The pair is the identity (tested).

use nanomotion_core::block::Linearisation;
use nanomotion_core::lti::StateSpace;
use nanomotion_core::{Block, BuildContext, ParamError, Params, Tick, declared_block};
use serde::{Deserialize, Serialize};

/// `backlash_inverse`: inverse of the play operator (backlash) of width w: the
/// wanted output ± w/2 by its direction, held while it holds; before the actuator.
/// Input `u`: the wanted output; output `y`: the input to give the play.
///
/// u = P⁻¹(w) for the play operator P of total width `width`; the ports are
/// those of an effect block.
#[derive(Debug, Clone, Serialize, Deserialize, Params)]
#[serde(deny_unknown_fields)]
#[block(type_name = "backlash_inverse", role = Controller, ports = "u -> y")]
pub struct BacklashInverse {
    /// Total play w (unit of the signal).
    #[param(non_negative)]
    pub width: f64,
    /// (last wanted output, last input given), after the first sample.
    #[serde(skip)]
    last: Option<(f64, f64)>,
}

impl BacklashInverse {
    /// The inverse of a play of total width `width`.
    pub fn new(width: f64) -> Self {
        Self { width, last: None }
    }

    /// One sample. No allocation.
    pub fn step(&mut self, w: f64) -> f64 {
        if !w.is_finite() {
            return self.last.map_or(0.0, |(_, u)| u);
        }
        let h = 0.5 * self.width;
        let u = match self.last {
            None => w,
            Some((prev, u)) if w == prev => u,
            Some((prev, _)) if w > prev => w + h,
            Some(_) => w - h,
        };
        self.last = Some((w, u));
        u
    }
}

#[declared_block]
impl Block for BacklashInverse {
    fn build(&mut self, _ctx: &BuildContext) -> Result<(), ParamError> {
        self.check_params()?;
        self.last = None;
        Ok(())
    }
    fn output(&mut self, _tick: Tick, u: &[f64], y: &mut [f64]) {
        y[0] = self.step(u[0]);
    }
    /// Gain 1 between the jumps at the reversals.
    fn linearisation(&self) -> Option<Linearisation> {
        Some(Linearisation::single(
            StateSpace::gain(nalgebra::DMatrix::identity(1, 1), None),
            format!(
                "backlash inverse judged as gain 1 (it adds ±{} at the reversals)",
                0.5 * self.width
            ),
        ))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use nanomotion_core::Role;
    use nanomotion_plf::effects::Backlash;

    /// P(P⁻¹(w)) = w with the plf `backlash` block (the operator the diagnosis
    /// fits), for a wanted output with reversals and holds.
    #[test]
    fn the_inverse_cancels_the_play() {
        let worst = crate::worst_of_pair(
            &mut BacklashInverse::new(0.4),
            &mut Backlash::new(0.4),
            5000,
            |_, t| {
                (2.0 * std::f64::consts::PI * 0.7 * t)
                    .sin()
                    .clamp(-0.8, 0.8)
                    + 0.2 * (2.0 * std::f64::consts::PI * 3.1 * t).sin()
            },
        );
        assert!(worst < 1e-12, "{worst:e}");
    }

    /// One declaration: the bound on `width` refuses a negative or non-finite
    /// play by name when the block is built, and is what `nanomotion blocks` and
    /// the schema show.
    #[test]
    fn a_negative_or_non_finite_width_is_refused_by_name() {
        let ctx = BuildContext::new("b", 1e-3, 0);
        for w in [-0.1, f64::NAN, f64::INFINITY] {
            let e = BacklashInverse::new(w).build(&ctx).unwrap_err();
            assert_eq!(e.field, "width", "{w}: {e}");
        }
        BacklashInverse::new(0.0).build(&ctx).unwrap();
        let doc = nanomotion_core::block::block_docs()
            .into_iter()
            .find(|d| d.type_name == "backlash_inverse")
            .expect("registered");
        let params = doc.param_docs();
        assert_eq!(params.len(), 1);
        assert_eq!(params[0].name, "width");
        assert_eq!(params[0].bounds, ["≥ 0"]);
        assert!(params[0].required);
        assert_eq!(params[0].schema["minimum"], 0);
        assert!(doc.closed);
        assert_eq!(doc.role, Role::Controller);
    }

    #[test]
    fn ticks_do_not_allocate() {
        let mut inv = BacklashInverse::new(0.1);
        inv.build(&BuildContext::new("b", 1e-3, 0)).unwrap();
        let mut y = [0.0];
        let info = allocation_counter::measure(|| {
            for k in 0..10_000u64 {
                inv.output(Tick::new(k, 1e-3), &[(k as f64 * 1e-2).sin()], &mut y);
            }
        });
        assert_eq!(info.count_total, 0);
    }
}
