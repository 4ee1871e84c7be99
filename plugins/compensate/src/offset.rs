//! `drive_offset`: a constant added to the drive — the feed-forward of a
//! drive's zero that is off (a `drift` the diagnosis fitted on the drive:
//! the offset o, set back by adding −o before the actuator).

use nanomotion_core::block::Linearisation;
use nanomotion_core::lti::StateSpace;
use nanomotion_core::{Block, Params, Tick, declared_block};
use serde::{Deserialize, Serialize};

/// `drive_offset`: y = u + offset, a constant added to the drive (the
/// feed-forward that sets back a drive's zero). Input `u`: the drive asked for;
/// output `y`: the drive given, in the unit of `u`.
///
/// `u` is the drive the controller asks for, `y` the drive given to the
/// actuator: the ports of an effect block.
#[derive(Debug, Clone, Serialize, Deserialize, Params)]
#[serde(deny_unknown_fields)]
#[block(type_name = "drive_offset", role = Controller, ports = "u -> y [unit of u]")]
pub struct DriveOffset {
    /// The constant added (unit of the drive).
    #[param(finite)]
    pub offset: f64,
}

impl DriveOffset {
    /// y = u + `offset`.
    pub fn new(offset: f64) -> Self {
        Self { offset }
    }
}

#[declared_block]
impl Block for DriveOffset {
    fn output(&mut self, _tick: Tick, u: &[f64], y: &mut [f64]) {
        y[0] = u[0] + self.offset;
    }
    /// Gain 1: a constant added changes no loop's stability.
    fn linearisation(&self) -> Option<Linearisation> {
        Some(Linearisation::single(
            StateSpace::gain(nalgebra::DMatrix::identity(1, 1), None),
            format!(
                "drive offset judged as gain 1 (it adds the constant {:e})",
                self.offset
            ),
        ))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use nanomotion_core::BuildContext;
    use nanomotion_plf::effects::Drift;

    /// The fitted drift of the drive (plf's `drift`, rate and curvature 0)
    /// after its feed-forward is the identity to round-off.
    #[test]
    fn the_feed_forward_cancels_the_drive_s_offset() {
        let o = 0.37;
        let worst = crate::worst_of_pair(
            &mut DriveOffset::new(-o),
            &mut Drift::new(o, 0.0, 0.0),
            5000,
            |_, t| (2.0 * std::f64::consts::PI * 0.7 * t).sin(),
        );
        assert!(worst < 1e-15, "{worst:e}");
    }

    #[test]
    fn a_non_finite_offset_is_refused_by_name_and_the_tick_does_not_allocate() {
        let ctx = BuildContext::new("b", 1e-3, 0);
        for o in [f64::NAN, f64::INFINITY] {
            assert_eq!(DriveOffset::new(o).build(&ctx).unwrap_err().field, "offset");
        }
        let mut b = DriveOffset::new(0.1);
        b.build(&ctx).unwrap();
        let mut y = [0.0];
        let info = allocation_counter::measure(|| {
            for k in 0..10_000u64 {
                b.output(Tick::new(k, 1e-3), &[(k as f64 * 1e-2).sin()], &mut y);
            }
        });
        assert_eq!(info.count_total, 0);
    }
}
