//! Issue 13 item 9: blocks declare output units (or the graph's `units:`
//! section sets them); they appear in CSV headers, `metrics.json` and plot axes
//! (engineering prefixes, not ×1e-9); the cumulative PSD is drawn as its square
//! root in the signal's unit, its end value the standard deviation.

use nanomotion::core::graph::GraphSpec;

fn quickstart(duration_s: f64) -> GraphSpec {
    nanomotion::link_plugins();
    let mut spec = GraphSpec::from_file(std::path::Path::new("examples/quickstart.yaml")).unwrap();
    spec.duration_s = duration_s;
    spec
}

#[test]
fn units_reach_csv_headers_metrics_and_plot_axes() {
    let (mut sched, report) = quickstart(1.0).build_streamed(None).unwrap();
    let dir = std::env::temp_dir().join(format!("nm-units-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    let mut w = nanomotion::output::RunWriter::new(&dir, sched.score_signals()).unwrap();
    let result = sched.run_streamed(|c| w.chunk(c), |_| {}).unwrap();
    w.finish(&result, &report.rate_transitions, |_, _| {})
        .unwrap();

    // Declared (`constant_velocity` → m), set by `units:` (stage.y, pi.u) and
    // followed through a sum and a quantizer (err.y = ref − encoder).
    let csv = std::fs::read_to_string(dir.join("signals_4000hz.csv")).unwrap();
    let header = csv.lines().next().unwrap();
    assert_eq!(header, "t_s,ref.y (m),pi.u (Hz),err.y (m)");
    let csv = std::fs::read_to_string(dir.join("signals_40000hz.csv")).unwrap();
    assert_eq!(
        csv.lines().next().unwrap(),
        "t_s,stage.y (m),true_err.y (m)"
    );

    let m: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("metrics.json")).unwrap()).unwrap();
    for s in m["scores"].as_array().unwrap() {
        assert_eq!(s["unit"], "m", "{s}");
    }
    for (c, s) in m["cumulative_psd_end"]
        .as_array()
        .unwrap()
        .iter()
        .zip(m["scores"].as_array().unwrap())
    {
        assert_eq!(c["unit"], "m²");
        let (end, std) = (c["end"].as_f64().unwrap(), c["std"].as_f64().unwrap());
        assert!((std - end.sqrt()).abs() <= 1e-14 * std);
        // The end is the variance: rms² − mean² of the scored samples (within
        // Welch's window loss), not rms² — true_err has a mean of about −1.1 nm.
        let (rms, mean) = (s["rms"].as_f64().unwrap(), s["mean"].as_f64().unwrap());
        let var = rms * rms - mean * mean;
        assert!((end - var).abs() < 0.1 * var, "{end} vs {var} ({s})");
    }

    // Axes in engineering units: the stage moves 10 µm, the errors are nm.
    let trace = std::fs::read_to_string(dir.join("trace_stage_y.svg")).unwrap();
    assert!(trace.contains("stage.y (µm)"), "stage trace axis");
    assert!(!trace.contains("×1e"));
    let cp = std::fs::read_to_string(dir.join("cumulative_psd.svg")).unwrap();
    assert!(cp.contains("√(cumulative PSD) (nm)"), "cumulative PSD axis");
    assert!(cp.contains("from 0.5 s"));
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn a_units_entry_for_a_missing_signal_is_an_error_naming_it() {
    let mut spec = quickstart(0.1);
    spec.units.insert("stag.y".into(), "m".into());
    let e = spec.build().unwrap_err().to_string();
    assert!(e.contains("stag.y") && e.contains("units"), "{e}");
    let mut spec = quickstart(0.1);
    spec.units.insert("stage.y".into(), "m\n".into());
    let e = spec.build().unwrap_err().to_string();
    assert!(e.contains("printable"), "{e}");
}
