//! DRC per-tick cost of this crate's part: the three frame rotations of Fig. 7.11
//! (reference Rᵀ r_r, error R e_a, controller output Rᵀ u_r) through the `Block`
//! interface the scheduler calls. The RC on z adds the `repetitive_control` step of
//! the dvrc plugin (`cargo bench -p nanomotion-dvrc --bench dvrc_step`).
//!
//! Also the one-off estimation tick of `rotation_estimator`: the estimate
//! (7.18)–(7.21) of four lines in its preallocated workspace
//! (`estimate_rotation_in`), at 5 kHz (5 000 samples per line, ±22 lags, the YAML
//! scan) and 20 kHz (20 000 samples, ±82 lags, the thesis's rate).
//!
//! Run: `cargo bench -p nanomotion-directional-rc --bench drc_step`

use criterion::{Criterion, Throughput, criterion_group, criterion_main};
use nanomotion_core::{Block, BuildContext, Tick};
use nanomotion_directional_rc::estimate::{
    EstimatorOptions, LineRef, Workspace, estimate_rotation_in,
};
use nanomotion_directional_rc::frame::{Direction, FrameRotation};
use std::hint::black_box;

const TICKS: u64 = 20_000;

fn bench(c: &mut Criterion) {
    let dt = 1.0 / 20e3;
    let ctx = BuildContext::new("r", dt, 0);
    let mut to_a = FrameRotation::new(0.022, Direction::ToActuator, 3);
    let mut to_s = FrameRotation::new(0.022, Direction::ToSample, 2);
    let mut u_a = FrameRotation::new(0.022, Direction::ToActuator, 2);
    for b in [&mut to_a as &mut dyn Block, &mut to_s, &mut u_a] {
        b.build(&ctx).unwrap();
    }
    let mut g = c.benchmark_group("drc_tick");
    g.throughput(Throughput::Elements(TICKS));
    g.bench_function("three_frame_rotations", |b| {
        let (mut r, mut e, mut u) = ([0.0; 3], [0.0; 2], [0.0; 2]);
        b.iter(|| {
            for k in 0..TICKS {
                let t = Tick::new(k, dt);
                let x = k as f64 * 1e-9;
                to_a.output(t, black_box(&[x, 2.0 * x, 0.5]), &mut r);
                to_s.output(t, black_box(&[r[0] - 1e-9, r[1] + 1e-9]), &mut e);
                u_a.output(t, black_box(&e), &mut u);
                black_box(&u);
            }
        })
    });
    g.finish();

    // The estimation tick: a 10 µm grating rotated by 0.022 rad, four lines 1 µm
    // apart along y at 25 µm/s for 1 s.
    let mut g = c.benchmark_group("rotation_estimator_tick");
    g.sample_size(10);
    for fs in [5e3, 20e3] {
        let n = fs as usize;
        let dy = 25e-6 / fs;
        let a = 0.022f64;
        let lines: Vec<Vec<f64>> = (0..4)
            .map(|i| {
                let x = i as f64 * 1e-6;
                (0..n)
                    .map(|k| {
                        let s = (-x * a.sin() + k as f64 * dy * a.cos()) / 10e-6;
                        if s - s.floor() < 0.5 { 20e-9 } else { 0.0 }
                    })
                    .collect()
            })
            .collect();
        let refs: Vec<LineRef<'_>> = lines
            .iter()
            .enumerate()
            .map(|(i, z)| LineRef {
                x_m: i as f64 * 1e-6,
                y0_m: 0.0,
                dy_m: dy,
                z_m: z,
            })
            .collect();
        let mut ws = Workspace::new(4, n);
        let o = EstimatorOptions::default();
        g.bench_function(format!("four_lines_{n}_samples"), |b| {
            b.iter(|| black_box(estimate_rotation_in(black_box(&refs), &o, &mut ws).unwrap()))
        });
    }
    g.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
