//! Issue 25: YAML graphs with the PLF effect blocks in a feedback loop are
//! judged by the stability gate through their slope ranges: a piezo loop with
//! the `hysteresis` block (Table 6.2 parameters) and integral control is proven,
//! the same loop with too much gain refused as unstable at the centre slope,
//! a `backlash` under integral control stays unproven with the figure (its
//! slope 0 inside the play leaves the integrator alone: ‖M R‖∞ ≥ r/k0 = 1 at
//! DC), and a loop through `friction` (no slope range) stays unproven.

use nanomotion_core::gate;
use nanomotion_core::graph::GraphSpec;

fn _link() {
    let _ = std::any::type_name::<nanomotion_plf::effects::Effect>();
}

/// r → e → k_i/(z − 1) → `nl` → 0.1/(z − 0.9) → y, at 1 kHz.
fn graph(ki: f64, nl: &str) -> String {
    format!(
        r#"base_rate_hz: 1000
duration_s: 0.1
blocks:
  - {{ name: ref, type: constant, value: 1.0 }}
  - {{ name: err, type: sum, signs: "+-" }}
  - {{ name: ctrl, type: transfer_function, num: [{ki:e}], den: [1.0, -1.0], discrete: true }}
  - {{ name: act, {nl} }}
  - {{ name: plant, type: transfer_function, num: [0.1], den: [1.0, -0.9], discrete: true }}
connections:
  - {{ from: ref.y, to: err.in0 }}
  - {{ from: plant.y, to: err.in1 }}
  - {{ from: err.y, to: ctrl.u }}
  - {{ from: ctrl.y, to: act.u }}
  - {{ from: act.y, to: plant.u }}
"#
    )
}

fn check(yaml: &str) -> gate::GateReport {
    _link();
    let spec = GraphSpec::from_yaml(yaml, "test").unwrap();
    let require = spec.require.clone().unwrap_or_default();
    let (sched, _) = spec.build().unwrap();
    gate::analyse(&sched, &require)
}

const HYST: &str = "type: hysteresis, alpha: 0.03, b: 1.0, c: 0.7";

#[test]
fn effect_blocks_in_a_loop_are_proven_refused_or_unproven_by_their_slope_range() {
    // Proven: the centre loop (k0 = 0.7) is stable and ‖M R‖∞ < 1.
    let r = check(&graph(0.2, HYST));
    assert!(r.passes() && r.proven(), "{r}");
    let c = r.loops[0].points[0].circle.as_ref().unwrap();
    assert!(c.holds(), "{r}");
    assert_eq!(c.blocks.len(), 1);
    let (name, lower, upper) = &c.blocks[0];
    assert!(name == "act" && (lower - 0.4).abs() < 1e-12 && (upper - 1.0).abs() < 1e-12);
    // Refused: unstable at the centre slope.
    let r = check(&graph(2.0, HYST));
    assert!(!r.passes());
    assert!(
        r.failures()[0].contains("unstable")
            && r.failures()[0].contains("centre slope k0 = 0.7 of `act`"),
        "{r}"
    );
    // Backlash [0, 1] under integral control: unproven, with the figure ≥ 1.
    let r = check(&graph(0.2, "type: backlash, width: 0.01"));
    assert!(!r.passes() && !r.proven());
    let c = r.loops[0].points[0].circle.as_ref().unwrap();
    assert!(c.norm >= 1.0 - 1e-9, "{}", c.norm);
    assert!(
        r.failures()[0].contains("circle criterion: ‖M R‖∞ = "),
        "{r}"
    );
    // Hysteresis then creep (linear, `Block::lti`) in the loop: still proven.
    let yaml = graph(0.2, HYST).replace(
        "  - { from: act.y, to: plant.u }\n",
        "  - { from: act.y, to: creep.u }\n  - { from: creep.y, to: plant.u }\n",
    );
    let yaml = yaml.replace(
        "  - { name: plant,",
        "  - { name: creep, type: creep, terms: [{ gain: 0.05, tau_s: 0.05 }, { gain: 0.05, tau_s: 0.5 }] }\n  - { name: plant,",
    );
    let r = check(&yaml);
    assert!(r.passes() && r.proven(), "{r}");
    assert_eq!(r.loops[0].blocks.len(), 5);
    // Friction has no slope range: unproven as before.
    let r = check(&graph(
        0.2,
        "type: friction, coulomb: 0.1, v_stribeck: 0.01, v_eps: 0.001",
    ));
    assert!(!r.passes());
    assert!(
        r.failures()[0].contains("has no linear model and no slope range"),
        "{r}"
    );
}
