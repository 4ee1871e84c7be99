//! Loop timing: ns per tick of whole graphs, scheduler overhead per block step, and
//! per-block step costs. Figures are kept in docs/performance.md.
//!
//! Run: `cargo bench --bench loop_timing`

use criterion::{BenchmarkId, Criterion, Throughput, criterion_group, criterion_main};
use nanomotion::core::graph::GraphSpec;
use nanomotion::core::{Block, BuildContext, Port, Tick};
use serde::{Deserialize, Serialize};
use std::hint::black_box;

/// y = u: the cheapest possible block, to expose the scheduler's own cost.
#[derive(Debug, Serialize, Deserialize)]
struct BenchPass {}
#[typetag::serde(name = "bench_pass")]
impl Block for BenchPass {
    fn inputs(&self) -> Vec<Port> {
        vec![Port::new("u", 1)]
    }
    fn outputs(&self) -> Vec<Port> {
        vec![Port::new("y", 1)]
    }
    fn output(&mut self, _t: Tick, u: &[f64], y: &mut [f64]) {
        y[0] = u[0];
    }
}

fn graph(yaml: &str) -> nanomotion::core::Scheduler {
    GraphSpec::from_yaml(yaml, "bench")
        .expect("bench graph parses")
        .build()
        .expect("bench graph builds")
        .0
}

const TICKS: u64 = 1000;

fn bench_graphs(c: &mut Criterion) {
    let mut g = c.benchmark_group("graph_tick");
    g.throughput(Throughput::Elements(TICKS));
    let quickstart = std::fs::read_to_string(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/examples/quickstart.yaml"
    ))
    .expect("examples/quickstart.yaml");
    // Long duration so that nothing stops; logging off so memory stays flat.
    let quickstart = strip_logs(&quickstart);
    let mut s = graph(&quickstart);
    g.bench_function("quickstart", |b| b.iter(|| s.step_n(black_box(TICKS))));
    let mut s = graph(TEN_BLOCKS);
    g.bench_function("ten_blocks", |b| b.iter(|| s.step_n(black_box(TICKS))));
    g.finish();
}

/// Remove `log:` and `score:` sections (benchmarks measure the loop alone).
fn strip_logs(yaml: &str) -> String {
    let mut out = String::new();
    let mut skipping = false;
    for line in yaml.lines() {
        if line.starts_with("log:") || line.starts_with("score:") {
            skipping = true;
            continue;
        }
        if skipping && (line.starts_with(' ') || line.starts_with('-')) {
            continue;
        }
        skipping = false;
        out.push_str(line);
        out.push('\n');
    }
    out
}

fn chain(n: usize) -> String {
    let mut y = String::from(
        "base_rate_hz: 1000\nduration_s: 1\nblocks:\n  - { name: src, type: constant, value: 1.0 }\n",
    );
    for i in 0..n {
        y.push_str(&format!("  - {{ name: b{i}, type: bench_pass }}\n"));
    }
    y.push_str("connections:\n  - { from: src.y, to: b0.u }\n");
    for i in 1..n {
        y.push_str(&format!("  - {{ from: b{}.y, to: b{i}.u }}\n", i - 1));
    }
    y
}

fn bench_overhead(c: &mut Criterion) {
    // Cost per block step of the scheduler itself: a chain of pass-through blocks.
    let mut g = c.benchmark_group("scheduler_overhead_per_block_step");
    for n in [10usize, 100] {
        g.throughput(Throughput::Elements(TICKS * (n as u64 + 1)));
        let mut s = graph(&chain(n));
        g.bench_with_input(BenchmarkId::from_parameter(n), &n, |b, _| {
            b.iter(|| s.step_n(black_box(TICKS)))
        });
    }
    g.finish();

    // The floor: five boxed dyn blocks over a flat buffer, no scheduler at all.
    let mut g = c.benchmark_group("floor");
    g.throughput(Throughput::Elements(TICKS));
    let mut blocks: Vec<Box<dyn Block>> = (0..5)
        .map(|_| Box::new(BenchPass {}) as Box<dyn Block>)
        .collect();
    let mut buf = [1.0f64; 6];
    g.bench_function("bare_loop_5_dyn_blocks", |b| {
        b.iter(|| {
            for k in 0..TICKS {
                for (i, blk) in blocks.iter_mut().enumerate() {
                    let (a, rest) = buf.split_at_mut(i + 1);
                    blk.output(Tick::new(k, 1e-3), &a[i..=i], &mut rest[..1]);
                }
            }
            black_box(buf[5])
        })
    });
    g.finish();
}

fn bench_blocks(c: &mut Criterion) {
    // Per-block step cost, called directly (no scheduler).
    let mut g = c.benchmark_group("block_step");
    g.throughput(Throughput::Elements(TICKS));
    for (name, yaml) in BLOCKS {
        let mut b: Box<dyn Block> =
            nanomotion::core::yaml::from_str(yaml, name).expect("block parses");
        b.build(&BuildContext::new(*name, 2.5e-4, 1))
            .expect("block builds");
        let n_in: usize = b.inputs().iter().map(|p| p.width).sum();
        let n_out: usize = b.outputs().iter().map(|p| p.width).sum();
        let u = vec![0.3; n_in];
        let mut y = vec![0.0; n_out];
        let ft = b.direct_feedthrough();
        g.bench_function(*name, |bch| {
            bch.iter(|| {
                for k in 0..TICKS {
                    let t = Tick::new(k, 2.5e-4);
                    b.output(t, black_box(&u), &mut y);
                    if !ft {
                        b.update(t, &u);
                    }
                }
                black_box(y[0])
            })
        });
    }
    g.finish();
}

/// The closed loop `nanomotion diagnose` simulates ~22 700 times on the EMPS
/// record (issue #24): examples/diagnose/emps_nominal.yaml with its two compared
/// logs, run as the fit's evaluator runs it (reset, then every sample), on a
/// synthetic record of the EMPS length (24 841 samples at 1 kHz; the values do
/// not change the work per sample). `emps_nominal` is the nominal graph,
/// `emps_bouc_wen` the same with a Bouc–Wen hysteresis candidate in series
/// before the amplifier limit. Throughput elements are samples (ticks).
fn bench_emps(c: &mut Criterion) {
    use nanomotion::core::data::Dataset;
    use std::sync::Arc;
    const SAMPLES: usize = 24_841;
    let nominal = std::fs::read_to_string(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/examples/diagnose/emps_nominal.yaml"
    ))
    .expect("examples/diagnose/emps_nominal.yaml");
    let with_bouc_wen = nominal
        .replace(
            "  - { name: one_sample,",
            "  - { name: hysteresis, type: bouc_wen, a: 0.5, beta: 0.3, gamma: 0.2, linear: 0.8 }\n  - { name: one_sample,",
        )
        .replace(
            "{ from: kv.y, to: amplifier_limit.u }",
            "{ from: kv.y, to: hysteresis.u }\n  - { from: hysteresis.y, to: amplifier_limit.u }",
        );
    // A slow sweep of ±2 cm as the reference, so that the loop moves.
    let reference: Vec<f64> = (0..SAMPLES)
        .map(|k| 0.02 * (k as f64 * 1e-3 * 0.7).sin())
        .collect();
    let data = Arc::new(
        Dataset::from_columns(
            "emps_synthetic",
            1000.0,
            0.0,
            vec![
                ("q_ref_m".into(), reference),
                ("q_meas_m".into(), vec![0.0; SAMPLES]),
                ("u_v".into(), vec![0.0; SAMPLES]),
            ],
        )
        .expect("synthetic EMPS record"),
    );
    nanomotion::link_plugins();
    let mut g = c.benchmark_group("emps_closed_loop");
    g.throughput(Throughput::Elements(SAMPLES as u64));
    for (name, yaml) in [
        ("emps_nominal", &nominal),
        ("emps_bouc_wen", &with_bouc_wen),
    ] {
        let mut s = GraphSpec::from_yaml(yaml, name)
            .expect("EMPS graph parses")
            .build_with_data(data.clone())
            .expect("EMPS graph builds")
            .0;
        g.bench_function(name, |b| {
            b.iter(|| {
                s.reset().expect("EMPS graph restarts");
                s.step_n(black_box(SAMPLES as u64));
                black_box(s.compare_log(0).map(|(l, _)| l[SAMPLES - 1]))
            })
        });
    }
    g.finish();
}

criterion_group!(
    benches,
    bench_graphs,
    bench_overhead,
    bench_blocks,
    bench_emps
);
criterion_main!(benches);

/// Ten blocks at 4 kHz: reference, noise, sum, PID, saturation, low-pass, plant,
/// quantiser, notch, lead-lag.
const TEN_BLOCKS: &str = r#"
base_rate_hz: 4000
duration_s: 1000
blocks:
  - { name: ref, type: sinusoid, amplitude: 1.0e-6, frequency_hz: 5 }
  - { name: noise, type: white_noise, std: 1.0e-9 }
  - { name: err, type: sum, signs: "+--" }
  - { name: pid, type: pid, kp: 2.0e5, ki: 1.0e7, kd: 50, derivative_cutoff_hz: 500, output_min: -2000, output_max: 2000 }
  - { name: lead, type: lead_lag, zero_hz: 30, pole_hz: 300, gain: 1.0 }
  - { name: notch, type: notch, centre_hz: 575, damping: 0.3, depth: 0.1 }
  - { name: lp, type: low_pass, order: 2, cutoff_hz: 1000 }
  - { name: sat, type: saturation, lower: -2000, upper: 2000 }
  - { name: stage, type: transfer_function, num: [3.685e-4, 13.3135], den: [0.255, 92.1, 3.32837e6, 0.0], discretisation: zoh }
  - { name: enc, type: quantizer, lsb: 5.0e-9 }
connections:
  - { from: ref.y, to: err.in0 }
  - { from: enc.y, to: err.in1 }
  - { from: noise.y, to: err.in2 }
  - { from: err.y, to: pid.e }
  - { from: pid.u, to: lead.u }
  - { from: lead.y, to: notch.u }
  - { from: notch.y, to: lp.u }
  - { from: lp.y, to: sat.u }
  - { from: sat.y, to: stage.u }
  - { from: stage.y, to: enc.u }
"#;

/// One YAML snippet per standard block, stepped directly.
const BLOCKS: &[(&str, &str)] = &[
    ("gain", "type: gain\nk: 2.0\n"),
    ("sum", "type: sum\nsigns: \"+-\"\n"),
    ("saturation", "type: saturation\nlower: -1\nupper: 1\n"),
    (
        "pid",
        "type: pid\nkp: 1.0\nki: 10.0\nkd: 0.01\nderivative_cutoff_hz: 200\n",
    ),
    (
        "low_pass_5th_order",
        "type: low_pass\norder: 5\ncutoff_hz: 100\n",
    ),
    (
        "notch",
        "type: notch\ncentre_hz: 500\ndamping: 0.3\ndepth: 0.1\n",
    ),
    (
        "transfer_function_stage",
        "type: transfer_function\nnum: [3.685e-4, 13.3135]\nden: [0.255, 92.1, 3.32837e6, 0.0]\ndiscretisation: zoh\n",
    ),
    ("delay_3", "type: delay\nd: 3\n"),
    ("quantizer", "type: quantizer\nlsb: 5.0e-9\n"),
    ("white_noise", "type: white_noise\nstd: 1.0\n"),
    (
        "point_to_point",
        "type: point_to_point\ntarget_m: 1.0e-3\nv_max_m_s: 1.0e-3\na_max_m_s2: 1.0e-2\nj_max_m_s3: 1.0\n",
    ),
];
