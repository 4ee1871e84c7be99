//! # nanomotion-hots
//!
//! **Higher-order time-stamping (HOTS)** for optical incremental encoders after
//! R.J.E. Merry, *Performance-driven control of nano-motion systems*, PhD thesis,
//! TU Eindhoven, 2009, Chapter 9 ("Optimal higher-order time-stamping") — a chapter
//! missing from our copy of the text, so this crate is a reconstruction from first
//! principles (derivation in `docs/plugins/hots.md`), built on the Chapter 8
//! time-stamping of the `nanomotion-timestamp-encoder` crate, **on which this crate
//! depends** (the encoder, the register with skip and the LS fit are reused).
//!
//! | what | where | block `type:` |
//! |---|---|---|
//! | error model: truncation bias² + variance of the LS fit for (m, n, σ), from slit-error statistics and the clock; optimiser over a grid | [`model`] | — |
//! | slit-error calibration: per-edge table jointly with a smooth motion by LS, serde-storable | [`calibration`] | — |
//! | estimator with a stored calibration (loaded from a JSON file or given inline) | [`HotsEstimator`] | `hots_estimator` |
//! | the calibration's table on a position reading (the count nearest its corrected reading) | [`SlitCorrection`] | `slit_correction` |
//! | simulation harness (brute-force check, Sec. 8.5) | [`sim`] | — |
//!
//! Examples: `cargo run --release -p nanomotion-hots --example sec8_5` reproduces
//! the comparison of Sec. 8.5 (Figs. 8.7–8.8 and the −54 % / −92 % claim, in shape):
//! rms position/velocity/acceleration errors of differencing, time-stamping for each
//! skip σ ∈ {0, …, 5, 10, 20}, and HOTS + calibration, on a 100-line encoder with
//! the real US Digital E2 slit-error profile, with random slit errors and without
//! slit errors — against the true trajectory and against the thesis's reference, a
//! 5000-line encoder filtered forward-backward by a 5th-order 50 Hz Butterworth
//! ([`sim::reference_encoder`]). Tables and discussion: `docs/encoders.md`.
//!
//! ```
//! use hots::model::{optimise, sinusoid_samples, ErrorModel, Grid, Target};
//! use hots::sim::simulate;
//! use timestamp_encoder::TimestampEncoder;
//! // Choose (m, n, σ) for velocity on (π/2) sin(2π t) rad (100 counts amplitude)
//! // with white edge errors of 0.03 counts, then check it in simulation.
//! let model = ErrorModel::white(0.03, 20e6);
//! let best = optimise(&Grid::thesis_hardware(), Target::Velocity, &model, &sinusoid_samples(100.0, 1.0, 500))[0].0;
//! let enc = TimestampEncoder { skip: best.skip as i64, register_len: best.register_len, ..Default::default() };
//! let (a, w) = (std::f64::consts::FRAC_PI_2, std::f64::consts::TAU);
//! let run = simulate(&enc, best.order, &[], 1e3, 1.0, 0, false, |t| {
//!     [a * (w * t).sin(), a * w * (w * t).cos(), -a * w * w * (w * t).sin()]
//! }).unwrap();
//! assert!(run.errors(0.05).v < 0.5, "{:?}", run.errors(0.05));
//! ```

pub mod calibration;
pub mod correction;
pub mod model;
pub mod sim;

pub use calibration::{CalibrationError, SlitCalibration};
pub use correction::SlitCorrection;
pub use model::{ErrorModel, Grid, MotionSample, Settings, Target};

use nanomotion_core::Params;
use nanomotion_core::block::check;
use nanomotion_core::{Block, BuildContext, Estimator, ParamError, Port, Tick, declared_block};
use serde::{Deserialize, Serialize};
use timestamp_encoder::{Fallback, TimestampEstimator};

fn d_m() -> usize {
    2
}
fn d_n() -> usize {
    5
}
fn d_band() -> f64 {
    1.0
}
fn d_timeout() -> f64 {
    0.01
}

/// Largest `calibration_file` read: 16 MiB (a real calibration is a few kB).
pub const MAX_CALIBRATION_BYTES: u64 = 16 << 20;

/// `hots_estimator`: HOTS (Ch. 9 reconstruction): time-stamping LS estimator of order m
/// with a stored per-edge slit calibration applied to the events.
///
/// The time-stamping estimator of order m with a stored slit
/// calibration applied to every event before the fit. The calibration comes from
/// `calibration_file` (a [`SlitCalibration`] as JSON, read once in `build`) or
/// inline `edge_offsets_counts` (not both). Choose `order` here and `register_len`
/// / `skip` on the `timestamp_encoder` with [`model::optimise`].
///
/// Input `register` (2 + 2n, the encoder's layout); outputs `y` = [x̂, ẋ̂, ẍ̂] and
/// `status`, as `timestamp_estimator`.
#[derive(Debug, Clone, Serialize, Deserialize, Params)]
#[serde(deny_unknown_fields)]
#[block(type_name = "hots_estimator", role = Estimator, ports = "register[2+2n] -> y[3] = [x, v, a], status")]
pub struct HotsEstimator {
    /// Polynomial order m, default 2.
    /// At most 4.
    #[serde(default = "d_m")]
    pub order: usize,
    /// Register length n of the encoder, default 5.
    /// n > m.
    #[serde(default = "d_n")]
    pub register_len: usize,
    /// Resolution Δ (units per count).
    pub resolution: f64,
    /// Fallback band (counts), default 1.
    #[serde(default = "d_band")]
    pub band_counts: f64,
    /// Out-of-band rule (Sec. 8.3): `thesis` (default: position → count, v̂/â
    /// from the fit) or `zero_standstill` (also v̂ = â = 0, plus the standstill
    /// rule); see `timestamp_encoder::Fallback`.
    #[serde(default)]
    #[param(default_doc = "thesis")]
    pub fallback: Fallback,
    /// Standstill timeout (s), default 0.01 (`fallback: zero_standstill` only).
    /// 0 disables.
    #[serde(default = "d_timeout")]
    pub standstill_timeout_s: f64,
    /// Path of a JSON [`SlitCalibration`], read in `build`.
    /// At most 16 MiB; a relative path is relative to the graph file's folder.
    #[serde(default)]
    pub calibration_file: Option<String>,
    /// Inline calibration table ê (counts per edge).
    #[serde(default)]
    pub edge_offsets_counts: Vec<f64>,
    #[serde(skip)]
    inner: Option<TimestampEstimator>,
}

impl HotsEstimator {
    /// An estimator of order `m`, register `n`, resolution Δ, with calibration `cal`.
    pub fn new(
        m: usize,
        n: usize,
        resolution: f64,
        cal: &SlitCalibration,
    ) -> Result<Self, ParamError> {
        let mut h = Self {
            order: m,
            register_len: n,
            resolution,
            band_counts: d_band(),
            fallback: Fallback::Thesis,
            standstill_timeout_s: d_timeout(),
            calibration_file: None,
            edge_offsets_counts: cal.edge_offsets_counts.clone(),
            inner: None,
        };
        h.prepare(&BuildContext::new("hots_estimator", 1.0, 0))?;
        Ok(h)
    }

    /// Validate, read the calibration (a relative `calibration_file` resolves
    /// against the graph file's folder, `ctx.base_dir`) and build the estimator.
    fn prepare(&mut self, ctx: &BuildContext) -> Result<(), ParamError> {
        let table = calibration_table(
            self.calibration_file.as_deref(),
            &self.edge_offsets_counts,
            ctx,
        )?;
        let mut e = TimestampEstimator::new(self.order, self.register_len, self.resolution)?;
        e.band_counts = self.band_counts;
        e.fallback = self.fallback;
        e.standstill_timeout_s = self.standstill_timeout_s;
        e.edge_offsets_counts = table;
        e.validate()?;
        self.inner = Some(e);
        Ok(())
    }
}

/// The calibration table ê of a block: read from `calibration_file` (a JSON
/// [`SlitCalibration`], relative to the graph file's folder, at most
/// [`MAX_CALIBRATION_BYTES`]) or the inline `edge_offsets_counts` (not both),
/// every entry finite.
pub(crate) fn calibration_table(
    calibration_file: Option<&str>,
    edge_offsets_counts: &[f64],
    ctx: &BuildContext,
) -> Result<Vec<f64>, ParamError> {
    let table = match calibration_file {
        Some(path) => {
            if !edge_offsets_counts.is_empty() {
                return Err(ParamError::new(
                    "calibration_file",
                    "given together with edge_offsets_counts",
                    "give one of calibration_file and edge_offsets_counts",
                ));
            }
            let resolved = ctx.resolve(path);
            let text = nanomotion_core::graph::read_text_capped(&resolved, MAX_CALIBRATION_BYTES)
                .map_err(|e| {
                    ParamError::new(
                        "calibration_file",
                        format!("cannot read `{}`: {e}", resolved.display()),
                        "give the path of a JSON calibration, relative to the graph file's folder or absolute",
                    )
                })?;
            let cal: SlitCalibration = serde_json::from_str(&text).map_err(|e| {
                ParamError::new(
                    "calibration_file",
                    format!("`{path}` is not a calibration: {e}"),
                    "write it with serde_json::to_string(&SlitCalibration)",
                )
            })?;
            cal.edge_offsets_counts
        }
        None => edge_offsets_counts.to_vec(),
    };
    check::all_finite("edge_offsets_counts", &table)?;
    Ok(table)
}

impl Estimator for HotsEstimator {
    fn estimate(&mut self, t: f64, measurement: &[f64], estimate: &mut [f64]) {
        match &mut self.inner {
            Some(e) => e.estimate(t, measurement, estimate),
            None => estimate.iter_mut().for_each(|v| *v = f64::NAN),
        }
    }
}

#[declared_block]
impl Block for HotsEstimator {
    fn inputs(&self) -> Vec<Port> {
        vec![Port::new("register", 2 + 2 * self.register_len)]
    }
    fn outputs(&self) -> Vec<Port> {
        vec![Port::new("y", 3), Port::new("status", 1)]
    }
    fn build(&mut self, ctx: &BuildContext) -> Result<(), ParamError> {
        self.prepare(ctx)
    }
    fn output(&mut self, tick: Tick, u: &[f64], y: &mut [f64]) {
        match &mut self.inner {
            Some(e) => {
                let s = e.estimate_from_register(tick.t, u, &mut y[..3]);
                y[3] = s as u8 as f64;
            }
            None => y.iter_mut().for_each(|v| *v = f64::NAN),
        }
    }
}
