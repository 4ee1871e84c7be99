//! A block defined outside the workspace's plugins (`examples/third-party-block`)
//! is usable from YAML by linking alone.

use nanomotion::core::graph::GraphSpec;
use third_party_block as _;

#[test]
fn third_party_block_loads_from_yaml_and_runs() {
    let yaml = r#"
base_rate_hz: 100
duration_s: 0.1
blocks:
  - { name: ramp, type: constant_velocity, velocity_m_s: 100.0 }
  - { name: avg, type: moving_average, window: 4 }
connections:
  - { from: ramp.y, to: avg.u }
log: [ramp.y, avg.y]
"#;
    let (mut s, _) = GraphSpec::from_yaml(yaml, "tp.yaml")
        .unwrap()
        .build()
        .unwrap();
    let res = s.run(|_| {});
    // ramp[k] = k (100 m/s at 100 Hz); the 4-sample average of a ramp lags by 1.5
    // samples once the window is full: y[k] = k − 1.5 for k ≥ 3.
    let y = &res.logs[1].data;
    for (k, yk) in y.iter().enumerate().skip(3) {
        assert!((yk - (k as f64 - 1.5)).abs() < 1e-12, "k={k}: {yk}");
    }
    // Before the window fills, zeros are averaged in: y[1] = (0 + 1)/4.
    assert!((y[1] - 0.25).abs() < 1e-12);
    assert!(
        nanomotion::core::block::registered_types()
            .iter()
            .any(|t| t == "moving_average")
    );
}

#[test]
fn third_party_parameters_are_validated() {
    let yaml = "base_rate_hz: 10\nduration_s: 1\nblocks:\n  - { name: a, type: moving_average, window: 0 }\n";
    let err = GraphSpec::from_yaml(yaml, "tp.yaml")
        .unwrap()
        .build()
        .unwrap_err()
        .to_string();
    assert!(err.contains("block `a`") && err.contains("window"), "{err}");
    // A huge window is an error naming the field, not an allocation abort.
    let huge = yaml.replace("window: 0", "window: 18446744073709551615");
    let err = GraphSpec::from_yaml(&huge, "tp.yaml")
        .unwrap()
        .build()
        .unwrap_err()
        .to_string();
    assert!(err.contains("`window`"), "{err}");
}

/// Issue 25 (class 3): the third-party example declares its window before it
/// is built, so many of the longest windows (2^24 samples, 128 MiB each) are
/// refused naming `window` before any is allocated.
#[test]
fn third_party_windows_are_declared_and_refused_before_allocating() {
    use nanomotion::core::Block;
    let ma = third_party_block::MovingAverage::new(1000);
    assert_eq!(ma.planned_bytes(1e-3), ("window", 8000));
    let mut yaml = String::from(
        "base_rate_hz: 100\nduration_s: 0.1\nblocks:\n  - { name: c, type: constant, value: 1.0 }\n",
    );
    for i in 0..40 {
        yaml.push_str(&format!(
            "  - {{ name: m{i}, type: moving_average, window: 16777216 }}\n"
        ));
    }
    yaml.push_str("connections:\n");
    for i in 0..40 {
        yaml.push_str(&format!("  - {{ from: c.y, to: m{i}.u }}\n"));
    }
    let e = GraphSpec::from_yaml(&yaml, "ma.yaml")
        .unwrap()
        .build()
        .expect_err("refused")
        .to_string();
    assert!(
        e.contains("field `window`") && e.contains("block `m32`"),
        "{e}"
    );
    assert!(e.contains("checked before anything is allocated"), "{e}");
}
