//! `nanomotion run MODEL --data FILE`: measured data played and compared, and every
//! kind of bad data reported as an error naming file, row and column (exit code 1,
//! never a panic).

use std::path::{Path, PathBuf};
use std::process::Command;

fn nm() -> Command {
    let mut c = Command::new(env!("CARGO_BIN_EXE_nanomotion"));
    c.current_dir(env!("CARGO_MANIFEST_DIR"));
    c
}

/// A fresh temporary folder for one test.
fn tmp(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("nm-data-cli-{}-{name}", std::process::id()));
    std::fs::remove_dir_all(&d).ok();
    std::fs::create_dir_all(&d).unwrap();
    d
}

/// The measured record of the happy path: 100 Hz, 64 samples.
fn record() -> (Vec<f64>, Vec<f64>) {
    let u: Vec<f64> = (0..64).map(|k| (0.3 * k as f64).sin()).collect();
    let y: Vec<f64> = (0..64)
        .map(|k| 2.0 * u[k] + 0.1 * (1.7 * k as f64).cos())
        .collect();
    (u, y)
}

fn csv(rows: &[(f64, f64, f64)]) -> String {
    let mut s = String::from("# measured on the bench\nt_s,u,y\n");
    for (t, u, y) in rows {
        s.push_str(&format!("{t},{u},{y}\n"));
    }
    s
}

fn good_rows() -> Vec<(f64, f64, f64)> {
    let (u, y) = record();
    (0..64).map(|k| (k as f64 / 100.0, u[k], y[k])).collect()
}

const MODEL: &str = "title: gain model\nbase_rate_hz: 100\nduration_s: 1\nblocks:\n  - { name: src, type: data_column, column: u }\n  - { name: g, type: gain, k: 2.0 }\nconnections:\n  - { from: src.y, to: g.u }\ncompare:\n  - { signal: g.y, column: y }\n";

fn write(dir: &Path, name: &str, text: &str) -> PathBuf {
    let p = dir.join(name);
    std::fs::write(&p, text).unwrap();
    p
}

/// Run with `model` and `data`; returns (exit code, stdout, stderr).
fn run(dir: &Path, model: &str, data: &Path) -> (Option<i32>, String, String) {
    let m = write(dir, "model.yaml", model);
    let o = nm()
        .arg("run")
        .arg(&m)
        .arg("--data")
        .arg(data)
        .arg("--out")
        .arg(dir.join("out"))
        .output()
        .expect("binary runs");
    (
        o.status.code(),
        String::from_utf8_lossy(&o.stdout).into_owned(),
        String::from_utf8_lossy(&o.stderr).into_owned(),
    )
}

/// Bad data: exit code 1, `error:` with every fragment, no panic.
fn fails_with(name: &str, model: &str, data_text: Option<&str>, fragments: &[&str]) {
    let dir = tmp(name);
    let data = match data_text {
        Some(t) => write(&dir, "rec.csv", t),
        None => dir.join("missing.csv"),
    };
    let (code, _, stderr) = run(&dir, model, &data);
    assert_eq!(code, Some(1), "{name}: {stderr}");
    assert!(stderr.starts_with("error: "), "{name}: {stderr}");
    assert!(!stderr.contains("panicked"), "{name}: {stderr}");
    for f in fragments {
        assert!(stderr.contains(f), "{name}: `{f}` missing from:\n{stderr}");
    }
    std::fs::remove_dir_all(dir).ok();
}

#[test]
fn happy_path_prints_the_hand_computed_fit() {
    let dir = tmp("happy");
    let data = write(&dir, "rec.csv", &csv(&good_rows()));
    let (code, stdout, stderr) = run(&dir, MODEL, &data);
    assert_eq!(code, Some(0), "{stderr}");
    // By hand: model ŷ = 2u, residual r = y − ŷ.
    let (u, y) = record();
    let mean = y.iter().sum::<f64>() / 64.0;
    let num: f64 = (0..64)
        .map(|k| (y[k] - 2.0 * u[k]).powi(2))
        .sum::<f64>()
        .sqrt();
    let den: f64 = y.iter().map(|v| (v - mean).powi(2)).sum::<f64>().sqrt();
    let fit = 100.0 * (1.0 - num / den);
    let rms = num / 8.0;
    let line = stdout
        .lines()
        .find(|l| l.starts_with("g.y "))
        .unwrap_or_else(|| panic!("no comparison row:\n{stdout}"));
    let cells: Vec<&str> = line.split_whitespace().collect();
    assert_eq!(cells[1], "y", "{line}");
    let printed_fit: f64 = cells[4].parse().unwrap();
    assert!(
        (printed_fit - fit).abs() <= 5e-4 + 1e-12,
        "{printed_fit} vs {fit}"
    );
    assert!(fit > 90.0 && fit < 99.9, "{fit}");
    let printed_rms: f64 = cells[2].parse().unwrap();
    assert!(
        (printed_rms - rms).abs() <= 1e-4 * rms,
        "{printed_rms} vs {rms}"
    );
    assert!(stdout.contains("64 samples at 100 Hz"), "{stdout}");
    // The JSON holds the full-precision numbers; one SVG per compared signal.
    let json = std::fs::read_to_string(dir.join("out/comparison.json")).unwrap();
    let v: serde_json::Value = serde_json::from_str(&json).unwrap();
    let c = &v["comparisons"][0];
    assert!(
        (c["fit_percent"].as_f64().unwrap() - fit).abs() < 1e-9,
        "{json}"
    );
    assert!((c["rms"].as_f64().unwrap() - rms).abs() < 1e-15, "{json}");
    assert_eq!(c["samples"].as_u64(), Some(64));
    let svg = std::fs::read_to_string(dir.join("out/compare_g_y.svg")).unwrap();
    assert!(
        svg.contains("measured y") && svg.contains("residual"),
        "svg"
    );
    std::fs::remove_dir_all(dir).ok();
}

#[test]
fn missing_column_lists_the_columns() {
    fails_with(
        "column",
        &MODEL.replace("column: u }", "column: force }"),
        Some(&csv(&good_rows())),
        &[
            "block `src`",
            "`force` is not a column",
            "its columns are: u, y",
        ],
    );
}

#[test]
fn nan_is_located() {
    let mut rows = good_rows();
    rows[10].1 = f64::NAN;
    // Header on line 2 (one comment), sample 10 on line 13.
    fails_with(
        "nan",
        MODEL,
        Some(&csv(&rows)),
        &["rec.csv, row 13, column `u`", "NaN"],
    );
}

#[test]
fn non_monotonic_time_is_located() {
    let mut rows = good_rows();
    rows[20].0 = rows[18].0;
    fails_with(
        "monotonic",
        MODEL,
        Some(&csv(&rows)),
        &[
            "row 23, column `t_s`",
            "time does not increase",
            "sort the rows",
        ],
    );
}

#[test]
fn non_uniform_time_is_located_with_the_tolerance() {
    let mut rows = good_rows();
    rows.remove(30);
    fails_with(
        "uniform",
        MODEL,
        Some(&csv(&rows)),
        &[
            "row 33, column `t_s`",
            "not uniformly sampled",
            "from 0.29 s to 0.31 s",
            "1e-6·Δt",
        ],
    );
}

#[test]
fn block_rate_must_match_the_data_rate() {
    fails_with(
        "rate",
        &MODEL.replace("base_rate_hz: 100", "base_rate_hz: 200"),
        Some(&csv(&good_rows())),
        &["block `src`", "200 Hz", "100 Hz", "rate_hz: 100"],
    );
}

#[test]
fn too_few_samples() {
    fails_with(
        "few",
        MODEL,
        Some(&csv(&good_rows()[..10])),
        &["rec.csv", "10 samples, fewer than the minimum of 16"],
    );
}

#[test]
fn constant_measured_column() {
    let rows: Vec<(f64, f64, f64)> = good_rows()
        .into_iter()
        .map(|(t, u, _)| (t, u, 3.0))
        .collect();
    fails_with(
        "constant",
        MODEL,
        Some(&csv(&rows)),
        &[
            "column `y`",
            "comparing `g.y`",
            "measured column is constant",
            "fit %",
        ],
    );
}

#[test]
fn unreadable_file() {
    fails_with(
        "unreadable",
        MODEL,
        None,
        &["missing.csv: cannot be opened"],
    );
}

#[test]
fn compare_without_data_and_runs_longer_than_the_data() {
    let dir = tmp("nodata");
    let m = write(&dir, "model.yaml", MODEL);
    let o = nm().arg("run").arg(&m).arg("--no-files").output().unwrap();
    let stderr = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(1));
    assert!(
        stderr.contains("`compare:`") && stderr.contains("--data FILE"),
        "{stderr}"
    );
    let data = write(&dir, "rec.csv", &csv(&good_rows()));
    let o = nm()
        .arg("run")
        .arg(&m)
        .arg("--data")
        .arg(&data)
        .args(["--duration", "1.0", "--no-files"])
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(1));
    assert!(
        stderr.contains("lasts 1 s") && stderr.contains("lasts only 0.64 s"),
        "{stderr}"
    );
    std::fs::remove_dir_all(dir).ok();
}

/// `../shared/data/boucwen_benchmark`, or `None` after a loud skip; with `CI` set a
/// missing folder fails the test.
fn boucwen() -> Option<PathBuf> {
    let p = Path::new(env!("CARGO_MANIFEST_DIR")).join("../shared/data/boucwen_benchmark");
    nanomotion::core::data::shared_data_or_skip(&p, "data_cli (Bou-Wen benchmark)")
}

#[test]
fn boucwen_mat_pair_and_csv_give_the_same_comparison() {
    let Some(bw) = boucwen() else { return };
    let dir = tmp("boucwen");
    let model = |u: &str, y: &str| {
        format!(
            "base_rate_hz: 750\nduration_s: 1\nblocks:\n  - {{ name: u, type: data_column, column: {u} }}\n  - {{ name: g, type: gain, k: 1.0e-6 }}\nconnections:\n  - {{ from: u.y, to: g.u }}\ncompare:\n  - {{ signal: g.y, column: {y} }}\n"
        )
    };
    let m = write(&dir, "mat.yaml", &model("uval_multisine", "yval_multisine"));
    let o = nm()
        .arg("run")
        .arg(&m)
        .arg("--data")
        .arg(bw.join("uval_multisine.mat"))
        .arg("--data")
        .arg(bw.join("yval_multisine.mat"))
        .args(["--data-rate", "750", "--no-files"])
        .output()
        .unwrap();
    let mat_out = String::from_utf8_lossy(&o.stdout).into_owned();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let (code, csv_out, stderr) = run(
        &dir,
        &model("u_force_N", "y_disp_m"),
        &bw.join("bw_val_multisine.csv"),
    );
    assert_eq!(code, Some(0), "{stderr}");
    let row = |out: &str| -> Vec<String> {
        let line = out
            .lines()
            .find(|l| l.starts_with("g.y "))
            .unwrap()
            .to_string();
        line.split_whitespace()
            .skip(2)
            .map(str::to_string)
            .collect()
    };
    assert_eq!(row(&mat_out), row(&csv_out), "{mat_out}\n{csv_out}");
    assert!(mat_out.contains("8192 samples at 750 Hz"), "{mat_out}");
    std::fs::remove_dir_all(dir).ok();
}
