//! Sec. 7.5 reproduced on the simulated AFM: rms e_z per iteration for RC and DRC
//! with the grating rotated by 0.022 and 0.015 rad (Fig. 7.17(a), Table 7.3).
//!
//! Run: `cargo run --release --example directional_rc [ITERATIONS [FS_HZ [Q_CUTOFF_HZ|design [noiseless] [unquantized] [linear_z]]]]`
//! or `cargo run --release --example directional_rc loop-check [FS_HZ [Q_CUTOFF_HZ|design [noiseless] [flat]]]`
//! (defaults 15, 20 000, designed by (7.16);
//! about a minute in release). See `nanomotion::experiments::directional_rc` for the
//! set-up and docs/directional-rc.md for the figures and their reading.

use nanomotion::experiments::directional_rc as sim;

fn main() {
    let arg = |i: usize| std::env::args().nth(i);
    if arg(1).is_some_and(|a| a == "loop-check") {
        let flag = |f: &str| std::env::args().skip(4).any(|a| a == f);
        let w_nm: f64 = std::env::args()
            .skip(4)
            .find_map(|a| {
                a.strip_prefix("w=")
                    .map(|v| v.parse().expect("w=NM: a number"))
            })
            .unwrap_or(2.0);
        return loop_check(
            arg(2),
            arg(3),
            [flag("noiseless"), flag("flat"), flag("unquantized")],
            w_nm,
        );
    }
    let iterations: usize = arg(1)
        .map(|a| a.parse().expect("ITERATIONS must be a whole number"))
        .unwrap_or(15);
    let fs_hz: f64 = arg(2)
        .map(|a| a.parse().expect("FS_HZ must be a number"))
        .unwrap_or(20e3);
    let q_cutoff_hz: Option<f64> = arg(3)
        .filter(|a| a != "design")
        .map(|a| a.parse().expect("Q_CUTOFF_HZ must be a number or `design`"));
    let flag = |f: &str| std::env::args().skip(4).any(|a| a == f);
    let (noiseless, unquantized, linear_z) =
        (flag("noiseless"), flag("unquantized"), flag("linear_z"));
    println!(
        "f_s = {fs_hz} Hz, {iterations} iterations, Q cut-off {q_cutoff_hz:?} Hz (None: designed), noiseless: {noiseless}, unquantized: {unquantized}, linear z piezo: {linear_z}"
    );
    let mut rows = Vec::new();
    for alpha in [0.022, 0.015] {
        for drc in [false, true] {
            let o = sim::run(&sim::Config {
                fs_hz,
                q_cutoff_hz,
                q_taps: 101,
                noiseless,
                unquantized,
                linear_z,
                iterations,
                alpha_rad: alpha,
                drc,
                rc: true,
                seed: 7,
                image_every: 0,
            });
            if let Some(e) = &o.estimate {
                println!("α = {alpha} rad: estimate {e}");
            }
            if rows.is_empty() {
                println!(
                    "RC design: Q cut-off {:.1} Hz (101 taps); criterion (7.16): {}",
                    o.q_cutoff_hz, o.criterion
                );
                println!(
                    "(7.16) with the z piezo's slope at its smallest: {}\n(7.16) with the slope at its largest: {}",
                    o.criterion_slopes[0], o.criterion_slopes[1]
                );
                println!(
                    "controllers (6.5), f_LP = 60 Hz: k = {:?} V/(m·s); T_z num {:?} den {:?}; start x, y, contact z = {:?} m",
                    o.k_gains, o.t_num_den.0, o.t_num_den.1, o.start_m
                );
            }
            println!(
                "{} α = {alpha}: per iteration rms w {:.0?} nm; e_z above 1 kHz {:.3?} nm; w above 1 kHz {:.0?} nm; rms u_z {:.3?} V; clipped drive samples {}",
                if drc { "DRC" } else { "RC" },
                o.w_rms_nm,
                o.ez_hf_nm,
                o.w_hf_nm,
                o.uz_rms_v,
                o.clips
            );
            rows.push((alpha, drc, o.rms_nm));
        }
    }
    println!("\nrms e_z (nm) per iteration k (iteration 1: RC memory still empty)");
    print!("{:>4}", "k");
    for (a, drc, _) in &rows {
        print!(
            " {:>14}",
            format!("{} α={a}", if *drc { "DRC" } else { "RC" })
        );
    }
    println!();
    for k in 0..iterations {
        print!("{:>4}", k + 1);
        for (_, _, r) in &rows {
            print!(" {:>14.3}", r[k]);
        }
        println!();
    }
    let last = iterations - 1;
    for pair in rows.chunks(2) {
        let (a, rc, drc) = (pair[0].0, pair[0].2[last], pair[1].2[last]);
        println!(
            "α = {a} rad, k = {iterations}: RC {rc:.3} nm → DRC {drc:.3} nm ({:+.0} %)",
            100.0 * (drc / rc - 1.0)
        );
    }
}

/// `loop-check [FS_HZ [Q_CUTOFF_HZ|design [noiseless] [flat] [unquantized] [w=NM]]]`:
/// criterion (7.16) with the T the simulation closes (measured with white noise of
/// NM nm std injected where RC adds w, default 2) vs the model T_z; `flat`: no
/// topography.
fn loop_check(fs: Option<String>, q: Option<String>, flags: [bool; 3], w_nm: f64) {
    let [noiseless, flat, unquantized] = flags;
    let fs_hz: f64 = fs.map_or(20e3, |a| a.parse().expect("FS_HZ must be a number"));
    let q_cutoff_hz = q
        .filter(|a| a != "design")
        .map(|a| a.parse().expect("Q_CUTOFF_HZ must be a number or `design`"));
    let cfg = sim::Config {
        fs_hz,
        q_cutoff_hz,
        q_taps: 101,
        noiseless,
        unquantized,
        linear_z: false,
        iterations: 0,
        alpha_rad: 0.022,
        drc: true,
        rc: false,
        seed: 7,
        image_every: 0,
    };
    let r = sim::loop_check(&cfg, w_nm * 1e-9, 3, 2048, flat);
    println!(
        "f_s = {fs_hz} Hz, Q cut-off {:.1} Hz, noiseless {noiseless}, flat {flat}, unquantized {unquantized}; w: white, {w_nm} nm std, 3 periods; Welch 2048",
        r.q_cutoff_hz
    );
    println!(
        "{:>8} {:>8} {:>9} {:>9} {:>10} {:>11} {:>11}",
        "f (Hz)", "coh", "|T| meas", "|T| model", "∠ diff (°)", "crit meas", "crit model"
    );
    let mut worst = (0.0f64, 0.0f64, 0.0f64);
    for i in 1..r.f_hz.len() {
        if r.coherence[i] > 0.9 && r.crit_meas[i] > worst.0 {
            worst = (r.crit_meas[i], r.f_hz[i], r.crit_model[i]);
        }
        if i % 32 == 0 || (i < 32 && i % 4 == 0) {
            let d = (r.t_meas[i] / r.t_model[i]).arg().to_degrees();
            println!(
                "{:>8.0} {:>8.3} {:>9.4} {:>9.4} {:>10.1} {:>11.4} {:>11.4}",
                r.f_hz[i],
                r.coherence[i],
                r.t_meas[i].norm(),
                r.t_model[i].norm(),
                d,
                r.crit_meas[i],
                r.crit_model[i]
            );
        }
    }
    let over: Vec<f64> = (1..r.f_hz.len())
        .filter(|&i| r.coherence[i] > 0.9 && r.crit_meas[i] > 1.0)
        .map(|i| r.f_hz[i])
        .collect();
    println!(
        "largest |Q(1 − T L z^l)| with the measured T (coherence > 0.9): {:.4} at {:.0} Hz (model there: {:.4}); bins above 1: {} ({:.0}–{:.0} Hz); clipped drive samples {}",
        worst.0,
        worst.1,
        worst.2,
        over.len(),
        over.first().copied().unwrap_or(f64::NAN),
        over.last().copied().unwrap_or(f64::NAN),
        r.clips
    );
}
