//! The effects `nanomotion diagnose` named, read from its `report.json` or from
//! the augmented model itself, and where each one enters the augmented model.

use crate::CompError;
use nanomotion_core::graph::GraphSpec;
use nanomotion_plf::effects::Effect;
use serde::{Deserialize, Serialize};

/// One effect named by the diagnosis: its vocabulary name and the block that
/// models it in the augmented model (`model_augmented.yaml`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct NamedEffect {
    /// Vocabulary name (`hysteresis`, `repetitive_disturbance`, ...).
    pub effect: String,
    /// The effect's block in the augmented model.
    pub block: String,
    /// Where it entered, in the diagnosis's words (for the report only: the place
    /// is read from the augmented graph's connections).
    #[serde(default)]
    pub site: String,
}

/// The named effects of a diagnosis report (its `steps`, in the order found).
pub fn from_report(report: &nanomotion_plf::Report) -> Vec<NamedEffect> {
    report
        .steps
        .iter()
        .map(|s| NamedEffect {
            effect: s.effect.clone(),
            block: s.block.name.clone(),
            site: s.site.clone(),
        })
        .collect()
}

/// The named effects of the `report.json` that `nanomotion diagnose` wrote
/// (`origin` names the file in errors).
pub fn from_report_json(text: &str, origin: &str) -> Result<Vec<NamedEffect>, CompError> {
    let bad = |problem: String| CompError::Input {
        place: origin.to_string(),
        problem,
        fix: "give the report.json that `nanomotion diagnose` wrote beside the augmented model"
            .into(),
    };
    let v: serde_json::Value =
        serde_json::from_str(text).map_err(|e| bad(format!("not JSON ({e})")))?;
    let steps = v
        .get("steps")
        .and_then(|s| s.as_array())
        .ok_or_else(|| bad("has no `steps` list: not a diagnosis report".into()))?;
    steps
        .iter()
        .enumerate()
        .map(|(i, s)| {
            let text = |path: &[&str]| -> Result<String, CompError> {
                let mut x = s;
                for p in path {
                    x = x.get(*p).unwrap_or(&serde_json::Value::Null);
                }
                x.as_str()
                    .map(str::to_string)
                    .ok_or_else(|| bad(format!("steps[{i}].{} is missing", path.join("."))))
            };
            Ok(NamedEffect {
                effect: text(&["effect"])?,
                block: text(&["block", "name"])?,
                site: text(&["site"]).unwrap_or_default(),
            })
        })
        .collect()
}

/// The effect blocks of an augmented model without its report: blocks named
/// `plf_<effect>…` whose type is one of that effect's block types
/// ([`Effect::block_types`]), in graph order (the order the diagnosis inserted
/// them).
pub fn from_graph(augmented: &GraphSpec) -> Vec<NamedEffect> {
    augmented
        .blocks
        .iter()
        .filter_map(|b| {
            let ty = b.block.typetag_name();
            let e = Effect::ALL.into_iter().find(|e| {
                e.block_types().contains(&ty)
                    && b.name
                        .strip_prefix("plf_")
                        .is_some_and(|rest| rest.starts_with(e.name()))
            })?;
            Some(NamedEffect {
                effect: e.name().to_string(),
                block: b.name.clone(),
                site: String::new(),
            })
        })
        .collect()
}

/// Where an effect block sits in the augmented model.
#[derive(Debug, Clone, PartialEq)]
pub(crate) enum Where {
    /// In series on the drive, ahead of the plant-side input `to`.
    Input { to: String },
    /// A force from `position` added to the plant input `to`.
    Feedback { to: String, position: String },
    /// On the measured output: it reads `signal`.
    Output { signal: String },
}

/// An effect's place and the signals on its port `s`.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct Placement {
    pub place: Where,
    pub s: Vec<String>,
}

pub(crate) fn split(reference: &str) -> (&str, &str) {
    reference.split_once('.').unwrap_or((reference, ""))
}

/// The source of the connection into `to`.
pub(crate) fn source_of<'a>(spec: &'a GraphSpec, to: &str) -> Option<&'a str> {
    spec.connections
        .iter()
        .find(|c| c.to == to)
        .map(|c| c.from.as_str())
}

/// Where `e`'s block sits in `aug`; `effect_blocks` are the names of every
/// effect block (an effect chain is followed through them).
pub(crate) fn locate(
    aug: &GraphSpec,
    e: &NamedEffect,
    effect_blocks: &[String],
    origin: &str,
) -> Result<Placement, CompError> {
    let name = e.block.as_str();
    let place_err = |problem: String| CompError::Input {
        place: format!("{origin}: block `{name}`"),
        problem,
        fix: "give the model_augmented.yaml that `nanomotion diagnose` wrote, unedited".into(),
    };
    if !aug.blocks.iter().any(|b| b.name == name) {
        return Err(CompError::Input {
            place: origin.to_string(),
            problem: format!(
                "has no block `{name}`, which the report names for `{}`",
                e.effect
            ),
            fix: "give the report.json written in the same folder as this model_augmented.yaml"
                .into(),
        });
    }
    let input = source_of(aug, &format!("{name}.u"))
        .ok_or_else(|| place_err("nothing is connected to its input `u`".into()))?
        .to_string();
    let is_effect = |b: &str| effect_blocks.iter().any(|n| n == b);
    // Signals on port `s`: one, or the inputs of its own `mux`.
    let s = match source_of(aug, &format!("{name}.s")) {
        None => Vec::new(),
        Some(src) if split(src).0.starts_with(&format!("{name}_mux")) => {
            let mux = split(src).0;
            let mut v: Vec<(usize, String)> = aug
                .connections
                .iter()
                .filter_map(|c| {
                    let (b, p) = split(&c.to);
                    (b == mux)
                        .then(|| p.strip_prefix("in")?.parse().ok())
                        .flatten()
                        .map(|k: usize| (k, c.from.clone()))
                })
                .collect();
            v.sort();
            v.into_iter().map(|(_, f)| f).collect()
        }
        Some(src) => vec![src.to_string()],
    };
    // Follow the output forward through other effects.
    let mut at = format!("{name}.y");
    for _ in 0..32 {
        if aug.compare.iter().any(|c| c.signal == at) {
            return Ok(Placement {
                place: Where::Output { signal: input },
                s,
            });
        }
        let dests: Vec<&str> = aug
            .connections
            .iter()
            .filter(|c| c.from == at)
            .map(|c| c.to.as_str())
            .collect();
        if let Some(sum) = dests
            .iter()
            .find(|d| split(d).0.starts_with(&format!("{name}_sum")))
        {
            let sum = split(sum).0;
            let to = aug
                .connections
                .iter()
                .find(|c| c.from == format!("{sum}.y"))
                .map(|c| c.to.clone())
                .ok_or_else(|| place_err(format!("its sum `{sum}` feeds nothing")))?;
            return Ok(Placement {
                place: Where::Feedback {
                    to,
                    position: input,
                },
                s,
            });
        }
        // The sum another effect added at the plant input passes the drive on.
        let helper_sum = |b: &str| {
            effect_blocks
                .iter()
                .any(|n| b.starts_with(&format!("{n}_sum")))
        };
        match dests.as_slice() {
            [] => return Err(place_err("its output `y` feeds nothing".into())),
            [one] if is_effect(split(one).0) && split(one).1 == "u" => {
                at = format!("{}.y", split(one).0);
            }
            [one] if helper_sum(split(one).0) && split(one).1 == "in0" => {
                at = format!("{}.y", split(one).0);
            }
            [one] => {
                return Ok(Placement {
                    place: Where::Input {
                        to: one.to_string(),
                    },
                    s,
                });
            }
            many => {
                // A sensor-path effect read by the controller and compared.
                if many.iter().all(|d| !is_effect(split(d).0)) {
                    return Ok(Placement {
                        place: Where::Output { signal: input },
                        s,
                    });
                }
                return Err(place_err(format!(
                    "its output feeds {} places ({}), not one chain",
                    many.len(),
                    many.join(", ")
                )));
            }
        }
    }
    Err(place_err(
        "the chain of effects after it is too long".into(),
    ))
}
