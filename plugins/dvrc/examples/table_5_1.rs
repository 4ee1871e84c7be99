//! Table 5.1-style comparison (issue 7 item 5) on the linear fitted stage (5.31)
//! with a ripple periodic in the leg angle α (Fig. 5.6(b)), PI 50 Hz bandwidth at
//! 4 kHz, L = ZPETC of T, one 101-tap Q for all RC variants designed for the
//! largest delay spread of the experiments. See docs/repetitive-control.md.
//!
//! Run: `cargo run --release -p nanomotion-dvrc --example table_5_1`

#[path = "../tests/common/table51.rs"]
mod table51;
use table51::*;

fn main() {
    let s = setup();
    let profiles = [
        ("1 µm/s", Velocity::Constant(1e-6), 120.0),
        ("10 µm/s", Velocity::Constant(1e-5), 40.0),
        ("0.1 mm/s", Velocity::Constant(1e-4), 20.0),
        ("1 mm/s", Velocity::Constant(1e-3), 20.0),
        (
            "10 µm/s·(1 + 0.5 sin 0.2πt)",
            Velocity::Sinusoidal {
                v0: 1e-5,
                a: 0.5,
                f_hz: 0.1,
            },
            80.0,
        ),
    ];
    // Worst-case spread over the experiments (q + l + 1 = 56 samples minimum delay).
    let comp = 56;
    let spread = profiles
        .iter()
        .map(|(_, v, _)| {
            let (_, _, m, mm) = delay_range(&s, *v, comp);
            mm - m
        })
        .max()
        .unwrap();
    let (q, fc) = q_for(&s, spread);
    println!("Q: 101 taps, cut-off {fc:.1} Hz, designed for M − m = {spread}");
    println!(
        "| reference | [m, M] (samples) | none, no ripple (nm) | none (nm) | RC (nm) | high-order RC (nm) | DVRC (nm) | N_k seen by DVRC |"
    );
    println!("|---|---|---|---|---|---|---|---|");
    for (name, v, dur) in profiles {
        let (_, _, m, mm) = delay_range(&s, v, comp);
        let floor = run_with(&s, &q, v, Rc::None, dur, 0.0).0 * 1e9;
        let r: Vec<(f64, (usize, usize))> = [Rc::None, Rc::Standard, Rc::HighOrder, Rc::Dvrc]
            .iter()
            .map(|&w| run(&s, &q, v, w, dur))
            .collect();
        println!(
            "| {name} | [{m}, {mm}] | {floor:.3} | {:.3} | {:.3} | {:.3} | {:.3} | {:?} |",
            r[0].0 * 1e9,
            r[1].0 * 1e9,
            r[2].0 * 1e9,
            r[3].0 * 1e9,
            r[3].1
        );
    }
    println!("{}", criterion_text(&s, &q, 56, 56 + spread));
}
