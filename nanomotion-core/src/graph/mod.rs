//! YAML controller graphs: the schema ([`GraphSpec`]), loading with located errors,
//! and compilation into a [`Scheduler`](crate::scheduler::Scheduler).
//!
//! - `spec.rs`: the schema, the limits, the builder methods for graphs written in Rust;
//! - [`include`](mod@include): `- include: FILE` block entries, spliced before parsing;
//! - `load.rs`: YAML text and files to a [`GraphSpec`], "did you mean";
//! - `compile.rs`: [`GraphSpec::build`] and its variants, in named phases.
//!
//! The compiler sits on the block contract ([`crate::block`]) and the scheduler;
//! the stability gate ([`crate::gate`]) and the data layer ([`crate::data`]) read
//! the built [`Scheduler`](crate::scheduler::Scheduler), not the compiler.
//!
//! The format is documented in `docs/graph-format.md`. In short:
//!
//! ```
//! use nanomotion_core::graph::GraphSpec;
//! let yaml = r#"
//! base_rate_hz: 1000
//! duration_s: 0.01
//! seed: 1
//! blocks:
//!   - { name: src, type: graph_doc_const, value: 2.0 }
//! log: [src.y]
//! "#;
//! # use nanomotion_core::{Block, Port, Tick};
//! # #[derive(Debug, serde::Serialize, serde::Deserialize)]
//! # struct C { value: f64 }
//! # #[typetag::serde(name = "graph_doc_const")]
//! # impl Block for C {
//! #     fn outputs(&self) -> Vec<Port> { vec![Port::new("y", 1)] }
//! #     fn output(&mut self, _t: Tick, _u: &[f64], y: &mut [f64]) { y[0] = self.value; }
//! # }
//! let spec = GraphSpec::from_yaml(yaml, "doc.yaml").unwrap();
//! let (mut sched, _report) = spec.build().unwrap();
//! let result = sched.run(|_| {});
//! assert_eq!(result.logs[0].data, vec![2.0; 10]);
//! ```

mod compile;
pub mod include;
mod load;
mod schema;
mod spec;

pub use crate::files::read_text_capped;
pub use crate::scheduler::RATE_TRANSITION_PREFIX;
pub(crate) use load::nearest;
pub use load::{MAX_SUGGEST_BYTES, edit_distance, is_near};
pub use schema::graph_schema;
pub use spec::{
    BlockSpec, BuildReport, CompareSpec, Connection, Graph, GraphSpec, LOG_CHUNK_TICKS,
    MAX_BLOCK_NAME_CHARS, MAX_GRAPH_BYTES, MAX_GRAPH_FILE_BYTES, MAX_RATE_HZ, MAX_TICKS,
    MAX_TITLE_CHARS, MAX_UNIT_CHARS, MIN_RATE_HZ, OverrunPolicy, RealtimeSpec, ScoreSpec,
    valid_block_name,
};
