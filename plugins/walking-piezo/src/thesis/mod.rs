//! Thesis experiments on the simulated stage as library code, so that an
//! example, a test and `nanomotion reproduce` call the same function:
//!
//! - [`tables`]: Tables 2.2 and 2.3 (jogging and point-to-point moves through
//!   the example graphs; needs the `gain-scheduling` plugin linked);
//! - [`sec45`]: Sec. 4.5 / Fig. 4.14, the waveform optimisations and their
//!   validation on the perturbed stage.

pub mod sec45;
pub mod tables;
