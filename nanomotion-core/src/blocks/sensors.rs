//! Generic sensor imperfections: `quantizer` (finite resolution) and
//! `measurement_noise` (additive seeded noise, Gaussian or bounded uniform). Both
//! implement [`Sensor`]; input `u` is the true quantity, output `y` the measurement.
//!
//! The thesis's sensors: the metrological AFM's interferometers resolve 0.15 nm
//! ([`INTERFEROMETER_LSB_M`]) with noise bounds of ±5, ±4 and ±2 nm on x, y, z
//! (Table 6.1); the walking-piezo stage of Ch. 2 is measured with 5 nm resolution.
//!
//! ```
//! use nanomotion_core::Sensor;
//! use nanomotion_core::blocks::sensors::{Quantizer, Rounding, INTERFEROMETER_LSB_M};
//! let mut q = Quantizer::new(INTERFEROMETER_LSB_M, Rounding::Round);
//! let mut y = [0.0];
//! q.measure(0.0, &[1.0e-9], &mut y);
//! assert!((y[0] - 7.0 * 0.15e-9).abs() < 1e-24); // 1 nm reads as 7 counts
//! ```

use crate::block::check;
use crate::rng::Rng;
use crate::{Block, BuildContext, ParamError, Params, Sensor, Tick, Tunable, declared_block};
use serde::{Deserialize, Serialize};

/// Resolution of the metrological AFM's laser interferometers (m), Ch. 6.
pub const INTERFEROMETER_LSB_M: f64 = 0.15e-9;

fn one() -> usize {
    1
}

/// How a [`Quantizer`] maps a value onto its grid of `lsb` steps.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, Params)]
#[serde(rename_all = "snake_case")]
pub enum Rounding {
    /// To the nearest step (ties away from zero): error in [−lsb/2, lsb/2],
    /// zero mean, variance lsb²/12. An interferometer or an interpolating ADC.
    Round,
    /// To the step below (towards −∞): error in (−lsb, 0], mean −lsb/2. An
    /// incremental encoder's count.
    Floor,
}

fn round() -> Rounding {
    Rounding::Round
}

/// `quantizer`: finite resolution, y = lsb·round(u/lsb) or lsb·⌊u/lsb⌋,
/// element-wise; with an `offset` o the grid is shifted: y = o + lsb·round((u − o)/lsb).
///
/// [`Tunable`] parameter vector: `[lsb, offset]`.
#[derive(Debug, Clone, Serialize, Deserialize, Params)]
#[serde(deny_unknown_fields)]
#[block(type_name = "quantizer", role = Sensor, ports = "u[width] -> y[width] [unit of u]")]
pub struct Quantizer {
    /// Resolution: one least-significant bit (unit of u, e.g. 0.15e-9 m for the
    /// interferometer).
    #[param(positive)]
    pub lsb: f64,
    /// `round` (nearest: interferometer) or `floor` (encoder count).
    #[serde(default = "round")]
    pub rounding: Rounding,
    /// Signal width n.
    #[serde(default = "one")]
    #[param(width)]
    pub width: usize,
    /// Offset o of the grid (unit of u): the levels are o + k·lsb; tunable with
    /// `lsb` (parameter vector `[lsb, offset]`).
    #[serde(default, skip_serializing_if = "is_zero")]
    #[param(finite)]
    pub offset: f64,
}

fn is_zero(x: &f64) -> bool {
    *x == 0.0
}

impl Quantizer {
    /// A scalar quantiser with resolution `lsb`.
    pub fn new(lsb: f64, rounding: Rounding) -> Self {
        Self {
            lsb,
            rounding,
            width: 1,
            offset: 0.0,
        }
    }
    /// The same quantiser with its grid shifted by `offset` (unit of u).
    pub fn with_offset(mut self, offset: f64) -> Self {
        self.offset = offset;
        self
    }
    /// One value quantised.
    pub fn quantize(&self, x: f64) -> f64 {
        if self.offset == 0.0 {
            return self.grid(x / self.lsb) * self.lsb;
        }
        self.offset + self.grid((x - self.offset) / self.lsb) * self.lsb
    }
    fn grid(&self, q: f64) -> f64 {
        match self.rounding {
            Rounding::Round => q.round(),
            Rounding::Floor => q.floor(),
        }
    }
}

impl Tunable for Quantizer {
    fn param_names(&self) -> Vec<String> {
        vec!["lsb".into(), "offset".into()]
    }
    fn params(&self) -> Vec<f64> {
        vec![self.lsb, self.offset]
    }
    fn set_params(&mut self, p: &[f64]) -> Result<(), ParamError> {
        if p.len() != 2 {
            return Err(ParamError::new(
                "params",
                format!("{} values given", p.len()),
                "give [lsb, offset]",
            ));
        }
        let tuned = Self {
            lsb: p[0],
            offset: p[1],
            ..self.clone()
        };
        tuned.check_params()?;
        *self = tuned;
        Ok(())
    }
}

impl Sensor for Quantizer {
    fn measure(&mut self, _t: f64, x: &[f64], y: &mut [f64]) {
        for (yi, &xi) in y.iter_mut().zip(x) {
            *yi = self.quantize(xi);
        }
    }
}

#[declared_block]
impl Block for Quantizer {
    fn output(&mut self, tick: Tick, u: &[f64], y: &mut [f64]) {
        self.measure(tick.t, u, y);
    }
    fn linearisation(&self) -> Option<crate::block::Linearisation> {
        Some(crate::block::Linearisation::single(
            crate::lti::StateSpace::gain(nalgebra::DMatrix::identity(self.width, self.width), None),
            format!(
                "quantiser (lsb {}) judged as gain 1 (its error, at most lsb/2, is bounded noise)",
                self.lsb
            ),
        ))
    }
    fn tunable(&self) -> Option<&dyn Tunable> {
        Some(self)
    }
    fn tunable_mut(&mut self) -> Option<&mut dyn Tunable> {
        Some(self)
    }
}

// ---------------------------------------------------------------------------------
// measurement_noise
// ---------------------------------------------------------------------------------

/// Distribution of [`MeasurementNoise`].
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, Params)]
#[serde(rename_all = "snake_case")]
pub enum NoiseDistribution {
    /// N(0, σ²) with σ = `std`.
    Gaussian,
    /// Uniform in [−`bound`, `bound`]: bounded noise like the interferometer noise
    /// bounds ±5/±4/±2 nm of Table 6.1 (σ = bound/√3).
    Uniform,
}

fn placeholder_rng() -> Rng {
    Rng::new(0)
}

/// `measurement_noise`: y = u + w with w white (gaussian with `std`, or uniform
/// in ±`bound`: Table 6.1), seeded from [`BuildContext::seed`] (same seed, same
/// bits), independent per channel.
#[derive(Debug, Clone, Serialize, Deserialize, Params)]
#[serde(deny_unknown_fields)]
#[block(type_name = "measurement_noise", role = Sensor, ports = "u[width] -> y[width] [unit of u]")]
pub struct MeasurementNoise {
    /// Distribution of w.
    #[serde(default = "gaussian")]
    pub distribution: NoiseDistribution,
    /// Standard deviation σ (unit of u), for `gaussian`.
    #[serde(default)]
    pub std: Option<f64>,
    /// Half-width of the uniform noise (unit of u, e.g. 5e-9 m), for `uniform`.
    #[serde(default)]
    pub bound: Option<f64>,
    /// Signal width n.
    #[serde(default = "one")]
    #[param(width)]
    pub width: usize,
    #[serde(skip)]
    scale: f64,
    #[serde(skip, default = "placeholder_rng")]
    rng: Rng,
}

fn gaussian() -> NoiseDistribution {
    NoiseDistribution::Gaussian
}

impl MeasurementNoise {
    /// Gaussian noise of standard deviation `std`, seeded with `seed`.
    pub fn gaussian(std: f64, seed: u64) -> Result<Self, ParamError> {
        let mut m = Self::unseeded(NoiseDistribution::Gaussian, Some(std), None);
        m.prepare(seed)?;
        Ok(m)
    }
    /// Uniform noise in [−bound, bound], seeded with `seed`.
    pub fn uniform(bound: f64, seed: u64) -> Result<Self, ParamError> {
        let mut m = Self::unseeded(NoiseDistribution::Uniform, None, Some(bound));
        m.prepare(seed)?;
        Ok(m)
    }
    fn unseeded(distribution: NoiseDistribution, std: Option<f64>, bound: Option<f64>) -> Self {
        Self {
            distribution,
            std,
            bound,
            width: 1,
            scale: 0.0,
            rng: placeholder_rng(),
        }
    }
    fn prepare(&mut self, seed: u64) -> Result<(), ParamError> {
        self.check_params()?;
        self.scale = match (self.distribution, self.std, self.bound) {
            (NoiseDistribution::Gaussian, Some(s), None) => {
                check::non_negative("std", s)?;
                s
            }
            (NoiseDistribution::Uniform, None, Some(b)) => {
                check::non_negative("bound", b)?;
                b
            }
            (NoiseDistribution::Gaussian, _, _) => {
                return Err(ParamError::new(
                    "std",
                    "gaussian noise needs `std` (and no `bound`)",
                    "give std, or set distribution: uniform with bound",
                ));
            }
            (NoiseDistribution::Uniform, _, _) => {
                return Err(ParamError::new(
                    "bound",
                    "uniform noise needs `bound` (and no `std`)",
                    "give bound, or set distribution: gaussian with std",
                ));
            }
        };
        self.rng = Rng::new(seed);
        Ok(())
    }
}

impl Sensor for MeasurementNoise {
    fn measure(&mut self, _t: f64, x: &[f64], y: &mut [f64]) {
        for (yi, &xi) in y.iter_mut().zip(x) {
            let w = match self.distribution {
                NoiseDistribution::Gaussian => self.rng.normal(),
                NoiseDistribution::Uniform => self.rng.uniform_in(-1.0, 1.0),
            };
            *yi = xi + self.scale * w;
        }
    }
}

#[declared_block]
impl Block for MeasurementNoise {
    fn build(&mut self, ctx: &BuildContext) -> Result<(), ParamError> {
        self.prepare(ctx.seed)
    }
    fn output(&mut self, tick: Tick, u: &[f64], y: &mut [f64]) {
        self.measure(tick.t, u, y);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const DT: f64 = 5e-5; // 20 kHz, the Ch. 7 rate

    fn built(text: &str, seed: u64) -> Box<dyn Block> {
        let mut b: Box<dyn Block> = crate::yaml::from_str(text, "test").unwrap();
        b.build(&BuildContext::new("sensor", DT, seed)).unwrap();
        b
    }

    fn build_err(text: &str) -> String {
        let mut b: Box<dyn Block> = crate::yaml::from_str(text, "test").unwrap();
        b.build(&BuildContext::new("sensor", DT, 0))
            .unwrap_err()
            .field
    }

    fn run(b: &mut dyn Block, k: u64, u: &[f64]) -> Vec<f64> {
        let mut y = vec![0.0; u.len()];
        b.output(Tick::new(k, DT), u, &mut y);
        y
    }

    #[test]
    fn quantizer_round_and_floor_error_bands() {
        let lsb = INTERFEROMETER_LSB_M;
        let mut r = Quantizer::new(lsb, Rounding::Round);
        let mut f = Quantizer::new(lsb, Rounding::Floor);
        let (mut sum_r, mut sum_f, mut sq_r) = (0.0, 0.0, 0.0);
        let n = 10_000;
        let mut rng = Rng::new(11);
        for _ in 0..n {
            // Positions spread over many steps (both signs), unrelated to the grid.
            let x = rng.uniform_in(-500e-9, 500e-9);
            let (mut yr, mut yf) = ([0.0], [0.0]);
            r.measure(0.0, &[x], &mut yr);
            f.measure(0.0, &[x], &mut yf);
            // On the grid.
            assert!(((yr[0] / lsb) - (yr[0] / lsb).round()).abs() < 1e-6);
            let (er, ef) = (yr[0] - x, yf[0] - x);
            assert!(er.abs() <= lsb / 2.0 * (1.0 + 1e-9), "round error {er}");
            assert!(
                ef <= 1e-9 * lsb && ef > -lsb * (1.0 + 1e-9),
                "floor error {ef}"
            );
            sum_r += er;
            sum_f += ef;
            sq_r += er * er;
        }
        // Uniform quantisation error: mean 0 (round) or −lsb/2 (floor), var lsb²/12.
        let n = n as f64;
        assert!((sum_r / n).abs() < 0.02 * lsb);
        assert!((sum_f / n + lsb / 2.0).abs() < 0.02 * lsb);
        assert!((sq_r / n / (lsb * lsb / 12.0) - 1.0).abs() < 0.05);
        // Exact values.
        assert_eq!(Quantizer::new(0.5, Rounding::Round).quantize(1.3), 1.5);
        assert_eq!(Quantizer::new(0.5, Rounding::Floor).quantize(1.3), 1.0);
        assert_eq!(Quantizer::new(0.5, Rounding::Floor).quantize(-0.1), -0.5);
    }

    #[test]
    fn quantizer_from_yaml_and_validation() {
        let mut q = built(
            "type: quantizer\nlsb: 5.0e-9\nrounding: floor\nwidth: 2\n",
            0,
        );
        let y = run(q.as_mut(), 0, &[12e-9, -1e-9]);
        assert!(
            (y[0] - 10e-9).abs() < 1e-24 && (y[1] + 5e-9).abs() < 1e-24,
            "{y:?}"
        );
        assert_eq!(build_err("type: quantizer\nlsb: 0\n"), "lsb");
        assert_eq!(build_err("type: quantizer\nlsb: .nan\n"), "lsb");
        assert!(
            crate::yaml::from_str::<Box<dyn Block>>(
                "type: quantizer\nlsb: 1\nrounding: ceil\n",
                "t"
            )
            .is_err()
        );
    }

    #[test]
    fn uniform_noise_is_bounded_with_variance_bound_sq_over_3() {
        let bound = 5e-9; // x-axis bound of Table 6.1
        let mut b = built(
            "type: measurement_noise\ndistribution: uniform\nbound: 5.0e-9\n",
            9,
        );
        let n = 100_000;
        let (mut s, mut s2, mut max) = (0.0, 0.0, 0.0f64);
        for k in 0..n {
            let w = run(b.as_mut(), k, &[1e-6])[0] - 1e-6;
            s += w;
            s2 += w * w;
            max = max.max(w.abs());
        }
        assert!(max <= bound * (1.0 + 1e-9));
        assert!(max > 0.999 * bound, "fills the band");
        let mean = s / n as f64;
        let var = s2 / n as f64 - mean * mean;
        assert!(mean.abs() < 0.02 * bound);
        assert!(
            (var / (bound * bound / 3.0) - 1.0).abs() < 0.02,
            "var ratio {}",
            var / (bound * bound / 3.0)
        );
    }

    #[test]
    fn gaussian_noise_moments_and_determinism() {
        let text = "type: measurement_noise\nstd: 2.0\nwidth: 2\n";
        let mut b = built(text, 4);
        let n = 100_000;
        let draws: Vec<Vec<f64>> = (0..n).map(|k| run(b.as_mut(), k, &[3.0, -3.0])).collect();
        for (i, u) in [3.0, -3.0].into_iter().enumerate() {
            let mean = draws.iter().map(|y| y[i] - u).sum::<f64>() / n as f64;
            let var = draws.iter().map(|y| (y[i] - u - mean).powi(2)).sum::<f64>() / n as f64;
            assert!(mean.abs() < 0.03, "mean {mean}");
            assert!((var - 4.0).abs() < 0.08, "var {var}");
        }
        b.build(&BuildContext::new("sensor", DT, 4)).unwrap();
        let again: Vec<Vec<f64>> = (0..100).map(|k| run(b.as_mut(), k, &[3.0, -3.0])).collect();
        assert_eq!(again, draws[..100].to_vec(), "rebuild gives the same bits");
        let mut plain = MeasurementNoise::gaussian(2.0, 4).unwrap();
        plain.width = 2;
        let mut y = [0.0; 2];
        plain.measure(0.0, &[3.0, -3.0], &mut y);
        assert_eq!(y.to_vec(), draws[0]);
        assert_eq!(build_err("type: measurement_noise\n"), "std");
        assert_eq!(
            build_err("type: measurement_noise\ndistribution: uniform\nstd: 1\n"),
            "bound"
        );
        assert_eq!(build_err("type: measurement_noise\nstd: -1\n"), "std");
        assert!(MeasurementNoise::uniform(f64::NAN, 0).is_err());
    }

    #[test]
    fn ticks_do_not_allocate() {
        for text in [
            "type: quantizer\nlsb: 1.0e-9\nwidth: 3\n",
            "type: measurement_noise\nstd: 1.0e-9\nwidth: 3\n",
            "type: measurement_noise\ndistribution: uniform\nbound: 1.0e-9\nwidth: 3\n",
        ] {
            let mut b = built(text, 1);
            let u = [1e-6, 2e-6, 3e-6];
            let mut y = [0.0; 3];
            let info = allocation_counter::measure(|| {
                for k in 0..1000 {
                    b.output(Tick::new(k, DT), &u, &mut y);
                }
            });
            assert_eq!(info.count_total, 0, "{text}");
        }
    }
}
