//! Issue 13 item 3: a long run's log memory is bounded and independent of its
//! duration. Logs are streamed chunk by chunk into the CSV writer
//! (`GraphSpec::build_streamed`, `Scheduler::run_streamed`, `output::RunWriter`),
//! scores and cumulative PSDs are computed online.

use nanomotion::core::graph::{GraphSpec, LOG_CHUNK_TICKS, MAX_GRAPH_BYTES};
use nanomotion::output::RunWriter;

/// Noise and a sinusoid at `rate` Hz for `duration` s; both logged, the sum
/// scored twice (from 0 s and from 0.5 s).
fn graph(rate: f64, duration: f64) -> GraphSpec {
    let yaml = format!(
        "title: streamed\nbase_rate_hz: {rate}\nduration_s: {duration}\nseed: 3\nblocks:\n  - {{ name: n, type: white_noise, std: 2.0, mean: 0.5 }}\n  - {{ name: s, type: sinusoid, amplitude: 1.0, frequency_hz: 37.0 }}\n  - {{ name: e, type: sum, signs: \"++\" }}\nconnections:\n  - {{ from: n.y, to: e.in0 }}\n  - {{ from: s.y, to: e.in1 }}\nlog: [n.y, s.y]\nscore:\n  - {{ signal: e.y }}\n  - {{ signal: e.y, from_s: 0.5 }}\n"
    );
    GraphSpec::from_yaml(&yaml, "streamed.yaml").unwrap()
}

fn scratch(tag: &str) -> std::path::PathBuf {
    let d = std::env::temp_dir().join(format!("nm-streamed-{tag}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    d
}

/// Run `spec` streamed into `dir`; returns (peak heap bytes during the run and
/// the writing, the run result).
fn run_streamed(spec: GraphSpec, dir: &std::path::Path) -> (u64, serde_json::Value) {
    let (mut sched, report) = spec.build_streamed(None).unwrap();
    let mut metrics = serde_json::Value::Null;
    let info = allocation_counter::measure(|| {
        let mut w = RunWriter::new(dir, sched.score_signals()).unwrap();
        let result = sched.run_streamed(|c| w.chunk(c), |_| {}).unwrap();
        assert!(result.logs.iter().all(|l| l.data.is_empty()));
        w.finish(&result, &report.rate_transitions, |_, _| {})
            .unwrap();
    });
    sched.check_finite().unwrap();
    if let Ok(t) = std::fs::read_to_string(dir.join("metrics.json")) {
        metrics = serde_json::from_str(&t).unwrap();
    }
    (info.bytes_max, metrics)
}

fn csv_rows(path: &std::path::Path) -> usize {
    std::fs::read_to_string(path).unwrap().lines().count() - 1
}

#[test]
fn a_run_whose_whole_logs_exceed_the_memory_cap_builds_streamed_with_one_chunk_of_logs() {
    nanomotion::link_plugins();
    // 1e9 ticks (inside the 2e9 limit), two logs and a score: 24 GB of whole logs.
    let whole = graph(1.0e6, 1000.0).build().unwrap_err().to_string();
    assert!(
        whole.contains("more than the") && whole.contains("build_streamed"),
        "{whole}"
    );
    let (sched, _) = graph(1.0e6, 1000.0).build_streamed(None).unwrap();
    assert!(sched.is_streamed());
    // Three channels of width 1, one chunk each.
    assert_eq!(sched.log_capacity_bytes() as u64, 3 * LOG_CHUNK_TICKS * 8);
    assert!(sched.log_capacity_bytes() < MAX_GRAPH_BYTES / 1000);
}

#[test]
fn streamed_memory_does_not_grow_with_duration_and_the_files_are_complete() {
    nanomotion::link_plugins();
    let rate = 100_000.0;
    let short = scratch("short");
    let long = scratch("long");
    let (peak_short, _) = run_streamed(graph(rate, 1.5), &short);
    let (peak_long, metrics) = run_streamed(graph(rate, 6.0), &long);
    let rows = 600_000;
    // The CSV has every sample; the times run to the end.
    assert_eq!(csv_rows(&long.join("signals.csv")), rows);
    let last = std::fs::read_to_string(long.join("signals.csv"))
        .unwrap()
        .lines()
        .last()
        .unwrap()
        .split(',')
        .next()
        .unwrap()
        .parse::<f64>()
        .unwrap();
    assert_eq!(last, (rows - 1) as f64 / rate);
    // Whole logs of the long run would be 3 × 600 000 × 8 = 14.4 MB; streamed, the
    // peak is a fraction of that and the same for a run four times shorter.
    let whole_bytes = 3 * rows as u64 * 8;
    assert!(
        peak_long < whole_bytes / 3,
        "peak {peak_long} B vs whole logs {whole_bytes} B"
    );
    assert!(
        peak_long <= peak_short + peak_short / 20,
        "peak grows with duration: {peak_short} B for 1.5 s, {peak_long} B for 6 s"
    );

    // Scores and cumulative-PSD ends equal those of the whole-log run.
    let (mut sched, report) = graph(rate, 6.0).build().unwrap();
    let whole = sched.run(|_| {});
    let whole_dir = scratch("whole");
    nanomotion::output::write_all(&whole_dir, &whole, &report.rate_transitions).unwrap();
    let m_whole: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(whole_dir.join("metrics.json")).unwrap())
            .unwrap();
    assert_eq!(metrics["scores"], m_whole["scores"], "scores bit for bit");
    let (a, b) = (
        metrics["cumulative_psd_end"].as_array().unwrap(),
        m_whole["cumulative_psd_end"].as_array().unwrap(),
    );
    assert_eq!(a.len(), 2);
    for (x, y) in a.iter().zip(b) {
        assert_eq!(x["from_s"], y["from_s"]);
        let (x, y) = (x["end"].as_f64().unwrap(), y["end"].as_f64().unwrap());
        assert!((x - y).abs() <= 1e-12 * y.abs(), "{x} vs {y}");
    }
    // An independent check of the end: the variance of the scored samples
    // (std 2 noise plus a unit sinusoid: 4 + 1/2, within Welch's leakage).
    let end = a[0]["end"].as_f64().unwrap();
    assert!((end - 4.5).abs() < 0.05, "{end}");
    // Same CSV content as the whole-log writer.
    assert_eq!(
        std::fs::read(long.join("signals.csv")).unwrap(),
        std::fs::read(whole_dir.join("signals.csv")).unwrap()
    );
    for d in [short, long, whole_dir] {
        let _ = std::fs::remove_dir_all(d);
    }
}
