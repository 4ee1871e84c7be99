//! `nanomotion diagnose`: the model-discrepancy workflow from the command line.

use indicatif::{ProgressBar, ProgressStyle};
use nanomotion::core::data::Dataset;
use nanomotion::core::graph::GraphSpec;
use nanomotion::output::{Manifest, OutputFolder, write_atomic};
use nanomotion::plf::diagnose::{Options, PlotData, Report, diagnose_records};
use nanomotion::plot::{Figure, Scale, Series, draw_svg};
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

/// Arguments of the command.
pub struct Args {
    pub model: PathBuf,
    pub data: PathBuf,
    /// Held-out records (empty: the end of `data` is held out).
    pub validation: Vec<PathBuf>,
    pub out: Option<PathBuf>,
    pub json: Option<PathBuf>,
    pub max_effects: usize,
    pub holdout: f64,
    pub seed: Option<u64>,
    pub effects: Vec<String>,
    /// `--phase`: a signal a disturbance may be periodic in (`Options::phase`).
    pub phase: Option<String>,
    pub force: bool,
}

/// A measured record: a data file (CSV, `.mat`) or a recording (`.mcap`: a
/// column per hardware channel).
fn load_record(path: &Path) -> Result<Dataset, String> {
    nanomotion_rt::load_dataset(path, None).map_err(|e| e.to_string())
}

pub fn run(a: Args) -> Result<(), String> {
    let spec = GraphSpec::from_file(&a.model).map_err(|e| e.to_string())?;
    let mut records = vec![load_record(&a.data)?];
    for v in &a.validation {
        records.push(load_record(v)?);
    }
    let data = &records[0];
    let out = a.out.clone().unwrap_or_else(|| {
        PathBuf::from("out").join(format!(
            "diagnose_{}",
            a.model
                .file_stem()
                .map(|s| s.to_string_lossy().to_string())
                .unwrap_or_default()
        ))
    });
    if !(0.05..=0.8).contains(&a.holdout) {
        return Err(format!(
            "--holdout {} is outside [0.05, 0.8]: give the fraction of the record, at its end, to hold out (0.3 = the last 30 %)",
            a.holdout
        ));
    }
    // The folder is checked (and its staging folder made) before the work, so
    // a bad --out costs nothing; files appear only when all are written.
    let folder = OutputFolder::prepare(&out, a.force).map_err(|e| e.to_string())?;
    let opts = Options {
        max_effects: a.max_effects,
        holdout: a.holdout,
        seed: a.seed,
        effects: a.effects.clone(),
        phase: a.phase.clone(),
        ..Options::default()
    };
    let held_out = if a.validation.is_empty() {
        format!("last {:.0} % held out", 100.0 * a.holdout)
    } else {
        let names: Vec<String> = a
            .validation
            .iter()
            .map(|v| v.display().to_string())
            .collect();
        format!(
            "estimation only; held out: {} ({} samples)",
            names.join(", "),
            records[1..].iter().map(Dataset::len).sum::<usize>()
        )
    };
    say!(
        "diagnosing {} against {} ({} samples at {} Hz; {held_out})",
        a.model.display(),
        a.data.display(),
        data.len(),
        data.rate_hz(),
    );
    let start = Instant::now();
    let mut bar: Option<ProgressBar> = None;
    let report = diagnose_records(&spec, &records, &opts, &mut |what, frac| {
        if bar.is_none() && start.elapsed() > Duration::from_millis(500) {
            let b = ProgressBar::new(1000);
            b.set_style(
                ProgressStyle::with_template(
                    "{spinner} {msg} [{bar:30}] {percent:>3}% ({elapsed})",
                )
                .expect("static template")
                .progress_chars("=> "),
            );
            bar = Some(b);
        }
        if let Some(b) = &bar {
            b.set_message(what.to_string());
            b.set_position((frac * 1000.0) as u64);
        }
    })
    .map_err(|e| e.to_string())?;
    if let Some(b) = bar {
        b.finish_and_clear();
    }
    print_report(&report);
    say!(
        "({} graph runs in {:.1} s)",
        report.runs,
        start.elapsed().as_secs_f64()
    );
    let json = write(folder.dir(), &report, &a)?;
    let model = a.model.display().to_string();
    let files = folder
        .commit(Some(&Manifest {
            command: "diagnose",
            graph: &model,
            title: &spec.title,
            stability_gate: &[],
        }))
        .map_err(|e| e.to_string())?;
    if let Some(extra) = &a.json {
        write_atomic(extra, &json).map_err(|e| e.to_string())?;
    }
    say!("wrote {} files to {}", files.len(), out.display());
    say!(
        "re-run the augmented model: nanomotion run {} --data {}",
        out.join("model_augmented.yaml").display(),
        a.data.display()
    );
    Ok(())
}

fn print_report(r: &Report) {
    say!("\nnominal model:");
    say!(
        "  rms {:.4e}, held-out rms {:.4e}, fit {:.1} %",
        r.nominal.rms,
        r.nominal.holdout_rms,
        r.nominal.fit_percent
    );
    for t in &r.nominal_tests {
        say!(
            "  {}: whiteness Ljung–Box Q = {:.0} (p = {:.1e}{}); input correlation with {} |z| = {:.1} at lag {} (p = {:.1e}{}); strongest line {:.3} Hz (Fisher g p = {:.1e}); noise floor ≈ {:.3e}",
            t.signal,
            t.whiteness.statistic,
            t.whiteness.p_value,
            if t.whiteness.p_value < 0.01 {
                ": not white"
            } else {
                ": white at 1 %"
            },
            t.input,
            t.input_correlation.statistic,
            t.input_lag,
            t.input_correlation.p_value,
            if t.input_correlation.p_value < 0.01 {
                ": the model misses an input-driven effect"
            } else {
                ""
            },
            t.line_hz,
            t.periodic_line.p_value,
            t.noise_floor
        );
    }
    if let Some(c) = &r.calibration {
        let fmt = |m: &std::collections::BTreeMap<String, f64>| {
            m.iter()
                .map(|(k, v)| match c.uncertainty.get(k) {
                    Some(u) if m == &c.params => format!("{k} = {v:.4} ± {u:.1e}"),
                    _ => format!("{k} = {v:.4}"),
                })
                .collect::<Vec<_>>()
                .join(", ")
        };
        say!(
            "\nstep 0: nominal calibration {}: {}",
            if c.accepted {
                "(kept: the nominal's own parameters were off)"
            } else {
                "(not kept: the nominal's parameters explain no significant share)"
            },
            fmt(&c.params)
        );
        if !c.held.is_empty() {
            say!(
                "     held at the nominal, the data do not determine them (σ ≥ the value; the fit went to {})",
                fmt(&c.held)
            );
        }
        if c.accepted && !c.final_params.is_empty() && c.final_params != c.params {
            say!(
                "     in model_augmented.yaml (after the later joint refits): {}",
                fmt(&c.final_params)
            );
        }
        say!(
            "     held-out rms {:.4e} -> {:.4e} ({:.1} % cut, {:.0} % of the excess over the noise floor, p = {:.1e})",
            c.holdout_rms_before,
            c.holdout_rms_after,
            c.cut_percent,
            c.excess_cut_percent,
            c.p_value
        );
        if let Some(why) = &c.with_effect {
            say!("     {why}");
        }
    }
    for (k, s) in r.steps.iter().enumerate() {
        if s.candidates.is_empty() {
            say!("\nstep {}: read off the record itself (no fit):", k + 1);
        } else {
            say!("\nstep {}: candidates tried (best first):", k + 1);
        }
        for c in s.candidates.iter().take(8) {
            match &c.note {
                None => say!(
                    "  {:<24} {:<52} {:>2} params  held-out rms {:.4e}",
                    c.effect,
                    c.site,
                    c.n_params,
                    c.holdout_rms
                ),
                Some(n) => say!("  {:<24} {:<52} {n}", c.effect, c.site),
            }
        }
        if s.candidates.len() > 8 {
            say!(
                "  ... and {} more (see the JSON report)",
                s.candidates.len() - 8
            );
        }
        say!(
            "  => named: {} (block `{}`, type `{}`), {}",
            s.effect,
            s.block.name,
            s.block.type_name,
            s.site
        );
        say!("     evidence: {}", s.evidence);
        for a in &s.ambiguous_with {
            say!(
                "     ambiguous: [{}, {}] — {} ({}) explains the held-out data as well (held-out rms {:.4e}; {} better only with p = {:.2}); to tell them apart: {}",
                s.effect,
                a.effect,
                a.effect,
                a.site,
                a.holdout_rms,
                s.effect,
                a.p_value,
                a.experiment
            );
        }
        let params: Vec<String> = s
            .params
            .iter()
            .map(|(k, v)| match s.uncertainty.get(k) {
                Some(u) => format!("{k} = {v:.4e} ± {u:.1e}"),
                None => format!("{k} = {v:.4e}"),
            })
            .collect();
        say!("     parameters at this step: {}", params.join(", "));
        // Later steps refit earlier effects jointly; say where they ended up.
        if s.final_params != s.params {
            let fin: Vec<String> = s
                .final_params
                .iter()
                .map(|(k, v)| format!("{k} = {v:.4e}"))
                .collect();
            say!(
                "     in model_augmented.yaml (after the later joint refits): {}",
                fin.join(", ")
            );
        }
        if !s.derived.is_empty() {
            let d: Vec<String> = s
                .derived
                .iter()
                .map(|(k, v)| format!("{k} = {v:.4e}"))
                .collect();
            say!("     derived from the final fit: {}", d.join(", "));
        }
        say!(
            "     held-out rms {:.4e} -> {:.4e} ({:.1} % cut, p = {:.1e}{})",
            s.holdout_rms_before,
            s.holdout_rms_after,
            s.cut_percent,
            s.p_value,
            if s.candidates.is_empty() {
                " of the test in the evidence"
            } else {
                ""
            }
        );
    }
    for d in &r.dropped {
        say!(
            "dropped at the end: {} ({}) — the effects named after it explain the held-out data without it: held-out rms {:.4e} with it, {:.4e} without (p = {:.1e}, {:.0} % of the excess over the noise floor)",
            d.effect,
            d.site,
            d.holdout_rms_with,
            d.holdout_rms_without,
            d.p_value,
            d.excess_cut_percent
        );
    }
    say!(
        "\nfound: [{}]",
        r.found
            .iter()
            .map(|f| format!("\"{f}\""))
            .collect::<Vec<_>>()
            .join(", ")
    );
    say!(
        "final: rms {:.4e}, held-out rms {:.4e}, fit {:.1} % (nominal held-out {:.4e}: {:.1} % cut{})",
        r.final_scores.rms,
        r.final_scores.holdout_rms,
        r.final_scores.fit_percent,
        r.nominal.holdout_rms,
        r.holdout_cut_percent,
        if r.final_scores.per_output.len() > 1 {
            ", each output in units of its noise floor"
        } else {
            ""
        }
    );
    say!("stopped because {}", r.stopped_because);
    for note in &r.excitation_notes {
        say!("note: {note}");
    }
    if !r.rejected_candidates.is_empty() {
        say!("  (the last step's best candidates:");
        for c in r.rejected_candidates.iter().take(4) {
            say!(
                "     {:<24} {:<52} {:>2} params  held-out rms {:.4e}",
                c.effect,
                c.site,
                c.n_params,
                c.holdout_rms
            );
        }
        say!("  )");
    }
}

fn plot(p: &PlotData, path: &Path) -> Result<(), String> {
    // Loops (hysteresis, backlash) read in time order; other clouds sorted by x.
    let loops = p.name.contains("hysteresis") || p.name.contains("backlash");
    let series = p
        .series
        .iter()
        .map(|(label, x, y)| {
            let (mut x, mut y) = (x.clone(), y.clone());
            if !loops {
                let mut idx: Vec<usize> = (0..x.len()).collect();
                idx.sort_by(|&a, &b| x[a].total_cmp(&x[b]));
                let xx = x.clone();
                x = idx.iter().map(|&i| xx[i]).collect();
                let yy = y.clone();
                y = idx.iter().map(|&i| yy[i]).collect();
            }
            Series {
                label: label.clone(),
                x,
                y,
            }
        })
        .collect();
    draw_svg(
        &Figure {
            title: p.title.clone(),
            x_label: p.x_label.clone(),
            y_label: p.y_label.clone(),
            y_unit: None,
            x_scale: Scale::Linear,
            series,
        },
        path,
    )
    .map_err(|e| e.to_string())
}

/// Write the files into `out` (the staging folder); returns the JSON report.
fn write(out: &Path, r: &Report, a: &Args) -> Result<String, String> {
    let io = |p: &Path| {
        let p = p.display().to_string();
        move |e: std::io::Error| format!("cannot write {p}: {e}")
    };
    if let Some(spec) = &r.augmented {
        let yaml = nanomotion::core::yaml::to_string(spec).map_err(|e| e.to_string())?;
        let path = out.join("model_augmented.yaml");
        let header = format!(
            "# Written by `nanomotion diagnose {} {}`: the nominal graph plus the effects found ({}).\n",
            a.model.display(),
            a.data.display(),
            if r.found.is_empty() {
                "none".to_string()
            } else {
                r.found.join(", ")
            }
        );
        std::fs::write(&path, header + &yaml).map_err(io(&path))?;
    }
    let json = serde_json::to_string_pretty(r).map_err(|e| e.to_string())?;
    let path = out.join("report.json");
    std::fs::write(&path, &json).map_err(io(&path))?;
    for p in &r.plots {
        let path = out.join(format!("evidence_{}.svg", p.name));
        plot(p, &path)?;
    }
    for (signal, before, after) in &r.residuals {
        let stem = nanomotion::output::file_stem(signal);
        let t: Vec<f64> = (0..before.len()).map(|k| k as f64 / r.rate_hz).collect();
        let path = out.join(format!("residual_{stem}.svg"));
        draw_svg(
            &Figure {
                title: format!("residual of {signal}, before and after"),
                x_label: "time (s)".into(),
                y_label: "measured − model".into(),
                y_unit: None,
                x_scale: Scale::Linear,
                series: vec![
                    Series {
                        label: "nominal".into(),
                        x: t.clone(),
                        y: before.clone(),
                    },
                    Series {
                        label: "augmented".into(),
                        x: t,
                        y: after.clone(),
                    },
                ],
            },
            &path,
        )
        .map_err(|e| e.to_string())?;
        // As the thesis reads it: the square root of the cumulative PSD, in the
        // signal's unit, whose end value is the residual's standard deviation.
        let root = |(f, c): (Vec<f64>, Vec<f64>)| {
            (
                f,
                c.into_iter().map(|v| v.max(0.0).sqrt()).collect::<Vec<_>>(),
            )
        };
        let (f0, c0) = root(nanomotion::output::cumulative_psd(before, r.rate_hz));
        let (f1, c1) = root(nanomotion::output::cumulative_psd(after, r.rate_hz));
        let path = out.join(format!("residual_cpsd_{stem}.svg"));
        draw_svg(
            &Figure {
                title: format!("√(cumulative PSD) of the residual of {signal}"),
                x_label: "frequency (Hz)".into(),
                y_label: "√(cumulative PSD) (signal unit; end value = std)".into(),
                y_unit: None,
                x_scale: Scale::Log,
                series: vec![
                    Series {
                        label: "nominal".into(),
                        x: f0,
                        y: c0,
                    },
                    Series {
                        label: "augmented".into(),
                        x: f1,
                        y: c1,
                    },
                ],
            },
            &path,
        )
        .map_err(|e| e.to_string())?;
    }
    Ok(json)
}
