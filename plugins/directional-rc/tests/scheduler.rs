//! The DRC frame rotations in a graph: a raster scan planned in the sample frame
//! (core `triangular_scan` on y_r, `constant_velocity` on x_r) mapped to the
//! actuators by Rᵀ and back by R gives the plan again; ticks do not allocate.

use nanomotion_core::GraphSpec;
use nanomotion_directional_rc as _;

const YAML: &str = r#"
base_rate_hz: 20000
duration_s: 1.0
blocks:
  - { name: fast, type: triangular_scan, amplitude: 25.0e-6, frequency_hz: 0.25 }
  - { name: slow, type: constant_velocity, velocity_m_s: 125.0e-9 }
  - { name: plan, type: mux, widths: [1, 1] }
  - { name: to_a, type: frame_rotation, alpha_rad: 0.022, direction: to_actuator }
  - { name: to_s, type: frame_rotation, alpha_rad: 0.022, direction: to_sample }
connections:
  - { from: slow.y, to: plan.in0 }
  - { from: fast.y, to: plan.in1 }
  - { from: plan.y, to: to_a.u }
  - { from: to_a.y, to: to_s.u }
log: [plan.y, to_a.y, to_s.y]
"#;

#[test]
fn round_trip_in_a_graph_and_no_allocation_per_tick() {
    let (mut s, _) = GraphSpec::from_yaml(YAML, "drc.yaml")
        .unwrap()
        .build()
        .unwrap();
    s.step_n(10);
    let info = allocation_counter::measure(|| s.step_n(10_000));
    assert_eq!(info.count_total, 0, "{info:?}");
    s.step_n(20_000 - 10_010);
    let r = s.result();
    let get = |n: &str| r.logs.iter().find(|l| l.name == n).unwrap();
    let (plan, act, back) = (get("plan.y"), get("to_a.y"), get("to_s.y"));
    let (sn, cs) = 0.022f64.sin_cos();
    let mut max_dev = 0.0f64;
    for k in (0..20_000).step_by(97) {
        let (xr, yr) = (plan.data[2 * k], plan.data[2 * k + 1]);
        let (xa, ya) = (act.data[2 * k], act.data[2 * k + 1]);
        // Rᵀ of (7.17): x_a = c x_r − s y_r, y_a = s x_r + c y_r.
        assert!((xa - (cs * xr - sn * yr)).abs() < 1e-18);
        assert!((ya - (sn * xr + cs * yr)).abs() < 1e-18);
        max_dev = max_dev
            .max((back.data[2 * k] - xr).abs())
            .max((back.data[2 * k + 1] - yr).abs());
    }
    assert!(max_dev < 1e-18, "{max_dev}");
}
