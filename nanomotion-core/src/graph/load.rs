//! Reading a graph: YAML text or a file (bounded), `- include:` entries spliced
//! first ([`include`](mod@super::include)), errors located at their line, and "did you
//! mean" for unknown block types and names.

use super::include;
use super::spec::{GraphSpec, MAX_GRAPH_FILE_BYTES};
use crate::error::GraphError;
use crate::files::read_text_capped;

impl GraphSpec {
    /// Parse a graph from YAML text; `origin` (file name) prefixes errors.
    /// `- include: FILE` entries ([`crate::include`](mod@crate::include)) resolve against the
    /// working directory here, against the file's folder in [`GraphSpec::from_file`].
    pub fn from_yaml(text: &str, origin: &str) -> Result<Self, GraphError> {
        Self::from_yaml_in(text, origin, std::path::Path::new("."), Vec::new())
    }

    /// [`GraphSpec::from_yaml`] with includes resolved against `base`.
    /// `stack`: the file itself (for the include-cycle check), when known.
    fn from_yaml_in(
        text: &str,
        origin: &str,
        base: &std::path::Path,
        mut stack: Vec<std::path::PathBuf>,
    ) -> Result<Self, GraphError> {
        if include::has_includes(text) {
            let expanded = include::expand(text, origin, base, &mut stack)?;
            let mut spec = Self::from_yaml_in(&expanded, origin, base, Vec::new())?;
            // Connection lines from the file as written (not the expanded text).
            let lines = connection_lines(text);
            spec.connection_lines =
                (lines.len() == spec.connections.len()).then(|| (origin.to_string(), lines));
            return Ok(spec);
        }
        let mut spec =
            crate::yaml::from_str::<GraphSpec>(text, origin).map_err(add_type_suggestion)?;
        let lines = connection_lines(text);
        if lines.len() == spec.connections.len() {
            spec.connection_lines = Some((origin.to_string(), lines));
        }
        Ok(spec)
    }

    /// Read and parse a graph file (at most [`MAX_GRAPH_FILE_BYTES`]). Relative
    /// file names in block parameters will resolve against its folder.
    pub fn from_file(path: impl AsRef<std::path::Path>) -> Result<Self, GraphError> {
        let path = path.as_ref();
        let text =
            read_text_capped(path, MAX_GRAPH_FILE_BYTES).map_err(|source| GraphError::Io {
                path: path.display().to_string(),
                source,
            })?;
        let base = path
            .parent()
            .filter(|p| !p.as_os_str().is_empty())
            .map_or_else(
                || std::path::PathBuf::from("."),
                std::path::Path::to_path_buf,
            );
        let root = path.canonicalize().unwrap_or_else(|_| path.to_path_buf());
        let mut spec = Self::from_yaml_in(&text, &path.display().to_string(), &base, vec![root])?;
        spec.base_dir = Some(base);
        Ok(spec)
    }
}

/// Add "did you mean" to unknown-type errors.
fn add_type_suggestion(e: GraphError) -> GraphError {
    let GraphError::Parse {
        origin,
        mut message,
    } = e
    else {
        return e;
    };
    if let Some(pos) = message.find("unknown variant `") {
        let rest = &message[pos + "unknown variant `".len()..];
        if let Some(end) = rest.find('`') {
            let bad = rest[..end].to_string();
            let known = crate::block::parse_expected_list(&message);
            // Another field's choice (`discretisation: zohh`, `overrun: …`)
            // lists its own variants, not the block types: serde's message
            // already names them, and "did you mean" picks among those.
            let types = crate::block::registered_types();
            let is_block_type = !known.is_empty() && known.iter().all(|k| types.contains(k));
            if !is_block_type {
                if let Some(best) = nearest(&bad, known.iter().map(String::as_str)) {
                    message = format!("{message}\nhint: did you mean `{best}`?");
                }
            } else if let Some(best) = nearest(&bad, known.iter().map(String::as_str)) {
                message = format!(
                    "{message}\nhint: unknown block type `{bad}`; did you mean `{best}`? (`nanomotion blocks` lists all types)"
                );
            } else {
                message = format!(
                    "{message}\nhint: unknown block type `{bad}` (`nanomotion blocks` lists all types)"
                );
            }
        }
    }
    GraphError::Parse { origin, message }
}

/// 1-based lines of the entries of a block-style top-level `connections:` list
/// (`- ` items at its first indentation); empty for a flow-style list.
fn connection_lines(text: &str) -> Vec<usize> {
    let mut out = Vec::new();
    let mut inside = false;
    let mut indent: Option<usize> = None;
    for (n, line) in text.lines().enumerate() {
        let trimmed = line.trim_start();
        if trimmed.is_empty() || trimmed.starts_with('#') {
            continue;
        }
        let ind = line.len() - trimmed.len();
        if ind == 0 {
            inside = trimmed.starts_with("connections:")
                && trimmed["connections:".len()..]
                    .trim_start()
                    .split('#')
                    .next()
                    == Some("");
            continue;
        }
        if inside && trimmed.starts_with('-') && *indent.get_or_insert(ind) == ind {
            out.push(n + 1);
        }
    }
    out
}

/// Levenshtein distance in characters (for "did you mean" suggestions).
pub fn edit_distance(a: &str, b: &str) -> usize {
    let b: Vec<char> = b.chars().collect();
    let mut prev: Vec<usize> = (0..=b.len()).collect();
    for (i, ca) in a.chars().enumerate() {
        let mut cur = vec![i + 1; b.len() + 1];
        for (j, cb) in b.iter().enumerate() {
            let sub = prev[j] + usize::from(ca != *cb);
            cur[j + 1] = sub.min(prev[j + 1] + 1).min(cur[j] + 1);
        }
        prev = cur;
    }
    prev[b.len()]
}

/// Longest word (bytes) "did you mean" compares: the edit distance costs the
/// product of the two lengths, and a name this long is no typo of a short one.
pub const MAX_SUGGEST_BYTES: usize = 64;

/// Whether `candidate` is near enough to `word` to suggest it ("did you mean").
/// Words longer than [`MAX_SUGGEST_BYTES`] are never compared (audit D8: the
/// comparison was quadratic in the length of a 160 000-character name).
pub fn is_near(word: &str, candidate: &str) -> bool {
    word.len() <= MAX_SUGGEST_BYTES
        && candidate.len() <= MAX_SUGGEST_BYTES
        && edit_distance(word, candidate) <= (candidate.len().max(word.len()) / 2).max(2)
}

/// The candidate nearest to `word`, if it is reasonably near.
pub(crate) fn nearest<'a>(
    word: &str,
    candidates: impl Iterator<Item = &'a str>,
) -> Option<&'a str> {
    candidates
        .filter(|c| is_near(word, c))
        .map(|c| (edit_distance(word, c), c))
        .min_by_key(|(d, _)| *d)
        .map(|(_, c)| c)
}

#[cfg(test)]
mod tests {
    /// Audit D8: a 160 000-character block name and a reference to another one
    /// made "did you mean" run for minutes (quadratic edit distance).
    #[test]
    fn long_names_are_refused_at_once() {
        let n = 160_000;
        let (a, b) = ("a".repeat(n), "b".repeat(n));
        let text = format!(
            "base_rate_hz: 1000\nduration_s: 1\nblocks:\n  - {{ name: {a}, type: gain, k: 1.0 }}\n  - {{ name: c, type: constant, value: 1.0 }}\nconnections:\n  - {{ from: {b}.y, to: {a}.u }}\n"
        );
        let start = std::time::Instant::now();
        let e = super::GraphSpec::from_yaml(&text, "longname.yaml")
            .unwrap()
            .build()
            .err()
            .unwrap()
            .to_string();
        assert!(start.elapsed().as_secs_f64() < 2.0, "{:?}", start.elapsed());
        assert!(e.contains("160000 characters, more than 100"), "{e}");
        assert!(!super::is_near(&a, &b) && super::is_near("gian", "gain"));
        let start = std::time::Instant::now();
        assert_eq!(super::nearest(&a, [b.as_str()].into_iter()), None);
        assert!(start.elapsed().as_secs_f64() < 0.1);
    }
    /// A misspelt choice of a block's own field (`discretisation: zohh`) was
    /// hinted as an "unknown block type"; only a misspelt `type:` is one.
    #[test]
    fn a_misspelt_choice_is_not_called_a_block_type() {
        let graph = |disc: &str, ty: &str| {
            format!(
                "base_rate_hz: 1000\nduration_s: 1\nblocks:\n  - {{ name: p, type: {ty}, a: [[-1.0]], b: [[1.0]], c: [[1.0]], discretisation: {disc} }}\n"
            )
        };
        let e = super::GraphSpec::from_yaml(&graph("zohh", "state_space"), "g.yaml")
            .expect_err("refused")
            .to_string();
        assert!(e.contains("did you mean `zoh`"), "{e}");
        assert!(!e.contains("block type"), "{e}");
        let e = super::GraphSpec::from_yaml(&graph("zoh", "state_spac"), "g.yaml")
            .expect_err("refused")
            .to_string();
        assert!(
            e.contains("unknown block type `state_spac`; did you mean `state_space`"),
            "{e}"
        );
    }
    /// Audit D21: a wrong-type value inside a block named neither the field nor
    /// its line (the parser pointed at the entry's first line and the next one).
    #[test]
    fn a_wrong_type_value_names_its_field_and_line() {
        let text = "base_rate_hz: 4000\nduration_s: 0.1\nblocks:\n  - name: w\n    type: walking_waveform\n  - name: s\n    type: walking_piezo_stage\n    stage_mass_kg: 0.428\n    preload_n: 55.0\n    mu: 0.2\n    mu_pair_rel: 0.1\n    mu_spatial_rel: 0.1\n    substeps: 2\n    tol_n: fast\n    max_iter: 200\nconnections:\n  - { from: w.u, to: s.u }\n";
        // The core has no walking stage: a core block shows the same.
        let text = text
            .replace("walking_waveform", "constant\n    value: 1.0")
            .replace(
                "type: walking_piezo_stage\n    stage_mass_kg: 0.428\n    preload_n: 55.0\n    mu: 0.2\n    mu_pair_rel: 0.1\n    mu_spatial_rel: 0.1\n    substeps: 2\n    tol_n: fast\n    max_iter: 200",
                "type: pid\n    kp: 1.0\n    ki: 2.0\n    kd: fast\n    derivative_cutoff_hz: 100.0",
            )
            .replace("w.u, to: s.u", "w.y, to: s.e");
        let e = super::GraphSpec::from_yaml(&text, "typeerr.yaml")
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("line 11 column 5: field `kd`: invalid type: string \"fast\""),
            "{e}"
        );
        assert!(e.contains("11 |     kd: fast"), "{e}");
        // Flow style: the key on its own line too.
        let flow = "base_rate_hz: 10\nduration_s: 1\nblocks:\n  - { name: c, type: constant, value: 1.0 }\n  - { name: g, type: gain,\n      k: NaN }\n";
        let e = super::GraphSpec::from_yaml(flow, "f.yaml")
            .unwrap_err()
            .to_string();
        assert!(e.contains("line 6 column 7: field `k`"), "{e}");
    }

    /// YAML 1.1 booleans (issue 26): a graph file is read as YAML 1.2, as
    /// editors and `nanomotion schema` read it. `yes`/`on`/… where a boolean is
    /// wanted is an error naming the line, with the fix; elsewhere the words are
    /// text (blocks named `y` and `n`).
    #[test]
    fn yaml11_booleans_are_refused_with_the_fix_and_stay_text_elsewhere() {
        let fix = "write `true` or `false`";
        // a graph-level key (the old reading: strict_rates = true, silently)
        let text = "base_rate_hz: 10\nduration_s: 1\nstrict_rates: yes\nblocks:\n  - { name: c, type: constant, value: 1.0 }\n";
        let e = super::GraphSpec::from_yaml(text, "g.yaml")
            .unwrap_err()
            .to_string();
        assert!(e.contains("line 3"), "{e}");
        assert!(e.contains("3 | strict_rates: yes"), "{e}");
        assert!(e.contains(fix), "{e}");
        // a block's parameter (the parser buffers the block's map)
        let text = "base_rate_hz: 10\nduration_s: 1\nblocks:\n  - name: tf\n    type: transfer_function\n    num: [1.0]\n    den: [1.0, 0.5]\n    discrete: on\n";
        for word in ["on", "off", "yes", "No", "Y"] {
            let text = text.replace("discrete: on", &format!("discrete: {word}"));
            let e = super::GraphSpec::from_yaml(&text, "g.yaml")
                .unwrap_err()
                .to_string();
            assert!(e.contains("line 8 column 5: field `discrete`"), "{e}");
            assert!(e.contains(fix), "{e}");
        }
        // YAML 1.2 booleans, in any of its cases, are booleans
        for word in ["true", "True", "FALSE"] {
            let ok = text.replace("discrete: on", &format!("discrete: {word}"));
            super::GraphSpec::from_yaml(&ok, "g.yaml").unwrap();
        }
        // as text the words stay text: blocks named `y` and `n`, run: 3·2 = 6
        let text = "base_rate_hz: 10\nduration_s: 0.2\nblocks:\n  - { name: y, type: constant, value: 2.0 }\n  - { name: n, type: gain, k: 3.0 }\nconnections:\n  - { from: y.y, to: n.u }\nlog: [n.y]\n";
        let g = super::GraphSpec::from_yaml(text, "g.yaml").unwrap();
        assert_eq!(g.blocks[0].name, "y");
        assert_eq!(g.blocks[1].name, "n");
        let (mut s, _) = g.build().unwrap();
        let r = s.run(|_| {});
        assert_eq!(r.logs[0].data, vec![6.0; 2]);
    }

    use super::*;

    #[test]
    fn edit_distance_and_nearest() {
        assert_eq!(edit_distance("gain", "gian"), 2);
        assert_eq!(edit_distance("", "abc"), 3);
        assert_eq!(edit_distance("kitten", "sitting"), 3);
        assert_eq!(
            nearest("gian", ["gain", "sum", "pid"].into_iter()),
            Some("gain")
        );
        assert_eq!(nearest("zzzzzzzz", ["gain", "sum"].into_iter()), None);
    }
}
