//! One declaration per block: documentation, JSON Schema and parameter bounds
//! derived from the parameter struct.
//!
//! A block's parameter struct is the only place its parameters are described.
//! `#[derive(Params)]` reads
//!
//! - the struct's doc comment (its first paragraph is the block's one-line
//!   summary in `nanomotion blocks`; a leading "`tag`:" is dropped),
//! - each field's doc comment (unit and meaning),
//! - `#[serde(default …)]`, `#[serde(rename/alias …)]`, `#[serde(skip)]` (the
//!   default shown is the value the default function really returns),
//! - `#[param(…)]` bounds, which become both the JSON Schema's `minimum`/`maximum`
//!   and [`Params::check_params`], the validation `build()` calls — with exactly the
//!   messages of [`check`](crate::block::check) (field, problem, fix),
//! - `#[block(type_name = "…", role = …, ports = "…")]`: registers the block's
//!   [`BlockDoc`] for `nanomotion blocks` and `nanomotion schema`, and implements
//!   [`DeclaredBlock`](crate::block::DeclaredBlock) (the type name and role) and,
//!   when `ports` is a declaration rather than prose,
//!   [`DeclaredPorts`](crate::block::DeclaredPorts): `inputs -> outputs`, each a
//!   comma-separated list of `name[width] (unit) "note" [scheduling]` — `[width]` a whole
//!   number, a `usize` field or the sum of a list of widths (`[Σwidths]`; default 1),
//!   `(unit)` an SI symbol the port carries (`m`, `m/s²`, `V`, `count`),
//!   `"note"` words for the reader only (listed in parentheses: `pair "1 or 2"`),
//!   `[scheduling]` a scheduling input; an
//!   output may instead be `name[width] [unit of u]`, in the unit of input `u`
//!   whatever it is when the graph is built ([`Port::unit_of_input`](crate::Port::unit_of_input)).
//!   A port may end in `if flag` (it exists when the `bool` field `flag` is
//!   true: `amplitude (V) if amplitude_input`), or be a repeated group, `{i}` in
//!   its name: `in{i}[width] for i in 0..factors` (a `usize` field) or `for i in
//!   0..len(signs)` (a list's entries, a string's characters), with `[widths[i]]`
//!   entry `i` of the list counted (`mux`: `in{i}[widths[i]] for i in
//!   0..len(widths) -> y[Σwidths]`; `sum`'s output is `[unit of in0]`, the
//!   group's first). In a `#[serde(transparent)]` block the names are the
//!   wrapped struct's fields. The markers are not shown in the listing.
//!   `#[declared_block]` on the `impl Block` turns these into the block's
//!   methods (see [`crate::block`]),
//! - `#[block(…, live = "kp, zero_hz")]`: the parameters that may change while
//!   the graph runs, in the slot order of `Block::set_live_param` (each a
//!   field; a name that is not one does not compile) —
//!   [`DeclaredBlock::LIVE_PARAMS`](crate::block::DeclaredBlock::LIVE_PARAMS),
//!   the block's `Block::live_params`, [`BlockDoc::live`] (the `live:` line of
//!   `nanomotion blocks`) and [`live_params_by_type`].
//!
//! | `#[param(…)]` | check | schema |
//! |---|---|---|
//! | `finite` | [`check::finite`](crate::block::check::finite) (a vector: [`check::all_finite`](crate::block::check::all_finite)) | number |
//! | `positive` | [`check::positive`](crate::block::check::positive) | `exclusiveMinimum: 0` |
//! | `non_negative` | [`check::non_negative`](crate::block::check::non_negative) | `minimum: 0` |
//! | `range(lo, hi)` | [`check::in_range`](crate::block::check::in_range) (both ends inclusive) | `minimum`, `maximum` |
//! | `range(> lo)`, `range(>= lo)`, `range(< hi)`, `range(<= hi)`, `range(> lo, <= hi)`, … | [`check::between`](crate::block::check::between): each end with its operator, either left out | `exclusiveMinimum` (`>`) or `minimum` (`>=`), `exclusiveMaximum` (`<`) or `maximum` (`<=`) |
//! | `width` | [`check::width`](crate::block::check::width) | 1 to [`MAX_WIDTH`](crate::block::MAX_WIDTH) |
//! | `size(lo, hi)` | [`check::size`](crate::block::check::size) | `minimum`, `maximum` |
//! | `at_least_one` | [`check::at_least_one`](crate::block::check::at_least_one) | `minimum: 1` |
//! | `len(lo, hi)`, `len(>= lo)`, `len(<= hi)`, … (`range`'s forms) | [`check::entries`](crate::block::check::entries): how many entries a list holds (`is empty`, `has 6 entries, must have 1 to 5 entries`), before its entries' bounds if declared first | `minItems`, `maxItems` |
//! | `increasing` | [`check::increasing`](crate::block::check::increasing): each entry of a list of numbers above the one before | — (words: strictly increasing) |
//! | `at_most = other` | [`check::ordered`](crate::block::check::ordered) (this ≤ `other`), after every field's own bounds | — |
//! | `below_nyquist` | [`check::below_nyquist`](crate::block::check::below_nyquist) against the block's rate, by [`Params::check_at_rate`] (`build()` calls it with `ctx.dt`); an `f64` or `Option<f64>` field of a block | — (words: below Nyquist) |
//! | `same_len = other` | [`check::same_len`](crate::block::check::same_len): as many entries as the list `other` (breakpoints and their values), after every field's own bounds | — (words: as many entries as `other`) |
//! | `nested` | the field's own [`Params::check_params`], field names prefixed `field.` | the field type's schema |
//! | `hint = "…"` | adds its words to the fix of the field's bound errors (`give a whole number in [1, 1000], or raise the block's rate_hz`) | — |
//!
//! **Integer fields** (`u8` … `u64`, `usize`, `i8` … `i64`, `isize`) take the same
//! bounds, checked as whole numbers by [`check::whole`](crate::block::check::whole)
//! (`positive` is ≥ 1, `non_negative` ≥ 0, `range(> 0)` ≥ 1, …; a `usize`'s
//! `width`, `size` and `at_least_one` keep their own checks); their schema is
//! `type: integer` with the bounds as declared. `finite` or a fractional bound
//! (`range(0.5, 2)`) on an integer field is a compile error.
//!
//! **Enum fields**: an enum that derives `Params` (unit variants, serde's
//! `rename`/`rename_all`/`alias` honoured) is a `type: string` with an `enum`
//! list of the names serde accepts, and `nanomotion blocks` prints the choices
//! (`[zoh | tustin]`); variants with data are an `anyOf` of their forms. An enum
//! without the derive is "any value" in the schema.
//!
//! **Enum variants' fields** take bounds too: the enum's `check_params()` checks
//! the fields of the variant present, and a struct field of that enum type marked
//! `nested` calls it (`shape.overlap_q`).
//!
//! A bound on an `Option<T>` applies when the value is present, on a `Vec<T>` to
//! every element (named `field[i]`) — except `len` and `increasing`, which bound
//! the list itself; `nested` on a `Vec<T>` checks each entry (`field[i].x`).
//!
//! **A `#[serde(transparent)]` wrapper of a list** (or of another plain value:
//! `struct Schedule { #[param(len(>= 1), nested)] laws: Vec<Law> }`) is that
//! value in the schema, its field's bounds included, and its `check_params()`
//! names errors from where it stands (`[1].x`, or nothing for its length); a
//! field holding it marked `nested` names them `schedule[1].x` and `schedule`,
//! and says the list's length in the listing. [`within`] does the same for a
//! caller outside a block. A transparent wrapper of a parameter struct is that
//! struct's parameters (a block written as another's). `default_doc = "…"` says in words what a
//! default means when its value alone does not (`none` = computed from other
//! fields); `schema = "path"` gives a field's schema by a function. Checks run in
//! field order; cross-field rules that bounds cannot say stay in `build()`.
//!
//! ```
//! use nanomotion_core::doc::Params;
//! use serde::{Deserialize, Serialize};
//!
//! fn one() -> usize { 1 }
//!
//! /// `doc_gain`: y = k·u, element-wise.
//! #[derive(Debug, Clone, Serialize, Deserialize, Params)]
//! #[serde(deny_unknown_fields)]
//! #[block(type_name = "doc_gain", role = Math, ports = "u[n] -> y[n]")]
//! struct DocGain {
//!     /// Gain k (unit of y per unit of u).
//!     #[param(finite)]
//!     k: f64,
//!     /// Signal width n.
//!     #[serde(default = "one")]
//!     #[param(width)]
//!     width: usize,
//! }
//!
//! let bad = DocGain { k: 1.0, width: 0 };
//! let e = bad.check_params().unwrap_err();
//! assert_eq!(e.field, "width");
//! let docs = DocGain::param_docs();
//! assert_eq!(docs[1].default.as_deref(), Some("1"));
//! assert_eq!(docs[1].schema["maximum"], 1024);
//! let doc = nanomotion_core::block::block_docs()
//!     .into_iter()
//!     .find(|d| d.type_name == "doc_gain")
//!     .unwrap();
//! assert_eq!(doc.summary, "y = k·u, element-wise.");
//! ```

use crate::error::ParamError;
pub use nanomotion_derive::Params;
use serde_json::{Map, Value, json};

/// The role a block plays in a loop (for listings and documentation).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum Role {
    /// Reference generators and disturbance/noise sources.
    Source,
    /// Feedback and feed-forward controllers.
    Controller,
    /// Converts commands into physical drive signals (drivers, amplifiers).
    Actuator,
    /// The simulated physical system.
    Plant,
    /// Measures a physical quantity (encoders, interferometers, quantisers).
    Sensor,
    /// Reconstructs a quantity from measurements (velocity estimation, HOTS).
    Estimator,
    /// Learning filters of repetitive/iterative control (L, Q).
    LearningFilter,
    /// Arithmetic, routing and filtering.
    Math,
}

impl Role {
    /// Lower-case name of the role.
    pub fn as_str(self) -> &'static str {
        match self {
            Role::Source => "source",
            Role::Controller => "controller",
            Role::Actuator => "actuator",
            Role::Plant => "plant",
            Role::Sensor => "sensor",
            Role::Estimator => "estimator",
            Role::LearningFilter => "learning filter",
            Role::Math => "math",
        }
    }
}

/// A parameter struct (or enum) described by `#[derive(Params)]`.
pub trait Params {
    /// Whether unknown fields are refused (`#[serde(deny_unknown_fields)]`).
    const CLOSED: bool;
    /// Documentation and schema of every parameter, in declaration order.
    fn param_docs() -> Vec<ParamDoc>;
    /// Check the declared `#[param(…)]` bounds; the error names the field and the
    /// fix. `build()` calls it before anything else.
    fn check_params(&self) -> Result<(), ParamError>;
    /// Check the bounds that depend on the block's sample period `dt` (s):
    /// the fields declared `below_nyquist`. `build()` calls it after
    /// [`check_params`](Params::check_params), with its context's `dt`.
    fn check_at_rate(&self, dt: f64) -> Result<(), ParamError> {
        let _ = dt;
        Ok(())
    }
}

/// A type that can describe its YAML form as a JSON Schema (derived by
/// `#[derive(Params)]`; implement it by hand for types with a custom serde form).
pub trait ParamSchema {
    /// The JSON Schema (draft 7) of a value of this type.
    fn param_schema() -> Value;
}

/// Documentation of a parameter, for `nanomotion blocks` and the schema.
#[derive(Debug, Clone)]
pub struct ParamDoc {
    /// Field name in YAML.
    pub name: &'static str,
    /// Unit and meaning, with the thesis symbol where one exists.
    pub doc: &'static str,
    /// Default, if the field is optional, as shown to a reader.
    pub default: Option<String>,
    /// Declared bounds in words (`> 0`, `in [1, 1024]`).
    pub bounds: Vec<String>,
    /// JSON Schema of the value (description, default and bounds included).
    pub schema: Value,
    /// Whether the field must be given.
    pub required: bool,
    /// Other spellings the field accepts.
    pub aliases: &'static [&'static str],
    /// Whether the field's own fields are flattened into the block's map.
    pub flatten: bool,
}

impl ParamDoc {
    /// A parameter documented by hand (blocks not yet derived): no schema beyond
    /// its description, never required by the schema (the block checks).
    pub fn hand_written(
        name: &'static str,
        doc: &'static str,
        default: Option<&'static str>,
    ) -> Self {
        Self {
            name,
            doc,
            default: default.map(String::from),
            bounds: Vec::new(),
            schema: json!({ "description": doc }),
            required: false,
            aliases: &[],
            flatten: false,
        }
    }
}

/// Documentation of a block type, registered with [`inventory`] (by
/// `#[derive(Params)]` with `#[block(…)]`, or by hand with [`submit_block_doc!`](crate::submit_block_doc))
/// so that `nanomotion blocks` and `nanomotion schema` list it.
#[derive(Debug, Clone, Copy)]
pub struct BlockDoc {
    /// The `type:` tag.
    pub type_name: &'static str,
    /// The role of the block.
    pub role: Role,
    /// One line saying what it does.
    pub summary: &'static str,
    /// Port summary, e.g. `"u[n] -> y[n]"`.
    pub ports: &'static str,
    /// The parameters.
    pub params: fn() -> Vec<ParamDoc>,
    /// Whether unknown parameters are refused (`deny_unknown_fields`): the schema
    /// then refuses them too.
    pub closed: bool,
    /// The parameters that may change while the graph runs
    /// ([`DeclaredBlock::LIVE_PARAMS`](crate::block::DeclaredBlock::LIVE_PARAMS)).
    pub live: &'static [&'static str],
}

inventory::collect!(BlockDoc);

impl BlockDoc {
    /// The parameters' documentation.
    pub fn param_docs(&self) -> Vec<ParamDoc> {
        (self.params)()
    }

    /// The listing of `nanomotion blocks`: a header line, the ports, one line per
    /// parameter (name, meaning, bounds, default).
    pub fn describe(&self) -> String {
        let mut s = format!(
            "{} ({}): {}\n    ports: {}\n",
            self.type_name,
            self.role.as_str(),
            self.summary,
            self.ports
        );
        if !self.live.is_empty() {
            s.push_str(&format!(
                "    live: {} (may change while the graph runs: `set BLOCK.PARAM=VALUE`)\n",
                self.live.join(", ")
            ));
        }
        for p in self.param_docs() {
            let mut line = format!("    {:<22} {}", p.name, p.doc);
            if let Some(c) = choices(&p.schema) {
                line.push_str(&format!(" [{c}]"));
            }
            for a in p.aliases {
                line.push_str(&format!(" (also `{a}`)"));
            }
            if !p.bounds.is_empty() {
                line.push_str(&format!(" [{}]", p.bounds.join(", ")));
            }
            if let Some(d) = &p.default {
                line.push_str(&format!(" [default {d}]"));
            }
            s.push_str(&line);
            s.push('\n');
        }
        s
    }

    /// The JSON Schema of a block of this type: the keys `entry` (a graph's block
    /// entry has `name` and `rate_hz`: [`BlockSpec`](crate::graph::BlockSpec)'s
    /// fields; none for a block written inline), `type` and the parameters.
    pub fn schema(&self, entry: &[ParamDoc]) -> Value {
        let params = self.param_docs();
        let mut props = Map::new();
        let mut required = Vec::new();
        add_properties(&mut props, &mut required, entry);
        required.push(json!("type"));
        props.insert(
            "type".into(),
            json!({ "const": self.type_name, "description": self.summary }),
        );
        let closed = self.closed && !params.iter().any(|p| p.flatten);
        add_properties(&mut props, &mut required, &params);
        json!({
            "type": "object",
            "title": self.type_name,
            "description": format!("{} ({}; ports: {})", self.summary, self.role.as_str(), self.ports),
            "properties": props,
            "required": required,
            "additionalProperties": !closed,
        })
    }
}

/// The choices of an enumerated parameter, as a reader writes them: plain
/// names (`a | b | c`); an internally tagged enum's forms with their fields
/// (`{kind: table, x, gain} | {kind: power_db, a, b, c}`); an externally
/// tagged one's names and forms (`flat | {grating: {pitch_m, duty}}`). An
/// optional value lists its present form's choices, a list its items'.
fn choices(schema: &Value) -> Option<String> {
    let mut s = schema;
    loop {
        match s.get("anyOf").and_then(Value::as_array) {
            // an optional value: its non-null branch
            Some(a) if a.len() == 2 && a[1].get("type") == Some(&json!("null")) => s = &a[0],
            Some(_) => break,
            None if s.get("type") == Some(&json!("array")) => s = s.get("items")?,
            None => break,
        }
    }
    if let Some(values) = s.get("enum").and_then(Value::as_array) {
        let names: Vec<&str> = values.iter().filter_map(Value::as_str).collect();
        return Some(names.join(" | "));
    }
    let forms: Vec<String> = s
        .get("anyOf")?
        .as_array()?
        .iter()
        .map(form)
        .collect::<Option<_>>()?;
    Some(forms.join(" | "))
}

/// One branch of an enumeration's schema as a reader writes it (see
/// [`choices`]); `None` for a branch that is not a variant (a plain value).
fn form(branch: &Value) -> Option<String> {
    if let Some(name) = branch.get("const").and_then(Value::as_str) {
        return Some(name.to_string());
    }
    let props = branch.get("properties")?.as_object()?;
    // the fields in declaration order (the required ones, as `required`
    // lists them), then those with a default
    let fields = |b: &Value, o: &Map<String, Value>, skip: &str| -> Vec<String> {
        let required: Vec<&str> = b
            .get("required")
            .and_then(Value::as_array)
            .map(|r| r.iter().filter_map(Value::as_str).collect())
            .unwrap_or_default();
        let optional = o
            .keys()
            .map(String::as_str)
            .filter(|k| !required.contains(k));
        required
            .iter()
            .copied()
            .chain(optional)
            .filter(|k| *k != skip)
            .map(String::from)
            .collect()
    };
    // internally tagged: the tag is the property with a constant value
    if let Some((tag, name)) = props
        .iter()
        .find_map(|(k, v)| Some((k.as_str(), v.get("const")?.as_str()?)))
    {
        let mut parts = vec![format!("{tag}: {name}")];
        parts.extend(fields(branch, props, tag));
        return Some(format!("{{{}}}", parts.join(", ")));
    }
    // externally tagged: one property, the variant's name, holding its data
    let [(name, content)] = props.iter().collect::<Vec<_>>()[..] else {
        return None;
    };
    let inner = match content.get("properties").and_then(Value::as_object) {
        Some(o) => format!("{{{}}}", fields(content, o, "").join(", ")),
        None => "…".to_string(),
    };
    Some(format!("{{{name}: {inner}}}"))
}

fn add_properties(props: &mut Map<String, Value>, required: &mut Vec<Value>, params: &[ParamDoc]) {
    for p in params.iter().filter(|p| !p.flatten) {
        props.insert(p.name.into(), p.schema.clone());
        for a in p.aliases {
            props.insert((*a).into(), p.schema.clone());
        }
        if p.required && p.aliases.is_empty() {
            required.push(json!(p.name));
        }
    }
}

/// Register a [`BlockDoc`] by hand: for blocks whose parameters are not (yet)
/// derived. Accepts a `BlockDoc` value, or the older literal form with a
/// `params: &[ParamDoc { name, doc, default }]` list:
///
/// ```
/// use nanomotion_core::{BlockDoc, ParamDoc, Role};
/// nanomotion_core::submit_block_doc! {
///     BlockDoc {
///         type_name: "doc_example",
///         role: Role::Math,
///         summary: "an example",
///         params: &[ParamDoc { name: "k", doc: "gain (-)", default: None }],
///         ports: "u -> y",
///     }
/// }
/// ```
#[macro_export]
macro_rules! submit_block_doc {
    ($bd:path {
        type_name: $t:expr,
        role: $r:expr,
        summary: $s:expr,
        params: &[$($pd:path { name: $n:expr, doc: $d:expr, default: $def:expr $(,)? }),* $(,)?],
        ports: $p:expr $(,)?
    }) => {
        const _: () = {
            // The literal's type names, used (they are imported for it).
            #[allow(dead_code)]
            fn names() {
                let _: ::core::option::Option<$bd> = ::core::option::Option::None;
                $(let _: ::core::option::Option<$pd> = ::core::option::Option::None;)*
            }
            fn params() -> ::std::vec::Vec<$crate::ParamDoc> {
                ::std::vec![$($crate::ParamDoc::hand_written($n, $d, $def)),*]
            }
            $crate::__private::inventory::submit! {
                $crate::BlockDoc {
                    type_name: $t,
                    role: $r,
                    summary: $s,
                    ports: $p,
                    params,
                    closed: false,
                    live: &[],
                }
            }
        };
    };
    ($doc:expr) => {
        $crate::__private::inventory::submit! { $doc }
    };
}

/// Every registered block type that declares live parameters, sorted by type
/// name, in one line: `` `gain` `k`; `pi` `kp`, `zero_hz`; … `` — what
/// `nanomotion rt` says a graph without any could have, and what
/// docs/realtime.md lists (a test holds the two to this).
pub fn live_params_by_type() -> String {
    block_docs()
        .iter()
        .filter(|d| !d.live.is_empty())
        .map(|d| {
            let params: Vec<String> = d.live.iter().map(|p| format!("`{p}`")).collect();
            format!("`{}` {}", d.type_name, params.join(", "))
        })
        .collect::<Vec<_>>()
        .join("; ")
}

/// All registered block documentation, sorted by type name.
pub fn block_docs() -> Vec<&'static BlockDoc> {
    let mut v: Vec<&'static BlockDoc> = inventory::iter::<BlockDoc>.into_iter().collect();
    v.sort_by_key(|d| d.type_name);
    v
}

/// A check's error placed within `field`: its own field after a dot
/// (`topography` + `duty` → `topography.duty`), an entry's index directly
/// (`schedule` + `[1].x` → `schedule[1].x`), an unnamed value (a list's
/// length, checked by a wrapper of the list) as `field` itself.
pub fn within(field: &str, r: Result<(), ParamError>) -> Result<(), ParamError> {
    r.map_err(|mut e| {
        e.field = if e.field.is_empty() {
            field.to_string()
        } else if e.field.starts_with('[') {
            format!("{field}{}", e.field)
        } else {
            format!("{field}.{}", e.field)
        };
        e
    })
}

/// One end of an interval: the value itself allowed (`Inclusive`: ≥ or ≤)
/// or not (`Exclusive`: > or <). Here, below `block`, so that the checks
/// (`block::check`, which re-exports it) and the schema share it without an
/// import cycle.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Limit<T> {
    /// The end belongs to the interval.
    Inclusive(T),
    /// The end does not belong to the interval.
    Exclusive(T),
}

/// `n` entries, with the noun in its number: `1 entry`, `3 entries`.
pub(crate) fn entries_of(n: i128) -> String {
    if n == 1 {
        "1 entry".into()
    } else {
        format!("{n} entries")
    }
}

/// How many entries a list may hold, in words (`at least 1 entry`, `2 to
/// 65 entries`, `exactly 3 entries`), from its declared ends (a strict end
/// is said as the whole number next to it). `None` when nothing bounds it.
pub fn entries_words(lo: Option<Limit<i128>>, hi: Option<Limit<i128>>) -> Option<String> {
    let (lo, hi) = whole_ends(lo, hi);
    Some(match (lo, hi) {
        (Some(l), Some(h)) if l == h => format!("exactly {}", entries_of(l)),
        (Some(l), Some(h)) => format!("{l} to {h} entries"),
        (Some(l), None) => format!("at least {}", entries_of(l)),
        (None, Some(h)) => format!("at most {}", entries_of(h)),
        (None, None) => return None,
    })
}

/// The ends of an interval of whole numbers, both inclusive (`> 0` is `≥ 1`,
/// `< 4` is `≤ 3`).
pub(crate) fn whole_ends(
    lo: Option<Limit<i128>>,
    hi: Option<Limit<i128>>,
) -> (Option<i128>, Option<i128>) {
    let lo = lo.map(|l| match l {
        Limit::Inclusive(x) => x,
        Limit::Exclusive(x) => x.saturating_add(1),
    });
    let hi = hi.map(|h| match h {
        Limit::Inclusive(x) => x,
        Limit::Exclusive(x) => x.saturating_sub(1),
    });
    (lo, hi)
}

/// Whether `value` lies within `lo` and `hi` (each end inclusive or
/// exclusive, either left out: no bound on that side).
pub(crate) fn admits<T: PartialOrd>(value: T, lo: Option<Limit<T>>, hi: Option<Limit<T>>) -> bool {
    let above = match lo {
        None => true,
        Some(Limit::Inclusive(l)) => value >= l,
        Some(Limit::Exclusive(l)) => value > l,
    };
    let below = match hi {
        None => true,
        Some(Limit::Inclusive(h)) => value <= h,
        Some(Limit::Exclusive(h)) => value < h,
    };
    above && below
}

/// Helpers the derive's generated code calls; not a stable API.
#[doc(hidden)]
pub mod __derive {
    pub use super::Limit;
    use super::{ParamDoc, ParamSchema, add_properties};
    use crate::error::ParamError;
    use serde::Serialize;
    pub use serde_json::Value;
    use serde_json::{Map, json};
    use std::marker::PhantomData;

    pub fn number() -> Value {
        json!({ "type": "number" })
    }

    /// What a repeated port group `for i in 0..len(list)` counts: the
    /// entries of a list, the characters of a string (one input of `sum` per
    /// sign).
    pub trait PortCount {
        /// How many ports.
        fn port_count(&self) -> usize;
    }
    impl<T> PortCount for Vec<T> {
        fn port_count(&self) -> usize {
            self.len()
        }
    }
    impl<T, const N: usize> PortCount for [T; N] {
        fn port_count(&self) -> usize {
            N
        }
    }
    impl PortCount for String {
        fn port_count(&self) -> usize {
            self.chars().count()
        }
    }
    /// The ports of a group `for i in 0..len(list)`.
    pub fn port_count(list: &impl PortCount) -> usize {
        list.port_count()
    }
    pub fn unsigned() -> Value {
        json!({ "type": "integer", "minimum": 0 })
    }
    pub fn integer() -> Value {
        json!({ "type": "integer" })
    }
    pub fn boolean() -> Value {
        json!({ "type": "boolean" })
    }
    pub fn string() -> Value {
        json!({ "type": "string" })
    }
    pub fn any() -> Value {
        json!({})
    }
    pub fn block_ref() -> Value {
        json!({ "$ref": "#/definitions/block" })
    }
    pub fn array(items: Value) -> Value {
        json!({ "type": "array", "items": items })
    }
    pub fn fixed_array(items: Value, n: usize) -> Value {
        json!({ "type": "array", "items": items, "minItems": n, "maxItems": n })
    }
    pub fn nullable(inner: Value) -> Value {
        json!({ "anyOf": [inner, { "type": "null" }] })
    }
    pub fn map(values: Value) -> Value {
        json!({ "type": "object", "additionalProperties": values })
    }

    /// Autoref probe: the schema of `T` if it implements [`ParamSchema`], else
    /// any value (a type with a custom serde form that describes nothing).
    pub struct Probe<T: ?Sized>(PhantomData<T>);
    impl<T: ?Sized> Probe<T> {
        pub fn new() -> Self {
            Self(PhantomData)
        }
    }
    impl<T: ?Sized> Default for Probe<T> {
        fn default() -> Self {
            Self::new()
        }
    }
    pub trait ViaSchema {
        fn schema(&self) -> Value;
    }
    impl<T: ParamSchema + ?Sized> ViaSchema for &Probe<T> {
        fn schema(&self) -> Value {
            T::param_schema()
        }
    }
    pub trait ViaAny {
        fn schema(&self) -> Value;
    }
    impl<T: ?Sized> ViaAny for Probe<T> {
        fn schema(&self) -> Value {
            any()
        }
    }

    fn num(x: f64) -> Value {
        if x.fract() == 0.0 && x.abs() < 9.0e15 {
            json!(x as i64)
        } else {
            json!(x)
        }
    }

    fn fmt_num(x: f64) -> String {
        if x.fract() == 0.0 && x.abs() < 9.0e15 {
            format!("{}", x as i64)
        } else {
            format!("{x}")
        }
    }

    /// Add a lower (`exclusive`: strict) and/or upper (inclusive) bound to `s`
    /// (see [`limits`]).
    pub fn bound(
        s: &mut Value,
        words: &mut Vec<String>,
        min: Option<f64>,
        exclusive: bool,
        max: Option<f64>,
    ) {
        let lo = min.map(|x| {
            if exclusive {
                Limit::Exclusive(x)
            } else {
                Limit::Inclusive(x)
            }
        });
        limits(s, words, lo, max.map(Limit::Inclusive));
    }

    /// Add a lower and/or upper bound, each inclusive (`minimum`, `maximum`)
    /// or exclusive (`exclusiveMinimum`, `exclusiveMaximum`), to `s`, into the
    /// non-null branch of an optional value and the items of an array; its
    /// words to `words` (`1 to 1024` for two inclusive ends as before; `> 0`,
    /// `≤ 1`, `in (0, 1]` otherwise).
    pub fn limits(
        s: &mut Value,
        words: &mut Vec<String>,
        lo: Option<Limit<f64>>,
        hi: Option<Limit<f64>>,
    ) {
        let split = |l: Limit<f64>| match l {
            Limit::Inclusive(x) => (x, false),
            Limit::Exclusive(x) => (x, true),
        };
        let lo = lo.map(split);
        let hi = hi.map(split);
        let mut each = false;
        let mut target = &mut *s;
        loop {
            if target.get("anyOf").is_some() {
                target = &mut target["anyOf"][0];
            } else if target.get("type") == Some(&json!("array")) {
                each = true;
                target = &mut target["items"];
            } else {
                break;
            }
        }
        let text = match (lo, hi) {
            (Some((l, false)), Some((h, false))) => format!("{} to {}", fmt_num(l), fmt_num(h)),
            (Some((l, lx)), Some((h, hx))) => format!(
                "in {}{}, {}{}",
                if lx { '(' } else { '[' },
                fmt_num(l),
                fmt_num(h),
                if hx { ')' } else { ']' }
            ),
            (Some((l, true)), None) => format!("> {}", fmt_num(l)),
            (Some((l, false)), None) => format!("≥ {}", fmt_num(l)),
            (None, Some((h, true))) => format!("< {}", fmt_num(h)),
            (None, Some((h, false))) => format!("≤ {}", fmt_num(h)),
            (None, None) => return,
        };
        if let Some(o) = target.as_object_mut() {
            if let Some((l, exclusive)) = lo {
                let key = if exclusive {
                    "exclusiveMinimum"
                } else {
                    "minimum"
                };
                o.insert(key.into(), num(l));
            }
            if let Some((h, exclusive)) = hi {
                let key = if exclusive {
                    "exclusiveMaximum"
                } else {
                    "maximum"
                };
                o.insert(key.into(), num(h));
            }
        }
        words.push(if each { format!("each {text}") } else { text });
    }

    /// A default value as JSON (`None` if it cannot be written).
    pub fn some_value<T: Serialize>(v: &T) -> Option<Value> {
        Some(serde_json::to_value(v).unwrap_or(Value::Null))
    }

    /// A value as a reader sees it: numbers without a trailing `.0`, strings
    /// without quotes, `none` for null.
    pub fn show(v: &Value) -> String {
        match v {
            Value::Null => "none".into(),
            Value::Bool(b) => b.to_string(),
            Value::Number(n) => match n.as_f64() {
                Some(x) if n.is_f64() => {
                    if x != 0.0 && (x.abs() < 1e-3 || x.abs() >= 1e7) {
                        format!("{x:e}")
                    } else {
                        fmt_num(x)
                    }
                }
                _ => n.to_string(),
            },
            Value::String(s) => s.clone(),
            Value::Array(a) => format!("[{}]", a.iter().map(show).collect::<Vec<_>>().join(", ")),
            Value::Object(o) => format!(
                "{{{}}}",
                o.iter()
                    .map(|(k, v)| format!("{k}: {}", show(v)))
                    .collect::<Vec<_>>()
                    .join(", ")
            ),
        }
    }

    /// The words of how many entries a nested type's list holds (a
    /// `#[serde(transparent)]` wrapper with `len(…)`), read back from its
    /// schema's `minItems`/`maxItems`, so that the field holding it says them.
    pub fn nested_entries(s: &Value, words: &mut Vec<String>) {
        let mut target = s;
        while let Some(a) = target.get("anyOf").and_then(Value::as_array) {
            target = &a[0];
        }
        let end = |k: &str| {
            target
                .get(k)
                .and_then(Value::as_i64)
                .map(|x| Limit::Inclusive(x as i128))
        };
        if target.get("type") == Some(&json!("array")) {
            words.extend(super::entries_words(end("minItems"), end("maxItems")));
        }
    }

    /// A parameter's documentation, from what the derive read.
    #[allow(clippy::too_many_arguments)]
    pub fn param(
        name: &'static str,
        doc: &'static str,
        default: Option<Value>,
        default_doc: Option<&'static str>,
        mut schema: Value,
        bounds: Vec<String>,
        aliases: &'static [&'static str],
        flatten: bool,
    ) -> ParamDoc {
        if let Some(o) = schema.as_object_mut() {
            if !doc.is_empty() {
                o.insert("description".into(), json!(doc));
            }
            if let Some(d) = &default
                && !d.is_null()
            {
                o.insert("default".into(), d.clone());
            }
        }
        ParamDoc {
            name,
            doc,
            required: default.is_none(),
            default: match (default_doc, &default) {
                (Some(words), _) => Some(words.to_string()),
                (None, Some(v)) => Some(show(v)),
                (None, None) => None,
            },
            bounds,
            schema,
            aliases,
            flatten,
        }
    }

    /// A bound error with the field's `hint = "…"` added to its fix.
    pub fn hint(mut e: ParamError, hint: &str) -> ParamError {
        e.fix = format!("{}, {hint}", e.fix);
        e
    }

    /// A nested parameter struct's error, its field placed within `field`
    /// (see [`within`](super::within)).
    pub fn nested(field: &str, r: Result<(), ParamError>) -> Result<(), ParamError> {
        super::within(field, r)
    }

    /// Add to `s` how many entries a list holds (`minItems`, `maxItems`, into
    /// the non-null branch of an optional list), and its words to `words`.
    pub fn entries(
        s: &mut Value,
        words: &mut Vec<String>,
        lo: Option<Limit<i128>>,
        hi: Option<Limit<i128>>,
    ) {
        let (min, max) = super::whole_ends(lo, hi);
        let mut target = &mut *s;
        while target.get("anyOf").is_some() {
            target = &mut target["anyOf"][0];
        }
        if let Some(o) = target.as_object_mut() {
            if let Some(l) = min {
                o.insert("minItems".into(), json!(l.max(0)));
            }
            if let Some(h) = max {
                o.insert("maxItems".into(), json!(h.max(0)));
            }
        }
        words.extend(super::entries_words(lo, hi));
    }

    /// The schema of a parameter struct.
    pub fn object(description: &str, params: &[ParamDoc], closed: bool) -> Value {
        let mut props = Map::new();
        let mut required = Vec::new();
        add_properties(&mut props, &mut required, params);
        let closed = closed && !params.iter().any(|p| p.flatten);
        let mut s = json!({
            "type": "object",
            "properties": props,
            "additionalProperties": !closed,
        });
        if !required.is_empty() {
            s["required"] = Value::Array(required);
        }
        if !description.is_empty() {
            s["description"] = json!(description);
        }
        s
    }

    /// How an enum is written (serde's representations).
    pub enum Tagging {
        /// `variant` or `{variant: content}`.
        External,
        /// `{tag: variant, ...fields}`.
        Internal(&'static str),
        /// The content alone.
        Untagged,
    }

    /// One variant (or one alias of it).
    pub struct Variant {
        pub name: &'static str,
        pub doc: &'static str,
        /// The schema of the variant's data, `None` for a unit variant.
        pub content: Option<Value>,
    }

    /// The schema of an enum.
    pub fn enumeration(
        description: &str,
        tagging: Tagging,
        variants: Vec<Variant>,
        closed: bool,
    ) -> Value {
        let _ = closed;
        let mut s = if variants.iter().all(|v| v.content.is_none())
            && !matches!(tagging, Tagging::Internal(_))
        {
            json!({ "type": "string", "enum": variants.iter().map(|v| v.name).collect::<Vec<_>>() })
        } else {
            let branches: Vec<Value> = variants
                .into_iter()
                .map(|v| {
                    let mut b = match (&tagging, v.content) {
                        (Tagging::External, None) => json!({ "const": v.name }),
                        (Tagging::External, Some(c)) => json!({
                            "type": "object",
                            "properties": { v.name: c },
                            "required": [v.name],
                            "additionalProperties": false,
                        }),
                        (Tagging::Untagged, None) => json!({ "type": "null" }),
                        (Tagging::Untagged, Some(c)) => c,
                        (Tagging::Internal(tag), content) => {
                            let mut c = content.unwrap_or_else(|| {
                                json!({ "type": "object", "properties": {}, "additionalProperties": false })
                            });
                            if c.get("properties").is_some() {
                                c["properties"][*tag] = json!({ "const": v.name });
                                let mut req = c
                                    .get("required")
                                    .cloned()
                                    .unwrap_or_else(|| json!([]));
                                if let Some(r) = req.as_array_mut() {
                                    r.insert(0, json!(tag));
                                }
                                c["required"] = req;
                                c
                            } else {
                                // newtype of a type without properties: only the tag is known
                                json!({
                                    "type": "object",
                                    "properties": { *tag: { "const": v.name } },
                                    "required": [tag],
                                })
                            }
                        }
                    };
                    if !v.doc.is_empty()
                        && let Some(o) = b.as_object_mut()
                    {
                        o.insert("description".into(), json!(v.doc));
                    }
                    b
                })
                .collect();
            json!({ "anyOf": branches })
        };
        if !description.is_empty() {
            s["description"] = json!(description);
        }
        s
    }
}
