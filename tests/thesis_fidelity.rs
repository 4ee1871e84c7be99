//! docs/thesis-fidelity.md is the output of `nanomotion reproduce --quick`: this test
//! regenerates the quick set in-process (once, shared by the tests below) and
//! compares it with the committed file byte for byte; the other tests check
//! invariants of the reports of each experiment.
//!
//! When stale, regenerate with the command in `nanomotion::thesis::REGENERATE_DOCS`
//! (or run this test with `UPDATE_THESIS_FIDELITY=1`).

use nanomotion::thesis::{self, Mode, Outcome, Report, Verdict};
use std::sync::OnceLock;

const DOC: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/docs/thesis-fidelity.md");

fn outcomes() -> &'static [Outcome] {
    static OUT: OnceLock<Vec<Outcome>> = OnceLock::new();
    OUT.get_or_init(|| {
        let chosen = thesis::select(&[], true).expect("the quick set");
        thesis::run_all(&chosen, Mode::Quick, |_, _| {})
    })
}

fn report(id: &str) -> &'static Report {
    let o = outcomes()
        .iter()
        .find(|o| o.id == id)
        .unwrap_or_else(|| panic!("{id} is not in the quick set"));
    o.report
        .as_ref()
        .unwrap_or_else(|| panic!("{id} did not run: {:?}", o.error))
}

#[test]
fn docs_thesis_fidelity_is_the_current_quick_output() {
    let md = thesis::fidelity_markdown(outcomes(), Mode::Quick, "nanomotion reproduce --quick");
    if std::env::var_os("UPDATE_THESIS_FIDELITY").is_some() {
        std::fs::write(DOC, &md).unwrap();
    }
    let committed = std::fs::read_to_string(DOC).unwrap_or_default();
    if committed != md {
        let diff: Vec<String> = committed
            .lines()
            .zip(md.lines())
            .enumerate()
            .filter(|(_, (a, b))| a != b)
            .take(5)
            .map(|(i, (a, b))| format!("line {}:\n  committed: {a}\n  now:       {b}", i + 1))
            .collect();
        panic!(
            "docs/thesis-fidelity.md is stale ({} vs {} lines; first differences below). Regenerate: {}\n(or UPDATE_THESIS_FIDELITY=1 cargo test --test thesis_fidelity)\n{}",
            committed.lines().count(),
            md.lines().count(),
            thesis::REGENERATE_DOCS,
            diff.join("\n")
        );
    }
    for o in outcomes() {
        assert!(o.is_ok(), "{} did not run: {:?}", o.id, o.error);
    }
}

/// Every row: a thesis figure, ours, a reason that states the tolerance.
#[test]
fn every_row_states_its_tolerance_and_figures() {
    for o in outcomes() {
        let Some(r) = &o.report else { continue };
        assert_eq!(r.mode, Mode::Quick);
        assert!(!r.rows.is_empty(), "{}", r.id);
        assert!(!r.command.is_empty() && !r.section.is_empty(), "{}", r.id);
        for row in &r.rows {
            assert!(!row.thesis.is_empty() && !row.ours.is_empty(), "{row:?}");
            assert!(row.reason.len() > 20, "{row:?}");
        }
    }
    for id in ["ch6", "sec_7_5", "sec_8_5"] {
        for row in &report(id).rows {
            assert!(
                row.reason.contains("tolerance") || row.verdict == Verdict::Shape,
                "{id}: {row:?}"
            );
        }
    }
}

#[test]
fn sec_8_5_thesis_rule_gains_at_least_as_much_as_the_others() {
    let r = report("sec_8_5");
    // Rows: (thesis, zero_standstill, pseudo_event) × (v, a), random v/a, amplitude.
    assert_eq!(r.rows.len(), 9);
    let pct = |i: usize| -> f64 {
        let s = &r.rows[i].ours;
        let n = s.split(' ').next().unwrap().replace('−', "-");
        n.parse().unwrap()
    };
    // The thesis's rule keeps v̂ where zero_standstill zeroes it: a skip gains at
    // least as much in velocity; every rule's best skip is no worse than σ = 0.
    assert!(pct(0) <= pct(2), "{} vs {}", r.rows[0].ours, r.rows[2].ours);
    for i in 0..8 {
        assert!(pct(i) <= 0.0, "{:?}", r.rows[i]);
    }
    // Larger slit errors: larger gains (random 0.05 counts vs the E2's 0.018).
    assert!(pct(6) < pct(0) && pct(7) < pct(1));
}

#[test]
fn sec_7_5_drc_recovers_the_rotation_and_beats_rc() {
    let r = report("sec_7_5");
    assert_eq!(r.rows[0].verdict, Verdict::Matches, "{:?}", r.rows[0]);
    let last = r.rows.last().unwrap();
    assert!(last.ours.starts_with('−'), "DRC below RC: {last:?}");
}

#[test]
fn ch6_hysteresis_ff_beats_feedback_only() {
    let r = report("ch6");
    assert_eq!(r.rows.len(), 5);
    // Both reductions are reductions.
    for row in &r.rows[3..] {
        assert!(row.ours.starts_with('−'), "{row:?}");
    }
}

/// The CLI: `--list`, an unknown id (exit status 1, nearest id named), and a run of
/// one experiment written twice to the same bytes, equal to the in-process output.
#[test]
fn cli_lists_refuses_unknown_ids_and_writes_the_same_bytes_twice() {
    use std::process::Command;
    let exe = env!("CARGO_BIN_EXE_nanomotion");
    let list = Command::new(exe)
        .args(["reproduce", "--list"])
        .output()
        .unwrap();
    assert!(list.status.success());
    let text = String::from_utf8_lossy(&list.stdout);
    for e in thesis::experiments() {
        assert!(text.contains(e.id), "{text}");
    }
    let bad = Command::new(exe)
        .args(["reproduce", "sec_8_6"])
        .output()
        .unwrap();
    assert!(!bad.status.success());
    let err = String::from_utf8_lossy(&bad.stderr);
    assert!(err.contains("nearest: `sec_8_5`"), "{err}");
    let dir = std::env::temp_dir().join(format!("nanomotion-reproduce-{}", std::process::id()));
    let run = || {
        let out = Command::new(exe)
            .args(["reproduce", "sec_8_5", "--quick", "--out"])
            .arg(&dir)
            .output()
            .unwrap();
        assert!(
            out.status.success(),
            "{}",
            String::from_utf8_lossy(&out.stderr)
        );
        (
            std::fs::read(dir.join("fidelity.md")).unwrap(),
            std::fs::read(dir.join("fidelity.json")).unwrap(),
        )
    };
    let first = run();
    assert_eq!(first, run(), "a re-run gives the same bytes");
    assert!(dir.join("timings.json").exists());
    let ours = outcomes().iter().find(|o| o.id == "sec_8_5").unwrap();
    let md = thesis::fidelity_markdown(
        std::slice::from_ref(ours),
        Mode::Quick,
        "nanomotion reproduce sec_8_5 --quick",
    );
    assert_eq!(String::from_utf8(first.0).unwrap(), md);
    let _ = std::fs::remove_dir_all(&dir);
}
