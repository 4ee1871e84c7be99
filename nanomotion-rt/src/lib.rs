//! # nanomotion-rt
//!
//! Run a nanomotion graph on the wall clock, against hardware.
//!
//! - [`RealtimeRunner`] ticks a built [`Scheduler`](nanomotion_core::Scheduler)
//!   on a dedicated thread at the graph's base rate: absolute deadlines
//!   (`clock_nanosleep(CLOCK_MONOTONIC, TIMER_ABSTIME)`), `SCHED_FIFO`, CPU
//!   pinning and `mlockall` where permitted (refused privileges are named with
//!   their fix; the run goes on at normal priority only if allowed), overruns
//!   counted and handled by an [`OverrunPolicy`], a stop at too many overruns
//!   or at a device fault with the outputs put in their safe state.
//! - [`Timing`]: wake-up latency, period and execution time — per tick and,
//!   when asked ([`RtConfig::block_timing`]), per block — in fixed-memory
//!   [`Histogram`]s (p50/p99/p99.9/max), reported as a [`TimingReport`].
//! - [`Device`]: the hardware boundary (read at the start of a tick, write after
//!   it, safe state, watchdog), connected to a graph by the `hw_input` and
//!   `hw_output` blocks of the same name.
//! - [`live`]: parameter updates while the loop runs (`set ctrl.kp=1.2`),
//!   judged off the loop (the block's own validation, optionally the
//!   stability gate), applied at a tick boundary through a wait-free ring,
//!   recorded and replayed.
//! - [`record`]: every hardware sample and live parameter update of a run as
//!   MCAP, and a bit-exact replay of it through the graph.
//! - [`shm`]: a plant graph in another process (`nanomotion plant --serve`)
//!   behind a [`ShmDevice`], over shared memory.
//! - [`through`]: the stability gate on the loop closed through a device, with
//!   the device's declared latency ([`Device::latency_ticks`]) as a delay in it.
//!
//! Nothing in a tick allocates, locks or calls the system except the sleep and
//! the device's own I/O; events leave the loop through a wait-free ring.
//!
//! ```
//! use nanomotion_core::GraphSpec;
//! use nanomotion_rt::{NoDevice, RealtimeRunner, RtConfig};
//! let yaml = "base_rate_hz: 1000\nduration_s: 0.02\nblocks:\n  - { name: c, type: constant, value: 1.0 }\nlog: [c.y]\n";
//! let (sched, _) = GraphSpec::from_yaml(yaml, "doc.yaml").unwrap().build().unwrap();
//! let mut cfg = RtConfig::default();
//! cfg.allow_soft = true; // run even where SCHED_FIFO is not permitted
//! let mut runner = RealtimeRunner::new(sched, NoDevice, cfg).unwrap();
//! let report = runner.run(|_event| {}).unwrap();
//! assert_eq!(report.ticks, 20);
//! assert_eq!(report.wakeup_latency.count, 20);
//! ```

pub mod clock;
pub mod device;
pub mod histogram;
pub mod live;
pub mod record;
pub mod runner;
pub mod shm;
pub mod through;

pub use clock::{Missing, Privileges};
pub use device::{Channel, Device, DeviceError, HwInput, HwOutput};
pub use histogram::{Histogram, Summary};
pub use live::{LiveError, LiveParam, ParamSender, ParamUpdate, live_params};
pub use nanomotion_core::graph::RealtimeSpec;
pub use record::{
    ReplayReport, SimRecorder, hw_log_names, load_dataset, read_mcap, replay, write_mcap,
};
pub use runner::{
    BlockTime, Event, NoDevice, OverrunPolicy, ParamChange, RealtimeRunner, Recording, RtConfig,
    RtError, Stop, Timing, TimingReport, hw_blocks,
};
pub use shm::{ConnectError, PlantInfo, ShmDevice, ShmPlant};

/// Make sure this crate's blocks (`hw_input`, `hw_output`) are linked into a
/// binary that only loads YAML (typetag registers them through the linker).
pub fn link_blocks() {
    let _ = std::any::type_name::<HwInput>();
    let _ = std::any::type_name::<HwOutput>();
}
