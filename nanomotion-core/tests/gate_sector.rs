//! Issue 25: loops through blocks with a slope range (`Block::sector`) are
//! judged at the centre slope and proven by the circle criterion ‖M R‖∞ < 1.
//!
//! The piezo loop of these tests: r → e = r − y → C(z) = k_i/(z − 1) (integral
//! control) → Coleman–Hodgdon hysteresis H (slopes [2c − b, b]) → plant
//! G(z) = 0.1/(z − 0.9) → y. With the hysteresis at its centre slope k0 and a
//! signal w added to its output, its input is u = −C G (k0 u + w) + …, so
//! M = −C G/(1 + k0 C G): the figure the gate reports is checked against a dense
//! frequency sweep of that closed form, the poles against the roots of
//! (z − 1)(z − 0.9) + 0.1 k0 k_i, and the verdicts against simulations of the
//! graphs with the real hysteresis (refused: the loop does not settle) and with
//! random slope histories (proven: the loop settles).

use nanomotion_core::gate::{self, GateReport};
use nanomotion_core::lti::Complex;
use nanomotion_core::models::hysteresis::{ChParams, ColemanHodgdon};
use nanomotion_core::rng::Rng;
use nanomotion_core::{Block, BuildContext, GraphSpec, ParamError, Port, Sector, Tick};
use proptest::prelude::*;
use serde::{Deserialize, Serialize};
use std::f64::consts::PI;

/// Coleman–Hodgdon hysteresis as a graph block (the core has the model; the
/// plugins' blocks wrap it the same way): y₀ = b·u₀, slope range from the model.
#[derive(Debug, Clone, Serialize, Deserialize)]
struct TestCh {
    alpha: f64,
    b: f64,
    c: f64,
    #[serde(skip)]
    h: Option<ColemanHodgdon>,
    #[serde(skip)]
    started: bool,
}

#[typetag::serde(name = "test_ch")]
impl Block for TestCh {
    fn inputs(&self) -> Vec<Port> {
        vec![Port::new("u", 1)]
    }
    fn outputs(&self) -> Vec<Port> {
        vec![Port::new("y", 1)]
    }
    fn build(&mut self, _ctx: &BuildContext) -> Result<(), ParamError> {
        self.h = Some(ColemanHodgdon::symmetric(ChParams::new(
            self.alpha, self.b, self.c,
        ))?);
        self.started = false;
        Ok(())
    }
    fn output(&mut self, _t: Tick, u: &[f64], y: &mut [f64]) {
        let h = self.h.as_mut().expect("built");
        if !self.started {
            h.reset(self.b * u[0], u[0]);
            self.started = true;
        }
        y[0] = h.step(u[0]);
    }
    fn sector(&self) -> Option<Sector> {
        self.h.as_ref()?.sector()
    }
}

/// A block with a random slope history in [lower, upper]: y[k] = y[k−1] +
/// s_k (u[k] − u[k−1]), s_k at either end or uniform in between (seeded),
/// y[0] = y0 + s_0 u[0] (a random initial state).
#[derive(Debug, Clone, Serialize, Deserialize)]
struct TestSlopes {
    lower: f64,
    upper: f64,
    seed: u64,
    y0: f64,
    #[serde(skip)]
    rng: Option<Rng>,
    #[serde(skip)]
    last: Option<(f64, f64)>,
}

#[typetag::serde(name = "test_slopes")]
impl Block for TestSlopes {
    fn inputs(&self) -> Vec<Port> {
        vec![Port::new("u", 1)]
    }
    fn outputs(&self) -> Vec<Port> {
        vec![Port::new("y", 1)]
    }
    fn build(&mut self, _ctx: &BuildContext) -> Result<(), ParamError> {
        self.rng = Some(Rng::new(self.seed));
        self.last = None;
        Ok(())
    }
    fn output(&mut self, _t: Tick, u: &[f64], y: &mut [f64]) {
        let rng = self.rng.as_mut().expect("built");
        let s = match rng.next_u64() % 3 {
            0 => self.lower,
            1 => self.upper,
            _ => rng.uniform_in(self.lower, self.upper),
        };
        y[0] = match self.last {
            None => self.y0 + s * u[0],
            Some((u1, y1)) => y1 + s * (u[0] - u1),
        };
        self.last = Some((u[0], y[0]));
    }
    fn sector(&self) -> Option<Sector> {
        Some(Sector::new(self.lower, self.upper, "test slope history"))
    }
}

/// The piezo loop with integral gain `ki`, the nonlinear block `nl` (YAML
/// flow mapping without name) and plant 0.1·g/(z − p)… here g(1 − p)/(z − p).
fn piezo_loop(ki: f64, nl: &str, g: f64, p: f64, r: f64, duration_s: f64, extra: &str) -> String {
    format!(
        r#"base_rate_hz: 1000
duration_s: {duration_s}
{extra}
blocks:
  - {{ name: ref, type: constant, value: {r:e} }}
  - {{ name: err, type: sum, signs: "+-" }}
  - {{ name: ctrl, type: transfer_function, num: [{ki:e}], den: [1.0, -1.0], discrete: true }}
  - {{ name: hyst, {nl} }}
  - {{ name: plant, type: transfer_function, num: [{:e}], den: [1.0, {:e}], discrete: true }}
connections:
  - {{ from: ref.y, to: err.in0 }}
  - {{ from: plant.y, to: err.in1 }}
  - {{ from: err.y, to: ctrl.u }}
  - {{ from: ctrl.y, to: hyst.u }}
  - {{ from: hyst.y, to: plant.u }}
log: [plant.y]
"#,
        g * (1.0 - p),
        -p
    )
}

const CH: &str = "type: test_ch, alpha: 0.03, b: 1.0, c: 0.7";
/// Slopes of `CH`: [2c − b, b] = [0.4, 1.0]; centre 0.7, radius 0.3.
const K0: f64 = 0.7;
const R: f64 = 0.3;

fn check(yaml: &str) -> GateReport {
    let spec = GraphSpec::from_yaml(yaml, "test").unwrap();
    let require = spec.require.clone().unwrap_or_default();
    let (sched, _) = spec.build().unwrap();
    gate::analyse(&sched, &require)
}

/// ‖M R‖∞ by a dense sweep of r·|C G/(1 + k0 C G)| on the unit circle,
/// C = ki/(z − 1), G = g(1 − p)/(z − p).
fn sweep_mr(ki: f64, g: f64, p: f64, k0: f64, r: f64) -> f64 {
    let n = 200_000;
    (1..=n)
        .map(|i| {
            let z = Complex::from_polar(1.0, PI * i as f64 / n as f64);
            let cg = ki / (z - 1.0) * (g * (1.0 - p)) / (z - p);
            r * (cg / (cg * k0 + 1.0)).norm()
        })
        .fold(0.0, f64::max)
        // θ → 0: C G → ∞, M → 1/k0.
        .max(r / k0.abs())
}

/// Largest root modulus of (z − 1)(z − p) + g(1 − p) k0 ki.
fn centre_radius(ki: f64, g: f64, p: f64, k0: f64) -> f64 {
    let (a1, a0) = (-(1.0 + p), p + g * (1.0 - p) * k0 * ki);
    let disc = a1 * a1 - 4.0 * a0;
    if disc >= 0.0 {
        let s = disc.sqrt();
        ((-a1 + s) / 2.0).abs().max(((-a1 - s) / 2.0).abs())
    } else {
        a0.sqrt()
    }
}

#[test]
fn a_piezo_loop_with_hysteresis_and_integral_control_is_proven_by_the_circle_criterion() {
    let ki = 0.2;
    let r = check(&piezo_loop(ki, CH, 1.0, 0.9, 1.0, 0.1, ""));
    assert!(r.passes() && r.proven(), "{r}");
    let l = &r.loops[0];
    assert!(l.unproven.is_empty() && l.stable());
    assert_eq!(l.sectors.len(), 1);
    assert!(
        l.linearised[0]
            .contains("`hyst`: judged at the centre slope k0 = 0.7 of its slope range [0.4, 1]"),
        "{:?}",
        l.linearised
    );
    let p = &l.points[0];
    assert!((p.spectral_radius - centre_radius(ki, 1.0, 0.9, K0)).abs() < 1e-9);
    let c = p.circle.as_ref().expect("circle criterion evaluated");
    let want = sweep_mr(ki, 1.0, 0.9, K0, R);
    assert!(c.holds() && want < 1.0);
    assert!(
        (c.norm - want).abs() < 1e-6 * want,
        "{} vs sweep {want}",
        c.norm
    );
    assert!((c.m_norm - want / R).abs() < 1e-6 * want / R);
    let text = r.to_string();
    assert!(
        text.contains(&format!(
            "circle criterion: ‖M R‖∞ = {:.4} < 1 over slopes [0.4, 1] of `hyst`",
            want
        )),
        "{text}"
    );
    assert!(text.contains("ok (circle)"), "{text}");
}

#[test]
fn an_unstable_centre_slope_is_refused_and_the_graph_does_not_settle() {
    // (z − 1)(z − 0.9) + 0.07 ki: unstable for ki > 1/0.07 = 1.43 at k0 = 0.7.
    let ki = 2.0;
    let yaml = piezo_loop(ki, CH, 1.0, 0.9, 1.0, 4.0, "");
    let r = check(&yaml);
    assert!(!r.passes());
    let rho = centre_radius(ki, 1.0, 0.9, K0);
    assert!((r.loops[0].points[0].spectral_radius - rho).abs() < 1e-9 && rho > 1.0);
    let f = r.failures().join("\n");
    assert!(
        f.contains("unstable")
            && f.contains("at the centre slope k0 = 0.7 of `hyst` (slope range [0.4, 1])"),
        "{f}"
    );
    // Allowing unproven loops does not let a known instability run.
    let allowed = piezo_loop(
        ki,
        CH,
        1.0,
        0.9,
        1.0,
        4.0,
        "require: { allow_unproven: \"bench\" }",
    );
    assert!(!check(&allowed).passes());
    // The real hysteresis in the loop: the error never settles; it grows.
    let (mut sched, _) = GraphSpec::from_yaml(&yaml, "t").unwrap().build().unwrap();
    let y = sched.run(|_| {}).logs[0].data.clone();
    let amp = |s: &[f64]| {
        s.iter().fold(f64::NEG_INFINITY, |m, v| m.max(*v))
            - s.iter().fold(f64::INFINITY, |m, v| m.min(*v))
    };
    let n = y.len();
    let (early, late) = (amp(&y[n / 10..n / 5]), amp(&y[n * 9 / 10..]));
    assert!(
        !late.is_finite() || late > 10.0 * early.max(1e-12),
        "the refused loop settled: swing {early} -> {late}"
    );
}

#[test]
fn a_loop_whose_circle_criterion_fails_stays_unproven_with_the_figure() {
    // Stable at k0 (0.984 + … < 1) but the resonance makes ‖M‖∞ large.
    let ki = 1.2;
    let want = sweep_mr(ki, 1.0, 0.9, K0, R);
    assert!(want > 1.0 && centre_radius(ki, 1.0, 0.9, K0) < 1.0);
    let r = check(&piezo_loop(ki, CH, 1.0, 0.9, 1.0, 0.1, ""));
    assert!(!r.passes() && !r.proven());
    let l = &r.loops[0];
    assert!(l.points[0].stable);
    let c = l.points[0].circle.as_ref().unwrap();
    assert!((c.norm - want).abs() < 1e-6 * want, "{} vs {want}", c.norm);
    let f = r.failures().join("\n");
    assert!(
        f.contains(&format!(
            "circle criterion: ‖M R‖∞ = {want:.4} ≥ 1 over slopes [0.4, 1] of `hyst`"
        )) && f.contains(&format!(
            "lower the loop gain until ‖M‖∞ = {:.4} < 1/r = 3.3333, or narrow the slope range",
            want / R
        )),
        "{f}"
    );
    // `allow_unproven` lets it run, as for any unproven loop …
    let allowed = "require: { allow_unproven: \"limit cycle bounded on the bench\" }";
    let r = check(&piezo_loop(ki, CH, 1.0, 0.9, 1.0, 0.1, allowed));
    assert!(r.passes(), "{r}");
    assert!(r.to_string().contains("UNPROVEN, allowed"));
    // … but the bounds still apply to the analysed point.
    let bound = "require: { allow_unproven: \"bench\", phase_margin_deg: 80 }";
    let r = check(&piezo_loop(ki, CH, 1.0, 0.9, 1.0, 0.1, bound));
    assert!(!r.passes());
    assert!(r.failures().join("\n").contains("phase margin"), "{r}");
}

#[test]
fn a_sector_block_faster_than_the_loop_stays_unproven_with_the_reason() {
    // Everything at 500 Hz but the hysteresis at 1 kHz.
    let mut yaml = piezo_loop(0.2, CH, 1.0, 0.9, 1.0, 0.1, "");
    for b in ["ref", "err", "ctrl", "plant"] {
        yaml = yaml.replace(
            &format!("  - {{ name: {b}, "),
            &format!("  - {{ name: {b}, rate_hz: 500, "),
        );
    }
    let r = check(&yaml);
    assert!(!r.passes());
    assert!(
        r.failures()[0]
            .contains("sector block `hyst` runs faster than the loop's analysis rate 500 Hz"),
        "{r}"
    );
}

#[test]
fn a_dead_zone_has_slopes_zero_to_one_and_a_proportional_loop_through_it_is_proven() {
    use nanomotion_core::blocks::math::Deadzone;
    let mut dz = Deadzone::new(-0.3, 0.5);
    dz.build(&BuildContext::new("dz", 1e-3, 0)).unwrap();
    let s = dz.sector().unwrap();
    assert_eq!((s.lower, s.upper), (0.0, 1.0));
    let mut rng = Rng::new(5);
    let (mut lo, mut hi, mut u0) = (f64::INFINITY, f64::NEG_INFINITY, 0.0);
    for _ in 0..10_000 {
        let u1 = rng.uniform_in(-2.0, 2.0);
        let ratio = (dz.map(u1) - dz.map(u0)) / (u1 - u0);
        assert!((-1e-12..=1.0 + 1e-12).contains(&ratio), "{ratio}");
        lo = lo.min(ratio);
        hi = hi.max(ratio);
        u0 = u1;
    }
    assert!(lo < 1e-9 && hi > 1.0 - 1e-9);
    // P control k = 0.5 of 0.1/(z − 0.9) through the dead zone: k0 = 0.5,
    // r = 0.5, M = −kG/(1 + k0 kG).
    let yaml = piezo_loop(
        1.0,
        "type: deadzone, lower: -0.01, upper: 0.01",
        1.0,
        0.9,
        1.0,
        0.1,
        "",
    )
    .replace("num: [1e0], den: [1.0, -1.0]", "num: [0.5], den: [1.0]");
    let r = check(&yaml);
    assert!(r.passes() && r.proven(), "{r}");
    let n = 200_000;
    let want = (0..=n)
        .map(|i| {
            let z = Complex::from_polar(1.0, PI * i as f64 / n as f64);
            let kg = 0.5 * 0.1 / (z - 0.9);
            0.5 * (kg / (kg * 0.5 + 1.0)).norm()
        })
        .fold(0.0, f64::max);
    let c = r.loops[0].points[0].circle.as_ref().unwrap();
    assert!((c.norm - want).abs() < 1e-6 * want, "{} vs {want}", c.norm);
}

/// Two sector blocks in series (hysteresis [0.4, 1] then a dead zone [0, 1])
/// under P control k of 0.1/(z − 0.9): M is 2 × 2,
/// M = [[−k2 CG, −CG], [1, −k1 CG]]/(1 + k1 k2 CG) from (w1, w2) to (u1, u2),
/// and ‖M R‖∞ is the largest singular value of M·diag(r1, r2) over a sweep.
#[test]
fn two_sector_blocks_are_judged_together_by_the_largest_singular_value() {
    let kp = 0.5;
    let yaml = piezo_loop(1.0, CH, 1.0, 0.9, 1.0, 0.1, "")
        .replace(
            "num: [1e0], den: [1.0, -1.0]",
            &format!("num: [{kp}], den: [1.0]"),
        )
        .replace(
            "  - { from: hyst.y, to: plant.u }\n",
            "  - { from: hyst.y, to: dz.u }\n  - { from: dz.y, to: plant.u }\n",
        )
        .replace(
            "  - { name: plant,",
            "  - { name: dz, type: deadzone, lower: -0.01, upper: 0.01 }\n  - { name: plant,",
        );
    let r = check(&yaml);
    let l = &r.loops[0];
    assert_eq!(l.sectors.len(), 2, "{r}");
    let c = l.points[0].circle.as_ref().expect("evaluated");
    let (k1, r1, k2, r2) = (K0, R, 0.5, 0.5);
    let n = 100_000;
    let want = (0..=n)
        .map(|i| {
            let z = Complex::from_polar(1.0, PI * i as f64 / n as f64);
            let cg = kp * 0.1 / (z - 0.9);
            let d = cg * (k1 * k2) + 1.0;
            // M·R, entries m[row][col].
            let m = [
                [-cg * k2 / d * r1, -cg / d * r2],
                [Complex::new(1.0, 0.0) / d * r1, -cg * k1 / d * r2],
            ];
            // Largest eigenvalue of Mᴴ M (2 × 2 Hermitian).
            let h = |i: usize, j: usize| m[0][i].conj() * m[0][j] + m[1][i].conj() * m[1][j];
            let (a, b, dd) = (h(0, 0).re, h(0, 1), h(1, 1).re);
            let tr = a + dd;
            let det = a * dd - b.norm_sqr();
            ((tr + (tr * tr - 4.0 * det).max(0.0).sqrt()) / 2.0).sqrt()
        })
        .fold(0.0, f64::max);
    assert!(
        (c.norm - want).abs() < 1e-6 * want,
        "{} vs sweep {want}",
        c.norm
    );
    assert_eq!(c.holds(), r.passes(), "{r}");
    let names: Vec<&str> = c.blocks.iter().map(|b| b.0.as_str()).collect();
    assert_eq!(names, vec!["hyst", "dz"]);
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 40, rng_seed: proptest::test_runner::RngSeed::Fixed(25), ..ProptestConfig::default() })]

    /// Whenever the gate proves a loop with a slope range, the loop settles
    /// under a random slope history in that range from a random initial state.
    #[test]
    fn a_proven_loop_settles_under_any_slope_history(
        g in 0.2f64..5.0,
        p in 0.0f64..0.98,
        ki in 0.01f64..1.5,
        lower in 0.05f64..1.0,
        width in 0.0f64..1.5,
        seed in 0u64..1_000_000,
        y0 in -5.0f64..5.0,
        reference in -3.0f64..3.0,
    ) {
        let upper = lower + width;
        let nl = format!("type: test_slopes, lower: {lower:e}, upper: {upper:e}, seed: {seed}, y0: {y0:e}");
        let r = check(&piezo_loop(ki, &nl, g, p, reference, 0.1, ""));
        let l = &r.loops[0];
        let k0 = 0.5 * (lower + upper);
        // The figure agrees with the sweep of the closed form.
        if let Some(c) = &l.points[0].circle {
            let want = sweep_mr(ki, g, p, k0, 0.5 * width);
            prop_assert!((c.norm - want).abs() < 1e-5 * want.max(1e-3), "{} vs {}", c.norm, want);
        }
        prop_assume!(r.passes() && r.proven());
        let n = 20_000;
        let yaml = piezo_loop(ki, &nl, g, p, reference, n as f64 / 1000.0, "");
        let (mut sched, _) = GraphSpec::from_yaml(&yaml, "t").unwrap().build().unwrap();
        let y = sched.run(|_| {}).logs[0].data.clone();
        let tail = &y[n * 9 / 10..];
        let spread = tail.iter().cloned().fold(f64::NEG_INFINITY, f64::max)
            - tail.iter().cloned().fold(f64::INFINITY, f64::min);
        let scale = y.iter().fold(0.0f64, |m, v| m.max(v.abs())).max(1e-9);
        prop_assert!(spread <= 1e-6 * scale, "proven loop did not settle: spread {} of {}", spread, scale);
        // Integral action: it settles at the reference.
        prop_assert!((tail[tail.len() - 1] - reference).abs() <= 1e-6 * scale);
    }
}
