//! The `mimo_controller` block with the thesis's order-17 controller: built
//! from the synth config, run through the scheduler from YAML, and zero heap
//! allocation per tick.

use nanomotion_core::{Block, BuildContext, GraphSpec, Tick};
use nanomotion_mimo::config::{SynthConfig, run};

fn controller() -> nanomotion_mimo::MimoController {
    let cfg = SynthConfig::from_yaml(
        include_str!("../../../examples/mimo/afm_synth.yaml"),
        "afm_synth.yaml",
    )
    .unwrap();
    run(&cfg).unwrap().block
}

#[test]
fn a_tick_allocates_nothing() {
    let mut k = controller();
    k.build(&BuildContext::new("k", 5e-5, 0)).unwrap();
    let mut u = [0.0; 3];
    let mut inp = [0.0; 6];
    let info = allocation_counter::measure(|| {
        for t in 0..20_000u64 {
            let tick = Tick::new(t, 5e-5);
            inp[0] = 1e-9 * (t as f64 * 1e-3).sin();
            inp[4] = 2e-10;
            k.output(tick, &inp, &mut u);
            if !k.direct_feedthrough() {
                k.update(tick, &inp);
            }
            std::hint::black_box(u[0]);
        }
    });
    assert_eq!(info.count_total, 0, "{info:?}");
}

/// The block in a YAML graph (the scheduler's vector ports): a step of 1 nm on
/// r_x with y = 0 gives the controller's step response; its first output is
/// u₀ + D·e, checked against the discrete model's D.
#[test]
fn runs_in_a_yaml_graph_with_vector_ports() {
    let k = controller();
    let d00 = k.model.d[0][0];
    let mut entry = serde_json::to_value(&k).unwrap();
    let m = entry.as_object_mut().unwrap();
    m.insert("name".into(), "k".into());
    m.insert("type".into(), "mimo_controller".into());
    let blocks = serde_json::json!([
        {"name": "rx", "type": "constant", "value": 1.0e-9},
        {"name": "r0", "type": "constant", "value": 0.0, "width": 2},
        {"name": "r", "type": "mux", "widths": [1, 2]},
        {"name": "y", "type": "constant", "value": 0.0, "width": 3},
        entry
    ]);
    let graph = serde_json::json!({
        "base_rate_hz": 20000, "duration_s": 0.001, "blocks": blocks,
        "connections": [
            {"from": "rx.y", "to": "r.in0"}, {"from": "r0.y", "to": "r.in1"},
            {"from": "r.y", "to": "k.r"}, {"from": "y.y", "to": "k.y"}],
        "log": ["k.u"]
    });
    // JSON is YAML.
    let yaml = serde_json::to_string(&graph).unwrap();
    let (mut s, _) = GraphSpec::from_yaml(&yaml, "k.yaml")
        .unwrap()
        .build()
        .unwrap();
    let res = s.run(|_| {});
    let u = &res.logs[0].data;
    // Log is interleaved [u_x, u_y, u_z] per tick.
    let want = 50.0 + d00 * 1.0; // error_scale 1e9: e = 1 nm
    assert!(
        (u[0] - want).abs() < 1e-9 * want.abs().max(1.0),
        "{} vs {want}",
        u[0]
    );
    assert_eq!(u.len() % 3, 0);
    assert!(u.iter().all(|v| v.is_finite() && (0.0..=100.0).contains(v)));
}
