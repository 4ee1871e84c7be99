//! The workflow: nominal residual → candidate effects fitted at every place they
//! can enter → the one that cuts the held-out residual most, significantly, is
//! named and inserted → repeat with earlier effects refitted jointly → stop when
//! nothing significant is left.
//!
//! Decisions, in the order they are taken:
//! 1. The record is split in time: the first `1 − holdout` part estimates
//!    parameters, the rest only scores them. With several records
//!    ([`diagnose_records`]) the first estimates and the others — with other
//!    excitations, the benchmark convention — only score; each record is
//!    simulated from rest on its own.
//! 2. Every candidate (effect × site) is fitted on the estimation part
//!    (Levenberg–Marquardt, several starts for the non-convex parameters such as
//!    delays, periods and hysteresis rates), earlier effects held.
//! 3. Candidates are ranked by their held-out mean square times a BIC-like
//!    flexibility factor (1 + k·ln N/N)·(1 + k/√N_hold) — a harmonic series or a
//!    resonance pays for every parameter.
//! 4. The best is refitted jointly with the effects named before (so an effect
//!    fitted first cannot keep what belongs to another) and accepted only if the
//!    held-out improvement is significant (batch-means t-test at α / number of
//!    candidates, Bonferroni) *and* it removes at least `min_excess_cut` of the
//!    residual's mean square above its noise floor — what stops padding.
//! 5. It stops after `max_effects`, when the residual is at its noise floor, or
//!    when no candidate passes step 4.

use crate::PlfError;
use crate::effects::creep::{Creep, CreepTerm};
use crate::effects::delay::{MIN_RESOLVED_DELAY_SAMPLES, TimeDelay};
use crate::effects::prandtl_ishlinskii::PrandtlIshlinskii;
use crate::effects::resonance::{MAX_RESONANT_DAMPING, UnmodeledResonance};
use crate::effects::slit::MAX_SLITS;
use crate::fit::{
    BlockEvaluator, Evaluator, FreeParam, Problem, Records, Scale, levenberg_marquardt,
};
use crate::stats;
use crate::surgery::{self, Channel, Site};
use nanomotion_core::data::Dataset;
use nanomotion_core::graph::{BlockSpec, GraphSpec};
use serde::Serialize;
use serde_json::json;
use std::collections::BTreeMap;
use std::sync::Arc;

/// The vocabulary names, in [`Effect::ALL`](crate::effects::Effect::ALL) order.
pub fn vocabulary() -> Vec<&'static str> {
    crate::effects::Effect::ALL
        .iter()
        .map(|e| e.name())
        .collect()
}

/// Options of [`diagnose`].
#[derive(Debug, Clone, PartialEq)]
pub struct Options {
    /// At most this many effects (default 3). With 0 (and `calibrate`), the
    /// nominal calibration alone is fitted and kept when significant.
    pub max_effects: usize,
    /// Fraction of the record, at its end, held out for scoring (default 0.3).
    pub holdout: f64,
    /// Seed (the workflow itself is deterministic; the seed is passed to the graph).
    pub seed: Option<u64>,
    /// Family-wise false-alarm level of a step (default 0.01).
    pub alpha: f64,
    /// Share of the mean square above the noise floor an effect must remove
    /// (default 0.3).
    pub min_excess_cut: f64,
    /// Restrict the candidates to these vocabulary names (empty: all).
    pub effects: Vec<String>,
    /// Worker threads for candidate fits (default 2).
    pub threads: usize,
    /// Let the nominal model's own parameters compete with the effects
    /// (default true): the gain and the time, damping, lag and per-mode
    /// scales of every continuous `state_space` block (see [`Calibration`]).
    pub calibrate: bool,
    /// A signal of the graph, `block.port`, that a disturbance may be
    /// periodic in besides the position: the drive's phase, e.g. the leg
    /// angle α = 2π∫f_α of a walking piezo drive (thesis Ch. 5), computed in
    /// the model (`alpha.y`). A `repetitive_disturbance` periodic in it is
    /// then a candidate on the measured output and on every plant input, its
    /// period found from the data by the same searches as a position's pitch
    /// (`position_period`, `force_pitch`); where the model's position
    /// follows it in proportion, the position's own candidates are left out
    /// (`periodic_variables`; docs/plf.md, "A disturbance periodic in a
    /// declared phase"). `None` (default): periodic in time or in
    /// the position only. A signal the model lacks is a
    /// [`PlfError::Option`] naming it.
    pub phase: Option<String>,
}

impl Default for Options {
    fn default() -> Self {
        Self {
            max_effects: 3,
            holdout: 0.3,
            seed: None,
            alpha: 0.01,
            min_excess_cut: 0.3,
            effects: Vec::new(),
            threads: 2,
            calibrate: true,
            phase: None,
        }
    }
}

/// Scores of one compared output.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct OutputScore {
    /// Model signal.
    pub signal: String,
    /// Measured column.
    pub column: String,
    /// rms of the residual over the whole record.
    pub rms: f64,
    /// rms over the held-out part.
    pub holdout_rms: f64,
    /// 100(1 − ‖y − ŷ‖/‖y − ȳ‖) over the whole record.
    pub fit_percent: f64,
}

/// Scores of a model against the record.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Scores {
    /// √(mean over outputs of the squared rms).
    pub rms: f64,
    /// The same over the held-out part.
    pub holdout_rms: f64,
    /// Mean fit % over the outputs.
    pub fit_percent: f64,
    /// Per output.
    pub per_output: Vec<OutputScore>,
}

/// Residual tests of one output.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct ResidualTests {
    /// The output.
    pub signal: String,
    /// Ljung–Box on 20 lags: statistic and p-value (small p: not white).
    pub whiteness: stats::Test,
    /// Largest residual–input cross-correlation (|z| with Bartlett's variance),
    /// Bonferroni p-value, at `input_lag` samples, against `input`.
    pub input_correlation: stats::Test,
    /// The input tested against.
    pub input: String,
    /// Lag of the largest correlation (samples).
    pub input_lag: isize,
    /// Fisher's g test for a periodic line; `line_hz` its frequency.
    pub periodic_line: stats::Test,
    /// Frequency of the strongest line (Hz).
    pub line_hz: f64,
    /// Noise floor σ: the residual's white part (robust, from its
    /// differences), at least q/√12 on a column quantised with step q.
    pub noise_floor: f64,
    /// rms of the residual (estimation part).
    pub rms: f64,
}

/// One candidate tried in a step.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Candidate {
    /// Vocabulary name.
    pub effect: String,
    /// Where it was inserted.
    pub site: String,
    /// Number of fitted parameters.
    pub n_params: usize,
    /// Held-out rms with it (NaN when the fit failed).
    pub holdout_rms: f64,
    /// Ranking score (weighted held-out mean square × flexibility factor).
    pub score: f64,
    /// Why it failed, if it did.
    pub note: Option<String>,
}

/// The inserted block.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct BlockRef {
    /// Its name in the augmented graph.
    pub name: String,
    /// Its `type:`.
    #[serde(rename = "type")]
    pub type_name: String,
}

/// A named effect.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Step {
    /// Vocabulary name.
    pub effect: String,
    /// The inserted block.
    pub block: BlockRef,
    /// Where it entered.
    pub site: String,
    /// Parameters as fitted at this step (all of the block's tunable parameters).
    /// Later steps refit earlier effects jointly, so these can differ from
    /// `final_params`.
    pub params: BTreeMap<String, f64>,
    /// The same parameters in the final augmented model (`model_augmented.yaml`),
    /// after every later joint refit.
    pub final_params: BTreeMap<String, f64>,
    /// Physical quantities derived from the final fitted block, in the units of
    /// the signal it acts on: `coulomb` (the Coulomb level of a friction force
    /// of the stage's own motion, whichever block fitted it; see `ForceSplit`).
    pub derived: BTreeMap<String, f64>,
    /// One standard deviation of the fitted parameters (from the Jacobian).
    pub uncertainty: BTreeMap<String, f64>,
    /// One line a person can check.
    pub evidence: String,
    /// Held-out rms before and after.
    pub holdout_rms_before: f64,
    /// Held-out rms after.
    pub holdout_rms_after: f64,
    /// Cut of the held-out residual (%), each output in units of its noise
    /// floor (the cut of the held-out rms for one output).
    pub cut_percent: f64,
    /// p-value of the held-out improvement test (an effect read off the
    /// record itself, with no candidates: of the test its evidence names).
    pub p_value: f64,
    /// Scores per output after the step.
    pub per_output: Vec<OutputScore>,
    /// Every candidate tried, best first.
    pub candidates: Vec<Candidate>,
    /// Other names the held-out data cannot tell from this one (empty: the
    /// name is clear). The step keeps the best-scoring name; each alternative
    /// says which experiment would decide.
    pub ambiguous_with: Vec<Alternative>,
}

/// A second name that explains a step's data as well as the one taken.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Alternative {
    /// Vocabulary name.
    pub effect: String,
    /// Where it entered.
    pub site: String,
    /// Held-out rms with it instead of the named effect.
    pub holdout_rms: f64,
    /// p-value of "the named effect predicts the held-out data better than
    /// this one" (large: the data cannot tell them apart).
    pub p_value: f64,
    /// The experiment that would tell the two apart.
    pub experiment: String,
}

/// An effect named during the search and taken out at its end: refitted
/// without it, the effects named with it predict the held-out data as well —
/// it no longer passes the tests a name must pass (docs/plf.md, Method,
/// "Backward elimination").
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Dropped {
    /// Vocabulary name.
    pub effect: String,
    /// Where it had entered.
    pub site: String,
    /// Held-out rms with it (the model before it was taken out).
    pub holdout_rms_with: f64,
    /// Held-out rms without it, the rest refitted.
    pub holdout_rms_without: f64,
    /// p-value of "the model with it predicts the held-out data better"
    /// (it had to be below the level it was named at).
    pub p_value: f64,
    /// Share of the excess over the noise floor it still removes (%).
    pub excess_cut_percent: f64,
}

/// The nominal calibration: the nominal model's own parameters — the gain g,
/// the time scale λ (every mode's frequency × λ), the damping scale d (every
/// complex pair's decay rate × d), the lag scale ℓ (every real pole × ℓ) and
/// a time scale per complex pair after the first (up to the fourth) of each
/// continuous `state_space` block (d, ℓ and the pair scales where its spectrum
/// has such modes). A nominal that is a few per cent off is a *nominal
/// error*, not a missing effect: left alone, it is what a flexible effect
/// block (a gain varying with position, a resonance) would be named for. At
/// every step until it is taken, it competes with the best effect and is
/// taken (without using up a step) when it passes the same tests and either
/// scores better on the penalised held-out score or the effect does not
/// predict the held-out data significantly better (p < 0.05); later steps
/// refit it jointly with every effect. An effect that also moves a gain or a
/// time scale a little (creep, a delay) is named when it predicts better.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Calibration {
    /// Whether it was kept.
    pub accepted: bool,
    /// Fitted values, `block.parameter` → value (1 = as the nominal gives it).
    pub params: BTreeMap<String, f64>,
    /// The same in the final augmented model, after the later joint refits.
    pub final_params: BTreeMap<String, f64>,
    /// One standard deviation of the fitted values (from the Jacobian).
    pub uncertainty: BTreeMap<String, f64>,
    /// Held-out rms before.
    pub holdout_rms_before: f64,
    /// Held-out rms after.
    pub holdout_rms_after: f64,
    /// Cut of the held-out rms (%).
    pub cut_percent: f64,
    /// p-value of the held-out improvement test.
    pub p_value: f64,
    /// Share of the mean square above the noise floor it removed (%).
    pub excess_cut_percent: f64,
    /// Scales the data do not determine (σ ≥ the value), held at the
    /// nominal: `block.parameter` → the value the fit drove them to.
    pub held: BTreeMap<String, f64>,
    /// Why it was kept although it does not pass alone: the effect that,
    /// fitted on the calibrated nominal, passes together with it where
    /// neither passes alone (see `Search::calibration_with_effect`).
    pub with_effect: Option<String>,
}

/// Data behind a plot (the CLI draws it).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct PlotData {
    /// File stem.
    pub name: String,
    /// Title.
    pub title: String,
    /// x label.
    pub x_label: String,
    /// y label.
    pub y_label: String,
    /// Draw points instead of lines.
    pub scatter: bool,
    /// (label, x, y).
    pub series: Vec<(String, Vec<f64>, Vec<f64>)>,
}

/// What [`diagnose`] found.
#[derive(Debug, Serialize)]
pub struct Report {
    /// The nominal model's scores.
    pub nominal: Scores,
    /// Residual tests of the nominal model.
    pub nominal_tests: Vec<ResidualTests>,
    /// The nominal calibration as last tried (`None` when off or nothing to
    /// calibrate); `accepted` says whether the model carries it.
    pub calibration: Option<Calibration>,
    /// Names of the effects found, in order.
    pub found: Vec<String>,
    /// The steps.
    pub steps: Vec<Step>,
    /// Scores of the augmented model.
    #[serde(rename = "final")]
    pub final_scores: Scores,
    /// Cut of the held-out residual from the nominal to the augmented model
    /// (%), each output in units of its noise floor (the measure every decision
    /// uses; equal to the cut of the held-out rms for one output).
    pub holdout_cut_percent: f64,
    /// Residual tests of the augmented model.
    pub final_tests: Vec<ResidualTests>,
    /// Why the workflow stopped.
    pub stopped_because: String,
    /// What the record's excitation cannot show (a single tone: linear
    /// effects indistinguishable from the nominal's gain and phase there; a
    /// misfit that acts before the held-out part only, which that part cannot
    /// confirm).
    pub excitation_notes: Vec<String>,
    /// The candidates of the step that named nothing (best first), if it came to one.
    pub rejected_candidates: Vec<Candidate>,
    /// Effects named in the search that the effects named after them made
    /// unnecessary (see [`Dropped`]): not in `found`, `steps` or the
    /// augmented model.
    pub dropped: Vec<Dropped>,
    /// The records: the estimation record first, then the held-out ones (one
    /// name when a single record is split in time).
    pub records: Vec<String>,
    /// Samples used for estimation and held out.
    pub estimation_samples: usize,
    /// Held-out samples.
    pub holdout_samples: usize,
    /// Graph runs spent.
    pub runs: usize,
    /// The augmented model (the nominal graph plus the inserted effect blocks).
    #[serde(skip)]
    pub augmented: Option<GraphSpec>,
    /// Evidence plots (one per step) and residuals before/after.
    #[serde(skip)]
    pub plots: Vec<PlotData>,
    /// Residual (per output) of the nominal and the augmented model, for PSD plots.
    #[serde(skip)]
    pub residuals: Vec<(String, Vec<f64>, Vec<f64>)>,
    /// Data rate (Hz).
    #[serde(skip)]
    pub rate_hz: f64,
}

/// Progress of a diagnosis: (what is being done, fraction of the step done).
pub type Progress<'a> = &'a mut dyn FnMut(&str, f64);

/// Run the workflow. See the [module documentation](self).
pub fn diagnose(spec: &GraphSpec, data: &Dataset, opts: &Options) -> Result<Report, PlfError> {
    diagnose_with_progress(spec, data, opts, &mut |_, _| {})
}

/// [`diagnose_with_progress`] on one record split in time (`opts.holdout`).
pub fn diagnose_with_progress(
    spec: &GraphSpec,
    data: &Dataset,
    opts: &Options,
    progress: Progress<'_>,
) -> Result<Report, PlfError> {
    diagnose_records(spec, std::slice::from_ref(data), opts, progress)
}

/// The state of the model between steps.
struct Current {
    /// The graph in its serde form (shareable between threads; blocks are not `Sync`).
    graph: serde_json::Value,
    /// Inserted effects: (block name, free parameters).
    free: Vec<FreeParam>,
    residual: Vec<Vec<f64>>,
    model: Vec<Vec<f64>>,
}

struct Ctx<'a> {
    /// The records end to end.
    data: &'a Arc<Dataset>,
    /// The records, each simulated from rest.
    records: &'a Records,
    channels: Vec<Channel>,
    n: usize,
    n_est: usize,
    fs: f64,
    /// Per compared output, 1 / its scale: every residual is weighed in units of
    /// its own noise floor (see [`output_scales`]), so that outputs in different
    /// units (a position in m, a drive in V) count alike.
    weights: Vec<f64>,
    /// Per compared output and [`Part`], the noise a quantised measurement
    /// carries whatever the model: q/√12 for a column on a grid of step q
    /// (`stats::lattice` on that part), else 0. See [`floor_sigma`]. Per part:
    /// a held-out record may come from another sensor setting (EMPS: the
    /// validation record's position is not on the estimation record's grid).
    grid_floors: Vec<[f64; 2]>,
    /// The level at which a line in a residual is structure, not noise
    /// ([`at_noise_floor`]): a step's false-alarm level, [`Options::alpha`].
    line_level: f64,
    /// Worker threads for independent runs ([`Options::threads`]).
    threads: usize,
}

/// The estimation or the held-out samples of a record (or records).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Part {
    Estimation = 0,
    HeldOut = 1,
}

impl Ctx<'_> {
    /// The samples of `part` of `x` (a series over all `n` samples).
    fn part<'x>(&self, x: &'x [f64], part: Part) -> &'x [f64] {
        match part {
            Part::Estimation => &x[..self.n_est],
            Part::HeldOut => &x[self.n_est..],
        }
    }
}

/// The noise floor (σ) of `part` of output `i`'s residual `r` (all samples): the white part from its
/// sample-to-sample differences ([`stats::noise_floor`]), but never below the
/// rounding noise of a quantised measurement (q/√12, Widrow's model). On a
/// column that holds its level most samples (a slow stage on a coarse
/// encoder), the differences are mostly zero and their spread says nothing
/// of the rounding error every model must leave.
fn floor_sigma(ctx: &Ctx<'_>, i: usize, r: &[f64], part: Part) -> f64 {
    stats::noise_floor(ctx.part(r, part)).max(grid_floor(ctx, i, part))
}

/// The rounding noise q/√12 of output `i`'s measured column on `part` (0 off a grid).
fn grid_floor(ctx: &Ctx<'_>, i: usize, part: Part) -> f64 {
    ctx.grid_floors.get(i).map_or(0.0, |g| g[part as usize])
}

/// The options must be in range (`holdout`, `max-effects`, every
/// `effects` name in the vocabulary).
fn check_options(opts: &Options) -> Result<(), PlfError> {
    if !(0.05..=0.8).contains(&opts.holdout) {
        return Err(PlfError::Option {
            option: "holdout",
            problem: format!(
                "is {}; give a fraction in [0.05, 0.8] (0.3 holds out the last 30 %)",
                opts.holdout
            ),
        });
    }
    if opts.max_effects > 13 {
        return Err(PlfError::Option {
            option: "max-effects",
            problem: format!("is {}; at most 13 (the vocabulary)", opts.max_effects),
        });
    }
    for e in &opts.effects {
        if !vocabulary().contains(&e.as_str()) {
            return Err(PlfError::Option {
                option: "effects",
                problem: format!(
                    "`{e}` is not in the vocabulary: {}",
                    vocabulary().join(", ")
                ),
            });
        }
    }
    Ok(())
}

/// The declared phase ([`Options::phase`]) must be a scalar output of a block
/// of the model: `BLOCK.PORT`.
fn check_phase(spec: &GraphSpec, opts: &Options) -> Result<(), PlfError> {
    let Some(phase) = opts.phase.as_deref() else {
        return Ok(());
    };
    let scalar_outputs = || {
        let all: Vec<String> = spec
            .blocks
            .iter()
            .flat_map(|b| {
                b.block
                    .outputs()
                    .into_iter()
                    .filter(|p| p.width == 1)
                    .map(move |p| format!("{}.{}", b.name, p.name))
            })
            .collect();
        all.join(", ")
    };
    let problem = match phase.split_once('.') {
        None => format!("`{phase}` is not a signal BLOCK.PORT"),
        Some((block, port)) => match spec.blocks.iter().find(|b| b.name == block) {
            None => format!("the model has no block `{block}`"),
            Some(b) => match b.block.outputs().into_iter().find(|p| p.name == port) {
                None => format!("block `{block}` has no output `{port}`"),
                Some(p) if p.width != 1 => {
                    format!(
                        "`{phase}` has width {}; the phase must be a scalar",
                        p.width
                    )
                }
                Some(_) => return Ok(()),
            },
        },
    };
    Err(PlfError::Option {
        option: "phase",
        problem: format!(
            "{problem}: give a scalar signal of the model the disturbance may be periodic in, such as an integrator of the drive scaled to the leg angle (alpha.y); the model's scalar signals: {}",
            scalar_outputs()
        ),
    })
}

/// [`diagnose`] on several records with a progress callback: with one record,
/// its last `opts.holdout` is held out; with more, `records[0]` estimates every
/// parameter and the others (same columns and rate, other excitations) are
/// held out whole and decide what is named — an effect must help on records
/// it was not fitted on. Each record is simulated from rest.
pub fn diagnose_records(
    spec: &GraphSpec,
    records: &[Dataset],
    opts: &Options,
    progress: Progress<'_>,
) -> Result<Report, PlfError> {
    check_options(opts)?;
    check_record_lengths(records)?;
    let records = Records::concat(records)?;
    let data = records.all.clone();
    check_phase(spec, opts)?;
    let (ctx, nominal, nominal_scores, runs) = context(spec, &records, &data, opts)?;
    let mut search = Search::new(&ctx, opts, nominal, nominal_scores, runs)?;
    // No effect asked for: the nominal calibration alone.
    if opts.max_effects == 0 && opts.calibrate {
        search.calibration_only()?;
    }
    while search.steps.len() < opts.max_effects {
        if let Next::Stop = search.step(progress)? {
            break;
        }
    }
    search.prune()?;
    search.rounding_from_grid()?;
    search.report(spec)
}

/// Each record must be long enough to estimate on (and, alone, to hold out
/// a part of).
fn check_record_lengths(records: &[Dataset]) -> Result<(), PlfError> {
    let split = records.len() == 1;
    for (j, r) in records.iter().enumerate() {
        let need = if split { 200 } else { 100 };
        if r.len() < need {
            return Err(PlfError::Data(format!(
                "{} has {} samples; the workflow needs at least {need} {}",
                r.origin(),
                r.len(),
                if split {
                    "to estimate and hold out"
                } else if j == 0 {
                    "to estimate"
                } else {
                    "in a held-out record"
                }
            )));
        }
    }
    Ok(())
}

/// What every step reads: the records, the compared outputs, the estimation
/// and held-out parts, each output's weight (1 / its scale on the nominal's
/// residual) — and the nominal model run on the records, its scores (every
/// output weighed alike) and the graph runs spent.
fn context<'a>(
    spec: &GraphSpec,
    records: &'a Records,
    data: &'a Arc<Dataset>,
    opts: &Options,
) -> Result<(Ctx<'a>, Current, Scores, usize), PlfError> {
    let n = data.len();
    let fs = data.rate_hz();
    let n_est = if records.parts.len() == 1 {
        ((1.0 - opts.holdout) * n as f64).round() as usize
    } else {
        records.parts[0].len()
    };
    let mut nominal = surgery::clone_spec(spec)?;
    nominal.duration_s = n as f64 / fs;
    if let Some(s) = opts.seed {
        nominal.seed = s;
    }
    let channels = surgery::channels(&nominal, data)?;
    check_columns(data, &channels)?;
    let grid_floors = channels
        .iter()
        .map(|ch| {
            let measured = data.column(&ch.column).unwrap_or(&[]);
            let cut = n_est.min(measured.len());
            let floor = |part: &[f64]| stats::lattice(part).map_or(0.0, |(q, _)| q / 12f64.sqrt());
            [floor(&measured[..cut]), floor(&measured[cut..])]
        })
        .collect();
    let mut ctx = Ctx {
        data,
        records,
        weights: vec![1.0; channels.len()],
        grid_floors,
        channels,
        n,
        n_est,
        fs,
        line_level: opts.alpha,
        threads: opts.threads.max(1),
    };
    let mut runs = 0usize;
    let cur = evaluate_current(&ctx, nominal, Vec::new(), &mut runs)?;
    let nominal_scores = scores(&ctx, &cur);
    check_finite(data, &nominal_scores)?;
    ctx.weights = output_scales(&ctx, &cur.residual)
        .iter()
        .map(|s| 1.0 / s)
        .collect();
    Ok((ctx, cur, nominal_scores, runs))
}

/// What a step decides next.
enum Next {
    /// Another step (an effect was named, the calibration was taken, or the
    /// step is tried again with the candidates locked to the excitation).
    Step,
    /// The search ends (`Search::stopped` says why).
    Stop,
}

/// The search for missing effects (docs/plf.md, "Method"): the model reached
/// so far and what was named on the way.
struct Search<'c, 'a> {
    ctx: &'c Ctx<'a>,
    opts: &'c Options,
    /// The nominal's scores and tests, and its residuals (the report's
    /// "before").
    nominal_scores: Scores,
    nominal_tests: Vec<ResidualTests>,
    first_residuals: Vec<Vec<f64>>,
    /// The model reached so far.
    cur: Current,
    /// The nominal calibration competes with the effects at every step until
    /// it is taken (see `Calibration`); the last one tried is reported.
    calibration: Option<Calibration>,
    steps: Vec<Step>,
    plots: Vec<PlotData>,
    /// Why the search stopped.
    stopped: String,
    /// The candidate table of the step that named nothing.
    rejected_candidates: Vec<Candidate>,
    /// (effect, the outputs it concerns, its site's kind) of every step taken.
    named: Vec<(&'static str, Vec<usize>, &'static str)>,
    /// Per step: (force signal, position) of an effect fed by the stage's own motion.
    own_forces: Vec<Option<(String, String)>>,
    /// Per step: the level it was significant at (α over the step's candidates).
    levels: Vec<f64>,
    /// Steps taken out at the end (see `prune`).
    dropped: Vec<Dropped>,
    /// A step being tried again with the candidates refused as locked to the
    /// excitation (see `step`): why the step had stopped, its table, and the
    /// number of candidates its level was set by.
    locked_retry: Option<(String, Vec<Candidate>, usize)>,
    /// The nominal calibration of the step's model, computed while its
    /// candidates are fitted (see `fit_and_rank`) for `calibration_competes`,
    /// with the graph runs it took (counted when it is used).
    early_calibration: Option<(CalibrateResult, usize)>,
    /// Graph runs spent.
    runs: usize,
}

/// What [`calibrate`] returns.
type CalibrateResult = Result<Option<(Calibration, Current, (f64, f64))>, PlfError>;

/// A step's candidates, fitted and ranked.
struct Ranked {
    /// The new candidates (a copy of a named effect is not among them).
    cands: Vec<Cand>,
    /// Their fits, in `cands` order (`None`: failed, or taken out of the race).
    results: Vec<Option<Fitted>>,
    /// Refusals before any fit (see `phase_locked`), in `cands` order.
    locked: Vec<Option<String>>,
    /// Whether a candidate was refused as locked to the excitation.
    any_locked: bool,
    /// How many candidates the step's level is set by.
    n_tested: usize,
    /// The best copy of a named effect, by its own penalised score.
    same_form: Option<(Fitted, Cand)>,
    /// The candidate table of the report.
    table: Vec<Candidate>,
    /// Indices of the fitted candidates, best score first.
    order: Vec<usize>,
}

impl<'c, 'a> Search<'c, 'a> {
    fn new(
        ctx: &'c Ctx<'a>,
        opts: &'c Options,
        nominal: Current,
        nominal_scores: Scores,
        runs: usize,
    ) -> Result<Self, PlfError> {
        Ok(Search {
            ctx,
            opts,
            nominal_scores,
            nominal_tests: tests(ctx, &nominal)?,
            first_residuals: nominal.residual.clone(),
            cur: nominal,
            calibration: None,
            steps: Vec::new(),
            plots: Vec::new(),
            stopped: format!("reached --max-effects {}", opts.max_effects),
            rejected_candidates: Vec::new(),
            named: Vec::new(),
            own_forces: Vec::new(),
            levels: Vec::new(),
            dropped: Vec::new(),
            locked_retry: None,
            early_calibration: None,
            runs,
        })
    }

    /// `--max-effects 0`: the nominal calibration alone, judged as an effect
    /// is (significant at α, at least `min_excess_cut` of the excess).
    fn calibration_only(&mut self) -> Result<(), PlfError> {
        let (ctx, opts) = (self.ctx, self.opts);
        let excess = excess_ms(ctx, &self.cur);
        let at_floor = at_noise_floor(ctx, &self.cur);
        if let Some((mut cal, calibrated, (before_ms, cal_ms))) =
            calibrate(ctx, &self.cur, &mut self.runs)?
        {
            let cut = excess_cut(ctx, &excess, at_floor, before_ms, cal_ms);
            cal.accepted = !at_floor && cal.p_value < opts.alpha && cut >= opts.min_excess_cut;
            cal.excess_cut_percent = 100.0 * cut;
            if cal.accepted {
                self.cur = calibrated;
            }
            self.stopped = format!(
                "--max-effects 0: the nominal calibration only ({})",
                if cal.accepted { "kept" } else { "not kept" }
            );
            self.calibration = Some(cal);
        }
        Ok(())
    }

    /// One step: the candidates fitted and ranked, the finalists refitted
    /// with what is named, the calibration's competition, the tests a name
    /// must pass, and the name.
    fn step(&mut self, progress: Progress<'_>) -> Result<Next, PlfError> {
        let (ctx, opts) = (self.ctx, self.opts);
        let step_no = self.steps.len();
        // At the noise floor already? The floor is estimated from the residual's
        // sample-to-sample differences, so a model error that is itself white —
        // an encoder's rounding when the stage crosses about an lsb per sample —
        // looks like noise. Only memoryless functions of the measured position
        // (quantization, slit errors) can be white that way; at the floor only
        // they are tried, and they must then cut the whole mean square (not an
        // excess the floor cannot separate from the noise).
        let excess = excess_ms(ctx, &self.cur);
        let at_floor = at_noise_floor(ctx, &self.cur);
        let floor_stop = "the held-out residual is at its noise floor (mean square within 20 % of the white-noise estimate)";
        let Some(mut ranked) = self.fit_and_rank(at_floor, step_no, progress)? else {
            self.stopped = floor_stop.into();
            return Ok(Next::Stop);
        };
        if ranked.order.is_empty() {
            self.stopped = "no candidate could be fitted".into();
            if let Some((why, table, _)) = self.locked_retry.take() {
                (self.stopped, self.rejected_candidates) = (why, table);
            }
            return Ok(Next::Stop);
        }
        // The level an effect must be significant at (α over the candidates).
        let level = opts.alpha / ranked.n_tested.max(1) as f64;
        let finalists = self.finalists(&mut ranked, level, &excess, at_floor);
        let (best, same_form) =
            self.decide_finalists(&mut ranked, finalists, level, &excess, at_floor);
        let Some((bi, win, best_score)) = best else {
            self.stopped = "no candidate could be fitted as a physical effect".into();
            self.rejected_candidates = ranked.table.clone();
            if let Some((why, table, _)) = self.locked_retry.take() {
                (self.stopped, self.rejected_candidates) = (why, table);
            }
            return Ok(Next::Stop);
        };
        if self.calibration_competes(
            &ranked, &win, best_score, &excess, at_floor, step_no, progress,
        )? {
            self.locked_retry = None;
            return Ok(Next::Step);
        }
        let cand = &ranked.cands[bi];
        let (test, excess_cut) =
            held_out_gain(ctx, (&excess, at_floor), &self.cur.residual, &win.residual);
        let hb = holdout_rms(ctx, &self.cur.residual);
        let ha = holdout_rms(ctx, &win.residual);
        if !passes(opts, level, &test, excess_cut) {
            if let Some((why, table, _)) = self.locked_retry.take() {
                (self.stopped, self.rejected_candidates) = (why, table);
                return Ok(Next::Stop);
            }
            self.rejected_candidates = ranked.table.clone();
            if at_floor {
                self.stopped = format!(
                    "{floor_stop}; of the effects that can hide in white noise the best was {} ({}), held-out rms {:.4e} -> {:.4e}, p = {:.2e}",
                    cand.effect,
                    cand.site.describe(),
                    hb,
                    ha,
                    test.p_value
                );
                return Ok(Next::Stop);
            }
            self.stopped = format!(
                "no candidate cut the held-out residual significantly: best was {} ({}), held-out rms {:.4e} -> {:.4e}, p = {:.2e} (needed < {:.1e}), {:.0} % of the excess over the noise floor (needed {:.0} %)",
                cand.effect,
                cand.site.describe(),
                hb,
                ha,
                test.p_value,
                level,
                100.0 * excess_cut,
                100.0 * opts.min_excess_cut
            );
            if self.calibration_with_effect(
                &ranked,
                level,
                (&excess, at_floor),
                step_no,
                progress,
            )? {
                self.locked_retry = None;
                return Ok(Next::Step);
            }
            // Only before anything is named: once a map of the input is,
            // a line locked to the excitation is likelier what its form leaves.
            if ranked.any_locked && self.named.is_empty() {
                self.locked_retry =
                    Some((self.stopped.clone(), ranked.table.clone(), ranked.n_tested));
                return Ok(Next::Step);
            }
            return Ok(Next::Stop);
        }
        // The named effects' own form: the record's effect is rarely in the
        // exact shape of our block (another hysteresis law, a smoother limit,
        // creep with other time constants), and what our block leaves is
        // structured, so a flexible new block cuts it significantly. A new
        // name must therefore predict the held-out data better than another
        // copy of an effect already named (refitted jointly like the winner):
        // on the penalised score and significantly, at the level it must beat
        // the model at — as against the nominal calibration, when the data
        // cannot tell a new effect from the form of one named, one effect is
        // the likelier and simpler explanation.
        if let Some((c, f, sc)) = &same_form {
            let vs_copy = held_out_test(ctx, &f.residual, &win.residual);
            if *sc <= best_score || vs_copy.p_value >= level {
                self.rejected_candidates = ranked.table.clone();
                self.stopped = format!(
                    "the rest is the form of the effects named, not a new effect: the best new effect, {} ({}), held-out rms {:.4e}, does not predict the held-out data significantly better than another {} ({}), {:.4e} (p = {:.2e}, needed < {:.1e})",
                    cand.effect,
                    cand.site.describe(),
                    ha,
                    c.effect,
                    c.site.describe(),
                    holdout_rms(ctx, &f.residual),
                    vs_copy.p_value,
                    level
                );
                return Ok(Next::Stop);
            }
        }
        self.name(ranked, bi, win, test, (level, &excess, at_floor), step_no)?;
        Ok(Next::Step)
    }

    /// The step's candidates, fitted (one per core) and ranked by their
    /// penalised score; `None` when the residual is at its noise floor and
    /// no candidate that could hide in white noise is left.
    fn fit_and_rank(
        &mut self,
        at_floor: bool,
        step_no: usize,
        progress: Progress<'_>,
    ) -> Result<Option<Ranked>, PlfError> {
        let (ctx, opts) = (self.ctx, self.opts);
        let named = &self.named;
        // An effect named before on an axis is never a new effect there (the
        // joint refit adjusts the first; a second copy at another place of the
        // same axis — another output of the same loop, another connection in
        // series on it — would only be padding).
        // A hysteretic force of the stage's own motion after friction was named
        // there is that same force again.
        // Those copies (`again`) at the kind of place the effect was named
        // (on the drive, inside the loop, on the output) are fitted all the
        // same: they are what a new name must beat (see `same_form` in
        // `step`). A copy at another kind of place is another physical
        // claim, not the named effect's form: a hysteresis of the stage's own
        // position inside the loop adds dynamics (the plant's lag on its
        // input) that a hysteresis on the drive has not, and stood for creep
        // (blind 5368: after the drive's hysteresis, creep cut the held-out
        // rms 2.0 -> 0.37, such a copy 0.41, so creep was not named).
        // `None`: not a copy; `Some(at the named one's kind of place)`.
        let copy = |c: &Cand| {
            let outs = outputs_of(ctx, &c.site);
            let own_motion = matches!(c.site, Site::Feedback { .. });
            let kinds: Vec<&str> = named
                .iter()
                .filter(|(e, o, _)| {
                    (*e == c.effect || (own_motion && *e == "friction"))
                        && o.iter().any(|&k| {
                            outs.iter()
                                .any(|&j| ctx.channels[k].same_axis(&ctx.channels[j]))
                        })
                })
                .map(|&(_, _, kind)| kind)
                .collect();
            (!kinds.is_empty()).then(|| kinds.contains(&c.site.kind()))
        };
        let (mut cands, mut again) = (Vec::new(), Vec::new());
        for c in enumerate(ctx, &self.cur, opts, &mut self.runs)? {
            match copy(&c) {
                None => cands.push(c),
                Some(true) => again.push(c),
                Some(false) => {}
            }
        }
        // A second slit table on an axis that has one has no form the first
        // lacks (every entry of a table is free): no copy to beat.
        again.retain(|c| c.effect != "encoder_slit_error");
        if at_floor {
            cands.retain(|c| {
                can_look_white(c.effect)
                    && matches!(c.site, Site::Output { .. } | Site::Sensor { .. })
            });
            again.clear();
            if cands.is_empty() {
                return Ok(None);
            }
        }
        let mut total = cands.len();
        cands.append(&mut again);
        // Names refused before any fit, by physics (see `phase_locked`).
        let spec_now = self.cur.spec()?;
        let mut locked: Vec<Option<String>> = cands
            .iter()
            .map(|c| time_period(c).and_then(|p| phase_locked(ctx, &self.cur, &spec_now, p)))
            .collect();
        let any_locked = locked[..total].iter().any(Option::is_some);
        // The level is set by every candidate of the step, tried again or not.
        let n_tested = self.locked_retry.as_ref().map_or(total, |r| r.2);
        // Locked to the excitation means a map of the input *could* leave the
        // line; when none of those tried explains it and nothing is named yet,
        // the disturbance is the explanation left: the refused candidates are
        // fitted after all.
        if self.locked_retry.is_some() {
            let keep: Vec<bool> = (0..cands.len())
                .map(|i| i >= total || locked[i].is_some())
                .collect();
            total = (0..total).filter(|&i| keep[i]).count();
            let mut k = keep.into_iter();
            cands.retain(|_| k.next().unwrap_or(false));
            locked = vec![None; cands.len()];
        }
        // The nominal calibration of this model competes with the step's
        // best candidate (`calibration_competes`): it depends on the model
        // alone, so it is computed beside the candidates' fits, on a thread
        // of its own — the same result as computed after them, with the cores
        // busy while the queue's last fits run.
        let calibrate_early =
            opts.calibrate && !self.calibration.as_ref().is_some_and(|c| c.accepted);
        // With one thread asked for (`Options::threads`), it runs after
        // the fits on the caller's thread: the same result.
        let cur = &self.cur;
        let calibrate_now = || {
            let mut runs = 0;
            let r = calibrate(ctx, cur, &mut runs);
            (r, runs)
        };
        let ((mut results, mut failures, fit_runs), early) = if opts.threads > 1 {
            std::thread::scope(|sc| {
                let early = calibrate_early.then(|| sc.spawn(calibrate_now));
                let fits =
                    fit_candidates(ctx, cur, &cands, &locked, opts.threads, step_no, progress);
                let early =
                    early.map(|h| h.join().unwrap_or_else(|e| std::panic::resume_unwind(e)));
                (fits, early)
            })
        } else {
            let fits = fit_candidates(ctx, cur, &cands, &locked, opts.threads, step_no, progress);
            (fits, calibrate_early.then(calibrate_now))
        };
        self.early_calibration = early;
        self.runs += fit_runs;
        let again = cands.split_off(total);
        let again_results = results.split_off(total);
        failures.truncate(total);
        // The best copy of a named effect, by its own penalised score.
        let same_form = again_results
            .into_iter()
            .zip(again)
            .filter_map(|(f, c)| f.map(|f| (f, c)))
            .min_by(|a, b| a.0.score.total_cmp(&b.0.score));
        progress(&format!("step {}: deciding", step_no + 1), 1.0);
        let table = candidate_table(ctx, &cands, &results, &failures);
        let mut order: Vec<usize> = (0..results.len())
            .filter(|&i| results[i].is_some())
            .collect();
        order.sort_by(|&a, &b| {
            let sa = results[a].as_ref().map_or(f64::INFINITY, |f| f.score);
            let sb = results[b].as_ref().map_or(f64::INFINITY, |f| f.score);
            sa.total_cmp(&sb)
        });
        Ok(Some(Ranked {
            cands,
            results,
            locked,
            any_locked,
            n_tested,
            same_form,
            table,
            order,
        }))
    }

    /// The finalists: the best one by score (three once effects are named,
    /// for the joint refit), passing over fits that are not physical as
    /// named (their results are taken out, their table rows say why).
    fn finalists(
        &self,
        ranked: &mut Ranked,
        level: f64,
        excess: &[(f64, f64)],
        at_floor: bool,
    ) -> Vec<usize> {
        let (ctx, opts, cur) = (self.ctx, self.opts, &self.cur);
        let Ranked {
            cands,
            results,
            table,
            order,
            ..
        } = ranked;
        let mut finalists: Vec<usize> = Vec::new();
        // The best fit that does not cut the held-out residual as a name must
        // (`held_out_gain`): passed over (ranked first by its penalised score,
        // it would stop the search before a candidate that does is tested; the
        // level is over all candidates, so testing each one is allowed for),
        // but the finalist when no candidate passes, so the report says why
        // the search stopped. Once effects are named, a finalist is refitted
        // jointly with them and only then decided (the refit can make it
        // pass), so only a fit that cuts nothing at all is passed over.
        let mut not_cutting: Option<usize> = None;
        for &i in order.iter() {
            if finalists.len() == if cur.free.is_empty() { 1 } else { 3 } {
                break;
            }
            let Some(f) = &results[i] else { continue };
            // A hysteresis block whose fitted map has no loop is not hysteresis
            // (see `memory_share`): it stands in for a gain, a saturation or a
            // smooth misfit; nor is one that runs backwards after reversals
            // (see `reversed_travel`); a friction force that is all viscous is
            // a damping.
            let note = if let Some(why) = not_physical(ctx, &cands[i], f) {
                format!("refused as not physical: {why}")
            } else if let (test, cut) =
                held_out_gain(ctx, (excess, at_floor), &cur.residual, &f.residual)
                && if cur.free.is_empty() {
                    !passes(opts, level, &test, cut)
                } else {
                    cut <= 0.0
                }
            {
                if not_cutting.is_none() {
                    not_cutting = Some(i);
                    continue;
                }
                NOT_CUTTING.into()
            } else if let Some(why) = degenerate_explains(
                ctx,
                cur,
                &cands[i],
                f,
                (level, excess, at_floor, opts.min_excess_cut),
                None,
            ) {
                format!("refused: {why}")
            } else {
                finalists.push(i);
                continue;
            };
            annotate(table, &cands[i], f.score, note);
            results[i] = None;
        }
        if finalists.is_empty() {
            finalists.extend(not_cutting);
        } else if let Some(i) = not_cutting
            && let Some(f) = results[i].take()
        {
            annotate(table, &cands[i], f.score, NOT_CUTTING.into());
        }
        finalists
    }

    /// The finalists refitted jointly with the effects named (one per core),
    /// each decided on its refit: the best by penalised score (index, fit,
    /// score), the others put back into `ranked.results` as alternatives;
    /// and the best copy of a named effect, refitted jointly too (with its
    /// candidate and score).
    #[allow(clippy::type_complexity)]
    fn decide_finalists(
        &mut self,
        ranked: &mut Ranked,
        finalists: Vec<usize>,
        level: f64,
        excess: &[(f64, f64)],
        at_floor: bool,
    ) -> (Option<(usize, Fitted, f64)>, Option<(Cand, Fitted, f64)>) {
        let (ctx, opts) = (self.ctx, self.opts);
        let score_of =
            |f: &Fitted, ms: f64| penalised(ctx, flexibility(f.effect, f.free_indices.len()), ms);
        let mut top: Vec<Fitted> = finalists
            .iter()
            .map(|&i| ranked.results[i].take().expect("fitted"))
            .collect();
        // The copy of a named effect is refitted jointly too, last.
        let same_form = ranked.same_form.take().map(|(f, c)| {
            top.push(f);
            c
        });
        // The joint refits are independent: one per core.
        type Joint = Option<(Result<Fitted, PlfError>, usize)>;
        let top: Vec<(Fitted, Joint)> = if self.cur.free.is_empty() {
            top.into_iter().map(|f| (f, None)).collect()
        } else {
            crate::pool::map(
                top,
                opts.threads,
                |_| 1.0,
                |f| {
                    let mut n_runs = 0;
                    let j = joint_refit(ctx, &f, &mut n_runs);
                    (f, Some((j, n_runs)))
                },
            )
        };
        let mut top: Vec<(Fitted, Option<Fitted>)> = top
            .into_iter()
            .map(|(f, joint)| {
                let joint = joint.map(|(j, n_runs)| {
                    self.runs += n_runs;
                    j
                });
                match joint {
                    Some(Ok(j))
                        if weighted_holdout_ms(ctx, &j.residual)
                            < weighted_holdout_ms(ctx, &f.residual)
                            && implausible(
                                ctx,
                                &j.spec,
                                j.free.iter().map(|p| p.block.as_str()),
                            )
                            .is_none() =>
                    {
                        (f, Some(j))
                    }
                    _ => (f, None),
                }
            })
            .collect();
        // The named effects' own form: the best copy of one (pushed last),
        // jointly refitted.
        let same_form = same_form.and_then(|c| {
            let (f, j) = top.pop()?;
            let f = j.unwrap_or(f);
            let sc = score_of(&f, weighted_holdout_ms(ctx, &f.residual));
            Some((c, f, sc))
        });
        let mut best: Option<(usize, Fitted, f64)> = None;
        for (&i, (mut f, joint)) in finalists.iter().zip(top) {
            if let Some(j) = joint
                && not_physical(ctx, &ranked.cands[i], &j).is_none()
            {
                f = j;
            }
            // Once effects are named, what makes the effect must also show
            // on the joint refit (see `degenerate_explains`), against the
            // degenerate form refitted jointly too.
            if !self.cur.free.is_empty()
                && let Some(why) = degenerate_explains(
                    ctx,
                    &self.cur,
                    &ranked.cands[i],
                    &f,
                    (level, excess, at_floor, opts.min_excess_cut),
                    Some(&mut self.runs),
                )
            {
                annotate(
                    &mut ranked.table,
                    &ranked.cands[i],
                    f.score,
                    format!("refused: {why}"),
                );
                continue;
            }
            let sc = score_of(&f, weighted_holdout_ms(ctx, &f.residual));
            if best.as_ref().is_none_or(|b| sc < b.2) {
                if let Some((j, beaten, _)) = best.take() {
                    ranked.results[j] = Some(beaten);
                }
                best = Some((i, f, sc));
            } else {
                // Kept: an alternative name is judged against the winner below.
                ranked.results[i] = Some(f);
            }
        }
        (best, same_form)
    }

    /// The nominal's own parameters against the best effect `win` (score
    /// `best_score`); `true` when the calibration is taken (the model is
    /// then the calibrated nominal, and the step is tried again on it).
    ///
    /// A nominal a few per cent off is a nominal error, which a flexible
    /// effect would otherwise be named for; an effect that also moves a gain
    /// and a time scale a little (creep, a delay) is named when it predicts
    /// better — on the penalised score *and* significantly on the held-out
    /// data, at the level it must beat the nominal at (α over the
    /// candidates: the best of many always beats the calibration a little):
    /// every identified nominal is somewhat off, so when the data cannot
    /// tell the two apart, a nominal error is the likelier (and simpler)
    /// explanation, and the effect is still tried next step.
    #[allow(clippy::too_many_arguments)]
    fn calibration_competes(
        &mut self,
        ranked: &Ranked,
        win: &Fitted,
        best_score: f64,
        excess: &[(f64, f64)],
        at_floor: bool,
        step_no: usize,
        progress: Progress<'_>,
    ) -> Result<bool, PlfError> {
        let (ctx, opts) = (self.ctx, self.opts);
        if !opts.calibrate || self.calibration.as_ref().is_some_and(|c| c.accepted) {
            return Ok(false);
        }
        let calibration = match self.early_calibration.take() {
            Some((r, runs)) => {
                self.runs += runs;
                r
            }
            None => calibrate(ctx, &self.cur, &mut self.runs),
        };
        let Some((mut cal, calibrated, (before_ms, cal_ms))) = calibration? else {
            return Ok(false);
        };
        let cands = &ranked.cands;
        let cal_score = penalised(ctx, (cal.params.len(), cal.params.len()), cal_ms);
        let cut = excess_cut(ctx, excess, at_floor, before_ms, cal_ms);
        let level = opts.alpha / (ranked.n_tested + 1) as f64;
        let effect_vs_cal = held_out_test(ctx, &calibrated.residual, &win.residual);
        let significant = !at_floor && cal.p_value < level && cut >= opts.min_excess_cut;
        cal.accepted = significant && (cal_score < best_score || effect_vs_cal.p_value >= level);
        // The effects fitted on the calibrated nominal too: an effect
        // fitted on a nominal that is off takes what the nominal's own
        // error leaves as well, and a flexible block (a hysteresis inside
        // the loop) can then beat the effect that is there (a backlash on
        // the drive, fitting to 17 % of that rms once the gain and the lag
        // are right: tuning 346). Like is compared with like: the best of
        // them against the best effect with the nominal then calibrated
        // on it (each pair charged for both parameter sets), as the steps
        // would go on from it. The calibration is taken when the first
        // scores better. (Against the effect alone, a calibration that
        // had taken a friction's viscous part as damping (× 6.6) won
        // with a hysteresis inside the loop over the friction that is
        // there: tuning 288.) Of the step's candidates, the best
        // [`CAL_COMPETES_TRIED`] by their score on the nominal as it is are
        // fitted again, not every one (for speed, #24; what it assumes: an
        // effect the nominal's error hid still ranks among the best on it —
        // on the held-out scenarios 4888–5019 it changed one record of 115).
        if significant && !cal.accepted {
            let top: Vec<usize> = ranked
                .order
                .iter()
                .copied()
                .take(CAL_COMPETES_TRIED)
                .collect();
            let cands: Vec<Cand> = top.iter().map(|&i| cands[i].clone()).collect();
            let locked: Vec<Option<String>> =
                top.iter().map(|&i| ranked.locked[i].clone()).collect();
            let cands = &cands;
            let (on_cal, _, fit_runs) = fit_candidates(
                ctx,
                &calibrated,
                cands,
                &locked,
                opts.threads,
                step_no,
                progress,
            );
            self.runs += fit_runs;
            let k_cal = cal.params.len();
            let with_cal = |f: &Fitted, ms: f64| {
                let (k, flex) = flexibility(f.effect, f.free_indices.len());
                penalised(ctx, (k + k_cal, flex + k_cal), ms)
            };
            let best_on_cal = on_cal
                .iter()
                .zip(cands)
                .filter_map(|(f, c)| f.as_ref().map(|f| (f, c)))
                .filter(|(f, c)| not_physical(ctx, c, f).is_none())
                .map(|(f, _)| with_cal(f, weighted_holdout_ms(ctx, &f.residual)))
                .fold(f64::INFINITY, f64::min);
            if best_on_cal < best_score {
                let effect_first = evaluate_current(
                    ctx,
                    surgery::clone_spec(&win.spec)?,
                    win.free.clone(),
                    &mut self.runs,
                )?;
                let then_cal = calibrate(ctx, &effect_first, &mut self.runs)?.map_or(
                    weighted_holdout_ms(ctx, &win.residual),
                    |(_, _, (_, ms))| ms,
                );
                cal.accepted = best_on_cal < with_cal(win, then_cal);
            }
        }
        cal.excess_cut_percent = 100.0 * cut;
        let accepted = cal.accepted;
        self.calibration = Some(cal);
        if accepted {
            self.cur = calibrated;
        }
        Ok(accepted)
    }

    /// Before anything is named, when neither the nominal calibration nor
    /// any effect passes alone: the best [`CAL_WITH_EFFECT_TRIED`]
    /// candidates fitted on the calibrated nominal, and the calibration kept
    /// (`true`: the next step names on it) when one of them passes together
    /// with it — against the nominal as it is, at the step's level and on
    /// the excess. A nominal that is off and an effect can share the
    /// residual so that each alone explains too little: blind 5027 (a drive
    /// delay of 3 samples, its own calibrated visibility 70, on a nominal
    /// off by up to 10 %) — the calibration alone cut 19 % of the excess,
    /// the delay alone 20 %, and nothing was named. The effect itself is
    /// still judged next step, by every test, on the calibrated nominal.
    fn calibration_with_effect(
        &mut self,
        ranked: &Ranked,
        level: f64,
        (excess, at_floor): (&[(f64, f64)], bool),
        step_no: usize,
        progress: Progress<'_>,
    ) -> Result<bool, PlfError> {
        let (ctx, opts) = (self.ctx, self.opts);
        if !opts.calibrate
            || at_floor
            || !self.named.is_empty()
            || self.calibration.as_ref().is_none_or(|c| c.accepted)
        {
            return Ok(false);
        }
        let Some((mut cal, calibrated, _)) = calibrate(ctx, &self.cur, &mut self.runs)? else {
            return Ok(false);
        };
        let top: Vec<usize> = ranked
            .order
            .iter()
            .copied()
            .take(CAL_WITH_EFFECT_TRIED)
            .collect();
        let cands: Vec<Cand> = top.iter().map(|&i| ranked.cands[i].clone()).collect();
        let locked: Vec<Option<String>> = top.iter().map(|&i| ranked.locked[i].clone()).collect();
        let (on_cal, _, fit_runs) = fit_candidates(
            ctx,
            &calibrated,
            &cands,
            &locked,
            opts.threads,
            step_no,
            progress,
        );
        self.runs += fit_runs;
        let best = on_cal
            .iter()
            .zip(&cands)
            .filter_map(|(f, c)| f.as_ref().map(|f| (f, c)))
            .filter(|(f, c)| not_physical(ctx, c, f).is_none())
            .min_by(|a, b| a.0.score.total_cmp(&b.0.score));
        let Some((f, c)) = best else {
            return Ok(false);
        };
        let (test, cut) = held_out_gain(ctx, (excess, at_floor), &self.cur.residual, &f.residual);
        if !passes(opts, level, &test, cut) {
            return Ok(false);
        }
        cal.accepted = true;
        cal.excess_cut_percent = 100.0
            * excess_cut(
                ctx,
                excess,
                at_floor,
                weighted_holdout_ms(ctx, &self.cur.residual),
                weighted_holdout_ms(ctx, &calibrated.residual),
            );
        cal.with_effect = Some(format!(
            "kept with {} ({}): alone it does not pass, fitted on it that effect takes the held-out rms {:.4e} -> {:.4e} together (p = {:.1e}, needed < {:.1e}; {:.0} % of the excess over the noise floor)",
            c.effect,
            c.site.describe(),
            holdout_rms(ctx, &self.cur.residual),
            holdout_rms(ctx, &f.residual),
            test.p_value,
            level,
            100.0 * cut
        ));
        self.calibration = Some(cal);
        self.cur = calibrated;
        Ok(true)
    }

    /// Name candidate `bi` of the step (its fit `win` passed every test):
    /// its evidence and plot, the model with it, its name by physics (a
    /// hysteretic force of the stage's own motion set by the direction of
    /// motion is friction), the names the data cannot tell from it, and the
    /// step's record.
    fn name(
        &mut self,
        ranked: Ranked,
        bi: usize,
        win: Fitted,
        test: stats::Test,
        (level, excess, at_floor): (f64, &[(f64, f64)], bool),
        step_no: usize,
    ) -> Result<(), PlfError> {
        let (ctx, opts) = (self.ctx, self.opts);
        let cand = &ranked.cands[bi];
        let hb = holdout_rms(ctx, &self.cur.residual);
        let before_ms = weighted_holdout_ms(ctx, &self.cur.residual);
        let evidence = format!(
            "{}{}; fitted {} {}: held-out rms {:.4e} -> {:.4e} (p = {:.1e})",
            match self.locked_retry.take() {
                Some(_) =>
                    "named although its line is locked to the excitation (a map of the input could leave such a line): none of the maps of the input tried explains it; an excitation at a frequency that is not a multiple of the line's would tell them apart; ",
                None => "",
            },
            evidence(ctx, &self.cur, cand, &mut self.runs),
            cand.effect,
            cand.site.describe(),
            hb,
            holdout_rms(ctx, &win.residual),
            test.p_value
        );
        self.plots
            .push(evidence_plot(ctx, &self.cur, cand, &win, step_no + 1));
        // A slit table is held at its fit from here on: its entries each move
        // only their slit's samples, so later effects hardly shift them, and
        // refitting hundreds of them with every later candidate took minutes
        // (tuning 837, 1350).
        let free: Vec<FreeParam> = win
            .free
            .iter()
            .filter(|p| !(cand.effect == "encoder_slit_error" && p.block == win.block_name))
            .cloned()
            .collect();
        let new = evaluate_current(ctx, surgery::clone_spec(&win.spec)?, free, &mut self.runs)?;
        // A hysteretic force of the stage's own motion that the direction of
        // motion sets is friction (see `ForceSplit`), whichever block fitted it.
        let own_force = match &cand.site {
            Site::Feedback { position, .. } => {
                Some((format!("{}.y", win.block_name), position.clone()))
            }
            _ => None,
        };
        let split = match &own_force {
            Some((force, position)) => force_split(
                &signal(ctx, &new, force)?,
                &signal(ctx, &new, position)?,
                ctx.fs,
            ),
            None => None,
        };
        let (effect_name, evidence) = match split {
            Some(sp) if cand.effect == "hysteresis" && sp.is_friction() => (
                "friction",
                format!(
                    "named friction, not hysteresis: the fitted force of the stage's own motion is set by the direction of motion (corr² with sign v = {:.2}, with the position = {:.2}), a Coulomb level of {:.4e} — the Dahl/presliding form of friction; {evidence}",
                    sp.direction_r2, sp.position_r2, sp.coulomb
                ),
            ),
            _ => (cand.effect, evidence),
        };
        let ambiguous_with = alternatives(
            ctx,
            &self.cur,
            &ranked.cands,
            &ranked.results,
            &ranked.order,
            &win,
            [effect_name, cand.effect],
            (level, excess, at_floor, opts.min_excess_cut),
        );
        let new_spec = new.spec()?;
        let (type_name, params, unc) = fitted_params(&new_spec, &win)?;
        let sc = scores(ctx, &new);
        self.named
            .push((effect_name, outputs_of(ctx, &cand.site), cand.site.kind()));
        self.own_forces.push(own_force);
        self.levels.push(level);
        self.steps.push(Step {
            effect: effect_name.to_string(),
            block: BlockRef {
                name: win.block_name.clone(),
                type_name,
            },
            site: cand.site.describe(),
            params,
            final_params: BTreeMap::new(),
            derived: BTreeMap::new(),
            uncertainty: unc,
            evidence,
            holdout_rms_before: hb,
            holdout_rms_after: sc.holdout_rms,
            cut_percent: cut_percent(before_ms, weighted_holdout_ms(ctx, &win.residual)),
            p_value: test.p_value,
            per_output: sc.per_output,
            candidates: ranked.table,
            ambiguous_with,
        });
        self.cur = new;
        Ok(())
    }

    /// Backward elimination: an effect named early can be made unnecessary
    /// by those named after it (a delay that took a hysteresis's phase
    /// before the hysteresis was named). Once two or more are named, each is
    /// taken out in turn and the rest refitted without it; one that no
    /// longer passes the tests a name must pass — against that model, at
    /// the level it was named at — is dropped, the weakest (largest p)
    /// first, and the rest judged again.
    fn prune(&mut self) -> Result<(), PlfError> {
        let (ctx, opts) = (self.ctx, self.opts);
        if self.steps.len() < 2 {
            return Ok(());
        }
        while !self.steps.is_empty() {
            let mut weakest: Option<(usize, Current, stats::Test, f64)> = None;
            for i in 0..self.steps.len() {
                let Some(without) = self.without(i)? else {
                    continue;
                };
                let excess = excess_ms(ctx, &without);
                let at_floor = at_noise_floor(ctx, &without);
                let (test, cut) = held_out_gain(
                    ctx,
                    (&excess, at_floor),
                    &without.residual,
                    &self.cur.residual,
                );
                // At the floor only what can look white is looked for (see `step`).
                let needed = passes(opts, self.levels[i], &test, cut)
                    && (!at_floor || can_look_white(&self.steps[i].effect));
                if !needed && weakest.as_ref().is_none_or(|w| test.p_value > w.2.p_value) {
                    weakest = Some((i, without, test, cut));
                }
            }
            let Some((i, without, test, cut)) = weakest else {
                break;
            };
            let step = self.steps.remove(i);
            self.named.remove(i);
            self.own_forces.remove(i);
            self.levels.remove(i);
            if i < self.plots.len() {
                self.plots.remove(i);
            }
            self.dropped.push(Dropped {
                effect: step.effect,
                site: step.site,
                holdout_rms_with: holdout_rms(ctx, &self.cur.residual),
                holdout_rms_without: holdout_rms(ctx, &without.residual),
                p_value: test.p_value,
                excess_cut_percent: 100.0 * cut,
            });
            self.cur = without;
        }
        Ok(())
    }

    /// The model without step `i`'s effect, the rest (and the calibration)
    /// refitted; `None` when that refit does not run.
    fn without(&mut self, i: usize) -> Result<Option<Current>, PlfError> {
        let name = self.steps[i].block.name.clone();
        let mut spec = self.cur.spec()?;
        surgery::remove(&mut spec, &name)?;
        let free: Vec<FreeParam> = self
            .cur
            .free
            .iter()
            .filter(|p| p.block != name)
            .cloned()
            .collect();
        if !free.is_empty() {
            match refit(self.ctx, &spec, &free) {
                Ok((fitted, _, _, n)) => {
                    self.runs += n;
                    spec = fitted;
                }
                Err(_) => return Ok(None),
            }
        }
        evaluate_current(self.ctx, spec, free, &mut self.runs).map(Some)
    }

    /// Rounding read off the record: simulation cannot show it where the
    /// model is off by more than a step, but the measured values sit on its
    /// grid.
    fn rounding_from_grid(&mut self) -> Result<(), PlfError> {
        while self.steps.len() < self.opts.max_effects
            && let Some((i, step, new)) =
                quantization_from_grid(self.ctx, &self.cur, self.opts, &self.named, &mut self.runs)?
        {
            self.named.push(("quantization", vec![i], "output"));
            self.own_forces.push(None);
            self.levels.push(self.opts.alpha);
            self.steps.push(step);
            self.cur = new;
        }
        Ok(())
    }

    /// The report: final scores and tests, the augmented model (with its
    /// fitted loops allowed by the gate), the final parameters of every step
    /// and of the calibration, the residuals before and after.
    fn report(self, spec: &GraphSpec) -> Result<Report, PlfError> {
        let ctx = self.ctx;
        let Search {
            nominal_scores,
            nominal_tests,
            first_residuals,
            cur,
            mut calibration,
            mut steps,
            plots,
            stopped,
            rejected_candidates,
            own_forces,
            dropped,
            runs,
            ..
        } = self;
        let final_scores = scores(ctx, &cur);
        let holdout_cut_percent = cut_percent(
            weighted_holdout_ms(ctx, &first_residuals),
            weighted_holdout_ms(ctx, &cur.residual),
        );
        let final_tests = tests(ctx, &cur)?;
        let mut augmented = cur.spec()?;
        if let Some(cal) = calibration.as_mut().filter(|c| c.accepted) {
            for key in cal.params.keys().cloned().collect::<Vec<_>>() {
                if let Some((block, param)) = key.split_once('.')
                    && let Some(v) = tunable_params(&augmented, block).get(param)
                {
                    cal.final_params.insert(key, *v);
                }
            }
        }
        for (st, own) in steps.iter_mut().zip(&own_forces) {
            st.final_params = tunable_params(&augmented, &st.block.name);
            if let (Some((force, position)), "friction") = (own, st.effect.as_str())
                && let Some(sp) = force_split(
                    &signal(ctx, &cur, force)?,
                    &signal(ctx, &cur, position)?,
                    ctx.fs,
                )
            {
                st.derived.insert("coulomb".into(), sp.coulomb);
            }
        }
        allow_fitted_loops(&mut augmented, ctx.data, &steps)?;
        let residuals = ctx
            .channels
            .iter()
            .enumerate()
            .map(|(i, c)| {
                (
                    c.signal.clone(),
                    first_residuals[i].clone(),
                    cur.residual[i].clone(),
                )
            })
            .collect();
        Ok(Report {
            nominal: nominal_scores,
            nominal_tests,
            calibration,
            found: steps.iter().map(|s| s.effect.clone()).collect(),
            steps,
            final_scores,
            holdout_cut_percent,
            final_tests,
            stopped_because: stopped,
            excitation_notes: single_tone_notes(ctx, spec)
                .into_iter()
                .chain(early_residual_notes(ctx, &cur))
                .collect(),
            rejected_candidates,
            dropped,
            records: ctx
                .records
                .parts
                .iter()
                .map(|p| p.origin().to_string())
                .collect(),
            estimation_samples: ctx.n_est,
            holdout_samples: ctx.n - ctx.n_est,
            runs,
            augmented: Some(augmented),
            plots,
            residuals,
            rate_hz: ctx.fs,
        })
    }
}

/// A step's fits: every candidate (refused ones, `locked`, are not tried),
/// from a work queue on `threads` workers, longest first; results land in
/// their candidate's slot, so the outcome does not depend on timing. Returns the
/// fits, why each failed one failed, and the graph runs spent.
#[allow(clippy::type_complexity)]
fn fit_candidates(
    ctx: &Ctx<'_>,
    cur: &Current,
    cands: &[Cand],
    locked: &[Option<String>],
    threads: usize,
    step_no: usize,
    progress: Progress<'_>,
) -> (Vec<Option<Fitted>>, Vec<Option<String>>, usize) {
    let total = cands.len();
    let mut runs = 0;
    let mut results: Vec<Option<Fitted>> = Vec::with_capacity(total);
    // Why each failed candidate failed (shown in the candidate table).
    let mut failures: Vec<Option<String>> = Vec::with_capacity(total);
    let threads = threads.max(1);
    let queue = crate::pool::longest_first(cands, fit_cost);
    let next = std::sync::atomic::AtomicUsize::new(0);
    let slots: Vec<std::sync::Mutex<Option<Result<Fitted, String>>>> =
        (0..total).map(|_| std::sync::Mutex::new(None)).collect();
    let (tx, rx) = std::sync::mpsc::channel::<()>();
    std::thread::scope(|sc| {
        for _ in 0..threads.min(total.max(1)) {
            let tx = tx.clone();
            let (next, slots, queue) = (&next, &slots, &queue);
            sc.spawn(move || {
                loop {
                    let k = next.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
                    let Some(&i) = queue.get(k) else {
                        break;
                    };
                    let r = match &locked[i] {
                        Some(why) => Err(format!("not tried: {why}")),
                        None => std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| {
                            fit_candidate(ctx, cur, &cands[i])
                        }))
                        .unwrap_or_else(|_| Err("the fit panicked".into())),
                    };
                    if let Ok(mut slot) = slots[i].lock() {
                        *slot = Some(r);
                    }
                    let _ = tx.send(());
                }
            });
        }
        drop(tx);
        let mut done = 0;
        while rx.recv().is_ok() {
            done += 1;
            progress(
                &format!("step {}: fitting candidates", step_no + 1),
                done as f64 / total as f64,
            );
        }
    });
    for (c, slot) in cands.iter().zip(slots) {
        match slot.into_inner().ok().flatten() {
            Some(Ok(f)) => {
                runs += f.runs;
                results.push(Some(f));
            }
            Some(Err(e)) => {
                tracing::debug!(effect = c.effect, site = %c.site.describe(), "candidate failed: {e}");
                results.push(None);
                failures.push(Some(e));
                continue;
            }
            None => results.push(None),
        }
        failures.push(None);
    }
    (results, failures, runs)
}

/// The inserted block of the fit `win` in `spec`: its type, every parameter's
/// value, and the σ of the fitted ones (where finite).
#[allow(clippy::type_complexity)]
fn fitted_params(
    spec: &GraphSpec,
    win: &Fitted,
) -> Result<(String, BTreeMap<String, f64>, BTreeMap<String, f64>), PlfError> {
    let block = spec
        .blocks
        .iter()
        .find(|b| b.name == win.block_name)
        .ok_or_else(|| PlfError::Model("inserted block vanished".into()))?;
    let tun = block.block.tunable();
    let names = tun.map(|t| t.param_names()).unwrap_or_default();
    let values = tun.map(|t| t.params()).unwrap_or_default();
    let mut params = BTreeMap::new();
    let mut unc = BTreeMap::new();
    for (k, (nm, v)) in names.iter().zip(&values).enumerate() {
        params.insert(nm.clone(), *v);
        if let Some(pos) = win.free_indices.iter().position(|&i| i == k)
            && let Some(s) = win.std.get(pos)
            && s.is_finite()
        {
            unc.insert(nm.clone(), *s);
        }
    }
    Ok((block.block.typetag_name().to_string(), params, unc))
}

/// The step's candidate table, best score first: each fit's held-out rms
/// and score, or why it failed.
fn candidate_table(
    ctx: &Ctx<'_>,
    cands: &[Cand],
    results: &[Option<Fitted>],
    failures: &[Option<String>],
) -> Vec<Candidate> {
    let mut table: Vec<Candidate> = cands
        .iter()
        .zip(results)
        .zip(failures)
        .map(|((c, r), why)| {
            let (holdout_rms, score, note) = match r {
                Some(f) => (holdout_rms(ctx, &f.residual), f.score, None),
                None => (
                    f64::NAN,
                    f64::INFINITY,
                    Some(why.clone().unwrap_or_else(|| "fit failed".into())),
                ),
            };
            Candidate {
                effect: c.effect.to_string(),
                site: c.site.describe(),
                n_params: c.free.len(),
                holdout_rms,
                score,
                note,
            }
        })
        .collect();
    table.sort_by(|a, b| a.score.total_cmp(&b.score));
    table
}

/// The p-value above which the held-out data are said not to tell the named
/// effect from an alternative.
const AMBIGUOUS_P: f64 = 0.05;

/// The names other than `named` (fitted as `fitted_as`) whose best candidate would itself have been
/// accepted at this step (significant, removing `min_cut` of the excess) and
/// that the winner does not beat significantly on the held-out data
/// (p ≥ [`AMBIGUOUS_P`]); the best candidate of each other effect, at most two.
#[allow(clippy::too_many_arguments)]
fn alternatives(
    ctx: &Ctx<'_>,
    cur: &Current,
    cands: &[Cand],
    results: &[Option<Fitted>],
    order: &[usize],
    win: &Fitted,
    [named, fitted_as]: [&str; 2],
    (level, excess, at_floor, min_cut): (f64, &[(f64, f64)], bool, f64),
) -> Vec<Alternative> {
    let mut seen: Vec<&str> = vec![named, fitted_as];
    let mut out = Vec::new();
    for &i in order {
        let (c, Some(f)) = (&cands[i], &results[i]) else {
            continue;
        };
        if seen.contains(&c.effect) {
            continue;
        }
        seen.push(c.effect);
        let (own, cut) = held_out_gain(ctx, (excess, at_floor), &cur.residual, &f.residual);
        if own.p_value >= level || cut < min_cut {
            continue;
        }
        let vs = held_out_test(ctx, &f.residual, &win.residual);
        if vs.p_value >= AMBIGUOUS_P {
            out.push(Alternative {
                effect: c.effect.to_string(),
                site: c.site.describe(),
                holdout_rms: holdout_rms(ctx, &f.residual),
                p_value: vs.p_value,
                experiment: telling_experiment(named, c.effect).to_string(),
            });
            if out.len() == 2 {
                break;
            }
        }
    }
    out
}

/// The experiment that tells effect `a` from effect `b` (the physics each
/// has and the other has not).
fn telling_experiment(a: &str, b: &str) -> &'static str {
    let pair = |x: &str, y: &str| (a == x && b == y) || (a == y && b == x);
    let one = |x: &str| a == x || b == x;
    if pair("friction", "hysteresis") {
        "strokes at two speeds with a stop between reversals: friction depends on the direction of motion and lets go at rest; hysteresis follows the drive's turning points whatever the speed"
    } else if pair("drift", "creep") {
        "hold the drive after a step for several times the record's longest time constant: creep settles towards a level, drift goes on whether the drive moved or not"
    } else if pair("time_delay", "unmodeled_resonance") {
        "a sine sweep through the band: a delay's phase falls in proportion to frequency at constant gain, a resonance shows a peak in gain"
    } else if pair("quantization", "encoder_slit_error") {
        "a slow move over several revolutions: rounding error repeats every lsb, slit errors every revolution with a pattern of their own"
    } else if one("saturation") {
        "strokes of several amplitudes: saturation acts only above a level, the alternative at every amplitude"
    } else if one("repetitive_disturbance") {
        "a record with the drive held still (or at another period): an external disturbance goes on, an effect of the drive does not"
    } else if one("drift") || one("creep") {
        "a long record at rest after a step: what remains is drift or creep, without the dynamic effects"
    } else {
        "a second record with another excitation (amplitude, speed, frequency content), scored with both augmented models"
    }
}

/// The share of the held-out mean square above the noise floor that going
/// from `before_ms` to `after_ms` removes — of the whole mean square
/// `at_floor`, and when the floors claim the whole mean square of all outputs
/// together (one output above its floor, another below: there is then no
/// excess to share out, and the floor, read off sample-to-sample differences,
/// is above the noise — slit errors crossed at about a line per sample look
/// white).
fn excess_cut(
    ctx: &Ctx<'_>,
    excess: &[(f64, f64)],
    at_floor: bool,
    before_ms: f64,
    after_ms: f64,
) -> f64 {
    let floor_ms: f64 = excess
        .iter()
        .enumerate()
        .map(|(i, &(_, f))| f * f * weight(ctx, i).powi(2))
        .sum();
    let excess_before = if at_floor || before_ms <= floor_ms {
        before_ms
    } else {
        before_ms - floor_ms
    };
    if excess_before > 0.0 {
        (before_ms - after_ms) / excess_before
    } else {
        0.0
    }
}

/// The nominal calibration (see [`Calibration`]): fit the gain and the time,
/// damping, lag and per-mode scales of every continuous `state_space` block
/// of the current model, from λ = 1 and from λ = 1 ∓ 8 % (a lightly damped
/// mode a few per cent off is a local minimum away), each per-mode scale
/// started on a grid ([`scan_mode_scales`]), with the named effects' parameters
/// refitted too. Returns the report (not yet judged), the calibrated model,
/// and the weighted held-out mean squares it is judged by (the named effects
/// refitted alone, the calibrated model); `None` when the model has nothing
/// to calibrate or no fit runs.
#[allow(clippy::type_complexity)]
fn calibrate(
    ctx: &Ctx<'_>,
    cur: &Current,
    runs: &mut usize,
) -> Result<Option<(Calibration, Current, (f64, f64))>, PlfError> {
    let spec = cur.spec()?;
    let mut free = Vec::new();
    for b in &spec.blocks {
        if b.block.typetag_name() != "state_space" {
            continue;
        }
        let names = b
            .block
            .tunable()
            .map(|t| t.param_names())
            .unwrap_or_default();
        if names.iter().any(|n| n == "frequency_scale") {
            for index in 0..names.len() {
                free.push(FreeParam {
                    block: b.name.clone(),
                    index,
                    scale: Scale::Log,
                });
            }
        }
    }
    if free.is_empty() {
        return Ok(None);
    }
    // A scale the data do not determine (its σ at least its value: a
    // damping the record cannot see, an amplifier pole sent far above the
    // band) is not calibrated: left free, it wanders to absurd values and
    // absorbs an effect. It is held at the nominal, reported with the value
    // it went to, and the rest refitted; so is a mode's own scale that moves
    // the mode away ([`moves_a_mode_away`]).
    // The effects named so far are refitted with the scales, as every new
    // effect is refitted with them (see `joint_refit`): the calibration
    // competes on the same terms, and an effect fitted against the
    // uncalibrated nominal keeps nothing of the nominal's error.
    let mut best = None;
    let mut held = BTreeMap::new();
    while !free.is_empty() {
        let Some(fit) = fit_calibration(ctx, &spec, &free, &cur.free, runs)? else {
            return Ok(None);
        };
        let undetermined: Vec<usize> = (0..free.len())
            .filter(|&k| {
                let value = param_value(&fit.1, &free[k]).unwrap_or(f64::NAN);
                !fit.2.get(k).is_some_and(|s| s.abs() < value.abs())
                    || moves_a_mode_away(&param_key(&fit.1, &free[k]), value)
            })
            .collect();
        if undetermined.is_empty() {
            best = Some(fit);
            break;
        }
        for &k in &undetermined {
            if let Some(v) = param_value(&fit.1, &free[k]) {
                held.insert(param_key(&fit.1, &free[k]), v);
            }
        }
        free = free
            .into_iter()
            .enumerate()
            .filter(|(k, _)| !undetermined.contains(k))
            .map(|(_, f)| f)
            .collect();
    }
    let Some((_, fitted, std, _)) = best else {
        return Ok(None);
    };
    // Run with the model's quantizers back in (the fit passed them through).
    let calibrated =
        evaluate_current(ctx, fitted, [cur.free.clone(), free.clone()].concat(), runs)?;
    let residual = calibrated.residual.clone();
    // Judged against the named effects refitted alone: that the joint fit
    // converges further than the fit of the step that named them is no
    // evidence of a nominal error.
    let before = match cur.free.is_empty() {
        true => None,
        false => refit(ctx, &spec, &cur.free).ok().map(|(_, _, r, n)| {
            *runs += n;
            r
        }),
    }
    .filter(|r| weighted_holdout_ms(ctx, r) < weighted_holdout_ms(ctx, &cur.residual))
    .unwrap_or_else(|| cur.residual.clone());
    let before_ms = weighted_holdout_ms(ctx, &before);
    let after_ms = weighted_holdout_ms(ctx, &residual);
    let test = held_out_test(ctx, &before, &residual);
    let mut params = BTreeMap::new();
    let mut uncertainty = BTreeMap::new();
    let fitted = calibrated.spec()?;
    for (k, f) in free.iter().enumerate() {
        if let Some(v) = param_value(&fitted, f) {
            let key = param_key(&fitted, f);
            params.insert(key.clone(), v);
            if let Some(s) = std.get(k).filter(|s| s.is_finite()) {
                uncertainty.insert(key, *s);
            }
        }
    }
    let hb = holdout_rms(ctx, &before);
    let ha = holdout_rms(ctx, &residual);
    let cal = Calibration {
        accepted: false,
        params,
        final_params: BTreeMap::new(),
        uncertainty,
        holdout_rms_before: hb,
        holdout_rms_after: ha,
        cut_percent: cut_percent(before_ms, after_ms),
        p_value: test.p_value,
        excess_cut_percent: f64::NAN,
        held,
        with_effect: None,
    };
    Ok(Some((cal, calibrated, (before_ms, after_ms))))
}

/// The furthest a mode's own calibration scale (`mode_K_…_scale`, relative
/// to the model's) may go, either way: a factor 3.
const MODE_SCALE_MAX: f64 = 3.0;

/// Whether the calibration parameter `key` (`block.name`) at `value` is a
/// mode's own scale moved beyond [`MODE_SCALE_MAX`] either way. That is no
/// longer the nominal's mode calibrated but another model: a gain scale
/// towards 0 deletes the mode, a frequency scale of 0.003 with a damping scale
/// of 1 000 turns it into a slow real lag (blind 4953's creep was so taken
/// into the calibration), a frequency scale of 7 sends it out of the band the
/// record excites. Held at the nominal like a scale the data do not
/// determine (see [`calibrate`]).
fn moves_a_mode_away(key: &str, value: f64) -> bool {
    let name = key.rsplit('.').next().unwrap_or(key);
    name.starts_with("mode_") && !(1.0 / MODE_SCALE_MAX..=MODE_SCALE_MAX).contains(&value)
}

/// The value of the tunable parameter `f` in `spec`.
fn param_value(spec: &GraphSpec, f: &FreeParam) -> Option<f64> {
    spec.blocks
        .iter()
        .find(|b| b.name == f.block)
        .and_then(|b| b.block.tunable())
        .and_then(|t| t.params().get(f.index).copied())
}

/// `block.parameter` of the tunable parameter `f` in `spec`.
fn param_key(spec: &GraphSpec, f: &FreeParam) -> String {
    let name = spec
        .blocks
        .iter()
        .find(|b| b.name == f.block)
        .and_then(|b| b.block.tunable())
        .and_then(|t| t.param_names().get(f.index).cloned())
        .unwrap_or_else(|| format!("#{}", f.index));
    format!("{}.{name}", f.block)
}

/// (estimation cost, calibrated graph, σ of the parameters, residuals)
type CalibrationFit = (f64, GraphSpec, Vec<f64>, Vec<Vec<f64>>);

/// The best of the calibration fits of the nominal's scales `free` (with the
/// named effects' parameters `named`, listed after them in the fit's σ) from
/// the three starts (see [`calibrate`]); `None` when no fit runs.
fn fit_calibration(
    ctx: &Ctx<'_>,
    spec: &GraphSpec,
    free: &[FreeParam],
    named: &[FreeParam],
    runs: &mut usize,
) -> Result<Option<CalibrationFit>, PlfError> {
    let mut best: Option<CalibrationFit> = None;
    let all = [free, named].concat();
    // The model's quantizers pass through while the scales are fitted: through
    // a rounding the cost is a staircase in every scale, flat between steps,
    // which a gradient fit cannot descend (it stopped where it started, with
    // σ ≈ 1e-7 that it had not earned: tuning 213). They are put back in the
    // calibrated graph, and the calibration is judged with them in
    // ([`calibrate`] runs that graph).
    let smooth = smooth_quantizers(spec)?;
    for start in [1.0, 0.92, 1.08] {
        let mut start_spec = surgery::clone_spec(&smooth)?;
        for b in start_spec.blocks.iter_mut() {
            // The time scale (parameter 1) is started off 1 only while free.
            if free.iter().any(|f| f.block == b.name && f.index == 1)
                && let Some(t) = b.block.tunable_mut()
            {
                let mut p = t.params();
                p[1] *= start;
                t.set_params(&p)
                    .map_err(|e| PlfError::Model(format!("block `{}`: {e}", b.name)))?;
            }
        }
        let mut ev = Evaluator::over(surgery::clone_spec(&start_spec)?, ctx.records, &all, 0)?;
        ev.set_weights(&ctx.weights);
        let mut z0 = vec![0.0; all.len()];
        scan_mode_scales(&mut ev, spec, free, &mut z0, ctx.n_est);
        let Some(fit) = levenberg_marquardt(&mut ev, &z0, ctx.n_est, 25) else {
            continue;
        };
        *runs += fit.runs + 1;
        let mut fitted = surgery::clone_spec(spec)?;
        ev.export(&fit.z, &mut fitted)?;
        if !ev.run(&fit.z, ctx.n) {
            continue;
        }
        if best.as_ref().is_none_or(|b| fit.cost < b.0) {
            let residual = (0..ev.outputs())
                .map(|i| ev.residual(i, 0..ctx.n))
                .collect();
            best = Some((fit.cost, fitted, fit.std, residual));
        }
    }
    Ok(best)
}

/// `spec` with every `quantizer` made fine (its lsb 10⁻⁶ of itself): the
/// rounding passes the signal through, to 10⁻⁶ lsb.
fn smooth_quantizers(spec: &GraphSpec) -> Result<GraphSpec, PlfError> {
    let mut smooth = surgery::clone_spec(spec)?;
    for b in smooth.blocks.iter_mut() {
        if b.block.typetag_name() != "quantizer" {
            continue;
        }
        if let Some(t) = b.block.tunable_mut() {
            let mut p = t.params();
            p[0] *= 1e-6;
            t.set_params(&p)
                .map_err(|e| PlfError::Model(format!("block `{}`: {e}", b.name)))?;
        }
    }
    Ok(smooth)
}

/// Start each per-mode frequency scale (`mode_K_frequency_scale`) of the
/// calibration at the best of a grid over ± 15 % in 1.5 % steps, the others
/// held: a lightly damped mode (ζ ≈ 0.01) that is 10 % off sits in a cost
/// basin about ζ wide, which descent from 1 does not reach.
fn scan_mode_scales(
    ev: &mut Evaluator,
    spec: &GraphSpec,
    free: &[FreeParam],
    z0: &mut [f64],
    n_est: usize,
) {
    let mut buf = Vec::new();
    for j in 0..free.len() {
        let is_mode_scale = spec
            .blocks
            .iter()
            .find(|b| b.name == free[j].block)
            .and_then(|b| b.block.tunable())
            .is_some_and(|t| {
                t.param_names()
                    .get(free[j].index)
                    .is_some_and(|n| n.starts_with("mode_") && n.ends_with("frequency_scale"))
            });
        if !is_mode_scale {
            continue;
        }
        let mut best = (f64::INFINITY, z0[j]);
        for k in -10..=10 {
            let mut z = z0.to_vec();
            z[j] = (1.0 + 0.015 * f64::from(k)).ln();
            if ev.weighted_residuals(&z, n_est, &mut buf) {
                let cost: f64 = buf.iter().map(|v| v * v).sum();
                if cost < best.0 {
                    best = (cost, z[j]);
                }
            }
        }
        z0[j] = best.1;
    }
}

/// Why one of the effect blocks `names` of `spec` is not physical as a
/// diagnosis (see each effect's `implausible`), or `None`. The band the data
/// resolve runs from two periods in the record to 0.45 × the sample rate.
fn implausible<'n>(
    ctx: &Ctx<'_>,
    spec: &GraphSpec,
    names: impl Iterator<Item = &'n str>,
) -> Option<String> {
    let band = (2.0 * ctx.fs / ctx.n as f64, 0.45 * ctx.fs);
    let mut seen: Vec<&str> = Vec::new();
    for name in names {
        if seen.contains(&name) {
            continue;
        }
        seen.push(name);
        let b = spec.blocks.iter().find(|b| b.name == name)?;
        let p = b.block.tunable().map(|t| t.params()).unwrap_or_default();
        let why = match (b.block.typetag_name(), p.as_slice()) {
            ("unmodeled_resonance", &[fp, zp, fz, zz]) => UnmodeledResonance::new(fp, zp, fz, zz)
                .implausible(band)
                .or_else(|| moved_mode(spec, ctx.fs, fp, (fz, zz))),
            ("creep", terms) if terms.len() % 2 == 0 => Creep::new(
                terms
                    .chunks(2)
                    .map(|c| CreepTerm {
                        gain: c[0],
                        tau_s: c[1],
                    })
                    .collect(),
            )
            .implausible(ctx.n as f64 / ctx.fs, 1.0 / ctx.fs),
            ("time_delay", &[delay_s]) => {
                TimeDelay::new(delay_s, delay_s).implausible(1.0 / ctx.fs)
            }
            ("prandtl_ishlinskii", _) => {
                PrandtlIshlinskii::from_block_json(&surgery::block_to_json(b.block.as_ref()))
                    .and_then(|pi| pi.implausible())
            }
            _ => None,
        };
        if let Some(why) = why {
            return Some(format!("{name}: {why}"));
        }
    }
    None
}

/// The lightly damped modes — (natural frequency in Hz, damping ratio ζ <
/// sin(π/8), the pairs with a half-power bandwidth) — of the model's own
/// continuous linear blocks (`state_space` and `transfer_function` not
/// `discrete`: the plant, not the controller; effect blocks have other
/// types), each built at `fs` with its calibration and mapped back from its
/// discrete poles (s = f_s·ln z).
fn plant_modes(spec: &GraphSpec, fs: f64) -> Vec<(f64, f64)> {
    let mut modes = Vec::new();
    for b in &spec.blocks {
        let json = surgery::block_to_json(b.block.as_ref());
        let continuous = matches!(
            json.get("type").and_then(|t| t.as_str()),
            Some("state_space" | "transfer_function")
        ) && !json
            .get("discrete")
            .and_then(|d| d.as_bool())
            .unwrap_or(false);
        let Ok(mut block) = surgery::block_from_json(json) else {
            continue;
        };
        let ctx = nanomotion_core::BuildContext::new(&b.name, 1.0 / fs, 0);
        if !continuous || block.build(&ctx).is_err() {
            continue;
        }
        let Some(ss) = block.lti() else { continue };
        for z in nanomotion_core::lti::linalg::eigvals(&ss.a) {
            let s = z.ln() * fs;
            let (w, zeta) = (s.norm(), -s.re / s.norm());
            if s.im > 0.0 && w.is_finite() && zeta > 0.0 && zeta < MAX_RESONANT_DAMPING {
                modes.push((w / std::f64::consts::TAU, zeta));
            }
        }
    }
    modes
}

/// Why a fitted resonance (pole pair at f_p, zero pair (f_z, ζ_z)) is a
/// mode of the nominal moved rather than one it lacks, or `None`: its zero
/// pair sits on a lightly damped mode of the model ([`plant_modes`]) — within
/// that mode's half-power half-width ζ·f, or the zero's own, the wider — so
/// it cancels that mode and its pole pair puts one in its place. A stage
/// whose spring is 10 % stiff was fitted so (zero 14.68 Hz on the nominal's
/// 15 Hz, ζ = 0.05; pole 15.66 Hz), as was a nominal 8 % off (blind 2977);
/// the calibration's frequency and damping scales are that explanation. A
/// missing mode — a mass on a spring attached to the stage — has its
/// anti-resonance at its own frequency, not on a mode the nominal has.
fn moved_mode(spec: &GraphSpec, fs: f64, fp: f64, (fz, zz): (f64, f64)) -> Option<String> {
    plant_modes(spec, fs)
        .into_iter()
        .find(|&(f, zeta)| (fz - f).abs() <= (zeta * f).max(zz * fz))
        .map(|(f, zeta)| {
            format!(
                "its zero pair ({fz:.4e} Hz, ζ = {zz:.3}) cancels the nominal's mode at {f:.4e} Hz (ζ = {zeta:.3}) and its pole pair puts one at {fp:.4e} Hz: the nominal's mode is off (what the calibration's frequency and damping scales fit), not a missing resonance"
            )
        })
}

/// The tunable parameters of block `name` of `spec`, by name.
fn tunable_params(spec: &GraphSpec, name: &str) -> BTreeMap<String, f64> {
    spec.blocks
        .iter()
        .find(|b| b.name == name)
        .and_then(|b| b.block.tunable())
        .map(|t| t.param_names().into_iter().zip(t.params()).collect())
        .unwrap_or_default()
}

/// An effect inside a loop (friction, a sensor's delay, hysteresis on a
/// controller's drive) has no linear model, so the stability gate calls the
/// augmented loop unproven and refuses to run it — yet it is a fitted model of
/// the measured stage, not a design to prove. When the gate's only objection is
/// that, the augmented model says so in `require: { allow_unproven: … }`, so the
/// printed `nanomotion run` re-run works; an unstable loop is never allowed.
fn allow_fitted_loops(
    spec: &mut GraphSpec,
    data: &Arc<Dataset>,
    steps: &[Step],
) -> Result<(), PlfError> {
    if steps.is_empty() {
        return Ok(());
    }
    let mut require = spec.require.clone().unwrap_or_default();
    let (sched, _) = surgery::clone_spec(spec)?
        .build_with_data(data.clone())
        .map_err(|e| PlfError::Model(format!("the augmented model does not build: {e}")))?;
    let report = nanomotion_core::gate::analyse(&sched, &require);
    let unproven = report.loops.iter().any(|l| !l.unproven.is_empty());
    if report.passes() || !unproven || require.allow_unproven.is_some() {
        return Ok(());
    }
    let blocks: Vec<&str> = steps.iter().map(|s| s.block.name.as_str()).collect();
    require.allow_unproven = Some(format!(
        "a fitted model of the measured stage (nanomotion diagnose inserted {}), not a design: the gate cannot prove a loop through its effect blocks (no linear model, or a slope range too wide for the circle criterion)",
        blocks.join(", ")
    ));
    spec.require = Some(require);
    Ok(())
}

fn weight(ctx: &Ctx<'_>, i: usize) -> f64 {
    ctx.weights[i]
}

/// The scale of each compared output's residual: the nominal residual's noise
/// floor ([`floor_sigma`]) on the held-out samples (the ones every decision
/// is made on), but at least 1/1000 of the
/// residual's rms (a floor of zero — a quantised signal that mostly repeats its
/// value — must not give one output all the weight), and the measured column's
/// deviation when the residual is zero.
fn output_scales(ctx: &Ctx<'_>, residual: &[Vec<f64>]) -> Vec<f64> {
    residual
        .iter()
        .zip(&ctx.channels)
        .enumerate()
        .map(|(i, (r, ch))| {
            let held = ctx.part(r, Part::HeldOut);
            let s =
                floor_sigma(ctx, i, r, Part::HeldOut).max(1e-3 * stats::mean_square(held).sqrt());
            if s > 0.0 && s.is_finite() {
                s
            } else {
                std_of(ctx.data.column(&ch.column).unwrap_or(&[])).max(f64::MIN_POSITIVE)
            }
        })
        .collect()
}

/// The measured columns must carry information: a constant column (a stuck or
/// disconnected sensor) has no fit to improve, and anything fitted to it would be
/// a confident answer from bad data (audit D1).
fn check_columns(data: &Dataset, channels: &[Channel]) -> Result<(), PlfError> {
    for ch in channels {
        let col = data.column(&ch.column).unwrap_or(&[]);
        let (lo, hi) = col
            .iter()
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), &v| {
                (a.min(v), b.max(v))
            });
        // Constant up to the rounding of its own magnitude.
        if hi - lo <= 4.0 * f64::EPSILON * lo.abs().max(hi.abs()) {
            return Err(PlfError::Data(format!(
                "measured column `{}` of {} is constant ({lo:e}) over all {} samples: a stuck or disconnected sensor leaves nothing to diagnose (its fit % is undefined); check the sensor and that `compare:` names the right column",
                ch.column,
                data.origin(),
                col.len()
            )));
        }
    }
    Ok(())
}

/// Scores must be finite: finite but huge data (a corrupt sample of 1e308) make
/// the mean squares overflow, and a diagnosis on them would be no answer (audit D18).
fn check_finite(data: &Dataset, s: &Scores) -> Result<(), PlfError> {
    for o in &s.per_output {
        if !(o.rms.is_finite() && o.holdout_rms.is_finite()) {
            let col = data.column(&o.column).unwrap_or(&[]);
            let big = col.iter().fold(0.0f64, |a, v| a.max(v.abs()));
            return Err(PlfError::Data(format!(
                "the residual of {} against column `{}` of {} overflows (its mean square is not finite; the column reaches {big:e}): check the record for a corrupt sample, or rescale its units",
                o.signal,
                o.column,
                data.origin()
            )));
        }
    }
    Ok(())
}

/// The compared outputs a site concerns: its own output, or every output whose
/// plant the site's input drives (an effect is named once per output).
fn outputs_of(ctx: &Ctx<'_>, site: &Site) -> Vec<usize> {
    match site {
        Site::Output { compare, .. } | Site::Sensor { compare, .. } => vec![*compare],
        Site::Input { to, .. } | Site::Feedback { to, .. } => ctx
            .channels
            .iter()
            .enumerate()
            .filter(|(_, ch)| ch.plant_inputs.iter().any(|(_, t)| t == to))
            .map(|(i, _)| i)
            .collect(),
    }
}

impl Current {
    fn spec(&self) -> Result<GraphSpec, PlfError> {
        serde_json::from_value(self.graph.clone())
            .map_err(|e| PlfError::Model(format!("cannot copy the graph: {e}")))
    }
}

/// Run the whole record on `spec` and record residuals and model outputs.
fn evaluate_current(
    ctx: &Ctx<'_>,
    spec: GraphSpec,
    free: Vec<FreeParam>,
    runs: &mut usize,
) -> Result<Current, PlfError> {
    let graph = serde_json::to_value(&spec)
        .map_err(|e| PlfError::Model(format!("cannot copy the graph: {e}")))?;
    let mut run_spec = surgery::clone_spec(&spec)?;
    // Log every signal a candidate may need.
    for c in &ctx.channels {
        for sig in std::iter::once(&c.position).chain(c.plant_inputs.iter().map(|(f, _)| f)) {
            if !run_spec.log.contains(sig) {
                run_spec.log.push(sig.clone());
            }
        }
    }
    let mut ev = Evaluator::over(run_spec, ctx.records, &[], 0)?;
    *runs += 1;
    if !ev.run(&[], ctx.n) {
        return Err(PlfError::Model(
            "the model does not run on this data (a non-finite output): check the graph with `nanomotion run --data`".into(),
        ));
    }
    let residual = (0..ev.outputs())
        .map(|i| ev.residual(i, 0..ctx.n))
        .collect();
    let model = (0..ev.outputs())
        .map(|i| ev.model_series(i, 0..ctx.n))
        .collect();
    Ok(Current {
        graph,
        free,
        residual,
        model,
    })
}

/// A signal of the current model at the data rate (re-run with it logged).
fn signal(ctx: &Ctx<'_>, cur: &Current, name: &str) -> Result<Vec<f64>, PlfError> {
    let mut s = cur.spec()?;
    if !s.log.iter().any(|l| l == name) {
        s.log.push(name.to_string());
    }
    let mut ev = Evaluator::over(s, ctx.records, &[], 0)?;
    if !ev.run(&[], ctx.n) {
        return Err(PlfError::Model(
            "the model does not run on this data".into(),
        ));
    }
    ev.log_series(name)
        .map(|mut v| {
            v.resize(ctx.n, *v.last().unwrap_or(&0.0));
            v
        })
        .ok_or_else(|| PlfError::Model(format!("signal {name} is not a scalar signal")))
}

fn scores(ctx: &Ctx<'_>, cur: &Current) -> Scores {
    let per_output: Vec<OutputScore> = ctx
        .channels
        .iter()
        .enumerate()
        .map(|(i, c)| {
            let r = &cur.residual[i];
            let y = ctx.data.column(&c.column).unwrap_or(&[]);
            let ym = stats::mean(y);
            let dev: f64 = y.iter().map(|v| (v - ym) * (v - ym)).sum::<f64>().sqrt();
            let err: f64 = r.iter().map(|v| v * v).sum::<f64>().sqrt();
            OutputScore {
                signal: c.signal.clone(),
                column: c.column.clone(),
                rms: stats::mean_square(r).sqrt(),
                holdout_rms: stats::mean_square(&r[ctx.n_est..]).sqrt(),
                fit_percent: if dev > 0.0 {
                    100.0 * (1.0 - err / dev)
                } else {
                    f64::NAN
                },
            }
        })
        .collect();
    let k = per_output.len() as f64;
    Scores {
        rms: (per_output.iter().map(|o| o.rms * o.rms).sum::<f64>() / k).sqrt(),
        holdout_rms: (per_output
            .iter()
            .map(|o| o.holdout_rms * o.holdout_rms)
            .sum::<f64>()
            / k)
            .sqrt(),
        fit_percent: per_output.iter().map(|o| o.fit_percent).sum::<f64>() / k,
        per_output,
    }
}

fn holdout_rms(ctx: &Ctx<'_>, residual: &[Vec<f64>]) -> f64 {
    let k = residual.len() as f64;
    (residual
        .iter()
        .map(|r| stats::mean_square(&r[ctx.n_est..]))
        .sum::<f64>()
        / k)
        .sqrt()
}

fn weighted_holdout_ms(ctx: &Ctx<'_>, residual: &[Vec<f64>]) -> f64 {
    residual
        .iter()
        .enumerate()
        .map(|(i, r)| stats::mean_square(&r[ctx.n_est..]) * weight(ctx, i).powi(2))
        .sum()
}

/// How much `after` improves on `before` on the held-out data: the
/// improvement test (see [`stats::improvement_test`]) and the share of the
/// excess over the noise floor it cuts (see [`excess_cut`]). An effect is named
/// only when the test's p is below the step's level and the cut reaches
/// `min_excess_cut`.
fn held_out_gain(
    ctx: &Ctx<'_>,
    (excess, at_floor): (&[(f64, f64)], bool),
    before: &[Vec<f64>],
    after: &[Vec<f64>],
) -> (stats::Test, f64) {
    let test = held_out_test(ctx, before, after);
    let cut = excess_cut(
        ctx,
        excess,
        at_floor,
        weighted_holdout_ms(ctx, before),
        weighted_holdout_ms(ctx, after),
    );
    (test, cut)
}

/// Whether the model with residuals `better` predicts the held-out data
/// better than the one with `worse` ([`stats::improvement_test`] over the
/// weighted held-out residuals of all outputs, 200 lags).
fn held_out_test(ctx: &Ctx<'_>, worse: &[Vec<f64>], better: &[Vec<f64>]) -> stats::Test {
    let (worse, better) = holdout_weighted_vectors(ctx, worse, better);
    stats::improvement_test(&worse, &better, 200).0
}

/// Held-out residuals of all outputs, weighted, as one vector per model (outputs
/// interleaved sample by sample so that batches span every output).
fn holdout_weighted_vectors(ctx: &Ctx<'_>, a: &[Vec<f64>], b: &[Vec<f64>]) -> (Vec<f64>, Vec<f64>) {
    let len = (ctx.n - ctx.n_est) * a.len();
    let mut va = Vec::with_capacity(len);
    let mut vb = Vec::with_capacity(len);
    for k in ctx.n_est..ctx.n {
        for (i, (ai, bi)) in a.iter().zip(b).enumerate() {
            let w = weight(ctx, i);
            va.push(ai[k] * w);
            vb.push(bi[k] * w);
        }
    }
    (va, vb)
}

/// Whether an effect can itself look like white noise: memoryless functions
/// of the measured position (a rounding, slit errors), when the stage
/// crosses about an lsb per sample — the only effects looked for at the
/// noise floor.
fn can_look_white(effect: &str) -> bool {
    matches!(effect, "quantization" | "encoder_slit_error")
}

/// Step 5's tests of a name: significant at `level` and at least
/// `min_excess_cut` of the excess over the noise floor removed (`cut`).
fn passes(opts: &Options, level: f64, test: &stats::Test, cut: f64) -> bool {
    test.p_value < level && cut >= opts.min_excess_cut
}

/// Whether every output's held-out mean square is within 20 % of its noise
/// floor's: nothing above the noise to explain. The floor here is
/// [`floor_sigma`]'s once the residual's significant spectral lines are out
/// ([`stats::noise_floor_without_lines`] at [`Ctx::line_level`]): a line is
/// structure however fast it is, and one near the Nyquist frequency (a
/// disturbance periodic in position on a fast scan) makes large
/// sample-to-sample differences that the plain estimate counts as white —
/// the search stopped "at the floor" with nothing named. Without a
/// significant line it is `floor_sigma` exactly. (Only this decision reads
/// it: the floor an effect's cut is measured against, and the outputs'
/// weights, stay `floor_sigma`'s.)
fn at_noise_floor(ctx: &Ctx<'_>, cur: &Current) -> bool {
    cur.residual.iter().enumerate().all(|(i, r)| {
        let held = ctx.part(r, Part::HeldOut);
        let floor = stats::noise_floor_without_lines(held, ctx.line_level).max(grid_floor(
            ctx,
            i,
            Part::HeldOut,
        ));
        stats::mean_square(held) <= 1.2 * floor * floor
    })
}

/// (held-out mean square, its noise floor σ) per output.
fn excess_ms(ctx: &Ctx<'_>, cur: &Current) -> Vec<(f64, f64)> {
    cur.residual
        .iter()
        .enumerate()
        .map(|(i, r)| {
            (
                stats::mean_square(ctx.part(r, Part::HeldOut)),
                floor_sigma(ctx, i, r, Part::HeldOut),
            )
        })
        .collect()
}

fn tests(ctx: &Ctx<'_>, cur: &Current) -> Result<Vec<ResidualTests>, PlfError> {
    let mut out = Vec::new();
    for (i, c) in ctx.channels.iter().enumerate() {
        let r = ctx.part(&cur.residual[i], Part::Estimation);
        let (input, u) = match c.plant_inputs.first() {
            Some((from, _)) => (from.clone(), signal(ctx, cur, from)?),
            None => (c.signal.clone(), cur.model[i].clone()),
        };
        let (ic, lag) = stats::input_correlation(r, &u[..ctx.n_est], 50);
        let (line, f) = stats::fisher_g(r);
        out.push(ResidualTests {
            signal: c.signal.clone(),
            whiteness: stats::ljung_box(r, 20),
            input_correlation: ic,
            input,
            input_lag: lag,
            periodic_line: line,
            line_hz: f * ctx.fs,
            noise_floor: floor_sigma(ctx, i, &cur.residual[i], Part::Estimation),
            rms: stats::mean_square(r).sqrt(),
        });
    }
    Ok(out)
}

/// A candidate: an effect at a site with start values.
#[derive(Clone)]
struct Cand {
    effect: &'static str,
    site: Site,
    /// Output index for output sites.
    output: Option<usize>,
    /// Full block JSON per start.
    starts: Vec<serde_json::Value>,
    /// Free parameters: (tunable index, scale).
    free: Vec<(usize, Scale)>,
    /// Signals wired to port `s`.
    s: Vec<String>,
    /// Rate of the inserted block.
    rate_hz: Option<f64>,
}

struct Fitted {
    effect: &'static str,
    spec: GraphSpec,
    block_name: String,
    free: Vec<FreeParam>,
    free_indices: Vec<usize>,
    std: Vec<f64>,
    residual: Vec<Vec<f64>>,
    score: f64,
    runs: usize,
}

fn range(x: &[f64]) -> f64 {
    let (lo, hi) = x
        .iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), &v| {
            (a.min(v), b.max(v))
        });
    (hi - lo).max(f64::MIN_POSITIVE)
}

fn std_of(x: &[f64]) -> f64 {
    let m = stats::mean(x);
    stats::mean_square(&x.iter().map(|v| v - m).collect::<Vec<_>>()).sqrt()
}

/// The period (s) of a candidate disturbance periodic in *time*, if it is one.
fn time_period(c: &Cand) -> Option<f64> {
    let start = c.starts.first()?;
    (c.effect == "repetitive_disturbance" && start.get("variable")?.as_str()? == "time")
        .then(|| start.get("period")?.as_f64())
        .flatten()
}

/// A residual line is locked to a measured input when the input repeats
/// after one of the first `PHASE_LOCK_HARMONICS` multiples of the line's
/// period with at least this correlation. The line's period is refined off
/// the periodogram's grid ([`stats::refine_line`]), so a truly locked line
/// correlates to within round-off of the refinement; a looser bound (0.95,
/// ±18° of phase) called a disturbance locked whenever one of eight
/// multiples of its period happened to come near a multiple of a sine
/// excitation's (about one record in two): 0.998 is ±3.6°.
const PHASE_LOCK_CORRELATION: f64 = 0.998;
/// The harmonics m = 1…this of an excitation's period, or of one of its
/// lines, that a residual line may sit at to be locked to it
/// ([`phase_locked`]).
const PHASE_LOCK_HARMONICS: usize = 6;

/// Why a residual periodic in time with period `period_s` must not be named an
/// external disturbance: when an excitation of the model (a `data_column` the
/// graph reads: the drive, or a closed loop's reference) repeats every m
/// periods (m = 1…[`PHASE_LOCK_HARMONICS`]: its own period, or the residual is
/// one of its harmonics), or — repeating or not, a multisine — carries a line
/// at the residual's frequency or at its m-th subharmonic, any map of the
/// input (a hysteresis, a saturation, a gain the nominal has wrong near a
/// resonance) leaves a residual line locked in phase to it there, and a
/// disturbance independent of the input cannot be told from that on this
/// record. The excitation's line must stand out of its own spectrum's local
/// level at the step's level ([`stats::line_near`], Bonferroni over the
/// harmonics, columns and bins searched) and a harmonic of it must not differ
/// from the residual's line significantly (at that level) given how well
/// the two frequencies are known ([`stats::line_frequency_sd`]), and the
/// residual's line must be weaker than the model's own response at the
/// excitation's line (a map changes that response by less than all of it);
/// a disturbance that close to an excitation line is not resolved by this
/// record either. The input-driven effects stay candidates. `None` when no
/// excitation is locked.
fn phase_locked(ctx: &Ctx<'_>, cur: &Current, spec: &GraphSpec, period_s: f64) -> Option<String> {
    let n = ctx.n;
    let lag0 = period_s * ctx.fs;
    if !(lag0.is_finite() && lag0 >= 2.0) {
        return None;
    }
    let excitations = excitations(ctx, spec);
    // How well the residual's line frequency is known: from its clearest
    // output's estimation part (and which output that is).
    let clearest = cur
        .residual
        .iter()
        .enumerate()
        .filter_map(|(i, r)| {
            let est = ctx.part(r, Part::Estimation);
            stats::line_near(est, 1.0 / lag0).map(|(_, ratio)| (i, ratio))
        })
        .max_by(|a, b| a.1.total_cmp(&b.1));
    // That output, its line's frequency scatter and its power there.
    let residual_line = clearest.map(|(i, ratio)| {
        let est = ctx.part(&cur.residual[i], Part::Estimation);
        (
            i,
            stats::line_frequency_sd(ratio, ctx.n_est),
            stats::power_at(est, 1.0 / lag0),
        )
    });
    // The excitation lines tried: every harmonic of every column.
    let tests = (PHASE_LOCK_HARMONICS * excitations.len()) as f64;
    for (col, x) in excitations {
        let m0 = stats::mean(x);
        for m in 1..=PHASE_LOCK_HARMONICS {
            let lag = m as f64 * lag0;
            if lag > 0.5 * n as f64 {
                break;
            }
            // Correlation of x(k) with x(k + lag), the latter interpolated
            // linearly at the fractional lag.
            let (li, frac) = (lag.floor() as usize, lag.fract());
            let (mut sxy, mut sxx, mut syy) = (0.0, 0.0, 0.0);
            for k in 0..n - li - 1 {
                let a = x[k] - m0;
                let b = (1.0 - frac) * x[k + li] + frac * x[k + li + 1] - m0;
                sxy += a * b;
                sxx += a * a;
                syy += b * b;
            }
            let c = sxy / (sxx * syy).sqrt().max(f64::MIN_POSITIVE);
            if c > PHASE_LOCK_CORRELATION {
                return Some(format!(
                    "the residual's line (period {period_s:.4e} s) is locked to the excitation: column `{col}` repeats every {m} × that period (correlation {c:.3}), so the residual is what a map of the input leaves, not a disturbance independent of it; an excitation that does not repeat at this period would tell them apart"
                ));
            }
        }
        // One of the excitation's lines, the whole not repeating (a
        // multisine): a map of the input leaves lines at its harmonics, at
        // m·f_d exactly — to within what the two lines' frequencies can be
        // told from their records (`stats::line_frequency_sd`).
        let f = 1.0 / lag0;
        let Some((out, residual_sd, residual_power)) = residual_line else {
            continue;
        };
        for m in 1..=PHASE_LOCK_HARMONICS {
            let Some((fd, ratio)) = stats::line_near(x, f / m as f64) else {
                break;
            };
            let sd = (m as f64 * stats::line_frequency_sd(ratio, n)).hypot(residual_sd);
            // A map of the input changes what the model makes of the line by
            // less than all of it: a residual line stronger than the model's
            // own response at f_d is no map's (a weak line of a multisine and
            // a strong disturbance near one of its harmonics).
            let within_response =
                residual_power <= stats::power_at(ctx.part(&cur.model[out], Part::Estimation), fd);
            if ratio > (stats::LINE_NEAR_SEARCHED * tests / ctx.line_level).ln()
                && within_response
                && 2.0 * stats::normal_sf((m as f64 * fd - f).abs() / sd) >= ctx.line_level
            {
                let which = if m == 1 {
                    "at".to_string()
                } else {
                    format!("at the harmonic {m} of")
                };
                return Some(format!(
                    "the residual's line at {:.4} Hz sits {which} a line of the excitation: column `{col}` carries a sine at {:.4} Hz ({ratio:.0}× its spectrum's local level), so the residual is what a map of the input leaves there, not a disturbance independent of it; an excitation without a line at {:.4} Hz would tell them apart",
                    f * ctx.fs,
                    fd * ctx.fs,
                    f / m as f64 * ctx.fs
                ));
            }
        }
    }
    None
}

/// The measured columns the graph plays (its `data_column` blocks: the drive
/// in open loop, the reference in a closed one), with their samples.
fn excitations<'d>(ctx: &Ctx<'d>, spec: &GraphSpec) -> Vec<(String, &'d [f64])> {
    spec.blocks
        .iter()
        .filter(|b| b.block.typetag_name() == "data_column")
        .filter_map(|b| {
            let json = surgery::block_to_json(b.block.as_ref());
            let col = json.get("column")?.as_str()?.to_string();
            let x = ctx.data.column(&col)?;
            Some((col, x))
        })
        .collect()
}

/// The share of an excitation's power at one frequency above which the
/// record is said to show the system at that frequency only
/// ([`single_tone_notes`]).
const SINGLE_TONE_SHARE: f64 = 0.95;

/// What the excitation cannot show: for each excitation column whose power
/// sits at one frequency ([`stats::tone_share`] ≥ [`SINGLE_TONE_SHARE`]), a
/// note that at one frequency a linear effect is a gain and a phase — the
/// nominal calibration's — so in steady state creep, a delay or a resonance
/// cannot be told from the nominal's error there (the start-up transient
/// still can: tuning 717 names its creep under a sine), whatever is named.
/// How many times its held-out rms an output's final residual must be over
/// the estimation part (and how many noise floors there) for
/// [`early_residual_notes`]. Over a few hundred samples or more, the rms of
/// the same noise in two parts differs by per cents, of coloured noise by
/// tens of per cent: a factor 3 (9 in mean square) is a difference in the
/// record, not in the noise.
const EARLY_RESIDUAL_RATIO: f64 = 3.0;

/// Outputs whose final residual is mostly before the held-out part: there the
/// model still misses something (a limit reached only on the first strokes,
/// a start-up transient) that the held-out part never shows, so no name can
/// be confirmed for it — the user is told where it is and what would show
/// it, rather than nothing (blind 3056, 3186: a drive saturating on the
/// first steps only, residual 15–65 noise floors before the held-out part
/// and below one floor in it).
fn early_residual_notes(ctx: &Ctx<'_>, cur: &Current) -> Vec<String> {
    cur.residual
        .iter()
        .enumerate()
        .filter_map(|(i, r)| {
            let (est, held) = (ctx.part(r, Part::Estimation), ctx.part(r, Part::HeldOut));
            let (e, h) = (
                stats::mean_square(est).sqrt(),
                stats::mean_square(held).sqrt(),
            );
            let floor = floor_sigma(ctx, i, r, Part::Estimation);
            (e > EARLY_RESIDUAL_RATIO * h && e > EARLY_RESIDUAL_RATIO * floor).then(|| {
                format!(
                    "the residual of `{}` is {:.1}× as large before the held-out part as in it ({:.3e} against {:.3e}; noise floor {:.3e}): the model still misses something that acts early (a limit reached only on the first strokes, a start-up transient) and that the held-out part never shows, so no name can be confirmed for it; a validation record with such events (diagnose MODEL EST.csv VAL.csv), or a holdout that includes them, would",
                    ctx.channels[i].signal,
                    e / h.max(f64::MIN_POSITIVE),
                    e,
                    h,
                    floor
                )
            })
        })
        .collect()
}

fn single_tone_notes(ctx: &Ctx<'_>, spec: &GraphSpec) -> Vec<String> {
    excitations(ctx, spec)
        .into_iter()
        .filter_map(|(col, x)| {
            let (share, f) = stats::tone_share(x);
            (share >= SINGLE_TONE_SHARE).then(|| {
                format!(
                    "the excitation `{col}` is a single tone at {:.4} Hz ({:.0} % of its power within ±{} bins): at one frequency a linear effect (creep, a delay, an unmodelled resonance) is a gain and a phase, which the nominal calibration takes as well — in steady state this record cannot tell them apart (only its start-up transient can); a multisine or a sweep through the band would",
                    f * ctx.fs,
                    100.0 * share,
                    stats::TONE_BINS
                )
            })
        })
        .collect()
}

/// The period (in samples) of the strongest line of `r`, if at least three periods
/// fit in `r` (a slower "period" is a trend, not a repetition).
fn line_period(r: &[f64]) -> Option<f64> {
    let (_, f) = stats::fisher_g(r);
    let f = stats::refine_line(r, f);
    (f > 0.0 && 1.0 / f <= r.len() as f64 / 3.0).then(|| 1.0 / f)
}

/// How a force fed back from the stage's own motion into its force balance
/// splits, over the samples where the stage moves (|v| above a tenth of its
/// rms): the part set by the direction of motion — a friction force (Coulomb,
/// and Dahl/presliding friction, whose loop is a hysteresis of the position
/// that saturates within a short presliding distance) — and the part that
/// follows the position — a hysteretic restoring force (Bouc–Wen mounts,
/// piezo stacks' elastic hysteresis). An engineer names the first friction
/// and the second hysteresis, whichever block fits it.
#[derive(Debug, Clone, Copy, PartialEq)]
struct ForceSplit {
    /// corr(force, sign v)² over the moving samples.
    direction_r2: f64,
    /// corr(force, position)² over the same samples.
    position_r2: f64,
    /// |Fc|: the sign(v) coefficient of the least-squares fit
    /// force ≈ f₀ + k·position + Fc·sign(v) (force units).
    coulomb: f64,
}

impl ForceSplit {
    fn is_friction(&self) -> bool {
        self.direction_r2 > self.position_r2
    }
}

fn force_split(force: &[f64], pos: &[f64], fs: f64) -> Option<ForceSplit> {
    let n = force.len().min(pos.len());
    if n < 3 {
        return None;
    }
    let v: Vec<f64> = pos[..n].windows(2).map(|w| (w[1] - w[0]) * fs).collect();
    let v_rms = stats::mean_square(&v).sqrt();
    if v_rms.is_nan() || v_rms <= 0.0 {
        return None;
    }
    // Sample k + 1 is the one the velocity v[k] leads into.
    let rows: Vec<(f64, f64, f64)> = v
        .iter()
        .enumerate()
        .filter(|(_, vk)| vk.abs() > 0.1 * v_rms)
        .map(|(k, vk)| (force[k + 1], pos[k + 1], vk.signum()))
        .collect();
    if rows.len() < 10 {
        return None;
    }
    let corr2 = |a: &dyn Fn(&(f64, f64, f64)) -> f64, b: &dyn Fn(&(f64, f64, f64)) -> f64| {
        let m = rows.len() as f64;
        let (ma, mb) = rows
            .iter()
            .fold((0.0, 0.0), |(x, y), r| (x + a(r) / m, y + b(r) / m));
        let (mut sab, mut saa, mut sbb) = (0.0, 0.0, 0.0);
        for r in &rows {
            let (da, db) = (a(r) - ma, b(r) - mb);
            sab += da * db;
            saa += da * da;
            sbb += db * db;
        }
        if saa > 0.0 && sbb > 0.0 {
            sab * sab / (saa * sbb)
        } else {
            0.0
        }
    };
    let direction_r2 = corr2(&|r| r.0, &|r| r.2);
    let position_r2 = corr2(&|r| r.0, &|r| r.1);
    // The position standardised, so that nm and m strokes condition alike.
    let ys: Vec<f64> = rows.iter().map(|r| r.1).collect();
    let (ym, ysd) = (stats::mean(&ys), std_of(&ys).max(f64::MIN_POSITIVE));
    let mut ata = nalgebra::Matrix3::<f64>::zeros();
    let mut atb = nalgebra::Vector3::<f64>::zeros();
    for &(f, y, s) in &rows {
        let a = nalgebra::Vector3::new(1.0, (y - ym) / ysd, s);
        ata += a * a.transpose();
        atb += a * f;
    }
    let coef = ata.lu().solve(&atb)?;
    coef[2].is_finite().then(|| ForceSplit {
        direction_r2,
        position_r2,
        coulomb: coef[2].abs(),
    })
}

/// How much of a rate-independent map's nonlinear part has memory (see
/// [`memory_share`]).
#[derive(Debug, Clone, Copy, PartialEq)]
enum Memory {
    /// The map is linear to round-off.
    Linear,
    /// The share of the nonlinear part that depends on the path (0–1).
    Share(f64),
    /// The input holds too few levels to tell a loop from a curve through
    /// them.
    Undetermined,
}

/// Share of the nonlinear part of a rate-independent map x ↦ y that has
/// memory: y minus its straight-line fit on x is the nonlinear part; the
/// rest after its single-valued part depends on the path (the loop).
///
/// Where the input moves through its levels (a sweep, a noisy drive), the
/// single-valued part is the mean in 64 bins of equal count over x. Where it
/// holds a few levels (a step excitation: m plateaus, m < 3·64), a bin holds
/// one plateau, one branch, and any single-valued map passes through it; the
/// single-valued part is then a polynomial of degree 7 in x, and the share of
/// what it leaves is scaled by m/(m − 8), the degrees of freedom it has left
/// (a loop's share at random levels is otherwise taken in part by the
/// polynomial), at most 1. Fewer than 16 levels: [`Memory::Undetermined`].
fn memory_share(x: &[f64], y: &[f64]) -> Memory {
    let n = x.len().min(y.len());
    if n < 128 {
        return Memory::Undetermined;
    }
    let (x, y) = (&x[..n], &y[..n]);
    let (xm, ym) = (stats::mean(x), stats::mean(y));
    let (mut sxy, mut sxx) = (0.0, 0.0);
    for k in 0..n {
        sxy += (x[k] - xm) * (y[k] - ym);
        sxx += (x[k] - xm) * (x[k] - xm);
    }
    let slope = if sxx > 0.0 { sxy / sxx } else { 0.0 };
    let nl: Vec<f64> = (0..n).map(|k| y[k] - ym - slope * (x[k] - xm)).collect();
    let nl_ms = stats::mean_square(&nl);
    let y_ms = stats::mean_square(&y.iter().map(|v| v - ym).collect::<Vec<_>>());
    if nl_ms.is_nan() || nl_ms <= 1e-12 * y_ms {
        return Memory::Linear;
    }
    let bins = 64;
    let tiny = 1e-9 * range(x);
    let levels = 1 + (1..n).filter(|&k| (x[k] - x[k - 1]).abs() > tiny).count();
    if levels >= 3 * bins {
        let mut idx: Vec<usize> = (0..n).collect();
        idx.sort_by(|&a, &b| x[a].total_cmp(&x[b]));
        let mut mem = 0.0;
        for b in 0..bins {
            let part = &idx[b * n / bins..(b + 1) * n / bins];
            if part.is_empty() {
                continue;
            }
            let m = part.iter().map(|&k| nl[k]).sum::<f64>() / part.len() as f64;
            mem += part.iter().map(|&k| (nl[k] - m).powi(2)).sum::<f64>();
        }
        return Memory::Share(mem / n as f64 / nl_ms);
    }
    const TERMS: usize = 8;
    if levels < 2 * TERMS {
        return Memory::Undetermined;
    }
    // Chebyshev polynomials of x mapped onto [−1, 1], by least squares.
    let lo = x.iter().copied().fold(f64::INFINITY, f64::min);
    let span = range(x).max(f64::MIN_POSITIVE);
    let basis = |v: f64| {
        let t = 2.0 * (v - lo) / span - 1.0;
        let mut p = nalgebra::SVector::<f64, TERMS>::zeros();
        p[0] = 1.0;
        p[1] = t;
        for i in 2..TERMS {
            p[i] = 2.0 * t * p[i - 1] - p[i - 2];
        }
        p
    };
    let mut ata = nalgebra::SMatrix::<f64, TERMS, TERMS>::zeros();
    let mut atb = nalgebra::SVector::<f64, TERMS>::zeros();
    for k in 0..n {
        let p = basis(x[k]);
        ata += p * p.transpose();
        atb += p * nl[k];
    }
    let Some(c) = ata.svd(true, true).solve(&atb, 1e-12).ok() else {
        return Memory::Undetermined;
    };
    let left = (0..n)
        .map(|k| (nl[k] - basis(x[k]).dot(&c)).powi(2))
        .sum::<f64>()
        / n as f64;
    let m = levels as f64;
    Memory::Share((left / nl_ms * m / (m - TERMS as f64)).min(1.0))
}

/// How many of a step's best candidates are fitted on the calibrated nominal
/// when neither passes alone ([`Search::calibration_with_effect`]): a full
/// step's worth of fits would double the time of every record that names
/// nothing.
const CAL_WITH_EFFECT_TRIED: usize = 3;

/// The candidates of a step (the best by their penalised score on the
/// nominal as it is) fitted again on the calibrated nominal when the
/// calibration competes with the step's best effect (see
/// `Search::calibration_competes`).
const CAL_COMPETES_TRIED: usize = 8;

/// The plays of the Prandtl–Ishlinskii hysteresis candidate (see
/// [`pi_radius`]): each costs a graph run at every fitting step.
const PI_PLAYS: usize = 6;

/// The widest play's radius, as a share of the drive's span: its play must
/// move on a major loop (travel 2r below the span) and still hold over most
/// of a reversal.
const PI_WIDEST: f64 = 0.4;

/// The narrowest play's radius over the widest's.
const PI_NARROWEST: f64 = 0.02;

/// Radius of play `j` (0-based, of [`PI_PLAYS`]) of the Prandtl–Ishlinskii
/// candidate for a drive of span `span`: geometric, from [`PI_NARROWEST`] ×
/// [`PI_WIDEST`]·span up to [`PI_WIDEST`]·span (a factor of about 2.2
/// between neighbours). A drive's reversals come in every size, from a
/// random drive's sample-to-sample wiggle to a scan's whole stroke; plays a
/// constant factor apart follow loops of every size with the same relative
/// resolution, where evenly spaced radii leave every loop smaller than a
/// seventh of the span to the first play alone. On record 4903 of the blind
/// set 4888–5002 (a Bouc–Wen loop under a PID loop) the even grid left 4.6 ×
/// the Bouc–Wen candidate's held-out rms, the geometric one 1.001 ×.
fn pi_radius(span: f64, j: usize) -> f64 {
    let widest = PI_WIDEST * span;
    widest * PI_NARROWEST.powf((PI_PLAYS - 1 - j) as f64 / (PI_PLAYS - 1) as f64)
}

/// The span of `x` without its outer 0.5 % on either side: a closed loop's
/// drive spikes at the first samples (a derivative kick on the first
/// reference step), and plays scaled to the spike never move.
fn robust_span(x: &[f64]) -> f64 {
    if x.is_empty() {
        return 0.0;
    }
    let mut v = x.to_vec();
    let k = ((v.len() - 1) as f64 * 0.005).round() as usize;
    let hi = v.len() - 1 - k;
    let (_, &mut upper, _) = v.select_nth_unstable_by(hi, f64::total_cmp);
    let (_, &mut lower, _) = v.select_nth_unstable_by(k, f64::total_cmp);
    upper - lower
}

/// The least share of its nonlinear part a fitted hysteresis map must owe to
/// memory (a loop) to be named hysteresis.
const MIN_MEMORY_SHARE: f64 = 0.25;

/// Share of the input's travel over which a map's output moves against its
/// overall direction (the sign of Σ Δx·Δy: the way the output mostly moves
/// with the input; friction's force falls as the position rises). A
/// material's hysteresis is monotone on every branch — Preisach and
/// Prandtl–Ishlinskii maps with non-negative weights are, and so is a
/// Coleman–Hodgdon loop while its slope right after a reversal, 2c − b, is
/// positive (thesis Table 6.2: b ≈ 1, c ≈ 0.7 µm/V, 2c − b ≈ 0.4) — so the
/// share is 0. A fit that runs backwards after each reversal stands in for
/// something else (a play with a gain error, the loop's response to noise).
/// `None` when the input does not move or the map has no direction.
fn reversed_travel(x: &[f64], y: &[f64]) -> Option<f64> {
    let n = x.len().min(y.len());
    if n < 3 {
        return None;
    }
    let sxy: f64 = (1..n).map(|k| (x[k] - x[k - 1]) * (y[k] - y[k - 1])).sum();
    let direction = sxy.signum();
    // Moves of the output below this are round-off, not a direction.
    let tiny = 1e-9 * range(&y[..n]);
    let (mut against, mut travel) = (0.0, 0.0);
    for k in 1..n {
        let (dx, dy) = (x[k] - x[k - 1], y[k] - y[k - 1]);
        travel += dx.abs();
        if dy.abs() > tiny && dx * dy * direction < 0.0 {
            against += dx.abs();
        }
    }
    (sxy != 0.0 && travel > 0.0 && travel.is_finite()).then(|| against / travel)
}

/// The largest share of the input's travel a fitted hysteresis map may move
/// against its direction (see [`reversed_travel`]): 0 for every monotone map;
/// the allowance covers a fit that ends a hair past monotone.
const MAX_REVERSED_TRAVEL: f64 = 1e-3;

/// Why fitted candidate `f` is not the physical effect `c` names, or
/// `None`: a hysteresis fit without a loop or running backwards
/// ([`not_hysteresis`]), a friction force that is all viscous
/// ([`viscous_only`]), or a fit that leaves a block — its own or one named
/// before and refitted with it — with parameters no physical effect has
/// ([`implausible`]: a creep that relaxes, a resonance outside the band, a
/// Prandtl–Ishlinskii loop whose branches go flat or turn back). Judged on
/// each fit and again after a joint refit, which can take an effect's
/// parameters where its own fit would not go (blind 5050: a sum of plays,
/// refitted with the resonance named after it, went to slopes 0.002, 4.8,
/// 10⁻⁵ — a dead band, then a cliff).
fn not_physical(ctx: &Ctx<'_>, c: &Cand, f: &Fitted) -> Option<String> {
    let blocks = f
        .free
        .iter()
        .map(|p| p.block.as_str())
        .chain(std::iter::once(f.block_name.as_str()));
    implausible(ctx, &f.spec, blocks).or_else(|| match c.effect {
        "hysteresis" => not_hysteresis(ctx, f, matches!(c.site, Site::Input { .. })),
        "friction" => viscous_only(ctx, f),
        _ => None,
    })
}

/// Why fitted hysteresis candidate `f` is not hysteresis, or `None`: its
/// block's output against its input (the drive, or the stage position for a
/// force inside the loop) is close to a single-valued map, or, for a map on
/// the drive (`on_drive`: the actuator's material), runs backwards after
/// reversals (not monotone, see [`reversed_travel`]). A force of the stage's
/// own motion is named by [`ForceSplit`] instead.
fn not_hysteresis(ctx: &Ctx<'_>, f: &Fitted, on_drive: bool) -> Option<String> {
    let (input, x, y) = fitted_map(ctx, f)?;
    if let Some(share) = reversed_travel(&x, &y).filter(|&s| on_drive && s > MAX_REVERSED_TRAVEL) {
        return Some(format!(
            "the fitted map from {input} runs backwards over {:.0} % of the input's travel (at most {:.0} %): a material's hysteresis is monotone on every branch",
            100.0 * share,
            100.0 * MAX_REVERSED_TRAVEL
        ));
    }
    match memory_share(&x, &y) {
        Memory::Share(share) if share < MIN_MEMORY_SHARE => Some(format!(
            "the fitted map from {input} has no loop to speak of ({:.0} % of its nonlinear part has memory, {:.0} % needed): a single-valued map, not hysteresis",
            100.0 * share,
            100.0 * MIN_MEMORY_SHARE
        )),
        Memory::Linear => Some(format!(
            "the fitted map from {input} is linear: a gain, not hysteresis"
        )),
        Memory::Share(_) | Memory::Undetermined => None,
    }
}

/// The fitted `f`'s degenerate form: the same block with what makes it the
/// effect taken out, only its linear part free — for a hysteresis the loop
/// (Coleman–Hodgdon with b = c and α so large that the output sits on y = b·u;
/// Bouc–Wen with a = 0 and Prandtl–Ishlinskii with every weight 0 (ratios 1),
/// y = linear·u), for a position-dependent gain the
/// dependence (g_i = 0, g_0 free: a constant gain error). `None` for other
/// effects.
fn degenerate_twin(c: &Cand, f: &Fitted) -> Option<Cand> {
    let block = f.spec.blocks.iter().find(|b| b.name == f.block_name)?;
    let mut json = surgery::block_to_json(block.block.as_ref());
    let linear = match json.get("type")?.as_str()? {
        "hysteresis" => {
            let b = json.get("b")?.as_f64()?;
            let alpha = json.get("alpha")?.as_f64()?;
            json["c"] = json!(b);
            json["alpha"] = json!(alpha * 1e9);
            1
        }
        "bouc_wen" => {
            json["a"] = json!(0.0);
            3
        }
        "prandtl_ishlinskii" => {
            // Every ratio 1: y = linear·u.
            let plays = json.get_mut("plays")?.as_array_mut()?;
            plays.iter_mut().for_each(|p| p["weight"] = json!(0.0));
            0
        }
        "position_dependent_gain" => {
            let coeffs = json.get_mut("coeffs")?.as_array_mut()?;
            coeffs.iter_mut().for_each(|g| *g = json!(0.0));
            coeffs.len()
        }
        _ => return None,
    };
    // Its own scale when the candidate frees it; else (g₀ of a gain on the
    // output, dimensionless like the g_i) that of the first free parameter.
    let &(_, scale) = c
        .free
        .iter()
        .find(|(k, _)| *k == linear)
        .or(c.free.first())?;
    Some(Cand {
        effect: c.effect,
        site: c.site.clone(),
        output: c.output,
        starts: vec![json],
        free: vec![(linear, scale)],
        s: c.s.clone(),
        rate_hz: c.rate_hz,
    })
}

/// Why fitted `f` is not evidence of its effect, or `None`: its degenerate
/// form ([`degenerate_twin`], a gain or a stiffness) fitted in its place
/// explains nearly as much. What makes it the effect (a hysteresis's loop,
/// a gain's variation) must pass the test a name passes, against what the
/// degenerate form leaves: cut it significantly (at `level`) and by
/// `min_cut` of its excess over the noise floor. A Coleman–Hodgdon force of
/// the position with b ≈ c is a stiffness; fitted to an attached mass below
/// its resonance (an added mass at one tone) or to a nominal's stiffness
/// error, it cut 56–92 % of the held-out residual with a loop that cut
/// nothing of what the stiffness leaves; after friction, a hysteresis on the
/// drive with b ≈ c took the friction form's leftover (tuning 306, 796).
/// Not a share of the fit's whole cut: a true hysteresis that also changes
/// the gain by a third owes 2 % of its mean-square cut to its loop — the
/// loop is what takes the residual from twice the noise to the noise
/// (generator seed 1). Once effects are named, it is taken twice: with the
/// named effects held, and on the joint refits of both (the candidate's and
/// its twin's); it must pass both — held alone, a hysteresis after friction
/// passed on friction's leftover (tuning 40, 642, 796); refitted jointly
/// alone, a loop the joint refit made of a resonance's leftover passed
/// (tuning 374). A twin that cannot run the record stands in for nothing.
fn degenerate_explains(
    ctx: &Ctx<'_>,
    cur: &Current,
    c: &Cand,
    f: &Fitted,
    (level, excess, at_floor, min_cut): (f64, &[(f64, f64)], bool, f64),
    joint: Option<&mut usize>,
) -> Option<String> {
    let twin = degenerate_twin(c, f)?;
    let mut t = fit_candidate(ctx, cur, &twin).ok()?;
    // `f` refitted jointly with the named effects (`joint`: the runs counted
    // there): the twin is too — like against like.
    if let Some(runs) = joint
        && let Ok(j) = joint_refit(ctx, &t, runs)
        && weighted_holdout_ms(ctx, &j.residual) < weighted_holdout_ms(ctx, &t.residual)
    {
        t = j;
    }
    // A degenerate form that cannot even run the record (its residual not
    // finite: the linear part alone diverges, or no start converged) stands
    // in for nothing: what is left is the loop's (the variation's) doing.
    if !holdout_rms(ctx, &t.residual).is_finite() {
        return None;
    }
    let (test, cut) = held_out_gain(ctx, (excess, at_floor), &t.residual, &f.residual);
    (test.p_value >= level || cut < min_cut).then(|| {
        format!(
            "{} explains little beyond {}: fitted alone, that leaves held-out rms {:.4e}, the whole fit {:.4e} (from {:.4e}): p = {:.1e} (needed < {:.1e}), {:.0} % of the excess over the noise floor it leaves (at least {:.0} % needed)",
            if c.effect == "hysteresis" { "its loop" } else { "its variation" },
            if c.effect == "hysteresis" {
                "its linear part (a gain, or a stiffness inside the loop)"
            } else {
                "a constant gain (a nominal gain error)"
            },
            holdout_rms(ctx, &t.residual),
            holdout_rms(ctx, &f.residual),
            holdout_rms(ctx, &cur.residual),
            test.p_value,
            level,
            100.0 * cut,
            100.0 * min_cut,
        )
    })
}

/// The fitted block's input (its source's name) and the block's input and
/// output over the records, from one run of the fitted graph.
fn fitted_map(ctx: &Ctx<'_>, f: &Fitted) -> Option<(String, Vec<f64>, Vec<f64>)> {
    let output = format!("{}.y", f.block_name);
    let input = f
        .spec
        .connections
        .iter()
        .find(|c| c.to == format!("{}.u", f.block_name))?
        .from
        .clone();
    let mut spec = surgery::clone_spec(&f.spec).ok()?;
    for name in [&input, &output] {
        if !spec.log.contains(name) {
            spec.log.push(name.clone());
        }
    }
    let mut ev = Evaluator::over(spec, ctx.records, &[], 0).ok()?;
    if !ev.run(&[], ctx.n) {
        return None;
    }
    let (x, y) = (ev.log_series(&input)?, ev.log_series(&output)?);
    Some((input, x, y))
}

/// The least share of a fitted friction force's variance that must come from
/// its Coulomb (direction-set) part for it to be named friction.
const MIN_COULOMB_SHARE: f64 = 0.25;

/// Why fitted friction candidate `f` is not friction, or `None`: its force is
/// mostly the viscous term, proportional to the velocity — a damping the
/// nominal has wrong (a linear model error), not the direction-set force
/// friction is. Shares from the fitted parameters and the stage velocity:
/// Coulomb F_c² (|sign v| = 1 while moving) against (F_v·v_rms)².
fn viscous_only(ctx: &Ctx<'_>, f: &Fitted) -> Option<String> {
    let block = f.spec.blocks.iter().find(|b| b.name == f.block_name)?;
    let p = block.block.tunable()?.params();
    let (coulomb, viscous) = (p.first()?.abs(), p.get(3)?.abs());
    let (_, x, _) = fitted_map(ctx, f)?;
    let v: Vec<f64> = x.windows(2).map(|w| (w[1] - w[0]) * ctx.fs).collect();
    let fv = viscous * stats::mean_square(&v).sqrt();
    let share = coulomb * coulomb / (coulomb * coulomb + fv * fv).max(f64::MIN_POSITIVE);
    (share < MIN_COULOMB_SHARE).then(|| {
        format!(
            "the fitted force is {:.0} % viscous (Coulomb level {coulomb:.3e} against a viscous force of {fv:.3e} rms): a damping the nominal has wrong, not friction",
            100.0 * (1.0 - share)
        )
    })
}

/// The spatial period of `r` as a function of `pos` (binned on a uniform grid)
/// and the p-value of its line (Fisher's g), when significant at 1 %.
fn position_period(r: &[f64], pos: &[f64]) -> Option<(f64, f64)> {
    let bins = 512usize;
    let (lo, span) = (
        pos.iter().copied().fold(f64::INFINITY, f64::min),
        range(pos),
    );
    let mut sum = vec![0.0; bins];
    let mut cnt = vec![0usize; bins];
    for (v, p) in r.iter().zip(pos) {
        let b = (((p - lo) / span) * (bins - 1) as f64).round() as usize;
        sum[b.min(bins - 1)] += v;
        cnt[b.min(bins - 1)] += 1;
    }
    let filled: Vec<f64> = sum
        .iter()
        .zip(&cnt)
        .map(|(s, &c)| if c > 0 { s / c as f64 } else { 0.0 })
        .collect();
    let (t, f) = stats::fisher_g(&filled);
    // At least three spatial periods over the range travelled.
    (t.p_value < 0.01 && f > 0.0 && 1.0 / f <= bins as f64 / 3.0)
        .then(|| (span / (bins - 1) as f64 / f, t.p_value))
}

/// The clearest spatial line of the compared residuals binned against the
/// position `pos` ([`position_period`] of each, estimation part): (period,
/// p-value, compared output). In a loop the controller's output counters a
/// force periodic in position and shows its pitch where the position's own
/// residual may not (tuning 248: p = 1e-44 against 4e-15 at another period).
fn clearest_position_period(
    ctx: &Ctx<'_>,
    cur: &Current,
    pos: &[f64],
) -> Option<(f64, f64, usize)> {
    (0..ctx.channels.len())
        .filter_map(|j| {
            let r = ctx.part(&cur.residual[j], Part::Estimation);
            position_period(r, &pos[..ctx.n_est.min(pos.len())]).map(|(p, pv)| (p, pv, j))
        })
        .min_by(|a, b| a.1.total_cmp(&b.1))
}

/// The pitch of a force periodic in the position `position` (values `pos`)
/// acting at `site`, found as a matched filter through the current model:
/// for each pitch p on a grid (three to 128 periods over the range travelled
/// in the estimation part, every half period over the range, the best few
/// refined to an eighth, none shorter
/// than four times the travel of a fast sample), the model is run with a
/// small force ε·cos(2πx/p) and ε·sin(2πx/p) added at the site, the two
/// responses g_c, g_s (what the loop and the plant make of that force at the
/// compared outputs, weighted as the residuals are) are regressed on the
/// residual, and the pitch whose pair explains most of it wins: (pitch,
/// cos and sin amplitudes, the share of the residual's weighted sum of
/// squares explained). Where the force reaches the position through a
/// mass or a loop, its pitch shows in the response, not in the residual
/// binned against the position (a phase that varies with the speed blurs
/// the bins). `None` when no pitch explains anything or the record does not
/// move.
/// The grid of [`force_pitch`]: periods over the range travelled, apart.
const PITCH_COARSE_STEP: f64 = 0.5;
/// The local maxima of [`force_pitch`]'s coarse grid refined (the best first).
const PITCH_PEAKS_REFINED: usize = 3;

fn force_pitch(
    ctx: &Ctx<'_>,
    cur: &Current,
    site: &Site,
    position: &str,
    pos: &[f64],
    runs: &mut usize,
) -> Option<(f64, f64, f64, f64)> {
    // The phase is read off the measured position where it is measured: the
    // model's position is off by the very residual looked into (a cogging
    // force moves the stage by many pitches' worth of phase in an open loop).
    let measured = ctx
        .channels
        .iter()
        .find(|c| c.signal == position)
        .and_then(|c| Some((c.column.clone(), ctx.data.column(&c.column)?)));
    let pos = measured.as_ref().map_or(pos, |m| m.1);
    let est = &pos[..ctx.n_est.min(pos.len())];
    let span = range(est);
    if !(span.is_finite() && span > 0.0) {
        return None;
    }
    // A fast sample's travel: the 90th percentile of |Δx|.
    let mut travel: Vec<f64> = est.windows(2).map(|w| (w[1] - w[0]).abs()).collect();
    travel.sort_by(f64::total_cmp);
    let fast = travel.get(travel.len() * 9 / 10).copied().unwrap_or(0.0);
    let k_max = (span / (4.0 * fast).max(f64::MIN_POSITIVE)).min(128.0);
    let k_min = 3.0;
    if k_max <= k_min {
        return None;
    }
    let p0 = span / k_min;
    // A force small beside the drive: the responses are the loop's linear ones.
    let Site::Input { from, .. } = site else {
        return None;
    };
    *runs += 1;
    let eps = 1e-3 * std_of(&signal(ctx, cur, from).ok()?).max(1e-300);
    // One evaluator per worker, each built the same way from the current
    // model (same graph, same bits): the pitches are independent runs.
    let build = || -> Option<Evaluator> {
        let block = surgery::block_from_json(
            json!({"type": "repetitive_disturbance", "period": p0, "variable": "signal", "cos": [0.0], "sin": [0.0]}),
        )
        .ok()?;
        let mut spec = cur.spec().ok()?;
        let phase_signal = match &measured {
            Some((column, _)) => {
                let reader = surgery::fresh_name(&spec, "plf_pitch_position");
                spec.blocks.push(BlockSpec {
                    name: reader.clone(),
                    rate_hz: None,
                    block: surgery::block_from_json(
                        json!({"type": "data_column", "column": column}),
                    )
                    .ok()?,
                });
                format!("{reader}.y")
            }
            None => position.to_string(),
        };
        let name = surgery::insert(
            &mut spec,
            "plf_pitch_scan",
            block,
            site,
            &[phase_signal],
            None,
        )
        .ok()?;
        let free: Vec<FreeParam> = [Scale::Log, Scale::Linear(eps), Scale::Linear(eps)]
            .into_iter()
            .enumerate()
            .map(|(index, scale)| FreeParam {
                block: name.clone(),
                index,
                scale,
            })
            .collect();
        let mut ev = Evaluator::over(spec, ctx.records, &free, 0).ok()?;
        ev.set_weights(&ctx.weights);
        Some(ev)
    };
    let mut ev = build()?;
    let n = ctx.n_est;
    *runs += 1;
    if !ev.run(&[0.0, 0.0, 0.0], n) {
        return None;
    }
    let outputs = ev.outputs();
    let base: Vec<Vec<f64>> = (0..outputs).map(|i| ev.model_series(i, 0..n)).collect();
    // The residual, each output weighed as in the fit, end to end.
    let r: Vec<f64> = (0..outputs)
        .flat_map(|i| {
            let w = ev.weight(i);
            ev.residual(i, 0..n).into_iter().map(move |v| v * w)
        })
        .collect();
    let threads = ctx.threads;
    let mut evaluators = vec![ev];
    for _ in 1..threads {
        evaluators.push(build()?);
    }
    let evaluators = std::sync::Mutex::new(evaluators);
    // (explained, a, b) of the pitch with k periods over the range, and the
    // runs it took.
    let explain = |ev: &mut Evaluator, k: f64| -> (Option<(f64, f64, f64)>, usize) {
        let z = (k_min / k).ln();
        let mut used = 0;
        let mut g = [Vec::new(), Vec::new()];
        for (j, gj) in g.iter_mut().enumerate() {
            let zz = [
                z,
                if j == 0 { 1.0 } else { 0.0 },
                if j == 1 { 1.0 } else { 0.0 },
            ];
            used += 1;
            if !ev.run(&zz, n) {
                return (None, used);
            }
            *gj = (0..outputs)
                .map(|i| {
                    ev.model_series(i, 0..n)
                        .iter()
                        .zip(&base[i])
                        .map(|(m, b)| (m - b) * ev.weight(i))
                        .collect::<Vec<f64>>()
                })
                .collect::<Vec<_>>()
                .concat();
        }
        let dot = |a: &[f64], b: &[f64]| a.iter().zip(b).map(|(x, y)| x * y).sum::<f64>();
        let (cc, cs, ss) = (dot(&g[0], &g[0]), dot(&g[0], &g[1]), dot(&g[1], &g[1]));
        let (rc, rs) = (dot(&g[0], &r), dot(&g[1], &r));
        let det = cc * ss - cs * cs;
        let e = (det > 1e-12 * cc * ss && det.is_finite()).then(|| {
            let a = (ss * rc - cs * rs) / det;
            let b = (cc * rs - cs * rc) / det;
            (a * rc + b * rs, a, b)
        });
        (e, used)
    };
    // Every pitch of `ks` on the workers (each result in its pitch's slot:
    // the same values whichever worker ran it), the runs counted.
    let mut explain_all = |ks: &[f64]| -> Vec<(f64, f64, f64, f64)> {
        let results = crate::pool::map(
            ks.to_vec(),
            threads,
            |_| 1.0,
            |k| {
                let mut ev = evaluators
                    .lock()
                    .ok()
                    .and_then(|mut e| e.pop())
                    .expect("an evaluator per worker");
                let out = explain(&mut ev, k);
                if let Ok(mut e) = evaluators.lock() {
                    e.push(ev);
                }
                out
            },
        );
        let mut found = Vec::new();
        for (&k, (e, used)) in ks.iter().zip(results) {
            *runs += used;
            if let Some((e, a, b)) = e {
                found.push((k, e, a, b));
            }
        }
        found
    };
    // Coarse to fine. Moving k by δ turns the phase at the range's far end by
    // 2πδ, so a pitch's peak is about one period over the range wide: on a
    // grid of half a period the peak is within a quarter of one (at least
    // about 80 % of its height), and the best few local maxima are refined
    // to an eighth.
    let grid: Vec<f64> = (0..)
        .map(|j| k_min + PITCH_COARSE_STEP * j as f64)
        .take_while(|&k| k <= k_max)
        .collect();
    let coarse = explain_all(&grid);
    let mut peaks: Vec<(f64, f64, f64, f64)> = (0..coarse.len())
        .filter(|&j| {
            let e = coarse[j].1;
            (j == 0 || coarse[j - 1].1 <= e) && coarse.get(j + 1).is_none_or(|c| c.1 <= e)
        })
        .map(|j| coarse[j])
        .collect();
    peaks.sort_by(|x, y| y.1.total_cmp(&x.1));
    peaks.truncate(PITCH_PEAKS_REFINED);
    let mut candidates = peaks.clone();
    let fine: Vec<f64> = peaks
        .iter()
        .flat_map(|&(k0, ..)| {
            [-3.0, -2.0, -1.0, 1.0, 2.0, 3.0].map(|d| k0 + d * PITCH_COARSE_STEP / 4.0)
        })
        .filter(|k| (k_min..=k_max).contains(k))
        .collect();
    candidates.extend(explain_all(&fine));
    let best = candidates
        .into_iter()
        .filter(|c| c.1 > 0.0)
        .max_by(|x, y| x.1.total_cmp(&y.1))
        .map(|(k, e, a, b)| (e, span / k, a * eps, b * eps));
    let total: f64 = r.iter().map(|v| v * v).sum();
    tracing::debug!(
        span,
        k_max,
        ?best,
        total,
        "force_pitch: (explained, pitch, cos, sin)"
    );
    best.map(|(e, p, c, s)| (p, c, s, e / total.max(f64::MIN_POSITIVE)))
}

fn enumerate(
    ctx: &Ctx<'_>,
    cur: &Current,
    opts: &Options,
    runs: &mut usize,
) -> Result<Vec<Cand>, PlfError> {
    let want = |e: &str| opts.effects.is_empty() || opts.effects.iter().any(|x| x == e);
    let mut out = Vec::new();
    let fs = ctx.fs;
    let t_len = ctx.n as f64 / fs;
    let spec_now = cur.spec()?;
    for (i, ch) in ctx.channels.iter().enumerate() {
        let first_of_channel = out.len();
        let mut sensor_slits: Option<Cand> = None;
        let r = ctx.part(&cur.residual[i], Part::Estimation);
        let yhat = &cur.model[i];
        let pos = signal(ctx, cur, &ch.position)?;
        let periodic_in = periodic_variables(ctx, cur, &ch.position, &pos, opts)?;
        let (sr, sy) = (std_of(r).max(1e-300), std_of(&pos).max(1e-300));
        let out_site = Site::Output {
            compare: i,
            signal: ch.signal.clone(),
        };
        let out_rate = Some(fs);
        // Output side.
        if want("drift") {
            out.push(Cand {
                effect: "drift",
                site: out_site.clone(),
                output: Some(i),
                starts: vec![
                    json!({"type": "drift", "offset": 0.0, "rate": 0.0, "curvature": 0.0}),
                ],
                free: vec![
                    (0, Scale::Linear(sr)),
                    (1, Scale::Linear(sr / t_len)),
                    (2, Scale::Linear(sr / (t_len * t_len))),
                ],
                s: vec![],
                rate_hz: out_rate,
            });
        }
        if want("repetitive_disturbance") {
            if let Some(p) = line_period(r) {
                out.push(repetitive(
                    out_site.clone(),
                    Some(i),
                    p / fs,
                    vec![],
                    sr,
                    out_rate,
                ));
            }
            for (variable, values) in &periodic_in {
                if let Some((p, _)) = position_period(r, &values[..ctx.n_est]) {
                    out.push(repetitive(
                        out_site.clone(),
                        Some(i),
                        p,
                        vec![variable.clone()],
                        sr,
                        out_rate,
                    ));
                }
            }
        }
        if want("quantization") {
            let q0 = range(r).max(1e-300);
            // The lsb is hard to find by descent once the record spans many
            // levels (the fit is exact only on the right grid): when the measured
            // values sit on a grid, start there.
            let measured: Vec<f64> = r.iter().zip(yhat).map(|(r, m)| r + m).collect();
            let grid = stats::lattice(&measured)
                .map(|(lsb, offset)| json!({"type": "quantizer", "lsb": lsb, "offset": offset}));
            // When noise after the rounding hides the grid, the rounding error
            // still shows: a sawtooth of period lsb in the (model) position,
            // whose fundamental gives the lsb and the grid's offset. At least
            // eight levels, at most 10⁵, over the range travelled. Only a start:
            // the held-out test judges the fit, so the line need not be
            // significant by itself.
            let sawtooth = stats::spatial_line(r, yhat, range(yhat) * 1e-5, range(yhat) / 8.0).map(
                |l| json!({"type": "quantizer", "lsb": l.period, "offset": l.rounding_offset()}),
            );
            out.push(Cand {
                effect: "quantization",
                site: out_site.clone(),
                output: Some(i),
                starts: grid
                    .into_iter()
                    .chain(sawtooth)
                    .chain(
                        [0.5, 0.8, 1.0, 1.3]
                            .iter()
                            .map(|f| json!({"type": "quantizer", "lsb": q0 * f})),
                    )
                    .collect(),
                free: vec![(0, Scale::Log), (1, Scale::Linear(0.05 * q0))],
                s: vec![],
                rate_hz: out_rate,
            });
        }
        if want("position_dependent_gain") {
            out.push(Cand {
                effect: "position_dependent_gain",
                site: out_site.clone(),
                output: Some(i),
                starts: vec![json!({"type": "position_dependent_gain", "variable": "input", "center": stats::mean(yhat), "scale": range(yhat) / 2.0, "coeffs": [0.0, 0.0]})],
                free: vec![(0, Scale::Linear(0.01)), (1, Scale::Linear(0.01))],
                s: vec![],
                rate_hz: out_rate,
            });
        }
        if want("time_delay") {
            out.push(time_delay(fs, out_site.clone(), Some(i), out_rate));
        }
        if want("unmodeled_resonance") {
            out.push(resonance(r, fs, out_site.clone(), Some(i), out_rate));
        }
        if want("encoder_slit_error")
            && let Some(lsb) = quantizer_lsb(&cur.spec()?, &ch.signal)
        {
            let slits = (range(yhat) / lsb).round() as usize;
            let table = slit_table(r, &yhat[..ctx.n_est], lsb, slits);
            if let Some(t) = &table {
                out.push(Cand {
                    effect: "encoder_slit_error",
                    site: out_site.clone(),
                    output: Some(i),
                    starts: vec![json!({"type": "encoder_slit_error", "pitch": lsb, "origin": -0.5 * lsb, "errors": t.start})],
                    free: t.fitted.iter().map(|&k| (k, Scale::Linear(sr))).collect(),
                    s: vec![],
                    rate_hz: out_rate,
                });
            }
            // In the sensor path inside a loop the controller acts on the
            // errors and the compared residual shows them filtered by the loop,
            // not as a table of the slit: fitted from zero, every slit seen —
            // unless the table is too large for the record (see
            // [`MAX_TABLE_CHARGE`]).
            let nn = table
                .as_ref()
                .map_or(slits + 1, |t| t.start.len())
                .min(MAX_SLITS);
            let seen = slits_seen(&yhat[..ctx.n_est], lsb, nn);
            let n_est = ctx.n_est as f64;
            sensor_slits = (seen.len() as f64 * n_est.ln() / n_est <= MAX_TABLE_CHARGE).then(|| Cand {
                effect: "encoder_slit_error",
                site: out_site.clone(),
                output: None,
                starts: vec![
                    json!({"type": "encoder_slit_error", "pitch": lsb, "origin": -0.5 * lsb, "errors": vec![0.0; nn]}),
                ],
                free: seen.into_iter().map(|k| (k, Scale::Linear(0.1 * lsb))).collect(),
                s: vec![],
                rate_hz: None,
            });
        }
        if want("axis_coupling") && ctx.channels.len() > 1 {
            let others: Vec<String> = ctx
                .channels
                .iter()
                .enumerate()
                .filter(|(j, _)| *j != i)
                .map(|(_, c)| c.signal.clone())
                .collect();
            let so = others.len();
            out.push(Cand {
                effect: "axis_coupling",
                site: out_site.clone(),
                output: Some(i),
                starts: vec![json!({"type": "axis_coupling", "coupling": vec![0.0; so]})],
                free: (0..so).map(|k| (k, Scale::Linear(sr / sy))).collect(),
                s: others,
                rate_hz: out_rate,
            });
        }
        // A compared signal that also feeds back (closed-loop data): the sensor
        // effects are tried in the measurement path too, where the controller
        // acts on them; the held-out score decides which place it is. A
        // compared drive is no measurement (`Channel::drive`): tuning 220 named
        // a drift "on controller.y as the controller sees it", a drive offset
        // that the input side's drift already offers.
        let compared = spec_now
            .compare
            .get(i)
            .map(|c| c.signal.clone())
            .unwrap_or_default();
        if !ch.drive && spec_now.connections.iter().any(|k| k.from == compared) {
            let in_loop: Vec<Cand> = out[first_of_channel..]
                .iter()
                .filter(|c| matches!(c.effect, "time_delay" | "quantization" | "drift"))
                .chain(&sensor_slits)
                .map(|c| Cand {
                    effect: c.effect,
                    site: Site::Sensor {
                        compare: i,
                        signal: compared.clone(),
                    },
                    output: None,
                    starts: c.starts.clone(),
                    free: c.free.clone(),
                    s: c.s.clone(),
                    rate_hz: None,
                })
                .collect();
            out.extend(in_loop);
        }
        // Input side and inside the loop, for every scalar input of the plant.
        for (from, to) in &ch.plant_inputs {
            let u = signal(ctx, cur, from)?;
            let (ru, su) = (range(&u), std_of(&u).max(1e-300));
            let inp = Site::Input {
                from: from.clone(),
                to: to.clone(),
            };
            let fb = Site::Feedback {
                from: from.clone(),
                to: to.clone(),
                position: ch.position.clone(),
            };
            let g = su / sy;
            if want("hysteresis") {
                out.push(Cand {
                    effect: "hysteresis",
                    site: inp.clone(),
                    output: None,
                    starts: [1.0, 4.0, 15.0]
                        .iter()
                        .map(|a| json!({"type": "hysteresis", "alpha": a / ru, "b": 1.0, "c": 0.8}))
                        .collect(),
                    free: vec![
                        (0, Scale::Log),
                        (1, Scale::Linear(0.1)),
                        (2, Scale::Linear(0.1)),
                    ],
                    s: vec![],
                    rate_hz: None,
                });
                let ry = range(&pos);
                out.push(Cand {
                    effect: "hysteresis",
                    site: fb.clone(),
                    output: None,
                    starts: [1.0, 4.0, 15.0]
                        .iter()
                        .map(|a| json!({"type": "hysteresis", "alpha": a / ry, "b": 0.0, "c": -0.1 * g}))
                        .collect(),
                    free: vec![(0, Scale::Log), (1, Scale::Linear(0.1 * g)), (2, Scale::Linear(0.1 * g))],
                    s: vec![],
                    rate_hz: None,
                });
            }
            if want("hysteresis") {
                // Bouc–Wen: saturating loops (restoring forces, mounts).
                let ry = range(&pos);
                out.push(Cand {
                    effect: "hysteresis",
                    site: fb.clone(),
                    output: None,
                    starts: [(0.3, 1.0), (1.0, 4.0), (1.0, 15.0)]
                        .iter()
                        .map(|(a, b)| json!({"type": "bouc_wen", "a": -a * g, "beta": b / ry, "gamma": 0.0, "linear": 0.0}))
                        .collect(),
                    free: vec![
                        (0, Scale::Linear(0.1 * g)),
                        (1, Scale::Log),
                        (2, Scale::Linear(1.0 / ry)),
                        (3, Scale::Linear(0.1 * g)),
                    ],
                    s: vec![],
                    rate_hz: None,
                });
                out.push(Cand {
                    effect: "hysteresis",
                    site: inp.clone(),
                    output: None,
                    starts: [1.0, 4.0, 15.0]
                        .iter()
                        .map(|b| json!({"type": "bouc_wen", "a": 0.5, "beta": b / ru, "gamma": 0.0, "linear": 0.5}))
                        .collect(),
                    free: vec![
                        (0, Scale::Linear(0.1)),
                        (1, Scale::Log),
                        (2, Scale::Linear(1.0 / ru)),
                        (3, Scale::Linear(0.1)),
                    ],
                    s: vec![],
                    rate_hz: None,
                });
            }
            // Prandtl–Ishlinskii: a loop of any shape a sum of plays makes
            // (piezo and magnetostrictive actuators' standard model), where
            // Coleman–Hodgdon's and Bouc–Wen's loops have one shape each
            // ([`pi_radius`] for the plays). Not on a drive that never moves.
            let span = if want("hysteresis") {
                robust_span(&u[..ctx.n_est.min(u.len())])
            } else {
                0.0
            };
            if span > 0.0 {
                out.push(Cand {
                    effect: "hysteresis",
                    site: inp.clone(),
                    output: None,
                    starts: vec![json!({
                        "type": "prandtl_ishlinskii",
                        "linear": 1.0,
                        "plays": (0..PI_PLAYS)
                            .map(|j| json!({"radius": pi_radius(span, j), "weight": 0.0}))
                            .collect::<Vec<_>>(),
                    })],
                    // The slopes' ratios on a log scale: every loop fitted
                    // is monotone (the material's), ratios of 1 the nominal.
                    free: (0..=PI_PLAYS).map(|k| (k, Scale::Log)).collect(),
                    s: vec![],
                    rate_hz: None,
                });
            }
            if want("friction") {
                let v: Vec<f64> = pos.windows(2).map(|w| (w[1] - w[0]) * fs).collect();
                let sv = std_of(&v).max(1e-300);
                out.push(Cand {
                    effect: "friction",
                    site: fb.clone(),
                    output: None,
                    starts: [(0.1, 0.001), (0.1, 0.01), (0.3, 0.05)]
                        .iter()
                        .map(|(f, e)| json!({"type": "friction", "coulomb": f * su, "stribeck": 0.0, "v_stribeck": sv, "viscous": 0.0, "v_eps": e * sv}))
                        .collect(),
                    free: vec![(0, Scale::Log), (3, Scale::Linear(0.1 * su / sv))],
                    s: vec![],
                    rate_hz: None,
                });
            }
            if want("time_delay") {
                out.push(time_delay(fs, inp.clone(), None, None));
            }
            if want("drift") {
                // A drive's zero that is off or moves (an amplifier's offset, a
                // constant force on the stage): inside a loop the controller
                // answers it, so it shows on the drive rather than at the output.
                out.push(Cand {
                    effect: "drift",
                    site: inp.clone(),
                    output: None,
                    starts: vec![
                        json!({"type": "drift", "offset": 0.0, "rate": 0.0, "curvature": 0.0}),
                    ],
                    // The offset only: a trend of the drive fitted on the
                    // estimation part is the loop's answer to everything else.
                    free: vec![(0, Scale::Linear(0.1 * su))],
                    s: vec![],
                    rate_hz: None,
                });
            }
            if want("saturation") {
                let (lo, hi) = u
                    .iter()
                    .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), &v| {
                        (a.min(v), b.max(v))
                    });
                let mid = 0.5 * (lo + hi);
                out.push(Cand {
                    effect: "saturation",
                    site: inp.clone(),
                    output: None,
                    starts: [0.95, 0.8, 0.6]
                        .iter()
                        .map(|f| json!({"type": "saturation", "lower": mid - f * (mid - lo), "upper": mid + f * (hi - mid)}))
                        .collect(),
                    free: vec![(0, Scale::Linear(0.02 * ru)), (1, Scale::Linear(0.02 * ru))],
                    s: vec![],
                    rate_hz: None,
                });
                // An amplifier that limits gradually (the smooth form of
                // `saturation`): its asymptotes lie beyond what the drive
                // reaches, and the whole range is compressed a little.
                out.push(Cand {
                    effect: "saturation",
                    site: inp.clone(),
                    output: None,
                    starts: [(1.2, 2.0), (1.6, 3.0), (1.1, 6.0)]
                        .iter()
                        .map(|(f, p)| json!({"type": "saturation", "lower": mid - f * (mid - lo), "upper": mid + f * (hi - mid), "sharpness": p}))
                        .collect(),
                    free: vec![
                        (0, Scale::Linear(0.02 * ru)),
                        (1, Scale::Linear(0.02 * ru)),
                        (2, Scale::Log),
                    ],
                    s: vec![],
                    rate_hz: None,
                });
            }
            if want("backlash") {
                out.push(Cand {
                    effect: "backlash",
                    site: inp.clone(),
                    output: None,
                    starts: [0.01, 0.05, 0.15]
                        .iter()
                        .map(|f| json!({"type": "backlash", "width": f * ru}))
                        .collect(),
                    free: vec![(0, Scale::Log)],
                    s: vec![],
                    rate_hz: None,
                });
            }
            if want("creep") {
                let (lo, hi) = Creep::time_constants(t_len, 1.0 / fs);
                let tau_within = Scale::LogWithin { lo, hi };
                out.push(Cand {
                    effect: "creep",
                    site: inp.clone(),
                    output: None,
                    starts: [50.0, 10.0, 3.0]
                        .iter()
                        .map(|d| json!({"type": "creep", "terms": [{"gain": 0.01, "tau_s": t_len / d}]}))
                        .collect(),
                    free: vec![(0, Scale::Linear(0.05)), (1, tau_within)],
                    s: vec![],
                    rate_hz: None,
                });
                // Piezo creep grows with the logarithm of time: one lag per decade
                // (record/3, /30, /300, none faster than two samples), time
                // constants fixed. Fitted twice: gains signed (linear in them,
                // so found in a step or two where a single lag's time constant
                // cannot be) and gains positive — every lag adding to the
                // growth, so the step response never falls, as
                // `Creep::implausible` asks: where the signed fit finds a
                // relaxation, refused, the positive one is creep's best
                // (tuning 80, 721, 1378).
                let decade = |d: f64| (t_len / d).max(2.0 / fs);
                let lags = |g: f64| {
                    json!({"type": "creep", "terms": [
                        {"gain": g, "tau_s": decade(3.0)},
                        {"gain": g, "tau_s": decade(30.0)},
                        {"gain": g, "tau_s": decade(300.0)}]})
                };
                out.push(Cand {
                    effect: "creep",
                    site: inp.clone(),
                    output: None,
                    starts: vec![lags(0.0)],
                    free: vec![
                        (0, Scale::Linear(0.05)),
                        (2, Scale::Linear(0.05)),
                        (4, Scale::Linear(0.05)),
                    ],
                    s: vec![],
                    rate_hz: None,
                });
                out.push(Cand {
                    effect: "creep",
                    site: inp.clone(),
                    output: None,
                    starts: vec![lags(0.01)],
                    free: vec![(0, Scale::Log), (2, Scale::Log), (4, Scale::Log)],
                    s: vec![],
                    rate_hz: None,
                });
            }
            if want("position_dependent_gain") {
                out.push(Cand {
                    effect: "position_dependent_gain",
                    site: inp.clone(),
                    output: None,
                    starts: vec![json!({"type": "position_dependent_gain", "variable": "signal", "center": stats::mean(&pos), "scale": range(&pos) / 2.0, "coeffs": [0.0, 0.0]})],
                    free: vec![
                        (0, Scale::Linear(0.05)),
                        (1, Scale::Linear(0.05)),
                        (2, Scale::Linear(0.05)),
                    ],
                    s: vec![ch.position.clone()],
                    rate_hz: None,
                });
            }
            if want("unmodeled_resonance") {
                out.push(resonance(r, fs, inp.clone(), None, None));
            }
            if want("repetitive_disturbance") {
                if let Some(p) = line_period(r) {
                    out.push(repetitive(
                        inp.clone(),
                        None,
                        p / fs,
                        vec![],
                        0.1 * su,
                        None,
                    ));
                }
                // A force periodic in the stage's position (cogging, a
                // drive-rod or magnet pitch) acts in the force balance, where
                // the loop reacts to it through the plant: added to the drive,
                // read from the position. Added to the measured output
                // instead (the output-side candidate), the loop's reaction is
                // missing, and in a closed loop that fit cut nothing (tuning
                // 248, 497, 743).
                //
                // Its pitch is looked for through the loop's own response
                // ([`force_pitch`]); the residual binned against the position
                // ([`clearest_position_period`]) is a second start where it
                // shows another pitch. Binned alone, a force that reaches the
                // position through the plant's dynamics blurs: in the blind set
                // 4373–4715, seven of ten cogging forces were not named.
                // The best of some hundred pitches always explains a little
                // of any residual: a pitch is a start only where it explains
                // the share of the residual a name must cut (tuning 635: a
                // pitch explaining 19 % of what a hysteresis left was named
                // for 18 % more; the cogging forces named explain 31–96 %).
                //
                // A disturbance periodic in a declared phase (the leg angle α
                // of a walking drive, Ch. 5: a leg's take-over every cycle)
                // is looked for the same way, over that signal
                // ([`periodic_variables`]).
                for (variable, values) in &periodic_in {
                    out.extend(periodic_in_signal(
                        ctx,
                        cur,
                        &inp,
                        (variable, values),
                        0.1 * su,
                        opts,
                        runs,
                    ));
                }
            }
        }
    }
    Ok(out)
}

/// A periodic disturbance of three harmonics with period `period` (s, or in the
/// unit of the signal `s` when one is given), coefficients on the scale `scale`.
fn repetitive(
    site: Site,
    output: Option<usize>,
    period: f64,
    s: Vec<String>,
    scale: f64,
    rate_hz: Option<f64>,
) -> Cand {
    let h = 3;
    let variable = if s.is_empty() { "time" } else { "signal" };
    Cand {
        effect: "repetitive_disturbance",
        site,
        output,
        starts: vec![
            json!({"type": "repetitive_disturbance", "period": period, "variable": variable, "cos": vec![0.0; h], "sin": vec![0.0; h]}),
        ],
        free: std::iter::once((0, Scale::Log))
            .chain((1..=2 * h).map(|k| (k, Scale::Linear(scale))))
            .collect(),
        s,
        rate_hz,
    }
}

/// The signals a disturbance may be periodic in, with their values over the
/// record: the position `position` (values `pos`) and the declared phase
/// ([`Options::phase`]). Where the model's position follows the phase in
/// proportion — within 10⁻³ of its range off an affine map of it, as a walking
/// stage's x_s = c·α/2π does — a disturbance periodic in the one is periodic
/// in the other and no record run on this model can tell them apart: the
/// phase declared is kept and the position left out (else the step would
/// fit the same disturbance twice and name whichever rounding favours).
fn periodic_variables(
    ctx: &Ctx<'_>,
    cur: &Current,
    position: &str,
    pos: &[f64],
    opts: &Options,
) -> Result<Vec<(String, Vec<f64>)>, PlfError> {
    let Some(phase) = opts.phase.as_deref().filter(|p| *p != position) else {
        return Ok(vec![(position.to_string(), pos.to_vec())]);
    };
    let values = signal(ctx, cur, phase)?;
    let n = pos.len().min(values.len());
    let phi = nalgebra::DMatrix::from_fn(n, 2, |k, j| if j == 0 { 1.0 } else { values[k] });
    let follows = stats::least_squares(&phi, &pos[..n]).is_some_and(|(th, _)| {
        let off: Vec<f64> = (0..n).map(|k| pos[k] - th[0] - th[1] * values[k]).collect();
        stats::mean_square(&off).sqrt() <= 1e-3 * range(pos)
    });
    let mut out = Vec::new();
    if !follows {
        out.push((position.to_string(), pos.to_vec()));
    }
    out.push((phase.to_string(), values));
    Ok(out)
}

/// A disturbance on the drive `inp` periodic in the signal `variable` (name,
/// values over the record): its period started where a force of that period,
/// run through the model, explains at least the share of the residual a name
/// must cut ([`force_pitch`]), and where the compared residual binned against
/// the signal shows its clearest line ([`clearest_position_period`]) when that
/// is another period. `None` when neither gives a start. Coefficients on the
/// scale `scale`.
fn periodic_in_signal(
    ctx: &Ctx<'_>,
    cur: &Current,
    inp: &Site,
    (variable, values): (&str, &[f64]),
    scale: f64,
    opts: &Options,
    runs: &mut usize,
) -> Option<Cand> {
    let matched =
        force_pitch(ctx, cur, inp, variable, values, runs).filter(|m| m.3 >= opts.min_excess_cut);
    let binned = clearest_position_period(ctx, cur, values).map(|(p, _, _)| p);
    let mut starts: Vec<serde_json::Value> = matched
        .iter()
        .map(|&(p, c, s, _)| {
            json!({"type": "repetitive_disturbance", "period": p, "variable": "signal", "cos": [c, 0.0, 0.0], "sin": [s, 0.0, 0.0]})
        })
        .collect();
    if let Some(p) = binned.filter(|p| matched.is_none_or(|m| (p / m.0).ln().abs() > 0.05)) {
        starts.push(json!({"type": "repetitive_disturbance", "period": p, "variable": "signal", "cos": [0.0, 0.0, 0.0], "sin": [0.0, 0.0, 0.0]}));
    }
    if starts.is_empty() {
        return None;
    }
    let mut c = repetitive(
        inp.clone(),
        None,
        1.0,
        vec![variable.to_string()],
        scale,
        None,
    );
    c.starts = starts;
    Some(c)
}

/// A fractional delay, started at 0.5 to 20 samples (buffer up to 200 samples).
/// A delay on `site`, started at 0.5–20 samples and fitted within what a
/// record sampled at `fs` shows as a delay: from
/// [`MIN_RESOLVED_DELAY_SAMPLES`] (what `TimeDelay::implausible` refuses
/// below) to 200 samples. Fitted freely, a delay took the phase a nominal a
/// few per cent off leaves (0.08–0.39 samples after the calibration: tuning
/// 52, 80, 213, 768, 1440) and was named; refused after the fit, a real delay of one
/// sample fitted at 0.46 on the nominal before its calibration was lost
/// (tuning 738).
fn time_delay(fs: f64, site: Site, output: Option<usize>, rate_hz: Option<f64>) -> Cand {
    let longest = 200.0 / fs;
    Cand {
        effect: "time_delay",
        site,
        output,
        starts: [0.5, 2.0, 6.0, 20.0]
            .iter()
            .map(|d| json!({"type": "time_delay", "max_delay_s": longest, "delay_s": d / fs}))
            .collect(),
        free: vec![(
            0,
            Scale::LogWithin {
                lo: MIN_RESOLVED_DELAY_SAMPLES / fs,
                hi: longest,
            },
        )],
        s: vec![],
        rate_hz,
    }
}

/// A resonance on `site`, started at the residual `r`'s strongest line and,
/// where the spectrum has a peak elsewhere that stands [`PEAK_RATIO`] over
/// its neighbours ([`stats::prominent_peak`]), there too: the fit cannot
/// move a pole pair across the band (its cost is many-valleyed in the
/// frequency), and the strongest line of a residual is often the slow
/// misfit or the coloured noise at the lowest frequencies, not the mode
/// ringing after every step (blind 5343: a mode at 79.8 Hz, the line at
/// 11 Hz, the fit ended on a cancelling pair there).
fn resonance(r: &[f64], fs: f64, site: Site, output: Option<usize>, rate_hz: Option<f64>) -> Cand {
    let (_, f) = stats::fisher_g(r);
    let at = |f: f64| (f * fs).clamp(fs * 1e-4, 0.4 * fs);
    let mut poles = vec![at(f)];
    // A start within 15 % of the first lies in the same valley of the cost.
    if let Some((fpk, ratio)) = stats::prominent_peak(r)
        && ratio >= PEAK_RATIO
        && (at(fpk) / poles[0]).ln().abs() > 0.15
    {
        poles.push(at(fpk));
    }
    Cand {
        effect: "unmodeled_resonance",
        site,
        output,
        starts: poles
            .iter()
            .flat_map(|&fp| [0.7, 1.4].map(|k| (fp, k)))
            .map(|(fp, k)| {
                json!({"type": "unmodeled_resonance", "f_pole_hz": fp, "zeta_pole": 0.05, "f_zero_hz": (k * fp).min(0.45 * fs), "zeta_zero": 0.05})
            })
            .collect(),
        free: vec![(0, Scale::Log), (1, Scale::Log), (2, Scale::Log), (3, Scale::Log)],
        s: vec![],
        rate_hz,
    }
}

/// How far a spectral peak must stand over its neighbours' median to start a
/// resonance's fit there too (see [`resonance`]): Welch's average of 16 or
/// more segments leaves noise bins within about twice their level.
const PEAK_RATIO: f64 = 4.0;

/// The lsb of a `quantizer` producing `signal`, if one does.
fn quantizer_lsb(spec: &GraphSpec, signal: &str) -> Option<f64> {
    let (b, _) = signal.split_once('.')?;
    let blk = spec.blocks.iter().find(|x| x.name == b)?;
    if blk.block.typetag_name() != "quantizer" {
        return None;
    }
    surgery::block_to_json(blk.block.as_ref())
        .get("lsb")?
        .as_f64()
}

/// The slit table to fit for a residual `r` against the model's position `y`
/// on slits of `pitch`, `slits` of them spanned by the whole record: the
/// number N of entries, the start (each entry the mean residual on its slits,
/// the least-squares table for the residual as it stands) and the entries seen
/// in `r`, the ones to fit. `None` when no table explains the residual better
/// than none by BIC, or when the table is mostly smooth (see
/// [`MIN_SLIT_ROUGHNESS`]).
///
/// N is chosen by BIC among a table repeating every N slits (2 ≤ N ≤ slits/2:
/// every slit seen on at least two revolutions, the errors of a rotary disc)
/// and one entry per slit spanned (a linear scale, or a disc turned less than
/// twice: each line's own error, the period not determinable; held-out records
/// 1815 and 1945 spanned 170–300 lines of 250–500-slit discs, and the
/// periodic tables were all the search had).
fn slit_table(r: &[f64], y: &[f64], pitch: f64, slits: usize) -> Option<SlitTable> {
    let n = r.len() as f64;
    let sse0: f64 = r.iter().map(|v| v * v).sum();
    let bic = |sse: f64, k: usize| n * (sse.max(1e-300) / n).ln() + k as f64 * n.ln();
    let index: Vec<i64> = y.iter().map(|&p| slit_of(p, pitch)).collect();
    // Per-entry sums and counts of a table of `nn` entries.
    let table = |nn: usize| {
        let mut sum = vec![0.0; nn];
        let mut cnt = vec![0usize; nn];
        for (v, i) in r.iter().zip(&index) {
            let k = i.rem_euclid(nn as i64) as usize;
            sum[k] += v;
            cnt[k] += 1;
        }
        (sum, cnt)
    };
    let bic_of = |(sum, cnt): &(Vec<f64>, Vec<usize>)| {
        let cut: f64 = sum
            .iter()
            .zip(cnt)
            .map(|(s, &c)| if c > 0 { s * s / c as f64 } else { 0.0 })
            .sum();
        bic(sse0 - cut, cnt.iter().filter(|&&c| c > 0).count())
    };
    let bic0 = bic(sse0, 0);
    let spanned = slits + 1;
    let mut best: Option<(usize, f64)> = None;
    let sizes = (2..=(slits / 2).min(512)).chain((spanned <= MAX_SLITS).then_some(spanned));
    for nn in sizes {
        let b = bic_of(&table(nn));
        if b < bic0 - 10.0 && best.is_none_or(|(_, bb)| b < bb) {
            best = Some((nn, b));
        }
    }
    let (nn, _) = best?;
    let (sum, cnt) = table(nn);
    let start: Vec<f64> = sum
        .iter()
        .zip(&cnt)
        .map(|(s, &c)| if c > 0 { s / c as f64 } else { 0.0 })
        .collect();
    let fitted: Vec<usize> = (0..nn).filter(|&k| cnt[k] > 0).collect();
    let seen: Vec<f64> = fitted.iter().map(|&k| start[k]).collect();
    (roughness(&seen, nn < spanned) >= MIN_SLIT_ROUGHNESS).then_some(SlitTable { start, fitted })
}

/// The share of a table's variance that changes from one entry to the next:
/// Σ(t − t̄ₖ)² / Σ(t − mean)², t̄ₖ the mean of the entries within
/// [`SLIT_SMOOTHING`] of entry k (around the table when it is `periodic`).
fn roughness(t: &[f64], periodic: bool) -> f64 {
    let n = t.len() as i64;
    let m = stats::mean(t);
    let total: f64 = t.iter().map(|v| (v - m).powi(2)).sum();
    let h = SLIT_SMOOTHING as i64;
    let rough: f64 = (0..n)
        .map(|k| {
            let near: Vec<f64> = (k - h..=k + h)
                .filter_map(|j| match periodic {
                    true => Some(t[j.rem_euclid(n) as usize]),
                    false => (0..n).contains(&j).then(|| t[j as usize]),
                })
                .collect();
            (t[k as usize] - stats::mean(&near)).powi(2)
        })
        .sum();
    if total > 0.0 { rough / total } else { 0.0 }
}

/// Half-width (entries) of the running mean a slit table's smooth part is
/// read with (see [`roughness`]).
const SLIT_SMOOTHING: usize = 4;

/// The least share of a slit table's variance that must change from one slit
/// to the next ([`roughness`]): slit errors are each line's own (independent
/// errors: 8/9 of it; the measured US Digital E2 disc of
/// `shared/data/usdigital_e2_slit_errors`, 0.83), while a smooth error of the
/// position (a gain, a force periodic in position, the once-per-revolution
/// eccentricity alone) is the other effects' — a sine over 60 lines keeps
/// 0.2 % of its variance (over 300 lines).
const MIN_SLIT_ROUGHNESS: f64 = 0.5;

/// The largest BIC charge k ln N / N (method step 3) of a slit table fitted
/// without evidence from the residual (in the sensor path inside a loop): a
/// table charged more must cut a third of the held-out mean square only to
/// tie with leaving it as it is — 362 entries on 2754 samples (tuning 837:
/// charge 1.04) cut 14 % and took two minutes of graph runs.
const MAX_TABLE_CHARGE: f64 = 0.5;

/// A slit table to fit (see [`slit_table`]).
struct SlitTable {
    /// Start of each entry (unit of the position).
    start: Vec<f64>,
    /// Entries seen in the estimation part: the ones fitted.
    fitted: Vec<usize>,
}

/// The slit a position `p` is on, slits of `pitch` centred on its multiples:
/// the index the inserted `encoder_slit_error` block (origin −pitch/2) looks up
/// before the modulo.
fn slit_of(p: f64, pitch: f64) -> i64 {
    ((p + 0.5 * pitch) / pitch).floor() as i64
}

/// The entries of a table of `nn` slits of `pitch` that the positions `y` are on.
fn slits_seen(y: &[f64], pitch: f64, nn: usize) -> Vec<usize> {
    let mut seen = vec![false; nn];
    for &p in y.iter().filter(|p| p.is_finite()) {
        seen[slit_of(p, pitch).rem_euclid(nn as i64) as usize] = true;
    }
    (0..nn).filter(|&k| seen[k]).collect()
}

/// Whether a grid of step `q` in a record can be the sampling of a
/// constant-speed sweep rather than a rounding: a sweep at speed v sampled
/// every dt puts its values on a grid of step v·dt — and of v·dt/m, so q
/// divides the step per sample — each pass at the same places. It is when
/// most samples of the model's (noise-free) output `model` that move at least
/// half a step per sample move the same whole number m ≥ 1 of steps q
/// (within 5 %); a rounding of a motion whose speed varies, or of one slower
/// than a step per sample, is not mistaken for it.
fn sampled_sweep(model: &[f64], q: f64) -> bool {
    let mut ratios: Vec<f64> = model
        .windows(2)
        .map(|w| (w[1] - w[0]).abs() / q)
        .filter(|r| *r >= 0.5)
        .collect();
    if ratios.len() < 200 {
        return false;
    }
    let m = stats::median(&mut ratios).round().max(1.0);
    let on_m = ratios
        .iter()
        .filter(|r| (*r / m - 1.0).abs() <= 0.05)
        .count();
    2 * on_m >= ratios.len()
}

/// The largest share of an output's held-out mean square a rounding read off
/// the record may claim: a model without the quantizer leaves the rounding
/// error (q²/12, Widrow) in its residual beside its own error, so a residual
/// well below q²/12 says the values are not rounded to that step (EMPS: a
/// weak "grid" of a trapezoidal reference's sampling with q²/12 at 70× the
/// position's held-out mean square). 1.5 leaves room for a model error that
/// partly follows the rounding.
const MAX_ROUNDING_SHARE: f64 = 1.5;

/// Quantization named from the record's own values (see [`stats::value_grid`])
/// on the first compared output whose measured column sits on a grid (p below
/// α over the outputs) that the model has no quantizer for and that is not
/// the sampling of a constant-speed sweep ([`sampled_sweep`]), with no
/// quantization named on its axis, where the rounding error's mean square
/// (q²/12) reaches `min_excess_cut` of the output's held-out mean square or
/// of its noise floor's, the smaller (a finer rounding is not what the model
/// misses; a misfit of another effect's form, left large beside it, does not
/// make the sensor's resolution less of a fact) and at most
/// [`MAX_ROUNDING_SHARE`] of it. A quantizer with the grid's
/// step and offset goes on the output; its held-out change is reported as it
/// is — a rounding's pattern is not predicted by a simulation off by more
/// than a step, so the grid is the evidence, not the cut.
fn quantization_from_grid(
    ctx: &Ctx<'_>,
    cur: &Current,
    opts: &Options,
    named: &[(&'static str, Vec<usize>, &'static str)],
    runs: &mut usize,
) -> Result<Option<(usize, Step, Current)>, PlfError> {
    let spec = cur.spec()?;
    let level = opts.alpha / ctx.channels.len() as f64;
    for (i, ch) in ctx.channels.iter().enumerate() {
        let on_axis = named.iter().any(|(e, o, _)| {
            *e == "quantization" && o.iter().any(|&k| ctx.channels[k].same_axis(ch))
        });
        if on_axis || quantizer_lsb(&spec, &ch.signal).is_some() {
            continue;
        }
        let measured: Vec<f64> = cur.residual[i]
            .iter()
            .zip(&cur.model[i])
            .map(|(r, m)| r + m)
            .collect();
        let Some(grid) = stats::value_grid(&measured) else {
            continue;
        };
        if sampled_sweep(&cur.model[i], grid.pitch) {
            continue;
        }
        let held_out_ms = stats::mean_square(&cur.residual[i][ctx.n_est..]);
        let rounding_ms = grid.pitch * grid.pitch / 12.0;
        let floor = floor_sigma(ctx, i, &cur.residual[i], Part::HeldOut);
        if grid.test.p_value >= level
            || rounding_ms < opts.min_excess_cut * held_out_ms.min(floor * floor)
            || rounding_ms > MAX_ROUNDING_SHARE * held_out_ms
        {
            continue;
        }
        let site = Site::Output {
            compare: i,
            signal: ch.signal.clone(),
        };
        let block = surgery::block_from_json(
            json!({"type": "quantizer", "lsb": grid.pitch, "offset": grid.offset}),
        )
        .map_err(|e| PlfError::Model(e.to_string()))?;
        let mut new_spec = surgery::clone_spec(&spec)?;
        let name = surgery::insert(
            &mut new_spec,
            "plf_quantization",
            block,
            &site,
            &[],
            Some(ctx.fs),
        )
        .map_err(|e| PlfError::Model(e.to_string()))?;
        let new = evaluate_current(ctx, new_spec, cur.free.clone(), runs)?;
        let sc = scores(ctx, &new);
        let (hb, ha) = (holdout_rms(ctx, &cur.residual), sc.holdout_rms);
        let step = Step {
            effect: "quantization".into(),
            block: BlockRef {
                name,
                type_name: "quantizer".into(),
            },
            site: site.describe(),
            params: BTreeMap::from([
                ("lsb".to_string(), grid.pitch),
                ("offset".to_string(), grid.offset),
            ]),
            final_params: BTreeMap::new(),
            derived: BTreeMap::new(),
            uncertainty: BTreeMap::new(),
            evidence: format!(
                "the measured {} sits on a grid of step {:.4e} while it moves (Rayleigh z = {:.1} over {} samples in motion, {:.1} per occupied bin; p = {:.1e} over the steps searched); its rounding error ({:.4e} rms) is {:.0} % of the held-out residual's mean square. Named from the record: a simulation off by more than a step does not predict the rounding's pattern, so the held-out change ({:.4e} -> {:.4e}) is not the evidence",
                ch.column,
                grid.pitch,
                grid.test.statistic,
                grid.samples,
                grid.repeats,
                grid.test.p_value,
                grid.pitch / 12f64.sqrt(),
                100.0 * grid.pitch * grid.pitch / 12.0 / held_out_ms,
                hb,
                ha
            ),
            holdout_rms_before: hb,
            holdout_rms_after: ha,
            cut_percent: cut_percent(
                weighted_holdout_ms(ctx, &cur.residual),
                weighted_holdout_ms(ctx, &new.residual),
            ),
            p_value: grid.test.p_value,
            per_output: sc.per_output,
            candidates: Vec::new(),
            ambiguous_with: Vec::new(),
        };
        return Ok(Some((i, step, new)));
    }
    Ok(None)
}

/// The cut (%) of a held-out rms whose mean square went from `before_ms` to
/// `after_ms` (negative when it grew).
fn cut_percent(before_ms: f64, after_ms: f64) -> f64 {
    100.0 * (1.0 - (after_ms / before_ms).sqrt())
}

const NOT_CUTTING: &str = "passed over: it does not cut the held-out residual significantly (p and share of the excess as for a name)";

/// Writes `note` on the row of candidate `c` (fitted to `score`) in the step's table.
fn annotate(table: &mut [Candidate], c: &Cand, score: f64, note: String) {
    if let Some(row) = table
        .iter_mut()
        .find(|r| r.effect == c.effect && r.site == c.site.describe() && r.score == score)
    {
        row.note = Some(note);
    }
}

/// A rough cost of fitting candidate `c`, for the work queue's order only (it
/// changes no result): runs ≈ starts × (parameters + 2) per iteration, a run of
/// the whole graph costing several times a run of an output-side block alone.
/// The penalised held-out score of a fit with `k` free parameters, `flex` of
/// them counted as flexibility (see [`flexibility`]), and weighted held-out
/// mean square `ms` (method step 3): a BIC-like factor (1 + k ln N/N) times a
/// flexibility charge (1 + flex/√N_hold).
fn penalised(ctx: &Ctx<'_>, (k, flex): (usize, usize), ms: f64) -> f64 {
    let ne = ctx.n_est as f64;
    let nh = (ctx.n - ctx.n_est) as f64;
    ms * (1.0 + k as f64 * ne.ln() / ne) * (1.0 + flex as f64 / nh.sqrt())
}

/// The parameter count of `k` free parameters of `effect` and the share of
/// them the flexibility charge counts (see [`penalised`]). The charge is for
/// shapes a fit can bend over the whole held-out record: each parameter that
/// moves every sample adds a chance of a lucky held-out cut as large as the
/// one before. The entries of a slit table each move only the samples on
/// their slit, disjoint sets, and their chance gains add up to that of one
/// parameter moving all samples — a 66-entry table cutting 42 % of the
/// held-out mean square was ranked behind 1-parameter fits cutting 1 %
/// (tuning 1789). The BIC factor still counts every entry.
fn flexibility(effect: &str, k: usize) -> (usize, usize) {
    match effect {
        "encoder_slit_error" => (k, k.min(1)),
        _ => (k, k),
    }
}

fn fit_cost(c: &Cand) -> f64 {
    let per_run = if c.output.is_some() { 1.0 } else { 8.0 };
    c.starts.len() as f64 * (c.free.len() + 2) as f64 * per_run
}

fn fit_candidate(ctx: &Ctx<'_>, cur: &Current, c: &Cand) -> Result<Fitted, String> {
    // (cost, spec, block name, free parameters, their σ, residuals)
    type Best = (
        f64,
        GraphSpec,
        String,
        Vec<FreeParam>,
        Vec<f64>,
        Vec<Vec<f64>>,
    );
    let mut best: Option<Best> = None;
    let mut refused: Option<String> = None;
    let mut runs = 0;
    for start in &c.starts {
        let block = surgery::block_from_json(start.clone()).map_err(|e| e.to_string())?;
        let mut spec = cur.spec().map_err(|e| e.to_string())?;
        let stem = format!("plf_{}", c.effect);
        let name = surgery::insert(&mut spec, &stem, block, &c.site, &c.s, c.rate_hz)
            .map_err(|e| e.to_string())?;
        let new_free: Vec<FreeParam> = c
            .free
            .iter()
            .map(|&(index, scale)| FreeParam {
                block: name.clone(),
                index,
                scale,
            })
            .collect();
        let (cost, std, residual) = if let Some(i) = c.output {
            // Output side: the effect alone on the current model output.
            let mut inputs = vec![cur.model[i].clone()];
            for sname in &c.s {
                let j = ctx.channels.iter().position(|ch| &ch.signal == sname);
                inputs.push(match j {
                    Some(j) => cur.model[j].clone(),
                    None => signal(ctx, cur, sname).map_err(|e| e.to_string())?,
                });
            }
            let measured = ctx
                .data
                .column(&ctx.channels[i].column)
                .unwrap_or(&[])
                .to_vec();
            let block = surgery::block_from_json(start.clone()).map_err(|e| e.to_string())?;
            let mut be = BlockEvaluator::new(
                block,
                &c.free,
                inputs,
                measured.clone(),
                weight(ctx, i),
                ctx.fs,
                0,
            )
            .map_err(|e| e.to_string())?
            .with_restarts(&ctx.records.starts());
            let z0 = vec![0.0; c.free.len()];
            let Some(fit) = levenberg_marquardt(&mut be, &z0, ctx.n_est, 30) else {
                continue;
            };
            runs += fit.runs;
            if !be.run(&fit.z, ctx.n) {
                continue;
            }
            // Write the fitted values into the inserted block of the spec.
            let theta = be.theta(&fit.z);
            let b = spec
                .blocks
                .iter_mut()
                .find(|b| b.name == name)
                .expect("inserted");
            let t = b.block.tunable_mut().ok_or("effect block is not tunable")?;
            let mut p = t.params();
            for (k, &(idx, _)) in c.free.iter().enumerate() {
                p[idx] = theta[k];
            }
            t.set_params(&p).map_err(|e| e.to_string())?;
            let mut residual = cur.residual.clone();
            residual[i] = measured.iter().zip(&be.y).map(|(m, y)| m - y).collect();
            (fit.cost, fit.std, residual)
        } else {
            let mut ev = Evaluator::over(
                surgery::clone_spec(&spec).map_err(|e| e.to_string())?,
                ctx.records,
                &new_free,
                0,
            )
            .map_err(|e| e.to_string())?;
            ev.set_weights(&ctx.weights);
            let z0 = vec![0.0; new_free.len()];
            let Some(fit) = levenberg_marquardt(&mut ev, &z0, ctx.n_est, 25) else {
                continue;
            };
            runs += fit.runs + 1;
            ev.export(&fit.z, &mut spec).map_err(|e| e.to_string())?;
            if !ev.run(&fit.z, ctx.n) {
                continue;
            }
            let residual = (0..ev.outputs())
                .map(|i| ev.residual(i, 0..ctx.n))
                .collect();
            (fit.cost, fit.std, residual)
        };
        if let Some(why) = implausible(ctx, &spec, std::iter::once(name.as_str())) {
            refused = Some(why);
            continue;
        }
        if best.as_ref().is_none_or(|b| cost < b.0) {
            best = Some((cost, spec, name, new_free, std, residual));
        }
    }
    let (_, spec, name, new_free, std, residual) = best.ok_or_else(|| match refused {
        Some(why) => format!("refused as not physical: {why}"),
        None => "fit failed (refused parameters or diverging runs at every start)".to_string(),
    })?;
    let score = penalised(
        ctx,
        flexibility(c.effect, c.free.len()),
        weighted_holdout_ms(ctx, &residual),
    );
    let mut free = cur.free.clone();
    free.extend(new_free);
    Ok(Fitted {
        effect: c.effect,
        spec,
        block_name: name,
        free_indices: c.free.iter().map(|&(i, _)| i).collect(),
        free,
        std,
        residual,
        score,
        runs,
    })
}

/// Refit the free parameters `free` of `spec` together on the full graph,
/// from their values in it: the fitted graph, each parameter's σ, the
/// residuals, and the graph runs spent.
#[allow(clippy::type_complexity)]
fn refit(
    ctx: &Ctx<'_>,
    spec: &GraphSpec,
    free: &[FreeParam],
) -> Result<(GraphSpec, Vec<f64>, Vec<Vec<f64>>, usize), PlfError> {
    let mut fitted = surgery::clone_spec(spec)?;
    let mut ev = Evaluator::over(surgery::clone_spec(spec)?, ctx.records, free, 0)?;
    ev.set_weights(&ctx.weights);
    let z0 = vec![0.0; free.len()];
    let fit = levenberg_marquardt(&mut ev, &z0, ctx.n_est, 15)
        .ok_or_else(|| PlfError::Model("joint refit could not run".into()))?;
    ev.export(&fit.z, &mut fitted)?;
    if !ev.run(&fit.z, ctx.n) {
        return Err(PlfError::Model(
            "joint refit diverges on the held-out part".into(),
        ));
    }
    let residual = (0..ev.outputs())
        .map(|i| ev.residual(i, 0..ctx.n))
        .collect();
    Ok((fitted, fit.std, residual, fit.runs + 1))
}

/// Refit all effects' free parameters together on the full graph.
fn joint_refit(ctx: &Ctx<'_>, win: &Fitted, runs: &mut usize) -> Result<Fitted, PlfError> {
    let (spec, std, residual, n_runs) = refit(ctx, &win.spec, &win.free)?;
    *runs += n_runs;
    let k0 = win.free.len() - win.free_indices.len();
    Ok(Fitted {
        effect: win.effect,
        spec,
        block_name: win.block_name.clone(),
        free: win.free.clone(),
        free_indices: win.free_indices.clone(),
        std: std[k0..].to_vec(),
        residual,
        score: win.score,
        runs: n_runs - 1,
    })
}

/// The variable an effect shows itself against, its label, and its values.
fn revealing_variable(ctx: &Ctx<'_>, cur: &Current, c: &Cand) -> (String, Vec<f64>) {
    let i = c.output.unwrap_or(0);
    let t: Vec<f64> = (0..ctx.n).map(|k| k as f64 / ctx.fs).collect();
    let input = |site: &Site| -> Option<(String, Vec<f64>)> {
        match site {
            Site::Input { from, .. } => signal(ctx, cur, from).ok().map(|v| (from.clone(), v)),
            Site::Feedback { position, .. } => signal(ctx, cur, position)
                .ok()
                .map(|v| (position.clone(), v)),
            Site::Output { .. } | Site::Sensor { .. } => None,
        }
    };
    match c.effect {
        "hysteresis" | "backlash" | "saturation" | "position_dependent_gain" => {
            input(&c.site).unwrap_or_else(|| (ctx.channels[i].signal.clone(), cur.model[i].clone()))
        }
        "friction" => {
            let p = signal(ctx, cur, &ctx.channels[i].position).unwrap_or_default();
            let mut v: Vec<f64> = p.windows(2).map(|w| (w[1] - w[0]) * ctx.fs).collect();
            v.insert(0, 0.0);
            (format!("velocity d({})/dt", ctx.channels[i].position), v)
        }
        "quantization" | "encoder_slit_error" => {
            (ctx.channels[i].signal.clone(), cur.model[i].clone())
        }
        "repetitive_disturbance" if !c.s.is_empty() => signal(ctx, cur, &c.s[0])
            .map(|v| (c.s[0].clone(), v))
            .unwrap_or_else(|_| ("time (s)".into(), t)),
        "axis_coupling" => {
            let j = (i + 1) % ctx.channels.len();
            (ctx.channels[j].signal.clone(), cur.model[j].clone())
        }
        _ => ("time (s)".into(), t),
    }
}

fn evidence(ctx: &Ctx<'_>, cur: &Current, c: &Cand, runs: &mut usize) -> String {
    let i = c.output.unwrap_or(0);
    let r = &cur.residual[i][..ctx.n_est];
    let (var, x) = revealing_variable(ctx, cur, c);
    let x = &x[..ctx.n_est.min(x.len())];
    match c.effect {
        "hysteresis" | "backlash" => {
            // Branch gap: residual on rising vs falling x, binned over x.
            let bins = 20;
            let (lo, span) = (x.iter().copied().fold(f64::INFINITY, f64::min), range(x));
            let mut acc = vec![[0.0f64; 4]; bins];
            for k in 1..x.len().min(r.len()) {
                let b = ((((x[k] - lo) / span) * bins as f64) as usize).min(bins - 1);
                let up = usize::from(x[k] < x[k - 1]) * 2;
                acc[b][up] += r[k];
                acc[b][up + 1] += 1.0;
            }
            let gaps: Vec<f64> = acc
                .iter()
                .filter(|a| a[1] > 0.0 && a[3] > 0.0)
                .map(|a| a[0] / a[1] - a[2] / a[3])
                .collect();
            let gap = stats::mean_square(&gaps).sqrt();
            format!(
                "the residual differs by {gap:.3e} (rms over {} bins of {var}) between rising and falling {var} — a loop, not a curve (residual rms {:.3e})",
                gaps.len(),
                std_of(r)
            )
        }
        "friction" => {
            let near: Vec<usize> = (1..x.len())
                .filter(|&k| x[k].signum() != x[k - 1].signum())
                .collect();
            let mut mask = vec![false; x.len()];
            for &k in &near {
                for m in mask
                    .iter_mut()
                    .take((k + 5).min(x.len()))
                    .skip(k.saturating_sub(5))
                {
                    *m = true;
                }
            }
            let (a, b): (Vec<f64>, Vec<f64>) = (0..r.len().min(x.len()))
                .map(|k| (mask[k], r[k]))
                .fold((Vec::new(), Vec::new()), |(mut a, mut b), (m, v)| {
                    if m {
                        a.push(v)
                    } else {
                        b.push(v)
                    }
                    (a, b)
                });
            format!(
                "{} velocity reversals; residual rms within 5 samples of one is {:.2}x the rms elsewhere",
                near.len(),
                stats::mean_square(&a).sqrt() / stats::mean_square(&b).sqrt().max(1e-300)
            )
        }
        "time_delay" => {
            let dx: Vec<f64> = cur.model[i].windows(2).map(|w| w[1] - w[0]).collect();
            let (t, lag) = stats::input_correlation(&r[1..], &dx[..r.len() - 1], 30);
            format!(
                "the residual correlates with the model output's rate of change (|z| = {:.1}, p = {:.1e}, lag {lag} samples)",
                t.statistic, t.p_value
            )
        }
        "repetitive_disturbance" if !c.s.is_empty() => {
            match clearest_position_period(ctx, cur, x) {
                Some((period, p, j)) => format!(
                    "the residual of {} binned against {var} repeats every {period:.4e} (Fisher g over the bins, p = {p:.1e})",
                    ctx.channels[j].column
                ),
                None => match force_pitch(ctx, cur, &c.site, &c.s[0], x, runs) {
                    Some((period, _, _, share)) => format!(
                        "a force of pitch {period:.4e} in {var} on the drive, run through the model, explains {:.0} % of the residual (the best of the pitches tried)",
                        100.0 * share
                    ),
                    None => format!("a residual periodic in {var}"),
                },
            }
        }
        "repetitive_disturbance" | "unmodeled_resonance" => {
            let (t, f) = stats::fisher_g(r);
            format!(
                "a periodic line at {:.4} Hz holds {:.0} % of the residual's periodogram (Fisher g, p = {:.1e})",
                f * ctx.fs,
                100.0 * t.statistic,
                t.p_value
            )
        }
        "drift" => {
            let phi = nalgebra::DMatrix::from_fn(r.len(), 2, |k, j| {
                if j == 0 { 1.0 } else { k as f64 / ctx.fs }
            });
            match stats::least_squares(&phi, r) {
                Some((th, cov)) => format!(
                    "the residual trends by {:.3e} per second (t = {:.1})",
                    th[1],
                    th[1] / cov[(1, 1)].sqrt()
                ),
                None => "the residual trends".into(),
            }
        }
        _ => {
            let w = stats::ljung_box(r, 20);
            format!(
                "residual not white (Ljung–Box Q = {:.0}, p = {:.1e}); best explained against {var}",
                w.statistic, w.p_value
            )
        }
    }
}

fn evidence_plot(ctx: &Ctx<'_>, cur: &Current, c: &Cand, win: &Fitted, step: usize) -> PlotData {
    let i = c.output.unwrap_or(0);
    let (var, x) = revealing_variable(ctx, cur, c);
    let n = x.len().min(ctx.n);
    // At most 4000 points per series.
    let stride = (n / 4000).max(1);
    let pick = |v: &[f64]| -> Vec<f64> { v.iter().take(n).step_by(stride).copied().collect() };
    let xs = pick(&x);
    PlotData {
        name: format!("step{step}_{}", c.effect),
        title: format!("step {step}: {} ({})", c.effect, c.site.describe()),
        x_label: var,
        y_label: format!("residual {} (measured − model)", ctx.channels[i].column),
        scatter: true,
        series: vec![
            ("before".into(), xs.clone(), pick(&cur.residual[i])),
            ("after".into(), xs, pick(&win.residual[i])),
        ],
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use nanomotion_core::models::hysteresis::{ChParams, ColemanHodgdon};

    /// A Coleman–Hodgdon loop on a triangle of amplitude `amp`, 2000 samples
    /// per stroke, from its anhysteretic line: (input, output).
    fn ch_triangle(p: ChParams, amp: f64, strokes: usize) -> (Vec<f64>, Vec<f64>) {
        let mut h = ColemanHodgdon::symmetric(p).unwrap();
        h.reset(-p.b * amp, -amp);
        let per = 2000;
        let x: Vec<f64> = (0..strokes * per)
            .map(|k| {
                let s = (k % per) as f64 / per as f64;
                let up = (k / per) % 2 == 0;
                if up {
                    -amp + 2.0 * amp * s
                } else {
                    amp - 2.0 * amp * s
                }
            })
            .collect();
        let y = x.iter().map(|&u| h.step(u)).collect();
        (x, y)
    }

    /// A line near the Nyquist frequency (a disturbance periodic in position on
    /// a fast scan looks like this in time) is structure, not noise: on an
    /// effect-free record with a sine at 0.31 of the sample rate, three times
    /// the noise's σ, added to the measured position, the floor from the
    /// sample-to-sample differences alone counted the sine as white (σ × 3.5)
    /// and the search stopped "at its noise floor" with nothing named. With the
    /// line taken out of the floor, the disturbance is named, at its period and
    /// amplitude.
    #[test]
    fn a_fast_periodic_disturbance_is_not_taken_for_the_noise_floor() {
        let _ = std::any::type_name::<crate::effects::Effect>();
        let rec = crate::generate::second_order("none", 5, 12_000, false).unwrap();
        let y = rec.data.column("y").unwrap();
        let sigma = stats::noise_floor(y);
        let (f_line, amp) = (0.31, 3.0 * sigma);
        let with_line: Vec<f64> = y
            .iter()
            .enumerate()
            .map(|(k, y)| y + amp * (std::f64::consts::TAU * f_line * k as f64 + 0.4).sin())
            .collect();
        assert!(stats::noise_floor(&with_line) > 3.0 * sigma);
        let data = rec.data.with_column("y", with_line).unwrap();
        let spec = GraphSpec::from_yaml(&rec.nominal_yaml, "nominal.yaml").unwrap();
        let r = diagnose(&spec, &data, &Options::default()).unwrap();
        assert_eq!(r.found, ["repetitive_disturbance"], "{}", r.stopped_because);
        let p = &r.steps[0].final_params;
        let period_s = 1.0 / (f_line * data.rate_hz());
        assert!((p["period"] - period_s).abs() < 1e-4 * period_s, "{p:?}");
        let fitted = p["cos[0]"].hypot(p["sin[0]"]);
        assert!((fitted - amp).abs() < 0.05 * amp, "{fitted} vs {amp}");
    }

    /// Backward elimination (`Search::prune`): with the record's drift in
    /// the model twice (two output-side drift blocks, fitted jointly), either
    /// one alone explains what both do — one is dropped, with a p-value the
    /// level a name needs refuses, and the other is kept, since without it
    /// the drift is back; the model left predicts the held-out part as the
    /// two did.
    #[test]
    fn an_effect_the_others_make_unnecessary_is_dropped_and_one_the_data_need_kept() {
        let _ = std::any::type_name::<crate::effects::Effect>();
        let rec = crate::generate::second_order("drift", 3, 4000, false).unwrap();
        let spec = GraphSpec::from_yaml(&rec.nominal_yaml, "nominal.yaml").unwrap();
        let records = Records::concat(std::slice::from_ref(&rec.data)).unwrap();
        let data = records.all.clone();
        let opts = Options::default();
        let (ctx, nominal, scores, runs) = context(&spec, &records, &data, &opts).unwrap();
        let mut search = Search::new(&ctx, &opts, nominal, scores, runs).unwrap();
        let site = Site::Output {
            compare: 0,
            signal: ctx.channels[0].signal.clone(),
        };
        let scale = std_of(&search.cur.residual[0]);
        let t_len = ctx.n as f64 / ctx.fs;
        let mut twice = search.cur.spec().unwrap();
        let mut free = Vec::new();
        for _ in 0..2 {
            let drift = surgery::block_from_json(
                json!({"type": "drift", "offset": 0.0, "rate": 0.0, "curvature": 0.0}),
            )
            .unwrap();
            let name = surgery::insert(&mut twice, "plf_drift", drift, &site, &[], None).unwrap();
            for (index, s) in [scale, scale / t_len, scale / (t_len * t_len)]
                .into_iter()
                .enumerate()
            {
                free.push(FreeParam {
                    block: name.clone(),
                    index,
                    scale: Scale::Linear(s),
                });
            }
            search.steps.push(Step {
                effect: "drift".into(),
                block: BlockRef {
                    name,
                    type_name: "drift".into(),
                },
                site: site.describe(),
                params: BTreeMap::new(),
                final_params: BTreeMap::new(),
                derived: BTreeMap::new(),
                uncertainty: BTreeMap::new(),
                evidence: String::new(),
                holdout_rms_before: f64::NAN,
                holdout_rms_after: f64::NAN,
                cut_percent: f64::NAN,
                p_value: f64::NAN,
                per_output: Vec::new(),
                candidates: Vec::new(),
                ambiguous_with: Vec::new(),
            });
            search.named.push(("drift", vec![0], site.kind()));
            search.own_forces.push(None);
            search.levels.push(opts.alpha);
        }
        let (fitted, _, _, _) = refit(&ctx, &twice, &free).unwrap();
        search.cur = evaluate_current(&ctx, fitted, free, &mut search.runs).unwrap();
        let both = weighted_holdout_ms(&ctx, &search.cur.residual);
        let nominal_ms = weighted_holdout_ms(&ctx, &search.first_residuals);
        assert!(both < 0.5 * nominal_ms, "{both} vs {nominal_ms}");
        search.prune().unwrap();
        assert_eq!(search.steps.len(), 1, "{:?}", search.dropped);
        assert_eq!(search.dropped.len(), 1);
        let d = &search.dropped[0];
        assert_eq!(d.effect, "drift");
        assert!(d.p_value >= opts.alpha, "{d:?}");
        let one = weighted_holdout_ms(&ctx, &search.cur.residual);
        assert!((one / both - 1.0).abs() < 0.01, "{one} vs {both}");
        // The drift left is the one the data need.
        let name = &search.steps[0].block.name;
        assert!(
            search
                .cur
                .spec()
                .unwrap()
                .blocks
                .iter()
                .any(|b| &b.name == name)
        );
        assert!(
            search
                .cur
                .free
                .iter()
                .all(|p| &p.block == name || !p.block.starts_with("plf_drift"))
        );
    }

    #[test]
    fn a_grid_at_the_step_per_sample_of_a_constant_speed_sweep_is_not_called_a_rounding() {
        // A triangle at 2.37e-3 per sample: its values sit on grids of steps
        // 2.37e-3/m; a rounding of 1e-3 on it, or any grid on a sine, is no
        // sampling of a constant speed.
        let tri = stats::sampled_triangle(2.37e-3, 1000, 12_000);
        assert!(sampled_sweep(&tri, 2.37e-3));
        assert!(sampled_sweep(&tri, 2.37e-3 / 2.0));
        assert!(!sampled_sweep(&tri, 1e-3));
        let sine: Vec<f64> = (0..12_000)
            .map(|k| (2.0 * std::f64::consts::PI * k as f64 / 3000.0).sin())
            .collect();
        assert!(!sampled_sweep(&sine, 1e-3));
    }

    /// Thesis Table 6.2's loop (2c − b > 0) is monotone; with 2c − b < 0 the
    /// output runs backwards after each reversal over the input travel
    /// s* = ln(2(b − c)/b)/α (slope b − 2(b − c)e^{−αs} on a saturated branch),
    /// a share s*/(2A) of a stroke of 2A; the first stroke, from the
    /// anhysteretic line (slope b − (b − c)e^{−αs}), runs backwards over
    /// ln((b − c)/b)/α.

    #[test]
    fn a_hysteresis_that_runs_backwards_after_reversals_is_measured_by_its_travel() {
        let strokes = 20;
        let (x, y) = ch_triangle(ChParams::new(20.0, 1.0, 0.7), 1.0, strokes);
        assert_eq!(reversed_travel(&x, &y), Some(0.0));
        let (alpha, b, c, amp) = (20.0, 1.0, -0.2, 1.0);
        let (x, y) = ch_triangle(ChParams::new(alpha, b, c), amp, strokes);
        let backwards = ((b - c) / b).ln() + (strokes - 1) as f64 * (2.0 * (b - c) / b).ln();
        let expected = backwards / alpha / (strokes as f64 * 2.0 * amp);
        let got = reversed_travel(&x, &y).unwrap();
        assert!(
            (got - expected).abs() < 0.01 * expected,
            "share {got}, closed form {expected}"
        );
        assert!(got > MAX_REVERSED_TRAVEL);
        // A map that does not move has no direction.
        assert_eq!(reversed_travel(&x, &vec![1.0; x.len()]), None);
    }

    /// A play (backlash) of half-width r after a saturating curve, and the
    /// same curve alone: (memory share of the play, of the curve) on `x`.
    fn play_and_curve_shares(x: &[f64], r: f64) -> (f64, f64) {
        let curve = |v: f64| v.tanh();
        let mut p = x[0];
        let play: Vec<f64> = x
            .iter()
            .map(|&v| {
                p = p.clamp(v - r, v + r);
                curve(p)
            })
            .collect();
        let single: Vec<f64> = x.iter().map(|&v| curve(v)).collect();
        let share = |y: &[f64]| match memory_share(x, y) {
            Memory::Share(s) => s,
            other => panic!("{other:?}"),
        };
        (share(&play), share(&single))
    }

    #[test]
    fn a_loop_shows_its_memory_under_sweeps_and_under_steps_a_curve_does_not() {
        // Ten triangle strokes over ±2 (2000 samples each): every bin is
        // entered on both branches.
        let x: Vec<f64> = (0..20_000)
            .map(|k| {
                let s = (k % 2000) as f64 / 2000.0;
                if (k / 2000) % 2 == 0 {
                    -2.0 + 4.0 * s
                } else {
                    2.0 - 4.0 * s
                }
            })
            .collect();
        let (play, curve) = play_and_curve_shares(&x, 0.3);
        assert!(
            play > 0.5 && curve < 0.01,
            "triangle: play {play}, curve {curve}"
        );
        // Twenty plateaus of 300 samples at levels drawn once each: a bin of
        // 64 holds one plateau (one branch); the polynomial through the
        // plateaus leaves the curve nothing and the play its shifts.
        let mut rng = nanomotion_core::rng::Rng::new(11);
        let levels: Vec<f64> = (0..20).map(|_| rng.uniform_in(-2.0, 2.0)).collect();
        let x: Vec<f64> = (0..6000).map(|k| levels[k / 300]).collect();
        let (play, curve) = play_and_curve_shares(&x, 0.3);
        assert!(
            play >= MIN_MEMORY_SHARE && curve < 0.1 * MIN_MEMORY_SHARE,
            "steps: play {play}, curve {curve}"
        );
        // Twelve levels cannot tell a loop from a curve through them.
        let x: Vec<f64> = (0..6000).map(|k| levels[k / 500]).collect();
        assert_eq!(
            memory_share(&x, &x.iter().map(|v| v.tanh()).collect::<Vec<_>>()),
            Memory::Undetermined
        );
    }

    /// A stage swept back and forth over `lines` lines of pitch 1, 40 times,
    /// 100 samples a line: its positions, and the residual `error(line)` plus
    /// white noise of σ = 0.1.
    fn swept(lines: usize, error: impl Fn(i64) -> f64) -> (Vec<f64>, Vec<f64>) {
        let mut rng = nanomotion_core::rng::Rng::new(7);
        let per_pass = lines * 100;
        let y: Vec<f64> = (0..40 * per_pass)
            .map(|k| {
                let s = (k % per_pass) as f64 / per_pass as f64 * lines as f64;
                if (k / per_pass).is_multiple_of(2) {
                    s
                } else {
                    lines as f64 - s
                }
            })
            .collect();
        let r = y
            .iter()
            .map(|p| error(p.round() as i64) + 0.1 * rng.normal())
            .collect();
        (y, r)
    }

    /// Errors of σ = 0.1 drawn for 64 slits, by slit index.
    fn slit_errors(n: usize) -> Vec<f64> {
        let mut rng = nanomotion_core::rng::Rng::new(3);
        (0..n).map(|_| 0.1 * rng.normal()).collect()
    }

    #[test]
    fn a_slit_table_repeats_every_revolution_or_covers_the_lines_spanned() {
        // A disc of 64 slits turned over 300 lines: the 64-entry table, each
        // entry near its error (≈ 470 samples per entry: σ/√470 ≈ 0.005).
        let e = slit_errors(64);
        let (y, r) = swept(300, |i| e[i.rem_euclid(64) as usize]);
        let t = slit_table(&r, &y, 1.0, 300).expect("a table");
        assert_eq!(t.start.len(), 64);
        for (got, want) in t.start.iter().zip(&e) {
            assert!((got - want).abs() < 0.03, "{got} vs {want}");
        }
        assert_eq!(t.fitted, (0..64).collect::<Vec<_>>());
        // A scale of 300 lines each with its own error, never repeating: one
        // entry per line spanned.
        let e = slit_errors(301);
        let (y, r) = swept(300, |i| e[i as usize]);
        let t = slit_table(&r, &y, 1.0, 300).expect("a table");
        assert_eq!(t.start.len(), 301);
        // Noise alone, and a smooth error of the position (a sine over 60
        // lines, as large as the slit errors), are no slit errors.
        assert!(slit_table(&swept(300, |_| 0.0).1, &y, 1.0, 300).is_none());
        let smooth = |i: i64| 0.1 * (i as f64 / 60.0 * std::f64::consts::TAU).sin();
        assert!(slit_table(&swept(300, smooth).1, &y, 1.0, 300).is_none());
    }

    /// A measured disc's slit errors pass the roughness a slit table needs:
    /// the US Digital E2 profile of the shared data (100 slits; a check that
    /// the threshold does not exclude a real encoder, not where it came from).
    #[test]
    fn a_measured_discs_slit_errors_are_rough_enough_to_be_named() {
        let path = std::path::PathBuf::from(env!("CARGO_MANIFEST_DIR")).join(
            "../../../shared/data/usdigital_e2_slit_errors/us_digital_e2_100cpr_tick_errors.csv",
        );
        let Some(path) =
            nanomotion_core::data::shared_data_or_skip(&path, "US Digital E2 roughness")
        else {
            return;
        };
        // tick_index, angle_error_elec_deg, ...: the second column.
        let text = std::fs::read_to_string(&path).unwrap();
        let e: Vec<f64> = text
            .lines()
            .skip(1)
            .map(|l| l.split(',').nth(1).unwrap().trim().parse().unwrap())
            .collect();
        assert_eq!(e.len(), 100);
        let r = roughness(&e, true);
        assert!((0.8..0.87).contains(&r), "{r}");
        assert!(r > MIN_SLIT_ROUGHNESS);
    }
}
