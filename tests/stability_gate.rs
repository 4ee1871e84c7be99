//! The stability gate through the facade (issue 17): every shipped example passes
//! it or states why it may run unproven; `nanomotion check` names the loop and the
//! violated bound and fails; `nanomotion run` (and `rt`) refuses an unstable graph unless
//! `--allow-unproven`, and then says so.

use nanomotion::core::data::Dataset;
use nanomotion::core::gate;
use nanomotion::core::graph::GraphSpec;
use std::path::{Path, PathBuf};
use std::process::Command;

/// Every `.yaml` under examples/, at any depth (examples/compensate/position_ripple/…).
fn graphs() -> Vec<PathBuf> {
    fn walk(dir: &Path, v: &mut Vec<PathBuf>) {
        for e in std::fs::read_dir(dir).unwrap() {
            let p = e.unwrap().path();
            if p.is_dir() {
                walk(&p, v);
            } else if p.extension().is_some_and(|x| x == "yaml") {
                v.push(p);
            }
        }
    }
    let mut v = Vec::new();
    walk(
        &Path::new(env!("CARGO_MANIFEST_DIR")).join("examples"),
        &mut v,
    );
    v.sort();
    v
}

#[test]
fn every_shipped_example_passes_the_gate_or_says_why_not() {
    nanomotion::link_plugins();
    let (mut analysed, mut with_loops, mut proven) = (0, 0, 0);
    for path in graphs() {
        // Configuration files of other commands (optimize-waveform) are not graphs.
        let Ok(spec) = GraphSpec::from_file(&path) else {
            continue;
        };
        let require = spec.require.clone().unwrap_or_default();
        // Graphs that play measured columns get zeros in those columns (the
        // gate needs the built blocks, not the data).
        let text = std::fs::read_to_string(&path).unwrap();
        let mut columns: Vec<String> = text
            .split("column:")
            .skip(1)
            .filter_map(|rest| {
                rest.split(|c: char| !(c.is_alphanumeric() || c == '_'))
                    .find(|w| !w.is_empty())
                    .map(str::to_string)
            })
            .collect();
        columns.sort();
        columns.dedup();
        let built = if columns.is_empty() {
            spec.build()
        } else {
            // The data must be sampled at the playing block's rate: try the
            // rates the file names.
            let rates: Vec<f64> = std::iter::once(spec.base_rate_hz)
                .chain(text.split("rate_hz:").skip(1).filter_map(|r| {
                    r.split([',', '}', '\n'])
                        .next()
                        .and_then(|v| v.trim().parse().ok())
                }))
                .collect();
            let duration = spec.duration_s;
            let mut result = spec.build();
            for rate in rates {
                let n = (duration * rate).ceil() as usize + 2;
                let cols = columns.iter().map(|c| (c.clone(), vec![0.0; n])).collect();
                let data = Dataset::from_columns("zeros", rate, 0.0, cols).unwrap();
                result = GraphSpec::from_file(&path)
                    .unwrap()
                    .build_with_data(std::sync::Arc::new(data));
                if result.is_ok() {
                    break;
                }
            }
            result
        };
        let (sched, _) = built.unwrap_or_else(|e| panic!("{}: {e}", path.display()));
        let report = gate::analyse(&sched, &require);
        assert!(report.passes(), "{}:\n{report}", path.display());
        analysed += 1;
        if !report.loops.is_empty() {
            with_loops += 1;
        }
        if !report.loops.is_empty() && report.proven() {
            proven += 1;
        }
        for l in &report.loops {
            if !l.unproven.is_empty() {
                let why = l.allowed.as_deref().unwrap_or("");
                assert!(
                    why.len() > 20,
                    "{}: loop `{}` runs unproven without a reason",
                    path.display(),
                    l.name
                );
            }
        }
    }
    assert!(analysed >= 10, "found {analysed} example graphs");
    assert!(
        with_loops >= 7 && proven >= 1,
        "{with_loops} with loops, {proven} proven"
    );
}

fn nm() -> Command {
    let mut c = Command::new(env!("CARGO_BIN_EXE_nanomotion"));
    c.current_dir(env!("CARGO_MANIFEST_DIR"));
    c
}

fn out(c: &mut Command) -> (Option<i32>, String, String) {
    let o = c.output().expect("binary runs");
    (
        o.status.code(),
        String::from_utf8_lossy(&o.stdout).into_owned(),
        String::from_utf8_lossy(&o.stderr).into_owned(),
    )
}

/// quickstart.yaml with its PI gain times `factor` and a `require:` section.
fn quickstart_variant(dir: &Path, name: &str, factor: f64, require: &str) -> PathBuf {
    let text = std::fs::read_to_string(
        Path::new(env!("CARGO_MANIFEST_DIR")).join("examples/quickstart.yaml"),
    )
    .unwrap();
    let kp = 3.1416e7 * factor;
    let text = text
        .replace("kp: 3.1416e7", &format!("kp: {kp:e}"))
        .replace("seed: 1\n", &format!("seed: 1\n{require}\n"))
        .replace("from_s: 0.5", "from_s: 0.0");
    let p = dir.join(name);
    std::fs::write(&p, text).unwrap();
    p
}

#[test]
fn check_and_run_obey_the_gate() {
    let dir = std::env::temp_dir().join(format!("nm-gate-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    // The shipped quickstart: a table with the loop, judged on linearisations.
    let (code, stdout, stderr) = out(nm().args(["check", "examples/quickstart.yaml"]));
    assert_eq!(code, Some(0), "{stderr}");
    assert!(
        stdout.contains("stability gate: 1 feedback loop") && stdout.contains("ok (linearised)"),
        "{stdout}"
    );
    // A bound it misses: PM ≈ 78° (see the table) against 85° required.
    let g = quickstart_variant(&dir, "pm.yaml", 1.0, "require: { phase_margin_deg: 85 }");
    let (code, _, stderr) = out(nm().arg("check").arg(&g));
    assert_eq!(code, Some(1));
    assert!(
        stderr.contains("loop `pi`") && stderr.contains("phase_margin_deg"),
        "{stderr}"
    );
    // Ten times the gain: unstable, refused by check and run, named.
    let g = quickstart_variant(&dir, "hot.yaml", 10.0, "");
    let (code, _, stderr) = out(nm().arg("check").arg(&g));
    assert_eq!(code, Some(1));
    assert!(stderr.contains("loop `pi` is unstable"), "{stderr}");
    let (code, _, stderr) = out(nm().arg("run").arg(&g).arg("--no-files"));
    assert_eq!(code, Some(1));
    assert!(
        stderr.contains("--allow-unproven") && stderr.contains("unstable"),
        "{stderr}"
    );
    // With the flag it runs (0.05 s: the divergence stays finite) and says so.
    let (code, stdout, stderr) =
        out(nm()
            .arg("run")
            .arg(&g)
            .args(["--no-files", "--allow-unproven", "--duration", "0.05"]));
    assert_eq!(code, Some(0), "{stderr}");
    assert!(
        stdout.contains("running anyway because of --allow-unproven")
            && stdout.contains("unstable"),
        "{stdout}"
    );
    // With files, the run folder's manifest says so too.
    let run_dir = dir.join("run");
    let (code, _, stderr) = out(nm().arg("run").arg(&g).arg("--out").arg(&run_dir).args([
        "--allow-unproven",
        "--duration",
        "0.05",
    ]));
    assert_eq!(code, Some(0), "{stderr}");
    let manifest: serde_json::Value = serde_json::from_str(
        &std::fs::read_to_string(run_dir.join("nanomotion-run.json")).unwrap(),
    )
    .unwrap();
    let gate_lines = manifest["stability_gate"]
        .as_array()
        .expect("stability_gate");
    assert!(
        gate_lines
            .iter()
            .any(|l| l.as_str().unwrap_or("").contains("--allow-unproven")),
        "{manifest}"
    );
    // `rt` judges the graph the same way before the loop drives anything: an
    // unstable graph never starts on the wall clock, and with the flag it runs
    // and says so first, in its report and in the run folder's manifest.
    let rt = |extra: &[&str]| {
        out(nm()
            .arg("rt")
            .arg(&g)
            .args(["--allow-soft", "--duration", "0.01"])
            .args(extra))
    };
    let (code, stdout, stderr) = rt(&[]);
    assert_eq!(code, Some(1));
    assert!(
        stderr.contains("--allow-unproven") && stderr.contains("loop `pi` is unstable"),
        "{stderr}"
    );
    assert!(!stdout.contains("ticks at"), "the loop started: {stdout}");
    let rt_dir = dir.join("rt");
    let (code, stdout, stderr) = rt(&["--allow-unproven", "--out", rt_dir.to_str().unwrap()]);
    assert_eq!(code, Some(0), "{stderr}");
    let (said, started) = (
        stdout
            .find("running anyway because of --allow-unproven")
            .expect(&stdout),
        stdout.find("ticks at").expect(&stdout),
    );
    assert!(said < started, "{stdout}");
    let manifest: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(rt_dir.join("nanomotion-run.json")).unwrap())
            .unwrap();
    assert!(
        manifest["stability_gate"]
            .as_array()
            .expect("stability_gate")
            .iter()
            .any(|l| l.as_str().unwrap_or("").contains("unstable")),
        "{manifest}"
    );
    std::fs::remove_dir_all(&dir).ok();
}

/// The gate's learning criterion for a graph file's text, and rc-check's (whose T
/// comes from the block's `t_model`, not from the loop).
fn learning_both(text: &str) -> (gate::GateReport, nanomotion::dvrc::check::RcCheckReport) {
    nanomotion::link_plugins();
    let spec = GraphSpec::from_yaml(text, "rc").unwrap();
    let rc = nanomotion::dvrc::check::rc_check_graph(&GraphSpec::from_yaml(text, "rc").unwrap());
    let require = spec.require.clone().unwrap_or_default();
    let (sched, _) = spec.build().unwrap();
    (gate::analyse(&sched, &require), rc)
}

#[test]
fn learning_blocks_are_judged_by_their_criterion_with_the_loops_t() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("examples");
    for (file, criterion) in [("rc_standard.yaml", "(5.5)"), ("rc_dvrc.yaml", "(5.9)")] {
        let text = std::fs::read_to_string(root.join(file)).unwrap();
        let (g, rc) = learning_both(&text);
        assert!(g.passes() && g.proven(), "{file}:\n{g}");
        let c = &g.loops[0].points[0].learning[0];
        assert_eq!(c.criterion(), criterion);
        // T assembled from the loop (gain, stage, sums) equals the declared
        // t_model: the same ‖H‖∞ as rc-check.
        let rc_hinf = rc.blocks[0].criterion.as_ref().unwrap().hinf;
        assert!(
            (c.hinf - rc_hinf).abs() < 1e-9 * rc_hinf,
            "{} vs {rc_hinf}",
            c.hinf
        );
    }
    // Widening the DVRC delay range to [150, 400] lowers the bound of (5.9) to
    // 1/√251 = 0.063 < ‖H‖∞ = 0.091: refused, naming the block and the criterion.
    let text = std::fs::read_to_string(root.join("rc_dvrc.yaml"))
        .unwrap()
        .replace("n_max: 250", "n_max: 400");
    let (g, rc) = learning_both(&text);
    assert!(!rc.all_hold());
    assert!(!g.passes());
    let f = g.failures().join("\n");
    assert!(f.contains("learning block `rc` violates (5.9)"), "{f}");
    // ‖Q‖∞ ≈ 1 is above the bound 0.063: a lower learning gain cannot fix it
    // (audit, "smaller issues": the hint said so).
    assert!(
        f.contains("lowering the learning gain cannot help")
            && !f.contains("fix: lower the learning gain"),
        "{f}"
    );
    // A learning filter inverting a T four times too small (L·T ≈ 4, so
    // |1 − T L| ≈ 3) breaks (5.5) for the standard RC, as rc-check (with the
    // declared t_model) also finds.
    let text = std::fs::read_to_string(root.join("rc_standard.yaml"))
        .unwrap()
        .replace(
            "learning: { kind: zpetc, num: [0.22]",
            "learning: { kind: zpetc, num: [0.05]",
        );
    let (g, rc) = learning_both(&text);
    let c = &g.loops[0].points[0].learning[0];
    let rc_c = rc.blocks[0].criterion.as_ref().unwrap();
    assert!((c.hinf - rc_c.hinf).abs() < 1e-9 * rc_c.hinf);
    assert!(!c.holds() && !rc_c.holds(), "{c}");
    assert!(g.failures().join("\n").contains("violates (5.5)"));
}
