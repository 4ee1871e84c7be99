//! The graphs `plugins/dvrc/graphs/rc_*.yaml` (copied to the repository's
//! `examples/`) parse, pass `rc-check`, run, and
//! suppress the ripple.

use nanomotion_core::GraphSpec;

// Link the block registrations.
use dvrc as _;

fn path(name: &str) -> std::path::PathBuf {
    std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../../examples")
        .join(name)
}

fn run(name: &str) -> (f64, f64, String) {
    let report = dvrc::check::rc_check_file(&path(name)).unwrap();
    assert!(report.all_hold(), "{report}");
    let spec = GraphSpec::from_file(path(name)).unwrap();
    let (mut sched, _) = spec.build().unwrap();
    let r = sched.run(|_| {});
    assert_eq!(r.scores.len(), 2);
    println!(
        "{name}: rms(e) {:.3e} m overall, {:.3e} m after 1.5 s\n{report}",
        r.scores[0].rms, r.scores[1].rms
    );
    (r.scores[0].rms, r.scores[1].rms, report.to_string())
}

#[test]
fn standard_rc_example_checks_and_learns() {
    let (all, late, report) = run("rc_standard.yaml");
    assert!(report.contains("(5.5) fixed N"), "{report}");
    assert!(all > 1e-9, "{all}");
    assert!(late < 0.02 * all, "{all} → {late}");
}

#[test]
fn dvrc_example_checks_and_learns() {
    let (all, late, report) = run("rc_dvrc.yaml");
    assert!(report.contains("(5.9) N ∈ [150, 250]"), "{report}");
    assert!(all > 1e-9, "{all}");
    assert!(late < 0.02 * all, "{all} → {late}");
}

#[test]
fn repository_examples_are_copies_of_the_graphs_here() {
    for name in ["rc_standard.yaml", "rc_dvrc.yaml"] {
        let ours = std::fs::read_to_string(path(name)).unwrap();
        let root = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("../../examples")
            .join(name);
        match std::fs::read_to_string(&root) {
            Ok(theirs) => assert_eq!(ours, theirs, "examples/{name} differs from graphs/{name}"),
            Err(_) => {
                eprintln!("note: examples/{name} is missing (copy plugins/dvrc/graphs/{name})")
            }
        }
    }
}
