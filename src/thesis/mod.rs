//! Thesis reproductions: every table and figure of Merry (2009) that the simulators
//! can reproduce, as functions that return the thesis's figure next to ours with a
//! verdict and the reason. `nanomotion reproduce` runs them and writes
//! `fidelity.md` / `fidelity.json`; `docs/thesis-fidelity.md` is its output.
//!
//! An experiment is a plain function `fn(Mode) -> Result<Report, ReproduceError>`
//! registered in [`experiments`]. The computation itself lives in the plugins'
//! libraries (or here when it needs two plugins, e.g. DVRC on the walking-piezo
//! stage); the function here only runs it and words the comparison.
//!
//! Rules for a verdict: `Matches` when our figure is within the tolerance the row
//! states of the thesis's; `Shape` when the qualitative result holds (same ranking,
//! same sign and order of magnitude of an improvement) but the figure is off;
//! `Deviates` otherwise. The reason says which, with numbers. Never tune a model
//! toward a thesis figure.

pub mod ch2;
pub mod ch4;
pub mod ch5;

use serde::{Deserialize, Serialize};

pub mod ch3;
pub mod ch6;
pub mod ch7;
pub mod ch7_3;
pub mod ch8;

/// How big a run: `Quick` is what `reproduce --quick` and the freshness test run
/// (the whole quick set in under two minutes), `Full` the documented figure.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Mode {
    /// Shorter records / fewer seeds; figures may differ from `Full` (the report says so).
    Quick,
    /// The figures the docs quote.
    Full,
}

/// How close a reproduction got.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Verdict {
    /// Within the stated tolerance of the thesis's figure.
    Matches,
    /// Qualitatively the thesis's result (ranking, sign, order of magnitude), figure off.
    Shape,
    /// Not the thesis's result.
    Deviates,
}

impl Verdict {
    /// `Matches` if |ours − thesis| ≤ `rel_tol`·|thesis|, else `Shape` if both have the
    /// same sign and are within a factor `shape_factor` of each other, else `Deviates`.
    pub fn by_ratio(thesis: f64, ours: f64, rel_tol: f64, shape_factor: f64) -> Verdict {
        if !(thesis.is_finite() && ours.is_finite()) {
            return Verdict::Deviates;
        }
        if (ours - thesis).abs() <= rel_tol * thesis.abs() {
            Verdict::Matches
        } else if thesis != 0.0
            && ours.signum() == thesis.signum()
            && (ours / thesis).abs() <= shape_factor
            && (thesis / ours).abs() <= shape_factor
        {
            Verdict::Shape
        } else {
            Verdict::Deviates
        }
    }

    /// The word used in the tables.
    pub fn as_str(self) -> &'static str {
        match self {
            Verdict::Matches => "matches",
            Verdict::Shape => "shape",
            Verdict::Deviates => "deviates",
        }
    }
}

/// One thesis figure against ours.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Row {
    /// What is compared, e.g. "DVRC, rms e at 10 µm/s".
    pub quantity: String,
    /// The thesis's figure as printed, with unit (text: ranges and lost digits stay
    /// visible), e.g. "2.77 nm" or "4–5.2 µm".
    pub thesis: String,
    /// Ours, with unit, e.g. "3.89 nm".
    pub ours: String,
    /// Verdict under the rule the reason states.
    pub verdict: Verdict,
    /// Why it matches or deviates, with numbers (the tolerance used, the cause).
    pub reason: String,
}

/// The result of one experiment.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Report {
    /// Stable id used on the command line, e.g. "table_5_1".
    pub id: String,
    /// Title, e.g. "Table 5.1 — repetitive control of the walking piezo stage".
    pub title: String,
    /// Thesis section, e.g. "Sec. 5.4".
    pub section: String,
    /// The command that shows the experiment in detail (prints these figures).
    pub command: String,
    /// The mode it ran in.
    pub mode: Mode,
    /// One row per compared figure.
    pub rows: Vec<Row>,
    /// Notes that apply to the whole experiment (modelling choices, readings of lost digits).
    pub notes: Vec<String>,
}

/// An experiment failed to run (not: deviated from the thesis — that is a verdict).
#[derive(Debug, thiserror::Error)]
#[error("{id}: {message}")]
pub struct ReproduceError {
    /// The experiment's id.
    pub id: String,
    /// What went wrong and how to fix it.
    pub message: String,
}

/// A registered experiment.
#[derive(Clone, Copy)]
pub struct Experiment {
    /// Stable id, e.g. "table_5_1".
    pub id: &'static str,
    /// One-line title.
    pub title: &'static str,
    /// Part of `reproduce --quick` (and of the freshness test of docs/thesis-fidelity.md).
    pub in_quick: bool,
    /// Runs it.
    pub run: fn(Mode) -> Result<Report, ReproduceError>,
}

/// Every registered experiment, in thesis order. Adding one: write
/// `fn(Mode) -> Result<Report, ReproduceError>` (in a `chN.rs` here) and add one line.
pub fn experiments() -> Vec<Experiment> {
    vec![
        Experiment {
            id: "table_2_2",
            title: "Table 2.2 — jogging with non-overlapping vs overlapping tip trajectories",
            in_quick: true,
            run: ch2::table_2_2,
        },
        Experiment {
            id: "table_2_3",
            title: "Table 2.3 — point-to-point moves with and without FF + GS",
            in_quick: true,
            run: ch2::table_2_3,
        },
        Experiment {
            id: "table_3_2",
            title: "Table 3.2 — leg model gain and first resonance against n_m",
            in_quick: true,
            run: ch3::table_3_2,
        },
        Experiment {
            id: "fig_3_9",
            title: "Fig. 3.9 — leg model FRF over a drive cycle",
            in_quick: true,
            run: ch3::fig_3_9,
        },
        Experiment {
            id: "fig_3_11_3_14",
            title: "Figs. 3.11–3.14, (3.28)–(3.29) — static map vs tip trajectory; c_x, c_y",
            in_quick: true,
            run: ch3::fig_3_11_3_14,
        },
        Experiment {
            id: "table_4_2",
            title: "Table 4.2 — strokes and model errors per waveform at 10 Hz",
            in_quick: true,
            run: ch3::table_4_2,
        },
        Experiment {
            id: "sec_4_5",
            title: "Sec. 4.5 — waveform optimisation (model- and data-based)",
            in_quick: true,
            run: ch4::sec_4_5,
        },
        Experiment {
            id: "table_5_1",
            title: "Table 5.1 — repetitive control on the linear fitted stage",
            in_quick: true,
            run: ch5::table_5_1,
        },
        Experiment {
            id: "table_5_1_nonlinear",
            title: "Table 5.1 — repetitive control of the nonlinear walking piezo stage",
            in_quick: true,
            run: ch5::table_5_1_nonlinear,
        },
        Experiment {
            id: "ch6",
            title: ch6::TITLE,
            in_quick: true,
            run: ch6::run,
        },
        Experiment {
            id: "sec_7_3",
            title: ch7_3::TITLE,
            in_quick: true,
            run: ch7_3::run,
        },
        Experiment {
            id: "sec_7_5",
            title: ch7::TITLE,
            in_quick: true,
            run: ch7::run,
        },
        Experiment {
            id: "sec_8_5",
            title: ch8::TITLE,
            in_quick: true,
            run: ch8::run,
        },
    ]
}

/// The result of running one experiment: its report, or why it could not run
/// (an error or a panic, caught so that the others still run).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Outcome {
    /// The experiment's id.
    pub id: String,
    /// Its title.
    pub title: String,
    /// The report, if it ran.
    #[serde(skip_serializing_if = "Option::is_none", default)]
    pub report: Option<Report>,
    /// Why it did not run, if it did not.
    #[serde(skip_serializing_if = "Option::is_none", default)]
    pub error: Option<String>,
}

impl Outcome {
    /// Whether it ran.
    pub fn is_ok(&self) -> bool {
        self.error.is_none()
    }
}

/// Run one experiment in `mode`; an error or a panic becomes an [`Outcome`] with
/// `error` set (the panic message kept), never a panic of the caller.
pub fn run_experiment(e: &Experiment, mode: Mode) -> Outcome {
    let run = e.run;
    let caught = std::panic::catch_unwind(move || run(mode));
    let (report, error) = match caught {
        Ok(Ok(mut r)) => {
            if r.id != e.id {
                tracing::warn!(
                    "experiment {} reported id {}; using the registered id",
                    e.id,
                    r.id
                );
                r.id = e.id.to_string();
            }
            (Some(r), None)
        }
        Ok(Err(err)) => (None, Some(err.message)),
        Err(panic) => {
            let msg = panic
                .downcast_ref::<&str>()
                .map(|s| s.to_string())
                .or_else(|| panic.downcast_ref::<String>().cloned())
                .unwrap_or_else(|| "(no message)".into());
            (None, Some(format!("panicked: {msg}")))
        }
    };
    Outcome {
        id: e.id.to_string(),
        title: e.title.to_string(),
        report,
        error,
    }
}

/// The experiments to run for the ids `names` (empty: all; `quick`: only the
/// `in_quick` ones of those). An unknown id is an error listing the ids and the
/// nearest one.
pub fn select(names: &[String], quick: bool) -> Result<Vec<Experiment>, String> {
    let all = experiments();
    let mut chosen = Vec::new();
    for n in names {
        match all.iter().find(|e| e.id == n) {
            Some(e) if !chosen.iter().any(|c: &Experiment| c.id == e.id) => chosen.push(*e),
            Some(_) => {}
            None => {
                let ids: Vec<&str> = all.iter().map(|e| e.id).collect();
                let near = ids
                    .iter()
                    .min_by_key(|id| nanomotion_core::graph::edit_distance(n, id))
                    .map(|id| format!("; nearest: `{id}`"))
                    .unwrap_or_default();
                return Err(format!(
                    "no experiment `{n}`{near} (fix: give one of {}; `nanomotion reproduce --list` lists them)",
                    ids.join(", ")
                ));
            }
        }
    }
    if names.is_empty() {
        chosen = all;
    }
    if quick {
        chosen.retain(|e| e.in_quick);
    }
    Ok(chosen)
}

/// Counts of row verdicts over `outcomes`: (matches, shape, deviates, errors), an
/// experiment that did not run counting as one error.
pub fn tally(outcomes: &[Outcome]) -> [usize; 4] {
    let mut n = [0; 4];
    for o in outcomes {
        match &o.report {
            Some(r) => {
                for row in &r.rows {
                    n[row.verdict as usize] += 1;
                }
            }
            None => n[3] += 1,
        }
    }
    n
}

/// Escape a table cell (pipes and line breaks).
fn cell(s: &str) -> String {
    s.replace('|', "\\|").replace('\n', " ")
}

/// The command that regenerates `docs/thesis-fidelity.md`.
pub const REGENERATE_DOCS: &str = "cargo run -- reproduce --quick --out out/fidelity && cp out/fidelity/fidelity.md docs/thesis-fidelity.md";

/// `fidelity.md`: a summary count, then per experiment its title, section,
/// command, the table thesis | ours | verdict | reason, and notes. Deterministic
/// (no dates, timings or paths): the same outcomes give the same bytes.
pub fn fidelity_markdown(outcomes: &[Outcome], mode: Mode, command: &str) -> String {
    use std::fmt::Write as _;
    let mut s = String::new();
    let [m, sh, d, e] = tally(outcomes);
    let _ = writeln!(s, "# Thesis fidelity: thesis figures against ours\n");
    let _ = writeln!(
        s,
        "Generated by `{command}` ({} mode) — do not edit by hand. {}",
        match mode {
            Mode::Quick => "quick",
            Mode::Full => "full",
        },
        match mode {
            Mode::Quick =>
                "Quick mode runs shorter records where an experiment says so in its notes; the full figures: `nanomotion reproduce` (`--list` lists the experiments). Regenerate this page: `cargo run -- reproduce --quick --out out/fidelity && cp out/fidelity/fidelity.md docs/thesis-fidelity.md` (checked by `tests/thesis_fidelity.rs`).",
            Mode::Full => "",
        }
    );
    let _ = writeln!(
        s,
        "\n**{} experiments, {} rows: {m} matches, {sh} shape, {d} deviates{}.**\n",
        outcomes.len(),
        m + sh + d,
        if e > 0 {
            format!(", {e} error(s)")
        } else {
            String::new()
        }
    );
    let _ = writeln!(
        s,
        "Verdicts: *matches* — within the tolerance the reason states; *shape* — the qualitative result holds (ranking, sign, order of magnitude), the figure is off; *deviates* — not the thesis's result. Thesis figures are as printed in our copy of the thesis (digit 0 lost in the extraction; our reading in brackets where it matters). Nothing is tuned toward a thesis figure.\n"
    );
    let _ = writeln!(s, "| id | experiment | matches | shape | deviates |");
    let _ = writeln!(s, "|---|---|---|---|---|");
    for o in outcomes {
        match &o.report {
            Some(_) => {
                let c = tally(std::slice::from_ref(o));
                let _ = writeln!(
                    s,
                    "| [`{}`](#{}) | {} | {} | {} | {} |",
                    o.id,
                    o.id,
                    cell(&o.title),
                    c[0],
                    c[1],
                    c[2]
                );
            }
            None => {
                let _ = writeln!(
                    s,
                    "| `{}` | {} | error | error | error |",
                    o.id,
                    cell(&o.title)
                );
            }
        }
    }
    for o in outcomes {
        let _ = writeln!(s, "\n## {}\n", o.id);
        match &o.report {
            Some(r) => {
                let _ = writeln!(s, "**{}** ({})\n", r.title, r.section);
                let _ = writeln!(s, "Detail: `{}`\n", r.command);
                let _ = writeln!(s, "| quantity | thesis | ours | verdict | reason |");
                let _ = writeln!(s, "|---|---|---|---|---|");
                for row in &r.rows {
                    let _ = writeln!(
                        s,
                        "| {} | {} | {} | {} | {} |",
                        cell(&row.quantity),
                        cell(&row.thesis),
                        cell(&row.ours),
                        row.verdict.as_str(),
                        cell(&row.reason)
                    );
                }
                if !r.notes.is_empty() {
                    let _ = writeln!(s, "\nNotes:\n");
                    for n in &r.notes {
                        let _ = writeln!(s, "- {n}");
                    }
                }
            }
            None => {
                let _ = writeln!(s, "**{}**\n", o.title);
                let _ = writeln!(
                    s,
                    "| quantity | thesis | ours | verdict | reason |\n|---|---|---|---|---|\n| (experiment) | — | — | error | {} |",
                    cell(o.error.as_deref().unwrap_or(""))
                );
            }
        }
    }
    s
}

/// `fidelity.json`: the outcomes (reports or errors), pretty-printed, deterministic.
pub fn fidelity_json(outcomes: &[Outcome]) -> String {
    let mut s = serde_json::to_string_pretty(outcomes).unwrap_or_else(|e| {
        // Reports are plain strings and numbers: serialisation cannot fail.
        format!("{{\"error\": \"{e}\"}}")
    });
    s.push('\n');
    s
}

/// Run `chosen` in `mode`, calling `progress(index, id)` before each.
pub fn run_all(
    chosen: &[Experiment],
    mode: Mode,
    mut progress: impl FnMut(usize, &str),
) -> Vec<Outcome> {
    chosen
        .iter()
        .enumerate()
        .map(|(i, e)| {
            progress(i, e.id);
            run_experiment(e, mode)
        })
        .collect()
}

/// Format a figure with `digits` significant digits (for the `ours` column).
pub fn sig(x: f64, digits: usize) -> String {
    if !x.is_finite() {
        return format!("{x}");
    }
    if x == 0.0 {
        return "0".into();
    }
    let mag = x.abs().log10().floor() as i32;
    let decimals = (digits as i32 - 1 - mag).max(0) as usize;
    format!("{x:.decimals$}")
}

/// How a reason states the rule of [`Verdict::by_ratio`]: "tolerance ±10 %, shape
/// within a factor 2".
pub fn tolerance_text(rel_tol: f64, shape_factor: f64) -> String {
    format!(
        "tolerance ±{:.0} %, shape within a factor {shape_factor}",
        100.0 * rel_tol
    )
}

/// A `ReproduceError` for experiment `id`.
pub fn fail(id: &str, message: impl std::fmt::Display) -> ReproduceError {
    ReproduceError {
        id: id.to_string(),
        message: message.to_string(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn ok(_: Mode) -> Result<Report, ReproduceError> {
        Ok(Report {
            id: "ok".into(),
            title: "t".into(),
            section: "Sec. 0".into(),
            command: "c".into(),
            mode: Mode::Quick,
            rows: vec![Row {
                quantity: "q | p".into(),
                thesis: "1 nm".into(),
                ours: "1.05 nm".into(),
                verdict: Verdict::Matches,
                reason: "within 10 %".into(),
            }],
            notes: vec!["n".into()],
        })
    }
    fn boom(_: Mode) -> Result<Report, ReproduceError> {
        panic!("deliberate")
    }
    fn err(_: Mode) -> Result<Report, ReproduceError> {
        Err(fail("err", "cannot"))
    }

    #[test]
    fn a_panic_or_error_is_an_outcome_and_the_output_is_deterministic() {
        let list = [
            Experiment {
                id: "ok",
                title: "ok",
                in_quick: true,
                run: ok,
            },
            Experiment {
                id: "boom",
                title: "boom",
                in_quick: true,
                run: boom,
            },
            Experiment {
                id: "err",
                title: "err",
                in_quick: true,
                run: err,
            },
        ];
        let out = run_all(&list, Mode::Quick, |_, _| {});
        assert!(out[0].is_ok());
        assert_eq!(out[1].error.as_deref(), Some("panicked: deliberate"));
        assert_eq!(out[2].error.as_deref(), Some("cannot"));
        assert_eq!(tally(&out), [1, 0, 0, 2]);
        let md = fidelity_markdown(&out, Mode::Quick, "x");
        assert!(
            md.contains("1 matches, 0 shape, 0 deviates, 2 error(s)"),
            "{md}"
        );
        assert!(
            md.contains("| q \\| p | 1 nm | 1.05 nm | matches | within 10 % |"),
            "{md}"
        );
        assert!(md.contains("| (experiment) | — | — | error | panicked: deliberate |"));
        assert_eq!(
            md,
            fidelity_markdown(&run_all(&list, Mode::Quick, |_, _| {}), Mode::Quick, "x")
        );
        let back: Vec<Outcome> = serde_json::from_str(&fidelity_json(&out)).unwrap();
        assert_eq!(back, out);
    }

    #[test]
    fn selection_by_id_quick_and_nearest() {
        let all = experiments();
        assert!(!all.is_empty());
        let ids: Vec<&str> = all.iter().map(|e| e.id).collect();
        let mut unique = ids.clone();
        unique.sort();
        unique.dedup();
        assert_eq!(unique.len(), ids.len(), "ids are unique");
        assert_eq!(select(&[], false).unwrap().len(), all.len());
        let quick = select(&[], true).unwrap();
        assert!(quick.iter().all(|e| e.in_quick));
        let one = select(&["sec_8_5".into()], false).unwrap();
        assert_eq!(one.len(), 1);
        let e = select(&["sec_8_6".into()], false).err().unwrap();
        assert!(e.contains("nearest: `sec_8_5`"), "{e}");
        assert_eq!(sig(2.5712, 3), "2.57");
        assert_eq!(sig(160.94, 4), "160.9");
        assert_eq!(sig(0.021454, 3), "0.0215");
    }

    #[test]
    fn verdict_by_ratio_follows_its_rule() {
        assert_eq!(Verdict::by_ratio(2.77, 2.9, 0.1, 3.0), Verdict::Matches);
        assert_eq!(Verdict::by_ratio(2.77, 3.89, 0.1, 3.0), Verdict::Shape);
        assert_eq!(Verdict::by_ratio(2.77, 9.0, 0.1, 3.0), Verdict::Deviates);
        assert_eq!(Verdict::by_ratio(-33.0, 19.0, 0.1, 3.0), Verdict::Deviates);
        assert_eq!(
            Verdict::by_ratio(1.0, f64::NAN, 0.1, 3.0),
            Verdict::Deviates
        );
    }
}
