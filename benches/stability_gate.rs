//! The stability gate's cost on the shipped examples: `gate::analyse` of each
//! built example graph (what `nanomotion check`/`run` add to building it).
//! Figures are kept in docs/performance.md.
//!
//! Run: `cargo bench --bench stability_gate`

use criterion::{Criterion, criterion_group, criterion_main};
use nanomotion::core::gate;
use nanomotion::core::graph::GraphSpec;
use std::hint::black_box;

fn bench(c: &mut Criterion) {
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

criterion_group!(benches, bench);
criterion_main!(benches);
