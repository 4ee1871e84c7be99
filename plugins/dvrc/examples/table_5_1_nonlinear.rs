//! Table 5.1-style comparison (issue 7 item 5) on the *nonlinear* walking piezo
//! stage: `WaveformDriver` with the asymmetric waveforms (q = 1/3) driving
//! `WalkingPiezoStage` (10 sub-steps of 25 µs per 4 kHz sample, seeded μ variation,
//! unequal pairs), PI on f_α with 50 Hz bandwidth designed on the fitted linear
//! model (5.31), L = ZPETC of the linear T, one 101-tap Q for all RC variants
//! designed so (5.9) holds for the largest delay spread of the experiments. DVRC
//! takes α from the driver. No ripple is added: the error is the model's stepping.
//! See docs/repetitive-control.md.
//!
//! Run: `cargo run --release -p nanomotion-dvrc --example table_5_1_nonlinear`

#[path = "../tests/common/table51.rs"]
mod table51;
#[path = "../tests/common/table51_nonlinear.rs"]
mod table51_nonlinear;
use std::f64::consts::TAU;
use table51::{Rc, Velocity, criterion_text, setup};
use table51_nonlinear::*;

/// Relative margin on [m, M] for the irregular stepping.
const MARGIN: f64 = 0.25;

fn main() {
    let s = setup();
    let mg = margins(&s);
    println!(
        "PI (k_p = {:.4e} Hz/m, zero 5 Hz) on the fitted linear model: crossover {:.1} Hz, \
         PM {:.1}°, GM {:.1} dB, modulus margin {:.2}",
        s.kp,
        mg.gain_crossover_rad_s / TAU,
        mg.phase_margin_deg,
        20.0 * mg.gain_margin.log10(),
        mg.modulus_margin
    );
    let profiles = [
        ("1 µm/s", Velocity::Constant(1e-6), 300.0),
        ("10 µm/s", Velocity::Constant(1e-5), 60.0),
        ("0.1 mm/s", Velocity::Constant(1e-4), 20.0),
        ("1 mm/s", Velocity::Constant(1e-3), 20.0),
        (
            "10 µm/s·(1 + 0.5 sin 0.2πt)",
            Velocity::Sinusoidal {
                v0: 1e-5,
                a: 0.5,
                f_hz: 0.1,
            },
            100.0,
        ),
    ];
    // Nominal step per α cycle of the nonlinear stage (open loop, at the nominal
    // drive frequency of each profile, starting from c of the linear model).
    let steps: Vec<f64> = profiles
        .iter()
        .map(|(_, v, _)| {
            let (a, b) = v.range();
            let f = 0.5 * (a + b) / s.c_m_per_cycle;
            step_per_cycle(f, 8)
        })
        .collect();
    let comp = 56;
    let spread = profiles
        .iter()
        .zip(&steps)
        .map(|((_, v, _), &st)| {
            let (_, _, m, mm) = delay_range(st, *v, comp, MARGIN);
            mm - m
        })
        .max()
        .unwrap();
    let (q, fc) = q_for(&s, spread);
    println!("Q: 101 taps, cut-off {fc:.1} Hz, designed for M − m = {spread}");
    println!(
        "| reference | step/cycle (µm) | duration (s) | N (RC) | [m, M] | none (nm) | RC (nm) | high-order RC (nm) | DVRC (nm) | N_k seen by DVRC |"
    );
    println!("|---|---|---|---|---|---|---|---|---|---|");
    for ((name, v, dur), &st) in profiles.iter().zip(&steps) {
        let (_, n, m, mm) = delay_range(st, *v, comp, MARGIN);
        let r: Vec<Outcome> = [Rc::None, Rc::Standard, Rc::HighOrder, Rc::Dvrc]
            .iter()
            .map(|&w| run(&s, &q, st, MARGIN, *v, w, *dur))
            .collect();
        let nc: u64 = r.iter().map(|o| o.nonconverged).sum();
        println!(
            "| {name} | {:.3} | {dur} | {} | [{m}, {mm}] | {:.3} | {:.3} | {:.3} | {:.3} | {:?} |{}",
            st * 1e6,
            n.round(),
            r[0].rms * 1e9,
            r[1].rms * 1e9,
            r[2].rms * 1e9,
            r[3].rms * 1e9,
            r[3].seen,
            if nc > 0 {
                format!(" ({nc} non-converged sub-steps)")
            } else {
                String::new()
            }
        );
    }
    println!("{}", criterion_text(&s, &q, comp, comp + spread));
    // Sensitivity (not part of Table 5.1): lower nominal μ (same relative
    // variation) to look for irregular stepping at 10 µm/s, same Q and L.
    println!(
        "\n| μ (10 µm/s) | step/cycle (µm) | N (RC) | none (nm) | RC (nm) | DVRC (nm) | N_k seen by DVRC |"
    );
    println!("|---|---|---|---|---|---|---|");
    for mu in [0.2, 0.05, 0.02, 0.01, 0.005] {
        let p = walking_piezo::StageParams {
            mu,
            ..stage_params()
        };
        let v = Velocity::Constant(1e-5);
        let st = step_per_cycle_on(&p, 1e-5 / s.c_m_per_cycle, 8);
        let (_, n, _, _) = delay_range(st, v, comp, MARGIN);
        let r: Vec<Outcome> = [Rc::None, Rc::Standard, Rc::Dvrc]
            .iter()
            .map(|&w| run_on(&p, &s, &q, st, MARGIN, v, w, 60.0))
            .collect();
        println!(
            "| {mu} | {:.3} | {} | {:.3} | {:.3} | {:.3} | {:?} |",
            st * 1e6,
            n.round(),
            r[0].rms * 1e9,
            r[1].rms * 1e9,
            r[2].rms * 1e9,
            r[2].seen
        );
    }
    // The same Q and L against T with c = the nonlinear stage's step per cycle:
    // the fixed-N criterion (5.5) (m = M) as seen by the loop that actually runs.
    let t_nl = t_with_gain(&s, steps[1]);
    let c = dvrc::stability::rc_criterion(&t_nl, &s.l, &q, 2808, 2808).unwrap();
    println!(
        "with c = {:.3} µm/cycle: ‖Q(1 − T L z^l)‖∞ = {:.4} at {:.1} Hz (standard RC needs < 1; \
         the high-order W = 2 − z^-N has Σ|w_i| = 3, so the small-gain test needs < 1/3 = 0.333)",
        steps[1] * 1e6,
        c.hinf,
        c.peak_hz
    );
}
