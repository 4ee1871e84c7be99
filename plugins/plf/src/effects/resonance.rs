//! `unmodeled_resonance`: a series pole–zero pair with unity DC gain.

use super::check_len;
use nanomotion_core::Params;
use nanomotion_core::block::check;
use nanomotion_core::lti::{C2dMethod, StateSpace, TransferFunction};
use nanomotion_core::{Block, BuildContext, ParamError, Tick, Tunable, declared_block};
use serde::{Deserialize, Serialize};
use std::f64::consts::TAU;

/// Largest damping ratio accepted (beyond this the pair is two real, far-apart
/// roots and no longer a resonance).
pub const MAX_DAMPING: f64 = 100.0;

/// The least damping ratio of a structural resonance's pole pair, and of its
/// zero pair (Q = 5000; flexure stages and piezo stacks in air have ζ ≈ 10⁻³
/// and more, at their anti-resonances too).
pub const MIN_POLE_DAMPING: f64 = 1e-4;

/// The largest damping ratio of a resonance's pole pair: a resonance has a
/// half-power bandwidth (its Q), which needs the pair's peak to stand at least
/// 3 dB above its static gain — 1/(2ζ√(1−ζ²)) ≥ √2, i.e. ζ ≤ sin(π/8) ≈ 0.383.
/// A pair damped more is a lag or lead the nominal lacks, not a resonance.
pub const MAX_RESONANT_DAMPING: f64 = 0.382_683_432_365_089_8; // sin(π/8)

/// Smallest departure of |R(jω)| from 1 (dB) that a diagnosed resonance must
/// show in the data's band ([`UnmodeledResonance::implausible`]).
pub const MIN_PEAK_DB: f64 = 1.0;

/// `unmodeled_resonance`: PLF effect: pole–zero pair
/// R(s) = (ω_p²/ω_z²)(s² + 2ζ_zω_z s + ω_z²)/(s² + 2ζ_pω_p s + ω_p²), unity DC gain,
/// Tustin pre-warped at ω_p, one biquad; tunable all four.
///
/// ```text
/// R(s) = (ω_p²/ω_z²) · (s² + 2ζ_z ω_z s + ω_z²) / (s² + 2ζ_p ω_p s + ω_p²)
/// ```
///
/// (unity DC gain; ω = 2πf) discretised at the block's rate with Tustin pre-warped
/// at ω_p (the core's [`c2d`](nanomotion_core::lti::c2d)), so the discrete response
/// equals R(jω_p) exactly at the resonance, and run as one biquad (direct form II
/// transposed). The state starts at the steady state of the first input (no start-up
/// transient). [`Block::lti`] returns the discrete model.
///
/// [`Tunable`] vector: `[f_pole_hz, zeta_pole, f_zero_hz, zeta_zero]`.
#[derive(Debug, Clone, Serialize, Deserialize, Params)]
#[serde(deny_unknown_fields)]
#[block(type_name = "unmodeled_resonance", role = Plant, ports = "u -> y")]
pub struct UnmodeledResonance {
    /// Pole (resonance) frequency f_p (Hz), 0 < f_p < Nyquist.
    pub f_pole_hz: f64,
    /// Pole damping ratio ζ_p, 0 < ζ_p ≤ [`MAX_DAMPING`].
    /// `MAX_DAMPING` = 100.
    pub zeta_pole: f64,
    /// Zero (anti-resonance) frequency f_z (Hz), 0 < f_z < Nyquist.
    pub f_zero_hz: f64,
    /// Zero damping ratio ζ_z, 0 < ζ_z ≤ [`MAX_DAMPING`].
    /// `MAX_DAMPING` = 100.
    pub zeta_zero: f64,
    /// Normalised biquad [b0, b1, b2, a1, a2] (a0 = 1).
    #[serde(skip)]
    coef: [f64; 5],
    #[serde(skip)]
    z: [f64; 2],
    #[serde(skip)]
    started: bool,
    #[serde(skip)]
    dt: Option<f64>,
    #[serde(skip)]
    model: Option<StateSpace>,
}

impl UnmodeledResonance {
    /// A pole pair at `f_pole_hz` with damping `zeta_pole` and a zero pair at
    /// `f_zero_hz` with damping `zeta_zero`.
    pub fn new(f_pole_hz: f64, zeta_pole: f64, f_zero_hz: f64, zeta_zero: f64) -> Self {
        Self {
            f_pole_hz,
            zeta_pole,
            f_zero_hz,
            zeta_zero,
            coef: [0.0; 5],
            z: [0.0; 2],
            started: false,
            dt: None,
            model: None,
        }
    }

    /// The continuous transfer function R(s).
    pub fn continuous(&self) -> Result<TransferFunction, ParamError> {
        let (wp, wz) = (TAU * self.f_pole_hz, TAU * self.f_zero_hz);
        let g = (wp / wz) * (wp / wz);
        TransferFunction::new(
            vec![g, g * 2.0 * self.zeta_zero * wz, g * wz * wz],
            vec![1.0, 2.0 * self.zeta_pole * wp, wp * wp],
            None,
        )
        .map_err(|e| ParamError::new("f_pole_hz", e.to_string(), "check the frequencies"))
    }

    /// Why these parameters are not a mode an engineer would accept as a stage's
    /// missing resonance when the data cover `band_hz` = (lowest, highest
    /// frequency resolved), or `None` when they are. A flexible pole–zero pair can
    /// absorb any leftover of an imperfect fit; as a *diagnosis* it must be a
    /// lightly damped mode inside the band that changes the response visibly:
    /// - ζ ≤ 1 for both pairs (above 1 a pair is two real roots: a lag or lead,
    ///   not a resonance; the block itself accepts up to [`MAX_DAMPING`]), and
    ///   the pole pair's below [`MAX_RESONANT_DAMPING`] (a peak 3 dB high);
    /// - both frequencies inside the band (a pair at 0.02 Hz in a 6 s record is a
    ///   drift in disguise, one above the band is invisible);
    /// - not a near-cancelling pair: |R(jω)| departs from 1 by at least
    ///   [`MIN_PEAK_DB`] somewhere in the band.
    pub fn implausible(&self, band_hz: (f64, f64)) -> Option<String> {
        let (lo, hi) = band_hz;
        for (what, z) in [("pole", self.zeta_pole), ("zero", self.zeta_zero)] {
            if !(z > 0.0 && z <= 1.0) {
                return Some(format!(
                    "damping ratio of the {what} pair ζ = {z:.3e} is not that of a resonance (0 < ζ ≤ 1)"
                ));
            }
        }
        if self.zeta_pole >= MAX_RESONANT_DAMPING {
            return Some(format!(
                "the pole pair's damping ζ = {:.3} is above sin(π/8) ≈ 0.383: its peak stands less than 3 dB above its static gain, so it has no half-power bandwidth — a lag or lead the nominal lacks, not a resonance",
                self.zeta_pole
            ));
        }
        if self.zeta_pole < MIN_POLE_DAMPING {
            return Some(format!(
                "the pole pair's damping ζ = {:.3e} is below {MIN_POLE_DAMPING:.0e} (Q > 5000): an undamped oscillator rings on at {:.4e} Hz without the drive — what a periodic disturbance does, not a structure's resonance",
                self.zeta_pole, self.f_pole_hz
            ));
        }
        if self.zeta_zero < MIN_POLE_DAMPING {
            return Some(format!(
                "the zero pair's damping ζ = {:.3e} is below {MIN_POLE_DAMPING:.0e}: a perfect notch at {:.4e} Hz — a structure's anti-resonance is damped like its modes",
                self.zeta_zero, self.f_zero_hz
            ));
        }
        for (what, f) in [("pole", self.f_pole_hz), ("zero", self.f_zero_hz)] {
            if !(f >= lo && f <= hi) {
                return Some(format!(
                    "{what} frequency {f:.4e} Hz lies outside the band the data resolve ({lo:.3e}–{hi:.3e} Hz)"
                ));
            }
        }
        let (wp, wz) = (TAU * self.f_pole_hz, TAU * self.f_zero_hz);
        let g = (wp / wz) * (wp / wz);
        let mag_db = |f: f64| {
            let w = TAU * f;
            let num = (g * (wz * wz - w * w)).hypot(g * 2.0 * self.zeta_zero * wz * w);
            let den = (wp * wp - w * w).hypot(2.0 * self.zeta_pole * wp * w);
            20.0 * (num / den).log10()
        };
        // On a log grid, plus the two pairs' own frequencies (where the peak and
        // the notch are).
        let grid = 400;
        let peak = (0..=grid)
            .map(|k| lo * (hi / lo).powf(k as f64 / grid as f64))
            .chain([self.f_pole_hz, self.f_zero_hz])
            .map(|f| mag_db(f).abs())
            .fold(0.0f64, f64::max);
        if peak < MIN_PEAK_DB {
            return Some(format!(
                "the pole and zero pairs ({:.4e} Hz, {:.4e} Hz) nearly cancel: the response departs from 1 by {peak:.2} dB at most (a resonance shows at least {MIN_PEAK_DB} dB)",
                self.f_pole_hz, self.f_zero_hz
            ));
        }
        None
    }

    /// The normalised biquad coefficients [b0, b1, b2, a1, a2] (a0 = 1) in z⁻¹
    /// (valid after `build`).
    pub fn biquad(&self) -> [f64; 5] {
        self.coef
    }

    fn check(p: [f64; 4], dt: Option<f64>) -> Result<(), ParamError> {
        let names = ["f_pole_hz", "zeta_pole", "f_zero_hz", "zeta_zero"];
        for (i, v) in p.iter().enumerate() {
            check::positive(names[i], *v)?;
        }
        check::in_range("zeta_pole", p[1], 0.0, MAX_DAMPING)?;
        check::in_range("zeta_zero", p[3], 0.0, MAX_DAMPING)?;
        if let Some(dt) = dt {
            let nyq = 0.5 / dt;
            for i in [0, 2] {
                if p[i] >= nyq {
                    return Err(ParamError::new(
                        names[i],
                        format!(
                            "{} Hz is not below the Nyquist frequency {nyq} Hz of the block's rate",
                            p[i]
                        ),
                        "give a lower frequency or run the block at a higher rate",
                    ));
                }
            }
        }
        Ok(())
    }

    /// Discretise: Tustin pre-warped at f_p, then the 2-state model's transfer
    /// function num/den in closed form (den = z² − tr(A)z + det A,
    /// num = D·den + (CB)z + C·adj(−A)·B).
    fn discretise(&self, dt: f64) -> Result<(StateSpace, [f64; 5]), ParamError> {
        let bad = |e: String| ParamError::new("f_pole_hz", e, "check the frequencies and damping");
        let ss = self
            .continuous()?
            .c2d(
                dt,
                C2dMethod::Tustin {
                    prewarp_hz: Some(self.f_pole_hz),
                },
            )
            .map_err(|e| bad(e.to_string()))?;
        if ss.nstates() != 2 {
            return Err(bad(format!("{} states, 2 expected", ss.nstates())));
        }
        let a = &ss.a;
        let (a11, a12, a21, a22) = (a[(0, 0)], a[(0, 1)], a[(1, 0)], a[(1, 1)]);
        let (b1, b2, c1, c2, d) = (
            ss.b[(0, 0)],
            ss.b[(1, 0)],
            ss.c[(0, 0)],
            ss.c[(0, 1)],
            ss.d[(0, 0)],
        );
        let tr = a11 + a22;
        let det = a11 * a22 - a12 * a21;
        let cb = c1 * b1 + c2 * b2;
        // adj(−A) = [[−a22, a12], [a21, −a11]]
        let cmb = c1 * (-a22 * b1 + a12 * b2) + c2 * (a21 * b1 - a11 * b2);
        let coef = [d, cb - d * tr, d * det + cmb, -tr, det];
        if coef.iter().any(|v| !v.is_finite()) {
            return Err(bad("the discrete coefficients are not finite".into()));
        }
        Ok((ss, coef))
    }
}

#[declared_block]
impl Block for UnmodeledResonance {
    fn build(&mut self, ctx: &BuildContext) -> Result<(), ParamError> {
        check::positive("dt", ctx.dt)?;
        Self::check(
            [
                self.f_pole_hz,
                self.zeta_pole,
                self.f_zero_hz,
                self.zeta_zero,
            ],
            Some(ctx.dt),
        )?;
        let (ss, coef) = self.discretise(ctx.dt)?;
        self.coef = coef;
        self.model = Some(ss);
        self.dt = Some(ctx.dt);
        self.z = [0.0; 2];
        self.started = false;
        Ok(())
    }
    fn output(&mut self, _tick: Tick, u: &[f64], y: &mut [f64]) {
        let [b0, b1, b2, a1, a2] = self.coef;
        let x = u[0];
        if !self.started {
            // Steady state for a constant input x: y = G·x, G = Σb/(1 + a1 + a2).
            let g = (b0 + b1 + b2) / (1.0 + a1 + a2);
            let ys = g * x;
            self.z[1] = b2 * x - a2 * ys;
            self.z[0] = b1 * x - a1 * ys + self.z[1];
            self.started = true;
        }
        let out = b0 * x + self.z[0];
        self.z[0] = b1 * x - a1 * out + self.z[1];
        self.z[1] = b2 * x - a2 * out;
        y[0] = out;
    }
    fn lti(&self) -> Option<StateSpace> {
        self.model.clone()
    }
    fn tunable(&self) -> Option<&dyn Tunable> {
        Some(self)
    }
    fn tunable_mut(&mut self) -> Option<&mut dyn Tunable> {
        Some(self)
    }
}

impl Tunable for UnmodeledResonance {
    fn param_names(&self) -> Vec<String> {
        ["f_pole_hz", "zeta_pole", "f_zero_hz", "zeta_zero"]
            .map(String::from)
            .to_vec()
    }
    fn params(&self) -> Vec<f64> {
        vec![
            self.f_pole_hz,
            self.zeta_pole,
            self.f_zero_hz,
            self.zeta_zero,
        ]
    }
    fn set_params(&mut self, p: &[f64]) -> Result<(), ParamError> {
        check_len(p, 4, "[f_pole_hz, zeta_pole, f_zero_hz, zeta_zero]")?;
        Self::check([p[0], p[1], p[2], p[3]], self.dt)?;
        self.f_pole_hz = p[0];
        self.zeta_pole = p[1];
        self.f_zero_hz = p[2];
        self.zeta_zero = p[3];
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The peak of a pole pair alone over its static gain, 1/(2ζ√(1−ζ²)),
    /// reaches √2 (3 dB, the half-power bandwidth exists) exactly at ζ = sin(π/8).
    #[test]
    fn a_pole_pair_without_a_half_power_bandwidth_is_a_lag_not_a_resonance() {
        let band = (0.1, 1000.0);
        let peak = |z: f64| 1.0 / (2.0 * z * (1.0 - z * z).sqrt());
        assert!((peak(MAX_RESONANT_DAMPING) - 2f64.sqrt()).abs() < 1e-12);
        assert!((MAX_RESONANT_DAMPING - (std::f64::consts::PI / 8.0).sin()).abs() < 1e-15);
        // Zero pair at 400 Hz: the pair's departure from 1 is large either way.
        let light = UnmodeledResonance::new(20.0, 0.05, 400.0, 0.05);
        assert_eq!(light.implausible(band), None);
        let just_below = UnmodeledResonance::new(20.0, 0.38, 400.0, 0.05);
        assert_eq!(just_below.implausible(band), None);
        let heavy = UnmodeledResonance::new(20.0, 0.39, 400.0, 0.05);
        let why = heavy.implausible(band).expect("refused");
        assert!(why.contains("half-power"), "{why}");
        // A perfect notch (the zero pair undamped) is not a structure's either.
        let notch = UnmodeledResonance::new(20.0, 0.05, 30.0, 1e-42);
        let why = notch.implausible(band).expect("refused");
        assert!(why.contains("perfect notch"), "{why}");
    }
}
