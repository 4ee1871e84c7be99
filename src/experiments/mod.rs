//! Thesis experiments that need several plugins, as library code: the example,
//! the test and `nanomotion reproduce` (`thesis::ch5`, `thesis::ch7`) call the same
//! functions.
//!
//! - [`directional_rc`]: the Sec. 7.5 experiment (afm-stage, dvrc,
//!   directional-rc): the rotation estimate, RC against DRC; run by
//!   `cargo run --release --example directional_rc` and
//!   `tests/directional_rc_example.rs`;
//! - [`table51`], [`table51_nonlinear`]: Table 5.1 on the linear fitted stage
//!   and on the nonlinear walking piezo stage (dvrc, walking-piezo); run by the
//!   dvrc plugin's examples `table_5_1`, `table_5_1_nonlinear` and its tests of
//!   the same names (which reach this crate as a dev-dependency).

pub mod directional_rc;
pub mod table51;
pub mod table51_nonlinear;
