//! The `rotation_estimator` block fed by a `drc_scan_plan` over a rotated grating:
//! its α̂ is the offline estimator's on the lines it recorded, bit for bit, it
//! recovers the hidden rotation, and no tick allocates — including the tick that
//! runs the estimate. Failures come out on `status` (and α = NaN or 0).

use nanomotion_core::{Block, BuildContext, Tick};
use nanomotion_directional_rc::estimate::{
    EstimateError, EstimatorOptions, LineScan, estimate_rotation,
};
use nanomotion_directional_rc::{OnFailure, RotationEstimator, ScanPlan};

const DT: f64 = 1.0 / 5000.0;

/// A 10 µm grating of 20 nm steps whose lines run along the sample's x_r, rotated
/// by α: seen from the actuators at (x_a, y_a).
fn grating(alpha: f64) -> impl Fn(f64, f64) -> f64 {
    move |x: f64, y: f64| {
        let s = (-x * alpha.sin() + y * alpha.cos() - 0.3e-6) / 10e-6;
        if s - s.floor() < 0.5 { 20e-9 } else { 0.0 }
    }
}

/// Run plan and estimator through the estimation phase (+ one period); returns
/// the estimator, the outputs per tick (α, σ, status) and the allocation count of
/// all ticks.
fn run(
    h: &dyn Fn(f64, f64) -> f64,
    mut est: RotationEstimator,
) -> (RotationEstimator, Vec<[f64; 3]>, u64) {
    let mut plan = ScanPlan::new(25e-6, 4.0, 125e-9, 4, 1e-6, 1);
    plan.build(&BuildContext::new("plan", DT, 0)).unwrap();
    est.build(&BuildContext::new("est", DT, 0)).unwrap();
    let total = plan.scan_start_tick() + plan.period_samples();
    let mut outs = Vec::with_capacity(total as usize);
    let mut p = [0.0; 4];
    let mut y = [0.0; 3];
    let info = allocation_counter::measure(|| {
        for k in 0..total {
            let t = Tick::new(k, DT);
            plan.output(t, &[], &mut p);
            est.output(t, &[], &mut y);
            outs.push(y);
            // The stage at the planned point (α = 0 before the estimate), plus a
            // start offset.
            let z = h(40e-6 + p[0], 42e-6 + p[1]);
            est.update(t, &[z, p[2], p[0], p[1]]);
        }
    });
    (est, outs, info.count_total)
}

#[test]
fn in_graph_estimate_is_the_offline_one_and_ticks_do_not_allocate() {
    for alpha in [0.022, -0.015, 0.04] {
        let (est, outs, allocs) = run(&grating(alpha), RotationEstimator::new(4, 1.0));
        assert_eq!(allocs, 0, "α = {alpha}");
        let c = est.outcome().expect("estimated").expect("valid");
        // Offline, on the lines the block recorded.
        let lines: Vec<LineScan> = est
            .recorded_lines()
            .into_iter()
            .map(|(x, y0, dy, z)| LineScan::new(x, y0, dy, z))
            .collect();
        assert_eq!(lines.len(), 4);
        assert!(lines.iter().all(|l| l.z_m.len() == 5000));
        let off = estimate_rotation(&lines, &EstimatorOptions::default()).unwrap();
        assert_eq!(c.alpha_rad.to_bits(), off.alpha_rad.to_bits(), "{off}");
        assert_eq!(c.std_error_rad.to_bits(), off.std_error_rad.to_bits());
        // The hidden rotation: within the estimator's stated tolerance.
        assert!((c.alpha_rad - alpha).abs() < 2e-3, "{off}");
        assert!((c.alpha_rad - alpha).abs() < 4.0 * c.std_error_rad, "{off}");
        // Outputs: 0 while estimating; α̂ from the tick after the last line ended.
        let end = 4 * 20_000 + 5000; // period 4 (line 3) ends at p = 1/4
        assert!(outs[..=end].iter().all(|y| *y == [0.0, 0.0, 0.0]));
        assert_eq!(outs[end + 1], [c.alpha_rad, c.std_error_rad, 1.0]);
        assert_eq!(*outs.last().unwrap(), outs[end + 1]);
    }
}

#[test]
fn failures_are_reported_on_status() {
    let flat = |_x: f64, _y: f64| 5e-9;
    let (est, outs, allocs) = run(&flat, RotationEstimator::new(4, 1.0));
    assert_eq!(allocs, 0);
    let e = est.outcome().unwrap().unwrap_err();
    assert!(matches!(e, EstimateError::Flat { line: 0, .. }), "{e}");
    let last = outs.last().unwrap();
    assert!(last[0].is_nan());
    assert_eq!(last[2], -f64::from(e.code()));
    assert_eq!(e.code(), 7);
    // plain_rc: α = 0, the scan goes on.
    let mut b = RotationEstimator::new(4, 1.0);
    b.on_failure = OnFailure::PlainRc;
    let (_, outs, _) = run(&flat, b);
    assert_eq!(*outs.last().unwrap(), [0.0, 0.0, -7.0]);
    // Lines longer than the buffers: code 12, named.
    let (est, outs, _) = run(&grating(0.02), RotationEstimator::new(4, 0.5));
    let e = est.outcome().unwrap().unwrap_err();
    assert!(matches!(e, EstimateError::TooLong { line: 0, .. }), "{e}");
    assert!(e.to_string().contains("max_line_s"));
    assert_eq!(outs.last().unwrap()[2], -12.0);
}

#[test]
fn bad_parameters_name_the_field() {
    for (yaml, field) in [
        (
            "type: rotation_estimator\nlines: 1\nmax_line_s: 1.0\n",
            "lines",
        ),
        (
            "type: rotation_estimator\nlines: 17\nmax_line_s: 1.0\n",
            "lines",
        ),
        (
            "type: rotation_estimator\nlines: 4\nmax_line_s: 0.0\n",
            "max_line_s",
        ),
        (
            "type: rotation_estimator\nlines: 16\nmax_line_s: 1.0e6\n",
            "max_line_s",
        ),
        (
            "type: rotation_estimator\nlines: 4\nmax_line_s: 1.0\nmax_angle_rad: 2.0\n",
            "max_angle_rad",
        ),
        (
            "type: rotation_estimator\nlines: 4\nmax_line_s: 1.0\nalias_level: 0.1\n",
            "alias_level",
        ),
        (
            "type: rotation_estimator\nlines: 4\nmax_line_s: 1.0\nmin_correlation: 1.0\n",
            "min_correlation",
        ),
    ] {
        let mut b: Box<dyn Block> = nanomotion_core::yaml::from_str(yaml, "t").unwrap();
        let e = b.build(&BuildContext::new("e", DT, 0)).unwrap_err();
        assert_eq!(e.field, field, "{yaml}: {e:?}");
    }
    // `lines` and `max_line_s` are bounded by their declaration, which the
    // schema shows too.
    use nanomotion_core::doc::Params;
    let docs = RotationEstimator::param_docs();
    let lines = docs.iter().find(|p| p.name == "lines").unwrap();
    assert_eq!(lines.schema["minimum"], 2);
    assert_eq!(lines.schema["maximum"], 16);
    let max_line = docs.iter().find(|p| p.name == "max_line_s").unwrap();
    assert_eq!(max_line.schema["exclusiveMinimum"], 0);
}

/// In a graph: a flat sample makes the estimate fail; with `on_failure: stop` the
/// run's non-finite check names the estimator's `alpha` port, and `status` says
/// why (−7: flat line).
#[test]
fn a_failed_estimate_stops_the_run_at_the_estimator() {
    use nanomotion_core::{GraphError, GraphSpec};
    let yaml = |on_failure: &str| {
        format!(
            r#"
base_rate_hz: 1000
duration_s: 22.0
blocks:
  - {{ name: plan, type: drc_scan_plan, amplitude_m: 25.0e-6, period_s: 4.0, slow_velocity_m_s: 125.0e-9, estimation_lines: 4, line_spacing_m: 1.0e-6 }}
  - {{ name: z, type: constant, value: 3.0e-9 }}
  - {{ name: est, type: rotation_estimator, lines: 4, max_line_s: 1.0, on_failure: {on_failure} }}
  - {{ name: to_a, type: frame_rotation, alpha_input: true, direction: to_actuator }}
connections:
  - {{ from: z.y, to: est.z }}
  - {{ from: plan.line, to: est.line }}
  - {{ from: plan.r, to: est.r }}
  - {{ from: plan.r, to: to_a.u }}
  - {{ from: est.alpha, to: to_a.alpha }}
log: [est.status, to_a.y]
"#
        )
    };
    let (mut s, _) = GraphSpec::from_yaml(&yaml("stop"), "flat.yaml")
        .unwrap()
        .build()
        .unwrap();
    let r = s.run(|_| {});
    let status = &r.logs.iter().find(|l| l.name == "est.status").unwrap().data;
    assert_eq!(*status.last().unwrap(), -7.0);
    match s.check_finite() {
        Err(GraphError::NonFinite {
            block, port, tick, ..
        }) => {
            assert_eq!((block.as_str(), port.as_str()), ("est", "alpha"));
            // Line 3 ends at 17 s: the estimate runs in the update of tick 17 000,
            // α is NaN from the next tick.
            assert_eq!(tick, 17_001);
        }
        other => panic!("{other:?}"),
    }
    // plain_rc: the scan continues unrotated.
    let (mut s, _) = GraphSpec::from_yaml(&yaml("plain_rc"), "flat.yaml")
        .unwrap()
        .build()
        .unwrap();
    let r = s.run(|_| {});
    assert!(s.check_finite().is_ok());
    let status = &r.logs.iter().find(|l| l.name == "est.status").unwrap().data;
    assert_eq!(*status.last().unwrap(), -7.0);
}

/// The open intervals of `max_angle_rad`, `min_correlation` and
/// `alias_level` are declared on the fields (`range(> lo, < hi)`, #26): the
/// schema says them with `exclusiveMinimum`/`exclusiveMaximum`, the check
/// refuses the ends themselves, and `on_failure` lists its choices.
#[test]
fn open_intervals_and_choices_are_declared() {
    use nanomotion_core::doc::Params;
    let docs = RotationEstimator::param_docs();
    let doc = |n: &str| docs.iter().find(|p| p.name == n).unwrap().clone();
    for (name, lo, hi) in [
        ("max_angle_rad", 0.0, 1.5),
        ("min_correlation", 0.0, 1.0),
        ("alias_level", 0.25, 1.0),
    ] {
        let d = doc(name);
        assert_eq!(d.schema["exclusiveMinimum"].as_f64(), Some(lo), "{name}");
        assert_eq!(d.schema["exclusiveMaximum"].as_f64(), Some(hi), "{name}");
        for v in [lo, hi] {
            let yaml =
                format!("type: rotation_estimator\nlines: 4\nmax_line_s: 1.0\n{name}: {v}\n");
            let mut b: Box<dyn Block> = nanomotion_core::yaml::from_str(&yaml, "t").unwrap();
            let e = b.build(&BuildContext::new("e", DT, 0)).unwrap_err();
            assert_eq!(e.field, name);
            assert!(
                e.fix.contains(&format!("give a value in ({lo}, {hi})")),
                "{e:?}"
            );
        }
    }
    assert_eq!(
        doc("on_failure").schema["enum"].to_string(),
        r#"["stop","plain_rc"]"#
    );
}
