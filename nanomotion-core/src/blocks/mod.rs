//! The standard block library. Every block is a plain Rust type implementing its
//! role trait (see [`crate::roles`]) and, as a thin adapter, [`crate::Block`]
//! registered with `typetag` under the `type:` name given in its docs.

pub mod control;
pub mod data_column;
pub mod linear;
pub mod math;
pub mod sensors;
pub mod sources;
