//! # nanomotion-plf — the performance-limiting-factor (PLF) workflow
//!
//! The last step of the thesis's design loop (Merry 2009, Ch. 1.2–1.3, Fig. 1.1:
//! identify the performance-limiting factor, model it, compensate it, validate),
//! made automatic: given a model graph and a measured record, find where they
//! disagree, name the missing effect from a vocabulary of the thesis's PLFs, fit
//! it, insert it into the graph, and show the residual shrink.
//!
//! - [`effects`]: the effect blocks (one registered block type per vocabulary
//!   entry), each [`Tunable`](nanomotion_core::Tunable) so the workflow can fit it.

pub mod effects;
pub mod stats;
