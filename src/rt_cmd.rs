//! `nanomotion rt` (a graph on the wall clock, against a device) and
//! `nanomotion plant` (a plant graph served to a controller in another process),
//! on top of the `nanomotion-rt` crate. See docs/realtime.md.
//!
//! While `rt` runs, lines on standard input (a terminal, or a pipe from a
//! script) change live parameters: `set ctrl.kp=1.2` (the grammar of `--set`),
//! judged by the block's validation and the stability gate before they reach
//! the loop, acknowledged on standard error with the tick they took effect at.

use nanomotion::core::graph::GraphSpec;
use nanomotion::core::{Override, Scheduler};
use nanomotion::output::{Manifest, OutputFolder};
use nanomotion::plot::{Figure, Scale, Series, draw_svg_panels};
use nanomotion_rt::clock::Privileges;
use nanomotion_rt::{
    Device, DeviceError, Event, Histogram, NoDevice, OverrunPolicy, ParamSender, PlantInfo,
    RealtimeRunner, RealtimeSpec, RtConfig, ShmDevice, ShmPlant, Stop, TimingReport, hw_blocks,
};
use std::path::{Path, PathBuf};
use std::time::Duration;

/// Real-time settings shared by `rt` and `plant`.
#[derive(clap::Args, Debug)]
pub struct Loop {
    /// Override the graph's duration (s): the number of ticks the loop runs.
    #[arg(long)]
    duration: Option<f64>,
    /// Pin the loop thread to this CPU (see isolcpus in docs/realtime.md).
    #[arg(long)]
    cpu: Option<usize>,
    /// SCHED_FIFO priority of the loop thread (1–99).
    #[arg(long, default_value_t = 80, value_parser = clap::value_parser!(u8).range(1..=99))]
    priority: u8,
    /// Run at normal priority when SCHED_FIFO or memory locking is refused
    /// (without it the run is refused, naming what is missing).
    #[arg(long)]
    allow_soft: bool,
    /// Overruns: `skip` the missed deadlines and stay on the grid, or `catch-up`
    /// (default: the graph's `realtime: { overrun }`, else skip).
    #[arg(long, value_name = "skip|catch-up")]
    overrun: Option<OverrunPolicy>,
    /// Stop (outputs safe) after more than N overruns (default: the graph's
    /// `realtime: { max_overruns }`, else never).
    #[arg(long, value_name = "N")]
    max_overruns: Option<u64>,
    /// Let the CPUs enter deep idle states during the run. By default the run
    /// holds /dev/cpu_dma_latency at 0 µs (as cyclictest does): the loop wakes
    /// tens of µs sooner on a quiet machine, at the cost of power.
    #[arg(long)]
    allow_idle_states: bool,
    /// Run even if the stability gate refuses the graph (an unstable, unproven
    /// or out-of-bounds loop inside it), as `run --allow-unproven` does; the
    /// run's report says so. Without it such a graph never starts.
    #[arg(long)]
    allow_unproven: bool,
    /// Busy-wait the last µs before each deadline (lower latency, one CPU busy).
    #[arg(long, default_value_t = 0.0, value_name = "US")]
    spin_us: f64,
    /// Stop when the other side has been silent this long (ms).
    #[arg(long, default_value_t = 50.0, value_name = "MS")]
    watchdog_ms: f64,
    /// Override a graph parameter by dotted path before building (repeatable),
    /// e.g. `--set base_rate_hz=20000`.
    #[arg(long = "set", value_name = "PATH=VALUE")]
    set: Vec<Override>,
    /// Output folder: timing.json, timing.svg and the logged signals (CSV).
    #[arg(long, short)]
    out: Option<PathBuf>,
    /// Replace a non-empty output folder that does not hold a previous run.
    #[arg(long)]
    force: bool,
    /// Record every hardware input and output sample into OUT/run.mcap (for
    /// Foxglove/PlotJuggler and `nanomotion replay`); needs --out.
    #[arg(long, requires = "out")]
    record: bool,
    /// Time every block of every tick: p50/p99/p99.9/max per block in the
    /// summary and timing.json (costs two clock reads per block and tick).
    #[arg(long)]
    block_timing: bool,
}

/// `nanomotion rt`.
#[derive(clap::Args, Debug)]
pub struct RtArgs {
    /// The graph file (YAML); its `hw_input`/`hw_output` blocks are the device's
    /// channels by name.
    graph: PathBuf,
    /// The device: `shm:NAME` (a plant served by `nanomotion plant --serve NAME`);
    /// without it the graph runs on the wall clock alone (no hw blocks allowed).
    #[arg(long, value_name = "shm:NAME")]
    device: Option<String>,
    /// How long to wait for the plant to appear (s).
    #[arg(long, default_value_t = 10.0, value_name = "S")]
    connect_timeout: f64,
    #[command(flatten)]
    lp: Loop,
}

/// `nanomotion plant`.
#[derive(clap::Args, Debug)]
pub struct PlantArgs {
    /// The plant graph (YAML): `hw_input` blocks are what the controller drives,
    /// `hw_output` blocks what it measures.
    graph: PathBuf,
    /// Serve the plant under this name (`/dev/shm/nanomotion-NAME`); a controller
    /// connects with `nanomotion rt CONTROLLER.yaml --device shm:NAME`.
    #[arg(long, value_name = "NAME")]
    serve: String,
    #[command(flatten)]
    lp: Loop,
}

/// The graph file with the command line's overrides and duration.
fn load(graph: &Path, lp: &Loop) -> Result<GraphSpec, String> {
    let mut spec =
        GraphSpec::from_file_with_overrides(graph, &lp.set).map_err(|e| e.to_string())?;
    if let Some(d) = lp.duration {
        spec.duration_s = d;
    }
    Ok(spec)
}

/// A graph built for the wall clock.
struct Built {
    sched: Scheduler,
    /// Its `realtime:` settings.
    settings: RealtimeSpec,
    /// What the stability gate said, for the run's report (empty when every
    /// loop passed without a note).
    gate: Vec<String>,
}

/// The graph built, judged by the stability gate as `run` judges it — before
/// the loop drives anything: a graph the gate refuses never starts unless
/// `--allow-unproven`, and then the run says so first.
fn build(graph: &Path, lp: &Loop) -> Result<Built, String> {
    let spec = load(graph, lp)?;
    let require = spec.require.clone();
    let settings = spec.realtime.unwrap_or_default();
    let (sched, report) = spec.build().map_err(|e| e.to_string())?;
    for r in &report.rate_transitions {
        tell!("note: rate transition {r}");
    }
    let gate = crate::gate_cmd::before_run(
        &crate::gate_cmd::analyse(&sched, require.as_ref()),
        lp.allow_unproven,
    )
    .map_err(|e| format!("{}: {e}", graph.display()))?;
    for l in &gate {
        say!("stability gate: {l}");
    }
    Ok(Built {
        sched,
        settings,
        gate,
    })
}

/// The loop's configuration: the command line's settings over the graph's.
fn config(lp: &Loop, graph: RealtimeSpec) -> Result<RtConfig, String> {
    if !(lp.spin_us.is_finite() && (0.0..=1000.0).contains(&lp.spin_us)) {
        return Err(format!(
            "--spin-us {}: must be within 0..=1000 µs (fix: e.g. --spin-us 5)",
            lp.spin_us
        ));
    }
    let privileges = Privileges {
        priority: Some(lp.priority),
        cpu: lp.cpu,
        lock_memory: true,
        hold_cpu_latency: !lp.allow_idle_states,
    };
    let settings = graph.overridden_by(RealtimeSpec {
        overrun: lp.overrun,
        max_overruns: lp.max_overruns,
    });
    Ok(RtConfig {
        spin_ns: (lp.spin_us * 1e3) as u64,
        block_timing: lp.block_timing,
        ..RtConfig::new(privileges, lp.allow_soft, settings)
    })
}

fn watchdog(lp: &Loop) -> Result<Duration, String> {
    nanomotion_rt::shm::watchdog_ms(lp.watchdog_ms).map_err(|e| format!("--watchdog-ms: {e}"))
}

/// Print a status line on a terminal (stderr) for each status event, and
/// every live parameter update applied (`params`: the paths of the graph's
/// live parameters); pass Ctrl-C on to the loop.
fn status(
    stop: std::sync::Arc<std::sync::atomic::AtomicBool>,
    rate_hz: f64,
    params: Vec<String>,
) -> impl FnMut(Event) {
    let tty = std::io::IsTerminal::is_terminal(&std::io::stderr());
    move |e| {
        if nanomotion::output::signals::interrupted().is_some() {
            stop.store(true, std::sync::atomic::Ordering::Relaxed);
        }
        match e {
            Event::Status {
                ticks,
                overruns,
                worst_latency_ns,
                worst_execution_ns,
            } if tty => {
                eprint!(
                    "\r  t {:>8.2} s  ticks {ticks:>10}  overruns {overruns:>5}  worst wake-up {:>8.1} µs  worst tick {:>8.1} µs   ",
                    ticks as f64 / rate_hz,
                    worst_latency_ns as f64 * 1e-3,
                    worst_execution_ns as f64 * 1e-3
                );
            }
            Event::Param { tick, param, value } => {
                let path = params.get(param as usize).map_or("?", String::as_str);
                tell!(
                    "{}  set {path} = {value} at tick {tick} (t = {:.6} s){:20}",
                    if tty { "\r" } else { "" },
                    tick as f64 / rate_hz,
                    ""
                );
            }
            Event::Overrun { tick, late_ns } if tty => {
                eprint!(
                    "\r  overrun at tick {tick}: {:.1} µs late{:40}\n",
                    late_ns as f64 * 1e-3,
                    ""
                );
            }
            _ => {}
        }
    }
}

/// Read `set PATH=VALUE` lines from standard input on a thread of its own
/// (detached: it may stay blocked on a terminal after the loop ends) and send
/// them into the loop; refusals are printed and the loop goes on.
fn read_updates(mut sender: ParamSender) {
    use std::io::BufRead as _;
    let usage = |sender: &ParamSender| {
        let live: Vec<&str> = sender.params().iter().map(|p| p.path.as_str()).collect();
        format!(
            "write `set BLOCK.PARAM=VALUE`, e.g. `set {}=1.2` (live parameters: {})",
            live.first().copied().unwrap_or("ctrl.kp"),
            if live.is_empty() {
                "none in this graph".to_string()
            } else {
                live.join(", ")
            }
        )
    };
    let spawned = std::thread::Builder::new()
        .name("nanomotion-rt-stdin".into())
        .spawn(move || {
            for line in std::io::stdin().lock().lines() {
                let Ok(line) = line else { break };
                let line = line.trim();
                if line.is_empty() {
                    continue;
                }
                match line.strip_prefix("set ") {
                    Some(text) => {
                        if let Err(e) = sender.set_text(text.trim()) {
                            tell!("  refused: {e}");
                        }
                    }
                    None => tell!("  `{line}`: unknown command ({})", usage(&sender)),
                }
            }
        });
    if let Err(e) = spawned {
        tell!("note: live parameter updates from standard input are off: {e}");
    }
}

fn run_loop<D: Device>(
    graph: &Path,
    Built {
        sched,
        settings,
        gate,
    }: Built,
    device: D,
    lp: &Loop,
    command: &str,
    ticks: Option<u64>,
) -> Result<(TimingReport, Scheduler, nanomotion_rt::Timing), String> {
    let cfg = RtConfig {
        ticks,
        record: lp.record,
        ..config(lp, settings)?
    };
    let rate = sched.base_rate_hz();
    let folder = match &lp.out {
        Some(out) => Some(OutputFolder::prepare(out, lp.force).map_err(|e| e.to_string())?),
        None => None,
    };
    let mut runner = RealtimeRunner::new(sched, device, cfg).map_err(|e| e.to_string())?;
    let stop = runner.stop_handle();
    say!(
        "{}: {command} at {rate} Hz on the wall clock, device {}",
        graph.display(),
        runner.device().name()
    );
    let params: Vec<String> = runner.live_params().into_iter().map(|p| p.path).collect();
    if command == "rt" {
        // Live updates from standard input, judged by the stability gate on a
        // second build of the same graph (never ticked), joined with the
        // device's plant and latency when the loop closes through it.
        let sender = runner
            .param_sender()
            .map_err(|e| e.to_string())?
            .gated_through(load(graph, lp)?, runner.device())
            .map_err(|e| e.to_string())?;
        if !params.is_empty() && std::io::IsTerminal::is_terminal(&std::io::stdin()) {
            tell!(
                "live parameters: {} (type `set {}=VALUE` and Enter to change one while the loop runs)",
                params.join(", "),
                params[0]
            );
        }
        read_updates(sender);
    }
    let report = runner
        .run(status(stop, rate, params))
        .map_err(|e| e.to_string())?;
    if std::io::IsTerminal::is_terminal(&std::io::stderr()) {
        eprintln!();
    }
    let timing = runner.timing().clone();
    let recording = runner.take_recording();
    let (sched, device) = runner.into_parts();
    // Let the device go before writing anything, so that the other side (a
    // plant's watchdog) sees the end now, not after the files are written.
    drop(device);
    if let (Some(folder), Some(rec)) = (&folder, &recording) {
        nanomotion_rt::write_mcap(&folder.dir().join("run.mcap"), rec)
            .map_err(|e| e.to_string())?;
    }
    print_report(&report);
    if let Some(folder) = folder
        && nanomotion::output::signals::interrupted().is_none()
    {
        let result = sched.result();
        write_outputs(&folder, &report, &timing, &result.logs)?;
        let files = folder
            .commit(Some(&Manifest {
                command,
                graph: &graph.display().to_string(),
                title: &result.title,
                stability_gate: &gate,
            }))
            .map_err(|e| e.to_string())?;
        say!(
            "wrote {} files to {}",
            files.len(),
            lp.out
                .as_ref()
                .map_or(String::new(), |p| p.display().to_string())
        );
    }
    Ok((report, sched, timing))
}

fn print_report(r: &TimingReport) {
    say!(
        "{} ticks at {} Hz ({}), {}; overruns {}, missed ticks {} (policy {}, limit {}), events dropped {}, live parameter updates {}",
        r.ticks,
        r.rate_hz,
        r.scheduling,
        r.stop,
        r.overruns,
        r.missed_ticks,
        r.overrun_policy,
        r.max_overruns.map_or("none".to_string(), |m| m.to_string()),
        r.events_dropped,
        r.param_updates
    );
    for m in &r.missing_privileges {
        say!("soft run: {m}");
    }
    if let Some(m) = &r.cpu_latency_refused {
        say!("note: {m} (the loop wakes later from deep idle states)");
    }
    // The first column fits the longest row name (`  block NAME`).
    let w = r
        .blocks
        .iter()
        .map(|b| b.name.chars().count() + 8)
        .max()
        .unwrap_or(0)
        .max(18);
    say!(
        "{:<w$} {:>10} {:>10} {:>10} {:>10} {:>10}",
        "µs",
        "p50",
        "p99",
        "p99.9",
        "max",
        "mean"
    );
    let us = |v: Option<u64>| v.map_or("-".to_string(), |v| format!("{:.2}", v as f64 * 1e-3));
    let blocks = r
        .blocks
        .iter()
        .map(|b| (format!("  block {}", b.name), &b.time));
    for (name, s) in [
        ("wake-up latency", &r.wakeup_latency),
        ("period", &r.period),
        ("|period − T|", &r.period_jitter),
        ("execution", &r.execution),
    ]
    .into_iter()
    .map(|(n, s)| (n.to_string(), s))
    .chain(blocks)
    {
        say!(
            "{:<w$} {:>10} {:>10} {:>10} {:>10} {:>10}",
            name,
            us(s.p50_ns),
            us(s.p99_ns),
            us(s.p999_ns),
            us(s.max_ns),
            s.mean_ns
                .map_or("-".to_string(), |m| format!("{:.2}", m * 1e-3))
        );
    }
}

/// The fraction of ticks at or above each bucket (an exceedance curve: the
/// tail that a histogram's linear axis hides), in µs against log10(fraction).
fn exceedance(label: &str, h: &Histogram) -> Series {
    let n = h.count().max(1) as f64;
    let mut above = h.count();
    let (mut x, mut y) = (Vec::new(), Vec::new());
    for (lo, hi, c) in h.buckets() {
        x.push(lo.max(1) as f64 * 1e-3);
        y.push((above as f64 / n).log10());
        above -= c;
        x.push(hi.max(1) as f64 * 1e-3);
        y.push(((above.max(1)) as f64 / n).log10().min(0.0));
    }
    Series {
        label: label.into(),
        x,
        y,
    }
}

fn write_outputs(
    folder: &OutputFolder,
    report: &TimingReport,
    timing: &nanomotion_rt::Timing,
    logs: &[nanomotion::core::scheduler::SignalLog],
) -> Result<(), String> {
    let dir = folder.dir();
    let json = serde_json::to_string_pretty(report).map_err(|e| e.to_string())?;
    std::fs::write(dir.join("timing.json"), json + "\n")
        .map_err(|e| format!("{}: {e}", dir.join("timing.json").display()))?;
    let panel = |title: &str, h: &Histogram| Figure {
        title: format!("{title} ({} ticks)", h.count()),
        x_label: "µs".into(),
        y_label: "log10 fraction of ticks ≥ x".into(),
        y_unit: None,
        x_scale: Scale::Log,
        series: vec![exceedance(title, h)],
    };
    draw_svg_panels(
        &[
            panel("wake-up latency", &timing.wakeup_latency),
            panel("|period − T|", &timing.period_jitter),
            panel("execution time", &timing.execution),
        ],
        &dir.join("timing.svg"),
    )
    .map_err(|e| e.to_string())?;
    nanomotion::output::write_csv(dir, logs).map_err(|e| e.to_string())?;
    Ok(())
}

/// `nanomotion rt GRAPH [--device shm:NAME]`.
pub fn rt(a: RtArgs) -> Result<(), String> {
    nanomotion_rt::link_blocks();
    let built = build(&a.graph, &a.lp)?;
    let (report, sched, _) =
        match a.device.as_deref() {
            None => run_loop(&a.graph, built, NoDevice, &a.lp, "rt", None)?,
            Some(d) => {
                let dev = ShmDevice::connect_named(d, a.connect_timeout, a.lp.watchdog_ms)
                    .map_err(|e| match e {
                        nanomotion_rt::ConnectError::ConnectTimeout(_) => {
                            format!("--connect-timeout: {e}")
                        }
                        nanomotion_rt::ConnectError::Watchdog(_) => format!("--watchdog-ms: {e}"),
                        _ => e.to_string(),
                    })?;
                // The loop closes through the device: the gate judges it with
                // the plant's graph and the device's latency, before it runs.
                let mut built = built;
                let lines = nanomotion_rt::through::before_run_through(
                    load(&a.graph, &a.lp)?,
                    &dev,
                    a.lp.allow_unproven,
                    &nanomotion::core::gate::FrontEnd::CLI,
                )
                .map_err(|e| format!("{}: {e}", a.graph.display()))?;
                for l in &lines {
                    say!("stability gate: {l}");
                }
                built.gate.extend(lines);
                run_loop(&a.graph, built, dev, &a.lp, "rt", None)?
            }
        };
    print_scores(&sched);
    match report.stopped {
        Stop::Completed | Stop::Interrupted => Ok(()),
        other => Err(format!("{}: {other}", a.graph.display())),
    }
}

fn print_scores(sched: &Scheduler) {
    for s in sched.result().scores {
        say!(
            "score {:<28} rms {:.4e} max |.| {:.4e} {}",
            s.signal,
            s.rms,
            s.max_abs,
            s.unit.as_deref().unwrap_or("")
        );
    }
}

/// `nanomotion plant GRAPH --serve NAME`.
pub fn plant(a: PlantArgs) -> Result<(), String> {
    nanomotion_rt::link_blocks();
    let mut lp = a.lp;
    // Without --duration the plant runs until the controller leaves.
    let ticks = lp.duration.take();
    let built = build(&a.graph, &lp)?;
    let (to_plant, from_plant) = hw_blocks(&built.sched);
    let channel = |(name, unit): (String, Option<String>)| nanomotion_rt::Channel { name, unit };
    let info = PlantInfo {
        title: built.sched.result().title,
        rate_hz: built.sched.base_rate_hz(),
        to_plant: to_plant.into_iter().map(channel).collect(),
        from_plant: from_plant.into_iter().map(channel).collect(),
        // For the controller's stability gate on the loop through the device.
        graph: Some(serde_json::to_value(load(&a.graph, &lp)?).map_err(|e| e.to_string())?),
    };
    if info.to_plant.is_empty() && info.from_plant.is_empty() {
        return Err(format!(
            "{}: the plant graph has no hw_input or hw_output block, nothing to serve (fix: `- {{ name: drive, type: hw_input }}` for what the controller drives, `- {{ name: position, type: hw_output }}` for what it measures)",
            a.graph.display()
        ));
    }
    let rate = built.sched.base_rate_hz();
    let device = ShmPlant::serve(&a.serve, info, watchdog(&lp)?).map_err(|e| e.to_string())?;
    say!(
        "serving `{}` ({} in, {} out): connect with `nanomotion rt CONTROLLER.yaml --device shm:{}`",
        a.serve,
        device.inputs().len(),
        device.outputs().len(),
        a.serve
    );
    // Logs hold the graph's duration; a longer plant run drops (and counts)
    // the samples beyond it, without allocating.
    let ticks = ticks.map_or(u64::MAX, |d| (d * rate).round() as u64);
    let (report, _, _) = run_loop(&a.graph, built, device, &lp, "plant", Some(ticks))?;
    match report.stopped {
        Stop::Completed | Stop::Interrupted | Stop::Device(DeviceError::Closed(_)) => Ok(()),
        other => Err(format!("{}: {other}", a.graph.display())),
    }
}

/// `nanomotion replay`.
#[derive(clap::Args, Debug)]
pub struct ReplayArgs {
    /// A recording written by `nanomotion rt --record` (OUT/run.mcap).
    recording: PathBuf,
    /// The controller graph that was recorded (YAML).
    graph: PathBuf,
    /// Override a graph parameter before building (repeatable): replaying with a
    /// changed gain shows where the outputs part.
    #[arg(long = "set", value_name = "PATH=VALUE")]
    set: Vec<Override>,
}

/// `nanomotion replay RUN.mcap GRAPH`: the recorded inputs through the graph,
/// outputs compared bit for bit.
pub fn replay(a: ReplayArgs) -> Result<(), String> {
    nanomotion_rt::link_blocks();
    let rec = nanomotion_rt::read_mcap(&a.recording).map_err(|e| e.to_string())?;
    let mut spec =
        GraphSpec::from_file_with_overrides(&a.graph, &a.set).map_err(|e| e.to_string())?;
    spec.duration_s = rec.ticks() as f64 / rec.rate_hz;
    let (mut sched, _) = spec.build().map_err(|e| e.to_string())?;
    let r = nanomotion_rt::replay(&mut sched, &rec).map_err(|e| e.to_string())?;
    match &r.first {
        None => {
            let updates = match rec.param_changes.len() {
                0 => String::new(),
                1 => " with its live parameter update".to_string(),
                n => format!(" with its {n} live parameter updates"),
            };
            say!(
                "{}: replayed {} ticks through {}{updates}: all {} output samples bit-identical",
                a.recording.display(),
                r.ticks,
                a.graph.display(),
                r.compared
            );
            Ok(())
        }
        Some((tick, channel, want, got)) => Err(format!(
            "{}: {} of {} output samples differ; first at tick {tick}, `{channel}`: recorded {want:e}, replayed {got:e} (the graph or its parameters are not the ones recorded)",
            a.recording.display(),
            r.mismatches,
            r.compared
        )),
    }
}
