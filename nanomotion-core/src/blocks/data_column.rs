//! `data_column`: plays one column of the measured data attached to the graph
//! (`nanomotion run --data FILE`, [`GraphSpec::build_with_data`]) sample by sample.
//!
//! Sample k of the column is the output at the block's own tick k (t_k = k / rate;
//! the data's own start time is not used). After the end of the data the block holds
//! the last sample; [`GraphSpec::build_with_data`] refuses a graph that runs longer
//! than the data, so this happens only when the block runs slower than the base rate
//! would need.
//!
//! The block's rate (`rate_hz:`, default the base rate) must equal the data's rate to
//! 1e-9 relative: the block never resamples.
//!
//! [`GraphSpec::build_with_data`]: crate::graph::GraphSpec::build_with_data

use crate::{Block, BuildContext, ParamError, Params, Tick, declared_block};
use serde::{Deserialize, Serialize};

/// Relative tolerance between the block's rate and the data's rate.
pub const RATE_REL_TOL: f64 = 1e-9;

/// `data_column`: plays one column of the measured data (`--data FILE`) at its own
/// rate: output `y` = sample k of column `column` at tick k; holds the last sample
/// after the end.
#[derive(Debug, Clone, Serialize, Deserialize, Params)]
#[serde(deny_unknown_fields)]
#[block(type_name = "data_column", role = Source, ports = "-> y")]
pub struct DataColumn {
    /// Name of the measured column to play (CSV header / .mat variable).
    #[serde(deserialize_with = "column_name")]
    #[param(schema = "column_schema")]
    pub column: String,
    /// The column's samples, copied from the data at build.
    #[serde(skip)]
    values: Vec<f64>,
}

impl DataColumn {
    /// A block playing `column`.
    pub fn new(column: impl Into<String>) -> Self {
        Self {
            column: column.into(),
            values: Vec::new(),
        }
    }
    /// The samples copied at build (empty before).
    pub fn values(&self) -> &[f64] {
        &self.values
    }
}

/// The schema of `column`: a string (what [`column_name`] reads).
fn column_schema() -> serde_json::Value {
    serde_json::json!({ "type": "string" })
}

/// A column name; the message for a value YAML reads as a boolean or a number
/// (`true`, `1` unquoted) says to quote it. (`y`, `n`, `on`, `off` are text in a
/// graph file: YAML 1.2 booleans, `crate::yaml::from_str`.)
fn column_name<'de, D: serde::Deserializer<'de>>(d: D) -> Result<String, D::Error> {
    struct V;
    impl serde::de::Visitor<'_> for V {
        type Value = String;
        fn expecting(&self, f: &mut std::fmt::Formatter) -> std::fmt::Result {
            f.write_str("a column name (quote names that YAML reads as booleans or numbers, e.g. column: \"true\")")
        }
        fn visit_str<E: serde::de::Error>(self, v: &str) -> Result<String, E> {
            Ok(v.to_string())
        }
    }
    d.deserialize_str(V)
}

#[declared_block]
impl Block for DataColumn {
    fn build(&mut self, ctx: &BuildContext) -> Result<(), ParamError> {
        let Some(data) = &ctx.data else {
            if ctx.placeholder_data {
                // Checking without data: a placeholder 0 (the rate and column are
                // checked when the data are given).
                self.values = vec![0.0];
                return Ok(());
            }
            return Err(ParamError::new(
                "column",
                format!(
                    "plays measured column `{}`, but no data is attached to the graph",
                    self.column
                ),
                "run with --data FILE, `nanomotion check` with or without --data (or build with GraphSpec::build_with_data / build_without_data)",
            ));
        };
        let values = data.column(&self.column).ok_or_else(|| {
            ParamError::new(
                "column",
                format!(
                    "`{}` is not a column of {}; its columns are: {}",
                    self.column,
                    data.origin(),
                    data.names().join(", ")
                ),
                "name one of the columns above",
            )
        })?;
        let block_rate = 1.0 / ctx.dt;
        let data_rate = data.rate_hz();
        if (block_rate - data_rate).abs() > RATE_REL_TOL * data_rate {
            return Err(ParamError::new(
                "rate_hz",
                format!(
                    "the block runs at {block_rate} Hz but {} is sampled at {data_rate} Hz",
                    data.origin()
                ),
                format!(
                    "set `rate_hz: {data_rate}` on this block (the base rate must be a multiple of it), or resample the data"
                ),
            ));
        }
        self.values.clear();
        self.values.extend_from_slice(values);
        Ok(())
    }
    fn output(&mut self, tick: Tick, _u: &[f64], y: &mut [f64]) {
        let last = self.values.len().saturating_sub(1);
        let k = usize::try_from(tick.k).unwrap_or(usize::MAX).min(last);
        y[0] = self.values.get(k).copied().unwrap_or(0.0);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::data::Dataset;
    use std::sync::Arc;

    fn data() -> Arc<Dataset> {
        Arc::new(
            Dataset::from_columns(
                "rec.csv",
                100.0,
                0.0,
                vec![
                    ("u".into(), vec![1.0, 2.0, 3.0]),
                    ("y".into(), vec![0.0; 3]),
                ],
            )
            .unwrap(),
        )
    }

    #[test]
    fn plays_the_column_and_holds_the_last_sample() {
        let mut b = DataColumn::new("u");
        b.build(&BuildContext::new("src", 0.01, 0).with_data(Some(data())))
            .unwrap();
        let mut y = [0.0];
        let got: Vec<f64> = (0..5)
            .map(|k| {
                b.output(Tick::new(k, 0.01), &[], &mut y);
                y[0]
            })
            .collect();
        assert_eq!(got, vec![1.0, 2.0, 3.0, 3.0, 3.0]);
    }

    /// A name YAML 1.2 reads as a boolean (`true`) gets the hint to quote it;
    /// `y` (a boolean to YAML 1.1 only) is the column `y`, as an editor reads it.
    #[test]
    fn unquoted_boolean_names_get_a_hint() {
        let yaml = "base_rate_hz: 100\nduration_s: 0.01\nblocks:\n  - { name: s, type: data_column, column: true }\n";
        let e = crate::GraphSpec::from_yaml(yaml, "g.yaml")
            .unwrap_err()
            .to_string();
        assert!(e.contains("column: \"true\""), "{e}");
        let spec = crate::GraphSpec::from_yaml(
            &yaml.replace("column: true", "column: \"true\""),
            "g.yaml",
        );
        assert!(spec.is_ok());
        for name in ["y", "n", "on", "off"] {
            let text = yaml.replace("column: true", &format!("column: {name}"));
            let spec = crate::GraphSpec::from_yaml(&text, "g.yaml").unwrap();
            let block = serde_json::to_value(&spec.blocks[0].block).unwrap();
            assert_eq!(block["column"], name, "{block}");
        }
    }

    #[test]
    fn errors_name_the_fix() {
        let mut b = DataColumn::new("u");
        let e = b.build(&BuildContext::new("src", 0.01, 0)).unwrap_err();
        assert!(e.fix.contains("--data FILE"), "{e}");
        let mut b = DataColumn::new("x");
        let e = b
            .build(&BuildContext::new("src", 0.01, 0).with_data(Some(data())))
            .unwrap_err();
        assert!(e.problem.contains("its columns are: u, y"), "{e}");
        let mut b = DataColumn::new("u");
        let e = b
            .build(&BuildContext::new("src", 0.001, 0).with_data(Some(data())))
            .unwrap_err();
        assert_eq!(e.field, "rate_hz");
        assert!(
            e.problem.contains("1000 Hz") && e.problem.contains("100 Hz"),
            "{e}"
        );
        assert!(e.fix.contains("rate_hz: 100"), "{e}");
    }
}
