//! Synthesis time of the thesis's AFM problem (plain and near-axis design) and the per-tick cost of the
//! order-17 3×3 `mimo_controller`.
//!
//! `cargo bench -p nanomotion-mimo --bench mimo -- --warm-up-time 1 --measurement-time 3`

use criterion::{Criterion, criterion_group, criterion_main};
use nanomotion_core::{Block, BuildContext, Tick};
use nanomotion_mimo::config::{SynthConfig, run};
use nanomotion_mimo::synth::synthesise;
use std::hint::black_box;

fn bench(c: &mut Criterion) {
    let cfg = SynthConfig::from_yaml(
        include_str!("../../../examples/mimo/afm_synth.yaml"),
        "afm_synth.yaml",
    )
    .unwrap();
    let g = cfg.plant_ss().unwrap();
    let mut grp = c.benchmark_group("mimo");
    grp.sample_size(10);
    grp.bench_function("synthesise_afm", |b| {
        b.iter(|| black_box(synthesise(&g, &cfg.weights).unwrap().gamma))
    });
    // The near-axis design at the thesis's 2π·10⁻⁶ rad/s (docs/mimo.md): the
    // synthesis at 10⁻³ Hz plus the structured verification and factored grid.
    grp.bench_function("synthesise_afm_near_axis", |b| {
        b.iter(|| {
            black_box(
                nanomotion_mimo::synth::synthesise_near_axis(&g, &cfg.weights, 1e-3)
                    .unwrap()
                    .gamma,
            )
        })
    });
    drop(grp);
    let mut k = run(&cfg).unwrap().block;
    let dt = 1.0 / cfg.rate_hz;
    k.build(&BuildContext::new("k", dt, 0)).unwrap();
    let mut u = [0.0; 3];
    let mut inp = [0.0; 6];
    let mut t = 0u64;
    c.bench_function("mimo_controller_tick_order17_3x3", |b| {
        b.iter(|| {
            let tick = Tick::new(t, dt);
            inp[0] = 1e-9 * ((t % 1000) as f64 * 1e-3);
            k.output(tick, &inp, &mut u);
            if !k.direct_feedthrough() {
                k.update(tick, black_box(&inp));
            }
            t += 1;
            black_box(u[0])
        })
    });
}

criterion_group!(benches, bench);
criterion_main!(benches);
