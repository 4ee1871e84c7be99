//! Records of the walking-piezo plant (Ch. 5 fitted model (5.31), 4 kHz) with one
//! hidden effect: the truth the discrepancy workflow (the `plf` plugin) is
//! validated on, called by its `tests/walking_piezo.rs` and its `confusion`
//! example. See that test for what each effect is in the truth.

use crate::{FittedStage, FittedStageParams};
use nanomotion_core::Plant;
use nanomotion_core::data::Dataset;
use nanomotion_core::rng::Rng;
use std::f64::consts::PI;

/// Sample rate of the records (Hz).
pub const RATE: f64 = 4000.0;
/// Samples per record (3 s).
pub const N: usize = 12_000;

/// The nominal graph (the fitted stage driven by the record's `f_alpha`,
/// compared with its `x`).
pub fn nominal_yaml() -> String {
    format!(
        "title: walking piezo stage, fitted model (5.31), nominal\nbase_rate_hz: {RATE}\nduration_s: {}\nblocks:\n  - {{ name: drive, type: data_column, column: f_alpha }}\n  - {{ name: stage, type: walking_piezo_fitted }}\nconnections:\n  - {{ from: drive.y, to: stage.f_alpha }}\ncompare:\n  - {{ signal: stage.x_s, column: x }}\n",
        N as f64 / RATE
    )
}

/// Drive frequency f_α (Hz): slow back-and-forth strokes (peak 40 Hz, so the
/// stage travels some 100 µm each way) plus a 5–600 Hz multisine of 4 Hz rms
/// that excites the resonances.
fn drive(rng: &mut Rng) -> Vec<f64> {
    let slow: Vec<(f64, f64, f64)> = (0..4)
        .map(|_| {
            (
                rng.uniform_in(0.3, 2.0),
                rng.uniform_in(0.0, 2.0 * PI),
                rng.uniform_in(0.5, 1.0),
            )
        })
        .collect();
    let fast: Vec<(f64, f64)> = (0..30)
        .map(|_| (rng.uniform_in(5.0, 600.0), rng.uniform_in(0.0, 2.0 * PI)))
        .collect();
    let raw: Vec<f64> = (0..N)
        .map(|k| {
            let t = k as f64 / RATE;
            slow.iter()
                .map(|(f, p, a)| a * (2.0 * PI * f * t + p).sin())
                .sum::<f64>()
        })
        .collect();
    let peak = raw.iter().fold(0.0f64, |m, v| m.max(v.abs()));
    raw.iter()
        .enumerate()
        .map(|(k, v)| {
            let t = k as f64 / RATE;
            let q: f64 = fast
                .iter()
                .map(|(f, p)| (2.0 * PI * f * t + p).sin())
                .sum::<f64>()
                * (2.0 / fast.len() as f64).sqrt();
            40.0 * v / peak + 4.0 * q
        })
        .collect()
}

/// Simulate the stage on `f` with an input-side transform `input(k, f_k, x_k)`.
fn simulate(f: &[f64], mut input: impl FnMut(usize, f64, f64) -> f64) -> Result<Vec<f64>, String> {
    let mut stage =
        FittedStage::new(FittedStageParams::default(), 1.0 / RATE).map_err(|e| e.to_string())?;
    let mut x = Vec::with_capacity(f.len());
    let mut y = [0.0];
    for (k, &fk) in f.iter().enumerate() {
        stage.plant_output(&mut y);
        x.push(y[0]);
        stage.advance(&[input(k, fk, y[0])]);
    }
    Ok(x)
}

/// A record with `hidden` (one of [`EFFECTS`]) in the truth, seeded; returns
/// (data, truth in words). An unknown effect is an error listing the known ones.
pub fn record(hidden: &str, seed: u64) -> Result<(Dataset, String), String> {
    let mut rng = Rng::new(seed ^ 0x3a1c_0f5e);
    let f = drive(&mut rng);
    let nominal = simulate(&f, |_, fk, _| fk)?;
    let (lo, hi) = nominal
        .iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), &v| {
            (a.min(v), b.max(v))
        });
    let (mid, half) = (0.5 * (lo + hi), 0.5 * (hi - lo));
    let step = FittedStageParams::default().gain_m_per_cycle;
    let sign = |rng: &mut Rng| if rng.uniform() < 0.5 { -1.0 } else { 1.0 };
    let (x, truth): (Vec<f64>, String) = match hidden {
        "position_dependent_gain" => {
            let g = rng.uniform_in(0.15, 0.3) * sign(&mut rng);
            (
                simulate(&f, |_, fk, xk| fk * (1.0 + g * (xk - mid) / half))?,
                format!("step size × (1 + {g:.3}·(x − x̄)/{half:.3e} m)"),
            )
        }
        "time_delay" => {
            let d = 2 + (rng.uniform() * 5.0) as usize;
            (
                simulate(&f, |k, _, _| if k >= d { f[k - d] } else { f[0] })?,
                format!("{d} extra samples of delay"),
            )
        }
        "saturation" => {
            let peak = f.iter().fold(0.0f64, |m, v| m.max(v.abs()));
            let lim = rng.uniform_in(0.6, 0.8) * peak;
            (
                simulate(&f, |_, fk, _| fk.clamp(-lim, lim))?,
                format!("drive frequency limited to ±{lim:.1} Hz"),
            )
        }
        "quantization" => {
            let q = rng.uniform_in(40e-9, 80e-9);
            (
                nominal.iter().map(|x| q * (x / q).round()).collect(),
                format!("encoder lsb {q:.3e} m"),
            )
        }
        "repetitive_disturbance" => {
            let (a1, a2) = (rng.uniform_in(20e-9, 50e-9), rng.uniform_in(0.0, 15e-9));
            let (p1, p2) = (rng.uniform_in(0.0, 2.0 * PI), rng.uniform_in(0.0, 2.0 * PI));
            (
                nominal
                    .iter()
                    .map(|x| {
                        let ph = 2.0 * PI * x / step;
                        x + a1 * (ph + p1).sin() + a2 * (2.0 * ph + p2).sin()
                    })
                    .collect(),
                format!("step ripple {a1:.2e} m per step of {step:.3e} m"),
            )
        }
        "drift" => {
            let b = rng.uniform_in(0.2e-6, 0.5e-6) * sign(&mut rng);
            let a = rng.uniform_in(-0.1e-6, 0.1e-6);
            let c = rng.uniform_in(-0.02e-6, 0.02e-6);
            (
                nominal
                    .iter()
                    .enumerate()
                    .map(|(k, x)| {
                        let t = k as f64 / RATE;
                        x + a + b * t + c * t * t
                    })
                    .collect(),
                format!("drift {b:.2e} m/s"),
            )
        }
        other => {
            return Err(format!(
                "no walking-piezo truth for `{other}`; the effects are: {}",
                EFFECTS.join(", ")
            ));
        }
    };
    let sigma = 2e-9; // encoder/interferometer noise, 2 nm rms
    let y: Vec<f64> = x.iter().map(|v| v + sigma * rng.normal()).collect();
    let data = Dataset::from_columns(
        "walking_piezo",
        RATE,
        0.0,
        vec![("f_alpha".into(), f), ("x".into(), y)],
    )
    .map_err(|e| e.to_string())?;
    Ok((data, truth))
}

/// The effects the walking-piezo records can hide (the `confusion` example
/// iterates over them; the tests name each).
pub const EFFECTS: [&str; 6] = [
    "position_dependent_gain",
    "time_delay",
    "saturation",
    "quantization",
    "repetitive_disturbance",
    "drift",
];

/// The legs' take-over (thesis Ch. 5): where one pair of legs hands the stage to
/// the other, the stage's velocity dips. A dip of relative depth `depth`, a
/// raised cosine of half-width `half_width_rad` in the leg angle α, centred on
/// α ≡ 2πj/`per_cycle` — a disturbance periodic in α with period
/// 2π/`per_cycle` (the linear Table 5.1 model's dip: depth 0.5, half-width π/8,
/// two per cycle).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TakeOver {
    /// Take-overs per cycle of α (2: two leg pairs).
    pub per_cycle: usize,
    /// Relative depth of the velocity dip, in [0, 1).
    pub depth: f64,
    /// Half-width of the dip in α (rad), at most π/`per_cycle`.
    pub half_width_rad: f64,
}

impl TakeOver {
    /// The dip δ(α): the share of the velocity lost at leg angle α (rad).
    pub fn dip(&self, alpha: f64) -> f64 {
        let spacing = 2.0 * PI / self.per_cycle as f64;
        let a = alpha.rem_euclid(spacing);
        let d = a.min(spacing - a);
        if d < self.half_width_rad {
            0.5 * self.depth * (1.0 + (PI * d / self.half_width_rad).cos())
        } else {
            0.0
        }
    }

    /// The mean of δ over a cycle of α, in closed form: each dip holds
    /// depth·half-width of it, `per_cycle` of them per 2π.
    pub fn mean(&self) -> f64 {
        self.per_cycle as f64 * self.depth * self.half_width_rad / (2.0 * PI)
    }
}

/// A record of the Table 5.1 loop (thesis Ch. 5): the identified stage (5.31)
/// with `gain_m_per_cycle` and no delay, under the PI k_p(s + 2π·5 Hz)/s with
/// k_p = 2π·50 Hz/c, tracking the velocity v(1 + a·sin 2πf_v t) from rest
/// (v = `velocity_m_s`, (a, f_v) = `velocity_swing`; Table 5.1's last row
/// swings a = 0.5 at 0.1 Hz) — the reference v t + (a v/ω)(1 − cos ωt),
/// ω = 2πf_v — at [`RATE`]. The stage
/// is driven by f_α·(1 − (δ(α) − δ̄)) — the take-over dip about its mean (the
/// identified c is the mean step per cycle) — with α = 2π∫f_α the driver's leg
/// angle, α_k = 2πT_s Σ_{j<k} f_α,j. The controller reads the position with
/// white noise of `noise_m` rms (seeded). Simulated here in plain Rust
/// (forward-Euler integral of the PI), not with a graph.
#[derive(Debug, Clone, PartialEq)]
pub struct LegAngleLoop {
    /// The stage's step per cycle c (m).
    pub gain_m_per_cycle: f64,
    /// The reference's mean velocity v (m/s).
    pub velocity_m_s: f64,
    /// The reference velocity's swing (a, f_v): relative amplitude and
    /// frequency (Hz); `None`: constant velocity.
    pub velocity_swing: Option<(f64, f64)>,
    /// Length of the record (s).
    pub duration_s: f64,
    /// The take-over dip, or none (the stage as identified).
    pub take_over: Option<TakeOver>,
    /// Samples of delay between the driver and the stage the identified
    /// model does not have (0: none; another hidden effect, not periodic in α).
    pub drive_delay_samples: usize,
    /// Position noise (m rms).
    pub noise_m: f64,
    /// Seed of the noise.
    pub seed: u64,
}

impl LegAngleLoop {
    /// The record: columns `f_alpha` (Hz, the PI's output, what the driver
    /// was asked for) and `x` (m, the measured position).
    pub fn record(&self) -> Result<Dataset, String> {
        let dt = 1.0 / RATE;
        let c = self.gain_m_per_cycle;
        let params = FittedStageParams {
            gain_m_per_cycle: c,
            delay_s: 0.0,
            ..FittedStageParams::default()
        };
        let mut stage = FittedStage::new(params, dt).map_err(|e| e.to_string())?;
        let (kp, wz) = (2.0 * PI * 50.0 / c, 2.0 * PI * 5.0);
        let mut rng = Rng::new(self.seed);
        let n = (self.duration_s * RATE).round() as usize;
        let (mut f, mut x) = (Vec::with_capacity(n), Vec::with_capacity(n));
        let (mut integral, mut alpha) = (0.0, 0.0);
        let mut y = [0.0];
        for k in 0..n {
            stage.plant_output(&mut y);
            let measured = y[0] + self.noise_m * rng.normal();
            let t = k as f64 * dt;
            let swing = self.velocity_swing.map_or(0.0, |(a, f_v)| {
                let w = 2.0 * PI * f_v;
                a * self.velocity_m_s / w * (1.0 - (w * t).cos())
            });
            let e = self.velocity_m_s * t + swing - measured;
            let u = kp * (e + wz * integral);
            integral += e * dt;
            let gain = self
                .take_over
                .map_or(1.0, |t| 1.0 - (t.dip(alpha) - t.mean()));
            f.push(u);
            x.push(measured);
            let late = f[k.saturating_sub(self.drive_delay_samples)];
            stage.advance(&[late * gain]);
            alpha += 2.0 * PI * dt * u;
        }
        Dataset::from_columns(
            "leg_angle_loop",
            RATE,
            0.0,
            vec![("f_alpha".into(), f), ("x".into(), x)],
        )
        .map_err(|e| e.to_string())
    }

    /// The nominal graph of the record: the identified stage (c, no delay)
    /// driven by the record's `f_alpha`, compared with its `x`, and the leg
    /// angle the driver computes, `alpha.y` = 2πT_s Σ_{j<k} f_α,j (the phase a
    /// disturbance may be periodic in: `diagnose --phase alpha.y`).
    pub fn nominal_yaml(&self) -> String {
        format!(
            "title: walking piezo stage in the Table 5.1 loop, identified model (5.31), nominal\nbase_rate_hz: {RATE}\nduration_s: {}\nblocks:\n  - {{ name: drive, type: data_column, column: f_alpha }}\n  - {{ name: stage, type: walking_piezo_fitted, gain_m_per_cycle: {:e}, delay_s: 0.0 }}\n  - {{ name: alpha, type: transfer_function, num: [{:e}], den: [1.0, -1.0], discrete: true }}\nconnections:\n  - {{ from: drive.y, to: stage.f_alpha }}\n  - {{ from: drive.y, to: alpha.u }}\ncompare:\n  - {{ signal: stage.x_s, column: x }}\n",
            self.duration_s,
            self.gain_m_per_cycle,
            2.0 * PI / RATE
        )
    }
}
