//! Discretisation of continuous models (python-control `c2d`): zero-order hold
//! (exact for piecewise-constant inputs) and Tustin (bilinear) with optional
//! pre-warping, both in state-space form.

use super::linalg::expm;
use super::{LtiError, StateSpace, TransferFunction};
use nalgebra::DMatrix;
use serde::{Deserialize, Serialize};
use std::f64::consts::PI;

/// Discretisation method of [`c2d`].
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum C2dMethod {
    /// Zero-order hold: A_d = e^{AT}, B_d = ∫₀ᵀ e^{Aτ}dτ·B, from the matrix
    /// exponential of the augmented matrix [[A, B], [0, 0]]·T.
    Zoh,
    /// Tustin (bilinear) s = k(z − 1)/(z + 1) with k = 2/T, or with pre-warping
    /// at `prewarp_hz` f₀: k = ω₀/tan(ω₀T/2), ω₀ = 2πf₀, so that the discrete
    /// response equals the continuous one exactly at f₀.
    ///
    /// The pre-warp frequency is in **Hz** (as the name says), unlike the
    /// toolkit's frequency grids in rad/s; [`C2dMethod::tustin_prewarp_rad_s`]
    /// builds this variant from a frequency in rad/s.
    Tustin {
        /// Pre-warp frequency f₀ in Hz (must be below Nyquist, 1/(2T) Hz),
        /// `None` for plain Tustin.
        prewarp_hz: Option<f64>,
    },
}

impl C2dMethod {
    /// Plain Tustin without pre-warping.
    pub const TUSTIN: C2dMethod = C2dMethod::Tustin { prewarp_hz: None };

    /// Tustin pre-warped at the angular frequency `w0_rad_s` (rad/s, the unit
    /// of every frequency grid of the toolkit): the same method as
    /// `Tustin { prewarp_hz: Some(w0_rad_s / 2π) }`. The range is checked by
    /// [`c2d`] (> 0 and below the Nyquist frequency π/T rad/s).
    ///
    /// ```
    /// use nanomotion_core::lti::{C2dMethod, TransferFunction};
    /// let w0 = 2.0 * std::f64::consts::PI * 300.0; // rad/s
    /// let g = TransferFunction::new(vec![1.0], vec![1e-3, 1.0], None).unwrap();
    /// let gd = g.c2d(1e-3, C2dMethod::tustin_prewarp_rad_s(w0)).unwrap();
    /// let (c, d) = (g.freqresp(&[w0])[0], gd.freqresp_siso(&[w0])[0]);
    /// assert!((c - d).norm() < 1e-12);
    /// let back = C2dMethod::tustin_prewarp_rad_s(w0).prewarp_rad_s().unwrap();
    /// assert!((back - w0).abs() < 1e-12 * w0);
    /// ```
    pub fn tustin_prewarp_rad_s(w0_rad_s: f64) -> C2dMethod {
        C2dMethod::Tustin {
            prewarp_hz: Some(w0_rad_s / (2.0 * PI)),
        }
    }

    /// Tustin pre-warped at `f0_hz` (Hz): `Tustin { prewarp_hz: Some(f0_hz) }`.
    pub fn tustin_prewarp_hz(f0_hz: f64) -> C2dMethod {
        C2dMethod::Tustin {
            prewarp_hz: Some(f0_hz),
        }
    }

    /// The pre-warp frequency in rad/s (`None` for ZOH and plain Tustin).
    pub fn prewarp_rad_s(&self) -> Option<f64> {
        match self {
            C2dMethod::Tustin {
                prewarp_hz: Some(f0),
            } => Some(2.0 * PI * f0),
            _ => None,
        }
    }
}

/// Discretise a continuous state-space model at sample period `dt` (s)
/// (python-control `c2d(sys, Ts, method)`).
pub fn c2d(sys: &StateSpace, dt: f64, method: C2dMethod) -> Result<StateSpace, LtiError> {
    sys.validate()?;
    if sys.dt.is_some() {
        return Err(LtiError::Domain(
            "c2d needs a continuous model (dt = None)".into(),
        ));
    }
    if !(dt.is_finite() && dt > 0.0) {
        return Err(LtiError::param(
            "dt",
            format!("sample period {dt} s must be finite and > 0"),
        ));
    }
    let n = sys.nstates();
    let m = sys.ninputs();
    match method {
        C2dMethod::Zoh => {
            let mut aug = DMatrix::zeros(n + m, n + m);
            aug.view_mut((0, 0), (n, n)).copy_from(&(&sys.a * dt));
            aug.view_mut((0, n), (n, m)).copy_from(&(&sys.b * dt));
            let e = expm(&aug);
            if e.iter().any(|v| !v.is_finite()) {
                return Err(LtiError::param(
                    "dt",
                    format!(
                        "ZOH: e^(AT) overflows at T = {dt} s (‖A‖₁·T = {:.3e}): the model's fastest unstable mode grows beyond f64 in one sample",
                        super::linalg::norm_1(&sys.a) * dt
                    ),
                ));
            }
            Ok(StateSpace {
                a: e.view((0, 0), (n, n)).into_owned(),
                b: e.view((0, n), (n, m)).into_owned(),
                c: sys.c.clone(),
                d: sys.d.clone(),
                dt: Some(dt),
            })
        }
        C2dMethod::Tustin { prewarp_hz } => {
            let k = tustin_k(prewarp_hz, dt)?;
            // Mp = (I − A/k)⁻¹; A_d = Mp (I + A/k); B_d = (2/k) Mp B; C_d = C Mp;
            // D_d = D + C Mp B / k.
            let ident = DMatrix::<f64>::identity(n, n);
            let mp = (&ident - &sys.a / k).try_inverse().ok_or_else(|| {
                LtiError::Singular(format!(
                    "Tustin: continuous pole at s = {k} (I − A/k singular)"
                ))
            })?;
            let a = &mp * (&ident + &sys.a / k);
            let mpb = &mp * &sys.b;
            let c = &sys.c * &mp;
            let d = &sys.d + &sys.c * &mpb / k;
            Ok(StateSpace {
                a,
                b: mpb * (2.0 / k),
                c,
                d,
                dt: Some(dt),
            })
        }
    }
}

/// The scale k of the bilinear map s = k·(z − 1)/(z + 1) at period `dt` (s):
/// 2/T, or ω₀/tan(ω₀T/2) pre-warped at `prewarp_hz` f₀ = ω₀/2π (which must be
/// above 0 and below Nyquist). Allocates only when it refuses.
pub(crate) fn tustin_k(prewarp_hz: Option<f64>, dt: f64) -> Result<f64, LtiError> {
    Ok(match prewarp_hz {
        None => 2.0 / dt,
        Some(f0) => {
            if !(f0.is_finite() && f0 > 0.0 && f0 < 0.5 / dt) {
                return Err(LtiError::param(
                    "prewarp_hz",
                    format!(
                        "{f0} Hz ({} rad/s) must be > 0 and below the Nyquist frequency {} Hz ({} rad/s)",
                        2.0 * PI * f0,
                        0.5 / dt,
                        PI / dt
                    ),
                ));
            }
            let w0 = 2.0 * PI * f0;
            w0 / (w0 * dt / 2.0).tan()
        }
    })
}

impl StateSpace {
    /// Discretise at period `dt` (s); see [`c2d`].
    pub fn c2d(&self, dt: f64, method: C2dMethod) -> Result<StateSpace, LtiError> {
        c2d(self, dt, method)
    }
}

impl TransferFunction {
    /// Discretise at period `dt` (s) in state-space form (via the
    /// well-conditioned section cascade), see [`c2d`].
    pub fn c2d(&self, dt: f64, method: C2dMethod) -> Result<StateSpace, LtiError> {
        c2d(&self.to_ss_cascade()?, dt, method)
    }
}

/// Continuous model with the same H∞ norm: the bilinear map s = (z − 1)/(z + 1)
/// taking the unit circle onto the imaginary axis (z = e^{jθ} ↔ s = j·tan(θ/2)).
/// Requires I + A invertible (no pole at z = −1).
pub(crate) fn bilinear_d2c_unit(sys: &StateSpace) -> Result<StateSpace, LtiError> {
    let n = sys.nstates();
    let ident = DMatrix::<f64>::identity(n, n);
    let m = (&ident + &sys.a)
        .try_inverse()
        .ok_or_else(|| LtiError::Singular("pole at z = −1: bilinear map undefined".into()))?;
    let a = &m * (&sys.a - &ident);
    let s2 = std::f64::consts::SQRT_2;
    let b = &m * &sys.b * s2;
    let c = &sys.c * &m * s2;
    let d = &sys.d - &sys.c * &m * &sys.b;
    Ok(StateSpace {
        a,
        b,
        c,
        d,
        dt: None,
    })
}

/// The inverse of [`bilinear_d2c_unit`]: z = (1 + s)/(1 − s), a discrete model
/// with period `dt` and the same frequency response along the map. Requires
/// I − A invertible (no pole at s = 1).
pub(crate) fn bilinear_c2d_unit(sys: &StateSpace, dt: f64) -> Result<StateSpace, LtiError> {
    let n = sys.nstates();
    let ident = DMatrix::<f64>::identity(n, n);
    let m = (&ident - &sys.a)
        .try_inverse()
        .ok_or_else(|| LtiError::Singular("pole at s = 1: bilinear map undefined".into()))?;
    let s2 = std::f64::consts::SQRT_2;
    Ok(StateSpace {
        a: &m * (&ident + &sys.a),
        b: &m * &sys.b * s2,
        c: &sys.c * &m * s2,
        d: &sys.d + &sys.c * &m * &sys.b,
        dt: Some(dt),
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::lti::Complex;

    /// RK4 integration of the continuous model with a constant input (an
    /// independent check of ZOH): returns the state after `t` seconds.
    fn rk4(
        sys: &StateSpace,
        x0: &DMatrix<f64>,
        u: &DMatrix<f64>,
        t: f64,
        steps: usize,
    ) -> DMatrix<f64> {
        let h = t / steps as f64;
        let f = |x: &DMatrix<f64>| &sys.a * x + &sys.b * u;
        let mut x = x0.clone();
        for _ in 0..steps {
            let k1 = f(&x);
            let k2 = f(&(&x + &k1 * (h / 2.0)));
            let k3 = f(&(&x + &k2 * (h / 2.0)));
            let k4 = f(&(&x + &k3 * h));
            x += (k1 + k2 * 2.0 + k3 * 2.0 + k4) * (h / 6.0);
        }
        x
    }

    #[test]
    fn zoh_first_order_closed_form() {
        // a/(s + a): A_d = e^{-aT}, B_d C = 1 − e^{-aT}.
        let a = 30.0;
        let dt = 0.01;
        let sys = StateSpace::new(
            DMatrix::from_element(1, 1, -a),
            DMatrix::from_element(1, 1, 1.0),
            DMatrix::from_element(1, 1, a),
            DMatrix::zeros(1, 1),
            None,
        )
        .unwrap();
        let d = c2d(&sys, dt, C2dMethod::Zoh).unwrap();
        assert!((d.a[(0, 0)] - (-a * dt).exp()).abs() < 1e-15);
        assert!((d.b[(0, 0)] * d.c[(0, 0)] - (1.0 - (-a * dt).exp())).abs() < 1e-14);
        // Double integrator 1/s²: B_d = [T²/2, T].
        let di = StateSpace::new(
            DMatrix::from_row_slice(2, 2, &[0.0, 1.0, 0.0, 0.0]),
            DMatrix::from_row_slice(2, 1, &[0.0, 1.0]),
            DMatrix::from_row_slice(1, 2, &[1.0, 0.0]),
            DMatrix::zeros(1, 1),
            None,
        )
        .unwrap();
        let d = c2d(&di, 0.1, C2dMethod::Zoh).unwrap();
        assert!((d.a[(0, 1)] - 0.1).abs() < 1e-15);
        assert!((d.b[(0, 0)] - 0.005).abs() < 1e-16 && (d.b[(1, 0)] - 0.1).abs() < 1e-16);
    }

    #[test]
    fn zoh_matches_rk4_on_random_systems() {
        let mut rng = crate::rng::Rng::new(11);
        for trial in 0..10 {
            let n = 1 + trial % 5;
            let a = DMatrix::from_fn(n, n, |_, _| rng.uniform_in(-3.0, 3.0));
            let b = DMatrix::from_fn(n, 2, |_, _| rng.uniform_in(-1.0, 1.0));
            let sys =
                StateSpace::new(a, b, DMatrix::identity(n, n), DMatrix::zeros(n, 2), None).unwrap();
            let dt = 0.05;
            let d = c2d(&sys, dt, C2dMethod::Zoh).unwrap();
            let x0 = DMatrix::from_fn(n, 1, |_, _| rng.uniform_in(-1.0, 1.0));
            let u = DMatrix::from_fn(2, 1, |_, _| rng.uniform_in(-1.0, 1.0));
            let want = rk4(&sys, &x0, &u, dt, 2000);
            let got = &d.a * &x0 + &d.b * &u;
            assert!(
                (got - &want).amax() < 1e-11 * (1.0 + want.amax()),
                "trial {trial}"
            );
        }
    }

    #[test]
    fn tustin_matches_substitution_and_prewarp_is_exact() {
        // Lightly damped resonance ω²/(s² + 2ζω s + ω²).
        let w0 = 2.0 * PI * 500.0;
        let z = 0.05;
        let tf =
            TransferFunction::new(vec![w0 * w0], vec![1.0, 2.0 * z * w0, w0 * w0], None).unwrap();
        let sys = tf.to_ss().unwrap();
        let dt = 1.0 / 4000.0;
        let d = c2d(&sys, dt, C2dMethod::TUSTIN).unwrap();
        let dp = c2d(
            &sys,
            dt,
            C2dMethod::Tustin {
                prewarp_hz: Some(500.0),
            },
        )
        .unwrap();
        for &w in &[1.0, 300.0, 2000.0, 3141.0, 10000.0] {
            let zz = Complex::from_polar(1.0, w * dt);
            let s = (zz - 1.0) / (zz + 1.0) * (2.0 / dt);
            assert!(
                (d.freqresp_siso_at(w) - tf.eval(s)).norm() < 1e-10 * tf.eval(s).norm().max(1.0)
            );
        }
        let at = dp.freqresp_siso_at(w0);
        let want = tf.eval(Complex::new(0.0, w0));
        assert!((at - want).norm() < 1e-9 * want.norm(), "{at} vs {want}");
        // Without pre-warp the resonance is shifted: the response differs there.
        assert!((d.freqresp_siso_at(w0) - want).norm() > 0.1 * want.norm());
        assert!(
            c2d(
                &sys,
                dt,
                C2dMethod::Tustin {
                    prewarp_hz: Some(3000.0)
                }
            )
            .is_err()
        );
        assert!(c2d(&d, dt, C2dMethod::Zoh).is_err());
    }

    #[test]
    fn bilinear_unit_map_preserves_response() {
        let dt = 1e-3;
        let tf = TransferFunction::new(vec![0.1, 0.05], vec![1.0, -1.5, 0.7], Some(dt)).unwrap();
        let d = tf.to_ss().unwrap();
        let c = bilinear_d2c_unit(&d).unwrap();
        for &th in &[0.0, 0.3, 1.0, 2.5, 3.1] {
            let gz = d.freqresp_siso_at(th / dt);
            let gs = c.freqresp_siso_at((th / 2.0).tan());
            assert!((gz - gs).norm() < 1e-12, "θ={th}");
        }
    }
}
