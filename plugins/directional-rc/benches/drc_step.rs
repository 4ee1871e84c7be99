//! DRC per-tick cost of this crate's part: the three frame rotations of Fig. 7.11
//! (reference Rᵀ r_r, error R e_a, controller output Rᵀ u_r) through the `Block`
//! interface the scheduler calls. The RC on z adds the `repetitive_control` step of
//! the dvrc plugin (`cargo bench -p nanomotion-dvrc --bench dvrc_step`).
//!
//! Run: `cargo bench -p nanomotion-directional-rc --bench drc_step`

use criterion::{Criterion, Throughput, criterion_group, criterion_main};
use nanomotion_core::{Block, BuildContext, Tick};
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
}

criterion_group!(benches, bench);
criterion_main!(benches);
