//! Reproducers of issue 13 that need only the core: block names, size
//! parameters, memory bounds, non-finite detection and graph-level edges.

// The helpers return the library's own `GraphError` so tests can match variants.
#![allow(clippy::result_large_err)]

use nanomotion_core::graph::{GraphSpec, MAX_GRAPH_BYTES};
use nanomotion_core::{Block, GraphError, Port, Tick};
use serde::{Deserialize, Serialize};

fn build(yaml: &str) -> Result<nanomotion_core::Scheduler, GraphError> {
    GraphSpec::from_yaml(yaml, "r.yaml")?
        .build()
        .map(|(s, _)| s)
}

fn build_err(yaml: &str) -> String {
    match build(yaml) {
        Err(e) => e.to_string(),
        Ok(_) => panic!("graph should not build:\n{yaml}"),
    }
}

// ---- item 1: names -------------------------------------------------------------

const TWO_RATES: &str = r#"
base_rate_hz: 1000
duration_s: 0.05
blocks:
  - { name: src, type: constant, value: 1.0, rate_hz: 100 }
  - { name: stage, type: gain, k: 2.0 }
connections:
  - { from: src.y, to: stage.u }
log: [stage.y]
"#;

#[test]
fn colon_in_a_user_name_is_refused() {
    // The name the loader gives the inserted transition, written by a user.
    let yaml = TWO_RATES.replace(
        "connections:",
        "  - { name: \"rt:src:y:stage\", type: constant, value: 99.0 }\nconnections:",
    );
    let e = build_err(&yaml);
    assert!(
        e.contains("rt:src:y:stage") && e.contains("not a valid block name") && e.contains("`:`"),
        "{e}"
    );
    // Other characters the documented rule excludes.
    for bad in ["a.b", "a b", "ä", ""] {
        let yaml = TWO_RATES
            .replace("name: stage", &format!("name: \"{bad}\""))
            .replace("stage.", &format!("{bad}."));
        let e = build_err(&yaml);
        assert!(e.contains("not a valid block name"), "`{bad}`: {e}");
    }
}

#[test]
fn inserted_transition_cannot_be_replaced_by_a_user_block() {
    // A user block whose name is the transition's with `:` spelled `_` is just a
    // block: the transition is still inserted and feeds the stage.
    let yaml = TWO_RATES.replace(
        "connections:",
        "  - { name: rt_src_y_stage, type: constant, value: 99.0 }\nconnections:",
    );
    let (mut s, report) = GraphSpec::from_yaml(&yaml, "r.yaml")
        .unwrap()
        .build()
        .unwrap();
    assert_eq!(report.rate_transitions.len(), 1);
    assert!(report.order.iter().any(|n| n == "rt:src:y:stage"));
    let r = s.run(|_| {});
    assert!(r.logs[0].data.iter().all(|&v| v == 2.0), "{:?}", r.logs[0]);
}

// ---- item 2: sizes -------------------------------------------------------------

/// `block` ("type: x, p: v, ...") written in block style, as users write it.
fn block_style(block: &str) -> String {
    block
        .split(", ")
        .map(|kv| format!("    {kv}\n"))
        .collect::<String>()
}

fn one_block(block: &str) -> String {
    format!(
        "base_rate_hz: 1000\nduration_s: 0.01\nblocks:\n  - {{ name: src, type: constant, value: 1.0 }}\n  - name: b\n{}connections:\n  - {{ from: src.y, to: b.u }}\n",
        block_style(block)
    )
}

fn source_block(block: &str) -> String {
    format!(
        "base_rate_hz: 1000\nduration_s: 0.01\nblocks:\n  - name: b\n{}",
        block_style(block)
    )
}

#[test]
fn huge_sizes_are_param_errors_not_aborts() {
    let cases = [
        (one_block("type: delay, d: 18446744073709551615"), "`d`"),
        (one_block("type: delay, d: 1000000000000"), "`d`"),
        (one_block("type: delay, d: 100000, width: 1000"), "`d`"),
        (
            source_block("type: constant, value: 1, width: 10000000000"),
            "`width`",
        ),
        (
            source_block("type: white_noise, std: 1, width: 10000000000"),
            "`width`",
        ),
        (
            one_block("type: low_pass, cutoff_hz: 10, order: 10000000000"),
            "`order`",
        ),
        (
            one_block("type: low_pass, cutoff_hz: 10, order: 100000"),
            "`order`",
        ),
        (one_block("type: gain, k: 1, width: 100000"), "`width`"),
        (
            source_block("type: mux, widths: [1,1000000000000]"),
            "`widths[1]`",
        ),
        (
            source_block("type: product, factors: 1000000000"),
            "`factors`",
        ),
    ];
    for (yaml, field) in cases {
        let e = build(&yaml).expect_err(&yaml);
        assert!(
            matches!(e, GraphError::Param { .. }) && e.to_string().contains(field),
            "{yaml}\n-> {e}"
        );
    }
}

#[test]
fn negative_and_fractional_sizes_are_errors() {
    // serde refuses these spellings for a whole-number field, naming the line.
    for v in ["-1", "2.5", "-1e12", "1e12", ".nan", ".inf"] {
        let yaml = one_block(&format!("type: delay, d: {v}"));
        assert!(build(&yaml).is_err(), "d: {v} accepted");
        let yaml = source_block(&format!("type: constant, value: 1, width: {v}"));
        assert!(build(&yaml).is_err(), "width: {v} accepted");
    }
}

#[test]
fn long_logs_are_refused_with_the_memory_estimate() {
    // 50 000 s at 4 kHz: 2e8 samples per log, 1.6 GB each; three logs exceed 4 GiB.
    let yaml = "base_rate_hz: 4000\nduration_s: 50000\nblocks:\n  - { name: a, type: constant, value: 1.0 }\n  - { name: b, type: constant, value: 1.0 }\n  - { name: c, type: constant, value: 1.0 }\nlog: [a.y, b.y, c.y]\n";
    let e = build_err(yaml);
    assert!(
        e.contains("GiB") && e.contains("log") && e.contains("fewer signals"),
        "{e}"
    );
    assert_eq!(MAX_GRAPH_BYTES, 4 << 30);
    // Wide logs over the longest run: no capacity overflow.
    let yaml = "base_rate_hz: 1e9\nduration_s: 2\nblocks:\n  - { name: a, type: constant, value: 1.0, width: 1024 }\nlog: [a.y]\n";
    assert!(build_err(yaml).contains("log"));
}

#[test]
fn many_long_delays_exceed_the_graph_memory_bound() {
    // Each delay line is 2^24 values (128 MiB, the per-block bound); 33 of them
    // are more than 4 GiB. The build stops at the block that crosses the bound.
    let mut yaml = String::from(
        "base_rate_hz: 1000\nduration_s: 0.01\nblocks:\n  - { name: src, type: constant, value: 1.0 }\n",
    );
    let mut conns = String::from("connections:\n");
    for i in 0..33 {
        yaml.push_str(&format!("  - {{ name: d{i}, type: delay, d: 16777216 }}\n"));
        conns.push_str(&format!("  - {{ from: src.y, to: d{i}.u }}\n"));
    }
    yaml.push_str(&conns);
    let e = build_err(&yaml);
    assert!(e.contains("GiB") && e.contains("d32"), "{e}");
}

// ---- item 11 (graph-level edges) --------------------------------------------------

#[test]
fn tiny_and_huge_rates_are_refused() {
    let e = build_err(&TWO_RATES.replace("rate_hz: 100 }", "rate_hz: 5e-324 }"));
    assert!(e.contains("rate"), "{e}");
    let e = build_err(&TWO_RATES.replace("base_rate_hz: 1000", "base_rate_hz: 5e-324"));
    assert!(e.contains("base_rate_hz"), "{e}");
    let e = build_err(&TWO_RATES.replace("base_rate_hz: 1000", "base_rate_hz: 1e300"));
    assert!(e.contains("base_rate_hz"), "{e}");
}

#[test]
fn control_characters_in_titles_are_refused() {
    let yaml = format!("title: \"a\\0b\"\n{TWO_RATES}");
    let e = build_err(&yaml);
    assert!(e.contains("title") && e.contains("U+0000"), "{e}");
}

#[test]
fn score_from_s_past_the_end_is_an_error() {
    let yaml = format!("{TWO_RATES}score:\n  - {{ signal: stage.y, from_s: 1.0 }}\n");
    let e = build_err(&yaml);
    assert!(
        e.contains("from_s") && e.contains("nothing would be scored"),
        "{e}"
    );
    // Just inside the run is fine.
    let yaml = format!("{TWO_RATES}score:\n  - {{ signal: stage.y, from_s: 0.049 }}\n");
    let mut s = build(&yaml).unwrap();
    let r = s.run(|_| {});
    assert_eq!(r.scores[0].samples, 1);
}

// ---- item 8: non-finite detection ------------------------------------------------

/// Outputs `u` except at tick `at`, where it outputs +inf (a transient that
/// recovers on the next sample).
#[derive(Debug, Serialize, Deserialize)]
struct Spike {
    at: u64,
}
#[typetag::serde(name = "rel_spike")]
impl Block for Spike {
    fn inputs(&self) -> Vec<Port> {
        vec![Port::new("u", 1)]
    }
    fn outputs(&self) -> Vec<Port> {
        vec![Port::new("y", 1)]
    }
    fn output(&mut self, t: Tick, u: &[f64], y: &mut [f64]) {
        y[0] = if t.k == self.at { f64::INFINITY } else { u[0] };
    }
}

const SPIKE: &str = r#"
base_rate_hz: 1000
duration_s: 1.0
blocks:
  - { name: first, type: constant, value: 1.0 }
  - { name: spike, type: rel_spike, at: 321 }
  - { name: sat, type: saturation, lower: -1, upper: 1 }
  - { name: last, type: gain, k: 2 }
connections:
  - { from: first.y, to: spike.u }
  - { from: spike.y, to: sat.u }
  - { from: sat.y, to: last.u }
log: [last.y]
"#;

#[test]
fn a_transient_inf_is_found_at_its_block_and_tick() {
    // The inf passes through `last` into the log for one sample, then recovers:
    // today this exits 0 with an `inf` row in the CSV.
    let yaml = SPIKE.replace(
        "  - { from: spike.y, to: sat.u }\n  - { from: sat.y, to: last.u }",
        "  - { from: spike.y, to: last.u }\n  - { from: first.y, to: sat.u }",
    );
    let mut s = build(&yaml).unwrap();
    let r = s.run(|_| {});
    assert!(r.logs[0].data[322].is_finite());
    let e = s.check_finite().unwrap_err().to_string();
    assert!(
        e.contains("`spike`") && e.contains("tick 321") && e.contains("rel_spike"),
        "{e}"
    );
}

#[test]
fn a_transient_inf_in_a_logged_signal_is_found() {
    // The saturation clamps the inf, so only the logged spike shows it.
    let yaml = SPIKE.replace("log: [last.y]", "log: [spike.y]");
    let mut s = build(&yaml).unwrap();
    s.step_n(1000);
    let e = s.check_finite().unwrap_err().to_string();
    assert!(e.contains("`spike`") && e.contains("tick 321"), "{e}");
}

#[test]
fn a_transient_inf_in_a_streamed_log_is_found_after_its_chunk_was_handed_over() {
    // Streamed: the log holding the inf is emptied after its chunk (100 ticks
    // here), long before the end; the chunk scan still notices it.
    let yaml = SPIKE
        .replace("log: [last.y]", "log: [spike.y]")
        .replace("duration_s: 1.0", "duration_s: 10.0");
    let spec = GraphSpec::from_yaml(&yaml, "spike.yaml").unwrap();
    let (mut s, _) = spec.build_streamed(None).unwrap();
    let mut handed = 0;
    s.run_streamed(
        |c| {
            handed += c[0].data.len();
            Ok::<(), ()>(())
        },
        |_| {},
    )
    .unwrap();
    assert_eq!(handed, 10_000);
    let e = s.check_finite().unwrap_err().to_string();
    assert!(e.contains("`spike`") && e.contains("tick 321"), "{e}");
}

#[test]
fn a_persistent_nan_is_blamed_on_its_producer_not_the_first_block() {
    // `acc` (a delay, no feed-through) comes first in execution order and holds
    // the NaN at the end; the NaN comes from `spike` at tick 321 and persists
    // through the loop s = spike + acc, acc = z^-1 s.
    let yaml = r#"
base_rate_hz: 1000
duration_s: 1.0
blocks:
  - { name: acc, type: delay, d: 1 }
  - { name: zero, type: constant, value: 0.0 }
  - { name: spike, type: rel_spike, at: 321 }
  - { name: s, type: sum, signs: "++" }
connections:
  - { from: zero.y, to: spike.u }
  - { from: spike.y, to: s.in0 }
  - { from: acc.y, to: s.in1 }
  - { from: s.y, to: acc.u }
log: [zero.y]
"#;
    let mut s = build(yaml).unwrap();
    let _ = s.run(|_| {});
    let e = s.check_finite().unwrap_err().to_string();
    assert!(e.contains("`spike`") && e.contains("tick 321"), "{e}");
    // A clean run passes, and reset clears the finding.
    s.reset().unwrap();
    s.step_n(100);
    s.check_finite().unwrap();
}

// ---- item 12: library ------------------------------------------------------------

#[test]
fn pi_limits_take_effect() {
    use nanomotion_core::Controller;
    use nanomotion_core::blocks::control::{AntiWindup, Pi};
    let mut pi = Pi::new(100.0, 5.0, 1e-3)
        .unwrap()
        .with_limits(-1.0, 1.0, AntiWindup::Clamping)
        .unwrap();
    assert_eq!(pi.output_limits(), (Some(-1.0), Some(1.0)));
    let mut u = [0.0];
    for _ in 0..10 {
        pi.control(&[1.0], &mut u);
        assert!(u[0] <= 1.0, "output {} above the limit", u[0]);
    }
    assert!(
        Pi::new(1.0, 5.0, 1e-3)
            .unwrap()
            .with_limits(1.0, -1.0, AntiWindup::Clamping)
            .is_err()
    );
}

#[test]
fn graph_spec_score_from_rust() {
    let mut g = GraphSpec::new(1000.0, 0.01);
    g.add("c", nanomotion_core::blocks::math::Gain::with_width(1.0, 1));
    g.add("k", nanomotion_core::blocks::sources::Constant::new(2.0));
    g.connect("k.y", "c.u").score("c.y", 0.002);
    let (mut s, _) = g.build().unwrap();
    let r = s.run(|_| {});
    assert_eq!(r.scores[0].rms, 2.0);
    assert_eq!(r.scores[0].samples, 8);
}

// ---- item 10: messages -----------------------------------------------------------

#[test]
fn parse_errors_name_the_file_and_hide_the_parser_internals() {
    let dup = "base_rate_hz: 1000\nduration_s: 1\nduration_s: 2\nblocks:\n  - { name: a, type: gain, k: 1 }\n";
    let e = GraphSpec::from_yaml(dup, "f.yaml").unwrap_err().to_string();
    assert!(e.starts_with("f.yaml: line 3"), "{e}");
    assert!(
        e.contains("--> f.yaml:3:1") && !e.contains("<input>"),
        "{e}"
    );
    assert!(
        !e.contains("DuplicateKeyPolicy") && e.contains("appear once"),
        "{e}"
    );
    let two = "base_rate_hz: 1000\nduration_s: 1\nblocks:\n  - { name: a, type: gain, k: 1 }\n---\nx: 1\n";
    let e = GraphSpec::from_yaml(two, "f.yaml").unwrap_err().to_string();
    assert!(
        !e.contains("from_str_multiple") && e.contains("one YAML document"),
        "{e}"
    );
    let mut many = String::from("base_rate_hz: 1000\nduration_s: 1\nblocks: []\nlog: [");
    for _ in 0..300_000 {
        many.push_str("a,");
    }
    many.push_str("a]\n");
    let e = GraphSpec::from_yaml(&many, "f.yaml")
        .unwrap_err()
        .to_string();
    assert!(
        !e.contains("Nodes {") && !e.contains("budget breached"),
        "{e}"
    );
}

#[test]
fn overflowing_pi_gain_names_kp() {
    let yaml = "base_rate_hz: 1000\nduration_s: 1\nblocks:\n  - { name: a, type: pi, kp: 1e308, zero_hz: 5 }\n  - { name: c, type: constant, value: 1 }\nconnections:\n  - { from: c.y, to: a.e }\n";
    let e = build_err(yaml);
    assert!(e.contains("`kp`") && !e.contains("`ki`"), "{e}");
    assert!(!e.contains("000000000000"), "numbers in e-notation: {e}");
}

#[test]
fn connection_errors_count_from_one_and_list_the_blocks() {
    let yaml = "base_rate_hz: 1000\nduration_s: 1\nblocks:\n  - { name: amp, type: gain, k: 1 }\n  - { name: c, type: constant, value: 1 }\nconnections:\n  - { from: c.y, to: amp.u }\n  - { from: c.y, to: zzz.u }\n";
    let e = build_err(yaml);
    assert!(
        e.contains("connection 2 ") && e.contains("known blocks: amp, c"),
        "{e}"
    );
}

#[test]
fn an_unknown_field_inside_a_block_is_located_on_its_own_line() {
    let yaml = "base_rate_hz: 1000\nduration_s: 1\nblocks:\n  - name: a\n    type: gain\n    k: 1\n    kk: 2\n    width: 1\n";
    let e = GraphSpec::from_yaml(yaml, "f.yaml")
        .unwrap_err()
        .to_string();
    // The message and its snippet are at the typo's line (7), not at the
    // block's first line (4) with "at line" of its last field.
    assert!(
        e.contains("line 7 column 5: unknown field `kk`") && e.contains("--> f.yaml:7:5"),
        "{e}"
    );
    assert!(
        e.contains("7 |     kk: 2\n  |     ^ unknown field `kk`"),
        "{e}"
    );
    assert!(!e.contains("line 4") && !e.contains("at line"), "{e}");
}

#[test]
fn connection_errors_name_the_file_line() {
    let yaml = "base_rate_hz: 1000\nduration_s: 1\nblocks:\n  - { name: amp, type: gain, k: 1 }\n  - { name: c, type: constant, value: 1 }\nconnections:\n  # the loop\n  - { from: c.y, to: amp.u }\n\n  - from: c.y\n    to: amp.x\n";
    let e = GraphSpec::from_yaml(yaml, "g.yaml")
        .unwrap()
        .build()
        .unwrap_err()
        .to_string();
    assert!(
        e.starts_with("g.yaml: line 10: connection 2 (`amp.x`)") && e.contains("u (width 1)"),
        "{e}"
    );
}

#[test]
fn model_orders_are_bounded() {
    let den: Vec<String> = (0..2001).map(|_| "1".to_string()).collect();
    let yaml = one_block(&format!(
        "type: transfer_function, num: [1], den: [{}], discrete: true",
        den.join(",")
    ));
    let e = build(&yaml).unwrap_err().to_string();
    assert!(e.contains("field `den`") && e.contains("65"), "{e}");
}
