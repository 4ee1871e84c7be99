//! # nanomotion-compensate — from a named effect to its compensation
//!
//! The last two steps of the thesis's design loop (Merry 2009, Fig. 1.1):
//! *compensate* the performance-limiting factor that `nanomotion diagnose`
//! ([`nanomotion_plf`]) named, and *validate* that the tracking error shrinks.
//!
//! Input: the augmented model the diagnosis wrote (the nominal graph plus one
//! fitted effect block per named effect, `model_augmented.yaml`), the effects it
//! named ([`named`]: its `report.json`, or the `plf_*` blocks of the model), and
//! the user's closed-loop graph (reference, controller, the nominal plant; its
//! first `score:` entry is the tracking error). [`compensate`] then
//!
//! 1. synthesises one compensator per effect ([`synth`]), from the thesis where
//!    it has one: the inverse hysteresis feed-forward (6.6) before the actuator
//!    (the exact Lambert-W inverse of the fitted Coleman–Hodgdon loop,
//!    [`inverse`], fed with the reference through the nominal's static gain and
//!    the feedback) — for a Bouc–Wen loop on the drive its exact inverse
//!    ([`bouc_wen`]); standard repetitive control (5.1) — or delay-varying RC
//!    (5.7)–(5.8) for a disturbance periodic in the position — with L =
//!    ZPETC(T) of the loop's own T and the FIR Q of the largest cut-off that
//!    keeps (5.5)/(5.9), the criterion reported; friction (and a hysteretic
//!    restoring force) feed-forward from the reference; the exact inverses of
//!    fitted creep and backlash ([`backlash`]); the inverse of a fitted
//!    pole–zero pair (a notch); gain scheduling (2.13) on 1/g of a
//!    position-dependent gain; static decoupling; the offset of a drive fed
//!    forward ([`offset`]); the slit-error correction
//!    table of a diagnosed encoder (hots' `slit_correction`, ê = −e/pitch: each
//!    reading back on its slit's centre); anti-windup for a saturation
//!    on the drive of a core `pid`/`pi` (the controller itself gets the fitted
//!    limits as its output limits, with clamping: no block is inserted); a
//!    core `pid`/`pi` re-tuned for a fitted delay (its crossover lowered, the
//!    zero/pole ratios kept, until the gate finds the loop *with the delay*
//!    within its margin; no block is inserted); and for the rest a stated "no
//!    compensation: this is what it limits" with its figure (a quantiser's
//!    lsb/√12, a delay's phase at the crossover under another controller, how
//!    often a saturation clips a controller that has no output limits, how
//!    far a drift of the reading moves the stage over the scored window);
//! 2. **validates** on the augmented model: the user's loop with the fitted
//!    effects transplanted where the diagnosis put them (the plant as
//!    diagnosed), simulated before, with each compensator alone and with all;
//!    a compensator that does not cut the tracking error's rms is dropped
//!    (unless [`Options::keep`]);
//! 3. returns the user's graph with the kept compensators (`comp_<effect>`
//!    blocks; anti-windup and the delay's re-tune change the user's `pid`
//!    instead), which the
//!    stability gate ([`nanomotion_core::gate`]) must pass.
//!
//! This crate is the one plugin allowed to depend on other plugins
//! (docs/ARCHITECTURE.md): the compensators are theirs (afm-stage's Lambert-W
//! branch inverse, dvrc's RC, Q design and criterion, hots' slit table).

pub mod backlash;
pub mod bouc_wen;
pub mod inverse;
pub mod named;
pub mod offset;
pub mod synth;

pub use backlash::BacklashInverse;
pub use bouc_wen::BoucWenInverse;
pub use inverse::HysteresisInverse;
pub use named::NamedEffect;
pub use offset::DriveOffset;

use named::{Where, locate, source_of, split};
use nanomotion_core::graph::{Connection, GraphSpec};
use nanomotion_plf::surgery::{self, Site};
use serde::Serialize;
use std::collections::BTreeMap;

/// What can go wrong, each naming the place and the fix.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum CompError {
    /// An input file or its content cannot be used.
    #[error("{place}: {problem}; fix: {fix}")]
    Input {
        /// File (and field or block).
        place: String,
        /// What is wrong.
        problem: String,
        /// How to fix it.
        fix: String,
    },
    /// The controller graph lacks the place a compensator (or an effect) goes.
    #[error("{graph}: {problem} (needed for `{effect}`); fix: {fix}")]
    NoPlace {
        /// The controller graph.
        graph: String,
        /// The effect being placed or compensated.
        effect: String,
        /// What is missing.
        problem: String,
        /// How to fix it.
        fix: String,
    },
    /// A design step failed.
    #[error("designing the compensator of `{effect}`: {problem}")]
    Design {
        /// The effect.
        effect: String,
        /// What failed.
        problem: String,
    },
    /// A loop could not be built or simulated.
    #[error("simulating {variant}: {problem}")]
    Simulation {
        /// Which loop (before, with `comp_x`, ...).
        variant: String,
        /// What failed.
        problem: String,
    },
    /// The stability gate refuses the compensated graph.
    #[error("the stability gate refuses the compensated graph: {0}")]
    Gate(String),
}

/// A signal recorded from your loop on the real stage (without the
/// compensators), sampled at `rate_hz`: for delay-varying RC, the variable the
/// disturbance is periodic in (the thesis measures N(α) so, Fig. 5.7).
#[derive(Debug, Clone, PartialEq)]
pub struct MeasuredSignal {
    /// The signal's name in your graph, `block.port` (e.g. `alpha.y`).
    pub signal: String,
    /// Sample rate (Hz).
    pub rate_hz: f64,
    /// The samples.
    pub values: Vec<f64>,
    /// Where the record came from, in messages (a file and its column).
    pub origin: String,
}

impl MeasuredSignal {
    /// A record read from `FILE[:COLUMN]` (the CLI's `--measured-alpha`,
    /// Python's `measured_alpha`): a data file as `nanomotion run` writes it
    /// (CSV with a `t_s` column first, or `.mat`:
    /// [`Dataset::from_file`](nanomotion_core::data::Dataset::from_file)), the
    /// column `COLUMN` — or the file's only data column — as the signal of
    /// your graph of that name (e.g. `signals_4000hz.csv:alpha.y`). A whole
    /// argument that is an existing file is read as the file (a path may hold
    /// a `:`).
    pub fn from_file_column(arg: &str) -> Result<Self, CompError> {
        let (path, column) = match arg.rsplit_once(':') {
            Some((p, c)) if !c.is_empty() && !std::path::Path::new(arg).is_file() => (p, Some(c)),
            _ => (arg, None),
        };
        let data =
            nanomotion_core::data::Dataset::from_file(path).map_err(|e| CompError::Input {
                place: format!(
                    "{}{}{}",
                    e.origin,
                    e.row.map(|r| format!(", row {r}")).unwrap_or_default(),
                    e.column
                        .as_ref()
                        .map(|c| format!(", column `{c}`"))
                        .unwrap_or_default()
                ),
                problem: e.problem,
                fix: e.fix,
            })?;
        let column = match (column, data.names()) {
            (Some(c), _) => c.to_string(),
            (None, [one]) => one.clone(),
            (None, names) => {
                return Err(CompError::Input {
                    place: path.to_string(),
                    problem: format!(
                        "has {} data columns ({}), so which one is the record is not said",
                        names.len(),
                        names.join(", ")
                    ),
                    fix: format!(
                        "name the column of the signal the disturbance is periodic in after the file, `{path}:COLUMN`{}",
                        names
                            .first()
                            .map(|n| format!(", e.g. `{path}:{n}`"))
                            .unwrap_or_default()
                    ),
                });
            }
        };
        let values = data
            .require(&column)
            .map_err(|e| CompError::Input {
                place: format!("{path}, column `{column}`"),
                problem: e.problem,
                fix: format!("{} (`{path}:COLUMN`)", e.fix),
            })?
            .to_vec();
        Ok(Self {
            origin: format!("{path}, column `{column}`"),
            signal: column,
            rate_hz: data.rate_hz(),
            values,
        })
    }
}

/// Delay-varying RC's widening of the delay range [m, M] when no record of
/// the signal is given: the relative spread of the delay the thesis measured
/// on its stage at 10 µm/s, N(α) ∈ [2026, 2209] samples (Fig. 5.7), 9.0 %.
/// Your loop on the nominal plant and on the plant as diagnosed cannot show
/// that spread: both are periodic in the signal at a constant velocity, so each
/// takes the same number of samples for every period (docs/compensate.md,
/// the leg-angle case, against the walking stage's per-sample spread).
/// The models' delay lies somewhere inside the real stage's range, so the
/// range is widened by the whole spread on each side.
pub const DELAY_SPREAD_UNMEASURED: f64 = 2209.0 / 2026.0 - 1.0;

/// Delay-varying RC's widening of the delay range [m, M] when a record of the
/// signal is given ([`Options::measured`]): the record shows the stage's own
/// spread, and ±2 % covers what one record does not (the hand design of
/// docs/repetitive-control.md's Table 5.1: the measured range ± 2 %).
pub const DELAY_MARGIN_MEASURED: f64 = 0.02;

/// Options of [`compensate`].
#[derive(Debug, Clone)]
pub struct Options {
    /// Keep compensators that do not cut the error (default false: dropped).
    pub keep: bool,
    /// Validate on this reference instead of the graph's own: a block map
    /// (`{type: …, …}`) that replaces the block feeding the error sum's `in0`.
    pub reference: Option<serde_json::Value>,
    /// The augmented model's name in messages.
    pub augmented_name: String,
    /// The controller graph's name in messages.
    pub controller_name: String,
    /// Least relative rms cut (of the loop without it) a compensator must give
    /// to be kept (default 0.01).
    pub min_cut: f64,
    /// Delay-varying RC: relative widening, on each side, of the delay range
    /// [m, M] found from your loop's motion (on the nominal plant, on the
    /// plant as diagnosed, and in [`Options::measured`]), for the variation
    /// of N_k they do not show; a fraction in [0, 0.5). Default `None`: from
    /// what was measured — [`DELAY_MARGIN_MEASURED`] with a record of the
    /// signal, else [`DELAY_SPREAD_UNMEASURED`]. The design figure
    /// `delay_margin` is the one used.
    pub delay_margin: Option<f64>,
    /// Signals recorded from your loop on the real stage: a record of the
    /// signal a disturbance is periodic in adds the delays it shows to the
    /// range [m, M] of delay-varying RC (before the widening by
    /// [`Options::delay_margin`]); a record no delay-varying RC follows is
    /// refused. Default none.
    pub measured: Vec<MeasuredSignal>,
}

impl Default for Options {
    fn default() -> Self {
        Self {
            keep: false,
            reference: None,
            augmented_name: "the augmented model".into(),
            controller_name: "the controller graph".into(),
            min_cut: 0.01,
            delay_margin: None,
            measured: Vec::new(),
        }
    }
}

/// rms and largest |e| of the tracking error over the scored window.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct ErrorStats {
    /// Root mean square.
    pub rms: f64,
    /// Largest absolute value.
    pub max_abs: f64,
}

/// One synthesised compensator and what it did.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct CompensatorReport {
    /// The effect it compensates.
    pub effect: String,
    /// Its block in the compensated graph (`comp_<effect>`; for anti-windup
    /// and a delay's re-tune, the user's `pid`/`pi`, changed in place, as no
    /// block is inserted).
    pub block: String,
    /// Its block type.
    #[serde(rename = "type")]
    pub type_name: String,
    /// What it is and why, in one line.
    pub why: String,
    /// Where it goes.
    pub place: String,
    /// Design figures (criterion values, frequencies, ...).
    pub design: BTreeMap<String, f64>,
    /// The tracking error with this compensator alone.
    pub alone: ErrorStats,
    /// Cut of the rms with it alone (%).
    pub cut_percent: f64,
    /// Cut (%) of the error the effects cause (e − e of the loop without
    /// them, rms over the scored window) with it alone.
    pub effect_error_cut_percent: f64,
    /// Whether it is in the compensated graph.
    pub kept: bool,
    /// Why it was dropped, or a caveat.
    pub note: Option<String>,
}

/// An effect left without a compensator, and what it limits.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct NotCompensated {
    /// The effect.
    pub effect: String,
    /// Why, and what it limits.
    pub reason: String,
    /// The figure it limits (name → value), if there is one.
    pub figures: BTreeMap<String, f64>,
}

/// The stability gate's verdict on the compensated graph.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct GateSummary {
    /// Whether it passes.
    pub passes: bool,
    /// Loops judged with a `require:` allowance, and failures.
    pub lines: Vec<String>,
}

/// What [`compensate`] did.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Report {
    /// The scored tracking error.
    pub error_signal: String,
    /// Samples before this time are not scored (s).
    pub from_s: f64,
    /// The effects named, in order.
    pub effects: Vec<NamedEffect>,
    /// The user's loop as it is (on the nominal plant, no effects).
    pub nominal: ErrorStats,
    /// The loop on the augmented model without compensation.
    pub before: ErrorStats,
    /// rms of the error the effects cause, e − e_nominal, over the scored
    /// window: before, and with the kept compensators.
    pub effect_error_before: f64,
    /// The same with the kept compensators.
    pub effect_error_after: f64,
    /// One per compensator, in the order of the effects.
    pub compensators: Vec<CompensatorReport>,
    /// All compensators together (`None` when fewer than two).
    pub all: Option<ErrorStats>,
    /// The kept compensators together (the compensated graph on the augmented model).
    pub after: ErrorStats,
    /// Cut of the rms from `before` to `after` (%).
    pub cut_percent: f64,
    /// Cut of the largest |e| (%).
    pub max_cut_percent: f64,
    /// Effects without a compensator.
    pub not_compensated: Vec<NotCompensated>,
    /// The gate's verdict on the compensated graph.
    pub gate: GateSummary,
}

/// A tracking-error trace for plots: (label, time (s), error).
pub type Trace = (String, Vec<f64>, Vec<f64>);

/// The result of [`compensate`].
#[derive(Debug)]
pub struct Outcome {
    /// The user's graph with the kept compensators.
    pub compensated: GraphSpec,
    /// The report.
    pub report: Report,
    /// The error before and after, on the augmented model.
    pub traces: Vec<Trace>,
}

/// The loop a compensator acts on: names in the user's controller graph.
#[derive(Debug, Clone)]
pub(crate) struct LoopInfo {
    /// The scored tracking error `block.port`.
    pub error: String,
    /// Its `from_s`.
    pub from_s: f64,
}

/// Synthesise, validate and insert compensators for `effects`, named in
/// `augmented` (the diagnosis's model), into `controller` (the user's loop on
/// the nominal plant). See the [crate documentation](crate).
pub fn compensate(
    augmented: &GraphSpec,
    controller: &GraphSpec,
    effects: &[NamedEffect],
    opts: &Options,
) -> Result<Outcome, CompError> {
    let score = controller.score.first().ok_or_else(|| CompError::Input {
        place: format!("{}: `score:`", opts.controller_name),
        problem: "is empty, so there is no tracking error to cut".into(),
        fix: "score the tracking error, e.g. `score: [{signal: err.y, from_s: 0.5}]`".into(),
    })?;
    if effects.is_empty() {
        return Err(CompError::Input {
            place: opts.augmented_name.clone(),
            problem: "names no effect (the diagnosis found none), so there is nothing to compensate".into(),
            fix: "run `nanomotion diagnose` on a record and give its model_augmented.yaml and report.json".into(),
        });
    }
    if let Some(e) = effects
        .iter()
        .find(|e| nanomotion_plf::effects::Effect::from_name(&e.effect).is_none())
    {
        return Err(CompError::Input {
            place: format!("the report: effect `{}` (block `{}`)", e.effect, e.block),
            problem: "is not a name of the diagnosis's vocabulary, so it has no compensator".into(),
            fix: format!(
                "give the report `nanomotion diagnose` wrote; the names are {}",
                nanomotion_plf::diagnose::vocabulary().join(", ")
            ),
        });
    }
    if let Some(m) = opts.delay_margin
        && !(m.is_finite() && (0.0..0.5).contains(&m))
    {
        return Err(CompError::Input {
            place: "the delay margin of delay-varying RC".into(),
            problem: format!("is {m}, not a fraction in [0, 0.5)"),
            fix: "give the relative widening of the delay range on each side, e.g. 0.09 for ±9 %"
                .into(),
        });
    }
    let info = LoopInfo {
        error: score.signal.clone(),
        from_s: score.from_s,
    };
    // The loop on the plant as diagnosed.
    let mut base = clone(controller, &opts.controller_name)?;
    if let Some(r) = &opts.reference {
        replace_reference(&mut base, &info, r, opts)?;
    }
    let validation = transplant(&base, augmented, effects, opts)?;
    // One compensator per effect.
    let mut comps = Vec::new();
    let mut not_compensated = Vec::new();
    for e in effects {
        let block = augmented
            .blocks
            .iter()
            .find(|b| b.name == e.block)
            .expect("located above");
        let params = surgery::block_to_json(block.block.as_ref());
        let effect_blocks: Vec<String> = effects.iter().map(|e| e.block.clone()).collect();
        let placement = locate(augmented, e, &effect_blocks, &opts.augmented_name)?;
        match synth::synthesise(e, &params, &placement, controller, &validation, &info, opts)? {
            synth::Outcome::Compensator(c) => comps.push(c),
            synth::Outcome::None(n) => not_compensated.push(n),
        }
    }
    // A record no delay-varying RC follows was given for nothing (a column
    // named otherwise than the signal, or no disturbance periodic in it).
    let followed: Vec<&str> = comps.iter().filter_map(|c| c.alpha()).collect();
    if let Some(m) = opts
        .measured
        .iter()
        .find(|m| !followed.contains(&m.signal.as_str()))
    {
        return Err(CompError::Input {
            place: m.origin.clone(),
            problem: format!(
                "no delay-varying RC follows `{}`: {}",
                m.signal,
                if followed.is_empty() {
                    "no disturbance periodic in a signal of your loop was compensated".to_string()
                } else {
                    format!("the signals followed are {}", followed.join(", "))
                }
            ),
            fix: if followed.is_empty() {
                "give a record only with a disturbance periodic in a signal (a `repetitive_disturbance` with `variable: signal`)".into()
            } else {
                format!(
                    "name the record's column after the signal it records, `{}`, or leave the record out",
                    followed[0]
                )
            },
        });
    }
    let before = simulate(&validation, &info, "the loop on the augmented model")?;
    let nominal = simulate(&base, &info, "the loop on the nominal plant")?;
    let excess = |t: &Trial| effect_error(t, &nominal, info.from_s);
    let excess_before = excess(&before);
    let mut reports = Vec::new();
    let mut alone_traces = Vec::new();
    for c in &comps {
        let mut g = clone(&validation, "the validation loop")?;
        c.apply(&mut g, controller, opts)?;
        let t = simulate(&g, &info, &format!("the loop with `{}` alone", c.name))?;
        let cut = 100.0 * (1.0 - t.stats.rms / before.stats.rms);
        let helps = t.stats.rms < (1.0 - opts.min_cut) * before.stats.rms;
        reports.push(CompensatorReport {
            effect: c.effect.clone(),
            block: c.name.clone(),
            type_name: c.type_name(),
            why: c.why.clone(),
            place: c.place.clone(),
            design: c.design.clone(),
            alone: t.stats,
            cut_percent: cut,
            effect_error_cut_percent: 100.0 * (1.0 - excess(&t) / excess_before),
            kept: helps || opts.keep,
            note: match (helps, opts.keep) {
                (true, _) => c.note.clone(),
                (false, true) => Some(format!(
                    "kept because of --keep although it does not cut the rms by {:.0} %{}",
                    100.0 * opts.min_cut,
                    c.note.as_ref().map_or(String::new(), |n| format!("; {n}"))
                )),
                (false, false) => Some(format!(
                    "dropped: alone it does not cut the rms by {:.0} % ({:.3e} -> {:.3e}); keep it with --keep{}",
                    100.0 * opts.min_cut,
                    before.stats.rms,
                    t.stats.rms,
                    c.note.as_ref().map_or(String::new(), |n| format!("; {n}"))
                )),
            },
        });
        alone_traces.push((format!("with {} alone", c.label()), t.t, t.e));
    }
    let all = if comps.len() > 1 {
        let mut g = clone(&validation, "the validation loop")?;
        for c in &comps {
            c.apply(&mut g, controller, opts)?;
        }
        Some(simulate(&g, &info, "the loop with every compensator")?.stats)
    } else {
        None
    };
    let kept: Vec<&synth::Compensator> = comps
        .iter()
        .zip(&reports)
        .filter(|(_, r)| r.kept)
        .map(|(c, _)| c)
        .collect();
    let mut final_loop = clone(&validation, "the validation loop")?;
    let mut compensated = clone(controller, &opts.controller_name)?;
    for c in &kept {
        c.apply(&mut final_loop, controller, opts)?;
        c.apply(&mut compensated, controller, opts)?;
    }
    let after = if kept.is_empty() {
        before.clone()
    } else {
        simulate(&final_loop, &info, "the compensated loop")?
    };
    let gate = gate(&compensated, controller, opts)?;
    let report = Report {
        error_signal: info.error.clone(),
        from_s: info.from_s,
        effects: effects.to_vec(),
        nominal: nominal.stats,
        before: before.stats,
        effect_error_before: excess_before,
        effect_error_after: excess(&after),
        compensators: reports,
        all,
        after: after.stats,
        cut_percent: 100.0 * (1.0 - after.stats.rms / before.stats.rms),
        max_cut_percent: 100.0 * (1.0 - after.stats.max_abs / before.stats.max_abs),
        not_compensated,
        gate,
    };
    let mut traces = vec![("before".to_string(), before.t, before.e)];
    if kept.len() != 1 || alone_traces.len() != 1 {
        traces.push(("compensated".to_string(), after.t, after.e));
    }
    traces.extend(alone_traces);
    Ok(Outcome {
        compensated,
        report,
        traces,
    })
}

/// A deep copy of a graph.
pub(crate) fn clone(spec: &GraphSpec, name: &str) -> Result<GraphSpec, CompError> {
    surgery::clone_spec(spec).map_err(|e| CompError::Input {
        place: name.to_string(),
        problem: e.to_string(),
        fix: "give a graph that `nanomotion check` accepts".into(),
    })
}

pub(crate) fn has_block(spec: &GraphSpec, name: &str) -> bool {
    spec.blocks.iter().any(|b| b.name == name)
}

/// The block feeding the error sum's `in0` (the reference), or why not.
pub(crate) fn reference_of(
    spec: &GraphSpec,
    info: &LoopInfo,
    graph: &str,
    effect: &str,
) -> Result<String, CompError> {
    let (eb, _) = split(&info.error);
    let is_error_sum = spec.blocks.iter().any(|b| {
        b.name == eb
            && surgery::block_to_json(b.block.as_ref())
                .get("signs")
                .and_then(|s| s.as_str())
                .is_some_and(|s| s.starts_with("+-"))
    });
    let src = source_of(spec, &format!("{eb}.in0"));
    match (is_error_sum, src) {
        (true, Some(r)) => Ok(r.to_string()),
        _ => Err(CompError::NoPlace {
            graph: graph.to_string(),
            effect: effect.to_string(),
            problem: format!(
                "the scored error `{}` is not a `sum` with `signs: \"+-\"` fed by the reference on `in0`",
                info.error
            ),
            fix: "score the error sum r − y (reference on in0, measured position on in1)".into(),
        }),
    }
}

fn replace_reference(
    spec: &mut GraphSpec,
    info: &LoopInfo,
    block: &serde_json::Value,
    opts: &Options,
) -> Result<(), CompError> {
    let r = reference_of(spec, info, &opts.controller_name, "--reference")?;
    let name = split(&r).0.to_string();
    let new = surgery::block_from_json(block.clone()).map_err(|e| CompError::Input {
        place: "--reference".into(),
        problem: e.to_string(),
        fix: "give one block map, e.g. `{type: triangular_scan, amplitude: 1.0e-5, frequency_hz: 1.0}`".into(),
    })?;
    let b = spec
        .blocks
        .iter_mut()
        .find(|b| b.name == name)
        .expect("the reference's block exists");
    b.block = new;
    Ok(())
}

/// The user's loop with every named effect inserted where the diagnosis put it.
fn transplant(
    controller: &GraphSpec,
    aug: &GraphSpec,
    effects: &[NamedEffect],
    opts: &Options,
) -> Result<GraphSpec, CompError> {
    let mut g = clone(controller, &opts.controller_name)?;
    let effect_blocks: Vec<String> = effects.iter().map(|e| e.block.clone()).collect();
    let mut renamed: BTreeMap<String, String> = BTreeMap::new();
    let map = |sig: &str, renamed: &BTreeMap<String, String>| -> String {
        let (b, p) = split(sig);
        match renamed.get(b) {
            Some(n) => format!("{n}.{p}"),
            None => sig.to_string(),
        }
    };
    let no_place = |effect: &str, problem: String, fix: String| CompError::NoPlace {
        graph: opts.controller_name.clone(),
        effect: effect.to_string(),
        problem,
        fix,
    };
    for e in effects {
        let p = locate(aug, e, &effect_blocks, &opts.augmented_name)?;
        let spec = aug
            .blocks
            .iter()
            .find(|b| b.name == e.block)
            .expect("located");
        let block = surgery::block_from_json(surgery::block_to_json(spec.block.as_ref())).map_err(
            |err| CompError::Input {
                place: format!("{}: block `{}`", opts.augmented_name, e.block),
                problem: err.to_string(),
                fix: "give the model_augmented.yaml that `nanomotion diagnose` wrote".into(),
            },
        )?;
        let need = |sig: &str| -> Result<(), CompError> {
            if has_block(&g, split(sig).0) {
                Ok(())
            } else {
                Err(no_place(
                    &e.effect,
                    format!(
                        "has no block `{}`, whose signal `{sig}` the effect's block `{}` reads in {}",
                        split(sig).0,
                        e.block,
                        opts.augmented_name
                    ),
                    "name the plant and its signals in the controller graph as in the model you diagnosed".into(),
                ))
            }
        };
        let site = match &p.place {
            Where::Input { to } => {
                let from = source_of(controller, to).ok_or_else(|| {
                    no_place(
                        &e.effect,
                        format!(
                            "has no connection into `{to}`, where `{}` enters {}",
                            e.block, opts.augmented_name
                        ),
                        format!("drive the plant through `{to}` as in the model you diagnosed"),
                    )
                })?;
                Site::Input {
                    from: from.to_string(),
                    to: to.clone(),
                }
            }
            Where::Feedback { to, position } => {
                let from = source_of(controller, to).ok_or_else(|| {
                    no_place(
                        &e.effect,
                        format!(
                            "has no connection into `{to}`, where `{}` adds its force in {}",
                            e.block, opts.augmented_name
                        ),
                        format!("drive the plant through `{to}` as in the model you diagnosed"),
                    )
                })?;
                need(position)?;
                Site::Feedback {
                    from: from.to_string(),
                    to: to.clone(),
                    position: map(position, &renamed),
                }
            }
            Where::Output { signal } => {
                let signal = map(signal, &renamed);
                need(&signal)?;
                Site::Sensor { compare: 0, signal }
            }
        };
        let s: Vec<String> = p.s.iter().map(|x| map(x, &renamed)).collect();
        for x in &s {
            need(x)?;
        }
        let name = surgery::insert(&mut g, &e.block, block, &site, &s, None).map_err(|err| {
            no_place(
                &e.effect,
                err.to_string(),
                "the controller graph must contain the place the diagnosis named".into(),
            )
        })?;
        renamed.insert(e.block.clone(), name);
    }
    Ok(g)
}

/// One simulated loop: the error statistics and the trace.
#[derive(Debug, Clone)]
struct Trial {
    stats: ErrorStats,
    t: Vec<f64>,
    e: Vec<f64>,
}

fn simulate(spec: &GraphSpec, info: &LoopInfo, variant: &str) -> Result<Trial, CompError> {
    let sim = |problem: String| CompError::Simulation {
        variant: variant.to_string(),
        problem,
    };
    let mut g = clone(spec, variant)?;
    if g.reads_data() {
        return Err(sim(
            "the controller graph reads measured data (`data_column`); give a closed loop with its own reference".into(),
        ));
    }
    g.score.truncate(1);
    let (mut sched, _) = g.build().map_err(|e| sim(e.to_string()))?;
    let run = sched.run(|_| {});
    let score = run.scores.first().ok_or_else(|| sim("no score".into()))?;
    if !(score.rms.is_finite() && score.max_abs.is_finite()) || score.samples == 0 {
        return Err(sim(format!(
            "the tracking error `{}` is not finite (rms {}): the loop diverged",
            info.error, score.rms
        )));
    }
    let log = run
        .logs
        .iter()
        .find(|l| l.name == info.error)
        .ok_or_else(|| sim(format!("`{}` was not logged", info.error)))?;
    let t: Vec<f64> = (0..log.data.len())
        .map(|k| k as f64 / log.rate_hz)
        .collect();
    Ok(Trial {
        stats: ErrorStats {
            rms: score.rms,
            max_abs: score.max_abs,
        },
        t,
        e: log.data.clone(),
    })
}

/// rms over t ≥ `from_s` of the difference of two error traces.
fn effect_error(t: &Trial, nominal: &Trial, from_s: f64) -> f64 {
    let (mut sum, mut n) = (0.0, 0usize);
    for ((time, e), e0) in t.t.iter().zip(&t.e).zip(&nominal.e) {
        if *time >= from_s {
            sum += (e - e0) * (e - e0);
            n += 1;
        }
    }
    (sum / n.max(1) as f64).sqrt()
}

fn gate(
    compensated: &GraphSpec,
    controller: &GraphSpec,
    opts: &Options,
) -> Result<GateSummary, CompError> {
    let judge = |spec: &GraphSpec| -> Result<nanomotion_core::gate::GateReport, String> {
        let g = surgery::clone_spec(spec).map_err(|e| e.to_string())?;
        let require = g.require.clone().unwrap_or_default();
        let (sched, _) = g.build().map_err(|e| e.to_string())?;
        Ok(nanomotion_core::gate::analyse(&sched, &require))
    };
    let after = judge(compensated).map_err(|e| CompError::Simulation {
        variant: "the compensated graph".into(),
        problem: e,
    })?;
    if !after.passes() {
        let before_passes = judge(controller).map(|r| r.passes()).unwrap_or(false);
        return Err(CompError::Gate(format!(
            "{}{}",
            after.failures().join("; "),
            if before_passes {
                String::new()
            } else {
                format!(
                    " ({} itself does not pass the gate: fix it first, `nanomotion check`)",
                    opts.controller_name
                )
            }
        )));
    }
    Ok(GateSummary {
        passes: true,
        lines: after.allowed(),
    })
}

/// Connect `from` to `to` (helper for edits).
pub(crate) fn connect(spec: &mut GraphSpec, from: String, to: String) {
    spec.connections.push(Connection { from, to });
}

// Blocks the compensators name by `type:` (gain scheduling) register through
// the linker: reference the crate so they are never missing.
use gain_scheduling as _;

/// For the inverse blocks' tests: the largest |op(inv(w_k)) − w_k| over
/// k < `n` samples at 1 kHz, `inv` feeding `op` sample by sample (both built).
#[cfg(test)]
pub(crate) fn worst_of_pair(
    inv: &mut dyn nanomotion_core::Block,
    op: &mut dyn nanomotion_core::Block,
    n: u64,
    w: impl Fn(u64, f64) -> f64,
) -> f64 {
    use nanomotion_core::{BuildContext, Tick};
    let ctx = BuildContext::new("b", 1e-3, 0);
    inv.build(&ctx).unwrap();
    op.build(&ctx).unwrap();
    let mut worst: f64 = 0.0;
    for k in 0..n {
        let w = w(k, k as f64 * 1e-3);
        let mut u = [0.0];
        inv.output(Tick::new(k, 1e-3), &[w], &mut u);
        let mut y = [0.0];
        op.output(Tick::new(k, 1e-3), &u, &mut y);
        worst = worst.max((y[0] - w).abs());
    }
    worst
}
