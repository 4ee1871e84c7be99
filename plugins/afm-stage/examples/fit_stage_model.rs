//! Identify the extended model (6.4) on the default simulated stage's x hysteresis
//! (Sec. 6.3.2) and print it as YAML for `hysteresis_feedforward`, together with
//! the decentralised controller gains (6.5) for a 6 dB modulus margin.
//!
//! `cargo run -p nanomotion-afm-stage --example fit_stage_model`

use afm_stage::control::{log_grid, tune_for_modulus_margin};
use afm_stage::hysteresis::{ColemanHodgdon, Direction};
use afm_stage::ident::{THESIS_RANGES_V, fit_extended, measure_loops};
use afm_stage::stage::AfmStage;
use nanomotion_core::lti::Complex;
use std::f64::consts::TAU;

fn main() {
    let stage = AfmStage::default();
    let hx = ColemanHodgdon::new(stage.hysteresis[0].trace, stage.hysteresis[0].retrace).unwrap();
    let (tr, re) = measure_loops(&hx, 50.0, &THESIS_RANGES_V, 61, 0.002, 3).unwrap();
    let (m, rt, rr) = fit_extended(&tr, &re).unwrap();
    println!(
        "# accuracy: trace {:.2} %, retrace {:.2} %",
        rt.accuracy_percent, rr.accuracy_percent
    );
    for (name, b) in [("trace", m.trace), ("retrace", m.retrace)] {
        let a = b.to_array();
        let fields: Vec<String> = afm_stage::ExtendedBranch::NAMES
            .iter()
            .zip(a)
            .map(|(n, v)| format!("{n}: {v:.6e}"))
            .collect();
        println!("    {name}: {{{}}}", fields.join(", "));
    }
    let lp = hx.steady_loop(30.0, 70.0).unwrap();
    println!(
        "# loop centre (µm): {}",
        0.5 * (lp.eval(30.0, Direction::Trace) + lp.eval(70.0, Direction::Trace))
    );
    let g = [0, 1, 2].map(|i| 0.5 * (stage.hysteresis[i].trace.b + stage.hysteresis[i].trace.c));
    let p = stage.small_signal_model(g).unwrap();
    let f = log_grid(0.1, 2000.0, 1500);
    for i in 0..3 {
        let pi: Vec<Complex<f64>> = f
            .iter()
            .map(|&ff| p.evalfr(Complex::new(0.0, TAU * ff))[(i, i)])
            .collect();
        let c = tune_for_modulus_margin(&f, &pi, 60.0, 6.0);
        println!("# axis {i}: k = {:.6e} V/(m s), f_LP = 60 Hz", c.k);
    }
}
