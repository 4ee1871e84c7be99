//! # nanomotion-mimo
//!
//! MIMO control of R.J.E. Merry, *Performance-driven control of nano-motion
//! systems* (TU/e 2009), Chapter 7.1–7.3, for any LTI MIMO plant (the 3-DOF
//! AFM stage of the thesis is the worked example in `examples/mimo/` and
//! `docs/mimo.md`; this crate does not depend on the `afm-stage` plugin):
//!
//! | module | what | thesis |
//! |---|---|---|
//! | [`plant`] | diagonal second-order terms + constant couplings, fitted to an FRF | (7.1), Sec. 7.2 |
//! | [`weights`] | W_S, W_KS, W_T of the mixed-sensitivity design | (7.10)–(7.12), Table 7.2 |
//! | [`synth`] | generalised plant, H∞ synthesis, verification, crossovers, margins, discretisation, balanced truncation | (7.5)–(7.9) |
//! | [`decentral`] | loop-shaped decentralised controller | (7.2) |
//! | [`robust`] | E = (G − G_d)G_d⁻¹, μ bounds, the (7.4) test, generalised Nyquist | (7.3), (7.4), Fig. 7.6, 7.9 |
//! | [`block`] | `mimo_controller`: a MIMO state-space controller block | Sec. 7.5 |
//! | [`config`] | the `nanomotion synth CONFIG.yaml` design | — |
//! | [`stage3`] | the fixed x, y, z view of a 3-axis stage (glam `DVec3`) | Ch. 7 |
//! | [`thesis`] | the thesis-vs-ours figures of Sec. 7.3 as plain data | Sec. 7.3.2 |
//!
//! ```
//! use nanomotion_mimo::plant::{CoupledPlant, SecondOrderTerm};
//! use nanomotion_mimo::weights::MixedSensitivityWeights;
//! use nanomotion_mimo::synth::synthesise;
//! let t = |k, f| SecondOrderTerm { gain: k, f_hz: f, damping: 0.05 };
//! let g = CoupledPlant {
//!     diagonal: vec![t(850.0, 124.0), t(850.0, 126.0), t(170.0, 350.0)],
//!     coupling: vec![vec![0.0, 8.0, 3.0], vec![8.0, 0.0, 3.0], vec![0.7, 0.7, 0.0]],
//! };
//! let syn = synthesise(&g.to_ss().unwrap(), &MixedSensitivityWeights::thesis_afm()).unwrap();
//! assert_eq!(syn.controller.nstates(), 17); // plant 6 + weights 11, as in the thesis
//! assert!(syn.closed_loop_norm <= syn.gamma * (1.0 + 1e-6));
//! ```

// `!(x > 0.0)` is used on purpose: it also rejects NaN.
#![allow(clippy::neg_cmp_op_on_partial_ord)]

pub mod block;
pub mod config;
pub mod decentral;
pub mod error;
pub mod optim;
pub mod plant;
pub mod robust;
pub mod stage3;
pub mod synth;
pub mod thesis;
pub mod weights;

pub use block::MimoController;
pub use error::MimoError;
