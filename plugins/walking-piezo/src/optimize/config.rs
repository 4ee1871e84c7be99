//! The YAML configuration of `nanomotion optimize-waveform` and its validation:
//! every error names the field (with its line where it is in the file) and the fix.

use super::objective::Points;
use super::search::Budget;
use crate::stage::StageParams;
use nanomotion_core::ParamError;
use serde::{Deserialize, Serialize};
use std::fmt;
use std::path::Path;

/// Which objective to minimise.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum ObjectiveKind {
    /// Model-based (4.23)–(4.24): leg velocities of the nominal model near contact.
    Model,
    /// "Data-based" (4.25): stage velocity error measured on the perturbed stage.
    Data,
}

impl ObjectiveKind {
    /// `model` or `data`.
    pub fn name(self) -> &'static str {
        match self {
            ObjectiveKind::Model => "model",
            ObjectiveKind::Data => "data",
        }
    }
}

/// Simulation lengths.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct SimulationSettings {
    /// Drive cycles simulated before scoring (start-up from rest).
    pub warmup_cycles: u32,
    /// Drive cycles scored.
    pub cycles: u32,
}

impl Default for SimulationSettings {
    fn default() -> Self {
        Self {
            warmup_cycles: 1,
            cycles: 3,
        }
    }
}

/// The stage that plays the real setup in the data-based objective and in the
/// evaluation (Fig. 4.14).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct RealSettings {
    /// Seed of the parameter perturbation (which "setup" it is).
    pub seed: u64,
    /// Seed of the experiments run during the optimisation (μ profile and noise);
    /// validation runs use other seeds.
    pub experiment_seed: u64,
    /// Relative standard deviation of the parameter perturbation.
    pub perturbation_rel: f64,
    /// Keep the seeded μ variation (per pair, along the strip, in time) on.
    pub mu_variation: bool,
    /// Position measurement noise (m, rms).
    pub noise_m: f64,
    /// Sampling frequency of the measurement and the driver (Hz); thesis 4 kHz.
    pub sample_hz: f64,
    /// Solver sub-steps per sample (10 at 4 kHz is the thesis's 25 µs).
    pub substeps: u32,
    /// Order of the zero-phase low-pass on the differentiated position; thesis 5.
    pub filter_order: usize,
    /// Its cut-off (Hz); thesis "5 Hz" as extracted, read as 50 Hz.
    pub filter_hz: f64,
}

impl Default for RealSettings {
    fn default() -> Self {
        Self {
            seed: 11,
            experiment_seed: 1,
            perturbation_rel: 0.03,
            mu_variation: true,
            noise_m: 2e-9,
            sample_hz: 4000.0,
            substeps: 10,
            filter_order: 5,
            filter_hz: 50.0,
        }
    }
}

/// The configuration of a waveform optimisation (Sec. 4.5).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct OptimizeConfig {
    /// Free text.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub title: Option<String>,
    /// `model` (4.23)–(4.24) or `data` (4.25).
    pub objective: ObjectiveKind,
    /// Drive frequency f_α (Hz) of the optimisation; thesis 14 Hz.
    #[serde(default = "d_f")]
    pub f_alpha_hz: f64,
    /// Reference velocity ẋ_r (m/s); thesis 50 µm/s.
    #[serde(default = "d_v")]
    pub velocity_m_s: f64,
    /// Drive amplitude A (V) for every waveform; leave out to calibrate it so that
    /// the asymmetric waveform walks at `velocity_m_s` at `f_alpha_hz` on the
    /// nominal model (the thesis's choice of f_α, transferred to our stage).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub amplitude_v: Option<f64>,
    /// Amplifier range V_max (V); the points are bounded to [0, V_max].
    #[serde(default = "d_vmax")]
    pub voltage_max_v: f64,
    /// Clearance δy (m) of (4.24); negative is an open distance to the strip.
    #[serde(default = "d_dy")]
    pub clearance_m: f64,
    /// Overlap q of the asymmetric reference waveform (and of the default start).
    #[serde(default = "d_q")]
    pub overlap_q: f64,
    /// Start points ξ₀ (4 × 8 V); default: the asymmetric waveform sampled.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub start_points_v: Option<Points>,
    /// Seed of the search.
    #[serde(default)]
    pub seed: u64,
    /// Simulation lengths.
    #[serde(default)]
    pub simulation: SimulationSettings,
    /// Budgets per phase.
    #[serde(default)]
    pub budget: Budget,
    /// The nominal model (fields of `walking_piezo_stage`); default: the default
    /// parameters without μ variation.
    #[serde(default = "d_stage")]
    pub stage: StageParams,
    /// The "real" stage.
    #[serde(default)]
    pub real: RealSettings,
}

fn d_f() -> f64 {
    14.0
}
fn d_v() -> f64 {
    50e-6
}
fn d_vmax() -> f64 {
    46.0
}
fn d_dy() -> f64 {
    -0.05e-6
}
fn d_q() -> f64 {
    1.0 / 3.0
}
fn d_stage() -> StageParams {
    StageParams::default().without_mu_variation()
}

/// A configuration that cannot be used.
#[derive(Debug, Clone, PartialEq)]
pub enum ConfigError {
    /// The file could not be read.
    Io {
        /// The file.
        origin: String,
        /// The system's message.
        message: String,
    },
    /// The YAML does not parse or does not match the schema (unknown field, wrong
    /// type); the message carries line and column.
    Parse {
        /// The file.
        origin: String,
        /// The parser's message.
        message: String,
    },
    /// A value is out of its range.
    Invalid {
        /// The file.
        origin: String,
        /// The field, as a path (`budget.sa.iterations`, `start_points_v[1][3]`).
        field: String,
        /// Line and column of the field in the file, when it is there.
        location: Option<(usize, usize)>,
        /// What is wrong.
        problem: String,
        /// How to fix it.
        fix: String,
    },
}

impl ConfigError {
    /// The offending field, for [`ConfigError::Invalid`].
    pub fn field(&self) -> Option<&str> {
        match self {
            ConfigError::Invalid { field, .. } => Some(field),
            _ => None,
        }
    }
}

impl fmt::Display for ConfigError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            ConfigError::Io { origin, message } => write!(f, "{origin}: {message}"),
            ConfigError::Parse { origin, message } => write!(f, "{origin}: {message}"),
            ConfigError::Invalid {
                origin,
                field,
                location,
                problem,
                fix,
            } => {
                write!(f, "{origin}")?;
                if let Some((l, c)) = location {
                    write!(f, ":{l}:{c}")?;
                }
                write!(f, ": field `{field}`: {problem} (fix: {fix})")
            }
        }
    }
}

impl std::error::Error for ConfigError {}

/// Line and column (1-based) of a dotted field path in YAML text: each segment
/// (indices dropped) is searched as a key after the previous one.
pub fn locate(text: &str, field: &str) -> Option<(usize, usize)> {
    let mut from = 0usize;
    let mut found = None;
    for seg in field.split('.') {
        let key = seg.split('[').next().unwrap_or(seg);
        if key.is_empty() {
            continue;
        }
        let mut hit = None;
        for (ln, line) in text.lines().enumerate().skip(from) {
            let code = line.split('#').next().unwrap_or("");
            let mut search = 0;
            while let Some(pos) = code[search..].find(key) {
                let at = search + pos;
                let before = code[..at].chars().last();
                let after = code[at + key.len()..].trim_start();
                let boundary = before.is_none_or(|c| !(c.is_alphanumeric() || c == '_'));
                if boundary && after.starts_with(':') {
                    hit = Some((ln, at));
                    break;
                }
                search = at + key.len();
            }
            if hit.is_some() {
                break;
            }
        }
        match hit {
            Some((ln, col)) => {
                from = ln;
                found = Some((ln + 1, col + 1));
            }
            None => break,
        }
    }
    found
}

impl OptimizeConfig {
    /// Parse YAML text (`origin` names it in errors) and validate it.
    pub fn from_yaml(text: &str, origin: &str) -> Result<Self, ConfigError> {
        let cfg: Self =
            nanomotion_core::yaml::from_str(text, origin).map_err(|e| ConfigError::Parse {
                origin: origin.to_string(),
                message: match e {
                    nanomotion_core::GraphError::Parse { message, .. } => message,
                    other => other.to_string(),
                },
            })?;
        cfg.validate().map_err(|e| ConfigError::Invalid {
            origin: origin.to_string(),
            location: locate(text, &e.field),
            field: e.field,
            problem: e.problem,
            fix: e.fix,
        })?;
        Ok(cfg)
    }

    /// Read, parse and validate a file.
    pub fn from_file(path: &Path) -> Result<Self, ConfigError> {
        let origin = path.display().to_string();
        // Bounded like a graph file (`/dev/zero` is an error, not an endless read).
        let text = nanomotion_core::graph::read_text_capped(
            path,
            nanomotion_core::graph::MAX_GRAPH_FILE_BYTES,
        )
        .map_err(|e| ConfigError::Io {
            origin: origin.clone(),
            message: e.to_string(),
        })?;
        Self::from_yaml(&text, &origin)
    }

    /// Check every field; the error names it.
    pub fn validate(&self) -> Result<(), ParamError> {
        use nanomotion_core::block::check;
        let err =
            |field: &str, problem: String, fix: &str| Err(ParamError::new(field, problem, fix));
        check::positive("voltage_max_v", self.voltage_max_v)?;
        let vmax = self.voltage_max_v;
        if !(self.f_alpha_hz.is_finite() && (1.0..=200.0).contains(&self.f_alpha_hz)) {
            return err(
                "f_alpha_hz",
                format!(
                    "is {}, must be a finite drive frequency in [1, 200] Hz",
                    self.f_alpha_hz
                ),
                "give the drive frequency, e.g. 14 (thesis)",
            );
        }
        if !(self.velocity_m_s.is_finite() && self.velocity_m_s > 0.0 && self.velocity_m_s < 0.1) {
            return err(
                "velocity_m_s",
                format!("is {}, must be in (0, 0.1) m/s", self.velocity_m_s),
                "give the reference velocity, e.g. 50.0e-6 (thesis)",
            );
        }
        if let Some(a) = self.amplitude_v
            && !(a.is_finite() && a > 0.0 && a <= vmax)
        {
            return err(
                "amplitude_v",
                format!("is {a}, outside the voltage range (0, {vmax}] V"),
                "give an amplitude within the amplifier range, or leave it out to calibrate it",
            );
        }
        if !(self.clearance_m.is_finite() && self.clearance_m.abs() <= 10e-6) {
            return err(
                "clearance_m",
                format!("is {}, must be finite and within ±10 µm", self.clearance_m),
                "give δy in metres, e.g. -0.05e-6 (0.05 µm above the strip)",
            );
        }
        if !(self.overlap_q.is_finite() && self.overlap_q > 0.0 && self.overlap_q < 1.0) {
            return err(
                "overlap_q",
                format!("is {}, must be in the open interval (0, 1)", self.overlap_q),
                "give the relative overlap, e.g. 0.3333 (thesis)",
            );
        }
        if let Some(p) = &self.start_points_v {
            for (i, ch) in p.iter().enumerate() {
                for (j, &v) in ch.iter().enumerate() {
                    if !(v.is_finite() && (0.0..=vmax).contains(&v)) {
                        return err(
                            &format!("start_points_v[{i}][{j}]"),
                            format!("is {v}, outside [0, {vmax}] V"),
                            "give waveform points within the amplifier range",
                        );
                    }
                }
            }
        }
        if self.simulation.cycles == 0 || self.simulation.cycles > 100 {
            return err(
                "simulation.cycles",
                format!("is {}, must be in 1..=100", self.simulation.cycles),
                "score a few drive cycles, e.g. 3",
            );
        }
        if self.simulation.warmup_cycles > 100 {
            return err(
                "simulation.warmup_cycles",
                format!("is {}, must be at most 100", self.simulation.warmup_cycles),
                "warm up for a cycle or two",
            );
        }
        let b = &self.budget;
        let pos = |v: f64| v.is_finite() && v > 0.0;
        let count = |field: &str, v: u32, min: u32| {
            if v < min || v > 1_000_000 {
                err(
                    field,
                    format!("is {v}, must be in {min}..=1000000"),
                    "give a positive count",
                )
            } else {
                Ok(())
            }
        };
        count("budget.sa.chunks", b.sa.chunks, 0)?;
        count("budget.sa.iterations", b.sa.iterations, 1)?;
        count("budget.pso.chunks", b.pso.chunks, 0)?;
        count("budget.pso.iterations", b.pso.iterations, 1)?;
        count("budget.pso.particles", b.pso.particles, 2)?;
        count("budget.local.chunks", b.local.chunks, 0)?;
        count("budget.local.iterations", b.local.iterations, 1)?;
        for (field, v) in [
            ("budget.sa.temperature", b.sa.temperature),
            ("budget.sa.step_v", b.sa.step_v),
            ("budget.pso.spread_v", b.pso.spread_v),
            ("budget.local.step_v", b.local.step_v),
        ] {
            if !pos(v) {
                return err(
                    field,
                    format!("is {v}, must be finite and > 0"),
                    "give a positive value",
                );
            }
        }
        self.stage
            .validate(super::objective::MODEL_DT_S)
            .map_err(|e| ParamError::new(format!("stage.{}", e.field), e.problem, e.fix))?;
        let r = &self.real;
        if !(r.perturbation_rel.is_finite() && (0.0..=0.3).contains(&r.perturbation_rel)) {
            return err(
                "real.perturbation_rel",
                format!("is {}, must be in [0, 0.3]", r.perturbation_rel),
                "give a few percent, e.g. 0.03",
            );
        }
        if !(r.noise_m.is_finite() && (0.0..=1e-6).contains(&r.noise_m)) {
            return err(
                "real.noise_m",
                format!("is {}, must be in [0, 1e-6] m", r.noise_m),
                "give the position noise in metres, e.g. 2.0e-9",
            );
        }
        if !(r.sample_hz.is_finite() && (100.0..=40_000.0).contains(&r.sample_hz)) {
            return err(
                "real.sample_hz",
                format!("is {}, must be in [100, 40000] Hz", r.sample_hz),
                "give the sampling frequency, e.g. 4000 (thesis)",
            );
        }
        if r.substeps == 0 || r.substeps > 100 {
            return err(
                "real.substeps",
                format!("is {}, must be in 1..=100", r.substeps),
                "give 10 at 4 kHz (25 µs steps)",
            );
        }
        if r.filter_order == 0 || r.filter_order > 12 {
            return err(
                "real.filter_order",
                format!("is {}, must be in 1..=12", r.filter_order),
                "give 5 (thesis)",
            );
        }
        if !(r.filter_hz.is_finite() && r.filter_hz > 0.0 && r.filter_hz < 0.5 * r.sample_hz) {
            return err(
                "real.filter_hz",
                format!("is {}, must be in (0, sample_hz/2)", r.filter_hz),
                "give the low-pass cut-off, e.g. 50",
            );
        }
        Ok(())
    }
}
