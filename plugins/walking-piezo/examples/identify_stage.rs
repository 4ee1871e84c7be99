//! Identification of the Ch. 4 model from simulated stage data (sinusoidal
//! waveforms at 20 Hz; Table 4.2 itself, nine waveforms at 10 Hz, is
//! `--example table_4_2`):
//! "measured" records come from a stage with hidden, unequal per-stack
//! coefficients and a seeded, varying friction; the y-parameters are identified
//! first from the housing signal, then the x-parameters from the stage position
//! (4.20); validation on waveforms not used for identification.
//!
//! `cargo run --release -p nanomotion-walking-piezo --example identify_stage`

use walking_piezo::SinusoidalWaveform;
use walking_piezo::identify::*;
use walking_piezo::stage::StageParams;

fn main() {
    let truth = StageParams {
        c_x_m_v: [66.0e-9, 63.0e-9, 60.0e-9, 58.0e-9],
        c_y_m_v: [31.0e-9, 29.0e-9, 28.5e-9, 27.5e-9],
        mu: 0.25,
        ..StageParams::default()
    };
    let proto = Protocol {
        settle_periods: 1,
        periods: 3,
        dt: 50e-6,
    };
    let wave = |a: f64, phi: f64| SinusoidalWaveform {
        f_alpha_hz: 20.0,
        amplitude_v: a,
        phase_rad: phi,
        alpha0_rad: 0.0,
    };
    let id_waves = [wave(46.0, 0.0), wave(46.0, -0.4), wave(36.0, 0.2)];
    let val_waves = [wave(40.0, -0.2), wave(46.0, 0.35)];
    let rec = |w: &SinusoidalWaveform| simulate_record(&truth, w, &proto, 11).unwrap();
    let id_records: Vec<Record> = id_waves.iter().map(rec).collect();
    let val_records: Vec<Record> = val_waves.iter().map(rec).collect();
    let base = StageParams::default();
    let settings = OptimiserSettings::default();
    let t0 = std::time::Instant::now();
    let ys: Vec<(IdParam, f64, f64)> = (0..4).map(|i| (IdParam::Cy(i), 20e-9, 40e-9)).collect();
    let stage_y = identify(&base, &ys, &id_records, &proto, Channels::Y, &settings).unwrap();
    let mut xs: Vec<(IdParam, f64, f64)> = (0..4).map(|i| (IdParam::Cx(i), 45e-9, 85e-9)).collect();
    xs.push((IdParam::Mu, 0.05, 0.6));
    let stage_x = identify(
        &stage_y.params,
        &xs,
        &id_records,
        &proto,
        Channels::X,
        &settings,
    )
    .unwrap();
    let p = stage_x.params.clone();
    println!(
        "identified in {:.1} s ({} + {} evaluations)",
        t0.elapsed().as_secs_f64(),
        stage_y.evaluations,
        stage_x.evaluations
    );
    println!("{:>6} {:>10} {:>10}", "param", "truth", "identified");
    for i in 0..4 {
        println!(
            "{:>6} {:>10.2} {:>10.2}",
            format!("c_x{}", i + 1),
            truth.c_x_m_v[i] * 1e9,
            p.c_x_m_v[i] * 1e9
        );
    }
    for i in 0..4 {
        println!(
            "{:>6} {:>10.2} {:>10.2}",
            format!("c_y{}", i + 1),
            truth.c_y_m_v[i] * 1e9,
            p.c_y_m_v[i] * 1e9
        );
    }
    println!("{:>6} {:>10.3} {:>10.3}", "mu", truth.mu, p.mu);
    println!("\nTable 4.2 style (20 Hz): rms model error per waveform");
    println!(
        "{:>14} {:>12} {:>12} {:>12} {:>12}",
        "waveform", "stroke x um", "rms e_x um", "stroke y um", "rms e_y um"
    );
    let nominal = base.clone().without_mu_variation();
    for (kind, recs) in [("ident", &id_records), ("valid", &val_records)] {
        for r in recs.iter() {
            let m =
                simulate_record(&p.clone().without_mu_variation(), &r.waveform, &proto, 0).unwrap();
            let n = simulate_record(&nominal, &r.waveform, &proto, 0).unwrap();
            let rms = |a: &[f64], b: &[f64]| {
                (a.iter().zip(b).map(|(u, v)| (u - v).powi(2)).sum::<f64>() / a.len() as f64).sqrt()
            };
            let stroke = |a: &[f64]| {
                a.iter().cloned().fold(f64::MIN, f64::max)
                    - a.iter().cloned().fold(f64::MAX, f64::min)
            };
            println!(
                "{:>5} A={:>2} φ={:>5.2} {:>10.3} {:>12.4} {:>12.4} {:>12.4}  (nominal model: e_x {:.4})",
                kind,
                r.waveform.amplitude_v,
                r.waveform.phase_rad,
                stroke(&r.x) * 1e6,
                rms(&r.x, &m.x) * 1e6,
                stroke(&r.y) * 1e6,
                rms(&r.y, &m.y) * 1e6,
                rms(&r.x, &n.x) * 1e6
            );
        }
    }
}
