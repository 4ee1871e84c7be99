//! Seeded, slowly varying friction coefficient.
//!
//! The thesis measured a friction coefficient between legs and drive strip that
//! "showed a large variation, possibly due to the orientation of the contact
//! surfaces at a microscopic level, environmental conditions or contamination"
//! (Sec. 4.3.1). A real stage therefore steps irregularly; repetitive control
//! (Ch. 5) is judged on exactly that. The model here, for pair i:
//!
//! μ_i = μ · (1 + δ_i) · max(0.05, 1 + σ_x ξ_i(p_i) + σ_t η_i(t)),
//!
//! - δ_i: a per-pair difference drawn once, δ_i ~ σ_p·N(0, 1) (clamped > −0.9);
//! - ξ_i(p): a smooth random profile of unit variance along the drive strip
//!   (Catmull-Rom interpolation of independent N(0, 1) knots spaced by the
//!   correlation length), evaluated at the strip coordinate p_i = x_i − x_s under
//!   the pair's tip: the friction repeats where the stage has been before;
//! - η_i(t): a stationary Ornstein–Uhlenbeck process of unit variance and
//!   correlation time τ (discretised exactly), for environmental drift.
//!
//! All draws come from `nanomotion_core::rng::Rng` seeded by the caller: same
//! seed, same bits. Nothing allocates after construction.

use nanomotion_core::rng::Rng;

/// Number of knots of each strip profile (the profile repeats after
/// `KNOTS × correlation length`, 82 mm at the default 20 µm).
pub const KNOTS: usize = 4096;

/// Parameters of the μ variation.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MuVariationParams {
    /// Nominal μ (−).
    pub mu: f64,
    /// σ_p: relative standard deviation of the per-pair difference.
    pub pair_rel: f64,
    /// σ_x: relative standard deviation along the strip.
    pub spatial_rel: f64,
    /// Correlation length of the strip profile (m).
    pub spatial_corr_m: f64,
    /// σ_t: relative standard deviation in time.
    pub temporal_rel: f64,
    /// Correlation time τ of the temporal variation (s).
    pub temporal_tau_s: f64,
}

/// The μ generator of both pairs.
#[derive(Debug, Clone)]
pub struct MuVariation {
    p: MuVariationParams,
    pair_scale: [f64; 2],
    profiles: Vec<f64>,
    eta: [f64; 2],
    ou_a: f64,
    ou_b: f64,
    rng: Rng,
}

impl MuVariation {
    /// Draw the pair differences and strip profiles from `seed`; the OU process
    /// advances by `dt` (s) per [`MuVariation::next`].
    pub fn new(p: MuVariationParams, dt: f64, seed: u64) -> Self {
        let mut rng = Rng::new(seed);
        let pair_scale = [
            (1.0 + p.pair_rel * rng.normal()).max(0.1),
            (1.0 + p.pair_rel * rng.normal()).max(0.1),
        ];
        let profiles = (0..2 * KNOTS).map(|_| rng.normal()).collect();
        let eta = if p.temporal_rel > 0.0 {
            [rng.normal(), rng.normal()]
        } else {
            [0.0; 2]
        };
        let ou_a = if p.temporal_tau_s > 0.0 {
            (-dt / p.temporal_tau_s).exp()
        } else {
            0.0
        };
        let ou_b = (1.0 - ou_a * ou_a).sqrt();
        Self {
            p,
            pair_scale,
            profiles,
            eta,
            ou_a,
            ou_b,
            rng,
        }
    }

    /// The per-pair factors 1 + δ_i.
    pub fn pair_scale(&self) -> [f64; 2] {
        self.pair_scale
    }

    /// Unit-variance strip profile ξ_i at strip coordinate `pos_m` (m).
    pub fn profile(&self, i: usize, pos_m: f64) -> f64 {
        let u = pos_m / self.p.spatial_corr_m;
        let fl = u.floor();
        let t = u - fl;
        let base = (fl as i64).rem_euclid(KNOTS as i64) as usize;
        let knot = |j: usize| self.profiles[i * KNOTS + (base + j + KNOTS - 1) % KNOTS];
        let (p0, p1, p2, p3) = (knot(0), knot(1), knot(2), knot(3));
        // Catmull-Rom through p1 (t = 0) and p2 (t = 1).
        0.5 * (2.0 * p1
            + (-p0 + p2) * t
            + (2.0 * p0 - 5.0 * p1 + 4.0 * p2 - p3) * t * t
            + (-p0 + 3.0 * p1 - 3.0 * p2 + p3) * t * t * t)
    }

    /// μ of both pairs at strip coordinates `pos_m`, then advance the temporal
    /// process by one step.
    pub fn next(&mut self, pos_m: [f64; 2]) -> [f64; 2] {
        let mut mu = [0.0; 2];
        for (i, m) in mu.iter_mut().enumerate() {
            let mut f = 1.0;
            if self.p.spatial_rel > 0.0 {
                f += self.p.spatial_rel * self.profile(i, pos_m[i]);
            }
            if self.p.temporal_rel > 0.0 {
                f += self.p.temporal_rel * self.eta[i];
            }
            *m = self.p.mu * self.pair_scale[i] * f.max(0.05);
        }
        if self.p.temporal_rel > 0.0 {
            for e in &mut self.eta {
                *e = self.ou_a * *e + self.ou_b * self.rng.normal();
            }
        }
        mu
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn params() -> MuVariationParams {
        MuVariationParams {
            mu: 0.2,
            pair_rel: 0.1,
            spatial_rel: 0.1,
            spatial_corr_m: 20e-6,
            temporal_rel: 0.05,
            temporal_tau_s: 0.5,
        }
    }

    #[test]
    fn same_seed_same_bits_and_zero_variation_is_constant() {
        let mut a = MuVariation::new(params(), 25e-6, 3);
        let mut b = MuVariation::new(params(), 25e-6, 3);
        for k in 0..1000 {
            let p = [k as f64 * 1e-7, -(k as f64) * 1e-7];
            assert_eq!(a.next(p).map(f64::to_bits), b.next(p).map(f64::to_bits));
        }
        let flat = MuVariationParams {
            pair_rel: 0.0,
            spatial_rel: 0.0,
            temporal_rel: 0.0,
            ..params()
        };
        let mut c = MuVariation::new(flat, 25e-6, 3);
        assert_eq!(c.next([1e-3, 5e-3]), [0.2, 0.2]);
    }

    #[test]
    fn profile_interpolates_knots_is_continuous_and_periodic() {
        let v = MuVariation::new(params(), 25e-6, 9);
        let l = 20e-6;
        for j in 0..10 {
            assert!((v.profile(1, j as f64 * l) - v.profiles[KNOTS + j]).abs() < 1e-12);
        }
        // Continuity across a knot and the wrap-around (negative positions).
        let eps = 1e-12;
        assert!((v.profile(0, 3.0 * l - eps) - v.profile(0, 3.0 * l + eps)).abs() < 1e-6);
        assert!((v.profile(0, -eps) - v.profile(0, eps)).abs() < 1e-6);
        assert!((v.profile(0, 0.3 * l) - v.profile(0, 0.3 * l + KNOTS as f64 * l)).abs() < 1e-9);
    }

    #[test]
    fn temporal_process_has_unit_variance_and_the_right_correlation() {
        let p = MuVariationParams {
            pair_rel: 0.0,
            spatial_rel: 0.0,
            temporal_rel: 1.0,
            temporal_tau_s: 1e-3,
            ..params()
        };
        let dt = 1e-4;
        let mut v = MuVariation::new(p, dt, 5);
        let n = 200_000;
        let mut xs = Vec::with_capacity(n);
        for _ in 0..n {
            xs.push(v.eta[0]);
            v.next([0.0; 2]);
        }
        let var = xs.iter().map(|x| x * x).sum::<f64>() / n as f64;
        let lag = 10; // 1 ms = τ: correlation e^{-1}
        let c = xs.windows(lag + 1).map(|w| w[0] * w[lag]).sum::<f64>() / (n - lag) as f64 / var;
        // 2000 correlation times: standard error of the variance ≈ √(2/1000) ≈ 0.045.
        assert!((var - 1.0).abs() < 0.15, "var {var}");
        assert!((c - (-1.0f64).exp()).abs() < 0.05, "corr {c}");
    }
}
