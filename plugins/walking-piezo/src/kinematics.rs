//! Leg kinematics (4.2): the static map from the four stack voltages to the tip
//! positions of the two leg pairs, with one coefficient per stack (unequal pairs are
//! the realistic case, Table 4.1):
//!
//! x_p1 = c_x1 u1 − c_x2 u2,  y_p1 = c_y1 u1 + c_y2 u2,
//! x_p2 = c_x3 u3 − c_x4 u4,  y_p2 = c_y3 u3 + c_y4 u4.
//!
//! With equal coefficients this is (2.1)/(4.1). Pair p1 = legs {A, D} is driven by
//! u1, u2 and pair p2 = {B, C} by u3, u4.

use nalgebra::DMatrix;
use nanomotion_core::Params;
use nanomotion_core::block::check;
use nanomotion_core::lti::StateSpace;
use nanomotion_core::{Block, BuildContext, ParamError, Tick, declared_block};
use serde::{Deserialize, Serialize};

/// Bending coefficient c_x of the Ch. 5 motor (m/V).
pub const C_X_M_PER_V: f64 = 64.5e-9;
/// Extension coefficient c_y of the Ch. 5 motor (m/V).
pub const C_Y_M_PER_V: f64 = 29.8e-9;

/// Per-stack bending and extension coefficients of (4.2).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize, Params)]
#[serde(default, deny_unknown_fields)]
pub struct LegKinematics {
    /// Bending coefficients c_x1..c_x4 (m/V); default 64.5 nm/V each (Ch. 5).
    pub c_x_m_v: [f64; 4],
    /// Extension coefficients c_y1..c_y4 (m/V); default 29.8 nm/V each (Ch. 5).
    pub c_y_m_v: [f64; 4],
}

impl Default for LegKinematics {
    fn default() -> Self {
        Self {
            c_x_m_v: [C_X_M_PER_V; 4],
            c_y_m_v: [C_Y_M_PER_V; 4],
        }
    }
}

/// Tip positions of the two leg pairs (m).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct LegTips {
    /// x_p1, x_p2: bending (drive direction).
    pub x: [f64; 2],
    /// y_p1, y_p2: extension (towards the drive strip).
    pub y: [f64; 2],
}

impl LegKinematics {
    /// The same coefficients for all four stacks (2.1).
    pub fn uniform(c_x_m_v: f64, c_y_m_v: f64) -> Self {
        Self {
            c_x_m_v: [c_x_m_v; 4],
            c_y_m_v: [c_y_m_v; 4],
        }
    }

    /// Check the coefficients: finite and positive.
    pub fn validate(&self) -> Result<(), ParamError> {
        for i in 0..4 {
            check::positive(&format!("c_x_m_v[{i}]"), self.c_x_m_v[i])?;
            check::positive(&format!("c_y_m_v[{i}]"), self.c_y_m_v[i])?;
        }
        Ok(())
    }

    /// Free (unloaded) tip positions for voltages `u` = [u1, u2, u3, u4] (V), (4.2).
    ///
    /// ```
    /// use walking_piezo::LegKinematics;
    /// let k = LegKinematics::uniform(64.5e-9, 29.8e-9);
    /// let t = k.tips(&[46.0, 0.0, 0.0, 46.0]);
    /// assert!((t.x[0] - 46.0 * 64.5e-9).abs() < 1e-18);
    /// assert!((t.x[1] + 46.0 * 64.5e-9).abs() < 1e-18);
    /// assert!((t.y[0] - t.y[1]).abs() < 1e-18);
    /// ```
    pub fn tips(&self, u: &[f64; 4]) -> LegTips {
        let (cx, cy) = (&self.c_x_m_v, &self.c_y_m_v);
        LegTips {
            x: [cx[0] * u[0] - cx[1] * u[1], cx[2] * u[2] - cx[3] * u[3]],
            y: [cy[0] * u[0] + cy[1] * u[1], cy[2] * u[2] + cy[3] * u[3]],
        }
    }

    /// The map as a 4×4 matrix from (u1..u4) to (x_p1, x_p2, y_p1, y_p2).
    pub fn matrix(&self) -> DMatrix<f64> {
        let (cx, cy) = (&self.c_x_m_v, &self.c_y_m_v);
        DMatrix::from_row_slice(
            4,
            4,
            &[
                cx[0], -cx[1], 0.0, 0.0, //
                0.0, 0.0, cx[2], -cx[3], //
                cy[0], cy[1], 0.0, 0.0, //
                0.0, 0.0, cy[2], cy[3],
            ],
        )
    }
}

/// `walking_piezo_legs`: walking piezo leg kinematics (4.2): four stack voltages to the
/// two pairs' free tip positions.
///
/// Graph block `walking_piezo_legs`: u (4 V) → x_p (2, m), y_p (2, m), the static
/// map (4.2).
#[derive(Debug, Clone, Default, Serialize, Deserialize, Params)]
#[serde(transparent)]
#[block(type_name = "walking_piezo_legs", role = Math, ports = "u[4] (V) -> x_p[2] (m), y_p[2] (m)")]
pub struct LegKinematicsBlock {
    /// The coefficients.
    pub kinematics: LegKinematics,
    #[serde(skip)]
    dt: f64,
}

#[declared_block]
impl Block for LegKinematicsBlock {
    fn build(&mut self, ctx: &BuildContext) -> Result<(), ParamError> {
        self.kinematics.validate()?;
        self.dt = ctx.dt;
        Ok(())
    }
    fn output(&mut self, _tick: Tick, u: &[f64], y: &mut [f64]) {
        let t = self.kinematics.tips(&[u[0], u[1], u[2], u[3]]);
        y[..2].copy_from_slice(&t.x);
        y[2..4].copy_from_slice(&t.y);
    }
    fn lti(&self) -> Option<StateSpace> {
        Some(StateSpace::gain(self.kinematics.matrix(), Some(self.dt)))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn per_stack_coefficients_enter_where_they_should() {
        let k = LegKinematics {
            c_x_m_v: [1.0, 2.0, 3.0, 4.0],
            c_y_m_v: [5.0, 6.0, 7.0, 8.0],
        };
        let t = k.tips(&[1.0, 10.0, 100.0, 1000.0]);
        assert_eq!(t.x, [1.0 - 20.0, 300.0 - 4000.0]);
        assert_eq!(t.y, [5.0 + 60.0, 700.0 + 8000.0]);
        let m = k.matrix();
        let v = m * nalgebra::DVector::from_vec(vec![1.0, 10.0, 100.0, 1000.0]);
        assert_eq!(v.as_slice(), &[t.x[0], t.x[1], t.y[0], t.y[1]]);
    }

    #[test]
    fn sinusoidal_waveforms_give_the_4_um_step() {
        // (2.2) with A = 46 V, φ = 0: u1 − u2 has amplitude A/√2·... the stroke of x_p1
        // is c_x·A·√2 ≈ 4.2 µm ("maximum step size 4 µm", Sec. 2.2).
        let k = LegKinematics::default();
        let a = 46.0;
        let (mut lo, mut hi) = (f64::MAX, f64::MIN);
        for i in 0..3600 {
            let al = i as f64 * std::f64::consts::TAU / 3600.0;
            let u1 = a / 2.0 * al.sin() + a / 2.0;
            let u2 = a / 2.0 * (al + std::f64::consts::FRAC_PI_2).sin() + a / 2.0;
            let x = k.tips(&[u1, u2, 0.0, 0.0]).x[0];
            lo = lo.min(x);
            hi = hi.max(x);
        }
        let expect = C_X_M_PER_V * a * 2f64.sqrt();
        assert!(((hi - lo) - expect).abs() < 1e-11, "{}", hi - lo);
    }

    #[test]
    fn bad_coefficients_name_the_stack() {
        let mut k = LegKinematics::default();
        k.c_y_m_v[2] = -1.0;
        assert_eq!(k.validate().unwrap_err().field, "c_y_m_v[2]");
    }
}
