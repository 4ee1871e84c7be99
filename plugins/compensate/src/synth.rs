//! One compensator per named effect, from the fitted effect block's parameters
//! and the user's loop.
//!
//! | effect | compensator | block | place |
//! |---|---|---|---|
//! | `hysteresis` (Coleman–Hodgdon on the drive) | inverse feed-forward (6.6): H⁻¹(r/G₀ + feedback), Lambert W | `hysteresis_inverse` (+ `position_feedforward`) | before the actuator |
//! | `hysteresis` (Prandtl–Ishlinskii on the drive) | its exact inverse, another Prandtl–Ishlinskii operator (the loading curve's inverse, [`nanomotion_plf::effects::PrandtlIshlinskii::inverse`]); none where a branch's slope reaches 0 | `prandtl_ishlinskii` | before the actuator |
//! | `hysteresis` (Bouc–Wen on the drive) | its exact inverse: the drive giving each wanted output, by bisection on the operator's exact step ([`crate::bouc_wen`]); none where its slope can reach 0 | `bouc_wen_inverse` | before the actuator |
//! | `repetitive_disturbance` periodic in time | standard RC (5.1), L = ZPETC(T), FIR Q of the largest cut-off keeping (5.5) | `repetitive_control` | on the error before the controller (Fig. 5.1) |
//! | `repetitive_disturbance` periodic in a signal | delay-varying RC (5.7)–(5.8), α = the signal, [m, M] from the loop's motion, (5.9) | `dvrc` | as RC, `alpha` ← the signal |
//! | `friction` | the fitted friction of the reference's velocity, subtracted | `friction` | added at the plant input |
//! | `hysteresis` inside the loop (a restoring force of the position) | the fitted force at the reference, subtracted | `bouc_wen` / `hysteresis` | added at the plant input |
//! | `unmodeled_resonance` | its inverse R⁻¹ (poles ↔ zeros): a notch | `unmodeled_resonance` | before the plant |
//! | `position_dependent_gain` | gain scheduling (2.13) on 1/g(position) | `gain_scheduled` | before the plant |
//! | `axis_coupling` (on the measurement) | static decoupling −c | `axis_coupling` | in the measurement path |
//! | `encoder_slit_error` (on the measurement) | slit-error correction table (hots' calibration format): ê = −e/pitch, each reading put back on its slit's centre (`slit_correction`) | `slit_correction` | in the measurement path, after the reading |
//! | `backlash` (on the drive) | its inverse: ± half the play by the direction | `backlash_inverse` | before the actuator |
//! | `creep` (on the drive) | its exact discrete inverse (creep feed-forward) | `state_space` | before the actuator |
//! | `saturation` (on the drive), driven by a core `pid`/`pi` (directly or through a scalar `gain` k) | anti-windup: the fitted limits (÷ k) as that controller's output limits, clamping | none inserted: your `pid` changed | the controller itself |
//! | `drift` on the drive (a drive's zero that is off: the diagnosis fits its offset o) | offset feed-forward (`drift_offset`): −o added to the drive, the exact inverse; a fitted trend is not fed forward (a note with its rate) | `drive_offset` | before the actuator |
//! | `drift` of the measured position (the sensor's zero moves) | none (`drift_of_the_reading`): feedback makes the reading follow the reference, so the stage moves by the drift; figures: its rate and its change over the scored window | — | — |
//! | `time_delay`, the scored error driving a core `pid`/`pi` | re-tune ([`delay`]): the crossover lowered by β (zero/pole ratios kept, gain placing it at β·f_c) to the largest β whose loop *with the fitted delay* the gate finds stable with a phase margin ≥ max(yours − 5°, `require:`) | none inserted: your `pid` changed | the controller itself |
//! | `time_delay`, another controller | none: the phase 360°·f_c·d it takes, the fix (a core `pid`/`pi`, or the crossover by hand); a Smith predictor is a note | — | — |
//! | the rest | none; the report says what it limits | — | — |

use crate::named::{Placement, Where, source_of, split};
use crate::{CompError, LoopInfo, NotCompensated, Options, connect, reference_of};
use dvrc::filters::FilterSpec;
use dvrc::stability::{design_q_cutoff, rc_criterion};
use nanomotion_core::LearningFilter;
use nanomotion_core::Role;
use nanomotion_core::graph::GraphSpec;
use nanomotion_plf::surgery::{self, Site};
use serde_json::{Value, json};
use std::collections::BTreeMap;

pub mod delay;

/// How a compensator enters a graph (names of the user's controller graph).
#[derive(Debug, Clone, PartialEq)]
pub(crate) enum Edit {
    /// In series just before the plant-side input `to`, nearest the controller;
    /// with `ff`, a feed-forward block reading `ff.0` (port `r` → `v`) is added
    /// to its input.
    Before {
        to: String,
        ff: Option<(String, Value)>,
    },
    /// Reads `reads`; its output is subtracted at the plant input `to`.
    SubtractAt { to: String, reads: String },
    /// In the measurement path after `signal`; port `s` reads `s`.
    Sensor { signal: String, s: Vec<String> },
    /// In the measurement path after the reading `signal` and after the
    /// effect blocks chained on it in the validation loop (blocks not in the
    /// user's graph): a correction of what they do to the reading.
    Reading { signal: String },
    /// Learning on the error (Fig. 5.1): `e` ← error, error + `w` → `controller_input`;
    /// DVRC's `alpha` ← `alpha`.
    Learning {
        error: String,
        controller_input: String,
        alpha: Option<String>,
    },
    /// Before `to`, its `sigma` reading `sigma`.
    Scheduled { to: String, sigma: String },
    /// No block inserted: the user's controller `block` (a `pid` or `pi`) gets
    /// output limits [`lower`, `upper`] and the anti-windup `scheme`.
    Limits {
        block: String,
        lower: f64,
        upper: f64,
        scheme: String,
    },
    /// No block inserted: the user's controller `block` (a `pid` or `pi`) gets
    /// the compensator's block map as its parameters (re-tuned).
    Retune { block: String },
}

/// A synthesised compensator.
#[derive(Debug, Clone, PartialEq)]
pub struct Compensator {
    /// The effect.
    pub effect: String,
    /// Block name, `comp_<effect>` (for anti-windup: the user's controller,
    /// which is changed instead of a block inserted).
    pub name: String,
    /// The block (`type:` and parameters).
    pub block: Value,
    /// What and why.
    pub why: String,
    /// Where, in words.
    pub place: String,
    /// Design figures.
    pub design: BTreeMap<String, f64>,
    /// A caveat.
    pub note: Option<String>,
    pub(crate) edit: Edit,
}

/// A compensator, or why there is none.
#[derive(Debug, Clone, PartialEq)]
pub enum Outcome {
    /// Insert this.
    Compensator(Compensator),
    /// No compensation, and what the effect limits.
    None(NotCompensated),
}

impl Compensator {
    /// What the traces and messages call it: the inserted block's name, or
    /// "`pid`'s output limits" when the user's controller itself is changed.
    pub fn label(&self) -> String {
        match &self.edit {
            Edit::Limits { block, .. } => format!("{block}'s output limits"),
            Edit::Retune { block } => format!("{block} re-tuned"),
            _ => self.name.clone(),
        }
    }

    /// The signal a delay-varying RC follows (its `alpha`), if it is one.
    pub fn alpha(&self) -> Option<&str> {
        match &self.edit {
            Edit::Learning { alpha, .. } => alpha.as_deref(),
            _ => None,
        }
    }

    /// Its `type:`.
    pub fn type_name(&self) -> String {
        self.block
            .get("type")
            .and_then(Value::as_str)
            .unwrap_or("")
            .to_string()
    }

    /// Insert into `spec` (the user's loop, with or without the effects);
    /// `controller` is the user's graph the names refer to.
    pub(crate) fn apply(
        &self,
        spec: &mut GraphSpec,
        controller: &GraphSpec,
        opts: &Options,
    ) -> Result<(), CompError> {
        let no_place = |problem: String| CompError::NoPlace {
            graph: opts.controller_name.clone(),
            effect: self.effect.clone(),
            problem,
            fix: "keep the plant's input and the error signal as in the graph compensated".into(),
        };
        let block =
            surgery::block_from_json(self.block.clone()).map_err(|e| CompError::Design {
                effect: self.effect.clone(),
                problem: e.to_string(),
            })?;
        let from = |to: &str| -> Result<String, CompError> {
            source_of(controller, to)
                .map(str::to_string)
                .ok_or_else(|| no_place(format!("has no connection into `{to}`")))
        };
        let insert =
            |spec: &mut GraphSpec, block, site: &Site, s: &[String]| -> Result<String, CompError> {
                surgery::insert(spec, &self.name, block, site, s, None)
                    .map_err(|e| no_place(e.to_string()))
            };
        match &self.edit {
            Edit::Limits {
                block,
                lower,
                upper,
                scheme,
            } => {
                let b = spec
                    .blocks
                    .iter_mut()
                    .find(|b| b.name == *block)
                    .ok_or_else(|| no_place(format!("has no controller block `{block}`")))?;
                let mut params = surgery::block_to_json(b.block.as_ref());
                params["output_min"] = json!(lower);
                params["output_max"] = json!(upper);
                params["anti_windup"] = json!(scheme);
                b.block = surgery::block_from_json(params).map_err(|e| CompError::Design {
                    effect: self.effect.clone(),
                    problem: format!("`{block}` with the output limits: {e}"),
                })?;
                return Ok(());
            }
            Edit::Retune { block } => {
                return delay::set_params(spec, block, &self.block).map_err(no_place);
            }
            Edit::Before { to, ff } => {
                let site = Site::Input {
                    from: from(to)?,
                    to: to.clone(),
                };
                let name = insert(spec, block, &site, &[])?;
                if let Some((reads, ff)) = ff {
                    let rate = surgery::rate_of(spec, &name);
                    let ff_name = surgery::fresh_name(spec, &format!("{name}_ff"));
                    let sum = surgery::fresh_name(spec, &format!("{name}_sum"));
                    let k = spec
                        .connections
                        .iter()
                        .position(|c| c.to == format!("{name}.u"))
                        .ok_or_else(|| no_place("the inserted block has no input".into()))?;
                    spec.connections[k].to = format!("{sum}.in0");
                    let blocks = [
                        (ff_name.clone(), ff.clone()),
                        (sum.clone(), json!({"type": "sum", "signs": "++"})),
                    ];
                    for (n, b) in blocks {
                        let b = surgery::block_from_json(b).map_err(|e| no_place(e.to_string()))?;
                        spec.blocks.push(nanomotion_core::graph::BlockSpec {
                            name: n,
                            rate_hz: rate,
                            block: b,
                        });
                    }
                    connect(spec, reads.clone(), format!("{ff_name}.r"));
                    connect(spec, format!("{ff_name}.v"), format!("{sum}.in1"));
                    connect(spec, format!("{sum}.y"), format!("{name}.u"));
                }
            }
            Edit::Scheduled { to, sigma } => {
                let site = Site::Input {
                    from: from(to)?,
                    to: to.clone(),
                };
                let name = insert(spec, block, &site, &[])?;
                connect(spec, sigma.clone(), format!("{name}.sigma"));
            }
            Edit::SubtractAt { to, reads } => {
                let site = Site::Feedback {
                    from: from(to)?,
                    to: to.clone(),
                    position: reads.clone(),
                };
                let name = insert(spec, block, &site, &[])?;
                let sum = spec
                    .connections
                    .iter()
                    .find(|c| c.from == format!("{name}.y"))
                    .map(|c| split(&c.to).0.to_string())
                    .ok_or_else(|| no_place("the inserted sum is missing".into()))?;
                let minus = surgery::block_from_json(json!({"type": "sum", "signs": "+-"}))
                    .map_err(|e| no_place(e.to_string()))?;
                if let Some(b) = spec.blocks.iter_mut().find(|b| b.name == sum) {
                    b.block = minus;
                }
            }
            Edit::Reading { signal } => {
                let mut at = signal.clone();
                for _ in 0..32 {
                    let readers: Vec<&str> = spec
                        .connections
                        .iter()
                        .filter(|c| c.from == at)
                        .map(|c| c.to.as_str())
                        .collect();
                    match readers.as_slice() {
                        [one] if !crate::has_block(controller, split(one).0) => {
                            at = format!("{}.y", split(one).0);
                        }
                        _ => break,
                    }
                }
                let site = Site::Sensor {
                    compare: 0,
                    signal: at,
                };
                insert(spec, block, &site, &[])?;
            }
            Edit::Sensor { signal, s } => {
                let site = Site::Sensor {
                    compare: 0,
                    signal: signal.clone(),
                };
                insert(spec, block, &site, s)?;
            }
            Edit::Learning {
                error,
                controller_input,
                alpha,
            } => {
                let rate = surgery::rate_of(spec, split(controller_input).0);
                let name = surgery::fresh_name(spec, &self.name);
                let sum = surgery::fresh_name(spec, &format!("{name}_sum"));
                let plus = surgery::block_from_json(json!({"type": "sum", "signs": "++"}))
                    .map_err(|e| no_place(e.to_string()))?;
                let k = spec
                    .connections
                    .iter()
                    .position(|c| c.from == *error && c.to == *controller_input)
                    .ok_or_else(|| {
                        no_place(format!(
                            "has no connection {error} -> {controller_input} to put the learning on"
                        ))
                    })?;
                spec.connections[k].from = format!("{sum}.y");
                for (n, b) in [(name.clone(), block), (sum.clone(), plus)] {
                    spec.blocks.push(nanomotion_core::graph::BlockSpec {
                        name: n,
                        rate_hz: rate,
                        block: b,
                    });
                }
                connect(spec, error.clone(), format!("{sum}.in0"));
                connect(spec, format!("{name}.w"), format!("{sum}.in1"));
                connect(spec, error.clone(), format!("{name}.e"));
                if let Some(a) = alpha {
                    connect(spec, a.clone(), format!("{name}.alpha"));
                }
            }
        }
        Ok(())
    }
}

fn num(params: &Value, key: &str) -> f64 {
    params.get(key).and_then(Value::as_f64).unwrap_or(f64::NAN)
}

fn none(effect: &str, reason: String, figures: &[(&str, f64)]) -> Outcome {
    Outcome::None(NotCompensated {
        effect: effect.to_string(),
        reason,
        figures: figures
            .iter()
            .filter(|(_, v)| v.is_finite())
            .map(|(k, v)| (k.to_string(), *v))
            .collect(),
    })
}

/// The compensator of one named effect (`params`: its fitted block as JSON;
/// `placement`: where it enters the augmented model).
pub(crate) fn synthesise(
    e: &crate::NamedEffect,
    params: &Value,
    placement: &Placement,
    controller: &GraphSpec,
    diagnosed: &GraphSpec,
    info: &LoopInfo,
    opts: &Options,
) -> Result<Outcome, CompError> {
    let name = format!("comp_{}", e.effect);
    let ty = params.get("type").and_then(Value::as_str).unwrap_or("");
    let make = |block: Value,
                why: &str,
                place: String,
                design: &[(&str, f64)],
                note: Option<String>,
                edit: Edit| {
        Outcome::Compensator(Compensator {
            effect: e.effect.clone(),
            name: name.clone(),
            block,
            why: why.to_string(),
            place,
            design: design.iter().map(|(k, v)| (k.to_string(), *v)).collect(),
            note,
            edit,
        })
    };
    Ok(match (e.effect.as_str(), &placement.place) {
        ("hysteresis", Where::Input { to }) if ty == "hysteresis" => {
            let mut block = json!({
                "type": "hysteresis_inverse",
                "alpha": num(params, "alpha"),
                "b": num(params, "b"),
                "c": num(params, "c"),
            });
            if let Some(r) = params.get("retrace") {
                block["retrace"] = r.clone();
            }
            let mut design = vec![
                ("alpha", num(params, "alpha")),
                ("b", num(params, "b")),
                ("c", num(params, "c")),
            ];
            // The feed-forward of (6.6) maps the reference to the drive through
            // the inverse: H⁻¹(r/G₀ + feedback), G₀ the nominal's static gain.
            let (ff, note) = match static_feedforward(controller, to, info, opts, &e.effect)? {
                Ok((r, g0, y0)) => {
                    design.push(("static_gain", g0));
                    design.push(("static_offset", y0));
                    let ff = json!({"type": "position_feedforward",
                                    "gain_v_per_um": 1e-6 / g0, "offset_v": -y0 / g0});
                    (Some((r, ff)), None)
                }
                Err(why) => (
                    None,
                    Some(format!(
                        "no reference feed-forward: {why}; the inverse linearises the actuator for the feedback only"
                    )),
                ),
            };
            make(
                block,
                "inverse hysteresis feed-forward (6.6): the exact inverse of the fitted Coleman–Hodgdon loop (Lambert W) before the actuator, fed with the reference through the nominal's static gain plus the feedback",
                format!("before the actuator, on the connection into {to}"),
                &design,
                note,
                Edit::Before { to: to.clone(), ff },
            )
        }
        ("hysteresis", Where::Input { to }) if ty == "bouc_wen" => {
            let inv = crate::BoucWenInverse::new(
                num(params, "a"),
                num(params, "beta"),
                num(params, "gamma"),
                num(params, "linear"),
            );
            let design = [
                ("a", inv.a),
                ("beta", inv.beta),
                ("gamma", inv.gamma),
                ("linear", inv.linear),
            ];
            match inv.slope_bounds() {
                Ok((m, big_m)) => make(
                    json!({"type": "bouc_wen_inverse", "a": inv.a, "beta": inv.beta, "gamma": inv.gamma, "linear": inv.linear}),
                    "inverse Bouc–Wen feed-forward: for each drive the controller asks for, the input that makes the fitted Bouc–Wen loop give it (its exact per-sample integration inverted by bisection), before the actuator",
                    format!("before the actuator, on the connection into {to}"),
                    &[&design[..], &[("slope_min", m), ("slope_max", big_m)]].concat(),
                    Some("no reference feed-forward: the inverse linearises the actuator for the feedback".into()),
                    Edit::Before {
                        to: to.clone(),
                        ff: None,
                    },
                ),
                Err(why) => none(
                    &e.effect,
                    format!("no compensator: the fitted Bouc–Wen loop on the drive has no inverse: {why}"),
                    &design,
                ),
            }
        }
        ("hysteresis", Where::Input { to }) if ty == "prandtl_ishlinskii" => {
            let fitted = nanomotion_plf::effects::PrandtlIshlinskii::from_block_json(params);
            // The branch slopes' range (the operator's sector).
            let (lo, hi) = fitted
                .as_ref()
                .map_or((f64::NAN, f64::NAN), |p| p.slope_range());
            let design = [("slope_min", lo), ("slope_max", hi)];
            match fitted.as_ref().and_then(|p| p.inverse()) {
                Some(inv) => {
                    make(
                        surgery::block_to_json(&inv),
                        "inverse Prandtl–Ishlinskii feed-forward: the fitted operator's exact inverse — another Prandtl–Ishlinskii operator, whose loading curve is the inverse of the fitted one — before the actuator",
                        format!("before the actuator, on the connection into {to}"),
                        &design,
                        Some("no reference feed-forward: the inverse linearises the actuator for the feedback".into()),
                        Edit::Before {
                            to: to.clone(),
                            ff: None,
                        },
                    )
                }
                None => none(
                    &e.effect,
                    format!(
                        "no compensator: a branch of the fitted Prandtl–Ishlinskii loop on the drive stops or turns back (a slope ≤ 0: {}), so no drive gives every output",
                        fitted
                            .and_then(|p| p.implausible())
                            .unwrap_or_else(|| "its parameters do not read".into())
                    ),
                    &design,
                ),
            }
        }
        ("hysteresis", Where::Feedback { to, .. }) => {
            // A hysteretic restoring force of the position (Bouc–Wen or
            // Coleman–Hodgdon inside the loop): the fitted force at the
            // reference, subtracted, as for friction.
            let r = reference_of(controller, info, &opts.controller_name, &e.effect)?;
            make(
                params.clone(),
                "feed-forward of the fitted hysteretic force at the reference position, subtracted from the drive (the force cancels while the stage tracks)",
                format!("subtracted at {to}, computed from the reference {r}"),
                &[],
                None,
                Edit::SubtractAt {
                    to: to.clone(),
                    reads: r,
                },
            )
        }
        ("hysteresis", _) => none(
            &e.effect,
            format!(
                "no compensator in this version for a `{ty}` hysteresis {}: the inverse is synthesised for a Coleman–Hodgdon or Bouc–Wen loop on the drive",
                if matches!(placement.place, Where::Input { .. }) {
                    "on the drive"
                } else {
                    "inside the loop (a restoring force)"
                }
            ),
            &[],
        ),
        ("repetitive_disturbance", _) => {
            if params.get("variable").and_then(Value::as_str) == Some("signal") {
                match placement.s.first() {
                    Some(alpha) => {
                        delay_varying(e, params, alpha, controller, diagnosed, info, opts, &name)?
                    }
                    None => none(
                        &e.effect,
                        "periodic in a signal the augmented model does not wire: no delay-varying RC".into(),
                        &[("period", num(params, "period"))],
                    ),
                }
            } else {
                repetitive(e, params, controller, info, opts, &name)?
            }
        }
        ("friction", Where::Feedback { to, .. }) => {
            let r = reference_of(controller, info, &opts.controller_name, &e.effect)?;
            let mut block = params.clone();
            block["type"] = json!("friction");
            make(
                block,
                "feed-forward of the fitted friction at the reference's velocity (backward difference of the reference), subtracted from the drive",
                format!("subtracted at {to}, computed from the reference {r}"),
                &[
                    ("coulomb", num(params, "coulomb")),
                    ("viscous", num(params, "viscous")),
                ],
                Some("a loop with integral action already removes a constant friction force; the feed-forward acts at the reversals".into()),
                Edit::SubtractAt {
                    to: to.clone(),
                    reads: r,
                },
            )
        }
        ("unmodeled_resonance", place) => {
            let to = match place {
                Where::Input { to } | Where::Feedback { to, .. } => to.clone(),
                Where::Output { signal } => plant_input(controller, signal, &e.effect, opts)?,
            };
            let (fp, zp, fz, zz) = (
                num(params, "f_pole_hz"),
                num(params, "zeta_pole"),
                num(params, "f_zero_hz"),
                num(params, "zeta_zero"),
            );
            make(
                json!({"type": "unmodeled_resonance", "f_pole_hz": fz, "zeta_pole": zz, "f_zero_hz": fp, "zeta_zero": zp}),
                "notch: the inverse of the fitted pole–zero pair (its zeros on the resonance's poles), unity DC gain",
                format!("before the plant, on the connection into {to}"),
                &[
                    ("notch_hz", fp),
                    ("notch_zeta", zp),
                    ("pole_hz", fz),
                    ("pole_zeta", zz),
                ],
                None,
                Edit::Before { to, ff: None },
            )
        }
        ("position_dependent_gain", Where::Input { to })
            if params.get("variable").and_then(Value::as_str) != Some("input")
                && placement.s.len() == 1 =>
        {
            let (x, gain) = inverse_gain_table(params).ok_or_else(|| CompError::Design {
                effect: e.effect.clone(),
                problem: "the fitted gain is not positive around its centre: no schedule 1/g"
                    .into(),
            })?;
            let (lo, hi) = (x[0], x[x.len() - 1]);
            make(
                json!({"type": "gain_scheduled", "controller": {"type": "gain", "k": 1.0},
                       "schedule": [{"kind": "table", "x": x, "gain": gain}]}),
                "gain scheduling (2.13): the drive times 1/g(position) of the fitted gain, so the loop gain does not move with position",
                format!(
                    "before the plant, on the connection into {to}, scheduled on {}",
                    placement.s[0]
                ),
                &[("table_from", lo), ("table_to", hi)],
                None,
                Edit::Scheduled {
                    to: to.clone(),
                    sigma: placement.s[0].clone(),
                },
            )
        }
        ("axis_coupling", Where::Output { signal }) => {
            let c: Vec<f64> = params
                .get("coupling")
                .and_then(Value::as_array)
                .map(|v| v.iter().filter_map(Value::as_f64).map(|x| -x).collect())
                .unwrap_or_default();
            make(
                json!({"type": "axis_coupling", "coupling": c}),
                "static decoupling: the fitted coupling of the other axes subtracted from the measurement",
                format!(
                    "in the measurement path after {signal}, reading {}",
                    placement.s.join(", ")
                ),
                &[],
                None,
                Edit::Sensor {
                    signal: signal.clone(),
                    s: placement.s.clone(),
                },
            )
        }
        ("creep", Where::Input { to }) => {
            let terms: Vec<(f64, f64)> = params
                .get("terms")
                .and_then(Value::as_array)
                .map(|v| {
                    v.iter()
                        .map(|t| (num(t, "gain"), num(t, "tau_s")))
                        .collect()
                })
                .unwrap_or_default();
            let dt =
                1.0 / surgery::rate_of(controller, split(to).0).unwrap_or(controller.base_rate_hz);
            match creep_inverse(&terms, dt) {
                Some(block) => make(
                    block,
                    "creep feed-forward: the exact inverse of the fitted creep (the sum of first-order lags, discretised as the effect block is), so the drive's creep cancels",
                    format!("before the actuator, on the connection into {to}"),
                    &[("dc_gain", 1.0 / (1.0 + terms.iter().map(|t| t.0).sum::<f64>()))],
                    Some("starts at rest, as the creep block does at a first input of 0".into()),
                    Edit::Before { to: to.clone(), ff: None },
                ),
                None => none(
                    &e.effect,
                    "no compensation: the inverse of the fitted creep is unstable (a negative creep gain)".into(),
                    &[],
                ),
            }
        }
        ("backlash", Where::Input { to }) => make(
            json!({"type": "backlash_inverse", "width": num(params, "width")}),
            "backlash inverse: the wanted drive ± half the fitted play by its direction, so the play is taken up at every reversal",
            format!("before the actuator, on the connection into {to}"),
            &[("width", num(params, "width"))],
            Some("the drive jumps by the full play at each reversal".into()),
            Edit::Before {
                to: to.clone(),
                ff: None,
            },
        ),
        ("quantization", _) => {
            let lsb = num(params, "lsb");
            none(
                &e.effect,
                format!(
                    "no compensation: the feedback acts on the rounded position, so rounding to {lsb:.3e} limits the error to about lsb/√12 = {:.3e} rms (a finer sensor, or an estimator between counts, e.g. time-stamping (Ch. 8), is what helps)",
                    lsb / 12f64.sqrt()
                ),
                &[("lsb", lsb), ("rms_floor", lsb / 12f64.sqrt())],
            )
        }
        ("encoder_slit_error", Where::Output { signal }) => {
            slit_correction(e, params, signal, controller)?
        }
        ("encoder_slit_error", _) => none(
            &e.effect,
            "no compensator: the fitted slit errors are not on the measured position (a slit table corrects an encoder's reading)".into(),
            &[],
        ),
        ("drift", Where::Input { to }) => drift_offset(e, params, to, controller)?,
        ("drift", Where::Output { signal }) => drift_of_the_reading(e, params, signal, controller, info)?,
        ("time_delay", _) => delay::time_delay(e, params, placement, controller, info, opts)?,
        ("saturation", Where::Input { to }) => anti_windup(e, params, to, controller, info)?,
        (other, place) => none(
            other,
            format!(
                "no compensator in this version for `{other}` {} (creep, backlash and saturation are compensated on the drive only)",
                match place {
                    Where::Input { to } => format!("on the drive into {to}"),
                    Where::Feedback { to, .. } => format!("inside the loop at {to}"),
                    Where::Output { signal } => format!("on the measured {signal}"),
                }
            ),
            &[],
        ),
    })
}

/// The reference and the nominal plant's static map y = G₀·u + y₀ from the
/// plant-side input `to` to the measured position (the error sum's `in1`), by
/// two open-loop runs of the user's graph with `to` held at 0 and at 1.
/// `Ok(Err(why))` when there is none (the plant integrates, or does not settle).
fn static_feedforward(
    controller: &GraphSpec,
    to: &str,
    info: &LoopInfo,
    opts: &Options,
    effect: &str,
) -> Result<Result<(String, f64, f64), String>, CompError> {
    let r = reference_of(controller, info, &opts.controller_name, effect)?;
    let eb = split(&info.error).0;
    let Some(measured) = source_of(controller, &format!("{eb}.in1")).map(str::to_string) else {
        return Ok(Err(format!("nothing feeds `{eb}.in1`")));
    };
    let probe = |v: f64| -> Result<(f64, f64), String> {
        let mut g = surgery::clone_spec(controller).map_err(|e| e.to_string())?;
        g.connections.retain(|c| c.to != to);
        g.duration_s = g.duration_s.min(4.0);
        let name = surgery::fresh_name(&g, "probe");
        let b = surgery::block_from_json(json!({"type": "constant", "value": v}))
            .map_err(|e| e.to_string())?;
        g.blocks.push(nanomotion_core::graph::BlockSpec {
            name: name.clone(),
            rate_hz: surgery::rate_of(controller, split(to).0),
            block: b,
        });
        connect(&mut g, format!("{name}.y"), to.to_string());
        g.score.clear();
        g.log = vec![measured.clone()];
        let (mut s, _) = g.build().map_err(|e| e.to_string())?;
        let run = s.run(|_| {});
        let y = &run.logs.first().ok_or("no log")?.data;
        let tenth = (y.len() / 10).max(1);
        let mean = |x: &[f64]| x.iter().sum::<f64>() / x.len() as f64;
        Ok((
            mean(&y[y.len() - tenth..]),
            mean(&y[y.len() - 2 * tenth..y.len() - tenth]),
        ))
    };
    let ((y0, y0_prev), (y1, y1_prev)) = match (probe(0.0), probe(1.0)) {
        (Ok(a), Ok(b)) => (a, b),
        (Err(e), _) | (_, Err(e)) => return Ok(Err(format!("the static probe failed ({e})"))),
    };
    let g0 = y1 - y0;
    let settled = ((y1 - y1_prev) - (y0 - y0_prev)).abs() < 0.01 * g0.abs();
    if !(g0.is_finite() && g0 != 0.0 && settled) {
        return Ok(Err(format!(
            "the nominal plant from {to} to {measured} has no static gain (it integrates or does not settle)"
        )));
    }
    Ok(Ok((r, g0, y0)))
}

/// Anti-windup for a saturation on the drive into `to`: when the block driving
/// `to` is a core `pid` or `pi` (directly, or through a scalar `gain` k: the
/// limits ÷ k), that controller itself gets the fitted limits
/// as its output limits (intersected with any it has) and clamping
/// (conditional integration), or keeps back-calculation if it already uses it;
/// no block is inserted. Otherwise (or when it already limits itself within the
/// fitted limits with anti-windup on) a stated "no compensator" saying what to
/// do, with how often the loop asks for more than the limits.
fn anti_windup(
    e: &crate::NamedEffect,
    params: &Value,
    to: &str,
    controller: &GraphSpec,
    info: &LoopInfo,
) -> Result<Outcome, CompError> {
    let (lo, hi) = (num(params, "lower"), num(params, "upper"));
    if !(lo.is_finite() && hi.is_finite() && lo <= hi) {
        return Err(CompError::Design {
            effect: e.effect.clone(),
            problem: format!(
                "the fitted saturation's limits [{lo:e}, {hi:e}] are not finite with lower ≤ upper: give the model_augmented.yaml that `nanomotion diagnose` wrote"
            ),
        });
    }
    let share = clipped_share(controller, to, info.from_s, lo, hi);
    // Over the whole run too: a step's windup happens before a window that
    // starts after the move.
    let run_share = clipped_share(controller, to, 0.0, lo, hi);
    let asks = match (share, run_share) {
        (Some(p), Some(q)) => format!(
            "your loop on the nominal plant asks for more than the limits {:.1} % of the scored window ({:.1} % of the whole run)",
            100.0 * p,
            100.0 * q
        ),
        _ => "the command into the limits could not be simulated".into(),
    };
    let figures = [
        ("lower", lo),
        ("upper", hi),
        ("clipped_share", share.unwrap_or(f64::NAN)),
        ("clipped_share_run", run_share.unwrap_or(f64::NAN)),
    ];
    let driver_of = |input: &str| {
        source_of(controller, input)
            .map(|s| split(s).0.to_string())
            .and_then(|d| controller.blocks.iter().find(|b| b.name == d))
    };
    let mut found = driver_of(to);
    // A static gain k between the controller and the limited input (an
    // amplifier, a unit conversion): the controller's output is limited to
    // the fitted limits divided by k (their order swapped when k < 0).
    let mut through: Option<(String, f64)> = None;
    if let Some(g) = found
        && let json = surgery::block_to_json(g.block.as_ref())
        && json.get("type").and_then(Value::as_str) == Some("gain")
        && let Some(k) = json.get("k").and_then(Value::as_f64)
        && k.is_finite()
        && k != 0.0
        && json.get("width").and_then(Value::as_u64).unwrap_or(1) == 1
    {
        through = Some((g.name.clone(), k));
        found = driver_of(&format!("{}.u", g.name));
    }
    let (lo, hi) = match &through {
        Some((_, k)) if *k > 0.0 => (lo / k, hi / k),
        Some((_, k)) => (hi / k, lo / k),
        None => (lo, hi),
    };
    let via = through.as_ref().map_or(String::new(), |(g, k)| {
        format!(" through the gain `{g}` (k = {k:?})")
    });
    let Some(spec) = found else {
        return Ok(none(
            &e.effect,
            format!(
                "no compensator: nothing in your graph drives `{to}`, so no controller can be given the limits [{lo:.4e}, {hi:.4e}]"
            ),
            &figures,
        ));
    };
    let b = spec.name.clone();
    let current = surgery::block_to_json(spec.block.as_ref());
    let ty = current.get("type").and_then(Value::as_str).unwrap_or("");
    if ty != "pid" && ty != "pi" {
        return Ok(none(
            &e.effect,
            format!(
                "no compensator: anti-windup needs the controller to know the limits, and `{to}` is driven{via} by `{b}`, a `{ty}` block, which has no output limits. Fix: if `{b}` is a PID or PI, write it as a core `pid` (kp, ki, kd, derivative_cutoff_hz) or `pi` block driving `{to}` directly, and `nanomotion compensate` gives it `output_min: {lo:?}`, `output_max: {hi:?}` with `anti_windup: clamping` and validates it; otherwise keep its reference moves within what [{lo:.4e}, {hi:.4e}] can follow ({asks})"
            ),
            &figures,
        ));
    }
    let old = |k: &str| current.get(k).and_then(Value::as_f64);
    let (old_lo, old_hi) = (old("output_min"), old("output_max"));
    let scheme = current
        .get("anti_windup")
        .and_then(Value::as_str)
        .unwrap_or("clamping")
        .to_string();
    let limited = old_lo.is_some() || old_hi.is_some();
    let (new_lo, new_hi) = (
        old_lo.map_or(lo, |m| m.max(lo)),
        old_hi.map_or(hi, |m| m.min(hi)),
    );
    if new_lo > new_hi {
        return Ok(none(
            &e.effect,
            format!(
                "no compensator: `{b}`'s own output limits [{}, {}] do not overlap the fitted saturation [{lo:.4e}, {hi:.4e}]; fix: set its `output_min`/`output_max` within the fitted limits",
                old_lo.unwrap_or(f64::NEG_INFINITY),
                old_hi.unwrap_or(f64::INFINITY)
            ),
            &figures,
        ));
    }
    if limited && scheme != "none" && old_lo == Some(new_lo) && old_hi == Some(new_hi) {
        return Ok(none(
            &e.effect,
            format!(
                "no compensator needed: `{b}` already limits its output to [{new_lo:.4e}, {new_hi:.4e}], within the fitted saturation [{lo:.4e}, {hi:.4e}], with `{scheme}` anti-windup ({asks})"
            ),
            &figures,
        ));
    }
    // Clamping needs no tuning (the integrator holds while the output is at a
    // limit and the error pushes further); a back-calculation the user chose
    // is kept with its tracking time.
    let scheme = if scheme == "back_calculation" {
        scheme
    } else {
        "clamping".to_string()
    };
    let mut block = current.clone();
    block["output_min"] = json!(new_lo);
    block["output_max"] = json!(new_hi);
    block["anti_windup"] = json!(scheme);
    let mut design = vec![
        ("lower", num(params, "lower")),
        ("upper", num(params, "upper")),
        ("gain_between", through.as_ref().map_or(f64::NAN, |t| t.1)),
        ("output_min", new_lo),
        ("output_max", new_hi),
        ("clipped_share", share.unwrap_or(f64::NAN)),
        ("clipped_share_run", run_share.unwrap_or(f64::NAN)),
    ];
    design.retain(|(_, v)| v.is_finite());
    let how = if scheme == "clamping" {
        "clamping (conditional integration: the integrator holds while the output is at a limit and the error pushes further)"
    } else {
        "back-calculation (your pid's scheme, kept: the excess u − v fed back into the integrator)"
    };
    Ok(Outcome::Compensator(Compensator {
        effect: e.effect.clone(),
        name: b.clone(),
        block,
        why: format!(
            "anti-windup: no block inserted; your `{ty}` `{b}` is given the fitted saturation's limits{} as its output limits with {how}, so its integrator stops winding up on the error the actuator cannot act on",
            if via.is_empty() {
                String::new()
            } else {
                format!(" divided by the gain between them{via}")
            }
        ),
        place: format!(
            "the controller `{b}` itself (output_min, output_max, anti_windup), which drives {to}{via}"
        ),
        design: design.iter().map(|(k, v)| (k.to_string(), *v)).collect(),
        note: Some(format!(
            "{asks}{}",
            if limited {
                format!(
                    "; its own limits [{}, {}] are intersected with the fitted ones",
                    old_lo.unwrap_or(f64::NEG_INFINITY),
                    old_hi.unwrap_or(f64::INFINITY)
                )
            } else {
                String::new()
            }
        )),
        edit: Edit::Limits {
            block: b,
            lower: new_lo,
            upper: new_hi,
            scheme,
        },
    }))
}

/// Share of the samples from `from_s` on where the command into `to` lies
/// outside [lo, hi], in the user's loop on the nominal plant.
fn clipped_share(controller: &GraphSpec, to: &str, from_s: f64, lo: f64, hi: f64) -> Option<f64> {
    let command = source_of(controller, to)?.to_string();
    let mut g = surgery::clone_spec(controller).ok()?;
    g.log = vec![command];
    g.score.clear();
    let (mut sched, _) = g.build().ok()?;
    let run = sched.run(|_| {});
    let log = run.logs.first()?;
    let from = (from_s * log.rate_hz).ceil() as usize;
    let u = log.data.get(from..)?;
    (!u.is_empty()).then(|| u.iter().filter(|&&v| v < lo || v > hi).count() as f64 / u.len() as f64)
}

/// The exact discrete inverse of the `creep` block (terms (k_i, τ_i), ZOH at
/// `dt`): with a_i = e^{−dt/τ_i}, the creep is x⁺ = a x + (1 − a)u, y = u + kᵀx,
/// so u = w − kᵀx and x⁺ = (diag a − (1 − a)kᵀ)x + (1 − a)w. `None` when that
/// is unstable or a term is not finite.
fn creep_inverse(terms: &[(f64, f64)], dt: f64) -> Option<Value> {
    let n = terms.len();
    if n == 0
        || terms
            .iter()
            .any(|(k, t)| !(k.is_finite() && t.is_finite() && *t > 0.0))
    {
        return None;
    }
    let a: Vec<f64> = terms.iter().map(|(_, t)| (-dt / t).exp()).collect();
    let rows: Vec<Vec<f64>> = (0..n)
        .map(|i| {
            (0..n)
                .map(|j| if i == j { a[i] } else { 0.0 } - (1.0 - a[i]) * terms[j].0)
                .collect()
        })
        .collect();
    let m = nalgebra::DMatrix::from_fn(n, n, |i, j| rows[i][j]);
    if m.complex_eigenvalues().iter().any(|z| z.norm() >= 1.0) {
        return None;
    }
    Some(json!({
        "type": "state_space",
        "a": rows,
        "b": a.iter().map(|ai| vec![1.0 - ai]).collect::<Vec<_>>(),
        "c": [terms.iter().map(|t| -t.0).collect::<Vec<_>>()],
        "d": [[1.0]],
        "discrete": true,
    }))
}

/// 1/g on 65 points over centre ± 2·scale of a fitted `position_dependent_gain`
/// (`None` when g ≤ 0 there).
fn inverse_gain_table(params: &Value) -> Option<(Vec<f64>, Vec<f64>)> {
    let centre = params.get("center").and_then(Value::as_f64).unwrap_or(0.0);
    let scale = params.get("scale").and_then(Value::as_f64).unwrap_or(1.0);
    let g0 = params.get("g0").and_then(Value::as_f64).unwrap_or(0.0);
    let coeffs: Vec<f64> = params
        .get("coeffs")?
        .as_array()?
        .iter()
        .filter_map(Value::as_f64)
        .collect();
    let g = |s: f64| {
        let x = (s - centre) / scale;
        1.0 + g0 + coeffs.iter().rev().fold(0.0, |acc, c| (acc + c) * x)
    };
    let n = 65;
    let xs: Vec<f64> = (0..n)
        .map(|i| centre + scale * (-2.0 + 4.0 * i as f64 / (n - 1) as f64))
        .collect();
    let gains: Vec<f64> = xs.iter().map(|&s| 1.0 / g(s)).collect();
    gains
        .iter()
        .all(|k| k.is_finite() && *k > 0.0)
        .then_some((xs, gains))
}

/// The plant input upstream of the measured `signal`: walk up through single-input
/// blocks (sensors, demux) to a block with the plant role, and take the
/// connection into it.
fn plant_input(
    controller: &GraphSpec,
    signal: &str,
    effect: &str,
    opts: &Options,
) -> Result<String, CompError> {
    let role = |name: &str| {
        controller
            .blocks
            .iter()
            .find(|b| b.name == name)
            .map(|b| b.block.role())
    };
    let mut b = split(signal).0.to_string();
    for _ in 0..8 {
        let into: Vec<&str> = controller
            .connections
            .iter()
            .filter(|c| split(&c.to).0 == b)
            .map(|c| c.to.as_str())
            .collect();
        // The plant: a block with the plant role, or the one the controller drives.
        let driven = into.len() == 1
            && source_of(controller, into[0])
                .is_some_and(|src| role(split(src).0) == Some(Role::Controller));
        if (role(&b) == Some(Role::Plant) || driven) && !into.is_empty() {
            return Ok(into[0].to_string());
        }
        match into.as_slice() {
            [one] => {
                b = split(source_of(controller, one).unwrap_or(""))
                    .0
                    .to_string();
            }
            _ => break,
        }
    }
    Err(CompError::NoPlace {
        graph: opts.controller_name.clone(),
        effect: effect.to_string(),
        problem: format!(
            "no plant (a block with the plant role, or driven by a controller) upstream of `{signal}`"
        ),
        fix: "measure the plant's output through single-input blocks (sensor, demux)".into(),
    })
}

/// The controller input fed by the scored error (where RC adds its output).
fn controller_input(
    e: &crate::NamedEffect,
    controller: &GraphSpec,
    info: &LoopInfo,
    opts: &Options,
) -> Result<String, CompError> {
    // The reader with the controller role, or the only reader (a plain gain).
    let readers: Vec<&str> = controller
        .connections
        .iter()
        .filter(|c| c.from == info.error)
        .map(|c| c.to.as_str())
        .collect();
    let is_controller = |to: &&&str| {
        controller
            .blocks
            .iter()
            .any(|b| b.name == split(to).0 && b.block.role() == Role::Controller)
    };
    readers
        .iter()
        .find(is_controller)
        .or(if readers.len() == 1 { readers.first() } else { None })
        .map(|to| to.to_string())
        .ok_or_else(|| CompError::NoPlace {
            graph: opts.controller_name.clone(),
            effect: e.effect.clone(),
            problem: format!(
                "no controller reads the scored error `{}`: repetitive control adds its output to the error before the feedback controller (Fig. 5.1)",
                info.error
            ),
            fix: "score the error signal that feeds the controller".into(),
        })
}

/// A learning block's design from the loop: L = ZPETC(T) of the loop's T (the
/// stability gate's model of the user's graph with the block's output removed),
/// Q the FIR of the largest cut-off keeping (5.5)/(5.9) for delays
/// [n_min, n_max] with 10 % margin, and the criterion.
struct LearningDesign {
    learning: FilterSpec,
    robustness: FilterSpec,
    taps: usize,
    cutoff_hz: f64,
    criterion: dvrc::stability::RcCriterion,
    preview: usize,
}

fn design_learning(
    trial: &Compensator,
    controller: &GraphSpec,
    opts: &Options,
    dt: f64,
    n_min: usize,
    n_max: usize,
) -> Result<LearningDesign, CompError> {
    let design_err = |problem: String| CompError::Design {
        effect: trial.effect.clone(),
        problem,
    };
    let mut g = crate::clone(controller, &opts.controller_name)?;
    trial.apply(&mut g, controller, opts)?;
    let ts = dvrc::check::graph_loop_ts(g).map_err(design_err)?;
    let t = ts.get(&trial.name).ok_or_else(|| {
        design_err(format!(
            "the stability gate found no loop T(z) for `{}` (is the loop linear? `nanomotion check --print-loop` shows it)",
            trial.name
        ))
    })?;
    let tf = t.to_tf().map_err(|e| design_err(format!("T(z): {e}")))?;
    let learning = FilterSpec::Zpetc {
        num: tf.num.clone(),
        den: tf.den.clone(),
    };
    let l = learning
        .build_named("learning", dt)
        .map_err(|e| design_err(format!("L = ZPETC(T): {e}")))?;
    let taps = 31usize.min(if n_min.is_multiple_of(2) {
        n_min - 1
    } else {
        n_min - 2
    });
    let qd = design_q_cutoff(t, &l, taps, n_max - n_min, 0.1)
        .map_err(|e| design_err(format!("Q: {e}")))?;
    let robustness = FilterSpec::FirLowpass {
        taps,
        cutoff_hz: qd.cutoff_hz,
    };
    let q = robustness
        .build_named("robustness", dt)
        .map_err(|e| design_err(format!("Q: {e}")))?;
    let c =
        rc_criterion(t, &l, &q, n_min, n_max).map_err(|e| design_err(format!("criterion: {e}")))?;
    if !c.holds() {
        return Err(design_err(format!(
            "criterion {} fails with the designed Q: ‖Q(1 − T L z^l)‖∞ = {:.3} ≥ {:.3}",
            if n_min == n_max { "(5.5)" } else { "(5.9)" },
            c.hinf,
            c.bound
        )));
    }
    Ok(LearningDesign {
        learning,
        robustness,
        taps,
        cutoff_hz: qd.cutoff_hz,
        criterion: c,
        preview: l.preview_samples(),
    })
}

fn learning_figures(d: &LearningDesign, tag: &str) -> Vec<(String, f64)> {
    vec![
        ("q_taps".into(), d.taps as f64),
        ("q_cutoff_hz".into(), d.cutoff_hz),
        (format!("criterion_{tag}_hinf"), d.criterion.hinf),
        (format!("criterion_{tag}_bound"), d.criterion.bound),
        (format!("criterion_{tag}_peak_hz"), d.criterion.peak_hz),
        ("l_preview".into(), d.preview as f64),
    ]
}

/// Standard RC (5.1) on a disturbance periodic in time: N from the fitted period
/// at the controller's rate, L and Q from [`design_learning`], (5.5) reported.
fn repetitive(
    e: &crate::NamedEffect,
    params: &Value,
    controller: &GraphSpec,
    info: &LoopInfo,
    opts: &Options,
    name: &str,
) -> Result<Outcome, CompError> {
    let ctrl_in = controller_input(e, controller, info, opts)?;
    let rate = surgery::rate_of(controller, split(&ctrl_in).0).unwrap_or(controller.base_rate_hz);
    let dt = 1.0 / rate;
    let period = num(params, "period");
    let exact = period * rate;
    let n = exact.round();
    if !(8.0..=1e7).contains(&n) {
        return Err(CompError::Design {
            effect: e.effect.clone(),
            problem: format!(
                "the period {period:e} s is {exact:.1} samples at the controller's {rate} Hz: repetitive control needs 8 to 10⁷"
            ),
        });
    }
    let n = n as usize;
    let edit = Edit::Learning {
        error: info.error.clone(),
        controller_input: ctrl_in.clone(),
        alpha: None,
    };
    let trial = Compensator {
        effect: e.effect.clone(),
        name: name.to_string(),
        block: json!({"type": "repetitive_control", "n": n}),
        why: String::new(),
        place: String::new(),
        design: BTreeMap::new(),
        note: None,
        edit: edit.clone(),
    };
    let d = design_learning(&trial, controller, opts, dt, n, n)?;
    let block = json!({
        "type": "repetitive_control",
        "n": n,
        "learning": serde_json::to_value(&d.learning).unwrap_or(Value::Null),
        "robustness": serde_json::to_value(&d.robustness).unwrap_or(Value::Null),
    });
    let off = exact - n as f64;
    let mut design: BTreeMap<String, f64> = [
        ("n".to_string(), n as f64),
        ("period_s".to_string(), period),
        ("period_samples".to_string(), exact),
    ]
    .into_iter()
    .collect();
    design.extend(learning_figures(&d, "5_5"));
    Ok(Outcome::Compensator(Compensator {
        effect: e.effect.clone(),
        name: name.to_string(),
        block,
        why: "standard repetitive control (5.1): memory of one period N, L = ZPETC of the loop's T, Q the FIR low-pass with the largest cut-off keeping (5.5)".into(),
        place: format!("on the error {} before {} (Fig. 5.1)", info.error, ctrl_in),
        design,
        note: (off.abs() > 0.05).then(|| {
            format!(
                "the period is {exact:.2} samples; N = {n} leaves {off:+.2} samples per period, which the memory cannot learn exactly"
            )
        }),
        edit,
    }))
}

/// The shortest and longest number of samples of `log` (at its rate) that
/// the signal `x` takes to advance one `period`, over `x`: for each sample k,
/// k − j with j the last sample at or below x_k − period. Errors when the signal
/// does not advance two periods or moves backwards.
fn advance_range(x: &[f64], period: f64, alpha: &str, which: &str) -> Result<(f64, f64), String> {
    if period.is_nan() || period <= 0.0 || x.len() < 2 || x[x.len() - 1] - x[0] < 2.0 * period {
        return Err(format!(
            "`{alpha}` advances {:.3e} over the scored window of {which}, less than two periods ({:.3e}): delay-varying RC needs the signal to move forward through the period",
            x.last().zip(x.first()).map_or(0.0, |(b, a)| b - a),
            2.0 * period
        ));
    }
    if x.windows(2).any(|w| w[1] < w[0]) {
        return Err(format!(
            "`{alpha}` moves backwards in the scored window of {which}: the delay-varying memory follows a signal that only advances (DVRC, (5.7))"
        ));
    }
    let (mut lo, mut hi) = (f64::INFINITY, 0.0f64);
    let mut j = 0usize;
    for k in 0..x.len() {
        while j + 1 < k && x[j + 1] <= x[k] - period {
            j += 1;
        }
        if x[j] <= x[k] - period {
            lo = lo.min((k - j) as f64);
            hi = hi.max((k - j) as f64);
        }
    }
    Ok((lo, hi))
}

/// The shortest and longest delay k − j over a record `x` of the signal, j the
/// latest sample before k at or below x_k − `period` (the sample the DVRC's
/// memory reads back to): unlike [`advance_range`], a record from a real
/// stage may step back a little (a walking stage's legs slip); it must
/// advance at least two periods overall.
fn measured_range(x: &[f64], period: f64, alpha: &str) -> Result<(f64, f64), String> {
    let advance = x.last().zip(x.first()).map_or(0.0, |(b, a)| b - a);
    if period.is_nan() || period <= 0.0 || advance.is_nan() || advance < 2.0 * period {
        return Err(format!(
            "`{alpha}` advances {advance:.3e} over the record, less than two periods ({:.3e})",
            2.0 * period
        ));
    }
    let (mut lo, mut hi) = (f64::INFINITY, 0.0f64);
    let mut low = f64::INFINITY;
    for k in 0..x.len() {
        let target = x[k] - period;
        if low <= target
            && let Some(j) = (0..k).rev().find(|&j| x[j] <= target)
        {
            lo = lo.min((k - j) as f64);
            hi = hi.max((k - j) as f64);
        }
        low = low.min(x[k]);
    }
    Ok((lo, hi))
}

/// The delay range (controller samples at `rate`) that `alpha` takes to
/// advance one `period` over the scored window of `graph` run as it is.
fn loop_delay_range(
    graph: &GraphSpec,
    alpha: &str,
    period: f64,
    info: &LoopInfo,
    rate: f64,
    which: &str,
) -> Result<(f64, f64), String> {
    let mut g = crate::clone(graph, which).map_err(|e| e.to_string())?;
    g.log = vec![alpha.to_string()];
    g.score.clear();
    let (mut sched, _) = g.build().map_err(|e| format!("{which}: {e}"))?;
    let run = sched.run(|_| {});
    let log = run.logs.first().ok_or_else(|| format!("{which}: no log"))?;
    let from = (info.from_s * log.rate_hz).ceil() as usize;
    let x = log.data.get(from..).unwrap_or(&[]);
    let (lo, hi) = advance_range(x, period, alpha, which)?;
    let scale = rate / log.rate_hz;
    Ok((lo * scale, hi * scale))
}

/// Delay-varying RC (5.7)–(5.8) on a disturbance periodic in a signal (the
/// position, or the drive's phase α = 2π∫f_α computed in the loop): α = that
/// signal, P_α the fitted period, the delay range [m, M] from the loops'
/// motion — the user's loop on the nominal plant and on the plant as
/// diagnosed (how many controller samples the signal takes to advance one
/// period over the scored window), their union widened by
/// [`Options::delay_margin`] for the variation of N_k that neither model
/// shows (a walking stage's irregular steps) — and L and Q from
/// [`design_learning`] with (5.9) for that range. The `dvrc` block's `alpha`
/// is a scheduling input, so a phase integrated from the controller's output
/// inside the loop does not put the integrator's pole into the loop the gate
/// judges.
#[allow(clippy::too_many_arguments)]
fn delay_varying(
    e: &crate::NamedEffect,
    params: &Value,
    alpha: &str,
    controller: &GraphSpec,
    diagnosed: &GraphSpec,
    info: &LoopInfo,
    opts: &Options,
    name: &str,
) -> Result<Outcome, CompError> {
    let design_err = |problem: String| CompError::Design {
        effect: e.effect.clone(),
        problem,
    };
    if !crate::has_block(controller, split(alpha).0) {
        return Err(CompError::NoPlace {
            graph: opts.controller_name.clone(),
            effect: e.effect.clone(),
            problem: format!(
                "has no block `{}` for the signal `{alpha}` the disturbance is periodic in",
                split(alpha).0
            ),
            fix: "name the signal (the plant's position, or the block computing the drive's phase) as in the model you diagnosed".into(),
        });
    }
    let ctrl_in = controller_input(e, controller, info, opts)?;
    let rate = surgery::rate_of(controller, split(&ctrl_in).0).unwrap_or(controller.base_rate_hz);
    let period = num(params, "period");
    let (lo0, hi0) = loop_delay_range(
        controller,
        alpha,
        period,
        info,
        rate,
        "your loop on the nominal plant",
    )
    .map_err(design_err)?;
    let (lo1, hi1) = loop_delay_range(
        diagnosed,
        alpha,
        period,
        info,
        rate,
        "your loop on the plant as diagnosed",
    )
    .map_err(design_err)?;
    let (mut lo, mut hi) = (lo0.min(lo1), hi0.max(hi1));
    // A record of the signal from your loop on the real stage (Fig. 5.7).
    let mut measured = None;
    if let Some(m) = opts.measured.iter().find(|m| m.signal == alpha) {
        let place = m.origin.clone();
        if !(m.rate_hz.is_finite() && m.rate_hz > 0.0) {
            return Err(CompError::Input {
                place,
                problem: format!("its rate is {} Hz", m.rate_hz),
                fix: "give the record's sample rate in Hz, > 0".into(),
            });
        }
        if let Some(i) = m.values.iter().position(|v| !v.is_finite()) {
            return Err(CompError::Input {
                place,
                problem: format!("sample {i} is {}", m.values[i]),
                fix: "give a record of finite samples".into(),
            });
        }
        let (a, b) =
            measured_range(&m.values, period, alpha).map_err(|problem| CompError::Input {
                place: m.origin.clone(),
                problem,
                fix: "record your loop where the signal moves forward through at least two periods"
                    .into(),
            })?;
        let scale = rate / m.rate_hz;
        let (a, b) = (a * scale, b * scale);
        lo = lo.min(a);
        hi = hi.max(b);
        measured = Some((a, b));
    }
    let margin = opts.delay_margin.unwrap_or(if measured.is_some() {
        crate::DELAY_MARGIN_MEASURED
    } else {
        crate::DELAY_SPREAD_UNMEASURED
    });
    let n_min = ((lo * (1.0 - margin)).floor() as usize).saturating_sub(1);
    let n_max = (hi * (1.0 + margin)).ceil() as usize + 1;
    if n_min < 8 || n_max > 10_000_000 {
        return Err(design_err(format!(
            "the delay ranges over [{n_min}, {n_max}] samples: delay-varying RC needs 8 to 10⁷"
        )));
    }
    let edit = Edit::Learning {
        error: info.error.clone(),
        controller_input: ctrl_in.clone(),
        alpha: Some(alpha.to_string()),
    };
    let base = json!({"type": "dvrc", "period_alpha": period, "n_min": n_min, "n_max": n_max});
    let trial = Compensator {
        effect: e.effect.clone(),
        name: name.to_string(),
        block: base.clone(),
        why: String::new(),
        place: String::new(),
        design: BTreeMap::new(),
        note: None,
        edit: edit.clone(),
    };
    let d = design_learning(&trial, controller, opts, 1.0 / rate, n_min, n_max)?;
    let mut block = base;
    block["learning"] = serde_json::to_value(&d.learning).unwrap_or(Value::Null);
    block["robustness"] = serde_json::to_value(&d.robustness).unwrap_or(Value::Null);
    let mut design: BTreeMap<String, f64> = [
        ("period".to_string(), period),
        ("n_min".to_string(), n_min as f64),
        ("n_max".to_string(), n_max as f64),
        ("delay_nominal_min".to_string(), lo0),
        ("delay_nominal_max".to_string(), hi0),
        ("delay_diagnosed_min".to_string(), lo1),
        ("delay_diagnosed_max".to_string(), hi1),
        ("delay_margin".to_string(), margin),
    ]
    .into_iter()
    .collect();
    if let Some((a, b)) = measured {
        design.insert("delay_measured_min".into(), a);
        design.insert("delay_measured_max".into(), b);
    }
    design.extend(learning_figures(&d, "5_9"));
    Ok(Outcome::Compensator(Compensator {
        effect: e.effect.clone(),
        name: name.to_string(),
        block,
        why: format!(
            "delay-varying repetitive control (5.7)–(5.8) on {alpha}: the memory delay N_k follows the signal over one period, N_k ∈ [{n_min}, {n_max}] (your loop's range on the nominal plant{} and on the plant as diagnosed, ±{:.1} %{}), L = ZPETC of the loop's T, Q the FIR low-pass with the largest cut-off keeping (5.9)",
            if measured.is_some() {
                ", in the measured record"
            } else {
                ""
            },
            100.0 * margin,
            match (opts.delay_margin, measured) {
                (Some(_), _) => " as given",
                (None, Some(_)) => " beyond the record",
                (None, None) =>
                    ": the spread of the delay the thesis measured on its stage, Fig. 5.7, which no model shows",
            }
        ),
        place: format!(
            "on the error {} before {} (Fig. 5.1), α = {alpha}",
            info.error, ctrl_in
        ),
        design,
        note: match measured {
            // The validation runs on the augmented model, which is periodic in
            // the signal like the nominal: it cannot show a range too narrow.
            None => Some(format!(
                "the validation on the augmented model cannot tell whether [{n_min}, {n_max}] covers how far the real stage's period in {alpha} moves (no model shows it): a record of {alpha} from your loop on the stage without RC sizes the range (Fig. 5.7); a range too narrow pins N_k at its ends and can make the error worse"
            )),
            // The stage moves the signal at another speed than the models: a
            // gain of the nominal is off, and L = ZPETC(T) is designed on it.
            Some((a, b)) if b < lo0.min(lo1) || a > hi0.max(hi1) => Some(format!(
                "the record's delays {a} … {b} do not overlap your loops' {} … {}: the stage takes {:.2}× as many samples per period as your nominal plant and the plant as diagnosed, so a gain of the nominal is off (a walking stage's step per cycle?) — L = ZPETC of the loop's T is designed on it; correct the nominal plant and run `nanomotion diagnose` again",
                lo0.min(lo1),
                hi0.max(hi1),
                (a + b) / (lo0.min(lo1) + hi0.max(hi1))
            )),
            Some(_) => None,
        },
        edit,
    }))
}

/// The slit-error correction of a fitted `encoder_slit_error` (y = u + e[⌊(u −
/// origin)/pitch⌋ mod N]) on the reading `signal`: hots' `slit_correction`
/// with the table ê = −e/pitch in counts, Δ = pitch and count 0 read at slit
/// 0's centre, origin + pitch/2 ([`hots::SlitCorrection::inverse_of_slit_errors`]).
/// On a reading quantised to the slits' centres (a quantiser of lsb = pitch
/// before the errors, as the diagnosis fits them) it gives back the quantised
/// position exactly; the design figure `noise_margin` is how far a reading may
/// move (noise) and still be put on its own slit: half the smallest |j + (e_k −
/// e_{k−j})/pitch|·pitch over the slits k and the other counts j searched.
fn slit_correction(
    e: &crate::NamedEffect,
    params: &Value,
    signal: &str,
    controller: &GraphSpec,
) -> Result<Outcome, CompError> {
    let design_err = |problem: String| CompError::Design {
        effect: e.effect.clone(),
        problem,
    };
    let (pitch, origin) = (num(params, "pitch"), num(params, "origin"));
    let errors: Vec<f64> = params
        .get("errors")
        .and_then(Value::as_array)
        .map(|v| v.iter().map(|x| x.as_f64().unwrap_or(f64::NAN)).collect())
        .unwrap_or_default();
    let mut block = hots::SlitCorrection::inverse_of_slit_errors(pitch, origin, &errors);
    nanomotion_core::Block::build(
        &mut block,
        &nanomotion_core::BuildContext::new("comp_encoder_slit_error", 1.0, 0),
    )
    .map_err(|err| {
        design_err(format!(
            "the fitted slit errors (pitch {pitch:e}, origin {origin:e}, {} entries) give no table: {err}; give the model_augmented.yaml that `nanomotion diagnose` wrote",
            errors.len()
        ))
    })?;
    let n = errors.len() as i64;
    let largest = errors.iter().fold(0.0f64, |m, x| m.max(x.abs()));
    // Every count the block can search, from any slit's reading.
    let reach = 2 * ((largest / pitch).ceil() as i64 + 1);
    let mut closest = f64::INFINITY;
    for k in 0..n {
        for j in (-reach..=reach).filter(|&j| j != 0) {
            let other = errors[(k - j).rem_euclid(n) as usize];
            closest = closest.min((j as f64 + (errors[k as usize] - other) / pitch).abs());
        }
    }
    // Exact where the reading before the errors is on the slits' centres.
    let quantiser = controller
        .blocks
        .iter()
        .find(|b| b.name == split(signal).0)
        .map(|b| surgery::block_to_json(b.block.as_ref()))
        .filter(|b| b.get("type").and_then(Value::as_str) == Some("quantizer"));
    let on_centres = quantiser.is_some_and(|q| {
        let lsb = num(&q, "lsb");
        let offset = q.get("offset").and_then(Value::as_f64).unwrap_or(0.0);
        let shift = (origin + 0.5 * pitch - offset) / pitch;
        (lsb - pitch).abs() <= 1e-9 * pitch && (shift - shift.round()).abs() < 1e-9
    });
    let note = (!on_centres).then(|| {
        format!(
            "`{signal}` is not a quantiser of lsb {pitch:e} whose levels are the slits' centres: the table puts each reading on the nearest slit centre, exact only for positions on them"
        )
    });
    Ok(Outcome::Compensator(Compensator {
        effect: e.effect.clone(),
        name: format!("comp_{}", e.effect),
        block: json!({
            "type": "slit_correction",
            "resolution": block.resolution,
            "zero": block.zero,
            "edge_offsets_counts": block.edge_offsets_counts,
        }),
        why: "slit-error correction table (the hots calibration's per-edge table ê = −e/pitch, counts): each reading goes back to its slit's centre, so the loop acts on the position, not on the encoder's line errors".into(),
        place: format!("in the measurement path after {signal}, before every reader"),
        design: [
            ("pitch", pitch),
            ("slits", errors.len() as f64),
            ("largest_error", largest),
            ("noise_margin", 0.5 * closest * pitch),
        ]
        .iter()
        .map(|(k, v)| (k.to_string(), *v))
        .collect(),
        note,
        edit: Edit::Reading {
            signal: signal.to_string(),
        },
    }))
}

/// The fitted drift's (offset, rate, curvature) (`params`: the `drift`
/// block), each finite, or why not.
fn drift_terms(e: &crate::NamedEffect, params: &Value) -> Result<[f64; 3], CompError> {
    let terms = ["offset", "rate", "curvature"].map(|k| num(params, k));
    if terms.iter().all(|v| v.is_finite()) {
        Ok(terms)
    } else {
        Err(CompError::Design {
            effect: e.effect.clone(),
            problem: format!(
                "the fitted drift's offset, rate and curvature {terms:?} are not all finite: give the model_augmented.yaml that `nanomotion diagnose` wrote"
            ),
        })
    }
}

/// A drift on the drive into `to` (an amplifier's zero that is off, a
/// constant force): its offset o fed forward, −o added to the drive before
/// the actuator ([`crate::DriveOffset`], so the pair is the identity to
/// round-off). A fitted trend (rate, curvature) is the time since the
/// record started, not of the next run: not fed forward, said in the note.
/// Integral action of the controller driving `to` is noted: it removes the
/// offset in steady state; the feed-forward removes it from the start.
fn drift_offset(
    e: &crate::NamedEffect,
    params: &Value,
    to: &str,
    controller: &GraphSpec,
) -> Result<Outcome, CompError> {
    let [o, rate, curvature] = drift_terms(e, params)?;
    if o == 0.0 {
        return Ok(none(
            &e.effect,
            format!(
                "no compensator: the fitted drift on the drive into {to} has no offset to feed forward (offset {o:e}); a drift of the drive that is a trend is followed by your loop's integral action with an error of about rate/k_i"
            ),
            &[("offset", o), ("rate", rate), ("curvature", curvature)],
        ));
    }
    let driver = source_of(controller, to)
        .map(|s| split(s).0)
        .and_then(|d| controller.blocks.iter().find(|b| b.name == d))
        .map(|b| (b.name.clone(), surgery::block_to_json(b.block.as_ref())));
    let integral = driver.as_ref().and_then(|(name, b)| {
        let ty = b.get("type").and_then(Value::as_str)?;
        let ki = match ty {
            "pid" => num(b, "ki"),
            // A `pi`: k_p(1 + 2π f_i/s).
            "pi" => num(b, "kp") * std::f64::consts::TAU * num(b, "zero_hz"),
            _ => return None,
        };
        (ki.is_finite() && ki != 0.0).then(|| (name.clone(), ki))
    });
    let mut notes = Vec::new();
    if let Some((name, ki)) = &integral {
        notes.push(format!(
            "your `{name}`'s integral action (k_i = {ki:e}) removes a constant offset in steady state; the feed-forward removes it from the start"
        ));
    }
    if rate != 0.0 || curvature != 0.0 {
        notes.push(format!(
            "the fitted trend (rate {rate:e}/s, curvature {curvature:e}/s²) is the time since the diagnosed record started, not of this run: not fed forward"
        ));
    }
    Ok(Outcome::Compensator(Compensator {
        effect: e.effect.clone(),
        name: format!("comp_{}", e.effect),
        block: json!({"type": "drive_offset", "offset": -o}),
        why: "offset feed-forward: the fitted offset of the drive subtracted before the actuator (a drive's zero that is off), so the plant gets the drive the controller asks for".into(),
        place: format!("before the actuator, on the connection into {to}"),
        design: [("offset", o)]
            .iter()
            .map(|(k, v)| (k.to_string(), *v))
            .collect(),
        note: (!notes.is_empty()).then(|| notes.join("; ")),
        edit: Edit::Before {
            to: to.to_string(),
            ff: None,
        },
    }))
}

/// A drift of the measured position `signal` (the sensor's zero moves): no
/// compensation. Feedback makes the reading follow the reference, so the
/// stage moves by the drift below the crossover (x = T(r − d)); integral
/// action makes that exact rather than helping. Figures: the fitted offset,
/// rate and curvature, and d(T) − d(t₀) over the scored window of the user's
/// graph, t₀ = `from_s`, T = `duration_s` — how far the stage moves while
/// the reading says it tracks.
fn drift_of_the_reading(
    e: &crate::NamedEffect,
    params: &Value,
    signal: &str,
    controller: &GraphSpec,
    info: &LoopInfo,
) -> Result<Outcome, CompError> {
    let [offset, rate, curvature] = drift_terms(e, params)?;
    let (t0, t1) = (info.from_s, controller.duration_s);
    // d(t) = offset + rate·t + curvature·t²: the offset cancels.
    let moved = rate * (t1 - t0) + curvature * (t1 * t1 - t0 * t0);
    Ok(none(
        &e.effect,
        format!(
            "no compensation: the drift is of the reading {signal} (the sensor's zero moves), which feedback cannot tell from motion: your loop holds the reading on the reference, so the stage moves by the drift instead (x = T(r − d), all of it below the crossover; integral action makes that exact). It limits the absolute position: {rate:.3e} per second, {moved:.3e} over your scored window [{t0} s, {t1} s]; what helps is a reference for the sensor's zero (an index mark, a second stable sensor, re-zeroing), not the controller"
        ),
        &[
            ("offset", offset),
            ("rate", rate),
            ("curvature", curvature),
            ("drift_over_window", moved),
        ],
    ))
}
