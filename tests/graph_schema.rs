//! `nanomotion schema`: the JSON Schema of a graph file, derived from the blocks'
//! parameter structs. Every shipped example graph validates against it; files
//! with a typo'd parameter or a value outside a declared bound do not.

use nanomotion::core::graph::graph_schema;
use serde_json::Value;
use std::path::{Path, PathBuf};

fn schema() -> Value {
    nanomotion::link_plugins();
    // A third-party block is in the schema by linking alone.
    let _ = std::any::type_name::<third_party_block::MovingAverage>();
    graph_schema()
}

fn validator() -> jsonschema::Validator {
    jsonschema::draft7::new(&schema()).expect("the graph schema is a valid draft-7 schema")
}

/// Every `.yaml` below `dir` (recursively), sorted.
fn yaml_files(dir: &Path, out: &mut Vec<PathBuf>) {
    let Ok(entries) = std::fs::read_dir(dir) else {
        return;
    };
    for e in entries.flatten() {
        let p = e.path();
        if p.is_dir() {
            if p.file_name().is_some_and(|n| n != "target") {
                yaml_files(&p, out);
            }
        } else if p.extension().is_some_and(|x| x == "yaml" || x == "yml") {
            out.push(p);
        }
    }
    out.sort();
}

fn read_yaml(path: &Path) -> Value {
    let text = std::fs::read_to_string(path).unwrap();
    nanomotion::core::yaml::to_json_value(&text, &path.display().to_string())
        .unwrap_or_else(|e| panic!("{}: {e}", path.display()))
}

fn errors(v: &jsonschema::Validator, doc: &Value) -> Vec<String> {
    v.iter_errors(doc)
        .map(|e| format!("{} at {}", e, e.instance_path()))
        .collect()
}

#[test]
fn every_shipped_graph_validates_against_the_schema() {
    let v = validator();
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let mut files = Vec::new();
    yaml_files(&root.join("examples"), &mut files);
    yaml_files(&root.join("plugins"), &mut files);
    let (mut graphs, mut block_lists) = (0, 0);
    let mut failures = Vec::new();
    let mut validated = Vec::new();
    for path in &files {
        let doc = read_yaml(path);
        let errs = match &doc {
            // a graph
            Value::Object(m) if m.contains_key("blocks") => {
                graphs += 1;
                validated.push(path.strip_prefix(root).unwrap().to_path_buf());
                errors(&v, &doc)
            }
            // a list of block entries (the target of `- include:`)
            Value::Array(entries) => {
                block_lists += 1;
                validated.push(path.strip_prefix(root).unwrap().to_path_buf());
                let wrapped = serde_json::json!({ "base_rate_hz": 1.0, "blocks": entries });
                errors(&v, &wrapped)
            }
            // sweep studies, identification data, synthesis configurations
            _ => continue,
        };
        if !errs.is_empty() {
            failures.push(format!("{}:\n  {}", path.display(), errs.join("\n  ")));
        }
    }
    assert!(failures.is_empty(), "{}", failures.join("\n"));
    // The examples folder holds 20 graphs and a synthesised controller (a block
    // list); a glob that found nothing must not pass.
    assert!(graphs >= 20, "only {graphs} graphs found");
    assert!(block_lists >= 1, "no block list found");
    // Subfolders of examples/ (one and two levels down) and the plugins' own
    // example graphs are read too, not only examples/*.yaml.
    for nested in [
        "examples/compensate/controller.yaml",
        "examples/realtime/quickstart_plant.yaml",
        "examples/mimo/synthesised/controller.yaml",
    ] {
        assert!(
            validated.iter().any(|p| p == Path::new(nested)),
            "{nested} was not validated"
        );
    }
    assert!(validated.iter().any(|p| p.starts_with("plugins")));
}

#[test]
fn schema_lists_every_registered_block_including_third_party_ones() {
    let s = schema();
    let types: Vec<&str> = s["definitions"]["block"]["oneOf"]
        .as_array()
        .unwrap()
        .iter()
        .map(|b| b["properties"]["type"]["const"].as_str().unwrap())
        .collect();
    for t in nanomotion::core::block::registered_types() {
        assert!(types.contains(&t.as_str()), "`{t}` missing from the schema");
    }
    assert!(types.contains(&"moving_average"));
    assert!(types.contains(&"gain"));
}

#[test]
fn schema_refuses_unknown_parameters_and_values_outside_declared_bounds() {
    let v = validator();
    let graph = |block: &str| -> Value {
        let text =
            format!("base_rate_hz: 1000\nduration_s: 1\nblocks:\n  - {{ name: b, {block} }}\n");
        nanomotion::core::yaml::to_json_value(&text, "test").unwrap()
    };
    assert!(v.is_valid(&graph("type: gain, k: 2.0, width: 3")));
    // a typo in a parameter name
    assert!(!v.is_valid(&graph("type: gain, kk: 2.0")));
    // a required parameter missing
    assert!(!v.is_valid(&graph("type: gain")));
    // #[param(width)]: 1 to 1024
    assert!(!v.is_valid(&graph("type: gain, k: 1, width: 0")));
    assert!(!v.is_valid(&graph("type: gain, k: 1, width: 1025")));
    // #[param(positive)] on an optional value
    assert!(!v.is_valid(&graph(
        "type: lead_lag, zero_hz: 10, pole_hz: 100, prewarp_hz: -1"
    )));
    // an enumerated value
    assert!(!v.is_valid(&graph(
        "type: pi, kp: 1, zero_hz: 1, anti_windup: sometimes"
    )));
    assert!(v.is_valid(&graph("type: pi, kp: 1, zero_hz: 1, anti_windup: none")));
    // an unknown block type, and an unknown graph-level key
    assert!(!v.is_valid(&graph("type: no_such_block")));
    let mut g = graph("type: gain, k: 1");
    g["sead"] = 1.into();
    assert!(!v.is_valid(&g));
}

/// The graph level of the schema is `GraphSpec` with the compiler's limits:
/// what the schema refuses there, building the graph refuses too, naming the key.
#[test]
fn graph_level_limits_are_the_compilers() {
    use nanomotion::core::graph::{GraphSpec, MAX_RATE_HZ, MAX_TITLE_CHARS};
    let v = validator();
    let text = |settings: &str| {
        format!(
            "{settings}\nduration_s: 0.01\nblocks:\n  - {{ name: c, type: constant, value: 1 }}\n"
        )
    };
    let ok = text("base_rate_hz: 1000");
    assert!(v.is_valid(&nanomotion::core::yaml::to_json_value(&ok, "t").unwrap()));
    GraphSpec::from_yaml(&ok, "t").unwrap().build().unwrap();
    let long_title = format!(
        "base_rate_hz: 1000\ntitle: {}",
        "x".repeat(MAX_TITLE_CHARS + 1)
    );
    for (bad, key) in [
        (
            text(&format!("base_rate_hz: {:e}", 2.0 * MAX_RATE_HZ)),
            "base_rate_hz",
        ),
        (text("base_rate_hz: 0"), "base_rate_hz"),
        (text(&long_title), "title"),
    ] {
        let doc = nanomotion::core::yaml::to_json_value(&bad, "t").unwrap();
        assert!(!v.is_valid(&doc), "the schema accepts {bad}");
        let e = match GraphSpec::from_yaml(&bad, "t") {
            Ok(g) => g.build().map(|_| ()).expect_err("build refuses it too"),
            Err(e) => e,
        };
        assert!(e.to_string().contains(key), "{key}: {e}");
    }
}

#[test]
fn the_same_bound_refuses_the_value_when_the_block_is_built() {
    // One declaration: what the schema refuses, `build()` refuses with the
    // field named.
    use nanomotion::core::{Block, BuildContext};
    let mut b: Box<dyn Block> =
        nanomotion::core::yaml::from_str("type: gain\nk: 1\nwidth: 1025\n", "test").unwrap();
    let e = b.build(&BuildContext::new("g", 1e-3, 0)).unwrap_err();
    assert_eq!(e.field, "width");
    assert!(e.to_string().contains("[1, 1024]"), "{e}");
}

#[test]
fn the_cli_writes_the_schema_as_json() {
    let o = std::process::Command::new(env!("CARGO_BIN_EXE_nanomotion"))
        .arg("schema")
        .output()
        .expect("binary runs");
    assert!(o.status.success());
    let s: Value = serde_json::from_slice(&o.stdout).expect("`nanomotion schema` prints JSON");
    assert_eq!(s["$schema"], "http://json-schema.org/draft-07/schema#");
    let types: Vec<&str> = s["definitions"]["block_entry"]["oneOf"]
        .as_array()
        .unwrap()
        .iter()
        .filter_map(|b| b["properties"]["type"]["const"].as_str())
        .collect();
    for t in [
        "pid",
        "walking_piezo_stage",
        "dvrc",
        "hysteresis",
        "mimo_controller",
    ] {
        assert!(types.contains(&t), "`{t}` missing from `nanomotion schema`");
    }
    jsonschema::draft7::new(&s).expect("a valid draft-7 schema");
}
