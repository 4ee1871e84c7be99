//! Reproducers of issue 13 that need the plugins or the binary: size parameters
//! of plugin blocks, output folders, and the CLI's edges.

use nanomotion::core::GraphError;
use nanomotion::core::graph::GraphSpec;
use std::path::{Path, PathBuf};
use std::process::Command;

fn build(yaml: &str) -> Result<(), String> {
    nanomotion::link_plugins();
    let spec = GraphSpec::from_yaml(yaml, "r.yaml").map_err(|e: GraphError| e.to_string())?;
    spec.build().map(|_| ()).map_err(|e| e.to_string())
}

/// A graph with one block `b` (block style, as users write it) fed by a
/// constant of width `in_width` into input `port`.
fn fed(block: &[&str], port: &str, in_width: usize) -> String {
    let mut s = format!(
        "base_rate_hz: 4000\nduration_s: 0.01\nblocks:\n  - {{ name: src, type: constant, value: 1.0, width: {in_width} }}\n  - name: b\n"
    );
    for kv in block {
        s.push_str(&format!("    {kv}\n"));
    }
    s.push_str(&format!(
        "connections:\n  - {{ from: src.y, to: b.{port} }}\n"
    ));
    s
}

#[test]
fn plugin_sizes_are_param_errors_not_aborts() {
    let cases: Vec<(String, &str)> = vec![
        (
            fed(&["type: repetitive_control", "n: 100000000000"], "e", 1),
            "`n`",
        ),
        (
            fed(&["type: high_order_rc", "n: 18446744073709551615"], "e", 1),
            "`n`",
        ),
        (
            fed(
                &[
                    "type: repetitive_control",
                    "n: 400",
                    "robustness: { kind: fir_lowpass, taps: 100000001, cutoff_hz: 200 }",
                ],
                "e",
                1,
            ),
            "robustness.taps",
        ),
        (
            fed(
                &[
                    "type: repetitive_control",
                    "n: 400",
                    "learning: { kind: fir, coefficients: [1.0], delay: 18446744073709551615 }",
                ],
                "e",
                1,
            ),
            "learning.delay",
        ),
        (
            fed(
                &[
                    "type: timestamp_encoder",
                    "lines: 1000000000000",
                    "derivatives: 0",
                ],
                "x",
                1,
            ),
            "`lines`",
        ),
        (
            fed(
                &["type: walking_piezo_fitted", "delay_s: 1e9"],
                "f_alpha",
                1,
            ),
            "`delay_s`",
        ),
    ];
    for (yaml, field) in cases {
        let e = build(&yaml).expect_err(&yaml);
        assert!(e.contains(field), "{yaml}\n-> {e}");
    }
    // dvrc has two inputs.
    let yaml = "base_rate_hz: 4000\nduration_s: 0.01\nblocks:\n  - { name: e, type: constant, value: 0.0 }\n  - name: b\n    type: dvrc\n    n_min: 10\n    n_max: 100000000000\nconnections:\n  - { from: e.y, to: b.e }\n  - { from: e.y, to: b.alpha }\n";
    let e = build(yaml).unwrap_err();
    assert!(e.contains("`n_max`"), "{e}");
    // The documented thesis values still build.
    build(&fed(&["type: walking_piezo_fitted"], "f_alpha", 1)).unwrap();
    // Item 4: 3 s at 4 kHz (12 000 samples) used to build a dense 12 000-state
    // model (61 s, 2.3 GB); now it is a ring buffer.
    build(&fed(
        &["type: walking_piezo_fitted", "delay_s: 3.0"],
        "f_alpha",
        1,
    ))
    .unwrap();
    build(&fed(
        &[
            "type: repetitive_control",
            "n: 400",
            "robustness: { kind: fir_lowpass, taps: 101, cutoff_hz: 220 }",
        ],
        "e",
        1,
    ))
    .unwrap();
}

// ---- the binary ------------------------------------------------------------------

fn nm(dir: &Path) -> Command {
    let mut c = Command::new(env!("CARGO_BIN_EXE_nanomotion"));
    c.current_dir(dir);
    c
}

fn out(c: &mut Command) -> (i32, String, String) {
    let o = c.output().expect("binary runs");
    (
        o.status.code().unwrap_or(-1),
        String::from_utf8_lossy(&o.stdout).into_owned(),
        String::from_utf8_lossy(&o.stderr).into_owned(),
    )
}

/// A fresh scratch folder with a small graph `g.yaml`.
fn scratch(tag: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("nm-rel-{tag}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    std::fs::write(dir.join("g.yaml"), SMALL).unwrap();
    dir
}

const SMALL: &str = r#"title: small
base_rate_hz: 1000
duration_s: 0.1
blocks:
  - { name: r, type: sinusoid, amplitude: 1.0, frequency_hz: 5.0 }
  - { name: k, type: gain, k: 2.0 }
connections:
  - { from: r.y, to: k.u }
log: [k.y]
score:
  - { signal: k.y, from_s: 0.01 }
"#;

#[test]
fn run_folders_default_per_graph_replace_runs_and_refuse_foreign_content() {
    let dir = scratch("folders");
    let (rc, _, e) = out(nm(&dir).args(["run", "g.yaml"]));
    assert_eq!(rc, 0, "{e}");
    let run = dir.join("out/g");
    assert!(run.join("metrics.json").exists() && run.join("nanomotion-run.json").exists());
    // A stale file of an earlier run does not survive the next run.
    std::fs::write(run.join("trace_old_y.svg"), "stale").unwrap();
    let (rc, _, e) = out(nm(&dir).args(["run", "g.yaml"]));
    assert_eq!(rc, 0, "{e}");
    assert!(!run.join("trace_old_y.svg").exists());
    // No temporary folder is left behind.
    let left: Vec<_> = std::fs::read_dir(dir.join("out"))
        .unwrap()
        .map(|e| e.unwrap().file_name())
        .collect();
    assert_eq!(left, vec![std::ffi::OsString::from("g")]);
    // A non-empty folder that is not a run is refused before running, then
    // replaced with --force.
    let foreign = dir.join("mine");
    std::fs::create_dir_all(&foreign).unwrap();
    std::fs::write(foreign.join("notes.txt"), "keep").unwrap();
    let (rc, so, e) = out(nm(&dir).args(["run", "g.yaml", "--out", "mine"]));
    assert_eq!(rc, 1);
    assert!(e.contains("--force") && e.contains("notes.txt"), "{e}");
    assert!(!so.contains("simulated"), "ran before refusing:\n{so}");
    assert!(foreign.join("notes.txt").exists());
    let (rc, _, e) = out(nm(&dir).args(["run", "g.yaml", "--out", "mine", "--force"]));
    assert_eq!(rc, 0, "{e}");
    assert!(!foreign.join("notes.txt").exists() && foreign.join("metrics.json").exists());
    // --out naming a file is reported before the simulation.
    std::fs::write(dir.join("afile"), "x").unwrap();
    let (rc, so, e) = out(nm(&dir).args(["run", "g.yaml", "--out", "afile"]));
    assert_eq!(rc, 1);
    assert!(e.contains("is a file") && !so.contains("simulated"), "{e}");
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn zero_duration_runs_and_writes_a_complete_folder() {
    let dir = scratch("zero");
    let (rc, _, e) = out(nm(&dir).args(["run", "g.yaml", "--duration", "0", "--out", "z"]));
    assert_eq!(rc, 0, "{e}");
    assert!(dir.join("z/nanomotion-run.json").exists() && dir.join("z/metrics.json").exists());
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn a_non_finite_run_fails_naming_block_and_tick_and_writes_nothing() {
    let dir = scratch("nonfinite");
    // An unstable discrete pole at z = 10 overflows to inf after about 308
    // ticks; `first` comes before it in execution order and is finite.
    let g = "base_rate_hz: 1000\nduration_s: 1.0\nblocks:\n  - { name: first, type: constant, value: 1.0 }\n  - { name: p, type: transfer_function, num: [1.0], den: [1.0, -10.0], discrete: true }\n  - { name: k, type: gain, k: 1.0 }\nconnections:\n  - { from: first.y, to: p.u }\n  - { from: p.y, to: k.u }\nlog: [k.y]\n";
    std::fs::write(dir.join("inf.yaml"), g).unwrap();
    let (rc, _, e) = out(nm(&dir).args(["run", "inf.yaml"]));
    assert_eq!(rc, 1, "{e}");
    assert!(
        e.contains("block `p` (type `transfer_function`)") && e.contains("base tick 310"),
        "{e}"
    );
    assert!(!dir.join("out/inf").exists());
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn cli_edges() {
    let dir = scratch("edges");
    // rc-check of a graph without repetitive control is an error, not "unstable".
    let (rc, _, e) = out(nm(&dir).args(["rc-check", "g.yaml"]));
    assert_eq!(rc, 1, "{e}");
    assert!(e.contains("nothing to check"), "{e}");
    // A filter that matches no block type says so.
    let (rc, _, e) = out(nm(&dir).args(["blocks", "zzz"]));
    assert_eq!(rc, 1);
    assert!(e.contains("no block type contains `zzz`"), "{e}");
    let (rc, _, e) = out(nm(&dir).args(["blocks", "dealy"]));
    assert_eq!(rc, 1);
    assert!(e.contains("did you mean delay"), "{e}");
    // A graph file that never ends is capped, not read until memory runs out.
    if Path::new("/dev/zero").exists() {
        let (rc, _, e) = out(nm(&dir).args(["check", "/dev/zero"]));
        assert_eq!(rc, 1);
        assert!(e.contains("larger than"), "{e}");
    }
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn a_closed_pipe_does_not_panic_and_files_are_still_written() {
    use std::io::Read as _;
    let dir = scratch("pipe");
    let mut child = nm(&dir)
        .args(["run", "g.yaml"])
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    // Close our end at once, as `| head -0` would.
    drop(child.stdout.take());
    let mut err = String::new();
    child
        .stderr
        .take()
        .unwrap()
        .read_to_string(&mut err)
        .unwrap();
    let status = child.wait().unwrap();
    assert!(status.success(), "{status}: {err}");
    assert!(!err.contains("panicked"), "{err}");
    assert!(dir.join("out/g/metrics.json").exists());
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn relative_calibration_file_resolves_against_the_graph_folder() {
    let dir = scratch("cal");
    let sub = dir.join("graphs");
    std::fs::create_dir_all(&sub).unwrap();
    let cal = nanomotion::hots::SlitCalibration {
        edge_offsets_counts: vec![0.0; 400],
        residual_rms_counts: 0.0,
        events: 0,
    };
    std::fs::write(sub.join("cal.json"), serde_json::to_string(&cal).unwrap()).unwrap();
    let g = "base_rate_hz: 1000\nduration_s: 0.01\nblocks:\n  - { name: x, type: sinusoid, amplitude: 1.0, frequency_hz: 1.0 }\n  - { name: enc, type: timestamp_encoder, derivatives: 0 }\n  - { name: est, type: hots_estimator, resolution: 0.015707963267948967, calibration_file: cal.json }\nconnections:\n  - { from: x.y, to: enc.x }\n  - { from: enc.register, to: est.register }\n";
    std::fs::write(sub.join("h.yaml"), g).unwrap();
    // Run from the parent folder: `cal.json` is next to the graph, not here.
    let (rc, so, e) = out(nm(&dir).args(["check", "graphs/h.yaml"]));
    assert_eq!(rc, 0, "{e}");
    assert!(so.contains("ok"), "{so}");
    std::fs::remove_dir_all(&dir).ok();
}

/// Run by `missing_shared_data_fails_under_ci_and_skips_visibly_otherwise` in a
/// child process; does nothing in a normal run.
#[test]
fn shared_data_child() {
    if std::env::var_os("NM_SHARED_DATA_CHILD").is_none() {
        return;
    }
    let got = nanomotion::core::data::shared_data_or_skip(
        Path::new("/nonexistent/shared/data/xyz"),
        "shared_data_child",
    );
    assert!(got.is_none());
}

#[test]
fn missing_shared_data_fails_under_ci_and_skips_visibly_otherwise() {
    let child = |ci: bool| {
        let mut c = Command::new(std::env::current_exe().unwrap());
        c.args(["--exact", "shared_data_child", "--test-threads=1"])
            .env("NM_SHARED_DATA_CHILD", "1")
            .env_remove("CI");
        if ci {
            c.env("CI", "true");
        }
        c.output().unwrap()
    };
    let o = child(false);
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(o.status.success(), "{err}");
    // Visible without --nocapture.
    assert!(err.contains("SKIPPED: shared_data_child"), "{err}");
    let o = child(true);
    assert!(!o.status.success(), "a missing data set passed under CI");
}

#[test]
fn verbose_and_rust_log_show_the_library_diagnostics() {
    let dir = scratch("trace");
    let g = SMALL.replace(
        "{ name: k, type: gain, k: 2.0 }",
        "{ name: k, type: gain, k: 2.0, rate_hz: 500 }",
    );
    std::fs::write(dir.join("g.yaml"), g).unwrap();
    let (rc, _, quiet) = out(nm(&dir).args(["check", "g.yaml"]).env_remove("RUST_LOG"));
    assert_eq!(rc, 0, "{quiet}");
    assert!(!quiet.contains("INFO"), "{quiet}");
    let (rc, _, e) = out(nm(&dir)
        .args(["-v", "check", "g.yaml"])
        .env_remove("RUST_LOG"));
    assert_eq!(rc, 0, "{e}");
    assert!(e.contains("INFO") && e.contains("rate transition"), "{e}");
    assert!(!e.contains('\u{1b}'), "colour codes in a pipe: {e}");
    let (rc, _, e) = out(nm(&dir)
        .args(["check", "g.yaml"])
        .env("RUST_LOG", "nanomotion_core=debug"));
    assert_eq!(rc, 0, "{e}");
    assert!(e.contains("DEBUG") && e.contains("execution order"), "{e}");
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn two_scores_of_one_signal_stay_apart_in_metrics() {
    let dir = scratch("scores");
    let g = SMALL.replace(
        "  - { signal: k.y, from_s: 0.01 }\n",
        "  - { signal: k.y, from_s: 0.01 }\n  - { signal: k.y, from_s: 0.05 }\n",
    );
    std::fs::write(dir.join("g.yaml"), g).unwrap();
    let (rc, _, e) = out(nm(&dir).args(["run", "g.yaml"]));
    assert_eq!(rc, 0, "{e}");
    let m: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("out/g/metrics.json")).unwrap())
            .unwrap();
    let ends = m["cumulative_psd_end"].as_array().unwrap();
    let froms: Vec<f64> = ends.iter().map(|e| e["from_s"].as_f64().unwrap()).collect();
    assert_eq!(froms, vec![0.01, 0.05]);
    let svg = std::fs::read_to_string(dir.join("out/g/cumulative_psd.svg")).unwrap();
    assert!(svg.contains("k.y from 0.01 s") && svg.contains("k.y from 0.05 s"));
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn writing_reports_progress_file_by_file() {
    nanomotion::link_plugins();
    let (mut s, report) = GraphSpec::from_yaml(SMALL, "g.yaml")
        .unwrap()
        .build()
        .unwrap();
    let result = s.run(|_| {});
    let dir = scratch("progress").join("o");
    let mut seen: Vec<(String, f64)> = Vec::new();
    nanomotion::output::write_all_with_progress(&dir, &result, &report.rate_transitions, |w, f| {
        seen.push((w.to_string(), f));
    })
    .unwrap();
    let names: Vec<&str> = seen.iter().map(|(w, _)| w.as_str()).collect();
    assert_eq!(
        names,
        [
            "signals CSV",
            "trace of k.y",
            "cumulative PSD",
            "metrics.json"
        ]
    );
    assert!(seen.windows(2).all(|w| w[0].1 < w[1].1 && w[1].1 < 1.0));
    std::fs::remove_dir_all(dir.parent().unwrap()).ok();
}
