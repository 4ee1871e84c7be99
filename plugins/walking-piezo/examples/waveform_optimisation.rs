//! Sec. 4.5 / Fig. 4.14 of Merry (2009) in shape, on the simulated stage:
//!
//! 1. optimise the 32 waveform points with the model-based objective (4.23)–(4.24)
//!    on the nominal model and with the "data-based" objective (4.25) on the
//!    perturbed, noisy stage that plays the real setup (both at f_α = 14 Hz,
//!    ẋ_r = 50 µm/s; simulated annealing and particle swarm from `argmin`, then
//!    Nelder–Mead; seeded);
//! 2. "experiments": the velocity error rms(ẋ_r − ẋ_s,e) on the real stage for the
//!    asymmetric, the model-based and the data-based waveforms at
//!    f_α ∈ {10, 12, 14, 16, 18, 20} Hz, ẋ_r = 50 µm/s · f_α/14 Hz, averaged over
//!    three validation experiments whose μ profiles and noise were not seen by the
//!    optimisation.
//!
//! `cargo run --release -p nanomotion-walking-piezo --example waveform_optimisation`
//! (optional argument: a budget factor, default 1; e.g. 0.2 for a quick look).
use std::ops::ControlFlow;
use std::time::Instant;
use walking_piezo::WaveformShape;
use walking_piezo::optimize::OptimizeConfig;
use walking_piezo::optimize::{
    Drive, ObjectiveKind, Outcome, Phase, Prepared, optimize, real_stage,
};

fn config(objective: &str, factor: f64) -> OptimizeConfig {
    let path = format!(
        "{}/../../examples/optimize_waveform/{objective}.yaml",
        env!("CARGO_MANIFEST_DIR")
    );
    let mut c = OptimizeConfig::from_file(std::path::Path::new(&path)).expect("example config");
    c.budget = c.budget.scaled(factor);
    c
}

fn run(c: &OptimizeConfig, label: &str) -> (Prepared, Outcome) {
    let t = Instant::now();
    let p = Prepared::new(c).expect("prepare");
    let o = optimize(&p, None, &mut |pr| {
        eprintln!(
            "  [{label}] {:<20} chunk {:>3}/{:<3} evals {:>6}  best {:.4} um/s",
            pr.phase.name(),
            pr.chunks_done,
            pr.chunks_total,
            pr.evaluations,
            pr.best_cost
        );
        ControlFlow::Continue(())
    })
    .expect("optimise");
    let s = &o.search;
    println!(
        "{label}: A = {:.3} V; start (8-point asymmetric) {:.4}, asymmetric {:.4} -> optimised {:.4} um/s ({:+.1} %); SA best {:.4}, PSO best {:.4} ({} wins), {} evaluations in {:.1} s",
        o.amplitude_v,
        s.start.exact_cost(),
        o.asymmetric_cost,
        o.cost,
        100.0 * (o.cost / o.asymmetric_cost - 1.0),
        s.phase(Phase::SimulatedAnnealing).best.exact_cost(),
        s.phase(Phase::ParticleSwarm).best.exact_cost(),
        match s.global_winner() {
            Phase::ParticleSwarm => "PSO",
            _ => "SA",
        },
        s.evaluations(),
        t.elapsed().as_secs_f64()
    );
    (p, o)
}

fn main() {
    let factor: f64 = std::env::args()
        .nth(1)
        .and_then(|a| a.parse().ok())
        .unwrap_or(1.0);
    // The two readings of the extracted "dy = .5 um": 0.5 um and 0.05 um (default).
    let mut c1 = config("model", factor);
    c1.clearance_m = -0.5e-6;
    let (pm, om) = run(&c1, "model, dy = -0.5 um");
    let (_p2, om2) = run(&config("model", factor), "model, dy = -0.05 um");
    let (_pd, od) = run(&config("data", factor), "data");
    let c = &pm.config;
    assert_eq!(pm.config.objective, ObjectiveKind::Model);
    let free = |o: &Outcome| WaveformShape::Free { points_v: o.points };
    let shapes = [
        ("asymmetric", pm.asymmetric_shape()),
        ("model-based (dy -0.5 um)", free(&om)),
        ("model-based (dy -0.05 um)", free(&om2)),
        ("data-based", free(&od)),
    ];
    println!();
    println!("On the nominal model at 14 Hz (g of (4.23) with dy = -0.5 um):");
    for (name, shape) in &shapes {
        let e = pm.model.evaluate_shape(shape.clone()).expect("model");
        println!(
            "  {name:<26} mean velocity {:>7.2} um/s, rms(v_r - v_s) {:>7.2} um/s, g {:>7.2} um/s",
            e.mean_velocity_um_s, e.stage_error_um_s, e.g_um_s
        );
    }
    let seeds = [101u64, 102, 103];
    println!();
    println!(
        "Fig. 4.14 style: rms(v_r - v_s,e) (um/s) on the perturbed stage, mean of {} validation experiments, A = {:.3} V",
        seeds.len(),
        om.amplitude_v
    );
    println!(
        "{:>6} {:>9} {:>11} {:>14} {:>15} {:>11} {:>9} {:>9} {:>9}",
        "f (Hz)",
        "v (um/s)",
        "asymmetric",
        "model(-0.5um)",
        "model(-0.05um)",
        "data-based",
        "model",
        "model'",
        "data"
    );
    let freqs = [10.0, 12.0, 14.0, 16.0, 18.0, 20.0];
    let mut sums = [0.0; 4];
    for f in freqs {
        let v = c.velocity_m_s * f / c.f_alpha_hz;
        let drive = Drive {
            f_alpha_hz: f,
            amplitude_v: om.amplitude_v,
            voltage_max_v: c.voltage_max_v,
        };
        let mut e = [0.0; 4];
        for (k, (_, shape)) in shapes.iter().enumerate() {
            for &s in &seeds {
                let real = real_stage(c, s);
                let m = real
                    .measure(
                        shape.clone(),
                        &drive,
                        v,
                        c.simulation.warmup_cycles,
                        4 * c.simulation.cycles,
                    )
                    .expect("measure");
                e[k] += m.error_um_s / seeds.len() as f64;
            }
            sums[k] += e[k] / freqs.len() as f64;
        }
        let pct = |x: f64| 100.0 * (x / e[0] - 1.0);
        println!(
            "{f:>6.0} {:>9.1} {:>11.3} {:>14.3} {:>15.3} {:>11.3} {:>8.0}% {:>8.0}% {:>8.0}%",
            v * 1e6,
            e[0],
            e[1],
            e[2],
            e[3],
            pct(e[1]),
            pct(e[2]),
            pct(e[3])
        );
    }
    let pct = |x: f64| 100.0 * (x / sums[0] - 1.0);
    println!(
        "{:>6} {:>9} {:>11.3} {:>14.3} {:>15.3} {:>11.3} {:>8.0}% {:>8.0}% {:>8.0}%",
        "mean",
        "",
        sums[0],
        sums[1],
        sums[2],
        sums[3],
        pct(sums[1]),
        pct(sums[2]),
        pct(sums[3])
    );
    println!("(thesis, at 50 um/s: model-based -24 %, data-based -47 % against asymmetric)");
}
