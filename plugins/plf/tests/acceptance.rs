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
        for c in s.candidates.iter().take(5) {
            eprintln!(
                "    {} {} ({} params): held-out {:.3e}",
                c.effect, c.site, c.n_params, c.holdout_rms
            );
        }
    }
    assert_eq!(
        r.found.first().map(String::as_str),
        Some(effect),
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
