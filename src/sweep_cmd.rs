//! `nanomotion sweep SWEEP.yaml`: the command-line side of [`nanomotion::sweep`].

use nanomotion::sweep::{RunOptions, Study, run_study};
use std::path::{Path, PathBuf};

/// Run the study in `file`, writing into `out` (default `out/sweep_<stem>`).
pub fn sweep(
    file: &Path,
    out: Option<PathBuf>,
    jobs: usize,
    restart: bool,
    limit: Option<usize>,
) -> Result<(), String> {
    let study = Study::from_file(file).map_err(|e| e.to_string())?;
    let out = out.unwrap_or_else(|| {
        let stem = file
            .file_stem()
            .map_or_else(|| "sweep".into(), |s| s.to_string_lossy().into_owned());
        PathBuf::from("out").join(format!("sweep_{}", nanomotion::output::file_stem(&stem)))
    });
    let (jobs_used, capped) = nanomotion::sweep::capped_jobs(jobs);
    if let Some(note) = capped {
        tell!("note: {note}");
    }
    let plan = study.plan();
    tell!(
        "{}: {} study, {} runs (plan {}), {} parallel job(s), into {}",
        file.display(),
        plan.kind.as_str(),
        plan.len(),
        plan.study_hash,
        jobs_used,
        out.display()
    );
    let s = run_study(
        &study,
        &out,
        &RunOptions {
            jobs: jobs_used,
            restart,
            limit,
            progress: true,
        },
    )
    .map_err(|e| e.to_string())?;
    if s.resumed > 0 {
        say!(
            "resumed: {} finished rows kept from {}",
            s.resumed,
            out.display()
        );
    }
    say!(
        "computed {} runs in {:.3} s ({:.1} runs/s on {} job(s)); {} of the {} finished rows failed (see the `error` column)",
        s.computed,
        s.wall_s,
        s.computed as f64 / s.wall_s.max(1e-9),
        jobs_used,
        s.failed,
        s.resumed + s.computed
    );
    let left = s.planned - s.resumed - s.computed;
    if left > 0 {
        say!("{left} runs left: run the same command again to continue");
    }
    say!("wrote {} files to {}", s.files.len(), out.display());
    Ok(())
}
