//! `slit_correction`: a slit-error table applied to an encoder's position
//! reading, in the sensor path of a loop.
//!
//! The table is a [`SlitCalibration`]'s: ê_L (counts) is edge L's position
//! minus its nominal L. A reading y (unit of the position) is c = (y − zero)/Δ
//! counts. The block takes the count L whose correction brings the reading
//! nearest L itself — L minimises |c + ê_{L mod n} − L| over the counts within
//! reach of c — and gives zero + Δ·(c + ê_L). Two readings meet this rule:
//!
//! - an integer count L of a real encoder with |ê| < 1/2: L + ê_L, the position
//!   of the edge it last crossed (what [`SlitCalibration::correct`] gives);
//! - the `encoder_slit_error` model the diagnosis fits on a quantised position
//!   (y = kΔ + e_k, slit k centred on kΔ, plf's `effects::slit`): with
//!   ê_k = −e_k/Δ the reading goes back to kΔ exactly (to round-off), since the
//!   right k lands at distance 0 and any other at |k − L + (e_k − e_L)/Δ|, which
//!   is not 0 unless two slits' readings coincide.

use crate::SlitCalibration;
use nanomotion_core::Params;
use nanomotion_core::block::Linearisation;
use nanomotion_core::lti::StateSpace;
use nanomotion_core::{Block, BuildContext, ParamError, Port, Tick, declared_block};
use serde::{Deserialize, Serialize};

/// Longest table of a `slit_correction` (a disc of 4096 lines read in
/// quadrature).
pub const MAX_EDGES: usize = 16384;

/// `slit_correction`: slit-error correction table on an encoder's position
/// reading: the count L nearest its own corrected reading, then zero + Δ(c + ê_L).
///
/// Input `u` (the position reading y, c = (y − zero)/Δ counts), output `y` (the
/// corrected position), the ports of plf's `encoder_slit_error`. The table ê (counts per edge, 1 ≤ n ≤ 16384) comes from
/// `calibration_file` (a [`SlitCalibration`] as JSON, read once in `build`) or
/// inline `edge_offsets_counts` (one of the two).
#[derive(Debug, Clone, Serialize, Deserialize, Params)]
#[serde(deny_unknown_fields)]
#[block(
    type_name = "slit_correction",
    role = Estimator,
    ports = "u (position reading) -> y (corrected position)"
)]
pub struct SlitCorrection {
    /// Resolution Δ (unit of the reading per count).
    #[param(positive)]
    pub resolution: f64,
    /// Reading of count 0 (unit of the reading), default 0.
    #[serde(default)]
    #[param(finite)]
    pub zero: f64,
    /// Path of a JSON [`SlitCalibration`], read in `build`.
    /// At most 16 MiB; a relative path is relative to the graph file's folder.
    #[serde(default)]
    pub calibration_file: Option<String>,
    /// Inline table ê (counts per edge): edge L's position minus L.
    #[serde(default)]
    pub edge_offsets_counts: Vec<f64>,
    /// The table in use (built).
    #[serde(skip)]
    table: Vec<f64>,
    /// Counts searched either side of the reading: ⌈max |ê|⌉ + 1.
    #[serde(skip)]
    reach: i64,
}

impl SlitCorrection {
    /// The correction of a calibration `cal` on readings of resolution Δ with
    /// count 0 read as `zero`.
    pub fn new(resolution: f64, zero: f64, cal: &SlitCalibration) -> Self {
        Self::with_table(resolution, zero, cal.edge_offsets_counts.clone())
    }

    /// The correction of the table ê `edge_offsets_counts` (counts).
    pub fn with_table(resolution: f64, zero: f64, edge_offsets_counts: Vec<f64>) -> Self {
        Self {
            resolution,
            zero,
            calibration_file: None,
            edge_offsets_counts,
            table: Vec::new(),
            reach: 1,
        }
    }

    /// The table that undoes plf's `encoder_slit_error` (y = u + e[⌊(u −
    /// origin)/pitch⌋ mod N]) on positions on its slits' centres (a quantiser of
    /// lsb = pitch before it): Δ = pitch, zero = origin + pitch/2 (slit 0's
    /// centre), ê = −e/pitch.
    pub fn inverse_of_slit_errors(pitch: f64, origin: f64, errors: &[f64]) -> Self {
        Self::with_table(
            pitch,
            origin + 0.5 * pitch,
            errors.iter().map(|e| -e / pitch).collect(),
        )
    }

    /// The corrected position of the reading `y`. No allocation; a non-finite
    /// reading is passed on as it is.
    pub fn correct(&self, y: f64) -> f64 {
        let n = self.table.len() as i64;
        let c = (y - self.zero) / self.resolution;
        if !c.is_finite() || n == 0 {
            return y;
        }
        let centre = c.round() as i64;
        let mut best = (f64::INFINITY, 0.0);
        for l in centre.saturating_sub(self.reach)..=centre.saturating_add(self.reach) {
            let e = self.table[l.rem_euclid(n) as usize];
            let miss = (c + e - l as f64).abs();
            if miss < best.0 {
                best = (miss, e);
            }
        }
        y + self.resolution * best.1
    }

    /// The table in use, after `build`.
    pub fn table(&self) -> &[f64] {
        &self.table
    }
}

#[declared_block]
impl Block for SlitCorrection {
    fn inputs(&self) -> Vec<Port> {
        vec![Port::new("u", 1)]
    }
    fn outputs(&self) -> Vec<Port> {
        vec![Port::new("y", 1).unit_of_input(0)]
    }
    fn build(&mut self, ctx: &BuildContext) -> Result<(), ParamError> {
        self.check_params()?;
        let table = crate::calibration_table(
            self.calibration_file.as_deref(),
            &self.edge_offsets_counts,
            ctx,
        )?;
        if table.is_empty() || table.len() > MAX_EDGES {
            return Err(ParamError::new(
                "edge_offsets_counts",
                format!(
                    "has {} entries; a table needs 1 to {MAX_EDGES}",
                    table.len()
                ),
                "give the calibration's table (`edge_offsets_counts` or `calibration_file`)",
            ));
        }
        let largest = table.iter().fold(0.0f64, |m, e| m.max(e.abs()));
        if largest > 1e6 {
            return Err(ParamError::new(
                "edge_offsets_counts",
                format!("has an offset of {largest:e} counts"),
                "give offsets in counts (a fraction of one count on a real disc)",
            ));
        }
        self.reach = largest.ceil() as i64 + 1;
        self.table = table;
        Ok(())
    }
    fn output(&mut self, _tick: Tick, u: &[f64], y: &mut [f64]) {
        y[0] = self.correct(u[0]);
    }
    /// Gain 1: the correction moves the reading by at most max |ê|·Δ.
    fn linearisation(&self) -> Option<Linearisation> {
        let largest = self
            .table
            .iter()
            .chain(&self.edge_offsets_counts)
            .fold(0.0f64, |m, e| m.max(e.abs()));
        Some(Linearisation::single(
            StateSpace::gain(nalgebra::DMatrix::identity(1, 1), None),
            format!(
                "slit correction judged as gain 1 (it moves the reading by at most {:e})",
                largest * self.resolution
            ),
        ))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn built(mut c: SlitCorrection) -> SlitCorrection {
        c.build(&BuildContext::new("slit_correction", 1e-3, 0))
            .unwrap();
        c
    }

    /// plf's slit model y = kΔ + e_k on a quantised position, written here as
    /// its definition (slit k centred on kΔ, origin −Δ/2), then corrected: back
    /// to kΔ to round-off, for errors up to 0.9 of a pitch either way (the
    /// readings of neighbouring slits cross).
    #[test]
    fn it_undoes_the_diagnosed_slit_model() {
        let pitch = 5e-8;
        let errors: Vec<f64> = (0..13)
            .map(|i| 0.9 * pitch * (1.7 * i as f64 + 0.3).sin())
            .collect();
        let c = built(SlitCorrection::inverse_of_slit_errors(
            pitch,
            -0.5 * pitch,
            &errors,
        ));
        let mut worst: f64 = 0.0;
        for k in -500i64..500 {
            let x = k as f64 * pitch;
            let y = x + errors[k.rem_euclid(13) as usize];
            worst = worst.max((c.correct(y) - x).abs());
        }
        assert!(worst < 1e-12 * pitch, "{worst:e}");
    }

    /// Integer readings with a calibration of |ê| < 1/2 get L + ê_L, as
    /// [`SlitCalibration::correct`] (Δ = 2 µm, count 0 read as 1 mm).
    #[test]
    fn integer_counts_get_the_calibration_s_correction() {
        let cal = SlitCalibration {
            edge_offsets_counts: vec![0.1, -0.05, 0.3, -0.35],
            residual_rms_counts: 0.0,
            events: 0,
        };
        let (d, zero) = (2e-6, 1e-3);
        let c = built(SlitCorrection::new(d, zero, &cal));
        for l in 0..40 {
            let want = zero + d * cal.correct(l as f64);
            let got = c.correct(zero + d * l as f64);
            assert!((got - want).abs() < 1e-12 * d, "{l}: {got} vs {want}");
        }
    }

    #[test]
    fn bad_tables_are_refused_by_name_and_the_tick_does_not_allocate() {
        let ctx = BuildContext::new("b", 1e-3, 0);
        let field = |mut c: SlitCorrection| c.build(&ctx).unwrap_err().field;
        assert_eq!(
            field(SlitCorrection::with_table(1.0, 0.0, vec![])),
            "edge_offsets_counts"
        );
        assert_eq!(
            field(SlitCorrection::with_table(1.0, 0.0, vec![0.1, f64::NAN])),
            "edge_offsets_counts[1]"
        );
        assert_eq!(
            field(SlitCorrection::with_table(0.0, 0.0, vec![0.1])),
            "resolution"
        );
        let mut both = SlitCorrection::with_table(1.0, 0.0, vec![0.1]);
        both.calibration_file = Some("cal.json".into());
        assert_eq!(field(both), "calibration_file");
        let mut c = built(SlitCorrection::with_table(1e-6, 0.0, vec![0.2, -0.2, 0.1]));
        assert!(c.correct(f64::NAN).is_nan());
        assert_eq!(c.correct(f64::INFINITY), f64::INFINITY);
        let mut y = [0.0];
        let info = allocation_counter::measure(|| {
            for k in 0..10_000u64 {
                c.output(
                    Tick::new(k, 1e-3),
                    &[1e-6 * (k as f64 * 1e-3).sin()],
                    &mut y,
                );
            }
        });
        assert_eq!(info.count_total, 0);
    }
}
