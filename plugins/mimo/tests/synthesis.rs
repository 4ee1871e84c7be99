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
    // Verified: stable, ‖N‖∞ ≤ γ, and bracketed by the bisection. With the
    // thesis's 2π·10⁻⁶ rad/s near-integrators the controllers of the last
    // bisection steps fail the independent check (round-off), so the returned
    // γ sits above the bracket's infeasible end (≈ 3 %, see docs/mimo.md).
    assert!(s.closed_loop_norm <= s.gamma * (1.0 + 1e-6));
    assert!(s.gamma <= 1.05 * s.gamma_infeasible);
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

/// γ of a decoupled MIMO problem is the largest γ of its axes solved alone
/// (an independent computation: three 1×1 problems). Regression test for the
/// γ floor, which used the Frobenius norm of D₁₁ (√3·k_S here) instead of its
/// largest singular value and stopped the search at 0.866.
#[test]
fn decoupled_gamma_is_the_worst_axis_gamma() {
    let mut cfg = config();
    cfg.weights.near_integrator_hz = 1e-3;
    for a in cfg.weights.axes.iter_mut().take(2) {
        a.f_s3_hz = 1e-3;
    }
    let nanomotion_mimo::config::PlantSpec::Coupled(p) = &mut cfg.plant else {
        unreachable!()
    };
    for row in p.coupling.iter_mut() {
        row.fill(0.0);
    }
    let p = p.clone();
    let g = cfg.plant_ss().unwrap();
    let mimo = nanomotion_mimo::synth::synthesise(&g, &cfg.weights).unwrap();
    let mut worst: f64 = 0.0;
    for i in 0..3 {
        let pi = nanomotion_mimo::plant::CoupledPlant {
            diagonal: vec![p.diagonal[i]],
            coupling: vec![vec![0.0]],
        };
        let mut w = cfg.weights.clone();
        w.axes = vec![cfg.weights.axes[i]];
        let s = nanomotion_mimo::synth::synthesise(&pi.to_ss().unwrap(), &w).unwrap();
        println!("axis {i}: γ = {:.6}", s.gamma);
        worst = worst.max(s.gamma);
    }
    println!(
        "MIMO γ = {:.6} (bracket from {:.6}), worst axis {worst:.6}",
        mimo.gamma, mimo.gamma_infeasible
    );
    assert!(
        (mimo.gamma - worst).abs() < 1e-3 * worst,
        "{} vs {worst}",
        mimo.gamma
    );
}

/// Issue 15 item 1 at the thesis's near-integrator (2π·10⁻⁶ rad/s): the
/// relocated design is verified on the original weights and its γ is within
/// 1 % of the γ of the 10⁻³ Hz near-integrator problem (0.815694 by SLICOT
/// SB10AD, docs/mimo.md), which the plain order-17 design misses (0.839).
#[test]
fn near_axis_weights_reach_the_optimum_verified() {
    let cfg = config();
    assert_eq!(cfg.weights.near_integrator_hz, 1e-6);
    let g = cfg.plant_ss().unwrap();
    let t = std::time::Instant::now();
    let s = nanomotion_mimo::synth::synthesise_near_axis(&g, &cfg.weights, 1e-3).unwrap();
    let elapsed = t.elapsed().as_secs_f64();
    // Reference: the same problem with the near-integrators at 10⁻³ Hz,
    // solved directly (no relocation).
    let mut w3 = cfg.weights.clone();
    w3.near_integrator_hz = 1e-3;
    for a in w3.axes.iter_mut().take(2) {
        a.f_s3_hz = 1e-3;
    }
    let r = nanomotion_mimo::synth::synthesise(&g, &w3).unwrap();
    println!(
        "near-axis design: γ = {:.6} (‖N‖∞ {:.6} at {:.3e} Hz, direct {:.6}), order {}, {elapsed:.2} s; 10⁻³ Hz problem γ = {:.6} (infeasible {:.6})",
        s.gamma,
        s.closed_loop_norm,
        s.peak_hz,
        s.direct_norm_at_peak,
        s.controller.nstates(),
        r.gamma,
        r.gamma_infeasible
    );
    assert!(s.closed_loop_norm <= s.gamma * (1.0 + 1e-6));
    assert!((s.gamma - r.gamma).abs() < 0.01 * r.gamma);
    // The controller's near-integrators sit exactly at the weight's poles.
    let eps = std::f64::consts::TAU * 1e-6;
    let at_eps = s
        .controller
        .poles()
        .iter()
        .filter(|p| (p.re + eps).abs() < 1e-12 && p.im.abs() < 1e-9)
        .count();
    assert!(at_eps >= 1, "no pole at −ε");
    // The factored N(jω) at the peak agrees with the structured state space.
    assert!((s.direct_norm_at_peak - s.closed_loop_norm).abs() < 1e-6 * s.closed_loop_norm);
    // The controller stabilises the stage model's loop (poles of S_o).
    let rep = nanomotion_mimo::synth::loop_report(&g, &s.controller, &[1.0, 10.0, 100.0]).unwrap();
    assert!(rep.stable);
}

/// The plain-data Sec. 7.3 comparison agrees with the design run directly.
#[test]
fn sec_7_3_figures_are_the_designs() {
    let cfg = config();
    let t = nanomotion_mimo::thesis::sec_7_3(&cfg, None).unwrap();
    let r = run(&cfg).unwrap();
    println!("{}", serde_json::to_string(&t).unwrap());
    assert_eq!(t.gamma.ours, r.synthesis.gamma);
    assert_eq!(t.order.ours, r.synthesis.controller.nstates());
    assert_eq!(t.order.thesis, 17);
    for i in 0..3 {
        assert_eq!(
            Some(t.mimo_crossovers_hz.ours[i]),
            r.loop_report.crossovers_hz[i]
        );
    }
    assert!((t.decentralised_crossovers_hz.ours[0] - 16.7).abs() < 0.2);
    assert!(t.gamma_near_axis.is_none());
}
