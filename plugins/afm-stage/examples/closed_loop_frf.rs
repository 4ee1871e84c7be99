//! Closed-loop MIMO FRF identification of the simulated stage (Sec. 6.2 with the
//! decentralised controllers of Sec. 6.4 in the loop): white noise injected at all
//! three plant inputs, G = GS·S⁻¹, next to the naive H1 estimate from the plant
//! inputs, which closed-loop data biases towards −1/C.
//!
//! `cargo run --release -p nanomotion-afm-stage --example closed_loop_frf`

use afm_stage::experiments::{
    ClosedLoopIdentSetup, closed_loop_identification, decentralised_controllers, design_gains,
    linearised, naive_closed_loop_estimate,
};
use afm_stage::stage::AfmStage;
use nanomotion_core::lti::{C2dMethod, Complex};
use std::f64::consts::TAU;

const SHOW_HZ: [f64; 9] = [0.6, 1.2, 2.0, 5.0, 10.0, 20.0, 50.0, 124.0, 250.0];

fn report(title: &str, stage: &AfmStage, gains: [f64; 3], noise_std_v: f64) {
    let fs = 5000.0;
    let (c, p) = decentralised_controllers(stage, gains, 60.0).unwrap();
    let setup = ClosedLoopIdentSetup {
        v0: [50.0; 3],
        noise_std_v,
        controllers: c,
        fs_hz: fs,
        n_samples: 1 << 20,
        segment_len: 1 << 14,
        seed: 11,
    };
    let id = closed_loop_identification(stage, &setup).unwrap();
    let pd = p.c2d(1.0 / fs, C2dMethod::Zoh).unwrap();
    let cx = c[0].continuous().c2d(1.0 / fs, C2dMethod::TUSTIN).unwrap();
    println!(
        "\n{title}: σ_w = {noise_std_v} V, {} samples at {fs} Hz, Welch {} (Δf = {:.3} Hz); sensor noise σ_n = {:.2} nm (x); magnitudes in µm/V\n",
        setup.n_samples,
        setup.segment_len,
        fs / setup.segment_len as f64,
        id.sensor_noise_var_m2[0].sqrt() * 1e9
    );
    println!(
        "| f (Hz) | P_xx model | closed loop G = GS·S⁻¹ | naive H1 | naive, closed form | γ²(w→u) | γ²(w→y) | P_yx model | P_yx closed loop |"
    );
    println!("|---|---|---|---|---|---|---|---|---|");
    for f0 in SHOW_HZ {
        let k = id
            .freq_hz
            .iter()
            .enumerate()
            .min_by(|a, b| (a.1 - f0).abs().total_cmp(&(b.1 - f0).abs()))
            .unwrap()
            .0;
        let f = id.freq_hz[k];
        let z = Complex::from_polar(1.0, TAU * f / fs);
        let g = pd.evalfr(z);
        let want = naive_closed_loop_estimate(
            g[(0, 0)],
            cx.evalfr(z)[(0, 0)],
            id.sensor_noise_var_m2[0] / noise_std_v.powi(2),
        );
        println!(
            "| {f:.2} | {:.4} | {:.4} | {:.4} | {:.4} | {:.2} | {:.2} | {:.5} | {:.5} |",
            g[(0, 0)].norm() * 1e6,
            id.closed_loop[k][(0, 0)].norm() * 1e6,
            id.naive[k][(0, 0)].norm() * 1e6,
            want.norm() * 1e6,
            id.coherence_u[0][k],
            id.coherence_y[0][k],
            g[(1, 0)].norm() * 1e6,
            id.closed_loop[k][(1, 0)].norm() * 1e6,
        );
    }
}

fn main() {
    // The stage with its hysteresis replaced by a pure gain (u = b): the linear
    // model is then exact.
    let gains = [0.85, 0.84, 0.17];
    let lin = linearised(&AfmStage::default(), gains);
    report("linearised stage (hysteresis = gain b)", &lin, gains, 0.05);
    report("linearised stage (hysteresis = gain b)", &lin, gains, 0.5);
    // The default stage: the hysteresis makes the small-signal gain depend on the
    // excitation amplitude; the model column uses the design gain (b + u)/2.
    let stage = AfmStage::default();
    report(
        "default stage with hysteresis (model column: design gain (b+u)/2)",
        &stage,
        design_gains(&stage),
        0.5,
    );
}
