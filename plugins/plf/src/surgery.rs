//! Graph surgery: where an effect can enter a model graph, and inserting it there.
//!
//! Three kinds of place ([`Site`]):
//! - **input** — in series on a connection into the plant (actuator side):
//!   `from → effect.u`, `effect.y → to`;
//! - **output** — on a compared output (sensor side): the comparison (and logs)
//!   read `effect.y`, `effect.u ← signal`; nothing that feeds back changes;
//! - **feedback** — inside the plant's loop: the effect reads the plant's position
//!   and its output is added to the plant's input through a new `sum`
//!   (friction and hysteretic restoring forces);
//! - **sensor** — in the measurement path of a closed loop: every reader of the
//!   compared signal (the controller and the comparison) reads `effect.y` instead,
//!   `effect.u ← signal` (an encoder's rounding or delay that the controller acts
//!   on changes the loop, which an effect on the comparison alone cannot show).
//!
//! Effects that need a scheduling signal (port `s`: position for a
//! position-dependent gain, other axes for coupling) get it wired too.

use crate::PlfError;
use nanomotion_core::Role;
use nanomotion_core::block::Block;
use nanomotion_core::graph::{BlockSpec, Connection, GraphSpec};

/// A deep copy of a graph (blocks are trait objects: copied through their serde
/// form, which is what a saved graph is anyway).
pub fn clone_spec(spec: &GraphSpec) -> Result<GraphSpec, PlfError> {
    let v = serde_json::to_value(spec)
        .map_err(|e| PlfError::Model(format!("cannot copy the graph: {e}")))?;
    serde_json::from_value(v).map_err(|e| PlfError::Model(format!("cannot copy the graph: {e}")))
}

/// A block from its `type:` and parameters as JSON (the same map as in YAML).
pub fn block_from_json(v: serde_json::Value) -> Result<Box<dyn Block>, PlfError> {
    serde_json::from_value(v.clone())
        .map_err(|e| PlfError::Model(format!("cannot make block {v}: {e}")))
}

/// A block's parameters as JSON (its YAML map without the name).
pub fn block_to_json(b: &dyn Block) -> serde_json::Value {
    serde_json::to_value(b).unwrap_or(serde_json::Value::Null)
}

/// Where an effect enters.
#[derive(Debug, Clone, PartialEq)]
pub enum Site {
    /// In series on connection `from → to` (width 1) into the plant.
    Input {
        /// Source `block.port`.
        from: String,
        /// Destination `block.port` (a plant input).
        to: String,
    },
    /// On the `compare` entry with index `compare`, reading `signal`.
    Output {
        /// Index into the graph's `compare:` list.
        compare: usize,
        /// The compared model signal `block.port`.
        signal: String,
    },
    /// In the measurement path of a closed loop: every reader of `signal` (the
    /// controller and the `compare` entry with index `compare`) reads the effect.
    Sensor {
        /// Index into the graph's `compare:` list.
        compare: usize,
        /// The measured model signal `block.port`, which also feeds back.
        signal: String,
    },
    /// Added to the plant input `to` (fed by `from`), computed from `position`.
    Feedback {
        /// Source `block.port` of the plant input's connection.
        from: String,
        /// The plant input `block.port`.
        to: String,
        /// The plant output the effect reads.
        position: String,
    },
}

impl Site {
    /// `input`, `output` or `feedback`.
    pub fn kind(&self) -> &'static str {
        match self {
            Site::Input { .. } => "input",
            Site::Output { .. } => "output",
            Site::Sensor { .. } => "sensor",
            Site::Feedback { .. } => "feedback",
        }
    }
    /// One line for people.
    pub fn describe(&self) -> String {
        match self {
            Site::Input { from, to } => format!("input side, in series on {from} -> {to}"),
            Site::Output { signal, .. } => format!("output side, on the measured {signal}"),
            Site::Sensor { signal, .. } => {
                format!("in the sensor path inside the loop, on {signal} as the controller sees it")
            }
            Site::Feedback { to, position, .. } => {
                format!("inside the loop, from {position} added to {to}")
            }
        }
    }
}

/// What the workflow knows of one compared output.
#[derive(Debug, Clone)]
pub struct Channel {
    /// The compared model signal.
    pub signal: String,
    /// The measured column.
    pub column: String,
    /// The plant's position output (the compared signal, or the input of the
    /// sensor chain that produces it).
    pub position: String,
    /// The plant block.
    pub plant: String,
    /// Width-1 connections into the plant: `(from, to)`.
    pub plant_inputs: Vec<(String, String)>,
    /// Rate (Hz) of the compared signal's block, `None` for the base rate.
    pub rate_hz: Option<f64>,
}

fn split(reference: &str) -> (&str, &str) {
    reference.split_once('.').unwrap_or((reference, ""))
}

/// The compared channels of `spec`, with their plants (the spec is built once, a
/// copy, to learn port widths and roles).
pub fn channels(
    spec: &GraphSpec,
    data: &std::sync::Arc<nanomotion_core::data::Dataset>,
) -> Result<Vec<Channel>, PlfError> {
    let probe = clone_spec(spec)?;
    let roles: Vec<(String, Role)> = probe
        .blocks
        .iter()
        .map(|b| (b.name.clone(), b.block.role()))
        .collect();
    let probe_types: Vec<(String, String)> = probe
        .blocks
        .iter()
        .map(|b| (b.name.clone(), b.block.typetag_name().to_string()))
        .collect();
    let rates: Vec<(String, Option<f64>)> = probe
        .blocks
        .iter()
        .map(|b| (b.name.clone(), b.rate_hz))
        .collect();
    let (sched, _) = probe
        .build_with_data(data.clone())
        .map_err(|e| PlfError::Model(e.to_string()))?;
    let width_in = |reference: &str| -> usize {
        let (b, p) = split(reference);
        sched
            .block(b)
            .and_then(|blk| blk.inputs().into_iter().find(|q| q.name == p))
            .map_or(0, |q| q.width)
    };
    let role_of = |name: &str| roles.iter().find(|(n, _)| n == name).map(|(_, r)| *r);
    let mut out = Vec::new();
    for c in &spec.compare {
        let (mut block, _) = split(&c.signal);
        let mut position = c.signal.clone();
        // Walk up through sensor blocks (quantisers, measurement noise) and
        // `demux` splitters with a single input to the plant. Through a demux the
        // position stays the compared (scalar) signal.
        let type_of = |name: &str| {
            probe_types
                .iter()
                .find(|(n, _)| n == name)
                .map(|(_, t)| t.as_str())
                .unwrap_or("")
        };
        for _ in 0..8 {
            let is_demux = type_of(block) == "demux";
            if role_of(block) != Some(Role::Sensor) && !is_demux {
                break;
            }
            let feeding: Vec<&Connection> = spec
                .connections
                .iter()
                .filter(|k| split(&k.to).0 == block)
                .collect();
            if feeding.len() != 1 {
                break;
            }
            if !is_demux {
                position = feeding[0].from.clone();
            }
            block = split(&feeding[0].from).0;
        }
        // Scalar drives of the plant: width-1 connections into it, and the
        // width-1 inputs of a `mux` that assembles a vector drive.
        let mut plant_inputs: Vec<(String, String)> = Vec::new();
        for k in spec.connections.iter().filter(|k| split(&k.to).0 == block) {
            if width_in(&k.to) == 1 {
                plant_inputs.push((k.from.clone(), k.to.clone()));
            } else if type_of(split(&k.from).0) == "mux" {
                let mux = split(&k.from).0;
                for m in spec.connections.iter().filter(|m| split(&m.to).0 == mux) {
                    if width_in(&m.to) == 1 {
                        plant_inputs.push((m.from.clone(), m.to.clone()));
                    }
                }
            }
        }
        let rate_hz = rates
            .iter()
            .find(|(n, _)| n == split(&c.signal).0)
            .and_then(|(_, r)| *r);
        out.push(Channel {
            signal: c.signal.clone(),
            column: c.column.clone(),
            position,
            plant: block.to_string(),
            plant_inputs,
            rate_hz,
        });
    }
    Ok(out)
}

/// The rate of block `name` in `spec` (`None`: base rate).
pub fn rate_of(spec: &GraphSpec, name: &str) -> Option<f64> {
    spec.blocks
        .iter()
        .find(|b| b.name == name)
        .and_then(|b| b.rate_hz)
}

/// A block name not used in `spec`, from `stem`.
pub fn fresh_name(spec: &GraphSpec, stem: &str) -> String {
    if !spec.blocks.iter().any(|b| b.name == stem) {
        return stem.to_string();
    }
    (2..)
        .map(|i| format!("{stem}_{i}"))
        .find(|n| !spec.blocks.iter().any(|b| b.name == *n))
        .expect("some suffix is free")
}

/// Insert `block` (named from `stem`) at `site`. `s` lists the signals wired to the
/// block's port `s` (none, one, or several through a `mux`). `rate_hz` overrides
/// the block's rate (default: the rate of the block it sits beside). Returns the
/// new block's name.
pub fn insert(
    spec: &mut GraphSpec,
    stem: &str,
    block: Box<dyn Block>,
    site: &Site,
    s: &[String],
    rate_hz: Option<f64>,
) -> Result<String, PlfError> {
    let name = fresh_name(spec, stem);
    let find_conn = |spec: &GraphSpec, from: &str, to: &str| -> Result<usize, PlfError> {
        spec.connections
            .iter()
            .position(|c| c.from == from && c.to == to)
            .ok_or_else(|| PlfError::Model(format!("the graph has no connection {from} -> {to}")))
    };
    let rate = match site {
        Site::Input { to, .. } | Site::Feedback { to, .. } => {
            rate_hz.or_else(|| rate_of(spec, split(to).0))
        }
        Site::Output { signal, .. } | Site::Sensor { signal, .. } => {
            rate_hz.or_else(|| rate_of(spec, split(signal).0))
        }
    };
    spec.blocks.push(BlockSpec {
        name: name.clone(),
        rate_hz: rate,
        block,
    });
    match site {
        Site::Input { from, to } => {
            let i = find_conn(spec, from, to)?;
            spec.connections[i].to = format!("{name}.u");
            spec.connections.push(Connection {
                from: format!("{name}.y"),
                to: to.clone(),
            });
        }
        Site::Output { compare, .. } => {
            // In series after what is compared now: after the sensor chain, and
            // after any output-side effect inserted before (effects stack in the
            // order they were found, as the fit saw them).
            let c = spec
                .compare
                .get_mut(*compare)
                .ok_or_else(|| PlfError::Model(format!("no compare entry {compare}")))?;
            let from = std::mem::replace(&mut c.signal, format!("{name}.y"));
            spec.connections.push(Connection {
                from,
                to: format!("{name}.u"),
            });
        }
        Site::Sensor { signal, .. } => {
            let out = format!("{name}.y");
            for c in spec.connections.iter_mut().filter(|c| c.from == *signal) {
                c.from = out.clone();
            }
            for c in spec.compare.iter_mut().filter(|c| c.signal == *signal) {
                c.signal = out.clone();
            }
            spec.connections.push(Connection {
                from: signal.clone(),
                to: format!("{name}.u"),
            });
        }
        Site::Feedback { from, to, position } => {
            let i = find_conn(spec, from, to)?;
            let sum_name = fresh_name(spec, &format!("{name}_sum"));
            let sum = block_from_json(serde_json::json!({"type": "sum", "signs": "++"}))?;
            spec.blocks.push(BlockSpec {
                name: sum_name.clone(),
                rate_hz: rate,
                block: sum,
            });
            spec.connections[i].to = format!("{sum_name}.in0");
            spec.connections.push(Connection {
                from: format!("{name}.y"),
                to: format!("{sum_name}.in1"),
            });
            spec.connections.push(Connection {
                from: format!("{sum_name}.y"),
                to: to.clone(),
            });
            spec.connections.push(Connection {
                from: position.clone(),
                to: format!("{name}.u"),
            });
        }
    }
    match s {
        [] => {}
        [one] => spec.connections.push(Connection {
            from: one.clone(),
            to: format!("{name}.s"),
        }),
        many => {
            let mux_name = fresh_name(spec, &format!("{name}_mux"));
            let mux =
                block_from_json(serde_json::json!({"type": "mux", "widths": vec![1; many.len()]}))?;
            spec.blocks.push(BlockSpec {
                name: mux_name.clone(),
                rate_hz: rate,
                block: mux,
            });
            for (k, sig) in many.iter().enumerate() {
                spec.connections.push(Connection {
                    from: sig.clone(),
                    to: format!("{mux_name}.in{k}"),
                });
            }
            spec.connections.push(Connection {
                from: format!("{mux_name}.y"),
                to: format!("{name}.s"),
            });
        }
    }
    Ok(name)
}
