//! The stability gate on the command line: `nanomotion check` prints the table of
//! every feedback loop and fails naming the loop and the bound; `nanomotion run`
//! refuses an unstable, unproven or out-of-bounds graph unless `--allow-unproven`
//! (and then says so). See `docs/stability-gate.md`.

use nanomotion::core::Scheduler;
use nanomotion::core::gate::{self, GateReport, Require};

/// Analyse the loops of a built graph against its `require:` section.
pub fn analyse(sched: &Scheduler, require: Option<&Require>) -> GateReport {
    let _span = tracing::debug_span!("stability_gate").entered();
    let default = Require::default();
    gate::analyse(sched, require.unwrap_or(&default))
}

/// `Err` with one line per failure (loop and bound), for `check`.
pub fn verdict(report: &GateReport) -> Result<(), String> {
    if report.passes() {
        return Ok(());
    }
    Err(format!(
        "the stability gate refuses the graph:\n  {}",
        report.failures().join("\n  ")
    ))
}

/// For `run`: `Err` if the gate refuses and `allow` is false; with `allow`, the
/// lines to print in the run's report.
pub fn before_run(report: &GateReport, allow: bool) -> Result<Vec<String>, String> {
    let mut lines: Vec<String> = report.allowed();
    if report.passes() {
        return Ok(lines);
    }
    if !allow {
        return Err(format!(
            "the stability gate refuses the graph (see `nanomotion check`; fix the loop, or run anyway with --allow-unproven):\n  {}",
            report.failures().join("\n  ")
        ));
    }
    lines.push(
        "the stability gate refused this graph; running anyway because of --allow-unproven:".into(),
    );
    lines.extend(report.failures().into_iter().map(|f| format!("  {f}")));
    Ok(lines)
}
