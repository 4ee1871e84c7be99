//! # nanomotion-afm-stage
//!
//! The metrological AFM of R.J.E. Merry, *Performance-driven control of nano-motion
//! systems* (TU/e 2009), Chapter 6, as plain-Rust types and graph blocks:
//!
//! | module | what | thesis |
//! |---|---|---|
//! | [`hysteresis`] | Coleman–Hodgdon ODE (exact per sample), closed-loop branches, extended asymmetric model | (6.3), (6.4) |
//! | [`feedforward`] | exact inverse with the Lambert W function, trace/retrace switching at standstill; position feed-forward | (6.6), (6.7), Fig. 6.9 |
//! | [`stage`] | 3-DOF plant `afm_stage`: hysteresis, modes, coupling, interferometers, cantilever over a grating | Sec. 6.2, Table 6.1, (7.1) |
//! | [`ident`] | Levenberg–Marquardt fit of (6.4) on reversal curves, accuracy measures, FORC CSV reader | Sec. 6.3.2 |
//! | [`control`] | integral + low-pass controllers, margins, characteristic loci, the Sec. 6.5 scan | (6.5), Fig. 6.8, Sec. 6.5 |
//! | [`blocks`] | `coleman_hodgdon`, `extended_coleman_hodgdon` blocks | (6.3), (6.4) |
//! | [`experiments`] | Sec. 6.5 comparison and speed sweep, closed-loop MIMO FRF identification (G = GS·S⁻¹) | Fig. 6.11, Table 6.4, Figs. 6.4–6.5 |
//!
//! Block types: `afm_stage` (plant), `coleman_hodgdon`, `extended_coleman_hodgdon`
//! (actuators), `hysteresis_feedforward`, `position_feedforward` (controllers).
//! Hysteresis models work in V and µm (Table 6.2's units); the stage and the
//! feed-forward blocks take and give positions in m.
//!
//! ```
//! use afm_stage::hysteresis::{ChParams, ColemanHodgdon, Direction};
//! use afm_stage::ident::{fit_extended, measure_loops, THESIS_RANGES_V};
//! use afm_stage::feedforward::HysteresisFeedForward;
//!
//! // An asymmetric piezo (the "real" stage), its loops on the ranges of Sec. 6.3.2,
//! // the extended model fitted to them, and the inverse feed-forward for a ±18 µm scan.
//! let piezo = ColemanHodgdon::new(ChParams::new(0.03, 1.0, 0.7), ChParams::new(0.045, 0.93, 0.62)).unwrap();
//! let (trace, retrace) = measure_loops(&piezo, 50.0, &THESIS_RANGES_V, 41, 0.0, 1).unwrap();
//! let (model, rep_t, _) = fit_extended(&trace, &retrace).unwrap();
//! assert!(rep_t.accuracy_percent > 97.0);
//! let mut ff = HysteresisFeedForward::for_position_range(model, 27.0, 63.0).unwrap();
//! let v = ff.step(45.0);
//! assert!((ff.branch(Direction::Trace).eval(v) - 45.0).abs() < 1e-9);
//! ```

// `!(x > 0.0)` is used on purpose: it also rejects NaN, which `x <= 0.0` lets through.
#![allow(clippy::neg_cmp_op_on_partial_ord)]
// Per-axis loops index several parallel [_; 3] arrays at once.
#![allow(clippy::needless_range_loop)]

pub mod blocks;
pub mod control;
pub mod error;
pub mod experiments;
pub mod feedforward;
pub mod hysteresis;
pub mod ident;
pub mod stage;

pub use error::AfmError;
pub use feedforward::{HysteresisFeedForward, PositionFeedForward};
pub use hysteresis::{ChParams, ColemanHodgdon, Direction, ExtendedBranch, ExtendedCh};
pub use stage::AfmStage;
