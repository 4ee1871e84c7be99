//! Identification (4.20) recovers hidden per-stack coefficients from simulated
//! stage data with a seeded, varying friction, and the identified model predicts
//! waveforms not used for identification.

use walking_piezo::SinusoidalWaveform;
use walking_piezo::identify::*;
use walking_piezo::stage::StageParams;

fn rms(a: &[f64], b: &[f64]) -> f64 {
    (a.iter().zip(b).map(|(u, v)| (u - v).powi(2)).sum::<f64>() / a.len() as f64).sqrt()
}

#[test]
fn two_stage_identification_recovers_the_legs_and_validates() {
    let truth = StageParams {
        c_x_m_v: [66.0e-9, 63.0e-9, 60.0e-9, 58.0e-9],
        c_y_m_v: [31.0e-9, 29.0e-9, 28.5e-9, 27.5e-9],
        mu: 0.25,
        ..StageParams::default()
    };
    let proto = Protocol {
        settle_periods: 1,
        periods: 2,
        dt: 50e-6,
    };
    let wave = |a: f64, phi: f64| SinusoidalWaveform {
        f_alpha_hz: 20.0,
        amplitude_v: a,
        phase_rad: phi,
        alpha0_rad: 0.0,
    };
    let rec = |w: SinusoidalWaveform| simulate_record(&truth, &w, &proto, 11).unwrap();
    let id_records = vec![
        rec(wave(46.0, 0.0)),
        rec(wave(46.0, -0.4)),
        rec(wave(36.0, 0.2)),
    ];
    let val = rec(wave(40.0, -0.2));

    let base = StageParams::default();
    let settings = OptimiserSettings {
        particles: 12,
        swarm_iterations: 12,
        local_evaluations: 120,
        seed: 1,
    };
    // Stage 1: y (housing) — c_y only; stage 2: x (stage) — c_x and μ.
    let ys: Vec<(IdParam, f64, f64)> = (0..4).map(|i| (IdParam::Cy(i), 20e-9, 40e-9)).collect();
    let sy = identify(&base, &ys, &id_records, &proto, Channels::Y, &settings).unwrap();
    let mut xs: Vec<(IdParam, f64, f64)> = (0..4).map(|i| (IdParam::Cx(i), 45e-9, 85e-9)).collect();
    xs.push((IdParam::Mu, 0.05, 0.6));
    let sx = identify(&sy.params, &xs, &id_records, &proto, Channels::X, &settings).unwrap();
    assert!(sx.cost <= sx.cost_global);
    let p = sx.params;
    for i in 0..4 {
        assert!(
            (p.c_x_m_v[i] - truth.c_x_m_v[i]).abs() < 0.01 * truth.c_x_m_v[i],
            "c_x{i}: {:?}",
            p.c_x_m_v
        );
        assert!(
            (p.c_y_m_v[i] - truth.c_y_m_v[i]).abs() < 0.01 * truth.c_y_m_v[i],
            "c_y{i}: {:?}",
            p.c_y_m_v
        );
    }
    // Validation on an unseen waveform: the identified model is far closer to the
    // data than the nominal (equal-coefficient) model.
    let m = simulate_record(&p.clone().without_mu_variation(), &val.waveform, &proto, 0).unwrap();
    let n = simulate_record(&base.without_mu_variation(), &val.waveform, &proto, 0).unwrap();
    let (e_id, e_nom) = (rms(&val.x, &m.x), rms(&val.x, &n.x));
    assert!(e_id < 0.1 * e_nom, "identified {e_id}, nominal {e_nom}");
    assert!(rms(&val.y, &m.y) < 0.1 * rms(&val.y, &n.y));
}

#[test]
fn bad_bounds_are_refused() {
    let proto = Protocol {
        settle_periods: 0,
        periods: 1,
        dt: 50e-6,
    };
    let e = identify(
        &StageParams::default(),
        &[(IdParam::Mu, 0.5, 0.1)],
        &[],
        &proto,
        Channels::X,
        &OptimiserSettings::default(),
    )
    .unwrap_err();
    assert_eq!(e.field, "bounds[0].lo");
}
