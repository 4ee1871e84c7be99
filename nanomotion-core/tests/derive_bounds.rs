//! `#[derive(Params)]` beyond the float bounds: bounds on integer fields (the
//! same check, docs and JSON Schema as a float's, as whole numbers), open-ended
//! and exclusive ranges (`range(> 0)`, `range(<= 1)`, `range(> 0.25, < 1)`),
//! `hint = "…"`, and enum fields whose choices come from the enum itself.

mod common;

use nanomotion_core::block::check::{self, Limit};
use nanomotion_core::doc::{ParamSchema, Params};
use nanomotion_core::{GraphError, GraphSpec};
use proptest::prelude::*;
use serde::{Deserialize, Serialize};
use serde_json::json;

const MAX_TEST_SUBSTEPS: u32 = 1000;

fn one_u32() -> u32 {
    1
}
fn one_usize() -> usize {
    1
}

/// A choice written by name, as `discretisation: zoh | tustin`.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize, Params)]
#[serde(rename_all = "snake_case")]
enum Method {
    /// Zero-order hold.
    #[default]
    Zoh,
    /// Bilinear.
    Tustin,
    /// First-order hold.
    #[serde(alias = "foh")]
    FirstOrderHold,
    /// Matched poles and zeros.
    #[serde(rename = "matched")]
    MatchedPoleZero,
}

/// `test_counts`: y = u; integer parameters of every width, bounded.
#[derive(Debug, Clone, Serialize, Deserialize, Params)]
#[serde(deny_unknown_fields)]
#[block(type_name = "test_counts", role = Math, ports = "u -> y")]
struct Counts {
    /// Sub-steps per period (-).
    #[serde(default = "one_u32")]
    #[param(range(1, MAX_TEST_SUBSTEPS), hint = "or raise the block's rate_hz")]
    substeps: u32,
    /// Events to keep (-).
    #[serde(default)]
    #[param(range(<= 1_000_000))]
    keep: u64,
    /// Taps (-).
    #[serde(default = "one_usize")]
    #[param(range(> 0, < 64))]
    taps: usize,
    /// Offset in counts.
    #[serde(default)]
    #[param(range(>= -5, <= 5))]
    offset: i64,
    /// Skip σ (-).
    #[serde(default)]
    #[param(non_negative)]
    skip: i32,
    /// Filter order (-).
    #[serde(default = "one_u32")]
    #[param(positive)]
    order: u32,
    /// Optional cap (-).
    #[serde(default)]
    #[param(at_least_one)]
    cap: Option<u32>,
    /// Length of each channel (-).
    #[serde(default)]
    #[param(range(2, 8))]
    lengths: Vec<u16>,
    /// Channels (usize `width`: its own check).
    #[serde(default = "one_usize")]
    #[param(width)]
    width: usize,
    /// Discretisation.
    #[serde(default)]
    method: Method,
    /// Optional second method; none: the first.
    #[serde(default)]
    method2: Option<Method>,
}

impl Default for Counts {
    fn default() -> Self {
        Self {
            substeps: 1,
            keep: 0,
            taps: 1,
            offset: 0,
            skip: 0,
            order: 1,
            cap: None,
            lengths: Vec::new(),
            width: 1,
            method: Method::Zoh,
            method2: None,
        }
    }
}

pass_through_block!(Counts, "test_counts");

/// Open-ended and exclusive float ranges.
#[derive(Debug, Clone, Serialize, Deserialize, Params)]
struct Levels {
    /// Largest angle (rad).
    #[param(range(> 0, < 1.5), hint = "e.g. 0.1")]
    angle: f64,
    /// Alias level (-).
    #[param(range(> 0.25, <= 1))]
    level: f64,
    /// Lower bound only (-).
    #[param(range(>= 0.5))]
    at_least: f64,
    /// Upper bound only, strict (-).
    #[param(range(< 1))]
    below: f64,
    /// Both inclusive, the old form (V).
    #[param(range(0.0, 46.0))]
    both: f64,
    /// Optional, strictly positive.
    #[serde(default)]
    #[param(range(> 0))]
    maybe: Option<f64>,
}

fn levels() -> Levels {
    Levels {
        angle: 0.1,
        level: 0.5,
        at_least: 0.5,
        below: 0.0,
        both: 46.0,
        maybe: None,
    }
}

fn schema_of(docs: &[nanomotion_core::ParamDoc], name: &str) -> serde_json::Value {
    docs.iter()
        .find(|p| p.name == name)
        .unwrap_or_else(|| panic!("no parameter {name}"))
        .schema
        .clone()
}

fn bounds_of(docs: &[nanomotion_core::ParamDoc], name: &str) -> Vec<String> {
    docs.iter().find(|p| p.name == name).unwrap().bounds.clone()
}

#[test]
fn integer_bounds_check_as_whole_numbers_with_field_problem_and_fix() {
    assert!(Counts::default().check_params().is_ok());
    let e = Counts {
        substeps: 0,
        ..Counts::default()
    }
    .check_params()
    .unwrap_err();
    assert_eq!(e.field, "substeps");
    assert_eq!(e.problem, "is 0, outside the allowed range [1, 1000]");
    assert_eq!(
        e.fix,
        "give a whole number in [1, 1000], or raise the block's rate_hz"
    );
    let e = Counts {
        keep: 1_000_001,
        ..Counts::default()
    }
    .check_params()
    .unwrap_err();
    assert_eq!(
        (e.field.as_str(), e.problem.as_str(), e.fix.as_str()),
        (
            "keep",
            "is 1000001, must be ≤ 1000000",
            "give a whole number ≤ 1000000"
        )
    );
    // `> 0, < 64` on a usize: the whole numbers 1 to 63
    for (taps, ok) in [(0, false), (1, true), (63, true), (64, false)] {
        let r = Counts {
            taps,
            ..Counts::default()
        }
        .check_params();
        assert_eq!(r.is_ok(), ok, "taps = {taps}");
        if let Err(e) = r {
            assert_eq!(e.field, "taps");
            assert_eq!(e.fix, "give a whole number in [1, 63]");
        }
    }
    let e = Counts {
        offset: -6,
        ..Counts::default()
    }
    .check_params()
    .unwrap_err();
    assert_eq!(
        (e.field.as_str(), e.problem.as_str()),
        ("offset", "is -6, outside the allowed range [-5, 5]")
    );
    let e = Counts {
        skip: -1,
        ..Counts::default()
    }
    .check_params()
    .unwrap_err();
    assert_eq!(
        (e.field.as_str(), e.problem.as_str(), e.fix.as_str()),
        ("skip", "is -1, must be ≥ 0", "give a whole number ≥ 0")
    );
    // `positive` on an integer: ≥ 1
    let e = Counts {
        order: 0,
        ..Counts::default()
    }
    .check_params()
    .unwrap_err();
    assert_eq!(
        (e.field.as_str(), e.problem.as_str(), e.fix.as_str()),
        ("order", "is 0, must be ≥ 1", "give a whole number ≥ 1")
    );
    // an Option: checked when present
    let e = Counts {
        cap: Some(0),
        ..Counts::default()
    }
    .check_params()
    .unwrap_err();
    assert_eq!(e.field, "cap");
    // a Vec: every element, named by its index
    let e = Counts {
        lengths: vec![2, 8, 9],
        ..Counts::default()
    }
    .check_params()
    .unwrap_err();
    assert_eq!(
        (e.field.as_str(), e.problem.as_str()),
        ("lengths[2]", "is 9, outside the allowed range [2, 8]")
    );
    // a usize `width` keeps check::width's message
    let e = Counts {
        width: 0,
        ..Counts::default()
    }
    .check_params()
    .unwrap_err();
    assert_eq!(e, check::width("width", 0).unwrap_err());
}

#[test]
fn integer_bounds_reach_the_schema_and_the_listing() {
    let docs = Counts::param_docs();
    let s = schema_of(&docs, "substeps");
    assert_eq!(s["type"], "integer");
    assert_eq!((&s["minimum"], &s["maximum"]), (&json!(1), &json!(1000)));
    assert_eq!(s["default"], 1);
    assert_eq!(bounds_of(&docs, "substeps"), ["1 to 1000"]);
    let s = schema_of(&docs, "keep");
    assert_eq!(
        (&s["type"], &s["maximum"]),
        (&json!("integer"), &json!(1_000_000))
    );
    assert_eq!(s["minimum"], 0, "an unsigned type is ≥ 0");
    assert_eq!(bounds_of(&docs, "keep"), ["≤ 1000000"]);
    let s = schema_of(&docs, "taps");
    assert_eq!(s["exclusiveMinimum"], 0);
    assert_eq!(s["exclusiveMaximum"], 64);
    assert_eq!(bounds_of(&docs, "taps"), ["in (0, 64)"]);
    let s = schema_of(&docs, "offset");
    assert_eq!(s["type"], "integer");
    assert_eq!((&s["minimum"], &s["maximum"]), (&json!(-5), &json!(5)));
    assert_eq!(bounds_of(&docs, "offset"), ["-5 to 5"]);
    assert_eq!(schema_of(&docs, "skip")["minimum"], 0);
    assert_eq!(schema_of(&docs, "order")["exclusiveMinimum"], 0);
    assert_eq!(bounds_of(&docs, "order"), ["> 0"]);
    let s = schema_of(&docs, "cap");
    assert_eq!(s["anyOf"][0]["type"], "integer");
    assert_eq!(s["anyOf"][0]["minimum"], 1);
    let s = schema_of(&docs, "lengths");
    assert_eq!(s["items"]["type"], "integer");
    assert_eq!(
        (&s["items"]["minimum"], &s["items"]["maximum"]),
        (&json!(2), &json!(8))
    );
    assert_eq!(bounds_of(&docs, "lengths"), ["each 2 to 8"]);
    let doc = nanomotion_core::block::block_docs()
        .into_iter()
        .find(|d| d.type_name == "test_counts")
        .unwrap();
    let listing = doc.describe();
    assert!(
        listing.contains("Sub-steps per period (-). [1 to 1000] [default 1]"),
        "{listing}"
    );
    assert!(
        listing.contains("Taps (-). [in (0, 64)] [default 1]"),
        "{listing}"
    );
}

#[test]
fn open_and_exclusive_float_ranges_check_and_describe() {
    assert!(levels().check_params().is_ok());
    let e = Levels {
        angle: 1.5,
        ..levels()
    }
    .check_params()
    .unwrap_err();
    assert_eq!(
        (e.field.as_str(), e.problem.as_str(), e.fix.as_str()),
        (
            "angle",
            "is 1.5, not in (0, 1.5)",
            "give a value in (0, 1.5), e.g. 0.1"
        )
    );
    let e = Levels {
        angle: f64::NAN,
        ..levels()
    }
    .check_params()
    .unwrap_err();
    assert_eq!(e.problem, "is NaN, not a finite number");
    assert_eq!(
        Levels {
            level: 0.25,
            ..levels()
        }
        .check_params()
        .unwrap_err()
        .problem,
        "is 0.25, not in (0.25, 1]"
    );
    assert!(
        Levels {
            level: 1.0,
            ..levels()
        }
        .check_params()
        .is_ok()
    );
    let e = Levels {
        at_least: 0.4,
        ..levels()
    }
    .check_params()
    .unwrap_err();
    assert_eq!(
        (e.problem.as_str(), e.fix.as_str()),
        ("is 0.4, must be ≥ 0.5", "give a value ≥ 0.5")
    );
    let e = Levels {
        below: 1.0,
        ..levels()
    }
    .check_params()
    .unwrap_err();
    assert_eq!(
        (e.problem.as_str(), e.fix.as_str()),
        ("is 1, must be < 1", "give a value < 1")
    );
    // both inclusive: exactly the old `in_range` message
    let e = Levels {
        both: 46.5,
        ..levels()
    }
    .check_params()
    .unwrap_err();
    assert_eq!(e, check::in_range("both", 46.5, 0.0, 46.0).unwrap_err());
    let e = Levels {
        maybe: Some(0.0),
        ..levels()
    }
    .check_params()
    .unwrap_err();
    assert_eq!(
        (e.field.as_str(), e.problem.as_str()),
        ("maybe", "is 0, must be > 0")
    );

    let docs = Levels::param_docs();
    let s = schema_of(&docs, "angle");
    assert_eq!(s["type"], "number");
    assert_eq!(
        (&s["exclusiveMinimum"], &s["exclusiveMaximum"]),
        (&json!(0), &json!(1.5))
    );
    assert!(s.get("minimum").is_none() && s.get("maximum").is_none());
    let s = schema_of(&docs, "level");
    assert_eq!(
        (&s["exclusiveMinimum"], &s["maximum"]),
        (&json!(0.25), &json!(1))
    );
    assert_eq!(bounds_of(&docs, "level"), ["in (0.25, 1]"]);
    assert_eq!(schema_of(&docs, "at_least")["minimum"], 0.5);
    assert_eq!(bounds_of(&docs, "at_least"), ["≥ 0.5"]);
    assert_eq!(schema_of(&docs, "below")["exclusiveMaximum"], 1);
    assert_eq!(bounds_of(&docs, "below"), ["< 1"]);
    assert_eq!(bounds_of(&docs, "both"), ["0 to 46"]);
    assert_eq!(schema_of(&docs, "maybe")["anyOf"][0]["exclusiveMinimum"], 0);
}

#[test]
fn check_between_and_whole_directly() {
    assert!(check::between("x", 0.0, Some(Limit::Inclusive(0.0)), None).is_ok());
    assert!(check::between("x", 0.0, Some(Limit::Exclusive(0.0)), None).is_err());
    assert!(check::between("x", 2.0, None, Some(Limit::Inclusive(2.0))).is_ok());
    assert!(check::between("x", 2.0, None, Some(Limit::Exclusive(2.0))).is_err());
    assert!(check::between("x", f64::INFINITY, None, None).is_err());
    // an integer `< 10` is ≤ 9; `> -1` is ≥ 0
    let e = check::whole("n", 10, None, Some(Limit::Exclusive(10))).unwrap_err();
    assert_eq!(
        (e.problem.as_str(), e.fix.as_str()),
        ("is 10, must be ≤ 9", "give a whole number ≤ 9")
    );
    assert!(check::whole("n", 0, Some(Limit::Exclusive(-1)), None).is_ok());
    // both ends: check::size's words
    let e = check::whole("n", 0, Some(Limit::Inclusive(1)), Some(Limit::Inclusive(4))).unwrap_err();
    assert_eq!(e, check::size("n", 0, 1, 4).unwrap_err());
}

/// The names an enum's schema lists.
fn listed(schema: &serde_json::Value) -> Vec<String> {
    let s = schema.get("anyOf").map_or(schema, |a| &a[0]);
    s["enum"]
        .as_array()
        .unwrap_or_else(|| panic!("no enum list in {s}"))
        .iter()
        .map(|v| v.as_str().unwrap().to_string())
        .collect()
}

#[test]
fn an_enum_field_lists_exactly_the_names_serde_accepts() {
    let docs = Counts::param_docs();
    let names = listed(&schema_of(&docs, "method"));
    assert_eq!(
        names,
        ["zoh", "tustin", "first_order_hold", "foh", "matched"]
    );
    assert_eq!(schema_of(&docs, "method")["type"], "string");
    assert_eq!(listed(&schema_of(&docs, "method2")), names);
    assert_eq!(listed(&Method::param_schema()), names);
    // every listed name reads …
    for n in &names {
        serde_json::from_value::<Method>(json!(n)).unwrap_or_else(|e| panic!("{n}: {e}"));
    }
    // … and serde's own list of the names it knows is within it
    let e = serde_json::from_value::<Method>(json!("bogus"))
        .unwrap_err()
        .to_string();
    let pos = e.find("expected one of").expect(&e);
    let known: Vec<String> = e[pos + "expected one of".len()..]
        .split(',')
        .map(|s| s.trim().trim_matches('`').to_string())
        .collect();
    assert!(!known.is_empty());
    for k in &known {
        assert!(
            names.contains(k),
            "serde knows `{k}`, the schema does not list it: {e}"
        );
    }
    // Rust's own spelling of a variant is not a choice
    assert!(serde_json::from_value::<Method>(json!("Zoh")).is_err());
    assert!(!names.contains(&"Zoh".to_string()));
    // the listing shows the choices
    let doc = nanomotion_core::block::block_docs()
        .into_iter()
        .find(|d| d.type_name == "test_counts")
        .unwrap();
    assert!(
        doc.describe().contains(
            "Discretisation. [zoh | tustin | first_order_hold | foh | matched] [default zoh]"
        ),
        "{}",
        doc.describe()
    );
}

fn graph(substeps: &str) -> String {
    format!(
        "base_rate_hz: 100\nduration_s: 0.1\nblocks:\n  - {{ name: src, type: constant, value: 1.0 }}\n  - {{ name: counts, type: test_counts, substeps: {substeps} }}\nconnections:\n  - {{ from: src.y, to: counts.u }}\n"
    )
}

proptest! {
    /// A graph file's `substeps` (declared `range(1, 1000)` on a u32) builds
    /// exactly when it is within the bound; otherwise the error names the
    /// block, its type, the field and the fix, and nothing panics.
    #[test]
    fn a_loaded_integer_bound_is_the_declared_one(n in -5i64..3000) {
        let spec = GraphSpec::from_yaml(&graph(&n.to_string()), "counts.yaml");
        match spec {
            // a negative number is not a u32: serde's own error, located
            Err(e) => {
                prop_assert!(n < 0, "{e}");
                prop_assert!(e.to_string().contains("counts.yaml"), "{e}");
            }
            Ok(spec) => {
                prop_assert!(n >= 0);
                match spec.build() {
                    Ok(_) => prop_assert!((1..=1000).contains(&n), "{n} was accepted"),
                    Err(e) => {
                        prop_assert!(!(1..=1000).contains(&n), "{n} refused: {e}");
                        let text = e.to_string();
                        prop_assert!(
                            text.contains("block `counts` (type `test_counts`): field `substeps`")
                                && text.contains(&format!("is {n}, outside the allowed range [1, 1000]"))
                                && text.contains("give a whole number in [1, 1000], or raise the block's rate_hz"),
                            "{text}"
                        );
                        let mut e = &e;
                        while let GraphError::At { source, .. } = e {
                            e = source;
                        }
                        prop_assert!(matches!(e, GraphError::Param { .. }), "{e:?}");
                    }
                }
            }
        }
    }
}

/// A choice with data: bounds on its variants' fields.
#[derive(Debug, Clone, Serialize, Deserialize, Params)]
#[serde(tag = "kind", rename_all = "snake_case", deny_unknown_fields)]
enum Filter {
    /// No filter.
    Identity,
    /// A moving average.
    Average {
        /// Taps (-).
        #[param(range(1, 99), hint = "an odd number")]
        taps: u32,
        /// Lowest weight (-).
        #[param(non_negative, at_most = hi)]
        lo: f64,
        /// Highest weight (-).
        hi: f64,
    },
    /// A low-pass.
    LowPass {
        /// Cut-off (Hz).
        #[param(range(> 0))]
        cutoff_hz: f64,
    },
}

/// A block's parameters holding the choice.
#[derive(Debug, Clone, Serialize, Deserialize, Params)]
struct Holder {
    /// The filter.
    #[param(nested)]
    filter: Filter,
    /// An optional second one.
    #[serde(default)]
    #[param(nested)]
    second: Option<Filter>,
}

#[test]
fn bounds_on_enum_variant_fields_are_checked_through_nested() {
    let ok = Holder {
        filter: Filter::Average {
            taps: 5,
            lo: 0.0,
            hi: 0.0,
        },
        second: Some(Filter::Identity),
    };
    assert!(ok.check_params().is_ok());
    let e = Holder {
        filter: Filter::Average {
            taps: 100,
            lo: 0.0,
            hi: 0.0,
        },
        second: None,
    }
    .check_params()
    .unwrap_err();
    assert_eq!(
        (e.field.as_str(), e.problem.as_str(), e.fix.as_str()),
        (
            "filter.taps",
            "is 100, outside the allowed range [1, 99]",
            "give a whole number in [1, 99], an odd number"
        )
    );
    // at_most between two fields of the variant
    let e = Filter::Average {
        taps: 3,
        lo: 0.5,
        hi: 0.25,
    }
    .check_params()
    .unwrap_err();
    assert_eq!(e, check::ordered("lo", 0.5, "hi", 0.25).unwrap_err());
    let e = Holder {
        filter: Filter::Identity,
        second: Some(Filter::LowPass { cutoff_hz: 0.0 }),
    }
    .check_params()
    .unwrap_err();
    assert_eq!(
        (e.field.as_str(), e.problem.as_str()),
        ("second.cutoff_hz", "is 0, must be > 0")
    );
    // the schema of the variant's field carries its bounds
    let s = Filter::param_schema();
    let avg = s["anyOf"]
        .as_array()
        .unwrap()
        .iter()
        .find(|b| b["properties"]["kind"]["const"] == "average")
        .unwrap();
    assert_eq!(avg["properties"]["taps"]["type"], "integer");
    assert_eq!(avg["properties"]["taps"]["maximum"], 99);
}
