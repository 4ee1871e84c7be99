//! # nanomotion-core
//!
//! The core of **nanomotion**, a framework for controlling nano-motion systems
//! (piezo-driven stages, optical-encoder systems) after R.J.E. Merry,
//! *Performance-driven control of nano-motion systems*, PhD thesis, TU Eindhoven, 2009.
//!
//! What lives here:
//! - [`block`]: the [`Block`] trait every graph block implements (registered with
//!   `typetag`, so YAML names a block by `type:`), ports, build context and parameter
//!   validation helpers;
//! - [`doc`]: one declaration per block: `#[derive(Params)]` turns the parameter
//!   struct into the block's documentation, JSON Schema and bound checks;
//! - [`roles`]: the role traits [`Actuator`], [`Sensor`], [`Estimator`],
//!   [`Controller`], [`LearningFilter`], [`Plant`] and [`Source`], which give every
//!   block a typed Rust API usable without any graph;
//! - [`graph`] and [`scheduler`]: YAML controller graphs, validated and compiled once
//!   into a flat, allocation-free multi-rate tick loop;
//! - [`gate`] (the stability gate) and [`data`] (measured data, `compare`): beside
//!   the compiler, they read a built graph ([`Scheduler`]); [`learning`]: what a
//!   learning block exposes to the gate and the criteria (5.5)/(5.9);
//! - [`lti`]: discrete LTI toolkit (transfer functions, state space, Tustin/ZOH,
//!   delays, frequency response, H∞ norm, FIR design, ZPETC);
//! - [`analysis`]: Welch PSD/CPSD, cumulative PSD, FRF identification (open and
//!   closed loop), zero-phase filtering, metrics;
//! - [`models`]: physical models several plugins share (Coleman–Hodgdon
//!   hysteresis);
//! - [`blocks`]: the standard block library (gains, sums, filters, PID, noise,
//!   references, ...);
//! - [`overrides`]: parameter overrides by dotted path (`blocks.pi.kp=2.0`)
//!   applied to a graph before it is built;
//! - [`rng`]: the seeded, version-stable random number generator behind all noise.
//!
//! The thesis's equation numbers are given as (n.m) in the documentation.

pub mod analysis;
pub mod block;
pub mod blocks;
pub mod data;
pub mod doc;
pub mod error;
mod files;
pub mod gate;
pub mod graph;
/// `- include: FILE` block entries (part of reading a graph: [`graph::include`](mod@graph::include)).
pub use graph::include;
pub mod learning;
pub mod lti;
#[cfg(feature = "mat")]
mod mat5;
pub mod models;
pub mod overrides;
mod require;
pub mod rng;
pub mod roles;
pub mod scheduler;
pub mod yaml;

/// The linear-algebra crate the toolkit's matrices come from ([`lti`] models are
/// `nalgebra::DMatrix<f64>`), re-exported so that callers build and read
/// models with exactly the version the core is compiled against, without a
/// nalgebra dependency of their own: `use nanomotion_core::nalgebra::DMatrix;`.
pub use nalgebra;

pub use block::MeasuredData;
// The derive (`nanomotion-derive`) names `::nanomotion_core` paths, in this crate too.
extern crate self as nanomotion_core;

pub use block::{
    Block, BuildContext, DeclaredBlock, DeclaredPorts, Linearisation, Port, Sector, Tick, Tunable,
    declared_block,
};
pub use doc::Params;
pub use doc::{BlockDoc, ParamDoc, Role};
pub use error::{GraphError, ParamError};
pub use graph::{Graph, GraphSpec};
pub use overrides::Override;
pub use roles::{Actuator, Controller, Estimator, LearningFilter, Plant, Sensor, Source};
pub use scheduler::Scheduler;

/// Re-exported so that plugin and third-party crates register blocks with the same
/// `typetag` and `inventory` versions as the core.
#[doc(hidden)]
pub mod __private {
    pub use inventory;
    pub use serde_json;
    pub use typetag;
}
