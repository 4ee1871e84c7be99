//! The generic gain-scheduled block: laws, bumplessness, YAML, no allocation.

use gain_scheduling::{
    FitError, GainLaw, GainSchedule, GainScheduledBlock, Placement, Scheduled, fit_power_db,
};
use nanomotion_core::blocks::control::Pi;
use nanomotion_core::{Block, BuildContext, Controller, Port, Tick};

const DT: f64 = 2.5e-4;

#[test]
fn laws_interpolate_and_multiply() {
    let t = GainLaw::Table {
        x: vec![1.0, 2.0, 4.0],
        gain: vec![4.0, 2.0, 1.0],
    };
    assert_eq!(t.gain(0.0), 4.0);
    assert_eq!(t.gain(1.5), 3.0);
    assert_eq!(t.gain(3.0), 1.5);
    assert_eq!(t.gain(9.0), 1.0);
    let d = GainLaw::TableDb {
        x: vec![0.0, 1.0],
        gain_db: vec![20.0, 0.0],
    };
    assert!((d.gain(0.5) - 10f64.powf(0.5)).abs() < 1e-12);
    let p = GainLaw::PowerDb {
        a: -6.0,
        b: 0.5,
        c: 12.0,
    };
    // 10^((−6·√4 + 12)/20) = 1.
    assert!((p.gain(4.0) - 1.0).abs() < 1e-12);
    let s = GainSchedule::new(vec![t, p, GainLaw::Constant { gain: 2.0 }]).unwrap();
    assert!((s.gain(&[1.5, 4.0, 0.0]) - 6.0).abs() < 1e-12);
}

#[test]
fn invalid_laws_name_their_field() {
    let e = GainSchedule::new(vec![
        GainLaw::Constant { gain: 1.0 },
        GainLaw::Table {
            x: vec![1.0, 1.0],
            gain: vec![1.0, 2.0],
        },
    ])
    .unwrap_err();
    assert_eq!(e.field, "schedule[1].x[1]");
    let e = GainSchedule::new(vec![GainLaw::Table {
        x: vec![1.0, 2.0],
        gain: vec![1.0, -2.0],
    }])
    .unwrap_err();
    assert_eq!(e.field, "schedule[0].gain[1]");
    let e = GainSchedule::new(vec![GainLaw::PowerDb {
        a: 1.0,
        b: f64::NAN,
        c: 0.0,
    }])
    .unwrap_err();
    assert_eq!(e.field, "schedule[0].b");
    assert_eq!(GainSchedule::new(vec![]).unwrap_err().field, "schedule");
}

#[test]
fn power_db_fit_recovers_an_exact_law_and_rejects_bad_data() {
    // Gains falling with amplitude A ∈ [23, 46] V: 0 dB at 46 V.
    let (a, b, c) = (-40.0, 0.6, 40.0 * 46f64.powf(0.6));
    let s: Vec<f64> = (0..8).map(|i| 23.0 + 23.0 * i as f64 / 7.0).collect();
    let g: Vec<f64> = s.iter().map(|x| a * x.powf(b) + c).collect();
    let (law, rms) = fit_power_db(&s, &g).unwrap();
    let GainLaw::PowerDb {
        a: fa,
        b: fb,
        c: fc,
    } = law.clone()
    else {
        panic!()
    };
    assert!(rms < 1e-8, "{rms}");
    assert!((fb - b).abs() < 1e-5 && (fa / a - 1.0).abs() < 1e-4 && (fc / c - 1.0).abs() < 1e-4);
    assert!((law.gain(46.0) - 1.0).abs() < 1e-6);
    assert_eq!(
        fit_power_db(&[1.0, 2.0], &[0.0, 1.0]).unwrap_err(),
        FitError::TooFewPoints { sigma: 2, gain: 2 }
    );
    assert!(matches!(
        fit_power_db(&[1.0, -2.0, 3.0], &[0.0, 1.0, 2.0]),
        Err(FitError::BadPoint { index: 1, .. })
    ));
}

/// Run a PI to steady state on a constant error (integrator loaded), then step
/// the scheduling variable; return the output jump at the gain change.
fn jump(placement: Placement) -> (f64, f64) {
    let pi = Pi::new(2.0, 5.0, DT).unwrap();
    let law = GainLaw::Table {
        x: vec![0.0, 1.0],
        gain: vec![1.0, 3.0],
    };
    let mut c = Scheduled::new(pi, GainSchedule::new(vec![law]).unwrap(), placement);
    let e = 0.01;
    let mut u = [0.0];
    for _ in 0..4000 {
        c.control(&[e], &[0.0], &mut u);
    }
    let before = u[0];
    let mut u2 = [0.0];
    c.control(&[e], &[0.0], &mut u2);
    let ramp = u2[0] - before; // the integrator's own increment per sample
    c.control(&[e], &[1.0], &mut u);
    (u[0] - u2[0] - ramp, u2[0])
}

#[test]
fn input_placement_is_bumpless_output_placement_is_not() {
    // PI (Tustin): u_k = kp·e_k + I_k, I_k = I_{k−1} + ki·Δt/2·(e_k + e_{k−1}).
    let (kp, ki) = (2.0, 2.0 * std::f64::consts::TAU * 5.0);
    let (dk, e) = (2.0, 0.01);
    let (jump_in, u_before) = jump(Placement::Input);
    // Only the direct part moves: kp·ΔK·e + ki·Δt/2·ΔK·e (the integrator state is kept).
    let expected = kp * dk * e + ki * DT / 2.0 * dk * e;
    assert!(
        (jump_in - expected).abs() < 1e-12,
        "{jump_in} vs {expected}"
    );
    // Output placement multiplies the stored integral action too: jump ≈ ΔK·u.
    let (jump_out, u_out) = jump(Placement::Output);
    assert!(
        (jump_out - dk * u_out).abs() < 0.1 * dk * u_out.abs(),
        "{jump_out}"
    );
    assert!(u_before > 10.0 * expected, "integrator loaded: {u_before}");
    assert!(jump_out > 10.0 * jump_in);
}

#[test]
fn block_wraps_any_inner_block_from_yaml_without_allocation() {
    let text = "type: gain_scheduled
controller: {type: pi, kp: 2.0, zero_hz: 5.0}
schedule:
  - {kind: power_db, a: -6.0, b: 0.5, c: 12.0}
  - {kind: table, x: [0.0, 1.0], gain: [1.0, 3.0]}
";
    let mut b: Box<dyn Block> = nanomotion_core::yaml::from_str(text, "test").unwrap();
    b.build(&BuildContext::new("gs", DT, 0)).unwrap();
    assert_eq!(
        b.inputs(),
        vec![Port::new("e", 1), Port::new("sigma", 2).scheduling_input()]
    );
    assert_eq!(b.outputs(), vec![Port::new("u", 1), Port::new("gain", 1)]);
    let mut reference = Pi::new(2.0, 5.0, DT).unwrap();
    let mut y = [0.0; 2];
    let info = allocation_counter::measure(|| {
        for k in 0..500 {
            let e = (k as f64 * 0.01).sin();
            b.output(Tick::new(k, DT), &[e, 4.0, 0.5], &mut y);
            // K = 1 · 2 = 2 at the input.
            let mut r = [0.0];
            reference.control(&[2.0 * e], &mut r);
            assert!((y[0] - r[0]).abs() < 1e-12);
            assert!((y[1] - 2.0).abs() < 1e-12);
        }
    });
    assert_eq!(info.count_total, 0);
    // Inner errors are prefixed with `controller.`.
    let bad = "type: gain_scheduled\ncontroller: {type: pi, kp: .nan, zero_hz: 5.0}\nschedule: [{kind: constant, gain: 1.0}]\n";
    let mut b: Box<dyn Block> = nanomotion_core::yaml::from_str(bad, "test").unwrap();
    assert_eq!(
        b.build(&BuildContext::new("gs", DT, 0)).unwrap_err().field,
        "controller.kp"
    );
    // Unknown fields are refused.
    assert!(
        nanomotion_core::yaml::from_str::<Box<dyn Block>>(
            "type: gain_scheduled\ncontroller: {type: pi, kp: 1, zero_hz: 1}\nschedule: []\nextra: 1\n",
            "test"
        )
        .is_err()
    );
    // Direct construction.
    let _ = GainScheduledBlock::new(
        Box::new(Pi::new(1.0, 1.0, DT).unwrap()),
        GainSchedule::new(vec![GainLaw::Constant { gain: 1.0 }]).unwrap(),
        Placement::Input,
    );
}

#[test]
fn inner_blocks_without_feedthrough_are_advanced() {
    // A one-sample delay inside: y_k = K·e_{k−1}.
    let text = "type: gain_scheduled
controller: {type: delay, d: 1}
schedule: [{kind: constant, gain: 2.0}]
";
    let mut b: Box<dyn Block> = nanomotion_core::yaml::from_str(text, "test").unwrap();
    b.build(&BuildContext::new("gs", DT, 0)).unwrap();
    assert!(b.direct_feedthrough());
    let mut y = [0.0; 2];
    let mut prev = 0.0;
    for k in 0..20 {
        let e = k as f64;
        b.output(Tick::new(k, DT), &[e, 0.0], &mut y);
        assert_eq!(y[0], 2.0 * prev);
        prev = e;
    }
}

/// The stability gate judges a gain-scheduled loop at every schedule point: with
/// K ∈ {0.5, 2.5} (table breakpoints) around L = K/(z − 1), K = 0.5 is stable
/// (pole 0.5) and K = 2.5 is not (pole −1.5), and the refusal names the point.
#[test]
fn the_gate_judges_each_schedule_point() {
    let _ = GainLaw::Constant { gain: 1.0 }; // link this crate's blocks
    let yaml = |gains: &str| {
        format!(
            r#"base_rate_hz: 1000
duration_s: 0.1
blocks:
  - {{ name: ref, type: constant, value: 1.0 }}
  - {{ name: sigma, type: constant, value: 0.3 }}
  - {{ name: err, type: sum, signs: "+-" }}
  - name: k
    type: gain_scheduled
    controller: {{ type: gain, k: 1.0 }}
    schedule: [ {{ kind: table, x: [0.0, 1.0], gain: {gains} }} ]
  - {{ name: plant, type: transfer_function, num: [1.0], den: [1.0, -1.0], discrete: true }}
connections:
  - {{ from: ref.y, to: err.in0 }}
  - {{ from: plant.y, to: err.in1 }}
  - {{ from: err.y, to: k.u }}
  - {{ from: sigma.y, to: k.sigma }}
  - {{ from: k.y, to: plant.u }}
"#
        )
    };
    let report = |gains: &str| {
        let spec = nanomotion_core::GraphSpec::from_yaml(&yaml(gains), "gs").unwrap();
        let (sched, _) = spec.build().unwrap();
        nanomotion_core::gate::analyse(&sched, &Default::default())
    };
    let ok = report("[0.5, 1.5]");
    assert!(ok.passes(), "{ok}");
    let radii: Vec<f64> = ok.loops[0]
        .points
        .iter()
        .map(|p| p.spectral_radius)
        .collect();
    assert_eq!(radii.len(), 2);
    assert!((radii[0] - 0.5).abs() < 1e-12 && (radii[1] - 0.5).abs() < 1e-12);
    assert!(ok.loops[0].linearised[0].contains("each schedule point"));
    let bad = report("[0.5, 2.5]");
    assert!(!bad.passes());
    let f = bad.failures();
    assert_eq!(f.len(), 1, "{f:?}");
    assert!(f[0].contains("at k: K = 2.5000 is unstable"), "{f:?}");
}

/// σ is a scheduling input (like a DVRC's α): when it is computed inside the
/// loop — here σ = ∑ 0.01·u, an integrator of the controller's output — the
/// connection into it is cut and the loop is judged with σ frozen, at every
/// schedule point: err = r − y, u = K·err, y⁺ = y + u gives the pole 1 − K.
/// Without the cut the σ integrator's pole at 1 (which K(σ) frozen leaves
/// open) would be in the loop.
#[test]
fn a_loop_through_sigma_is_cut_and_judged_with_sigma_frozen() {
    let _ = GainLaw::Constant { gain: 1.0 }; // link this crate's blocks
    let yaml = r#"base_rate_hz: 1000
duration_s: 0.1
blocks:
  - { name: ref, type: constant, value: 1.0 }
  - { name: err, type: sum, signs: "+-" }
  - name: k
    type: gain_scheduled
    controller: { type: gain, k: 1.0 }
    schedule: [ { kind: table, x: [0.0, 1.0], gain: [0.5, 0.25] } ]
  - { name: plant, type: transfer_function, num: [1.0], den: [1.0, -1.0], discrete: true }
  - { name: sig, type: transfer_function, num: [0.01], den: [1.0, -1.0], discrete: true }
connections:
  - { from: ref.y, to: err.in0 }
  - { from: plant.y, to: err.in1 }
  - { from: err.y, to: k.u }
  - { from: sig.y, to: k.sigma }
  - { from: k.y, to: plant.u }
  - { from: k.y, to: sig.u }
"#;
    let spec = nanomotion_core::GraphSpec::from_yaml(yaml, "gs").unwrap();
    let (sched, _) = spec.build().unwrap();
    let r = nanomotion_core::gate::analyse(&sched, &Default::default());
    assert!(r.passes(), "{r}");
    assert_eq!(r.loops.len(), 1, "{r}");
    let l = &r.loops[0];
    assert!(!l.blocks.iter().any(|b| b == "sig"), "{:?}", l.blocks);
    assert!(l.blocks.iter().any(|b| b == "k"), "{:?}", l.blocks);
    let radii: Vec<f64> = l.points.iter().map(|p| p.spectral_radius).collect();
    assert_eq!(radii.len(), 2);
    assert!((radii[0] - 0.5).abs() < 1e-12, "{radii:?}");
    assert!((radii[1] - 0.75).abs() < 1e-12, "{radii:?}");
    let text = r.to_string();
    assert!(
        text.contains("`sigma` is a scheduling input") && text.contains("sig.y -> k.sigma"),
        "{text}"
    );
}
