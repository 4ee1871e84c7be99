//! Writing a run's results: CSV signals, JSON metrics, SVG plots.

use crate::plot::{Figure, PlotError, Scale, Series, draw_svg};
use nanomotion_core::scheduler::{RunResult, SignalLog};
use serde::Serialize;
use std::path::{Path, PathBuf};

/// Errors while writing results.
#[derive(Debug, thiserror::Error)]
pub enum OutputError {
    /// A file or folder could not be written.
    #[error(
        "cannot write `{path}`: {source} (fix: check that the folder is writable, or pass another --out)"
    )]
    Io {
        /// The path.
        path: String,
        /// The cause.
        #[source]
        source: std::io::Error,
    },
    /// A CSV file could not be written.
    #[error("cannot write `{path}`: {message}")]
    Csv {
        /// The path.
        path: String,
        /// The cause.
        message: String,
    },
    /// A plot could not be drawn.
    #[error(transparent)]
    Plot(#[from] PlotError),
    /// The output folder cannot be used.
    #[error("output folder `{path}`: {problem} (fix: {fix})")]
    Folder {
        /// The folder.
        path: String,
        /// What is wrong.
        problem: String,
        /// How to fix it.
        fix: String,
    },
}

/// Name of the manifest written last into every run folder: a folder without it
/// is not a complete run (and a folder with it came from `nanomotion run`).
pub const MANIFEST: &str = "nanomotion-run.json";

/// The manifest (`nanomotion-run.json`), written last.
#[derive(Debug, Serialize)]
pub struct Manifest<'a> {
    /// The graph file.
    pub graph: &'a str,
    /// Graph title.
    pub title: &'a Option<String>,
    /// Files of the run (names inside the folder).
    pub files: Vec<String>,
    /// Always `true`: the run was written completely.
    pub complete: bool,
}

/// An output folder being written: files go into a hidden temporary sibling
/// folder, which [`RunFolder::commit`] renames to the target in one step, so a
/// reader sees the previous complete run or the new complete run, never a mix.
/// Dropped without commit (an error, a panic), the temporary folder is removed.
#[derive(Debug)]
pub struct RunFolder {
    target: PathBuf,
    tmp: PathBuf,
    replace: bool,
    committed: bool,
}

impl RunFolder {
    /// Check `target` before a run and create the temporary folder beside it.
    ///
    /// - a missing folder is created (with its parents);
    /// - a folder holding a previous complete run (its [`MANIFEST`]) is replaced;
    /// - an empty folder is used;
    /// - any other non-empty folder is refused unless `force`, then replaced
    ///   whole (stale files of earlier graphs never stay beside new ones);
    /// - a file, or a folder that cannot be written, is an error now, before
    ///   the simulation runs.
    pub fn prepare(target: &Path, force: bool) -> Result<Self, OutputError> {
        let folder_err = |problem: String, fix: &str| OutputError::Folder {
            path: target.display().to_string(),
            problem,
            fix: fix.into(),
        };
        let mut replace = false;
        match std::fs::metadata(target) {
            Ok(m) if !m.is_dir() => {
                return Err(folder_err(
                    "is a file, not a folder".into(),
                    "pass another --out, or remove the file",
                ));
            }
            Ok(_) => {
                let entries: Vec<String> = std::fs::read_dir(target)
                    .map_err(io(target))?
                    .filter_map(Result::ok)
                    .map(|e| e.file_name().to_string_lossy().into_owned())
                    .collect();
                if !entries.is_empty() {
                    let ours = entries.iter().any(|e| e == MANIFEST);
                    if !ours && !force {
                        let mut shown: Vec<&str> =
                            entries.iter().take(3).map(String::as_str).collect();
                        if entries.len() > 3 {
                            shown.push("...");
                        }
                        return Err(folder_err(
                            format!(
                                "is not empty and does not hold a previous nanomotion run ({} entries: {})",
                                entries.len(),
                                shown.join(", ")
                            ),
                            "pass --force to replace its whole content, or choose another --out",
                        ));
                    }
                    replace = true;
                }
            }
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => {}
            Err(e) => return Err(io(target)(e)),
        }
        let parent = match target.parent() {
            Some(p) if !p.as_os_str().is_empty() => p.to_path_buf(),
            _ => PathBuf::from("."),
        };
        std::fs::create_dir_all(&parent).map_err(io(&parent))?;
        let name = target
            .file_name()
            .map_or_else(|| "out".into(), |n| n.to_string_lossy().into_owned());
        let tmp = parent.join(format!(".{name}.partial-{}", std::process::id()));
        if tmp.exists() {
            std::fs::remove_dir_all(&tmp).map_err(io(&tmp))?;
        }
        std::fs::create_dir(&tmp).map_err(io(&tmp))?;
        Ok(Self {
            target: target.to_path_buf(),
            tmp,
            replace,
            committed: false,
        })
    }

    /// The folder to write the files into (the temporary one).
    pub fn dir(&self) -> &Path {
        &self.tmp
    }

    /// The final folder.
    pub fn target(&self) -> &Path {
        &self.target
    }

    /// Write the manifest last, then put the folder in place of the target.
    pub fn commit(mut self, manifest: &Manifest<'_>) -> Result<(), OutputError> {
        let path = self.tmp.join(MANIFEST);
        let text = serde_json::to_string_pretty(manifest).map_err(|e| OutputError::Csv {
            path: path.display().to_string(),
            message: e.to_string(),
        })?;
        std::fs::write(&path, text).map_err(io(&path))?;
        if self.replace {
            let old = self.tmp.with_file_name(format!(
                "{}.old",
                self.tmp.file_name().unwrap_or_default().to_string_lossy()
            ));
            std::fs::rename(&self.target, &old).map_err(io(&self.target))?;
            if let Err(e) = std::fs::rename(&self.tmp, &self.target) {
                // Put the previous run back.
                let _ = std::fs::rename(&old, &self.target);
                return Err(io(&self.target)(e));
            }
            std::fs::remove_dir_all(&old).map_err(io(&old))?;
        } else {
            if self.target.exists() {
                // An empty folder made before the run.
                std::fs::remove_dir(&self.target).map_err(io(&self.target))?;
            }
            std::fs::rename(&self.tmp, &self.target).map_err(io(&self.target))?;
        }
        self.committed = true;
        Ok(())
    }
}

impl Drop for RunFolder {
    fn drop(&mut self) {
        if !self.committed {
            let _ = std::fs::remove_dir_all(&self.tmp);
        }
    }
}

fn io(path: &Path) -> impl FnOnce(std::io::Error) -> OutputError + '_ {
    move |source| OutputError::Io {
        path: path.display().to_string(),
        source,
    }
}

/// The metrics file.
#[derive(Debug, Serialize)]
pub struct MetricsFile<'a> {
    /// Graph title.
    pub title: &'a Option<String>,
    /// Simulated time (s).
    pub duration_s: f64,
    /// Scores of the `score:` signals.
    pub scores: &'a [nanomotion_core::scheduler::Score],
    /// Rate transitions the loader inserted.
    pub rate_transitions: &'a [String],
    /// Cumulative-PSD end values per score (the variance seen through the
    /// spectrum: rms² − mean²), for cross-checking the scores.
    pub cumulative_psd_end: Vec<CumulativePsdEnd>,
}

/// The end value of one score's cumulative PSD.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct CumulativePsdEnd {
    /// `block.port` (with `[j]` for an element of a vector signal).
    pub signal: String,
    /// Samples before this time (s) were left out, as for the score.
    pub from_s: f64,
    /// The end value (unit²): the variance of the scored samples.
    pub end: f64,
}

/// File-name-safe form of a signal name.
pub fn file_stem(name: &str) -> String {
    name.chars()
        .map(|c| {
            if c.is_ascii_alphanumeric() || c == '-' || c == '_' {
                c
            } else {
                '_'
            }
        })
        .collect()
}

/// Column names of a log: `name` or `name[j]`.
fn columns(log: &SignalLog) -> Vec<String> {
    if log.width == 1 {
        vec![log.name.clone()]
    } else {
        (0..log.width)
            .map(|j| format!("{}[{j}]", log.name))
            .collect()
    }
}

/// Write signals grouped by rate: `signals.csv` if all logs share one rate, else one
/// `signals_<rate>hz.csv` per rate. Returns the files written.
pub fn write_csv(dir: &Path, logs: &[SignalLog]) -> Result<Vec<PathBuf>, OutputError> {
    let mut rates: Vec<f64> = Vec::new();
    for l in logs {
        if !rates.contains(&l.rate_hz) {
            rates.push(l.rate_hz);
        }
    }
    let mut written = Vec::new();
    for &rate in &rates {
        let group: Vec<&SignalLog> = logs.iter().filter(|l| l.rate_hz == rate).collect();
        let path = if rates.len() == 1 {
            dir.join("signals.csv")
        } else {
            dir.join(format!("signals_{rate}hz.csv"))
        };
        let csv_err = |e: csv::Error| OutputError::Csv {
            path: path.display().to_string(),
            message: e.to_string(),
        };
        let mut w = csv::Writer::from_path(&path).map_err(csv_err)?;
        let mut header = vec!["t_s".to_string()];
        for l in &group {
            header.extend(columns(l));
        }
        w.write_record(&header).map_err(csv_err)?;
        let n = group.iter().map(|l| l.len()).max().unwrap_or(0);
        let mut row: Vec<String> = Vec::with_capacity(header.len());
        for i in 0..n {
            row.clear();
            row.push(format!("{}", i as f64 / rate));
            for l in &group {
                for j in 0..l.width {
                    row.push(
                        l.data
                            .get(i * l.width + j)
                            .map_or(String::new(), |v| format!("{v:e}")),
                    );
                }
            }
            w.write_record(&row).map_err(csv_err)?;
        }
        w.flush().map_err(io(&path))?;
        written.push(path);
    }
    Ok(written)
}

/// Cumulative PSD (unit²) of `x` sampled at `fs_hz`: frequencies and the running
/// integral of the one-sided Welch PSD. Its end value is the signal's variance.
pub fn cumulative_psd(x: &[f64], fs_hz: f64) -> (Vec<f64>, Vec<f64>) {
    use nanomotion_core::analysis::{WelchOptions, psd_welch};
    // Segments of up to 2^14 samples (frequency resolution fs/16384), at least 8.
    let seg = x.len().clamp(8, 1 << 14);
    match psd_welch(x, fs_hz, &WelchOptions::new(seg)) {
        Ok(p) => {
            let c = p.cumulative();
            (p.freq_hz, c)
        }
        Err(_) => (Vec::new(), Vec::new()),
    }
}

/// Write everything about a run into `dir`: CSV, `metrics.json`, SVG plots.
/// Returns the files written.
pub fn write_all(
    dir: &Path,
    result: &RunResult,
    rate_transitions: &[String],
) -> Result<Vec<PathBuf>, OutputError> {
    write_all_with_progress(dir, result, rate_transitions, |_, _| {})
}

/// [`write_all`], calling `progress(file, fraction)` before each file is written
/// (`fraction` of the files done, 0..1), so a caller can show what is being
/// written (a long run's CSV and plots take seconds).
pub fn write_all_with_progress(
    dir: &Path,
    result: &RunResult,
    rate_transitions: &[String],
    mut progress: impl FnMut(&str, f64),
) -> Result<Vec<PathBuf>, OutputError> {
    std::fs::create_dir_all(dir).map_err(io(dir))?;
    let traces = result.logs.iter().filter(|l| !l.is_empty()).count();
    let total = (traces + 3) as f64; // CSV, traces, cumulative PSD, metrics
    let mut step = 0.0;
    let mut tell = |what: &str| {
        progress(what, step / total);
        step += 1.0;
    };
    tell("signals CSV");
    let mut written = write_csv(dir, &result.logs)?;
    let title = result
        .title
        .clone()
        .unwrap_or_else(|| "nanomotion run".into());

    // One trace plot per logged signal (none for an empty log: `duration_s: 0`).
    for log in result.logs.iter().filter(|l| !l.is_empty()) {
        let t = log.times();
        let series = (0..log.width)
            .map(|j| Series {
                label: columns(log)[j].clone(),
                x: t.clone(),
                y: log.column(j),
            })
            .collect();
        let fig = Figure {
            title: format!("{title}: {}", log.name),
            x_label: "time (s)".into(),
            y_label: log.name.clone(),
            x_scale: Scale::Linear,
            series,
        };
        let path = dir.join(format!("trace_{}.svg", file_stem(&log.name)));
        tell(&format!("trace of {}", log.name));
        draw_svg(&fig, &path)?;
        written.push(path);
    }

    // Cumulative PSD of the scored signals (the thesis's way to judge a result).
    tell("cumulative PSD");
    let mut cps = Vec::new();
    let mut cp_series = Vec::new();
    for s in &result.scores {
        let (base, j) = match s.signal.find('[') {
            Some(p) => (
                &s.signal[..p],
                s.signal[p + 1..s.signal.len() - 1]
                    .parse::<usize>()
                    .unwrap_or(0),
            ),
            None => (s.signal.as_str(), 0),
        };
        let Some(log) = result.logs.iter().find(|l| l.name == base) else {
            continue;
        };
        let first = (s.from_s * log.rate_hz - 1e-9).ceil().max(0.0) as usize;
        let x: Vec<f64> = log.column(j).into_iter().skip(first).collect();
        if x.len() < 16 {
            continue;
        }
        let (f, c) = cumulative_psd(&x, log.rate_hz);
        if let Some(&end) = c.last() {
            cps.push(CumulativePsdEnd {
                signal: s.signal.clone(),
                from_s: s.from_s,
                end,
            });
            cp_series.push(Series {
                label: format!("{} from {} s (end {:.3e})", s.signal, s.from_s, end),
                x: f,
                y: c,
            });
        }
    }
    if !cp_series.is_empty() {
        let fig = Figure {
            title: format!("{title}: cumulative PSD of the scored signals"),
            x_label: "frequency (Hz)".into(),
            y_label: "cumulative PSD (unit²)".into(),
            x_scale: Scale::Log,
            series: cp_series,
        };
        let path = dir.join("cumulative_psd.svg");
        draw_svg(&fig, &path)?;
        written.push(path);
    }

    let metrics = MetricsFile {
        title: &result.title,
        duration_s: result.duration_s,
        scores: &result.scores,
        rate_transitions,
        cumulative_psd_end: cps,
    };
    tell("metrics.json");
    let path = dir.join("metrics.json");
    let text = serde_json::to_string_pretty(&metrics).map_err(|e| OutputError::Csv {
        path: path.display().to_string(),
        message: e.to_string(),
    })?;
    std::fs::write(&path, text).map_err(io(&path))?;
    written.push(path);
    Ok(written)
}

/// The comparison file (`comparison.json`) of `nanomotion run --data`.
#[derive(Debug, Serialize)]
pub struct ComparisonFile<'a> {
    /// The data file.
    pub data: &'a str,
    /// The data's sample rate (Hz).
    pub data_rate_hz: f64,
    /// Samples in the data.
    pub data_samples: usize,
    /// One entry per `compare:` pair; the residual is `measured − model`.
    pub comparisons: &'a [nanomotion_core::data::Comparison],
}

/// Write `comparison.json` and one SVG per compared signal
/// (`compare_<signal>.svg`: measured and model against time on top, the residual
/// below). Returns the files written.
pub fn write_comparisons(
    dir: &Path,
    title: &str,
    data: &nanomotion_core::data::Dataset,
    comparisons: &[nanomotion_core::data::Comparison],
) -> Result<Vec<PathBuf>, OutputError> {
    std::fs::create_dir_all(dir).map_err(io(dir))?;
    let mut written = Vec::new();
    for c in comparisons {
        let t = c.times();
        let top = Figure {
            title: format!("{title}: {} against measured `{}`", c.signal, c.column),
            x_label: "time (s)".into(),
            y_label: c.column.clone(),
            x_scale: Scale::Linear,
            series: vec![
                Series {
                    label: format!("measured {}", c.column),
                    x: t.clone(),
                    y: c.measured.clone(),
                },
                Series {
                    label: format!("model {}", c.signal),
                    x: t.clone(),
                    y: c.model.clone(),
                },
            ],
        };
        let bottom = Figure {
            title: format!(
                "residual (measured − model): rms {:.3e}, max {:.3e}, fit {:.2} %",
                c.rms, c.max_abs, c.fit_percent
            ),
            x_label: "time (s)".into(),
            y_label: "residual".into(),
            x_scale: Scale::Linear,
            series: vec![Series {
                label: "measured − model".into(),
                x: t,
                y: c.residual.clone(),
            }],
        };
        let path = dir.join(format!("compare_{}.svg", file_stem(&c.signal)));
        crate::plot::draw_svg_panels(&[top, bottom], &path)?;
        written.push(path);
    }
    let file = ComparisonFile {
        data: data.origin(),
        data_rate_hz: data.rate_hz(),
        data_samples: data.len(),
        comparisons,
    };
    let path = dir.join("comparison.json");
    let text = serde_json::to_string_pretty(&file).map_err(|e| OutputError::Csv {
        path: path.display().to_string(),
        message: e.to_string(),
    })?;
    std::fs::write(&path, text).map_err(io(&path))?;
    written.push(path);
    Ok(written)
}
