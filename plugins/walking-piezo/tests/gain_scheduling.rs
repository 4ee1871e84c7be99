//! Gain variation identified on the simulated nonlinear stage with the core
//! closed-loop FRF tools, and the fitted schedule (2.13) (Sec. 2.5.1).

use gain_scheduling::{GainLaw, fit_power_db};
use std::f64::consts::FRAC_PI_2;
use walking_piezo::gain_id::{
    GainIdConfig, gain_variation_db, identify_operating_point, open_loop_step_per_cycle,
};

#[test]
fn amplitude_gain_variation_is_identified_and_fitted() {
    let cfg = GainIdConfig::default();
    let amps = [46.0, 38.0, 30.0, 23.0];
    let pts: Vec<_> = amps
        .iter()
        .map(|&a| identify_operating_point(&cfg, a, FRAC_PI_2).unwrap())
        .collect();
    for p in &pts {
        assert!(p.coherence > 0.4, "{p:?}");
    }
    let k_db = gain_variation_db(&pts);
    assert_eq!(k_db[0], 0.0);
    // Smaller amplitude, smaller step: the controller gain must rise monotonically.
    assert!(k_db.windows(2).all(|w| w[1] > w[0]), "{k_db:?}");
    // The FRF-identified variation matches the open-loop step ratio (an independent
    // measurement on the same stage) within 1.5 dB.
    let c46 = open_loop_step_per_cycle(&cfg, 46.0, FRAC_PI_2, 10.0, 8).unwrap();
    let c23 = open_loop_step_per_cycle(&cfg, 23.0, FRAC_PI_2, 10.0, 8).unwrap();
    let k_ol = 20.0 * (c46 / c23).log10();
    assert!((k_db[3] - k_ol).abs() < 1.5, "{k_db:?} vs open loop {k_ol}");
    // The first-order power series on a dB scale passes through the points
    // (4 points, 3 parameters) and gives 0 dB at the nominal amplitude.
    let (law, rms) = fit_power_db(&amps, &k_db).unwrap();
    assert!(rms < 0.5, "{law:?} rms {rms}");
    assert!(matches!(law, GainLaw::PowerDb { .. }));
    assert!(law.gain(46.0) > 10f64.powf(-0.5 / 20.0) && law.gain(46.0) < 10f64.powf(0.5 / 20.0));
    assert!(law.gain(23.0) > law.gain(46.0));
}
