//! Ch. 3 leg model, every reproduction of `walking_piezo::thesis_ch3`: Table 3.2
//! (static gain and first resonance of H_x,u1 against the number of layers n_m),
//! the FRF H_ru(jω) (3.15) of the n_m = 6 model (Fig. 3.8), the variation over a
//! drive cycle (Fig. 3.9, waveforms (3.24)–(3.25)), the static map (3.26)–(3.29)
//! against the full dynamic Lagrange model driven by the waveforms (Figs.
//! 3.11–3.14), and the gap between (3.28)–(3.29) and Ch. 5's c_x, c_y.
//!
//! `cargo run -p nanomotion-walking-piezo --example ch3_frf [-- --quick]`
//! (`--quick`: the dynamic run at one drive frequency only, what `nanomotion
//! reproduce --quick` runs).

use walking_piezo::leg_model::{LegModel, LegModelParams};
use walking_piezo::thesis_ch3::*;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let quick = std::env::args().any(|a| a == "--quick");
    let (u1, u2) = TABLE_3_2_EQUILIBRIUM_V;
    println!("Table 3.2 — H_x,u1 about u = ({u1}, {u2}) V");
    println!(
        "{:>4} {:>16} {:>12} {:>12} {:>14}",
        "n_m", "|H_x,u1(0)| dB", "(nm/V)", "H_y,u1 nm/V", "f_res (kHz)"
    );
    for r in table_3_2()? {
        println!(
            "{:>4} {:>16.2} {:>12.2} {:>12.2} {:>14.1}",
            r.n_m, r.gain_x_u1_db, r.gain_x_u1_nm_v, r.gain_y_u1_nm_v, r.f_res_khz
        );
    }

    let leg = LegModel::new(LegModelParams::default())?;
    let freqs = log_grid(1e3, 1e6, 25);
    let frf = &fig_3_8(&freqs)?[2];
    println!(
        "\nFRF H_ru(jω) (3.15), {}, magnitudes in dB re 1 nm/V",
        frf.label
    );
    println!(
        "{:>10} {:>10} {:>10} {:>10} {:>10}",
        "f (kHz)", "x<-u1", "x<-u2", "y<-u1", "y<-u2"
    );
    for (k, f) in freqs.iter().enumerate() {
        println!(
            "{:>10.1} {:>10.2} {:>10.2} {:>10.2} {:>10.2}",
            f / 1e3,
            frf.db[0][k],
            frf.db[1][k],
            frf.db[2][k],
            frf.db[3][k]
        );
    }

    println!("\nFig. 3.9 — n_m = 6 over a drive cycle, α = 0, π/36, …, 2π");
    println!(
        "{:>18} {:>10} {:>10} {:>10} {:>10} {:>22}",
        "waveform", "Δ|Hxu1|", "Δ|Hxu2|", "Δ|Hyu1|", "Δ|Hyu2|", "f_res range (kHz)"
    );
    for wave in [Ch3Waveform::Sinusoidal, Ch3Waveform::Asymmetric] {
        let v = fig_3_9(wave)?;
        let pct = |x: f64| format!("{:.4} %", 100.0 * x);
        println!(
            "{:>18} {:>10} {:>10} {:>10} {:>10} {:>10.3} – {:>8.3}",
            wave.as_str(),
            pct(v.gain_spread[0]),
            pct(v.gain_spread[1]),
            pct(v.gain_spread[2]),
            pct(v.gain_spread[3]),
            v.f_res_range_khz.0,
            v.f_res_range_khz.1
        );
    }
    println!("(Δ = (max − min)/mean of the static gain over the cycle)");

    let (cx, cy) = leg.static_coefficients();
    println!(
        "\nStatic map (3.28)-(3.29), n_m = 6: c_x = {:.2} nm/V, c_y = {:.2} nm/V",
        cx * 1e9,
        cy * 1e9
    );
    println!("\nFigs. 3.11-3.14 — full Lagrange model vs the static map (minima aligned)");
    println!(
        "{:>18} {:>10} {:>11} {:>11} {:>11} {:>11} {:>9} {:>9} {:>13}",
        "waveform",
        "f (Hz)",
        "stroke x um",
        "stroke y um",
        "rms e_x nm",
        "rms e_y nm",
        "acc x",
        "acc y",
        "dyn dev x/y"
    );
    let dyn_freqs: &[f64] = if quick { &[5e3] } else { &[1e3, 5e3, 20e3] };
    for wave in [Ch3Waveform::Sinusoidal, Ch3Waveform::Asymmetric] {
        let qs = quasi_static_tip(wave, 1.0, 720)?;
        let line = |c: &TipComparison, dev: String| {
            println!(
                "{:>18} {:>10} {:>11.4} {:>11.4} {:>11.4} {:>11.4} {:>8.4}% {:>8.4}% {:>13}",
                c.waveform.as_str(),
                c.f_drive_hz,
                c.stroke.0 * 1e6,
                c.stroke.1 * 1e6,
                c.rms_error.0 * 1e9,
                c.rms_error.1 * 1e9,
                100.0 * c.accuracy.0,
                100.0 * c.accuracy.1,
                dev
            )
        };
        line(&qs, "quasi-static".into());
        for &f in dyn_freqs {
            let t0 = std::time::Instant::now();
            let (c, dev) = dynamic_tip(wave, f, 1e-7, 400)?;
            line(&c, format!("{:.2e}/{:.2e}", dev.0, dev.1));
            eprintln!(
                "  (dynamic run at {f} Hz: {:.1} s)",
                t0.elapsed().as_secs_f64()
            );
        }
    }
    println!("Linearised prediction of the dynamic deviation, Σ_k |(H(jkω) − H(0))U_k| (x, y):");
    for wave in [Ch3Waveform::Sinusoidal, Ch3Waveform::Asymmetric] {
        for f in [1.0, 10.0, 1e3, 5e3, 20e3] {
            let (px, py) = predicted_dynamic_deviation(wave, f)?;
            println!("  {:>18} f = {f:>7} Hz: {px:.2e} / {py:.2e}", wave.as_str());
        }
    }

    let g = coefficient_gap()?;
    println!("\n(3.28)-(3.29) vs Ch. 5 (5.29)");
    println!(
        "  ours c_x = {:.2}, c_y = {:.2} nm/V; Ch. 5: {:.1} / {:.1} nm/V; ours/Ch. 5 = {:.3} / {:.3}",
        g.c_x_nm_v, g.c_y_nm_v, g.ch5_nm_v.0, g.ch5_nm_v.1, g.ratio.0, g.ratio.1
    );
    println!(
        "  lumping: c_x with n_m = n_t = 96 layers = {:.2} nm/V (×{:.3})",
        g.c_x_n_t_layers_nm_v,
        g.c_x_n_t_layers_nm_v / g.c_x_nm_v
    );
    println!(
        "  material: c_y = n_t·d33/2·K_a/k, K_a/k = {:.4}; d33 = {:.0} pm/V gives ours, {:.0} pm/V would give Ch. 5's",
        g.preload_factor, g.d33_pm_v, g.d33_for_ch5_c_y_pm_v
    );
    println!(
        "  geometry: c_x/c_y = {:.3} (n_m = 6), {:.3} (n_m = 96), Ch. 5 {:.3}",
        g.ratio_x_over_y.0, g.ratio_x_over_y.1, g.ratio_x_over_y.2
    );
    Ok(())
}
