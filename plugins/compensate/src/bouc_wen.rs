//! `bouc_wen_inverse`: the exact inverse of the Bouc–Wen operator, placed before
//! the actuator so that a Bouc–Wen hysteresis the diagnosis named on the drive
//! cancels.
//!
//! The plf `bouc_wen` block is y = linear·u + z with ż = a·u̇ − β|u̇|z − γ·u̇|z|
//! (ν = 1), z(0) = 0, advanced exactly per sample ([`BoucWen::advance`]). From the
//! state (u_p, z_p) of the last sample, the output for the next input u is
//! g(u) = linear·u + advance(z_p, u − u_p), and its slope is linear + dz/du, with
//! dz/du inside the bounds [lo, hi] of [`BoucWen::z_slopes`] (the loop never leaves
//! |z| ≤ a/(β + γ) from inside). Where linear + lo > 0 the map is strictly
//! increasing, so each wanted output w has exactly one drive u, between
//! u_p + Δ/(linear + hi) and u_p + Δ/(linear + lo), Δ = w − g(u_p); the block
//! finds it by bisection to the last bit, then advances z with that u as the
//! operator will. Fed into a `bouc_wen` block with the same parameters, the pair
//! is the identity to rounding (tested). A loop whose slope can reach 0 (a
//! saturating loop with no linear part) has no inverse: refused at build.

use nanomotion_core::block::Linearisation;
use nanomotion_core::lti::StateSpace;
use nanomotion_core::{Block, BuildContext, ParamError, Params, Tick, declared_block};
use nanomotion_plf::effects::BoucWen;
use serde::{Deserialize, Serialize};

/// `bouc_wen_inverse`: inverse of the Bouc–Wen operator y = linear·u + z (ν = 1):
/// for each wanted output the drive that gives it; before the actuator. Input
/// `u`: the wanted output; output `y`: the drive to give the operator.
///
/// u = BW⁻¹(w) for the plf `bouc_wen` block with the same parameters. Needs a
/// loop whose slope linear + dz/du stays positive.
#[derive(Debug, Clone, Serialize, Deserialize, Params)]
#[serde(deny_unknown_fields)]
#[block(type_name = "bouc_wen_inverse", role = Controller, ports = "u -> y")]
pub struct BoucWenInverse {
    /// a of the operator: slope of z right after a reversal.
    #[param(finite)]
    pub a: f64,
    /// β of the operator (≥ 0).
    #[param(non_negative)]
    pub beta: f64,
    /// γ of the operator.
    #[param(finite)]
    pub gamma: f64,
    /// Linear part of the operator's output.
    #[param(finite)]
    pub linear: f64,
    /// (last drive, z after it), after the first sample.
    #[serde(skip)]
    state: Option<(f64, f64)>,
    /// The operator whose exact per-sample integration is inverted.
    #[serde(skip)]
    op: Option<BoucWen>,
    /// Bounds of the operator's slope linear + dz/du.
    #[serde(skip)]
    slopes: (f64, f64),
}

impl BoucWenInverse {
    /// The inverse of `bouc_wen` with parameters (a, β, γ, linear).
    pub fn new(a: f64, beta: f64, gamma: f64, linear: f64) -> Self {
        Self {
            a,
            beta,
            gamma,
            linear,
            state: None,
            op: None,
            slopes: (f64::NAN, f64::NAN),
        }
    }

    /// The bounds (m, M) of the operator's slope linear + dz/du, or why it has
    /// no inverse (its slope can reach 0 or is unbounded).
    pub fn slope_bounds(&self) -> Result<(f64, f64), String> {
        let Some((lo, hi)) = BoucWen::z_slopes(self.a, self.beta, self.gamma, 0.0) else {
            return Err(format!(
                "the loop does not saturate (a = {:e}, β + γ = {:e}): dz/du has no bound",
                self.a,
                self.beta + self.gamma
            ));
        };
        let (m, big_m) = (self.linear + lo, self.linear + hi);
        if m > 0.0 && big_m.is_finite() {
            Ok((m, big_m))
        } else {
            Err(format!(
                "its slope linear + dz/du reaches {m:e} ≤ 0 (linear = {:e}, dz/du down to {lo:e}): a wanted output beyond the saturated loop has no drive",
                self.linear
            ))
        }
    }

    /// One sample: the drive for the wanted output `w`. No allocation.
    pub fn step(&mut self, w: f64) -> f64 {
        let Some(op) = &self.op else { return 0.0 };
        if !w.is_finite() {
            return self.state.map_or(0.0, |(u, _)| u);
        }
        let (up, zp) = match self.state {
            // The operator's first sample: z = 0, no advance.
            None => {
                let u = w / self.linear;
                self.state = Some((u, 0.0));
                return u;
            }
            Some(s) => s,
        };
        let g = |u: f64| self.linear * u + op.advance(zp, u - up);
        let delta = w - (self.linear * up + zp);
        if delta == 0.0 {
            return up;
        }
        let (m, big_m) = self.slopes;
        // The root lies between the steps of the steepest and the flattest
        // slope; the map is increasing, so bisect on its sign.
        let (mut lo, mut hi) = {
            let (a, b) = (up + delta / big_m, up + delta / m);
            (a.min(b), a.max(b))
        };
        for _ in 0..200 {
            let mid = 0.5 * (lo + hi);
            if mid <= lo || mid >= hi {
                break;
            }
            if g(mid) < w {
                lo = mid;
            } else {
                hi = mid;
            }
        }
        let u = if (g(lo) - w).abs() <= (g(hi) - w).abs() {
            lo
        } else {
            hi
        };
        self.state = Some((u, op.advance(zp, u - up)));
        u
    }
}

#[declared_block]
impl Block for BoucWenInverse {
    fn build(&mut self, _ctx: &BuildContext) -> Result<(), ParamError> {
        self.check_params()?;
        self.slopes = self.slope_bounds().map_err(|why| {
            ParamError::new(
                "linear",
                format!("the Bouc–Wen loop is not invertible: {why}"),
                "only a loop with a linear part steeper than its steepest falling dz/du has an inverse; compensate it in the loop instead",
            )
        })?;
        let mut op = BoucWen::new(self.a, self.beta, self.gamma);
        op.linear = self.linear;
        self.op = Some(op);
        self.state = None;
        Ok(())
    }
    fn output(&mut self, _tick: Tick, u: &[f64], y: &mut [f64]) {
        y[0] = self.step(u[0]);
    }
    /// Judged as gain 1: with the actuator's loop after it the pair is the
    /// identity (alone its slope lies between 1/M and 1/m).
    fn linearisation(&self) -> Option<Linearisation> {
        Some(Linearisation::single(
            StateSpace::gain(nalgebra::DMatrix::identity(1, 1), None),
            format!(
                "Bouc–Wen inverse judged as gain 1, the identity it makes with the actuator (alone its slope lies in [{:.3e}, {:.3e}])",
                1.0 / self.slopes.1,
                1.0 / self.slopes.0
            ),
        ))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// BW(BW⁻¹(w)) = w with the plf `bouc_wen` block (the operator the diagnosis
    /// fits) for wanted outputs with reversals, holds and steps, on loops of
    /// both signs of γ and both signs of a.
    #[test]
    fn the_inverse_cancels_the_loop() {
        for (a, beta, gamma, linear) in [
            (0.5, 4.0, 1.0, 0.5),
            (0.8, 15.0, -3.0, 0.3),
            (-0.2, 2.0, 0.5, 1.0),
        ] {
            let mut op = BoucWen::new(a, beta, gamma);
            op.linear = linear;
            let worst = crate::worst_of_pair(
                &mut BoucWenInverse::new(a, beta, gamma, linear),
                &mut op,
                6000,
                |k, t| {
                    0.3 + 0.6
                        * (2.0 * std::f64::consts::PI * 0.7 * t)
                            .sin()
                            .clamp(-0.8, 0.8)
                        + 0.15 * (2.0 * std::f64::consts::PI * 4.3 * t).sin()
                        + if k % 1500 < 40 { 0.2 } else { 0.0 }
                },
            );
            assert!(worst < 1e-12, "({a}, {beta}, {gamma}, {linear}): {worst:e}");
        }
    }

    /// A saturating loop with no linear part has no inverse: refused at build,
    /// naming `linear`.
    #[test]
    fn a_loop_whose_slope_reaches_zero_is_refused() {
        let ctx = BuildContext::new("b", 1e-3, 0);
        let e = BoucWenInverse::new(0.5, 4.0, 1.0, 0.0)
            .build(&ctx)
            .unwrap_err();
        assert_eq!(e.field, "linear", "{e}");
        assert!(e.to_string().contains("not invertible"), "{e}");
        let e = BoucWenInverse::new(0.5, f64::NAN, 1.0, 1.0)
            .build(&ctx)
            .unwrap_err();
        assert_eq!(e.field, "beta", "{e}");
    }
}
