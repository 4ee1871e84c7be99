//! Reproducers of issue 25 (audit defects-ae8dad2) about measured data, `check`,
//! `scan-image` and the graph memory bound, run through the binary or the
//! plugins: D1, D3, D4, D6, D17, D18, D19, D20 and the `duration_s` default.

use nanomotion::core::graph::GraphSpec;
use std::path::{Path, PathBuf};
use std::process::{Command, Output};

fn nm(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_nanomotion"))
        .args(args)
        .current_dir(env!("CARGO_MANIFEST_DIR"))
        .output()
        .unwrap()
}

fn text(o: &Output) -> String {
    format!(
        "{}{}",
        String::from_utf8_lossy(&o.stdout),
        String::from_utf8_lossy(&o.stderr)
    )
}

/// `run` of the data-replay example on the record `csv`, writing no files.
fn replay(csv: &Path) -> Output {
    nm(&[
        "run",
        "examples/data_replay/model.yaml",
        "--data",
        csv.to_str().unwrap(),
        "--no-files",
    ])
}

fn scratch(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("nm-hostile-data-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    d
}

/// The replay record with its measured column (or one input value) replaced.
fn record_with(dir: &Path, name: &str, edit: impl Fn(usize, &mut Vec<String>)) -> PathBuf {
    let text = std::fs::read_to_string(
        Path::new(env!("CARGO_MANIFEST_DIR")).join("examples/data_replay/record.csv"),
    )
    .unwrap();
    let mut out = String::new();
    let mut row = 0;
    for line in text.lines().filter(|l| !l.starts_with('#')) {
        if line.starts_with("t_s") {
            out.push_str(line);
        } else {
            let mut f: Vec<String> = line.split(',').map(str::to_string).collect();
            edit(row, &mut f);
            row += 1;
            out.push_str(&f.join(","));
        }
        out.push('\n');
    }
    let p = dir.join(name);
    std::fs::write(&p, out).unwrap();
    p
}

/// D1: a stuck sensor printed a fit of −5.6e17 % with exit 0.
#[test]
fn run_refuses_a_constant_measured_column() {
    let d = scratch("const");
    let csv = record_with(&d, "const_col.csv", |_, f| f[2] = "1e-6".into());
    let o = replay(&csv);
    let t = text(&o);
    assert_eq!(o.status.code(), Some(1), "{t}");
    assert!(
        t.contains("column `y_pos_m`") && t.contains("constant"),
        "{t}"
    );
    assert!(
        !t.lines().any(|l| l.starts_with("stage.y ")),
        "no scores: {t}"
    );
    let _ = std::fs::remove_dir_all(&d);
}

/// D18: one input sample of 1e308 gave rms = inf, fit % = −inf and exit 0.
#[test]
fn run_refuses_scores_that_overflow() {
    let d = scratch("huge");
    let csv = record_with(&d, "huge_val.csv", |row, f| {
        if row == 100 {
            f[1] = "1e308".into();
        }
    });
    let o = replay(&csv);
    let t = text(&o);
    assert_eq!(o.status.code(), Some(1), "{t}");
    assert!(
        t.contains("overflow") && t.contains("corrupt sample"),
        "{t}"
    );
    assert!(!t.contains("inf "), "{t}");
    let _ = std::fs::remove_dir_all(&d);
}

/// D3: `check` refused every graph with `data_column` and had no `--data`.
#[test]
fn check_validates_graphs_that_read_data() {
    let o = nm(&["check", "examples/data_replay/model.yaml"]);
    let t = text(&o);
    assert!(o.status.success(), "{t}");
    assert!(
        t.contains("placeholder 0") && t.contains("--data FILE"),
        "{t}"
    );
    let o = nm(&[
        "check",
        "examples/data_replay/model.yaml",
        "--data",
        "examples/data_replay/record.csv",
    ]);
    let t = text(&o);
    assert!(o.status.success(), "{t}");
    assert!(t.contains("2001 ticks") || t.contains("2000 ticks"), "{t}");
    // A wiring error is found without data.
    let d = scratch("wiring");
    let g = d.join("bad_port.yaml");
    let model = std::fs::read_to_string(
        Path::new(env!("CARGO_MANIFEST_DIR")).join("examples/data_replay/model.yaml"),
    )
    .unwrap();
    std::fs::write(&g, model.replace("to: stage.u", "to: stage.uu")).unwrap();
    let o = nm(&["check", g.to_str().unwrap()]);
    let t = text(&o);
    assert_eq!(o.status.code(), Some(1), "{t}");
    assert!(
        t.contains("uu") && !t.contains("no data is attached"),
        "{t}"
    );
    // A wrong column is found with data.
    std::fs::write(&g, model.replace("column: u_force_N", "column: u_force")).unwrap();
    let o = nm(&[
        "check",
        g.to_str().unwrap(),
        "--data",
        "examples/data_replay/record.csv",
    ]);
    let t = text(&o);
    assert_eq!(o.status.code(), Some(1), "{t}");
    assert!(t.contains("`u_force` is not a column"), "{t}");
    let _ = std::fs::remove_dir_all(&d);
}

/// D17: `run --data` on a graph that reads no data silently ran for the data's
/// length.
#[test]
fn data_for_a_graph_that_reads_none_is_refused() {
    let o = nm(&[
        "run",
        "examples/quickstart.yaml",
        "--data",
        "examples/diagnose/record.csv",
        "--no-files",
    ]);
    let t = text(&o);
    assert_eq!(o.status.code(), Some(1), "{t}");
    assert!(
        t.contains("reads no data") && t.contains("drop --data"),
        "{t}"
    );
    assert!(!t.contains("simulated"), "{t}");
}

/// A graph that reads data may leave `duration_s` out: it runs for the data.
#[test]
fn a_graph_that_reads_data_takes_the_data_length_when_duration_is_absent() {
    let model = std::fs::read_to_string(
        Path::new(env!("CARGO_MANIFEST_DIR")).join("examples/data_replay/model.yaml"),
    )
    .unwrap();
    let without: String = model
        .lines()
        .filter(|l| !l.starts_with("duration_s"))
        .map(|l| format!("{l}\n"))
        .collect();
    let data = std::sync::Arc::new(
        nanomotion::core::data::Dataset::from_file(
            Path::new(env!("CARGO_MANIFEST_DIR")).join("examples/data_replay/record.csv"),
        )
        .unwrap(),
    );
    nanomotion::link_plugins();
    let spec = GraphSpec::from_yaml(&without, "m.yaml").unwrap();
    assert!(spec.reads_data());
    let (sched, _) = spec.build_with_data(data.clone()).unwrap();
    let expected = (data.duration_s() * 1000.0).round() as u64;
    assert_eq!(sched.ticks_total(), expected);
    // Without data, the missing duration is named.
    let e = GraphSpec::from_yaml(&without, "m.yaml")
        .unwrap()
        .build()
        .err()
        .unwrap()
        .to_string();
    assert!(e.contains("duration_s") && e.contains("missing"), "{e}");
}

/// D4: two 16 385-tap FIR filters cost 4.2 GB and 29 s in `check`.
#[test]
fn long_fir_filters_build_without_a_dense_model() {
    let yaml = "base_rate_hz: 1000\nduration_s: 0.01\nblocks:\n  - { name: c, type: constant, value: 1.0 }\n  - { name: a, type: constant, value: 0.0 }\n  - { name: f0, type: dvrc, n_min: 20000, n_max: 20001, robustness: { kind: fir_lowpass, taps: 16385, cutoff_hz: 100.0 } }\n  - { name: f1, type: dvrc, n_min: 20000, n_max: 20001, robustness: { kind: fir_lowpass, taps: 16385, cutoff_hz: 100.0 } }\nconnections:\n  - { from: c.y, to: f0.e }\n  - { from: a.y, to: f0.alpha }\n  - { from: c.y, to: f1.e }\n  - { from: a.y, to: f1.alpha }\n";
    nanomotion::link_plugins();
    let start = std::time::Instant::now();
    let (sched, _) = GraphSpec::from_yaml(yaml, "fir2.yaml")
        .unwrap()
        .build()
        .unwrap();
    assert!(start.elapsed().as_secs_f64() < 5.0, "{:?}", start.elapsed());
    let bytes: usize = ["f0", "f1"]
        .iter()
        .map(|n| sched.block(n).unwrap().memory_bytes())
        .sum();
    assert!(bytes < 16 << 20, "{bytes} bytes");
}

/// D6: 40 delays of 2^24 samples allocated 4.1 GiB before the bound was
/// checked; the bound is now checked by each block before it allocates.
#[test]
fn the_memory_bound_is_checked_before_the_delay_lines_are_allocated() {
    let mut yaml = String::from(
        "base_rate_hz: 1000\nduration_s: 0.01\nblocks:\n  - { name: c, type: constant, value: 1.0 }\n",
    );
    for i in 0..40 {
        yaml.push_str(&format!("  - {{ name: d{i}, type: delay, d: 16777216 }}\n"));
    }
    yaml.push_str("connections:\n");
    for i in 0..40 {
        yaml.push_str(&format!("  - {{ from: c.y, to: d{i}.u }}\n"));
    }
    let e = GraphSpec::from_yaml(&yaml, "delays.yaml")
        .unwrap()
        .build()
        .err()
        .unwrap()
        .to_string();
    assert!(e.contains("block `d32`") && e.contains("field `d`"), "{e}");
    assert!(e.contains("checked before anything is allocated"), "{e}");
}

/// D19 and D20: `scan-image` on a multi-rate run, with names without units;
/// `--pixels` and `--from-s` checked.
#[test]
fn scan_image_reads_multi_rate_runs_and_plain_names() {
    let d = scratch("scan");
    let out = d.join("q");
    let o = nm(&[
        "run",
        "examples/quickstart.yaml",
        "--out",
        out.to_str().unwrap(),
        "--duration",
        "0.05",
        "--set",
        "score.0.from_s=0.01",
        "--set",
        "score.1.from_s=0.01",
    ]);
    assert!(o.status.success(), "{}", text(&o));
    assert!(
        !out.join("signals.csv").exists(),
        "quickstart is multi-rate"
    );
    let csvs: Vec<String> = std::fs::read_dir(&out)
        .unwrap()
        .filter_map(Result::ok)
        .map(|e| e.file_name().to_string_lossy().into_owned())
        .filter(|n| n.starts_with("signals_"))
        .collect();
    assert!(csvs.len() >= 2, "{csvs:?}");
    // Columns of the stage's rate, named without their units.
    let header =
        std::fs::read_to_string(out.join(csvs.iter().find(|n| n.contains("40000")).unwrap()))
            .unwrap()
            .lines()
            .next()
            .unwrap()
            .to_string();
    let names: Vec<&str> = header
        .split(',')
        .skip(1)
        .map(|h| h.split(" (").next().unwrap())
        .collect();
    assert!(names.len() >= 2, "{header}");
    let spec = format!("a={},{},{}", names[0], names[1], names[0]);
    let o = nm(&["scan-image", out.to_str().unwrap(), "--image", &spec]);
    assert!(o.status.success(), "{}", text(&o));
    assert!(out.join("a.svg").exists());
    for (args, want) in [
        (
            vec!["--pixels", "100000", "100000"],
            "--pixels 100000 100000",
        ),
        (vec!["--from-s", "nan"], "--from-s NaN"),
    ] {
        let mut all = vec!["scan-image", out.to_str().unwrap(), "--image", &spec];
        all.extend(args);
        let o = nm(&all);
        let t = text(&o);
        assert_eq!(o.status.code(), Some(1), "{t}");
        assert!(t.contains(want) && t.contains("fix:"), "{t}");
    }
    let _ = std::fs::remove_dir_all(&d);
}

/// The learning design loop (issue 25, "also from the same trial"): `rc-check`
/// refused a block without `t_model` although `check` assembles T itself; now it
/// takes T from the graph's loop, and `check --print-loop` prints it to paste.
#[test]
fn rc_check_takes_t_from_the_graph_and_check_prints_it() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let graph = std::fs::read_to_string(root.join("examples/rc_standard.yaml"))
        .unwrap()
        .replace(
            "learning: { kind: zpetc, num: [0.22], den: [1.0, -0.8] }",
            "learning: { kind: identity }",
        );
    assert!(graph.contains("kind: identity"));
    let d = scratch("rc");
    let with_t = d.join("with_t.yaml");
    std::fs::write(&with_t, &graph).unwrap();
    let without_t = d.join("without_t.yaml");
    std::fs::write(
        &without_t,
        graph.replace(
            "    t_model: { num: [0.2], den: [1.0, -0.8] }   # the true T, for rc-check\n",
            "",
        ),
    )
    .unwrap();
    nanomotion::link_plugins();
    let declared = nanomotion::dvrc::check::rc_check_file(&with_t).unwrap();
    let from_graph = nanomotion::dvrc::check::rc_check_file(&without_t).unwrap();
    let (a, b) = (
        declared.blocks[0].criterion.as_ref().unwrap().hinf,
        from_graph.blocks[0].criterion.as_ref().unwrap().hinf,
    );
    assert!((a - b).abs() < 1e-9 * a, "{a} vs {b}");
    // Without the graph's T (the old path) the block is refused.
    let spec = GraphSpec::from_file(&without_t).unwrap();
    let old = nanomotion::dvrc::check::rc_check_graph(&spec);
    assert!(
        old.blocks[0]
            .criterion
            .as_ref()
            .unwrap_err()
            .contains("no T(z)")
    );
    // `check --print-loop` prints T to paste as `t_model:`: 0.2/(z − 0.8).
    let o = nm(&["check", "examples/rc_standard.yaml", "--print-loop"]);
    let t = text(&o);
    assert!(o.status.success(), "{t}");
    for key in ["    L: {", "    S: {", "    T: {", "      - block: rc"] {
        assert!(t.contains(key), "{key}: {t}");
    }
    let line = t
        .lines()
        .find(|l| l.trim_start().starts_with("t_model:"))
        .unwrap();
    let tf: nanomotion::dvrc::rc::TfModel =
        nanomotion::core::yaml::from_str(line.trim_start().trim_start_matches("t_model:"), "t")
            .unwrap();
    for w in [0.1, 1.0, 2.5] {
        let z = nanomotion::core::lti::Complex::from_polar(1.0, w);
        let ev = |c: &[f64]| {
            c.iter()
                .fold(nanomotion::core::lti::Complex::new(0.0, 0.0), |a, &x| {
                    a * z + x
                })
        };
        let got = ev(&tf.num) / ev(&tf.den);
        let want = nanomotion::core::lti::Complex::new(0.2, 0.0) / (z - 0.8);
        assert!(
            (got - want).norm() < 1e-9 * want.norm(),
            "{w}: {got} vs {want}"
        );
    }
    let _ = std::fs::remove_dir_all(&d);
}
