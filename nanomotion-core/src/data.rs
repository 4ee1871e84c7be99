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
}
