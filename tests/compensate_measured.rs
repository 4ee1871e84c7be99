//! `nanomotion compensate --measured-alpha FILE[:COLUMN] --delay-margin F` on
//! the shipped position-ripple example (examples/compensate/position_ripple:
//! delay-varying RC on the stage's position): a record's delays and the
//! margin make the range [m, M] as the report's figures say, the default
//! margin follows what was measured, and bad records and margins are refused
//! naming the file, the column and the fix, with nothing written.

mod common;

use common::{cli, scratch};
use nanomotion::compensate::{DELAY_MARGIN_MEASURED, DELAY_SPREAD_UNMEASURED};
use nanomotion::core::data::Dataset;
use std::path::Path;

const RATE: f64 = 4000.0;
/// The ripple's pitch in the example's augmented model (m).
const PITCH: f64 = 5e-7;
const MODEL: &str = "examples/compensate/position_ripple/model_augmented.yaml";
const CONTROLLER: &str = "examples/compensate/position_ripple/controller.yaml";

/// A record of the position moving at `v` (m/s) for 0.2 s, as a run writes
/// it (column `stage.y`), with a second column `u`.
fn record(dir: &Path, v: f64) -> String {
    std::fs::create_dir_all(dir).unwrap();
    let x: Vec<f64> = (0..800).map(|k| v * k as f64 / RATE).collect();
    let u = vec![0.0; x.len()];
    let d = Dataset::from_columns(
        "record",
        RATE,
        0.0,
        vec![("stage.y".into(), x), ("u".into(), u)],
    )
    .unwrap();
    let path = dir.join("alpha.csv");
    std::fs::write(&path, d.to_csv_string()).unwrap();
    path.display().to_string()
}

/// `compensate` on the example with `extra` options into `out`: its report.
fn compensate(out: &Path, extra: &[&str]) -> serde_json::Value {
    let o = out.display().to_string();
    let mut args = vec!["compensate", MODEL, CONTROLLER, "--out", &o];
    args.extend_from_slice(extra);
    let (ok, stdout, stderr) = cli(&args);
    assert!(ok, "{args:?}\n{stdout}\n{stderr}");
    serde_json::from_str(&std::fs::read_to_string(out.join("report.json")).unwrap()).unwrap()
}

/// The design figures of the one compensator, a `dvrc`.
fn design(report: &serde_json::Value) -> serde_json::Map<String, serde_json::Value> {
    let c = &report["compensators"][0];
    assert_eq!(c["type"], "dvrc", "{c}");
    c["design"].as_object().unwrap().clone()
}

#[test]
fn a_measured_record_and_a_margin_make_the_delay_range() {
    let f = |d: &serde_json::Map<String, serde_json::Value>, k: &str| d[k].as_f64().unwrap();
    // Without either: the models' delays widened by the unmeasured spread;
    // the report says the validation cannot judge that range.
    let r = compensate(&scratch("comp_measured_none"), &[]);
    let note = r["compensators"][0]["note"].as_str().unwrap_or_default();
    assert!(note.contains("cannot tell whether"), "{note}");
    let d = design(&r);
    assert_eq!(f(&d, "delay_margin"), DELAY_SPREAD_UNMEASURED);
    assert!(!d.contains_key("delay_measured_min"));
    let lo = f(&d, "delay_nominal_min").min(f(&d, "delay_diagnosed_min"));
    assert_eq!(
        f(&d, "n_min"),
        (lo * (1.0 - DELAY_SPREAD_UNMEASURED)).floor() - 1.0
    );
    // The loop moves 10 µm/s: one pitch takes PITCH·RATE/v = 200 samples
    // (the latest sample a whole pitch back: 200 or, by round-off, 201).
    assert!(
        (200.0..=201.0).contains(&f(&d, "delay_nominal_min")),
        "{d:?}"
    );

    // A record at 15 µm/s: every sample's delay is ⌈PITCH·RATE/v⌉ = ⌈133.3⌉
    // = 134, below the loops'; it sets m, with the margin given.
    let rec = record(&scratch("comp_measured_record"), 1.5e-5);
    let column = format!("{rec}:stage.y");
    let r = compensate(
        &scratch("comp_measured_out"),
        &["--measured-alpha", &column, "--delay-margin", "0.05"],
    );
    let d = design(&r);
    let n = (PITCH * RATE / 1.5e-5).ceil();
    // The stage (the record) moves faster than the models: said.
    let note = r["compensators"][0]["note"].as_str().unwrap_or_default();
    assert!(note.contains("do not overlap"), "{note}");
    assert_eq!(
        (f(&d, "delay_measured_min"), f(&d, "delay_measured_max")),
        (n, n)
    );
    assert_eq!(f(&d, "delay_margin"), 0.05);
    assert_eq!(f(&d, "n_min"), (n * 0.95).floor() - 1.0);
    let hi = f(&d, "delay_nominal_max").max(f(&d, "delay_diagnosed_max"));
    assert_eq!(f(&d, "n_max"), (hi * 1.05).ceil() + 1.0);
    // (5.9) for that range, with its bound 1/√(M − m + 1).
    let bound = 1.0 / (f(&d, "n_max") - f(&d, "n_min") + 1.0).sqrt();
    assert!((f(&d, "criterion_5_9_bound") - bound).abs() < 1e-12);
    assert!(f(&d, "criterion_5_9_hinf") < bound);
    // With the record and no margin: the measured default.
    let d = design(&compensate(
        &scratch("comp_measured_default"),
        &["--measured-alpha", &column],
    ));
    assert_eq!(f(&d, "delay_margin"), DELAY_MARGIN_MEASURED);
    assert_eq!(
        f(&d, "n_min"),
        (n * (1.0 - DELAY_MARGIN_MEASURED)).floor() - 1.0
    );

    // `--help` says what the options take and the defaults.
    let (ok, help, _) = cli(&["compensate", "--help"]);
    assert!(ok);
    assert!(help.contains("--measured-alpha <FILE[:COLUMN]>"), "{help}");
    assert!(help.contains("--delay-margin <FRACTION>"), "{help}");
    assert!(
        help.contains(&format!("{DELAY_SPREAD_UNMEASURED:.3}"))
            && help.contains(&format!("{DELAY_MARGIN_MEASURED:.3}")),
        "{help}"
    );
}

#[test]
fn bad_records_and_margins_are_refused_naming_the_file_column_and_fix() {
    let dir = scratch("comp_measured_bad_inputs");
    let rec = record(&dir, 1.5e-5);
    let bad = scratch("comp_measured_bad");
    let b = bad.display().to_string();
    let refused = |extra: &[&str]| {
        let mut args = vec!["compensate", MODEL, CONTROLLER, "--out", &b];
        args.extend_from_slice(extra);
        let (ok, _, stderr) = cli(&args);
        assert!(!ok, "{args:?} was not refused");
        assert!(stderr.contains("fix:"), "{stderr}");
        stderr
    };
    // Two data columns and none named.
    let e = refused(&["--measured-alpha", &rec]);
    assert!(
        e.contains(&rec) && e.contains("stage.y, u") && e.contains(&format!("{rec}:stage.y")),
        "{e}"
    );
    // A column the file does not have: its columns listed.
    let e = refused(&["--measured-alpha", &format!("{rec}:alpha.y")]);
    assert!(e.contains("alpha.y") && e.contains("stage.y, u"), "{e}");
    // A column no delay-varying RC follows: the signal followed named.
    let e = refused(&["--measured-alpha", &format!("{rec}:u")]);
    assert!(
        e.contains("column `u`")
            && e.contains("no delay-varying RC follows `u`")
            && e.contains("`stage.y`"),
        "{e}"
    );
    // No such file.
    let e = refused(&["--measured-alpha", "no/such/alpha.csv:stage.y"]);
    assert!(e.contains("no/such/alpha.csv"), "{e}");
    // A record that does not advance two periods (0.2 s at 2 µm/s: 0.4 µm).
    let slow = record(&dir.join("slow"), 2e-6);
    let e = refused(&["--measured-alpha", &format!("{slow}:stage.y")]);
    assert!(e.contains("less than two periods"), "{e}");
    // A margin outside [0, 0.5).
    let e = refused(&["--delay-margin", "0.7"]);
    assert!(e.contains("delay margin") && e.contains("0.7"), "{e}");
    assert!(!bad.exists(), "a refused command left {b}");
}
