//! The quickstart graph, end to end through the library: it builds with the
//! reported rate transitions, tracks the ramp within the encoder's resolution, its
//! outputs are written and consistent with each other, and ticks do not allocate.

use nanomotion::core::graph::GraphSpec;
use std::path::PathBuf;

fn quickstart() -> String {
    std::fs::read_to_string(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/examples/quickstart.yaml"
    ))
    .unwrap()
}

#[test]
fn quickstart_tracks_within_one_encoder_count_and_writes_outputs() {
    nanomotion::link_plugins();
    let (mut s, report) = GraphSpec::from_yaml(&quickstart(), "quickstart.yaml")
        .unwrap()
        .build()
        .unwrap();
    // 4 kHz blocks feeding the 40 kHz stage and back: transitions are explicit.
    assert!(
        report
            .rate_transitions
            .iter()
            .any(|r| r.contains("zero-order hold"))
    );
    assert!(
        report
            .rate_transitions
            .iter()
            .any(|r| r.contains("decimation"))
    );
    let res = s.run(|_| {});
    s.check_finite().unwrap();
    assert_eq!(res.duration_s, 2.0);

    let lsb = 5e-9;
    let measured = res.scores.iter().find(|s| s.signal == "err.y").unwrap();
    let truth = res
        .scores
        .iter()
        .find(|s| s.signal == "true_err.y")
        .unwrap();
    // A type-2 loop (integrator in plant and controller) tracks a ramp with zero
    // steady-state error: what is left is the encoder quantisation, at most one
    // count in the measured error, and the true error stays within a count too.
    assert!(
        measured.max_abs <= lsb * 1.0001,
        "measured error {:e}",
        measured.max_abs
    );
    assert!(truth.max_abs < 2.0 * lsb, "true error {:e}", truth.max_abs);
    assert!(truth.rms > 0.0 && truth.rms < lsb);

    // Files.
    let dir = std::env::temp_dir().join(format!("nm-quickstart-{}", std::process::id()));
    let files = nanomotion::output::write_all(&dir, &res, &report.rate_transitions).unwrap();
    let names: Vec<String> = files
        .iter()
        .map(|f| f.file_name().unwrap().to_string_lossy().into_owned())
        .collect();
    for want in ["metrics.json", "cumulative_psd.svg", "trace_stage_y.svg"] {
        assert!(
            names.iter().any(|n| n == want),
            "missing {want} in {names:?}"
        );
    }
    // Logs at two rates -> one CSV per rate, with a row per sample.
    let csv40k = read(&dir.join("signals_40000hz.csv"));
    assert_eq!(csv40k.lines().count(), 1 + 80_000);
    assert!(csv40k.starts_with("t_s,stage.y"));
    let csv4k = read(&dir.join("signals_4000hz.csv"));
    assert_eq!(csv4k.lines().count(), 1 + 8_000);

    // metrics.json: the cumulative PSD's end value is the variance (Welch detrends
    // the mean), i.e. rms² − mean² of the same samples, up to the segments' edges.
    let m: serde_json::Value = serde_json::from_str(&read(&dir.join("metrics.json"))).unwrap();
    let ends = m["cumulative_psd_end"].as_array().unwrap();
    for e in ends {
        let sig = e["signal"].as_str().unwrap();
        let from_s = e["from_s"].as_f64().unwrap();
        let end = e["end"].as_f64().unwrap();
        let sc = res
            .scores
            .iter()
            .find(|s| s.signal == sig && s.from_s == from_s)
            .unwrap();
        let var = sc.rms * sc.rms - sc.mean * sc.mean;
        assert!(
            (end - var).abs() < 0.25 * var,
            "{sig}: cumulative PSD end {end:e} vs variance {var:e}"
        );
    }
    std::fs::remove_dir_all(dir).ok();
}

fn read(p: &PathBuf) -> String {
    std::fs::read_to_string(p).unwrap_or_else(|e| panic!("{}: {e}", p.display()))
}

#[test]
fn quickstart_ticks_do_not_allocate() {
    let yaml = quickstart().replace("duration_s: 2.0", "duration_s: 1.0");
    let (mut s, _) = GraphSpec::from_yaml(&yaml, "quickstart.yaml")
        .unwrap()
        .build()
        .unwrap();
    s.tick();
    let info = allocation_counter::measure(|| s.step_n(10_000));
    assert_eq!(info.count_total, 0, "{info:?}");
}

#[test]
fn quickstart_is_bit_for_bit_deterministic() {
    let run = || {
        let (mut s, _) = GraphSpec::from_yaml(&quickstart(), "q")
            .unwrap()
            .build()
            .unwrap();
        s.run(|_| {})
    };
    let (a, b) = (run(), run());
    let bits = |r: &nanomotion::core::scheduler::RunResult| {
        r.logs
            .iter()
            .flat_map(|l| l.data.iter().map(|v| v.to_bits()))
            .collect::<Vec<_>>()
    };
    assert_eq!(bits(&a), bits(&b));
}
