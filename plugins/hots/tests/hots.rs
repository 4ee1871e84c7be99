//! HOTS: error model against brute-force simulation, slit calibration on hidden
//! errors and on the real US Digital E2 profile, the block.

use hots::model::{ErrorModel, Grid, Settings, Target, expected_ms, optimise, sinusoid_samples};
use hots::sim::simulate;
use hots::{HotsEstimator, SlitCalibration};
use nanomotion_core::rng::Rng;
use nanomotion_core::{Block, BuildContext, Tick};
use std::f64::consts::{FRAC_PI_2, TAU};
use timestamp_encoder::TimestampEncoder;

fn sine(t: f64) -> [f64; 3] {
    let (a, w) = (FRAC_PI_2, TAU);
    [
        a * (w * t).sin(),
        a * w * (w * t).cos(),
        -a * w * w * (w * t).sin(),
    ]
}

/// The real per-slit profile (counts), or None with a loud message.
pub fn real_profile() -> Option<Vec<f64>> {
    let path = concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../../../shared/data/usdigital_e2_slit_errors/us_digital_e2_100cpr_tick_errors.csv"
    );
    let path = nanomotion_core::data::shared_data_or_skip(
        std::path::Path::new(path),
        "hots (real US Digital E2 slit-error profile)",
    )?;
    let text = std::fs::read_to_string(path).ok()?;
    let mut v = Vec::new();
    for line in text.lines().skip(1) {
        let cols: Vec<&str> = line.split(',').collect();
        // angle_error_rev × 400 counts/rev.
        v.push(
            cols[2]
                .trim()
                .parse::<f64>()
                .expect("numeric angle_error_rev")
                * 400.0,
        );
    }
    assert_eq!(v.len(), 100, "one value per slit of the 100-CPR encoder");
    Some(v)
}

fn random_edges(std: f64, seed: u64) -> Vec<f64> {
    let mut r = Rng::new(seed);
    (0..400).map(|_| std * r.normal()).collect()
}

#[test]
fn model_agrees_with_brute_force_simulation() {
    let edges = random_edges(0.03, 11);
    let model = ErrorModel::from_edge_errors(&edges, 20e6);
    let samples = sinusoid_samples(100.0, 1.0, 1000);
    let grid = Grid {
        orders: vec![1, 2, 3],
        register_lens: vec![4, 5, 8],
        skips: vec![0, 1, 2, 3, 5, 10, 20],
    };
    let mut rows = Vec::new();
    for &m in &grid.orders {
        for &n in &grid.register_lens {
            for &skip in &grid.skips {
                let s = Settings {
                    order: m,
                    register_len: n,
                    skip,
                };
                let Some(pred) = expected_ms(s, Target::Velocity, &model, &samples) else {
                    continue;
                };
                let enc = TimestampEncoder {
                    skip: skip as i64,
                    register_len: n,
                    slit_errors_counts: edges.clone(),
                    ..Default::default()
                };
                let run = simulate(&enc, m, &[], 1e3, 2.0, 0, false, sine).unwrap();
                // rad/s → counts/s.
                let sim = run.errors(0.1).v * 400.0 / TAU;
                rows.push((s, pred.sqrt(), sim));
            }
        }
    }
    let best_sim = rows.iter().map(|r| r.2).fold(f64::INFINITY, f64::min);
    let ranked = optimise(&grid, Target::Velocity, &model, &samples);
    let chosen = ranked[0].0;
    let chosen_sim = rows.iter().find(|r| r.0 == chosen).unwrap().2;
    let mut within = 0;
    for (s, p, q) in &rows {
        eprintln!(
            "m {} n {} σ {:2}: model {:8.3} sim {:8.3} counts/s",
            s.order, s.register_len, s.skip, p, q
        );
        if (0.5..2.0).contains(&(p / q)) {
            within += 1;
        }
    }
    eprintln!(
        "chosen {chosen:?}: sim {chosen_sim:.3}, brute-force best {best_sim:.3}; {within}/{} within ×2",
        rows.len()
    );
    assert!(
        chosen_sim <= 1.25 * best_sim,
        "the model's choice is near the brute-force optimum"
    );
    assert!(within * 10 >= rows.len() * 7, "{within}/{}", rows.len());
}

#[test]
fn calibration_recovers_hidden_slit_errors() {
    // Hidden: per-slit spacing (seeded), quadrature and eccentricity errors.
    let enc = TimestampEncoder {
        slit_error_std_counts: 0.04,
        quadrature_error_counts: 0.02,
        eccentricity_counts: 0.03,
        eccentricity_phase_rad: 0.7,
        register_len: 16,
        ..Default::default()
    };
    let seed = 99;
    let truth = {
        let mut e = enc.clone();
        e.prepare(seed).unwrap();
        let v = e.edge_errors_counts().to_vec();
        let mean = v.iter().sum::<f64>() / v.len() as f64;
        v.iter().map(|x| x - mean).collect::<Vec<_>>()
    };
    // Calibration run: ~2 rev/s with a slow speed ripple, 20 revolutions.
    let w = 4.0 * std::f64::consts::PI;
    let cal_traj = |t: f64| {
        let p = TAU * 0.2;
        [
            w * t + 0.05 * (p * t).sin(),
            w + 0.05 * p * (p * t).cos(),
            -0.05 * p * p * (p * t).sin(),
        ]
    };
    let cal_run = simulate(&enc, 2, &[], 1e3, 10.0, seed, true, cal_traj).unwrap();
    let (t, l): (Vec<f64>, Vec<f64>) = cal_run.events.iter().copied().unzip();
    let cal = SlitCalibration::learn(&t, &l, 400, 4, 800).unwrap();
    let rms = |v: &[f64]| (v.iter().map(|x| x * x).sum::<f64>() / v.len() as f64).sqrt();
    let diff: Vec<f64> = cal
        .edge_offsets_counts
        .iter()
        .zip(&truth)
        .map(|(a, b)| a - b)
        .collect();
    eprintln!(
        "edge errors rms {:.4}, calibration error rms {:.5}, fit residual {:.5} counts",
        rms(&truth),
        rms(&diff),
        cal.residual_rms_counts
    );
    assert!(rms(&diff) < 0.05 * rms(&truth));
    // Validation on data not used for calibration: the Sec. 8.5 sinusoid.
    let mut enc5 = enc.clone();
    enc5.register_len = 5;
    let val = simulate(&enc5, 2, &[], 1e3, 2.0, seed, true, sine).unwrap();
    let d = TAU / 400.0;
    let (mut raw, mut corr) = (Vec::new(), Vec::new());
    for &(tk, lk) in &val.events {
        let x = sine(tk)[0] / d;
        raw.push(lk - x);
        corr.push(cal.correct(lk) - x);
    }
    // A common offset of all edges is unobservable (and harmless for v, a): compare
    // the residuals about their means.
    let centred = |v: &[f64]| {
        let m = v.iter().sum::<f64>() / v.len() as f64;
        rms(&v.iter().map(|x| x - m).collect::<Vec<_>>())
    };
    eprintln!(
        "validation event residual (about its mean): raw {:.4}, calibrated {:.5} counts",
        centred(&raw),
        centred(&corr)
    );
    assert!(centred(&corr) < 0.01 * centred(&raw));
    // Estimation errors on a motion without reversals (at the sinusoid's reversals
    // the turnaround fallback dominates both): x = 2t + 0.1 sin(2πt) rad, speed 1.4 to 2.6 rad/s.
    let wobble = |t: f64| {
        [
            2.0 * t + 0.1 * (TAU * t).sin(),
            2.0 + 0.1 * TAU * (TAU * t).cos(),
            -0.1 * TAU * TAU * (TAU * t).sin(),
        ]
    };
    let plain = simulate(&enc5, 2, &[], 1e3, 2.0, seed, false, wobble)
        .unwrap()
        .errors(0.1);
    let calibrated = simulate(
        &enc5,
        2,
        &cal.edge_offsets_counts,
        1e3,
        2.0,
        seed,
        false,
        wobble,
    )
    .unwrap()
    .errors(0.1);
    eprintln!(
        "velocity rms: plain {:.4}, calibrated {:.4} rad/s; acceleration {:.2} -> {:.2}",
        plain.v, calibrated.v, plain.a, calibrated.a
    );
    assert!(calibrated.v < 0.2 * plain.v && calibrated.a < 0.2 * plain.a);
    // Stored and restored.
    let json = serde_json::to_string(&cal).unwrap();
    let back: SlitCalibration = serde_json::from_str(&json).unwrap();
    assert_eq!(back.events, cal.events);
    assert!(
        back.edge_offsets_counts
            .iter()
            .zip(&cal.edge_offsets_counts)
            .all(|(a, b)| (a - b).abs() < 1e-15)
    );
}

#[test]
fn calibration_on_the_real_usdigital_e2_profile() {
    let Some(profile) = real_profile() else {
        return;
    };
    let enc = TimestampEncoder {
        slit_errors_counts: profile.clone(),
        register_len: 16,
        ..Default::default()
    };
    let w = 4.0 * std::f64::consts::PI;
    let run = simulate(&enc, 2, &[], 1e3, 10.0, 0, true, |t| [w * t, w, 0.0]).unwrap();
    let (t, l): (Vec<f64>, Vec<f64>) = run.events.iter().copied().unzip();
    let cal = SlitCalibration::learn(&t, &l, 400, 2, 800).unwrap();
    let mean = profile.iter().sum::<f64>() / 100.0;
    let rms = |v: &[f64]| (v.iter().map(|x| x * x).sum::<f64>() / v.len() as f64).sqrt();
    let truth: Vec<f64> = (0..400).map(|l| profile[l / 4] - mean).collect();
    let diff: Vec<f64> = cal
        .edge_offsets_counts
        .iter()
        .zip(&truth)
        .map(|(a, b)| a - b)
        .collect();
    eprintln!(
        "US Digital E2: profile rms {:.4} counts, calibration error rms {:.5}",
        rms(&truth),
        rms(&diff)
    );
    assert!(rms(&diff) < 0.05 * rms(&truth));
    let mut enc5 = enc.clone();
    enc5.register_len = 5;
    let wobble = |t: f64| {
        [
            2.0 * t + 0.1 * (TAU * t).sin(),
            2.0 + 0.1 * TAU * (TAU * t).cos(),
            -0.1 * TAU * TAU * (TAU * t).sin(),
        ]
    };
    let plain = simulate(&enc5, 2, &[], 1e3, 2.0, 0, false, wobble)
        .unwrap()
        .errors(0.1);
    let cald = simulate(
        &enc5,
        2,
        &cal.edge_offsets_counts,
        1e3,
        2.0,
        0,
        false,
        wobble,
    )
    .unwrap()
    .errors(0.1);
    eprintln!(
        "US Digital E2 velocity rms: plain {:.4}, calibrated {:.4} rad/s; acceleration {:.2} -> {:.2}",
        plain.v, cald.v, plain.a, cald.a
    );
    assert!(cald.v < 0.2 * plain.v && cald.a < 0.5 * plain.a);
}

#[test]
fn hots_block_loads_a_calibration_and_does_not_allocate() {
    let cal = SlitCalibration {
        edge_offsets_counts: vec![0.01; 400],
        residual_rms_counts: 0.0,
        events: 0,
    };
    let path = std::env::temp_dir().join(format!("hots_cal_{}.json", std::process::id()));
    std::fs::write(&path, serde_json::to_string(&cal).unwrap()).unwrap();
    let text = format!(
        "type: hots_estimator\nresolution: 0.015707963267948967\ncalibration_file: \"{}\"\n",
        path.display()
    );
    let mut est: Box<dyn Block> = nanomotion_core::yaml::from_str(&text, "t").unwrap();
    est.build(&BuildContext::new("hots", 1e-3, 0)).unwrap();
    let mut enc = TimestampEncoder::default();
    enc.prepare(0).unwrap();
    let mut reg = vec![0.0; 12];
    let mut y = [0.0; 4];
    let info = allocation_counter::measure(|| {
        for k in 0..10_000u64 {
            let tick = Tick::new(k, 1e-3);
            let tr = sine(tick.t);
            enc.advance(tick.t, &tr[..2]);
            enc.read_register(&mut reg);
            est.output(tick, &reg, &mut y);
        }
    });
    assert_eq!(info.count_total, 0);
    assert!(y.iter().all(|v| v.is_finite()));
    std::fs::remove_file(&path).ok();
    let err = |text: &str| {
        let mut b: Box<dyn Block> = nanomotion_core::yaml::from_str(text, "t").unwrap();
        b.build(&BuildContext::new("b", 1e-3, 0)).unwrap_err().field
    };
    assert_eq!(
        err("type: hots_estimator\nresolution: 1\ncalibration_file: /nonexistent/cal.json\n"),
        "calibration_file"
    );
    assert_eq!(
        err("type: hots_estimator\nresolution: 1\norder: 3\nregister_len: 3\n"),
        "register_len"
    );
    let cal2 = HotsEstimator::new(2, 5, 1.0, &cal).unwrap();
    assert_eq!(cal2.edge_offsets_counts.len(), 400);
}
