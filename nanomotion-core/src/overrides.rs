//! Parameter overrides by dotted path, applied to a graph before it is built:
//! `blocks.pi.kp=2.0`, `duration_s=0.5`, `seed=3`, `blocks.stage.den.0=0.3`.
//!
//! A path walks the graph as YAML writes it, with every field the loader knows
//! (defaults included, so `blocks.pi.output_min` can be set even when the file
//! leaves it out):
//! - a map key by name (`duration_s`, `kp`);
//! - a list entry by index, `.N` or `[N]` (`connections.0.from`, `den[2]`);
//! - a block in `blocks:` by its `name:` (`blocks.pi`), so a path does not move
//!   when blocks are reordered.
//!
//! The value is YAML (`2.0`, `true`, `[1, 2]`, `{ a: 1 }`); it must have the type
//! of the value it replaces (a number for a number, an integer for an integer
//! field such as `seed`, a list for a list). A path that does not exist, a type
//! that does not match or a value the block then rejects is a
//! [`GraphError::Override`] naming the path, the nearest existing key and the fix.
//!
//! ```
//! use nanomotion_core::graph::GraphSpec;
//! use nanomotion_core::overrides::Override;
//! # use nanomotion_core::{Block, Port, Tick};
//! # #[derive(Debug, serde::Serialize, serde::Deserialize)]
//! # struct C { value: f64 }
//! # #[typetag::serde(name = "overrides_doc_const")]
//! # impl Block for C {
//! #     fn outputs(&self) -> Vec<Port> { vec![Port::new("y", 1)] }
//! #     fn output(&mut self, _t: Tick, _u: &[f64], y: &mut [f64]) { y[0] = self.value; }
//! # }
//! let yaml = "base_rate_hz: 1000\nduration_s: 0.01\nblocks:\n  - { name: src, type: overrides_doc_const, value: 2.0 }\nlog: [src.y]\n";
//! let set = [Override::parse("blocks.src.value=5").unwrap(), Override::parse("duration_s=0.002").unwrap()];
//! let spec = GraphSpec::from_yaml_with_overrides(yaml, "doc.yaml", &set).unwrap();
//! let (mut sched, _) = spec.build().unwrap();
//! assert_eq!(sched.run(|_| {}).logs[0].data, vec![5.0, 5.0]);
//!
//! let bad = [Override::parse("blocks.src.valeu=5").unwrap()];
//! let e = GraphSpec::from_yaml_with_overrides(yaml, "doc.yaml", &bad).unwrap_err();
//! assert!(e.to_string().contains("did you mean `blocks.src.value`"));
//! ```

use crate::error::GraphError;
use crate::graph::GraphSpec;
use serde::{Deserialize, Serialize};
use serde_json::Value;
use std::fmt;

/// One step of an override path.
#[derive(Debug, Clone, PartialEq, Eq, Hash)]
pub enum Segment {
    /// A map key, or the `name:` of an entry of a list of named maps (`blocks`).
    Key(String),
    /// A list index (0-based).
    Index(usize),
}

/// A parsed dotted path (`blocks.pi.kp`, `blocks.stage.den[0]`).
#[derive(Debug, Clone, PartialEq, Eq, Hash)]
pub struct Path(pub Vec<Segment>);

impl Path {
    /// Parse `a.b.0.c[1]`. Keys are non-empty and hold no `.`, `[`, `]`, `=` or
    /// white space; a key of digits only is an index.
    pub fn parse(text: &str) -> Result<Self, GraphError> {
        let bad = |problem: String| {
            GraphError::Override {
            path: text.to_string(),
            problem,
            fix: "write the path as keys and indices separated by dots, e.g. `blocks.pi.kp`, `duration_s` or `blocks.stage.den.0` (or `den[0]`)".into(),
        }
        };
        if text.is_empty() {
            return Err(bad("is empty".into()));
        }
        let mut out = Vec::new();
        for part in text.split('.') {
            // `key[1][2]`: the key, then indices.
            let (key, mut rest) = match part.find('[') {
                Some(i) => (&part[..i], &part[i..]),
                None => (part, ""),
            };
            if key.is_empty() && rest.is_empty() {
                return Err(bad(
                    "has an empty key (two dots in a row, or a dot at an end)".into(),
                ));
            }
            if let Some(c) = key
                .chars()
                .find(|c| matches!(c, ']' | '=' | '[') || c.is_whitespace() || c.is_control())
            {
                return Err(bad(format!("key `{key}` contains `{}`", c.escape_debug())));
            }
            if out.is_empty() && key.bytes().all(|b| b.is_ascii_digit()) && !key.is_empty() {
                return Err(bad("starts with an index; it must start with a key".into()));
            }
            if !key.is_empty() {
                out.push(segment_of(key));
            } else if out.is_empty() {
                return Err(bad("starts with an index; it must start with a key".into()));
            }
            while !rest.is_empty() {
                let Some(end) = rest.find(']') else {
                    return Err(bad(format!("`{part}` has a `[` without `]`")));
                };
                let idx = &rest[1..end];
                let Ok(i) = idx.parse::<usize>() else {
                    return Err(bad(format!("`[{idx}]` is not a list index (0, 1, 2, ...)")));
                };
                out.push(Segment::Index(i));
                rest = &rest[end + 1..];
                if !rest.is_empty() && !rest.starts_with('[') {
                    return Err(bad(format!("`{part}` has text after `]`")));
                }
            }
        }
        Ok(Path(out))
    }
}

fn segment_of(key: &str) -> Segment {
    if key.bytes().all(|b| b.is_ascii_digit())
        && let Ok(i) = key.parse::<usize>()
    {
        return Segment::Index(i);
    }
    Segment::Key(key.to_string())
}

impl fmt::Display for Path {
    /// The canonical form: keys and indices separated by dots (`blocks.stage.den.0`).
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        for (i, s) in self.0.iter().enumerate() {
            if i > 0 {
                f.write_str(".")?;
            }
            match s {
                Segment::Key(k) => f.write_str(k)?,
                Segment::Index(n) => write!(f, "{n}")?,
            }
        }
        Ok(())
    }
}

/// A parameter override: a dotted path and the value to put there.
///
/// Serialises as `{ "path": "blocks.pi.kp", "value": 2.0 }`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(try_from = "OverrideRepr", into = "OverrideRepr")]
pub struct Override {
    /// The path as written.
    pub path: String,
    /// The parsed path.
    pub segments: Path,
    /// The new value.
    pub value: Value,
}

#[derive(Serialize, Deserialize)]
struct OverrideRepr {
    path: String,
    value: Value,
}

impl TryFrom<OverrideRepr> for Override {
    type Error = GraphError;
    fn try_from(r: OverrideRepr) -> Result<Self, GraphError> {
        Override::new(&r.path, r.value)
    }
}

impl From<Override> for OverrideRepr {
    fn from(o: Override) -> Self {
        OverrideRepr {
            path: o.path,
            value: o.value,
        }
    }
}

impl Override {
    /// An override of `path` by `value` (already a value, e.g. from a sweep plan).
    pub fn new(path: &str, value: impl Into<Value>) -> Result<Self, GraphError> {
        let value = value.into();
        if value.is_null() {
            return Err(GraphError::Override {
                path: path.into(),
                problem: "the value is null (or a non-finite number, which JSON cannot hold)"
                    .into(),
                fix: "give a finite number, a string, a boolean, a list or a map".into(),
            });
        }
        Ok(Override {
            segments: Path::parse(path)?,
            path: path.to_string(),
            value,
        })
    }

    /// Parse `PATH=VALUE` (the form of `nanomotion run --set`); VALUE is YAML
    /// (`2.0`, `true`, `[1.0, 2.0]`, `text`).
    pub fn parse(text: &str) -> Result<Self, GraphError> {
        let Some((path, value)) = text.split_once('=') else {
            return Err(GraphError::Override {
                path: text.into(),
                problem: "has no `=`".into(),
                fix: "write PATH=VALUE, e.g. `blocks.pi.kp=2.0` or `duration_s=0.5`".into(),
            });
        };
        Self::parse_value(path.trim(), value.trim())
    }

    /// An override of `path` by `value`, the value written as YAML text.
    pub fn parse_value(path: &str, value: &str) -> Result<Self, GraphError> {
        let bad = |problem: String| {
            GraphError::Override {
            path: path.into(),
            problem,
            fix: "give the value as YAML: a number (`2.0`, `1e-3`), `true`/`false`, a string, a list `[1, 2]` or a map `{ a: 1 }`".into(),
        }
        };
        if value.is_empty() {
            return Err(bad("has no value after `=`".into()));
        }
        let lower = value.to_ascii_lowercase();
        if [".nan", ".inf", "+.inf", "-.inf"].contains(&lower.as_str()) {
            return Err(bad(format!("`{value}` is not a finite number")));
        }
        let parsed: Value = crate::yaml::from_str(value, "override value")
            .map_err(|e| bad(format!("`{value}` is not a YAML value: {e}")))?;
        Self::new(path, parsed)
    }
}

impl std::str::FromStr for Override {
    type Err = GraphError;
    fn from_str(s: &str) -> Result<Self, GraphError> {
        Override::parse(s)
    }
}

impl fmt::Display for Override {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}={}", self.path, self.value)
    }
}

impl GraphSpec {
    /// [`GraphSpec::from_yaml`], then [`apply_overrides`].
    pub fn from_yaml_with_overrides(
        text: &str,
        origin: &str,
        overrides: &[Override],
    ) -> Result<Self, GraphError> {
        apply_overrides(Self::from_yaml(text, origin)?, overrides)
    }

    /// [`GraphSpec::from_file`], then [`apply_overrides`].
    pub fn from_file_with_overrides(
        path: impl AsRef<std::path::Path>,
        overrides: &[Override],
    ) -> Result<Self, GraphError> {
        apply_overrides(Self::from_file(path)?, overrides)
    }

    /// [`apply_overrides`] as a method.
    pub fn with_overrides(self, overrides: &[Override]) -> Result<Self, GraphError> {
        apply_overrides(self, overrides)
    }
}

/// Apply `overrides` in order to a loaded graph (not yet built). The graph is
/// serialised (with every default), each value put at its path, and the result
/// read back, so a value goes through the same deserialisation as the file's.
pub fn apply_overrides(spec: GraphSpec, overrides: &[Override]) -> Result<GraphSpec, GraphError> {
    if overrides.is_empty() {
        return Ok(spec);
    }
    let first = &overrides[0];
    let mut tree = serde_json::to_value(&spec).map_err(|e| GraphError::Override {
        path: first.path.clone(),
        problem: format!("the graph cannot be represented for overriding: {e}"),
        fix: "remove non-finite numbers (`.nan`, `.inf`) from the graph file".into(),
    })?;
    let mut inserted = Vec::new();
    for o in overrides {
        if apply_one(&mut tree, o)? {
            inserted.push(o);
        }
    }
    let mut out = match serde_json::from_value::<GraphSpec>(tree) {
        Ok(out) => out,
        Err(e) => return Err(culprit(&spec, overrides, e)),
    };
    // Keys that were absent (an optional field left out) must be fields the
    // loader knows: it keeps them when it writes the graph back.
    if !inserted.is_empty() {
        let back = serde_json::to_value(&out).unwrap_or(Value::Null);
        for o in inserted {
            if !lookup(&back, &o.segments.0).is_some_and(|v| same(v, &o.value)) {
                return Err(missing_key_error(&spec, o));
            }
        }
    }
    if out.connections.len() == spec.connections.len() {
        out.connection_lines = spec.connection_lines.clone();
    }
    out.base_dir = spec.base_dir.clone();
    Ok(out)
}

/// Which override makes the graph unreadable: the first that fails alone.
fn culprit(spec: &GraphSpec, overrides: &[Override], e: serde_json::Error) -> GraphError {
    let base = serde_json::to_value(spec).unwrap_or(Value::Null);
    for o in overrides {
        let mut t = base.clone();
        let Ok(inserted) = apply_one(&mut t, o) else {
            continue;
        };
        if let Err(e1) = serde_json::from_value::<GraphSpec>(t) {
            if inserted {
                return missing_key_error(spec, o);
            }
            return value_rejected(o, &e1.to_string());
        }
    }
    let paths: Vec<&str> = overrides.iter().map(|o| o.path.as_str()).collect();
    GraphError::Override {
        path: paths.join(", "),
        problem: format!("together these overrides make the graph unreadable: {e}"),
        fix: "check that the overridden values are consistent with each other".into(),
    }
}

fn value_rejected(o: &Override, message: &str) -> GraphError {
    if message.contains("unknown field") {
        return GraphError::Override {
            path: o.path.clone(),
            problem: format!("the graph does not accept it: {message}"),
            fix: "use a field the block has (`nanomotion blocks TYPE` lists them)".into(),
        };
    }
    GraphError::Override {
        path: o.path.clone(),
        problem: format!("the value {} is not accepted: {message}", o.value),
        fix:
            "give a value of the type the field expects (`nanomotion blocks TYPE` lists the fields)"
                .into(),
    }
}

/// Equal values, numbers compared as numbers (`20000` and `20000.0`).
fn same(a: &Value, b: &Value) -> bool {
    match (a, b) {
        (Value::Number(x), Value::Number(y)) => x.as_f64() == y.as_f64(),
        _ => a == b,
    }
}

fn lookup<'a>(mut v: &'a Value, path: &[Segment]) -> Option<&'a Value> {
    for s in path {
        v = match (v, s) {
            (Value::Object(m), Segment::Key(k)) => m.get(k)?,
            (Value::Array(a), Segment::Index(i)) => a.get(*i)?,
            (Value::Array(a), Segment::Key(k)) => a
                .iter()
                .find(|e| e.get("name").and_then(Value::as_str) == Some(k.as_str()))?,
            _ => return None,
        };
    }
    Some(v)
}

fn missing_key_error(spec: &GraphSpec, o: &Override) -> GraphError {
    let tree = serde_json::to_value(spec).unwrap_or(Value::Null);
    match apply_one(&mut tree.clone(), o) {
        Err(e) => e,
        Ok(_) => {
            // Find the map the last key was to go into and name its keys.
            let parent = &o.segments.0[..o.segments.0.len() - 1];
            let last = match o.segments.0.last() {
                Some(Segment::Key(k)) => k.as_str(),
                _ => "",
            };
            let keys: Vec<String> = lookup(&tree, parent)
                .and_then(Value::as_object)
                .map(|m| m.keys().cloned().collect())
                .unwrap_or_default();
            not_found(&o.path, &Path(parent.to_vec()), last, &keys)
        }
    }
}

fn not_found(full: &str, parent: &Path, key: &str, keys: &[String]) -> GraphError {
    let prefix = if parent.0.is_empty() {
        String::new()
    } else {
        format!("{parent}.")
    };
    let near = crate::graph::nearest(key, keys.iter().map(String::as_str));
    let fix = match near {
        Some(n) => format!(
            "did you mean `{prefix}{n}`? (keys here: {})",
            keys.join(", ")
        ),
        None => format!("use one of the keys here: {}", keys.join(", ")),
    };
    GraphError::Override {
        path: full.to_string(),
        problem: format!(
            "no key `{key}` {}",
            if parent.0.is_empty() {
                "at the top of the graph".to_string()
            } else {
                format!("in `{parent}`")
            }
        ),
        fix,
    }
}

/// Put `o.value` at `o.segments` in `tree`. Ok(true) when the last key was
/// absent and has been added (checked after reading the graph back).
fn apply_one(tree: &mut Value, o: &Override) -> Result<bool, GraphError> {
    let segs = &o.segments.0;
    let mut v = tree;
    for (n, s) in segs.iter().enumerate() {
        let here = Path(segs[..n].to_vec());
        let last = n + 1 == segs.len();
        let at = |problem: String, fix: String| GraphError::Override {
            path: o.path.clone(),
            problem,
            fix,
        };
        v = match (v, s) {
            (Value::Object(m), Segment::Key(k)) => {
                if !m.contains_key(k) {
                    if last {
                        // Perhaps an optional field left out: add it; read back
                        // and checked by the caller.
                        m.insert(k.clone(), o.value.clone());
                        return Ok(true);
                    }
                    let keys: Vec<String> = m.keys().cloned().collect();
                    return Err(not_found(&o.path, &here, k, &keys));
                }
                m.get_mut(k).expect("checked")
            }
            (Value::Object(_), Segment::Index(i)) => {
                return Err(at(
                    format!("`{here}` is a map, not a list, so it has no index {i}"),
                    "name a key of the map instead of an index".into(),
                ));
            }
            (Value::Array(a), Segment::Index(i)) => {
                let len = a.len();
                match a.get_mut(*i) {
                    Some(e) => e,
                    None => {
                        return Err(at(
                            format!("`{here}` has {len} entries, there is no index {i}"),
                            format!("use an index from 0 to {}", len.saturating_sub(1)),
                        ));
                    }
                }
            }
            (Value::Array(a), Segment::Key(k)) => {
                let names: Vec<String> = a
                    .iter()
                    .filter_map(|e| e.get("name").and_then(Value::as_str).map(String::from))
                    .collect();
                if names.is_empty() {
                    return Err(at(
                        format!("`{here}` is a list, and `{k}` is not an index"),
                        format!("use an index from 0 to {}", a.len().saturating_sub(1)),
                    ));
                }
                match a
                    .iter_mut()
                    .find(|e| e.get("name").and_then(Value::as_str) == Some(k.as_str()))
                {
                    Some(e) => e,
                    None => {
                        let near = crate::graph::nearest(k, names.iter().map(String::as_str));
                        return Err(at(
                            format!("no entry named `{k}` in `{here}`"),
                            match near {
                                Some(n) => format!(
                                    "did you mean `{here}.{n}`? (names here: {})",
                                    names.join(", ")
                                ),
                                None => format!("use one of the names: {}", names.join(", ")),
                            },
                        ));
                    }
                }
            }
            (other, _) => {
                return Err(at(
                    format!(
                        "`{here}` is {}, it has no `{}`",
                        kind(other),
                        Path(vec![s.clone()])
                    ),
                    format!("stop the path at `{here}`"),
                ));
            }
        };
    }
    *v = checked_value(v, o)?;
    Ok(false)
}

fn kind(v: &Value) -> &'static str {
    match v {
        Value::Null => "empty",
        Value::Bool(_) => "a boolean",
        Value::Number(n) if n.is_f64() => "a number",
        Value::Number(_) => "an integer",
        Value::String(_) => "a string",
        Value::Array(_) => "a list",
        Value::Object(_) => "a map",
    }
}

/// The new value if its type fits the old one.
fn checked_value(old: &Value, o: &Override) -> Result<Value, GraphError> {
    let new = &o.value;
    let mismatch = |fix: &str| GraphError::Override {
        path: o.path.clone(),
        problem: format!(
            "is {} ({old}) but the override gives {} ({new})",
            kind(old),
            kind(new)
        ),
        fix: fix.to_string(),
    };
    Ok(match (old, new) {
        (Value::Null, _) => new.clone(),
        (Value::Number(a), Value::Number(b)) => {
            if !a.is_f64() && b.is_f64() {
                let x = b.as_f64().unwrap_or(f64::NAN);
                if x.fract() == 0.0 && x.abs() < 9.0e15 {
                    if a.is_u64() && x >= 0.0 {
                        Value::from(x as u64)
                    } else {
                        Value::from(x as i64)
                    }
                } else {
                    return Err(mismatch("give a whole number"));
                }
            } else if a.is_u64() && !b.is_u64() {
                return Err(mismatch("give a non-negative whole number"));
            } else {
                new.clone()
            }
        }
        (Value::String(_), Value::String(_)) => new.clone(),
        (Value::String(_), Value::Number(n)) => Value::String(n.to_string()),
        (Value::String(_), Value::Bool(b)) => Value::String(b.to_string()),
        (Value::Bool(_), Value::Bool(_)) => new.clone(),
        (Value::Array(_), Value::Array(_)) => new.clone(),
        (Value::Object(_), Value::Object(_)) => new.clone(),
        (Value::Number(_), _) => return Err(mismatch("give a number, e.g. 2.0 or 1e-3")),
        (Value::Bool(_), _) => return Err(mismatch("give true or false")),
        (Value::Array(_), _) => return Err(mismatch("give a list, e.g. [1.0, 2.0]")),
        (Value::Object(_), _) => return Err(mismatch("give a map, e.g. { a: 1 }")),
        (Value::String(_), _) => return Err(mismatch("give a string")),
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    fn key() -> impl Strategy<Value = String> {
        "[a-z_][a-z0-9_-]{0,8}"
    }

    fn segment() -> impl Strategy<Value = Segment> {
        prop_oneof![
            key().prop_map(Segment::Key),
            (0usize..1000).prop_map(Segment::Index)
        ]
    }

    proptest! {
        /// The canonical text of any path parses back to the same path.
        #[test]
        fn path_round_trips(first in key(), rest in proptest::collection::vec(segment(), 0..6)) {
            let mut segs = vec![Segment::Key(first)];
            segs.extend(rest);
            let p = Path(segs);
            prop_assert_eq!(Path::parse(&p.to_string()).unwrap(), p);
        }

        /// `a[1][2]` and `a.1.2` are the same path.
        #[test]
        fn brackets_equal_dots(k in key(), i in 0usize..100, j in 0usize..100) {
            prop_assert_eq!(
                Path::parse(&format!("{k}[{i}][{j}]")).unwrap(),
                Path::parse(&format!("{k}.{i}.{j}")).unwrap()
            );
        }

        /// A finite number survives `PATH=VALUE` exactly.
        #[test]
        fn number_values_round_trip(k in key(), x in proptest::num::f64::NORMAL | proptest::num::f64::ZERO) {
            let o = Override::parse(&format!("{k}={x:e}")).unwrap();
            prop_assert_eq!(o.value.as_f64(), Some(x));
            prop_assert_eq!(o.segments, Path(vec![Segment::Key(k)]));
        }

        /// Arbitrary text never panics the parser: it is an override or an error.
        #[test]
        fn arbitrary_text_is_ok_or_error(s in "\\PC{0,30}") {
            let _ = Override::parse(&s);
        }

        /// A JSON-serialised override reads back equal.
        #[test]
        fn override_json_round_trips(k in key(), i in 0usize..5, x in -1e6f64..1e6) {
            let o = Override::new(&format!("blocks.{k}.den.{i}"), x).unwrap();
            let text = serde_json::to_string(&o).unwrap();
            prop_assert_eq!(serde_json::from_str::<Override>(&text).unwrap(), o);
        }
    }

    #[test]
    fn malformed_paths_are_errors_naming_the_path() {
        for bad in [
            "", "a..b", ".a", "a.", "a[", "a[x]", "a[1]b", "[0]", "a b", "=3",
        ] {
            let e = Path::parse(bad).unwrap_err().to_string();
            assert!(e.contains(&format!("override `{bad}`")), "{bad}: {e}");
            assert!(e.contains("fix:"), "{e}");
        }
        for bad in ["kp", "kp=", "x=.nan", "x=[1,"] {
            assert!(Override::parse(bad).is_err(), "{bad}");
        }
    }

    #[test]
    fn values_are_yaml() {
        assert_eq!(Override::parse("a=2").unwrap().value, Value::from(2u64));
        assert_eq!(Override::parse("a = 2.5").unwrap().value, Value::from(2.5));
        assert_eq!(Override::parse("a=true").unwrap().value, Value::from(true));
        assert_eq!(
            Override::parse("a=[1.0, 2]").unwrap().value,
            serde_json::json!([1.0, 2])
        );
        assert_eq!(Override::parse("a=+-").unwrap().value, Value::from("+-"));
    }
}
