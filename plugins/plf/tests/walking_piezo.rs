//! The walking-piezo plant (Ch. 5, `walking-piezo`): the "measured" stage
//! position comes from the fitted model (5.31) — integrator, 527 Hz resonance,
//! 624 Hz anti-resonance, 650 Hz resonance, 3-sample delay, at 4 kHz — driven by
//! a recorded drive frequency f_α, with one effect hidden in the truth that a
//! walking piezo stage plausibly has and the nominal model lacks:
//!
//! | hidden | in the truth (written out here, not with the plf blocks) |
//! |---|---|
//! | `position_dependent_gain` | step size varies along the drive strip: f_α·(1 + g·(x − x̄)/L) |
//! | `time_delay` | extra driver/communication delay of 2–6 samples |
//! | `quantization` | a coarse encoder: x rounded to q = 40–80 nm |
//! | `repetitive_disturbance` | step ripple periodic in position with the step length c |
//! | `saturation` | the driver's drive-frequency limit, ±(60–80 %) of the peak |
//! | `drift` | thermal drift: offset + rate + curvature |
//!
//! The workflow gets only the nominal graph (data_column f_α → walking_piezo_fitted)
//! and the record; it must name the hidden effect alone and cut the held-out rms by
//! at least half. (walking-piezo is a dev-dependency only: plugins never depend on
//! each other.)

use nanomotion_core::graph::GraphSpec;
use nanomotion_plf::diagnose::{Options, diagnose};
use walking_piezo::records as wp;
use wp::{nominal_yaml, record};

fn check_named(hidden: &str, seed: u64) {
    let _ = std::any::type_name::<walking_piezo::FittedStageBlock>();
    let _ = std::any::type_name::<nanomotion_plf::effects::Effect>();
    let (data, truth) = record(hidden, seed).unwrap();
    let spec = GraphSpec::from_yaml(&nominal_yaml(), "walking_piezo_nominal.yaml").unwrap();
    let opts = Options {
        max_effects: 2,
        ..Options::default()
    };
    let r = diagnose(&spec, &data, &opts).unwrap();
    eprintln!(
        "walking piezo, {hidden} ({truth}), seed {seed}: found {:?}; held-out rms {:.3e} -> {:.3e} m; {}",
        r.found, r.nominal.holdout_rms, r.final_scores.holdout_rms, r.stopped_because
    );
    for s in &r.steps {
        for c in s.candidates.iter().take(4) {
            eprintln!(
                "    {} {} ({} params): held-out {:.3e}",
                c.effect, c.site, c.n_params, c.holdout_rms
            );
        }
    }
    assert_eq!(r.found, vec![hidden.to_string()], "{hidden}: {truth}");
    let s = &r.steps[0];
    let cut = 1.0 - s.holdout_rms_after / s.holdout_rms_before;
    assert!(cut >= 0.5, "{hidden}: cut {:.0} %", 100.0 * cut);
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
    walking_piezo_position_dependent_gain_is_named: "position_dependent_gain",
    walking_piezo_time_delay_is_named: "time_delay",
    walking_piezo_saturation_is_named: "saturation",
    walking_piezo_quantization_is_named: "quantization",
    walking_piezo_step_ripple_is_named: "repetitive_disturbance",
    walking_piezo_drift_is_named: "drift",
}
