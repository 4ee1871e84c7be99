//! The AFM plant (Ch. 6, `afm-stage`): the "measured" x position comes from the
//! simulated metrological AFM stage with its asymmetric Coleman–Hodgdon
//! hysteresis, Table 6.1 noise and cross-coupling, driven open loop through a
//! `mux` (a vector drive); the nominal model is the same stage with its hysteresis
//! made linear (c = b: the anhysteretic line). The workflow must find the missing
//! hysteresis on the x drive, inside the `mux`, and cut the held-out rms by half.
//! (afm-stage is a dev-dependency only: plugins never depend on each other.)

use nanomotion_core::data::Dataset;
use nanomotion_core::graph::GraphSpec;
use nanomotion_plf::diagnose::{Options, diagnose};
use std::f64::consts::PI;
use std::sync::Arc;

const RATE: f64 = 1000.0;
const N: usize = 8000;

fn graph(hysteresis: &str) -> String {
    format!(
        "base_rate_hz: {RATE}\nduration_s: {}\nseed: 5\nblocks:\n  - {{ name: drive, type: data_column, column: v }}\n  - {{ name: v_yz, type: constant, value: 50.0, width: 2 }}\n  - {{ name: mux, type: mux, widths: [1, 2] }}\n  - {{ name: stage, type: afm_stage, initial_v: [50.0, 50.0, 50.0]{hysteresis} }}\n  - {{ name: split, type: demux, widths: [1, 2] }}\nconnections:\n  - {{ from: drive.y, to: mux.in0 }}\n  - {{ from: v_yz.y, to: mux.in1 }}\n  - {{ from: mux.y, to: stage.v }}\n  - {{ from: stage.pos, to: split.u }}\ncompare:\n  - {{ signal: split.y0, column: \"x\" }}\n",
        N as f64 / RATE
    )
}

#[test]
fn missing_hysteresis_of_the_afm_stage_is_named() {
    let _ = std::any::type_name::<afm_stage::stage::AfmStage>();
    let _ = std::any::type_name::<nanomotion_plf::effects::Effect>();
    // Drive: 50 V ± 20 V strokes at 0.25 Hz and 0.7 Hz, plus a little 5–40 Hz content.
    let v: Vec<f64> = (0..N)
        .map(|k| {
            let t = k as f64 / RATE;
            50.0 + 14.0 * (2.0 * PI * 0.25 * t).sin()
                + 6.0 * (2.0 * PI * 0.7 * t + 1.0).sin()
                + 0.5 * (2.0 * PI * 13.0 * t).sin()
                + 0.3 * (2.0 * PI * 37.0 * t + 0.4).sin()
        })
        .collect();
    let drive = Dataset::from_columns("afm", RATE, 0.0, vec![("v".into(), v.clone())]).unwrap();
    // Truth: the stage as it is.
    let mut truth = GraphSpec::from_yaml(&graph(""), "truth.yaml").unwrap();
    truth.log.push("split.y0".into());
    let (mut s, _) = truth.build_with_data(Arc::new(drive)).unwrap();
    let r = s.run(|_| {});
    let x = r
        .logs
        .iter()
        .find(|l| l.name == "split.y0")
        .unwrap()
        .data
        .clone();
    let data =
        Dataset::from_columns("afm", RATE, 0.0, vec![("v".into(), v), ("x".into(), x)]).unwrap();
    // Nominal: no hysteresis (c = b on every axis).
    let linear = ", hysteresis: [{ trace: { alpha: 0.03, b: 1.0, c: 1.0 }, retrace: { alpha: 0.03, b: 1.0, c: 1.0 } }, { trace: { alpha: 0.03, b: 0.98, c: 0.98 }, retrace: { alpha: 0.03, b: 0.98, c: 0.98 } }, { trace: { alpha: 0.03, b: 0.2, c: 0.2 }, retrace: { alpha: 0.03, b: 0.2, c: 0.2 } }]";
    let nominal = GraphSpec::from_yaml(&graph(linear), "nominal.yaml").unwrap();
    let rep = diagnose(&nominal, &data, &Options::default()).unwrap();
    eprintln!(
        "AFM: found {:?}; held-out rms {:.3e} -> {:.3e} m; {}",
        rep.found, rep.nominal.holdout_rms, rep.final_scores.holdout_rms, rep.stopped_because
    );
    for c in rep.steps.first().map(|s| &s.candidates[..4]).unwrap_or(&[]) {
        eprintln!("    {} {} {:.3e}", c.effect, c.site, c.holdout_rms);
    }
    assert_eq!(
        rep.found.first().map(String::as_str),
        Some("hysteresis"),
        "{:?}",
        rep.found
    );
    let s = &rep.steps[0];
    assert!(s.site.contains("mux.in0"), "{}", s.site);
    assert!(s.holdout_rms_after < 0.5 * s.holdout_rms_before);
}
