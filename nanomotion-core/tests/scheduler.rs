//! Graph compilation and scheduling, with small blocks defined here (which also
//! shows that blocks defined outside the core register by linking alone).

use nanomotion_core::block::check;
use nanomotion_core::graph::GraphSpec;
use nanomotion_core::rng::Rng;
use nanomotion_core::{Block, BuildContext, GraphError, ParamError, Port, Tick};
use serde::{Deserialize, Serialize};

#[derive(Debug, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
struct TConst {
    value: f64,
}
#[typetag::serde(name = "t_const")]
impl Block for TConst {
    fn outputs(&self) -> Vec<Port> {
        vec![Port::new("y", 1)]
    }
    fn build(&mut self, _ctx: &BuildContext) -> Result<(), ParamError> {
        check::finite("value", self.value)
    }
    fn output(&mut self, _t: Tick, _u: &[f64], y: &mut [f64]) {
        y[0] = self.value;
    }
}

/// y = a - b
#[derive(Debug, Serialize, Deserialize)]
struct TDiff {}
#[typetag::serde(name = "t_diff")]
impl Block for TDiff {
    fn inputs(&self) -> Vec<Port> {
        vec![Port::new("a", 1), Port::new("b", 1)]
    }
    fn outputs(&self) -> Vec<Port> {
        vec![Port::new("y", 1)]
    }
    fn output(&mut self, _t: Tick, u: &[f64], y: &mut [f64]) {
        y[0] = u[0] - u[1];
    }
}

#[derive(Debug, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
struct TGain {
    k: f64,
    #[serde(default = "one")]
    width: usize,
}
fn one() -> usize {
    1
}
#[typetag::serde(name = "t_gain")]
impl Block for TGain {
    fn inputs(&self) -> Vec<Port> {
        vec![Port::new("u", self.width)]
    }
    fn outputs(&self) -> Vec<Port> {
        vec![Port::new("y", self.width)]
    }
    fn build(&mut self, _ctx: &BuildContext) -> Result<(), ParamError> {
        check::finite("k", self.k)
    }
    fn output(&mut self, _t: Tick, u: &[f64], y: &mut [f64]) {
        for (yi, ui) in y.iter_mut().zip(u) {
            *yi = self.k * ui;
        }
    }
}

/// x[k+1] = x[k] + u[k], y = x (no feed-through).
#[derive(Debug, Serialize, Deserialize)]
struct TAccumulator {
    #[serde(skip)]
    x: f64,
}
#[typetag::serde(name = "t_accumulator")]
impl Block for TAccumulator {
    fn inputs(&self) -> Vec<Port> {
        vec![Port::new("u", 1)]
    }
    fn outputs(&self) -> Vec<Port> {
        vec![Port::new("y", 1)]
    }
    fn direct_feedthrough(&self) -> bool {
        false
    }
    fn build(&mut self, _ctx: &BuildContext) -> Result<(), ParamError> {
        self.x = 0.0;
        Ok(())
    }
    fn output(&mut self, _t: Tick, _u: &[f64], y: &mut [f64]) {
        y[0] = self.x;
    }
    fn update(&mut self, _t: Tick, u: &[f64]) {
        self.x += u[0];
    }
}

/// Counts its own ticks and reports its time.
#[derive(Debug, Serialize, Deserialize)]
struct TClock {}
#[typetag::serde(name = "t_clock")]
impl Block for TClock {
    fn outputs(&self) -> Vec<Port> {
        vec![Port::new("k", 1), Port::new("t", 1)]
    }
    fn output(&mut self, t: Tick, _u: &[f64], y: &mut [f64]) {
        y[0] = t.k as f64;
        y[1] = t.t;
    }
}

/// Seeded Gaussian noise.
#[derive(Debug, Serialize, Deserialize)]
struct TNoise {
    #[serde(skip)]
    rng: Option<Rng>,
}
#[typetag::serde(name = "t_noise")]
impl Block for TNoise {
    fn outputs(&self) -> Vec<Port> {
        vec![Port::new("y", 1)]
    }
    fn build(&mut self, ctx: &BuildContext) -> Result<(), ParamError> {
        self.rng = Some(Rng::new(ctx.seed));
        Ok(())
    }
    fn output(&mut self, _t: Tick, _u: &[f64], y: &mut [f64]) {
        y[0] = self.rng.as_mut().map_or(0.0, Rng::normal);
    }
}

const LOOP: &str = r#"
title: proportional loop around an accumulator
base_rate_hz: 1000
duration_s: 0.05
seed: 3
blocks:
  - { name: r, type: t_const, value: 1.0 }
  - { name: e, type: t_diff }
  - { name: c, type: t_gain, k: 0.3 }
  - { name: p, type: t_accumulator }
connections:
  - { from: r.y, to: e.a }
  - { from: p.y, to: e.b }
  - { from: e.y, to: c.u }
  - { from: c.y, to: p.u }
log: [p.y]
score:
  - { signal: e.y, from_s: 0.01 }
"#;

#[test]
fn closed_loop_matches_closed_form() {
    // x[k+1] = x[k] + kp (1 - x[k])  =>  x[k] = 1 - (1 - kp)^k
    let (mut s, report) = GraphSpec::from_yaml(LOOP, "loop.yaml")
        .unwrap()
        .build()
        .unwrap();
    assert!(report.rate_transitions.is_empty());
    // The accumulator has no feed-through, so it may run first; the rest follow data flow.
    let order = &report.order;
    let pos = |n: &str| order.iter().position(|o| o == n).unwrap();
    assert!(pos("e") < pos("c"));
    let res = s.run(|_| {});
    let y = &res.logs[0].data;
    assert_eq!(y.len(), 50);
    for (k, yk) in y.iter().enumerate() {
        let exact = 1.0 - 0.7f64.powi(k as i32);
        assert!((yk - exact).abs() < 1e-14, "k={k}: {yk} vs {exact}");
    }
    // Score of e = (1 - kp)^k = 0.7^k from k = 10.
    let sc = &res.scores[0];
    assert_eq!(sc.samples, 40);
    let max = 0.7f64.powi(10);
    assert!((sc.max_abs - max).abs() < 1e-14);
    let rms = ((10..50).map(|k| 0.7f64.powi(2 * k)).sum::<f64>() / 40.0).sqrt();
    assert!((sc.rms - rms).abs() < 1e-14);
}

#[test]
fn multirate_holds_and_reports_transitions() {
    let yaml = r#"
base_rate_hz: 100
duration_s: 0.2
blocks:
  - { name: slow, type: t_clock, rate_hz: 10 }
  - { name: fast, type: t_gain, k: 1.0 }
  - { name: slower, type: t_gain, k: 2.0, rate_hz: 5 }
connections:
  - { from: slow.k, to: fast.u }
  - { from: fast.y, to: slower.u }
log: [fast.y, slower.y, slow.t]
"#;
    let (mut s, report) = GraphSpec::from_yaml(yaml, "mr.yaml")
        .unwrap()
        .build()
        .unwrap();
    assert_eq!(
        report.rate_transitions.len(),
        2,
        "{:?}",
        report.rate_transitions
    );
    assert!(report.rate_transitions[0].contains("zero-order hold"));
    assert!(report.rate_transitions[1].contains("decimation"));
    let res = s.run(|_| {});
    let fast = &res.logs[0];
    assert_eq!(fast.rate_hz, 100.0);
    assert_eq!(fast.len(), 20);
    // slow counts 0,1 at 10 Hz: held for 10 fast samples each.
    for (i, v) in fast.data.iter().enumerate() {
        assert_eq!(*v, (i / 10) as f64);
    }
    let slower = &res.logs[1];
    assert_eq!(slower.rate_hz, 5.0);
    assert_eq!(slower.data, vec![0.0]);
    let t = &res.logs[2];
    assert_eq!(t.data, vec![0.0, 0.1]);

    // Strict mode refuses the same graph.
    let strict = yaml.replace("duration_s: 0.2", "duration_s: 0.2\nstrict_rates: true");
    let err = GraphSpec::from_yaml(&strict, "mr.yaml")
        .unwrap()
        .build()
        .unwrap_err();
    assert!(
        matches!(err.root(), GraphError::RateMismatch { .. }),
        "{err}"
    );
}

/// A `rate_transition` written in a graph file is the declared block: its
/// output carries its input's unit, and a width outside [1, MAX_WIDTH] is
/// refused by name when it is built.
#[test]
fn a_written_rate_transition_passes_the_unit_and_checks_its_width() {
    let yaml = |width: usize| {
        format!(
            r#"
base_rate_hz: 100
duration_s: 0.05
blocks:
  - {{ name: slow, type: t_clock, rate_hz: 10 }}
  - {{ name: hold, type: rate_transition, width: {width} }}
connections:
  - {{ from: slow.k, to: hold.u }}
units: {{ slow.k: m }}
log: [hold.y]
"#
        )
    };
    let (mut s, _) = GraphSpec::from_yaml(&yaml(1), "rt.yaml")
        .unwrap()
        .build()
        .unwrap();
    let res = s.run(|_| {});
    assert_eq!(res.logs[0].unit.as_deref(), Some("m"));
    assert_eq!(res.logs[0].data, vec![0.0; 5]);
    for width in [0, nanomotion_core::block::MAX_WIDTH + 1] {
        let err = GraphSpec::from_yaml(&yaml(width), "rt.yaml")
            .unwrap()
            .build()
            .unwrap_err();
        match err.root() {
            GraphError::Param {
                block,
                type_name,
                source,
            } => {
                assert_eq!(
                    (block.as_str(), type_name.as_str()),
                    ("hold", "rate_transition")
                );
                assert_eq!(source.field, "width", "{err}");
            }
            other => panic!("{other}"),
        }
    }
}

#[test]
fn algebraic_loop_is_rejected_with_the_cycle() {
    let yaml = r#"
base_rate_hz: 10
duration_s: 1
blocks:
  - { name: a, type: t_gain, k: 0.5 }
  - { name: b, type: t_gain, k: 0.5 }
connections:
  - { from: a.y, to: b.u }
  - { from: b.y, to: a.u }
"#;
    let err = GraphSpec::from_yaml(yaml, "l.yaml")
        .unwrap()
        .build()
        .unwrap_err();
    let msg = err.to_string();
    assert!(matches!(err, GraphError::AlgebraicLoop { .. }));
    assert!(
        msg.contains("a -> b -> a") || msg.contains("b -> a -> b"),
        "{msg}"
    );
    // Broken by a block without feed-through: fine.
    let ok = yaml.replace(
        "{ name: b, type: t_gain, k: 0.5 }",
        "{ name: b, type: t_accumulator }",
    );
    assert!(GraphSpec::from_yaml(&ok, "l.yaml").unwrap().build().is_ok());
}

fn build_err(yaml: &str) -> String {
    match GraphSpec::from_yaml(yaml, "bad.yaml") {
        Err(e) => e.to_string(),
        Ok(spec) => match spec.build() {
            Err(e) => e.to_string(),
            Ok(_) => panic!("graph should not build:\n{yaml}"),
        },
    }
}

#[test]
fn bad_graphs_get_located_typed_errors() {
    let base = LOOP;
    let cases: &[(&str, &str, &[&str])] = &[
        (
            "type: t_gain, k: 0.3",
            "type: t_gian, k: 0.3",
            &["line", "t_gian", "did you mean `t_gain`"],
        ),
        (
            "r.y, to: e.a",
            "r.z, to: e.a",
            &["no output port `z`", "y (width 1)"],
        ),
        (
            "p.y, to: e.b",
            "pp.y, to: e.b",
            &["unknown block `pp`", "did you mean `p`"],
        ),
        (
            "{ from: p.y, to: e.b }",
            "{ from: p.y, to: e.a }",
            &["connected twice"],
        ),
        (
            "  - { from: p.y, to: e.b }\n",
            "",
            &["`e.b` is not connected"],
        ),
        (
            "{ name: c, type: t_gain",
            "{ name: r, type: t_gain",
            &["duplicate block name `r`"],
        ),
        (
            "k: 0.3 }",
            "k: .nan }",
            &["block `c`", "field `k`", "finite"],
        ),
        ("k: 0.3 }", "k: abc }", &["line", "expected f64"]),
        ("k: 0.3 }", "k: 0.3, kk: 1 }", &["unknown field `kk`"]),
        (
            "{ name: p, type: t_accumulator }",
            "{ name: p, type: t_accumulator, rate_hz: 300 }",
            &["not an integer divisor"],
        ),
        ("base_rate_hz: 1000", "base_rate_hz: -5", &["base_rate_hz"]),
        ("log: [p.y]", "log: [p.x]", &["has no output `x`"]),
        ("log: [p.y]", "log: [py]", &["block.port"]),
        (
            "{ from: r.y, to: e.a }",
            "{ from: ry, to: e.a }",
            &["not a port reference"],
        ),
        ("seed: 3", "sed: 3", &["unknown field `sed`"]),
        ("k: 0.3 }", "k: 0.3, width: 2 }", &["width mismatch"]),
    ];
    for (from, to, needles) in cases {
        assert!(
            base.contains(from),
            "test case pattern `{from}` not in base"
        );
        let yaml = base.replacen(from, to, 1);
        let msg = build_err(&yaml);
        for n in *needles {
            assert!(
                msg.contains(n),
                "error for `{to}` should mention `{n}`:\n{msg}"
            );
        }
    }
}

#[test]
fn same_seed_same_bits_and_reset_replays() {
    let yaml = r#"
base_rate_hz: 1000
duration_s: 0.1
seed: 11
blocks:
  - { name: n1, type: t_noise }
  - { name: n2, type: t_noise }
log: [n1.y, n2.y]
"#;
    let run = |seed_line: &str| {
        let y = yaml.replace("seed: 11", seed_line);
        let (mut s, _) = GraphSpec::from_yaml(&y, "n.yaml").unwrap().build().unwrap();
        let a = s.run(|_| {});
        s.reset().unwrap();
        let b = s.run(|_| {});
        assert_eq!(a, b, "reset must replay bit for bit");
        a
    };
    let a = run("seed: 11");
    let b = run("seed: 11");
    let c = run("seed: 12");
    let bits = |r: &nanomotion_core::scheduler::RunResult| {
        r.logs[0]
            .data
            .iter()
            .map(|v| v.to_bits())
            .collect::<Vec<_>>()
    };
    assert_eq!(bits(&a), bits(&b));
    assert_ne!(bits(&a), bits(&c));
    // Two blocks of one graph get different streams.
    assert_ne!(a.logs[0].data, a.logs[1].data);
}

#[test]
fn graph_built_from_rust_and_signal_handles() {
    let mut g = GraphSpec::new(1000.0, 0.01);
    g.add("r", TConst { value: 2.0 })
        .add("k", TGain { k: 3.0, width: 1 })
        .connect("r.y", "k.u")
        .log("k.y");
    let (mut s, _) = g.build().unwrap();
    let id = s.signal_id("k.y").unwrap();
    s.tick();
    assert_eq!(s.read(id), &[6.0]);
    assert!(s.signal_id("k.nope").is_none());
    assert_eq!(s.block_names().len(), 2);
    assert!(s.describe()[0].contains("t_const"));
    s.check_finite().unwrap();
}

#[test]
fn ticks_do_not_allocate() {
    // Multi-rate loop with noise, logging and a rate transition, 10 000 ticks.
    let yaml = LOOP
        .replace("duration_s: 0.05", "duration_s: 20")
        .replace(
            "{ name: c, type: t_gain, k: 0.3 }",
            "{ name: c, type: t_gain, k: 0.3, rate_hz: 500 }",
        )
        .replace("blocks:\n", "blocks:\n  - { name: n, type: t_noise }\n")
        .replace("log: [p.y]", "log: [p.y, n.y, c.y]");
    let (mut s, report) = GraphSpec::from_yaml(&yaml, "na.yaml")
        .unwrap()
        .build()
        .unwrap();
    assert_eq!(report.rate_transitions.len(), 2);
    s.tick(); // first tick outside the measurement (nothing is lazily initialised, but be fair)
    let info = allocation_counter::measure(|| {
        s.step_n(10_000);
    });
    assert_eq!(info.count_total, 0, "a tick allocated: {info:?}");
    assert_eq!(s.ticks_done(), 10_001);
    let res = s.result();
    assert_eq!(res.logs[0].len(), 10_001);
    assert_eq!(res.logs[2].len(), 5_001);
}

#[test]
fn single_rate_ticks_do_not_allocate() {
    // One base rate: every tick takes the single-rate path (one `Tick` for all
    // steps), and `e` (two scalar inputs) the paired gather.
    let yaml = LOOP.replace("duration_s: 0.05", "duration_s: 20");
    let (mut s, report) = GraphSpec::from_yaml(&yaml, "single.yaml")
        .unwrap()
        .build()
        .unwrap();
    assert!(report.rate_transitions.is_empty());
    s.tick();
    let info = allocation_counter::measure(|| {
        s.step_n(10_000);
    });
    assert_eq!(info.count_total, 0, "a tick allocated: {info:?}");
    assert_eq!(s.result().logs[0].len(), 10_001);
}

mod mutated_graphs {
    use super::*;
    use proptest::prelude::*;

    /// Mutations a user (or a bad editor) makes to a graph file.
    #[derive(Debug, Clone)]
    enum Mutation {
        DeleteChar(usize),
        InsertChar(usize, char),
        DeleteLine(usize),
        DuplicateLine(usize),
        SwapLines(usize, usize),
        ReplaceNumber(usize, String),
    }

    fn mutation() -> impl Strategy<Value = Mutation> {
        let ch = prop::sample::select(vec![
            ':', '-', ' ', '\n', '{', '}', '[', ']', '.', ',', '"', 'x', '0', '#', '&', '*', '!',
            '|', '\t',
        ]);
        let num = prop::sample::select(vec![
            "0",
            "-1",
            "1e308",
            "-1e308",
            ".nan",
            ".inf",
            "-.inf",
            "1e-320",
            "18446744073709551616",
            "abc",
            "~",
            "[]",
            "{}",
            "3.5",
            "2",
            "1000000000000",
            // Sizes: huge, at the edge of usize, negative, fractional.
            "18446744073709551615",
            "4294967296",
            "16777217",
            "1025",
            "-3",
            "0.5",
            "1e12",
        ])
        .prop_map(String::from);
        prop_oneof![
            any::<usize>().prop_map(Mutation::DeleteChar),
            (any::<usize>(), ch).prop_map(|(i, c)| Mutation::InsertChar(i, c)),
            any::<usize>().prop_map(Mutation::DeleteLine),
            any::<usize>().prop_map(Mutation::DuplicateLine),
            (any::<usize>(), any::<usize>()).prop_map(|(a, b)| Mutation::SwapLines(a, b)),
            (any::<usize>(), num).prop_map(|(i, n)| Mutation::ReplaceNumber(i, n)),
        ]
    }

    fn apply(text: &str, m: &Mutation) -> String {
        let mut lines: Vec<String> = text.lines().map(String::from).collect();
        let chars: Vec<char> = text.chars().collect();
        match m {
            Mutation::DeleteChar(i) => {
                let i = i % chars.len();
                chars
                    .iter()
                    .enumerate()
                    .filter(|(j, _)| *j != i)
                    .map(|(_, c)| c)
                    .collect()
            }
            Mutation::InsertChar(i, c) => {
                let i = i % (chars.len() + 1);
                let mut v = chars.clone();
                v.insert(i, *c);
                v.into_iter().collect()
            }
            Mutation::DeleteLine(i) => {
                let i = i % lines.len();
                lines.remove(i);
                lines.join("\n")
            }
            Mutation::DuplicateLine(i) => {
                let i = i % lines.len();
                let l = lines[i].clone();
                lines.insert(i, l);
                lines.join("\n")
            }
            Mutation::SwapLines(a, b) => {
                let (a, b) = (a % lines.len(), b % lines.len());
                lines.swap(a, b);
                lines.join("\n")
            }
            Mutation::ReplaceNumber(i, n) => {
                // Replace the i-th numeric token.
                let mut out = String::new();
                let mut count = 0usize;
                let mut idx = 0usize;
                let bytes: Vec<char> = text.chars().collect();
                let numbers = bytes.iter().filter(|c| c.is_ascii_digit()).count().max(1);
                let target = i % numbers;
                while idx < bytes.len() {
                    if bytes[idx].is_ascii_digit() {
                        let start = idx;
                        while idx < bytes.len()
                            && (bytes[idx].is_ascii_digit() || bytes[idx] == '.')
                        {
                            idx += 1;
                        }
                        if count == target {
                            out.push_str(n);
                        } else {
                            out.extend(&bytes[start..idx]);
                        }
                        count += 1;
                    } else {
                        out.push(bytes[idx]);
                        idx += 1;
                    }
                }
                out
            }
        }
    }

    /// A graph whose numbers are mostly sizes (delay lengths, widths, orders,
    /// port counts), for the size mutations.
    const SIZED: &str = r#"
base_rate_hz: 1000
duration_s: 0.05
blocks:
  - name: src
    type: constant
    value: 1
    width: 2
  - name: d
    type: delay
    d: 3
    width: 2
  - name: lp
    type: low_pass
    cutoff_hz: 50
    order: 4
    width: 2
  - name: m
    type: mux
    widths: [2, 2]
  - name: p
    type: product
    factors: 2
    width: 4
  - name: n
    type: white_noise
    std: 1
    width: 4
connections:
  - { from: src.y, to: d.u }
  - { from: d.y, to: lp.u }
  - { from: lp.y, to: m.in0 }
  - { from: src.y, to: m.in1 }
  - { from: m.y, to: p.in0 }
  - { from: n.y, to: p.in1 }
log: [p.y]
"#;

    proptest! {
        #![proptest_config(ProptestConfig { cases: 300, .. ProptestConfig::default() })]
        /// Sizes mutated to huge, negative and fractional values: every outcome
        /// is a value (never an abort), and building allocates a bounded amount.
        #[test]
        fn mutated_sizes_never_abort_and_memory_is_bounded(
            muts in prop::collection::vec(
                (any::<usize>(), prop::sample::select(vec![
                    "18446744073709551615", "1000000000000", "4294967296", "16777217",
                    "1025", "1024", "-3", "0.5", "2.5", "1e12", "-1e12", "0",
                ])),
                1..4,
            )
        ) {
            let mut text = SIZED.to_string();
            for (i, n) in &muts {
                text = apply(&text, &Mutation::ReplaceNumber(*i, n.to_string()));
            }
            let info = allocation_counter::measure(|| {
                if let Ok(spec) = GraphSpec::from_yaml(&text, "sized.yaml")
                    && let Ok((mut s, _)) = spec.build()
                {
                    s.step_n(s.ticks_total().min(20));
                    let _ = s.check_finite();
                }
            });
            prop_assert!(info.bytes_max < 1 << 30, "{} bytes for\n{text}", info.bytes_max);
        }
    }

    proptest! {
        #![proptest_config(ProptestConfig { cases: 400, .. ProptestConfig::default() })]
        #[test]
        fn mutated_graphs_never_panic(muts in prop::collection::vec(mutation(), 1..4)) {
            let mut text = LOOP.to_string();
            for m in &muts {
                text = apply(&text, m);
            }
            // Parse, build, and run a few ticks: every outcome is a value, never a panic.
            if let Ok(spec) = GraphSpec::from_yaml(&text, "mutated.yaml")
                && let Ok((mut s, _)) = spec.build()
            {
                s.step_n(s.ticks_total().min(100));
                let _ = s.check_finite();
                let _ = s.result();
            }
        }
    }
}

#[test]
fn data_column_ticks_do_not_allocate_and_hold_the_last_sample() {
    use nanomotion_core::data::Dataset;
    let values: Vec<f64> = (0..1000).map(|k| k as f64 * 0.5).collect();
    let data = std::sync::Arc::new(
        Dataset::from_columns("rec.csv", 1000.0, 0.0, vec![("u".into(), values)]).unwrap(),
    );
    let yaml = "base_rate_hz: 2000\nduration_s: 1.0\nblocks:\n  - { name: d, type: data_column, column: u, rate_hz: 1000 }\nlog: [d.y]\n";
    let (mut s, _) = GraphSpec::from_yaml(yaml, "d.yaml")
        .unwrap()
        .build_with_data(data)
        .unwrap();
    s.tick();
    let info = allocation_counter::measure(|| {
        s.step_n(1999);
    });
    assert_eq!(info.count_total, 0, "a tick allocated: {info:?}");
    let res = s.result();
    let y = &res.logs[0].data;
    assert_eq!(y.len(), 1000);
    assert_eq!((y[0], y[1], y[999]), (0.0, 0.5, 499.5));
    // Stepping past the end (the scheduler lets a caller tick on) holds the last sample.
    s.step_n(10);
    let id = s.signal_id("d.y").unwrap();
    assert_eq!(s.read(id), &[499.5]);
}

/// Every user block's output handle (inserted rate transitions left out).
fn user_signals(
    s: &nanomotion_core::Scheduler,
) -> Vec<(String, nanomotion_core::scheduler::SignalId)> {
    s.wiring()
        .iter()
        .filter(|b| {
            !b.name
                .starts_with(nanomotion_core::graph::RATE_TRANSITION_PREFIX)
        })
        .flat_map(|b| {
            b.outputs.iter().map(|p| {
                let r = format!("{}.{}", b.name, p.name);
                let id = s.signal_id(&r).expect("an output");
                (r, id)
            })
        })
        .collect()
}

fn bits(v: &[f64]) -> Vec<u64> {
    v.iter().map(|x| x.to_bits()).collect()
}

/// `Scheduler::tick` folds an inserted rate transition that only its consumer
/// reads into the consumer's input (issue #29); `tick_probed` runs every block
/// as built. Both give the same samples, bit for bit, on every tick — with
/// zero-order holds and decimations, harmonic and not (3 kHz → 4 kHz), into
/// blocks with and without feed-through, vector and scalar — and so does a
/// run that alternates them. A logged transition is not folded.
#[test]
fn folded_rate_transitions_give_the_same_samples_bit_for_bit() {
    let quickstart = include_str!("../../examples/quickstart.yaml");
    let mixed = r#"
base_rate_hz: 12000
duration_s: 0.05
seed: 5
blocks:
  - { name: a, type: sinusoid, amplitude: 1.0, frequency_hz: 37 }
  - { name: n, type: white_noise, rate_hz: 3000, std: 0.1 }
  - { name: s, type: sum, rate_hz: 4000, signs: "+-" }
  - { name: g, type: t_gain, rate_hz: 6000, k: 2.0 }
  - { name: m, type: mux, rate_hz: 6000, widths: [1, 1] }
  - { name: v, type: t_gain, rate_hz: 6000, k: -1.5, width: 2 }
  - { name: d, type: delay, d: 2, width: 2 }
  - { name: lp, type: low_pass, rate_hz: 4000, order: 2, cutoff_hz: 500, width: 2 }
  - { name: tap, type: t_gain, k: 1.0 }
  - { name: w, type: t_gain, k: 3.0, width: 2, rate_hz: 3000 }
connections:
  - { from: a.y, to: s.in0 }
  - { from: n.y, to: s.in1 }
  - { from: s.y, to: g.u }
  - { from: g.y, to: m.in0 }
  - { from: a.y, to: m.in1 }
  - { from: m.y, to: v.u }
  - { from: v.y, to: d.u }
  - { from: d.y, to: lp.u }
  - { from: n.y, to: tap.u }
  - { from: lp.y, to: w.u }
log: [s.y, lp.y, tap.y, "rt:a:y:s.y"]
"#;
    for (name, yaml) in [("quickstart", quickstart), ("mixed", mixed)] {
        let build = || GraphSpec::from_yaml(yaml, name).unwrap().build().unwrap().0;
        let (mut folded, mut plain, mut alternating) = (build(), build(), build());
        assert!(!folded.rate_transitions().is_empty(), "{name}");
        let signals = user_signals(&folded);
        let transitions: Vec<_> = folded
            .wiring()
            .iter()
            .filter(|b| {
                b.name
                    .starts_with(nanomotion_core::graph::RATE_TRANSITION_PREFIX)
            })
            .map(|b| {
                (
                    b.name.clone(),
                    folded.signal_id(&format!("{}.y", b.name)).unwrap(),
                )
            })
            .collect();
        let mut written_by_plain = vec![false; transitions.len()];
        let n = folded.ticks_total().min(4000);
        for k in 0..n {
            folded.tick();
            plain.tick_probed(&mut ());
            if k % 3 == 0 {
                alternating.tick();
            } else {
                alternating.tick_probed(&mut ());
            }
            for (r, id) in &signals {
                assert_eq!(
                    bits(folded.read(*id)),
                    bits(plain.read(*id)),
                    "{name}: {r} at tick {k}"
                );
                assert_eq!(
                    bits(alternating.read(*id)),
                    bits(plain.read(*id)),
                    "{name}: {r} at tick {k}"
                );
            }
            for (j, (_, id)) in transitions.iter().enumerate() {
                written_by_plain[j] |= plain.read(*id).iter().any(|&x| x != 0.0);
            }
        }
        for (j, (t, id)) in transitions.iter().enumerate() {
            assert!(written_by_plain[j], "{name}: {t} never carried a value");
            if t == "rt:a:y:s" {
                // Logged: kept, written by `tick` as by `tick_probed`.
                assert_eq!(bits(folded.read(*id)), bits(plain.read(*id)), "{name}: {t}");
            } else {
                // Folded: `tick` skips it (its consumer read its source).
                assert!(
                    folded.read(*id).iter().all(|&x| x == 0.0),
                    "{name}: {t} was not folded"
                );
            }
        }
        let (a, b) = (folded.result(), plain.result());
        assert_eq!(a.logs.len(), b.logs.len());
        for (x, y) in a.logs.iter().zip(&b.logs) {
            assert_eq!(bits(&x.data), bits(&y.data), "{name}: log {}", x.name);
        }
    }
}
