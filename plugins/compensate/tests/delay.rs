//! A time delay → the user's `pid` re-tuned for it (issue #28).
//!
//! End to end from a record: plf's truth generator (`generate::second_order`,
//! the delay written out as a shift of the force on a 20× finer grid, not the
//! fitted `time_delay` block) with the delay hidden, `diagnose` on the nominal
//! stage (it names `time_delay` on the drive), then `compensate` on a PID loop
//! around the nominal stage at the record's 2 kHz, tracking a 1 µm sine at
//! 5 Hz.
//!
//! Every figure the tests hold the result to is computed here from first
//! principles, independently of the gate and of the simulation: the stage's
//! exact ZOH model (matrix exponential), the PID's Tustin transfer function
//! and the fitted delay's interpolation e^{−jωnT}((1 − f) + f e^{−jωT}) give
//! L(e^{jωT}); from it the phase margin at the gain crossover, ‖S‖∞ and, with
//! the characteristic polynomial's roots, the closed-loop poles; a stable
//! loop's error on the sine is then A·|S(e^{jω_r T})|/√2 rms once the
//! transient has decayed, and an unstable loop's grows as ρ^k, ρ its largest
//! pole modulus.

mod support;

use nalgebra::{Complex, DMatrix};
use nanomotion_compensate::{Options, Outcome, compensate, named};
use nanomotion_core::graph::GraphSpec;
use nanomotion_plf::diagnose::{self, diagnose};
use nanomotion_plf::{generate, surgery};
use serde_json::Value;
use std::f64::consts::PI;

const T: f64 = 1.0 / generate::RATE_HZ;
/// The reference: a sine of amplitude A at F_R.
const A: f64 = 1e-6;
const F_R: f64 = 5.0;
/// Scored over the last second of 4 s: five periods of the sine, after the
/// re-tuned loop's slowest pole (its integral action, lowered with the gain)
/// has decayed.
const FROM_S: f64 = 3.0;
const DURATION_S: f64 = 4.0;
/// The margin the re-tune may give up (a design choice, not a result).
const GIVEN_UP_DEG: f64 = nanomotion_compensate::synth::delay::MARGIN_GIVEN_UP_DEG;

/// The PID loop of [`support::pid_loop`] with a crossover near `fc`, the
/// sine reference, `extra` appended (e.g. a `require:` section).
fn controller(stage: &Value, fc: f64, extra: &str) -> GraphSpec {
    support::pid_loop(
        stage,
        fc,
        &format!("type: sinusoid, amplitude: {A:?}, frequency_hz: {F_R:?}"),
        (DURATION_S, FROM_S),
        extra,
    )
}

/// A generated record with the delay hidden, its diagnosis, the loop and the
/// outcome of `compensate`; also the true delay in samples (from the
/// generator's words).
struct Case {
    delay_samples: f64,
    /// Where the diagnosis put it (`input side…`, `output side…`).
    site: String,
    fitted_delay_s: f64,
    loop_: GraphSpec,
    out: Outcome,
}

fn case(seed: u64, fc: f64, extra: &str, keep: bool) -> Case {
    let _ = std::any::type_name::<nanomotion_plf::effects::Effect>();
    let rec = generate::second_order("time_delay", seed, 8000, false).unwrap();
    let nominal = GraphSpec::from_yaml(&rec.nominal_yaml, "nominal.yaml").unwrap();
    let rep = diagnose(&nominal, &rec.data, &diagnose::Options::default()).unwrap();
    assert_eq!(rep.found, vec!["time_delay".to_string()], "{}", rec.truth);
    let delay_samples: f64 = rec
        .truth
        .strip_prefix("input delay ")
        .and_then(|s| s.strip_suffix(" samples"))
        .and_then(|s| s.parse().ok())
        .unwrap_or_else(|| panic!("{}", rec.truth));
    let fitted_delay_s = rep.steps[0].final_params["delay_s"];
    let stage = nominal.blocks.iter().find(|b| b.name == "stage").unwrap();
    let loop_ = controller(&surgery::block_to_json(stage.block.as_ref()), fc, extra);
    let out = support::compensate_named(&rep, &loop_, keep, &format!("seed {seed}: {}", rec.truth));
    Case {
        delay_samples,
        site: rep.steps[0].site.clone(),
        fitted_delay_s,
        loop_,
        out,
    }
}

// ---------------------------------------------------------------------------------
// The loop from first principles
// ---------------------------------------------------------------------------------

/// A polynomial in z, highest power first.
type Poly = Vec<f64>;

fn mul(a: &[f64], b: &[f64]) -> Poly {
    let mut c = vec![0.0; a.len() + b.len() - 1];
    for (i, x) in a.iter().enumerate() {
        for (j, y) in b.iter().enumerate() {
            c[i + j] += x * y;
        }
    }
    c
}

fn add(a: &[f64], b: &[f64]) -> Poly {
    let n = a.len().max(b.len());
    let pad = |p: &[f64]| {
        let mut v = vec![0.0; n - p.len()];
        v.extend_from_slice(p);
        v
    };
    pad(a).iter().zip(pad(b)).map(|(x, y)| x + y).collect()
}

fn eval(p: &[f64], z: Complex<f64>) -> Complex<f64> {
    p.iter().fold(Complex::new(0.0, 0.0), |acc, c| acc * z + c)
}

/// A discrete SISO transfer function num/den.
#[derive(Clone)]
struct Tf {
    num: Poly,
    den: Poly,
}

impl Tf {
    fn times(&self, o: &Tf) -> Tf {
        Tf {
            num: mul(&self.num, &o.num),
            den: mul(&self.den, &o.den),
        }
    }
    fn at(&self, w: f64) -> Complex<f64> {
        let z = Complex::from_polar(1.0, w * T);
        eval(&self.num, z) / eval(&self.den, z)
    }
    /// The roots of den + num: the closed-loop poles of the unity negative
    /// feedback loop.
    fn closed_loop_poles(&self) -> Vec<Complex<f64>> {
        let mut p = add(&self.num, &self.den);
        while p[0] == 0.0 {
            p.remove(0);
        }
        let n = p.len() - 1;
        let companion = DMatrix::from_fn(n, n, |i, j| {
            if i == 0 {
                -p[j + 1] / p[0]
            } else if i == j + 1 {
                1.0
            } else {
                0.0
            }
        });
        companion.complex_eigenvalues().iter().copied().collect()
    }
}

/// The stage's exact ZOH model at T: x⁺ = A_d x + B_d u, y = x₁, so
/// P(z) = [b₁z + a₁₂b₂ − a₂₂b₁] / [z² − (a₁₁ + a₂₂)z + a₁₁a₂₂ − a₁₂a₂₁].
fn stage_tf(stage: &Value) -> Tf {
    let a = |i: usize, j: usize| stage["a"][i][j].as_f64().unwrap();
    let b = |i: usize| stage["b"][i][0].as_f64().unwrap();
    let mut m = DMatrix::zeros(3, 3);
    for i in 0..2 {
        for j in 0..2 {
            m[(i, j)] = a(i, j) * T;
        }
        m[(i, 2)] = b(i) * T;
    }
    let e = m.exp();
    let (a11, a12, a21, a22) = (e[(0, 0)], e[(0, 1)], e[(1, 0)], e[(1, 1)]);
    let (b1, b2) = (e[(0, 2)], e[(1, 2)]);
    Tf {
        num: vec![b1, a12 * b2 - a22 * b1],
        den: vec![1.0, -(a11 + a22), a11 * a22 - a12 * a21],
    }
}

/// The core `pid` (Tustin): k_p + (k_iT/2)(z + 1)/(z − 1) + β_d(z − 1)/(z − α),
/// α = (2 − ω_dT)/(2 + ω_dT), β_d = 2k_dω_d/(2 + ω_dT).
fn pid_tf(p: &Value) -> Tf {
    let f = |k: &str| p[k].as_f64().unwrap();
    let (kp, ki, kd) = (f("kp"), f("ki"), f("kd"));
    let wd = 2.0 * PI * f("derivative_cutoff_hz");
    let alpha = (2.0 - wd * T) / (2.0 + wd * T);
    let beta = 2.0 * kd * wd / (2.0 + wd * T);
    let g = ki * T / 2.0;
    let den = mul(&[1.0, -1.0], &[1.0, -alpha]);
    let num = add(
        &add(
            &mul(&[kp], &den),
            &mul(&[g], &mul(&[1.0, 1.0], &[1.0, -alpha])),
        ),
        &mul(&[beta], &mul(&[1.0, -1.0], &[1.0, -1.0])),
    );
    Tf { num, den }
}

/// The `time_delay` block: d = (n + f)T, y = (1 − f)u_{k−n} + f·u_{k−n−1}:
/// ((1 − f)z + f)/z^{n+1}.
fn delay_tf(d: f64) -> Tf {
    let x = d / T;
    let n = x.floor();
    let f = x - n;
    let mut den = vec![0.0; n as usize + 2];
    den[0] = 1.0;
    Tf {
        num: vec![1.0 - f, f],
        den,
    }
}

fn block_params(spec: &GraphSpec, name: &str) -> Value {
    surgery::block_to_json(
        spec.blocks
            .iter()
            .find(|b| b.name == name)
            .unwrap()
            .block
            .as_ref(),
    )
}

/// The loop transfer of `spec`'s pid and stage, with the delay `d` (s) on the drive.
fn loop_tf(spec: &GraphSpec, d: f64) -> Tf {
    pid_tf(&block_params(spec, "pid"))
        .times(&stage_tf(&block_params(spec, "stage")))
        .times(&delay_tf(d))
}

/// Phase margin (°) and gain crossover (Hz): over every crossing of |L| = 1
/// (each refined by bisection to 10⁻¹² Hz), the margin 180° + ∠L taken in
/// (−180°, 180°] nearest 0 (the crossing nearest −1; the resonance of the
/// stage crosses too, far from −1).
fn phase_margin(l: &Tf) -> (f64, f64) {
    crossings(l)
        .into_iter()
        .fold((f64::INFINITY, f64::NAN), |best, c| {
            if c.0.abs() < best.0.abs() { c } else { best }
        })
}

/// Every crossing of |L| = 1: (180° + ∠L in (−180°, 180°], frequency (Hz)).
fn crossings(l: &Tf) -> Vec<(f64, f64)> {
    let mag = |f: f64| l.at(2.0 * PI * f).norm();
    let grid: Vec<f64> = (0..=20000)
        .map(|i| 0.1 * (0.499 * generate::RATE_HZ / 0.1).powf(i as f64 / 20000.0))
        .collect();
    let mut out = Vec::new();
    for w in grid.windows(2) {
        if (mag(w[0]) - 1.0) * (mag(w[1]) - 1.0) <= 0.0 {
            let (mut a, mut b) = (w[0], w[1]);
            while b - a > 1e-12 {
                let m = 0.5 * (a + b);
                if (mag(a) - 1.0) * (mag(m) - 1.0) <= 0.0 {
                    b = m;
                } else {
                    a = m;
                }
            }
            let fc = 0.5 * (a + b);
            let pm =
                (180.0 + l.at(2.0 * PI * fc).arg().to_degrees() + 180.0).rem_euclid(360.0) - 180.0;
            out.push((pm, fc));
        }
    }
    out
}

/// |S| = 1/|1 + L| at `f` (Hz).
fn sensitivity(l: &Tf, f: f64) -> f64 {
    1.0 / (1.0 + l.at(2.0 * PI * f)).norm()
}

/// ‖S‖∞ over a fine grid up to Nyquist.
fn s_peak(l: &Tf) -> f64 {
    (1..=40000)
        .map(|i| sensitivity(l, i as f64 * 0.5 * generate::RATE_HZ / 40000.0))
        .fold(0.0, f64::max)
}

/// Largest closed-loop pole modulus, and the damping ratio of the dominant
/// oscillatory pair (largest modulus among poles off the real axis),
/// ζ = −Re s/|s| with s = ln(p)/T.
fn poles(l: &Tf) -> (f64, f64) {
    let p = l.closed_loop_poles();
    let rho = p.iter().map(|z| z.norm()).fold(0.0, f64::max);
    let pair = p
        .iter()
        .filter(|z| z.im > 1e-9)
        .max_by(|a, b| a.norm().total_cmp(&b.norm()))
        .unwrap();
    let s = pair.ln() / T;
    (rho, -s.re / s.norm())
}

/// The step response's error of `spec`'s pid and stage with the delay `d`
/// on the drive (the plant as diagnosed), a unit step at 0.1 s: its first
/// difference Δe from the step on (the slow tail of the integral action
/// nearly cancels in it, the ringing stays).
fn step_ringing(spec: &GraphSpec, d: f64) -> Vec<f64> {
    let mut pid = block_params(spec, "pid");
    pid["name"] = "pid".into();
    let mut stage = block_params(spec, "stage");
    stage["name"] = "stage".into();
    let g = GraphSpec::from_yaml(
        &format!(
            "base_rate_hz: {}\nduration_s: 0.5\nblocks:\n  - {{ name: ref, type: step, time_s: 0.09975, initial: 0.0, final: 1.0 }}\n  - {{ name: err, type: sum, signs: \"+-\" }}\n  - {pid}\n  - {{ name: delay, type: time_delay, max_delay_s: 0.01, delay_s: {d:?} }}\n  - {stage}\nconnections:\n  - {{ from: ref.y, to: err.in0 }}\n  - {{ from: stage.y, to: err.in1 }}\n  - {{ from: err.y, to: pid.e }}\n  - {{ from: pid.u, to: delay.u }}\n  - {{ from: delay.y, to: stage.u }}\nlog: [err.y]\n",
            generate::RATE_HZ
        ),
        "step.yaml",
    )
    .unwrap();
    let (mut s, _) = g.build().unwrap();
    let e = s.run(|_| {}).logs[0].data.clone();
    let k0 = (0.1 / T).round() as usize;
    e[k0..].windows(2).map(|w| w[1] - w[0]).collect()
}

/// Ratio of the third to the second positive peak of `x` after its largest
/// |x| (the step's kick; the first peak still carries the faster modes), and
/// the distance between them (samples); each peak interpolated by the
/// parabola through its three samples.
fn peak_ratio(x: &[f64]) -> (f64, f64) {
    let start = (0..x.len())
        .max_by(|&a, &b| x[a].abs().total_cmp(&x[b].abs()))
        .unwrap();
    let peaks: Vec<(f64, f64)> = (start + 1..x.len() - 1)
        .filter(|&k| x[k] > 0.0 && x[k] >= x[k - 1] && x[k] > x[k + 1])
        .skip(1)
        .take(2)
        .map(|k| {
            let (y0, y1, y2) = (x[k - 1], x[k], x[k + 1]);
            let delta = 0.5 * (y0 - y2) / (y0 - 2.0 * y1 + y2);
            (k as f64 + delta, y1 - 0.25 * (y0 - y2) * delta)
        })
        .collect();
    (peaks[1].1 / peaks[0].1, peaks[1].0 - peaks[0].0)
}

/// The dominant oscillatory closed-loop pole (largest modulus off the real axis).
fn dominant_pair(l: &Tf) -> Complex<f64> {
    l.closed_loop_poles()
        .into_iter()
        .filter(|z| z.im > 1e-9)
        .max_by(|a, b| a.norm().total_cmp(&b.norm()))
        .unwrap()
}

fn retuned(out: &Outcome) -> &nanomotion_compensate::CompensatorReport {
    let c = &out.report.compensators[0];
    assert_eq!(
        (c.effect.as_str(), c.block.as_str(), c.type_name.as_str()),
        ("time_delay", "pid", "pid")
    );
    assert!(
        c.why
            .starts_with("re-tune for the delay: no block inserted"),
        "{}",
        c.why
    );
    c
}

/// The written pid's gains are the user's scaled in frequency by β (every
/// zero/pole ratio kept) and in gain by γ, as the design figures say.
fn check_scaling(user: &Value, design: &std::collections::BTreeMap<String, f64>) {
    let (b, g) = (design["frequency_scale"], design["gain_scale"]);
    let f = |k: &str| user[k].as_f64().unwrap();
    for (k, want) in [
        ("kp", g * f("kp")),
        ("ki", g * b * f("ki")),
        ("kd", g * f("kd") / b),
        ("derivative_cutoff_hz", b * f("derivative_cutoff_hz")),
    ] {
        assert!(
            (design[k] - want).abs() <= 1e-9 * want.abs(),
            "{k}: {} vs {want}",
            design[k]
        );
    }
}

// ---------------------------------------------------------------------------------
// Tests
// ---------------------------------------------------------------------------------

/// Seed 5: a 3.55-sample delay (1.78 ms) on a stage at 2 kHz, the PID at about
/// 80 Hz — the delay takes more than the loop's margin: unstable with it.
#[test]
fn a_delay_that_destabilises_the_pid_loop_is_met_by_lowering_its_crossover() {
    let Case {
        delay_samples,
        site,
        fitted_delay_s: d,
        loop_,
        out,
    } = case(5, 80.0, "", false);
    assert!(site.starts_with("input side"), "{site}");
    // The diagnosis found the delay to within 0.05 samples of the truth.
    assert!(
        (d / T - delay_samples).abs() < 0.05,
        "{d} s vs {delay_samples} samples"
    );
    let r = &out.report;
    let c = retuned(&out);
    // (a) the written graph: the user's four blocks, only the pid changed, and
    // the stability gate passes it (here and in the report).
    assert!(c.kept && r.gate.passes, "{c:?}");
    // The re-tuned graph on the wall clock, bit for bit as offline.
    support::runs_on_the_wall_clock_as_offline(&out.compensated, &[]);
    let g = &out.compensated;
    assert_eq!(g.blocks.len(), 4);
    assert_eq!(g.connections.len(), loop_.connections.len());
    let new_pid = block_params(g, "pid");
    for k in ["kp", "ki", "kd", "derivative_cutoff_hz"] {
        assert_eq!(new_pid[k].as_f64(), Some(c.design[k]), "{k}");
    }
    check_scaling(&block_params(&loop_, "pid"), &c.design);
    let judged = {
        let s = surgery::clone_spec(g).unwrap();
        let (sched, _) = s.build().unwrap();
        nanomotion_core::gate::analyse(&sched, &Default::default())
    };
    assert!(judged.passes(), "{:?}", judged.failures());

    // (b) the margins, from the model here: the user's loop without the
    // delay, with it, and the re-tuned loop with it.
    let (pm0, fc0) = phase_margin(&loop_tf(&loop_, 0.0));
    let (pm_d, _) = phase_margin(&loop_tf(&loop_, d));
    let (pm1, fc1) = phase_margin(&loop_tf(g, d));
    let target = pm0 - GIVEN_UP_DEG;
    eprintln!(
        "PM {pm0:.2}° at {fc0:.2} Hz; with the delay {pm_d:.2}°; re-tuned {pm1:.2}° at {fc1:.2} Hz (target {target:.2}°)"
    );
    assert!(pm_d < 0.0, "the delay eats the whole margin: {pm_d}");
    assert!(pm1 >= target - 1e-6, "{pm1} < {target}");
    // The gate's figures agree with the model's.
    assert!((c.design["phase_margin_deg"] - pm0).abs() < 1e-3, "{pm0}");
    assert!(
        (c.design["retuned_phase_margin_deg"] - pm1).abs() < 1e-3,
        "{pm1}"
    );
    assert!(
        (c.design["retuned_crossover_hz"] - fc1).abs() < 1e-3 * fc1,
        "{fc1}"
    );
    // Without the delay the re-tuned loop crosses over at β f_c exactly (γ
    // places it there; the fitted delay's interpolation, |(1 − f) + f e^{−jωT}|
    // < 1, lowers the crossover with it a little).
    let beta = c.design["frequency_scale"];
    let xs = crossings(&loop_tf(g, 0.0));
    assert!(
        xs.iter()
            .any(|(_, f)| (f / (beta * fc0) - 1.0).abs() < 1e-6),
        "{xs:?} vs {beta} · {fc0}"
    );

    // (c) the error. Without the re-tune the loop is unstable: its largest
    // closed-loop pole ρ > 1, so the error grows by ρ^N over N samples; the
    // before trace does (the rms of its last 0.25 s over the 0.25 s before,
    // within 2 %).
    let (rho_d, _) = poles(&loop_tf(&loop_, d));
    let (rho1, _) = poles(&loop_tf(g, d));
    assert!(rho_d > 1.0 && rho1 < 1.0, "{rho_d} {rho1}");
    let before = &out.traces.iter().find(|t| t.0 == "before").unwrap().2;
    let q = (0.25 / T) as usize;
    let n = before.len();
    let growth = support::rms(&before[n - q..]) / support::rms(&before[n - 2 * q..n - q]);
    let predicted = rho_d.powi(q as i32);
    eprintln!("growth per 0.25 s {growth:.4e}, ρ^N = {predicted:.4e}");
    assert!(
        (growth / predicted - 1.0).abs() < 0.02,
        "{growth} vs {predicted}"
    );
    // Re-tuned it is stable, its transient gone by the window (ρ^{from} < 10⁻³),
    // and its error on the sine is A|S(ω_r)|/√2.
    eprintln!("largest closed-loop pole: {rho_d:.6} with the delay, {rho1:.6} re-tuned");
    assert!(rho1.powf(FROM_S / T) < 1e-3);
    let after = A * sensitivity(&loop_tf(g, d), F_R) / 2f64.sqrt();
    eprintln!("after: rms {:.4e}, predicted {after:.4e}", r.after.rms);
    assert!(
        (r.after.rms / after - 1.0).abs() < 0.02,
        "{} vs {after}",
        r.after.rms
    );
    // And the user's loop without the delay: A|S₀(ω_r)|/√2.
    let nominal = A * sensitivity(&loop_tf(&loop_, 0.0), F_R) / 2f64.sqrt();
    assert!(
        (r.nominal.rms / nominal - 1.0).abs() < 0.02,
        "{} vs {nominal}",
        r.nominal.rms
    );
    assert!(r.cut_percent > 99.9, "{}", r.cut_percent);
}

/// Seed 2: a 2.70-sample delay (1.35 ms), the same PID: the loop stays stable
/// with the delay but rings (its margin falls from 59° to 12°). The re-tune
/// restores the margin and the damping; on this 5 Hz sine the slower loop
/// tracks worse, so the validation drops it by default and says so (the
/// criterion is the rms of the error on the user's reference), and keeps it
/// with `keep`.
#[test]
fn a_delay_that_leaves_the_loop_ringing_is_re_tuned_and_judged_on_the_reference() {
    let Case {
        fitted_delay_s: d,
        loop_,
        out,
        ..
    } = case(2, 80.0, "", false);
    let r = &out.report;
    let c = retuned(&out);
    let user = loop_tf(&loop_, d);
    let (pm0, _) = phase_margin(&loop_tf(&loop_, 0.0));
    let (pm_d, fc_d) = phase_margin(&user);
    // The re-tuned pid, as the design figures give it, in the user's loop.
    let mut g = surgery::clone_spec(&loop_).unwrap();
    let mut p = block_params(&loop_, "pid");
    check_scaling(&p, &c.design);
    for k in ["kp", "ki", "kd", "derivative_cutoff_hz"] {
        p[k] = c.design[k].into();
    }
    g.blocks.iter_mut().find(|b| b.name == "pid").unwrap().block =
        surgery::block_from_json(p).unwrap();
    let re = loop_tf(&g, d);
    let (pm1, fc1) = phase_margin(&re);
    eprintln!(
        "PM {pm0:.2}°; with the delay {pm_d:.2}° at {fc_d:.2} Hz; re-tuned {pm1:.2}° at {fc1:.2} Hz"
    );
    // (b) the margin with the delay is back to the target.
    assert!(pm_d > 0.0 && pm_d < pm0 - GIVEN_UP_DEG, "{pm_d}");
    assert!(pm1 >= pm0 - GIVEN_UP_DEG - 1e-6, "{pm1}");
    // (c) the ringing: at a crossover |1 + L| = 2 sin(PM/2), so
    // ‖S‖∞ ≥ 1/(2 sin(PM/2)): with the delay at least 4.7 here (6.2, the
    // loop amplifies disturbances near 100 Hz six-fold); re-tuned the whole
    // peak is below 40 % of that bound, and the dominant closed-loop pair
    // (ζ = −Re s/|s|, s = ln p/T) is more than twice as damped.
    let (s_d, s1) = (s_peak(&user), s_peak(&re));
    let bound = |pm: f64| 1.0 / (2.0 * (pm.to_radians() / 2.0).sin());
    let ((rho_d, zeta_d), (rho1, zeta1)) = (poles(&user), poles(&re));
    eprintln!("‖S‖∞ {s_d:.3} -> {s1:.3}; ζ {zeta_d:.3} -> {zeta1:.3}");
    assert!(s_d >= bound(pm_d) * (1.0 - 1e-9) && s1 >= bound(pm1) * (1.0 - 1e-9));
    assert!(s1 < 0.4 * bound(pm_d), "{s_d} -> {s1}");
    assert!(zeta1 > 2.0 * zeta_d, "{zeta_d} -> {zeta1}");
    // The ringing in the simulated step response (the plant as diagnosed):
    // successive peaks of Δe (interpolated between samples) decay by |p|^N
    // over the N samples of one period of the dominant pair p, N = 2π/∠p;
    // re-tuned the pair loses more than twice as much per period of its own
    // (too little is left after the kick to find two peaks in the run).
    let p = dominant_pair(&user);
    let period = 2.0 * PI / p.arg();
    let (ratio, n) = peak_ratio(&step_ringing(&loop_, d));
    let predicted = p.norm().powf(period);
    let p1 = dominant_pair(&re);
    let predicted1 = p1.norm().powf(2.0 * PI / p1.arg());
    eprintln!(
        "with the delay: ringing at {:.1} Hz, peaks {ratio:.4} apart {n:.2} samples; dominant pair: {predicted:.4} per {period:.1} samples; re-tuned: {predicted1:.4} per period",
        p.arg() / (2.0 * PI * T)
    );
    assert!((n - period).abs() < 0.05 * period, "{n} vs {period}");
    assert!(
        (ratio / predicted - 1.0).abs() < 0.05,
        "{ratio} vs {predicted}"
    );
    assert!(predicted1 < 0.5 * predicted, "{predicted1} vs {predicted}");
    // The tracking error on the sine, both loops stable and settled:
    // A|S(ω_r)|/√2.
    assert!(rho_d.max(rho1).powf(FROM_S / T) < 1e-3, "{rho_d} {rho1}");
    let (e_d, e1) = (
        A * sensitivity(&user, F_R) / 2f64.sqrt(),
        A * sensitivity(&re, F_R) / 2f64.sqrt(),
    );
    eprintln!(
        "rms on the sine: {:.4e} (predicted {e_d:.4e}) -> {:.4e} (predicted {e1:.4e})",
        r.before.rms, c.alone.rms
    );
    assert!((r.before.rms / e_d - 1.0).abs() < 0.02);
    assert!((c.alone.rms / e1 - 1.0).abs() < 0.02);
    // Here the slower loop tracks the 5 Hz sine worse: dropped, and said.
    assert!(e1 > e_d);
    assert!(!c.kept, "{c:?}");
    assert!(c.note.as_deref().unwrap().starts_with("dropped"), "{c:?}");
    assert_eq!(
        block_params(&out.compensated, "pid"),
        block_params(&loop_, "pid")
    );
    assert!(r.gate.passes);
}

/// Seed 1: the diagnosis puts the 2.35-sample delay on the measured position
/// (the output side; in the loop a delay anywhere in the ring is the same
/// factor of L), and the user's graph asks the gate for 53° of phase margin,
/// more than its 56° less 5°: the target is then the gate's 53°.
#[test]
fn a_delay_on_the_measurement_with_a_required_margin_is_re_tuned_to_it() {
    let Case {
        site,
        fitted_delay_s: d,
        loop_,
        out,
        ..
    } = case(1, 80.0, "require: { phase_margin_deg: 53.0 }\n", true);
    assert!(site.starts_with("output side"), "{site}");
    let c = retuned(&out);
    let (pm0, _) = phase_margin(&loop_tf(&loop_, 0.0));
    let (pm_d, _) = phase_margin(&loop_tf(&loop_, d));
    let (pm1, _) = phase_margin(&loop_tf(&out.compensated, d));
    let target = (pm0 - GIVEN_UP_DEG).max(53.0);
    eprintln!("PM {pm0:.2}°, with the delay {pm_d:.2}°, re-tuned {pm1:.2}° (target {target:.2}°)");
    assert_eq!(c.design["target_phase_margin_deg"], target);
    assert!(pm_d < target && pm1 >= target - 1e-6, "{pm_d} {pm1}");
    // Kept with `keep`: the written graph carries it and passes the gate
    // with its `require:`.
    assert!(c.kept && out.report.gate.passes);
    check_scaling(&block_params(&loop_, "pid"), &c.design);
    // The re-tuned graph on the wall clock, bit for bit as offline.
    support::runs_on_the_wall_clock_as_offline(&out.compensated, &[]);
}

/// A controller that is not a core `pid`/`pi` (the same PID written as a
/// `transfer_function`) is not re-tuned: the report states what the delay
/// takes and the fix.
#[test]
fn a_delay_before_a_transfer_function_controller_is_stated_with_the_fix() {
    let aug = GraphSpec::from_yaml(
        "base_rate_hz: 1000\nduration_s: 1\nblocks:\n  - { name: drive, type: data_column, column: u }\n  - { name: stage, type: state_space, a: [[0.0, 1.0], [0.0, 0.0]], b: [[0.0], [1.0]], c: [[1.0, 0.0]], discretisation: zoh }\n  - { name: plf_time_delay, type: time_delay, max_delay_s: 0.01, delay_s: 0.002 }\nconnections:\n  - { from: drive.y, to: plf_time_delay.u }\n  - { from: plf_time_delay.y, to: stage.u }\ncompare:\n  - { signal: stage.y, column: y }\n",
        "model_augmented.yaml",
    )
    .unwrap();
    // C(s) = 5020 (s/40 + 1)/(s/400 + 1) on 1/s²: a lead with its most
    // phase, 55°, at the 20 Hz crossover; the 2 ms delay takes 14°.
    let ctl = GraphSpec::from_yaml(
        "base_rate_hz: 1000\nduration_s: 1\nblocks:\n  - { name: ref, type: sinusoid, amplitude: 1.0, frequency_hz: 1.0 }\n  - { name: err, type: sum, signs: \"+-\" }\n  - { name: ctl, type: transfer_function, num: [125.5, 5020.0], den: [0.0025, 1.0], discretisation: tustin }\n  - { name: stage, type: state_space, a: [[0.0, 1.0], [0.0, 0.0]], b: [[0.0], [1.0]], c: [[1.0, 0.0]], discretisation: zoh }\nconnections:\n  - { from: ref.y, to: err.in0 }\n  - { from: stage.y, to: err.in1 }\n  - { from: err.y, to: ctl.u }\n  - { from: ctl.y, to: stage.u }\nscore:\n  - { signal: err.y, from_s: 0.5 }\n",
        "controller.yaml",
    )
    .unwrap();
    let out = compensate(&aug, &ctl, &named::from_graph(&aug), &Options::default()).unwrap();
    assert!(out.report.compensators.is_empty());
    let n = &out.report.not_compensated[0];
    eprintln!("{}", n.reason);
    assert_eq!(n.effect, "time_delay");
    assert!(n.reason.starts_with("no compensator"), "{}", n.reason);
    assert!(
        n.reason.contains("`ctl`, a `transfer_function` block"),
        "{}",
        n.reason
    );
    assert!(
        n.reason.contains("Fix: write it as a core `pid`"),
        "{}",
        n.reason
    );
    let f = &n.figures;
    // The delay takes 360°·f_c·d of the margin at the user's crossover.
    assert!(
        (f["phase_margin_left_deg"] - (f["phase_margin_deg"] - 360.0 * f["crossover_hz"] * 0.002))
            .abs()
            < 1e-9
    );
    assert!(f["phase_margin_with_delay_deg"] < f["phase_margin_deg"]);
}

/// A `pi` (C = k_p(s + 2πf_i)/s) on an integrator stage 1/s at 1 kHz: with a
/// delay of 2 ms it is re-tuned (k_p by γ, the zero f_i by β: their ratio to
/// the crossover kept), and the margin with the delay, from the model
/// C·P·z^{−2} here, is back to the target; with 0.1 ms the delay takes less
/// than the 5° the re-tune would give up: no re-tune needed.
#[test]
fn a_pi_is_re_tuned_and_a_small_delay_needs_none() {
    let rate = 1000.0;
    let dt = 1.0 / rate;
    let aug = |d: f64| {
        GraphSpec::from_yaml(
            &format!("base_rate_hz: {rate}\nduration_s: 1\nblocks:\n  - {{ name: drive, type: data_column, column: u }}\n  - {{ name: stage, type: state_space, a: [[0.0]], b: [[1.0]], c: [[1.0]], discretisation: zoh }}\n  - {{ name: plf_time_delay, type: time_delay, max_delay_s: 0.01, delay_s: {d:?} }}\nconnections:\n  - {{ from: drive.y, to: plf_time_delay.u }}\n  - {{ from: plf_time_delay.y, to: stage.u }}\ncompare:\n  - {{ signal: stage.y, column: y }}\n"),
            "model_augmented.yaml",
        )
        .unwrap()
    };
    // k_p = 2π·60 puts the crossover near 60 Hz; the zero at 6 Hz.
    let (kp, fi) = (2.0 * PI * 60.0, 6.0);
    let ctl = GraphSpec::from_yaml(
        &format!("base_rate_hz: {rate}\nduration_s: 1\nblocks:\n  - {{ name: ref, type: sinusoid, amplitude: 1.0, frequency_hz: 1.0 }}\n  - {{ name: err, type: sum, signs: \"+-\" }}\n  - {{ name: pi, type: pi, kp: {kp:?}, zero_hz: {fi:?} }}\n  - {{ name: stage, type: state_space, a: [[0.0]], b: [[1.0]], c: [[1.0]], discretisation: zoh }}\nconnections:\n  - {{ from: ref.y, to: err.in0 }}\n  - {{ from: stage.y, to: err.in1 }}\n  - {{ from: err.y, to: pi.e }}\n  - {{ from: pi.u, to: stage.u }}\nscore:\n  - {{ signal: err.y, from_s: 0.5 }}\n"),
        "controller.yaml",
    )
    .unwrap();
    // The model: Tustin PI k_p + k_p·2πf_i·(T/2)(z + 1)/(z − 1), ZOH 1/s = T/(z − 1),
    // the integer delay 1/z².
    let loop_at = |kp: f64, fi: f64, w: f64, delay: i32| {
        let z = Complex::from_polar(1.0, w * dt);
        let one = Complex::new(1.0, 0.0);
        let c = kp + kp * 2.0 * PI * fi * dt / 2.0 * (z + one) / (z - one);
        c * dt / (z - one) / z.powi(delay)
    };
    let margin_with = |kp: f64, fi: f64, delay: i32| {
        // The single crossover of this loop, by bisection on |L| = 1.
        let (mut a, mut b) = (1.0, 0.49 * rate);
        while b - a > 1e-10 {
            let m = 0.5 * (a + b);
            if loop_at(kp, fi, 2.0 * PI * m, delay).norm() > 1.0 {
                a = m;
            } else {
                b = m;
            }
        }
        180.0 + loop_at(kp, fi, 2.0 * PI * a, delay).arg().to_degrees()
    };
    let margin = |kp: f64, fi: f64| margin_with(kp, fi, 2);
    let out = compensate(
        &aug(0.002),
        &ctl,
        &named::from_graph(&aug(0.002)),
        &Options::default(),
    )
    .unwrap();
    let c = &out.report.compensators[0];
    assert_eq!((c.block.as_str(), c.type_name.as_str()), ("pi", "pi"));
    let (b, g) = (c.design["frequency_scale"], c.design["gain_scale"]);
    assert!((c.design["kp"] - g * kp).abs() < 1e-9 * kp);
    assert!((c.design["zero_hz"] - b * fi).abs() < 1e-12);
    let pm1 = margin(c.design["kp"], c.design["zero_hz"]);
    let pm0 = margin_with(kp, fi, 0);
    assert!((c.design["phase_margin_deg"] - pm0).abs() < 1e-3, "{pm0}");
    let target = pm0 - GIVEN_UP_DEG;
    eprintln!(
        "pi: PM with the delay {:.2}° -> {pm1:.2}° (target {target:.2}°)",
        margin(kp, fi)
    );
    assert!(
        margin(kp, fi) < target && pm1 >= target - 1e-6,
        "{pm1} {target}"
    );
    assert!(out.report.gate.passes);
    // The re-tuned graph on the wall clock, bit for bit as offline.
    support::runs_on_the_wall_clock_as_offline(&out.compensated, &[]);

    let out = compensate(
        &aug(0.0001),
        &ctl,
        &named::from_graph(&aug(0.0001)),
        &Options::default(),
    )
    .unwrap();
    assert!(out.report.compensators.is_empty());
    let n = &out.report.not_compensated[0];
    assert!(n.reason.starts_with("no re-tune needed"), "{}", n.reason);
    assert!(n.figures["phase_margin_with_delay_deg"] >= n.figures["target_phase_margin_deg"]);
}
