//! Ch. 3 leg model: Table 3.2 (static gain and first resonance of H_x,u1 against
//! the number of layers n_m) and the FRF H_ru(jω) (3.15) of the n_m = 6 model
//! (Fig. 3.8), about the thesis's equilibrium u1 = 2.2 V, u2 = 44.2 V.
//!
//! `cargo run -p nanomotion-walking-piezo --example ch3_frf`

use nalgebra::Complex;
use std::f64::consts::PI;
use walking_piezo::leg_model::{LegModel, LegModelParams};

fn db(x: f64) -> f64 {
    20.0 * x.abs().log10()
}

fn main() {
    let (u1, u2) = (2.2, 44.2);
    println!("Table 3.2 — H_x,u1 about u = ({u1}, {u2}) V");
    println!(
        "{:>4} {:>16} {:>12} {:>12} {:>14}",
        "n_m", "|H_x,u1(0)| dB", "(nm/V)", "c_y (nm/V)", "f_res (kHz)"
    );
    for n_m in [2, 4, 6, 8, 10] {
        let leg = LegModel::new(LegModelParams {
            n_m,
            ..Default::default()
        })
        .expect("valid parameters");
        let g = leg.static_gain(u1, u2);
        println!(
            "{:>4} {:>16.2} {:>12.2} {:>12.2} {:>14.1}",
            n_m,
            db(g[(0, 0)] * 1e9),
            g[(0, 0)] * 1e9,
            g[(1, 0)] * 1e9,
            leg.first_resonance_hz(u1, u2) / 1e3
        );
    }
    let leg = LegModel::new(LegModelParams::default()).expect("valid parameters");
    let (cx, cy) = leg.static_coefficients();
    println!(
        "\nStatic linearisation (3.28)-(3.29), n_m = 6: c_x = {:.2} nm/V, c_y = {:.2} nm/V",
        cx * 1e9,
        cy * 1e9
    );
    let ss = leg.linearize(u1, u2);
    println!("\nFRF H_ru(jω) (3.15), n_m = 6, magnitudes in dB re 1 nm/V");
    println!(
        "{:>10} {:>10} {:>10} {:>10} {:>10}",
        "f (kHz)", "x<-u1", "x<-u2", "y<-u1", "y<-u2"
    );
    for k in 0..=24 {
        let f = 1e3 * 10f64.powf(k as f64 / 8.0);
        let h = ss.evalfr(Complex::new(0.0, 2.0 * PI * f));
        println!(
            "{:>10.1} {:>10.2} {:>10.2} {:>10.2} {:>10.2}",
            f / 1e3,
            db(h[(0, 0)].norm() * 1e9),
            db(h[(0, 1)].norm() * 1e9),
            db(h[(1, 0)].norm() * 1e9),
            db(h[(1, 1)].norm() * 1e9)
        );
    }
}
