//! CPU time per `mimo_controller` tick (order 17, 3×3) for a loaded machine, where
//! criterion's wall-clock figures are inflated by other processes: run under
//! `time` and divide the *user* time by the tick count printed.
//!
//! `cargo build --release -p nanomotion-mimo --example tick_cpu && time target/release/examples/tick_cpu`

use nanomotion_core::{Block, BuildContext, Tick};
use nanomotion_mimo::config::{SynthConfig, run};
use std::hint::black_box;
use std::time::Instant;

fn main() {
    let cfg = SynthConfig::from_yaml(
        include_str!("../../../examples/mimo/afm_synth.yaml"),
        "afm_synth.yaml",
    )
    .expect("shipped config");
    let mut k = run(&cfg).expect("synthesis").block;
    let dt = 1.0 / cfg.rate_hz;
    k.build(&BuildContext::new("k", dt, 0)).expect("build");
    let (mut u, mut inp) = ([0.0; 3], [0.0; 6]);
    let n: u64 = 20_000_000;
    let t0 = Instant::now();
    for t in 0..n {
        let tick = Tick::new(t, dt);
        inp[0] = 1e-12 * (t % 1000) as f64;
        k.output(tick, black_box(&inp), &mut u);
        if !k.direct_feedthrough() {
            k.update(tick, &inp);
        }
        black_box(u[0]);
    }
    let wall = t0.elapsed().as_secs_f64();
    println!(
        "{n} ticks, wall {:.1} ns per tick (divide the user time of `time` by {n} for CPU time)",
        wall / n as f64 * 1e9
    );
}
