//! Sec. 4.5 / Fig. 4.14 of Merry (2009) on the simulated stage: the three
//! waveform optimisations (model-based (4.23)–(4.24) with δy = −0.5 µm and
//! −0.05 µm, data-based (4.25)) and the Fig. 4.14-style validation on the
//! perturbed stage. Called by the example `waveform_optimisation` and by
//! `nanomotion reproduce sec_4_5`; the graphs are the repository's
//! `examples/optimize_waveform/{model,data}.yaml`, compiled in.

use crate::WaveformShape;
use crate::optimize::{
    Drive, ObjectiveKind, OptimizeConfig, Outcome, Phase, Prepared, optimize, real_stage,
};
use std::ops::ControlFlow;

const MODEL_YAML: &str = include_str!("../../../../examples/optimize_waveform/model.yaml");
const DATA_YAML: &str = include_str!("../../../../examples/optimize_waveform/data.yaml");

/// One optimisation's result.
#[derive(Debug, Clone)]
pub struct OptimisationResult {
    /// e.g. "model, dy = -0.05 um".
    pub label: &'static str,
    /// The drive amplitude (V) the calibration found.
    pub amplitude_v: f64,
    /// Own objective of the 8-point start, the asymmetric waveform, SA's and
    /// PSO's best, and after Nelder–Mead (µm/s).
    pub start: f64,
    pub asymmetric: f64,
    pub sa_best: f64,
    pub pso_best: f64,
    pub optimised: f64,
    /// PSO won the global phase.
    pub pso_wins: bool,
    /// Objective evaluations.
    pub evaluations: u64,
    /// Wall time of the optimisation (s).
    pub seconds: f64,
    /// The optimised points.
    pub outcome: Outcome,
}

/// On the nominal model at 14 Hz: (name, mean velocity, rms(ẋ_r − ẋ_s), g with
/// δy = −0.5 µm), all µm/s.
pub type NominalRow = (&'static str, f64, f64, f64);

/// The Fig. 4.14-style validation at one f_α: ẋ_r (m/s) and the mean
/// rms(ẋ_r − ẋ_s,e) (µm/s) of [asymmetric, model δy −0.5, model δy −0.05, data].
#[derive(Debug, Clone, Copy)]
pub struct ValidationRow {
    pub f_alpha_hz: f64,
    pub v_m_s: f64,
    pub error_um_s: [f64; 4],
}

/// The whole Sec. 4.5 experiment.
#[derive(Debug, Clone)]
pub struct Sec45 {
    /// [model δy −0.5 µm, model δy −0.05 µm, data-based].
    pub optimisations: Vec<OptimisationResult>,
    /// The four waveforms on the nominal model at 14 Hz.
    pub nominal: Vec<NominalRow>,
    /// Validation rows, one per f_α.
    pub validation: Vec<ValidationRow>,
    /// Mean over the f_α of each column.
    pub validation_mean: [f64; 4],
    /// Validation seeds used.
    pub seeds: Vec<u64>,
}

/// An example configuration with its budget scaled by `factor`.
pub fn config(objective: &str, factor: f64) -> Result<OptimizeConfig, String> {
    let text = if objective == "model" {
        MODEL_YAML
    } else {
        DATA_YAML
    };
    let mut c = OptimizeConfig::from_yaml(text, &format!("optimize_waveform/{objective}.yaml"))
        .map_err(|e| e.to_string())?;
    c.budget = c.budget.scaled(factor);
    Ok(c)
}

fn run(
    c: &OptimizeConfig,
    label: &'static str,
    progress: &mut dyn FnMut(&str),
) -> Result<(Prepared, OptimisationResult), String> {
    let started = std::time::Instant::now();
    let p = Prepared::new(c).map_err(|e| e.to_string())?;
    let o = optimize(&p, None, &mut |pr| {
        progress(&format!(
            "  [{label}] {:<20} chunk {:>3}/{:<3} evals {:>6}  best {:.4} um/s",
            pr.phase.name(),
            pr.chunks_done,
            pr.chunks_total,
            pr.evaluations,
            pr.best_cost
        ));
        ControlFlow::Continue(())
    })
    .map_err(|e| e.to_string())?;
    let s = &o.search;
    let r = OptimisationResult {
        label,
        amplitude_v: o.amplitude_v,
        start: s.start.exact_cost(),
        asymmetric: o.asymmetric_cost,
        sa_best: s.phase(Phase::SimulatedAnnealing).best.exact_cost(),
        pso_best: s.phase(Phase::ParticleSwarm).best.exact_cost(),
        optimised: o.cost,
        pso_wins: matches!(s.global_winner(), Phase::ParticleSwarm),
        evaluations: s.evaluations(),
        seconds: started.elapsed().as_secs_f64(),
        outcome: o,
    };
    Ok((p, r))
}

/// Run Sec. 4.5 with the example budgets scaled by `factor` (1: the documented
/// figures), validating with `seeds` at `freqs` (Hz).
pub fn sec_4_5(
    factor: f64,
    seeds: &[u64],
    freqs: &[f64],
    progress: &mut dyn FnMut(&str),
) -> Result<Sec45, String> {
    // The two readings of the extracted "dy = .5 um": 0.5 um and 0.05 um (default).
    let mut c1 = config("model", factor)?;
    c1.clearance_m = -0.5e-6;
    let (pm, om) = run(&c1, "model, dy = -0.5 um", progress)?;
    let (_p2, om2) = run(&config("model", factor)?, "model, dy = -0.05 um", progress)?;
    let (_pd, od) = run(&config("data", factor)?, "data", progress)?;
    let c = &pm.config;
    if c.objective != ObjectiveKind::Model {
        return Err("model.yaml is not a model-based configuration".into());
    }
    let free = |o: &OptimisationResult| WaveformShape::Free {
        points_v: o.outcome.points,
    };
    let shapes = [
        ("asymmetric", pm.asymmetric_shape()),
        ("model-based (dy -0.5 um)", free(&om)),
        ("model-based (dy -0.05 um)", free(&om2)),
        ("data-based", free(&od)),
    ];
    let mut nominal = Vec::new();
    for (name, shape) in &shapes {
        let e = pm
            .model
            .evaluate_shape(shape.clone())
            .map_err(|e| e.to_string())?;
        nominal.push((*name, e.mean_velocity_um_s, e.stage_error_um_s, e.g_um_s));
    }
    let mut validation = Vec::new();
    let mut sums = [0.0; 4];
    for &f in freqs {
        let v = c.velocity_m_s * f / c.f_alpha_hz;
        let drive = Drive {
            f_alpha_hz: f,
            amplitude_v: om.amplitude_v,
            voltage_max_v: c.voltage_max_v,
        };
        let mut e = [0.0; 4];
        for (k, (_, shape)) in shapes.iter().enumerate() {
            for &s in seeds {
                let real = real_stage(c, s);
                let m = real
                    .measure(
                        shape.clone(),
                        &drive,
                        v,
                        c.simulation.warmup_cycles,
                        4 * c.simulation.cycles,
                    )
                    .map_err(|e| e.to_string())?;
                e[k] += m.error_um_s / seeds.len() as f64;
            }
            sums[k] += e[k] / freqs.len() as f64;
        }
        validation.push(ValidationRow {
            f_alpha_hz: f,
            v_m_s: v,
            error_um_s: e,
        });
    }
    Ok(Sec45 {
        optimisations: vec![om, om2, od],
        nominal,
        validation,
        validation_mean: sums,
        seeds: seeds.to_vec(),
    })
}
