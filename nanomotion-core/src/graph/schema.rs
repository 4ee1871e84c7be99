//! `nanomotion schema`: the JSON Schema (draft 7) of a whole graph file.
//!
//! Nothing in it is written twice: the graph-level keys are
//! [`GraphSpec`]'s fields and those of its parts (`Connection`, `ScoreSpec`,
//! `CompareSpec`, `Require`), each block entry's `name` and `rate_hz` are
//! [`BlockSpec`]'s, and every block type is its registered
//! [`BlockDoc`](crate::doc::BlockDoc) — all from `#[derive(Params)]`. The bounds
//! of the graph-level numbers are the limits of `spec.rs` (`MIN_RATE_HZ`, …),
//! which the compiler checks. Only the `- include: FILE` entry is described
//! here: it is spliced into the text before parsing
//! ([`include`](crate::graph::include)) and has no type of its own.

use super::spec::{BlockSpec, GraphSpec};
use crate::doc::{ParamSchema, Params, block_docs};
use serde_json::{Value, json};

/// The JSON Schema (draft 7) of a whole graph file (`nanomotion schema`), with
/// every block registered in this program (plugins and third-party crates that
/// are linked) as a `oneOf` on `type`.
pub fn graph_schema() -> Value {
    let docs = block_docs();
    let entry = BlockSpec::param_docs();
    let inline: Vec<Value> = docs.iter().map(|d| d.schema(&[])).collect();
    let mut entries: Vec<Value> = docs.iter().map(|d| d.schema(&entry)).collect();
    entries.push(json!({
        "type": "object",
        "title": "include",
        "description": "`- include: FILE`: the block entries of FILE (a YAML list), relative to this file's folder",
        "properties": { "include": { "type": "string" } },
        "required": ["include"],
        "additionalProperties": false,
    }));
    let mut schema = GraphSpec::param_schema();
    schema["$schema"] = json!("http://json-schema.org/draft-07/schema#");
    schema["title"] = json!("nanomotion graph");
    schema["description"] = json!(
        "A nanomotion controller graph (docs/graph-format.md); written by `nanomotion schema`."
    );
    schema["definitions"] = json!({
        "block": { "description": "a block inline (`type:` and its parameters)", "oneOf": inline },
        "block_entry": { "description": "a block of the graph, or `include: FILE`", "oneOf": entries },
    });
    schema
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::graph::{MAX_RATE_HZ, MIN_RATE_HZ};

    /// The graph level of the schema is `GraphSpec`: every field a property,
    /// exactly the fields without a default required, nothing else allowed, and
    /// the rate bounds the compiler's limits.
    #[test]
    fn the_graph_level_follows_graph_spec() {
        let s = graph_schema();
        let props = s["properties"].as_object().unwrap();
        let fields = GraphSpec::param_docs();
        let names: Vec<&str> = fields.iter().map(|p| p.name).collect();
        assert_eq!(
            names,
            [
                "title",
                "base_rate_hz",
                "duration_s",
                "seed",
                "strict_rates",
                "blocks",
                "connections",
                "log",
                "score",
                "compare",
                "require",
                "realtime",
                "units"
            ]
        );
        assert_eq!(props.len(), names.len());
        assert_eq!(s["required"], json!(["base_rate_hz", "blocks"]));
        assert_eq!(s["additionalProperties"], false);
        assert_eq!(props["base_rate_hz"]["minimum"], json!(MIN_RATE_HZ));
        assert_eq!(props["base_rate_hz"]["maximum"], json!(MAX_RATE_HZ));
        assert_eq!(props["seed"]["default"], 0);
        assert_eq!(props["strict_rates"]["default"], false);
        // `require:` is `Require`, its `loops` a map of `Bounds`
        let require = &props["require"]["anyOf"][0];
        assert_eq!(require["additionalProperties"], false);
        // its rustdoc example (a fenced YAML block) stays out of the description
        let text = require["description"].as_str().unwrap();
        assert!(text.starts_with("The `require:` section"), "{text}");
        assert!(
            !text.contains("```") && !text.contains("loops: pi"),
            "{text}"
        );
        let bounds = &require["properties"]["loops"]["additionalProperties"];
        assert!(bounds["properties"]["phase_margin_deg"].is_object());
        assert_eq!(bounds["additionalProperties"], false);
        // a score entry: `signal` required, `from_s` ≥ 0 with default 0
        let score = &props["score"]["items"];
        assert_eq!(score["required"], json!(["signal"]));
        assert_eq!(score["properties"]["from_s"]["minimum"], 0);
        assert_eq!(score["properties"]["from_s"]["default"], 0.0);
        // a block entry: BlockSpec's `name` (required) and `rate_hz`, then `type`
        let gain = s["definitions"]["block_entry"]["oneOf"]
            .as_array()
            .unwrap()
            .iter()
            .find(|b| b["title"] == "gain")
            .expect("the core's gain block");
        assert_eq!(gain["required"][0], "name");
        assert_eq!(gain["required"][1], "type");
        assert_eq!(gain["properties"]["rate_hz"]["minimum"], json!(MIN_RATE_HZ));
        assert_eq!(
            gain["properties"]["name"]["pattern"],
            format!(
                "^[A-Za-z0-9_-]{{1,{}}}$",
                crate::graph::MAX_BLOCK_NAME_CHARS
            )
        );
    }
}
