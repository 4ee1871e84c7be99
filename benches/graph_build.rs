//! Graph build cost against the number of blocks: parsing and building a chain
//! `src → b1 → b2 → … ` of N blocks (`graph_build/N`, N = 10 … 16 000; a chain of about 17 000 blocks
//! passes the YAML parser's budget of 250 000 values, docs/graph-format.md), what
//! `nanomotion check` does before the stability gate (a chain has no loop).
//! Figures are kept in docs/performance.md.
//!
//! Run: `cargo bench --bench graph_build` (the chains are also written to
//! `target/bench-graphs/chain_N.yaml`, for `nanomotion check`).

use criterion::{BenchmarkId, Criterion, Throughput, criterion_group, criterion_main};
use nanomotion::core::graph::GraphSpec;
use std::fmt::Write;
use std::hint::black_box;

/// Chain lengths of `graph_build`.
const BLOCKS: [usize; 5] = [10, 100, 1_000, 10_000, 16_000];

/// A chain of `n` blocks: a constant, then `n − 1` gains, one connection
/// between each two, the last one logged.
fn chain_yaml(n: usize) -> String {
    let mut s = format!(
        "title: generated chain of {n} blocks (benches/graph_build.rs)\nbase_rate_hz: 1000\nduration_s: 0.01\nblocks:\n  - {{ name: b0, type: constant, value: 1.0 }}\n"
    );
    for i in 1..n {
        let _ = writeln!(s, "  - {{ name: b{i}, type: gain, k: 1.0 }}");
    }
    s.push_str("connections:\n");
    for i in 1..n {
        let _ = writeln!(s, "  - {{ from: b{}.y, to: b{i}.u }}", i - 1);
    }
    let _ = writeln!(s, "log: [b{}.y]", n - 1);
    s
}

fn bench(c: &mut Criterion) {
    let out = concat!(env!("CARGO_MANIFEST_DIR"), "/target/bench-graphs");
    let _ = std::fs::create_dir_all(out);
    let mut group = c.benchmark_group("graph_build");
    group.sample_size(10);
    for n in BLOCKS {
        let yaml = chain_yaml(n);
        let _ = std::fs::write(format!("{out}/chain_{n}.yaml"), &yaml);
        group.throughput(Throughput::Elements(n as u64));
        group.bench_with_input(BenchmarkId::from_parameter(n), &yaml, |b, yaml| {
            b.iter(|| {
                let spec = GraphSpec::from_yaml(black_box(yaml), "chain").expect("chain parses");
                black_box(spec.build().expect("chain builds"))
            })
        });
    }
    group.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
