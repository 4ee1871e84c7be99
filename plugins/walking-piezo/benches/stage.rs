//! Real-time factor of the nonlinear stage: 10 s of simulated time at the thesis's
//! step of 25 µs (400 000 steps), sinusoidal waveforms at 10 Hz, default
//! parameters (seeded μ variation on).
//!
//! `cargo bench -p nanomotion-walking-piezo --bench stage`; the figure printed last
//! is simulated seconds per wall-clock second (target ≥ 50).

use criterion::{Criterion, criterion_group, criterion_main};
use std::hint::black_box;
use std::time::Instant;
use walking_piezo::{SinusoidalWaveform, StageParams, WalkingPiezoStage};

const DT: f64 = 25e-6;
const SIM_S: f64 = 10.0;

fn run_10s() -> f64 {
    let wave = SinusoidalWaveform::default();
    let mut s = WalkingPiezoStage::new(StageParams::default(), DT, 1).unwrap();
    let n = (SIM_S / DT).round() as usize;
    for k in 0..n {
        let _ = s.step(&wave.voltages(wave.alpha(k as f64 * DT)), 0.0);
    }
    s.signals().x_s
}

fn bench(c: &mut Criterion) {
    let mut g = c.benchmark_group("walking_piezo_stage");
    g.sample_size(10);
    g.bench_function("10s_at_25us", |b| b.iter(|| black_box(run_10s())));
    g.finish();
    // The headline figure, measured directly over a few runs.
    let runs = 5;
    let t0 = Instant::now();
    for _ in 0..runs {
        black_box(run_10s());
    }
    let wall = t0.elapsed().as_secs_f64() / runs as f64;
    println!(
        "walking_piezo_stage: {SIM_S} s simulated at {} µs in {wall:.4} s wall = {:.0}× real time",
        DT * 1e6,
        SIM_S / wall
    );
}

criterion_group!(benches, bench);
criterion_main!(benches);
