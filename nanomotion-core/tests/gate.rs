//! The stability gate (issue 17): loops known stable pass; loops made unstable by
//! gain, by added delay and by a sign error are refused with the right reason; a
//! saturation is judged on its linearisation and says so; multi-rate lifting
//! agrees with a single-rate ZOH model; MIMO loci agree with the SISO channels; and
//! over random loops the verdict agrees with time-domain simulation of the graph,
//! the poles with the roots of the characteristic polynomial, and the margins
//! with an independent frequency sweep.

use nanomotion_core::gate::{self, GateReport};
use nanomotion_core::lti::Complex;
use nanomotion_core::lti::linalg::{poly_from_roots, polyadd, polymul, roots};
use nanomotion_core::{GraphSpec, Scheduler};
use proptest::prelude::*;
use std::f64::consts::PI;

fn build(yaml: &str) -> (Scheduler, GateReport) {
    let spec = GraphSpec::from_yaml(yaml, "test").unwrap();
    let require = spec.require.clone().unwrap_or_default();
    let (sched, _) = spec.build().unwrap();
    let report = gate::analyse(&sched, &require);
    (sched, report)
}

/// k/(z − 1) plant, gain controller, optional delay and sum signs.
fn integrator_loop(k: f64, delay: usize, signs: &str, extra: &str) -> String {
    let (delay_block, into_plant) = if delay > 0 {
        (
            format!("  - {{ name: dl, type: delay, d: {delay} }}\n"),
            "  - { from: k.y, to: dl.u }\n  - { from: dl.y, to: plant.u }\n".to_string(),
        )
    } else {
        (
            String::new(),
            "  - { from: k.y, to: plant.u }\n".to_string(),
        )
    };
    format!(
        r#"base_rate_hz: 1000
duration_s: 0.5
{extra}
blocks:
  - {{ name: ref, type: constant, value: 1.0 }}
  - {{ name: err, type: sum, signs: "{signs}" }}
  - {{ name: k, type: gain, k: {k} }}
{delay_block}  - {{ name: plant, type: transfer_function, num: [1.0], den: [1.0, -1.0], discrete: true }}
connections:
  - {{ from: ref.y, to: err.in0 }}
  - {{ from: plant.y, to: err.in1 }}
  - {{ from: err.y, to: k.u }}
{into_plant}log: [plant.y]
"#
    )
}

#[test]
fn integrator_loop_has_the_closed_form_margins() {
    // L(z) = k/(z − 1): phase crossover at z = −1 where L = −k/2, so GM = 2/k;
    // gain crossover where 2 sin(θ/2) = k, with PM = 90° − θ/2.
    let k = 0.4;
    let (_, r) = build(&integrator_loop(k, 0, "+-", ""));
    assert!(r.passes(), "{r}");
    let l = &r.loops[0];
    // Execution order (the plant has no feed-through, so it comes first); no
    // block of the loop is a controller, so the loop is named by the first.
    assert_eq!(l.blocks, vec!["plant", "err", "k"]);
    assert_eq!(l.name, "plant");
    let p = &l.points[0];
    assert!((p.spectral_radius - (1.0 - k)).abs() < 1e-12);
    let m = p.margins.as_ref().unwrap();
    assert!(
        (m.gain_margin_db - 20.0 * (2.0 / k).log10()).abs() < 1e-6,
        "{m:?}"
    );
    let theta = 2.0 * (k / 2.0).asin();
    assert!((m.phase_margin_deg - (90.0 - theta.to_degrees() / 2.0)).abs() < 1e-6);
    // Delay margin PM/ω_c with ω_c = θ/T.
    let dm = (90.0 - theta.to_degrees() / 2.0).to_radians() / (theta * 1000.0);
    assert!((m.delay_margin_s - dm).abs() < 1e-9);
    // ‖S‖∞ is 1/modulus margin; for this loop S = (z − 1)/(z − 1 + k) peaks at
    // z = −1: 2/(2 − k).
    assert!((p.s_hinf - 2.0 / (2.0 - k)).abs() < 1e-7);
    assert!((1.0 / m.modulus_margin - p.s_hinf).abs() < 1e-6);
    // T = k/(z − 1 + k) peaks at z = 1: 1.
    assert!((p.t_hinf - 1.0).abs() < 1e-7);
    let ny = p.nyquist.unwrap();
    assert_eq!((ny.encirclements, ny.open_loop_unstable), (0, 0));
}

#[test]
fn too_much_gain_is_refused_as_unstable() {
    let (_, r) = build(&integrator_loop(2.5, 0, "+-", ""));
    assert!(!r.passes());
    let f = r.failures().join("\n");
    assert!(f.contains("loop `plant`") && f.contains("unstable"), "{f}");
    // Pole 1 − 2.5.
    assert!((r.loops[0].points[0].spectral_radius - 1.5).abs() < 1e-12);
    assert_eq!(r.loops[0].points[0].nyquist.unwrap().implied_unstable, 1);
}

/// Issue 26: the rule before a run and its refusal live in the library, one
/// text for the command line and the Python package, which differ only in how
/// they spell the check and the escape hatch.
#[test]
fn the_refusal_before_a_run_is_one_text_for_every_front_end() {
    use nanomotion_core::gate::FrontEnd;
    let (_, bad) = build(&integrator_loop(2.5, 0, "+-", ""));
    let failures = bad.failures().join("\n  ");
    assert_eq!(
        bad.verdict().unwrap_err(),
        format!("the stability gate refuses the graph:\n  {failures}")
    );
    assert_eq!(
        bad.before_run(false, &FrontEnd::CLI).unwrap_err(),
        format!(
            "the stability gate refuses the graph (see `nanomotion check`; fix the loop, or run anyway with --allow-unproven):\n  {failures}"
        )
    );
    assert_eq!(
        bad.before_run(false, &FrontEnd::PYTHON).unwrap_err(),
        format!(
            "the stability gate refuses the graph (see nanomotion.check; fix the loop, or run anyway with allow_unproven=True):\n  {failures}"
        )
    );
    let lines = bad.before_run(true, &FrontEnd::PYTHON).unwrap();
    assert_eq!(
        lines[0],
        "the stability gate refused this graph; running anyway because of allow_unproven=True:"
    );
    assert_eq!(lines.len(), 1 + bad.failures().len());
    let (_, good) = build(&integrator_loop(0.5, 0, "+-", ""));
    assert!(good.verdict().is_ok());
    assert_eq!(
        good.before_run(false, &FrontEnd::CLI).unwrap(),
        Vec::<String>::new()
    );
}

#[test]
fn added_delay_beyond_the_delay_margin_is_refused() {
    let k = 0.2;
    let (_, r0) = build(&integrator_loop(k, 0, "+-", ""));
    let dm = r0.loops[0].points[0]
        .margins
        .as_ref()
        .unwrap()
        .delay_margin_s;
    let dm_samples = dm * 1000.0;
    // Far enough from an integer that the (continuous) delay margin decides.
    let below = dm_samples.floor() as usize;
    let above = below + 1;
    assert!(dm_samples - below as f64 > 0.05 && (above as f64 - dm_samples) > 0.05);
    let (_, ok) = build(&integrator_loop(k, below, "+-", ""));
    assert!(ok.passes(), "{ok}");
    let (_, bad) = build(&integrator_loop(k, above, "+-", ""));
    assert!(!bad.passes());
    assert!(bad.failures()[0].contains("unstable"), "{bad}");
    // Independent: roots of z^d (z − 1) + k.
    let mut char_poly = vec![1.0, -1.0];
    char_poly.extend(std::iter::repeat_n(0.0, above));
    let n = char_poly.len();
    char_poly[n - 1] += k;
    let rho = roots(&char_poly)
        .iter()
        .map(|z| z.norm())
        .fold(0.0, f64::max);
    assert!((bad.loops[0].points[0].spectral_radius - rho).abs() < 1e-8);
}

#[test]
fn a_sign_error_in_the_sum_is_refused() {
    let (_, r) = build(&integrator_loop(0.4, 0, "++", ""));
    assert!(!r.passes());
    assert!(r.failures()[0].contains("unstable"));
    // Positive feedback: pole 1 + k.
    assert!((r.loops[0].points[0].spectral_radius - 1.4).abs() < 1e-12);
}

#[test]
fn requirements_name_the_loop_and_the_bound() {
    let (_, r) = build(&integrator_loop(
        0.4,
        0,
        "+-",
        "require: { phase_margin_deg: 30, loops: { k: { gain_margin_db: 20 } } }",
    ));
    assert!(!r.passes());
    let f = r.failures();
    assert_eq!(f.len(), 1, "{f:?}");
    // The loop is named by its require key; GM = 20 log10(5) = 14 dB < 20 dB.
    assert!(f[0].starts_with("loop `k`"), "{f:?}");
    assert!(
        f[0].contains("gain margin 13.98 dB < required 20 dB"),
        "{f:?}"
    );
    // A key naming no loop is an error naming the key.
    let (_, r) = build(&integrator_loop(
        0.4,
        0,
        "+-",
        "require: { loops: { ref: {} } }",
    ));
    assert!(r.failures()[0].contains("require.loops.ref"), "{r}");
}

#[test]
fn a_saturation_is_judged_on_its_linearisation_and_says_so() {
    let yaml = integrator_loop(0.4, 0, "+-", "").replace(
        "  - { from: k.y, to: plant.u }\n",
        "  - { from: k.y, to: sat.u }\n  - { from: sat.y, to: plant.u }\n",
    );
    let yaml = yaml.replace(
        "  - { name: plant,",
        "  - { name: sat, type: saturation, lower: -0.1, upper: 0.1 }\n  - { name: plant,",
    );
    let (_, r) = build(&yaml);
    assert!(r.passes(), "{r}");
    let l = &r.loops[0];
    assert_eq!(l.linearised.len(), 1);
    assert!(l.linearised[0].contains("saturation") && l.linearised[0].contains("gain 1"));
    assert!((l.points[0].spectral_radius - 0.6).abs() < 1e-12);
    assert!(r.to_string().contains("judged on its linearisation"));
}

/// A dead zone (slopes [0, 1]) under integral action: at slope 0 the loop is
/// open around the plant's integrator, so the circle criterion cannot prove it
/// (‖M R‖∞ ≥ r/k0 = 1 at DC): unproven, unless allowed.
#[test]
fn a_loop_the_gate_cannot_prove_is_unproven_unless_allowed() {
    let yaml = integrator_loop(0.4, 0, "+-", "").replace(
        "  - { from: k.y, to: plant.u }\n",
        "  - { from: k.y, to: dz.u }\n  - { from: dz.y, to: plant.u }\n",
    );
    let yaml = yaml.replace(
        "  - { name: plant,",
        "  - { name: dz, type: deadzone, lower: -0.01, upper: 0.01 }\n  - { name: plant,",
    );
    let (_, r) = build(&yaml);
    assert!(!r.passes());
    assert!(r.failures()[0].contains("unproven") && r.failures()[0].contains("`dz`"));
    assert!(r.failures()[0].contains("circle criterion"), "{r}");
    let allowed = yaml.replace(
        "duration_s: 0.5",
        "duration_s: 0.5\nrequire: { allow_unproven: \"dead zone tested on the bench\" }",
    );
    let (_, r) = build(&allowed);
    assert!(r.passes());
    assert!(r.allowed()[0].contains("dead zone tested on the bench"));
}

#[test]
fn a_multirate_loop_lifted_equals_the_plant_discretised_at_the_controller_rate() {
    // Continuous plant 1/(s (s/100 + 1)) by ZOH at 10 kHz, driven by a PI at
    // 1 kHz through a hold and sampled back: lifting must give exactly the loop
    // with the plant discretised by ZOH at 1 kHz (ZOH at m·T = m ZOH steps at T
    // under a held input).
    let graph = |plant_rate: u32| {
        format!(
            r#"base_rate_hz: 10000
duration_s: 0.1
blocks:
  - {{ name: ref, type: constant, value: 1.0, rate_hz: 1000 }}
  - {{ name: err, type: sum, signs: "+-", rate_hz: 1000 }}
  - {{ name: pi, type: pi, kp: 20.0, zero_hz: 2.0, rate_hz: 1000 }}
  - {{ name: plant, type: transfer_function, num: [1.0], den: [0.01, 1.0, 0.0], discretisation: zoh, rate_hz: {plant_rate} }}
connections:
  - {{ from: ref.y, to: err.in0 }}
  - {{ from: plant.y, to: err.in1 }}
  - {{ from: err.y, to: pi.e }}
  - {{ from: pi.u, to: plant.u }}
"#
        )
    };
    let (_, fast) = build(&graph(10000));
    let (_, slow) = build(&graph(1000));
    assert!(fast.passes() && slow.passes(), "{fast}\n{slow}");
    let (a, b) = (&fast.loops[0], &slow.loops[0]);
    assert_eq!(a.rate_hz, 1000.0);
    assert!(a.method.contains("10000 Hz lifted"), "{}", a.method);
    let mut pa = a.points[0].poles.clone();
    let mut pb = b.points[0].poles.clone();
    let key =
        |z: &Complex<f64>| (z.re * 1e9).round() as i64 * 1_000_000 + (z.im * 1e6).round() as i64;
    pa.sort_by_key(key);
    pb.sort_by_key(key);
    assert_eq!(pa.len(), pb.len());
    for (x, y) in pa.iter().zip(&pb) {
        assert!((x - y).norm() < 1e-7, "{pa:?} vs {pb:?}");
    }
    let (ma, mb) = (
        a.points[0].margins.as_ref().unwrap(),
        b.points[0].margins.as_ref().unwrap(),
    );
    assert!((ma.phase_margin_deg - mb.phase_margin_deg).abs() < 1e-6);
    assert!((ma.gain_margin_db - mb.gain_margin_db).abs() < 1e-6);
}

#[test]
fn mimo_loci_of_a_diagonal_loop_are_its_two_channels() {
    // Two decoupled integrator loops k1/(z−1), k2/(z−1) through one 2-wide
    // path: the characteristic loci are the two SISO loops, so the closest
    // approach to −1 is min over the channels of min|1 + k/(e^{jθ} − 1)|,
    // reached at θ = π: 1 − k/2.
    let yaml = r#"base_rate_hz: 1000
duration_s: 0.1
blocks:
  - { name: ref, type: constant, value: 1.0, width: 2 }
  - { name: err, type: sum, signs: "+-", width: 2 }
  - { name: k, type: state_space, a: [[0.0]], b: [[0.0, 0.0]], c: [[0.0], [0.0]], d: [[0.3, 0.0], [0.0, 0.9]], discrete: true }
  - { name: plant, type: transfer_function, num: [1.0], den: [1.0, -1.0], discrete: true, width: 2 }
connections:
  - { from: ref.y, to: err.in0 }
  - { from: plant.y, to: err.in1 }
  - { from: err.y, to: k.u }
  - { from: k.y, to: plant.u }
"#;
    let (_, r) = build(yaml);
    assert!(r.passes(), "{r}");
    let p = &r.loops[0].points[0];
    assert_eq!(p.width, 2);
    assert!(p.margins.is_none());
    let d = p.loci_min_distance.unwrap();
    assert!((d - (1.0 - 0.9 / 2.0)).abs() < 1e-3, "{d}");
    assert!((p.s_hinf - 2.0 / (2.0 - 0.9)).abs() < 1e-6);
    assert_eq!(p.nyquist.unwrap().implied_unstable, 0);
    let mut radii: Vec<f64> = p.poles.iter().map(|z| z.norm()).collect();
    radii.sort_by(f64::total_cmp);
    assert!(
        radii[0].abs() < 1e-12 && (radii[1] - 0.1).abs() < 1e-12 && (radii[2] - 0.7).abs() < 1e-12
    );
}

// ---------------------------------------------------------------------------
// Random loops against simulation and an independent sweep
// ---------------------------------------------------------------------------

/// A random loop: plant and controller as discrete transfer functions
/// (descending powers of z), and a delay.
#[derive(Debug, Clone)]
struct RandomLoop {
    plant_num: Vec<f64>,
    plant_den: Vec<f64>,
    ctrl_num: Vec<f64>,
    ctrl_den: Vec<f64>,
    delay: usize,
}

fn conj_roots(spec: &[(f64, f64)]) -> Vec<Complex<f64>> {
    // (radius, angle): angle 0 or π gives one real root, else a conjugate pair.
    let mut v = Vec::new();
    for &(r, a) in spec {
        if a == 0.0 || a == PI {
            v.push(Complex::from_polar(r, a));
        } else {
            v.push(Complex::from_polar(r, a));
            v.push(Complex::from_polar(r, -a));
        }
    }
    v
}

fn eval(p: &[f64], z: Complex<f64>) -> Complex<f64> {
    p.iter().fold(Complex::new(0.0, 0.0), |acc, &c| acc * z + c)
}

fn loop_at(l: &RandomLoop, theta: f64) -> Complex<f64> {
    let z = Complex::from_polar(1.0, theta);
    eval(&l.plant_num, z) / eval(&l.plant_den, z) * eval(&l.ctrl_num, z)
        / eval(&l.ctrl_den, z)
        / z.powu(l.delay as u32)
}

fn random_loop() -> impl Strategy<Value = RandomLoop> {
    let pole = (0.1f64..0.97, prop_oneof![Just(0.0), Just(PI), 0.05f64..3.0]);
    let zero = -0.9f64..0.9;
    (
        prop::collection::vec(pole, 1..=4),
        any::<bool>(),
        prop::collection::vec(zero, 0..=3),
        0usize..3,
        (-0.9f64..0.9, -0.9f64..0.95),
        0usize..=3,
        -2.0f64..2.0,
        0.02f64..0.5,
    )
        .prop_map(
            |(poles, integrator, zeros, kind, (a, b), delay, log_k, w0)| {
                let mut p = conj_roots(&poles);
                if integrator {
                    p.push(Complex::new(1.0, 0.0));
                }
                p.truncate(6);
                let nz = zeros.len().min(p.len() - 1);
                let z: Vec<Complex<f64>> =
                    zeros[..nz].iter().map(|&x| Complex::new(x, 0.0)).collect();
                let plant_den = poly_from_roots(&p);
                let plant_num = if z.is_empty() {
                    vec![1.0]
                } else {
                    poly_from_roots(&z)
                };
                // Controller: lead-lag (z − a)/(z − b), PI (z − a)/(z − 1) or
                // P-with-filter 1/(z − b)·(1 − b).
                let (ctrl_num, ctrl_den) = match kind {
                    0 => (vec![1.0, -a], vec![1.0, -b]),
                    1 => (vec![1.0, -a.abs()], vec![1.0, -1.0]),
                    _ => (vec![1.0 - b.abs()], vec![1.0, -b.abs()]),
                };
                let mut l = RandomLoop {
                    plant_num,
                    plant_den,
                    ctrl_num,
                    ctrl_den,
                    delay,
                };
                // Scale so |L| = 10^log_k at θ = w0·π.
                let g = loop_at(&l, w0 * PI).norm();
                let s = 10f64.powf(log_k) / g;
                l.ctrl_num.iter_mut().for_each(|c| *c *= s);
                l
            },
        )
}

fn fmt_list(v: &[f64]) -> String {
    let s: Vec<String> = v.iter().map(|x| format!("{x:e}")).collect();
    format!("[{}]", s.join(", "))
}

fn random_graph(l: &RandomLoop, duration_s: f64) -> String {
    let (delay_block, into_plant) = if l.delay > 0 {
        (
            format!("  - {{ name: dl, type: delay, d: {} }}\n", l.delay),
            "  - { from: c.y, to: dl.u }\n  - { from: dl.y, to: plant.u }\n",
        )
    } else {
        (String::new(), "  - { from: c.y, to: plant.u }\n")
    };
    format!(
        r#"base_rate_hz: 1000
duration_s: {duration_s}
blocks:
  - {{ name: ref, type: constant, value: 1.0 }}
  - {{ name: err, type: sum, signs: "+-" }}
  - {{ name: c, type: transfer_function, num: {}, den: {}, discrete: true }}
{delay_block}  - {{ name: plant, type: transfer_function, num: {}, den: {}, discrete: true }}
connections:
  - {{ from: ref.y, to: err.in0 }}
  - {{ from: plant.y, to: err.in1 }}
  - {{ from: err.y, to: c.u }}
{into_plant}log: [plant.y]
"#,
        fmt_list(&l.ctrl_num),
        fmt_list(&l.ctrl_den),
        fmt_list(&l.plant_num),
        fmt_list(&l.plant_den),
    )
}

/// Phase margin, gain margin (dB) and modulus margin by a dense sweep of L,
/// independent of the state-space assembly.
fn sweep_margins(l: &RandomLoop) -> (f64, f64, f64) {
    let n = 200_000;
    let thetas: Vec<f64> = (1..n).map(|i| PI * i as f64 / n as f64).collect();
    let vals: Vec<Complex<f64>> = thetas.iter().map(|&t| loop_at(l, t)).collect();
    let mut pm = f64::INFINITY;
    let mut gm = f64::INFINITY;
    let mut mm = f64::INFINITY;
    for i in 1..vals.len() {
        let (a, b) = (vals[i - 1], vals[i]);
        mm = mm.min((b + 1.0).norm());
        if (a.norm() - 1.0) * (b.norm() - 1.0) <= 0.0 {
            let m = 180.0 + b.arg().to_degrees();
            let m = if m > 180.0 { m - 360.0 } else { m };
            if m.abs() < pm.abs() {
                pm = m;
            }
        }
        if a.im * b.im <= 0.0 && b.re < 0.0 {
            let g = -20.0 * b.norm().log10();
            if g.abs() < gm.abs() {
                gm = g;
            }
        }
    }
    // θ = π exactly (the response is real there).
    let end = loop_at(l, PI);
    mm = mm.min((end + 1.0).norm());
    if end.re < 0.0 {
        let g = -20.0 * end.norm().log10();
        if g.abs() < gm.abs() {
            gm = g;
        }
    }
    (pm, gm, mm)
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 48, rng_seed: proptest::test_runner::RngSeed::Fixed(17), ..ProptestConfig::default() })]

    #[test]
    fn random_loops_agree_with_simulation_roots_and_a_sweep(l in random_loop()) {
        let (_, report) = build(&random_graph(&l, 0.0));
        prop_assert_eq!(report.loops.len(), 1);
        let p = &report.loops[0].points[0];
        let rho = p.spectral_radius;
        // Independent poles: roots of den_c·den_p·z^d + num_c·num_p.
        let mut lhs = polymul(&l.ctrl_den, &l.plant_den);
        lhs.extend(std::iter::repeat_n(0.0, l.delay));
        let char_poly = polyadd(&lhs, &polymul(&l.ctrl_num, &l.plant_num));
        let rho_roots = roots(&char_poly).iter().map(|z| z.norm()).fold(0.0, f64::max);
        prop_assert!((rho - rho_roots).abs() < 1e-5 * rho.max(1.0), "gate {} vs roots {}", rho, rho_roots);
        // The Nyquist count agrees with the eigenvalues.
        let cl_out = p.poles.iter().filter(|z| z.norm() > 1.0 + 1e-9).count() as i64;
        prop_assert_eq!(p.nyquist.unwrap().implied_unstable, cl_out);
        // Stay away from the boundary, where simulation cannot tell quickly.
        prop_assume!((rho - 1.0).abs() > 0.02);
        let n = ((1e12f64).ln() / (rho.ln().abs())).ceil().min(20_000.0) as usize + 100;
        let (mut sched, _) = GraphSpec::from_yaml(&random_graph(&l, n as f64 / 1000.0), "t").unwrap().build().unwrap();
        let y = sched.run(|_| {}).logs[0].data.clone();
        let max_in = |a: &[f64]| a.iter().fold(0.0f64, |m, v| m.max(v.abs()));
        if report.passes() {
            prop_assert!(rho < 1.0);
            // Converged: the last 10 % is flat.
            let tail = &y[y.len() * 9 / 10..];
            let spread = tail.iter().cloned().fold(f64::NEG_INFINITY, f64::max) - tail.iter().cloned().fold(f64::INFINITY, f64::min);
            prop_assert!(spread <= 1e-6 * max_in(&y).max(1e-12), "accepted loop not settled: spread {} of {}", spread, max_in(&y));
            // Margins against the sweep.
            let m = p.margins.as_ref().unwrap();
            let (pm, gm, mm) = sweep_margins(&l);
            if pm.is_finite() { prop_assert!((m.phase_margin_deg - pm).abs() < 0.05, "PM {} vs sweep {}", m.phase_margin_deg, pm); }
            else { prop_assert!(m.phase_margin_deg.is_infinite()); }
            if gm.is_finite() { prop_assert!((m.gain_margin_db - gm).abs() < 0.05, "GM {} vs sweep {}", m.gain_margin_db, gm); }
            prop_assert!((m.modulus_margin - mm).abs() < 1e-3 * mm.max(1e-3), "MM {} vs sweep {}", m.modulus_margin, mm);
            prop_assert!((1.0 / p.s_hinf - mm).abs() < 1e-3 * mm.max(1e-3));
        } else {
            prop_assert!(rho > 1.0);
            prop_assert!(report.failures()[0].contains("unstable"));
            // Diverges: the last 10 % is far above the first quarter.
            let early = max_in(&y[..y.len() / 4]);
            let late = max_in(&y[y.len() * 9 / 10..]);
            prop_assert!(late > 100.0 * early.max(1e-300), "refused loop did not diverge: {} -> {}", early, late);
        }
    }
}
