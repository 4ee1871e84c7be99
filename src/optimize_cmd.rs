//! `nanomotion optimize-waveform CONFIG.yaml`: the waveform optimisation of thesis
//! Sec. 4.5 (library: `walking_piezo::optimize`), with a progress bar on stderr, a
//! resumable run file and the optimised waveform as a driver YAML fragment.

use indicatif::{ProgressBar, ProgressStyle};
use nanomotion::output::signals::interrupted;
use nanomotion::output::{FolderLock, OutputError, write_atomic};
use nanomotion::walking_piezo::optimize::{
    OptimizeConfig, Phase, Prepared, optimize, read_run_file, waveform_yaml,
};
use std::ops::ControlFlow;
use std::path::Path;
use std::time::Instant;

/// Run file name inside the output folder.
pub const RUN_FILE: &str = "run.json";
/// Waveform fragment name inside the output folder.
pub const WAVEFORM_FILE: &str = "waveform.yaml";

/// Run (or resume) the optimisation of `config` into `out`; `budget` scales every
/// phase's iterations per chunk.
pub fn optimize_waveform(config: &Path, out: &Path, budget: Option<f64>) -> Result<(), String> {
    let mut cfg = OptimizeConfig::from_file(config).map_err(|e| e.to_string())?;
    if let Some(f) = budget {
        if !(f.is_finite() && f > 0.0 && f <= 1000.0) {
            return Err(format!(
                "--budget {f}: must be a factor in (0, 1000] on every phase's iterations (fix: e.g. --budget 0.1 for a quick run)"
            ));
        }
        cfg.budget = cfg.budget.scaled(f);
    }
    // One optimisation at a time writes a run file (a second is refused).
    let _lock = FolderLock::acquire(out).map_err(|e| e.to_string())?;
    let run_file = out.join(RUN_FILE);
    let start = Instant::now();
    tell!(
        "{}: {} objective at f_alpha = {} Hz, v_r = {} um/s",
        config.display(),
        cfg.objective.name(),
        cfg.f_alpha_hz,
        cfg.velocity_m_s * 1e6
    );
    let prepared = Prepared::new(&cfg).map_err(|e| e.to_string())?;
    if run_file.exists() {
        let f = read_run_file(&run_file).map_err(|e| e.to_string())?;
        let done: u32 = f.search.phases.iter().map(|p| p.chunks_done).sum();
        if f.fingerprint == prepared.fingerprint() {
            tell!("resuming from {} ({done} chunks done)", run_file.display());
        }
    }
    let total: u32 = [
        cfg.budget.sa.chunks,
        cfg.budget.pso.chunks,
        cfg.budget.local.chunks,
    ]
    .iter()
    .sum();
    let bar = ProgressBar::new(u64::from(total));
    bar.set_style(
        ProgressStyle::with_template(
            "{spinner} {msg:<44} [{bar:30}] {pos}/{len} chunks (eta {eta})",
        )
        .map_err(|e| e.to_string())?
        .progress_chars("=> "),
    );
    let outcome = optimize(&prepared, Some(&run_file), &mut |p| {
        bar.set_position(u64::from(p.chunks_done));
        bar.set_message(format!(
            "{}: best {:.4} um/s, {} evals",
            p.phase.name(),
            p.best_cost,
            p.evaluations
        ));
        // Ctrl-C: stop after this chunk (the run file holds it: resumable).
        match interrupted() {
            Some(_) => ControlFlow::Break(()),
            None => ControlFlow::Continue(()),
        }
    })
    .map_err(|e| e.to_string())?;
    bar.finish_and_clear();
    if let Some(signal) = interrupted() {
        return Err(OutputError::Interrupted { signal }.to_string());
    }
    let yaml = waveform_yaml(&prepared, &outcome);
    let wf = out.join(WAVEFORM_FILE);
    write_atomic(&wf, yaml).map_err(|e| e.to_string())?;
    let s = &outcome.search;
    say!(
        "{} objective: asymmetric {:.4} um/s -> optimised {:.4} um/s ({:+.1} %), A = {:.3} V",
        cfg.objective.name(),
        outcome.asymmetric_cost,
        outcome.cost,
        100.0 * (outcome.cost / outcome.asymmetric_cost - 1.0),
        outcome.amplitude_v
    );
    say!(
        "  simulated annealing {:.4}, particle swarm {:.4} ({} wins), local {:.4}; {} evaluations in {:.1} s",
        s.phase(Phase::SimulatedAnnealing).best.exact_cost(),
        s.phase(Phase::ParticleSwarm).best.exact_cost(),
        match s.global_winner() {
            Phase::ParticleSwarm => "particle swarm",
            _ => "simulated annealing",
        },
        s.phase(Phase::Local).best.exact_cost(),
        s.evaluations(),
        start.elapsed().as_secs_f64()
    );
    say!("wrote {} and {}", wf.display(), run_file.display());
    Ok(())
}
