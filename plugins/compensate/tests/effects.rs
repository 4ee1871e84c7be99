//! One effect at a time, end to end with no hand-written compensator: a record
//! from plf's truth simulator (`generate::second_order`: each effect in its own
//! physical form, not the block the workflow fits), `diagnose` on the nominal,
//! then `compensate` on a PID loop around the nominal stage.

mod support;

use nanomotion_compensate::{Options, Outcome, compensate, named};
use nanomotion_core::graph::GraphSpec;
use nanomotion_plf::diagnose::{self, diagnose};
use nanomotion_plf::{generate, surgery};
use serde_json::Value;

/// The PID loop of [`support::pid_loop`] at an 80 Hz crossover, the reference
/// `reference` (a block map), scored from 1.5 s of 3 s.
fn controller(stage: &Value, reference: &str) -> GraphSpec {
    support::pid_loop(stage, 80.0, reference, (3.0, 1.5), "")
}

/// Diagnose a generated record with `hidden`, then compensate the PID loop.
fn case(hidden: &str, seed: u64, reference: &str) -> (nanomotion_plf::Report, Outcome) {
    case_with(hidden, seed, reference, false)
}

/// [`case`], keeping every compensator when `keep`.
fn case_with(
    hidden: &str,
    seed: u64,
    reference: &str,
    keep: bool,
) -> (nanomotion_plf::Report, Outcome) {
    let _ = std::any::type_name::<nanomotion_plf::effects::Effect>();
    let rec = generate::second_order(hidden, seed, 8000, false).unwrap();
    let nominal = GraphSpec::from_yaml(&rec.nominal_yaml, "nominal.yaml").unwrap();
    let rep = diagnose(&nominal, &rec.data, &diagnose::Options::default()).unwrap();
    // Named first (a further name, padding, gets its own compensator, which the
    // validation keeps only if it helps).
    assert_eq!(
        rep.found.first().map(String::as_str),
        Some(hidden),
        "{}",
        rec.truth
    );
    let stage = nominal.blocks.iter().find(|b| b.name == "stage").unwrap();
    let loop_ = controller(&surgery::block_to_json(stage.block.as_ref()), reference);
    let out = support::compensate_named(&rep, &loop_, keep, &format!("{hidden}: {}", rec.truth));
    // Every written graph on the wall clock, bit for bit as offline.
    assert!(out.report.gate.passes, "{:?}", out.report.gate);
    support::runs_on_the_wall_clock_as_offline(&out.compensated, &[]);
    (rep, out)
}

fn connected(spec: &GraphSpec, from: &str, to: &str) -> bool {
    spec.connections
        .iter()
        .any(|c| c.from == from && c.to == to)
}

#[test]
fn friction_gets_a_feed_forward_from_the_reference_velocity() {
    let (_, out) = case(
        "friction",
        1,
        "type: sinusoid, amplitude: 1.0e-6, frequency_hz: 2.0",
    );
    let r = &out.report;
    let c = &r.compensators[0];
    assert_eq!(c.type_name, "friction");
    assert_eq!(c.effect, "friction");
    // The fitted friction, read from the reference, subtracted at the stage.
    let g = &out.compensated;
    assert!(connected(g, "ref.y", "comp_friction.u"));
    let sum = g
        .connections
        .iter()
        .find(|c| c.from == "comp_friction.y")
        .map(|c| c.to.split('.').next().unwrap().to_string())
        .unwrap();
    assert!(connected(g, &format!("{sum}.y"), "stage.u"));
    let signs = g.blocks.iter().find(|b| b.name == sum).unwrap();
    assert_eq!(surgery::block_to_json(signs.block.as_ref())["signs"], "+-");
    // The loop's error is mostly its own (the reference through S); of the
    // error the friction causes (e − e of the loop without it) the
    // feed-forward removes more than half.
    assert!(c.kept && c.effect_error_cut_percent > 50.0, "{c:?}");
}

#[test]
fn an_unmodelled_resonance_gets_its_inverse_as_a_notch() {
    let (rep, out) = case(
        "unmodeled_resonance",
        1,
        "type: sinusoid, amplitude: 1.0e-6, frequency_hz: 5.0",
    );
    let c = &out.report.compensators[0];
    assert_eq!(c.type_name, "unmodeled_resonance");
    // Its zeros sit on the fitted resonance's poles and its poles on the zeros.
    let fitted = &rep.steps[0].final_params;
    assert_eq!(c.design["notch_hz"], fitted["f_pole_hz"]);
    assert_eq!(c.design["notch_zeta"], fitted["zeta_pole"]);
    assert_eq!(c.design["pole_hz"], fitted["f_zero_hz"]);
    // Kept exactly when it cuts the rms by 1 % (this loop, far below the
    // resonance, hardly feels it: then it is dropped, and says so).
    assert_eq!(c.kept, c.cut_percent >= 1.0, "{c:?}");
    if !c.kept {
        assert!(c.note.as_deref().unwrap().starts_with("dropped"));
        assert!(!out.compensated.blocks.iter().any(|b| b.name == c.block));
    }
}

#[test]
fn a_position_dependent_gain_gets_gain_scheduling() {
    let (rep, out) = case(
        "position_dependent_gain",
        1,
        "type: sinusoid, amplitude: 1.0e-6, frequency_hz: 5.0",
    );
    let r = &out.report;
    let c = &r.compensators[0];
    assert_eq!(c.type_name, "gain_scheduled");
    assert!(
        c.place.contains("stage.u") && c.place.contains("stage.y"),
        "{}",
        c.place
    );
    // The schedule is 1/g of the fitted gain: at the fitted centre,
    // 1/(1 + g0) (the polynomial's terms vanish there).
    let p = &rep.steps[0].final_params;
    let centre = rep
        .augmented
        .as_ref()
        .unwrap()
        .blocks
        .iter()
        .find(|b| b.name == rep.steps[0].block.name)
        .map(|b| {
            surgery::block_to_json(b.block.as_ref())["center"]
                .as_f64()
                .unwrap_or(0.0)
        })
        .unwrap();
    let laws = nanomotion_plf::surgery::block_to_json(
        surgery::block_from_json(serde_json::json!({"type": "gain", "k": 1.0}))
            .unwrap()
            .as_ref(),
    );
    let _ = laws;
    assert!(c.design["table_from"] < centre && centre < c.design["table_to"]);
    let g0 = p.get("g0").copied().unwrap_or(0.0);
    let with = |k: &Value| k.as_f64().unwrap();
    if c.kept {
        let g = &out.compensated;
        let b = g
            .blocks
            .iter()
            .find(|b| b.name == "comp_position_dependent_gain")
            .unwrap();
        let v = surgery::block_to_json(b.block.as_ref());
        let law = &v["schedule"][0];
        let (x, k): (Vec<f64>, Vec<f64>) = (
            law["x"].as_array().unwrap().iter().map(with).collect(),
            law["gain"].as_array().unwrap().iter().map(with).collect(),
        );
        let mid = x.len() / 2;
        assert!((x[mid] - centre).abs() < 1e-12 * (x[x.len() - 1] - x[0]));
        assert!(
            (k[mid] - 1.0 / (1.0 + g0)).abs() < 1e-12,
            "{} vs {}",
            k[mid],
            1.0 / (1.0 + g0)
        );
        assert!(connected(
            g,
            "stage.y",
            "comp_position_dependent_gain.sigma"
        ));
    }
    assert_eq!(c.kept, c.cut_percent >= 1.0, "{c:?}");
}

#[test]
fn quantization_is_stated_with_the_floor_it_sets() {
    let (rep, out) = case(
        "quantization",
        1,
        "type: sinusoid, amplitude: 1.0e-6, frequency_hz: 5.0",
    );
    let r = &out.report;
    assert!(r.compensators.is_empty());
    let n = &r.not_compensated[0];
    assert_eq!(n.effect, "quantization");
    assert!(n.reason.starts_with("no compensation"), "{}", n.reason);
    // The floor is lsb/√12 of the fitted quantiser (uniform rounding error).
    let lsb = rep.steps[0].final_params["lsb"];
    assert!((n.figures["rms_floor"] - lsb / 12f64.sqrt()).abs() < 1e-15 * lsb);
    // Nothing inserted: the compensated graph is the user's graph.
    assert_eq!(out.compensated.blocks.len(), 4);
    assert_eq!(r.after, r.before);
}

#[test]
fn a_coupling_on_the_measurement_is_decoupled() {
    let rec = generate::two_axis("axis_coupling", 1, 8000).unwrap();
    let nominal = GraphSpec::from_yaml(&rec.nominal_yaml, "nominal.yaml").unwrap();
    let rep = diagnose(&nominal, &rec.data, &diagnose::Options::default()).unwrap();
    assert_eq!(
        rep.found.first().map(String::as_str),
        Some("axis_coupling"),
        "{}",
        rec.truth
    );
    // Two PID loops: x holds a set-point, y tracks a 5 Hz sine; x is scored.
    let loop_for = |axis: &str, reference: &str| {
        let stage = nominal
            .blocks
            .iter()
            .find(|b| b.name == format!("stage_{axis}"))
            .unwrap();
        let mut g = controller(&surgery::block_to_json(stage.block.as_ref()), reference);
        // Every block gets the axis suffix (the stage already has it).
        let name = |b: &str| {
            if b.starts_with("stage") {
                b.to_string()
            } else {
                format!("{b}_{axis}")
            }
        };
        let signal = |sig: &str| {
            let (b, p) = sig.split_once('.').unwrap();
            format!("{}.{p}", name(if b == "stage" { &stage.name } else { b }))
        };
        for b in &mut g.blocks {
            b.name = if b.name == "stage" {
                stage.name.clone()
            } else {
                name(&b.name)
            };
        }
        for c in &mut g.connections {
            c.from = signal(&c.from);
            c.to = signal(&c.to);
        }
        for sc in &mut g.score {
            sc.signal = signal(&sc.signal);
        }
        g
    };
    let mut two = loop_for("x", "type: constant, value: 1.0e-6");
    let y = loop_for("y", "type: sinusoid, amplitude: 1.0e-6, frequency_hz: 5.0");
    two.blocks.extend(y.blocks);
    two.connections.extend(y.connections);
    let out = compensate(
        rep.augmented.as_ref().unwrap(),
        &two,
        &named::from_report(&rep),
        &Options::default(),
    )
    .unwrap();
    eprintln!(
        "{}: {}",
        rec.truth,
        serde_json::to_string_pretty(&out.report).unwrap()
    );
    assert!(out.report.gate.passes, "{:?}", out.report.gate);
    support::runs_on_the_wall_clock_as_offline(&out.compensated, &[]);
    let c = &out.report.compensators[0];
    assert_eq!(c.type_name, "axis_coupling");
    // The decoupling is minus the fitted coupling, read from the other axis.
    let fitted = rep.steps[0].final_params.values().next().copied().unwrap();
    let b = out
        .compensated
        .blocks
        .iter()
        .find(|b| b.name == "comp_axis_coupling")
        .unwrap();
    let coupling = surgery::block_to_json(b.block.as_ref())["coupling"][0]
        .as_f64()
        .unwrap();
    assert_eq!(coupling, -fitted);
    // ... and minus the true coupling κ of the generator (`y = x1 + κ·x2`) within 5 %.
    let kappa: f64 = rec
        .truth
        .trim_start_matches("y = x1 + ")
        .trim_end_matches("·x2")
        .parse()
        .unwrap();
    assert!(
        (coupling + kappa).abs() < 0.05 * kappa.abs(),
        "{coupling} vs κ = {kappa}"
    );
    assert!(connected(
        &out.compensated,
        "stage_y.y",
        "comp_axis_coupling.s"
    ));
    assert!(connected(
        &out.compensated,
        "stage_x.y",
        "comp_axis_coupling.u"
    ));
    assert!(connected(
        &out.compensated,
        "comp_axis_coupling.y",
        "err_x.in1"
    ));
    // The x loop's measured error is then the nominal one (the set-point held):
    // the coupled motion of y is gone from it.
    assert!(out.report.cut_percent > 90.0, "{}", out.report.cut_percent);
    assert!(out.report.after.rms < 0.1 * out.report.before.rms);
}

#[test]
fn creep_gets_its_inverse_as_a_feed_forward() {
    let (rep, out) = case_with(
        "creep",
        1,
        "type: sinusoid, amplitude: 1.0e-6, frequency_hz: 0.5",
        true,
    );
    let c = &out.report.compensators[0];
    assert_eq!(c.type_name, "state_space");
    // Its static gain is 1/(1 + Σ k_i) of the fitted terms: checked on the
    // inserted block's own discrete model (the core's LTI view after build).
    let sum: f64 = rep.steps[0]
        .final_params
        .iter()
        .filter(|(k, _)| k.ends_with("gain"))
        .map(|(_, v)| v)
        .sum();
    let (s, _) = surgery::clone_spec(&out.compensated)
        .unwrap()
        .build()
        .unwrap();
    let dc = s.block("comp_creep").unwrap().lti().unwrap().dcgain()[(0, 0)].re;
    assert!(
        (dc - 1.0 / (1.0 + sum)).abs() < 1e-9,
        "{dc} vs {}",
        1.0 / (1.0 + sum)
    );
    assert!(connected(&out.compensated, "pid.u", "comp_creep.u"));
    assert!(connected(&out.compensated, "comp_creep.y", "stage.u"));
    // Validated on the augmented model: the error the creep adds is removed
    // (the loop then behaves as on the nominal plant).
    assert!(c.effect_error_cut_percent > 50.0, "{c:?}");
    // Whether that cuts the total is the validation's call (with --keep it is
    // kept either way, and the note says when it would have been dropped).
    assert_eq!(
        c.note.as_deref().is_some_and(|n| n.contains("--keep")),
        c.cut_percent < 1.0,
        "{c:?}"
    );
}

#[test]
fn backlash_gets_its_inverse_before_the_actuator() {
    let (rep, out) = case_with(
        "backlash",
        1,
        "type: sinusoid, amplitude: 1.0e-6, frequency_hz: 2.0",
        true,
    );
    let c = &out.report.compensators[0];
    assert_eq!(c.type_name, "backlash_inverse");
    assert_eq!(c.design["width"], rep.steps[0].final_params["width"]);
    assert!(connected(&out.compensated, "pid.u", "comp_backlash.u"));
    assert!(connected(&out.compensated, "comp_backlash.y", "stage.u"));
    // The error the play adds to the loop is mostly removed.
    assert!(c.effect_error_cut_percent > 50.0, "{c:?}");
}
