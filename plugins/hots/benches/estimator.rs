//! Estimator step (m = 2, n = 5), the fit alone by its fast path (normal
//! equations + LDLᵀ) and by Householder QR, and encoder event generation per
//! control tick. Figures in `docs/plugins/hots.md` (Performance).
//!
//!     cargo bench -p nanomotion-hots --bench estimator -- --warm-up-time 1 --measurement-time 3

use criterion::{Criterion, criterion_group, criterion_main};
use std::f64::consts::{FRAC_PI_2, TAU};
use std::hint::black_box;
use timestamp_encoder::fit::{fit_events, fit_events_qr};
use timestamp_encoder::{Status, TimestampEncoder, TimestampEstimator};

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
    // The benchmarked read is a real fit (not a fallback), on 5 valid events.
    assert_eq!(reg[1], 5.0);
    assert_eq!(
        est.estimate_from_register(0.3005, &reg, &mut y),
        Status::Fitted
    );
    c.bench_function("estimator m=2 n=5", |b| {
        b.iter(|| {
            est.estimate_from_register(black_box(0.3005), black_box(&reg), &mut y);
            black_box(y)
        })
    });
    // The fit alone: fast path (normal equations, LDLᵀ) against Householder QR.
    let ts: Vec<f64> = (0..5).map(|i| reg[2 + 2 * i]).collect();
    let xs: Vec<f64> = (0..5).map(|i| reg[3 + 2 * i]).collect();
    c.bench_function("fit m=2 n=5 (fast path)", |b| {
        b.iter(|| {
            black_box(fit_events(
                black_box(&ts),
                black_box(&xs),
                2,
                black_box(0.3005),
            ))
        })
    });
    c.bench_function("fit m=2 n=5 (Householder QR)", |b| {
        b.iter(|| {
            black_box(fit_events_qr(
                black_box(&ts),
                black_box(&xs),
                2,
                black_box(0.3005),
            ))
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
