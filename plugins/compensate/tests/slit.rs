//! Encoder slit errors → the slit-error correction table (hots' `slit_correction`).
//!
//! A record from plf's truth generator with slit errors hidden (the stage's
//! position rounded to the encoder's lsb q = 50 nm, each slit's reading
//! displaced by its own error, σ = q/2, 8–20 slits a revolution), `diagnose`
//! on the nominal (the stage and the encoder's rounding), then `compensate` on
//! the PID loop of `effects.rs` reading the position through the same encoder.

mod support;

use nanomotion_compensate::{CompError, Options, compensate, named};
use nanomotion_core::graph::GraphSpec;
use nanomotion_core::{BuildContext, Tick};
use nanomotion_plf::diagnose::{self, diagnose};
use nanomotion_plf::{generate, surgery};
use serde_json::{Value, json};

/// The diagnosis of a generated record with slit errors, its nominal, and the
/// PID loop (80 Hz crossover, a 1 µm sine at 5 Hz, scored from 1.5 s of 3 s)
/// whose error sum reads the stage through the nominal's `encoder`.
fn case(seed: u64) -> (nanomotion_plf::Report, GraphSpec, generate::Record) {
    let rec = generate::second_order("encoder_slit_error", seed, 8000, false).unwrap();
    let nominal = GraphSpec::from_yaml(&rec.nominal_yaml, "nominal.yaml").unwrap();
    let rep = diagnose(&nominal, &rec.data, &diagnose::Options::default()).unwrap();
    assert_eq!(
        rep.found.first().map(String::as_str),
        Some("encoder_slit_error"),
        "{}",
        rec.truth
    );
    let json_of = |name: &str| {
        let b = nominal.blocks.iter().find(|b| b.name == name).unwrap();
        surgery::block_to_json(b.block.as_ref())
    };
    let mut g = support::pid_loop(
        &json_of("stage"),
        80.0,
        "type: sinusoid, amplitude: 1.0e-6, frequency_hz: 5.0",
        (3.0, 1.5),
        "",
    );
    g.blocks.push(nanomotion_core::graph::BlockSpec {
        name: "encoder".into(),
        rate_hz: None,
        block: surgery::block_from_json(json_of("encoder")).unwrap(),
    });
    for c in &mut g.connections {
        if c.from == "stage.y" {
            c.from = "encoder.y".into();
        }
    }
    g.connections.push(nanomotion_core::graph::Connection {
        from: "stage.y".into(),
        to: "encoder.u".into(),
    });
    (rep, g, rec)
}

/// The fitted `encoder_slit_error` block of the augmented model.
fn fitted(rep: &nanomotion_plf::Report) -> Value {
    let aug = rep.augmented.as_ref().unwrap();
    let b = aug
        .blocks
        .iter()
        .find(|b| b.name == rep.steps[0].block.name)
        .unwrap();
    surgery::block_to_json(b.block.as_ref())
}

#[test]
fn slit_errors_get_the_correction_table_and_the_loop_tracks_as_on_the_nominal() {
    let (rep, loop_, rec) = case(1);
    // Kept with `keep` so the written block can be read whatever the 1 % rule
    // says (checked below through the note).
    let out = support::compensate_named(&rep, &loop_, true, &rec.truth);
    let r = &out.report;
    let c = &r.compensators[0];
    assert_eq!(
        (c.effect.as_str(), c.type_name.as_str()),
        ("encoder_slit_error", "slit_correction")
    );
    // The table is ê = −e/pitch of the fitted errors, count 0 read at slit
    // 0's centre (origin + pitch/2).
    let p = fitted(&rep);
    let (pitch, origin) = (p["pitch"].as_f64().unwrap(), p["origin"].as_f64().unwrap());
    let errors: Vec<f64> = p["errors"]
        .as_array()
        .unwrap()
        .iter()
        .map(|v| v.as_f64().unwrap())
        .collect();
    let b = out
        .compensated
        .blocks
        .iter()
        .find(|b| b.name == "comp_encoder_slit_error")
        .expect("kept with keep");
    let v = surgery::block_to_json(b.block.as_ref());
    assert_eq!(v["resolution"].as_f64(), Some(pitch));
    assert_eq!(v["zero"].as_f64(), Some(origin + 0.5 * pitch));
    let table: Vec<f64> = v["edge_offsets_counts"]
        .as_array()
        .unwrap()
        .iter()
        .map(|v| v.as_f64().unwrap())
        .collect();
    assert_eq!(table, errors.iter().map(|e| -e / pitch).collect::<Vec<_>>());
    // In the measurement path: the encoder → the table → the error sum.
    let connected = |from: &str, to: &str| {
        out.compensated
            .connections
            .iter()
            .any(|c| c.from == from && c.to == to)
    };
    assert!(connected("encoder.y", "comp_encoder_slit_error.u"));
    assert!(connected("comp_encoder_slit_error.y", "err.in1"));
    assert!(r.gate.passes);
    support::runs_on_the_wall_clock_as_offline(
        &out.compensated,
        &["encoder.y", "comp_encoder_slit_error.y", "err.y"],
    );
    // The exact inverse: every reading kq + e_k goes back to kq, so the loop on
    // the augmented model with the table is the user's loop on the nominal
    // plant, simulated here on its own, to round-off.
    let nominal = support::score_rms(&loop_);
    eprintln!(
        "rms: nominal {nominal:.4e}, with the slit errors {:.4e}, corrected {:.4e} ({:.1} % cut; {} slits, largest error {:.3} lsb, noise margin {:.3} lsb)",
        r.before.rms,
        r.after.rms,
        r.cut_percent,
        errors.len(),
        c.design["largest_error"] / pitch,
        c.design["noise_margin"] / pitch
    );
    assert!(
        (c.alone.rms - nominal).abs() < 1e-9 * nominal,
        "{} vs {nominal}",
        c.alone.rms
    );
    assert!(c.effect_error_cut_percent > 100.0 - 1e-6, "{c:?}");
    // The 1 % rule: without `keep` it would be dropped exactly when it cuts
    // the scored rms by less than 1 % (the loop's own error at 5 Hz is most
    // of it); the note says so when `keep` alone keeps it.
    assert_eq!(
        c.note.as_deref().is_some_and(|n| n.contains("--keep")),
        c.cut_percent < 1.0,
        "{c:?}"
    );
    // The noise margin, by brute force on the built block: a reading kq + e_k
    // moved by 0.99 of it either way still lands on kq + the move.
    let mut block = surgery::block_from_json(v.clone()).unwrap();
    block.build(&BuildContext::new("b", 1e-3, 0)).unwrap();
    let margin = c.design["noise_margin"];
    assert!(margin > 0.0 && margin < 0.5 * pitch, "{margin:e}");
    for k in -200i64..200 {
        for d in [-0.99 * margin, 0.0, 0.99 * margin] {
            let e = errors[k.rem_euclid(errors.len() as i64) as usize];
            let reading = k as f64 * pitch + e + d;
            let mut y = [0.0];
            block.output(Tick::new(0, 1e-3), &[reading], &mut y);
            assert!(
                (y[0] - (k as f64 * pitch + d)).abs() < 1e-9 * pitch,
                "slit {k}, {d:e}"
            );
        }
    }
}

/// A fitted table that is not one (a non-positive pitch) is refused naming the
/// effect and the fix, before any loop is simulated.
#[test]
fn a_slit_table_without_a_pitch_is_refused_by_name() {
    let (rep, loop_, _) = case(1);
    let mut aug = surgery::clone_spec(rep.augmented.as_ref().unwrap()).unwrap();
    let name = rep.steps[0].block.name.clone();
    let b = aug.blocks.iter_mut().find(|b| b.name == name).unwrap();
    let mut v = surgery::block_to_json(b.block.as_ref());
    v["pitch"] = json!(-1.0e-8);
    b.block = surgery::block_from_json(v).unwrap();
    let err = compensate(&aug, &loop_, &named::from_report(&rep), &Options::default()).unwrap_err();
    assert!(
        matches!(&err, CompError::Design { effect, problem } if effect == "encoder_slit_error" && problem.contains("resolution") && problem.contains("model_augmented.yaml")),
        "{err}"
    );
}
