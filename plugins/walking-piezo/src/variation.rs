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

/// Knots of the drive-strip height profile (the profile repeats after
/// `STRIP_KNOTS × correlation length`, 131 mm at the 2 µm default).
pub const STRIP_KNOTS: usize = 1 << 16;

/// Parameters of the drive-strip height profile ([`StripProfile`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct StripProfileParams {
    /// rms σ_h of the strip height (m); 0 switches the profile off.
    pub rms_m: f64,
    /// Correlation length (knot spacing) of the profile along the strip (m).
    pub corr_m: f64,
    /// Pitch of the four legs A, B, C, D along the strip (m).
    pub leg_pitch_m: f64,
}

/// A seeded random height profile h(p) of the drive strip (roughness and
/// waviness of the ceramic strip, Sec. 4.4: "roughness of the drive strip,
/// contamination"): independent N(0, 1) knots spaced by the correlation length,
/// Catmull-Rom interpolated and scaled so that the profile's rms over the strip
/// is σ_h. Positive h is a strip surface set back from the housing (less
/// penetration).
///
/// The four legs stand in a row with pitch a: A at 0, B at a, C at 2a, D at 3a
/// from the pair's tip coordinate. A pair's height is the mean of its two legs'
/// heights: pair 1 = {A, D}, pair 2 = {B, C}. For a ≫ the correlation length the
/// pairs see independent heights.
///
/// The profile is a function of the strip coordinate, so it repeats where the
/// stage has been before, but it is not periodic in the leg angle α: a pair
/// touches down on a fresh spot of the strip every step.
#[derive(Debug, Clone)]
pub struct StripProfile {
    p: StripProfileParams,
    /// Knots already scaled by σ_h / (rms of the unit-knot interpolant).
    knots: Vec<f64>,
}

/// Mean over t ∈ [0, 1) of the variance of the Catmull-Rom interpolant of
/// independent unit-variance knots, ∫₀¹ Σ_j w_j(t)² dt = 57/70 (1 at the knots,
/// 0.64 half-way); checked numerically in the tests.
const CATMULL_ROM_MEAN_VARIANCE: f64 = 57.0 / 70.0;

impl StripProfile {
    /// Draw the profile from `seed` (its own stream: the μ variation drawn from
    /// the same seed is unchanged by switching the profile on).
    pub fn new(p: StripProfileParams, seed: u64) -> Self {
        // "STRIPHGT" in ASCII: a stream independent of MuVariation's.
        let mut rng = Rng::new(seed ^ 0x5354_5249_5048_4754);
        let scale = p.rms_m / CATMULL_ROM_MEAN_VARIANCE.sqrt();
        let knots = (0..STRIP_KNOTS).map(|_| scale * rng.normal()).collect();
        Self { p, knots }
    }

    /// The parameters.
    pub fn params(&self) -> StripProfileParams {
        self.p
    }

    /// The Catmull-Rom segment under `pos_m`: the local parameter t ∈ [0, 1) and
    /// the four knots around it.
    #[inline]
    fn segment(&self, pos_m: f64) -> (f64, [f64; 4]) {
        let u = pos_m / self.p.corr_m;
        let fl = u.floor();
        let base = (fl as i64).rem_euclid(STRIP_KNOTS as i64) as usize;
        let knot = |j: usize| self.knots[(base + j + STRIP_KNOTS - 1) % STRIP_KNOTS];
        (u - fl, [knot(0), knot(1), knot(2), knot(3)])
    }

    /// Strip height h (m) at strip coordinate `pos_m` (m).
    #[inline]
    pub fn height(&self, pos_m: f64) -> f64 {
        let (t, [p0, p1, p2, p3]) = self.segment(pos_m);
        0.5 * (2.0 * p1
            + (-p0 + p2) * t
            + (2.0 * p0 - 5.0 * p1 + 4.0 * p2 - p3) * t * t
            + (-p0 + 3.0 * p1 - 3.0 * p2 + p3) * t * t * t)
    }

    /// Slope dh/dp (−) of the profile at strip coordinate `pos_m` (m): the
    /// derivative of the interpolant.
    #[inline]
    pub fn slope(&self, pos_m: f64) -> f64 {
        let (t, [p0, p1, p2, p3]) = self.segment(pos_m);
        0.5 * ((-p0 + p2)
            + 2.0 * (2.0 * p0 - 5.0 * p1 + 4.0 * p2 - p3) * t
            + 3.0 * (-p0 + 3.0 * p1 - 3.0 * p2 + p3) * t * t)
            / self.p.corr_m
    }

    /// Slopes (−) under pair 1 = {A, D} and pair 2 = {B, C}: the mean over the
    /// pair's two legs (as [`StripProfile::pair_heights`]).
    #[inline]
    pub fn pair_slopes(&self, pos_m: [f64; 2]) -> [f64; 2] {
        let a = self.p.leg_pitch_m;
        [
            0.5 * (self.slope(pos_m[0]) + self.slope(pos_m[0] + 3.0 * a)),
            0.5 * (self.slope(pos_m[1] + a) + self.slope(pos_m[1] + 2.0 * a)),
        ]
    }

    /// Heights (m) under pair 1 = {A, D} and pair 2 = {B, C} when the pairs' tips
    /// are at strip coordinates `pos_m`: the mean over the pair's two legs.
    #[inline]
    pub fn pair_heights(&self, pos_m: [f64; 2]) -> [f64; 2] {
        let a = self.p.leg_pitch_m;
        [
            0.5 * (self.height(pos_m[0]) + self.height(pos_m[0] + 3.0 * a)),
            0.5 * (self.height(pos_m[1] + a) + self.height(pos_m[1] + 2.0 * a)),
        ]
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn catmull_rom_mean_variance_is_57_over_70() {
        let n = 100_000;
        let mean: f64 = (0..n)
            .map(|i| {
                let t = (i as f64 + 0.5) / n as f64;
                let (t2, t3) = (t * t, t * t * t);
                [
                    0.5 * (-t + 2.0 * t2 - t3),
                    0.5 * (2.0 - 5.0 * t2 + 3.0 * t3),
                    0.5 * (t + 4.0 * t2 - 3.0 * t3),
                    0.5 * (-t2 + t3),
                ]
                .iter()
                .map(|w| w * w)
                .sum::<f64>()
            })
            .sum::<f64>()
            / n as f64;
        assert!((mean - CATMULL_ROM_MEAN_VARIANCE).abs() < 1e-9, "{mean}");
    }

    #[test]
    fn strip_profile_has_the_requested_rms_and_correlation_and_is_seeded() {
        let p = StripProfileParams {
            rms_m: 50e-9,
            corr_m: 2e-6,
            leg_pitch_m: 2e-3,
        };
        let a = StripProfile::new(p, 4);
        let b = StripProfile::new(p, 4);
        let c = StripProfile::new(p, 5);
        // Sample the whole strip (irrational step: all phases between knots).
        let n = 400_000;
        let len = STRIP_KNOTS as f64 * p.corr_m;
        let step = len / n as f64 * 0.999_37;
        let xs: Vec<f64> = (0..n).map(|k| a.height(k as f64 * step)).collect();
        let mean = xs.iter().sum::<f64>() / n as f64;
        let rms = (xs.iter().map(|x| x * x).sum::<f64>() / n as f64).sqrt();
        // 65 536 independent knots: rms within a few per cent.
        assert!((rms / p.rms_m - 1.0).abs() < 0.03, "rms {rms:e}");
        assert!(mean.abs() < 0.02 * p.rms_m, "mean {mean:e}");
        // Correlated below the knot spacing, uncorrelated beyond two spacings.
        let corr = |lag: f64| {
            let m = 100_000;
            let s: f64 = (0..m)
                .map(|k| {
                    let x = k as f64 * 7.3e-6;
                    a.height(x) * a.height(x + lag)
                })
                .sum();
            s / m as f64 / (rms * rms)
        };
        assert!(corr(0.2 * p.corr_m) > 0.8);
        assert!(corr(3.0 * p.corr_m).abs() < 0.05);
        // Seeded: same seed same bits, other seed other profile; periodic strip.
        for k in 0..100 {
            let x = k as f64 * 0.37e-6 - 10e-6;
            assert_eq!(a.height(x).to_bits(), b.height(x).to_bits());
            assert!((a.height(x) - a.height(x + len)).abs() < 1e-8 * p.rms_m);
        }
        assert_ne!(a.height(1e-6), c.height(1e-6));
        // The slope is the derivative of the height.
        for k in 0..50 {
            let x = k as f64 * 0.731e-6;
            let hh = 1e-10;
            let num = (a.height(x + hh) - a.height(x - hh)) / (2.0 * hh);
            assert!((a.slope(x) - num).abs() < 1e-5 * (1.0 + num.abs()), "{x}");
        }
        // The pairs see the legs' mean height.
        let h = a.pair_heights([1e-6, -3e-6]);
        assert_eq!(h[0], 0.5 * (a.height(1e-6) + a.height(1e-6 + 6e-3)));
        assert_eq!(
            h[1],
            0.5 * (a.height(-3e-6 + 2e-3) + a.height(-3e-6 + 4e-3))
        );
    }

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
