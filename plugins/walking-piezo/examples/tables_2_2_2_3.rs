//! Table 2.2 and Table 2.3 of Merry (2009) in shape, on the simulated stage, from the
//! YAML example graphs `examples/walking_piezo_jogging.yaml` and
//! `examples/walking_piezo_ff_gs.yaml`:
//!
//! - jogging at 100 nm/s … 2 mm/s with sinusoidal (non-overlapping) vs asymmetric
//!   (overlapping, q = 1/3) waveforms: max |e| over the second half of the run;
//! - point-to-point moves of 100 nm … 1 mm with and without feed-forward (2.11)–(2.12)
//!   and gain scheduling (2.13): overshoot M_p and settling time t_s (time after the
//!   end of the move until the encoder reading stays within one 5 nm count).
//!
//! Both graphs measure the stage through a 5 nm encoder (core `quantizer`, floor):
//! the thesis's errors include its resolution, so the measured columns are the
//! comparable ones; the true-position columns show what the quantisation hides.
//! The computation is [`walking_piezo::thesis::tables`] (also run by `nanomotion
//! reproduce`).
//!
//! `cargo run --release -p nanomotion-walking-piezo --example tables_2_2_2_3`
use gain_scheduling as _;
use walking_piezo::thesis::tables;

fn main() -> Result<(), String> {
    println!("Table 2.2 style: max |e| (nm) when jogging, second half of 2 s");
    println!("  measured e = r - x_enc (5 nm encoder count, as in the thesis); true e = r - x_s");
    println!(
        "{:>10} {:>14} {:>14} {:>10} {:>14} {:>14}",
        "v (m/s)", "non-ovl meas", "overl meas", "reduction", "non-ovl true", "overl true"
    );
    for r in tables::table_2_2()? {
        println!(
            "{:>10.0e} {:>14.2} {:>14.2} {:>9.0}% {:>14.2} {:>14.2}",
            r.v,
            r.measured_sinusoidal * 1e9,
            r.measured_asymmetric * 1e9,
            100.0 * (1.0 - r.measured_asymmetric / r.measured_sinusoidal),
            r.true_sinusoidal * 1e9,
            r.true_asymmetric * 1e9
        );
    }
    println!();
    println!("Table 2.3 style: point-to-point moves (minimum jerk, peak velocity 1.875 D/T)");
    println!(
        "  with the 5 nm encoder in the loop (as in the thesis): Mp and ts from the count x_enc,"
    );
    println!("  ts = time after the move until |d - x_enc| stays <= 5 nm (one count);");
    println!("  ideal sensor (encoder bypassed, x_s fed back): ts until |d - x_s| stays <= 5 nm");
    println!(
        "{:>9} {:>6} | {:>8} {:>7} {:>8} {:>7} {:>6} {:>5} | {:>8} {:>7} {:>8} {:>7} {:>6} {:>5}",
        "step (m)",
        "T (s)",
        "Mp noFF",
        "ts",
        "Mp FFGS",
        "ts",
        "dMp",
        "dts",
        "Mp noFF",
        "ts",
        "Mp FFGS",
        "ts",
        "dMp",
        "dts"
    );
    let pct = |a: f64, b: f64| {
        if a > 0.0 {
            format!("{:+.0}%", 100.0 * (b / a - 1.0))
        } else {
            "-".to_string()
        }
    };
    let t = tables::table_2_3()?;
    for r in &t.rows {
        let ([e0, e1], [i0, i1]) = (r.encoder, r.ideal);
        println!(
            "{:>9.0e} {:>6.3} | {:>8.1} {:>7.3} {:>8.1} {:>7.3} {:>6} {:>5} | {:>8.1} {:>7.3} {:>8.1} {:>7.3} {:>6} {:>5}",
            r.d,
            r.t_move,
            e0.mp * 1e9,
            e0.ts,
            e1.mp * 1e9,
            e1.ts,
            pct(e0.mp, e1.mp),
            pct(e0.ts, e1.ts),
            i0.mp * 1e9,
            i0.ts,
            i1.mp * 1e9,
            i1.ts,
            pct(i0.mp, i1.mp),
            pct(i0.ts, i1.ts),
        );
    }
    println!();
    println!(
        "Recovery after the move, ideal sensor: e = d - x_s (nm) at 0 / 50 / 100 / 150 ms after its end"
    );
    for r in &t.rows {
        let f = |e: [f64; 4]| e.map(|v| format!("{:7.1}", v * 1e9)).join(" ");
        println!(
            "{:>9.0e} T {:.3} s   no FF: {}   FF+GS: {}",
            r.d,
            r.t_move,
            f(r.ideal[0].tail),
            f(r.ideal[1].tail)
        );
    }
    for (name, mp) in ["encoder", "ideal sensor"]
        .iter()
        .zip(t.output_placement_mp)
    {
        println!(
            "0.1 mm, T = 1 s, FF + GS with the gain at the PI's output ({name}): Mp {:.1} nm",
            mp * 1e9
        );
    }
    Ok(())
}
