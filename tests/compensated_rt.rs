//! Issue #28: the compensated graph of each shipped compensation case runs in
//! the real-time runner. The repository ships one runnable case,
//! `examples/compensate/` (the AFM x axis of Ch. 6: hysteresis → inverse
//! feed-forward). Its `compensated.yaml` is produced here as `nanomotion
//! diagnose` + `nanomotion compensate` produce it (the library calls behind the
//! commands, on the shipped model, record and controller), written to a
//! scratch folder and read back; then it runs (a) offline, ticked by the
//! scheduler as `nanomotion run` does, and (b) on the wall clock by
//! `RealtimeRunner` without a device, as `nanomotion rt compensated.yaml
//! --allow-soft` does. Wall-clock execution must not change a single value:
//! every logged sample of (b) equals (a)'s bit for bit.

mod common;

use nanomotion::compensate::{Options, compensate, named};
use nanomotion::core::data::Dataset;
use nanomotion::core::graph::GraphSpec;
use nanomotion::plf::diagnose::{self, diagnose};
use nanomotion::rt::{NoDevice, RealtimeRunner, Stop};
use std::path::{Path, PathBuf};
use std::process::Command;

/// Simulated (and wall-clock) duration of the runs: the controller's scored
/// window starts at 4 s, so 4.5 s scores half a second of it.
const DURATION_S: f64 = 4.5;

fn example(file: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("examples/compensate")
        .join(file)
}

/// The AFM case's `compensated.yaml`, from the shipped inputs, written into
/// `dir` as `nanomotion compensate --out DIR` names it; its path.
fn compensated_afm(dir: &Path) -> PathBuf {
    let data = Dataset::from_file(example("record.csv")).unwrap();
    let nominal = GraphSpec::from_file(example("model.yaml")).unwrap();
    // `diagnose --effects hysteresis` (as tests/compensate_example.rs runs it).
    let opts = diagnose::Options {
        effects: vec!["hysteresis".into()],
        max_effects: 1,
        ..Default::default()
    };
    let rep = diagnose(&nominal, &data, &opts).unwrap();
    assert_eq!(rep.found, vec!["hysteresis".to_string()]);
    let augmented = rep.augmented.as_ref().unwrap();
    let controller = GraphSpec::from_file(example("controller.yaml")).unwrap();
    let out = compensate(
        augmented,
        &controller,
        &named::from_report(&rep),
        &Options::default(),
    )
    .unwrap();
    let c = &out.report.compensators[0];
    assert_eq!(c.type_name, "hysteresis_inverse");
    assert!(c.kept);
    assert!(out.report.gate.passes);
    let _ = std::fs::remove_dir_all(dir);
    std::fs::create_dir_all(dir).unwrap();
    let path = dir.join("compensated.yaml");
    let yaml = nanomotion::core::yaml::to_string(&out.compensated).unwrap();
    std::fs::write(&path, yaml).unwrap();
    path
}

/// The graph file with `duration_s` overridden (as `--duration` does) and
/// `extra_log` logged besides the graph's own `log:`.
fn load(path: &Path, extra_log: &[&str]) -> GraphSpec {
    let mut spec = GraphSpec::from_file(path).unwrap();
    spec.duration_s = DURATION_S;
    spec.log.extend(extra_log.iter().map(|s| s.to_string()));
    spec
}

/// Runs `path` offline and on the wall clock and compares them bit for bit.
fn offline_equals_wall_clock(path: &Path, extra_log: &[&str]) {
    // (a) Offline, as `nanomotion run`.
    let spec = load(path, extra_log);
    let rate = spec.base_rate_hz;
    let (mut offline, _) = spec.build().unwrap();
    let want = offline.run(|_| {});
    let ticks = (DURATION_S * rate).round() as u64;
    assert_eq!(offline.ticks_done(), ticks);

    // (b) On the wall clock, without a device, at normal priority where
    // SCHED_FIFO is refused; late ticks caught up, none dropped.
    let (sched, _) = load(path, extra_log).build().unwrap();
    let cfg = common::soft_catch_up();
    let mut runner = RealtimeRunner::new(sched, NoDevice, cfg).unwrap();
    let report = runner.run(|_| {}).unwrap();
    let (wall, _) = runner.into_parts();
    assert_eq!(report.stopped, Stop::Completed, "{}", report.stop);
    assert_eq!(report.ticks, ticks);
    assert_eq!(report.missed_ticks, 0);
    assert_eq!(report.overrun_policy, "catch-up");
    assert_eq!(report.rate_hz, rate);
    assert_eq!(report.period_ns, 1e9 / rate);
    assert_eq!(report.wakeup_latency.count, ticks);
    assert_eq!(wall.ticks_done(), ticks);
    eprintln!(
        "{}: {} ticks at {} Hz on the wall clock ({}), {} overruns caught up",
        path.display(),
        report.ticks,
        report.rate_hz,
        report.scheduling,
        report.overruns
    );

    // Every logged signal, sample for sample, bit for bit.
    let got = wall.result();
    assert_eq!(got.logs.len(), want.logs.len());
    assert!(!want.logs.is_empty(), "the graph logs something to compare");
    for (w, g) in want.logs.iter().zip(&got.logs) {
        assert_eq!(g.name, w.name);
        assert_eq!(g.width, w.width);
        assert_eq!(g.rate_hz, w.rate_hz, "{}", w.name);
        assert_eq!(w.len() as u64, ticks * w.rate_hz as u64 / rate as u64);
        assert_eq!(g.data.len(), w.data.len(), "{}", w.name);
        for (i, (a, b)) in w.data.iter().zip(&g.data).enumerate() {
            assert_eq!(
                a.to_bits(),
                b.to_bits(),
                "{} sample {i}: offline {a:e}, wall clock {b:e}",
                w.name
            );
        }
        // The loop moved: the comparison is not of constants.
        assert!(
            w.data.iter().any(|&v| v != w.data[0]),
            "{} is constant",
            w.name
        );
    }
    // And so the scores over the scored window.
    assert_eq!(got.scores.len(), want.scores.len());
    assert!(!want.scores.is_empty());
    for (w, g) in want.scores.iter().zip(&got.scores) {
        assert_eq!(g.signal, w.signal);
        assert_eq!(g.rms.to_bits(), w.rms.to_bits(), "{}", w.signal);
        assert_eq!(g.max_abs.to_bits(), w.max_abs.to_bits(), "{}", w.signal);
    }
}

#[test]
fn the_compensated_afm_graph_runs_on_the_wall_clock_bit_for_bit_as_offline() {
    nanomotion::link_plugins();
    let dir = Path::new(env!("CARGO_TARGET_TMPDIR")).join("compensated_rt_afm");
    let path = compensated_afm(&dir);
    // The written file holds the inverse before the actuator (compensate's
    // report said so above); it is what runs below.
    let yaml = std::fs::read_to_string(&path).unwrap();
    assert!(
        yaml.contains("- name: comp_hysteresis\n  type: hysteresis_inverse\n"),
        "{yaml}"
    );
    // Logged besides the graph's own log (ref.y, split.y0) and score (err.y):
    // the compensator's drive into the actuator and its static feed-forward.
    offline_equals_wall_clock(&path, &["comp_hysteresis.y", "comp_hysteresis_ff.v"]);

    // The command docs/compensate.md gives runs the written file (long enough
    // to reach the scored window from 4 s, which a shorter run refuses).
    let out = Command::new(env!("CARGO_BIN_EXE_nanomotion"))
        .arg("rt")
        .arg(&path)
        .args(["--allow-soft", "--duration", "4.5", "--allow-idle-states"])
        .output()
        .unwrap();
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(
        out.status.success(),
        "{text}{}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert!(text.contains("4500 ticks at 1000 Hz"), "{text}");
    let _ = std::fs::remove_dir_all(&dir);
}
