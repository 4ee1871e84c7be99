//! Held-out scenario records studied after their blind set was reported
//! (issue 24): each was scored once, blind, in docs/plf.md; a change made after
//! looking at them is judged on the next blind set, and these tests keep what
//! it fixed. They are regression tests, not evidence of generalisation.

use nanomotion_core::graph::GraphSpec;
use nanomotion_plf::diagnose::{Options, diagnose};
use nanomotion_plf::scenario::{self, Split};
use nanomotion_plf::stats;

fn studied(seed: u64) -> scenario::Scenario {
    let s = scenario::draw(seed).unwrap();
    assert_eq!(
        s.family.split(),
        Split::HeldOut,
        "seed {seed} is a held-out record"
    );
    s
}

fn diagnose_studied(seed: u64) -> nanomotion_plf::Report {
    // typetag registers the effect blocks through the linker.
    let _ = std::any::type_name::<nanomotion_plf::effects::Effect>();
    let s = studied(seed);
    let spec = GraphSpec::from_yaml(&s.record.nominal_yaml, "scenario.yaml").unwrap();
    diagnose(&spec, &s.record.data, &Options::default()).unwrap()
}

/// Blind set 4373–4715: a cogging force (a force periodic in the position,
/// the generator's own form) was named on three of ten records. On 4697 (a
/// free mass in a PD loop, steps) and 4608 (a lag stage in open loop, a
/// random drive) nothing was named: the residual binned against the position
/// showed no line, since the force reaches the position through the plant
/// and the loop, with a phase that changes with the speed. The pitch is now
/// also looked for through the model's own response to a force at each
/// pitch (`force_pitch`, a matched filter), and both are named — as a force
/// on the drive, periodic in the position.
#[test]
fn a_cogging_force_through_the_plant_is_named_by_its_response() {
    for seed in [4697, 4608] {
        assert!(studied(seed).record.truth.contains("cogging"));
        let r = diagnose_studied(seed);
        assert_eq!(
            r.found,
            ["repetitive_disturbance"],
            "{seed}: {}",
            r.stopped_because
        );
        let step = &r.steps[0];
        assert!(step.site.starts_with("input side"), "{seed}: {}", step.site);
        assert!(
            step.evidence.contains("binned against") || step.evidence.contains("of pitch"),
            "{seed}: periodic in the position, not in time: {}",
            step.evidence
        );
        assert!(
            step.cut_percent > 50.0,
            "{seed}: cut {:.0} %",
            step.cut_percent
        );
    }
}

/// Blind set 4373–4715: `quantization` was named from a "grid" of the
/// measured values on 4422 and 4515 (sines in a PID loop, no rounding
/// hidden) at z = 3.9, p = 10⁻³, with a concentration on the grid of 0.04
/// where the record's noise (σ/q = 0.02) asks 0.99 of a true one. The grid
/// must concentrate the values as its noise allows (`stats::value_grid`):
/// neither record has a grid now; 4463's and 4817's true roundings keep
/// theirs, at the step (4817's best pitch was half the step: the multiples
/// of the pitch found are tried too).
#[test]
fn a_grid_must_hold_the_values_as_tightly_as_the_noise_allows() {
    for seed in [4422, 4515] {
        let s = studied(seed);
        assert!(!s.record.truth.contains("rounded"), "{}", s.record.truth);
        let y = s.record.data.column("y").unwrap();
        assert!(
            stats::value_grid(y).is_none(),
            "{seed}: {:?}",
            stats::value_grid(y)
        );
    }
    for seed in [4463, 4817] {
        let s = studied(seed);
        assert!(s.record.truth.contains("rounded"), "{}", s.record.truth);
        let y = s.record.data.column("y").unwrap();
        let g = stats::value_grid(y).expect("the rounding's grid");
        assert!(g.test.p_value < 1e-20, "{seed}: {g:?}");
        // The step, not a fraction of it: the values concentrate more at it
        // than at half of it (4817's best pitch was half its step, where
        // they concentrate less than the noise allows) or at twice it.
        let concentration = |q: f64| {
            let (re, im) = y.iter().fold((0.0, 0.0), |(re, im), v| {
                let (s, c) = (2.0 * std::f64::consts::PI * v / q).sin_cos();
                (re + c, im + s)
            });
            re.hypot(im) / y.len() as f64
        };
        let at = concentration(g.pitch);
        assert!(at > concentration(0.5 * g.pitch), "{seed}: {g:?}");
        assert!(at > 2.0 * concentration(2.0 * g.pitch), "{seed}: {g:?}");
    }
}

/// Blind set 5003–5121: on 5027 (a drive delay of three samples, slightly
/// varying, behind a stage2 plant whose nominal is off, open loop, a
/// multisine at 500 Hz, pink noise; the delay's own calibrated visibility
/// 70) nothing was named: the calibration alone cut 19 % of the excess over
/// the noise floor and the delay alone 20 %, each short of the 30 % a name
/// needs. Fitted on the calibrated nominal, the delay takes most of the
/// rest: the calibration is kept for the effect it lets through, says so,
/// and the delay is named on it.
#[test]
fn a_nominal_that_is_off_is_kept_for_the_effect_it_lets_through() {
    let seed = 5027;
    assert!(studied(seed).record.truth.contains("delay"));
    let r = diagnose_studied(seed);
    assert_eq!(r.found, ["time_delay"], "{}", r.stopped_because);
    let cal = r.calibration.as_ref().unwrap();
    assert!(cal.accepted, "{cal:?}");
    assert!(
        cal.excess_cut_percent < 30.0,
        "the calibration passes alone: {cal:?}"
    );
    assert!(
        cal.with_effect
            .as_deref()
            .is_some_and(|w| w.starts_with("kept with time_delay")),
        "{cal:?}"
    );
    let cut = 1.0 - r.final_scores.holdout_rms / r.nominal.holdout_rms;
    assert!(cut > 0.5, "cut {:.0} %", 100.0 * cut);
}

/// Blind set 5122–5241: both false alarms were two-mode stages whose nominal
/// is off (5184: multisine at 10 kHz; 5224: a random drive at 1 kHz, AR(1)
/// noise). One damping scale for both modes could not put the first mode's
/// damping right without making the second's wrong, and a near-cancelling
/// pole–zero pair was named for what it left at the second mode. Each mode
/// now has its own damping and gain scales (a modal model's parameters); the
/// calibration takes the error and nothing is named.
#[test]
fn a_second_mode_off_in_damping_and_gain_is_calibrated_not_named() {
    for seed in [5184, 5224] {
        let s = studied(seed);
        assert_eq!(s.family.plant, "two_mode");
        assert!(s.record.hidden.is_empty(), "{seed}: an effect-free record");
        let r = diagnose_studied(seed);
        assert!(r.found.is_empty(), "{seed}: named {:?}", r.found);
        let cal = r.calibration.as_ref().unwrap();
        assert!(cal.accepted, "{seed}: {cal:?}");
        for k in ["plant.mode_2_damping_scale", "plant.mode_2_gain_scale"] {
            assert!(
                cal.params.contains_key(k),
                "{seed}: {k} not fitted: {cal:?}"
            );
        }
        let cut = 1.0 - r.final_scores.holdout_rms / r.nominal.holdout_rms;
        assert!(cut > 0.9, "{seed}: cut {:.0} %", 100.0 * cut);
    }
}

/// Blind set 5302–5421: on two lag stages with an attached mass (5392: 47.6
/// Hz, a sine drive at 1 kHz; 5343: 79.8 Hz, steps at 500 Hz) a hysteresis
/// was named for the mode: the resonance's fit started at the residual's
/// strongest line — the slow misfit, at 1–11 Hz — and ended on a pole–zero
/// pair that nearly cancels there. It now starts at the spectrum's peak over
/// its neighbours too (`stats::prominent_peak`). On 5343 the steps ring the
/// mode and the fit finds it (a hysteresis inside the loop is still named
/// first: padding left); 5392's one tone cannot place a mode (the fit ends at
/// 106 Hz: at one frequency a resonance is a gain and a phase), only the name
/// is right.
#[test]
fn a_mode_far_above_the_strongest_line_is_fitted_where_it_rings() {
    let s = studied(5343);
    assert!(s.record.truth.contains("79.8 Hz"), "{}", s.record.truth);
    let r = diagnose_studied(5343);
    let step = r
        .steps
        .iter()
        .find(|s| s.effect == "unmodeled_resonance")
        .unwrap_or_else(|| panic!("no resonance: {:?}, {}", r.found, r.stopped_because));
    let p = &step.final_params;
    for k in ["f_pole_hz", "f_zero_hz"] {
        assert!((p[k] / 79.8 - 1.0).abs() < 0.2, "{k} = {} Hz: {p:?}", p[k]);
    }
    let r = diagnose_studied(5392);
    assert_eq!(r.found, ["unmodeled_resonance"], "{}", r.stopped_because);
}

/// Blind set 5302–5421, 5368 (a first-order stage in open loop, a random
/// drive, hysteresis and creep): after the drive's hysteresis, creep cut the
/// held-out rms 2.0 → 0.37 but was not named — a second hysteresis *inside
/// the loop* (a hysteretic force of the stage's own position) cut it to 0.41,
/// and a new name must beat a copy of one named. A copy at another kind of
/// place is another physical claim (fed by the stage's lagged position it
/// has dynamics the drive's map has not): only copies where the effect was
/// named are the null now, and creep is named.
#[test]
fn creep_after_the_drives_hysteresis_beats_only_a_copy_on_the_drive() {
    let s = studied(5368);
    assert_eq!(s.record.hidden, ["hysteresis", "creep"]);
    let r = diagnose_studied(5368);
    assert_eq!(r.found, ["hysteresis", "creep"], "{}", r.stopped_because);
    for step in &r.steps {
        assert!(
            step.site.starts_with("input side"),
            "{}: {}",
            step.effect,
            step.site
        );
    }
    let cut = 1.0 - r.final_scores.holdout_rms / r.nominal.holdout_rms;
    assert!(cut > 0.95, "cut {:.0} %", 100.0 * cut);
}
