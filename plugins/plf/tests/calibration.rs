//! The nominal calibration and the noise floor on records whose nominal is
//! off in ways a real identified model is: a second mode's frequency, damping
//! and gain off by themselves, and a measurement quantised so coarsely that the stage holds its
//! level most samples.

use nanomotion_core::data::Dataset;
use nanomotion_core::graph::GraphSpec;
use nanomotion_core::rng::Rng;
use nanomotion_plf::diagnose::{Options, diagnose};
use std::f64::consts::PI;
use std::sync::Arc;

const RATE: f64 = 2000.0;

/// A stage with two modes (15 Hz, ζ = 0.05 and a second mode at `f2` Hz,
/// ζ = 0.02, a third of the first's static gain) in modal form, driven
/// open loop from the column `u`.
fn two_mode_graph(f2: f64, n: usize) -> String {
    second_mode_graph(f2, 0.02, 1.0 / 3.0, n)
}

/// [`two_mode_graph`] with the second mode's damping ratio `z2` and its share
/// `g2` of the first mode's static gain.
fn second_mode_graph(f2: f64, z2: f64, g2: f64, n: usize) -> String {
    let (w1, w2) = (2.0 * PI * 15.0, 2.0 * PI * f2);
    let z1 = 0.05;
    format!(
        "base_rate_hz: {RATE}\nduration_s: {}\nblocks:\n  - {{ name: drive, type: data_column, column: u }}\n  - {{ name: stage, type: state_space, a: [[0.0, 1.0, 0.0, 0.0], [{:?}, {:?}, 0.0, 0.0], [0.0, 0.0, 0.0, 1.0], [0.0, 0.0, {:?}, {:?}]], b: [[0.0], [1.0], [0.0], [1.0]], c: [[{:?}, 0.0, {:?}, 0.0]], discretisation: zoh }}\nconnections:\n  - {{ from: drive.y, to: stage.u }}\ncompare:\n  - {{ signal: stage.y, column: y }}\n",
        n as f64 / RATE,
        -w1 * w1,
        -2.0 * z1 * w1,
        -w2 * w2,
        -2.0 * z2 * w2,
        w1 * w1,
        w2 * w2 * g2,
    )
}

/// The position `graph` gives for the drive `u` (logged `stage.y`).
fn simulate(graph: &str, u: &[f64]) -> Vec<f64> {
    let drive = Dataset::from_columns("drive", RATE, 0.0, vec![("u".into(), u.to_vec())]).unwrap();
    let mut spec = GraphSpec::from_yaml(graph, "truth.yaml").unwrap();
    spec.log.push("stage.y".into());
    let (mut s, _) = spec.build_with_data(Arc::new(drive)).unwrap();
    let run = s.run(|_| {});
    run.logs
        .iter()
        .find(|l| l.name == "stage.y")
        .unwrap()
        .data
        .clone()
}

/// A multisine of 30 tones between 1 and 200 Hz, peak about 1.
fn multisine(rng: &mut Rng, n: usize) -> Vec<f64> {
    let tones: Vec<(f64, f64)> = (0..30)
        .map(|_| (rng.uniform_in(1.0, 200.0), rng.uniform_in(0.0, 2.0 * PI)))
        .collect();
    (0..n)
        .map(|k| {
            let t = k as f64 / RATE;
            tones
                .iter()
                .map(|(f, p)| (2.0 * PI * f * t + p).sin())
                .sum::<f64>()
                / 8.0
        })
        .collect()
}

/// A record of `truth` driven by a multisine (seeded `seed`), its position
/// measured with white noise of 0.2 % of its rms: columns `u` and `y`.
fn measured(truth: &str, n: usize, seed: u64) -> Dataset {
    let mut rng = Rng::new(seed);
    let u = multisine(&mut rng, n);
    let y_true = simulate(truth, &u);
    let rms = (y_true.iter().map(|v| v * v).sum::<f64>() / n as f64).sqrt();
    let y: Vec<f64> = y_true
        .iter()
        .map(|v| v + 2e-3 * rms * rng.normal())
        .collect();
    Dataset::from_columns("truth", RATE, 0.0, vec![("u".into(), u), ("y".into(), y)]).unwrap()
}

#[test]
fn a_second_mode_off_by_itself_is_calibrated_not_named() {
    // The truth's second mode is 8 % above the nominal's (70 → 75.6 Hz): a
    // nominal error a global time scale cannot reach (it moves both modes).
    // The calibration's frequency scale of the second pair must find it, and
    // nothing be named.
    let n = 8000;
    let data = measured(&two_mode_graph(70.0 * 1.08, n), n, 5);
    let nominal = GraphSpec::from_yaml(&two_mode_graph(70.0, n), "nominal.yaml").unwrap();
    let rep = diagnose(&nominal, &data, &Options::default()).unwrap();
    let cal = rep.calibration.as_ref().expect("a calibration was tried");
    eprintln!(
        "two modes: found {:?}; calibration {:?}; held-out rms {:.3e} -> {:.3e}; {}",
        rep.found,
        cal.params,
        rep.nominal.holdout_rms,
        rep.final_scores.holdout_rms,
        rep.stopped_because
    );
    assert!(rep.found.is_empty(), "named {:?}", rep.found);
    assert!(cal.accepted, "{cal:?}");
    // Both modes in place: the first's frequency through the time scale, the
    // second's through its own scale (relative to the time scale).
    let lambda = cal.params["stage.frequency_scale"];
    let second = lambda * cal.params["stage.mode_2_frequency_scale"];
    assert!((lambda - 1.0).abs() < 0.005, "time scale {lambda}");
    assert!((second - 1.08).abs() < 0.01, "second mode × {second}");
    // The gap closes to the noise: at least 90 % of the held-out rms removed.
    assert!(
        rep.final_scores.holdout_rms < 0.1 * rep.nominal.holdout_rms,
        "{:.3e} -> {:.3e}",
        rep.nominal.holdout_rms,
        rep.final_scores.holdout_rms
    );
}

#[test]
fn a_second_mode_with_its_own_damping_and_gain_off_is_calibrated_not_named() {
    // The second mode's frequency (+6 %), damping ratio (× 1.4) and share of
    // the static gain (× 0.8) are off by themselves, the first mode exact:
    // the damping of two modes comes from different dissipation and their
    // residues from the mode shapes, so a real identified model errs so. One
    // damping scale for both modes leaves the second's error, which a
    // resonance was then named for (two-mode records of the scenario set,
    // blind 5184 and 5224). The second pair's own damping and gain scales
    // must take it, and nothing be named.
    let n = 8000;
    let truth = second_mode_graph(70.0 * 1.06, 0.02 * 1.4, 0.8 / 3.0, n);
    let data = measured(&truth, n, 6);
    let nominal = GraphSpec::from_yaml(&two_mode_graph(70.0, n), "nominal.yaml").unwrap();
    let rep = diagnose(&nominal, &data, &Options::default()).unwrap();
    let cal = rep.calibration.as_ref().expect("a calibration was tried");
    eprintln!(
        "second mode off: found {:?}; calibration {:?}; held-out rms {:.3e} -> {:.3e}",
        rep.found, cal.params, rep.nominal.holdout_rms, rep.final_scores.holdout_rms,
    );
    assert!(rep.found.is_empty(), "named {:?}", rep.found);
    assert!(cal.accepted, "{cal:?}");
    let p = |k: &str| cal.params.get(k).copied().unwrap_or(1.0);
    // The first mode is left where it is; the second's scales are relative
    // to the model's (time scale λ, damping scale d, gain g).
    let (lambda, d, g) = (
        p("stage.frequency_scale"),
        p("stage.damping_scale"),
        p("stage.gain"),
    );
    assert!((lambda - 1.0).abs() < 0.005, "time scale {lambda}");
    assert!((d - 1.0).abs() < 0.05, "damping scale {d}");
    assert!((g - 1.0).abs() < 0.01, "gain {g}");
    let second = lambda * p("stage.mode_2_frequency_scale");
    let second_damping = d * p("stage.mode_2_damping_scale");
    let second_gain = g * p("stage.mode_2_gain_scale");
    assert!((second - 1.06).abs() < 0.005, "second mode × {second}");
    assert!(
        (second_damping - 1.4).abs() < 0.1,
        "second damping × {second_damping}"
    );
    assert!(
        (second_gain - 0.8).abs() < 0.02,
        "second gain × {second_gain}"
    );
    assert!(
        rep.final_scores.holdout_rms < 0.1 * rep.nominal.holdout_rms,
        "{:.3e} -> {:.3e}",
        rep.nominal.holdout_rms,
        rep.final_scores.holdout_rms
    );
}

#[test]
fn a_coarsely_quantised_slow_record_has_its_rounding_noise_as_floor() {
    // A 2 Hz lag driven by a 0.3 Hz sine, measured on a grid of 1/40 of the
    // stroke: the reading holds its level for tens of samples, so the
    // residual's sample-to-sample differences are mostly zero and say nothing
    // of the rounding error q/√12 (Widrow) every model without the encoder
    // must leave. The floor reported (and used for the weights and the stop
    // rule) must be that rounding noise, not a near-zero spread.
    let n = 6000;
    let graph = format!(
        "base_rate_hz: {RATE}\nduration_s: {}\nblocks:\n  - {{ name: drive, type: data_column, column: u }}\n  - {{ name: stage, type: state_space, a: [[{:?}]], b: [[{:?}]], c: [[1.0]], discretisation: zoh }}\nconnections:\n  - {{ from: drive.y, to: stage.u }}\ncompare:\n  - {{ signal: stage.y, column: y }}\n",
        n as f64 / RATE,
        -2.0 * PI * 2.0,
        2.0 * PI * 2.0,
    );
    let u: Vec<f64> = (0..n)
        .map(|k| (2.0 * PI * 0.3 * k as f64 / RATE).sin())
        .collect();
    let q = 2.0 / 40.0;
    let y: Vec<f64> = simulate(&graph, &u)
        .iter()
        .map(|v| (v / q).round() * q)
        .collect();
    let held = y.windows(2).filter(|w| w[0] == w[1]).count();
    assert!(
        held > n * 9 / 10,
        "the reading must hold its level: {held} of {n}"
    );
    let data =
        Dataset::from_columns("slow", RATE, 0.0, vec![("u".into(), u), ("y".into(), y)]).unwrap();
    let nominal = GraphSpec::from_yaml(&graph, "nominal.yaml").unwrap();
    let rep = diagnose(&nominal, &data, &Options::default()).unwrap();
    let floor = rep.nominal_tests[0].noise_floor;
    let rounding = q / 12f64.sqrt();
    eprintln!(
        "quantised: floor {floor:.4e}, q/√12 {rounding:.4e}, residual rms {:.4e}, found {:?}",
        rep.nominal_tests[0].rms, rep.found
    );
    assert!(
        (floor / rounding - 1.0).abs() < 0.05,
        "floor {floor:.4e} vs q/√12 = {rounding:.4e}"
    );
    // The nominal is exact: its residual is the rounding error itself.
    assert!((rep.nominal_tests[0].rms / rounding - 1.0).abs() < 0.1);
}

/// A stage (15 Hz, ζ = 0.05) behind an amplifier lag at `lag_hz`, in one
/// `state_space` (states: position, velocity, amplifier output), gain `g`.
fn lag_stage_graph(lag_hz: f64, g: f64, n: usize) -> String {
    let (w, p) = (2.0 * PI * 15.0, 2.0 * PI * lag_hz);
    format!(
        "base_rate_hz: {RATE}\nduration_s: {}\nblocks:\n  - {{ name: drive, type: data_column, column: u }}\n  - {{ name: stage, type: state_space, a: [[0.0, 1.0, 0.0], [{:?}, {:?}, {:?}], [0.0, 0.0, {:?}]], b: [[0.0], [0.0], [{:?}]], c: [[1.0, 0.0, 0.0]], discretisation: zoh }}\nconnections:\n  - {{ from: drive.y, to: stage.u }}\ncompare:\n  - {{ signal: stage.y, column: y }}\n",
        n as f64 / RATE,
        -w * w,
        -2.0 * 0.05 * w,
        w * w,
        -p,
        g * p,
    )
}

#[test]
fn a_scale_the_data_do_not_determine_is_held_at_the_nominal() {
    // The stage is behind an amplifier lag at 50 kHz — 25× the sample rate,
    // invisible in the record — and the nominal's gain is 5 % low. The lag
    // scale is not determined by the data (left free it wanders and absorbs
    // whatever else is wrong), so it is held at the nominal and reported as
    // held; the gain is calibrated, and nothing is named.
    let n = 8000;
    let data = measured(&lag_stage_graph(50_000.0, 1.05, n), n, 11);
    let nominal = GraphSpec::from_yaml(&lag_stage_graph(50_000.0, 1.0, n), "nominal.yaml").unwrap();
    let rep = diagnose(&nominal, &data, &Options::default()).unwrap();
    let cal = rep.calibration.as_ref().expect("a calibration was tried");
    eprintln!(
        "lag stage: found {:?}; calibration {:?}, held {:?}",
        rep.found, cal.params, cal.held
    );
    assert!(cal.held.contains_key("stage.lag_scale"), "{cal:?}");
    assert!(!cal.params.contains_key("stage.lag_scale"), "{cal:?}");
    for (name, v) in &cal.params {
        let s = cal.uncertainty[name];
        assert!(s < v.abs(), "{name} = {v} ± {s} is determined");
    }
    assert!(cal.accepted, "{cal:?}");
    let g = cal.params["stage.gain"];
    assert!((g - 1.05).abs() < 0.005, "gain × {g}");
    assert!(rep.found.is_empty(), "named {:?}", rep.found);
}

/// A stage (15 Hz, ζ = 0.05) whose spring is `stiffness` × the nominal's and
/// whose drive gain is `g`, open loop (states: position, velocity).
fn spring_stage_graph(stiffness: f64, g: f64, n: usize) -> String {
    let w = 2.0 * PI * 15.0;
    format!(
        "base_rate_hz: {RATE}\nduration_s: {}\nblocks:\n  - {{ name: drive, type: data_column, column: u }}\n  - {{ name: stage, type: state_space, a: [[0.0, 1.0], [{:?}, {:?}]], b: [[0.0], [{:?}]], c: [[1.0, 0.0]], discretisation: zoh }}\nconnections:\n  - {{ from: drive.y, to: stage.u }}\ncompare:\n  - {{ signal: stage.y, column: y }}\n",
        n as f64 / RATE,
        -stiffness * w * w,
        -2.0 * 0.05 * w,
        g * w * w,
    )
}

/// [`spring_stage_graph`] at the nominal's spring with a force `k`·y added to
/// the stage's input from its own position, sampled as the graph samples it:
/// a spring (1 − k) × the nominal's in the form a force of the position takes
/// in a `diagnose` model.
fn sampled_spring_graph(k: f64, n: usize) -> String {
    spring_stage_graph(1.0, 1.0, n)
        .replace(
            "connections:\n  - { from: drive.y, to: stage.u }",
            &format!(
                "  - {{ name: spring, type: gain, k: {k:?} }}\n  - {{ name: force, type: sum, signs: \"++\" }}\nconnections:\n  - {{ from: drive.y, to: force.in0 }}\n  - {{ from: stage.y, to: spring.u }}\n  - {{ from: spring.y, to: force.in1 }}\n  - {{ from: force.y, to: stage.u }}"
            ),
        )
}

#[test]
fn a_linear_error_is_not_named_hysteresis_a_position_dependent_gain_or_a_resonance() {
    // With the calibration off (so that only effects can explain it):
    // - a spring 10 % stiff, as a force of the position sampled as a
    //   `diagnose` model samples it, is fitted exactly by a Coleman–Hodgdon or
    //   Bouc–Wen force of the position with no loop (a stiffness): the loop
    //   must explain what the stiffness alone leaves, and here it leaves noise;
    // - the same spring in the continuous plant is fitted by a pole–zero
    //   pair that cancels the nominal's 15 Hz mode and puts one at
    //   15·√1.1 = 15.73 Hz: a mode the nominal has, moved (a Bouc–Wen force
    //   of the position is still named there: it takes the sampled force's
    //   phase error, a leftover proportional to the velocity — docs/plf.md,
    //   Limits);
    // - a drive gain 5 % high is what a position-dependent gain with g₀ alone
    //   fits: its variation must explain what the constant leaves.
    let n = 8000;
    let opts = Options {
        calibrate: false,
        max_effects: 1,
        ..Options::default()
    };
    // (record, its truth, the name it must not get, the refusal that says why)
    let cases = [
        (
            "sampled spring",
            sampled_spring_graph(-0.1, n),
            "hysteresis",
            "explains little beyond its linear part",
        ),
        (
            "spring",
            spring_stage_graph(1.1, 1.0, n),
            "unmodeled_resonance",
            "cancels the nominal's mode at 1.5000e1 Hz",
        ),
        (
            "gain",
            spring_stage_graph(1.0, 1.05, n),
            "position_dependent_gain",
            "explains little beyond a constant gain",
        ),
    ];
    for (what, truth, wrong, refusal) in cases {
        let data = measured(&truth, n, 17);
        let nominal =
            GraphSpec::from_yaml(&spring_stage_graph(1.0, 1.0, n), "nominal.yaml").unwrap();
        let rep = diagnose(&nominal, &data, &opts).unwrap();
        let notes: Vec<&str> = rep
            .steps
            .iter()
            .flat_map(|s| &s.candidates)
            .chain(&rep.rejected_candidates)
            .filter_map(|c| c.note.as_deref())
            .collect();
        eprintln!("{what}: found {:?}; {notes:#?}", rep.found);
        assert!(
            !rep.found.iter().any(|e| e == wrong),
            "{what}: named {:?}",
            rep.found
        );
        assert!(
            notes.iter().any(|n| n.contains(refusal)),
            "{what}: no fit was refused so: {refusal}"
        );
    }
}

#[test]
fn with_no_effect_asked_for_the_calibration_alone_is_fitted_and_judged() {
    // `max_effects: 0`: the nominal calibration alone. A gain 5 % off is
    // calibrated (× 1.05 found) and kept; an exact nominal's calibration
    // explains nothing significant and is not kept; nothing is ever named.
    let n = 8000;
    let opts = Options {
        max_effects: 0,
        ..Options::default()
    };
    let nominal = GraphSpec::from_yaml(&lag_stage_graph(50.0, 1.0, n), "nominal.yaml").unwrap();
    let off = measured(&lag_stage_graph(50.0, 1.05, n), n, 11);
    let rep = diagnose(&nominal, &off, &opts).unwrap();
    let cal = rep.calibration.as_ref().expect("a calibration was fitted");
    eprintln!("gain off: {cal:?}; {}", rep.stopped_because);
    assert!(cal.accepted, "{cal:?}");
    assert!((cal.params["stage.gain"] - 1.05).abs() < 0.005, "{cal:?}");
    assert!(rep.found.is_empty() && rep.steps.is_empty());
    assert!(
        rep.final_scores.holdout_rms < 0.2 * rep.nominal.holdout_rms,
        "{:.3e} -> {:.3e}",
        rep.nominal.holdout_rms,
        rep.final_scores.holdout_rms
    );
    let exact = measured(&lag_stage_graph(50.0, 1.0, n), n, 12);
    let rep = diagnose(&nominal, &exact, &opts).unwrap();
    let cal = rep.calibration.as_ref().expect("a calibration was fitted");
    eprintln!("exact: {cal:?}; {}", rep.stopped_because);
    assert!(!cal.accepted, "{cal:?}");
    assert_eq!(rep.final_scores, rep.nominal);
    assert!(rep.found.is_empty() && rep.steps.is_empty());
}

#[test]
fn a_limit_reached_only_before_the_held_out_part_is_pointed_out_not_named() {
    // The drive is large over the first 40 % of the record and reaches the
    // amplifier's limit there (±1); afterwards it stays well inside. The
    // held-out part (the last 30 %) never shows the limit, so no name can be
    // confirmed for it: nothing is named, and a note says where the misfit is.
    let n = 8000;
    let nominal_yaml = lag_stage_graph(50.0, 1.0, n);
    let truth = nominal_yaml
        .replace(
            "  - { name: stage,",
            "  - { name: amp, type: saturation, lower: -1.0, upper: 1.0 }\n  - { name: stage,",
        )
        .replace(
            "{ from: drive.y, to: stage.u }",
            "{ from: drive.y, to: amp.u }\n  - { from: amp.y, to: stage.u }",
        );
    let mut rng = Rng::new(21);
    let u: Vec<f64> = multisine(&mut rng, n)
        .iter()
        .enumerate()
        .map(|(k, v)| if k < 2 * n / 5 { 3.0 * v } else { 0.4 * v })
        .collect();
    let y_true = simulate(&truth, &u);
    let rms = (y_true.iter().map(|v| v * v).sum::<f64>() / n as f64).sqrt();
    let y: Vec<f64> = y_true
        .iter()
        .map(|v| v + 2e-3 * rms * rng.normal())
        .collect();
    let data =
        Dataset::from_columns("truth", RATE, 0.0, vec![("u".into(), u), ("y".into(), y)]).unwrap();
    let nominal = GraphSpec::from_yaml(&nominal_yaml, "nominal.yaml").unwrap();
    let rep = diagnose(&nominal, &data, &Options::default()).unwrap();
    eprintln!(
        "early limit: found {:?}; {}; notes {:?}",
        rep.found, rep.stopped_because, rep.excitation_notes
    );
    assert!(rep.found.is_empty(), "named {:?}", rep.found);
    assert!(
        rep.excitation_notes
            .iter()
            .any(|n| n.contains("`stage.y`") && n.contains("before the held-out part")),
        "{:?}",
        rep.excitation_notes
    );
    // The control: the same stage without the limit, the nominal exact — no note.
    let rep = diagnose(
        &nominal,
        &measured(&nominal_yaml, n, 22),
        &Options::default(),
    )
    .unwrap();
    assert!(
        !rep.excitation_notes
            .iter()
            .any(|n| n.contains("before the held-out part")),
        "{:?}",
        rep.excitation_notes
    );
}
