//! # nanomotion-directional-rc
//!
//! Directional repetitive control (DRC) after R.J.E. Merry, *Performance-driven
//! control of nano-motion systems*, PhD thesis, TU Eindhoven, 2009, **Sec. 7.4**
//! (SPEC §3): a sample rotated by α about z makes the topography non-repetitive
//! from one scan line to the next; estimating α from a few line scans and rotating
//! the scan references and the controller axes by R(α) makes it repetitive again,
//! so that repetitive control (RC) on the imaging axis z can learn it.
//!
//! | what | thesis | Rust | block `type:` |
//! |---|---|---|---|
//! | rotation estimate from line scans: correlation, sub-sample peak, shift, angle, averaging | (7.18)–(7.21) | [`estimate::estimate_rotation`] | — |
//! | the estimate inside a graph: records the lines, estimates once (preallocated, one tick), outputs α | (7.18)–(7.21) | [`estimator_block::RotationEstimator`] | `rotation_estimator` |
//! | the scan plan: estimation lines, then the raster scan in the sample frame | Sec. 7.4.3, Fig. 7.11 | [`plan::ScanPlan`] | `drc_scan_plan` |
//! | rotation R(α) of references, errors and controller outputs between actuator and sample frame | (7.17), Fig. 7.11 | [`frame::FrameRotation`] (glam `DMat2`) | `frame_rotation` |
//!
//! The RC itself (7.13) with its learning filter (ZPETC) and robustness filter Q is
//! the `repetitive_control` block of the `dvrc` plugin; this crate does not depend on
//! it. A DRC graph combines the two (see `examples/directional_rc/` and
//! `docs/directional-rc.md`).

pub mod estimate;
pub mod estimator_block;
pub mod frame;
pub mod plan;

pub use estimate::{
    EstimateError, EstimatorOptions, LineScan, RotationEstimate, estimate_rotation,
};
pub use estimator_block::{OnFailure, RotationEstimator};
pub use frame::{Direction, FrameRotation, rotation};
pub use plan::ScanPlan;
