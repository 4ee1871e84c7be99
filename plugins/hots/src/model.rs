//! The HOTS error model and the optimiser of (m, n, σ).
//!
//! Derivation (details in `docs/plugins/hots.md`). Assume locally constant speed
//! |v| (counts/s) and (m+1)-th derivative x^(m+1) (counts/s^(m+1)). The register
//! holds the newest event and n − 1 grid events σ + 1 counts apart (8.7); with the
//! newest event j ∈ {0, …, σ} counts past the last grid event (uniform over j; j = 0
//! means it is on the grid), the events sit at positions 0, −j, −j − (σ+1), …
//! counts relative to the newest, i.e. at scaled times τ_i = pos_i / span_j ∈ [−1, 0]
//! with span_j the window in counts and T = span_j/|v| in seconds. The read instant
//! is `age` counts after the newest event, uniform in [0, 1): τ_c = age/span_j.
//!
//! With A the n×(m+1) matrix of (8.1) in τ and w_r = φ_r(τ_c)ᵀ(AᵀA)⁻¹Aᵀ the weights
//! that map event positions to the r-th τ-derivative at τ_c:
//!
//! - **variance** (event errors ε_i: edge errors with autocovariance R(Δ) over the
//!   edge distance Δ, plus clock quantisation, white with variance v²/(12 f_clk²)):
//!   Var = |v|^{2r}/span^{2r} · (w_rᵀ C w_r + v²/(12 f_clk²) w_rᵀ w_r),
//!   C_ik = R(|pos_i − pos_k|). White edge errors (R(0) = σ_enc², else 0) give the
//!   SPEC's σ²/T^{2r} · φᵀ(AᵀA)⁻¹φ; a correlated R captures that the four edges of
//!   one slit share its offset and that quadrature errors repeat every 4 counts (a
//!   skip with σ + 1 a multiple of 4 cancels them).
//! - **truncation bias**: the LS fit reproduces the degree-≤m part exactly; the
//!   (m+1)-th term x^(m+1)/(m+1)! · T^{m+1} τ^{m+1} leaves the residual ρ(τ) = τ^{m+1}
//!   − (its LS projection), so bias_r = x^(m+1)/(m+1)! · T^{m+1−r} · ρ^{(r)}(τ_c).
//!
//! Averaged over j and age (Gauss–Legendre, 6 nodes, exact for the polynomial
//! dependence on τ_c), the expected squared error of the r-th derivative is
//!
//! ```text
//! E[e_r²] = |v|^{2r} (G_e + v²/(12 f_clk²) G_w) + (x^(m+1)/(m+1)!)² |v|^{−2(m+1−r)} H,
//! ```
//!
//! with `G_e = E[span^{−2r} wᵀCw]`, `G_w = E[span^{−2r} wᵀw]`, `H = E[span^{2(m+1−r)} ρ^{(r)}²]`
//! depending only on (m, n, σ, r) and R. Where this exceeds what the estimator's
//! fallback would give (1/12 count² in position, v² in velocity, a² in
//! acceleration: the count, zero, zero), the fallback value is used. Over a
//! trajectory the expected mean-square error is the average over its samples.
//!
//! [`optimise`] evaluates every (m, n, σ) of a [`Grid`] and sorts them.

use nalgebra::{DMatrix, DVector};
use serde::{Deserialize, Serialize};
use timestamp_encoder::fit::{MAX_M, MAX_N};

/// Which quantity the settings are optimised for (the derivative order r).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Target {
    /// r = 0.
    Position = 0,
    /// r = 1.
    Velocity = 1,
    /// r = 2.
    Acceleration = 2,
}

/// A choice of time-stamping settings.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
pub struct Settings {
    /// Polynomial order m.
    pub order: usize,
    /// Register length n (events).
    pub register_len: usize,
    /// Skip σ (events).
    pub skip: usize,
}

/// The event-error model: edge errors as a stationary sequence over the edge index
/// with autocovariance R(Δ), Δ in counts, plus the clock.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ErrorModel {
    /// R(Δ) (counts²) for Δ = 0, 1, …; zero beyond the end.
    pub edge_autocov_counts2: Vec<f64>,
    /// Time-stamp clock (Hz).
    pub clock_hz: f64,
}

impl ErrorModel {
    /// White edge errors of standard deviation `std_counts`.
    pub fn white(std_counts: f64, clock_hz: f64) -> Self {
        Self {
            edge_autocov_counts2: vec![std_counts * std_counts],
            clock_hz,
        }
    }
    /// From a full table of per-edge errors e_L (counts) of one revolution (4N
    /// values): the circular autocovariance R(Δ) = mean_L e_L e_{L+Δ} (not
    /// centred: a common offset is a position error too).
    pub fn from_edge_errors(e: &[f64], clock_hz: f64) -> Self {
        let n = e.len();
        let r = (0..n)
            .map(|d| (0..n).map(|l| e[l] * e[(l + d) % n]).sum::<f64>() / n as f64)
            .collect();
        Self {
            edge_autocov_counts2: r,
            clock_hz,
        }
    }
    fn r(&self, d: usize) -> f64 {
        let n = self.edge_autocov_counts2.len();
        if n == 0 {
            0.0
        } else if n > 1 && d >= n {
            // A full-table model is periodic.
            self.edge_autocov_counts2[d % n]
        } else {
            self.edge_autocov_counts2.get(d).copied().unwrap_or(0.0)
        }
    }
}

/// Local motion at one sample: speed and derivative magnitudes (counts, s).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct MotionSample {
    /// |x^(j)| for j = 0..=5 (counts/s^j); index 1 is the speed.
    pub deriv: [f64; 6],
}

/// The grid searched by [`optimise`].
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Grid {
    /// Orders m (each ≤ 4).
    pub orders: Vec<usize>,
    /// Register lengths n (each ≤ 16; pairs with n ≤ m are skipped).
    pub register_lens: Vec<usize>,
    /// Skips σ.
    pub skips: Vec<usize>,
}

impl Grid {
    /// The thesis's hardware: n = 5 fixed, m ∈ {1, 2, 3}, σ ∈ {0, …, 5, 10, 20}
    /// (Sec. 8.5's values) plus 7 and 15.
    pub fn thesis_hardware() -> Self {
        Self {
            orders: vec![1, 2, 3],
            register_lens: vec![5],
            skips: vec![0, 1, 2, 3, 4, 5, 7, 10, 15, 20],
        }
    }
}

/// The v-independent factors (G_e, G_w, H) of the model for one setting and target.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Factors {
    /// E[span^{−2r} wᵀCw] (counts² · counts^{−2r}).
    pub g_edge: f64,
    /// E[span^{−2r} wᵀw].
    pub g_white: f64,
    /// E[span^{2(m+1−r)} ρ^{(r)}(τ_c)²].
    pub h: f64,
}

const GL_X: [f64; 6] = [
    0.033_765_242_898_423_99,
    0.169_395_306_766_867_74,
    0.380_690_406_958_401_5,
    0.619_309_593_041_598_5,
    0.830_604_693_233_132_3,
    0.966_234_757_101_576,
];
const GL_W: [f64; 6] = [
    0.085_662_246_189_585_17,
    0.180_380_786_524_069_3,
    0.233_956_967_286_345_5,
    0.233_956_967_286_345_5,
    0.180_380_786_524_069_3,
    0.085_662_246_189_585_17,
];

fn falling(j: usize, r: usize) -> f64 {
    (0..r).map(|i| (j - i) as f64).product()
}

/// The model's factors for `s` and `target` (see the module documentation).
/// Returns `None` for settings the estimator does not support (n ≤ m, m > 4, n > 16).
pub fn factors(s: Settings, target: Target, model: &ErrorModel) -> Option<Factors> {
    let (m, n, sigma, r) = (s.order, s.register_len, s.skip, target as usize);
    if n <= m || m > MAX_M || !(2..=MAX_N).contains(&n) {
        return None;
    }
    let s1 = sigma + 1;
    let mut acc = Factors {
        g_edge: 0.0,
        g_white: 0.0,
        h: 0.0,
    };
    for j in 0..s1 {
        let pos: Vec<usize> = (0..n)
            .map(|i| {
                if j == 0 {
                    i * s1
                } else if i == 0 {
                    0
                } else {
                    j + (i - 1) * s1
                }
            })
            .collect();
        let span = pos[n - 1] as f64;
        let a = DMatrix::from_fn(n, m + 1, |i, k| (-(pos[i] as f64) / span).powi(k as i32));
        let ata_inv = (a.transpose() * &a).try_inverse()?;
        let pinv = &ata_inv * a.transpose(); // (m+1)×n
        let f = DVector::from_fn(n, |i, _| (-(pos[i] as f64) / span).powi(m as i32 + 1));
        let beta = &pinv * f;
        let c = DMatrix::from_fn(n, n, |i, k| model.r(pos[i].abs_diff(pos[k])));
        for (&xg, &wg) in GL_X.iter().zip(&GL_W) {
            let tau_c = xg / span;
            // φ_r(τ_c): d^r/dτ^r of τ^k.
            let phi = DVector::from_fn(m + 1, |k, _| {
                if k < r {
                    0.0
                } else {
                    falling(k, r) * tau_c.powi((k - r) as i32)
                }
            });
            let w = pinv.transpose() * &phi; // n
            let ge = (w.transpose() * &c * &w)[0];
            let gw = w.norm_squared();
            let rho = falling(m + 1, r) * tau_c.powi((m + 1 - r) as i32) - beta.dot(&phi);
            let weight = wg / s1 as f64;
            acc.g_edge += weight * ge * span.powi(-2 * r as i32);
            acc.g_white += weight * gw * span.powi(-2 * r as i32);
            acc.h += weight * rho * rho * span.powi(2 * (m + 1 - r) as i32);
        }
    }
    Some(acc)
}

fn factorial(k: usize) -> f64 {
    (1..=k).map(|i| i as f64).product()
}

/// Expected squared error of derivative r at one motion sample, capped at the
/// fallback's error (counts²/s^{2r}).
pub fn expected_sq_error(
    s: Settings,
    target: Target,
    model: &ErrorModel,
    f: &Factors,
    x: &MotionSample,
) -> f64 {
    let r = target as usize;
    let m = s.order;
    let v = x.deriv[1].abs();
    let fallback = match target {
        Target::Position => 1.0 / 12.0,
        Target::Velocity => v * v,
        Target::Acceleration => x.deriv[2] * x.deriv[2],
    };
    if v == 0.0 {
        return fallback;
    }
    let clock_var = v * v / (12.0 * model.clock_hz * model.clock_hz);
    let var = v.powi(2 * r as i32) * (f.g_edge + clock_var * f.g_white);
    let dm = if m < 5 {
        x.deriv[m + 1] / factorial(m + 1)
    } else {
        0.0
    };
    let bias2 = dm * dm * v.powi(-2 * (m + 1 - r) as i32) * f.h;
    let e = var + bias2;
    if e.is_finite() {
        e.min(fallback)
    } else {
        fallback
    }
}

/// Expected mean-square error over the motion samples (counts²/s^{2r}); `None` for
/// unsupported settings.
pub fn expected_ms(
    s: Settings,
    target: Target,
    model: &ErrorModel,
    samples: &[MotionSample],
) -> Option<f64> {
    let f = factors(s, target, model)?;
    let sum: f64 = samples
        .iter()
        .map(|x| expected_sq_error(s, target, model, &f, x))
        .sum();
    Some(sum / samples.len().max(1) as f64)
}

/// Every supported setting of `grid` with its expected mean-square error, best first.
///
/// ```
/// use hots::model::{optimise, sinusoid_samples, ErrorModel, Grid, Target};
/// // 100-line encoder (400 counts/rev) on (π/2) sin(2π t) rad = 100 counts amplitude,
/// // per-edge errors of 0.02 counts, 20 MHz clock.
/// let samples = sinusoid_samples(100.0, 1.0, 1000);
/// let ranked = optimise(&Grid::thesis_hardware(), Target::Velocity, &ErrorModel::white(0.02, 20e6), &samples);
/// let (best, ms) = ranked[0];
/// assert!(best.skip > 0, "slit errors favour a skip: {best:?}");
/// assert!(ms < ranked.last().unwrap().1);
/// ```
pub fn optimise(
    grid: &Grid,
    target: Target,
    model: &ErrorModel,
    samples: &[MotionSample],
) -> Vec<(Settings, f64)> {
    let mut out = Vec::new();
    for &m in &grid.orders {
        for &n in &grid.register_lens {
            for &skip in &grid.skips {
                let s = Settings {
                    order: m,
                    register_len: n,
                    skip,
                };
                if let Some(e) = expected_ms(s, target, model, samples) {
                    out.push((s, e));
                }
            }
        }
    }
    out.sort_by(|a, b| a.1.total_cmp(&b.1));
    out
}

/// Motion samples of x = A sin(2π f t) (A in counts) at `n` uniformly spaced times
/// over one period.
pub fn sinusoid_samples(amplitude_counts: f64, freq_hz: f64, n: usize) -> Vec<MotionSample> {
    let w = std::f64::consts::TAU * freq_hz;
    (0..n)
        .map(|i| {
            let ph = w * (i as f64 + 0.5) / (n as f64 * freq_hz);
            let mut d = [0.0; 6];
            for (j, dj) in d.iter_mut().enumerate() {
                let phase = ph + j as f64 * std::f64::consts::FRAC_PI_2;
                *dj = (amplitude_counts * w.powi(j as i32) * phase.sin()).abs();
            }
            MotionSample { deriv: d }
        })
        .collect()
}

/// Motion samples from a recorded trajectory `x` (counts) sampled every `dt` s:
/// derivatives by repeated central differences (interior samples only). The record
/// should be smooth (e.g. a reference or a filtered high-resolution measurement).
pub fn samples_from_trajectory(x: &[f64], dt: f64) -> Vec<MotionSample> {
    let mut ders: Vec<Vec<f64>> = vec![x.to_vec()];
    for _ in 1..6 {
        let prev = ders.last().unwrap();
        let d: Vec<f64> = (0..prev.len())
            .map(|i| {
                if i == 0 || i + 1 >= prev.len() {
                    f64::NAN
                } else {
                    (prev[i + 1] - prev[i - 1]) / (2.0 * dt)
                }
            })
            .collect();
        ders.push(d);
    }
    (5..x.len().saturating_sub(5))
        .map(|i| {
            let mut d = [0.0; 6];
            for j in 0..6 {
                d[j] = ders[j][i].abs();
            }
            MotionSample { deriv: d }
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn white_variance_matches_the_spec_formula() {
        // σ = 0, n events 1 count apart, white errors: G_w must equal the average of
        // φᵀ(AᵀA)⁻¹φ / span^{2r}, computed here independently.
        let model = ErrorModel::white(1.0, 1e300);
        for (m, n) in [(1usize, 3usize), (2, 5), (3, 8)] {
            let s = Settings {
                order: m,
                register_len: n,
                skip: 0,
            };
            for target in [Target::Position, Target::Velocity, Target::Acceleration] {
                let f = factors(s, target, &model).unwrap();
                let r = target as usize;
                let span = (n - 1) as f64;
                let a = DMatrix::from_fn(n, m + 1, |i, k| (-(i as f64) / span).powi(k as i32));
                let inv = (a.transpose() * &a).try_inverse().unwrap();
                let mut expect = 0.0;
                for (&x, &w) in GL_X.iter().zip(&GL_W) {
                    let tc: f64 = x / span;
                    let phi = DVector::from_fn(m + 1, |k, _| {
                        if k < r {
                            0.0
                        } else {
                            falling(k, r) * tc.powi((k - r) as i32)
                        }
                    });
                    expect += w * (phi.transpose() * &inv * &phi)[0] / span.powi(2 * r as i32);
                }
                assert!(
                    (f.g_white - expect).abs() < 1e-9 * expect.max(1e-12),
                    "{m} {n} {target:?}"
                );
                assert!((f.g_edge - f.g_white).abs() < 1e-9 * f.g_white.max(1e-12));
            }
        }
    }

    #[test]
    fn truncation_bias_matches_a_direct_fit() {
        // x(t) = v t + c t³ sampled at the constant-velocity event times of the model,
        // fitted with m = 2 by the real estimator fit: the mean squared velocity bias
        // over the read ages equals (x‴/3!)² v^{−4} H.
        let (v, c) = (500.0, 2.0e4);
        for skip in [0usize, 2] {
            let s = Settings {
                order: 2,
                register_len: 5,
                skip,
            };
            let f = factors(s, Target::Velocity, &ErrorModel::white(0.0, 1e300)).unwrap();
            let s1 = skip + 1;
            let mut direct = 0.0;
            for j in 0..s1 {
                let pos: Vec<f64> = (0..5)
                    .map(|i| {
                        if j == 0 {
                            (i * s1) as f64
                        } else if i == 0 {
                            0.0
                        } else {
                            (j + (i - 1) * s1) as f64
                        }
                    })
                    .collect();
                let t: Vec<f64> = pos.iter().map(|p| -p / v).collect();
                let x: Vec<f64> = t.iter().map(|&t| v * t + c * t * t * t).collect();
                for (&xg, &wg) in GL_X.iter().zip(&GL_W) {
                    let tc = xg / v;
                    let fit = timestamp_encoder::fit::fit_events(&t, &x, 2, tc).unwrap();
                    let bias = fit.v - (v + 3.0 * c * tc * tc);
                    direct += wg / s1 as f64 * bias * bias;
                }
            }
            let model = c * c * v.powi(-4) * f.h;
            assert!(
                (direct / model - 1.0).abs() < 1e-6,
                "σ {skip}: direct {direct:e}, model {model:e}"
            );
        }
    }
}
