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
//! The computation is [`walking_piezo::thesis::sec45`] (also run by `nanomotion
//! reproduce`).
use walking_piezo::thesis::sec45;

fn main() -> Result<(), String> {
    let factor: f64 = std::env::args()
        .nth(1)
        .and_then(|a| a.parse().ok())
        .unwrap_or(1.0);
    let seeds = [101u64, 102, 103];
    let freqs = [10.0, 12.0, 14.0, 16.0, 18.0, 20.0];
    let r = sec45::sec_4_5(factor, &seeds, &freqs, &mut |line| eprintln!("{line}"))?;
    for o in &r.optimisations {
        println!(
            "{}: A = {:.3} V; start (8-point asymmetric) {:.4}, asymmetric {:.4} -> optimised {:.4} um/s ({:+.1} %); SA best {:.4}, PSO best {:.4} ({} wins), {} evaluations in {:.1} s",
            o.label,
            o.amplitude_v,
            o.start,
            o.asymmetric,
            o.optimised,
            100.0 * (o.optimised / o.asymmetric - 1.0),
            o.sa_best,
            o.pso_best,
            if o.pso_wins { "PSO" } else { "SA" },
            o.evaluations,
            o.seconds
        );
    }
    println!();
    println!("On the nominal model at 14 Hz (g of (4.23) with dy = -0.5 um):");
    for (name, v, e, g) in &r.nominal {
        println!(
            "  {name:<26} mean velocity {v:>7.2} um/s, rms(v_r - v_s) {e:>7.2} um/s, g {g:>7.2} um/s"
        );
    }
    println!();
    println!(
        "Fig. 4.14 style: rms(v_r - v_s,e) (um/s) on the perturbed stage, mean of {} validation experiments, A = {:.3} V",
        seeds.len(),
        r.optimisations[0].amplitude_v
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
    for row in &r.validation {
        let e = row.error_um_s;
        let pct = |x: f64| 100.0 * (x / e[0] - 1.0);
        println!(
            "{:>6.0} {:>9.1} {:>11.3} {:>14.3} {:>15.3} {:>11.3} {:>8.0}% {:>8.0}% {:>8.0}%",
            row.f_alpha_hz,
            row.v_m_s * 1e6,
            e[0],
            e[1],
            e[2],
            e[3],
            pct(e[1]),
            pct(e[2]),
            pct(e[3])
        );
    }
    let sums = r.validation_mean;
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
    Ok(())
}
