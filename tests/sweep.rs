//! `nanomotion::sweep`: deterministic plans, Latin-hypercube strata, resume,
//! failed runs as error rows, and the CSV ↔ Parquet table.

use nanomotion::core::{Block, Port, Tick};
use nanomotion::sweep::{
    Kind, Plan, RunOptions, Study, SweepError, erfc, read_parquet_table, run_study,
};
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};

const QUICKSTART: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/examples/quickstart.yaml");

/// A block that panics when its input exceeds `limit`: a stand-in for a bug in
/// a block, to show the sweep survives it.
#[derive(Debug, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
struct PanicAbove {
    limit: f64,
}

#[typetag::serde(name = "sweep_test_panic_above")]
impl Block for PanicAbove {
    fn inputs(&self) -> Vec<Port> {
        vec![Port::new("u", 1)]
    }
    fn outputs(&self) -> Vec<Port> {
        vec![Port::new("y", 1)]
    }
    fn output(&mut self, _t: Tick, u: &[f64], y: &mut [f64]) {
        assert!(u[0] <= self.limit, "input {} above {}", u[0], self.limit);
        y[0] = u[0];
    }
}

fn dir(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("nm-sweep-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    d
}

/// A study of the quickstart (0.6 s per run, scored from 0.5 s).
fn study(body: &str) -> Study {
    nanomotion::link_plugins();
    let text = format!("graph: {QUICKSTART}\nset: {{ duration_s: 0.6 }}\n{body}");
    Study::from_yaml(&text, "test.yaml", Path::new(".")).unwrap()
}

const MC: &str = "study: monte-carlo\nruns: 12\nseed: 5\nparameters:\n  - { path: blocks.stage.den.0, normal: { mean: 0.255, std: 0.01 } }\n  - { path: blocks.stage.num.1, lognormal: { median: 13.3135, sigma: 0.1 } }\n  - { path: blocks.pi.zero_hz, values: [2.0, 4.0] }\n";

#[test]
fn the_same_study_gives_the_same_plan_bit_for_bit() {
    let a = study(MC).plan();
    let b = study(MC).plan();
    assert_eq!(
        serde_json::to_string(&a).unwrap(),
        serde_json::to_string(&b).unwrap()
    );
    assert_eq!(a.len(), 12);
    // The plan survives JSON exactly (float_roundtrip).
    let back: Plan = serde_json::from_str(&serde_json::to_string(&a).unwrap()).unwrap();
    assert_eq!(back, a);
    // Another sampling seed, another plan (and hash).
    let c = study(&MC.replace("seed: 5", "seed: 6")).plan();
    assert_ne!(c.runs().collect::<Vec<_>>(), a.runs().collect::<Vec<_>>());
    assert_ne!(c.study_hash, a.study_hash);
    // Draws follow their distributions: the mass around 0.255 within 6 σ.
    for r in a.runs() {
        let m = r.parameters[0].value.as_f64().unwrap();
        assert!((m - 0.255).abs() < 0.06, "{m}");
    }
}

#[test]
fn grid_is_the_cartesian_product_with_seeds_innermost() {
    let s = study(
        "study: grid\nseeds: [1, 2]\nparameters:\n  - { path: blocks.pi.kp, range: [1.0e7, 1.0e9], steps: 3, log: true }\n  - { path: blocks.pi.zero_hz, values: [2.0, 4.0] }\n",
    );
    let p = s.plan();
    assert_eq!(p.len(), 3 * 2 * 2);
    let kp: Vec<f64> = p
        .runs()
        .map(|r| r.parameters[0].value.as_f64().unwrap())
        .collect();
    // Log spacing: 1e7, 1e8, 1e9 (to rounding of powf).
    for (k, want) in [1e7, 1e8, 1e9].iter().enumerate() {
        assert!((kp[4 * k] - want).abs() < 1e-9 * want, "{kp:?}");
    }
    assert_eq!(p.run(0).unwrap().seed, Some(1));
    assert_eq!(p.run(1).unwrap().seed, Some(2));
    assert_eq!(
        p.run(2).unwrap().parameters[1].value,
        serde_json::json!(4.0)
    );
}

/// Each dimension's values, mapped back to probabilities (the range by plain
/// arithmetic, the normal by Φ from erfc, itself checked against tabulated values
/// in the unit tests), fall once into each of the n equal strata.
#[test]
fn latin_hypercube_hits_every_stratum_once_per_dimension() {
    for (n, seed) in [(1usize, 1u64), (7, 2), (50, 3), (200, 4)] {
        let s = study(&format!(
            "study: latin-hypercube\nruns: {n}\nseed: {seed}\nparameters:\n  - {{ path: blocks.pi.kp, range: [1.0e7, 5.0e7] }}\n  - {{ path: blocks.stage.den.0, normal: {{ mean: 0.255, std: 0.01 }} }}\n  - {{ path: blocks.pi.zero_hz, range: [1.0, 100.0], log: true }}\n"
        ));
        let p = s.plan();
        assert_eq!(p.kind, Kind::LatinHypercube);
        let strata = |f: &dyn Fn(f64) -> f64, k: usize| {
            let mut hit = vec![0usize; n];
            for r in p.runs() {
                let u = f(r.parameters[k].value.as_f64().unwrap());
                hit[((u * n as f64) as usize).min(n - 1)] += 1;
            }
            hit
        };
        let ones = vec![1usize; n];
        assert_eq!(strata(&|x| (x - 1e7) / 4e7, 0), ones, "kp, n {n}");
        assert_eq!(
            strata(
                &|x| 0.5 * erfc(-(x - 0.255) / 0.01 / std::f64::consts::SQRT_2),
                1
            ),
            ones,
            "mass, n {n}"
        );
        assert_eq!(strata(&|x| x.log10() / 2.0, 2), ones, "zero_hz, n {n}");
    }
}

fn read_csv(path: &Path) -> (Vec<String>, Vec<Vec<String>>) {
    let mut r = csv::Reader::from_path(path).unwrap();
    let header = r.headers().unwrap().iter().map(String::from).collect();
    let rows = r
        .records()
        .map(|x| x.unwrap().iter().map(String::from).collect())
        .collect();
    (header, rows)
}

/// The table without its wall-time column (the only thing that differs
/// between two computations of the same study).
fn without_wall(t: (Vec<String>, Vec<Vec<String>>)) -> (Vec<String>, Vec<Vec<String>>) {
    let w = t.0.iter().position(|h| h == "wall_s").unwrap();
    let strip = |v: &Vec<String>| {
        let mut v = v.clone();
        v.remove(w);
        v
    };
    (strip(&t.0), t.1.iter().map(strip).collect())
}

#[test]
fn a_killed_study_resumes_computing_only_the_rest_and_ends_identical() {
    let s = study(MC);
    let full = dir("full");
    let sum = run_study(
        &s,
        &full,
        &RunOptions {
            jobs: 2,
            ..Default::default()
        },
    )
    .unwrap();
    assert_eq!(
        (sum.planned, sum.resumed, sum.computed, sum.failed),
        (12, 0, 12, 0)
    );

    let part = dir("part");
    let opts = |limit| RunOptions {
        jobs: 1,
        limit,
        ..Default::default()
    };
    let first = run_study(&s, &part, &opts(Some(5))).unwrap();
    assert_eq!((first.resumed, first.computed), (0, 5));
    // A kill in the middle of writing a row leaves half a line: it is dropped.
    let rows = part.join("rows.jsonl");
    let mut text = std::fs::read_to_string(&rows).unwrap();
    assert_eq!(text.lines().count(), 5);
    text.push_str("{\"study\":\"");
    std::fs::write(&rows, text).unwrap();
    let second = run_study(&s, &part, &opts(None)).unwrap();
    assert_eq!((second.resumed, second.computed), (5, 7));
    assert_eq!(std::fs::read_to_string(&rows).unwrap().lines().count(), 12);
    // Nothing left: a third run computes nothing.
    let third = run_study(&s, &part, &opts(None)).unwrap();
    assert_eq!((third.resumed, third.computed), (12, 0));
    // Same table, bit for bit, whatever the jobs and the interruption.
    let a = without_wall(read_csv(&full.join("results.csv")));
    let b = without_wall(read_csv(&part.join("results.csv")));
    assert_eq!(a, b);
    assert_eq!(a.1.len(), 12);
    assert!(
        a.1.iter().all(|r| r.last().unwrap().is_empty()),
        "no errors"
    );

    // A changed study is refused in the same folder, and --restart starts over.
    let changed = study(&MC.replace("runs: 12", "runs: 13"));
    let e = run_study(&changed, &part, &opts(Some(1))).unwrap_err();
    assert!(matches!(e, SweepError::Changed { rows: 12, .. }), "{e}");
    assert!(e.to_string().contains("--restart"), "{e}");
    let restarted = run_study(
        &changed,
        &part,
        &RunOptions {
            restart: true,
            limit: Some(1),
            ..opts(None)
        },
    )
    .unwrap();
    assert_eq!((restarted.resumed, restarted.computed), (0, 1));
    for d in [full, part] {
        std::fs::remove_dir_all(d).ok();
    }
}

#[test]
fn failed_runs_are_rows_with_their_error() {
    // The second encoder resolution is negative: the block refuses it when built.
    let s = study(
        "study: grid\nparameters:\n  - { path: blocks.encoder.lsb, values: [5.0e-9, -1.0] }\n",
    );
    let p = s.plan();
    let rows = s.run_chunk(&p, &[0, 1, 7], 2, |_| {});
    assert!(
        rows[0].error.is_none() && rows[0].scores.len() == 2,
        "{:?}",
        rows[0]
    );
    assert_eq!(rows[0].gate.as_deref(), Some("pass"));
    let e = rows[1].error.as_deref().unwrap();
    assert!(e.contains("encoder") && e.contains("lsb"), "{e}");
    assert!(rows[1].scores.is_empty());
    assert!(
        rows[2]
            .error
            .as_deref()
            .unwrap()
            .contains("not in the plan")
    );
}

#[test]
fn a_panicking_block_is_an_error_row_and_the_study_goes_on() {
    nanomotion::link_plugins();
    let d = dir("panic");
    let graph = d.join("g.yaml");
    std::fs::write(
        &graph,
        "base_rate_hz: 100\nduration_s: 0.1\nblocks:\n  - { name: c, type: constant, value: 1.0 }\n  - { name: p, type: sweep_test_panic_above, limit: 2.0 }\nconnections:\n  - { from: c.y, to: p.u }\nscore: [{ signal: p.y }]\n",
    )
    .unwrap();
    let s = Study::from_yaml(
        "graph: g.yaml\nstudy: grid\ngate: off\nparameters:\n  - { path: blocks.c.value, values: [1.0, 3.0, 1.5] }\n",
        "panic.yaml",
        &d,
    )
    .unwrap();
    let sum = run_study(&s, &d.join("out"), &RunOptions::default()).unwrap();
    assert_eq!((sum.computed, sum.failed), (3, 1));
    let (h, rows) = read_csv(&d.join("out/results.csv"));
    let err = h.iter().position(|x| x == "error").unwrap();
    let rms = h.iter().position(|x| x == "p.y.rms").unwrap();
    assert!(
        rows[1][err].contains("the run panicked: input 3 above 2"),
        "{:?}",
        rows[1]
    );
    assert_eq!(rows[0][rms].parse::<f64>().unwrap(), 1.0);
    assert_eq!(rows[2][rms].parse::<f64>().unwrap(), 1.5);
    assert!(rows[1][rms].is_empty());
    std::fs::remove_dir_all(d).ok();
}

#[test]
fn parquet_table_reads_back_equal_to_the_csv() {
    let s = study(
        "study: random\nruns: 6\nseed: 9\nseeds: per-run\nparameters:\n  - { path: blocks.pi.kp, range: [1.0e7, 5.0e7] }\n  - { path: blocks.err.signs, values: [\"+-\", \"++\"] }\n",
    );
    let d = dir("pq");
    let sum = run_study(&s, &d, &RunOptions::default()).unwrap();
    assert_eq!(sum.planned, 6);
    let csv = read_csv(&d.join("results.csv"));
    let pq = read_parquet_table(&d.join("results.parquet")).unwrap();
    assert_eq!(pq.0, csv.0);
    assert_eq!(pq.1, csv.1);
    // Seeds differ run to run (per-run) and show in the table.
    let seeds: std::collections::BTreeSet<&String> = csv.1.iter().map(|r| &r[1]).collect();
    assert_eq!(seeds.len(), 6);
    for f in ["plan.json", "scatter_blocks_pi_kp.svg"] {
        assert!(d.join(f).exists(), "{f}");
    }
    std::fs::remove_dir_all(d).ok();
}

#[test]
fn bad_studies_are_refused_with_the_place_and_the_fix() {
    nanomotion::link_plugins();
    let bad = |body: &str| {
        let text = format!("graph: {QUICKSTART}\n{body}");
        Study::from_yaml(&text, "bad.yaml", Path::new("."))
            .unwrap_err()
            .to_string()
    };
    let e = bad("study: grid\nparameters:\n  - { path: blocks.pi.kpp, values: [1.0] }\n");
    assert!(e.contains("did you mean `blocks.pi.kp`"), "{e}");
    let e =
        bad("study: grid\nparameters:\n  - { path: blocks.pi.kp, normal: { mean: 1, std: 1 } }\n");
    assert!(
        e.contains("has no grid points") && e.contains("fix:"),
        "{e}"
    );
    let e = bad("study: monte-carlo\nparameters: []\n");
    assert!(e.contains("needs `runs`"), "{e}");
    let e = bad(
        "study: random\nruns: 3\nparameters:\n  - { path: blocks.pi.kp, range: [1, 2], values: [1] }\n",
    );
    assert!(e.contains("gives 2 designs"), "{e}");
    let e = bad("study: grid\nseeds: sometimes\n");
    assert!(
        e.contains("`seeds: \"sometimes\"` is not understood"),
        "{e}"
    );
    let e = bad("study: grid\nset: { blocks.pi.kp: fast }\n");
    assert!(e.contains("override `blocks.pi.kp`"), "{e}");
}

/// Every shipped graph reads back unchanged through the override tree: setting
/// `seed` to its own value builds the same blocks in the same order.
#[test]
fn every_example_graph_survives_an_identity_override() {
    nanomotion::link_plugins();
    let mut n = 0;
    let mut stack = vec![PathBuf::from(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/examples"
    ))];
    while let Some(d) = stack.pop() {
        for e in std::fs::read_dir(&d).unwrap() {
            let p = e.unwrap().path();
            if p.is_dir() {
                stack.push(p);
                continue;
            }
            if p.extension().is_none_or(|x| x != "yaml") {
                continue;
            }
            let Ok(spec) = nanomotion::core::GraphSpec::from_file(&p) else {
                continue; // not a graph (a study, a config)
            };
            let seed = spec.seed;
            let plain = spec.build();
            let same = nanomotion::core::GraphSpec::from_file_with_overrides(
                &p,
                &[nanomotion::core::Override::new("seed", seed).unwrap()],
            )
            .unwrap()
            .build();
            match (plain, same) {
                (Ok((a, _)), Ok((b, _))) => {
                    assert_eq!(a.describe(), b.describe(), "{}", p.display());
                    n += 1;
                }
                (Err(a), Err(b)) => assert_eq!(a.to_string(), b.to_string()),
                (a, b) => panic!("{}: {:?} vs {:?}", p.display(), a.is_ok(), b.is_ok()),
            }
        }
    }
    assert!(n >= 10, "{n} graphs checked");
}

/// The command line: `run --set` changes the run, a wrong path is refused with
/// the nearest key, and `sweep` writes its table.
#[test]
fn cli_set_and_sweep() {
    let bin = env!("CARGO_BIN_EXE_nanomotion");
    let run = |args: &[&str]| std::process::Command::new(bin).args(args).output().unwrap();
    let base = ["run", QUICKSTART, "--no-files", "--set", "duration_s=0.6"];
    let plain = run(&base);
    assert!(plain.status.success());
    let mut slower = base.to_vec();
    slower.extend(["--set", "blocks.pi.kp=1e7"]);
    let slower = run(&slower);
    assert!(slower.status.success());
    let true_rms = |o: &std::process::Output| -> f64 {
        let text = String::from_utf8_lossy(&o.stdout).to_string();
        let line = text
            .lines()
            .find(|l| l.starts_with("true_err.y"))
            .unwrap()
            .to_string();
        line.split_whitespace().nth(1).unwrap().parse().unwrap()
    };
    assert_ne!(true_rms(&plain), true_rms(&slower));
    let bad = run(&["run", QUICKSTART, "--no-files", "--set", "blocks.pi.kpp=1"]);
    assert!(!bad.status.success());
    let err = String::from_utf8_lossy(&bad.stderr);
    assert!(err.contains("did you mean `blocks.pi.kp`?"), "{err}");

    let d = dir("cli");
    let grid = concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/examples/sweep/pi_gain_grid.yaml"
    );
    let out = d.join("grid");
    let o = run(&["sweep", grid, "--out", out.to_str().unwrap(), "--jobs", "2"]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let (h, rows) = read_csv(&out.join("results.csv"));
    assert_eq!(rows.len(), 12);
    assert_eq!(&h[2..4], ["blocks.pi.kp", "blocks.pi.zero_hz"]);
    std::fs::remove_dir_all(d).ok();
}

// ---- issue 25: plans bounded and lazy, duplicates, locks, --jobs --------------

/// D5: a grid of 10⁸ points, or of more than 2⁶⁴, is refused when the study is
/// read, naming the parameter to lower; nothing is allocated first.
#[test]
fn a_grid_larger_than_the_bound_is_refused_naming_the_parameter() {
    nanomotion::link_plugins();
    let load = |body: &str| {
        Study::from_yaml(
            &format!("graph: {QUICKSTART}\nset: {{ duration_s: 0.6 }}\n{body}"),
            "steps_huge.yaml",
            Path::new("."),
        )
    };
    let e = load("study: grid\nparameters:\n  - path: blocks.pi.kp\n    range: [1.0e7, 1.0e8]\n    steps: 100000000\n")
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("100000000 runs")
            && e.contains(&nanomotion::sweep::MAX_RUNS.to_string())
            && e.contains("lower `steps` of parameter `blocks.pi.kp`"),
        "{e}"
    );
    let t = std::time::Instant::now();
    let e = load("study: grid\nparameters:\n  - { path: blocks.pi.kp, range: [1.0e7, 1.0e8], steps: 4294967296 }\n  - { path: blocks.pi.zero_hz, range: [1.0, 8.0], steps: 4294967297 }\n  - { path: blocks.stage.den.0, range: [0.2, 0.3], steps: 4294967296 }\n")
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("more than 2^64") && e.contains("`blocks.pi.zero_hz`"),
        "{e}"
    );
    assert!(t.elapsed().as_secs_f64() < 5.0, "{:?}", t.elapsed());
    // Sizes at the bound: exactly MAX_RUNS plans (lazily: its last run is the
    // range's end); one more is refused; a seeds list counts.
    let max = nanomotion::sweep::MAX_RUNS;
    let grid = |steps: usize, seeds: &str| {
        load(&format!(
            "study: grid\n{seeds}parameters:\n  - {{ path: blocks.pi.kp, range: [1.0e7, 1.0e8], steps: {steps} }}\n"
        ))
    };
    let p = grid(max, "").unwrap().plan();
    assert_eq!(p.len(), max);
    assert_eq!(
        p.run(max - 1).unwrap().parameters[0].value.as_f64(),
        Some(1.0e8)
    );
    assert!(grid(max + 1, "").is_err());
    assert_eq!(grid(max / 2, "seeds: [1, 2]\n").unwrap().plan().len(), max);
    let e = grid(max / 2 + 1, "seeds: [1, 2]\n")
        .unwrap_err()
        .to_string();
    assert!(e.contains("× 2 seeds"), "{e}");
    // A seeds list multiplies the size.
    let e = load("study: monte-carlo\nruns: 10000000\nseeds: [1, 2]\nparameters:\n  - { path: blocks.pi.kp, range: [1.0e7, 1.0e8] }\n")
        .unwrap_err()
        .to_string();
    assert!(e.contains("lower `runs`"), "{e}");
}

/// D5: a Monte-Carlo study at the documented maximum (10⁷ runs) plans at once
/// and runs 2 of them with a `plan.json` of its definition (a few hundred
/// bytes, not 1.8 GB), and its runs are generated on demand, the same every time.
#[test]
fn the_largest_monte_carlo_plan_is_lazy_and_its_plan_file_small() {
    let s = study(&format!(
        "study: monte-carlo\nruns: {}\nseed: 2009\nparameters:\n  - {{ path: blocks.pi.kp, range: [1.0e7, 1.0e8] }}\n",
        nanomotion::sweep::MAX_RUNS
    ));
    let t = std::time::Instant::now();
    let p = s.plan();
    assert_eq!(p.len(), nanomotion::sweep::MAX_RUNS);
    let last = p.run(p.len() - 1).unwrap();
    assert_eq!(last.index, p.len() - 1);
    assert!(p.run(p.len()).is_none());
    assert_eq!(s.plan().run(p.len() - 1), Some(last));
    assert!(t.elapsed().as_secs_f64() < 2.0, "{:?}", t.elapsed());
    let out = dir("mc_max");
    let sum = run_study(
        &s,
        &out,
        &RunOptions {
            jobs: 1,
            limit: Some(2),
            ..Default::default()
        },
    )
    .unwrap();
    assert_eq!(
        (sum.planned, sum.computed),
        (nanomotion::sweep::MAX_RUNS, 2)
    );
    let plan_len = std::fs::metadata(out.join("plan.json")).unwrap().len();
    assert!(plan_len < 4096, "plan.json is {plan_len} bytes");
    let back: Plan =
        serde_json::from_str(&std::fs::read_to_string(out.join("plan.json")).unwrap()).unwrap();
    assert_eq!(back, p);
    assert_eq!(back.run(1), p.run(1), "the file regenerates the runs");
    std::fs::remove_dir_all(&out).ok();
}

/// D15: the same path twice (or a path both fixed by `set:` and varied) is
/// refused, naming both lines.
#[test]
fn the_same_parameter_path_twice_is_refused_naming_both_lines() {
    nanomotion::link_plugins();
    let text = format!(
        "graph: {QUICKSTART}\nset: {{ duration_s: 0.6, score.0.from_s: 0.1 }}\nstudy: random\nruns: 4\nparameters:\n  - path: blocks.pi.kp\n    range: [1.0e7, 1.0e8]\n  - path: blocks.pi.kp\n    range: [1.0e7, 1.0e8]\n"
    );
    let e = Study::from_yaml(&text, "dup.yaml", Path::new("."))
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("`blocks.pi.kp` is given twice") && e.contains("line 6") && e.contains("line 8"),
        "{e}"
    );
    // Another spelling of the same place: den.0 and den[0].
    let text = format!(
        "graph: {QUICKSTART}\nstudy: grid\nparameters:\n  - {{ path: blocks.stage.den.0, values: [0.25] }}\n  - path: blocks.stage.den[0]\n    values: [0.26]\n"
    );
    let e = Study::from_yaml(&text, "dup.yaml", Path::new("."))
        .unwrap_err()
        .to_string();
    assert!(e.contains("line 4") && e.contains("line 5"), "{e}");
    // Fixed by `set:` and varied.
    let text = format!(
        "graph: {QUICKSTART}\nset: {{ duration_s: 0.6 }}\nstudy: grid\nparameters:\n  - {{ path: duration_s, values: [0.5] }}\n"
    );
    let e = Study::from_yaml(&text, "dup.yaml", Path::new("."))
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("both fixed by `set:` (line 2) and varied (line 5)"),
        "{e}"
    );
}

/// D16: a sweep into a folder another live sweep writes is refused naming its
/// process; the lock of a dead process is taken over, and released at the end.
#[test]
fn a_second_sweep_into_one_folder_is_refused_while_the_first_runs() {
    let s = study("study: grid\nparameters:\n  - { path: blocks.pi.zero_hz, values: [2.0] }\n");
    let out = dir("locked");
    let mut holder = std::process::Command::new("sleep")
        .arg("30")
        .spawn()
        .unwrap();
    std::fs::write(
        out.join(nanomotion::output::LOCK_FILE),
        format!("{}\n", holder.id()),
    )
    .unwrap();
    let opts = RunOptions {
        jobs: 1,
        ..Default::default()
    };
    let e = run_study(&s, &out, &opts).unwrap_err().to_string();
    assert!(
        e.contains(&format!("PID {}", holder.id())) && e.contains("another --out"),
        "{e}"
    );
    assert!(!out.join("rows.jsonl").exists(), "wrote rows while locked");
    holder.kill().unwrap();
    holder.wait().unwrap();
    let sum = run_study(&s, &out, &opts).unwrap();
    assert_eq!(sum.computed, 1);
    assert!(!out.join(nanomotion::output::LOCK_FILE).exists());
    std::fs::remove_dir_all(&out).ok();
}

/// D12: a sweep does not write into a folder of the user's.
#[test]
fn a_sweep_refuses_a_folder_that_is_not_a_sweep() {
    let s = study("study: grid\nparameters:\n  - { path: blocks.pi.zero_hz, values: [2.0] }\n");
    let out = dir("foreign");
    std::fs::write(out.join("notes.txt"), "mine").unwrap();
    let e = run_study(&s, &out, &RunOptions::default())
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("notes.txt") && e.contains("another --out"),
        "{e}"
    );
    std::fs::remove_dir_all(&out).ok();
}

/// D22: more jobs than cores are capped, with a note.
#[test]
fn jobs_beyond_the_cores_are_capped() {
    let cores = std::thread::available_parallelism().map_or(1, usize::from);
    let (n, note) = nanomotion::sweep::capped_jobs(100_000);
    assert_eq!(n, cores);
    assert!(note.unwrap().contains("--jobs 100000"));
    assert_eq!(nanomotion::sweep::capped_jobs(1), (1, None));
    assert_eq!(nanomotion::sweep::capped_jobs(0), (cores, None));
}
