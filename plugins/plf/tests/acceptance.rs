//! Acceptance tests of the discrepancy workflow (issue 12 §5): every vocabulary
//! effect hidden in generated data is named and cuts the held-out rms by at
//! least half; noise alone names nothing; two effects at once are both named.
//!
//! The truth is simulated by `nanomotion_plf::generate`, independently of the
//! effect blocks the workflow fits (see its module docs).

use nanomotion_core::graph::GraphSpec;
use nanomotion_plf::diagnose::{Options, diagnose};
use nanomotion_plf::generate;

fn link() {
    // typetag registers the effect blocks through the linker.
    let _ = std::any::type_name::<nanomotion_plf::effects::Effect>();
}

fn run(effect: &str, seed: u64, n: usize, max_effects: usize) -> nanomotion_plf::Report {
    link();
    let rec = generate::second_order(effect, seed, n, false).unwrap();
    let spec = GraphSpec::from_yaml(&rec.nominal_yaml, "generated.yaml").unwrap();
    let opts = Options {
        max_effects,
        ..Options::default()
    };
    diagnose(&spec, &rec.data, &opts).unwrap_or_else(|e| panic!("{effect} seed {seed}: {e}"))
}

fn check_named(effect: &str, seed: u64) {
    let r = run(effect, seed, 12_000, 2);
    let cut = 1.0 - r.final_scores.holdout_rms / r.nominal.holdout_rms;
    eprintln!(
        "{effect} seed {seed}: found {:?}, held-out rms {:.3e} -> {:.3e} ({:.0} % cut); {}",
        r.found,
        r.nominal.holdout_rms,
        r.final_scores.holdout_rms,
        100.0 * cut,
        r.stopped_because
    );
    for s in &r.steps {
        eprintln!("  step {} at {}: {:?}", s.effect, s.site, s.final_params);
        for c in s.candidates.iter().take(5) {
            eprintln!(
                "    {} {} ({} params): held-out {:.3e}",
                c.effect, c.site, c.n_params, c.holdout_rms
            );
        }
    }
    // Named, and nothing padded after it.
    assert_eq!(
        r.found,
        vec![effect.to_string()],
        "{effect} seed {seed}: found {:?}",
        r.found
    );
    let first_cut = 1.0 - r.steps[0].holdout_rms_after / r.steps[0].holdout_rms_before;
    assert!(
        first_cut >= 0.5,
        "{effect} seed {seed}: the named effect cut the held-out rms by {:.0} %",
        100.0 * first_cut
    );
}

macro_rules! named {
    ($($test:ident: $effect:literal,)*) => {$(
        #[test]
        fn $test() {
            check_named($effect, 1);
        }
    )*};
}

named! {
    hysteresis_is_named: "hysteresis",
    friction_is_named: "friction",
    time_delay_is_named: "time_delay",
    repetitive_disturbance_is_named: "repetitive_disturbance",
    position_dependent_gain_is_named: "position_dependent_gain",
    quantization_is_named: "quantization",
    unmodeled_resonance_is_named: "unmodeled_resonance",
    drift_is_named: "drift",
    creep_is_named: "creep",
    encoder_slit_error_is_named: "encoder_slit_error",
    saturation_is_named: "saturation",
    backlash_is_named: "backlash",
}

#[test]
fn axis_coupling_is_named_on_two_axes() {
    link();
    let rec = generate::two_axis("axis_coupling", 1, 8000).unwrap();
    let spec = GraphSpec::from_yaml(&rec.nominal_yaml, "two_axis.yaml").unwrap();
    let r = diagnose(&spec, &rec.data, &Options::default()).unwrap();
    eprintln!("{}: found {:?}; {}", rec.truth, r.found, r.stopped_because);
    assert_eq!(r.found, vec!["axis_coupling".to_string()]);
    // The coupled axis's own rms is cut by more than half; the clean axis is untouched.
    let s = &r.steps[0];
    assert!(s.per_output[0].holdout_rms < 0.5 * r.nominal.per_output[0].holdout_rms);
    assert_eq!(
        s.per_output[1].holdout_rms,
        r.nominal.per_output[1].holdout_rms
    );
}

#[test]
fn two_hidden_effects_are_both_named_each_cutting_the_gap() {
    for (pair, seed) in [
        ("backlash+drift", 3),
        ("hysteresis+repetitive_disturbance", 4),
        // Both on the output side: the second must stack after the first (the
        // graph and the fit must see the same chain).
        ("drift+repetitive_disturbance", 2),
    ] {
        let r = run(pair, seed, 12_000, 3);
        eprintln!("{pair}: found {:?}; {}", r.found, r.stopped_because);
        let mut want: Vec<&str> = pair.split('+').collect();
        let mut got: Vec<&str> = r.found.iter().map(String::as_str).collect();
        want.sort_unstable();
        got.sort_unstable();
        assert_eq!(got, want, "{pair}");
        for s in &r.steps {
            assert!(
                s.holdout_rms_after < s.holdout_rms_before,
                "{pair}: step {} did not cut",
                s.effect
            );
        }
    }
}

/// Noise alone — white, and white plus a strongly coloured (AR(1), a = 0.98)
/// component — must name nothing: the measured false-alarm rate over 50 seeds
/// is asserted at ≤ 5 % (issue 12 asks for ≥ 95 % `found: []`).
#[test]
fn noise_alone_names_nothing() {
    link();
    let mut alarms = Vec::new();
    for seed in 0..50u64 {
        let coloured = seed % 2 == 1;
        let rec = generate::second_order("none", 100 + seed, 4000, coloured).unwrap();
        let spec = GraphSpec::from_yaml(&rec.nominal_yaml, "generated.yaml").unwrap();
        let r = diagnose(&spec, &rec.data, &Options::default()).unwrap();
        if !r.found.is_empty() {
            alarms.push((seed, coloured, r.found.clone()));
        }
    }
    eprintln!("false alarms: {} of 50: {alarms:?}", alarms.len());
    assert!(
        alarms.len() <= 2,
        "{} false alarms of 50: {alarms:?}",
        alarms.len()
    );
}

/// Issue 24 §1: two effects that both enter on the plant's drive or inside its
/// loop. Before the fix every second input-side or in-loop candidate failed
/// ("the graph has no connection drive.y -> stage.u") and only one was named.
#[test]
fn two_drive_side_effects_are_both_named() {
    for (pair, seed) in [("hysteresis+creep", 5), ("friction+time_delay", 6)] {
        let r = run(pair, seed, 12_000, 3);
        eprintln!("{pair}: found {:?}; {}", r.found, r.stopped_because);
        for s in &r.steps {
            eprintln!(
                "  {} at {}: held-out {:.3e} -> {:.3e}",
                s.effect, s.site, s.holdout_rms_before, s.holdout_rms_after
            );
        }
        for want in pair.split('+') {
            assert!(
                r.found.iter().any(|f| f == want),
                "{pair}: {want} not named; found {:?}",
                r.found
            );
        }
        // The augmented model runs as printed: the gate accepts a fitted effect
        // inside the loop (friction), which has no linear model.
        let aug = nanomotion_plf::surgery::clone_spec(r.augmented.as_ref().unwrap()).unwrap();
        let require = aug.require.clone().unwrap_or_default();
        let rec = generate::second_order(pair, seed, 12_000, false).unwrap();
        let (sched, _) = aug.build_with_data(std::sync::Arc::new(rec.data)).unwrap();
        let gate = nanomotion_core::gate::analyse(&sched, &require);
        assert!(
            gate.passes(),
            "{pair}: the gate refuses the augmented model: {gate:?}"
        );
        // No candidate failed for want of a connection into the plant.
        for s in &r.steps {
            for c in &s.candidates {
                let note = c.note.as_deref().unwrap_or("");
                assert!(
                    !note.contains("has no connection") && !note.contains("has no path"),
                    "{pair}: {} at {}: {}",
                    c.effect,
                    c.site,
                    note
                );
            }
        }
    }
}

/// Issue 24 §6: an effect is named at most once per output, and every step's
/// `final_params` are the parameters of its block in the augmented model.
#[test]
fn found_is_unique_and_final_parameters_are_the_augmented_models() {
    let r = run("hysteresis+repetitive_disturbance", 4, 12_000, 4);
    let mut seen = r.found.clone();
    seen.sort();
    seen.dedup();
    assert_eq!(seen.len(), r.found.len(), "found twice: {:?}", r.found);
    let aug = r.augmented.as_ref().expect("an augmented model");
    for s in &r.steps {
        let b = aug
            .blocks
            .iter()
            .find(|b| b.name == s.block.name)
            .unwrap_or_else(|| panic!("{} is not in the augmented model", s.block.name));
        let t = b.block.tunable().expect("effect blocks are tunable");
        for (name, value) in t.param_names().into_iter().zip(t.params()) {
            assert_eq!(
                s.final_params.get(&name).copied(),
                Some(value),
                "{}.{name}",
                s.block.name
            );
        }
        assert_eq!(s.final_params.len(), s.params.len());
    }
}

/// Audit D1: a stuck sensor (a constant measured column) is bad data, not a
/// quantiser with a perfect fit.
#[test]
fn a_constant_measured_column_is_refused() {
    link();
    let rec = generate::second_order("none", 7, 2000, false).unwrap();
    let spec = GraphSpec::from_yaml(&rec.nominal_yaml, "generated.yaml").unwrap();
    let c = &spec.compare[0].column;
    let cols: Vec<(String, Vec<f64>)> = rec
        .data
        .names()
        .iter()
        .map(|name| {
            let v = rec.data.column(name).unwrap();
            let v = if name == c {
                vec![1.25e-3; v.len()]
            } else {
                v.to_vec()
            };
            (name.clone(), v)
        })
        .collect();
    let data =
        nanomotion_core::data::Dataset::from_columns("stuck.csv", rec.data.rate_hz(), 0.0, cols)
            .unwrap();
    let e = diagnose(&spec, &data, &Options::default()).unwrap_err();
    let msg = e.to_string();
    assert!(
        msg.contains(&format!("`{c}`")) && msg.contains("constant"),
        "{msg}"
    );
    assert!(msg.contains("stuck.csv"), "{msg}");
}

/// Audit D18: finite but huge samples overflow the mean squares; the answer is
/// an error naming the column, not a report with non-finite scores.
#[test]
fn finite_but_huge_samples_are_refused() {
    link();
    let rec = generate::second_order("none", 8, 2000, false).unwrap();
    let spec = GraphSpec::from_yaml(&rec.nominal_yaml, "generated.yaml").unwrap();
    let c = &spec.compare[0].column;
    let cols: Vec<(String, Vec<f64>)> = rec
        .data
        .names()
        .iter()
        .map(|name| {
            let mut v = rec.data.column(name).unwrap().to_vec();
            if name == c {
                v[1500] = 1e300;
            }
            (name.clone(), v)
        })
        .collect();
    let data =
        nanomotion_core::data::Dataset::from_columns("huge.csv", rec.data.rate_hz(), 0.0, cols)
            .unwrap();
    let e = diagnose(&spec, &data, &Options::default()).unwrap_err();
    let msg = e.to_string();
    assert!(
        msg.contains(&format!("`{c}`")) && msg.contains("overflows"),
        "{msg}"
    );
}

/// A stage at 30 Hz behind an amplifier that clips at ±0.6, driven by `u` at
/// 2 kHz, measured with 5 nm of white noise: the record, and the nominal model
/// (no clip), diagnosed with the default options.
fn clipped_drive(u: Vec<f64>) -> nanomotion_plf::Report {
    behind_the_drive(u, "type: saturation, lower: -0.6, upper: 0.6")
}

/// [`clipped_drive`] with any block `truth` (its YAML fields) between the drive
/// and the stage in the record, none in the nominal.
fn behind_the_drive(u: Vec<f64>, truth: &str) -> nanomotion_plf::Report {
    use nanomotion_core::data::Dataset;
    use std::sync::Arc;
    link();
    let (rate, n) = (2000.0, u.len());
    let graph = |clip: bool| {
        let (b, c) = if clip {
            (
                format!("  - {{ name: amp, {truth} }}\n"),
                "  - { from: drive.y, to: amp.u }\n  - { from: amp.y, to: stage.u }\n",
            )
        } else {
            (String::new(), "  - { from: drive.y, to: stage.u }\n")
        };
        format!(
            "base_rate_hz: {rate}\nduration_s: {}\nblocks:\n  - {{ name: drive, type: data_column, column: u }}\n{b}  - {{ name: stage, type: state_space, a: [[0.0, 1.0], [-35530.6, -37.7]], b: [[0.0], [35530.6e-6]], c: [[1.0, 0.0]], discretisation: zoh }}\nconnections:\n{c}compare:\n  - {{ signal: stage.y, column: y }}\n",
            n as f64 / rate
        )
    };
    let drive = Dataset::from_columns("drive", rate, 0.0, vec![("u".into(), u.clone())]).unwrap();
    let mut truth = GraphSpec::from_yaml(&graph(true), "truth.yaml").unwrap();
    truth.log.push("stage.y".into());
    let (mut s, _) = truth.build_with_data(Arc::new(drive)).unwrap();
    let run = s.run(|_| {});
    let mut rng = nanomotion_core::rng::Rng::new(11);
    let y: Vec<f64> = run
        .logs
        .iter()
        .find(|l| l.name == "stage.y")
        .unwrap()
        .data
        .iter()
        .map(|v| v + 5e-9 * rng.normal())
        .collect();
    let data =
        Dataset::from_columns("drive", rate, 0.0, vec![("u".into(), u), ("y".into(), y)]).unwrap();
    let nominal = GraphSpec::from_yaml(&graph(false), "nominal.yaml").unwrap();
    let r = diagnose(&nominal, &data, &Options::default()).unwrap();
    eprintln!("found {:?}; {}", r.found, r.stopped_because);
    for s in &r.steps {
        for c in s.candidates.iter().take(6) {
            eprintln!(
                "    {} {} {:.3e} {:?}",
                c.effect, c.site, c.holdout_rms, c.note
            );
        }
    }
    r
}

/// Whether a step's table refuses a time-periodic candidate with a note
/// containing `why`.
fn refused_as(r: &nanomotion_plf::Report, why: &str) -> bool {
    r.steps.iter().any(|s| {
        s.candidates
            .iter()
            .any(|c| c.note.as_deref().is_some_and(|n| n.contains(why)))
    })
}

/// Issue 24 §3: under a periodic drive, an input nonlinearity leaves a residual
/// periodic in time at the drive's own period. That is an effect of the input,
/// not an external disturbance: a saturating amplifier on a 4 Hz sine drive must
/// not be named `repetitive_disturbance` (the truth is the core `saturation`
/// block, a sharp clip; the plf candidate is a smooth-cornered saturation).
#[test]
fn a_residual_locked_to_a_periodic_drive_is_not_named_a_disturbance() {
    let u: Vec<f64> = (0..12_000)
        .map(|k| (2.0 * std::f64::consts::PI * 4.0 * k as f64 / 2000.0).sin())
        .collect();
    let r = clipped_drive(u);
    assert!(!r.found.is_empty(), "nothing named");
    assert!(
        !r.found.iter().any(|f| f == "repetitive_disturbance"),
        "found {:?}",
        r.found
    );
    assert!(
        refused_as(&r, "locked to the excitation"),
        "no disturbance candidate was refused as phase-locked"
    );
    assert_eq!(r.found[0], "saturation");
}

/// The same with a drive that never repeats — a multisine of eight lines at
/// incommensurate frequencies (3.1–97 Hz, random phases) — yet a clip of it
/// leaves lines at the drive's own frequencies (most at the one nearest the
/// stage's 30 Hz mode, which amplifies it): a residual line that sits at a
/// line of the excitation is what a map of the input leaves there, not a
/// disturbance (the 24 000-sample record of docs/performance.md was named
/// drift + a disturbance at its drive's 64.08 Hz line before this rule).
#[test]
fn a_residual_line_at_a_line_of_a_multisine_drive_is_not_named_a_disturbance() {
    let mut rng = nanomotion_core::rng::Rng::new(5);
    let lines: Vec<(f64, f64)> = [3.1, 7.7, 13.9, 22.3, 28.6, 41.3, 66.1, 97.0]
        .iter()
        .map(|&f| (f, rng.uniform_in(0.0, 2.0 * std::f64::consts::PI)))
        .collect();
    let u: Vec<f64> = (0..12_000)
        .map(|k| {
            let t = k as f64 / 2000.0;
            lines
                .iter()
                .map(|(f, p)| 0.3 * (2.0 * std::f64::consts::PI * f * t + p).sin())
                .sum()
        })
        .collect();
    let r = clipped_drive(u);
    assert!(
        refused_as(&r, "a line of the excitation"),
        "no disturbance candidate was refused at a line of the drive"
    );
    assert_eq!(r.found.first().map(String::as_str), Some("saturation"));
    assert!(
        !r.found.iter().any(|f| f == "repetitive_disturbance"),
        "found {:?}",
        r.found
    );
}

/// Two incommensurate sines at 2 kHz, 6 s: reversals of every size (minor
/// loops inside major ones).
fn two_sines() -> Vec<f64> {
    (0..12_000)
        .map(|k| {
            let t = k as f64 / 2000.0;
            0.7 * (2.0 * std::f64::consts::PI * 1.3 * t).sin()
                + 0.4 * (2.0 * std::f64::consts::PI * 4.1 * t + 0.5).sin()
        })
        .collect()
}

/// A loop of any shape a sum of plays makes: a Prandtl–Ishlinskii truth whose
/// branches steepen as the wider plays join (slopes 0.5, 0.7, 1.0, 1.4 — a
/// shape neither Coleman–Hodgdon's nor Bouc–Wen's loop has), under a drive of
/// two incommensurate sines, so its reversals come in every size (minor
/// loops inside major ones). It is hysteresis on the drive, and it is named
/// so, in that form, cutting the held-out rms by at least half (the
/// Coleman–Hodgdon and Bouc–Wen fits leave twice the Prandtl–Ishlinskii
/// fit's held-out rms: 2.2·10⁻⁸ and 2.9·10⁻⁸ against 1.0·10⁻⁸ m).
#[test]
fn a_loop_of_plays_on_the_drive_is_named_hysteresis() {
    let u = two_sines();
    let r = behind_the_drive(
        u,
        "type: prandtl_ishlinskii, linear: 0.5, plays: [{ radius: 0.05, weight: 0.2 }, { radius: 0.15, weight: 0.3 }, { radius: 0.35, weight: 0.4 }]",
    );
    assert_eq!(
        r.found.first().map(String::as_str),
        Some("hysteresis"),
        "{}",
        r.stopped_because
    );
    let s = &r.steps[0];
    let cut = 1.0 - s.holdout_rms_after / s.holdout_rms_before;
    eprintln!("named with {:?}: {:.0} % cut", s.block, 100.0 * cut);
    assert!(cut >= 0.5, "cut {:.0} %", 100.0 * cut);
    assert_eq!(s.block.type_name, "prandtl_ishlinskii");
}

/// A gear's play is not a material's loop: a backlash on the drive (a dead
/// band after every reversal) is named `backlash` although a sum of plays
/// fits it too; the Prandtl–Ishlinskii fit, whose branches start flat (a
/// dead band), is refused as hysteresis (before this rule, 2 of 4 backlash records of the
/// blind set 4888–5002 were named hysteresis).
#[test]
fn a_dead_band_after_each_reversal_is_backlash_not_hysteresis() {
    let u = two_sines();
    let r = behind_the_drive(u, "type: backlash, width: 0.2");
    assert_eq!(
        r.found.first().map(String::as_str),
        Some("backlash"),
        "{}",
        r.stopped_because
    );
    assert!(
        refused_as(&r, "dead band"),
        "the sum of plays was not refused as a dead band"
    );
}
