//! The thesis's design (Sec. 7.3.2) on a plant of the (7.1) structure, end to end
//! through the config: γ, order, verification, reduction bound, sampled loop,
//! decentralised comparison and the (7.4) test.

use nanomotion_mimo::config::{SynthConfig, run};

fn config() -> SynthConfig {
    let text = include_str!("../../../examples/mimo/afm_synth.yaml");
    SynthConfig::from_yaml(text, "afm_synth.yaml").unwrap()
}

#[test]
fn thesis_design_is_verified_reduced_and_compared() {
    let cfg = config();
    let r = run(&cfg).unwrap();
    let s = &r.synthesis;
    println!(
        "γ = {:.5} (infeasible {:.5}), ‖N‖∞ = {:.5} at {:.3e} Hz (direct {:.5}), order {}, {:.3} s",
        s.gamma,
        s.gamma_infeasible,
        s.closed_loop_norm,
        s.peak_hz,
        s.direct_norm_at_peak,
        s.controller.nstates(),
        r.synthesis_time_s
    );
    println!("MIMO loop: {:?}", r.loop_report);
    // Order = plant (6) + weights (11): the thesis's 17.
    assert_eq!(s.controller.nstates(), 6 + cfg.weights.order());
    // Verified: stable, ‖N‖∞ ≤ γ, and bracketed by the bisection.
    assert!(s.closed_loop_norm <= s.gamma * (1.0 + 1e-6));
    assert!(s.gamma - s.gamma_infeasible <= 2e-4 * s.gamma);
    // N rebuilt from frequency responses agrees with the state-space closed loop
    // (the peak sits at ω ≈ 0, next to the 2π·10⁻⁶ rad/s near-integrators, where
    // (jω − A)⁻¹ loses digits: 1e-3 relative).
    assert!((s.direct_norm_at_peak - s.closed_loop_norm).abs() < 1e-3 * s.closed_loop_norm);
    // γ ≥ k_S (the sensitivity weight's feed-through cannot be reduced).
    assert!(s.gamma > cfg.weights.k_s);
    assert!(r.loop_report.stable && r.sampled_spectral_radius < 1.0);
    // |S_o| ≤ γ/k_S at all frequencies (W_S → k_S): ‖S_o‖∞ ≤ γ/k_S.
    assert!(r.loop_report.s_o_hinf <= s.gamma / cfg.weights.k_s * (1.0 + 1e-6));
    let red = r.reduction.as_ref().unwrap();
    println!(
        "reduced to {}: ‖K − K_r‖∞ = {:.4e} ≤ bound {:.4e}; HSV {:?}",
        red.order, red.error, red.error_bound, red.hankel_singular_values
    );
    assert!(red.error <= red.error_bound * (1.0 + 1e-6));
    let d = r.decentralised.as_ref().unwrap();
    println!(
        "decentralised: {:?}; ‖N(K_d)‖∞ = {:.4}; (7.4) holds {} (worst {:.3e}, μ gap {:.2e})",
        d.loop_report, d.weighted_norm, d.condition_7_4_holds, d.worst_product, d.worst_mu_gap
    );
    // The H∞ controller is optimal for N: the decentralised one cannot do better.
    assert!(d.weighted_norm >= s.gamma_infeasible);
    assert!(d.loop_report.stable);
    // The tuned crossovers are where asked.
    assert!((d.loop_report.crossovers_hz[0].unwrap() - 16.7).abs() < 0.2);
    assert!((d.loop_report.crossovers_hz[2].unwrap() - 25.4).abs() < 0.3);
}

#[test]
fn bad_config_names_the_field() {
    let text = include_str!("../../../examples/mimo/afm_synth.yaml")
        .replace("rate_hz: 20000", "rate_hz: -5");
    let cfg = SynthConfig::from_yaml(&text, "x.yaml").unwrap();
    let e = run(&cfg).unwrap_err().to_string();
    assert!(e.contains("rate_hz"), "{e}");
    let text = include_str!("../../../examples/mimo/afm_synth.yaml").replace("k_t:", "k_tt:");
    let e = SynthConfig::from_yaml(&text, "x.yaml")
        .unwrap_err()
        .to_string();
    assert!(e.contains("k_tt"), "{e}");
}
