//! The hardware boundary: the [`Device`] trait and the `hw_input` / `hw_output`
//! blocks that connect a device's channels to a graph by name.
//!
//! # Contract (what is called where)
//!
//! | call | thread | when | may block, allocate? |
//! |---|---|---|---|
//! | the constructor (open) | any | before the runner | yes |
//! | [`Device::configure`] | the caller of [`RealtimeRunner::new`](crate::RealtimeRunner::new) | once, at build | yes |
//! | [`Device::read`] | the loop thread | start of every tick | **no**: bounded time, no allocation, no lock |
//! | [`Device::write`] | the loop thread | end of every tick | **no** |
//! | [`Device::safe_state`] | the loop thread | once, when the loop stops (end, fault, overruns, Ctrl-C) | bounded |
//! | [`Device::latency_ticks`], [`Device::plant_model`] | the caller, before the loop | once, for the stability gate on the loop through the device ([`crate::through`]) | yes |
//!
//! `read` and `write` may do the device's own I/O (a register access, a
//! `sendto`, a DMA kick) and nothing else. A device that loses contact returns
//! [`DeviceError::Watchdog`]: the loop stops and puts every output in its safe
//! state.
//!
//! # Example: a DAQ card skeleton
//!
//! ```
//! use nanomotion_rt::{Channel, Device, DeviceError};
//!
//! /// One ADC channel (a capacitive sensor, m) and one DAC channel (an amplifier, V).
//! struct Daq {
//!     inputs: Vec<Channel>,
//!     outputs: Vec<Channel>,
//!     /// Memory-mapped registers would live here; a plain array in this sketch.
//!     regs: [f64; 2],
//! }
//!
//! impl Device for Daq {
//!     fn name(&self) -> &str { "daq0" }
//!     fn inputs(&self) -> &[Channel] { &self.inputs }
//!     fn outputs(&self) -> &[Channel] { &self.outputs }
//!     fn configure(&mut self, rate_hz: f64) -> Result<(), DeviceError> {
//!         // Program the sample clock, ranges and filters here (may block).
//!         if rate_hz > 100_000.0 {
//!             return Err(DeviceError::Config(format!("daq0 samples at most 100 kHz, the graph runs at {rate_hz} Hz")));
//!         }
//!         Ok(())
//!     }
//!     fn read(&mut self, _now_ns: u64, inputs: &mut [f64]) -> Result<(), DeviceError> {
//!         inputs[0] = self.regs[0] * 1e-6; // counts → m
//!         Ok(())
//!     }
//!     fn write(&mut self, _now_ns: u64, outputs: &[f64]) -> Result<(), DeviceError> {
//!         self.regs[1] = outputs[0].clamp(-10.0, 10.0); // V
//!         Ok(())
//!     }
//! }
//!
//! let mut daq = Daq {
//!     inputs: vec![Channel::new("gap", Some("m"))],
//!     outputs: vec![Channel::new("amp", Some("V"))],
//!     regs: [0.0; 2],
//! };
//! daq.configure(10_000.0).unwrap();
//! daq.safe_state().unwrap(); // the default writes 0 V
//! assert_eq!(daq.regs[1], 0.0);
//! ```

use nanomotion_core::{Block, Params, Port, Tick, declared_block};
use serde::{Deserialize, Serialize};

/// A named scalar channel of a device, with its unit.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct Channel {
    /// Name; the graph's `hw_input` / `hw_output` block of the same name uses it.
    pub name: String,
    /// SI unit (`m`, `V`, `Hz`), if known.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub unit: Option<String>,
}

impl Channel {
    /// A channel called `name` in `unit`.
    pub fn new(name: &str, unit: Option<&str>) -> Self {
        Self {
            name: name.into(),
            unit: unit.map(Into::into),
        }
    }
}

/// What a device reports when it cannot go on.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum DeviceError {
    /// The device cannot be set up as asked (at build).
    #[error("device configuration: {0}")]
    Config(String),
    /// The other side stopped answering: the loop stops, outputs go safe.
    #[error(
        "watchdog: {device} gave no new sample for {silent_ms:.1} ms (limit {limit_ms:.1} ms) at tick {tick}"
    )]
    Watchdog {
        /// Device name.
        device: String,
        /// How long it has been silent (ms).
        silent_ms: f64,
        /// The watchdog limit (ms).
        limit_ms: f64,
        /// Loop tick at which it was noticed.
        tick: u64,
    },
    /// The other side left (a plant process stopped, a controller detached).
    #[error("{0} closed the connection")]
    Closed(String),
    /// Any other I/O failure (the message says which).
    #[error("device I/O: {0}")]
    Io(String),
}

/// A piece of hardware (or a stand-in for it) the real-time loop reads and drives.
///
/// See the [module documentation](self) for what is called on which thread and
/// what may block.
pub trait Device: Send {
    /// Name for messages (`daq0`, `shm:stage`).
    fn name(&self) -> &str;
    /// Channels [`Device::read`] fills, in order (sensors → graph).
    fn inputs(&self) -> &[Channel];
    /// Channels [`Device::write`] takes, in order (graph → actuators).
    fn outputs(&self) -> &[Channel];
    /// Set the device up for a loop at `rate_hz` (once, at build; may block).
    fn configure(&mut self, _rate_hz: f64) -> Result<(), DeviceError> {
        Ok(())
    }
    /// Fill `inputs` (one value per [`Device::inputs`] channel) at the start of a
    /// tick. Must not block beyond the device's own bounded I/O.
    fn read(&mut self, now_ns: u64, inputs: &mut [f64]) -> Result<(), DeviceError>;
    /// Take `outputs` (one value per [`Device::outputs`] channel) after a tick.
    fn write(&mut self, now_ns: u64, outputs: &[f64]) -> Result<(), DeviceError>;
    /// Put every output in its safe state when the loop stops (default: write
    /// zeros). Called once, also after a fault.
    fn safe_state(&mut self) -> Result<(), DeviceError> {
        let zeros = [0.0; 64];
        let n = self.outputs().len();
        if n <= zeros.len() {
            let now = crate::clock::now_ns();
            self.write(now, &zeros[..n])
        } else {
            let v = vec![0.0; n];
            self.write(crate::clock::now_ns(), &v)
        }
    }
    /// Transport delay this device adds, in loop ticks: how many ticks after
    /// [`Device::write`] the outputs reach what they drive and come back,
    /// measured, through [`Device::read`] (0 for a device sampled and driven
    /// at the tick). It is in the timing report (`device_latency_ticks`), and
    /// the stability gate adds it as a delay to the loop closed through the
    /// device when the device has a [`Device::plant_model`]
    /// ([`crate::through`]): a loop whose margin the latency eats is refused
    /// before it runs.
    fn latency_ticks(&self) -> u32 {
        0
    }
    /// A model of what the device drives and measures, for the stability
    /// gate ([`crate::through`]): a graph whose `hw_input` blocks are named
    /// like the device's outputs and whose `hw_output` blocks like its inputs
    /// (a plant graph, as `nanomotion plant --serve` runs). `Ok(None)`
    /// (the default): no model, and the gate has no loop through the device
    /// to judge. Called once, before the loop, on the caller's thread.
    fn plant_model(&self) -> Result<Option<nanomotion_core::GraphSpec>, DeviceError> {
        Ok(None)
    }
}

/// Type tag of the input block.
pub const HW_INPUT: &str = "hw_input";
/// Type tag of the output block.
pub const HW_OUTPUT: &str = "hw_output";

/// `hw_input`: the device channel named like this block, sampled at the start of
/// every tick (`y`, in `unit`). Without a device (`nanomotion run`) it outputs 0.
#[derive(Debug, Clone, Serialize, Deserialize, Params)]
#[serde(deny_unknown_fields)]
#[block(type_name = "hw_input", role = Sensor, ports = "-> y")]
pub struct HwInput {
    /// SI unit of the channel (`m`), checked against the device's when both are known.
    #[serde(default)]
    pub unit: Option<String>,
}

#[declared_block]
impl Block for HwInput {
    fn outputs(&self) -> Vec<Port> {
        let p = Port::new("y", 1);
        vec![match &self.unit {
            Some(u) => p.with_unit(u),
            None => p,
        }]
    }
    /// Writes nothing: the runner puts the device's sample into `y` before each
    /// tick (`Scheduler::write`), and the block holds it.
    fn output(&mut self, _tick: Tick, _u: &[f64], _y: &mut [f64]) {}
}

/// `hw_output`: sends `u` to the device channel named like this block after every
/// tick; `y` repeats `u` (to log it).
#[derive(Debug, Clone, Serialize, Deserialize, Params)]
#[serde(deny_unknown_fields)]
#[block(type_name = "hw_output", role = Actuator, ports = "u -> y")]
pub struct HwOutput {
    /// SI unit of the channel (`V`), checked against the device's when both are
    /// known; without it, `y` has the unit of `u`.
    #[serde(default)]
    pub unit: Option<String>,
}

#[declared_block]
impl Block for HwOutput {
    fn inputs(&self) -> Vec<Port> {
        vec![Port::new("u", 1)]
    }
    fn outputs(&self) -> Vec<Port> {
        let p = Port::new("y", 1);
        vec![match &self.unit {
            Some(u) => p.with_unit(u),
            None => p.unit_of_input(0),
        }]
    }
    fn output(&mut self, _tick: Tick, u: &[f64], y: &mut [f64]) {
        y[0] = u[0];
    }
}
