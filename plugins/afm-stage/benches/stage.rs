//! Cost of one `afm_stage` tick (the 3-DOF plant: clipping, three Coleman–Hodgdon
//! steps, 12-state dynamics, interferometer noise and the cantilever over the grating)
//! and of one inverse hysteresis feed-forward step (6.6) (Lambert W per sample).
//!
//! `cargo bench -p nanomotion-afm-stage --bench stage -- --warm-up-time 1 --measurement-time 3`

use afm_stage::experiments::Sec65;
use afm_stage::stage::{AfmStage, N_OUTPUTS};
use criterion::{Criterion, criterion_group, criterion_main};
use nanomotion_core::{Block, BuildContext, Plant, Tick};
use std::hint::black_box;

const DT: f64 = 2e-4; // 5 kHz, as in the Sec. 6.5 scan

fn bench(c: &mut Criterion) {
    let mut g = c.benchmark_group("afm_stage");
    // Through the Block interface, as the scheduler calls it: output + update.
    let mut b: Box<dyn Block> = Box::new(AfmStage::default());
    b.build(&BuildContext::new("stage", DT, 1)).unwrap();
    let mut y = [0.0; N_OUTPUTS];
    let mut k = 0u64;
    g.bench_function("tick_block", |bn| {
        bn.iter(|| {
            let v = 50.0 + 20.0 * ((k % 5000) as f64 * 1.2566e-3).sin();
            let t = Tick::new(k, DT);
            b.output(t, &[v, v, 50.0], &mut y);
            b.update(t, black_box(&[v, v, 50.0]));
            k += 1;
            black_box(y[0])
        })
    });
    // The plant alone (Plant trait), without noise: the deterministic part.
    let mut s = AfmStage::noiseless();
    s.build(&BuildContext::new("stage", DT, 1)).unwrap();
    let mut k = 0u64;
    g.bench_function("tick_plant_noiseless", |bn| {
        bn.iter(|| {
            let v = 50.0 + 20.0 * ((k % 5000) as f64 * 1.2566e-3).sin();
            s.plant_output(&mut y);
            s.advance(black_box(&[v, v, 50.0]));
            k += 1;
            black_box(y[0])
        })
    });
    g.finish();

    // The feed-forward of the Sec. 6.5 scan: ±18 µm triangle, 7.2 µm/s at 5 kHz.
    let sec = Sec65::new(&AfmStage::default(), 18.0, 7.2, 5000.0, 1).unwrap();
    let (lo, hi) = (sec.setup.x_lo_um, sec.setup.x_hi_um);
    let step = 7.2 * DT;
    let mut g = c.benchmark_group("feedforward");
    let mut hff = sec.hysteresis_ff.clone();
    let (mut r, mut dir) = (lo, 1.0);
    g.bench_function("hysteresis_ff_step", |bn| {
        bn.iter(|| {
            r += dir * step;
            if r >= hi || r <= lo {
                dir = -dir;
            }
            black_box(hff.step(black_box(r)))
        })
    });
    let pff = sec.position_ff;
    g.bench_function("position_ff_step", |bn| {
        bn.iter(|| {
            r += dir * step;
            if r >= hi || r <= lo {
                dir = -dir;
            }
            black_box(pff.voltage(black_box(r)))
        })
    });
    g.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
