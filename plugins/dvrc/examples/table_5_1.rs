//! Table 5.1-style comparison (issue 7 item 5, issue 18 item 3) on the linear
//! fitted stage (5.31) with a take-over velocity dip periodic in the leg angle α
//! (the stage sees f_α(1 − δ(α))), PI 50 Hz bandwidth at 4 kHz, L = ZPETC of T,
//! one 101-tap Q for all RC variants designed for the largest delay spread of the
//! experiments. The computation is `nanomotion::experiments::table51::linear_table`
//! (the facade: it needs walking-piezo too; shared with the test
//! and with `nanomotion reproduce table_5_1`). See docs/repetitive-control.md.
//!
//! Run: `cargo run --release -p nanomotion-dvrc --example table_5_1`

use nanomotion::experiments::table51::*;

fn main() {
    let quick = std::env::args().any(|a| a == "--quick");
    let t = linear_table(quick);
    println!(
        "velocity dip δ(α): depth {DIP_DEPTH}, half-width {:.4} rad at each take-over (α ≡ 0, π), mean {:.4}",
        DIP_HALF_WIDTH_RAD,
        dip_mean()
    );
    println!(
        "Q: 101 taps, cut-off {:.1} Hz, designed for M − m = {}",
        t.q_cutoff_hz, t.spread
    );
    println!(
        "| reference | run (s) | [m, M] (samples) | none, no dip (nm) | none (nm) | RC (nm) | high-order RC (nm) | DVRC (nm) | N_k seen by DVRC |"
    );
    println!("|---|---|---|---|---|---|---|---|---|");
    for r in &t.rows {
        println!(
            "| {} | {:.0} | [{}, {}] | {:.3} | {:.3} | {:.3} | {:.3} | {:.3} | {} … {} |",
            r.name,
            r.duration_s,
            r.m,
            r.mm,
            r.floor * 1e9,
            r.rms[0] * 1e9,
            r.rms[1] * 1e9,
            r.rms[2] * 1e9,
            r.rms[3] * 1e9,
            r.dvrc_n.0,
            r.dvrc_n.1
        );
    }
    println!("\nα-periodic part (α-synchronous average, 256 bins) and the rest, nm:");
    println!("| reference | none | RC | high-order RC | DVRC |\n|---|---|---|---|---|");
    for r in &t.rows {
        let f = |(_, p, q): (f64, f64, f64)| format!("{:.3} / {:.3}", p * 1e9, q * 1e9);
        println!(
            "| {} | {} | {} | {} | {} |",
            r.name,
            f(r.split[0]),
            f(r.split[1]),
            f(r.split[2]),
            f(r.split[3])
        );
    }
    println!(
        "\n10 µm/s with the former output ripple instead of the dip: none {:.3}, RC {:.3}, high-order RC {:.3}, DVRC {:.3} nm",
        t.ripple_10um[0] * 1e9,
        t.ripple_10um[1] * 1e9,
        t.ripple_10um[2] * 1e9,
        t.ripple_10um[3] * 1e9
    );
    println!("{}", t.criterion);
    for ((d, ho), (_, none)) in t.high_order_growth.iter().zip(&t.none_growth) {
        println!(
            "sinusoidal velocity, {d:.0} s run, rms over its last 10 s: high-order RC {:.3} nm, none {:.3} nm",
            ho * 1e9,
            none * 1e9
        );
    }
}
