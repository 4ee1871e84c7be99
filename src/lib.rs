//! # nanomotion
//!
//! Performance-driven control of nano-motion systems — piezo-driven stages and
//! optical-encoder systems that track nanometres — after R.J.E. Merry's PhD thesis
//! (TU Eindhoven, 2009).
//!
//! This facade re-exports the core ([`core`]) and every plugin crate, and linking it
//! registers every block type with the YAML loader. The `nanomotion` binary (see
//! `nanomotion --help`) runs YAML controller graphs.
//!
//! ```
//! use nanomotion::core::graph::GraphSpec;
//! let yaml = std::fs::read_to_string(concat!(env!("CARGO_MANIFEST_DIR"), "/examples/quickstart.yaml")).unwrap();
//! let (mut sched, _report) = GraphSpec::from_yaml(&yaml, "quickstart.yaml").unwrap().build().unwrap();
//! let result = sched.run(|_fraction_done| {});
//! assert!(!result.scores.is_empty());
//! ```

#[doc = include_str!("../README.md")]
#[cfg(doctest)]
pub struct ReadmeDoctests;

pub use afm_stage;
pub use dvrc;
pub use gain_scheduling;
pub use hots;
pub use nanomotion_compensate as compensate;
pub use nanomotion_core as core;
pub use nanomotion_core::{Block, GraphSpec, Scheduler};
pub use nanomotion_directional_rc as directional_rc;
pub use nanomotion_mimo as mimo;
pub use nanomotion_plf as plf;
pub use nanomotion_rt as rt;
pub use timestamp_encoder;
pub use walking_piezo;

/// `serde`, re-exported so that a crate defining blocks needs only `nanomotion`:
/// derive with `#[serde(crate = "nanomotion::serde")]`.
pub use serde;
/// `typetag`, re-exported so that a crate defining blocks needs only `nanomotion`:
/// bring it into scope with `use nanomotion::typetag;` (its expansion names
/// `typetag::`) and register with `#[typetag::serde(name = "...")]`.
///
/// ```
/// use nanomotion::typetag;
/// use nanomotion::serde::{Deserialize, Serialize};
/// use nanomotion::core::{Block, GraphSpec, Port, Tick};
///
/// /// y = 3·u, defined with nothing but `nanomotion`.
/// #[derive(Debug, Serialize, Deserialize)]
/// #[serde(crate = "nanomotion::serde", deny_unknown_fields)]
/// struct Triple {}
///
/// #[typetag::serde(name = "doc_facade_triple")]
/// impl Block for Triple {
///     fn inputs(&self) -> Vec<Port> { vec![Port::new("u", 1)] }
///     fn outputs(&self) -> Vec<Port> { vec![Port::new("y", 1)] }
///     fn output(&mut self, _t: Tick, u: &[f64], y: &mut [f64]) { y[0] = 3.0 * u[0]; }
/// }
///
/// let yaml = "base_rate_hz: 10\nduration_s: 0.1\nblocks:\n  - { name: c, type: constant, value: 2.0 }\n  - { name: t, type: doc_facade_triple }\nconnections:\n  - { from: c.y, to: t.u }\nlog: [t.y]\n";
/// let (mut s, _) = GraphSpec::from_yaml(yaml, "doc.yaml").unwrap().build().unwrap();
/// assert_eq!(s.run(|_| {}).logs[0].data, vec![6.0]);
/// ```
pub use typetag;

pub mod experiments;
pub mod image_plot;
pub mod output;
pub mod plot;
pub mod sweep;
pub mod thesis;

/// Make sure every plugin crate is linked (typetag registers blocks through the
/// linker: a plugin that is never referenced would silently miss from YAML). The
/// `pub use` re-exports above reference each plugin; call this from a binary or
/// test that uses only YAML to be explicit about it.
pub fn link_plugins() {
    // Referencing one item of each plugin keeps it in the link.
    let _ = std::any::type_name::<walking_piezo::WalkingPiezoStage>();
    let _ = std::any::type_name::<afm_stage::stage::AfmStage>();
    let _ = std::any::type_name::<timestamp_encoder::TimestampEncoder>();
    let _ = std::any::type_name::<hots::HotsEstimator>();
    let _ = std::any::type_name::<gain_scheduling::GainSchedule>();
    let _ = std::any::type_name::<dvrc::check::RcCheckReport>();
    let _ = std::any::type_name::<plf::effects::Hysteresis>();
    let _ = std::any::type_name::<directional_rc::FrameRotation>();
    let _ = std::any::type_name::<mimo::MimoController>();
    let _ = std::any::type_name::<compensate::HysteresisInverse>();
    nanomotion_rt::link_blocks();
}
