//! Several records (issue 24, item 4): `diagnose_records` estimates on the first
//! record and decides on the others, each simulated from rest on its own.
//!
//! The evaluator over records end to end must give, on each record, exactly
//! what a graph run on that record alone gives (an independent run: a fresh
//! graph built on the record by itself), and the workflow must name a hidden
//! effect when the held-out record is another stretch of the stage's motion.

use nanomotion_core::graph::GraphSpec;
use nanomotion_plf::diagnose::{Options, diagnose_records};
use nanomotion_plf::fit::{Evaluator, Records};
use nanomotion_plf::generate;
use std::sync::Arc;

fn link() {
    // typetag registers the effect blocks through the linker.
    let _ = std::any::type_name::<nanomotion_plf::effects::Effect>();
}

#[test]
fn records_end_to_end_run_each_from_rest_as_alone() {
    link();
    let rec = generate::second_order("friction", 3, 6000, false).unwrap();
    let (a, b) = (rec.data.slice(0..2500), rec.data.slice(2500..6000));
    let spec = || GraphSpec::from_yaml(&rec.nominal_yaml, "generated.yaml").unwrap();
    let both = Records::concat(&[a.clone(), b.clone()]).unwrap();
    assert_eq!(both.starts(), vec![0, 2500]);
    assert_eq!(both.all.len(), 6000);
    let mut ev = Evaluator::over(spec(), &both, &[], 0).unwrap();
    assert!(ev.run(&[], both.all.len()));
    for (part, start) in [(&a, 0usize), (&b, 2500)] {
        let mut alone = spec();
        alone.duration_s = part.len() as f64 / part.rate_hz();
        let mut one = Evaluator::new(alone, &Arc::new(part.clone()), &[], 0).unwrap();
        assert!(one.run(&[], part.len()));
        let together = ev.residual(0, start..start + part.len());
        let by_itself = one.residual(0, 0..part.len());
        assert_eq!(together, by_itself, "record at {start}");
    }
    // Run only into the first record: the second is not simulated, the first
    // is the same.
    assert!(ev.run(&[], 2500));
    assert_eq!(ev.residual(0, 0..2500), {
        let mut alone = spec();
        alone.duration_s = 2500.0 / a.rate_hz();
        let mut one = Evaluator::new(alone, &Arc::new(a.clone()), &[], 0).unwrap();
        assert!(one.run(&[], 2500));
        one.residual(0, 0..2500)
    });
}

#[test]
fn records_of_other_rates_are_refused_with_the_fix() {
    let rec = generate::second_order("none", 1, 1000, false).unwrap();
    let other = generate::second_order("none", 1, 1000, false).unwrap();
    let resampled = nanomotion_core::data::Dataset::from_columns(
        "resampled.csv",
        2.0 * rec.data.rate_hz(),
        0.0,
        vec![("u".into(), vec![0.0; 10]), ("y".into(), vec![0.0; 10])],
    )
    .unwrap();
    let e = Records::concat(&[rec.data.clone(), resampled]).unwrap_err();
    assert!(e.to_string().contains("one rate"), "{e}");
    assert_eq!(Records::concat(&[other.data]).unwrap().parts.len(), 1);
}

#[test]
fn an_effect_is_named_on_a_record_it_was_not_fitted_on() {
    link();
    let rec = generate::second_order("friction", 2, 12_000, false).unwrap();
    let spec = GraphSpec::from_yaml(&rec.nominal_yaml, "generated.yaml").unwrap();
    let (est, val) = (rec.data.slice(0..7000), rec.data.slice(7000..12_000));
    let opts = Options {
        max_effects: 2,
        ..Options::default()
    };
    let r = diagnose_records(&spec, &[est, val], &opts, &mut |_, _| {}).unwrap();
    eprintln!(
        "two records: found {:?}, held-out rms {:.3e} -> {:.3e}; {}",
        r.found, r.nominal.holdout_rms, r.final_scores.holdout_rms, r.stopped_because
    );
    assert_eq!(r.records.len(), 2);
    assert_eq!((r.estimation_samples, r.holdout_samples), (7000, 5000));
    assert_eq!(r.found, vec!["friction".to_string()]);
    assert!(r.final_scores.holdout_rms < 0.5 * r.nominal.holdout_rms);
}

/// The step's calibration runs beside the candidates' fits on a thread of
/// its own, or after them on the caller's with `threads: 1`: the report is
/// the same to the bit either way (results land in fixed slots; nothing
/// depends on timing).
#[test]
fn one_thread_or_two_give_the_same_report() {
    link();
    let rec = generate::second_order("friction", 3, 4000, false).unwrap();
    let spec = GraphSpec::from_yaml(&rec.nominal_yaml, "generated.yaml").unwrap();
    let report = |threads| {
        let opts = Options {
            threads,
            ..Options::default()
        };
        let r = nanomotion_plf::diagnose::diagnose(&spec, &rec.data, &opts).unwrap();
        serde_json::to_string(&r).unwrap()
    };
    let (one, two) = (report(1), report(2));
    assert!(one.contains("\"friction\""), "{one}");
    assert_eq!(one, two);
}
