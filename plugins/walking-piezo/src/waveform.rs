//! A minimal drive-waveform source: the sinusoidal waveforms (2.2) at a fixed drive
//! frequency f_α, so that the stage models can be run open loop. (The full driver
//! with frequency input, asymmetric, rhombic and free waveforms is
//! [`crate::driver::WaveformDriver`], block `walking_piezo_driver`.)
//!
//! u1 = A/2 sin α + A/2,           u2 = A/2 sin(α + π/2 + φ) + A/2,
//! u3 = A/2 sin(α + π) + A/2,      u4 = A/2 sin(α + 3π/2 + φ) + A/2,
//!
//! with α(t) = α0 + 2π f_α t.

use nanomotion_core::Params;
use nanomotion_core::{Block, BuildContext, ParamError, Source, Tick, declared_block};
use serde::{Deserialize, Serialize};
use std::f64::consts::{FRAC_PI_2, PI, TAU};

/// Sinusoidal walking waveforms (2.2) at a fixed drive frequency.
///
/// ```
/// use walking_piezo::SinusoidalWaveform;
/// use nanomotion_core::Source;
/// let mut w = SinusoidalWaveform::default();
/// let mut y = [0.0; 5];
/// w.sample(0.0, &mut y);
/// for (v, e) in y[..4].iter().zip([23.0, 46.0, 23.0, 0.0]) {   // α = 0, A = 46 V, φ = 0
///     assert!((v - e).abs() < 1e-12);
/// }
/// assert_eq!(y[4], 0.0);                          // α
/// ```
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize, Params)]
#[serde(default, deny_unknown_fields)]
pub struct SinusoidalWaveform {
    /// Drive frequency f_α (Hz).
    #[param(finite)]
    pub f_alpha_hz: f64,
    /// Amplitude A (V), the peak-to-peak voltage of each waveform; in [0, 46] V.
    #[param(range(0.0, 46.0))]
    pub amplitude_v: f64,
    /// Additional phase φ (rad) of (2.2); 0 gives the largest step.
    #[param(finite)]
    pub phase_rad: f64,
    /// Angle at t = 0 (rad).
    #[param(finite)]
    pub alpha0_rad: f64,
}

impl Default for SinusoidalWaveform {
    fn default() -> Self {
        Self {
            f_alpha_hz: 10.0,
            amplitude_v: 46.0,
            phase_rad: 0.0,
            alpha0_rad: 0.0,
        }
    }
}

impl SinusoidalWaveform {
    /// Check the parameters (A ∈ [0, 46] V, finite f_α and φ).
    pub fn validate(&self) -> Result<(), ParamError> {
        self.check_params()
    }
    /// The four voltages (2.2) at angle `alpha` (rad).
    pub fn voltages(&self, alpha: f64) -> [f64; 4] {
        let h = 0.5 * self.amplitude_v;
        let p = self.phase_rad;
        [
            h * alpha.sin() + h,
            h * (alpha + FRAC_PI_2 + p).sin() + h,
            h * (alpha + PI).sin() + h,
            h * (alpha + 3.0 * FRAC_PI_2 + p).sin() + h,
        ]
    }
    /// α(t) = α0 + 2π f_α t (rad), not wrapped.
    pub fn alpha(&self, t: f64) -> f64 {
        self.alpha0_rad + TAU * self.f_alpha_hz * t
    }
}

impl Source for SinusoidalWaveform {
    /// `y` = [u1, u2, u3, u4 (V), α (rad)].
    fn sample(&mut self, t: f64, y: &mut [f64]) {
        let a = self.alpha(t);
        y[..4].copy_from_slice(&self.voltages(a));
        y[4] = a;
    }
}

/// `walking_waveform`: sinusoidal walking-piezo waveforms (2.2) at a fixed drive
/// frequency f_α.
///
/// Graph block `walking_waveform`: outputs `u` (4, V) and `alpha` (1, rad).
#[derive(Debug, Clone, Default, Serialize, Deserialize, Params)]
#[serde(transparent)]
#[block(type_name = "walking_waveform", role = Source, ports = "-> u[4] (V), alpha[1] (rad)")]
pub struct WalkingWaveformBlock {
    /// The waveform.
    pub waveform: SinusoidalWaveform,
}

#[declared_block]
impl Block for WalkingWaveformBlock {
    fn build(&mut self, _ctx: &BuildContext) -> Result<(), ParamError> {
        self.waveform.validate()
    }
    fn output(&mut self, tick: Tick, _u: &[f64], y: &mut [f64]) {
        self.waveform.sample(tick.t, y);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn pairs_are_in_antiphase_and_voltages_in_range() {
        let w = SinusoidalWaveform {
            phase_rad: 0.3,
            ..Default::default()
        };
        for i in 0..100 {
            let a = i as f64 * 0.0731;
            let u = w.voltages(a);
            let v = w.voltages(a + PI);
            assert!((u[0] - v[2]).abs() < 1e-12 && (u[1] - v[3]).abs() < 1e-12);
            assert!(u.iter().all(|x| (-1e-12..=46.0 + 1e-12).contains(x)));
        }
        assert_eq!(
            SinusoidalWaveform {
                amplitude_v: 50.0,
                ..Default::default()
            }
            .validate()
            .unwrap_err()
            .field,
            "amplitude_v"
        );
    }
}
