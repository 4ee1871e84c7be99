//! The `nanomotion` command: run, check and inspect YAML controller graphs.

/// `println!` that survives a closed pipe (`nanomotion run … | head -1`): a
/// broken pipe ends the printing quietly (the command still finishes its work
/// and writes its files), any other write error is reported once on stderr.
macro_rules! say {
    ($($t:tt)*) => {
        $crate::emit(false, format_args!($($t)*))
    };
}

/// `eprintln!` that survives a closed pipe (`nanomotion run … 2>&1 | head -1`),
/// as [`say!`] does for standard output.
macro_rules! tell {
    ($($t:tt)*) => {
        $crate::emit(true, format_args!($($t)*))
    };
}

mod compensate_cmd;
mod diagnose_cmd;
mod gate_cmd;
mod optimize_cmd;
mod reproduce_cmd;
mod rt_cmd;
mod scan_image_cmd;
mod sweep_cmd;
mod synth_cmd;

use clap::{Parser, Subcommand};
use indicatif::{ProgressBar, ProgressStyle};
use nanomotion::core::block::{block_docs, registered_types};
use nanomotion::core::graph::GraphSpec;
use std::path::PathBuf;
use std::process::ExitCode;
use std::time::{Duration, Instant};

/// One line to standard output (`to_stderr`: standard error). A stream that
/// failed once (a closed pipe) is not written again.
fn emit(to_stderr: bool, args: std::fmt::Arguments<'_>) {
    use std::io::Write as _;
    use std::sync::atomic::{AtomicBool, Ordering};
    static FAILED: [AtomicBool; 2] = [AtomicBool::new(false), AtomicBool::new(false)];
    let failed = &FAILED[usize::from(to_stderr)];
    if failed.load(Ordering::Relaxed) {
        return;
    }
    let r = if to_stderr {
        let mut e = std::io::stderr().lock();
        e.write_fmt(args).and_then(|()| e.write_all(b"\n"))
    } else {
        let mut o = std::io::stdout().lock();
        o.write_fmt(args).and_then(|()| o.write_all(b"\n"))
    };
    if let Err(e) = r {
        failed.store(true, Ordering::Relaxed);
        if e.kind() != std::io::ErrorKind::BrokenPipe && !to_stderr {
            tell!("warning: cannot write to standard output: {e}");
        }
    }
}

/// Simulate and control nano-motion systems (piezo stages, encoders) from YAML
/// controller graphs.
///
/// A graph names blocks (references, controllers, plants, sensors) by `type:`, wires
/// their ports, and says what to log and score. See docs/graph-format.md, and
/// examples/quickstart.yaml for a first loop.
#[derive(Parser, Debug)]
#[command(
    name = "nanomotion",
    version,
    about,
    long_about,
    arg_required_else_help = true
)]
#[command(
    after_help = "Examples:\n  nanomotion run examples/quickstart.yaml --out out/quickstart\n  nanomotion check examples/quickstart.yaml\n  nanomotion rc-check examples/rc_dvrc.yaml\n  nanomotion optimize-waveform examples/optimize_waveform/model.yaml --budget 0.1\n  nanomotion diagnose examples/diagnose/model.yaml examples/diagnose/record.csv\n  nanomotion blocks"
)]
struct Cli {
    /// Show the library's diagnostics on stderr: -v build notes and progress
    /// (info), -vv details (debug), -vvv everything (trace). `RUST_LOG` (e.g.
    /// `RUST_LOG=nanomotion_core=debug`) overrides it.
    #[arg(short, long, action = clap::ArgAction::Count, global = true)]
    verbose: u8,
    #[command(subcommand)]
    command: Command,
}

/// Send `tracing` events to stderr: `RUST_LOG` if set, else by `-v` count
/// (default: warnings only).
fn init_tracing(verbose: u8) {
    use tracing_subscriber::EnvFilter;
    let filter = EnvFilter::try_from_default_env().unwrap_or_else(|_| {
        EnvFilter::new(match verbose {
            0 => "warn",
            1 => "info",
            2 => "debug",
            _ => "trace",
        })
    });
    let _ = tracing_subscriber::fmt()
        .with_env_filter(filter)
        .with_writer(std::io::stderr)
        .with_target(true)
        .with_ansi(std::io::IsTerminal::is_terminal(&std::io::stderr()))
        .without_time()
        .try_init();
}

#[derive(Subcommand, Debug)]
enum Command {
    /// Run a graph: print a metrics table and write signals (CSV), metrics (JSON)
    /// and plots (SVG) into the output folder.
    Run {
        /// The graph file (YAML).
        graph: PathBuf,
        /// Output folder (default out/<graph stem>). Written atomically: files go
        /// into a temporary folder that replaces this one when complete, with
        /// `nanomotion-run.json` written last. A folder holding a previous run is
        /// replaced; any other non-empty folder is refused unless --force.
        #[arg(long, short)]
        out: Option<PathBuf>,
        /// Replace a non-empty output folder that does not hold a previous run.
        #[arg(long)]
        force: bool,
        /// Override the graph's seed.
        #[arg(long)]
        seed: Option<u64>,
        /// Override the graph's duration (s).
        #[arg(long)]
        duration: Option<f64>,
        /// Write no files, print the metrics only.
        #[arg(long)]
        no_files: bool,
        /// Measured data (CSV with a `t_s` column, MATLAB v5 `.mat`, or a recording
        /// `RUN.mcap`, its hardware channels as columns): played by
        /// `data_column` blocks and compared with the graph's `compare:` signals
        /// (rms, max, fit %, `comparison.json`, `compare_*.svg`). The duration
        /// becomes the data's length unless --duration is given. Give it twice to
        /// merge two files of the same rate and length (e.g. input and output
        /// saved as separate `.mat` files).
        #[arg(long, value_name = "FILE")]
        data: Vec<PathBuf>,
        /// Sample rate (Hz) of a `.mat` data file that has no time vector `t`.
        #[arg(long, value_name = "HZ", requires = "data")]
        data_rate: Option<f64>,
        /// Run even if the stability gate refuses the graph (an unstable,
        /// unproven or out-of-bounds loop); the run's report says so.
        #[arg(long)]
        allow_unproven: bool,
        /// Override a graph parameter by dotted path before building, e.g.
        /// `--set blocks.pi.kp=2.0 --set duration_s=0.5` (repeatable; the value is
        /// YAML; list entries by index, `blocks.stage.den.0`). See docs/sweep.md.
        #[arg(long = "set", value_name = "PATH=VALUE")]
        set: Vec<nanomotion::core::Override>,
        /// Record every `hw_input`/`hw_output` sample into OUT/run.mcap, as
        /// `nanomotion rt --record` does (for Foxglove/PlotJuggler and
        /// `nanomotion replay`); the hw signals are logged too.
        #[arg(long, conflicts_with = "no_files")]
        record: bool,
    },
    /// Validate a graph without running it: parse, build every block, resolve ports,
    /// rates and execution order, report inserted rate transitions, and analyse every
    /// feedback loop (the stability gate: closed-loop poles, margins, ‖S‖∞, ‖T‖∞,
    /// learning criteria). Exits with status 1 naming the loop when one is unstable,
    /// unproven without a stated reason, or misses a `require:` bound.
    Check {
        /// The graph file (YAML).
        graph: PathBuf,
        /// Measured data for a graph that reads data (`data_column`, `compare:`),
        /// as for `run --data`: the columns and rates are checked too, and the
        /// duration becomes the data's length. Without it such a graph is checked
        /// with placeholder columns (wiring, rates and loops only).
        #[arg(long, value_name = "FILE")]
        data: Vec<PathBuf>,
        /// Sample rate (Hz) of a `.mat` data file that has no time vector `t`.
        #[arg(long, value_name = "HZ", requires = "data")]
        data_rate: Option<f64>,
        /// Also print each loop's L, S = 1/(1 + L) and T = L/(1 + L), and the T(z)
        /// of each learning block (`t_model:` to paste), as YAML transfer
        /// functions in z.
        #[arg(long)]
        print_loop: bool,
    },
    /// Check the stability criteria of the graph's repetitive controllers: (5.5) for
    /// a fixed period N, (5.9) ‖Q(1 − T L z^l)‖∞ < 1/√(M − m + 1) for a delay varying
    /// in [m, M] (DVRC), with the margin and the frequency where it is tightest; for
    /// small DVRC loops also the lifted switched system (5.13)–(5.16) (LMIs and a
    /// joint-spectral-radius bound), which can prove what (5.9) cannot. Exits with
    /// status 2 when stability is not guaranteed.
    RcCheck {
        /// The graph file (YAML).
        graph: PathBuf,
    },
    /// Optimise the walking-piezo drive waveforms (thesis Sec. 4.5): 32 points by
    /// simulated annealing and particle swarm, then Nelder–Mead, on the model-based
    /// (4.23) or data-based (4.25) objective. Writes `run.json` (resumable: run the
    /// same command again to continue) and `waveform.yaml` (a driver fragment).
    OptimizeWaveform {
        /// The optimisation config (YAML), e.g. examples/optimize_waveform/model.yaml.
        config: PathBuf,
        /// Output folder (created if missing).
        #[arg(long, short, default_value = "out/optimize_waveform")]
        out: PathBuf,
        /// Scale every phase's iterations per chunk by this factor (e.g. 0.1).
        #[arg(long)]
        budget: Option<f64>,
    },
    /// Find where a model and a measured record disagree, name the missing effect
    /// (hysteresis, friction, time_delay, repetitive_disturbance,
    /// position_dependent_gain, quantization, unmodeled_resonance, drift, creep,
    /// axis_coupling, encoder_slit_error, saturation, backlash), fit it, insert it
    /// into the graph and show the held-out residual shrink; repeat until nothing
    /// significant is left. Writes `model_augmented.yaml`, `report.json`, evidence
    /// plots and residual PSDs into the output folder.
    Diagnose {
        /// The nominal model graph (YAML) with `data_column` inputs and `compare:` entries.
        model: PathBuf,
        /// The measured record (CSV with a `t` or `t_s` column, MATLAB v5 `.mat`,
        /// or a recording `RUN.mcap` of `nanomotion rt --record`/`run --record`,
        /// its hardware channels as columns).
        data: PathBuf,
        /// Further records (same columns and rate, other excitations): DATA then
        /// estimates every parameter and these are held out whole — an effect is
        /// named only if it helps on them. Each record is simulated from rest.
        validation: Vec<PathBuf>,
        /// Output folder (default out/diagnose_<model stem>).
        #[arg(long, short)]
        out: Option<PathBuf>,
        /// Write the JSON report here too (default: <out>/report.json).
        #[arg(long)]
        json: Option<PathBuf>,
        /// Name at most this many effects (0: only calibrate the nominal's own
        /// parameters — gains, time scales, damping — and say whether that is
        /// significant).
        #[arg(long, default_value_t = 3)]
        max_effects: usize,
        /// Fraction of the record, at its end, held out for scoring (one record only).
        #[arg(long, default_value_t = 0.3)]
        holdout: f64,
        /// Override the graph's seed.
        #[arg(long)]
        seed: Option<u64>,
        /// Only try these effects (comma separated vocabulary names).
        #[arg(long, value_delimiter = ',')]
        effects: Vec<String>,
        /// A signal of the model (BLOCK.PORT) a disturbance may be periodic in
        /// besides the position, e.g. `alpha.y`, the drive's phase (the leg
        /// angle α = 2π∫f_α of a walking piezo drive, integrated in the model):
        /// a `repetitive_disturbance` periodic in it is tried on the measured
        /// output and on the drive, its period found from the data (docs/plf.md,
        /// "A disturbance periodic in a declared phase"). A signal the model
        /// lacks is refused, naming the model's signals.
        #[arg(long, value_name = "SIGNAL")]
        phase: Option<String>,
        /// Replace a non-empty output folder that does not hold a previous output.
        #[arg(long)]
        force: bool,
    },
    Compensate(compensate_cmd::Args),
    /// Heat maps of a scan from a run folder (`signals.csv`): for each `--image
    /// NAME=H,V,VALUE` an SVG `NAME.svg` of VALUE (nm, mean removed; a leading `-`
    /// flips its sign) over the plane (H, V) in µm, e.g. the topography and the
    /// error of the AFM scan in examples/directional_rc/scan_rc_vs_drc.yaml.
    ScanImage {
        /// The run folder (written by `nanomotion run`).
        run_dir: PathBuf,
        /// NAME=H_COLUMN,V_COLUMN,VALUE_COLUMN (repeatable).
        #[arg(long = "image", value_parser = scan_image_cmd::parse_spec)]
        images: Vec<scan_image_cmd::ImageSpec>,
        /// Use samples from this time on (s).
        #[arg(long, default_value_t = 0.0)]
        from_s: f64,
        /// Pixels along H and V.
        #[arg(long, num_args = 2, value_names = ["NH", "NV"], default_values_t = [200, 40])]
        pixels: Vec<usize>,
    },
    /// H∞ mixed-sensitivity synthesis (thesis Sec. 7.3.2) from a YAML config of
    /// plant, weights (7.10)–(7.12) and control rate. Writes `controller.yaml` (a
    /// `mimo_controller` block entry), `report.json`, `generalized_plant.json` and
    /// SVG plots of K, S_o, T_o, the characteristic loci and the (7.4) test.
    Synth {
        /// The synthesis config (YAML), e.g. examples/mimo/afm_synth.yaml.
        config: PathBuf,
        /// Output folder (created if missing; written atomically, as `run` does).
        #[arg(long, short, default_value = "out/synth")]
        out: PathBuf,
        /// Replace a non-empty output folder that does not hold a previous output.
        #[arg(long)]
        force: bool,
    },
    /// Run a parameter study (grid, random, latin-hypercube or monte-carlo over
    /// graph parameters by dotted path) in parallel: writes `results.csv`,
    /// `results.parquet` (one row per run: parameters, seed, scores, wall time,
    /// gate verdict, error), `plan.json` and SVG plots. Resumable: finished runs
    /// (`rows.jsonl`) are kept when the same command runs again. See docs/sweep.md.
    Sweep {
        /// The study file (YAML), e.g. examples/sweep/quickstart_monte_carlo.yaml.
        study: PathBuf,
        /// Output folder (default out/sweep_<study stem>).
        #[arg(long, short)]
        out: Option<PathBuf>,
        /// Parallel runs (default: all cores; more than the cores is capped).
        #[arg(long, short, default_value_t = 0)]
        jobs: usize,
        /// Discard the finished rows in the output folder and start again.
        #[arg(long)]
        restart: bool,
        /// Compute at most this many runs now (the rest on a later run).
        #[arg(long)]
        limit: Option<usize>,
    },
    /// Reproduce the thesis's tables and figures (`--list` lists them): run the
    /// experiments, print thesis vs ours with a verdict (matches / shape / deviates)
    /// and write `fidelity.md`, `fidelity.json` (deterministic: a re-run gives the
    /// same bytes) and `timings.json` into the output folder. docs/thesis-fidelity.md
    /// is the `--quick` output. Exits with status 1 if an experiment could not run.
    Reproduce {
        /// Experiment ids (default: all).
        names: Vec<String>,
        /// The quick set in quick mode (shorter records; under two minutes).
        #[arg(long)]
        quick: bool,
        /// Output folder (created if missing).
        #[arg(long, short, default_value = "out/fidelity")]
        out: PathBuf,
        /// List the experiments and exit.
        #[arg(long)]
        list: bool,
        /// Replace a non-empty output folder that does not hold a previous output.
        #[arg(long)]
        force: bool,
    },
    /// List the registered block types, with their ports and parameters.
    Blocks {
        /// Show only types whose name contains this text.
        filter: Option<String>,
    },
    /// Run a graph on the wall clock at its base rate (SCHED_FIFO, absolute
    /// deadlines), against a device (`--device shm:NAME`: a plant served by
    /// `nanomotion plant`); prints wake-up latency, period and execution time
    /// (p50/p99/p99.9/max) and overruns, writes timing.json, timing.svg and the
    /// logs. See docs/realtime.md.
    Rt(rt_cmd::RtArgs),
    /// Serve a plant graph to a controller in another process: runs it on its own
    /// real-time loop, its `hw_input`/`hw_output` blocks in shared memory
    /// (`/dev/shm/nanomotion-NAME`), until the controller leaves.
    Plant(rt_cmd::PlantArgs),
    /// Re-run a controller graph on the hardware inputs recorded by `nanomotion rt
    /// --record` (RUN.mcap) and check that it reproduces the recorded outputs bit
    /// for bit.
    Replay(rt_cmd::ReplayArgs),
    /// Print the JSON Schema of a graph file (every registered block type), for
    /// editors: `nanomotion schema > graph.schema.json` (see docs/graph-format.md).
    Schema,
}

fn main() -> ExitCode {
    nanomotion::link_plugins();
    let cli = Cli::parse();
    init_tracing(cli.verbose);
    if let Err(e) = nanomotion::output::signals::install() {
        tell!(
            "warning: cannot catch Ctrl-C ({e}): an interrupted command may leave a hidden `.OUT.partial-PID` folder, removed by the next command writing there"
        );
    }
    let result = match cli.command {
        Command::Run {
            graph,
            out,
            force,
            seed,
            duration,
            no_files,
            data,
            data_rate,
            allow_unproven,
            set,
            record,
        } => run(RunArgs {
            set,
            record,
            graph,
            out,
            force,
            seed,
            duration,
            no_files,
            data,
            data_rate,
            allow_unproven,
        }),
        Command::Check {
            graph,
            data,
            data_rate,
            print_loop,
        } => check(graph, &data, data_rate, print_loop),
        Command::RcCheck { graph } => match nanomotion::dvrc::check::rc_check_file(&graph) {
            Ok(report) if report.blocks.is_empty() => Err(format!(
                "{}: no repetitive_control, high_order_rc or dvrc block, nothing to check (fix: rc-check a graph with a repetitive controller, e.g. examples/rc_dvrc.yaml; `nanomotion check` validates any graph)",
                graph.display()
            )),
            Ok(report) => {
                say!("{}", report.to_string().trim_end());
                if !report.all_hold() {
                    return ExitCode::from(2);
                }
                Ok(())
            }
            Err(e) => Err(e.to_string()),
        },
        Command::OptimizeWaveform {
            config,
            out,
            budget,
        } => optimize_cmd::optimize_waveform(&config, &out, budget),
        Command::Diagnose {
            model,
            data,
            validation,
            out,
            json,
            max_effects,
            holdout,
            seed,
            effects,
            phase,
            force,
        } => diagnose_cmd::run(diagnose_cmd::Args {
            model,
            data,
            validation,
            out,
            json,
            max_effects,
            holdout,
            seed,
            effects,
            phase,
            force,
        }),
        Command::Compensate(a) => compensate_cmd::run(a),
        Command::ScanImage {
            run_dir,
            images,
            from_s,
            pixels,
        } => scan_image_cmd::run(&run_dir, &images, from_s, (pixels[0], pixels[1])),
        Command::Synth { config, out, force } => synth_cmd::synth(&config, &out, force),
        Command::Sweep {
            study,
            out,
            jobs,
            restart,
            limit,
        } => sweep_cmd::sweep(&study, out, jobs, restart, limit),
        Command::Rt(a) => rt_cmd::rt(a),
        Command::Plant(a) => rt_cmd::plant(a),
        Command::Replay(a) => rt_cmd::replay(a),
        Command::Blocks { filter } => blocks(filter.as_deref()),
        Command::Schema => serde_json::to_string_pretty(&nanomotion::core::graph::graph_schema())
            .map(|text| say!("{text}"))
            .map_err(|e| e.to_string()),
        Command::Reproduce {
            names,
            quick,
            out,
            list,
            force,
        } => match reproduce_cmd::run(reproduce_cmd::Args {
            names: &names,
            quick,
            out: &out,
            list,
            force,
        }) {
            Ok(true) => Ok(()),
            Ok(false) => return ExitCode::FAILURE,
            Err(e) => Err(e),
        },
    };
    if let Some(signal) = nanomotion::output::signals::interrupted() {
        // Stopped by Ctrl-C or SIGTERM: what was staged has been removed.
        tell!("interrupted by signal {signal}: stopped; no partial output was left");
        return ExitCode::from(128 + signal as u8);
    }
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(msg) => {
            tell!("error: {}", nanomotion::output::unstaged(&msg));
            ExitCode::FAILURE
        }
    }
}

fn load(graph: &PathBuf) -> Result<GraphSpec, String> {
    GraphSpec::from_file(graph).map_err(|e| e.to_string())
}

/// The measured data of `--data FILE…` (merged), refused for a graph that reads
/// no data (it would only change the duration: audit D17).
fn load_data(
    graph: &std::path::Path,
    spec: &GraphSpec,
    files: &[PathBuf],
    data_rate: Option<f64>,
) -> Result<Option<std::sync::Arc<nanomotion::core::data::Dataset>>, String> {
    if !files.is_empty() && !spec.reads_data() {
        return Err(format!(
            "{}: --data was given, but the graph reads no data (no `data_column` block, no `compare:` entry), so the data would only change its duration (fix: drop --data, or play a column with a `data_column` block / compare an output with `compare:`)",
            graph.display()
        ));
    }
    let mut merged: Option<nanomotion::core::data::Dataset> = None;
    for path in files {
        let d = nanomotion_rt::load_dataset(path, data_rate).map_err(|e| e.to_string())?;
        merged = Some(match merged {
            None => d,
            Some(m) => m.merge(d).map_err(|e| e.to_string())?,
        });
    }
    Ok(merged.map(std::sync::Arc::new))
}

fn check(
    graph: PathBuf,
    data: &[PathBuf],
    data_rate: Option<f64>,
    print_loop: bool,
) -> Result<(), String> {
    let mut spec = load(&graph)?;
    let require = spec.require.clone();
    let data = load_data(&graph, &spec, data, data_rate)?;
    let (sched, report) = match data {
        Some(d) => {
            spec.duration_s = d.duration_s();
            spec.build_with_data(d)
        }
        None if spec.reads_data() => {
            eprintln!(
                "note: no --data given: `data_column` blocks play a placeholder 0; names, ports, rates and loops are checked, the columns and the data's rate are not (fix: `nanomotion check {} --data FILE` checks them too)",
                graph.display()
            );
            spec.build_without_data()
        }
        None => spec.build(),
    }
    .map_err(|e| e.to_string())?;
    let gate = gate_cmd::analyse(&sched, require.as_ref());
    say!("{}: ok", graph.display());
    say!(
        "  base rate {} Hz, {} ticks",
        sched.base_rate_hz(),
        sched.ticks_total()
    );
    say!("  blocks in execution order:");
    for line in sched.describe() {
        say!("    {line}");
    }
    if report.rate_transitions.is_empty() {
        say!("  no rate transitions");
    } else {
        say!("  rate transitions inserted:");
        for r in &report.rate_transitions {
            say!("    {r}");
        }
    }
    say!("{}", gate.to_string().trim_end());
    if print_loop {
        say!("{}", gate_cmd::print_loops(&gate).trim_end());
    }
    gate_cmd::verdict(&gate)
}

/// The arguments of `nanomotion run`.
struct RunArgs {
    graph: PathBuf,
    out: Option<PathBuf>,
    force: bool,
    seed: Option<u64>,
    duration: Option<f64>,
    no_files: bool,
    data: Vec<PathBuf>,
    data_rate: Option<f64>,
    allow_unproven: bool,
    set: Vec<nanomotion::core::Override>,
    record: bool,
}

fn run(args: RunArgs) -> Result<(), String> {
    let RunArgs {
        graph,
        out,
        force,
        seed,
        duration,
        no_files,
        data,
        data_rate,
        allow_unproven,
        set,
        record,
    } = args;
    let mut spec = GraphSpec::from_file_with_overrides(&graph, &set).map_err(|e| e.to_string())?;
    if record {
        for name in nanomotion_rt::hw_log_names(&spec) {
            if !spec.log.contains(&name) {
                spec.log.push(name);
            }
        }
    }
    if let Some(s) = seed {
        spec.seed = s;
    }
    let data = load_data(&graph, &spec, &data, data_rate)?;
    if data.is_none() && !spec.compare.is_empty() {
        return Err(format!(
            "{}: the graph compares {} signal(s) with measured data (`compare:`), but no data was given (fix: run with --data FILE)",
            graph.display(),
            spec.compare.len()
        ));
    }
    match (duration, &data) {
        (Some(d), _) => spec.duration_s = d,
        (None, Some(d)) => spec.duration_s = d.duration_s(),
        (None, None) => {}
    }
    let require = spec.require.clone();
    // Logs are streamed to the CSV files while the run goes (memory independent
    // of the duration), except for `compare:`, which needs whole logs.
    let streamed = spec.compare.is_empty();
    let (mut sched, report) = match (&data, streamed) {
        (d, true) => spec.build_streamed(d.clone().map(|d| d as _)),
        (Some(d), false) => spec.build_with_data(d.clone()),
        (None, false) => spec.build(),
    }
    .map_err(|e| e.to_string())?;
    let mut recorder = if record {
        Some(nanomotion_rt::SimRecorder::new(&sched).map_err(|e| e.to_string())?)
    } else {
        None
    };
    let gate_lines =
        gate_cmd::before_run(&gate_cmd::analyse(&sched, require.as_ref()), allow_unproven)?;
    for r in &report.rate_transitions {
        tell!("note: rate transition {r}");
    }
    // The output folder is checked (and its temporary folder made) before the
    // simulation, so a bad --out costs nothing.
    let out = out.unwrap_or_else(|| {
        let stem = graph
            .file_stem()
            .map_or_else(|| "run".into(), |s| s.to_string_lossy().into_owned());
        PathBuf::from("out").join(nanomotion::output::file_stem(&stem))
    });
    let folder = if no_files {
        None
    } else {
        Some(nanomotion::output::OutputFolder::prepare(&out, force).map_err(|e| e.to_string())?)
    };
    if sched.ticks_total() == 0 {
        tell!("note: duration 0 s: nothing is simulated, logs are empty and no plots are drawn");
    }
    let mut writer = match &folder {
        Some(f) => Some(
            nanomotion::output::RunWriter::new(f.dir(), sched.score_signals())
                .map_err(|e| e.to_string())?,
        ),
        None => None,
    };
    let start = Instant::now();
    let mut bar: Option<ProgressBar> = None;
    let result = sched.run_streamed(
        |chunks| {
            if let Some(r) = &mut recorder {
                r.take(chunks);
            }
            match &mut writer {
                Some(w) => w.chunk(chunks),
                None => match nanomotion::output::signals::interrupted() {
                    Some(signal) => Err(nanomotion::output::OutputError::Interrupted { signal }),
                    None => Ok(()),
                },
            }
        },
        |fraction| {
            // Show a bar only for runs that last more than a second.
            if bar.is_none() && start.elapsed() > Duration::from_millis(300) && fraction < 0.7 {
                let b = ProgressBar::new(1000);
                b.set_style(
                    ProgressStyle::with_template(
                        "{spinner} simulating [{bar:40}] {percent:>3}% (eta {eta})",
                    )
                    .expect("static template")
                    .progress_chars("=> "),
                );
                bar = Some(b);
            }
            if let Some(b) = &bar {
                b.set_position((fraction * 1000.0) as u64);
            }
        },
    );
    if let Some(b) = bar {
        b.finish_and_clear();
    }
    let result = result.map_err(|e| e.to_string())?;
    let wall = start.elapsed().as_secs_f64();
    sched.check_finite().map_err(|e| e.to_string())?;
    say!(
        "{}: simulated {:.3} s in {:.3} s ({:.0}x real time)",
        result
            .title
            .as_deref()
            .unwrap_or(&graph.display().to_string()),
        result.duration_s,
        wall,
        result.duration_s / wall.max(1e-9)
    );
    for l in &gate_lines {
        say!("stability gate: {l}");
    }
    if !result.scores.is_empty() && sched.ticks_total() > 0 {
        say!(
            "{:<32} {:>12} {:>12} {:>12} {:>8} {:<6}",
            "signal",
            "rms",
            "max |.|",
            "mean",
            "from (s)",
            "unit"
        );
        for s in &result.scores {
            say!(
                "{:<32} {:>12.4e} {:>12.4e} {:>12.4e} {:>8} {:<6}",
                s.signal,
                s.rms,
                s.max_abs,
                s.mean,
                s.from_s,
                s.unit.as_deref().unwrap_or("")
            );
        }
    }
    let comparisons = match &data {
        Some(d) => nanomotion::core::data::compare(&sched, d).map_err(|e| e.to_string())?,
        None => Vec::new(),
    };
    if let Some(d) = &data {
        say!(
            "data {}: {} samples at {} Hz ({} s)",
            d.origin(),
            d.len(),
            d.rate_hz(),
            d.duration_s()
        );
    }
    if !comparisons.is_empty() {
        say!(
            "{:<24} {:<16} {:>12} {:>12} {:>9}",
            "signal",
            "column",
            "rms",
            "max |.|",
            "fit %"
        );
        for c in &comparisons {
            say!(
                "{:<24} {:<16} {:>12.4e} {:>12.4e} {:>9.3}",
                c.signal,
                c.column,
                c.rms,
                c.max_abs,
                c.fit_percent
            );
        }
    }
    if let (Some(folder), Some(writer)) = (folder, writer) {
        tell!("writing files to {} ...", out.display());
        let dir = folder.dir().to_path_buf();
        let started = Instant::now();
        let mut wbar: Option<ProgressBar> = None;
        let mut files = writer
            .finish(&result, &report.rate_transitions, |what, fraction| {
                // A bar once writing takes noticeable time.
                if wbar.is_none() && started.elapsed() > Duration::from_millis(300) {
                    let b = ProgressBar::new(1000);
                    b.set_style(
                        ProgressStyle::with_template("{spinner} writing [{bar:30}] {msg}")
                            .expect("static template")
                            .progress_chars("=> "),
                    );
                    wbar = Some(b);
                }
                if let Some(b) = &wbar {
                    b.set_position((fraction * 1000.0) as u64);
                    b.set_message(what.to_string());
                }
            })
            .map_err(|e| e.to_string())?;
        if let Some(b) = wbar {
            b.finish_and_clear();
        }
        if let Some(r) = recorder {
            let path = dir.join("run.mcap");
            nanomotion_rt::write_mcap(&path, &r.finish()).map_err(|e| e.to_string())?;
            files.push(path);
        }
        if let Some(d) = &data
            && !comparisons.is_empty()
        {
            let title = result
                .title
                .clone()
                .unwrap_or_else(|| graph.display().to_string());
            files.extend(
                nanomotion::output::write_comparisons(&dir, &title, d, &comparisons)
                    .map_err(|e| e.to_string())?,
            );
        }
        let graph_name = graph.display().to_string();
        let written = folder
            .commit(Some(&nanomotion::output::Manifest {
                command: "run",
                graph: &graph_name,
                title: &result.title,
                stability_gate: &gate_lines,
            }))
            .map_err(|e| e.to_string())?;
        debug_assert_eq!(written.len(), files.len() + 1);
        say!("wrote {} files to {}", written.len(), out.display());
    }
    Ok(())
}

fn blocks(filter: Option<&str>) -> Result<(), String> {
    let docs = block_docs();
    let types = registered_types();
    let shown: Vec<&String> = types
        .iter()
        .filter(|t| filter.is_none_or(|f| t.contains(f)))
        .collect();
    if let Some(f) = filter
        && shown.is_empty()
    {
        let close: Vec<&str> = types
            .iter()
            .filter(|t| nanomotion::core::graph::is_near(f, t))
            .map(String::as_str)
            .collect();
        let hint = if close.is_empty() {
            String::new()
        } else {
            format!("; did you mean {}?", close.join(", "))
        };
        return Err(format!(
            "no block type contains `{f}`{hint} (fix: `nanomotion blocks` lists all {} types)",
            types.len()
        ));
    }
    for t in shown {
        match docs.iter().find(|d| d.type_name == t) {
            Some(d) => say!("{}", d.describe().trim_end()),
            None => say!("{t}: (no documentation registered)"),
        }
    }
    Ok(())
}
