//! Closed-loop data: the sensor effect acts where the controller sees it.
//!
//! A PID position loop around a second-order stage (30 Hz, ζ = 0.05) at 2 kHz,
//! driven by a recorded reference; the truth measures the position through one
//! extra sample of delay *inside the loop* (the controller acts on the late
//! reading, which costs phase margin: the gate's delay margin of the nominal
//! loop is 2 samples). The nominal model has no delay. An effect tried only on
//! the comparison can shift the output in time but cannot reproduce the less
//! damped closed loop; the workflow must place the delay in the sensor path
//! inside the loop, and that place must predict the held-out data better than
//! the output side. (The truth's delay is the core `delay` block, an integer
//! ring buffer; the candidate is the plf `time_delay` block, a fractional delay
//! fitted from 0.5–20 samples.)

use nanomotion_core::data::Dataset;
use nanomotion_core::graph::GraphSpec;
use nanomotion_core::rng::Rng;
use nanomotion_plf::diagnose::{Options, diagnose};
use std::f64::consts::PI;
use std::sync::Arc;

const RATE: f64 = 2000.0;
const N: usize = 12_000;

fn graph(sensor_delay: bool) -> String {
    let (sensor_block, feedback) = if sensor_delay {
        (
            "  - { name: sensor, type: delay, d: 1 }\n",
            "  - { from: stage.y, to: sensor.u }\n  - { from: sensor.y, to: err.in1 }\n",
        )
    } else {
        ("", "  - { from: stage.y, to: err.in1 }\n")
    };
    let measured = if sensor_delay { "sensor.y" } else { "stage.y" };
    format!(
        "base_rate_hz: {RATE}\nduration_s: {}\nblocks:\n  - {{ name: ref, type: data_column, column: r }}\n  - {{ name: err, type: sum, signs: \"+-\" }}\n  - {{ name: ctrl, type: pid, kp: 2.0e5, ki: 2.0e6, kd: 600.0, derivative_cutoff_hz: 400.0 }}\n  - {{ name: stage, type: state_space, a: [[0.0, 1.0], [-35530.6, -18.85]], b: [[0.0], [1.0]], c: [[1.0, 0.0]], discretisation: zoh }}\n{sensor_block}connections:\n  - {{ from: ref.y, to: err.in0 }}\n{feedback}  - {{ from: err.y, to: ctrl.e }}\n  - {{ from: ctrl.u, to: stage.u }}\ncompare:\n  - {{ signal: {measured}, column: \"y\" }}\n",
        N as f64 / RATE
    )
}

/// The record of the loop `truth_yaml` under reference `r`: the reference
/// and the signal `measured` with white noise of 1 nm.
fn record(truth_yaml: &str, measured: &str, r: Vec<f64>, rng: &mut Rng) -> Dataset {
    let drive = Dataset::from_columns("loop", RATE, 0.0, vec![("r".into(), r.clone())]).unwrap();
    let mut truth = GraphSpec::from_yaml(truth_yaml, "truth.yaml").unwrap();
    truth.log.push(measured.into());
    let (mut s, _) = truth.build_with_data(Arc::new(drive)).unwrap();
    let run = s.run(|_| {});
    let y: Vec<f64> = run
        .logs
        .iter()
        .find(|l| l.name == measured)
        .unwrap()
        .data
        .iter()
        .map(|v| v + 1e-9 * rng.normal())
        .collect();
    Dataset::from_columns("loop", RATE, 0.0, vec![("r".into(), r), ("y".into(), y)]).unwrap()
}

#[test]
fn a_delay_in_the_sensor_path_is_placed_inside_the_loop() {
    let _ = std::any::type_name::<nanomotion_plf::effects::Effect>();
    let mut rng = Rng::new(17);
    // Reference: slow strokes plus steps of a point-to-point move and a multisine
    // to 200 Hz (µm scale).
    let tones: Vec<(f64, f64)> = (0..25)
        .map(|_| (rng.uniform_in(2.0, 200.0), rng.uniform_in(0.0, 2.0 * PI)))
        .collect();
    let r: Vec<f64> = (0..N)
        .map(|k| {
            let t = k as f64 / RATE;
            let steps = if (t * 1.5).floor() as i64 % 2 == 0 {
                0.5e-6
            } else {
                -0.5e-6
            };
            let ms: f64 = tones
                .iter()
                .map(|(f, p)| (2.0 * PI * f * t + p).sin())
                .sum();
            1e-6 * (2.0 * PI * 0.4 * t).sin() + steps + 0.05e-6 * ms / 5.0
        })
        .collect();
    let data = record(&graph(true), "sensor.y", r, &mut rng);
    let nominal = GraphSpec::from_yaml(&graph(false), "nominal.yaml").unwrap();
    let rep = diagnose(&nominal, &data, &Options::default()).unwrap();
    eprintln!(
        "closed loop: found {:?}; held-out rms {:.3e} -> {:.3e} m; {}",
        rep.found, rep.nominal.holdout_rms, rep.final_scores.holdout_rms, rep.stopped_because
    );
    let step = &rep.steps[0];
    for c in step.candidates.iter().take(6) {
        eprintln!("    {} {} {:.3e}", c.effect, c.site, c.holdout_rms);
    }
    assert_eq!(rep.found, vec!["time_delay".to_string()]);
    assert!(
        step.site.contains("sensor path inside the loop"),
        "{}",
        step.site
    );
    assert!(step.holdout_rms_after < 0.5 * step.holdout_rms_before);
    // The same effect on the comparison alone predicts worse.
    let output_side = step
        .candidates
        .iter()
        .find(|c| c.effect == "time_delay" && c.site.starts_with("output side"))
        .expect("the output-side delay was tried");
    assert!(
        output_side.holdout_rms > 2.0 * step.holdout_rms_after,
        "output side {:.3e} vs in the loop {:.3e}",
        output_side.holdout_rms,
        step.holdout_rms_after
    );
    // Issue 24 §6: the augmented model runs as printed (`nanomotion run`): the
    // stability gate accepts it (the fitted `time_delay` is analysed exactly,
    // issue 25).
    let aug =
        nanomotion_plf::surgery::clone_spec(rep.augmented.as_ref().expect("an augmented model"))
            .unwrap();
    let require = aug.require.clone().unwrap_or_default();
    let (sched, _) = aug.build_with_data(Arc::new(data.clone())).unwrap();
    let gate = nanomotion_core::gate::analyse(&sched, &require);
    assert!(
        gate.passes() && gate.proven(),
        "the gate refuses the augmented model or cannot prove it: {gate}"
    );
    // The fitted delay is the truth's one sample.
    let d = step.params["delay_s"] * RATE;
    assert!((d - 1.0).abs() < 0.05, "fitted delay {d} samples");
}

/// With the controller's output compared too (the drive of the position's
/// plant), the controller is not a plant: what enters it is computed inside
/// the digital controller, where no actuator, friction or creep acts. Input-
/// side effects are offered on the drive into the stage only, once.
#[test]
fn the_compared_drive_of_a_plant_is_not_itself_a_plant() {
    let _ = std::any::type_name::<nanomotion_plf::effects::Effect>();
    let yaml = graph(false).replace(
        "compare:\n  - { signal: stage.y, column: \"y\" }\n",
        "compare:\n  - { signal: stage.y, column: \"y\" }\n  - { signal: ctrl.u, column: \"u\" }\n",
    );
    let spec = GraphSpec::from_yaml(&yaml, "loop.yaml").unwrap();
    let zeros = vec![0.0; N];
    let data = Dataset::from_columns(
        "loop",
        RATE,
        0.0,
        vec![
            ("r".into(), zeros.clone()),
            ("y".into(), zeros.clone()),
            ("u".into(), zeros),
        ],
    )
    .unwrap();
    let channels = nanomotion_plf::surgery::channels(&spec, &Arc::new(data)).unwrap();
    assert_eq!(channels.len(), 2);
    assert_eq!(
        channels[0].plant_inputs,
        vec![("ctrl.u".to_string(), "stage.u".to_string())]
    );
    assert!(
        channels[1].plant_inputs.is_empty(),
        "{:?}",
        channels[1].plant_inputs
    );
    // The drive is no measurement either (no sensor-path sites on it); the
    // position is.
    assert!(channels[1].drive && !channels[0].drive);
    // Both outputs measure one axis (one SISO loop).
    assert!(channels[0].same_axis(&channels[1]));
}

/// A force periodic in the stage's position (a cogging force of pitch
/// 0.13 µm on the PID loop's stage, under a random move of ±1 µm): the loop
/// answers it, so the position shows it filtered by the closed loop. The
/// truth's force is the plf `repetitive_disturbance` block read from the
/// position; the diagnosis must name it, at its pitch and amplitude — as a
/// fundamental or as a harmonic of a multiple of the pitch (the same
/// function of the position). Its pitch is looked for through the model's
/// own response to a force at each pitch (`force_pitch` in diagnose.rs) and
/// in the residual binned against the position; on this record either finds
/// it (the scenarios where only the first does: `tuning_records.rs`).
#[test]
fn a_force_periodic_in_position_is_found_through_the_loops_response() {
    let _ = std::any::type_name::<nanomotion_plf::effects::Effect>();
    let mut rng = Rng::new(29);
    let (pitch, amp) = (0.13e-6, 4.0e-3);
    // A random move: 20 tones from 0.5 to 20 Hz at random phases (±1 µm).
    let tones: Vec<(f64, f64)> = (0..20)
        .map(|_| (rng.uniform_in(0.5, 20.0), rng.uniform_in(0.0, 2.0 * PI)))
        .collect();
    let r: Vec<f64> = (0..N)
        .map(|k| {
            let t = k as f64 / RATE;
            0.25e-6
                * tones
                    .iter()
                    .map(|(f, p)| (2.0 * PI * f * t + p).sin())
                    .sum::<f64>()
        })
        .collect();
    let truth_yaml = graph(false)
        .replace(
            "connections:\n",
            &format!(
                "  - {{ name: cogging, type: repetitive_disturbance, period: {pitch}, variable: signal, cos: [0.0], sin: [{amp}] }}\nconnections:\n"
            ),
        )
        .replace(
            "  - { from: ctrl.u, to: stage.u }\n",
            "  - { from: ctrl.u, to: cogging.u }\n  - { from: stage.y, to: cogging.s }\n  - { from: cogging.y, to: stage.u }\n",
        );
    let data = record(&truth_yaml, "stage.y", r, &mut rng);
    let nominal = GraphSpec::from_yaml(&graph(false), "nominal.yaml").unwrap();
    let rep = diagnose(&nominal, &data, &Options::default()).unwrap();
    eprintln!(
        "cogging: found {:?}; held-out rms {:.3e} -> {:.3e} m; {}",
        rep.found, rep.nominal.holdout_rms, rep.final_scores.holdout_rms, rep.stopped_because
    );
    assert_eq!(
        rep.found,
        ["repetitive_disturbance"],
        "{}",
        rep.stopped_because
    );
    let p = &rep.steps[0].final_params;
    // The harmonic that carries the force.
    let (h, fitted) = (0..3)
        .map(|h| {
            (
                h + 1,
                p[&format!("cos[{h}]")].hypot(p[&format!("sin[{h}]")]),
            )
        })
        .max_by(|a, b| a.1.total_cmp(&b.1))
        .unwrap();
    let fitted_pitch = p["period"] / h as f64;
    assert!((fitted_pitch - pitch).abs() < 0.01 * pitch, "{p:?}");
    assert!((fitted - amp).abs() < 0.1 * amp, "{fitted} vs {amp}");
    assert!(rep.final_scores.holdout_rms < 0.2 * rep.nominal.holdout_rms);
}
