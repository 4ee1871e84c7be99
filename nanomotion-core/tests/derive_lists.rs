//! `#[derive(Params)]` on lists: `len(…)` (how many entries: the check, the
//! listing's words and the schema's `minItems`/`maxItems`), `increasing`,
//! `same_len = other` (two lists paired entry by entry), `nested` on a list
//! of parameter enums, and a `#[serde(transparent)]` wrapper of a list whose
//! errors are named by the field that holds it.

mod common;

use nanomotion_core::GraphSpec;
use nanomotion_core::block::check::{self, Limit};
use nanomotion_core::doc::{ParamSchema, Params, within};
use proptest::prelude::*;
use serde::{Deserialize, Serialize};
use serde_json::json;

/// One segment of a test curve.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, Params)]
#[serde(tag = "kind", rename_all = "snake_case", deny_unknown_fields)]
enum Segment {
    /// A level.
    Level {
        /// Its value.
        #[param(finite)]
        value: f64,
    },
    /// Breakpoints and values.
    Table {
        /// Breakpoints.
        #[param(len(>= 1), finite, increasing, same_len = y)]
        x: Vec<f64>,
        /// Values at the breakpoints.
        #[param(positive)]
        y: Vec<f64>,
    },
}

/// The segments, one or more.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, Params)]
#[serde(transparent)]
struct Segments {
    /// The segments.
    #[param(len(1, 4), nested)]
    all: Vec<Segment>,
}

fn pair() -> Vec<f64> {
    vec![1.0, 1.0]
}

/// `test_lists`: y = u; list parameters with declared lengths.
#[derive(Debug, Clone, Serialize, Deserialize, Params)]
#[serde(deny_unknown_fields)]
#[block(type_name = "test_lists", role = Math, ports = "u -> y")]
struct Lists {
    /// Coefficients, highest power first.
    #[param(len(1, 5), finite, hint = "the coefficients, highest power first")]
    coefficients: Vec<f64>,
    /// A pair of weights.
    #[serde(default = "pair")]
    #[param(len(2, 2), non_negative)]
    weights: Vec<f64>,
    /// Optional sample times (s).
    #[serde(default)]
    #[param(len(<= 3), increasing)]
    times: Option<Vec<f64>>,
    /// The curve.
    #[param(nested)]
    curve: Segments,
}

pass_through_block!(Lists, "test_lists");

fn level() -> Segments {
    Segments {
        all: vec![Segment::Level { value: 1.0 }],
    }
}

fn lists(coefficients: Vec<f64>) -> Lists {
    Lists {
        coefficients,
        weights: pair(),
        times: None,
        curve: level(),
    }
}

fn error(l: &Lists) -> (String, String, String) {
    let e = l.check_params().unwrap_err();
    (e.field, e.problem, e.fix)
}

#[test]
fn a_length_bound_checks_with_field_problem_and_fix() {
    assert!(lists(vec![1.0]).check_params().is_ok());
    assert_eq!(
        error(&lists(vec![])),
        (
            "coefficients".into(),
            "is empty".into(),
            "give 1 to 5 entries, the coefficients, highest power first".into()
        )
    );
    assert_eq!(
        error(&lists(vec![1.0; 6])).1,
        "has 6 entries, must have 1 to 5 entries"
    );
    // the length is checked before the entries
    assert_eq!(error(&lists(vec![f64::NAN; 6])).0, "coefficients");
    assert_eq!(error(&lists(vec![1.0, f64::NAN])).0, "coefficients[1]");
    let mut l = lists(vec![1.0]);
    l.weights = vec![1.0];
    assert_eq!(
        error(&l),
        (
            "weights".into(),
            "has 1 entry, must have exactly 2 entries".into(),
            "give exactly 2 entries".into()
        )
    );
    // an optional list: bounded when present
    l.weights = pair();
    l.times = Some(vec![0.0, 1.0, 2.0, 3.0]);
    assert_eq!(error(&l).1, "has 4 entries, must have at most 3 entries");
    l.times = Some(vec![0.0, 2.0, 1.0]);
    assert_eq!(
        error(&l),
        (
            "times[2]".into(),
            "is 1, not above the entry before it, 2".into(),
            "sort the entries strictly increasing".into()
        )
    );
    l.times = Some(vec![0.0, f64::NAN]);
    assert_eq!(error(&l).0, "times[1]");
}

#[test]
fn lists_of_laws_are_named_entry_by_entry_through_the_wrapper() {
    let mut l = lists(vec![1.0]);
    l.curve = Segments { all: vec![] };
    let e = l.check_params().unwrap_err();
    assert_eq!(
        (e.field.as_str(), e.problem.as_str()),
        ("curve", "is empty")
    );
    l.curve = Segments {
        all: vec![
            Segment::Level { value: 1.0 },
            Segment::Table {
                x: vec![0.0, 1.0],
                y: vec![1.0, -1.0],
            },
        ],
    };
    assert_eq!(error(&l).0, "curve[1].y[1]");
    l.curve.all[1] = Segment::Table {
        x: vec![0.0, 1.0],
        y: vec![1.0],
    };
    assert_eq!(
        error(&l),
        (
            "curve[1].x".into(),
            "has 2 entries, y has 1 entry".into(),
            "give as many entries in x as in y, one per pair".into()
        )
    );
    // the wrapper alone names its entries from where it stands
    let e = within("schedule", Segments { all: vec![] }.check_params()).unwrap_err();
    assert_eq!(e.field, "schedule");
    let bad = Segments {
        all: vec![Segment::Level { value: f64::NAN }],
    };
    assert_eq!(
        within("schedule", bad.check_params()).unwrap_err().field,
        "schedule[0].value"
    );
}

#[test]
fn length_bounds_reach_the_schema_and_the_listing() {
    let docs = Lists::param_docs();
    let find = |n: &str| docs.iter().find(|d| d.name == n).unwrap();
    let c = find("coefficients");
    assert_eq!(
        (c.schema["minItems"].clone(), c.schema["maxItems"].clone()),
        (json!(1), json!(5))
    );
    assert_eq!(c.bounds, ["1 to 5 entries"]);
    let w = find("weights");
    assert_eq!(
        (w.schema["minItems"].clone(), w.schema["maxItems"].clone()),
        (json!(2), json!(2))
    );
    assert_eq!(w.bounds, ["exactly 2 entries", "each ≥ 0"]);
    let t = find("times");
    assert_eq!(t.schema["anyOf"][0]["maxItems"], json!(3));
    assert_eq!(t.bounds, ["at most 3 entries", "strictly increasing"]);
    // the wrapper's length: in its schema and said by the field holding it
    let curve = find("curve");
    assert_eq!(curve.schema["minItems"], json!(1));
    assert_eq!(curve.schema["maxItems"], json!(4));
    assert_eq!(curve.bounds, ["1 to 4 entries"]);
    assert_eq!(Segments::param_schema()["type"], json!("array"));
    let table = &curve.schema["items"]["anyOf"][1]["properties"];
    assert_eq!(table["x"]["minItems"], json!(1));
    let doc = nanomotion_core::block::block_docs()
        .into_iter()
        .find(|d| d.type_name == "test_lists")
        .unwrap()
        .describe();
    assert!(
        doc.contains("[{kind: level, value} | {kind: table, x, y}] [1 to 4 entries]"),
        "{doc}"
    );
}

#[test]
fn entries_checks_directly() {
    let at_least = |n| Some(Limit::Inclusive(n));
    assert!(check::entries("v", 1, at_least(1), None).is_ok());
    assert!(check::entries("v", 3, None, Some(Limit::Exclusive(3))).is_err());
    assert_eq!(
        check::entries("v", 0, Some(Limit::Exclusive(0)), None)
            .unwrap_err()
            .fix,
        "give at least 1 entry"
    );
    assert!(check::increasing("x", &[]).is_ok());
    assert!(check::increasing("x", &[1.0, 1.0]).is_err());
    assert!(check::same_len("x", 2, "y", 2).is_ok());
}

fn graph(coefficients: &str, curve: &str) -> String {
    format!(
        "base_rate_hz: 100\nduration_s: 0.1\nblocks:\n  - {{ name: src, type: constant, value: 1.0 }}\n  - {{ name: l, type: test_lists, coefficients: {coefficients}, curve: {curve} }}\nconnections:\n  - {{ from: src.y, to: l.u }}\n"
    )
}

proptest! {
    /// A graph file's lists build exactly when their lengths are within the
    /// declared bounds; otherwise the error names the block, the field and
    /// the fix, and nothing panics.
    #[test]
    fn loaded_lists_build_exactly_within_their_declared_lengths(
        n in 0usize..9,
        levels in 0usize..7,
    ) {
        let coefficients = format!("[{}]", vec!["1.0"; n].join(", "));
        let curve = format!("[{}]", vec!["{kind: level, value: 2.0}"; levels].join(", "));
        let spec = GraphSpec::from_yaml(&graph(&coefficients, &curve), "lists.yaml").unwrap();
        match spec.build() {
            Ok(_) => prop_assert!((1..=5).contains(&n) && (1..=4).contains(&levels)),
            Err(e) => {
                let text = e.to_string();
                prop_assert!(!((1..=5).contains(&n) && (1..=4).contains(&levels)), "{text}");
                prop_assert!(text.contains("block `l` (type `test_lists`)"), "{text}");
                let field = if (1..=5).contains(&n) { "curve" } else { "coefficients" };
                prop_assert!(text.contains(&format!("field `{field}`")), "{text}");
                prop_assert!(text.contains("give "), "{text}");
            }
        }
    }
}
