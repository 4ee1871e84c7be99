//! The stability gate on a loop that closes through a device.
//!
//! A controller graph run against a device has no loop inside it: its
//! `hw_output` blocks drive the device, its `hw_input` blocks read it, and the
//! loop closes outside, through the device and what it drives. When the
//! device knows a model of that outside — [`Device::plant_model`]: a plant
//! graph whose `hw_input` blocks are the device's outputs and whose
//! `hw_output` blocks are its inputs, as `nanomotion plant --serve` shares
//! its graph with the controller's [`ShmDevice`](crate::ShmDevice) — the gate
//! judges the loop as it runs: the two graphs joined channel by channel into
//! one ([`joined_through_device`]), with the device's declared transport delay
//! ([`Device::latency_ticks`]) as a `delay` of that many controller ticks on
//! the path from the controller to the plant. A loop whose margin the latency
//! eats is refused before the loop starts, as an unstable graph is.
//!
//! The joined graph, per channel `X` the controller drives and channel `Y`
//! it measures (every name of the plant graph prefixed with `plant_`):
//!
//! ```text
//! controller … ──▶ X (hw_output → delay of L ticks, or gain 1 for L = 0) ──▶ plant_X (hw_input → gain 1) ──▶ plant …
//! plant … ──▶ plant_Y (hw_output → gain 1) ──▶ Y (hw_input → gain 1) ──▶ controller …
//! ```
//!
//! Each block keeps its rate (a block without `rate_hz` runs at its own
//! graph's base rate); the joined base rate is the faster of the two, and the
//! scheduler inserts the rate transitions a real run has at the channel
//! boundary (the controller samples what the plant last published, the plant
//! holds the controller's last drive). Logs, scores and comparisons are left
//! out (the gate reads blocks and wiring only); `require:` is the
//! controller's.
//!
//! ```
//! use nanomotion_core::{GraphSpec, gate};
//! use nanomotion_rt::through::joined_through_device;
//! nanomotion_rt::link_blocks();
//! // y[k+1] = y[k] + u[k] (a discrete integrator) driven by a gain of 0.5.
//! let plant = "base_rate_hz: 1000\nduration_s: 0.1\nblocks:\n  - { name: u, type: hw_input }\n  - { name: p, type: transfer_function, num: [1.0], den: [1.0, -1.0], discrete: true }\n  - { name: y, type: hw_output }\nconnections:\n  - { from: u.y, to: p.u }\n  - { from: p.y, to: y.u }\n";
//! let controller = "base_rate_hz: 1000\nduration_s: 0.1\nblocks:\n  - { name: r, type: constant, value: 1.0 }\n  - { name: y, type: hw_input }\n  - { name: e, type: sum, signs: \"+-\" }\n  - { name: k, type: gain, k: 0.5 }\n  - { name: u, type: hw_output }\nconnections:\n  - { from: r.y, to: e.in0 }\n  - { from: y.y, to: e.in1 }\n  - { from: e.y, to: k.u }\n  - { from: k.y, to: u.u }\n";
//! let spec = |y: &str| GraphSpec::from_yaml(y, "doc.yaml").unwrap();
//! let gate = |latency| {
//!     let joined = joined_through_device(spec(controller), spec(plant), latency).unwrap();
//!     let (sched, _) = joined.build().unwrap();
//!     gate::analyse(&sched, &Default::default())
//! };
//! // L(z) = 0.5/(z − 1): the closed-loop pole 0.5; with one tick of latency
//! // L(z) = 0.5/(z(z − 1)): z² − z + 0.5, poles of modulus √0.5.
//! assert!((gate(0).loops[0].points[0].spectral_radius - 0.5).abs() < 1e-12);
//! assert!((gate(1).loops[0].points[0].spectral_radius - 0.5f64.sqrt()).abs() < 1e-12);
//! ```

use crate::device::{Device, HW_INPUT, HW_OUTPUT};
use nanomotion_core::gate::{self, FrontEnd, GateReport};
use nanomotion_core::graph::{BlockSpec, Connection, GraphSpec};
use serde_json::json;

/// What the plant graph's block names are prefixed with in the joined graph.
pub const PLANT_PREFIX: &str = "plant_";

/// Why the loop through a device cannot be judged, or was refused.
#[derive(Debug, thiserror::Error)]
pub enum ThroughError {
    /// A channel of one graph has no partner in the other.
    #[error(
        "channel `{channel}`: the controller's {kind} block has no partner in the plant graph (fix: give the plant graph a `{partner}` block named `{channel}`)"
    )]
    Unmatched {
        /// The channel.
        channel: String,
        /// `hw_input` or `hw_output` (the controller's block).
        kind: &'static str,
        /// The block the plant graph needs.
        partner: &'static str,
    },
    /// The plant's prefixed names clash with the controller's.
    #[error(
        "the plant's block `{0}` would be called like a controller block in the joined graph (fix: rename the controller block)"
    )]
    Clash(String),
    /// A replacement block could not be made (an internal error, named).
    #[error("joined graph: {0}")]
    Block(String),
    /// The joined graph does not build.
    #[error("the loop through it cannot be built for the stability gate: {0}")]
    Build(Box<nanomotion_core::error::GraphError>),
    /// The device's model of what it drives cannot be read.
    #[error("{0}")]
    Model(crate::DeviceError),
    /// The stability gate refuses the loop through the device
    /// ([`GateReport::before_run`]'s text).
    #[error("{0}")]
    Refused(String),
}

/// The type tag of a block spec.
fn kind(b: &BlockSpec) -> &str {
    b.block.typetag_name()
}

/// A block of the joined graph: `type_params` (a `type:` tag and its
/// parameters) named `name`, at `rate_hz`.
fn block(
    name: &str,
    rate_hz: f64,
    type_params: serde_json::Value,
) -> Result<BlockSpec, ThroughError> {
    let mut v = type_params;
    v["name"] = json!(name);
    v["rate_hz"] = json!(rate_hz);
    serde_json::from_value(v).map_err(|e| ThroughError::Block(format!("block `{name}`: {e}")))
}

/// `block.port` of the plant graph, renamed into the joined graph.
fn renamed(signal: &str) -> String {
    format!("{PLANT_PREFIX}{signal}")
}

/// The controller graph and the plant graph joined channel by channel into
/// one graph for the stability gate, with `latency_ticks` controller ticks of
/// delay from the controller to the plant (see the [module
/// documentation](self)).
pub fn joined_through_device(
    controller: GraphSpec,
    plant: GraphSpec,
    latency_ticks: u32,
) -> Result<GraphSpec, ThroughError> {
    let (c_rate, p_rate) = (controller.base_rate_hz, plant.base_rate_hz);
    let is = |b: &BlockSpec, k: &str| kind(b) == k;
    let names: Vec<String> = controller.blocks.iter().map(|b| b.name.clone()).collect();
    let partner = |name: &str, k: &str| plant.blocks.iter().any(|b| b.name == name && is(b, k));
    for b in &controller.blocks {
        let (needs, kind) = if is(b, HW_OUTPUT) {
            (HW_INPUT, HW_OUTPUT)
        } else if is(b, HW_INPUT) {
            (HW_OUTPUT, HW_INPUT)
        } else {
            continue;
        };
        if !partner(&b.name, needs) {
            return Err(ThroughError::Unmatched {
                channel: b.name.clone(),
                kind,
                partner: needs,
            });
        }
    }
    let mut blocks = Vec::new();
    let mut connections = controller.connections;
    for b in controller.blocks {
        let rate = b.rate_hz.unwrap_or(c_rate);
        blocks.push(if is(&b, HW_OUTPUT) {
            // The drive, `latency_ticks` controller ticks late at the plant.
            connections.push(Connection {
                from: format!("{}.y", b.name),
                to: renamed(&format!("{}.u", b.name)),
            });
            match latency_ticks {
                0 => block(&b.name, rate, json!({ "type": "gain", "k": 1.0 }))?,
                d => block(&b.name, rate, json!({ "type": "delay", "d": d }))?,
            }
        } else if is(&b, HW_INPUT) {
            // The measurement, as the plant published it.
            connections.push(Connection {
                from: renamed(&format!("{}.y", b.name)),
                to: format!("{}.u", b.name),
            });
            block(&b.name, rate, json!({ "type": "gain", "k": 1.0 }))?
        } else {
            BlockSpec {
                rate_hz: Some(rate),
                ..b
            }
        });
    }
    for b in plant.blocks {
        let name = renamed(&b.name);
        if names.contains(&name) {
            return Err(ThroughError::Clash(name));
        }
        let rate = b.rate_hz.unwrap_or(p_rate);
        blocks.push(if is(&b, HW_INPUT) || is(&b, HW_OUTPUT) {
            block(&name, rate, json!({ "type": "gain", "k": 1.0 }))?
        } else {
            BlockSpec {
                name,
                rate_hz: Some(rate),
                ..b
            }
        });
    }
    connections.extend(plant.connections.into_iter().map(|c| Connection {
        from: renamed(&c.from),
        to: renamed(&c.to),
    }));
    let mut units = controller.units;
    units.extend(plant.units.into_iter().map(|(k, v)| (renamed(&k), v)));
    Ok(GraphSpec {
        title: Some(format!(
            "{} through a device ({latency_ticks} ticks) to {}",
            controller.title.as_deref().unwrap_or("controller"),
            plant.title.as_deref().unwrap_or("plant")
        )),
        base_rate_hz: c_rate.max(p_rate),
        duration_s: controller.duration_s,
        seed: controller.seed,
        strict_rates: false,
        blocks,
        connections,
        log: Vec::new(),
        score: Vec::new(),
        compare: Vec::new(),
        require: controller.require,
        realtime: None,
        connection_lines: None,
        units,
        base_dir: controller.base_dir,
    })
}

/// The stability gate's verdict on the loop `controller` closes through
/// `device` ([`joined_through_device`] with the device's
/// [`plant_model`](Device::plant_model) and
/// [`latency_ticks`](Device::latency_ticks)), or `None` when the device knows
/// no model of what it drives (the gate then has no loop to judge).
/// `controller` is the graph as the loop runs it (its overrides applied).
pub fn gate_through_device<D: Device + ?Sized>(
    controller: GraphSpec,
    device: &D,
) -> Result<Option<GateReport>, ThroughError> {
    let Some(plant) = device.plant_model().map_err(ThroughError::Model)? else {
        return Ok(None);
    };
    let require = controller.require.clone().unwrap_or_default();
    let joined = joined_through_device(controller, plant, device.latency_ticks())?;
    let (sched, _) = joined
        .build()
        .map_err(|e| ThroughError::Build(Box::new(e)))?;
    Ok(Some(gate::analyse(&sched, &require)))
}

/// The gate on the loop through `device` before a run, one rule for every
/// front end: `Ok` with the lines for the run's report — one per loop naming
/// the device, its latency and the margins the gate computed with it, then
/// [`GateReport::before_run`]'s (a loop run unproven, or refused and run
/// anyway with `allow`) — or no line when the device has no
/// [`plant_model`](Device::plant_model); `Err(Refused)` when the gate
/// refuses the loop and `allow` is false.
pub fn before_run_through<D: Device + ?Sized>(
    controller: GraphSpec,
    device: &D,
    allow: bool,
    front: &FrontEnd,
) -> Result<Vec<String>, ThroughError> {
    let rate = controller.base_rate_hz;
    let Some(report) = gate_through_device(controller, device)? else {
        return Ok(Vec::new());
    };
    let latency = device.latency_ticks();
    let mut lines: Vec<String> = report
        .loops
        .iter()
        .map(|l| {
            let margins = l.points.first().and_then(|p| p.margins.as_ref()).map_or(
                String::new(),
                |m| {
                    format!(
                        ": phase margin {:.2}°, delay margin {:.4} ms ({:.2} ticks)",
                        m.phase_margin_deg,
                        m.delay_margin_s * 1e3,
                        m.delay_margin_s * rate
                    )
                },
            );
            format!(
                "loop `{}` closed through device `{}` with its latency of {latency} tick{} ({:.1} µs){margins}{}",
                l.name,
                device.name(),
                if latency == 1 { "" } else { "s" },
                f64::from(latency) / rate * 1e6,
                if l.passes() { "" } else { " — fails" }
            )
        })
        .collect();
    let verdict = report.before_run(allow, front).map_err(|e| {
        ThroughError::Refused(format!(
            "the loop through device `{}` with its latency of {latency} tick{}: {e}",
            device.name(),
            if latency == 1 { "" } else { "s" }
        ))
    })?;
    lines.extend(verdict);
    Ok(lines)
}
