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

/// Every registered experiment, in thesis order.
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
    ]
}

#[cfg(test)]
mod tests {
    use super::*;

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
