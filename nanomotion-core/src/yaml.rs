//! The one place that talks to the YAML crate (`serde-saphyr`, pinned): its major
//! versions move fast, so everything else goes through these two functions.

use crate::error::GraphError;
use serde::de::DeserializeOwned;

/// Parse YAML text into `T`. `origin` (a file name) prefixes error messages, which
/// carry line and column and a snippet of the offending text.
///
/// Non-finite floats (`.nan`, `.inf`) are let through the parser on purpose (typetag
/// buffers maps and would otherwise report them without a location): every block
/// validates its own fields and names the one that is not finite.
pub fn from_str<T: DeserializeOwned>(text: &str, origin: &str) -> Result<T, GraphError> {
    let opts = serde_saphyr::options!(
        non_finite_float_policy: serde_saphyr::NonFiniteFloatPolicy::PassThrough,
    );
    serde_saphyr::from_str_with_options(text, opts).map_err(|e| {
        // Inside a map the parser buffers (a block entry, a tagged config), an
        // unknown field or a wrong-type value is reported at the map's first
        // line: name the field at its own line.
        crate::graph::locate_field(
            GraphError::Parse {
                origin: origin.to_string(),
                message: plain_message(&e.to_string(), origin),
            },
            text,
        )
    })
}

/// The parser's message in the user's terms: the snippet names the file instead
/// of `<input>`, no second `error:` after the file name, and the parser's
/// internals (its option and function names, its budget's `Debug` output) are
/// replaced by what they mean for a graph file.
pub(crate) fn plain_message(message: &str, origin: &str) -> String {
    let mut m = message
        .strip_prefix("error: ")
        .unwrap_or(message)
        .replace("--> <input>", &format!("--> {origin}"))
        .replace(
            ", set DuplicateKeyPolicy in Options if acceptable",
            " (each key may appear once in a map: remove or merge the repeated one)",
        )
        .replace(
            "use from_str_multiple or from_str_multiple_with_options",
            "a graph file holds one YAML document: remove the `---` separators and what follows",
        );
    for (debug, plain) in [
        ("Nodes", "values"),
        ("Events", "parser events"),
        ("Aliases", "alias uses (`*name`)"),
        ("Anchors", "anchors (`&name`)"),
        ("Depth", "levels of nesting"),
        ("Documents", "documents"),
        ("ScalarBytes", "bytes of text in values"),
        ("MergeKeys", "merge keys (`<<`)"),
    ] {
        let field = debug.to_lowercase();
        let field = match debug {
            "ScalarBytes" => "total_scalar_bytes".to_string(),
            "MergeKeys" => "merge_keys".to_string(),
            _ => field,
        };
        let prefix = format!("budget breached: {debug} {{ {field}: ");
        while let Some(start) = m.find(&prefix) {
            let rest = &m[start + prefix.len()..];
            let Some(end) = rest.find(" }") else { break };
            let count = rest[..end].to_string();
            m = format!(
                "{}the file is too large or too deeply nested for a graph ({count} {plain}; is it the right file?){}",
                &m[..start],
                &rest[end + 2..]
            );
        }
    }
    m
}

/// Serialise `value` as YAML.
pub fn to_string<T: serde::Serialize>(value: &T) -> Result<String, GraphError> {
    serde_saphyr::to_string(value).map_err(|e| GraphError::Parse {
        origin: "serialisation".into(),
        message: e.to_string(),
    })
}

/// Parse YAML text into a JSON value as a YAML 1.2 editor reads it (the YAML
/// language server behind `# yaml-language-server: $schema=…`): only
/// `true`/`false` are booleans, so a block named `y` or a column `n` stays a
/// string. For checking files against `nanomotion schema`.
pub fn to_json_value(text: &str, origin: &str) -> Result<serde_json::Value, GraphError> {
    let opts = serde_saphyr::options!(strict_booleans: true);
    serde_saphyr::from_str_with_options(text, opts).map_err(|e| GraphError::Parse {
        origin: origin.to_string(),
        message: plain_message(&e.to_string(), origin),
    })
}
