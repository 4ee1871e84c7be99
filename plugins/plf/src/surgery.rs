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
    /// Width-1 connections into the plant: `(from, to)`; none when the
    /// compared signal is itself the drive of another compared output's plant
    /// (a controller's output: what enters it is computed inside the digital
    /// controller, where no actuator, friction or creep acts — the drive's own
    /// effects sit on the connection into that other plant).
    pub plant_inputs: Vec<(String, String)>,
    /// Whether the compared signal is the drive of another compared output's
    /// plant (a controller's output compared beside the position): no plant
    /// of its own, and no sensor either — the controller computes it, nothing
    /// reads it through a sensor, and a delay, rounding or offset of the drive
    /// is tried where it acts, on the connection into that plant.
    pub drive: bool,
    /// Rate (Hz) of the compared signal's block, `None` for the base rate.
    pub rate_hz: Option<f64>,
    /// The axis the output measures: outputs of blocks on one single-input
    /// single-output feedback loop (a position and its controller's drive)
    /// measure one axis and share this key; any other output is its own axis.
    pub axis: String,
}

impl Channel {
    /// Whether `self` and `other` measure one axis.
    pub fn same_axis(&self, other: &Channel) -> bool {
        self.axis == other.axis
    }
}

fn split(reference: &str) -> (&str, &str) {
    reference.split_once('.').unwrap_or((reference, ""))
}

/// The axis key of an output of `block` (see [`Channel::axis`]): the blocks of
/// the feedback loop through `block` (those it reaches and that reach it), when
/// that loop is single-input single-output (every connection between them of
/// width 1, no `mux`/`demux`); else `signal`, the output alone.
fn axis_of(
    spec: &GraphSpec,
    block: &str,
    signal: &str,
    width_in: &dyn Fn(&str) -> usize,
    types: &[(String, String)],
) -> String {
    let type_of = |name: &str| {
        types
            .iter()
            .find(|(n, _)| n == name)
            .map_or("", |(_, t)| t.as_str())
    };
    let reach = |forward: bool| -> Vec<&str> {
        let mut seen = vec![block];
        let mut stack = vec![block];
        while let Some(b) = stack.pop() {
            for k in &spec.connections {
                let (s, d) = (split(&k.from).0, split(&k.to).0);
                let (here, next) = if forward { (s, d) } else { (d, s) };
                if here == b && !seen.contains(&next) {
                    seen.push(next);
                    stack.push(next);
                }
            }
        }
        seen
    };
    let up = reach(false);
    let mut members: Vec<&str> = reach(true).into_iter().filter(|b| up.contains(b)).collect();
    let siso = members.len() > 1
        && members
            .iter()
            .all(|b| !matches!(type_of(b), "mux" | "demux"))
        && spec.connections.iter().all(|k| {
            !(members.contains(&split(&k.from).0) && members.contains(&split(&k.to).0))
                || width_in(&k.to) == 1
        });
    if siso {
        members.sort_unstable();
        format!("loop {}", members.join(", "))
    } else {
        signal.to_string()
    }
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
            drive: false,
            rate_hz,
            axis: axis_of(spec, block, &c.signal, &width_in, &probe_types),
        });
    }
    let drives: Vec<String> = out
        .iter()
        .flat_map(|ch| ch.plant_inputs.iter().map(|(from, _)| from.clone()))
        .collect();
    for ch in &mut out {
        if drives.contains(&ch.signal) {
            ch.plant_inputs.clear();
            ch.drive = true;
        }
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

/// The connections of `spec` leaving `block` (any of its outputs).
fn leaving<'a>(
    spec: &'a GraphSpec,
    block: &'a str,
) -> impl Iterator<Item = (usize, &'a Connection)> {
    spec.connections
        .iter()
        .enumerate()
        .filter(move |(_, c)| split(&c.from).0 == block)
}

/// How many blocks deep the path from a plant's drive to the plant may run
/// through effects inserted before (far more than `max_effects`).
const MAX_CHAIN: usize = 32;

/// The connection on which a map of the drive (`Site::Input`) goes: the first hop
/// out of `from` on the path to `to`. Effects inserted earlier sit on that path
/// (`from → plf_a.u`, `plf_a.y → to`), so the original connection is gone after
/// the first insertion; the new effect goes nearest the source, i.e. it acts on
/// the drive before the effects found earlier (an amplifier's saturation before
/// the actuator's hysteresis), and never on a force added inside the loop.
fn drive_connection(spec: &GraphSpec, from: &str, to: &str) -> Result<usize, PlfError> {
    // Breadth first from `from`'s connections; each entry remembers its first hop.
    let mut frontier: Vec<(usize, usize)> = spec
        .connections
        .iter()
        .enumerate()
        .filter(|(_, c)| c.from == from)
        .map(|(i, _)| (i, i))
        .collect();
    for _ in 0..MAX_CHAIN {
        if let Some(&(first, _)) = frontier
            .iter()
            .find(|&&(_, i)| spec.connections[i].to == to)
        {
            return Ok(first);
        }
        let mut next = Vec::new();
        for &(first, i) in &frontier {
            let via = split(&spec.connections[i].to).0;
            // Never through the plant itself or back through the source.
            if via == split(to).0 || via == split(from).0 {
                continue;
            }
            next.extend(leaving(spec, via).map(|(j, _)| (first, j)));
        }
        if next.is_empty() {
            break;
        }
        frontier = next;
    }
    Err(PlfError::Model(format!(
        "the graph has no path {from} -> {to} (through the effects inserted so far)"
    )))
}

/// The connection into the plant input `to` (a force added inside the loop goes
/// at the force balance, after every map of the drive found before). `from` only
/// names the drive in the message.
fn force_connection(spec: &GraphSpec, from: &str, to: &str) -> Result<usize, PlfError> {
    spec.connections
        .iter()
        .position(|c| c.to == to)
        .ok_or_else(|| PlfError::Model(format!("the graph has no connection {from} -> {to}")))
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
            // The effect takes over the first hop's destination (the plant itself
            // when nothing was inserted before, else the earlier effect nearest
            // the source).
            let i = drive_connection(spec, from, to)?;
            let next = std::mem::replace(&mut spec.connections[i].to, format!("{name}.u"));
            spec.connections.push(Connection {
                from: format!("{name}.y"),
                to: next,
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
            let i = force_connection(spec, from, to)?;
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

/// The signal wired into the input port `to` (`block.port`).
fn source_of(spec: &GraphSpec, to: &str) -> Option<String> {
    spec.connections
        .iter()
        .find(|c| c.to == to)
        .map(|c| c.from.clone())
}

/// The block named from `stem` (see [`fresh_name`]) at the other end of a
/// connection of `port` (`block.port`).
fn helper_on(spec: &GraphSpec, port: &str, stem: &str) -> Option<String> {
    spec.connections.iter().find_map(|c| {
        let other = if c.from == port {
            &c.to
        } else if c.to == port {
            &c.from
        } else {
            return None;
        };
        let block = split(other).0;
        block.starts_with(stem).then(|| block.to_string())
    })
}

/// Take out effect block `name` that [`insert`] put in, with the `sum` and
/// `mux` it brought: what it read goes where its output went (a map in
/// series or on a comparison), or the force balance it was added into is
/// left as it was before (a force inside the loop). The reverse of
/// [`insert`]: the effects inserted before and after it stay in their order.
pub fn remove(spec: &mut GraphSpec, name: &str) -> Result<(), PlfError> {
    let missing = || PlfError::Model(format!("no effect block {name} to take out"));
    if !spec.blocks.iter().any(|b| b.name == name) {
        return Err(missing());
    }
    let (u, y, s) = (
        format!("{name}.u"),
        format!("{name}.y"),
        format!("{name}.s"),
    );
    let read = source_of(spec, &u).ok_or_else(missing)?;
    // Helpers it brought: the sum it is added through, the mux of its `s`.
    let sum = helper_on(spec, &y, &format!("{name}_sum"));
    let mux = helper_on(spec, &s, &format!("{name}_mux"));
    let (source, output) = match &sum {
        // A force inside the loop: the sum's other input goes on alone.
        Some(sum) => (
            source_of(spec, &format!("{sum}.in0")).ok_or_else(missing)?,
            format!("{sum}.y"),
        ),
        // A map: what it read goes where its output went.
        None => (read, y),
    };
    for c in spec.connections.iter_mut().filter(|c| c.from == output) {
        c.from = source.clone();
    }
    for c in spec.compare.iter_mut().filter(|c| c.signal == output) {
        c.signal = source.clone();
    }
    let gone: Vec<String> = std::iter::once(name.to_string())
        .chain(sum)
        .chain(mux)
        .collect();
    let touches = |r: &str| gone.iter().any(|g| split(r).0 == g);
    spec.connections
        .retain(|c| !touches(&c.from) && !touches(&c.to));
    spec.log.retain(|l| !touches(l));
    spec.blocks.retain(|b| !gone.contains(&b.name));
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use nanomotion_core::data::Dataset;
    use std::sync::Arc;

    fn stage() -> GraphSpec {
        let _ = std::any::type_name::<crate::effects::Effect>();
        GraphSpec::from_yaml(
            "base_rate_hz: 1000\nduration_s: 0.2\nblocks:\n  - { name: drive, type: data_column, column: u }\n  - { name: stage, type: state_space, a: [[0.0, 1.0], [-1000.0, -10.0]], b: [[0.0], [1.0]], c: [[1.0, 0.0]], discretisation: zoh }\nconnections:\n  - { from: drive.y, to: stage.u }\ncompare:\n  - { signal: stage.y, column: y }\n",
            "stage.yaml",
        )
        .unwrap()
    }

    /// On [`stage`]: a map in series on its drive, and a force inside its loop.
    fn drive_and_force_sites() -> (Site, Site) {
        let input = Site::Input {
            from: "drive.y".into(),
            to: "stage.u".into(),
        };
        let feedback = Site::Feedback {
            from: "drive.y".into(),
            to: "stage.u".into(),
            position: "stage.y".into(),
        };
        (input, feedback)
    }

    fn conn(spec: &GraphSpec, from: &str, to: &str) -> bool {
        spec.connections
            .iter()
            .any(|c| c.from == from && c.to == to)
    }

    fn axes(yaml: &str, columns: &[&str]) -> Vec<String> {
        let spec = GraphSpec::from_yaml(yaml, "axes.yaml").unwrap();
        let cols: Vec<(String, Vec<f64>)> = columns
            .iter()
            .map(|c| (c.to_string(), vec![0.0; 200]))
            .collect();
        let data = Arc::new(Dataset::from_columns("axes", 1000.0, 0.0, cols).unwrap());
        channels(&spec, &data)
            .unwrap()
            .into_iter()
            .map(|c| c.axis)
            .collect()
    }

    /// A position and its controller's drive measure one axis (seed 339 of the
    /// held-out scenarios named one resonance on each); two loops are two
    /// axes; two outputs of one plant outside a loop are two.
    #[test]
    fn the_outputs_of_one_siso_loop_are_one_axis_and_two_loops_two() {
        let _ = std::any::type_name::<crate::effects::Effect>();
        let loop_of = |k: &str| {
            format!(
                "  - {{ name: r{k}, type: data_column, column: r{k} }}\n  - {{ name: e{k}, type: sum, signs: \"+-\" }}\n  - {{ name: c{k}, type: gain, k: 2.0 }}\n  - {{ name: p{k}, type: transfer_function, num: [0.1], den: [1.0, -0.9], discrete: true }}\n"
            )
        };
        let wires = |k: &str| {
            format!(
                "  - {{ from: r{k}.y, to: e{k}.in0 }}\n  - {{ from: p{k}.y, to: e{k}.in1 }}\n  - {{ from: e{k}.y, to: c{k}.u }}\n  - {{ from: c{k}.y, to: p{k}.u }}\n"
            )
        };
        let two_loops = format!(
            "base_rate_hz: 1000\nduration_s: 0.2\nblocks:\n{}{}connections:\n{}{}compare:\n  - {{ signal: p1.y, column: y1 }}\n  - {{ signal: c1.y, column: u1 }}\n  - {{ signal: p2.y, column: y2 }}\n",
            loop_of("1"),
            loop_of("2"),
            wires("1"),
            wires("2")
        );
        let a = axes(&two_loops, &["r1", "r2", "y1", "u1", "y2"]);
        assert_eq!(a[0], a[1], "{a:?}");
        assert_ne!(a[0], a[2], "{a:?}");
        let open = "base_rate_hz: 1000\nduration_s: 0.2\nblocks:\n  - { name: drive, type: data_column, column: u }\n  - { name: stage, type: state_space, a: [[0.5]], b: [[1.0]], c: [[1.0], [2.0]], discretisation: zoh }\n  - { name: split, type: demux, widths: [1, 1] }\nconnections:\n  - { from: drive.y, to: stage.u }\n  - { from: stage.y, to: split.u }\ncompare:\n  - { signal: split.y0, column: y0 }\n  - { signal: split.y1, column: y1 }\n";
        let b = axes(open, &["u", "y0", "y1"]);
        assert_ne!(b[0], b[1], "{b:?}");
    }

    /// Issue 24 §1: after one effect on the plant's drive, the connection
    /// `drive.y -> stage.u` is gone; a second and third input-side effect and a
    /// force inside the loop must still go in, in their physical order, and the
    /// graph must still build and run.
    #[test]
    fn several_effects_enter_on_the_drive_and_inside_the_loop() {
        let mut spec = stage();
        let (input, feedback) = drive_and_force_sites();
        let block = |v| block_from_json(v).unwrap();
        let a = insert(
            &mut spec,
            "plf_hysteresis",
            block(serde_json::json!({"type": "hysteresis", "alpha": 1.0, "b": 1.0, "c": 0.8})),
            &input,
            &[],
            None,
        )
        .unwrap();
        let b = insert(
            &mut spec,
            "plf_creep",
            block(serde_json::json!({"type": "creep", "terms": [{"gain": 0.01, "tau_s": 0.1}]})),
            &input,
            &[],
            None,
        )
        .unwrap();
        let f = insert(&mut spec, "plf_friction", block(serde_json::json!({"type": "friction", "coulomb": 0.1, "stribeck": 0.0, "v_stribeck": 1.0, "viscous": 0.0, "v_eps": 0.01})), &feedback, &[], None).unwrap();
        let d = insert(
            &mut spec,
            "plf_time_delay",
            block(serde_json::json!({"type": "time_delay", "max_delay_s": 0.01, "delay_s": 0.002})),
            &input,
            &[],
            None,
        )
        .unwrap();
        // The drive passes the maps in the reverse order they were found (each
        // new one nearest the source), then the force balance, then the plant.
        assert!(conn(&spec, "drive.y", &format!("{d}.u")));
        assert!(conn(&spec, &format!("{d}.y"), &format!("{b}.u")));
        assert!(conn(&spec, &format!("{b}.y"), &format!("{a}.u")));
        assert!(conn(&spec, &format!("{a}.y"), &format!("{f}_sum.in0")));
        assert!(conn(&spec, &format!("{f}.y"), &format!("{f}_sum.in1")));
        assert!(conn(&spec, &format!("{f}_sum.y"), "stage.u"));
        assert!(conn(&spec, "stage.y", &format!("{f}.u")));
        assert_eq!(
            spec.connections
                .iter()
                .filter(|c| c.to == "stage.u")
                .count(),
            1
        );
        let n = 200;
        let u: Vec<f64> = (0..n).map(|k| (k as f64 * 0.05).sin()).collect();
        let data = Dataset::from_columns(
            "test",
            1000.0,
            0.0,
            vec![("u".into(), u), ("y".into(), vec![0.0; n])],
        )
        .unwrap();
        spec.build_with_data(Arc::new(data))
            .expect("the augmented graph builds");
    }

    /// `remove` undoes `insert`: of four effects (two maps on the drive, a
    /// force inside the loop, a coupling on the comparison that reads two
    /// signals through a mux), taking any one out leaves a graph that runs
    /// bit for bit like the one the other three were inserted into, with
    /// none of the removed blocks' helpers left; a name that is not there is
    /// a typed error.
    #[test]
    fn removing_an_effect_leaves_the_graph_the_others_make() {
        let (input, feedback) = drive_and_force_sites();
        let output = Site::Output {
            compare: 0,
            signal: "stage.y".into(),
        };
        let effects = [
            (
                "plf_hysteresis",
                serde_json::json!({"type": "hysteresis", "alpha": 1.0, "b": 1.0, "c": 0.8}),
                &input,
                vec![],
            ),
            (
                "plf_friction",
                serde_json::json!({"type": "friction", "coulomb": 0.1, "stribeck": 0.0, "v_stribeck": 1.0, "viscous": 0.0, "v_eps": 0.01}),
                &feedback,
                vec![],
            ),
            (
                "plf_time_delay",
                serde_json::json!({"type": "time_delay", "max_delay_s": 0.01, "delay_s": 0.0025}),
                &input,
                vec![],
            ),
            (
                "plf_axis_coupling",
                serde_json::json!({"type": "axis_coupling", "coupling": [0.1, -0.2]}),
                &output,
                vec!["drive.y".to_string(), "stage.y".to_string()],
            ),
        ];
        let with = |skip: Option<usize>| {
            let mut spec = stage();
            let names: Vec<String> = effects
                .iter()
                .enumerate()
                .filter(|(i, _)| Some(*i) != skip)
                .map(|(_, (stem, json, site, s))| {
                    let b = block_from_json(json.clone()).unwrap();
                    insert(&mut spec, stem, b, site, s, None).unwrap()
                })
                .collect();
            (spec, names)
        };
        let n = 400;
        let u: Vec<f64> = (0..n).map(|k| (k as f64 * 0.03).sin()).collect();
        let data = Arc::new(
            Dataset::from_columns(
                "test",
                1000.0,
                0.0,
                vec![("u".into(), u), ("y".into(), vec![0.0; n])],
            )
            .unwrap(),
        );
        let compared = |mut spec: GraphSpec| -> Vec<f64> {
            let signal = spec.compare[0].signal.clone();
            spec.log.push(signal.clone());
            let (mut s, _) = spec.build_with_data(data.clone()).expect("builds");
            let run = s.run(|_| {});
            run.logs
                .iter()
                .find(|l| l.name == signal)
                .expect("logged")
                .data
                .clone()
        };
        let (all, names) = with(None);
        for (i, name) in names.iter().enumerate() {
            let mut reduced = clone_spec(&all).unwrap();
            remove(&mut reduced, name).unwrap();
            assert!(
                !reduced
                    .blocks
                    .iter()
                    .any(|b| b.name.starts_with(name.as_str())),
                "{name}: {:?}",
                reduced.blocks.iter().map(|b| &b.name).collect::<Vec<_>>()
            );
            let expected = compared(with(Some(i)).0);
            assert!(expected.iter().any(|v| *v != 0.0));
            assert_eq!(compared(reduced), expected, "without {name}");
        }
        let mut spec = stage();
        let e = remove(&mut spec, "plf_nothing").unwrap_err();
        assert!(e.to_string().contains("no effect block plf_nothing"), "{e}");
    }

    #[test]
    fn a_drive_that_does_not_reach_the_plant_is_a_typed_error() {
        let mut spec = stage();
        let site = Site::Input {
            from: "nowhere.y".into(),
            to: "stage.u".into(),
        };
        let b = block_from_json(serde_json::json!({"type": "backlash", "width": 0.1})).unwrap();
        let e = insert(&mut spec, "plf_backlash", b, &site, &[], None).unwrap_err();
        assert!(
            e.to_string().contains("no path nowhere.y -> stage.u"),
            "{e}"
        );
    }
}
