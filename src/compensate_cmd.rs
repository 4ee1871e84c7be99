//! `nanomotion compensate`: from the effects `diagnose` named to compensators in
//! the user's controller graph, validated in closed loop on the augmented model.

use nanomotion::compensate::{MeasuredSignal, Options, Outcome, compensate, named};
use nanomotion::core::graph::GraphSpec;
use nanomotion::output::{Manifest, OutputFolder};
use nanomotion::plot::{Figure, Scale, Series, draw_svg};
use std::path::{Path, PathBuf};

/// Synthesise compensators for the effects `nanomotion diagnose` named, insert
/// them into the controller graph (blocks `comp_<effect>`), validate the loop on
/// the augmented model before/after (each compensator alone and all together;
/// those that do not cut the error are dropped unless --keep) and check the
/// result with the stability gate. Writes `compensated.yaml`, `report.json`,
/// `error.svg` and `error_cpsd.svg`.
#[derive(clap::Args, Debug)]
pub struct Args {
    /// The augmented model `diagnose` wrote (model_augmented.yaml).
    pub augmented: PathBuf,
    /// Your closed loop: reference, controller and the nominal plant; its first
    /// `score:` entry is the tracking error.
    pub controller: PathBuf,
    /// The diagnosis report (default: report.json beside the augmented model; without
    /// one, the model's `plf_*` effect blocks).
    #[arg(long)]
    pub report: Option<PathBuf>,
    /// Validate on this reference: a YAML block map (`{type: …, …}`) replacing the
    /// block that feeds the error sum's in0.
    #[arg(long)]
    pub reference: Option<PathBuf>,
    /// Output folder (default out/compensate_<controller stem>).
    #[arg(long, short)]
    pub out: Option<PathBuf>,
    /// Keep compensators that do not cut the tracking error.
    #[arg(long)]
    pub keep: bool,
    /// Delay-varying RC: a record of the signal the disturbance is periodic in
    /// (e.g. the leg angle α), from your loop on the stage without RC — a CSV
    /// with `t_s` first, as `nanomotion run` writes signals_*.csv, or a .mat.
    /// COLUMN (default: the file's only data column) is the signal's name in
    /// your graph, e.g. `signals_4000hz.csv:alpha.y`. The delays it shows
    /// join the range [m, M] of N_k (thesis Fig. 5.7). Repeat for several
    /// signals.
    #[arg(long, value_name = "FILE[:COLUMN]")]
    pub measured_alpha: Vec<String>,
    #[arg(long, value_name = "FRACTION", help = delay_margin_help())]
    pub delay_margin: Option<f64>,
    /// Replace a non-empty output folder that does not hold a previous output.
    #[arg(long)]
    pub force: bool,
}

/// `--delay-margin`'s help, with the library's defaults.
fn delay_margin_help() -> String {
    format!(
        "Delay-varying RC: widen the range [m, M] of N_k by this fraction on each side, in [0, 0.5) (default: {:.3} beyond a --measured-alpha record, else {:.3}, the spread of N(α) the thesis measured, Fig. 5.7, which no model shows; the report's `delay_margin` is the one used)",
        nanomotion::compensate::DELAY_MARGIN_MEASURED,
        nanomotion::compensate::DELAY_SPREAD_UNMEASURED
    )
}

fn read(path: &Path) -> Result<String, String> {
    std::fs::read_to_string(path).map_err(|e| {
        format!(
            "{}: cannot read it ({e}); fix: give an existing file",
            path.display()
        )
    })
}

pub fn run(a: Args) -> Result<(), String> {
    let augmented = GraphSpec::from_file(&a.augmented).map_err(|e| e.to_string())?;
    let controller = GraphSpec::from_file(&a.controller).map_err(|e| e.to_string())?;
    let beside = a.augmented.with_file_name("report.json");
    let effects = match &a.report {
        Some(p) => named::from_report_json(&read(p)?, &p.display().to_string())
            .map_err(|e| e.to_string())?,
        None if beside.is_file() => {
            named::from_report_json(&read(&beside)?, &beside.display().to_string())
                .map_err(|e| e.to_string())?
        }
        None => {
            say!(
                "(no report.json beside {}: the effects are its `plf_*` blocks)",
                a.augmented.display()
            );
            named::from_graph(&augmented)
        }
    };
    let reference = match &a.reference {
        None => None,
        Some(p) => {
            let origin = p.display().to_string();
            let v: serde_json::Value =
                nanomotion::core::yaml::from_str(&read(p)?, &origin).map_err(|e| e.to_string())?;
            if v.get("type").and_then(|t| t.as_str()).is_none() {
                return Err(format!(
                    "{origin}: is not a block map with a `type:`; fix: give one block, e.g. `{{type: triangular_scan, amplitude: 1.0e-5, frequency_hz: 1.0}}`"
                ));
            }
            Some(v)
        }
    };
    let out = a.out.clone().unwrap_or_else(|| {
        PathBuf::from("out").join(format!(
            "compensate_{}",
            a.controller
                .file_stem()
                .map(|s| s.to_string_lossy().to_string())
                .unwrap_or_default()
        ))
    });
    let measured = a
        .measured_alpha
        .iter()
        .map(|m| MeasuredSignal::from_file_column(m).map_err(|e| e.to_string()))
        .collect::<Result<Vec<_>, _>>()?;
    let folder = OutputFolder::prepare(&out, a.force).map_err(|e| e.to_string())?;
    let opts = Options {
        keep: a.keep,
        delay_margin: a.delay_margin,
        measured,
        reference,
        augmented_name: a.augmented.display().to_string(),
        controller_name: a.controller.display().to_string(),
        ..Options::default()
    };
    say!(
        "compensating {} for [{}] named in {}",
        a.controller.display(),
        effects
            .iter()
            .map(|e| e.effect.as_str())
            .collect::<Vec<_>>()
            .join(", "),
        a.augmented.display()
    );
    let outcome =
        compensate(&augmented, &controller, &effects, &opts).map_err(|e| e.to_string())?;
    print(&outcome);
    write(folder.dir(), &outcome, &a)?;
    let graph = a.controller.display().to_string();
    let files = folder
        .commit(Some(&Manifest {
            command: "compensate",
            graph: &graph,
            title: &controller.title,
            stability_gate: &outcome.report.gate.lines,
        }))
        .map_err(|e| e.to_string())?;
    say!("wrote {} files to {}", files.len(), out.display());
    say!(
        "run it: nanomotion run {}",
        out.join("compensated.yaml").display()
    );
    Ok(())
}

fn print(o: &Outcome) {
    let r = &o.report;
    say!(
        "\ntracking error {} (from {} s), closed loop on the augmented model:",
        r.error_signal,
        r.from_s
    );
    say!(
        "  {:<24} {:<22} {:>12} {:>12} {:>8} {:>13}  kept",
        "effect",
        "compensator",
        "rms",
        "max |e|",
        "rms cut",
        "effects' cut"
    );
    say!(
        "  {:<24} {:<22} {:>12.4e} {:>12.4e}",
        "(nominal plant)",
        "your loop",
        r.nominal.rms,
        r.nominal.max_abs
    );
    say!(
        "  {:<24} {:<22} {:>12.4e} {:>12.4e} {:>8} {:>13}",
        "(augmented plant)",
        "your loop",
        r.before.rms,
        r.before.max_abs,
        "—",
        "—"
    );
    for c in &r.compensators {
        say!(
            "  {:<24} {:<22} {:>12.4e} {:>12.4e} {:>7.1}% {:>12.1}%  {}",
            c.effect,
            c.type_name,
            c.alone.rms,
            c.alone.max_abs,
            c.cut_percent,
            c.effect_error_cut_percent,
            if c.kept { "yes" } else { "no" }
        );
    }
    if let Some(all) = &r.all {
        say!(
            "  {:<24} {:<22} {:>12.4e} {:>12.4e} {:>7.1}%",
            "(all together)",
            "",
            all.rms,
            all.max_abs,
            100.0 * (1.0 - all.rms / r.before.rms)
        );
    }
    say!(
        "  => compensated: rms {:.4e} -> {:.4e} ({:.1} % cut), max {:.4e} -> {:.4e} ({:.1} % cut)",
        r.before.rms,
        r.after.rms,
        r.cut_percent,
        r.before.max_abs,
        r.after.max_abs,
        r.max_cut_percent
    );
    say!(
        "  (effects' cut: of the error the effects cause, e − e on the nominal plant: {:.4e} before, {:.4e} compensated)",
        r.effect_error_before,
        r.effect_error_after
    );
    for c in &r.compensators {
        say!("\n{} ({}): {}", c.block, c.effect, c.why);
        say!("  where: {}", c.place);
        if !c.design.is_empty() {
            let d: Vec<String> = c
                .design
                .iter()
                .map(|(k, v)| format!("{k} = {v:.4e}"))
                .collect();
            say!("  design: {}", d.join(", "));
        }
        if let Some(n) = &c.note {
            say!("  note: {n}");
        }
    }
    for n in &r.not_compensated {
        say!("\n{}: {}", n.effect, n.reason);
    }
    say!(
        "\nstability gate on the compensated graph: {}",
        if r.gate.passes { "passes" } else { "refuses" }
    );
    for l in &r.gate.lines {
        say!("  {l}");
    }
}

/// A trace (time, error) to the (x, y) of a plot.
type Transform<'a> = dyn Fn(&[f64], &[f64]) -> (Vec<f64>, Vec<f64>) + 'a;

/// Write the files into `out` (the staging folder).
fn write(out: &Path, o: &Outcome, a: &Args) -> Result<(), String> {
    let io = |p: &Path| {
        let p = p.display().to_string();
        move |e: std::io::Error| format!("cannot write {p}: {e}")
    };
    let yaml = nanomotion::core::yaml::to_string(&o.compensated).map_err(|e| e.to_string())?;
    let kept: Vec<&str> = o
        .report
        .compensators
        .iter()
        .filter(|c| c.kept)
        .map(|c| c.block.as_str())
        .collect();
    let header = format!(
        "# Written by `nanomotion compensate {} {}`: the controller graph with the compensators [{}].\n",
        a.augmented.display(),
        a.controller.display(),
        kept.join(", ")
    );
    let path = out.join("compensated.yaml");
    std::fs::write(&path, header + &yaml).map_err(io(&path))?;
    let json = serde_json::to_string_pretty(&o.report).map_err(|e| e.to_string())?;
    let path = out.join("report.json");
    std::fs::write(&path, json).map_err(io(&path))?;
    let series = |f: &Transform<'_>| -> Vec<Series> {
        o.traces
            .iter()
            .map(|(label, t, e)| {
                let (x, y) = f(t, e);
                Series {
                    label: label.clone(),
                    x,
                    y,
                }
            })
            .collect()
    };
    draw_svg(
        &Figure {
            title: format!(
                "tracking error {} on the augmented model, before and after",
                o.report.error_signal
            ),
            x_label: "time (s)".into(),
            y_label: o.report.error_signal.clone(),
            y_unit: None,
            x_scale: Scale::Linear,
            series: series(&|t, e| (t.to_vec(), e.to_vec())),
        },
        &out.join("error.svg"),
    )
    .map_err(|e| e.to_string())?;
    // The square root of the cumulative PSD over the scored window (end value =
    // the standard deviation), as the thesis reads an error.
    let from = o.report.from_s;
    draw_svg(
        &Figure {
            title: format!(
                "√(cumulative PSD) of {} from {from} s",
                o.report.error_signal
            ),
            x_label: "frequency (Hz)".into(),
            y_label: "√(cumulative PSD) (signal unit; end value = std)".into(),
            y_unit: None,
            x_scale: Scale::Log,
            series: series(&|t, e| {
                let rate = if t.len() > 1 {
                    1.0 / (t[1] - t[0])
                } else {
                    1.0
                };
                let start = t.iter().position(|&x| x >= from).unwrap_or(0);
                let (f, c) = nanomotion::output::cumulative_psd(&e[start..], rate);
                (f, c.into_iter().map(|v| v.max(0.0).sqrt()).collect())
            }),
        },
        &out.join("error_cpsd.svg"),
    )
    .map_err(|e| e.to_string())?;
    Ok(())
}
