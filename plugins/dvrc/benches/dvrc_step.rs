//! DVRC tick cost (issue 7 item 6): a 100-tap linear-phase Q (101 taps, q = 50),
//! a ZPETC L and a 4000-sample worst-case ring buffer, α advancing at a varying
//! rate (the forward search path) and, separately, with a reversal inside the
//! window (the full-scan path).
//!
//! Run: `cargo bench -p nanomotion-dvrc --bench dvrc_step`

use criterion::{Criterion, Throughput, criterion_group, criterion_main};
use dvrc::filters::FilterSpec;
use dvrc::rc::{Dvrc, RepetitiveControl};
use std::hint::black_box;

const DT: f64 = 1.0 / 4000.0;
const TICKS: u64 = 4000;

fn dvrc() -> Dvrc {
    let mut d = Dvrc::new(
        std::f64::consts::TAU,
        100,
        4000,
        FilterSpec::Zpetc {
            num: vec![0.2, 0.1],
            den: vec![1.0, -0.6, 0.0],
        },
        FilterSpec::q_fir(101, 220.0),
    );
    d.build_dt(DT).unwrap();
    d
}

fn bench(c: &mut Criterion) {
    let mut g = c.benchmark_group("dvrc_tick");
    g.throughput(Throughput::Elements(TICKS));
    g.bench_function("dvrc_q101_buf4000_monotone_alpha", |b| {
        let mut d = dvrc();
        let mut a = 0.0f64;
        let mut k = 0u64;
        b.iter(|| {
            for _ in 0..TICKS {
                k += 1;
                a += std::f64::consts::TAU / 300.0 * (1.0 + 0.5 * (k as f64 * 1e-3).sin());
                let e = (k as f64 * 0.01).sin();
                black_box(d.step(black_box(e), a));
            }
        })
    });
    g.bench_function("dvrc_q101_buf4000_reversing_alpha", |b| {
        let mut d = dvrc();
        let mut a = 0.0f64;
        let mut k = 0u64;
        b.iter(|| {
            for _ in 0..TICKS {
                k += 1;
                // Back and forth every 2000 samples: a decrease is always inside
                // the 4000-sample window, so every tick scans the window.
                a += if (k / 2000).is_multiple_of(2) {
                    0.02
                } else {
                    -0.01
                };
                let e = (k as f64 * 0.01).sin();
                black_box(d.step(black_box(e), a));
            }
        })
    });
    g.bench_function("standard_rc_q101_n4000", |b| {
        let mut r = RepetitiveControl::built(
            4000,
            FilterSpec::Zpetc {
                num: vec![0.2, 0.1],
                den: vec![1.0, -0.6, 0.0],
            },
            FilterSpec::q_fir(101, 220.0),
            DT,
        )
        .unwrap();
        let mut k = 0u64;
        b.iter(|| {
            for _ in 0..TICKS {
                k += 1;
                black_box(r.step(black_box((k as f64 * 0.01).sin())));
            }
        })
    });
    g.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
