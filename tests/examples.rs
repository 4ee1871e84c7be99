//! Every YAML example in `examples/` builds through the facade (all plugins linked)
//! and runs its first 0.05 s without producing a non-finite signal.

use nanomotion::core::graph::GraphSpec;

#[test]
fn every_example_graph_builds_and_starts() {
    nanomotion::link_plugins();
    let dir = concat!(env!("CARGO_MANIFEST_DIR"), "/examples");
    let mut n = 0;
    for entry in std::fs::read_dir(dir).unwrap() {
        let path = entry.unwrap().path();
        if path.extension().is_none_or(|e| e != "yaml") {
            continue;
        }
        let mut spec =
            GraphSpec::from_file(&path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
        spec.duration_s = spec.duration_s.min(0.05);
        // Scores that start after the shortened run would be refused (nothing to
        // score): drop them for this smoke test.
        let end = spec.duration_s;
        spec.score.retain(|s| s.from_s < end * 0.9);
        let (mut s, _) = spec
            .build()
            .unwrap_or_else(|e| panic!("{}: {e}", path.display()));
        s.run(|_| {});
        s.check_finite()
            .unwrap_or_else(|e| panic!("{}: {e}", path.display()));
        n += 1;
    }
    assert!(n >= 3, "expected the example graphs, found {n}");
}
