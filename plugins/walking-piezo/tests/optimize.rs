//! Waveform optimisation (Sec. 4.5): objectives against independent computations,
//! the search on a known problem, determinism and resumption, a short real
//! optimisation, the driver fragment in a graph, and bad configurations.

use nanomotion_core::graph::GraphSpec;
use proptest::prelude::*;
use std::ops::ControlFlow;
use walking_piezo::optimize::{
    Budget, ConfigError, Drive, LegVelocityCost, OptimizeConfig, Phase, Prepared, SearchState,
    asymmetric_points, optimize, points_to_vec, run_search, waveform_yaml,
};
use walking_piezo::{DriverParams, StageParams, WalkingPiezoStage, WaveformShape};

fn tiny_budget() -> Budget {
    let mut b = Budget::default();
    b.sa.chunks = 3;
    b.sa.iterations = 15;
    b.pso.chunks = 2;
    b.pso.iterations = 2;
    b.pso.particles = 4;
    b.local.chunks = 1;
    b.local.iterations = 20;
    b
}

fn model_config(extra: &str) -> OptimizeConfig {
    OptimizeConfig::from_yaml(&format!("objective: model\nseed: 5\n{extra}"), "test").unwrap()
}

#[test]
fn leg_velocity_cost_has_the_closed_form_of_4_23() {
    // Leg 1 in the region (y ≥ δy) for a fraction p of the samples at velocity v,
    // leg 2 always in the region at ẋ_r: g = sqrt(p(ẋ_r − v)² + (1 − p)ẋ_r²) + 0.
    let (vr, dy, v) = (50e-6, -0.5e-6, 30e-6);
    let mut acc = LegVelocityCost::new(vr, dy);
    let n = 1000;
    let inside = 300;
    for k in 0..n {
        let y1 = if k < inside { -0.4e-6 } else { -0.6e-6 };
        acc.push([v, vr], [y1, 0.1e-6]);
    }
    let p = inside as f64 / n as f64;
    let expect = (p * (vr - v).powi(2) + (1.0 - p) * vr * vr).sqrt();
    let r = acc.rms();
    assert!((r[0] - expect).abs() < 1e-15, "{} {expect}", r[0]);
    assert!(r[1].abs() < 1e-18);
    assert!((acc.g() - expect).abs() < 1e-15);
    // Exactly at the clearance the leg counts (y ≥ δy).
    let mut acc = LegVelocityCost::new(vr, dy);
    acc.push([vr, vr], [dy, dy]);
    assert_eq!(acc.g(), 0.0);
}

#[test]
fn model_objective_equals_a_recomputation_from_logged_leg_positions() {
    let cfg = model_config("amplitude_v: 30.0\nclearance_m: -0.3e-6\n");
    let p = Prepared::new(&cfg).unwrap();
    let mut pts = asymmetric_points(0.3);
    pts[2][5] = 12.0;
    pts[1][1] = 40.0;
    let shape = WaveformShape::Free { points_v: pts };
    let eval = p.model.evaluate_shape(shape.clone()).unwrap();
    assert!((p.cost(&points_to_vec(&pts)) - eval.g_um_s).abs() < 1e-12);

    // Independently: the driver block's parameters, the stage, leg x-velocities by
    // differencing the logged leg positions, then (4.24) and (4.23) by hand.
    let dt = 25e-6;
    let mut drv = walking_piezo::WaveformDriver::new(
        DriverParams {
            shape,
            amplitude_v: 30.0,
            ..Default::default()
        },
        dt,
    )
    .unwrap();
    let mut st = WalkingPiezoStage::new(cfg.stage.clone(), dt, 0).unwrap();
    let per = (1.0 / (cfg.f_alpha_hz * dt)).round() as usize;
    let warm = per * cfg.simulation.warmup_cycles as usize;
    let n = warm + per * cfg.simulation.cycles as usize;
    let mut x_prev = st.signals().x_leg;
    let (mut s1, mut s2, mut m) = (0.0, 0.0, 0.0);
    for k in 0..n {
        let (u, _) = drv.try_drive(cfg.f_alpha_hz, None, None).unwrap();
        let _ = st.step(&u, 0.0);
        let s = st.signals();
        if k >= warm {
            let mut e = [0.0; 2];
            for i in 0..2 {
                let v = (s.x_leg[i] - x_prev[i]) / dt;
                let w = if s.y_leg[i] >= cfg.clearance_m {
                    v
                } else {
                    0.0
                };
                e[i] = cfg.velocity_m_s - w;
            }
            s1 += e[0] * e[0];
            s2 += e[1] * e[1];
            m += 1.0;
        }
        x_prev = s.x_leg;
    }
    let g = ((s1 / m).sqrt() + (s2 / m).sqrt()) * 1e6;
    assert!(
        (g - eval.g_um_s).abs() < 1e-6 * g,
        "objective {} vs recomputed {g}",
        eval.g_um_s
    );
    // The clearance matters: counting every sample changes g.
    let mut all = p.model.clone();
    all.clearance_m = -1.0;
    assert!(
        (all.evaluate_shape(WaveformShape::Free { points_v: pts })
            .unwrap()
            .g_um_s
            - g)
            .abs()
            > 1e-3
    );
}

#[test]
fn calibrated_amplitude_makes_the_asymmetric_waveform_walk_at_the_reference() {
    let cfg = model_config("");
    let p = Prepared::new(&cfg).unwrap();
    assert!(p.drive.amplitude_v > 5.0 && p.drive.amplitude_v < 46.0);
    let e = p.model.evaluate_shape(p.asymmetric_shape()).unwrap();
    assert!(
        (e.mean_velocity_um_s - 50.0).abs() < 0.01,
        "{}",
        e.mean_velocity_um_s
    );
    // Too fast for the range at this f_α: refused, naming the field.
    let bad = model_config("velocity_m_s: 5.0e-3\n");
    let err = Prepared::new(&bad).unwrap_err().to_string();
    assert!(err.contains("velocity_m_s"), "{err}");
}

/// A bounded test problem with a known minimum at (1, −2, 0.5, 3), value 0.
fn bowl(x: &[f64]) -> f64 {
    let c = [1.0, -2.0, 0.5, 3.0];
    x.iter()
        .zip(c)
        .enumerate()
        .map(|(i, (v, c))| (1.0 + i as f64) * (v - c).powi(2))
        .sum::<f64>()
        + 0.3 * ((x[0] - 1.0) * (x[1] + 2.0)).powi(2)
}

fn bowl_search(
    budget: &Budget,
    stop_after: Option<u32>,
    resume: Option<SearchState>,
) -> SearchState {
    let lo = [-5.0; 4];
    let hi = [5.0; 4];
    let x0 = [4.0, 4.0, -4.0, -4.0];
    let mut state = resume.unwrap_or_else(|| SearchState::new(&x0, bowl(&x0), budget, 99));
    let mut n = 0;
    run_search(&bowl, &lo, &hi, budget, &mut state, &mut |_, _| {
        n += 1;
        if Some(n) == stop_after {
            ControlFlow::Break(())
        } else {
            ControlFlow::Continue(())
        }
    })
    .unwrap();
    state
}

fn bowl_budget() -> Budget {
    let mut b = Budget::default();
    b.sa.chunks = 4;
    b.sa.iterations = 400;
    b.sa.temperature = 5.0;
    b.sa.step_v = 1.0;
    b.pso.chunks = 4;
    b.pso.iterations = 30;
    b.pso.particles = 12;
    b.pso.spread_v = 2.0;
    b.local.chunks = 2;
    b.local.iterations = 400;
    b.local.step_v = 0.5;
    b
}

#[test]
fn search_finds_the_known_optimum_of_a_test_problem() {
    let s = bowl_search(&bowl_budget(), None, None);
    let best = s.best();
    let x = best.point();
    for (v, c) in x.iter().zip([1.0, -2.0, 0.5, 3.0]) {
        assert!((v - c).abs() < 1e-3, "{x:?}");
    }
    assert!(best.exact_cost() < 1e-6);
    // Both global phases make progress from the start (cost 85).
    assert!(s.phase(Phase::SimulatedAnnealing).best.exact_cost() < 1.0);
    assert!(s.phase(Phase::ParticleSwarm).best.exact_cost() < 1.0);
    assert!(s.finished() && s.evaluations() > 0);
}

#[test]
fn search_is_deterministic_and_resumes_bit_for_bit() {
    let b = bowl_budget();
    let a = bowl_search(&b, None, None);
    let again = bowl_search(&b, None, None);
    assert_eq!(a, again);
    // Stop after every possible chunk, resume through JSON, compare.
    for stop in [1, 4, 5, 9] {
        let part = bowl_search(&b, Some(stop), None);
        assert!(!part.finished());
        let text = serde_json::to_string(&part).unwrap();
        let back: SearchState = serde_json::from_str(&text).unwrap();
        let resumed = bowl_search(&b, None, Some(back));
        assert_eq!(resumed, a, "stopped after chunk {stop}");
    }
    // Another seed gives another path.
    let lo = [-5.0; 4];
    let hi = [5.0; 4];
    let x0 = [4.0, 4.0, -4.0, -4.0];
    let mut other = SearchState::new(&x0, bowl(&x0), &b, 100);
    run_search(&bowl, &lo, &hi, &b, &mut other, &mut |_, _| {
        ControlFlow::Continue(())
    })
    .unwrap();
    assert_ne!(other.phases, a.phases);
}

#[test]
fn run_file_resume_gives_the_same_bits_as_an_uninterrupted_run() {
    let dir = std::env::temp_dir().join(format!("nm-opt-resume-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let mut cfg = model_config("amplitude_v: 24.0\nsimulation: {warmup_cycles: 1, cycles: 1}\n");
    cfg.budget = tiny_budget();
    let p = Prepared::new(&cfg).unwrap();
    let full_path = dir.join("full.json");
    let part_path = dir.join("part.json");
    std::fs::remove_file(&full_path).ok();
    std::fs::remove_file(&part_path).ok();
    let full = optimize(&p, Some(&full_path), &mut |_| ControlFlow::Continue(())).unwrap();
    assert!(full.finished);
    // Interrupted after 2 chunks, then again after 2 more, then to the end.
    for _ in 0..2 {
        let mut n = 0;
        let o = optimize(&p, Some(&part_path), &mut |_| {
            n += 1;
            if n == 2 {
                ControlFlow::Break(())
            } else {
                ControlFlow::Continue(())
            }
        })
        .unwrap();
        assert!(!o.finished);
    }
    let resumed = optimize(&p, Some(&part_path), &mut |_| ControlFlow::Continue(())).unwrap();
    assert!(resumed.finished);
    assert_eq!(resumed.search, full.search);
    assert_eq!(
        std::fs::read_to_string(&full_path).unwrap(),
        std::fs::read_to_string(&part_path).unwrap()
    );
    for (a, b) in points_to_vec(&resumed.points)
        .iter()
        .zip(points_to_vec(&full.points))
    {
        assert_eq!(a.to_bits(), b.to_bits());
    }
    // A finished run file is not run again; a different config refuses it.
    let again = optimize(&p, Some(&full_path), &mut |_| panic!("no chunk left")).unwrap();
    assert_eq!(again.search, full.search);
    let mut other = cfg.clone();
    other.seed = 6;
    let err = optimize(
        &Prepared::new(&other).unwrap(),
        Some(&full_path),
        &mut |_| ControlFlow::Continue(()),
    )
    .unwrap_err()
    .to_string();
    assert!(err.contains("another configuration"), "{err}");
    // The refusal says what changed and how to continue.
    assert!(err.contains("seed: 5 -> 6"), "{err}");
    assert!(err.contains("--budget"), "{err}");
    let mut other = cfg.clone();
    other.budget.sa.iterations = 30;
    let err = optimize(
        &Prepared::new(&other).unwrap(),
        Some(&full_path),
        &mut |_| ControlFlow::Continue(()),
    )
    .unwrap_err()
    .to_string();
    assert!(err.contains("budget.sa.iterations: 15 -> 30"), "{err}");
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn short_model_based_optimisation_beats_the_asymmetric_waveform_and_drives_a_graph() {
    let mut cfg = model_config("");
    let mut b = Budget::default();
    b.sa.chunks = 6;
    b.sa.iterations = 100;
    b.pso.chunks = 1;
    b.pso.iterations = 2;
    b.pso.particles = 6;
    b.local.chunks = 1;
    b.local.iterations = 150;
    cfg.budget = b;
    let p = Prepared::new(&cfg).unwrap();
    let o = optimize(&p, None, &mut |_| ControlFlow::Continue(())).unwrap();
    // Default clearance δy = −0.05 µm; the full budget reaches −22 %.
    assert!(
        o.cost < 0.92 * o.asymmetric_cost && o.cost < o.search.start.exact_cost(),
        "optimised {} vs asymmetric {}",
        o.cost,
        o.asymmetric_cost
    );
    // The reported cost is the cost of the reported points.
    assert_eq!(
        p.cost(&points_to_vec(&o.points)).to_bits(),
        o.cost.to_bits()
    );

    // The fragment is a driver's parameters, bit for bit ...
    let yaml = waveform_yaml(&p, &o);
    let params: DriverParams = nanomotion_core::yaml::from_str(&yaml, "fragment").unwrap();
    params.validate().unwrap();
    match &params.shape {
        WaveformShape::Free { points_v } => {
            for (a, b) in points_to_vec(points_v).iter().zip(points_to_vec(&o.points)) {
                assert_eq!(a.to_bits(), b.to_bits());
            }
        }
        other => panic!("{other:?}"),
    }
    assert_eq!(params.amplitude_v.to_bits(), o.amplitude_v.to_bits());
    // ... and a graph whose driver block uses it parses, builds and walks the stage.
    let block: String = yaml
        .lines()
        .filter(|l| !l.starts_with('#'))
        .map(|l| format!("    {l}\n"))
        .collect();
    let graph = format!(
        "title: optimised waveform\nbase_rate_hz: 40000\nduration_s: 0.3\nseed: 1\nblocks:\n  - name: fa\n    type: constant\n    value: 14.0\n  - name: driver\n    type: walking_piezo_driver\n{block}  - name: stage\n    type: walking_piezo_stage\nconnections:\n  - {{ from: fa.y, to: driver.f_alpha }}\n  - {{ from: driver.u, to: stage.u }}\nlog: [stage.x_s]\n"
    );
    let spec: GraphSpec = nanomotion_core::yaml::from_str(&graph, "graph").unwrap();
    let (mut sched, _) = spec.build().unwrap();
    let res = sched.run(|_| {});
    let x = res
        .logs
        .iter()
        .find(|l| l.name == "stage.x_s")
        .unwrap()
        .column(0);
    let x_end = *x.last().unwrap();
    assert!(x_end > 2e-6 && x_end.is_finite(), "stage walked {x_end} m");
}

#[test]
fn short_data_based_optimisation_improves_on_its_start() {
    let mut cfg = OptimizeConfig::from_yaml(
        "objective: data\nseed: 3\namplitude_v: 24.0\nsimulation: {warmup_cycles: 1, cycles: 2}\n",
        "test",
    )
    .unwrap();
    let mut b = tiny_budget();
    b.sa.iterations = 25;
    cfg.budget = b;
    let p = Prepared::new(&cfg).unwrap();
    let o = optimize(&p, None, &mut |_| ControlFlow::Continue(())).unwrap();
    assert!(
        o.cost < o.search.start.exact_cost(),
        "{} {}",
        o.cost,
        o.search.start.exact_cost()
    );
    // The "real" stage is a different stage than the nominal model.
    let real = &p.data.real.params;
    assert_ne!(real.c_x_m_v, cfg.stage.c_x_m_v);
    assert!(real.mu_spatial_rel > 0.0 && real.substeps == 10);
    let nominal = StageParams::default();
    for i in 0..4 {
        assert!((real.c_x_m_v[i] / nominal.c_x_m_v[i] - 1.0).abs() < 0.2);
    }
    // Evaluated at another drive frequency through the same measurement chain.
    let d = Drive {
        f_alpha_hz: 10.0,
        ..p.drive
    };
    let m = p
        .data
        .real
        .measure(p.asymmetric_shape(), &d, 50e-6 * 10.0 / 14.0, 1, 2)
        .unwrap();
    assert!(
        m.error_um_s.is_finite() && (m.mean_velocity_um_s - 35.7).abs() < 5.0,
        "{m:?}"
    );
}

fn field_of(text: &str) -> String {
    match OptimizeConfig::from_yaml(text, "cfg.yaml").unwrap_err() {
        e @ ConfigError::Invalid { .. } => e.field().unwrap().to_string(),
        other => panic!("expected a field error, got {other}"),
    }
}

#[test]
fn bad_configs_are_typed_errors_naming_the_field() {
    assert_eq!(
        field_of("objective: model\nf_alpha_hz: .nan\n"),
        "f_alpha_hz"
    );
    assert_eq!(
        field_of("objective: model\nf_alpha_hz: .inf\n"),
        "f_alpha_hz"
    );
    assert_eq!(field_of("objective: model\nf_alpha_hz: -3\n"), "f_alpha_hz");
    assert_eq!(
        field_of("objective: model\namplitude_v: 50\n"),
        "amplitude_v"
    );
    assert_eq!(
        field_of("objective: model\namplitude_v: -1\n"),
        "amplitude_v"
    );
    assert_eq!(field_of("objective: model\noverlap_q: 1.0\n"), "overlap_q");
    assert_eq!(field_of("objective: model\noverlap_q: 0\n"), "overlap_q");
    let mut pts = [[10.0; 8]; 4];
    pts[2][6] = 46.5;
    let text = format!(
        "objective: model\nstart_points_v:\n{}",
        pts.iter()
            .map(|c| format!("  - {c:?}\n"))
            .collect::<String>()
    );
    assert_eq!(field_of(&text), "start_points_v[2][6]");
    assert_eq!(
        field_of("objective: data\nreal: {filter_hz: 3000}\n"),
        "real.filter_hz"
    );
    assert_eq!(
        field_of("objective: model\nbudget:\n  sa: {iterations: 0}\n"),
        "budget.sa.iterations"
    );
    assert_eq!(
        field_of("objective: model\nstage: {mu: -0.1}\n"),
        "stage.mu"
    );
    // The message names the place and the fix.
    let e = OptimizeConfig::from_yaml("objective: model\nseed: 1\noverlap_q: 1.5\n", "cfg.yaml")
        .unwrap_err()
        .to_string();
    assert!(
        e.starts_with("cfg.yaml:3:1: field `overlap_q`") && e.contains("fix:"),
        "{e}"
    );
    // Schema errors carry the parser's line and column.
    let e = OptimizeConfig::from_yaml("objective: model\nf_alpha: 14\n", "cfg.yaml").unwrap_err();
    assert!(matches!(e, ConfigError::Parse { .. }), "{e}");
    assert!(
        e.to_string().contains("f_alpha") && e.to_string().contains("line 2"),
        "{e}"
    );
    let e = OptimizeConfig::from_yaml("objective: gradient\n", "cfg.yaml").unwrap_err();
    assert!(matches!(e, ConfigError::Parse { .. }), "{e}");
    // The shipped examples are valid.
    for f in [
        "optimize_waveform/model.yaml",
        "optimize_waveform/data.yaml",
    ] {
        let path = format!("{}/../../examples/{f}", env!("CARGO_MANIFEST_DIR"));
        OptimizeConfig::from_file(std::path::Path::new(&path)).unwrap();
    }
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(200))]
    #[test]
    fn mutated_configs_never_panic(
        line in 0usize..40,
        value in prop_oneof![
            Just(".nan".to_string()), Just("-.inf".to_string()), Just("-1".to_string()),
            Just("0".to_string()), Just("1e308".to_string()), Just("[1, 2]".to_string()),
            Just("{}".to_string()), Just("\"x\"".to_string()), Just("".to_string()),
            Just("4294967296".to_string()), Just("0.5".to_string()), Just("~".to_string()),
        ],
    ) {
        let path = format!("{}/../../examples/optimize_waveform/data.yaml", env!("CARGO_MANIFEST_DIR"));
        let text = std::fs::read_to_string(path).unwrap();
        let mutated: String = text
            .lines()
            .enumerate()
            .map(|(i, l)| {
                if i == line && l.contains(':') && !l.trim_start().starts_with('#') {
                    let key = l.split(':').next().unwrap_or("");
                    format!("{key}: {value}\n")
                } else {
                    format!("{l}\n")
                }
            })
            .collect();
        if let Ok(cfg) = OptimizeConfig::from_yaml(&mutated, "mutated") {
            prop_assert!(cfg.validate().is_ok());
        }
    }
}
