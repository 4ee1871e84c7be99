//! The stability gate on the command line: `nanomotion check` prints the table of
//! every feedback loop and fails naming the loop and the bound; `nanomotion run`
//! refuses an unstable, unproven or out-of-bounds graph unless `--allow-unproven`
//! (and then says so). See `docs/stability-gate.md`.

use nanomotion::core::Scheduler;
use nanomotion::core::gate::{self, FrontEnd, GateReport, Require};

/// Analyse the loops of a built graph against its `require:` section.
pub fn analyse(sched: &Scheduler, require: Option<&Require>) -> GateReport {
    let _span = tracing::debug_span!("stability_gate").entered();
    let default = Require::default();
    gate::analyse(sched, require.unwrap_or(&default))
}

/// `Err` with one line per failure (loop and bound), for `check`.
pub fn verdict(report: &GateReport) -> Result<(), String> {
    report.verdict()
}

/// For `run`: `Err` if the gate refuses and `allow` is false; with `allow`, the
/// lines to print in the run's report (the library's rule and text, with the
/// command line's spelling).
pub fn before_run(report: &GateReport, allow: bool) -> Result<Vec<String>, String> {
    report.before_run(allow, &FrontEnd::CLI)
}

/// `check --print-loop`: for every analysed loop (its first schedule point) the
/// loop transfer L at the break, S = 1/(1 + L) and T = L/(1 + L), and for every
/// learning block the T(z) its criterion uses (what a learning filter L =
/// ZPETC(T) is designed from, pasteable as `t_model:`), as YAML: transfer
/// functions in descending powers of z at the loop's rate. MIMO loops give no
/// S and T (only SISO ones have a transfer function to paste).
pub fn print_loops(report: &GateReport) -> String {
    use nanomotion::core::lti::{StateSpace, feedback};
    use std::fmt::Write as _;
    let tf = |sys: &StateSpace| -> String {
        match sys.to_tf() {
            Ok(t) => {
                let list = |v: &[f64]| {
                    v.iter()
                        .map(|c| format!("{c:e}"))
                        .collect::<Vec<_>>()
                        .join(", ")
                };
                format!("{{ num: [{}], den: [{}] }}", list(&t.num), list(&t.den))
            }
            Err(e) => format!("null   # {e}"),
        }
    };
    let mut out = String::from("loops:\n");
    for lr in &report.loops {
        let _ = writeln!(out, "  - loop: {}", lr.name);
        let _ = writeln!(out, "    rate_hz: {}", lr.rate_hz);
        let Some(p) = lr.points.first() else {
            let _ = writeln!(out, "    # not analysed: {}", lr.unproven.join("; "));
            continue;
        };
        if !p.label.is_empty() {
            let _ = writeln!(out, "    # schedule point: {}", p.label);
        }
        match &p.loop_transfer {
            Some(l) if l.is_siso() => {
                let eye =
                    StateSpace::gain(nanomotion::core::nalgebra::DMatrix::identity(1, 1), l.dt);
                let _ = writeln!(out, "    break_at: \"{}\"", p.break_at);
                let _ = writeln!(out, "    L: {}", tf(l));
                for (name, sys) in [
                    ("S", feedback(&eye, l, -1.0)),
                    ("T", feedback(l, &eye, -1.0)),
                ] {
                    match sys {
                        Ok(s) => {
                            let _ = writeln!(out, "    {name}: {}", tf(&s));
                        }
                        Err(e) => {
                            let _ = writeln!(out, "    {name}: null   # {e}");
                        }
                    }
                }
            }
            Some(_) => {
                let _ = writeln!(
                    out,
                    "    # MIMO loop (break at {}): no scalar L, S, T",
                    p.break_at
                );
            }
            None => {
                let _ = writeln!(
                    out,
                    "    # loop transfer not formed: {}",
                    p.notes.join("; ")
                );
            }
        }
        if !p.learning.is_empty() {
            let _ = writeln!(out, "    learning:");
            for c in &p.learning {
                let _ = writeln!(out, "      - block: {}", c.block);
                let _ = writeln!(out, "        t_model: {}", tf(&c.t));
            }
        }
    }
    out
}
