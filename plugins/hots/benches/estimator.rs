//! Estimator step (m = 2, n = 5) and encoder event generation per control tick.
//!
//!     cargo bench -p nanomotion-hots --bench estimator

use criterion::{Criterion, criterion_group, criterion_main};
use std::f64::consts::{FRAC_PI_2, TAU};
use std::hint::black_box;
use timestamp_encoder::{TimestampEncoder, TimestampEstimator};

fn bench(c: &mut Criterion) {
    let mut enc = TimestampEncoder {
        skip: 3,
        ..Default::default()
    };
    enc.prepare(0).unwrap();
    let mut reg = [0.0; 12];
    for k in 0..=300 {
        let t = k as f64 * 1e-3;
        enc.measure_at(t, &mut reg);
    }
    let mut est = TimestampEstimator::new(2, 5, enc.resolution()).unwrap();
    let mut y = [0.0; 3];
    c.bench_function("estimator m=2 n=5", |b| {
        b.iter(|| {
            est.estimate_from_register(black_box(0.3005), black_box(&reg), &mut y);
            black_box(y)
        })
    });
    let mut k = 301u64;
    c.bench_function("encoder tick (sinusoid, 1 kHz)", |b| {
        b.iter(|| {
            k += 1;
            let t = (k % 100_000) as f64 * 1e-3 + 0.301;
            enc.measure_at(t, &mut reg);
            black_box(reg[0])
        })
    });
}

trait At {
    fn measure_at(&mut self, t: f64, reg: &mut [f64]);
}
impl At for TimestampEncoder {
    fn measure_at(&mut self, t: f64, reg: &mut [f64]) {
        let (a, w) = (FRAC_PI_2, TAU);
        self.advance(t, &[a * (w * t).sin(), a * w * (w * t).cos()]);
        self.read_register(reg);
    }
}

criterion_group!(benches, bench);
criterion_main!(benches);
