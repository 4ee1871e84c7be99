//! The coordinate rotation of DRC, (7.17) and Fig. 7.11.
//!
//! A sample rotated by α about z has its own axes (x_r, y_r); the actuators move
//! along (x_a, y_a). (7.17):
//!
//! ```text
//!   [x_r]   [ cos α  sin α  0] [x_a]
//!   [y_r] = [−sin α  cos α  0] [y_a]      R(α), RᵀR = I
//!   [z_r]   [   0      0    1] [z_a]
//! ```
//!
//! DRC (Fig. 7.11) plans the scan in the sample frame (fast axis along y_r, so the
//! topography is the same on every line) and maps it to the actuators with Rᵀ;
//! the measured errors go back into the sample frame with R, where the controllers
//! (and RC) act, and their outputs go to the actuators with Rᵀ. z is untouched.
//!
//! [`FrameRotation`] (`frame_rotation`) is that map for a 2- or 3-vector, with
//! `glam`'s f64 2×2 matrix built once at build time; a tick is one matrix–vector
//! product (no trigonometry, no allocation).
//!
//! ```
//! use nanomotion_directional_rc::frame::{FrameRotation, Direction};
//! let to_s = FrameRotation::new(0.022, Direction::ToSample, 2);
//! let to_a = FrameRotation::new(0.022, Direction::ToActuator, 2);
//! let a = [3e-6, -20e-6];
//! let r = to_s.apply(a);
//! // (7.17) written out.
//! let (s, c) = 0.022f64.sin_cos();
//! assert!((r[0] - (c * a[0] + s * a[1])).abs() < 1e-21);
//! assert!((r[1] - (-s * a[0] + c * a[1])).abs() < 1e-21);
//! // Rᵀ R = I.
//! let back = to_a.apply(r);
//! assert!((back[0] - a[0]).abs() < 1e-20 && (back[1] - a[1]).abs() < 1e-20);
//! ```

use glam::{DMat2, DVec2};
use nanomotion_core::Params;
use nanomotion_core::{Block, BuildContext, ParamError, Port, Tick, declared_block};
use serde::{Deserialize, Serialize};

/// Which way [`FrameRotation`] maps.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, Params)]
#[serde(rename_all = "snake_case")]
pub enum Direction {
    /// Actuator → sample frame: R(α) of (7.17) (errors into the controller frame).
    ToSample,
    /// Sample → actuator frame: R(α)ᵀ (scan references, controller outputs).
    ToActuator,
}

fn two() -> usize {
    2
}

/// R(α) of (7.17) as a glam matrix (columns: images of the unit x_a and y_a).
pub fn rotation(alpha_rad: f64) -> DMat2 {
    let (s, c) = alpha_rad.sin_cos();
    DMat2::from_cols(DVec2::new(c, -s), DVec2::new(s, c))
}

/// `frame_rotation`: DRC coordinate rotation (7.17): in-plane (x, y) by R(α)
/// (to_sample) or R(α)ᵀ (to_actuator); z passes.
///
/// Maps the in-plane part (x, y) of `u` between the actuator and
/// the sample frame by R(α) or R(α)ᵀ (7.17); a third component (z) passes
/// unchanged. See the [module docs](self).
#[derive(Debug, Clone, Serialize, Deserialize, Params)]
#[serde(deny_unknown_fields)]
#[block(type_name = "frame_rotation", role = Controller, ports = "u[width] (, alpha with alpha_input) -> y[width]")]
pub struct FrameRotation {
    /// Sample rotation α about z (rad), e.g. from
    /// [`estimate_rotation`](crate::estimate::estimate_rotation). Default 0; must
    /// stay 0 with `alpha_input`.
    #[serde(default)]
    #[param(finite)]
    pub alpha_rad: f64,
    /// Take α from an input port `alpha` (e.g. a `rotation_estimator`) instead of
    /// `alpha_rad`. The matrix is recomputed only when the value changes.
    #[serde(default)]
    pub alpha_input: bool,
    /// `to_sample` (R) or `to_actuator` (Rᵀ).
    /// R brings errors into the controller frame; Rᵀ takes references and controller
    /// outputs to the actuators.
    pub direction: Direction,
    /// Width of `u` and `y`: 2 (x, y) or 3 (x, y, z). Default 2.
    #[serde(default = "two")]
    #[param(size(2, 3))]
    pub width: usize,
    #[serde(skip)]
    m: Option<DMat2>,
    /// The α (bits) `m` was computed for, with `alpha_input`.
    #[serde(skip)]
    alpha_bits: u64,
}

impl FrameRotation {
    /// A built rotation by `alpha_rad` in `direction` for vectors of `width` (2 or 3).
    pub fn new(alpha_rad: f64, direction: Direction, width: usize) -> Self {
        let mut f = Self {
            alpha_rad,
            alpha_input: false,
            direction,
            width,
            m: None,
            alpha_bits: alpha_rad.to_bits(),
        };
        f.m = Some(f.matrix());
        f
    }

    /// The 2×2 matrix applied: R(α) or R(α)ᵀ.
    pub fn matrix(&self) -> DMat2 {
        self.matrix_for(self.alpha_rad)
    }

    fn matrix_for(&self, alpha_rad: f64) -> DMat2 {
        let r = rotation(alpha_rad);
        match self.direction {
            Direction::ToSample => r,
            Direction::ToActuator => r.transpose(),
        }
    }

    /// Map one in-plane vector \[x, y\].
    #[inline]
    pub fn apply(&self, v: [f64; 2]) -> [f64; 2] {
        let m = self.m.unwrap_or_else(|| self.matrix());
        (m * DVec2::from_array(v)).to_array()
    }
}

#[declared_block]
impl Block for FrameRotation {
    fn inputs(&self) -> Vec<Port> {
        if self.alpha_input {
            vec![Port::new("u", self.width), Port::new("alpha", 1)]
        } else {
            vec![Port::new("u", self.width)]
        }
    }
    fn outputs(&self) -> Vec<Port> {
        vec![Port::new("y", self.width)]
    }
    fn build(&mut self, _ctx: &BuildContext) -> Result<(), ParamError> {
        self.check_params()?;
        if self.alpha_input && self.alpha_rad != 0.0 {
            return Err(ParamError::new(
                "alpha_rad",
                format!("is {} with alpha_input: true", self.alpha_rad),
                "give either alpha_rad or alpha_input: true (α from the `alpha` port), not both",
            ));
        }
        if self.alpha_rad.abs() > std::f64::consts::FRAC_PI_4 {
            tracing::warn!(
                alpha_rad = self.alpha_rad,
                "frame_rotation: |α| > π/4 — a sample rotation this large swaps the roles of the scan axes; check the sign and unit (rad)"
            );
        }
        self.m = Some(self.matrix());
        self.alpha_bits = self.alpha_rad.to_bits();
        Ok(())
    }
    #[inline]
    fn output(&mut self, _tick: Tick, u: &[f64], y: &mut [f64]) {
        if self.alpha_input {
            // α from the port: new trigonometry only when it changes.
            let a = u[self.width];
            if a.to_bits() != self.alpha_bits || self.m.is_none() {
                self.alpha_bits = a.to_bits();
                self.m = Some(self.matrix_for(a));
            }
        }
        let m = match self.m {
            Some(m) => m,
            None => self.matrix(),
        };
        let v = m * DVec2::new(u[0], u[1]);
        y[0] = v.x;
        y[1] = v.y;
        if self.width == 3 {
            y[2] = u[2];
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn rotation_is_orthonormal_and_matches_7_17() {
        for a in [-0.05, 0.0, 0.015, 0.022, 1.0] {
            let r = rotation(a);
            let i = r.transpose() * r;
            assert!((i - DMat2::IDENTITY).abs_diff_eq(DMat2::ZERO, 1e-15));
            assert!((r.determinant() - 1.0).abs() < 1e-15);
            // A point on the sample's x_r axis, seen from the actuators, is at angle α.
            let p = rotation(a).transpose() * DVec2::X;
            assert!((p.y.atan2(p.x) - a).abs() < 1e-15);
        }
    }

    #[test]
    fn block_maps_and_passes_z() {
        let mut b: Box<dyn Block> = nanomotion_core::yaml::from_str(
            "type: frame_rotation\nalpha_rad: 0.3\ndirection: to_actuator\nwidth: 3\n",
            "t",
        )
        .unwrap();
        b.build(&BuildContext::new("r", 1e-3, 0)).unwrap();
        let mut y = [0.0; 3];
        b.output(Tick::new(0, 1e-3), &[1.0, 0.0, 7.0], &mut y);
        let (s, c) = 0.3f64.sin_cos();
        // Rᵀ e_x = first row of R = (c, s).
        assert!((y[0] - c).abs() < 1e-15 && (y[1] - s).abs() < 1e-15);
        assert_eq!(y[2], 7.0);
    }

    #[test]
    fn alpha_from_the_port_equals_the_parameter() {
        let mut a: Box<dyn Block> = nanomotion_core::yaml::from_str(
            "type: frame_rotation\nalpha_input: true\ndirection: to_sample\n",
            "t",
        )
        .unwrap();
        a.build(&BuildContext::new("r", 1e-3, 0)).unwrap();
        assert_eq!(a.inputs().len(), 2);
        let mut y = [0.0; 2];
        // α = 0 first: identity; then 0.022: as the fixed-α block.
        a.output(Tick::new(0, 1e-3), &[1.5, -2.0, 0.0], &mut y);
        assert_eq!(y, [1.5, -2.0]);
        let mut fixed = FrameRotation::new(0.022, Direction::ToSample, 2);
        let mut yf = [0.0; 2];
        fixed.output(Tick::new(0, 1e-3), &[1.5, -2.0], &mut yf);
        a.output(Tick::new(1, 1e-3), &[1.5, -2.0, 0.022], &mut y);
        assert_eq!(y, yf);
        let mut b: Box<dyn Block> = nanomotion_core::yaml::from_str(
            "type: frame_rotation\nalpha_input: true\nalpha_rad: 0.1\ndirection: to_sample\n",
            "t",
        )
        .unwrap();
        assert_eq!(
            b.build(&BuildContext::new("r", 1e-3, 0)).unwrap_err().field,
            "alpha_rad"
        );
    }

    #[test]
    fn bad_parameters_name_the_field() {
        for (yaml, field) in [
            (
                "type: frame_rotation\nalpha_rad: .nan\ndirection: to_sample\n",
                "alpha_rad",
            ),
            (
                "type: frame_rotation\nalpha_rad: 0.1\ndirection: to_sample\nwidth: 4\n",
                "width",
            ),
        ] {
            let Ok(mut b) = nanomotion_core::yaml::from_str::<Box<dyn Block>>(yaml, "t") else {
                // Non-finite numbers may already be refused by the loader.
                assert_eq!(field, "alpha_rad");
                continue;
            };
            let e = b.build(&BuildContext::new("r", 1e-3, 0)).unwrap_err();
            assert_eq!(e.field, field);
        }
        // width 3 (x, y, z) builds; 1 is refused like 4
        let mut f = FrameRotation::new(0.1, Direction::ToSample, 3);
        f.build(&BuildContext::new("r", 1e-3, 0)).unwrap();
        let e = FrameRotation::new(0.1, Direction::ToSample, 1)
            .build(&BuildContext::new("r", 1e-3, 0))
            .unwrap_err();
        assert_eq!(e.field, "width");
        assert!(e.to_string().contains("[2, 3]"), "{e}");
        // the same declaration bounds the schema (editors refuse width 4)
        let docs = FrameRotation::param_docs();
        let width = docs.iter().find(|p| p.name == "width").unwrap();
        assert_eq!(width.schema["minimum"], 2);
        assert_eq!(width.schema["maximum"], 3);
        assert_eq!(width.bounds, ["2 to 3"]);
        assert!(
            nanomotion_core::yaml::from_str::<Box<dyn Block>>(
                "type: frame_rotation\nalpha_rad: 0.1\ndirection: sideways\n",
                "t"
            )
            .is_err()
        );
    }
}
