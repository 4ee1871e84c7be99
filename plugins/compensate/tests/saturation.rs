//! A saturation on the drive: anti-windup. When a core `pid` drives the
//! saturating input, `compensate` gives that pid the fitted limits as its
//! output limits with clamping (no block inserted); any other controller gets a
//! stated "no compensator" with what to do.
//!
//! The loop: an integrator stage y' = u (ZOH at 1 kHz: y[k+1] = y[k] + T·u[k]
//! exactly), a PI (k_p = 50, k_i = 200 /s: ζ = k_p/(2√k_i) = 1.77 on the
//! linear loop), a step of R = 0.5 at t = 0.1 s, the drive limited to ±U = ±1.
//! While the drive is at +U both loops move identically: e[k0 + j] = R − jTU.
//! The clamped PI leaves the limit at the first j₁ with (k_p + k_iT/2)·e < U,
//! its integrator still 0; the scored window starts there. Two invariants then
//! fix the figures without a run (the loop has a double integrator, so the
//! integrator state returns to 0 once settled: Σe over the whole run is 0):
//! - without anti-windup the integrator summed the slew, so over the window
//!   Σe = −S, S = Σ_{j<j₁} (R − jTU) = j₁R − TU·j₁(j₁ − 1)/2 (the overshoot
//!   pays the slew back), hence rms ≥ S/N over the N samples (Cauchy–Schwarz);
//! - with clamping the integrator starts the window at 0, so Σe = 0 there, and
//!   the overdamped loop never exceeds its first error e₀ = R − j₁TU.
//!
//! So the rms cut is at least 1 − e₀/(S/N), computed below.

mod support;

use nanomotion_core::graph::GraphSpec;
use nanomotion_plf::surgery;
use serde_json::Value;

const RATE: f64 = 1000.0;
const T: f64 = 1.0 / RATE;
const R: f64 = 0.5;
const U: f64 = 1.0;
const KP: f64 = 50.0;
const KI: f64 = 200.0;
const DURATION: f64 = 4.0;
/// The step's sample: the step block's time sits half a sample before it.
const K0: usize = 100;

/// Samples of the slew before the clamped PI leaves the limit.
fn j1() -> usize {
    ((R - U / (KP + KI * T / 2.0)) / (T * U)).ceil() as usize
}

fn from_s() -> f64 {
    // Half a sample before the first scored sample K0 + j₁.
    ((K0 + j1()) as f64 - 0.5) / RATE
}

/// The augmented model as `diagnose` writes it: the saturation on the drive.
fn augmented() -> GraphSpec {
    let _ = std::any::type_name::<nanomotion_plf::effects::Effect>();
    GraphSpec::from_yaml(
        &format!("base_rate_hz: {RATE}\nduration_s: 1\nblocks:\n  - {{ name: drive, type: data_column, column: u }}\n  - {{ name: stage, type: state_space, a: [[0.0]], b: [[1.0]], c: [[1.0]], discretisation: zoh }}\n  - {{ name: plf_saturation, type: saturation, lower: {:?}, upper: {U:?} }}\nconnections:\n  - {{ from: drive.y, to: plf_saturation.u }}\n  - {{ from: plf_saturation.y, to: stage.u }}\ncompare:\n  - {{ signal: stage.y, column: y }}\n", -U),
        "model_augmented.yaml",
    )
    .unwrap()
}

/// The user's loop with controller `ctl` (`name, type: …`: a `pid` reads
/// `err.y` on port `e` and drives `stage.u` from `u`, another block from `u`
/// to `y`); with
/// `saturation`, the fitted limits on the drive as well (the plant as
/// diagnosed, built by hand).
fn closed_loop(ctl: &str, saturation: bool) -> GraphSpec {
    closed_loop_through(ctl, saturation, None)
}

/// [`closed_loop`] with, when `amplifier` is `Some(k)`, a `gain` block `amp`
/// of gain k between the controller and the drive.
fn closed_loop_through(ctl: &str, saturation: bool, amplifier: Option<f64>) -> GraphSpec {
    let (name, rest) = ctl.split_once(',').unwrap();
    let name = name.trim();
    let (input, output) = if rest.contains("type: pid") {
        ("e", "u")
    } else {
        ("u", "y")
    };
    let (mut sat, mut source) = (String::new(), format!("{name}.{output}"));
    let mut drive = String::new();
    if let Some(k) = amplifier {
        sat += &format!("  - {{ name: amp, type: gain, k: {k:?} }}\n");
        drive += &format!("  - {{ from: {source}, to: amp.u }}\n");
        source = "amp.y".into();
    }
    if saturation {
        sat += &format!(
            "  - {{ name: sat, type: saturation, lower: {:?}, upper: {U:?} }}\n",
            -U
        );
        drive += &format!("  - {{ from: {source}, to: sat.u }}\n");
        source = "sat.y".into();
    }
    drive += &format!("  - {{ from: {source}, to: stage.u }}\n");
    GraphSpec::from_yaml(
        &format!(
            "base_rate_hz: {RATE}\nduration_s: {DURATION}\nblocks:\n  - {{ name: ref, type: step, time_s: {:?}, initial: 0.0, final: {R:?} }}\n  - {{ name: err, type: sum, signs: \"+-\" }}\n  - {{ name: {name},{rest} }}\n  - {{ name: stage, type: state_space, a: [[0.0]], b: [[1.0]], c: [[1.0]], discretisation: zoh }}\n{sat}connections:\n  - {{ from: ref.y, to: err.in0 }}\n  - {{ from: stage.y, to: err.in1 }}\n  - {{ from: err.y, to: {name}.{input} }}\n{drive}score:\n  - {{ signal: err.y, from_s: {:?} }}\n",
            (K0 as f64 - 0.5) / RATE,
            from_s()
        ),
        "controller.yaml",
    )
    .unwrap()
}

fn pid(limits: bool) -> String {
    let mut s = format!("pid, type: pid, kp: {KP:?}, ki: {KI:?}");
    if limits {
        s += &format!(
            ", output_min: {:?}, output_max: {U:?}, anti_windup: clamping",
            -U
        );
    }
    s
}

/// The scored window of `err.y` of a hand-built loop.
fn window(spec: &GraphSpec) -> Vec<f64> {
    let mut g = surgery::clone_spec(spec).unwrap();
    g.log = vec!["err.y".into()];
    let (mut s, _) = g.build().unwrap();
    s.run(|_| {}).logs[0].data[K0 + j1()..].to_vec()
}

fn rms(x: &[f64]) -> f64 {
    (x.iter().map(|v| v * v).sum::<f64>() / x.len() as f64).sqrt()
}

#[test]
fn a_pid_winding_up_against_the_saturation_gets_the_limits_and_clamping() {
    let aug = augmented();
    let out = support::compensate_augmented(&aug, &closed_loop(&pid(false), false));
    let r = &out.report;
    let c = &r.compensators[0];
    assert_eq!((c.effect.as_str(), c.block.as_str()), ("saturation", "pid"));
    assert_eq!(c.type_name, "pid");
    assert!(
        c.why.starts_with("anti-windup: no block inserted"),
        "{}",
        c.why
    );
    assert_eq!((c.design["output_min"], c.design["output_max"]), (-U, U));
    assert!(c.kept && r.gate.passes, "{r:?}");
    // The written graph on the wall clock, bit for bit as offline.
    support::runs_on_the_wall_clock_as_offline(&out.compensated, &[]);
    // The written graph: the user's pid with the fitted limits and clamping,
    // nothing inserted.
    let g = &out.compensated;
    assert_eq!(g.blocks.len(), 4);
    let p = g.blocks.iter().find(|b| b.name == "pid").unwrap();
    let p = surgery::block_to_json(p.block.as_ref());
    assert_eq!(p["output_min"], -U);
    assert_eq!(p["output_max"], U);
    assert_eq!(p["anti_windup"], Value::from("clamping"));
    assert_eq!((p["kp"].as_f64(), p["ki"].as_f64()), (Some(KP), Some(KI)));

    // Before and after are the hand-built loops on the plant as diagnosed.
    let before = window(&closed_loop(&pid(false), true));
    let after = window(&closed_loop(&pid(true), true));

    windup_invariants(r, &before, &after);
}

/// The report's before and after are the rms of the scored windows `before`
/// and `after` of the hand-built loops, and those obey the invariants of the
/// module docs, from the closed forms.
fn windup_invariants(r: &nanomotion_compensate::Report, before: &[f64], after: &[f64]) {
    let close = |a: f64, b: f64| (a - b).abs() <= 1e-12 * b.abs();
    assert!(
        close(r.before.rms, rms(before)),
        "{} {}",
        r.before.rms,
        rms(before)
    );
    assert!(
        close(r.after.rms, rms(after)),
        "{} {}",
        r.after.rms,
        rms(after)
    );
    let j1 = j1() as f64;
    let s = j1 * R - T * U * j1 * (j1 - 1.0) / 2.0;
    let e0 = R - j1 * T * U;
    let n = before.len() as f64;
    let sum = |x: &[f64]| x.iter().sum::<f64>();
    assert!(
        (sum(before) + s).abs() < 0.01 * s,
        "{} vs −{s}",
        sum(before)
    );
    assert!(sum(after).abs() < 0.01 * s, "{}", sum(after));
    assert!((after[0] - e0).abs() < 1e-12, "{} {e0}", after[0]);
    assert!(r.after.max_abs <= e0 + 1e-12, "{} > {e0}", r.after.max_abs);
    let floor = 0.99 * s / n;
    assert!(r.before.rms >= floor, "{} < {floor}", r.before.rms);
    // Hence the cut: at least 1 − e₀/(S/N) (48 % here).
    let least = 100.0 * (1.0 - e0 / floor);
    assert!(least > 40.0, "{least}");
    assert!(
        r.cut_percent >= least,
        "cut {} % < {least} %",
        r.cut_percent
    );
    assert!(close(
        r.cut_percent,
        100.0 * (1.0 - r.after.rms / r.before.rms)
    ));
    eprintln!(
        "rms {:.4e} -> {:.4e} ({:.1} % cut; at least {least:.1} %: S = {s}, N = {n}, e0 = {e0})",
        r.before.rms, r.after.rms, r.cut_percent
    );
}

#[test]
fn through_a_gain_the_pid_gets_the_limits_divided_by_it() {
    // An amplifier of gain K = −2 between the PI and the limited drive, the
    // PI's gains divided by K: the same loop as above. The PI's limits must
    // be the drive's ±U divided by K, their order swapped (unswapped they
    // would cross), and the windup figures are those of the direct loop.
    const K: f64 = -2.0;
    let ctl = |limits: bool| {
        let mut s = format!("pid, type: pid, kp: {:?}, ki: {:?}", KP / K, KI / K);
        if limits {
            s += &format!(
                ", output_min: {:?}, output_max: {:?}, anti_windup: clamping",
                U / K,
                -U / K
            );
        }
        s
    };
    let aug = augmented();
    let out =
        support::compensate_augmented(&aug, &closed_loop_through(&ctl(false), false, Some(K)));
    let r = &out.report;
    let c = &r.compensators[0];
    assert_eq!((c.effect.as_str(), c.block.as_str()), ("saturation", "pid"));
    assert!(c.place.contains("through the gain `amp`"), "{}", c.place);
    assert_eq!(c.design["gain_between"], K);
    assert_eq!(
        (c.design["output_min"], c.design["output_max"]),
        (U / K, -U / K)
    );
    assert!(c.kept && r.gate.passes, "{r:?}");
    // The written graph on the wall clock, bit for bit as offline.
    support::runs_on_the_wall_clock_as_offline(&out.compensated, &[]);
    let before = window(&closed_loop_through(&ctl(false), true, Some(K)));
    let after = window(&closed_loop_through(&ctl(true), true, Some(K)));
    windup_invariants(r, &before, &after);
}

#[test]
fn a_transfer_function_controller_gets_no_compensator_and_the_fix() {
    // The same PI as a transfer function k_p + k_i/s: it cannot be given limits.
    let aug = augmented();
    let ctl = closed_loop(
        &format!(
            "ctl, type: transfer_function, num: [{KP:?}, {KI:?}], den: [1.0, 0.0], discretisation: tustin"
        ),
        false,
    );
    let out = support::compensate_augmented(&aug, &ctl);
    let r = &out.report;
    assert!(r.compensators.is_empty(), "{r:?}");
    let n = &r.not_compensated[0];
    eprintln!("{}: {}", n.effect, n.reason);
    assert_eq!(n.effect, "saturation");
    for needle in [
        "no compensator",
        "`stage.u` is driven by `ctl`, a `transfer_function` block",
        "core `pid`",
        "output_min: -1.0",
        "output_max: 1.0",
        "anti_windup: clamping",
    ] {
        assert!(n.reason.contains(needle), "{needle:?} not in {}", n.reason);
    }
    // The figures: the fitted limits and how often the loop on the nominal
    // plant asks for more, over the scored window and the whole run, against
    // the command logged independently.
    assert_eq!((n.figures["lower"], n.figures["upper"]), (-U, U));
    let mut g = surgery::clone_spec(&ctl).unwrap();
    g.log = vec!["ctl.y".into()];
    let (mut s, _) = g.build().unwrap();
    let u = s.run(|_| {}).logs[0].data.clone();
    let share = |x: &[f64]| x.iter().filter(|v| v.abs() > U).count() as f64 / x.len() as f64;
    assert_eq!(n.figures["clipped_share"], share(&u[K0 + j1()..]));
    assert_eq!(n.figures["clipped_share_run"], share(&u));
    // The step asks for k_p·R = 25 at once, so the command clips at the move.
    assert!(n.figures["clipped_share_run"] > 0.0);
    assert!(n.reason.contains("of the whole run"), "{}", n.reason);
    // Nothing inserted: the written graph is the user's.
    assert_eq!(out.compensated.blocks.len(), ctl.blocks.len());
    assert_eq!(r.after, r.before);
}

#[test]
fn a_pid_already_limited_within_the_saturation_needs_nothing() {
    let aug = augmented();
    let ctl = closed_loop(
        &format!("pid, type: pid, kp: {KP:?}, ki: {KI:?}, output_min: -0.5, output_max: 0.5"),
        false,
    );
    let out = support::compensate_augmented(&aug, &ctl);
    let n = &out.report.not_compensated[0];
    assert!(
        n.reason
            .starts_with("no compensator needed: `pid` already limits its output"),
        "{}",
        n.reason
    );
    assert!(out.report.compensators.is_empty());
}
