//! Property test of the loader with every plugin linked: the example graphs with
//! numbers replaced by sizes that are huge, at the edge of `usize`, negative or
//! fractional. Every outcome is a value (an error or a graph that runs), never an
//! abort or a panic, and building allocates a bounded amount.

use nanomotion::core::graph::GraphSpec;
use proptest::prelude::*;

/// The example graphs, read once.
fn examples() -> Vec<(String, String)> {
    let dir = concat!(env!("CARGO_MANIFEST_DIR"), "/examples");
    let mut v: Vec<(String, String)> = std::fs::read_dir(dir)
        .unwrap()
        .filter_map(Result::ok)
        .map(|e| e.path())
        .filter(|p| p.extension().is_some_and(|e| e == "yaml"))
        .map(|p| {
            (
                p.display().to_string(),
                std::fs::read_to_string(&p).unwrap(),
            )
        })
        .collect();
    v.sort();
    v
}

/// Replace the `i`-th number of `text` (modulo their count) by `n`.
fn replace_number(text: &str, i: usize, n: &str) -> String {
    let chars: Vec<char> = text.chars().collect();
    let count = {
        let mut c = 0;
        let mut k = 0;
        while k < chars.len() {
            if chars[k].is_ascii_digit() {
                c += 1;
                while k < chars.len() && (chars[k].is_ascii_digit() || chars[k] == '.') {
                    k += 1;
                }
            } else {
                k += 1;
            }
        }
        c.max(1)
    };
    let target = i % count;
    let mut out = String::new();
    let (mut seen, mut k) = (0, 0);
    while k < chars.len() {
        if chars[k].is_ascii_digit() {
            let start = k;
            while k < chars.len() && (chars[k].is_ascii_digit() || chars[k] == '.') {
                k += 1;
            }
            if seen == target {
                out.push_str(n);
            } else {
                out.extend(&chars[start..k]);
            }
            seen += 1;
        } else {
            out.push(chars[k]);
            k += 1;
        }
    }
    out
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 96, .. ProptestConfig::default() })]
    #[test]
    fn example_graphs_with_mutated_sizes_never_abort(
        which in any::<usize>(),
        muts in prop::collection::vec(
            (any::<usize>(), prop::sample::select(vec![
                "18446744073709551615", "1000000000000", "4294967296", "16777217",
                "100000", "1025", "-3", "0.5", "2.5", "1e12", "-1e12", "0",
            ])),
            1..3,
        )
    ) {
        nanomotion::link_plugins();
        let all = examples();
        let (name, text) = &all[which % all.len()];
        let mut text = text.clone();
        for (i, n) in &muts {
            text = replace_number(&text, *i, n);
        }
        let info = allocation_counter::measure(|| {
            if let Ok(mut spec) = GraphSpec::from_yaml(&text, name) {
                spec.duration_s = spec.duration_s.min(0.01);
                // Scores after the shortened run would be refused: drop them.
                spec.score.retain(|s| s.from_s < 0.009);
                if let Ok((mut s, _)) = spec.build() {
                    s.step_n(s.ticks_total().min(20));
                    let _ = s.check_finite();
                }
            }
        });
        prop_assert!(info.bytes_max < 2 << 30, "{} bytes for {name}:\n{text}", info.bytes_max);
    }
}
