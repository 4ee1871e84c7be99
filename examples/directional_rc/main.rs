//! Sec. 7.5 reproduced on the simulated AFM: rms e_z per iteration for RC and DRC
//! with the grating rotated by 0.022 and 0.015 rad (Fig. 7.17(a), Table 7.3).
//!
//! Run: `cargo run --release --example directional_rc [ITERATIONS [FS_HZ [Q_CUTOFF_HZ|design [noiseless]]]]`
//! (defaults 15, 20 000, designed by (7.16);
//! about a minute in release). See `sim.rs` for the set-up and
//! docs/directional-rc.md for the figures and their reading.

mod sim;

fn main() {
    let arg = |i: usize| std::env::args().nth(i);
    let iterations: usize = arg(1)
        .map(|a| a.parse().expect("ITERATIONS must be a whole number"))
        .unwrap_or(15);
    let fs_hz: f64 = arg(2)
        .map(|a| a.parse().expect("FS_HZ must be a number"))
        .unwrap_or(20e3);
    let q_cutoff_hz: Option<f64> = arg(3)
        .filter(|a| a != "design")
        .map(|a| a.parse().expect("Q_CUTOFF_HZ must be a number or `design`"));
    let noiseless = arg(4).is_some_and(|a| a == "noiseless");
    println!(
        "f_s = {fs_hz} Hz, {iterations} iterations, Q cut-off {q_cutoff_hz:?} Hz (None: designed), noiseless: {noiseless}"
    );
    let mut rows = Vec::new();
    for alpha in [0.022, 0.015] {
        for drc in [false, true] {
            let o = sim::run(&sim::Config {
                fs_hz,
                q_cutoff_hz,
                q_taps: 101,
                noiseless,
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
