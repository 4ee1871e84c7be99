//! Physical models shared by several plugin crates (plugins never depend on each
//! other, so a model two of them need lives here).
//!
//! - [`hysteresis`]: the Coleman–Hodgdon differential hysteresis model (Merry 2009,
//!   Sec. 6.3, (6.3)), integrated exactly per sample, unit-agnostic.

pub mod hysteresis;
