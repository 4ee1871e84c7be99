//! The objectives of Sec. 4.5: the model-based g(ξ) (4.23)–(4.24) on the leg
//! velocities of the nominal model near contact, and the "data-based" g(ξ) (4.25) on
//! the stage velocity measured from a perturbed, noisy stage that plays the real
//! setup.
//!
//! Both generate the waveforms exactly as the driver does (a [`WaveformDriver`] with
//! `shape: {kind: free, points_v: ξ}`: the 4th-order Fourier fit (4.21)–(4.22)
//! through the 8 points per channel, scaled into the voltage range), so a waveform
//! optimised here behaves identically in a graph.
//!
//! Costs are in µm/s.

use crate::driver::{DriverParams, WaveformDriver, WaveformShape, asymmetric_unit};
use crate::stage::{StageParams, StepError, WalkingPiezoStage};
use nanomotion_core::ParamError;
use nanomotion_core::analysis::filter::filtfilt_sos;
use nanomotion_core::lti::butter_lowpass;
use nanomotion_core::rng::Rng;
use std::f64::consts::{FRAC_PI_2, PI, TAU};

/// Channels × points per channel of ξ.
pub const N_PARAMS: usize = 32;

/// ξ in the driver's layout: `points[i][j]` is channel i + 1 at α = 2πj/8 (V).
pub type Points = [[f64; 8]; 4];

/// The step of the model-based simulation (s): the thesis's Δt = 25 µs.
pub const MODEL_DT_S: f64 = 25e-6;

/// Cost returned when a simulation breaks down (non-finite state): finite, so the
/// optimisers stay well defined, and far above any real cost (µm/s).
pub const FAILED_COST: f64 = 1.0e6;

/// ξ as a flat vector (channel-major), the optimisers' parameter.
pub fn points_to_vec(p: &Points) -> Vec<f64> {
    p.iter().flatten().copied().collect()
}

/// A flat vector (channel-major, length 32) as [`Points`], each projected into
/// [0, `v_max`] (NaN becomes 0).
pub fn points_from_slice(xi: &[f64], v_max: f64) -> Points {
    let mut p = [[0.0; 8]; 4];
    for (k, v) in xi.iter().take(N_PARAMS).enumerate() {
        let v = if v.is_nan() { 0.0 } else { *v };
        p[k / 8][k % 8] = v.clamp(0.0, v_max);
    }
    p
}

/// The asymmetric waveform with overlap q (Sec. 2.4.1) sampled at the 8 points per
/// channel, in the driver's phase pattern ψ = (0, π/2, π, 3π/2): the starting point
/// of the optimisation (Ā = 46 V, within [0, 46]).
pub fn asymmetric_points(q: f64) -> Points {
    let psi = [0.0, FRAC_PI_2, PI, 3.0 * FRAC_PI_2];
    let mut p = [[0.0; 8]; 4];
    for (i, ch) in p.iter_mut().enumerate() {
        for (j, v) in ch.iter_mut().enumerate() {
            let th = TAU * j as f64 / 8.0 + psi[i];
            *v = 23.0 * asymmetric_unit(th, q) + 23.0;
        }
    }
    p
}

/// How the waveforms are driven: amplitude, drive frequency, range.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Drive {
    /// Drive frequency f_α (Hz).
    pub f_alpha_hz: f64,
    /// Amplitude A (V): every waveform is scaled by A/46 V as in the driver.
    pub amplitude_v: f64,
    /// Voltage range V_max (V).
    pub voltage_max_v: f64,
}

impl Drive {
    /// A driver for `shape` sampled every `dt` (s).
    pub fn driver(&self, shape: WaveformShape, dt: f64) -> Result<WaveformDriver, ParamError> {
        WaveformDriver::new(
            DriverParams {
                shape,
                amplitude_v: self.amplitude_v,
                voltage_max_v: self.voltage_max_v,
                ..Default::default()
            },
            dt,
        )
    }
}

/// Run `driver` on `stage` for `n` periods of the driver's `dt`, calling `each(k,
/// stage)` after every step. A step that leaves a non-finite state stops the run
/// (`Err`); steps whose friction iteration hit its cap are taken (and counted by the
/// stage).
fn run_open_loop(
    driver: &mut WaveformDriver,
    stage: &mut WalkingPiezoStage,
    f_alpha_hz: f64,
    n: usize,
    mut each: impl FnMut(usize, &WalkingPiezoStage),
) -> Result<(), StepError> {
    for k in 0..n {
        let (u, _) = driver
            .try_drive(f_alpha_hz, None, None)
            .map_err(|_| StepError::NonFiniteState)?;
        match stage.step(&u, 0.0) {
            Ok(_) | Err(StepError::NotConverged { .. }) => {}
            Err(e) => return Err(e),
        }
        each(k, stage);
    }
    Ok(())
}

/// Samples per drive cycle at step `dt`, at least 1.
fn per_cycle(f_alpha_hz: f64, dt: f64) -> usize {
    ((1.0 / (f_alpha_hz * dt)).round() as usize).max(1)
}

// ---------------------------------------------------------------------------
// Model-based objective (4.23)–(4.24)
// ---------------------------------------------------------------------------

/// Accumulates (4.23)–(4.24) over samples of the two leg pairs:
/// g = rms(ẋ_r − x̄_1) + rms(ẋ_r − x̄_2), x̄_i = ẋ_i if y_i ≥ δy, else 0.
///
/// y_i is the leg's penetration into the strip (negative when lifted off), so
/// δy < 0 is an open distance to the strip (the thesis's convention).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LegVelocityCost {
    v_ref: f64,
    clearance_m: f64,
    sum_sq: [f64; 2],
    n: usize,
}

impl LegVelocityCost {
    /// Empty accumulator for reference velocity ẋ_r (m/s) and clearance δy (m).
    pub fn new(v_ref_m_s: f64, clearance_m: f64) -> Self {
        Self {
            v_ref: v_ref_m_s,
            clearance_m,
            sum_sq: [0.0; 2],
            n: 0,
        }
    }

    /// Add one sample: leg x-velocities ẋ_1,2 (m/s) and positions y_1,2 (m).
    pub fn push(&mut self, v_leg: [f64; 2], y_leg: [f64; 2]) {
        for i in 0..2 {
            let w = if y_leg[i] >= self.clearance_m {
                v_leg[i]
            } else {
                0.0
            };
            let e = self.v_ref - w;
            self.sum_sq[i] += e * e;
        }
        self.n += 1;
    }

    /// rms(ẋ_r − x̄_1), rms(ẋ_r − x̄_2) (m/s); zero without samples.
    pub fn rms(&self) -> [f64; 2] {
        let n = self.n.max(1) as f64;
        [(self.sum_sq[0] / n).sqrt(), (self.sum_sq[1] / n).sqrt()]
    }

    /// g of (4.23) (m/s).
    pub fn g(&self) -> f64 {
        let r = self.rms();
        r[0] + r[1]
    }
}

/// What one model-based evaluation found.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ModelEvaluation {
    /// g(ξ) of (4.23) (µm/s).
    pub g_um_s: f64,
    /// The two terms rms(ẋ_r − x̄_i) (µm/s).
    pub rms_um_s: [f64; 2],
    /// Mean stage velocity over the scored cycles (µm/s).
    pub mean_velocity_um_s: f64,
    /// rms(ẋ_r − ẋ_s) of the model stage velocity over the scored cycles (µm/s).
    pub stage_error_um_s: f64,
}

/// The model-based objective (4.23)–(4.24): the nominal stage (no μ variation)
/// simulated at Δt = 25 µs with the waveforms at f_α; after `warmup_cycles` the leg
/// velocities ẋ_i = ẋ_s + slip_i (the backward-Euler leg velocity, exactly the
/// difference quotient of the leg position) are scored for `cycles` cycles.
#[derive(Debug, Clone)]
pub struct ModelObjective {
    /// The nominal model (used as given: give it without μ variation for the
    /// thesis's deterministic model).
    pub stage: StageParams,
    /// Drive settings.
    pub drive: Drive,
    /// Reference velocity ẋ_r (m/s).
    pub velocity_m_s: f64,
    /// Clearance δy (m), ≤ 0 is an open distance.
    pub clearance_m: f64,
    /// Cycles simulated before scoring.
    pub warmup_cycles: u32,
    /// Cycles scored.
    pub cycles: u32,
}

impl ModelObjective {
    /// Evaluate any driver shape.
    pub fn evaluate_shape(&self, shape: WaveformShape) -> Result<ModelEvaluation, String> {
        let mut driver = self
            .drive
            .driver(shape, MODEL_DT_S)
            .map_err(|e| e.to_string())?;
        let mut stage =
            WalkingPiezoStage::new(self.stage.clone(), MODEL_DT_S, 0).map_err(|e| e.to_string())?;
        let pc = per_cycle(self.drive.f_alpha_hz, MODEL_DT_S);
        let warm = pc * self.warmup_cycles as usize;
        let n = warm + pc * self.cycles.max(1) as usize;
        let mut acc = LegVelocityCost::new(self.velocity_m_s, self.clearance_m);
        let (mut x0, mut x1, mut e2, mut m) = (0.0, 0.0, 0.0, 0usize);
        run_open_loop(
            &mut driver,
            &mut stage,
            self.drive.f_alpha_hz,
            n,
            |k, st| {
                let s = st.signals();
                if k + 1 == warm {
                    x0 = s.x_s;
                }
                if k >= warm {
                    acc.push([s.v_s + s.slip[0], s.v_s + s.slip[1]], s.y_leg);
                    e2 += (self.velocity_m_s - s.v_s).powi(2);
                    m += 1;
                    x1 = s.x_s;
                }
            },
        )
        .map_err(|e| e.to_string())?;
        let t = (n - warm) as f64 * MODEL_DT_S;
        let rms = acc.rms();
        Ok(ModelEvaluation {
            g_um_s: acc.g() * 1e6,
            rms_um_s: [rms[0] * 1e6, rms[1] * 1e6],
            mean_velocity_um_s: (x1 - x0) / t * 1e6,
            stage_error_um_s: (e2 / m.max(1) as f64).sqrt() * 1e6,
        })
    }

    /// g(ξ) (µm/s) for the points ξ (projected into the range); [`FAILED_COST`] if
    /// the simulation breaks down.
    pub fn cost(&self, points: &Points) -> f64 {
        match self.evaluate_shape(WaveformShape::Free { points_v: *points }) {
            Ok(e) if e.g_um_s.is_finite() => e.g_um_s,
            _ => FAILED_COST,
        }
    }
}

/// Mean stage velocity (m/s) of a shape on a stage model over `cycles` cycles after
/// `warmup_cycles`, at Δt = 25 µs (used to calibrate the amplitude).
pub fn mean_velocity(
    stage: &StageParams,
    drive: &Drive,
    shape: WaveformShape,
    warmup_cycles: u32,
    cycles: u32,
) -> Result<f64, String> {
    let mut driver = drive.driver(shape, MODEL_DT_S).map_err(|e| e.to_string())?;
    let mut st = WalkingPiezoStage::new(stage.clone(), MODEL_DT_S, 0).map_err(|e| e.to_string())?;
    let pc = per_cycle(drive.f_alpha_hz, MODEL_DT_S);
    let warm = pc * warmup_cycles as usize;
    let n = warm + pc * cycles.max(1) as usize;
    let (mut x0, mut x1) = (0.0, 0.0);
    run_open_loop(&mut driver, &mut st, drive.f_alpha_hz, n, |k, s| {
        if k + 1 == warm {
            x0 = s.signals().x_s;
        }
        x1 = s.signals().x_s;
    })
    .map_err(|e| e.to_string())?;
    Ok((x1 - x0) / ((n - warm) as f64 * MODEL_DT_S))
}

// ---------------------------------------------------------------------------
// The "real" stage and the data-based objective (4.25)
// ---------------------------------------------------------------------------

/// The stage that plays the real setup: perturbed parameters, μ variation, position
/// measured at `sample_hz` with noise, velocity by numerical differentiation and a
/// zero-phase Butterworth low-pass (Sec. 4.5: 5th order, f_c = 50 Hz).
#[derive(Debug, Clone)]
pub struct RealStage {
    /// Its (perturbed) parameters, μ variation included.
    pub params: StageParams,
    /// Seed of its μ profile (along the strip and in time).
    pub mu_seed: u64,
    /// Seed of the measurement noise.
    pub noise_seed: u64,
    /// Position noise (m, rms).
    pub noise_m: f64,
    /// Sampling frequency of the measurement and the driver (Hz).
    pub sample_hz: f64,
    /// Low-pass order.
    pub filter_order: usize,
    /// Low-pass cut-off (Hz).
    pub filter_hz: f64,
}

/// Perturb every physical parameter of `nominal` by a factor 1 + rel·N(0, 1)
/// (clamped to [0.5, 1.5]), seeded: c_x, c_y per stack, k_x, d_x, k_y, d_y per leg
/// pair, μ, q1 and the preload. μ variation keeps the nominal settings.
pub fn perturb(nominal: &StageParams, rel: f64, seed: u64) -> StageParams {
    let mut r = Rng::new(seed);
    let mut f = |v: &mut f64| *v *= (1.0 + rel * r.normal()).clamp(0.5, 1.5);
    let mut p = nominal.clone();
    p.c_x_m_v.iter_mut().for_each(&mut f);
    p.c_y_m_v.iter_mut().for_each(&mut f);
    p.leg_stiffness_x_n_m.iter_mut().for_each(&mut f);
    p.leg_damping_x_ns_m.iter_mut().for_each(&mut f);
    p.leg_stiffness_y_n_m.iter_mut().for_each(&mut f);
    p.leg_damping_y_ns_m.iter_mut().for_each(&mut f);
    f(&mut p.mu);
    f(&mut p.contact_q1);
    f(&mut p.preload_n);
    p
}

/// A measured run on the real stage.
#[derive(Debug, Clone, PartialEq)]
pub struct Measurement {
    /// Estimated stage velocity ẋ_s,e over the scored cycles (m/s), at `sample_hz`.
    pub velocity_m_s: Vec<f64>,
    /// rms(ẋ_r − ẋ_s,e) (µm/s), (4.25).
    pub error_um_s: f64,
    /// Mean velocity from the measured positions over the scored cycles (µm/s).
    pub mean_velocity_um_s: f64,
}

impl RealStage {
    /// Run `shape` with `drive` for `warmup_cycles + cycles` cycles (plus half a
    /// cycle of tail for the filter) and score rms(ẋ_r − ẋ_s,e) over the `cycles`.
    pub fn measure(
        &self,
        shape: WaveformShape,
        drive: &Drive,
        velocity_m_s: f64,
        warmup_cycles: u32,
        cycles: u32,
    ) -> Result<Measurement, String> {
        let ts = 1.0 / self.sample_hz;
        let mut driver = drive.driver(shape, ts).map_err(|e| e.to_string())?;
        let mut stage = WalkingPiezoStage::new(self.params.clone(), ts, self.mu_seed)
            .map_err(|e| e.to_string())?;
        let sos =
            butter_lowpass(self.filter_order, self.filter_hz, ts).map_err(|e| e.to_string())?;
        let pc = per_cycle(drive.f_alpha_hz, ts);
        let warm = pc * warmup_cycles as usize;
        let scored = pc * cycles.max(1) as usize;
        let n = warm + scored + pc / 2 + 1;
        let mut noise = Rng::new(self.noise_seed);
        let mut x = Vec::with_capacity(n + 1);
        x.push(stage.signals().x_s + self.noise_m * noise.normal());
        run_open_loop(&mut driver, &mut stage, drive.f_alpha_hz, n, |_, s| {
            x.push(s.signals().x_s + self.noise_m * noise.normal());
        })
        .map_err(|e| e.to_string())?;
        let v: Vec<f64> = x.windows(2).map(|w| (w[1] - w[0]) / ts).collect();
        let vf = filtfilt_sos(&sos, &v);
        let window = &vf[warm..warm + scored];
        let e2 = window
            .iter()
            .map(|v| (velocity_m_s - v).powi(2))
            .sum::<f64>()
            / scored as f64;
        let mean = (x[warm + scored] - x[warm]) / (scored as f64 * ts);
        Ok(Measurement {
            velocity_m_s: window.to_vec(),
            error_um_s: e2.sqrt() * 1e6,
            mean_velocity_um_s: mean * 1e6,
        })
    }
}

/// The data-based objective (4.25): rms(ẋ_r − ẋ_s,e(ξ)) (µm/s) measured on the real
/// stage. One fixed experiment (same μ profile, same noise realisation) per
/// evaluation, so the objective is a deterministic function of ξ; validation runs
/// use other seeds.
#[derive(Debug, Clone)]
pub struct DataObjective {
    /// The real stage.
    pub real: RealStage,
    /// Drive settings.
    pub drive: Drive,
    /// Reference velocity ẋ_r (m/s).
    pub velocity_m_s: f64,
    /// Cycles before scoring.
    pub warmup_cycles: u32,
    /// Cycles scored.
    pub cycles: u32,
}

impl DataObjective {
    /// rms(ẋ_r − ẋ_s,e) (µm/s) for any shape.
    pub fn evaluate_shape(&self, shape: WaveformShape) -> Result<Measurement, String> {
        self.real.measure(
            shape,
            &self.drive,
            self.velocity_m_s,
            self.warmup_cycles,
            self.cycles,
        )
    }

    /// g(ξ) of (4.25) (µm/s); [`FAILED_COST`] if the simulation breaks down.
    pub fn cost(&self, points: &Points) -> f64 {
        match self.evaluate_shape(WaveformShape::Free { points_v: *points }) {
            Ok(m) if m.error_um_s.is_finite() => m.error_um_s,
            _ => FAILED_COST,
        }
    }
}
