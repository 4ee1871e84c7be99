//! `bouc_wen`: the Bouc–Wen hysteresis operator (ν = 1), the second hysteresis
//! model of the `hysteresis` vocabulary entry. Coleman–Hodgdon (`hysteresis`) is
//! the thesis's piezo model (Sec. 6.3); Bouc–Wen is the standard model of
//! hysteretic restoring forces in structures and mounts (and of the Noël–Schoukens
//! benchmark), whose loops saturate instead of following an anhysteretic line.

use super::check_len;
use nanomotion_core::Params;
use nanomotion_core::block::check;
use nanomotion_core::{Block, BuildContext, ParamError, Sector, Tick, Tunable, declared_block};
use serde::{Deserialize, Serialize};

/// `bouc_wen`: PLF effect (hysteresis): Bouc–Wen y = linear·u + z, ż = a·u̇ − β|u̇|z −
/// γ·u̇|z| (ν = 1), exact per sample, z(0) = 0; tunable [a, beta, gamma, linear].
///
/// Y = linear·u + z with ż = a·u̇ − β|u̇|z − γ·u̇|z| (ν = 1), z(0) = 0.
///
/// Along a sample the input moves monotonically, so dz/du = a − (β·s ± γ)z on each
/// side of z = 0 (s = sign u̇) is linear and is integrated **exactly**, including
/// the crossing of z = 0 inside a sample. [`Tunable`] vector: `[a, beta, gamma,
/// linear]`.
///
/// Slope range ([`Block::sector`], see [`BoucWen::z_slopes`]): for a > 0 and
/// β + γ > 0, |z| stays below z_m = a/(β + γ) and dz/du lies between 0 and
/// max(a, 2aβ/(β + γ)); y's slope is `linear` plus that. a < 0 mirrors it
/// (z → −z, γ → −γ); a = 0 keeps z = 0. Otherwise (β + γ ≤ 0 for a > 0) the
/// loop does not saturate, z and its slope grow without bound: no range.
#[derive(Debug, Clone, Serialize, Deserialize, Params)]
#[serde(deny_unknown_fields)]
#[block(type_name = "bouc_wen", role = Actuator, ports = "u -> y")]
pub struct BoucWen {
    /// a (\[y\]/\[u\]): slope of z right after a reversal.
    pub a: f64,
    /// β (1/\[u\]) ≥ 0 with β + |γ| > 0 for a bounded loop.
    pub beta: f64,
    /// γ (1/\[u\]): shape (|γ| ≤ β keeps both branches saturating).
    pub gamma: f64,
    /// Linear part of the output (\[y\]/\[u\]), default 0.
    #[serde(default)]
    pub linear: f64,
    #[serde(skip)]
    z: f64,
    #[serde(skip)]
    u_prev: Option<f64>,
}

impl BoucWen {
    /// A Bouc–Wen operator with output z only.
    pub fn new(a: f64, beta: f64, gamma: f64) -> Self {
        Self {
            a,
            beta,
            gamma,
            linear: 0.0,
            z: 0.0,
            u_prev: None,
        }
    }

    fn validate(a: f64, beta: f64, gamma: f64, linear: f64) -> Result<(), ParamError> {
        check::finite("a", a)?;
        check::non_negative("beta", beta)?;
        check::finite("gamma", gamma)?;
        check::finite("linear", linear)?;
        for (name, v) in [
            ("a", a),
            ("beta", beta),
            ("gamma", gamma),
            ("linear", linear),
        ] {
            if v.abs() > 1e100 {
                return Err(ParamError::new(
                    name,
                    format!("is {v:e}"),
                    "give |value| ≤ 1e100",
                ));
            }
        }
        Ok(())
    }

    /// The range of dz/du from state z on, if bounded: for a > 0 and β + γ > 0,
    /// along increasing u dz/du = a − (β + γ)z for z ≥ 0 (towards z_m = a/(β+γ))
    /// and a + (β − γ)|z| for z < 0 (towards 0), mirrored for decreasing u, so
    /// [−z_m, z_m] is never left from inside it and the slope at its ends and
    /// at 0 is 0, 2aβ/(β + γ) and a (linear in z between): the range is their
    /// hull. a < 0 is the mirror image w = −z with (−a, β, −γ).
    pub fn z_slopes(a: f64, beta: f64, gamma: f64, z: f64) -> Option<(f64, f64)> {
        if a == 0.0 {
            // z stays where it is (0 from the built state): dz/du = −(β s ± γ) z.
            return (z == 0.0).then_some((0.0, 0.0));
        }
        if a < 0.0 {
            return Self::z_slopes(-a, beta, -gamma, -z).map(|(lo, hi)| (-hi, -lo));
        }
        let g = beta + gamma;
        if g <= 0.0 {
            return None;
        }
        let zm = a / g;
        if z.abs() > zm {
            return None;
        }
        let far = 2.0 * a * beta / g;
        Some((0f64.min(far), a.max(far)))
    }

    /// z after the input moves by `du` from state `z` (exact, see the type docs).
    pub fn advance(&self, mut z: f64, du: f64) -> f64 {
        if du == 0.0 {
            return z;
        }
        let s = du.signum();
        let mut rem = du;
        for _ in 0..4 {
            let positive = if z != 0.0 {
                z > 0.0
            } else {
                self.a * rem > 0.0
            };
            let k = if positive {
                self.beta * s + self.gamma
            } else {
                self.beta * s - self.gamma
            };
            let flow = |z: f64, d: f64| {
                if k.abs() * d.abs() < 1e-12 {
                    z + (self.a - k * z) * d
                } else {
                    self.a / k + (z - self.a / k) * (-k * d).exp()
                }
            };
            let zn = flow(z, rem);
            if z == 0.0 || (zn >= 0.0) == (z > 0.0) || zn == 0.0 {
                return zn;
            }
            // z crosses 0 inside the step: at δ with flow(z, δ) = 0.
            let delta = if k.abs() * rem.abs() < 1e-12 {
                -z / (self.a - k * z)
            } else {
                -(self.a / (self.a - k * z)).ln() / k
            };
            if !(delta.is_finite() && delta * rem > 0.0 && delta.abs() <= rem.abs()) {
                return zn;
            }
            rem -= delta;
            z = 0.0;
        }
        z
    }
}

#[declared_block]
impl Block for BoucWen {
    fn build(&mut self, _ctx: &BuildContext) -> Result<(), ParamError> {
        Self::validate(self.a, self.beta, self.gamma, self.linear)?;
        self.z = 0.0;
        self.u_prev = None;
        Ok(())
    }
    fn output(&mut self, _tick: Tick, u: &[f64], y: &mut [f64]) {
        let u = u[0];
        if !u.is_finite() {
            y[0] = self.z;
            return;
        }
        if let Some(p) = self.u_prev {
            self.z = self.advance(self.z, u - p);
        }
        self.u_prev = Some(u);
        y[0] = self.linear * u + self.z;
    }
    fn sector(&self) -> Option<Sector> {
        let (lo, hi) = Self::z_slopes(self.a, self.beta, self.gamma, self.z)?;
        let (lower, upper) = (self.linear + lo, self.linear + hi);
        (lower.is_finite() && upper.is_finite())
            .then(|| Sector::new(lower, upper, "Bouc–Wen: linear + dz/du, |z| ≤ a/(β + γ)"))
    }
    fn tunable(&self) -> Option<&dyn Tunable> {
        Some(self)
    }
    fn tunable_mut(&mut self) -> Option<&mut dyn Tunable> {
        Some(self)
    }
}

impl Tunable for BoucWen {
    fn param_names(&self) -> Vec<String> {
        ["a", "beta", "gamma", "linear"]
            .iter()
            .map(|s| s.to_string())
            .collect()
    }
    fn params(&self) -> Vec<f64> {
        vec![self.a, self.beta, self.gamma, self.linear]
    }
    fn set_params(&mut self, p: &[f64]) -> Result<(), ParamError> {
        check_len(p, 4, "[a, beta, gamma, linear]")?;
        Self::validate(p[0], p[1], p[2], p[3])?;
        self.a = p[0];
        self.beta = p[1];
        self.gamma = p[2];
        self.linear = p[3];
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The exact step agrees with a fine RK4 integration of dz/du, across z = 0.
    #[test]
    fn exact_step_matches_fine_integration() {
        let bw = BoucWen {
            a: 5e4,
            beta: 800.0,
            gamma: -1100.0,
            linear: 0.0,
            z: 0.0,
            u_prev: None,
        };
        for (z0, du) in [
            (0.0, 1e-3),
            (30.0, -2e-3),
            (-40.0, 3e-3),
            (10.0, -1e-4),
            (0.0, -5e-3),
        ] {
            let exact = bw.advance(z0, du);
            let steps = 200_000;
            let h = du / steps as f64;
            let s = du.signum();
            let f = |z: f64| bw.a - bw.beta * s * z - bw.gamma * z.abs();
            let mut z = z0;
            for _ in 0..steps {
                let k1 = f(z);
                let k2 = f(z + 0.5 * h * k1);
                let k3 = f(z + 0.5 * h * k2);
                let k4 = f(z + h * k3);
                z += h / 6.0 * (k1 + 2.0 * k2 + 2.0 * k3 + k4);
            }
            assert!(
                (exact - z).abs() <= 1e-6 * (1.0 + z.abs()),
                "z0 {z0} du {du}: {exact} vs {z}"
            );
        }
    }

    /// Under a large periodic input the loop saturates at the closed-form bound
    /// z → a/(β + γ) on a rising branch (z > 0).
    #[test]
    fn loop_saturates_at_the_closed_form_level() {
        let mut bw = BoucWen::new(2.0, 3.0, 1.0);
        bw.build(&BuildContext::new("bw", 1e-3, 0)).unwrap();
        let mut y = [0.0];
        for k in 0..=4000 {
            let u = 10.0 * (k as f64 / 4000.0);
            bw.output(Tick::new(k, 1e-3), &[u], &mut y);
        }
        assert!((y[0] - 2.0 / 4.0).abs() < 1e-9, "{}", y[0]);
    }
}
