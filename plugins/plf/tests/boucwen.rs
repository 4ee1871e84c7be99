//! A real third-party record: the Bouc–Wen nonlinear-system-identification
//! benchmark (Noël & Schoukens; multisine validation set in
//! `../shared/data/boucwen_benchmark/`, read in place, never copied). Nominal
//! model: the benchmark's linear part m_L ÿ + c_L ẏ + k_L y = u with its published
//! m_L = 2 kg, c_L = 10 N s/m, k_L = 5e4 N/m (`examples/diagnose/boucwen_nominal.yaml`).
//! The workflow must name `hysteresis`; the fitted Bouc–Wen operator is checked
//! against the benchmark's published α = 5e4 N/m and β·γ = 800 1/m.
//!
//! Needs `../shared/data`: fails when `CI` is set and the data is missing, and
//! says SKIPPED loudly otherwise.

use nanomotion_core::data::Dataset;
use nanomotion_core::graph::GraphSpec;
use nanomotion_plf::diagnose::{Options, diagnose};
use std::path::PathBuf;

fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../..")
}

#[test]
fn boucwen_benchmark_names_hysteresis() {
    let _ = std::any::type_name::<nanomotion_plf::effects::Effect>();
    let path = root().join("../shared/data/boucwen_benchmark/bw_val_multisine.csv");
    if !path.exists() {
        if std::env::var_os("CI").is_some() {
            panic!("{} is missing: CI must have ../shared/data", path.display());
        }
        eprintln!(
            "SKIPPED: {} not found — the Bouc–Wen benchmark test did not run",
            path.display()
        );
        return;
    }
    let data = Dataset::from_file(&path).unwrap();
    let spec = GraphSpec::from_file(root().join("examples/diagnose/boucwen_nominal.yaml")).unwrap();
    let r = diagnose(&spec, &data, &Options::default()).unwrap();
    eprintln!(
        "Bouc–Wen benchmark: found {:?}; held-out rms {:.3e} -> {:.3e} m (after step 1: {:.3e} m), whole record {:.3e} m; {}",
        r.found,
        r.nominal.holdout_rms,
        r.final_scores.holdout_rms,
        r.steps.first().map_or(f64::NAN, |s| s.holdout_rms_after),
        r.final_scores.rms,
        r.stopped_because
    );
    assert_eq!(r.found.first().map(String::as_str), Some("hysteresis"));
    let s = &r.steps[0];
    assert_eq!(s.block.type_name, "bouc_wen", "{:?}", s.block);
    // The inserted force is −z of the benchmark: a = −α, β' = β·γ_bench, |γ'| = β·|δ|.
    let a = s.params["a"];
    let beta = s.params["beta"];
    assert!((a + 5e4).abs() < 0.05 * 5e4, "a = {a}");
    assert!((beta - 800.0).abs() < 0.15 * 800.0, "beta = {beta}");
    assert!(s.holdout_rms_after < 1e-4, "{}", s.holdout_rms_after);
}
