//! **Waveform optimisation** (thesis Sec. 4.5): find the 4 × 8 points ξ (V) of the
//! free drive waveforms (4.21)–(4.22) that drive the stage most smoothly at a
//! reference velocity.
//!
//! - [`objective`]: the model-based objective (4.23)–(4.24) — leg x-velocities of
//!   the nominal model scored against ẋ_r while the leg is within the clearance δy
//!   of the strip — and the "data-based" objective (4.25) — rms(ẋ_r − ẋ_s,e) of the
//!   stage velocity measured (4 kHz, noise, numerical differentiation, zero-phase
//!   5th-order low-pass) on a *perturbed* stage with μ variation that plays the real
//!   setup. Waveforms are made by the driver's own code ([`crate::WaveformDriver`]
//!   with `shape: free`).
//! - [`search`]: simulated annealing and particle swarm from `argmin`, then
//!   Nelder–Mead, seeded and resumable per chunk.
//! - [`config`]: the YAML configuration with typed errors naming the field.
//! - here: amplitude calibration, the resumable run file, the driver YAML fragment.
//!
//! **Reading of the thesis's numbers** (its digit 0 was lost in the extraction):
//! ẋ_r = 50 µm/s, f_α = 14 Hz, δy = −0.05 µm (an open distance; the extraction
//! also drops minus signs; "δy = .5 µm" reads as 0.5 or 0.05 µm — with our
//! calibrated amplitude the legs' y-stroke is only ≈ 1.4 µm, and δy = −0.5 µm counts
//! a third of it, return strokes included, as "near contact": its optimum slows
//! the stage to half the reference, see `docs/plugins/walking-piezo.md`), the
//! low-pass cut-off 50 Hz, and the lost
//! value of x̄_i outside the clearance in (4.24) is 0 (the extracted text shows an
//! empty slot where a lone "0" stood). **ẋ_r and f_α:** the thesis chose f_α as
//! the frequency at which the asymmetric waveform walks at ẋ_r. Our stage makes
//! ≈ 7 µm per cycle at 46 V where the thesis's made ≈ 3.6 µm (50 µm/s / 14 Hz), so
//! we keep the thesis's f_α and ẋ_r and instead calibrate the drive amplitude A
//! (applied to every waveform as A/46 V, as the driver does) so that the
//! asymmetric waveform walks at ẋ_r at f_α on the nominal model. At another f_α
//! the reference is ẋ_r·f_α/f_α,opt (the asymmetric waveform's nominal speed
//! there), as along the velocity axis of Fig. 4.14.

pub mod config;
pub mod objective;
pub mod search;

pub use config::{ConfigError, ObjectiveKind, OptimizeConfig, RealSettings, SimulationSettings};
pub use objective::{
    DataObjective, Drive, LegVelocityCost, Measurement, ModelEvaluation, ModelObjective, Points,
    RealStage, asymmetric_points, perturb, points_from_slice, points_to_vec,
};
pub use search::{Budget, Incumbent, Phase, Progress, SearchError, SearchState, run_search};

use crate::driver::WaveformShape;
use nanomotion_core::rng::derive_seed;
use serde::{Deserialize, Serialize};
use std::ops::ControlFlow;
use std::path::Path;

/// Format tag of the run file.
pub const RUN_FILE_FORMAT: &str = "nanomotion-optimize-waveform/1";

/// Why an optimisation could not run.
#[derive(Debug, thiserror::Error)]
pub enum OptimizeError {
    /// The configuration is invalid.
    #[error(transparent)]
    Config(#[from] ConfigError),
    /// The amplitude cannot be calibrated.
    #[error(
        "field `velocity_m_s`: the asymmetric waveform walks at only {reached_um_s:.2} µm/s at f_alpha_hz = {f_alpha_hz} Hz with the full range {voltage_max_v} V, below the reference {velocity_um_s:.2} µm/s (fix: lower velocity_m_s or raise f_alpha_hz)"
    )]
    Unreachable {
        /// Reached velocity (µm/s).
        reached_um_s: f64,
        /// Reference (µm/s).
        velocity_um_s: f64,
        /// f_α (Hz).
        f_alpha_hz: f64,
        /// V_max (V).
        voltage_max_v: f64,
    },
    /// A simulation failed outright (bad model parameters).
    #[error("simulation: {0}")]
    Simulation(String),
    /// The search failed.
    #[error(transparent)]
    Search(#[from] SearchError),
    /// The run file is unreadable or belongs to another configuration.
    #[error("run file {path}: {problem} (fix: {fix})")]
    RunFile {
        /// The file.
        path: String,
        /// What is wrong.
        problem: String,
        /// How to fix it.
        fix: String,
    },
}

/// A configuration made ready to run: amplitude calibrated, objectives built.
#[derive(Debug, Clone)]
pub struct Prepared {
    /// The configuration.
    pub config: OptimizeConfig,
    /// Drive settings at the optimisation's f_α (amplitude calibrated or given).
    pub drive: Drive,
    /// The model-based objective.
    pub model: ModelObjective,
    /// The data-based objective (its real stage with the optimisation's experiment
    /// seed).
    pub data: DataObjective,
    /// Start point ξ₀ (flat, channel-major).
    pub x0: Vec<f64>,
}

impl Prepared {
    /// Validate, calibrate the amplitude and build the objectives.
    pub fn new(config: &OptimizeConfig) -> Result<Self, OptimizeError> {
        config.validate().map_err(|e| ConfigError::Invalid {
            origin: "config".into(),
            field: e.field,
            location: None,
            problem: e.problem,
            fix: e.fix,
        })?;
        let c = config;
        let amplitude_v = match c.amplitude_v {
            Some(a) => a,
            None => calibrate_amplitude(c)?,
        };
        let drive = Drive {
            f_alpha_hz: c.f_alpha_hz,
            amplitude_v,
            voltage_max_v: c.voltage_max_v,
        };
        let model = ModelObjective {
            stage: c.stage.clone(),
            drive,
            velocity_m_s: c.velocity_m_s,
            clearance_m: c.clearance_m,
            warmup_cycles: c.simulation.warmup_cycles,
            cycles: c.simulation.cycles,
        };
        let data = DataObjective {
            real: real_stage(c, c.real.experiment_seed),
            drive,
            velocity_m_s: c.velocity_m_s,
            warmup_cycles: c.simulation.warmup_cycles,
            cycles: c.simulation.cycles,
        };
        let x0 = points_to_vec(
            &c.start_points_v
                .unwrap_or_else(|| asymmetric_points(c.overlap_q)),
        );
        Ok(Self {
            config: c.clone(),
            drive,
            model,
            data,
            x0,
        })
    }

    /// The configured objective at ξ (flat, projected into the range), µm/s.
    pub fn cost(&self, xi: &[f64]) -> f64 {
        let p = points_from_slice(xi, self.config.voltage_max_v);
        match self.config.objective {
            ObjectiveKind::Model => self.model.cost(&p),
            ObjectiveKind::Data => self.data.cost(&p),
        }
    }

    /// The configured objective for any driver shape (µm/s).
    pub fn cost_of_shape(&self, shape: WaveformShape) -> Result<f64, OptimizeError> {
        match self.config.objective {
            ObjectiveKind::Model => self.model.evaluate_shape(shape).map(|e| e.g_um_s),
            ObjectiveKind::Data => self.data.evaluate_shape(shape).map(|m| m.error_um_s),
        }
        .map_err(OptimizeError::Simulation)
    }

    /// The exact asymmetric waveform (Sec. 2.4.1) with the configured q.
    pub fn asymmetric_shape(&self) -> WaveformShape {
        WaveformShape::Asymmetric {
            overlap_q: self.config.overlap_q,
        }
    }

    /// A fingerprint of everything that determines the run's bits (configuration
    /// and calibrated amplitude): a run file is resumed only under the same one.
    pub fn fingerprint(&self) -> u64 {
        let text = serde_json::to_string(&self.config).unwrap_or_default();
        let mut h: u64 = 0xCBF2_9CE4_8422_2325;
        for b in text
            .bytes()
            .chain(self.drive.amplitude_v.to_bits().to_le_bytes())
        {
            h ^= u64::from(b);
            h = h.wrapping_mul(0x0000_0100_0000_01B3);
        }
        h
    }
}

/// The perturbed stage of `config.real`, with μ profile and noise seeded from
/// `experiment_seed` (the setup itself, i.e. the perturbation, is `real.seed`).
pub fn real_stage(config: &OptimizeConfig, experiment_seed: u64) -> RealStage {
    let r = &config.real;
    let mut params = perturb(&config.stage, r.perturbation_rel, r.seed);
    let nominal_mu = crate::stage::StageParams::default();
    if r.mu_variation {
        // The nominal model has none by default: the real stage gets the defaults.
        if params.mu_pair_rel == 0.0
            && params.mu_spatial_rel == 0.0
            && params.mu_temporal_rel == 0.0
        {
            params.mu_pair_rel = nominal_mu.mu_pair_rel;
            params.mu_spatial_rel = nominal_mu.mu_spatial_rel;
            params.mu_temporal_rel = nominal_mu.mu_temporal_rel;
        }
    } else {
        params = params.without_mu_variation();
    }
    params.substeps = r.substeps;
    RealStage {
        params,
        mu_seed: derive_seed(experiment_seed, "mu"),
        noise_seed: derive_seed(experiment_seed, "noise"),
        noise_m: r.noise_m,
        sample_hz: r.sample_hz,
        filter_order: r.filter_order,
        filter_hz: r.filter_hz,
    }
}

/// The amplitude A (V) at which the asymmetric waveform walks at `velocity_m_s`
/// at `f_alpha_hz` on the nominal model (Illinois regula falsi on [0, V_max],
/// relative tolerance 1e-4).
pub fn calibrate_amplitude(c: &OptimizeConfig) -> Result<f64, OptimizeError> {
    let shape = WaveformShape::Asymmetric {
        overlap_q: c.overlap_q,
    };
    let v_at = |a: f64| {
        objective::mean_velocity(
            &c.stage,
            &Drive {
                f_alpha_hz: c.f_alpha_hz,
                amplitude_v: a,
                voltage_max_v: c.voltage_max_v,
            },
            shape.clone(),
            c.simulation.warmup_cycles,
            c.simulation.cycles,
        )
        .map_err(OptimizeError::Simulation)
    };
    let target = c.velocity_m_s;
    let (mut a_hi, mut f_hi) = (c.voltage_max_v, v_at(c.voltage_max_v)? - target);
    if f_hi < 0.0 {
        return Err(OptimizeError::Unreachable {
            reached_um_s: (f_hi + target) * 1e6,
            velocity_um_s: target * 1e6,
            f_alpha_hz: c.f_alpha_hz,
            voltage_max_v: c.voltage_max_v,
        });
    }
    let (mut a_lo, mut f_lo) = (0.0, -target);
    let mut side = 0i32;
    let mut a = a_hi;
    for _ in 0..40 {
        a = (a_lo * f_hi - a_hi * f_lo) / (f_hi - f_lo);
        let f = v_at(a)? - target;
        if f.abs() < 1e-4 * target {
            break;
        }
        if f > 0.0 {
            a_hi = a;
            f_hi = f;
            if side == 1 {
                f_lo *= 0.5;
            }
            side = 1;
        } else {
            a_lo = a;
            f_lo = f;
            if side == -1 {
                f_hi *= 0.5;
            }
            side = -1;
        }
    }
    Ok(a)
}

/// The run file: everything needed to resume a run bit for bit.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct RunFile {
    /// [`RUN_FILE_FORMAT`].
    pub format: String,
    /// [`Prepared::fingerprint`] of the configuration it belongs to.
    pub fingerprint: u64,
    /// Objective (informative).
    pub objective: ObjectiveKind,
    /// Amplitude A (V) used (informative; part of the fingerprint).
    pub amplitude_v: f64,
    /// Whether every phase is done.
    pub finished: bool,
    /// The search state.
    pub search: SearchState,
    /// The configuration it belongs to (to explain a refused resume); absent in
    /// run files written before it was recorded.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub config: Option<serde_json::Value>,
}

/// Where two configurations (as JSON) differ: `path: old -> new` lines, at
/// most `max` of them.
fn config_differences(old: &serde_json::Value, new: &serde_json::Value, max: usize) -> Vec<String> {
    fn walk(path: &str, a: &serde_json::Value, b: &serde_json::Value, out: &mut Vec<String>) {
        use serde_json::Value;
        match (a, b) {
            (Value::Object(x), Value::Object(y)) => {
                let mut keys: Vec<&String> = x.keys().chain(y.keys()).collect();
                keys.sort();
                keys.dedup();
                for k in keys {
                    let p = if path.is_empty() {
                        k.clone()
                    } else {
                        format!("{path}.{k}")
                    };
                    walk(
                        &p,
                        x.get(k).unwrap_or(&Value::Null),
                        y.get(k).unwrap_or(&Value::Null),
                        out,
                    );
                }
            }
            _ if a != b => out.push(format!("{path}: {a} -> {b}")),
            _ => {}
        }
    }
    let mut out = Vec::new();
    walk("", old, new, &mut out);
    let n = out.len();
    out.truncate(max);
    if n > max {
        out.push(format!("... and {} more", n - max));
    }
    out
}

/// Why run file `f` does not belong to `prepared`, in the user's terms.
fn refusal_reason(f: &RunFile, prepared: &Prepared) -> String {
    let c = &prepared.config;
    let mut diffs = match (&f.config, serde_json::to_value(c)) {
        (Some(old), Ok(new)) => config_differences(old, &new, 6),
        _ => Vec::new(),
    };
    if diffs.is_empty() {
        // An older run file: compare what it does record.
        if f.objective != c.objective {
            diffs.push(format!(
                "objective: {} -> {}",
                f.objective.name(),
                c.objective.name()
            ));
        }
        if f.search.seed != c.seed {
            diffs.push(format!("seed: {} -> {}", f.search.seed, c.seed));
        }
        let now = [
            c.budget.sa.chunks,
            c.budget.pso.chunks,
            c.budget.local.chunks,
        ];
        for (rec, n) in f.search.phases.iter().zip(now) {
            if rec.chunks != n {
                diffs.push(format!(
                    "{} chunks: {} -> {n}",
                    rec.phase.name(),
                    rec.chunks
                ));
            }
        }
    }
    if f.amplitude_v.to_bits() != prepared.drive.amplitude_v.to_bits() {
        diffs.push(format!(
            "amplitude A: {} V -> {} V",
            f.amplitude_v, prepared.drive.amplitude_v
        ));
    }
    if diffs.is_empty() {
        "belongs to another configuration (or budget)".into()
    } else {
        format!(
            "belongs to another configuration (or budget): {} (--budget scales the budget's iterations, so a different --budget is a different run)",
            diffs.join("; ")
        )
    }
}

/// Result of [`optimize`].
#[derive(Debug, Clone)]
pub struct Outcome {
    /// The search state (incumbents of every phase, evaluations).
    pub search: SearchState,
    /// Whether every phase finished (false when the progress callback stopped it).
    pub finished: bool,
    /// The best points ξ (V).
    pub points: Points,
    /// Their cost (µm/s).
    pub cost: f64,
    /// The cost of the exact asymmetric waveform on the same objective (µm/s).
    pub asymmetric_cost: f64,
    /// Amplitude A (V).
    pub amplitude_v: f64,
}

fn run_file_error(path: &Path, problem: impl Into<String>, fix: &str) -> OptimizeError {
    OptimizeError::RunFile {
        path: path.display().to_string(),
        problem: problem.into(),
        fix: fix.into(),
    }
}

/// Read a run file.
pub fn read_run_file(path: &Path) -> Result<RunFile, OptimizeError> {
    let text = nanomotion_core::graph::read_text_capped(
        path,
        nanomotion_core::graph::MAX_GRAPH_FILE_BYTES,
    )
    .map_err(|e| run_file_error(path, e.to_string(), "check the path"))?;
    let f: RunFile = serde_json::from_str(&text).map_err(|e| {
        run_file_error(
            path,
            format!("not a run file: {e}"),
            "delete it to start afresh",
        )
    })?;
    if f.format != RUN_FILE_FORMAT {
        return Err(run_file_error(
            path,
            format!("format `{}`, expected `{RUN_FILE_FORMAT}`", f.format),
            "delete it to start afresh",
        ));
    }
    Ok(f)
}

fn write_run_file(path: &Path, f: &RunFile) -> Result<(), OptimizeError> {
    let text = serde_json::to_string_pretty(f)
        .map_err(|e| run_file_error(path, e.to_string(), "report this"))?;
    let tmp = path.with_extension("json.tmp");
    std::fs::write(&tmp, text)
        .and_then(|()| std::fs::rename(&tmp, path))
        .map_err(|e| run_file_error(path, e.to_string(), "check that the folder is writable"))
}

/// Run the optimisation of `prepared`, writing the run file `run_file` (if given)
/// after every chunk and resuming from it when it exists. `progress` is called
/// after every chunk; returning `Break` stops the run there (resumable).
pub fn optimize(
    prepared: &Prepared,
    run_file: Option<&Path>,
    progress: &mut dyn FnMut(&Progress) -> ControlFlow<()>,
) -> Result<Outcome, OptimizeError> {
    let c = &prepared.config;
    let fingerprint = prepared.fingerprint();
    let vmax = c.voltage_max_v;
    let mut state = match run_file.filter(|p| p.exists()) {
        Some(path) => {
            let f = read_run_file(path)?;
            if f.fingerprint != fingerprint {
                return Err(run_file_error(
                    path,
                    refusal_reason(&f, prepared),
                    "run with the configuration and --budget it was made with to continue it, or delete it (or write to another --out folder) to start afresh",
                ));
            }
            let x = f.search.start.point();
            if x.len() != objective::N_PARAMS
                || f.search.phases.len() != 3
                || x.iter()
                    .any(|v| !(v.is_finite() && (0.0..=vmax).contains(v)))
            {
                return Err(run_file_error(
                    path,
                    "its start point is not 32 waveform points in the range",
                    "delete it to start afresh",
                ));
            }
            f.search
        }
        None => {
            let c0 = prepared.cost(&prepared.x0);
            SearchState::new(&prepared.x0, c0, &c.budget, c.seed)
        }
    };
    let lo = vec![0.0; objective::N_PARAMS];
    let hi = vec![vmax; objective::N_PARAMS];
    let cost = |x: &[f64]| prepared.cost(x);
    let mut write_err = None;
    let finished = run_search(&cost, &lo, &hi, &c.budget, &mut state, &mut |s, p| {
        if let Some(path) = run_file {
            let f = RunFile {
                format: RUN_FILE_FORMAT.into(),
                fingerprint,
                objective: c.objective,
                amplitude_v: prepared.drive.amplitude_v,
                finished: s.finished(),
                search: s.clone(),
                config: serde_json::to_value(c).ok(),
            };
            if let Err(e) = write_run_file(path, &f) {
                write_err = Some(e);
                return ControlFlow::Break(());
            }
        }
        tracing::debug!(
            target: "walking_piezo::optimize",
            phase = p.phase.name(),
            chunks_done = p.chunks_done,
            best_cost = p.best_cost,
            evaluations = p.evaluations,
            "waveform optimisation chunk done"
        );
        progress(p)
    })?;
    if let Some(e) = write_err {
        return Err(e);
    }
    if let Some(path) = run_file
        && !path.exists()
    {
        // Nothing to run (all budgets zero): still leave the state behind.
        write_run_file(
            path,
            &RunFile {
                format: RUN_FILE_FORMAT.into(),
                fingerprint,
                objective: c.objective,
                amplitude_v: prepared.drive.amplitude_v,
                finished,
                search: state.clone(),
                config: serde_json::to_value(c).ok(),
            },
        )?;
    }
    let best = state.best().clone();
    let asymmetric_cost = prepared.cost_of_shape(prepared.asymmetric_shape())?;
    Ok(Outcome {
        points: points_from_slice(&best.point(), vmax),
        cost: best.exact_cost(),
        search: state,
        finished,
        asymmetric_cost,
        amplitude_v: prepared.drive.amplitude_v,
    })
}

/// The optimised waveform as a YAML fragment for a `walking_piezo_driver` block
/// (its `shape` and `amplitude_v`), with a comment header. Numbers are written in
/// Rust's shortest round-trip form, so the driver reads back the same bits.
pub fn waveform_yaml(prepared: &Prepared, outcome: &Outcome) -> String {
    let c = &prepared.config;
    let mut s = String::new();
    s.push_str("# Optimised free waveforms (Merry 2009, Sec. 4.5), written by\n");
    s.push_str("# `nanomotion optimize-waveform`: paste into a walking_piezo_driver block.\n");
    s.push_str(&format!(
        "# objective {} ({}), f_alpha {} Hz, reference {} um/s, clearance {} um, seed {}\n",
        c.objective.name(),
        match c.objective {
            ObjectiveKind::Model => "(4.23)-(4.24)",
            ObjectiveKind::Data => "(4.25)",
        },
        c.f_alpha_hz,
        c.velocity_m_s * 1e6,
        (c.clearance_m * 1e9).round() / 1e3,
        c.seed
    ));
    s.push_str(&format!(
        "# cost {:.4} um/s (asymmetric waveform: {:.4} um/s), {} evaluations{}\n",
        outcome.cost,
        outcome.asymmetric_cost,
        outcome.search.evaluations(),
        if outcome.finished {
            ""
        } else {
            ", run not finished"
        }
    ));
    s.push_str("shape:\n  kind: free\n  points_v:\n");
    for ch in &outcome.points {
        let v: Vec<String> = ch.iter().map(|x| format!("{x}")).collect();
        s.push_str(&format!("    - [{}]\n", v.join(", ")));
    }
    s.push_str(&format!("amplitude_v: {}\n", outcome.amplitude_v));
    s.push_str(&format!("voltage_max_v: {}\n", c.voltage_max_v));
    s
}
