//! `- include: FILE` entries in a graph's `blocks:` list (docs/graph-format.md,
//! "Including blocks from another file"): the entry is replaced by the block
//! entries of FILE, a YAML list of block entries such as the `controller.yaml`
//! that `nanomotion synth` writes. FILE is relative to the including file's
//! folder (to the working directory for [`crate::GraphSpec::from_yaml`]);
//! included files may include others; a cycle is refused.
//!
//! Each included entry is checked on its own first (so an error names the
//! included file and its line, behind the including file and line), then spliced
//! as one line of flow YAML (JSON) at the place of the `include:` line, so the
//! including file's line numbers stay those of the file (an include of k > 1
//! blocks moves the parser's line numbers of later lines by k − 1; connection
//! errors still name the file's own lines).

use super::spec::{BlockSpec, MAX_GRAPH_FILE_BYTES};
use crate::error::GraphError;
use crate::files::read_text_capped;
use std::path::{Path, PathBuf};

/// Deepest chain of nested includes.
pub const MAX_INCLUDE_DEPTH: usize = 16;

/// The path of an `- include: FILE` line (quotes and a trailing comment removed).
fn include_target(line: &str) -> Option<&str> {
    let rest = line.trim_start().strip_prefix("- include:")?;
    let rest = match rest.find(" #") {
        Some(i) => &rest[..i],
        None => rest,
    };
    let t = rest.trim();
    let t = t
        .strip_prefix('"')
        .and_then(|s| s.strip_suffix('"'))
        .or_else(|| t.strip_prefix('\'').and_then(|s| s.strip_suffix('\'')))
        .unwrap_or(t);
    Some(t)
}

/// Whether `text` has an `include:` entry (cheap test before [`expand`]).
pub fn has_includes(text: &str) -> bool {
    text.lines().any(|l| include_target(l).is_some())
}

fn at(origin: &str, line: usize, what: String, message: String) -> GraphError {
    GraphError::At {
        origin: origin.to_string(),
        line,
        source: Box::new(GraphError::Parse {
            origin: what,
            message,
        }),
    }
}

/// `text` (read from `origin`, whose includes resolve against `base`) with
/// every `- include: FILE` line replaced by FILE's block entries. `stack`
/// holds the files being expanded (cycle check).
pub fn expand(
    text: &str,
    origin: &str,
    base: &Path,
    stack: &mut Vec<PathBuf>,
) -> Result<String, GraphError> {
    let mut out = String::with_capacity(text.len());
    for (i, line) in text.lines().enumerate() {
        let Some(target) = include_target(line) else {
            out.push_str(line);
            out.push('\n');
            continue;
        };
        let n = i + 1;
        let what = format!("include `{target}`");
        if target.is_empty() {
            return Err(at(
                origin,
                n,
                what,
                "no file named: write `- include: FILE.yaml` (relative to this file's folder)"
                    .into(),
            ));
        }
        let path = base.join(target);
        let text = read_text_capped(&path, MAX_GRAPH_FILE_BYTES).map_err(|e| {
            at(
                origin,
                n,
                what.clone(),
                format!(
                    "{}: {e} (the path is relative to the including file's folder {})",
                    path.display(),
                    base.display()
                ),
            )
        })?;
        let canon = path.canonicalize().unwrap_or_else(|_| path.clone());
        if stack.contains(&canon) {
            let chain: Vec<String> = stack
                .iter()
                .chain(std::iter::once(&canon))
                .map(|p| p.display().to_string())
                .collect();
            return Err(at(
                origin,
                n,
                what,
                format!(
                    "include cycle: {}; remove one of the includes",
                    chain.join(" → ")
                ),
            ));
        }
        if stack.len() >= MAX_INCLUDE_DEPTH {
            return Err(at(
                origin,
                n,
                what,
                format!("more than {MAX_INCLUDE_DEPTH} nested includes"),
            ));
        }
        let inc_origin = path.display().to_string();
        // An empty file (a 0-byte `controller.yaml` left by a failed write) is
        // not "no blocks": it is refused, naming the file.
        if text.lines().all(|l| {
            let l = l.trim();
            l.is_empty() || l.starts_with('#')
        }) {
            return Err(at(
                origin,
                n,
                what,
                format!(
                    "{inc_origin} is empty ({} bytes, no block entries): an included file holds a YAML list of block entries, `- name: …` (fix: write the file again, e.g. rerun the command that made it, or remove the include)",
                    text.len()
                ),
            ));
        }
        let inc_base = path
            .parent()
            .filter(|p| !p.as_os_str().is_empty())
            .map_or_else(|| PathBuf::from("."), Path::to_path_buf);
        stack.push(canon);
        let inner = expand(&text, &inc_origin, &inc_base, stack);
        stack.pop();
        let inner = inner.map_err(|e| at(origin, n, what.clone(), e.to_string()))?;
        // The included file must be a list of block entries on its own.
        crate::yaml::from_str::<Vec<BlockSpec>>(&inner, &inc_origin).map_err(|e| {
            at(
                origin,
                n,
                what.clone(),
                format!("{e} (an included file holds a YAML list of block entries, `- name: …`)"),
            )
        })?;
        let entries: Vec<serde_json::Value> = crate::yaml::from_str(&inner, &inc_origin)
            .map_err(|e| at(origin, n, what.clone(), e.to_string()))?;
        let indent = &line[..line.len() - line.trim_start().len()];
        for e in entries {
            let json = serde_json::to_string(&e).map_err(|e| {
                at(
                    origin,
                    n,
                    what.clone(),
                    format!("{e} (non-finite numbers cannot be included)"),
                )
            })?;
            out.push_str(indent);
            out.push_str("- ");
            out.push_str(&json);
            out.push('\n');
        }
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use crate::GraphSpec;
    use std::path::PathBuf;

    fn dir(tag: &str) -> PathBuf {
        let d = std::env::temp_dir().join(format!("nm_include_{tag}_{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&d);
        std::fs::create_dir_all(d.join("sub")).unwrap();
        d
    }

    const GRAPH: &str = "base_rate_hz: 1000
duration_s: 0.01
blocks:
  - name: c
    type: constant
    value: 2.0
  - include: sub/k.yaml   # the gain, written elsewhere
connections:
  - { from: c.y, to: k.u }
log: [k.y]
";

    #[test]
    fn included_block_runs_and_lines_stay_the_files() {
        let d = dir("ok");
        std::fs::write(
            d.join("sub/k.yaml"),
            "# a block list\n- name: k\n  type: gain\n  k: 3.0\n",
        )
        .unwrap();
        std::fs::write(d.join("g.yaml"), GRAPH).unwrap();
        let spec = GraphSpec::from_file(d.join("g.yaml")).unwrap();
        assert_eq!(spec.blocks.len(), 2);
        assert_eq!(spec.connection_lines.as_ref().unwrap().1, vec![9]);
        let (mut s, _) = spec.build().unwrap();
        let res = s.run(|_| {});
        let y = &res.logs[0].data;
        assert!(y.iter().all(|v| *v == 6.0), "{y:?}");
        // A bad connection after the include names the file's own line.
        std::fs::write(d.join("g.yaml"), GRAPH.replace("k.u }", "k.nope }")).unwrap();
        let e = GraphSpec::from_file(d.join("g.yaml"))
            .unwrap()
            .build()
            .unwrap_err()
            .to_string();
        assert!(e.contains("line 9"), "{e}");
        let _ = std::fs::remove_dir_all(&d);
    }

    #[test]
    fn missing_malformed_and_cyclic_includes_are_located() {
        let d = dir("bad");
        let g = d.join("g.yaml");
        std::fs::write(&g, GRAPH).unwrap();
        let e = GraphSpec::from_file(&g).unwrap_err().to_string();
        assert!(
            e.contains("g.yaml: line 7") && e.contains("sub/k.yaml"),
            "{e}"
        );
        // Malformed: an unknown parameter, named with the included file's line.
        std::fs::write(d.join("sub/k.yaml"), "- name: k\n  type: gain\n  kk: 3.0\n").unwrap();
        let e = GraphSpec::from_file(&g).unwrap_err().to_string();
        assert!(
            e.contains("g.yaml: line 7") && e.contains("k.yaml") && e.contains("kk"),
            "{e}"
        );
        // Not a list.
        std::fs::write(d.join("sub/k.yaml"), "name: k\ntype: gain\n").unwrap();
        let e = GraphSpec::from_file(&g).unwrap_err().to_string();
        assert!(e.contains("list of block entries"), "{e}");
        // An empty file (0 bytes, or comments only) is refused, naming it.
        for empty in ["", "# nothing yet\n\n"] {
            std::fs::write(d.join("sub/k.yaml"), empty).unwrap();
            let e = GraphSpec::from_file(&g).unwrap_err().to_string();
            assert!(
                e.contains("g.yaml: line 7") && e.contains("k.yaml is empty"),
                "{e}"
            );
        }
        // The graph including itself.
        std::fs::write(d.join("sub/k.yaml"), "- include: ../g.yaml\n").unwrap();
        let e = GraphSpec::from_file(&g).unwrap_err().to_string();
        assert!(e.contains("include cycle"), "{e}");
        // A cycle: k.yaml includes itself through j.yaml (paths relative to sub/).
        std::fs::write(d.join("sub/k.yaml"), "- include: j.yaml\n").unwrap();
        std::fs::write(d.join("sub/j.yaml"), "- include: k.yaml\n").unwrap();
        let e = GraphSpec::from_file(&g).unwrap_err().to_string();
        assert!(
            e.contains("include cycle") && e.contains("g.yaml: line 7"),
            "{e}"
        );
        let _ = std::fs::remove_dir_all(&d);
    }
}
