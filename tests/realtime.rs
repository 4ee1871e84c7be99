//! The quickstart loop split in two processes — the controller here, the stage
//! in `nanomotion plant` — tracks like the single-process simulation; `nanomotion
//! rt` writes its timing report.

mod common;

use nanomotion::core::graph::GraphSpec;
use nanomotion::rt::{RealtimeRunner, ShmDevice, Stop};
use std::process::{Command, Stdio};
use std::time::Duration;

const EXAMPLES: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/examples");

/// `nanomotion plant` serving the quickstart's stage under `name` (soft
/// real-time allowed), with `extra` options; output captured.
fn serve_quickstart_plant(name: &str, extra: &[&str]) -> std::process::Child {
    let graph = format!("{EXAMPLES}/realtime/quickstart_plant.yaml");
    serve_plant(std::path::Path::new(&graph), name, extra)
}

/// `nanomotion plant GRAPH` serving under `name` (soft real-time allowed), with
/// `extra` options; output captured.
fn serve_plant(graph: &std::path::Path, name: &str, extra: &[&str]) -> std::process::Child {
    Command::new(env!("CARGO_BIN_EXE_nanomotion"))
        .arg("plant")
        .arg(graph)
        .args(["--serve", name, "--allow-soft", "--priority", "70"])
        .args(extra)
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap()
}

/// The quickstart's plant half with its clock (t, s) published as the
/// channel `plant_time`.
fn with_plant_clock(yaml: &str) -> String {
    assert!(yaml.contains("\nblocks:\n") && yaml.contains("\nconnections:\n"));
    yaml.replacen(
        "\nblocks:\n",
        "\nblocks:\n  - { name: clock, type: constant_velocity, velocity_m_s: 1.0 }\n  - { name: plant_time, type: hw_output, unit: s }\n",
        1,
    )
    .replacen(
        "\nconnections:\n",
        "\nconnections:\n  - { from: clock.y, to: plant_time.u }\n",
        1,
    )
}

/// The quickstart's controller half reading and logging the plant's clock.
fn reading_plant_clock(yaml: &str) -> String {
    let log = "log: [ref.y, position.y, pi.u]";
    assert!(yaml.contains("\nblocks:\n") && yaml.contains(log));
    yaml.replacen(
        "\nblocks:\n",
        "\nblocks:\n  - { name: plant_time, type: hw_input, unit: s }\n",
        1,
    )
    .replacen(log, "log: [ref.y, position.y, pi.u, plant_time.y]", 1)
}

/// rms and mean of the `i`-th score's signal, from its log, after `from_s`.
fn err_stats(sched: &nanomotion::core::Scheduler, signal: &str, from_s: f64) -> (f64, f64, f64) {
    let r = sched.result();
    let s = r.scores.iter().find(|s| s.signal == signal).unwrap();
    assert_eq!(s.from_s, from_s);
    (s.rms, s.mean, s.max_abs)
}

#[test]
fn the_quickstart_split_in_two_processes_tracks_like_the_simulation() {
    nanomotion::link_plugins();
    // Single process: the quickstart as simulated.
    let (mut single, _) = GraphSpec::from_file(format!("{EXAMPLES}/quickstart.yaml"))
        .unwrap()
        .build()
        .unwrap();
    single.run(|_| {});
    let (rms1, _, _) = err_stats(&single, "err.y", 0.5);

    // Two processes: the stage served by `nanomotion plant`, the PI here;
    // both halves as shipped, with the plant's clock added as a channel to
    // measure the transport delay by.
    let name = format!("test-quickstart-{}", std::process::id());
    let dir = std::env::temp_dir().join(format!("nanomotion-rt-clock-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let plant_yaml = dir.join("quickstart_plant_with_clock.yaml");
    let plant_src =
        std::fs::read_to_string(format!("{EXAMPLES}/realtime/quickstart_plant.yaml")).unwrap();
    std::fs::write(&plant_yaml, with_plant_clock(&plant_src)).unwrap();
    let plant = serve_plant(&plant_yaml, &name, &["--overrun", "catch-up"]);
    let ctrl_src =
        std::fs::read_to_string(format!("{EXAMPLES}/realtime/quickstart_controller.yaml")).unwrap();
    let (sched, _) = GraphSpec::from_yaml(&reading_plant_clock(&ctrl_src), "controller.yaml")
        .unwrap()
        .build()
        .unwrap();
    let device =
        ShmDevice::connect(&name, Duration::from_secs(20), Duration::from_millis(200)).unwrap();
    let cfg = common::soft_catch_up();
    let mut runner = RealtimeRunner::new(sched, device, cfg).unwrap();
    let report = runner.run(|_| {}).unwrap();
    let (sched, device) = runner.into_parts();
    drop(device); // detach: the plant stops
    let out = plant.wait_with_output().unwrap();
    let plant_log =
        String::from_utf8_lossy(&out.stdout).into_owned() + &String::from_utf8_lossy(&out.stderr);
    let _ = std::fs::remove_dir_all(&dir);
    assert!(out.status.success(), "plant: {plant_log}");
    assert!(
        plant_log.contains("the controller closed the connection"),
        "{plant_log}"
    );
    assert_eq!(report.stopped, Stop::Completed);
    assert_eq!(report.ticks, 8000);
    assert_eq!(report.device_latency_ticks, 1);

    // The loop is type 2 (the stage integrates f_α, the PI integrates the
    // error): the ramp is tracked without a steady error in both set-ups.
    // The split adds a transport delay: below one controller sample T =
    // 250 µs when the plant keeps its schedule (it publishes every 25 µs; a
    // late tick is caught up, so its clock stays on the wall clock's), more
    // while it is scheduled late. A delay d moves the measured position by
    // v·d, and the encoder's 5 nm quantisation then rounds differently: the
    // rms error may differ by at most lsb + v·(T + the delay's rise over its
    // least, read off the plant's clock after the first 0.1 s, while the
    // plant starts).
    let (clock, _, _) = sched.log_view("plant_time.y").unwrap();
    let delay: Vec<f64> = (400..clock.len())
        .map(|k| k as f64 / 4000.0 - clock[k])
        .collect();
    let late = delay.iter().copied().fold(f64::NEG_INFINITY, f64::max)
        - delay.iter().copied().fold(f64::INFINITY, f64::min);
    let (rms2, mean2, _) = err_stats(&sched, "err.y", 0.5);
    let lsb = 5e-9;
    let v_t = 1e-5 * (1.0 / 4000.0 + late);
    assert!(
        (rms2 - rms1).abs() <= lsb + v_t,
        "two processes: rms {rms2:e} m, one process: {rms1:e} m (the plant up to {late:e} s late)"
    );
    assert!(mean2.abs() <= lsb, "steady error {mean2:e} m");
    // And the loop really was closed: the position followed the 10 µm/s ramp
    // to about 20 µm.
    let (pos, _, rate) = sched.log_view("position.y").unwrap();
    let (reference, _, _) = sched.log_view("ref.y").unwrap();
    assert_eq!(rate, 4000.0);
    assert_eq!(pos.len(), 8000);
    let (p, r) = (pos[7999], reference[7999]);
    assert!(r > 1.99e-5, "reference {r:e} m");
    assert!(
        (p - r).abs() < 2.0 * lsb + v_t,
        "end position {p:e} m, reference {r:e} m"
    );
}

#[test]
fn rt_writes_its_timing_report_and_refuses_a_missing_plant() {
    let dir = std::env::temp_dir().join(format!("nanomotion-rt-cli-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    let out = Command::new(env!("CARGO_BIN_EXE_nanomotion"))
        .args(["rt", &format!("{EXAMPLES}/quickstart.yaml")])
        .args([
            "--duration",
            "0.6",
            "--allow-soft",
            "--block-timing",
            "--out",
        ])
        .arg(&dir)
        .output()
        .unwrap();
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(
        out.status.success(),
        "{text}{}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert!(text.contains("24000 ticks at 40000 Hz"), "{text}");
    let timing: serde_json::Value =
        serde_json::from_slice(&std::fs::read(dir.join("timing.json")).unwrap()).unwrap();
    assert_eq!(timing["ticks"], 24000);
    assert_eq!(timing["wakeup_latency"]["count"], 24000);
    assert_eq!(timing["period_ns"], 25_000.0);
    assert!(dir.join("timing.svg").exists());
    // --block-timing: every block of the graph, in execution order, timed on
    // each tick it was due (24000 / its period in base ticks).
    let (sched, _) = GraphSpec::from_file(format!("{EXAMPLES}/quickstart.yaml"))
        .unwrap()
        .build()
        .unwrap();
    let blocks = timing["blocks"].as_array().unwrap();
    assert_eq!(blocks.len(), sched.block_names().len());
    let mut mean_sum = 0.0;
    for (b, w) in blocks.iter().zip(sched.wiring()) {
        assert_eq!(b["name"], w.name.as_str());
        assert_eq!(b["count"], 24000 / w.period, "{}", w.name);
        assert!(b["p50_ns"].as_u64().unwrap() <= b["max_ns"].as_u64().unwrap());
        mean_sum += b["mean_ns"].as_f64().unwrap() * b["count"].as_f64().unwrap() / 24000.0;
        // And in the printed summary.
        assert!(text.contains(&format!("  block {}", w.name)), "{text}");
    }
    // The blocks run inside the tick: their time per tick is at most the tick's.
    assert!(mean_sum <= timing["execution"]["mean_ns"].as_f64().unwrap());
    let _ = std::fs::remove_dir_all(&dir);

    // A controller whose plant is not there: named, with the fix, no files.
    let out = Command::new(env!("CARGO_BIN_EXE_nanomotion"))
        .args([
            "rt",
            &format!("{EXAMPLES}/realtime/quickstart_controller.yaml"),
        ])
        .args([
            "--device",
            "shm:nobody-serves-this",
            "--connect-timeout",
            "0",
        ])
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success());
    assert!(
        err.contains("no plant serves `nobody-serves-this`"),
        "{err}"
    );
    assert!(
        err.contains("nanomotion plant PLANT.yaml --serve nobody-serves-this"),
        "{err}"
    );
}

#[test]
fn a_recorded_two_process_run_replays_bit_for_bit_and_a_changed_gain_does_not() {
    let name = format!("test-record-{}", std::process::id());
    let dir = std::env::temp_dir().join(format!("nanomotion-rt-record-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    let bin = env!("CARGO_BIN_EXE_nanomotion");
    let plant = serve_quickstart_plant(&name, &[]);
    let controller = format!("{EXAMPLES}/realtime/quickstart_controller.yaml");
    let out = Command::new(bin)
        .args(["rt", &controller, "--device", &format!("shm:{name}")])
        .args(["--duration", "0.6", "--allow-soft", "--record", "--out"])
        .arg(&dir)
        .output()
        .unwrap();
    succeeded(&out);
    // Before the run, the stability gate judged the loop through the device:
    // the plant's graph (shared by `plant --serve`) with the device's one tick
    // of latency (nanomotion-rt's tests/through.rs checks the figures).
    let said = String::from_utf8_lossy(&out.stdout);
    assert!(
        said.contains(&format!(
            "stability gate: loop `pi` closed through device `shm:{name}` with its latency of 1 tick (250.0 µs): phase margin 76."
        )),
        "{said}"
    );
    let plant = plant.wait_with_output().unwrap();
    assert!(
        plant.status.success(),
        "plant: {}{}",
        String::from_utf8_lossy(&plant.stdout),
        String::from_utf8_lossy(&plant.stderr)
    );
    let mcap = dir.join("run.mcap");
    let text = replay_ok(&mcap, &controller);
    assert!(text.contains("replayed 2400 ticks"), "{text}");
    assert!(
        text.contains("all 2400 output samples bit-identical"),
        "{text}"
    );
    let changed = Command::new(bin)
        .arg("replay")
        .arg(&mcap)
        .arg(&controller)
        .args(["--set", "blocks.pi.kp=3.2e7"])
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&changed.stderr);
    assert!(!changed.status.success());
    assert!(
        err.contains("output samples differ; first at tick"),
        "{err}"
    );
    let _ = std::fs::remove_dir_all(&dir);
}

/// Asserts that a command exited with success, showing its standard error if not.
fn succeeded(out: &std::process::Output) {
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
}

/// `nanomotion replay MCAP CONTROLLER` that must succeed; its standard output.
fn replay_ok(mcap: &std::path::Path, controller: &str) -> String {
    let out = Command::new(env!("CARGO_BIN_EXE_nanomotion"))
        .arg("replay")
        .arg(mcap)
        .arg(controller)
        .output()
        .unwrap();
    succeeded(&out);
    String::from_utf8_lossy(&out.stdout).into_owned()
}

/// `nanomotion rt` with `lines` written to its standard input `after` the
/// start; its output.
fn rt_with_stdin(args: &[&str], lines: &str, after: Duration) -> std::process::Output {
    use std::io::Write as _;
    let mut child = Command::new(env!("CARGO_BIN_EXE_nanomotion"))
        .arg("rt")
        .args(args)
        .stdin(Stdio::piped())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    std::thread::sleep(after);
    let mut stdin = child.stdin.take().unwrap();
    stdin.write_all(lines.as_bytes()).unwrap();
    drop(stdin);
    child.wait_with_output().unwrap()
}

#[test]
fn rt_applies_a_gain_typed_on_stdin_and_refuses_bad_lines_with_their_reason() {
    // The single-process quickstart: its PI loop passes the gate, k_p = 3.1416e8
    // makes it unstable (tests of nanomotion-rt compare the gate's figures).
    let graph = format!("{EXAMPLES}/quickstart.yaml");
    let out = rt_with_stdin(
        &[&graph, "--duration", "1.5", "--allow-soft"],
        "set pi.kp=3.1416e8\nset pi.kq=1\nhello\nset pi.kp=4e7\n",
        Duration::from_millis(100),
    );
    let err = String::from_utf8_lossy(&out.stderr);
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(out.status.success(), "{err}");
    assert!(
        err.contains("`pi.kp` = 314160000 refused by the stability gate: loop `pi` is unstable"),
        "{err}"
    );
    assert!(
        err.contains("`kq` of block `pi` cannot change while the loop runs (its live parameters: kp, zero_hz)"),
        "{err}"
    );
    assert!(err.contains("`hello`: unknown command"), "{err}");
    assert!(err.contains("set pi.kp = 40000000 at tick "), "{err}");
    assert!(text.contains("live parameter updates 1"), "{text}");
}

#[test]
fn rt_judges_a_filter_corner_typed_on_stdin_with_the_new_corner() {
    // The quickstart with a 2nd-order low-pass `lp` (1 kHz) on the encoder's
    // reading: at 5 Hz its lag destabilises the loop (nanomotion-rt's
    // `the_stability_gate_judges_a_filter_corner_changed_live` compares the
    // gate's figures), 2 kHz is the block's Nyquist, 150 Hz is benign.
    let dir = std::env::temp_dir().join(format!("nanomotion-rt-lp-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let quickstart = std::fs::read_to_string(format!("{EXAMPLES}/quickstart.yaml")).unwrap();
    let feedback = "  - { from: encoder.y, to: err.in1 }\n";
    assert!(quickstart.contains(feedback));
    let filtered = quickstart
        .replace(
            feedback,
            "  - { from: encoder.y, to: lp.u }\n  - { from: lp.y, to: err.in1 }\n",
        )
        .replace(
            "connections:\n",
            "  - { name: lp, type: low_pass, rate_hz: 4000, cutoff_hz: 1000, order: 2 }\nconnections:\n",
        );
    let graph = dir.join("filtered_quickstart.yaml");
    std::fs::write(&graph, filtered).unwrap();
    let out = rt_with_stdin(
        &[graph.to_str().unwrap(), "--duration", "1.5", "--allow-soft"],
        "set lp.cutoff_hz=5\nset lp.cutoff_hz=2000\nset lp.order=4\nset lp.cutoff_hz=150\n",
        Duration::from_millis(100),
    );
    let err = String::from_utf8_lossy(&out.stderr);
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(out.status.success(), "{err}");
    assert!(
        err.contains("`lp.cutoff_hz` = 5 refused by the stability gate: loop `pi` "),
        "{err}"
    );
    assert!(
        err.contains("`lp.cutoff_hz` = 2000 refused by block `lp` (low_pass): field `cutoff_hz`: 2000 Hz is not below the Nyquist frequency 2000 Hz of the block's rate (fix: lower the frequency or raise the block's rate)"),
        "{err}"
    );
    assert!(
        err.contains("`order` of block `lp` cannot change while the loop runs (its live parameters: cutoff_hz)"),
        "{err}"
    );
    assert!(err.contains("set lp.cutoff_hz = 150 at tick "), "{err}");
    assert!(text.contains("live parameter updates 1"), "{text}");
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn a_gain_set_from_stdin_is_recorded_and_replays_bit_for_bit() {
    let name = format!("test-live-{}", std::process::id());
    let dir = std::env::temp_dir().join(format!("nanomotion-rt-live-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    let plant = serve_quickstart_plant(&name, &[]);
    let controller = format!("{EXAMPLES}/realtime/quickstart_controller.yaml");
    let out = rt_with_stdin(
        &[
            &controller,
            "--device",
            &format!("shm:{name}"),
            "--duration",
            "2",
            "--allow-soft",
            "--record",
            "--out",
            dir.to_str().unwrap(),
        ],
        "set pi.kp=3.1416e8\nset pi.kp=4e7\n",
        // Two seconds, the lines after 0.1 s: both are judged (the gate through
        // the device is the slow part, ~0.2 s in a debug build and more on a
        // loaded machine) and applied long before the run ends.
        Duration::from_millis(100),
    );
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "{err}");
    // The controller graph has no loop of its own: ten times the design's k_p
    // is judged on the loop through the device, with its one tick, where it
    // is unstable (tests/through.rs, nanomotion-rt, has the figures).
    assert!(
        err.contains(&format!(
            "refused: `pi.kp` = 314160000 refused by the stability gate on the loop through device `shm:{name}` with its latency of 1 tick: loop `pi` is unstable: closed-loop pole of modulus 1.068204 ≥ 1; with the values accepted so far loop `pi` had phase margin 76.16°"
        )),
        "{err}"
    );
    assert!(err.contains("set pi.kp = 40000000 at tick "), "{err}");
    let plant = plant.wait_with_output().unwrap();
    assert!(plant.status.success());
    let text = replay_ok(&dir.join("run.mcap"), &controller);
    assert!(
        text.contains("with its live parameter update: all 8000 output samples bit-identical"),
        "{text}"
    );
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn rt_refuses_without_cap_sys_nice_and_runs_soft_when_allowed() {
    // As root, drop CAP_SYS_NICE for the child (util-linux `setpriv`); the
    // real-time priority limit (`ulimit -r`) is 0 by default, so SCHED_FIFO is
    // refused.
    let run = |soft: bool| {
        let mut c = Command::new("setpriv");
        c.args(["--inh-caps=-sys_nice", "--bounding-set=-sys_nice", "--"])
            .arg(env!("CARGO_BIN_EXE_nanomotion"))
            .args([
                "rt",
                &format!("{EXAMPLES}/quickstart.yaml"),
                "--duration",
                "0.6",
            ]);
        if soft {
            c.arg("--allow-soft");
        }
        c.output().expect("setpriv (util-linux) runs")
    };
    let hard = run(false);
    let err = String::from_utf8_lossy(&hard.stderr);
    assert!(!hard.status.success());
    assert!(err.contains("SCHED_FIFO priority 80 refused"), "{err}");
    assert!(
        err.contains("ulimit -r 80") && err.contains("CAP_SYS_NICE"),
        "{err}"
    );
    assert!(err.contains("--allow-soft"), "{err}");
    assert!(!String::from_utf8_lossy(&hard.stdout).contains("ticks at"));
    let soft = run(true);
    let out = String::from_utf8_lossy(&soft.stdout);
    succeeded(&soft);
    assert!(
        out.contains("24000 ticks at 40000 Hz (SCHED_OTHER (normal priority))"),
        "{out}"
    );
    assert!(
        out.contains("soft run: SCHED_FIFO priority 80 refused"),
        "{out}"
    );
}

#[test]
fn rt_takes_the_overrun_policy_from_the_graph_and_the_command_line_over_it() {
    let dir = std::env::temp_dir().join(format!("nanomotion-rt-policy-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    let graph = |section: &str| {
        let path = dir.join("loop.yaml");
        std::fs::write(
            &path,
            format!("base_rate_hz: 1000\nduration_s: 0.05\n{section}blocks:\n  - {{ name: c, type: constant, value: 1.0 }}\nlog: [c.y]\n"),
        )
        .unwrap();
        path
    };
    let rt = |path: &std::path::Path, extra: &[&str]| {
        let out = dir.join("out");
        let o = Command::new(env!("CARGO_BIN_EXE_nanomotion"))
            .arg("rt")
            .arg(path)
            .args(["--allow-soft", "--force", "--out"])
            .arg(&out)
            .args(extra)
            .output()
            .unwrap();
        let timing = std::fs::read(out.join("timing.json"))
            .ok()
            .map(|b| serde_json::from_slice::<serde_json::Value>(&b).unwrap());
        let _ = std::fs::remove_dir_all(&out);
        (o, timing)
    };
    let with_section = graph("realtime:\n  overrun: catch-up\n  max_overruns: 7\n");
    let (o, t) = rt(&with_section, &[]);
    succeeded(&o);
    let t = t.unwrap();
    assert_eq!(
        (t["overrun_policy"].as_str(), t["max_overruns"].as_u64()),
        (Some("catch-up"), Some(7))
    );
    assert!(String::from_utf8_lossy(&o.stdout).contains("(policy catch-up, limit 7)"));
    // Each flag replaces its own setting only.
    let (o, t) = rt(&with_section, &["--overrun", "skip"]);
    assert!(o.status.success());
    let t = t.unwrap();
    assert_eq!(
        (t["overrun_policy"].as_str(), t["max_overruns"].as_u64()),
        (Some("skip"), Some(7))
    );
    let (_, t) = rt(&with_section, &["--max-overruns", "2"]);
    let t = t.unwrap();
    assert_eq!(
        (t["overrun_policy"].as_str(), t["max_overruns"].as_u64()),
        (Some("catch-up"), Some(2))
    );
    // Without the section: skip, no limit.
    let (_, t) = rt(&graph(""), &[]);
    let t = t.unwrap();
    assert_eq!(t["overrun_policy"], "skip");
    assert!(t["max_overruns"].is_null());
    // A bad value: refused before running, the file, line and field named.
    let bad = graph("realtime:\n  overrun: later\n");
    let (o, t) = rt(&bad, &[]);
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(!o.status.success() && t.is_none());
    assert!(err.contains("loop.yaml: line 4 column 12: unknown overrun policy `later` (fix: `skip` or `catch-up`)"), "{err}");
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn a_simulated_run_records_its_hw_samples_and_replays_bit_for_bit() {
    let dir = std::env::temp_dir().join(format!("nanomotion-run-record-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    let bin = env!("CARGO_BIN_EXE_nanomotion");
    let controller = format!("{EXAMPLES}/realtime/quickstart_controller.yaml");
    let out = Command::new(bin)
        .args(["run", &controller, "--duration", "0.6", "--record", "--out"])
        .arg(&dir)
        .output()
        .unwrap();
    succeeded(&out);
    let rec = nanomotion::rt::read_mcap(&dir.join("run.mcap")).unwrap();
    assert_eq!((rec.ticks(), rec.rate_hz), (2400, 4000.0));
    let names = |c: &[nanomotion::rt::Channel]| {
        c.iter()
            .map(|c| (c.name.clone(), c.unit.clone()))
            .collect::<Vec<_>>()
    };
    assert_eq!(names(&rec.inputs), [("position".into(), Some("m".into()))]);
    assert_eq!(names(&rec.outputs)[0].0, "drive");
    // Simulated time, one sample per tick of T = 250 µs.
    assert!(
        rec.t_ns
            .iter()
            .enumerate()
            .all(|(k, &t)| t == k as u64 * 250_000)
    );
    // Without a device the hw_input holds 0; the outputs are what the graph
    // computes from that, tick by tick (the same graph ticked here).
    assert!(rec.input_values.iter().all(|&v| v == 0.0));
    let mut spec = GraphSpec::from_file(&controller).unwrap();
    spec.duration_s = 0.6;
    let (mut sched, _) = spec.build().unwrap();
    let drive = sched.signal_id("drive.y").unwrap();
    for (k, want) in rec.output_values.iter().enumerate() {
        sched.tick();
        assert_eq!(sched.read(drive)[0].to_bits(), want.to_bits(), "tick {k}");
    }
    assert!(
        rec.output_values.iter().any(|&v| v != 0.0),
        "the PI drove something"
    );
    // `nanomotion replay` reproduces it, and parts from it with another gain.
    let text = replay_ok(&dir.join("run.mcap"), &controller);
    assert!(
        text.contains("all 2400 output samples bit-identical"),
        "{text}"
    );
    let changed = Command::new(bin)
        .arg("replay")
        .arg(dir.join("run.mcap"))
        .arg(&controller)
        .args(["--set", "blocks.pi.kp=3.2e7"])
        .output()
        .unwrap();
    assert!(!changed.status.success());
    // A graph without hw blocks has nothing to record: refused before running,
    // no folder written.
    let none = dir.join("none");
    let refused = Command::new(bin)
        .args([
            "run",
            &format!("{EXAMPLES}/quickstart.yaml"),
            "--record",
            "--out",
        ])
        .arg(&none)
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&refused.stderr);
    assert!(!refused.status.success());
    assert!(
        err.contains("nothing to record: the graph has no hw_input or hw_output block"),
        "{err}"
    );
    assert!(!none.exists());
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn diagnose_reads_a_recording_as_its_measured_data_like_the_same_csv() {
    use nanomotion::core::data::Dataset;
    use nanomotion::rt::{Channel, Recording};
    // The diagnose example's record (u: drive force, y: measured position,
    // 2 kHz) as a recording would hold it: y read from the stage (hw_input),
    // u written to it (hw_output), ticks on the grid from a CLOCK_MONOTONIC origin.
    let dir = std::env::temp_dir().join(format!("nanomotion-diagnose-mcap-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    let csv_path = format!("{EXAMPLES}/diagnose/record.csv");
    let csv = Dataset::from_file(&csv_path).unwrap();
    let n = csv.len();
    let rec = Recording {
        title: None,
        rate_hz: csv.rate_hz(),
        inputs: vec![Channel::new("y", Some("m"))],
        outputs: vec![Channel::new("u", Some("N"))],
        t_ns: (0..n as u64).map(|k| 987_654_321 + k * 500_000).collect(),
        input_values: csv.column("y").unwrap().to_vec(),
        output_values: csv.column("u").unwrap().to_vec(),
        ..Recording::default()
    };
    let mcap = dir.join("run.mcap");
    nanomotion::rt::write_mcap(&mcap, &rec).unwrap();
    // Read back as data: the CSV's columns, bit for bit, at its rate.
    let back = nanomotion::rt::read_mcap(&mcap)
        .unwrap()
        .to_dataset("run.mcap")
        .unwrap();
    assert_eq!(back.rate_hz(), csv.rate_hz());
    for c in ["u", "y"] {
        assert_eq!(back.column(c), csv.column(c), "column {c}");
    }
    // `diagnose` on the recording gives the report it gives on the CSV.
    let bin = env!("CARGO_BIN_EXE_nanomotion");
    let model = format!("{EXAMPLES}/diagnose/model.yaml");
    let report = |data: &str, out: &str| {
        let o = Command::new(bin)
            .args(["diagnose", &model, data, "--out"])
            .arg(dir.join(out))
            .output()
            .unwrap();
        succeeded(&o);
        std::fs::read_to_string(dir.join(out).join("report.json"))
            .unwrap()
            .replace(&mcap.display().to_string(), "DATA")
            .replace(&csv_path, "DATA")
    };
    // `run --data` too: the same comparison of the model with the recording
    // as with the CSV.
    let compared = |data: &str| {
        let o = Command::new(bin)
            .args(["run", &model, "--no-files", "--data", data])
            .output()
            .unwrap();
        succeeded(&o);
        let text = String::from_utf8_lossy(&o.stdout).into_owned();
        text.lines()
            .find(|l| l.starts_with("stage.y"))
            .unwrap_or_else(|| panic!("no comparison line in {text}"))
            .to_string()
    };
    assert_eq!(compared(&mcap.display().to_string()), compared(&csv_path));
    let from_mcap = report(&mcap.display().to_string(), "a");
    let from_csv = report(&csv_path, "b");
    // The effect hidden in the example's data (a Bouc–Wen input hysteresis,
    // tests/diagnose_example.rs) is named from the recording.
    assert!(from_mcap.contains("\"hysteresis\""), "{from_mcap}");
    assert_eq!(from_mcap, from_csv);
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn rt_lets_its_plant_go_before_writing_its_files() {
    // When the controller's loop ends, the plant must see the connection close
    // at once. `rt` used to keep the device until its files were written (an
    // 8 s recording takes longer than 100 ms here), so a plant with a short
    // watchdog stopped on it and failed; the device now detaches in its safe
    // state, from the loop thread as it stops, and the plant ends cleanly.
    //
    // The order is read off what the two processes recorded, not inferred from
    // a watchdog that did not fire: the plant's last tick, the one that found
    // the controller gone (its timing.json, CLOCK_MONOTONIC), came before `rt`
    // had finished writing any of its files (their modification times on the
    // same clock). The old order (files first, then the device let go) puts
    // that tick after all of them. Both watchdogs are long (10 s): whether a
    // loaded machine (CI's 2 cores running builds) ever stalls one loop for
    // the old 100 ms or the default 50 ms is not what this test is about, and
    // such a stall must not fail it.
    let name = format!("test-letgo-{}", std::process::id());
    let dir = std::env::temp_dir().join(format!("nanomotion-rt-letgo-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    let (plant_dir, rt_dir) = (dir.join("plant"), dir.join("rt"));
    let bin = env!("CARGO_BIN_EXE_nanomotion");
    let plant_out = plant_dir.display().to_string();
    let plant = serve_quickstart_plant(&name, &["--watchdog-ms", "10000", "--out", &plant_out]);
    let out = Command::new(bin)
        .args([
            "rt",
            &format!("{EXAMPLES}/realtime/quickstart_controller.yaml"),
        ])
        .args(["--device", &format!("shm:{name}"), "--duration", "8"])
        .args(["--watchdog-ms", "10000"])
        .args(["--allow-soft", "--record", "--out"])
        .arg(&rt_dir)
        .output()
        .unwrap();
    succeeded(&out);
    assert!(rt_dir.join("run.mcap").exists());
    let plant = plant.wait_with_output().unwrap();
    let log = String::from_utf8_lossy(&plant.stdout).into_owned()
        + &String::from_utf8_lossy(&plant.stderr);
    assert!(plant.status.success(), "plant: {log}");
    assert!(
        log.contains("the controller closed the connection"),
        "{log}"
    );
    let timing = |d: &std::path::Path| -> serde_json::Value {
        serde_json::from_str(&std::fs::read_to_string(d.join("timing.json")).unwrap()).unwrap()
    };
    let (plant_timing, rt_timing) = (timing(&plant_dir), timing(&rt_dir));
    assert_eq!(rt_timing["stop"], "completed", "{rt_timing}");
    assert_eq!(rt_timing["ticks"], 32_000, "{rt_timing}");
    assert_eq!(
        plant_timing["stop"], "stopped by the device: the controller closed the connection",
        "{plant_timing}"
    );
    let plant_saw_close = plant_timing["last_wake_ns"].as_u64().unwrap() as i128;
    // CLOCK_REALTIME − CLOCK_MONOTONIC, to put the files' times on the loops'
    // clock (a file time lags by at most a coarse-clock tick, a few ms).
    let since_epoch = |t: std::time::SystemTime| {
        t.duration_since(std::time::UNIX_EPOCH).unwrap().as_nanos() as i128
    };
    let offset =
        since_epoch(std::time::SystemTime::now()) - nanomotion::rt::clock::now_ns() as i128;
    let written: Vec<(String, i128)> = std::fs::read_dir(&rt_dir)
        .unwrap()
        .map(|e| {
            let e = e.unwrap();
            let t = since_epoch(e.metadata().unwrap().modified().unwrap()) - offset;
            (e.file_name().to_string_lossy().into_owned(), t)
        })
        .collect();
    assert!(written.len() >= 3, "{written:?}");
    for (file, t) in &written {
        assert!(
            plant_saw_close < *t,
            "the plant saw the controller close {} ms after `rt` wrote {file}",
            (plant_saw_close - t) as f64 * 1e-6
        );
    }
    let _ = std::fs::remove_dir_all(&dir);
}
