//! The Coleman–Hodgdon hysteresis model (Merry 2009, Sec. 6.3, (6.3)),
//! unit-agnostic: input u (V for a piezo stack, or any unit), output y (µm, m, ...).
//!
//! The rate-independent differential model
//!
//! ```text
//! dy/dt = α |du/dt| (b·u − y) + c·du/dt
//! ```
//!
//! (the thesis writes x for y, V for u, f(V) = bV for the anhysteretic curve and
//! g(V) = u for the slope right after a reversal, here `c`) is linear in y along a
//! monotone piece of u, so it is integrated **exactly** per sample
//! ([`ColemanHodgdon::step`]): for increasing u,
//! y(u) = bu − k + (y₀ − bu₀ + k)e^{−α(u−u₀)} with k = (b − c)/α, and for decreasing
//! u, y(u) = bu + k + (y₀ − bu₀ − k)e^{α(u−u₀)}. Separate parameter sets for
//! increasing (trace) and decreasing (retrace) input make the model asymmetric.
//!
//! The periodic orbit of a symmetric model on [u_m, u_M] is (6.3):
//!
//! ```text
//! y(u) = bu − (b−c)/α · (1 − 2e^{−αu} / (e^{−αu_m} + e^{−αu_M}))   if du/dt ≥ 0
//! y(u) = bu + (b−c)/α · (1 − 2e^{αu}  / (e^{αu_m}  + e^{αu_M}))    if du/dt < 0
//! ```
//!
//! ([`ch_closed_loop`]); [`ColemanHodgdon::steady_loop`] gives the periodic orbit of
//! the asymmetric model in closed form.
//!
//! **Slope range** ([`ColemanHodgdon::sector`]). With e = y − b·u (the distance
//! from the anhysteretic line) and k = (b − c)/α, the ODE reads
//! de/du = −α(e + k) for increasing u and de/du = α(e − k) for decreasing u:
//! along increasing u, e moves monotonically towards −k, along decreasing u
//! towards +k, so e never leaves the band between its start and ±k
//! (|e| ≤ |b − c|/α from y₀ = b·u₀). The slope is dy/du = c − α e (increasing u) or c + α e
//! (decreasing), so every slope lies in [c − |b − c|, c + |b − c|] =
//! [min(2c − b, b), max(2c − b, b)]: 2c − b right after a reversal from the far
//! side of the band, b far along a branch. Each sample's step is exact, so the
//! ratio Δy/Δu of a sample is the mean slope over the input's move: in the range
//! too. With separate trace/retrace sets of equal b the same argument gives the
//! band between e₀, −k_t and +k_r; with different b the output follows two lines
//! b_t·u and b_r·u that drift apart as |u| grows, e is unbounded over unbounded
//! inputs and so is the slope: no range.
//!
//! Units: α in 1/\[u\], b and c in \[y\]/\[u\]. The AFM-stage plugin uses V and µm
//! (Table 6.2); its YAML names `alpha_per_v`, `b_um_per_v`, `u_um_per_v` are
//! accepted as aliases of `alpha`, `b`, `c`.

use crate::block::{Sector, check};
use crate::error::ParamError;
use serde::{Deserialize, Serialize};

/// Direction of the input: trace (increasing, du/dt ≥ 0) or retrace (decreasing).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Direction {
    /// Increasing input (du/dt ≥ 0).
    Trace,
    /// Decreasing input (du/dt < 0).
    Retrace,
}

impl Direction {
    /// `"trace"` or `"retrace"`.
    pub fn as_str(self) -> &'static str {
        match self {
            Direction::Trace => "trace",
            Direction::Retrace => "retrace",
        }
    }
}

/// One parameter set of the Coleman–Hodgdon model (6.3).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize, crate::Params)]
#[serde(deny_unknown_fields)]
pub struct ChParams {
    /// α (1/\[u\]) > 0: rate at which y approaches the anhysteretic line after a
    /// reversal (YAML alias `alpha_per_v`).
    #[serde(alias = "alpha_per_v")]
    pub alpha: f64,
    /// b (\[y\]/\[u\]): slope of the anhysteretic curve f(u) = b·u (alias `b_um_per_v`).
    #[serde(alias = "b_um_per_v")]
    pub b: f64,
    /// c (\[y\]/\[u\]): slope g(u) = c right after a reversal (the thesis's u; alias
    /// `u_um_per_v`).
    #[serde(alias = "u_um_per_v")]
    pub c: f64,
}

impl ChParams {
    /// The field names used by [`ChParams::validate`].
    pub const NAMES: [&'static str; 3] = ["alpha", "b", "c"];

    /// A parameter set (α in 1/\[u\], b and c in \[y\]/\[u\]).
    pub fn new(alpha: f64, b: f64, c: f64) -> Self {
        Self { alpha, b, c }
    }

    /// Check α > 0 and b, c finite; `prefix` names the set in errors
    /// (e.g. `"retrace."`).
    pub fn validate(&self, prefix: &str) -> Result<(), ParamError> {
        self.validate_as(prefix, &Self::NAMES)
    }

    /// [`ChParams::validate`] with the fields called `names` ([α, b, c]) in errors,
    /// for callers whose YAML spells them differently.
    pub fn validate_as(&self, prefix: &str, names: &[&str; 3]) -> Result<(), ParamError> {
        check::positive(&format!("{prefix}{}", names[0]), self.alpha)?;
        check::finite(&format!("{prefix}{}", names[1]), self.b)?;
        check::finite(&format!("{prefix}{}", names[2]), self.c)?;
        // k = (b − c)/α must be finite too (tiny α with large b − c overflows).
        let k = self.k();
        if !k.is_finite() {
            return Err(ParamError::new(
                format!("{prefix}{}", names[0]),
                format!("(b − c)/α = {k} is not finite"),
                "give a larger α or a smaller b − c",
            ));
        }
        Ok(())
    }

    /// k = (b − c)/α (\[y\]): distance of the asymptotes from the anhysteretic line.
    pub fn k(&self) -> f64 {
        (self.b - self.c) / self.alpha
    }

    /// [α, b, c].
    pub fn to_array(&self) -> [f64; 3] {
        [self.alpha, self.b, self.c]
    }

    /// From [α, b, c].
    pub fn from_array(p: [f64; 3]) -> Self {
        Self::new(p[0], p[1], p[2])
    }
}

/// Right-hand side of the Coleman–Hodgdon ODE dy/dt = α|u̇|(bu − y) + cu̇.
pub fn ch_ode_rhs(p: &ChParams, y: f64, u: f64, u_dot: f64) -> f64 {
    p.alpha * u_dot.abs() * (p.b * u - y) + p.c * u_dot
}

/// The closed-loop branches (6.3) of the symmetric Coleman–Hodgdon model on
/// [u_m, u_M]: the periodic orbit of the ODE under an input oscillating between
/// u_m and u_M. Written in the overflow-free form e^{−α(u−u_m)}/(1 + e^{−αu_R}).
pub fn ch_closed_loop(p: &ChParams, u: f64, u_m: f64, u_max: f64, dir: Direction) -> f64 {
    let (a, b, k) = (p.alpha, p.b, p.k());
    let er = (-a * (u_max - u_m)).exp();
    match dir {
        Direction::Trace => b * u - k * (1.0 - 2.0 * (-a * (u - u_m)).exp() / (1.0 + er)),
        Direction::Retrace => b * u + k * (1.0 - 2.0 * (a * (u - u_max)).exp() / (1.0 + er)),
    }
}

/// Coleman–Hodgdon hysteresis operator with separate trace/retrace parameter sets,
/// integrated exactly sample by sample (input held piecewise monotone between
/// samples). No allocation in [`step`](Self::step).
///
/// ```
/// use nanomotion_core::models::hysteresis::{ChParams, ColemanHodgdon, Direction, ch_closed_loop};
/// let p = ChParams::new(0.03, 1.0, 0.7);
/// let mut h = ColemanHodgdon::symmetric(p).unwrap();
/// // Cycle between 0 and 100 until the loop is periodic, then compare with (6.3).
/// for _ in 0..5 {
///     for k in 0..=100 { h.step(k as f64); }
///     for k in (0..=100).rev() { h.step(k as f64); }
/// }
/// for k in 0..=50 { h.step(k as f64); }
/// let want = ch_closed_loop(&p, 50.0, 0.0, 100.0, Direction::Trace);
/// assert!((h.position() - want).abs() < 1e-9);
/// ```
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ColemanHodgdon {
    trace: ChParams,
    retrace: ChParams,
    x: f64,
    v: f64,
}

impl ColemanHodgdon {
    /// Asymmetric model: `trace` for increasing, `retrace` for decreasing input.
    /// Starts at y = 0, u = 0.
    pub fn new(trace: ChParams, retrace: ChParams) -> Result<Self, ParamError> {
        trace.validate("trace.")?;
        retrace.validate("retrace.")?;
        Ok(Self {
            trace,
            retrace,
            x: 0.0,
            v: 0.0,
        })
    }

    /// Symmetric model (the classical Coleman–Hodgdon model).
    pub fn symmetric(p: ChParams) -> Result<Self, ParamError> {
        Self::new(p, p)
    }

    /// Trace parameters.
    pub fn trace(&self) -> &ChParams {
        &self.trace
    }
    /// Retrace parameters.
    pub fn retrace(&self) -> &ChParams {
        &self.retrace
    }

    /// Set the state: output `x` at input `v`.
    pub fn reset(&mut self, x: f64, v: f64) {
        self.x = x;
        self.v = v;
    }

    /// Current output y.
    pub fn position(&self) -> f64 {
        self.x
    }
    /// Current input u.
    pub fn voltage(&self) -> f64 {
        self.v
    }

    /// Move the input monotonically from its present value to `v` and return the
    /// new output (exact solution of the ODE; no allocation).
    pub fn step(&mut self, v: f64) -> f64 {
        let dv = v - self.v;
        if dv > 0.0 {
            let p = &self.trace;
            let (b, k) = (p.b, p.k());
            self.x = b * v - k + (self.x - b * self.v + k) * (-p.alpha * dv).exp();
        } else if dv < 0.0 {
            let p = &self.retrace;
            let (b, k) = (p.b, p.k());
            self.x = b * v + k + (self.x - b * self.v - k) * (p.alpha * dv).exp();
        }
        self.v = v;
        self.x
    }

    /// The incremental slope range of the model from its present state on (see
    /// the [module documentation](self)): for every later sample,
    /// Δy/Δu ∈ [lower, upper]. With e = y − b·u now and k_t, k_r the trace and
    /// retrace k, e stays in [lo, hi] = the hull of {e, −k_t, +k_r}; the slope is
    /// c_t − α_t e increasing and c_r + α_r e decreasing, so the range is the
    /// union of those over [lo, hi]. `None` when trace and retrace b differ (the
    /// slope is unbounded over unbounded inputs: no range exists).
    pub fn sector(&self) -> Option<Sector> {
        let (t, r) = (&self.trace, &self.retrace);
        if t.b != r.b {
            return None;
        }
        let e = self.x - t.b * self.v;
        let lo = e.min(-t.k()).min(r.k());
        let hi = e.max(-t.k()).max(r.k());
        let lower = (t.c - t.alpha * hi).min(r.c + r.alpha * lo);
        let upper = (t.c - t.alpha * lo).max(r.c + r.alpha * hi);
        (lower.is_finite() && upper.is_finite()).then(|| {
            Sector::new(
                lower,
                upper,
                "Coleman–Hodgdon: slope c ∓ α(y − b·u) with y − b·u between its start and ±(b − c)/α",
            )
        })
    }

    /// The periodic orbit under an input oscillating between `v_m` and `v_max`, in
    /// closed form: trace y = b_t u − k_t + C e^{−α_t(u−u_m)}, retrace
    /// y = b_r u + k_r + D e^{α_r(u−u_M)}, with C, D from continuity at both turning
    /// points. For a symmetric model this is (6.3).
    pub fn steady_loop(&self, v_m: f64, v_max: f64) -> Result<SteadyLoop, ParamError> {
        check::finite("v_m", v_m)?;
        check::finite("v_max", v_max)?;
        if v_max <= v_m {
            return Err(ParamError::new(
                "v_max",
                format!("input range u_R = u_M − u_m = {} must be > 0", v_max - v_m),
                "give v_max > v_m",
            ));
        }
        let (t, r) = (&self.trace, &self.retrace);
        let vr = v_max - v_m;
        let et = (-t.alpha * vr).exp(); // e^{−α_t u_R}
        let er = (-r.alpha * vr).exp(); // e^{−α_r u_R}
        // At u_M: b_t u_M − k_t + C et = b_r u_M + k_r + D
        // At u_m: b_t u_m − k_t + C    = b_r u_m + k_r + D er
        let r1 = (r.b - t.b) * v_max + r.k() + t.k();
        let r0 = (r.b - t.b) * v_m + r.k() + t.k();
        // [et, −1; 1, −er] [C; D] = [r1; r0]
        let det = -et * er + 1.0;
        let c = (-er * r1 + r0) / det;
        let d = (et * r0 - r1) / det;
        Ok(SteadyLoop {
            trace: *t,
            retrace: *r,
            v_m,
            v_max,
            c,
            d,
        })
    }
}

/// Periodic orbit of a [`ColemanHodgdon`] model on [u_m, u_M]
/// (see [`ColemanHodgdon::steady_loop`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SteadyLoop {
    trace: ChParams,
    retrace: ChParams,
    /// Lower turning input u_m.
    pub v_m: f64,
    /// Upper turning input u_M.
    pub v_max: f64,
    c: f64,
    d: f64,
}

impl SteadyLoop {
    /// Output on the loop at input `v` in direction `dir`.
    pub fn eval(&self, v: f64, dir: Direction) -> f64 {
        match dir {
            Direction::Trace => {
                let p = &self.trace;
                p.b * v - p.k() + self.c * (-p.alpha * (v - self.v_m)).exp()
            }
            Direction::Retrace => {
                let p = &self.retrace;
                p.b * v + p.k() + self.d * (p.alpha * (v - self.v_max)).exp()
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn legacy_yaml_names_are_accepted() {
        let p: ChParams =
            crate::yaml::from_str("{alpha_per_v: 0.03, b_um_per_v: 1.0, u_um_per_v: 0.7}", "t")
                .unwrap();
        assert_eq!(p, ChParams::new(0.03, 1.0, 0.7));
        let q: ChParams = crate::yaml::from_str("{alpha: 0.03, b: 1.0, c: 0.7}", "t").unwrap();
        assert_eq!(p, q);
    }

    #[test]
    fn validation_names_fields() {
        let e = ChParams::new(-1.0, 1.0, 0.7)
            .validate("retrace.")
            .unwrap_err();
        assert_eq!(e.field, "retrace.alpha");
        let e = ChParams::new(0.1, f64::NAN, 0.7)
            .validate_as("", &["alpha_per_v", "b_um_per_v", "u_um_per_v"])
            .unwrap_err();
        assert_eq!(e.field, "b_um_per_v");
        assert!(ChParams::new(1e-300, 1e10, -1e10).validate("").is_err());
        let h = ColemanHodgdon::symmetric(ChParams::new(0.03, 1.0, 0.7)).unwrap();
        assert!(h.steady_loop(1.0, 1.0).is_err());
    }

    /// Step `h` along a random walk with random reversals and step sizes
    /// (seeded), returning the smallest and largest Δy/Δu seen and whether
    /// every one lay in `s` (up to the rounding of y over the step).
    fn increment_ratios(h: &mut ColemanHodgdon, s: &Sector, seed: u64) -> (f64, f64, bool) {
        let mut rng = crate::rng::Rng::new(seed);
        let (mut lo, mut hi, mut inside) = (f64::INFINITY, f64::NEG_INFINITY, true);
        let mut u = h.voltage();
        let mut dir = 1.0;
        for _ in 0..20_000 {
            if rng.uniform() < 0.02 {
                dir = -dir;
            }
            // Steps from 1e-4 to 30 (a long run to the branch's far end, a short
            // one right after a reversal).
            let du = dir * 10f64.powf(rng.uniform_in(-4.0, 1.5));
            let y0 = h.position();
            u += du;
            let y1 = h.step(u);
            let ratio = (y1 - y0) / du;
            lo = lo.min(ratio);
            hi = hi.max(ratio);
            // Rounding of y (≈ 1e-16·|y|) divided by a small step.
            let rounding = 1e-14 * (y0.abs() + y1.abs()) / du.abs();
            inside &= ratio >= s.lower - rounding && ratio <= s.upper + rounding
                || s.contains(ratio, 1e-9);
        }
        (lo, hi, inside)
    }

    #[test]
    fn the_slope_range_holds_for_every_sample_and_is_attained() {
        // Symmetric: [min(2c − b, b), max(2c − b, b)] by the closed form, for
        // c < b, c > b and a negative c.
        for (i, p) in [
            ChParams::new(0.03, 1.0, 0.7),
            ChParams::new(0.5, 1.0, 1.6),
            ChParams::new(2.0, 0.8, -0.2),
        ]
        .into_iter()
        .enumerate()
        {
            let mut h = ColemanHodgdon::symmetric(p).unwrap();
            let s = h.sector().unwrap();
            let (a, b) = ((2.0 * p.c - p.b).min(p.b), (2.0 * p.c - p.b).max(p.b));
            assert!(
                (s.lower - a).abs() < 1e-12 && (s.upper - b).abs() < 1e-12,
                "{s:?}"
            );
            let (lo, hi, inside) = increment_ratios(&mut h, &s, 7 + i as u64);
            assert!(
                inside,
                "{p:?}: a ratio outside [{a}, {b}]: seen [{lo}, {hi}]"
            );
            // Attained within 2 % of the range's width.
            let tol = 0.02 * (b - a);
            assert!(
                (lo - a).abs() < tol && (hi - b).abs() < tol,
                "{p:?}: [{lo}, {hi}] vs [{a}, {b}]"
            );
        }
        // Asymmetric with equal b: the declared range holds.
        let mut h =
            ColemanHodgdon::new(ChParams::new(0.05, 1.0, 0.6), ChParams::new(0.02, 1.0, 0.9))
                .unwrap();
        let s = h.sector().unwrap();
        let (_, _, inside) = increment_ratios(&mut h, &s, 11);
        assert!(inside, "{s:?}");
        // Different b: no range (the slope grows without bound with |u|).
        let h = ColemanHodgdon::new(ChParams::new(0.05, 1.0, 0.6), ChParams::new(0.05, 1.2, 0.6))
            .unwrap();
        assert!(h.sector().is_none());
    }

    #[test]
    fn stepper_is_exact_for_any_step_size() {
        let p = ChParams::new(0.03, 1.0, 0.7);
        let mut a = ColemanHodgdon::symmetric(p).unwrap();
        let mut b = a.clone();
        a.step(50.0);
        for k in 1..=5000 {
            b.step(k as f64 * 0.01);
        }
        assert!((a.position() - b.position()).abs() < 1e-10);
        let want = 50.0 - p.k() * (1.0 - (-0.03f64 * 50.0).exp());
        assert!((a.position() - want).abs() < 1e-12);
    }
}
