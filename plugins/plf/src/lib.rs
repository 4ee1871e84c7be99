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
//! - [`stats`]: the statistics it decides with (whiteness, input correlation,
//!   periodic lines, held-out improvement), tested for their false-alarm rates.
//! - [`surgery`]: where an effect can enter a graph, and inserting it.
//! - [`fit`]: parameter fitting by re-simulation (Levenberg–Marquardt).
//! - [`pool`]: independent fits run on every core, results in a fixed order.
//! - [`diagnose()`]: the workflow itself.
//! - [`datasets`]: measured records from outside, joined and scaled as their
//!   authors describe (the rack-and-pinion friction rig).

pub mod datasets;
pub mod diagnose;
pub mod effects;
pub mod fit;
pub mod generate;
pub mod pool;
pub mod scenario;
pub mod stats;
pub mod surgery;

pub use diagnose::{Options, Report, diagnose};

/// What can go wrong in the workflow.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum PlfError {
    /// The model graph cannot be used as it is (names the problem and the fix).
    #[error("model: {0}")]
    Model(String),
    /// The measured data cannot be used.
    #[error("data: {0}")]
    Data(String),
    /// An option is out of range.
    #[error("option `{option}`: {problem}")]
    Option {
        /// The option.
        option: &'static str,
        /// What is wrong and how to fix it.
        problem: String,
    },
}
