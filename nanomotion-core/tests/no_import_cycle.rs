//! No import cycle in the core (docs/ARCHITECTURE.md, "Architecture invariants").
//!
//! Reads every file of `nanomotion-core/src`, takes the paths that start with
//! `crate::`, `$crate::` or `super::` in code (not in comments, strings or
//! `#[cfg(test)]` items: a test may build a whole graph to check a low-level
//! module), resolves each to the module it names (items re-exported at the crate
//! root, such as `crate::Block`, to the module that defines them) and fails on a
//! cycle
//!
//! - between the top-level modules (`block`, `scheduler`, `graph`, `gate`,
//!   `data`, `lti`, ...), and
//! - between the sibling submodules of any folder module (`graph/spec.rs`,
//!   `graph/load.rs`, ...; a child naming its parent is not counted),
//!
//! naming the cycle and, for each step, the file and line of one path that makes it.
//! A second test pins the layers of the graph runtime that the issue asked for.

use std::collections::{BTreeMap, BTreeSet};
use std::path::Path;

/// A module path below the crate root (`[]` is the root, `["graph", "spec"]`
/// is `graph/spec.rs`).
type ModPath = Vec<String>;

/// One `crate::…` path of a file: the module it was written in, the module it
/// names, and where.
#[derive(Debug, Clone)]
struct Edge {
    from: ModPath,
    to: ModPath,
    file: String,
    line: usize,
    text: String,
}

/// The module a file defines, from its path relative to `src`.
fn module_of(rel: &str) -> ModPath {
    let rel = rel.trim_end_matches(".rs");
    let mut parts: Vec<String> = rel.split('/').map(str::to_string).collect();
    if matches!(parts.last().map(String::as_str), Some("mod" | "lib")) {
        parts.pop();
    }
    parts
}

/// The source with comments, string and character literals blanked out (line
/// breaks kept, so token lines stay right).
fn code_only(src: &str) -> String {
    let c: Vec<char> = src.chars().collect();
    let mut out = String::with_capacity(src.len());
    let blank = |ch: char| if ch == '\n' { '\n' } else { ' ' };
    let mut i = 0;
    while i < c.len() {
        let next = c.get(i + 1).copied();
        if c[i] == '/' && next == Some('/') {
            while i < c.len() && c[i] != '\n' {
                out.push(' ');
                i += 1;
            }
        } else if c[i] == '/' && next == Some('*') {
            let mut depth = 0;
            while i < c.len() {
                if c[i] == '/' && c.get(i + 1) == Some(&'*') {
                    depth += 1;
                    out.push_str("  ");
                    i += 2;
                } else if c[i] == '*' && c.get(i + 1) == Some(&'/') {
                    depth -= 1;
                    out.push_str("  ");
                    i += 2;
                    if depth == 0 {
                        break;
                    }
                } else {
                    out.push(blank(c[i]));
                    i += 1;
                }
            }
        } else if (c[i] == 'r' || (c[i] == 'b' && next == Some('r')))
            && !c
                .get(i.wrapping_sub(1))
                .is_some_and(|p| p.is_alphanumeric() || *p == '_')
            && {
                let mut j = i + if c[i] == 'b' { 2 } else { 1 };
                while c.get(j) == Some(&'#') {
                    j += 1;
                }
                c.get(j) == Some(&'"')
            }
        {
            // Raw string r#"…"#.
            let mut j = i + if c[i] == 'b' { 2 } else { 1 };
            let mut hashes = 0;
            while c[j] == '#' {
                hashes += 1;
                j += 1;
            }
            j += 1;
            while j < c.len() {
                if c[j] == '"' && (0..hashes).all(|h| c.get(j + 1 + h) == Some(&'#')) {
                    j += 1 + hashes;
                    break;
                }
                j += 1;
            }
            for &ch in &c[i..j.min(c.len())] {
                out.push(blank(ch));
            }
            i = j;
        } else if c[i] == '"' {
            out.push(' ');
            i += 1;
            while i < c.len() && c[i] != '"' {
                if c[i] == '\\' {
                    out.push(' ');
                    i += 1;
                }
                if i < c.len() {
                    out.push(blank(c[i]));
                    i += 1;
                }
            }
            out.push(' ');
            i += 1;
        } else if c[i] == '\'' {
            // A character literal ('a', '\n', '\u{1F}'), else a lifetime.
            let end = if next == Some('\\') {
                (i + 2..c.len()).find(|&j| c[j] == '\'')
            } else if c.get(i + 2) == Some(&'\'') {
                Some(i + 2)
            } else {
                None
            };
            match end {
                Some(e) => {
                    for &ch in &c[i..=e] {
                        out.push(blank(ch));
                    }
                    i = e + 1;
                }
                None => {
                    out.push('\'');
                    i += 1;
                }
            }
        } else {
            out.push(c[i]);
            i += 1;
        }
    }
    out
}

/// Tokens (identifiers with `$`, `::` and single punctuation) with their lines.
fn tokens(code: &str) -> Vec<(String, usize)> {
    let mut out = Vec::new();
    let c: Vec<char> = code.chars().collect();
    let (mut i, mut line) = (0, 1);
    while i < c.len() {
        let ch = c[i];
        if ch == '\n' {
            line += 1;
            i += 1;
        } else if ch.is_whitespace() {
            i += 1;
        } else if ch.is_alphanumeric() || ch == '_' || ch == '$' {
            let start = i;
            i += 1;
            while i < c.len() && (c[i].is_alphanumeric() || c[i] == '_') {
                i += 1;
            }
            out.push((c[start..i].iter().collect(), line));
        } else if ch == ':' && c.get(i + 1) == Some(&':') {
            out.push(("::".into(), line));
            i += 2;
        } else {
            out.push((ch.to_string(), line));
            i += 1;
        }
    }
    out
}

/// The paths written after `crate::` (or `super::`) at token `i`: one for a
/// plain path, several for a `{a::X, b::{Y, Z}}` group. Returns them and the
/// index after the path.
fn path_at(t: &[(String, usize)], mut i: usize) -> (Vec<Vec<String>>, usize) {
    let mut prefix = Vec::new();
    loop {
        match t.get(i).map(|x| x.0.as_str()) {
            Some("{") => {
                let mut all = Vec::new();
                i += 1;
                while i < t.len() && t[i].0 != "}" {
                    if t[i].0 == "," {
                        i += 1;
                        continue;
                    }
                    let (inner, j) = path_at(t, i);
                    for p in inner {
                        all.push(prefix.iter().cloned().chain(p).collect());
                    }
                    // Skip `as name` and anything else up to `,` or `}`.
                    i = j;
                    while i < t.len() && t[i].0 != "," && t[i].0 != "}" {
                        i += 1;
                    }
                }
                return (all, i + 1);
            }
            Some(s) if s.chars().all(|c| c.is_alphanumeric() || c == '_') => {
                prefix.push(s.to_string());
                i += 1;
                if t.get(i).map(|x| x.0.as_str()) == Some("::") {
                    i += 1;
                } else {
                    return (vec![prefix], i);
                }
            }
            _ => return (vec![prefix], i),
        }
    }
}

/// Index after the item starting at token `i` (up to its `;` or its balanced
/// `{…}` block).
fn skip_item(t: &[(String, usize)], mut i: usize) -> usize {
    let mut depth = 0usize;
    while i < t.len() {
        match t[i].0.as_str() {
            "{" | "(" | "[" => depth += 1,
            "}" | ")" | "]" => {
                depth = depth.saturating_sub(1);
                if depth == 0 && t[i].0 == "}" {
                    return i + 1;
                }
            }
            ";" if depth == 0 => return i + 1,
            _ => {}
        }
        i += 1;
    }
    i
}

/// Whether tokens from `i` are `# [ cfg ( test ) ]`.
fn is_cfg_test(t: &[(String, usize)], i: usize) -> bool {
    let want = ["#", "[", "cfg", "(", "test", ")", "]"];
    want.iter()
        .enumerate()
        .all(|(k, w)| t.get(i + k).is_some_and(|x| x.0 == *w))
}

/// The `crate::` paths of one file, with the module each was written in, and
/// the names of `#[macro_export]` macros it defines. Also returns the names of
/// child modules declared as `#[cfg(test)] mod x;` (test-only files).
struct Scan {
    paths: Vec<(ModPath, Vec<String>, usize, String)>,
    macros: Vec<String>,
    test_children: Vec<String>,
}

fn scan(module: &ModPath, src: &str) -> Scan {
    let t = tokens(&code_only(src));
    let mut out = Scan {
        paths: Vec::new(),
        macros: Vec::new(),
        test_children: Vec::new(),
    };
    // Inline modules: (name, brace depth inside it).
    let mut inline: Vec<(String, usize)> = Vec::new();
    let mut depth = 0usize;
    let mut macro_export = false;
    let mut i = 0;
    while i < t.len() {
        let tok = t[i].0.as_str();
        if is_cfg_test(&t, i) {
            let mut j = i + 7;
            // Further attributes, visibility.
            while t.get(j).is_some_and(|x| x.0 == "#") {
                j = skip_item(&t, j + 1);
            }
            if t.get(j).is_some_and(|x| x.0 == "pub") {
                j += 1;
            }
            if t.get(j).is_some_and(|x| x.0 == "mod") && t.get(j + 2).is_some_and(|x| x.0 == ";") {
                out.test_children.push(t[j + 1].0.clone());
            }
            i = skip_item(&t, j);
            continue;
        }
        match tok {
            "#" if t.get(i + 2).is_some_and(|x| x.0 == "macro_export") => macro_export = true,
            "macro_rules" if t.get(i + 1).is_some_and(|x| x.0 == "!") => {
                if macro_export {
                    out.macros.push(t[i + 2].0.clone());
                }
                macro_export = false;
            }
            "mod" if t.get(i + 2).is_some_and(|x| x.0 == "{") => {
                inline.push((t[i + 1].0.clone(), depth + 1));
                depth += 1;
                i += 3;
                continue;
            }
            "{" => depth += 1,
            "}" => {
                if inline.last().is_some_and(|(_, d)| *d == depth) {
                    inline.pop();
                }
                depth = depth.saturating_sub(1);
            }
            "crate" | "$crate" | "super"
                if t.get(i + 1).is_some_and(|x| x.0 == "::") && !(i > 0 && t[i - 1].0 == "::") =>
            {
                let here: ModPath = module
                    .iter()
                    .cloned()
                    .chain(inline.iter().map(|(n, _)| n.clone()))
                    .collect();
                let line = t[i].1;
                // `super::super::x`: climb once per `super`.
                let mut base = if tok == "super" {
                    let mut b = here.clone();
                    b.pop();
                    b
                } else {
                    Vec::new()
                };
                let mut j = i + 2;
                while tok == "super"
                    && t.get(j).is_some_and(|x| x.0 == "super")
                    && t.get(j + 1).is_some_and(|x| x.0 == "::")
                {
                    base.pop();
                    j += 2;
                }
                let (paths, end) = path_at(&t, j);
                let text: String = t[i..end.min(t.len())]
                    .iter()
                    .map(|x| x.0.as_str())
                    .collect();
                for p in paths {
                    let abs: Vec<String> = base.iter().cloned().chain(p).collect();
                    out.paths.push((here.clone(), abs, line, text.clone()));
                }
                i = end;
                continue;
            }
            _ => {}
        }
        i += 1;
    }
    out
}

/// Every module-to-module edge of the sources (`(path relative to src, text)`).
fn edges(files: &[(String, String)]) -> Vec<Edge> {
    let modules: BTreeSet<ModPath> = files.iter().map(|(p, _)| module_of(p)).collect();
    let scans: Vec<(String, ModPath, Scan)> = files
        .iter()
        .map(|(p, s)| {
            let m = module_of(p);
            let sc = scan(&m, s);
            (p.clone(), m, sc)
        })
        .collect();
    // Test-only files (`#[cfg(test)] mod tests;`) are left out.
    let test_only: BTreeSet<ModPath> = scans
        .iter()
        .flat_map(|(_, m, sc)| {
            sc.test_children
                .iter()
                .map(move |c| m.iter().cloned().chain([c.clone()]).collect())
        })
        .collect();
    // Names the root re-exports (`pub use block::{Block, ...}`) and exported macros.
    let mut root_names: BTreeMap<String, ModPath> = BTreeMap::new();
    for (_, m, sc) in &scans {
        for name in &sc.macros {
            root_names.insert(name.clone(), m.clone());
        }
    }
    if let Some((_, src)) = files.iter().find(|(p, _)| p == "lib.rs") {
        let t = tokens(&code_only(src));
        for i in 0..t.len() {
            if t[i].0 == "pub" && t.get(i + 1).is_some_and(|x| x.0 == "use") {
                let (paths, _) = path_at(&t, i + 2);
                for p in paths {
                    if let (Some(first), Some(last)) = (p.first(), p.last())
                        && modules.contains(&vec![first.clone()])
                    {
                        root_names.insert(last.clone(), p[..p.len() - 1].to_vec());
                    }
                }
            }
        }
    }
    let resolve = |abs: &[String]| -> ModPath {
        if let Some(first) = abs.first()
            && !modules.contains(&vec![first.clone()])
        {
            return root_names.get(first).cloned().unwrap_or_default();
        }
        (0..=abs.len())
            .rev()
            .map(|k| abs[..k].to_vec())
            .find(|p| modules.contains(p))
            .unwrap_or_default()
    };
    let mut out = Vec::new();
    for (file, m, sc) in &scans {
        if test_only.contains(m) {
            continue;
        }
        for (from, abs, line, text) in &sc.paths {
            let to = resolve(abs);
            out.push(Edge {
                from: from[..m.len()].to_vec(),
                to,
                file: file.clone(),
                line: *line,
                text: text.clone(),
            });
        }
    }
    out
}

/// The cycles among `nodes` under `edges` (node, node, evidence), one per
/// strongly connected component, each written `a -> b -> a` with one line of
/// evidence per step.
fn cycles(edges: &BTreeMap<(String, String), String>) -> Vec<String> {
    let mut next: BTreeMap<&str, BTreeSet<&str>> = BTreeMap::new();
    for (a, b) in edges.keys() {
        next.entry(a).or_default().insert(b);
    }
    let mut found = Vec::new();
    let mut seen_cycle: BTreeSet<BTreeSet<&str>> = BTreeSet::new();
    // Shortest cycle through each node, by breadth-first search back to it.
    for &start in next.keys() {
        let mut prev: BTreeMap<&str, &str> = BTreeMap::new();
        let mut queue = std::collections::VecDeque::from([start]);
        let mut closed = None;
        while let Some(n) = queue.pop_front() {
            for &m in next.get(n).into_iter().flatten() {
                if m == start {
                    closed = Some(n);
                    break;
                }
                if !prev.contains_key(m) {
                    prev.insert(m, n);
                    queue.push_back(m);
                }
            }
            if closed.is_some() {
                break;
            }
        }
        let Some(last) = closed else { continue };
        let mut path = vec![last];
        while *path.last().unwrap() != start {
            path.push(prev[path.last().unwrap()]);
        }
        path.reverse();
        let members: BTreeSet<&str> = path.iter().copied().collect();
        if !seen_cycle.insert(members) {
            continue;
        }
        path.push(start);
        let mut text = path.join(" -> ");
        for w in path.windows(2) {
            text.push_str(&format!(
                "\n    {} -> {}: {}",
                w[0],
                w[1],
                edges[&(w[0].to_string(), w[1].to_string())]
            ));
        }
        found.push(text);
    }
    found
}

/// The edges between top-level modules, and between the siblings of each folder
/// module, keyed by (from, to) with the first evidence found.
fn levels(all: &[Edge]) -> BTreeMap<String, BTreeMap<(String, String), String>> {
    let mut out: BTreeMap<String, BTreeMap<(String, String), String>> = BTreeMap::new();
    let evidence = |e: &Edge| format!("{}:{} `{}`", e.file, e.line, e.text);
    for e in all {
        let (Some(a), Some(b)) = (e.from.first(), e.to.first()) else {
            continue;
        };
        if a != b {
            out.entry("the top-level modules".into())
                .or_default()
                .entry((a.clone(), b.clone()))
                .or_insert_with(|| evidence(e));
        }
        // Siblings under every common folder module.
        let common = e.from.iter().zip(&e.to).take_while(|(x, y)| x == y).count();
        if common > 0 && e.from.len() > common && e.to.len() > common {
            let parent = e.from[..common].join("::");
            out.entry(format!("the submodules of `{parent}`"))
                .or_default()
                .entry((
                    format!("{parent}::{}", e.from[common]),
                    format!("{parent}::{}", e.to[common]),
                ))
                .or_insert_with(|| evidence(e));
        }
    }
    out
}

fn read_sources(dir: &Path, rel: &str, out: &mut Vec<(String, String)>) {
    let mut entries: Vec<_> = std::fs::read_dir(dir)
        .unwrap_or_else(|e| panic!("cannot read {}: {e}", dir.display()))
        .map(|e| e.unwrap().path())
        .collect();
    entries.sort();
    for p in entries {
        let name = p.file_name().unwrap().to_string_lossy().to_string();
        let r = if rel.is_empty() {
            name.clone()
        } else {
            format!("{rel}/{name}")
        };
        if p.is_dir() {
            read_sources(&p, &r, out);
        } else if name.ends_with(".rs") {
            out.push((r, std::fs::read_to_string(&p).unwrap()));
        }
    }
}

fn core_sources() -> Vec<(String, String)> {
    let mut files = Vec::new();
    read_sources(
        &Path::new(env!("CARGO_MANIFEST_DIR")).join("src"),
        "",
        &mut files,
    );
    assert!(files.len() > 30, "found only {} source files", files.len());
    files
}

fn cycle_report(files: &[(String, String)]) -> Vec<String> {
    let mut out = Vec::new();
    for (level, edges) in levels(&edges(files)) {
        for c in cycles(&edges) {
            out.push(format!("import cycle between {level}: {c}"));
        }
    }
    out
}

#[test]
fn the_core_has_no_import_cycle() {
    let found = cycle_report(&core_sources());
    assert!(
        found.is_empty(),
        "nanomotion-core/src has {} import cycle(s); each module must depend on the \
         ones below it only (docs/ARCHITECTURE.md, \"No import cycle in the core\"): \
         move the shared item down, or read the built graph through `Scheduler` \
         instead of the compiler's internals.\n\n{}",
        found.len(),
        found.join("\n\n")
    );
}

/// The layers of the graph runtime (issue 26): the block contract at the
/// bottom, the scheduler on it, the graph compiler on both; the gate and the
/// data layer beside the compiler, reading a built graph (`Scheduler`).
#[test]
fn the_graph_runtime_is_layered() {
    let all = edges(&core_sources());
    let uses = |from: &str, to: &str| -> Option<String> {
        all.iter()
            .find(|e| {
                e.from.first().map(String::as_str) == Some(from)
                    && e.to.first().map(String::as_str) == Some(to)
            })
            .map(|e| format!("{}:{} `{}`", e.file, e.line, e.text))
    };
    let forbidden = [
        (
            "block",
            ["scheduler", "graph", "gate", "data", "include"].as_slice(),
        ),
        ("scheduler", &["graph", "gate", "data", "include"]),
        ("graph", &["gate", "data"]),
        ("gate", &["graph", "data", "include"]),
        ("data", &["graph", "gate", "include"]),
    ];
    let mut wrong = Vec::new();
    for (from, tos) in forbidden {
        for to in tos {
            if let Some(at) = uses(from, to) {
                wrong.push(format!("`{from}` must not import `{to}`: {at}"));
            }
        }
    }
    assert!(wrong.is_empty(), "{}", wrong.join("\n"));
}

/// The checker itself: it finds a cycle written in code and names it, through
/// root re-exports, groups and `super::`; comments, strings and test modules
/// do not count.
#[test]
fn the_checker_finds_cycles_and_ignores_comments_strings_and_tests() {
    let file = |p: &str, s: &str| (p.to_string(), s.to_string());
    let clean = [
        file("lib.rs", "pub mod a;\npub mod b;\npub use a::Thing;\n"),
        file(
            "a.rs",
            "// crate::b::X in a comment\nconst S: &str = \"crate::b::X\";\nconst R: &str = r#\"crate::b::Y\"#;\nfn f<'a>(c: char) -> bool { c == '\"' }\npub struct Thing;\n#[cfg(test)]\nmod tests { use crate::b::X; }\n",
        ),
        file(
            "b.rs",
            "use crate::{Thing, a::Thing as T};\npub struct X;\n",
        ),
    ];
    assert!(
        cycle_report(&clean).is_empty(),
        "{:?}",
        cycle_report(&clean)
    );
    let mut knot = clean.to_vec();
    knot[1]
        .1
        .push_str("fn g() -> crate::b::X { crate::b::X }\n");
    let found = cycle_report(&knot);
    assert_eq!(found.len(), 1, "{found:?}");
    assert!(found[0].contains("a -> b -> a"), "{}", found[0]);
    assert!(found[0].contains("a.rs:8 `crate::b::X`"), "{}", found[0]);
    // Siblings of a folder module, through `super::`.
    let nested = [
        file("lib.rs", "pub mod g;\n"),
        file("g/mod.rs", "mod p;\nmod q;\n"),
        file("g/p.rs", "use super::q::Q;\npub struct P;\n"),
        file("g/q.rs", "use super::p::P;\npub struct Q;\n"),
    ];
    let found = cycle_report(&nested);
    assert!(
        found.len() == 1 && found[0].contains("submodules of `g`"),
        "{found:?}"
    );
}
