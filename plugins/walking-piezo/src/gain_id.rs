//! Identification of the **gain variation** of the walking stage with the waveform
//! amplitude A and phase difference φ̄ (Sec. 2.4.3, 2.5.1, Fig. 2.14), on the
//! simulated nonlinear stage ([`WalkingPiezoStage`]) with the foundation's FRF
//! tools: the closed-loop measurement of Fig. 2.8 (PI on f_α, constant-velocity
//! reference, white noise w added to f_α) and the indirect estimate
//! P̂ = Ŝ_P/Ŝ of [`nanomotion_core::analysis::frf_closed_loop`].
//!
//! At low frequencies P(s) ≈ c/s (2.7), so |P̂(f)|·2πf estimates the step per cycle
//! c(A, φ̄) at the operating point; the gain the controller must gain-schedule is
//! K = c(A_max, φ̄_max)/c(A, φ̄) (the FRF gain difference of Fig. 2.14 with the sign
//! flipped), to be fitted with `gain_scheduling::fit_power_db` (2.13).

use crate::control::design_pi;
use crate::driver::{DriverParams, WaveformDriver, WaveformShape};
use crate::linear::LinearStageParams;
use crate::stage::{StageParams, WalkingPiezoStage};
use nanomotion_core::analysis::{WelchOptions, frf_closed_loop};
use nanomotion_core::block::check;
use nanomotion_core::rng::Rng;
use nanomotion_core::{Controller, ParamError};
use std::f64::consts::{FRAC_PI_2, TAU};

/// Settings of one closed-loop FRF measurement.
#[derive(Debug, Clone, PartialEq)]
pub struct GainIdConfig {
    /// The stage (sub-steps chosen for the loop period).
    pub stage: StageParams,
    /// Waveform shape of the driver.
    pub shape: WaveformShape,
    /// Loop period Δt (s); thesis 4 kHz.
    pub dt: f64,
    /// Reference velocity (m/s) of the constant-velocity measurement.
    pub velocity_m_s: f64,
    /// Standard deviation (Hz) of the white noise w added to f_α.
    pub noise_hz: f64,
    /// Recorded time (s) after a settling time of 0.25 s.
    pub duration_s: f64,
    /// Welch segment length (samples).
    pub segment_len: usize,
    /// Frequency band (Hz) over which c is averaged.
    pub band_hz: (f64, f64),
    /// Bandwidth (Hz) of the PI of the measurement loop, designed on (2.7).
    pub bandwidth_hz: f64,
    /// Seed of the noise and the stage's friction variation.
    pub seed: u64,
}

impl Default for GainIdConfig {
    fn default() -> Self {
        Self {
            stage: StageParams {
                substeps: 10,
                ..StageParams::default()
            },
            shape: WaveformShape::default(),
            dt: 2.5e-4,
            velocity_m_s: 50e-6,
            noise_hz: 30.0,
            duration_s: 8.0,
            segment_len: 2048,
            band_hz: (2.0, 20.0),
            bandwidth_hz: 5.0,
            seed: 1,
        }
    }
}

/// One identified operating point.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct OperatingPointGain {
    /// Amplitude A (V).
    pub amplitude_v: f64,
    /// Phase difference φ̄ = φ + π/2 (rad).
    pub phase_diff_rad: f64,
    /// Identified step per cycle ĉ = mean over the band of |P̂(f)|·2πf (m).
    pub step_per_cycle_m: f64,
    /// Mean coherence of the estimate over the band.
    pub coherence: f64,
}

/// The open-loop step per cycle (m) at amplitude `amplitude_v`, phase difference
/// `phase_diff_rad` and drive frequency `f_alpha_hz`, from the stage travel over
/// `cycles` cycles (after one run-in cycle): the reference the FRF estimate is
/// checked against.
pub fn open_loop_step_per_cycle(
    cfg: &GainIdConfig,
    amplitude_v: f64,
    phase_diff_rad: f64,
    f_alpha_hz: f64,
    cycles: usize,
) -> Result<f64, ParamError> {
    check::positive("f_alpha_hz", f_alpha_hz)?;
    check::at_least_one("cycles", cycles)?;
    let dt = cfg.dt;
    let mut driver = WaveformDriver::new(
        DriverParams {
            shape: cfg.shape.clone(),
            amplitude_v,
            phase_rad: phase_diff_rad - FRAC_PI_2,
            ..Default::default()
        },
        dt,
    )?;
    let mut stage = WalkingPiezoStage::new(cfg.stage.clone(), dt, cfg.seed)?;
    let per_cycle = (1.0 / (f_alpha_hz * dt)).round() as usize;
    let mut x0 = 0.0;
    for k in 0..per_cycle * (cycles + 1) {
        if k == per_cycle {
            x0 = stage.signals().x_s;
        }
        let (u, _) = driver.try_drive(f_alpha_hz, None, None).map_err(|e| {
            ParamError::new("f_alpha_hz", e.to_string(), "give a finite drive frequency")
        })?;
        let _ = stage.step(&u, 0.0);
    }
    Ok((stage.signals().x_s - x0) / cycles as f64)
}

/// Measure the low-frequency plant gain at amplitude `amplitude_v` and phase
/// difference `phase_diff_rad` (closed loop, Fig. 2.8).
pub fn identify_operating_point(
    cfg: &GainIdConfig,
    amplitude_v: f64,
    phase_diff_rad: f64,
) -> Result<OperatingPointGain, ParamError> {
    check::positive("velocity_m_s", cfg.velocity_m_s)?;
    check::positive("noise_hz", cfg.noise_hz)?;
    check::positive("duration_s", cfg.duration_s)?;
    check::ordered("band_hz.0", cfg.band_hz.0, "band_hz.1", cfg.band_hz.1)?;
    let dt = cfg.dt;
    let mut driver = WaveformDriver::new(
        DriverParams {
            shape: cfg.shape.clone(),
            amplitude_v,
            phase_rad: phase_diff_rad - FRAC_PI_2,
            ..Default::default()
        },
        dt,
    )?;
    let mut stage = WalkingPiezoStage::new(cfg.stage.clone(), dt, cfg.seed)?;
    let mut pi =
        design_pi(&LinearStageParams::default(), cfg.bandwidth_hz, 75.0, dt)?.controller(dt)?;
    let mut rng = Rng::new(cfg.seed ^ 0x9e37_79b9_7f4a_7c15);
    let settle = (0.25 / dt) as usize;
    let n = (cfg.duration_s / dt) as usize;
    let (mut w_rec, mut u_rec, mut y_rec) = (
        Vec::with_capacity(n),
        Vec::with_capacity(n),
        Vec::with_capacity(n),
    );
    for k in 0..settle + n {
        let x = stage.signals().x_s;
        let e = cfg.velocity_m_s * k as f64 * dt - x;
        let mut f = [0.0];
        pi.control(&[e], &mut f);
        let w = if k >= settle {
            cfg.noise_hz * rng.normal()
        } else {
            0.0
        };
        let f_alpha = f[0] + w;
        let (u, _) = driver
            .try_drive(f_alpha, None, None)
            .map_err(|e| ParamError::new("f_alpha", e.to_string(), "lower the loop gain"))?;
        let _ = stage.step(&u, 0.0);
        if k >= settle {
            w_rec.push(w);
            u_rec.push(f_alpha);
            y_rec.push(x);
        }
    }
    let frf = frf_closed_loop(
        &w_rec,
        &u_rec,
        &y_rec,
        1.0 / dt,
        &WelchOptions::new(cfg.segment_len),
    )
    .map_err(|e| {
        ParamError::new(
            "segment_len",
            e.to_string(),
            "record longer or shorten segments",
        )
    })?;
    let (mut c_sum, mut coh, mut m) = (0.0, 0.0, 0usize);
    for (i, &f) in frf.freq_hz.iter().enumerate() {
        if f >= cfg.band_hz.0 && f <= cfg.band_hz.1 {
            c_sum += frf.plant[i].norm() * TAU * f;
            coh += frf.coherence_sensitivity[i].min(frf.coherence_process_sensitivity[i]);
            m += 1;
        }
    }
    if m == 0 {
        return Err(ParamError::new(
            "band_hz",
            "holds no frequency of the estimate",
            "widen the band or lengthen the segments",
        ));
    }
    Ok(OperatingPointGain {
        amplitude_v,
        phase_diff_rad,
        step_per_cycle_m: c_sum / m as f64,
        coherence: coh / m as f64,
    })
}

/// The gain the controller needs at each point relative to the first one
/// (the nominal A_max, φ̄_max): K = ĉ_nominal/ĉ, in dB.
pub fn gain_variation_db(points: &[OperatingPointGain]) -> Vec<f64> {
    let c0 = points.first().map_or(1.0, |p| p.step_per_cycle_m);
    points
        .iter()
        .map(|p| 20.0 * (c0 / p.step_per_cycle_m).log10())
        .collect()
}
