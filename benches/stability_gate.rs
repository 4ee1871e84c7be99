//! The stability gate's cost: `gate::analyse` of each built example graph (what
//! `nanomotion check`/`run` add to building it), and of generated loops of 7 to
//! 399 states (`loop_states/N`: how the gate scales with a loop's order).
//! Figures are kept in docs/performance.md.
//!
//! Run: `cargo bench --bench stability_gate` (the generated loops are also
//! written to `target/bench-graphs/loop_N.yaml`, for `nanomotion check`).

use criterion::{BenchmarkId, Criterion, criterion_group, criterion_main};
use nanomotion::core::gate;
use nanomotion::core::graph::GraphSpec;
use std::fmt::Write;
use std::hint::black_box;

/// Loop orders of `loop_states` (the 7 / 39 / 99 / 199, 399 below and
/// 599 above the gate's cap of margins and norms, `gate::MAX_MARGIN_STATES`).
const LOOP_STATES: [usize; 6] = [7, 39, 99, 199, 399, 599];

/// Most states of one generated `state_space` block (the block allows 256).
const STATES_PER_BLOCK: usize = 200;

/// A unity-feedback loop `ref → err → k → plant0 → plant1 → … → err` of `n`
/// states whose plant is a series of discrete `state_space` blocks of at most
/// [`STATES_PER_BLOCK`] states each (one block up to 200 states).
fn loop_yaml(n: usize) -> String {
    let sizes: Vec<usize> = (0..n.div_ceil(STATES_PER_BLOCK))
        .map(|i| (n - i * STATES_PER_BLOCK).min(STATES_PER_BLOCK))
        .collect();
    let mut blocks = String::new();
    let mut connections = String::from("  - { from: err.y, to: k.u }\n");
    let mut from = "k".to_string();
    for (i, &size) in sizes.iter().enumerate() {
        let _ = write!(blocks, "  - name: plant{i}\n{}", plant_yaml(size));
        let _ = writeln!(connections, "  - {{ from: {from}.y, to: plant{i}.u }}");
        from = format!("plant{i}");
    }
    format!(
        "title: generated loop of {n} states (benches/stability_gate.rs)\nbase_rate_hz: 1000\nduration_s: 0.1\nblocks:\n  - {{ name: ref, type: constant, value: 1.0 }}\n  - {{ name: err, type: sum, signs: \"+-\" }}\n  - {{ name: k, type: gain, k: 0.5 }}\n{blocks}connections:\n  - {{ from: ref.y, to: err.in0 }}\n  - {{ from: {from}.y, to: err.in1 }}\n{connections}"
    )
}

/// The fields of a discrete `state_space` block of `n` states: ⌊n/2⌋ lightly
/// damped resonances (|z| = 0.98, spread over 0.05 … 2.5 rad per sample) and
/// a real pole for odd `n`, in modal form behind the orthogonal similarity
/// Q = I − 2vvᵀ/vᵀv (so A is dense), with residues small enough that
/// |P| < 1 at every frequency (so the loop is stable with k = 0.5).
fn plant_yaml(n: usize) -> String {
    let pairs = n / 2;
    let mut a = vec![vec![0.0; n]; n];
    let mut b = vec![0.0; n];
    let mut c = vec![0.0; n];
    let r: f64 = 0.98;
    // Each mode's gain peak is |c b| / (1 − r) at most; the sum stays < 1.
    let weight = 0.9 * (1.0 - r) / (pairs + 1) as f64;
    for k in 0..pairs {
        let th = 0.05 + 2.45 * k as f64 / (pairs.max(2) - 1) as f64;
        let i = 2 * k;
        let (re, im) = (r * th.cos(), r * th.sin());
        a[i][i] = re;
        a[i + 1][i + 1] = re;
        a[i][i + 1] = im;
        a[i + 1][i] = -im;
        b[i] = weight.sqrt();
        c[i] = weight.sqrt();
    }
    if n % 2 == 1 {
        a[n - 1][n - 1] = 0.5;
        b[n - 1] = 0.5 * weight.sqrt();
        c[n - 1] = weight.sqrt();
    }
    // Q = I − 2 v vᵀ / vᵀv, v_i = 1 + sin(i): A ← Q A Q, B ← Q B, C ← C Q.
    let v: Vec<f64> = (0..n).map(|i| 1.0 + (i as f64).sin()).collect();
    let vv: f64 = v.iter().map(|x| x * x).sum();
    let reflect = |x: &mut Vec<f64>| {
        let s = 2.0 * x.iter().zip(&v).map(|(p, q)| p * q).sum::<f64>() / vv;
        x.iter_mut().zip(&v).for_each(|(p, q)| *p -= s * q);
    };
    for row in a.iter_mut() {
        reflect(row); // A Q
    }
    for j in 0..n {
        let mut col: Vec<f64> = a.iter().map(|row| row[j]).collect();
        reflect(&mut col); // Q (A Q)
        for (row, x) in a.iter_mut().zip(col) {
            row[j] = x;
        }
    }
    reflect(&mut b);
    reflect(&mut c);
    let rows = |m: &[Vec<f64>]| {
        let mut s = String::from("[");
        for (i, row) in m.iter().enumerate() {
            s.push_str(if i > 0 { ", [" } else { "[" });
            for (j, x) in row.iter().enumerate() {
                let _ = write!(s, "{}{x:?}", if j > 0 { ", " } else { "" });
            }
            s.push(']');
        }
        s.push(']');
        s
    };
    let col: Vec<Vec<f64>> = b.iter().map(|&x| vec![x]).collect();
    format!(
        "    type: state_space\n    discrete: true\n    a: {}\n    b: {}\n    c: {}\n    d: [[0.0]]\n",
        rows(&a),
        rows(&col),
        rows(&[c]),
    )
}

fn examples(c: &mut Criterion) {
    nanomotion::link_plugins();
    let dir = concat!(env!("CARGO_MANIFEST_DIR"), "/examples");
    let mut paths: Vec<_> = std::fs::read_dir(dir)
        .expect("examples folder")
        .map(|e| e.expect("entry").path())
        .filter(|p| p.extension().is_some_and(|x| x == "yaml"))
        .collect();
    paths.sort();
    let mut group = c.benchmark_group("stability_gate");
    group.sample_size(20);
    for path in paths {
        let spec = GraphSpec::from_file(&path).expect("example parses");
        let require = spec.require.clone().unwrap_or_default();
        let (sched, _) = spec.build().expect("example builds");
        let name = path
            .file_stem()
            .expect("stem")
            .to_string_lossy()
            .into_owned();
        group.bench_function(name, |b| {
            b.iter(|| black_box(gate::analyse(black_box(&sched), &require)))
        });
    }
    group.finish();
}

fn loop_states(c: &mut Criterion) {
    let out = concat!(env!("CARGO_MANIFEST_DIR"), "/target/bench-graphs");
    let _ = std::fs::create_dir_all(out);
    let mut group = c.benchmark_group("loop_states");
    group.sample_size(10);
    for n in LOOP_STATES {
        let yaml = loop_yaml(n);
        let _ = std::fs::write(format!("{out}/loop_{n}.yaml"), &yaml);
        let spec = GraphSpec::from_yaml(&yaml, "loop").expect("generated loop parses");
        let require = spec.require.clone().unwrap_or_default();
        let (sched, _) = spec.build().expect("generated loop builds");
        let report = gate::analyse(&sched, &require);
        let point = &report.loops[0].points[0];
        assert!(point.stable, "generated loop of {n} states is stable");
        assert_eq!(point.poles.len(), n);
        group.bench_with_input(BenchmarkId::from_parameter(n), &sched, |b, sched| {
            b.iter(|| black_box(gate::analyse(black_box(sched), &require)))
        });
    }
    group.finish();
}

criterion_group!(benches, examples, loop_states);
criterion_main!(benches);
