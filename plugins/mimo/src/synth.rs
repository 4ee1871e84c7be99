//! H∞ mixed-sensitivity synthesis of the thesis's Sec. 7.3.2: the generalised
//! plant (7.8) with the weights (7.10)–(7.12), the controller minimising
//! ‖N‖∞ of (7.9), its independent verification, its diagonal crossovers and
//! margins, its discretisation at the control rate and its order reduction.
//!
//! N stacks W_S S_o, W_KS K S_o and W_T T_o (the core's [`augw`] order; (7.8)
//! lists them as z₁ = W_KS u, z₂ = W_T G u, z₃ = W_S e: a permutation of the
//! rows, which leaves every singular value and so ‖N‖∞ unchanged).
//!
//! **Verification** (every returned design): the closed loop F_l(P, K) is
//! stable (its poles), ‖F_l(P, K)‖∞ ≤ γ(1 + 10⁻⁶) by the Hamiltonian
//! [`hinfnorm`]; and, independently of the state-space interconnection, N(jω)
//! is rebuilt from the frequency responses G(jω), K(jω) and the weights
//! (S_o = (I + GK)⁻¹, T_o = GKS_o) at the norm's peak frequency and on a grid:
//! both must agree with the state-space closed loop.

use crate::error::MimoError;
use crate::weights::MixedSensitivityWeights;
use nalgebra::DMatrix;
use nanomotion_core::analysis::CMatrix;
use nanomotion_core::lti::balred::{BalancedTruncation, balanced_truncation_offset, split_at};
use nanomotion_core::lti::{
    C2dMethod, Complex, HinfSynOptions, StateSpace, augw, c2d, feedback, hinfnorm, hinfsyn, lft,
    series,
};
use serde::Serialize;
use std::f64::consts::TAU;

/// A synthesised controller with its verification.
#[derive(Debug, Clone)]
pub struct Synthesis {
    /// The central H∞ controller (continuous; inputs e = r − y, outputs u).
    pub controller: StateSpace,
    /// γ of the controller (feasible end of the bisection).
    pub gamma: f64,
    /// Largest γ found infeasible (lower end of the bracket).
    pub gamma_infeasible: f64,
    /// ‖F_l(P, K)‖∞ by the Hamiltonian iteration.
    pub closed_loop_norm: f64,
    /// Peak frequency of ‖N(jω)‖ (Hz).
    pub peak_hz: f64,
    /// σ̄(N(jω_peak)) rebuilt from G, K and the weights (independent of lft).
    pub direct_norm_at_peak: f64,
    /// The continuous generalised plant P (7.8): inputs [w; u], outputs [z; v].
    pub generalized_plant: StateSpace,
    /// Number of measurements (v = e) = plant outputs.
    pub nmeas: usize,
    /// Number of controls (u) = plant inputs.
    pub ncon: usize,
}

/// N(jω) = [W_S S_o; W_KS K S_o; W_T T_o] from frequency responses only.
pub fn direct_n(
    g: &CMatrix,
    k: &CMatrix,
    ws: &CMatrix,
    wks: &CMatrix,
    wt: &CMatrix,
) -> Result<CMatrix, MimoError> {
    let p = g.nrows();
    let m = g.ncols();
    let s = (CMatrix::identity(p, p) + g * k)
        .try_inverse()
        .ok_or_else(|| {
            MimoError::param("controller", "I + GK is singular", "the loop is ill-posed")
        })?;
    let t = g * k * &s;
    let mut n = CMatrix::zeros(2 * p + m, p);
    n.view_mut((0, 0), (p, p)).copy_from(&(ws * &s));
    n.view_mut((p, 0), (m, p)).copy_from(&(wks * k * &s));
    n.view_mut((p + m, 0), (p, p)).copy_from(&(wt * t));
    Ok(n)
}

/// Largest singular value of a complex matrix.
pub fn sigma_max(m: &CMatrix) -> f64 {
    m.singular_values().iter().copied().fold(0.0, f64::max)
}

/// Synthesise the mixed-sensitivity controller for the plant `g` (continuous,
/// p outputs, m inputs) and the weights (one axis per output).
pub fn synthesise(g: &StateSpace, w: &MixedSensitivityWeights) -> Result<Synthesis, MimoError> {
    g.validate().map_err(MimoError::lti("plant"))?;
    if g.dt.is_some() {
        return Err(MimoError::param(
            "plant",
            "is discrete",
            "give the continuous plant; the controller is discretised at the control rate afterwards",
        ));
    }
    let (p, m) = (g.noutputs(), g.ninputs());
    if w.axes.len() != p {
        return Err(MimoError::param(
            "weights.axes",
            format!("has {} axes, the plant {p} outputs", w.axes.len()),
            "give one weight axis per plant output",
        ));
    }
    let ws = w.w_s()?;
    let wt = w.w_t()?;
    let wks = w.w_ks(m);
    let pg = augw(g, Some(&ws), Some(&wks), Some(&wt))
        .map_err(MimoError::lti("generalised plant (7.8)"))?;
    let syn =
        hinfsyn(&pg, p, m, &HinfSynOptions::default()).map_err(MimoError::lti("H∞ synthesis"))?;
    // Independent checks.
    if !syn.closed_loop.is_stable() {
        return Err(MimoError::param(
            "controller",
            "closed loop is not stable",
            "report this as a bug",
        ));
    }
    let norm = hinfnorm(&syn.closed_loop).map_err(MimoError::lti("‖N‖∞"))?;
    if norm.norm > syn.gamma * (1.0 + 1e-6) {
        return Err(MimoError::param(
            "controller",
            format!("‖N‖∞ = {} > γ = {}", norm.norm, syn.gamma),
            "report this as a bug",
        ));
    }
    let wpk = if norm.peak_rad_s.is_finite() {
        norm.peak_rad_s
    } else {
        1e9
    };
    let sj = Complex::new(0.0, wpk);
    let direct = sigma_max(&direct_n(
        &g.evalfr(sj),
        &syn.controller.evalfr(sj),
        &ws.evalfr(sj),
        &wks.evalfr(sj),
        &wt.evalfr(sj),
    )?);
    Ok(Synthesis {
        controller: syn.controller,
        gamma: syn.gamma,
        gamma_infeasible: syn.gamma_infeasible,
        closed_loop_norm: norm.norm,
        peak_hz: wpk / TAU,
        direct_norm_at_peak: direct,
        generalized_plant: pg,
        nmeas: p,
        ncon: m,
    })
}

/// Output sensitivity S_o = (I + GK)⁻¹ and T_o = I − S_o of a continuous loop
/// (state space).
pub fn sensitivities(
    g: &StateSpace,
    k: &StateSpace,
) -> Result<(StateSpace, StateSpace), MimoError> {
    let p = g.noutputs();
    let l = series(k, g).map_err(MimoError::lti("L = GK"))?;
    let eye = StateSpace::gain(DMatrix::identity(p, p), g.dt);
    let s = feedback(&eye, &l, -1.0).map_err(MimoError::lti("S_o"))?;
    let t = feedback(&l, &eye, -1.0).map_err(MimoError::lti("T_o"))?;
    Ok((s, t))
}

/// Closed-loop quantities of a MIMO loop, from state space.
#[derive(Debug, Clone, Serialize)]
pub struct LoopReport {
    /// The closed loop (S_o) is stable.
    pub stable: bool,
    /// ‖S_o‖∞ (absolute).
    pub s_o_hinf: f64,
    /// ‖T_o‖∞ (absolute).
    pub t_o_hinf: f64,
    /// Crossover of each diagonal loop gain |L_ii(j2πf)| = 1 (Hz; the highest
    /// crossing on the grid), None if it never crosses.
    pub crossovers_hz: Vec<Option<f64>>,
    /// Phase margin of each diagonal loop gain at its crossover (deg).
    pub phase_margins_deg: Vec<Option<f64>>,
    /// Smallest distance of the characteristic loci λ_i(L(jω)) to −1 on the grid.
    pub loci_distance_to_minus_one: f64,
}

/// The loop report of plant `g` and controller `k` on the grid `f_hz`.
pub fn loop_report(g: &StateSpace, k: &StateSpace, f_hz: &[f64]) -> Result<LoopReport, MimoError> {
    let (s, t) = sensitivities(g, k)?;
    let stable = s.is_stable();
    let (s_o_hinf, t_o_hinf) = if stable {
        (
            hinfnorm(&s).map_err(MimoError::lti("‖S_o‖∞"))?.norm,
            hinfnorm(&t).map_err(MimoError::lti("‖T_o‖∞"))?.norm,
        )
    } else {
        (f64::INFINITY, f64::INFINITY)
    };
    let p = g.noutputs();
    let l: Vec<CMatrix> = f_hz
        .iter()
        .map(|&f| {
            let sj = Complex::new(0.0, TAU * f);
            g.evalfr(sj) * k.evalfr(sj)
        })
        .collect();
    let mut crossovers_hz = Vec::with_capacity(p);
    let mut phase_margins_deg = Vec::with_capacity(p);
    for i in 0..p {
        let mut cross = None;
        for q in 1..f_hz.len() {
            let (a, b) = (l[q - 1][(i, i)].norm(), l[q][(i, i)].norm());
            if a >= 1.0 && b < 1.0 {
                // Interpolate in log-log.
                let r = a.ln() / (a.ln() - b.ln());
                let f = (f_hz[q - 1].ln() + r * (f_hz[q].ln() - f_hz[q - 1].ln())).exp();
                cross = Some((f, q));
            }
        }
        crossovers_hz.push(cross.map(|c| c.0));
        phase_margins_deg.push(cross.map(|(f, _)| {
            let sj = Complex::new(0.0, TAU * f);
            let lii = (g.evalfr(sj) * k.evalfr(sj))[(i, i)];
            let pm = (lii.arg().to_degrees() + 180.0).rem_euclid(360.0);
            if pm > 180.0 { pm - 360.0 } else { pm }
        }));
    }
    let mut dist = f64::INFINITY;
    for m in &l {
        let ev =
            nanomotion_core::analysis::mimo::eigenvalues(m).map_err(|e| MimoError::Analysis {
                context: "characteristic loci".into(),
                source: e,
            })?;
        for e in ev {
            dist = dist.min((e + 1.0).norm());
        }
    }
    Ok(LoopReport {
        stable,
        s_o_hinf,
        t_o_hinf,
        crossovers_hz,
        phase_margins_deg,
        loci_distance_to_minus_one: dist,
    })
}

/// The controller discretised at `rate_hz` (Tustin, pre-warped at `prewarp_hz`
/// when given), checked: the sampled loop with the ZOH-discretised plant is
/// stable. Returns the discrete controller and the spectral radius of the
/// sampled closed loop.
pub fn discretise(
    g: &StateSpace,
    k: &StateSpace,
    rate_hz: f64,
    prewarp_hz: Option<f64>,
) -> Result<(StateSpace, f64), MimoError> {
    crate::error::positive("rate_hz", rate_hz)?;
    let dt = 1.0 / rate_hz;
    let kd =
        c2d(k, dt, C2dMethod::Tustin { prewarp_hz }).map_err(MimoError::lti("controller c2d"))?;
    let gd = c2d(g, dt, C2dMethod::Zoh).map_err(MimoError::lti("plant c2d"))?;
    let l = series(&kd, &gd).map_err(MimoError::lti("sampled loop"))?;
    let p = g.noutputs();
    let eye = StateSpace::gain(DMatrix::identity(p, p), Some(dt));
    let s = feedback(&eye, &l, -1.0).map_err(MimoError::lti("sampled S_o"))?;
    let rho = s.poles().iter().map(|z| z.norm()).fold(0.0, f64::max);
    if !(rho < 1.0) {
        return Err(MimoError::param(
            "rate_hz",
            format!("the sampled loop at {rate_hz} Hz is unstable (spectral radius {rho})"),
            "raise the control rate or lower the bandwidth",
        ));
    }
    Ok((kd, rho))
}

/// Poles of K with Re ≥ −[`REDUCE_OFFSET_RAD_S`] (the near-integrators of W_S)
/// are kept whole by [`reduce`]; the rest is balanced and truncated.
pub const REDUCE_OFFSET_RAD_S: f64 = 1.0;

/// Balanced truncation of the controller to `order` states with the H∞ bound
/// of the error, and the error actually achieved: ‖K_b − K_br‖∞ of the balanced
/// part (the kept slow part cancels exactly in K − K_r), by the Hamiltonian
/// iteration.
pub fn reduce(k: &StateSpace, order: usize) -> Result<(BalancedTruncation, f64), MimoError> {
    let red = balanced_truncation_offset(k, order, REDUCE_OFFSET_RAD_S)
        .map_err(MimoError::lti("balanced truncation"))?;
    let (kb, _) = split_at(k, REDUCE_OFFSET_RAD_S).map_err(MimoError::lti("split"))?;
    let keep = order - red.unstable_states;
    let (rb, _) = split_at(&red.reduced, REDUCE_OFFSET_RAD_S).map_err(MimoError::lti("split"))?;
    if rb.nstates() != keep {
        return Err(MimoError::param(
            "reduce_to",
            "the reduced controller moved a pole across the offset",
            "keep more states",
        ));
    }
    let err =
        nanomotion_core::lti::parallel(&kb, &rb.scaled(-1.0)).map_err(MimoError::lti("K − K_r"))?;
    let achieved = hinfnorm(&err).map_err(MimoError::lti("‖K − K_r‖∞"))?.norm;
    Ok((red, achieved))
}

/// `n` log-spaced frequencies from `f0` to `f1` (Hz).
pub fn log_grid(f0: f64, f1: f64, n: usize) -> Vec<f64> {
    (0..n)
        .map(|k| f0 * (f1 / f0).powf(k as f64 / (n.max(2) - 1) as f64))
        .collect()
}

/// σ̄(N(jω)) on a grid from frequency responses (for plots and the grid check).
pub fn direct_n_on_grid(
    g: &StateSpace,
    k: &StateSpace,
    w: &MixedSensitivityWeights,
    f_hz: &[f64],
) -> Result<Vec<f64>, MimoError> {
    let ws = w.w_s()?;
    let wt = w.w_t()?;
    let wks = w.w_ks(g.ninputs());
    f_hz.iter()
        .map(|&f| {
            let sj = Complex::new(0.0, TAU * f);
            Ok(sigma_max(&direct_n(
                &g.evalfr(sj),
                &k.evalfr(sj),
                &ws.evalfr(sj),
                &wks.evalfr(sj),
                &wt.evalfr(sj),
            )?))
        })
        .collect()
}

/// ‖F_l(P, K)‖∞ for any controller `k` on the generalised plant `p` (e.g. the
/// decentralised (7.2) controller on the same weights), or ∞ if unstable.
pub fn weighted_norm(
    p: &StateSpace,
    k: &StateSpace,
    nmeas: usize,
    ncon: usize,
) -> Result<f64, MimoError> {
    let cl = lft(p, k, nmeas, ncon).map_err(MimoError::lti("F_l(P, K)"))?;
    if !cl.is_stable() {
        return Ok(f64::INFINITY);
    }
    Ok(hinfnorm(&cl).map_err(MimoError::lti("‖F_l(P, K)‖∞"))?.norm)
}

/// Largest off-diagonal |S_o(j2πf)_{ji}| (j ≠ i) over the grid frequencies in
/// `band_hz` (the coupling of a disturbance on one output into the error of
/// another, Fig. 7.10), from frequency responses.
pub fn offdiag_sensitivity(
    g: &StateSpace,
    k: &StateSpace,
    f_hz: &[f64],
    band_hz: [f64; 2],
) -> Result<f64, MimoError> {
    let f: Vec<f64> = f_hz
        .iter()
        .copied()
        .filter(|&f| f >= band_hz[0] && f <= band_hz[1])
        .collect();
    let resp = |sys: &StateSpace| -> Vec<CMatrix> {
        f.iter()
            .map(|&ff| sys.evalfr(Complex::new(0.0, TAU * ff)))
            .collect()
    };
    offdiag_sensitivity_frf(&f, &resp(g), &resp(k), band_hz)
}

/// [`offdiag_sensitivity`] from frequency responses: G(j2πf) (e.g. a measured
/// FRF) and K(j2πf) at the frequencies `f_hz`; S_o = (I + GK)⁻¹ per frequency.
pub fn offdiag_sensitivity_frf(
    f_hz: &[f64],
    g: &[CMatrix],
    k: &[CMatrix],
    band_hz: [f64; 2],
) -> Result<f64, MimoError> {
    if g.len() != f_hz.len() || k.len() != f_hz.len() {
        return Err(MimoError::param(
            "frf",
            format!(
                "{} frequencies, {} plant and {} controller responses",
                f_hz.len(),
                g.len(),
                k.len()
            ),
            "give one response of each per frequency",
        ));
    }
    let mut worst: f64 = 0.0;
    for ((&f, gf), kf) in f_hz.iter().zip(g).zip(k) {
        if f < band_hz[0] || f > band_hz[1] {
            continue;
        }
        let p = gf.nrows();
        let s = (CMatrix::identity(p, p) + gf * kf)
            .try_inverse()
            .ok_or_else(|| {
                MimoError::param(
                    "controller",
                    format!("I + GK singular at {f} Hz"),
                    "check the loop",
                )
            })?;
        for j in 0..p {
            for i in 0..p {
                if i != j {
                    worst = worst.max(s[(j, i)].norm());
                }
            }
        }
    }
    Ok(worst)
}

/// Inverse of a square system with an invertible feed-through:
/// (A − BD⁻¹C, BD⁻¹, −D⁻¹C, D⁻¹).
fn ss_inverse(sys: &StateSpace, what: &str) -> Result<StateSpace, MimoError> {
    let di = sys.d.clone().try_inverse().ok_or_else(|| {
        MimoError::param(
            what,
            "has a singular feed-through and cannot be inverted",
            "give biproper weights (k_S > 0)",
        )
    })?;
    Ok(StateSpace {
        a: &sys.a - &sys.b * &di * &sys.c,
        b: &sys.b * &di,
        c: -(&di * &sys.c),
        d: di,
        dt: sys.dt,
    })
}

/// The weights with every W_S pole below `safe_hz` (the near-integrator and
/// any f_S3 below it) moved to `safe_hz`.
pub fn relocated_weights(w: &MixedSensitivityWeights, safe_hz: f64) -> MixedSensitivityWeights {
    let mut w2 = w.clone();
    if w2.near_integrator_hz < safe_hz {
        w2.near_integrator_hz = safe_hz;
    }
    for a in w2.axes.iter_mut() {
        if a.f_s3_hz > 0.0 && a.f_s3_hz < safe_hz {
            a.f_s3_hz = safe_hz;
        }
    }
    w2
}

/// H∞ design for weights whose W_S has poles so close to the axis (the
/// thesis's 2π·10⁻⁶ rad/s) that the central controller cannot be formed in
/// double precision: the round-off of A_K (≈ ε_mach‖A_K‖) splits the
/// controller's double near-integrator pole by ≈ √(ε_mach‖A_K‖·50 rad/s) ≈
/// 10⁻⁶ rad/s, 20 % of the pole itself, and N(0) = W_S(0)S_o(0) — a ratio of
/// two ~1/ε² numbers — moves by percent (docs/mimo.md, "γ at the thesis's
/// near-integrator").
///
/// Instead the problem is solved with the near-axis poles at `safe_hz` (weights
/// W'), giving K′, and the near-integrators are moved back exactly in the
/// controller's error channels: K = K′·D with D = W′_S⁻¹W_S (diagonal, exact
/// poles at the thesis's ε). Where |GK| ≫ 1 (every frequency below the
/// bandwidth, so all of D's range) W_S S_o ≈ W_S K⁻¹G⁻¹ = W′_S K′⁻¹G⁻¹, so ‖N‖∞
/// is that of K′ on W′ up to the tiny S_o there.
///
/// **Verification** of K on the *original* weights, with every near-axis mode
/// cancelled structurally rather than by round-off: W_S S_o = (W_S⁻¹ +
/// G K′ W′_S⁻¹)⁻¹, K S_o = K′W′_S⁻¹·(W_S S_o), T_o = I − W_S⁻¹(W_S S_o) (W_S⁻¹
/// and W′_S⁻¹ have only W_S's zeros as poles), so no pole sits near the axis
/// and the Hamiltonian [`hinfnorm`] is well conditioned; the closed loop
/// F_l(P, K) must be stable (its poles), and N(jω) rebuilt from the factored
/// frequency responses G, K′, D and the weights on a grid must not exceed the
/// norm. γ returned is max(γ′, ‖N‖∞). The controller has order
/// n(K′) + (number of relocated poles).
pub fn synthesise_near_axis(
    g: &StateSpace,
    w: &MixedSensitivityWeights,
    safe_hz: f64,
) -> Result<Synthesis, MimoError> {
    crate::error::positive("safe_hz", safe_hz)?;
    let w2 = relocated_weights(w, safe_hz);
    let s2 = synthesise(g, &w2)?;
    let p = g.noutputs();
    // D = diag(W′_S,i⁻¹ W_S,i) = diag(den′_i / den_i) (same numerators).
    let mut dblocks = Vec::with_capacity(p);
    for i in 0..p {
        let (_, den) = w.w_s_tf(i);
        let (_, den2) = w2.w_s_tf(i);
        let di = nanomotion_core::lti::TransferFunction::new(den2, den, None)
            .and_then(|t| t.to_ss())
            .map_err(MimoError::lti(format!("near-integrator shift of axis {i}")))?;
        dblocks.push(di);
    }
    let d = nanomotion_core::lti::append(&dblocks).map_err(MimoError::lti("D"))?;
    let k = series(&d, &s2.controller).map_err(MimoError::lti("K = K′D"))?;
    let ws = w.w_s()?;
    let wt = w.w_t()?;
    let wks = w.w_ks(g.ninputs());
    let pg = augw(g, Some(&ws), Some(&wks), Some(&wt))
        .map_err(MimoError::lti("generalised plant (7.8)"))?;
    let cl = lft(&pg, &k, p, g.ninputs()).map_err(MimoError::lti("F_l(P, K)"))?;
    if !cl.is_stable() {
        return Err(MimoError::param(
            "controller",
            "the relocated controller does not stabilise the loop",
            "raise safe_hz is not the fix: lower it towards the weight's poles, or report a bug",
        ));
    }
    let n = structured_n(g, &s2.controller, w, &w2)?;
    let norm = hinfnorm(&n).map_err(MimoError::lti("‖N‖∞ (structured)"))?;
    let grid = log_grid(1e-9, 1e5, 400);
    let mut grid_max: f64 = 0.0;
    for &f in &grid {
        let sj = Complex::new(0.0, TAU * f);
        let kk = s2.controller.evalfr(sj) * d.evalfr(sj);
        let v = sigma_max(&direct_n(
            &g.evalfr(sj),
            &kk,
            &ws.evalfr(sj),
            &wks.evalfr(sj),
            &wt.evalfr(sj),
        )?);
        grid_max = grid_max.max(v);
    }
    if grid_max > norm.norm * (1.0 + 1e-6) {
        return Err(MimoError::param(
            "controller",
            format!(
                "the structured ‖N‖∞ = {} is below the factored grid's {grid_max}",
                norm.norm
            ),
            "report this as a bug",
        ));
    }
    let wpk = if norm.peak_rad_s.is_finite() {
        norm.peak_rad_s
    } else {
        1e9
    };
    let sj = Complex::new(0.0, wpk);
    let direct = sigma_max(&direct_n(
        &g.evalfr(sj),
        &(s2.controller.evalfr(sj) * d.evalfr(sj)),
        &ws.evalfr(sj),
        &wks.evalfr(sj),
        &wt.evalfr(sj),
    )?);
    Ok(Synthesis {
        controller: k,
        gamma: s2.gamma.max(norm.norm),
        gamma_infeasible: s2.gamma_infeasible,
        closed_loop_norm: norm.norm,
        peak_hz: wpk / TAU,
        direct_norm_at_peak: direct,
        generalized_plant: pg,
        nmeas: p,
        ncon: g.ninputs(),
    })
}

/// N = [W_S S_o; W_KS K S_o; W_T T_o] of K = K′·W′_S⁻¹W_S without near-axis
/// poles (see [`synthesise_near_axis`]).
fn structured_n(
    g: &StateSpace,
    k2: &StateSpace,
    w: &MixedSensitivityWeights,
    w2: &MixedSensitivityWeights,
) -> Result<StateSpace, MimoError> {
    let p = g.noutputs();
    let e = MimoError::lti;
    let wsi = ss_inverse(&w.w_s()?, "W_S")?;
    let ws2i = ss_inverse(&w2.w_s()?, "W′_S")?;
    // M = W_S⁻¹ + G K′ W′_S⁻¹; W_S S_o = M⁻¹.
    let gk = series(&series(&ws2i, k2).map_err(e("K′W′_S⁻¹"))?, g).map_err(e("GK′W′_S⁻¹"))?;
    let m = nanomotion_core::lti::parallel(&wsi, &gk).map_err(e("M"))?;
    let n1 = ss_inverse(&m, "W_S⁻¹ + GK′W′_S⁻¹")?;
    // One copy of W_S S_o's states: v = [a; w] with a = (W_S S_o)w, then
    // N = [a; W_KS K′W′_S⁻¹ a; W_T(w − W_S⁻¹a)].
    let ip = DMatrix::<f64>::identity(p, p);
    let gain = |m: DMatrix<f64>| StateSpace::gain(m, None);
    let mut dup = DMatrix::zeros(2 * p, p);
    dup.view_mut((0, 0), (p, p)).copy_from(&ip);
    dup.view_mut((p, 0), (p, p)).copy_from(&ip);
    let v = series(
        &gain(dup.clone()),
        &nanomotion_core::lti::append(&[n1, gain(ip.clone())]).map_err(e("[a; w]"))?,
    )
    .map_err(e("[a; w]"))?;
    let mut first = DMatrix::zeros(p, 2 * p);
    first.view_mut((0, 0), (p, p)).copy_from(&ip);
    let r1 = gain(first.clone());
    let ks = series(
        &series(&ws2i, k2).map_err(e("K′W′_S⁻¹"))?,
        &w.w_ks(g.ninputs()),
    )
    .map_err(e("W_KS K′W′_S⁻¹"))?;
    let r2 = series(&gain(first), &ks).map_err(e("W_KS K S_o"))?;
    let diff = series(
        &nanomotion_core::lti::append(&[wsi.scaled(-1.0), gain(ip.clone())]).map_err(e("T_o"))?,
        &gain(dup.transpose()),
    )
    .map_err(e("T_o"))?;
    let r3 = series(&diff, &w.w_t()?).map_err(e("W_T T_o"))?;
    let rows = nanomotion_core::lti::append(&[r1, r2, r3]).map_err(e("N"))?;
    let mut split = DMatrix::zeros(6 * p, 2 * p);
    for b in 0..3 {
        split
            .view_mut((2 * p * b, 0), (2 * p, 2 * p))
            .copy_from(&DMatrix::identity(2 * p, 2 * p));
    }
    let post = series(&gain(split), &rows).map_err(e("N"))?;
    series(&v, &post).map_err(e("N"))
}
