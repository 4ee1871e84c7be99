//! Measured data: uniformly sampled columns (a record from a real stage) that graphs
//! play through `data_column` blocks and compare their outputs with.
//!
//! A [`Dataset`] is a set of named, equally long columns sampled at one rate;
//! sample `k` is taken at `t_k = t0 + k / rate`.

use thiserror::Error;

/// Something wrong with a data file or a dataset: names the file and, where it
/// applies, the row (1-based, as an editor shows it) and the column.
#[derive(Debug, Clone, PartialEq, Error)]
#[error("{origin}{}{}: {problem} (fix: {fix})", row.map(|r| format!(", row {r}")).unwrap_or_default(), column.as_ref().map(|c| format!(", column `{c}`")).unwrap_or_default())]
pub struct DataError {
    /// The file (or other origin) of the data.
    pub origin: String,
    /// The row, 1-based counting the header, if the problem has one.
    pub row: Option<usize>,
    /// The column, if the problem has one.
    pub column: Option<String>,
    /// What is wrong.
    pub problem: String,
    /// How to fix it.
    pub fix: String,
}

impl DataError {
    /// A new data error about `origin`.
    pub fn new(
        origin: impl Into<String>,
        problem: impl Into<String>,
        fix: impl Into<String>,
    ) -> Self {
        Self {
            origin: origin.into(),
            row: None,
            column: None,
            problem: problem.into(),
            fix: fix.into(),
        }
    }
    /// The same error, at `row` (1-based).
    pub fn at_row(mut self, row: usize) -> Self {
        self.row = Some(row);
        self
    }
    /// The same error, in `column`.
    pub fn in_column(mut self, column: impl Into<String>) -> Self {
        self.column = Some(column.into());
        self
    }
}

/// Uniformly sampled named columns.
#[derive(Debug, Clone, PartialEq)]
pub struct Dataset {
    origin: String,
    rate_hz: f64,
    t0_s: f64,
    names: Vec<String>,
    columns: Vec<Vec<f64>>,
}

impl Dataset {
    /// A dataset from columns sampled at `rate_hz`, the first sample at `t0_s`.
    /// Every column must be as long as the first, finite, and named uniquely.
    pub fn from_columns(
        origin: impl Into<String>,
        rate_hz: f64,
        t0_s: f64,
        columns: Vec<(String, Vec<f64>)>,
    ) -> Result<Self, DataError> {
        let origin = origin.into();
        if !(rate_hz.is_finite() && rate_hz > 0.0) {
            return Err(DataError::new(
                &origin,
                format!("sample rate {rate_hz} Hz is not a positive number"),
                "give a positive sample rate",
            ));
        }
        if !t0_s.is_finite() {
            return Err(DataError::new(
                &origin,
                "start time is not finite",
                "give a finite start time",
            ));
        }
        if columns.is_empty() {
            return Err(DataError::new(
                &origin,
                "has no data columns",
                "add at least one column",
            ));
        }
        let n = columns[0].1.len();
        let mut names: Vec<String> = Vec::with_capacity(columns.len());
        let mut data = Vec::with_capacity(columns.len());
        for (name, col) in columns {
            if names.contains(&name) {
                return Err(DataError::new(
                    &origin,
                    "column name appears twice",
                    "rename one of them",
                )
                .in_column(name));
            }
            if col.len() != n {
                return Err(DataError::new(
                    &origin,
                    format!("has {} samples where the first column has {n}", col.len()),
                    "give every column the same length",
                )
                .in_column(name));
            }
            if let Some(i) = col.iter().position(|v| !v.is_finite()) {
                return Err(DataError::new(
                    &origin,
                    format!("sample {i} is {}, not a finite number", col[i]),
                    "remove or repair the sample (nanomotion never fills gaps silently)",
                )
                .in_column(name));
            }
            names.push(name);
            data.push(col);
        }
        Ok(Self {
            origin,
            rate_hz,
            t0_s,
            names,
            columns: data,
        })
    }

    /// Where the data came from (file name), for messages.
    pub fn origin(&self) -> &str {
        &self.origin
    }
    /// Sample rate (Hz).
    pub fn rate_hz(&self) -> f64 {
        self.rate_hz
    }
    /// Time of the first sample (s).
    pub fn t0_s(&self) -> f64 {
        self.t0_s
    }
    /// Number of samples per column.
    pub fn len(&self) -> usize {
        self.columns.first().map_or(0, Vec::len)
    }
    /// Whether the columns are empty.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }
    /// Length in seconds (`len / rate`).
    pub fn duration_s(&self) -> f64 {
        self.len() as f64 / self.rate_hz
    }
    /// Column names, in file order.
    pub fn names(&self) -> &[String] {
        &self.names
    }
    /// The column called `name`.
    pub fn column(&self, name: &str) -> Option<&[f64]> {
        let i = self.names.iter().position(|n| n == name)?;
        Some(&self.columns[i])
    }
    /// The column called `name`, or an error that lists the columns there are.
    pub fn require(&self, name: &str) -> Result<&[f64], DataError> {
        self.column(name).ok_or_else(|| {
            DataError::new(
                &self.origin,
                format!(
                    "has no column `{name}`; its columns are: {}",
                    self.names.join(", ")
                ),
                "name one of the columns above",
            )
            .in_column(name)
        })
    }
    /// Samples `range` of every column, as a new dataset (times keep their origin:
    /// `t0` moves to the first kept sample).
    pub fn slice(&self, range: std::ops::Range<usize>) -> Dataset {
        let end = range.end.min(self.len());
        let start = range.start.min(end);
        Dataset {
            origin: self.origin.clone(),
            rate_hz: self.rate_hz,
            t0_s: self.t0_s + start as f64 / self.rate_hz,
            names: self.names.clone(),
            columns: self
                .columns
                .iter()
                .map(|c| c[start..end].to_vec())
                .collect(),
        }
    }
    /// A copy with column `name` replaced (or added) — for generators of test data.
    pub fn with_column(mut self, name: &str, values: Vec<f64>) -> Result<Dataset, DataError> {
        if values.len() != self.len() {
            return Err(DataError::new(
                &self.origin,
                format!(
                    "new column has {} samples, the dataset {}",
                    values.len(),
                    self.len()
                ),
                "give the same length",
            )
            .in_column(name));
        }
        match self.names.iter().position(|n| n == name) {
            Some(i) => self.columns[i] = values,
            None => {
                self.names.push(name.to_string());
                self.columns.push(values);
            }
        }
        Ok(self)
    }
}

// ---------------------------------------------------------------------------------
// Loading files
// ---------------------------------------------------------------------------------

/// Read a text data file through a reader bounded by [`MAX_FILE_BYTES`] (a
/// device such as `/dev/zero`, or a huge file, is an error, not an endless read).
pub fn read_text_capped_data(path: &std::path::Path) -> std::io::Result<String> {
    crate::files::read_text_capped(path, MAX_FILE_BYTES)
}

/// A measured data set of the shared folder (`shared/data/…` beside the
/// workspace) that a test or example needs: `Some(path)` if it exists. If it does
/// not, with the environment variable `CI` set this panics (a CI run must not pass
/// a test that checked nothing); otherwise it prints `SKIPPED: <test>: <path> not
/// found` straight to the terminal's stderr — not through the test harness's
/// capture, so the skip is visible in a plain `cargo test` — and returns `None`.
pub fn shared_data_or_skip(path: &std::path::Path, test: &str) -> Option<std::path::PathBuf> {
    use std::io::Write as _;
    if path.exists() {
        return Some(path.to_path_buf());
    }
    assert!(
        std::env::var_os("CI").is_none(),
        "{test}: {} not found, and CI is set: the shared data must be beside the checkout",
        path.display()
    );
    // `std::io::stderr()` directly: the harness captures `eprintln!`, not this.
    let _ = writeln!(
        std::io::stderr(),
        "SKIPPED: {test}: {} not found (set up shared/data beside the workspace to run it)",
        path.display()
    );
    None
}

/// Largest data file read (bytes): 512 MiB. Files are read through a bounded
/// reader, so even an endless stream (`/dev/zero`) stops here.
pub const MAX_FILE_BYTES: u64 = 512 * 1024 * 1024;

/// Fewest samples a dataset may have: 16 (fewer cannot be scored or plotted
/// meaningfully, and usually mean a truncated file).
pub const MIN_SAMPLES: usize = 16;

/// Relative part of the tolerance on each time step: a step `Δt_k = t_k − t_{k−1}`
/// is uniform when `|Δt_k − Δt| ≤ 2·q + UNIFORM_REL_TOL·Δt + UNIFORM_ABS_TOL_S`,
/// where `Δt = 1/rate` and `q` is half a unit in the last printed digit of the
/// timestamps (their rounding when they were written).
pub const UNIFORM_REL_TOL: f64 = 1e-6;

/// Absolute part of the time-step tolerance (s), see [`UNIFORM_REL_TOL`].
pub const UNIFORM_ABS_TOL_S: f64 = 1e-12;

/// Largest timestamp rounding accepted, as a fraction of the sample period: the
/// timestamps must be printed with enough digits that half a unit of their last
/// digit is at most 1e-3·Δt.
pub const MAX_TIME_RESOLUTION_REL: f64 = 1e-3;

/// Read at most [`MAX_FILE_BYTES`] of `path`.
fn read_bounded(path: &std::path::Path) -> Result<Vec<u8>, DataError> {
    read_capped(path, MAX_FILE_BYTES)
}

/// Read at most `cap` bytes of `path`; more is an error.
fn read_capped(path: &std::path::Path, cap: u64) -> Result<Vec<u8>, DataError> {
    use std::io::Read;
    let origin = path.display().to_string();
    let file = std::fs::File::open(path).map_err(|e| {
        DataError::new(
            &origin,
            format!("cannot be opened: {e}"),
            "check the path and that the file is readable",
        )
    })?;
    let mut buf = Vec::new();
    file.take(cap + 1).read_to_end(&mut buf).map_err(|e| {
        DataError::new(
            &origin,
            format!("cannot be read: {e}"),
            "check that the path is a readable file, not a folder",
        )
    })?;
    if buf.len() as u64 > cap {
        return Err(DataError::new(
            &origin,
            format!(
                "is larger than the cap of {} MiB for data files",
                cap as f64 / (1024.0 * 1024.0)
            ),
            "cut the record into shorter files or decimate it",
        ));
    }
    Ok(buf)
}

/// Half a unit in the last printed digit of a decimal number (`"0.001333"` →
/// 5e-7, `"1.5e-3"` → 5e-5); `None` for a whole number without a decimal point or
/// exponent (`"0"`, `"12"`), which says nothing about the format's precision.
fn print_resolution(text: &str) -> Option<f64> {
    let (mantissa, exponent) = match text.find(['e', 'E']) {
        Some(p) => (&text[..p], Some(text[p + 1..].parse::<i32>().unwrap_or(0))),
        None => (text, None),
    };
    let decimals = mantissa.find('.').map(|p| (mantissa.len() - p - 1) as i32);
    if decimals.is_none() && exponent.is_none() {
        return None;
    }
    Some(0.5 * 10f64.powi(exponent.unwrap_or(0) - decimals.unwrap_or(0)))
}

/// `x` rounded to `digits` significant decimal digits.
fn round_significant(x: f64, digits: usize) -> f64 {
    format!("{:.*e}", digits.saturating_sub(1), x)
        .parse()
        .unwrap_or(x)
}

/// Where uniform timing first fails: sample index, step, mean step, tolerance.
struct StepFailure {
    k: usize,
    step: f64,
    dt: f64,
    rate: f64,
    tol: f64,
}

/// Rate and start time of timestamps `t` read as rounded by `q` (s) each: the rate
/// interval `(n−1)/(span ± 2q')` (q' = q plus a few ulp of binary rounding), the
/// value of it with the fewest significant digits, and every step checked against
/// `|Δt_k − Δt| ≤ 2q' + UNIFORM_REL_TOL·Δt + UNIFORM_ABS_TOL_S`.
fn uniform_fit(t: &[f64], q: f64) -> Result<(f64, f64), StepFailure> {
    let n = t.len();
    let (t0, span) = (t[0], t[n - 1] - t[0]);
    let qk = |k: usize| q + 4.0 * f64::EPSILON * t[k].abs();
    let estimate = (n - 1) as f64 / span;
    let slack = qk(0) + qk(n - 1);
    let lo = (n - 1) as f64 / (span + slack);
    let hi = if span > slack {
        (n - 1) as f64 / (span - slack)
    } else {
        f64::INFINITY
    };
    let rate = (1..=17)
        .map(|d| round_significant(estimate, d))
        .find(|r| (lo..=hi).contains(r))
        .unwrap_or(estimate);
    let dt = 1.0 / rate;
    let tol = |k: usize| qk(k) + qk(k - 1) + UNIFORM_REL_TOL * dt + UNIFORM_ABS_TOL_S;
    let Some(first) = (1..n).find(|&k| (t[k] - t[k - 1] - dt).abs() > tol(k)) else {
        return Ok((rate, t0));
    };
    // A gap skews the mean step so that every step fails: point at the first step
    // that differs from the median step instead, where the gap is.
    let mut steps: Vec<f64> = t.windows(2).map(|w| w[1] - w[0]).collect();
    steps.sort_by(f64::total_cmp);
    let median = steps[steps.len() / 2];
    let k = (1..n)
        .find(|&k| (t[k] - t[k - 1] - median).abs() > tol(k))
        .unwrap_or(first);
    Err(StepFailure {
        k,
        step: t[k] - t[k - 1],
        dt,
        rate,
        tol: tol(k),
    })
}

/// Sample rate and start time from timestamps `t` (strictly increasing, at least
/// two), checking that they are uniform; `rows` maps a sample index to the row
/// reported in errors.
///
/// The times are first taken at face value (exact up to binary rounding). If that
/// fails and `q` (half a unit in the last digit of the most precisely printed
/// timestamp, e.g. 5e-7 for `%.6f`) is at most [`MAX_TIME_RESOLUTION_REL`] of the
/// period, they are read as rounded by `q`: the rate is then known only to within
/// `(n−1)/(span ± 2q)`, and of that interval the value with the fewest significant
/// digits is taken (so times printed as `0.001333` at 750 Hz give exactly 750 Hz,
/// not 750.00002).
fn rate_from_times(
    origin: &str,
    column: &str,
    t: &[f64],
    q: Option<f64>,
    rows: impl Fn(usize) -> usize,
) -> Result<(f64, f64), DataError> {
    let exact = match uniform_fit(t, 0.0) {
        Ok(fit) => return Ok(fit),
        Err(f) => f,
    };
    let mut note = String::new();
    let failure = match q {
        Some(q) if q > 0.0 && q <= MAX_TIME_RESOLUTION_REL * exact.dt => match uniform_fit(t, q) {
            Ok(fit) => return Ok(fit),
            Err(f) => f,
        },
        Some(q) if q > 0.0 && uniform_fit(t, q).is_ok() => {
            note = format!(
                "; the timestamps are printed with too few digits to be read as rounded (±{q:e} s is more than {MAX_TIME_RESOLUTION_REL:e} of the period)"
            );
            exact
        }
        _ => exact,
    };
    let StepFailure {
        k,
        step,
        dt,
        rate,
        tol,
    } = failure;
    Err(DataError::new(
        origin,
        format!(
            "time is not uniformly sampled: the step from {} s to {} s is {step:e} s, the mean step Δt is {dt:e} s ({rate} Hz); tolerance |Δt_k − Δt| ≤ (rounding of the two timestamps) + {UNIFORM_REL_TOL:e}·Δt + {UNIFORM_ABS_TOL_S:e} s = {tol:e} s{note}",
            t[k - 1], t[k]
        ),
        if note.is_empty() {
            "give uniformly sampled data (a gap or a repeated sample shows here); nanomotion does not resample silently"
        } else {
            "write the times with more decimals, or give uniformly sampled data"
        },
    )
    .at_row(rows(k))
    .in_column(column))
}

impl Dataset {
    /// Load a data file, choosing the format by extension: `.mat` is MATLAB v5
    /// ([`Dataset::from_mat_file`]), anything else CSV ([`Dataset::from_csv_file`]).
    pub fn from_file(path: impl AsRef<std::path::Path>) -> Result<Self, DataError> {
        Self::from_file_with_rate(path, None)
    }

    /// [`Dataset::from_file`] with a sample rate for `.mat` files that hold no time
    /// vector (CSV files always carry their times; a rate given for one must agree).
    pub fn from_file_with_rate(
        path: impl AsRef<std::path::Path>,
        rate_hz: Option<f64>,
    ) -> Result<Self, DataError> {
        let path = path.as_ref();
        let is_mat = path
            .extension()
            .and_then(|e| e.to_str())
            .is_some_and(|e| e.eq_ignore_ascii_case("mat"));
        let d = if is_mat {
            Self::from_mat_file_with_rate(path, rate_hz)?
        } else {
            Self::from_csv_file(path)?
        };
        if let Some(r) = rate_hz
            && !is_mat
        {
            check_given_rate(&d, r)?;
        }
        Ok(d)
    }

    /// Load a CSV file (format in [`Dataset::from_csv_str`]). The file is read with
    /// a cap of [`MAX_FILE_BYTES`].
    pub fn from_csv_file(path: impl AsRef<std::path::Path>) -> Result<Self, DataError> {
        let path = path.as_ref();
        let bytes = read_bounded(path)?;
        Self::from_csv_bytes(&bytes, &path.display().to_string())
    }

    /// Parse CSV text; `origin` (a file name) prefixes errors.
    ///
    /// Format: optional comment lines starting with `#`, then a header row whose first
    /// column is `t` or `t_s` (time in seconds) followed by the names of the data
    /// columns, then one row per sample, all fields numbers. The times must increase
    /// strictly and be uniform (see [`UNIFORM_REL_TOL`]); at least [`MIN_SAMPLES`]
    /// rows. Every problem is a [`DataError`] with the row as an editor counts it.
    pub fn from_csv_str(text: &str, origin: &str) -> Result<Self, DataError> {
        Self::from_csv_bytes(text.as_bytes(), origin)
    }

    fn from_csv_bytes(bytes: &[u8], origin: &str) -> Result<Self, DataError> {
        // Skip a UTF-8 byte-order mark, then comment lines before the header.
        let mut rest = bytes.strip_prefix(b"\xEF\xBB\xBF").unwrap_or(bytes);
        let mut skipped_lines = 0usize;
        loop {
            let line_end = rest.iter().position(|&b| b == b'\n');
            let line = &rest[..line_end.unwrap_or(rest.len())];
            let trimmed = line.trim_ascii();
            if trimmed.starts_with(b"#") || (trimmed.is_empty() && line_end.is_some()) {
                skipped_lines += 1;
                rest = &rest[line_end.map_or(rest.len(), |e| e + 1)..];
            } else {
                break;
            }
        }
        let mut reader = csv::ReaderBuilder::new()
            .has_headers(false)
            .flexible(true)
            .trim(csv::Trim::All)
            .from_reader(rest);
        let line_of = |pos: Option<&csv::Position>| {
            pos.map_or(skipped_lines + 1, |p| p.line() as usize + skipped_lines)
        };
        let csv_error = |e: csv::Error| {
            let row = e.position().map(|p| p.line() as usize + skipped_lines);
            let mut d = DataError::new(
                origin,
                format!("is not valid CSV: {e}"),
                "save the file as plain comma-separated UTF-8 text",
            );
            d.row = row;
            d
        };
        let mut records = reader.byte_records();
        let header = match records.next() {
            None => {
                return Err(DataError::new(
                    origin,
                    "has no header row",
                    "start the file with a header such as `t_s,u,y` (time in seconds first)",
                )
                .at_row(skipped_lines + 1));
            }
            Some(r) => r.map_err(csv_error)?,
        };
        let header_row = line_of(header.position());
        let mut names = Vec::with_capacity(header.len());
        for (j, field) in header.iter().enumerate() {
            let name = std::str::from_utf8(field).map_err(|_| {
                DataError::new(
                    origin,
                    format!("header field {} is not UTF-8 text", j + 1),
                    "save the file as UTF-8",
                )
                .at_row(header_row)
            })?;
            if name.is_empty() {
                return Err(DataError::new(
                    origin,
                    format!("header field {} is empty", j + 1),
                    "name every column in the header",
                )
                .at_row(header_row));
            }
            names.push(name.to_string());
        }
        if names[0] != "t" && names[0] != "t_s" {
            let looks_numeric = names[0].parse::<f64>().is_ok();
            return Err(DataError::new(
                origin,
                if looks_numeric {
                    "has no header row (the first line holds numbers)".to_string()
                } else {
                    format!(
                        "first column is `{}`, not the time `t` or `t_s` (seconds)",
                        names[0]
                    )
                },
                "start the header with `t_s` (time in seconds), e.g. `t_s,u,y`",
            )
            .at_row(header_row)
            .in_column(names[0].clone()));
        }
        if names.len() < 2 {
            return Err(DataError::new(
                origin,
                "has only the time column",
                "add at least one data column after the time",
            )
            .at_row(header_row));
        }
        for (j, name) in names.iter().enumerate() {
            if names[..j].contains(name) {
                return Err(DataError::new(
                    origin,
                    "column name appears twice in the header",
                    "rename one of them",
                )
                .at_row(header_row)
                .in_column(name.clone()));
            }
        }
        let width = names.len();
        let mut columns: Vec<Vec<f64>> = vec![Vec::new(); width];
        let mut rows: Vec<usize> = Vec::new();
        let mut resolution: Option<f64> = None;
        for record in records {
            let record = record.map_err(csv_error)?;
            let row = line_of(record.position());
            if record.len() != width {
                return Err(DataError::new(
                    origin,
                    format!(
                        "has {} fields where the header has {width} ({})",
                        record.len(),
                        names.join(", ")
                    ),
                    "give every row one value per header column",
                )
                .at_row(row));
            }
            for (j, field) in record.iter().enumerate() {
                let col = &names[j];
                let text = std::str::from_utf8(field).unwrap_or("\u{fffd}");
                if text.is_empty() {
                    return Err(DataError::new(
                        origin,
                        "value is empty",
                        "fill in the value (nanomotion never fills gaps silently)",
                    )
                    .at_row(row)
                    .in_column(col.clone()));
                }
                let v: f64 = text.parse().map_err(|_| {
                    DataError::new(
                        origin,
                        format!("`{}` is not a number", text.escape_debug()),
                        "write a decimal number such as 1.5e-6",
                    )
                    .at_row(row)
                    .in_column(col.clone())
                })?;
                if !v.is_finite() {
                    return Err(DataError::new(
                        origin,
                        format!("value is {v}, not a finite number"),
                        "remove or repair the sample (nanomotion never fills gaps silently)",
                    )
                    .at_row(row)
                    .in_column(col.clone()));
                }
                if j == 0 {
                    if let Some(&prev) = columns[0].last()
                        && v <= prev
                    {
                        return Err(DataError::new(
                            origin,
                            format!(
                                "time does not increase: {v} s after {prev} s on row {}",
                                rows.last().copied().unwrap_or(row)
                            ),
                            "sort the rows by time and remove repeated samples",
                        )
                        .at_row(row)
                        .in_column(col.clone()));
                    }
                    if let Some(q) = print_resolution(text) {
                        resolution = Some(resolution.map_or(q, |r: f64| r.min(q)));
                    }
                }
                columns[j].push(v);
            }
            rows.push(row);
        }
        let n = rows.len();
        if n < MIN_SAMPLES {
            return Err(DataError::new(
                origin,
                format!("has {n} samples, fewer than the minimum of {MIN_SAMPLES}"),
                "give a longer record",
            ));
        }
        let (rate, t0) = rate_from_times(origin, &names[0], &columns[0], resolution, |k| rows[k])?;
        let mut columns = columns.into_iter();
        columns.next();
        Self::from_columns(
            origin,
            rate,
            t0,
            names.into_iter().skip(1).zip(columns).collect(),
        )
    }

    /// Load a MATLAB v5 `.mat` file whose time vector is a variable `t` or `t_s`
    /// (seconds), or whose rate is a scalar `fs`, `fs_hz` or `rate_hz` (Hz). See
    /// [`Dataset::from_mat_file_with_rate`].
    #[cfg(feature = "mat")]
    pub fn from_mat_file(path: impl AsRef<std::path::Path>) -> Result<Self, DataError> {
        Self::from_mat_file_with_rate(path, None)
    }

    /// Load a MATLAB v5 `.mat` file. Every numeric real variable that is a vector
    /// (1×n or n×1) becomes a column named after the variable; 1×1 scalars are not
    /// columns; matrices and complex arrays are errors; cells, structs and other
    /// non-numeric variables are skipped by the reader. The rate comes from, in
    /// order: a time vector `t` or `t_s` (s, checked like a CSV time column), a scalar
    /// `fs`, `fs_hz` or `rate_hz`, or `rate_hz` given here; when several are present
    /// they must agree to 1e-9 relative. Without a time vector the first sample is at
    /// t = 0. MATLAB v7.3 files (HDF5) are refused with a message saying so.
    #[cfg(feature = "mat")]
    pub fn from_mat_file_with_rate(
        path: impl AsRef<std::path::Path>,
        rate_hz: Option<f64>,
    ) -> Result<Self, DataError> {
        let path = path.as_ref();
        let bytes = read_bounded(path)?;
        Self::from_mat_bytes(&bytes, &path.display().to_string(), rate_hz)
    }

    /// Without the `mat` feature: an error saying how to get `.mat` support.
    #[cfg(not(feature = "mat"))]
    pub fn from_mat_file_with_rate(
        path: impl AsRef<std::path::Path>,
        _rate_hz: Option<f64>,
    ) -> Result<Self, DataError> {
        Err(DataError::new(
            path.as_ref().display().to_string(),
            "is a .mat file, but nanomotion-core was built without the `mat` feature",
            "rebuild with the default features, or export the data as CSV",
        ))
    }

    /// Parse the bytes of a MATLAB v5 `.mat` file (see
    /// [`Dataset::from_mat_file_with_rate`]).
    #[cfg(feature = "mat")]
    pub fn from_mat_bytes(
        bytes: &[u8],
        origin: &str,
        rate_hz: Option<f64>,
    ) -> Result<Self, DataError> {
        let head = &bytes[..bytes.len().min(128)];
        let text = String::from_utf8_lossy(&head[..head.len().min(116)]);
        let hdf5 = bytes.len() >= 520 && &bytes[512..520] == b"\x89HDF\r\n\x1a\n";
        if text.starts_with("MATLAB 7.3") || hdf5 {
            return Err(DataError::new(
                origin,
                "is a MATLAB v7.3 (HDF5) file, which nanomotion cannot read",
                "save it as v5 in MATLAB (`save(file, vars..., '-v7')`) or export CSV",
            ));
        }
        if bytes.len() < 128 || !text.starts_with("MATLAB 5.0 MAT-file") {
            return Err(DataError::new(
                origin,
                "is not a MATLAB v5 .mat file (no `MATLAB 5.0 MAT-file` header)",
                "save it as v5 in MATLAB (`save(file, vars..., '-v7')`) or export CSV",
            ));
        }
        let vars = crate::mat5::read(bytes, MAX_FILE_BYTES as usize).map_err(|problem| {
            DataError::new(
                origin,
                problem,
                "copy or save the file again completely (MATLAB `save(file, vars..., '-v7')`), or export CSV",
            )
        })?;
        let mut columns: Vec<(String, Vec<f64>)> = Vec::new();
        let mut scalar_rate: Option<(String, f64)> = None;
        for a in vars {
            if a.non_numeric {
                continue;
            }
            let name = a.name;
            let values = a.values.map_err(|p| {
                DataError::new(
                    origin,
                    p,
                    "save real numeric vectors, one variable per signal",
                )
                .in_column(&name)
            })?;
            let size = a.dims;
            let non_unit = size.iter().filter(|&&d| d != 1).count();
            if values.len() == 1 {
                if ["fs", "fs_hz", "rate_hz"].contains(&name.as_str()) {
                    scalar_rate = Some((name, values[0]));
                }
                continue;
            }
            if non_unit > 1 {
                let dims: Vec<String> = size.iter().map(usize::to_string).collect();
                return Err(DataError::new(
                    origin,
                    format!(
                        "variable is a {} array; only vectors become columns",
                        dims.join("×")
                    ),
                    "save each signal as its own vector variable",
                )
                .in_column(name));
            }
            columns.push((name, values));
        }
        let time_at = columns.iter().position(|(n, _)| n == "t" || n == "t_s");
        let mut rate = None;
        let mut t0 = 0.0;
        let mut sources: Vec<(String, f64)> = Vec::new();
        let mut time_len: Option<(String, usize)> = None;
        if let Some(i) = time_at {
            let (name, t) = columns.remove(i);
            if t.len() < MIN_SAMPLES {
                return Err(DataError::new(
                    origin,
                    format!(
                        "has {} samples, fewer than the minimum of {MIN_SAMPLES}",
                        t.len()
                    ),
                    "give a longer record",
                ));
            }
            if let Some(k) = t.iter().position(|v| !v.is_finite()) {
                return Err(DataError::new(
                    origin,
                    format!("time sample {} is {}, not a finite number", k + 1, t[k]),
                    "repair the time vector",
                )
                .in_column(name));
            }
            if let Some(k) = (1..t.len()).find(|&k| t[k] <= t[k - 1]) {
                return Err(DataError::new(
                    origin,
                    format!(
                        "time does not increase: sample {} is {} s after {} s",
                        k + 1,
                        t[k],
                        t[k - 1]
                    ),
                    "sort the samples by time and remove repeated samples",
                )
                .in_column(name));
            }
            let (r, start) = rate_from_times(origin, &name, &t, None, |k| k + 1)?;
            time_len = Some((name.clone(), t.len()));
            rate = Some(r);
            t0 = start;
            sources.push((format!("time vector `{name}`"), r));
        }
        if let Some((name, r)) = scalar_rate {
            sources.push((format!("scalar `{name}`"), r));
            rate = rate.or(Some(r));
        }
        if let Some(r) = rate_hz {
            sources.push(("the rate given".into(), r));
            rate = rate.or(Some(r));
        }
        let Some(rate) = rate else {
            return Err(DataError::new(
                origin,
                "has no time vector `t`/`t_s` and no rate scalar `fs`/`fs_hz`/`rate_hz`, so its sample rate is unknown",
                "give the rate (`--data-rate HZ` on the command line) or save a time vector `t` in seconds",
            ));
        };
        for (what, r) in &sources {
            if !r.is_finite() || (r - rate).abs() > 1e-9 * rate.abs() {
                return Err(DataError::new(
                    origin,
                    format!(
                        "sample rates disagree: {} says {} Hz, {} says {r} Hz",
                        sources[0].0, rate, what
                    ),
                    "make the time vector, the rate scalar and the given rate agree",
                ));
            }
        }
        if columns.is_empty() {
            return Err(DataError::new(
                origin,
                "has no numeric vector variables besides the time",
                "save each signal as a real numeric vector",
            ));
        }
        let n = columns[0].1.len();
        if let Some((name, len)) = time_len
            && len != n
        {
            return Err(DataError::new(
                origin,
                format!(
                    "time vector has {len} samples where `{}` has {n}",
                    columns[0].0
                ),
                "save the time and the signals with the same length",
            )
            .in_column(name));
        }
        if let Some((name, c)) = columns.iter().find(|(_, c)| c.len() != n) {
            return Err(DataError::new(
                origin,
                format!("has {} samples where `{}` has {n}", c.len(), columns[0].0),
                "save vectors of the same length",
            )
            .in_column(name.clone()));
        }
        if n < MIN_SAMPLES {
            return Err(DataError::new(
                origin,
                format!("has {n} samples, fewer than the minimum of {MIN_SAMPLES}"),
                "give a longer record",
            ));
        }
        Self::from_columns(origin, rate, t0, columns)
    }

    /// The dataset as CSV text in the format [`Dataset::from_csv_str`] reads: a
    /// header `t_s,<names>` and every value in Rust's shortest round-trip form (times plain, values in exponent form), so
    /// that reading it back gives the same numbers.
    pub fn to_csv_string(&self) -> String {
        use std::fmt::Write as _;
        let mut s = String::from("t_s");
        for n in &self.names {
            s.push(',');
            s.push_str(n);
        }
        s.push('\n');
        for k in 0..self.len() {
            let _ = write!(s, "{}", self.t0_s + k as f64 / self.rate_hz);
            for c in &self.columns {
                let _ = write!(s, ",{:e}", c[k]);
            }
            s.push('\n');
        }
        s
    }

    /// Merge the columns of `other` (same rate and length) into this dataset, e.g. an
    /// input and an output saved in two `.mat` files.
    pub fn merge(mut self, other: Dataset) -> Result<Dataset, DataError> {
        if (self.rate_hz - other.rate_hz).abs() > 1e-9 * self.rate_hz || self.len() != other.len() {
            return Err(DataError::new(
                format!("{} + {}", self.origin, other.origin),
                format!(
                    "cannot be merged: {} samples at {} Hz against {} samples at {} Hz",
                    self.len(),
                    self.rate_hz,
                    other.len(),
                    other.rate_hz
                ),
                "merge records of the same rate and length",
            ));
        }
        for (name, col) in other.names.into_iter().zip(other.columns) {
            if self.names.contains(&name) {
                return Err(DataError::new(
                    &other.origin,
                    "column name is also in the other file",
                    "rename one of them",
                )
                .in_column(name));
            }
            self.names.push(name);
            self.columns.push(col);
        }
        self.origin = format!("{} + {}", self.origin, other.origin);
        Ok(self)
    }
}

/// A rate given for a CSV file must agree with the file's times.
fn check_given_rate(d: &Dataset, rate_hz: f64) -> Result<(), DataError> {
    if !rate_hz.is_finite() || (d.rate_hz - rate_hz).abs() > 1e-9 * d.rate_hz {
        return Err(DataError::new(
            &d.origin,
            format!("its times give {} Hz but {rate_hz} Hz was given", d.rate_hz),
            "drop the given rate (CSV files carry their times) or correct it",
        ));
    }
    Ok(())
}

// ---------------------------------------------------------------------------------
// Comparing model outputs with measured columns
// ---------------------------------------------------------------------------------

/// A model output compared with a measured column: the residual
/// `measured − model` and its scores.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct Comparison {
    /// The model signal, `block.port`.
    pub signal: String,
    /// The measured column.
    pub column: String,
    /// Number of samples compared (at the data's rate).
    pub samples: usize,
    /// Rate of the comparison (the data's rate, Hz).
    pub rate_hz: f64,
    /// Every how many model samples one is compared (model rate / data rate).
    pub model_decimation: usize,
    /// Root mean square of the residual.
    pub rms: f64,
    /// Largest absolute residual.
    pub max_abs: f64,
    /// Mean residual.
    pub mean: f64,
    /// Fit (%) = 100·(1 − ‖y − ŷ‖ / ‖y − ȳ‖), y measured, ŷ model, ȳ the mean of y:
    /// 100 for a perfect model, 0 for one no better than the mean, negative when worse.
    pub fit_percent: f64,
    /// Measured samples compared.
    #[serde(skip)]
    pub measured: Vec<f64>,
    /// Model samples compared (every `model_decimation`-th).
    #[serde(skip)]
    pub model: Vec<f64>,
    /// `measured − model`.
    #[serde(skip)]
    pub residual: Vec<f64>,
}

impl Comparison {
    /// Sample times (s) of the compared samples, from 0.
    pub fn times(&self) -> Vec<f64> {
        (0..self.samples).map(|i| i as f64 / self.rate_hz).collect()
    }
}

/// Compare one model signal (`model`, `width` values per sample at `model_rate_hz`)
/// with column `column` of `data`.
///
/// The model's rate must be an integer multiple `m` of the data's rate (to 1e-9
/// relative): model sample `m·i` is compared with measured sample `i`, both at
/// t = i / rate. The comparison covers the samples both have (at least
/// [`MIN_SAMPLES`]). Errors: a signal wider than 1, a rate that is not a multiple,
/// too few samples, a constant measured column (fit % undefined).
pub fn compare_signal(
    signal: &str,
    model: &[f64],
    width: usize,
    model_rate_hz: f64,
    data: &Dataset,
    column: &str,
) -> Result<Comparison, DataError> {
    let err = |problem: String, fix: &str| {
        DataError::new(
            data.origin(),
            format!("comparing `{signal}`: {problem}"),
            fix,
        )
        .in_column(column)
    };
    let measured_all = data.require(column)?;
    if width != 1 {
        return Err(err(
            format!("the signal carries {width} values per sample; compare signals of width 1"),
            "compare one element: route it through a `demux`/`select` block, or compare a scalar output",
        ));
    }
    let ratio = model_rate_hz / data.rate_hz();
    let m = ratio.round();
    if !(m >= 1.0 && (ratio - m).abs() <= 1e-9 * ratio) {
        return Err(err(
            format!(
                "the model signal runs at {model_rate_hz} Hz, which is not an integer multiple of the data's {} Hz",
                data.rate_hz()
            ),
            "run the compared block at the data's rate (`rate_hz:`) or at an integer multiple of it",
        ));
    }
    let m = m as usize;
    let n = measured_all.len().min(model.len().div_ceil(m));
    if n < MIN_SAMPLES {
        return Err(err(
            format!(
                "only {n} samples overlap (the model logged {}), fewer than the minimum of {MIN_SAMPLES}",
                model.len()
            ),
            "run the model as long as the data (drop --duration)",
        ));
    }
    let model: Vec<f64> = model.iter().step_by(m).take(n).copied().collect();
    if !model.iter().all(|v| v.is_finite()) {
        return Err(err(
            "the model signal is not finite".into(),
            "check the model's parameters (an unstable model diverges)",
        ));
    }
    let measured = &measured_all[..n];
    if let Some(e) = constant_column(measured) {
        return Err(err(
            format!(
                "the measured column is constant ({e:e}) over the {n} compared samples (a stuck or disconnected sensor), so fit % = 100·(1 − ‖y − ŷ‖/‖y − ȳ‖) is undefined"
            ),
            "compare a column that varies: check the sensor, and that `compare:` names the right column",
        ));
    }
    let scores = Scores::of(measured, &model);
    if !scores.all_finite() {
        let largest = |v: &[f64]| v.iter().fold(0.0f64, |a, x| a.max(x.abs()));
        return Err(err(
            format!(
                "the scores overflow (rms {}, fit % {}): the measured column reaches {:e} and the model {:e}, too large to square in f64",
                scores.rms,
                scores.fit_percent,
                largest(measured),
                largest(&model)
            ),
            "check the record for a corrupt sample (a value like 1e308, in this column or in a played input column), or rescale its units",
        ));
    }
    let residual: Vec<f64> = measured.iter().zip(&model).map(|(y, h)| y - h).collect();
    Ok(Comparison {
        signal: signal.to_string(),
        column: column.to_string(),
        samples: n,
        rate_hz: data.rate_hz(),
        model_decimation: m,
        rms: scores.rms,
        max_abs: scores.max_abs,
        mean: scores.mean,
        fit_percent: scores.fit_percent,
        measured: measured.to_vec(),
        model,
        residual,
    })
}

/// The value of a column that is constant up to the rounding of its own magnitude
/// (all samples within 4 ulp of each other: a stuck or disconnected sensor), or
/// `None` if it varies. A constant measured column carries no information about a
/// model: its fit % is undefined.
pub fn constant_column(values: &[f64]) -> Option<f64> {
    let (lo, hi) = values
        .iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), &v| {
            (a.min(v), b.max(v))
        });
    (lo <= hi && hi - lo <= 4.0 * f64::EPSILON * lo.abs().max(hi.abs())).then_some(lo)
}

/// The residual scores of a comparison (see [`Comparison`]).
struct Scores {
    rms: f64,
    max_abs: f64,
    mean: f64,
    fit_percent: f64,
}

impl Scores {
    /// Scores of `measured − model`; the mean ȳ is taken about the first sample,
    /// so that a column that varies only in its last digits is not made to vary
    /// by the rounding of its mean.
    fn of(measured: &[f64], model: &[f64]) -> Self {
        let nf = measured.len() as f64;
        let y0 = measured.first().copied().unwrap_or(0.0);
        let mean_y = y0 + measured.iter().map(|y| y - y0).sum::<f64>() / nf;
        let spread = measured
            .iter()
            .map(|y| (y - mean_y) * (y - mean_y))
            .sum::<f64>()
            .sqrt();
        let residual = || measured.iter().zip(model).map(|(y, h)| y - h);
        let norm_r = residual().map(|r| r * r).sum::<f64>().sqrt();
        Self {
            rms: norm_r / nf.sqrt(),
            max_abs: residual().fold(0.0f64, |a, r| a.max(r.abs())),
            mean: residual().sum::<f64>() / nf,
            fit_percent: 100.0 * (1.0 - norm_r / spread),
        }
    }
    fn all_finite(&self) -> bool {
        [self.rms, self.max_abs, self.mean, self.fit_percent]
            .iter()
            .all(|v| v.is_finite())
    }
}

/// What blocks and the graph compiler read of a data set
/// ([`crate::block::MeasuredData`]): the same accessors.
impl crate::block::MeasuredData for Dataset {
    fn origin(&self) -> &str {
        Dataset::origin(self)
    }
    fn rate_hz(&self) -> f64 {
        Dataset::rate_hz(self)
    }
    fn len(&self) -> usize {
        Dataset::len(self)
    }
    fn duration_s(&self) -> f64 {
        Dataset::duration_s(self)
    }
    fn names(&self) -> &[String] {
        Dataset::names(self)
    }
    fn column(&self, name: &str) -> Option<&[f64]> {
        Dataset::column(self, name)
    }
}

/// Compare every `compare:` entry of a graph that has run with the measured data
/// (see [`compare_signal`]). Call it after [`Scheduler::run`](crate::Scheduler::run).
pub fn compare(
    sched: &crate::scheduler::Scheduler,
    data: &Dataset,
) -> Result<Vec<Comparison>, DataError> {
    let entries: Vec<(String, String)> = sched
        .compares()
        .map(|(s, c)| (s.to_string(), c.to_string()))
        .collect();
    let mut out = Vec::with_capacity(entries.len());
    for (signal, column) in entries {
        let (values, width, rate) = sched.log_view(&signal).ok_or_else(|| {
            DataError::new(
                data.origin(),
                format!("comparing `{signal}`: the signal was not logged"),
                "build the graph from a spec whose `compare:` names it",
            )
            .in_column(&column)
        })?;
        out.push(compare_signal(&signal, values, width, rate, data, &column)?);
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn columns_are_checked_and_named_in_errors() {
        let d = Dataset::from_columns(
            "x.csv",
            100.0,
            0.0,
            vec![("u".into(), vec![1.0, 2.0]), ("y".into(), vec![3.0, 4.0])],
        )
        .unwrap();
        assert_eq!(d.len(), 2);
        assert_eq!(d.column("y"), Some(&[3.0, 4.0][..]));
        let e = d.require("z").unwrap_err();
        assert!(e.to_string().contains("x.csv, column `z`"), "{e}");
        assert!(e.to_string().contains("u, y"), "{e}");
        let e = Dataset::from_columns("x.csv", 100.0, 0.0, vec![("u".into(), vec![1.0, f64::NAN])])
            .unwrap_err();
        assert!(e.to_string().contains("sample 1 is NaN"), "{e}");
        let e = Dataset::from_columns(
            "x.csv",
            100.0,
            0.0,
            vec![("u".into(), vec![1.0]), ("y".into(), vec![])],
        )
        .unwrap_err();
        assert_eq!(e.column.as_deref(), Some("y"));
        let s = d.slice(1..2);
        assert_eq!(s.column("u"), Some(&[2.0][..]));
        assert!((s.t0_s() - 0.01).abs() < 1e-15);
    }

    // ----------------------------------------------------------------- loaders

    /// A valid CSV text: `n` rows at `rate` Hz, columns u = k, y = sin(k).
    fn csv_text(n: usize, rate: f64) -> String {
        let mut s = String::from("# a comment\n# another\nt_s,u,y\n");
        for k in 0..n {
            s.push_str(&format!("{},{},{}\n", k as f64 / rate, k, (k as f64).sin()));
        }
        s
    }

    fn err_of(text: &str) -> DataError {
        Dataset::from_csv_str(text, "rec.csv").unwrap_err()
    }

    #[test]
    fn csv_loads_with_comments_and_exact_rate() {
        let d = Dataset::from_csv_str(&csv_text(20, 250.0), "rec.csv").unwrap();
        assert_eq!(d.rate_hz(), 250.0);
        assert_eq!(d.len(), 20);
        assert_eq!(d.names(), &["u".to_string(), "y".to_string()]);
        assert_eq!(d.column("u").unwrap()[19], 19.0);
        assert_eq!(d.column("y").unwrap()[3], 3f64.sin());
        assert_eq!(d.t0_s(), 0.0);
        assert!((d.duration_s() - 0.08).abs() < 1e-15);
        // `t` is accepted as well, with spaces and CRLF.
        let text = csv_text(16, 10.0)
            .replace("t_s,u,y", "t , u , y")
            .replace('\n', "\r\n");
        let d = Dataset::from_csv_str(&text, "rec.csv").unwrap();
        assert_eq!(d.rate_hz(), 10.0);
    }

    #[test]
    fn printed_times_give_the_rate_they_round() {
        // 750 Hz printed with 6 decimals (as the Bouc–Wen benchmark does): the rate is
        // exactly 750, not 750.00002.
        let mut s = String::from("t_s,u\n");
        for k in 0..1000 {
            s.push_str(&format!("{:.6},{}\n", k as f64 / 750.0, k % 7));
        }
        let d = Dataset::from_csv_str(&s, "bw.csv").unwrap();
        assert_eq!(d.rate_hz(), 750.0);
        // Printed with too few digits to resolve the period: an error, not a guess.
        let mut s = String::from("t_s,u\n");
        for k in 0..100 {
            s.push_str(&format!("{:.3},{}\n", k as f64 / 300.0, k % 7));
        }
        let e = err_of(&s);
        assert!(e.problem.contains("too few digits"), "{e}");
        // Exact short decimals (shortest round-trip printing) are taken at face value.
        let d = Dataset::from_csv_str(&csv_text(20, 250.0), "rec.csv").unwrap();
        assert_eq!(d.rate_hz(), 250.0);
    }

    #[test]
    fn csv_errors_name_row_column_and_fix() {
        let good = csv_text(20, 100.0);
        let lines: Vec<&str> = good.lines().collect();
        // Header is on line 3 (two comments), sample k on line 4 + k.
        let with_line = |k: usize, line: &str| {
            let mut l = lines.clone();
            l[k] = line;
            l.join("\n")
        };
        let e = err_of("");
        assert!(e.problem.contains("no header row"), "{e}");
        let e = err_of("# only comments\n");
        assert!(e.problem.contains("no header row"), "{e}");
        assert_eq!(e.row, Some(2));
        let e = err_of(&good.replace("t_s,u,y", "time,u,y"));
        assert_eq!((e.row, e.column.as_deref()), (Some(3), Some("time")));
        assert!(e.problem.contains("not the time `t` or `t_s`"), "{e}");
        assert!(e.fix.contains("t_s"), "{e}");
        let e = err_of(&good.replace("t_s,u,y\n", ""));
        assert!(e.problem.contains("first line holds numbers"), "{e}");
        let e = err_of(&good.replace("t_s,u,y", "t_s"));
        assert!(e.problem.contains("only the time"), "{e}");
        let e = err_of(&good.replace("t_s,u,y", "t_s,u,u"));
        assert_eq!(e.column.as_deref(), Some("u"));
        let e = err_of(&with_line(8, "0.05,5"));
        assert_eq!(e.row, Some(9));
        assert!(e.problem.contains("2 fields where the header has 3"), "{e}");
        let e = err_of(&with_line(8, "0.05,5,abc"));
        assert_eq!((e.row, e.column.as_deref()), (Some(9), Some("y")));
        assert!(e.problem.contains("`abc` is not a number"), "{e}");
        let e = err_of(&with_line(8, "0.05,5,"));
        assert!(e.problem.contains("empty"), "{e}");
        let e = err_of(&with_line(8, "0.05,NaN,1"));
        assert_eq!((e.row, e.column.as_deref()), (Some(9), Some("u")));
        assert!(e.problem.contains("NaN"), "{e}");
        let e = err_of(&with_line(8, "0.05,inf,1"));
        assert!(e.problem.contains("inf"), "{e}");
        let e = err_of(&with_line(8, "0.03,5,1"));
        assert_eq!((e.row, e.column.as_deref()), (Some(9), Some("t_s")));
        assert!(e.problem.contains("does not increase"), "{e}");
        // A missing sample: the step from row 9 to row 10 is twice the period.
        let mut l = lines.clone();
        l.remove(9);
        let e = err_of(&l.join("\n"));
        assert_eq!((e.row, e.column.as_deref()), (Some(10), Some("t_s")));
        assert!(e.problem.contains("not uniformly sampled"), "{e}");
        assert!(e.problem.contains("1e-6·Δt"), "{e}");
        // A jittered sample, 1e-5 of the period off (printed to 1e-7: too coarse to
        // explain it as rounding).
        let e = err_of(&with_line(8, "0.0400001,4,1"));
        assert!(e.problem.contains("not uniformly sampled"), "{e}");
        assert_eq!(e.row, Some(9));
        let e = err_of(&csv_text(15, 100.0));
        assert!(
            e.problem
                .contains("15 samples, fewer than the minimum of 16"),
            "{e}"
        );
        // Rendered message carries everything.
        let e = err_of(&with_line(8, "0.05,NaN,1")).to_string();
        assert!(e.starts_with("rec.csv, row 9, column `u`: "), "{e}");
        assert!(e.contains("(fix: "), "{e}");
    }

    #[test]
    fn unreadable_and_oversized_files_are_errors() {
        let e = Dataset::from_csv_file("/no/such/file.csv").unwrap_err();
        assert!(
            e.to_string()
                .contains("/no/such/file.csv: cannot be opened"),
            "{e}"
        );
        let e = Dataset::from_file("/tmp").unwrap_err();
        assert!(e.problem.contains("cannot be read"), "{e}");
        // An endless stream stops at the cap (a small cap here; MAX_FILE_BYTES for real).
        let e = read_capped(std::path::Path::new("/dev/zero"), 1 << 20).unwrap_err();
        assert!(e.problem.contains("larger than the cap of 1 MiB"), "{e}");
        assert_eq!(MAX_FILE_BYTES, 512 << 20);
    }

    /// `../shared/data/boucwen_benchmark`, or `None` after a loud skip; with `CI`
    /// set a missing folder fails the test.
    fn boucwen() -> Option<std::path::PathBuf> {
        let p = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("../../shared/data/boucwen_benchmark");
        shared_data_or_skip(&p, "data::tests (Bou-Wen benchmark)")
    }

    #[test]
    fn boucwen_csv_loads_at_750_hz() {
        let Some(dir) = boucwen() else { return };
        let d = Dataset::from_file(dir.join("bw_val_multisine.csv")).unwrap();
        assert_eq!(d.rate_hz(), 750.0);
        assert_eq!(d.len(), 8192);
        assert_eq!(d.names(), &["u_force_N", "y_disp_m"]);
        assert_eq!(d.column("u_force_N").unwrap()[0], -10.8634531806735);
        assert_eq!(d.column("y_disp_m").unwrap()[1], 0.000570313028664923);
    }

    #[cfg(feature = "mat")]
    #[test]
    fn boucwen_mat_loads_and_matches_the_csv() {
        let Some(dir) = boucwen() else { return };
        let u = dir.join("uval_multisine.mat");
        let e = Dataset::from_file(&u).unwrap_err();
        assert!(e.problem.contains("sample rate is unknown"), "{e}");
        assert!(e.fix.contains("--data-rate"), "{e}");
        let du = Dataset::from_file_with_rate(&u, Some(750.0)).unwrap();
        let dy =
            Dataset::from_mat_file_with_rate(dir.join("yval_multisine.mat"), Some(750.0)).unwrap();
        assert_eq!(du.names(), &["uval_multisine"]);
        assert_eq!(du.len(), 8192);
        let both = du.merge(dy).unwrap();
        assert_eq!(both.names(), &["uval_multisine", "yval_multisine"]);
        let csv = Dataset::from_file(dir.join("bw_val_multisine.csv")).unwrap();
        for (m, c) in [
            ("uval_multisine", "u_force_N"),
            ("yval_multisine", "y_disp_m"),
        ] {
            let (a, b) = (both.column(m).unwrap(), csv.column(c).unwrap());
            let scale = b.iter().fold(0.0f64, |s, v| s.max(v.abs()));
            let worst = a
                .iter()
                .zip(b)
                .fold(0.0f64, |s, (x, y)| s.max((x - y).abs()));
            assert!(worst <= 1e-12 * scale, "{m} vs {c}: {worst:e}");
        }
        // Damaged copies are errors, never panics.
        let bytes = std::fs::read(&u).unwrap();
        for cut in [0, 100, 128, 200, 1000, bytes.len() - 1] {
            assert!(Dataset::from_mat_bytes(&bytes[..cut], "cut.mat", Some(750.0)).is_err());
        }
    }

    #[cfg(feature = "mat")]
    #[test]
    fn mat_v73_and_foreign_files_are_refused_with_the_reason() {
        let mut v73 = b"MATLAB 7.3 MAT-file, Platform: GLNXA64, HDF5 schema 1.00".to_vec();
        v73.resize(600, b' ');
        let e = Dataset::from_mat_bytes(&v73, "x.mat", None).unwrap_err();
        assert!(e.problem.contains("v7.3 (HDF5)"), "{e}");
        let e = Dataset::from_mat_bytes(b"hello", "x.mat", None).unwrap_err();
        assert!(e.problem.contains("not a MATLAB v5"), "{e}");
    }

    // ----------------------------------------------------------------- compare

    fn dataset(measured: Vec<f64>) -> Dataset {
        let n = measured.len();
        Dataset::from_columns(
            "rec.csv",
            100.0,
            0.0,
            vec![("u".into(), vec![0.0; n]), ("y".into(), measured)],
        )
        .unwrap()
    }

    /// Audit D10 and D11: an int32 vector made a valid v5 file unreadable, and a
    /// file cut by one byte lost its last variable silently.
    #[cfg(feature = "mat")]
    #[test]
    fn mat_int32_columns_load_and_cut_files_name_the_variable() {
        use crate::mat5::tests::mat_file;
        let n = 40;
        let t: Vec<f64> = (0..n).map(|k| k as f64 / 1000.0).collect();
        let u: Vec<f64> = (0..n).map(|k| (k as f64 * 37.0) % 501.0 - 250.0).collect();
        let y: Vec<f64> = (0..n).map(|k| (k as f64 * 0.1).sin()).collect();
        for compress in [false, true] {
            let bytes = mat_file(
                &[
                    ("t_s", 6, t.clone()),
                    ("u_force_N", 12, u.clone()),
                    ("y_pos_m", 6, y.clone()),
                ],
                compress,
            );
            let d = Dataset::from_mat_bytes(&bytes, "int32_col.mat", None).unwrap();
            assert_eq!(d.column("u_force_N").unwrap(), &u[..]);
            assert_eq!(d.rate_hz(), 1000.0);
            // An int32 time vector in ms would be refused for its rate only; in
            // whole seconds at 1 Hz it is read.
            let secs: Vec<f64> = (0..n).map(|k| k as f64).collect();
            let b = mat_file(&[("t", 12, secs), ("y", 6, y.clone())], compress);
            assert_eq!(
                Dataset::from_mat_bytes(&b, "t32.mat", None)
                    .unwrap()
                    .rate_hz(),
                1.0
            );
            let four = mat_file(
                &[
                    ("t_s", 6, t.clone()),
                    ("u_force_N", 6, u.clone()),
                    ("y_pos_m", 6, y.clone()),
                    ("zz_extra", 6, y.clone()),
                ],
                compress,
            );
            let e = Dataset::from_mat_bytes(&four[..four.len() - 1], "trunc_one_byte.mat", None)
                .unwrap_err();
            assert!(
                e.problem.contains("cut off") && e.problem.contains("`zz_extra`"),
                "{e}"
            );
            assert!(e.problem.contains("after `y_pos_m`"), "{e}");
        }
    }

    #[test]
    fn scores_match_closed_forms() {
        let y: Vec<f64> = (0..32).map(|k| (k as f64 * 0.3).sin() + 2.0).collect();
        let d = dataset(y.clone());
        let c = compare_signal("m.y", &y, 1, 100.0, &d, "y").unwrap();
        assert_eq!(
            (c.rms, c.max_abs, c.mean, c.fit_percent),
            (0.0, 0.0, 0.0, 100.0)
        );
        assert_eq!(c.samples, 32);
        // Model = mean of the measurement: fit 0 %, rms = standard deviation.
        let mean = y.iter().sum::<f64>() / 32.0;
        let sd = (y.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / 32.0).sqrt();
        let c = compare_signal("m.y", &[mean; 32], 1, 100.0, &d, "y").unwrap();
        assert!(c.fit_percent.abs() < 1e-12, "{}", c.fit_percent);
        assert!((c.rms - sd).abs() < 1e-15);
        // Offset by 0.5: residual 0.5 everywhere.
        let off: Vec<f64> = y.iter().map(|v| v - 0.5).collect();
        let c = compare_signal("m.y", &off, 1, 100.0, &d, "y").unwrap();
        assert!((c.rms - 0.5).abs() < 1e-15 && (c.mean - 0.5).abs() < 1e-15);
        assert!((c.max_abs - 0.5).abs() < 1e-15);
        assert!((c.fit_percent - 100.0 * (1.0 - 0.5 / sd)).abs() < 1e-9);
        assert_eq!(c.residual[7], y[7] - off[7]);
        // Model at 3× the data rate: every third sample is compared.
        let fast: Vec<f64> = y.iter().flat_map(|&v| [v, 9.0, 9.0]).collect();
        let c = compare_signal("m.y", &fast, 1, 300.0, &d, "y").unwrap();
        assert_eq!((c.model_decimation, c.rms, c.samples), (3, 0.0, 32));
        assert_eq!(c.times()[2], 0.02);
    }

    #[test]
    fn compare_errors_are_typed() {
        let y: Vec<f64> = (0..32).map(|k| k as f64).collect();
        let d = dataset(y.clone());
        let e = compare_signal("m.y", &y, 1, 150.0, &d, "y").unwrap_err();
        assert!(e.problem.contains("not an integer multiple"), "{e}");
        let e = compare_signal("m.y", &y, 1, 50.0, &d, "y").unwrap_err();
        assert!(e.problem.contains("not an integer multiple"), "{e}");
        let e = compare_signal("m.y", &y, 2, 100.0, &d, "y").unwrap_err();
        assert!(e.problem.contains("2 values per sample"), "{e}");
        let e = compare_signal("m.y", &y, 1, 100.0, &d, "z").unwrap_err();
        assert!(e.problem.contains("its columns are: u, y"), "{e}");
        let e = compare_signal("m.y", &y, 1, 100.0, &d, "u").unwrap_err();
        assert!(e.problem.contains("constant"), "{e}");
        let e = compare_signal("m.y", &y[..10], 1, 100.0, &d, "y").unwrap_err();
        assert!(e.problem.contains("only 10 samples overlap"), "{e}");
    }

    /// Audit D1: a stuck sensor (a constant column whose mean is not exactly its
    /// value after rounding) gave a fit of −5.6e17 % instead of the documented error.
    #[test]
    fn a_constant_measured_column_is_refused_whatever_its_rounding() {
        let n = 6000;
        let d = Dataset::from_columns("const.csv", 1000.0, 0.0, vec![("y".into(), vec![1e-6; n])])
            .unwrap();
        let model: Vec<f64> = (0..n).map(|k| 1e-4 * (k as f64 * 0.01).sin()).collect();
        let e = compare_signal("stage.y", &model, 1, 1000.0, &d, "y").unwrap_err();
        assert!(e.problem.contains("constant (1e-6)"), "{e}");
        assert_eq!(e.column.as_deref(), Some("y"));
        assert_eq!(constant_column(&[2.0, 2.0 + 1e-9]), None);
        assert_eq!(constant_column(&[0.0; 3]), Some(0.0));
    }

    /// Audit D18: finite but huge values made the scores ±inf with a result.
    #[test]
    fn scores_that_overflow_are_refused() {
        let y: Vec<f64> = (0..32).map(|k| (k as f64 * 0.3).sin()).collect();
        let d = dataset(y.clone());
        let mut model = y.clone();
        model[5] = 3.6e303;
        let e = compare_signal("m.y", &model, 1, 100.0, &d, "y").unwrap_err();
        assert!(
            e.problem.contains("overflow") && e.problem.contains("3.6e303"),
            "{e}"
        );
        assert!(e.fix.contains("corrupt sample"), "{e}");
    }

    proptest::proptest! {
        /// Whatever finite columns are compared, a comparison is either refused
        /// or has finite scores, with fit % ≤ 100 and rms ≤ max |residual|.
        #[test]
        fn comparisons_are_finite_or_refused(
            y in proptest::collection::vec(-1.0f64..1.0, 16..64),
            scale in -300i32..=308,
        ) {
            let s = 10f64.powi(scale);
            let y: Vec<f64> = y.iter().map(|v| v * s).collect();
            let model: Vec<f64> = y.iter().rev().copied().collect();
            let d = dataset(y);
            if let Ok(c) = compare_signal("m.y", &model, 1, 100.0, &d, "y") {
                proptest::prop_assert!(c.rms.is_finite() && c.fit_percent.is_finite());
                proptest::prop_assert!(c.fit_percent <= 100.0);
                proptest::prop_assert!(c.rms <= c.max_abs * (1.0 + 1e-12));
            }
        }
    }

    #[test]
    fn graph_plays_data_and_compares() {
        use crate::graph::GraphSpec;
        let y: Vec<f64> = (0..40).map(|k| (k as f64 * 0.2).cos()).collect();
        let d = std::sync::Arc::new(
            Dataset::from_columns("rec.csv", 100.0, 0.0, vec![("pos".into(), y.clone())]).unwrap(),
        );
        let yaml = "base_rate_hz: 200\nduration_s: 0.4\nblocks:\n  - { name: u, type: data_column, column: pos, rate_hz: 100 }\n  - { name: g, type: gain, k: 0.5 }\nconnections:\n  - { from: u.y, to: g.u }\ncompare:\n  - { signal: u.y, column: pos }\n  - { signal: g.y, column: pos }\n";
        let spec = GraphSpec::from_yaml(yaml, "g.yaml").unwrap();
        let (mut sched, _) = spec.build_with_data(d.clone()).unwrap();
        sched.run(|_| {});
        let c = compare(&sched, &d).unwrap();
        assert_eq!(c[0].fit_percent, 100.0);
        assert_eq!(c[0].samples, 40);
        let half: Vec<f64> = y.iter().map(|v| 0.5 * v).collect();
        let want = compare_signal("g.y", &half, 1, 100.0, &d, "pos").unwrap();
        assert_eq!(c[1].rms, want.rms);
        // Longer than the data: refused, naming both durations.
        let spec = GraphSpec::from_yaml(&yaml.replace("0.4", "0.5"), "g.yaml").unwrap();
        let e = spec.build_with_data(d.clone()).unwrap_err().to_string();
        assert!(
            e.contains("lasts 0.5 s") && e.contains("lasts only 0.4 s"),
            "{e}"
        );
        // No data: the block says how to give it.
        let spec = GraphSpec::from_yaml(yaml, "g.yaml").unwrap();
        let e = spec.build().unwrap_err().to_string();
        assert!(e.contains("--data FILE"), "{e}");
    }

    // ----------------------------------------------------------------- properties

    mod props {
        use super::super::*;
        use proptest::prelude::*;

        proptest! {
            #![proptest_config(ProptestConfig::with_cases(256))]

            #[test]
            fn arbitrary_text_never_panics(text in "\\PC{0,400}") {
                let _ = Dataset::from_csv_str(&text, "p.csv");
            }

            #[test]
            fn arbitrary_bytes_never_panic(bytes in proptest::collection::vec(any::<u8>(), 0..600)) {
                let _ = Dataset::from_csv_bytes(&bytes, "p.csv");
                #[cfg(feature = "mat")]
                {
                    let mut b = b"MATLAB 5.0 MAT-file".to_vec();
                    b.extend_from_slice(&bytes);
                    let _ = Dataset::from_mat_bytes(&b, "p.mat", Some(1.0));
                }
            }

            #[test]
            fn valid_files_round_trip_exactly(
                rate in prop_oneof![1u32..100_000u32].prop_map(f64::from),
                t0 in prop_oneof![Just(0.0), -10.0..10.0f64],
                n in 16usize..80,
                ncol in 1usize..4,
                seed in any::<u64>(),
            ) {
                let mut rng = crate::rng::Rng::new(seed);
                let cols: Vec<(String, Vec<f64>)> = (0..ncol)
                    .map(|j| (format!("c{j}"), (0..n).map(|_| rng.normal() * 10f64.powi((j as i32) * 3 - 6)).collect()))
                    .collect();
                let d = Dataset::from_columns("p.csv", rate, t0, cols).unwrap();
                let text = d.to_csv_string();
                let back = Dataset::from_csv_str(&text, "p.csv").unwrap();
                prop_assert_eq!(back.rate_hz(), rate);
                prop_assert_eq!(back.t0_s(), t0);
                prop_assert_eq!(back.names(), d.names());
                for name in d.names() {
                    prop_assert_eq!(back.column(name), d.column(name));
                }
            }

            #[test]
            fn mutated_files_never_panic(
                seed in any::<u64>(),
                edits in proptest::collection::vec((any::<prop::sample::Index>(), any::<u8>()), 1..6),
            ) {
                let mut rng = crate::rng::Rng::new(seed);
                let cols = vec![("u".to_string(), (0..20).map(|_| rng.normal()).collect())];
                let text = Dataset::from_columns("p.csv", 1000.0, 0.0, cols).unwrap().to_csv_string();
                let mut bytes = text.into_bytes();
                for (at, b) in edits {
                    let i = at.index(bytes.len());
                    match b % 3 {
                        0 => bytes[i] = b"0123456789.,-e\nNa#t "[b as usize % 20],
                        1 => { bytes.remove(i); }
                        _ => bytes.insert(i, b"0123456789.,-e\nNa#t "[b as usize % 20]),
                    }
                }
                match Dataset::from_csv_bytes(&bytes, "p.csv") {
                    Ok(d) => prop_assert!(d.len() >= MIN_SAMPLES && d.rate_hz() > 0.0),
                    Err(e) => prop_assert!(!e.problem.is_empty() && !e.fix.is_empty()),
                }
            }
        }
    }
}
