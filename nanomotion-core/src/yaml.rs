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
///
/// Booleans are YAML 1.2's, as editors and `nanomotion schema` read them: only
/// `true`/`false` (any case). YAML 1.1's `yes`/`no`/`on`/`off`/`y`/`n` are text,
/// so a block named `y` stays a name, and `strict_rates: yes` is an error that
/// names its line and says to write `true` — never a silent reading that an
/// editor would not share.
pub fn from_str<T: DeserializeOwned>(text: &str, origin: &str) -> Result<T, GraphError> {
    let opts = serde_saphyr::options!(
        non_finite_float_policy: serde_saphyr::NonFiniteFloatPolicy::PassThrough,
        strict_booleans: true,
    );
    serde_saphyr::from_str_with_options(text, opts).map_err(|e| {
        // Inside a map the parser buffers (a block entry, a tagged config), an
        // unknown field or a wrong-type value is reported at the map's first
        // line: name the field at its own line.
        with_boolean_fix(locate_field(
            GraphError::Parse {
                origin: origin.to_string(),
                message: plain_message(&e.to_string(), origin),
            },
            text,
        ))
    })
}

/// The words YAML 1.1 read as booleans and YAML 1.2 (graph files) reads as text.
const YAML11_BOOLEANS: [&str; 6] = ["yes", "no", "on", "off", "y", "n"];

/// A boolean written the YAML 1.1 way: say what to write instead. The parser
/// reports it as a strict-mode boolean (a graph-level key) or, inside a block's
/// buffered map, as text where a boolean was expected.
fn with_boolean_fix(e: GraphError) -> GraphError {
    let GraphError::Parse { origin, message } = e else {
        return e;
    };
    let strict = message.contains("invalid boolean (strict mode expects true/false)");
    let buffered = message
        .split("invalid type: string \"")
        .nth(1)
        .and_then(|r| r.split_once("\", expected a boolean"))
        .is_some_and(|(word, _)| YAML11_BOOLEANS.iter().any(|w| w.eq_ignore_ascii_case(word)));
    if !(strict || buffered) {
        return GraphError::Parse { origin, message };
    }
    let message = message.replace(
        "invalid boolean (strict mode expects true/false)",
        "not a boolean",
    );
    GraphError::Parse {
        origin,
        message: format!(
            "{message}\n  = fix: write `true` or `false` (graph files are YAML 1.2, where `yes`, `no`, `on`, `off`, `y` and `n` are text, as editors read them)"
        ),
    }
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

/// Where an unknown field is: (0-based line, 1-based column, what the parser
/// said without its locations), searching from the reported line on.
fn unknown_field_site(
    message: &str,
    text: &str,
    first_line: usize,
) -> Option<(usize, usize, String)> {
    let pos = message.find("unknown field `")?;
    let rest = &message[pos + "unknown field `".len()..];
    let field = &rest[..rest.find('`')?];
    let is_key_on = |line: &str| {
        line.match_indices(&format!("{field}:")).any(|(i, _)| {
            i == 0
                || line[..i]
                    .chars()
                    .next_back()
                    .is_some_and(|c| c == ' ' || c == '{' || c == ',' || c == '-' || c == '\t')
        })
    };
    let (n, line) = text
        .lines()
        .enumerate()
        .skip(first_line.saturating_sub(1))
        .find(|(_, l)| is_key_on(l))?;
    let first = message.lines().next().unwrap_or("");
    let what = first[first.find("unknown field `").unwrap_or(0)..]
        .split(" at line ")
        .next()
        .unwrap_or("")
        .to_string();
    let column = line
        .match_indices(&format!("{field}:"))
        .map(|(i, _)| i + 1)
        .next()
        .unwrap_or(1);
    Some((n, column, what))
}

/// Where a value of the wrong type is (audit D21): inside a block the parser
/// reports the entry's first line and the line after it, not the field; the
/// field is the key between them whose value is the one the parser quotes
/// (`invalid type: string "fast", expected f64`). Returns (0-based line,
/// 1-based column of the key, the message naming the field).
fn bad_value_site(message: &str, text: &str, first_line: usize) -> Option<(usize, usize, String)> {
    let first = message.lines().next()?;
    let from = first.find("invalid type: ")?;
    let mut parts = first[from..].split(" at line ");
    let what = parts.next()?;
    let last_line = parts
        .next()
        .and_then(|r| r.split(|c: char| !c.is_ascii_digit()).next())
        .and_then(|n| n.parse::<usize>().ok())
        .filter(|&l| l >= first_line)
        .unwrap_or(usize::MAX);
    let unexpected = &what["invalid type: ".len()..];
    let value = match unexpected.strip_prefix("string \"") {
        Some(r) => r.split('"').next()?,
        None => unexpected.split('`').nth(1)?,
    };
    for (n, line) in text
        .lines()
        .enumerate()
        .skip(first_line.saturating_sub(1))
        .take(last_line.saturating_sub(first_line.saturating_sub(1)))
    {
        for (i, _) in line.match_indices(':') {
            let key_start = line[..i]
                .rfind(|c: char| !(c.is_ascii_alphanumeric() || c == '_'))
                .map_or(0, |k| k + 1);
            let key = &line[key_start..i];
            let token = line[i + 1..]
                .split([',', '}', '#'])
                .next()
                .unwrap_or("")
                .trim()
                .trim_matches(|c| c == '"' || c == '\'');
            if !key.is_empty() && token == value {
                return Some((n, key_start + 1, format!("field `{key}`: {what}")));
            }
        }
    }
    None
}

/// Inside a block, the parser (typetag buffers the block's map) reports an
/// unknown field or a value of the wrong type at the block's first line and "at
/// line" of its last field. Find the line that really holds the key and say so,
/// naming the field, with the text of that line.
fn locate_field(e: GraphError, text: &str) -> GraphError {
    let GraphError::Parse {
        origin,
        mut message,
    } = e
    else {
        return e;
    };
    // The reported line: "line N column M" at the start of the message.
    let first_line = message
        .strip_prefix("line ")
        .and_then(|r| r.split_whitespace().next())
        .and_then(|n| n.parse::<usize>().ok())
        .unwrap_or(1);
    let Some((n, column, what)) = unknown_field_site(&message, text, first_line)
        .or_else(|| bad_value_site(&message, text, first_line))
    else {
        return GraphError::Parse { origin, message };
    };
    // The message rebuilt at the typo's own line, with the lines around it.
    let lines: Vec<&str> = text.lines().collect();
    let width = (n + 2).to_string().len();
    let mut out = format!(
        "line {} column {column}: {what}\n{:width$}--> {origin}:{}:{column}\n{:width$} |\n",
        n + 1,
        "",
        n + 1,
        ""
    );
    let from = n.saturating_sub(1);
    for (k, l) in lines.iter().enumerate().take(n + 1).skip(from) {
        out.push_str(&format!("{:>width$} | {l}\n", k + 1));
    }
    out.push_str(&format!(
        "{:width$} | {}^ {what}\n",
        "",
        " ".repeat(column - 1)
    ));
    if let Some(next) = lines.get(n + 1) {
        out.push_str(&format!("{:>width$} | {next}\n", n + 2));
    }
    out.push_str(&format!("{:width$} |", ""));
    message = out;
    GraphError::Parse { origin, message }
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
