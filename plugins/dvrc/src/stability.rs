//! Stability tooling for RC and DVRC (Sec. 5.2.1, 5.3.2, 5.4).
//!
//! - [`loop_h`]: the system H(z) = Q(z)z^-l(1 − T(z)L(z)z^l) that the memory-loop
//!   delay sees (Fig. 5.2, (5.10a)), from T and the *built* filters;
//! - [`rc_criterion`]: criterion (5.5) (fixed N, m = M) and (5.9)
//!   ‖Q(1 − T L z^l)‖∞ < 1/√(M − m + 1) (Corollary 7) with the core's exact
//!   [`hinfnorm`], the margin and the frequency where it is tightest;
//! - [`design_q_cutoff`]: picks the largest cut-off of a linear-phase FIR Q for
//!   which (5.9) holds for a given M − m;
//! - [`lifted_check`]: the lifted switched system (5.13)–(5.15) for small cases,
//!   an independent and less conservative test by the joint spectral radius (see
//!   its docs);
//! - [`lifted_lmi_check`]: the same lifted system decided by the thesis's LMIs
//!   (5.16) with the core's LMI solver ([`nanomotion_core::lti::lmi`]), returning
//!   the certificate P_m … P_M;
//! - [`worst_case_gain_input`]: the input and delay sequence of the proof of
//!   Theorem 8.

use crate::filters::Filter;
use nalgebra::DMatrix;
use nanomotion_core::LearningFilter;
use nanomotion_core::lti::lmi::{
    LmiConstraint, LmiError, LmiOptions, LmiProblem, LmiStatus, LmiVar,
};
use nanomotion_core::lti::{Complex, LtiError, StateSpace, fir_lowpass, hinfnorm};
use std::f64::consts::PI;
use std::fmt;

/// H(z) = Q(z)(z^-l − T(z)·L_c(z)) with L_c = z^-l L the causal learning filter
/// (preview l): the map from the delay block's output to its input in Fig. 5.2.
/// |H(e^{jω})| = |Q(1 − T L z^l)| at every frequency.
///
/// The formula lives in the core ([`nanomotion_core::gate::learning::loop_h`]),
/// where the stability gate evaluates the same criteria for any graph.
pub fn loop_h(t: &StateSpace, l: &Filter, q: &Filter) -> Result<StateSpace, LtiError> {
    nanomotion_core::gate::learning::loop_h(t, l.model()?, l.preview_samples(), q.model()?)
}

/// Result of [`rc_criterion`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RcCriterion {
    /// ‖Q(1 − T L z^l)‖∞.
    pub hinf: f64,
    /// Frequency (Hz) where |Q(1 − T L z^l)| peaks, i.e. where the criterion is
    /// tightest (the bound is flat).
    pub peak_hz: f64,
    /// The bound 1/√(M − m + 1) (1 for a fixed delay: (5.5)).
    pub bound: f64,
    /// m and M (samples).
    pub n_min: usize,
    /// M.
    pub n_max: usize,
    /// Whether S (i.e. T) is stable: condition (a).
    pub s_stable: bool,
}

impl RcCriterion {
    /// Margin 20·log10(bound/‖H‖∞) in dB (> 0: the criterion holds).
    pub fn margin_db(&self) -> f64 {
        20.0 * (self.bound / self.hinf).log10()
    }
    /// Both conditions: S stable and ‖H‖∞ < bound.
    pub fn holds(&self) -> bool {
        self.s_stable && self.hinf < self.bound
    }
    /// The largest M − m for which (5.9) holds with this ‖H‖∞:
    /// ⌈1/‖H‖∞²⌉ − 2 (none if ‖H‖∞ ≥ 1).
    pub fn max_spread(&self) -> Option<usize> {
        if self.hinf >= 1.0 || !self.s_stable {
            return None;
        }
        let x = 1.0 / (self.hinf * self.hinf); // need spread + 1 < x
        let s = x.ceil() as i64 - 2;
        Some(s.max(0) as usize)
    }
}

impl fmt::Display for RcCriterion {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let which = if self.n_min == self.n_max {
            "(5.5) fixed N".to_string()
        } else {
            format!("(5.9) N ∈ [{}, {}]", self.n_min, self.n_max)
        };
        write!(
            f,
            "{which}: ‖Q(1 − T L z^l)‖∞ = {:.4} ({:.2} dB) at {:.1} Hz, bound {:.4} ({:.2} dB), margin {:+.2} dB, S stable: {} → {}",
            self.hinf,
            20.0 * self.hinf.log10(),
            self.peak_hz,
            self.bound,
            20.0 * self.bound.log10(),
            self.margin_db(),
            if self.s_stable { "yes" } else { "NO" },
            if self.holds() {
                "stability guaranteed"
            } else {
                "NOT guaranteed"
            }
        )
    }
}

/// Evaluate (5.5) (`n_min == n_max`) or (5.9) for N_k ∈ \[`n_min`, `n_max`\] with the
/// exact H∞ norm of [`loop_h`]. `t` is the discrete complementary sensitivity.
pub fn rc_criterion(
    t: &StateSpace,
    l: &Filter,
    q: &Filter,
    n_min: usize,
    n_max: usize,
) -> Result<RcCriterion, LtiError> {
    if n_max < n_min {
        return Err(LtiError::Parameter {
            name: "n_max",
            problem: format!("{n_max} < n_min = {n_min}"),
        });
    }
    let s_stable = t.is_stable();
    let h = loop_h(t, l, q)?;
    let r = hinfnorm(&h)?;
    Ok(RcCriterion {
        hinf: r.norm,
        peak_hz: r.peak_rad_s / (2.0 * PI),
        bound: 1.0 / ((n_max - n_min + 1) as f64).sqrt(),
        n_min,
        n_max,
        s_stable,
    })
}

/// |Q(1 − T L z^l)| on a frequency grid `f_hz` (for plots like Fig. 5.9).
pub fn criterion_curve(t: &StateSpace, l: &Filter, q: &Filter, f_hz: &[f64]) -> Vec<f64> {
    let dt = t.dt.unwrap_or(1.0);
    f_hz.iter()
        .map(|&f| {
            let w = 2.0 * PI * f;
            let tl = t.freqresp_siso_at(w)
                * l.freqresp_at(w)
                * Complex::from_polar(1.0, w * dt * l.preview_samples() as f64);
            (q.freqresp_at(w) * (Complex::new(1.0, 0.0) - tl)).norm()
        })
        .collect()
}

/// Result of [`design_q_cutoff`].
#[derive(Debug, Clone)]
pub struct QDesign {
    /// The chosen cut-off (Hz).
    pub cutoff_hz: f64,
    /// The FIR taps of Q.
    pub taps: Vec<f64>,
    /// The verified criterion with this Q.
    pub criterion: RcCriterion,
}

/// Pick the largest cut-off of a `n_taps`-tap linear-phase FIR Q (core
/// [`fir_lowpass`]) such that (5.9) holds for delays varying over `spread` = M − m
/// samples, with a relative safety `margin` (e.g. 0.05 for 5 %, i.e. ‖H‖∞ ≤
/// 0.95/√(spread + 1)). A dense frequency grid narrows the cut-off down, the exact
/// H∞ norm verifies the result (and lowers the cut-off if needed). Fails if no
/// cut-off above 0.5 % of Nyquist works (the model mismatch |1 − T L z^l| is
/// already too large at low frequencies: improve L or the model).
pub fn design_q_cutoff(
    t: &StateSpace,
    l: &Filter,
    n_taps: usize,
    spread: usize,
    margin: f64,
) -> Result<QDesign, LtiError> {
    let dt =
        t.dt.ok_or_else(|| LtiError::Domain("T(z) must be discrete".into()))?;
    let nyq = 0.5 / dt;
    let bound = (1.0 - margin) / ((spread + 1) as f64).sqrt();
    // 1 − T L z^l on a grid, once.
    let ng = 1500;
    let grid: Vec<f64> = (0..=ng).map(|i| nyq * i as f64 / ng as f64).collect();
    let one_minus: Vec<Complex<f64>> = grid
        .iter()
        .map(|&f| {
            let w = 2.0 * PI * f;
            Complex::new(1.0, 0.0)
                - t.freqresp_siso_at(w)
                    * l.freqresp_at(w)
                    * Complex::from_polar(1.0, w * dt * l.preview_samples() as f64)
        })
        .collect();
    let peak = |fc: f64| -> Result<f64, LtiError> {
        let h = fir_lowpass(n_taps, fc, dt)?;
        let q = Filter::fir(h, (n_taps - 1) / 2, dt);
        Ok(grid
            .iter()
            .zip(&one_minus)
            .map(|(&f, m)| (q.freqresp_at(2.0 * PI * f) * m).norm())
            .fold(0.0, f64::max))
    };
    let f_lo = 0.005 * nyq;
    if peak(f_lo)? >= bound {
        return Err(LtiError::Parameter {
            name: "cutoff_hz",
            problem: format!(
                "even a {f_lo:.1} Hz cut-off violates (5.9) for M − m = {spread}: |1 − T L z^l| is too large at low frequencies"
            ),
        });
    }
    // Largest passing cut-off on a geometric ladder, then bisection.
    let mut ok = f_lo;
    let mut bad = None;
    let mut f = f_lo;
    while f < 0.98 * nyq {
        let nf = (f * 1.15).min(0.98 * nyq);
        if peak(nf)? < bound {
            ok = nf;
        } else {
            bad = Some(nf);
            break;
        }
        f = nf;
    }
    if let Some(mut hi) = bad {
        for _ in 0..25 {
            let mid = 0.5 * (ok + hi);
            if peak(mid)? < bound {
                ok = mid;
            } else {
                hi = mid;
            }
        }
    }
    // Verify with the exact norm.
    let m_lo = 1usize;
    let mut fc = ok;
    for _ in 0..40 {
        let h = fir_lowpass(n_taps, fc, dt)?;
        let q = Filter::fir(h.clone(), (n_taps - 1) / 2, dt);
        let c = rc_criterion(t, l, &q, m_lo, m_lo + spread)?;
        if c.hinf < c.bound {
            return Ok(QDesign {
                cutoff_hz: fc,
                taps: h,
                criterion: c,
            });
        }
        fc *= 0.97;
    }
    Err(LtiError::Parameter {
        name: "cutoff_hz",
        problem: "no cut-off passed the exact H∞ verification".into(),
    })
}

/// The worst-case input of the proof of Theorem 8: q = (1, 0, 0, ...) and
/// N_k = k for k ∈ \[m, M\] (else M), over `len` samples; its output through the
/// varying delay has energy (M − m + 1)·|q_0|².
pub fn worst_case_gain_input(n_min: usize, n_max: usize, len: usize) -> (Vec<f64>, Vec<usize>) {
    let mut q = vec![0.0; len];
    if len > 0 {
        q[0] = 1.0;
    }
    let n = (0..len)
        .map(|k| {
            if (n_min..=n_max).contains(&k) {
                k
            } else {
                n_max
            }
        })
        .collect();
    (q, n)
}

/// The lifted matrix Λ(N) of (5.14)–(5.15) for x_{k+1} = A x + B v, q = C x + D v,
/// v_k = q_{k−N}, N ∈ \[1, M\]; state ξ = (x, q_{k−1}, …, q_{k−M}) (SISO q, v).
/// (The thesis's C x has no D; a D term from a Q with h\[0\] ≠ 0 enters the same way.)
pub fn lifted_matrix(h: &StateSpace, n: usize, n_max: usize) -> DMatrix<f64> {
    let nx = h.nstates();
    let dim = nx + n_max;
    let mut lam = DMatrix::zeros(dim, dim);
    lam.view_mut((0, 0), (nx, nx)).copy_from(&h.a);
    // v_k = ζ_N = q_{k−N} at column nx + N − 1.
    let col = nx + n - 1;
    for i in 0..nx {
        lam[(i, col)] += h.b[(i, 0)];
    }
    // new ζ_1 = q_k = C x + D v.
    for j in 0..nx {
        lam[(nx, j)] = h.c[(0, j)];
    }
    lam[(nx, col)] += h.d[(0, 0)];
    // shift.
    for i in 1..n_max {
        lam[(nx + i, nx + i - 1)] = 1.0;
    }
    lam
}

/// Verdict of [`lifted_check`].
#[derive(Debug, Clone, PartialEq)]
pub enum LiftedVerdict {
    /// The joint spectral radius is below 1: asymptotically stable for every
    /// sequence N_k ∈ \[m, M\] (a certificate like feasibility of (5.16)).
    Stable,
    /// A periodic delay sequence whose lifted product has spectral radius ≥ 1:
    /// the loop is not stable for all N_k ∈ \[m, M\]. Repeating `sequence`
    /// (delays in samples) makes it grow (or not decay).
    Unstable {
        /// One period of the destabilising delay sequence.
        sequence: Vec<usize>,
    },
    /// Neither bound decided within the budget.
    Inconclusive,
}

/// Result of [`lifted_check`].
#[derive(Debug, Clone)]
pub struct LiftedCheck {
    /// Lower bound on the joint spectral radius ρ of {Λ(N) : N ∈ \[m, M\]}.
    pub rho_lower: f64,
    /// Upper bound on ρ.
    pub rho_upper: f64,
    /// Products examined.
    pub nodes: usize,
    /// The verdict.
    pub verdict: LiftedVerdict,
}

impl fmt::Display for LiftedCheck {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "lifted (5.13)-(5.15): joint spectral radius in [{:.4}, {:.4}] ({} products) → {}",
            self.rho_lower,
            self.rho_upper,
            self.nodes,
            match &self.verdict {
                LiftedVerdict::Stable => "stable for all N_k ∈ [m, M]".to_string(),
                LiftedVerdict::Unstable { sequence } =>
                    format!("NOT stable: periodic delays {sequence:?}"),
                LiftedVerdict::Inconclusive => "inconclusive".to_string(),
            }
        )
    }
}

fn spectral_radius(a: &DMatrix<f64>) -> f64 {
    nanomotion_core::lti::linalg::eigvals(a)
        .iter()
        .map(|z| z.norm())
        .fold(0.0, f64::max)
}

fn norm2(a: &DMatrix<f64>) -> f64 {
    a.clone()
        .singular_values()
        .iter()
        .copied()
        .fold(0.0, f64::max)
}

/// Solve A^T P A − P = −I (Smith doubling); `None` if A is not Schur.
fn dlyap_identity(a: &DMatrix<f64>) -> Option<DMatrix<f64>> {
    let n = a.nrows();
    if spectral_radius(a) >= 1.0 {
        return None;
    }
    let mut p = DMatrix::<f64>::identity(n, n);
    let mut ak = a.clone();
    for _ in 0..60 {
        let dp = ak.transpose() * &p * &ak;
        let done = dp.norm() <= 1e-14 * p.norm();
        p += dp;
        ak = &ak * &ak;
        if done {
            return Some(p);
        }
    }
    Some(p)
}

/// The lifted switched-system test (5.13)–(5.16) for small cases: is
/// ξ_{k+1} = Λ(N_k) ξ_k stable for *every* delay sequence N_k ∈ \[`n_min`, `n_max`\]
/// (N ≥ 1), with the loop `h` (from [`loop_h`]; the delays here are the delays of
/// the delay block, D_k = N_k − q − l for an RC loop)?
///
/// The thesis checks the parameter-dependent LMIs (5.16) with an SDP solver. Without
/// one, this bounds the **joint spectral radius** ρ of {Λ(N)} instead, by
/// Gripenberg's branch-and-bound over products (norm: the Lyapunov norm of the
/// middle delay's Λ): ρ < 1 is exactly stability under arbitrary switching, which
/// any feasible (5.16) certifies; a product with spectral radius ≥ 1 is a
/// destabilising periodic sequence. Like (5.16) it does not use the small-gain
/// bound, so it is less conservative than (5.9) — and it is independent of it.
/// `max_nodes` caps the work ((M − m + 1)^depth products).
pub fn lifted_check(h: &StateSpace, n_min: usize, n_max: usize, max_nodes: usize) -> LiftedCheck {
    assert!(n_min >= 1 && n_max >= n_min, "need 1 ≤ n_min ≤ n_max");
    let mats: Vec<DMatrix<f64>> = (n_min..=n_max)
        .map(|n| lifted_matrix(h, n, n_max))
        .collect();
    let dim = mats[0].nrows();
    // Norm ‖R A R⁻¹‖₂ with P = RᵀR: the best of a few quadratic candidates (the
    // identity, the Lyapunov matrix of each Λ(N), and the averaged Lyapunov
    // matrix P = I + mean_N Λ(N)ᵀ P Λ(N)), by the largest one-step norm.
    let mut cands: Vec<DMatrix<f64>> = vec![DMatrix::identity(dim, dim)];
    for m in &mats {
        if let Some(p) = dlyap_identity(m) {
            cands.push(p);
        }
    }
    {
        let mut p = DMatrix::<f64>::identity(dim, dim);
        let inv = 1.0 / mats.len() as f64;
        let mut ok = false;
        for _ in 0..3000 {
            let mut np = DMatrix::<f64>::identity(dim, dim);
            for m in &mats {
                np += m.transpose() * &p * m * inv;
            }
            let diff = (&np - &p).norm();
            p = np;
            if !p.iter().all(|v| v.is_finite()) || p.norm() > 1e12 {
                break;
            }
            if diff <= 1e-10 * p.norm() {
                ok = true;
                break;
            }
        }
        if ok {
            cands.push(p);
        }
    }
    let mut best: Option<(f64, DMatrix<f64>, DMatrix<f64>)> = None;
    for p in cands {
        let Some(ch) = p.cholesky() else { continue };
        let r = ch.l().transpose();
        let Some(rinv) = r.clone().try_inverse() else {
            continue;
        };
        let worst = mats
            .iter()
            .map(|m| norm2(&(&r * m * &rinv)))
            .fold(0.0, f64::max);
        if best.as_ref().is_none_or(|b| worst < b.0) {
            best = Some((worst, r, rinv));
        }
    }
    let (_, r, rinv) = best.unwrap_or((
        0.0,
        DMatrix::identity(dim, dim),
        DMatrix::identity(dim, dim),
    ));
    let tm: Vec<DMatrix<f64>> = mats.iter().map(|m| &r * m * &rinv).collect();
    let mut lower = 0.0f64;
    let mut best_seq: Vec<usize> = vec![];
    for (i, m) in mats.iter().enumerate() {
        let s = spectral_radius(m);
        if s > lower {
            lower = s;
            best_seq = vec![n_min + i];
        }
    }
    // Frontier: (product in the R-basis, sequence, bound).
    let mut frontier: Vec<(DMatrix<f64>, Vec<u16>, f64)> = tm
        .iter()
        .enumerate()
        .map(|(i, m)| (m.clone(), vec![i as u16], norm2(m)))
        .collect();
    let mut pruned_max = 0.0f64;
    let mut nodes = frontier.len();
    let mut depth = 1usize;
    let mut exhausted = false;
    while !frontier.is_empty() {
        let mut next = Vec::new();
        for (p, seq, b) in frontier.drain(..) {
            if b < 1.0 {
                pruned_max = pruned_max.max(b);
                continue;
            }
            if nodes + tm.len() > max_nodes {
                exhausted = true;
                next.push((p, seq, b));
                continue;
            }
            for (i, m) in tm.iter().enumerate() {
                let prod = m * &p;
                let nb = b.min(norm2(&prod).powf(1.0 / (depth + 1) as f64));
                let mut s2 = seq.clone();
                s2.push(i as u16);
                // Spectral radius of the product (basis-invariant).
                let sr = spectral_radius(&prod).powf(1.0 / (depth + 1) as f64);
                if sr > lower {
                    lower = sr;
                    best_seq = s2.iter().map(|&j| n_min + j as usize).collect();
                }
                nodes += 1;
                next.push((prod, s2, nb));
            }
        }
        if exhausted {
            let fm = next.iter().map(|x| x.2).fold(0.0, f64::max);
            pruned_max = pruned_max.max(fm);
            break;
        }
        frontier = next;
        depth += 1;
        if lower >= 1.0 {
            // Decided: unstable.
            let fm = frontier.iter().map(|x| x.2).fold(0.0, f64::max);
            pruned_max = pruned_max.max(fm);
            break;
        }
    }
    let upper = pruned_max.max(lower);
    let verdict = if lower >= 1.0 {
        // Sequences are built product-last-applied-first: Λ_{s_d} ⋯ Λ_{s_1};
        // time order is s_1, s_2, ….
        LiftedVerdict::Unstable { sequence: best_seq }
    } else if upper < 1.0 {
        LiftedVerdict::Stable
    } else {
        LiftedVerdict::Inconclusive
    };
    LiftedCheck {
        rho_lower: lower,
        rho_upper: upper,
        nodes,
        verdict,
    }
}

/// Default limit on the scalar unknowns of [`lifted_lmi_check`]:
/// (M − m + 1)·d(d + 1)/2 with d = n_H + M. Problems near the limit (4 delays with
/// a 16-state lifted system = 544 unknowns, 2 delays with 23 states = 552) take
/// under a second even at the test profile (opt-level 1); the cost grows like the
/// cube of the unknowns.
pub const LIFTED_LMI_MAX_UNKNOWNS: usize = 600;

/// Scalar unknowns of (5.16) for an `nx`-state H and delays in
/// \[`n_min`, `n_max`\]: one symmetric P_N of size nx + M per delay.
pub fn lifted_lmi_unknowns(nx: usize, n_min: usize, n_max: usize) -> usize {
    let d = nx.saturating_add(n_max);
    let per = d.saturating_mul(d.saturating_add(1)) / 2;
    (n_max.saturating_sub(n_min).saturating_add(1)).saturating_mul(per)
}

/// How the LMIs (5.16) are posed to the solver (same feasibility set).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum LmiForm {
    /// P_i ≻ 0 and P_i − Λ(i)ᵀP_jΛ(i) ≻ 0 (the Schur complement of (5.16); half
    /// the matrix size, the default).
    #[default]
    Schur,
    /// \[P_i, Λ(i)ᵀP_j; P_jΛ(i), P_j\] ≻ 0, literally (5.16).
    Block,
}

/// Options of [`lifted_lmi_check`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LiftedLmiOptions {
    /// Schur-complement or block form.
    pub form: LmiForm,
    /// Solver options; `bound` normalises P_i ⪯ bound·I (default 1, so the
    /// margin is relative to ‖P_i‖ ≤ 1), `max_unknowns` defaults to
    /// [`LIFTED_LMI_MAX_UNKNOWNS`].
    pub solver: LmiOptions,
}

impl Default for LiftedLmiOptions {
    fn default() -> Self {
        Self {
            form: LmiForm::Schur,
            solver: LmiOptions {
                max_unknowns: LIFTED_LMI_MAX_UNKNOWNS,
                ..LmiOptions::default()
            },
        }
    }
}

/// Result of [`lifted_lmi_check`].
#[derive(Debug, Clone)]
pub struct LiftedLmi {
    /// Solver verdict: `Feasible` proves asymptotic stability of (5.13) for every
    /// delay sequence N_k ∈ \[m, M\] (V = ξᵀP_{N_k}ξ decreases along every
    /// trajectory); otherwise no such parameter-dependent quadratic Lyapunov
    /// function with normalised margin above `t_upper` exists (which does not by
    /// itself prove instability).
    pub status: LmiStatus,
    /// Verified min over all LMIs of λ_min (with P_i ⪯ I): > 0 when feasible.
    pub margin: f64,
    /// Upper bound on the normalised margin achievable (see
    /// [`LmiSolution::t_upper`](nanomotion_core::lti::lmi::LmiSolution::t_upper)).
    pub t_upper: f64,
    /// Lifted state dimension n_H + M.
    pub dim: usize,
    /// Number of delays M − m + 1 (number of P_i).
    pub n_delays: usize,
    /// Scalar unknowns.
    pub unknowns: usize,
    /// Number of LMIs: (M − m + 1)² (plus M − m + 1 for P_i ≻ 0 in the Schur form).
    pub n_lmis: usize,
    /// Newton steps of the solver.
    pub newton_steps: usize,
    /// The form used.
    pub form: LmiForm,
    /// m (smallest delay).
    pub n_min: usize,
    /// The certificate P_m, …, P_M (when feasible; else the solver's last
    /// iterate).
    pub p: Vec<DMatrix<f64>>,
    /// The bound on the joint spectral radius of {Λ(N)} that the certificate
    /// proves ([`LiftedLmi::jsr_bound`]; < 1 when feasible, `None` otherwise).
    pub jsr_upper: Option<f64>,
}

impl LiftedLmi {
    /// Whether (5.16) is feasible (stability for every N_k ∈ \[m, M\] proved).
    pub fn feasible(&self) -> bool {
        self.status == LmiStatus::Feasible
    }

    /// The upper bound on the joint spectral radius that the certificate gives:
    /// max_{i,j} ‖P_j^{1/2} Λ(i) P_i^{-1/2}‖₂ (< 1 when feasible). Computed with
    /// the Λ(N) of `h` (the same `h` as the check); `None` if not feasible.
    pub fn jsr_bound(&self, h: &StateSpace) -> Option<f64> {
        if !self.feasible() {
            return None;
        }
        let n_max = self.n_min + self.n_delays - 1;
        let mut worst: f64 = 0.0;
        for (i, pi) in self.p.iter().enumerate() {
            let lam = lifted_matrix(h, self.n_min + i, n_max);
            let li = pi.clone().cholesky()?.l(); // P_i = L Lᵀ
            let li_inv = li.try_inverse()?;
            for pj in &self.p {
                // λ_max(L⁻¹ ΛᵀP_jΛ L⁻ᵀ) = ‖P_j^{1/2} Λ P_i^{-1/2}‖².
                let m = &li_inv * lam.transpose() * pj * &lam * li_inv.transpose();
                let m = (&m + m.transpose()) * 0.5;
                let e = m
                    .symmetric_eigenvalues()
                    .iter()
                    .copied()
                    .fold(0.0, f64::max);
                worst = worst.max(e.max(0.0).sqrt());
            }
        }
        Some(worst)
    }
}

impl fmt::Display for LiftedLmi {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "lifted LMIs (5.16): {} P_N of size {} ({} unknowns, {} LMIs, {} Newton steps) → ",
            self.n_delays, self.dim, self.unknowns, self.n_lmis, self.newton_steps
        )?;
        match self.status {
            LmiStatus::Feasible => {
                write!(f, "feasible, margin {:.2e} (P_N ⪯ I)", self.margin)?;
                if let Some(b) = self.jsr_upper {
                    write!(
                        f,
                        ", certificate bounds the joint spectral radius by {b:.4}"
                    )?;
                }
                write!(f, ": stable for all N_k ∈ [m, M]")
            }
            LmiStatus::Infeasible | LmiStatus::InfeasibleWithinTolerance => write!(
                f,
                "infeasible (no parameter-dependent quadratic Lyapunov function with margin > {:.1e}): not proved",
                self.t_upper.max(0.0)
            ),
            LmiStatus::Undecided => write!(f, "undecided (solver budget): not proved"),
        }
    }
}

fn lmi_err(e: LmiError) -> LtiError {
    match e {
        LmiError::TooLarge { unknowns, limit } => LtiError::Parameter {
            name: "n_max",
            problem: format!(
                "lifted LMIs (5.16) too large: {unknowns} unknowns > limit {limit} (reduce n_max − n_min or the order of H)"
            ),
        },
        other => LtiError::Parameter {
            name: "lmi",
            problem: other.to_string(),
        },
    }
}

/// The lifted switched-system test with the thesis's LMIs (5.16): find
/// P_N ≻ 0, N ∈ \[`n_min`, `n_max`\], with
///
/// ```text
/// [ P_i        Λ(i)ᵀP_j ]
/// [ P_jΛ(i)    P_j      ]  ≻ 0   for all i, j ∈ [m, M]
/// ```
///
/// (equivalently P_i − Λ(i)ᵀP_jΛ(i) ≻ 0), Λ(N) from [`lifted_matrix`] (5.14)–(5.15)
/// for the loop `h` (from [`loop_h`]; delays of the delay block, D_k = N_k − q − l
/// for an RC loop). Feasibility means V(N_k, ξ_k) = ξ_kᵀP_{N_k}ξ_k is a
/// parameter-dependent Lyapunov function: the lifted system (5.13) is
/// asymptotically stable for **every** delay sequence in \[m, M\]. Solved by the
/// core's [`LmiProblem`] (primal barrier, certificate re-verified by eigenvalues);
/// an independent test next to [`lifted_check`] (joint spectral radius) and less
/// conservative than the small-gain criterion (5.9) (Remark 10 of the thesis).
///
/// Limits: for small cases only: (M − m + 1) unknown matrices of size n_H + M, i.e.
/// [`lifted_lmi_unknowns`] scalar unknowns, refused above
/// `opts.solver.max_unknowns` (default [`LIFTED_LMI_MAX_UNKNOWNS`]); the thesis
/// makes the same remark (its M ≈ 55 and n_H ≈ 118 are far beyond). Errors: SISO
/// discrete `h` and 1 ≤ `n_min` ≤ `n_max` required.
pub fn lifted_lmi_check(
    h: &StateSpace,
    n_min: usize,
    n_max: usize,
    opts: &LiftedLmiOptions,
) -> Result<LiftedLmi, LtiError> {
    if h.dt.is_none() {
        return Err(LtiError::Domain("H(z) must be discrete".into()));
    }
    if h.b.ncols() != 1 || h.c.nrows() != 1 {
        return Err(LtiError::Dimension(format!(
            "the lifted system needs a SISO H, got {} inputs and {} outputs",
            h.b.ncols(),
            h.c.nrows()
        )));
    }
    let nx = h.a.nrows();
    if h.a.ncols() != nx || h.b.nrows() != nx || h.c.ncols() != nx || h.d.shape() != (1, 1) {
        return Err(LtiError::Dimension(format!(
            "inconsistent H: A {:?}, B {:?}, C {:?}, D {:?}",
            h.a.shape(),
            h.b.shape(),
            h.c.shape(),
            h.d.shape()
        )));
    }
    if n_min == 0 {
        return Err(LtiError::Parameter {
            name: "n_min",
            problem: "the delay must be ≥ 1 sample".into(),
        });
    }
    if n_max < n_min {
        return Err(LtiError::Parameter {
            name: "n_max",
            problem: format!("{n_max} < n_min = {n_min}"),
        });
    }
    let all_finite = [&h.a, &h.b, &h.c, &h.d]
        .iter()
        .all(|m| m.iter().all(|v| v.is_finite()));
    if !all_finite {
        return Err(LtiError::Parameter {
            name: "h",
            problem: "non-finite entries in the state-space matrices".into(),
        });
    }
    let dim = h.nstates() + n_max;
    let n_delays = n_max - n_min + 1;
    let unknowns = lifted_lmi_unknowns(h.nstates(), n_min, n_max);
    if unknowns > opts.solver.max_unknowns {
        return Err(lmi_err(LmiError::TooLarge {
            unknowns,
            limit: opts.solver.max_unknowns,
        }));
    }
    let lams: Vec<DMatrix<f64>> = (n_min..=n_max)
        .map(|n| lifted_matrix(h, n, n_max))
        .collect();
    let mut lmi = LmiProblem::new();
    let ps: Vec<LmiVar> = (n_min..=n_max)
        .map(|n| lmi.variable(format!("P_{n}"), dim))
        .collect::<Result<_, _>>()
        .map_err(lmi_err)?;
    let build = |lmi: &mut LmiProblem| -> Result<(), LmiError> {
        match opts.form {
            LmiForm::Schur => {
                for (i, &pi) in ps.iter().enumerate() {
                    let mut c = LmiConstraint::new(format!("P_{} ≻ 0", n_min + i), dim);
                    c.var(pi, 1.0)?;
                    lmi.add(c)?;
                }
                for (i, &pi) in ps.iter().enumerate() {
                    for (j, &pj) in ps.iter().enumerate() {
                        let mut c = LmiConstraint::new(
                            format!(
                                "P_{a} − Λ({a})ᵀP_{b}Λ({a}) ≻ 0",
                                a = n_min + i,
                                b = n_min + j
                            ),
                            dim,
                        );
                        c.var(pi, 1.0)?.congruence(pj, &lams[i], -1.0)?;
                        lmi.add(c)?;
                    }
                }
            }
            LmiForm::Block => {
                let e1 = DMatrix::<f64>::identity(dim, dim).resize_horizontally(2 * dim, 0.0);
                let mut e2 = DMatrix::<f64>::zeros(dim, 2 * dim);
                e2.view_mut((0, dim), (dim, dim)).fill_with_identity();
                for (i, &pi) in ps.iter().enumerate() {
                    let le1 = &lams[i] * &e1;
                    for (j, &pj) in ps.iter().enumerate() {
                        let mut c = LmiConstraint::new(
                            format!("(5.16) i = {}, j = {}", n_min + i, n_min + j),
                            2 * dim,
                        );
                        c.congruence(pi, &e1, 1.0)?
                            .congruence(pj, &e2, 1.0)?
                            .sym_product(pj, &e2, &le1, 1.0)?;
                        lmi.add(c)?;
                    }
                }
            }
        }
        Ok(())
    };
    build(&mut lmi).map_err(lmi_err)?;
    let sol = lmi.solve(&opts.solver).map_err(lmi_err)?;
    let mut out = LiftedLmi {
        status: sol.status,
        margin: sol.margin,
        t_upper: sol.t_upper,
        dim,
        n_delays,
        unknowns,
        n_lmis: lmi.n_constraints(),
        newton_steps: sol.newton_steps,
        form: opts.form,
        n_min,
        p: sol.variables,
        jsr_upper: None,
    };
    out.jsr_upper = out.jsr_bound(h);
    Ok(out)
}

/// Simulate the interconnection of Fig. 5.2, x_{k+1} = A x + B v + E d,
/// q = C x + D v, v_k = q_{k−N_k} (zero history), with an additive disturbance d
/// on v (v_k = q_{k−N_k} + d_k). Returns (q, v). For tests and demonstrations.
pub fn simulate_delay_loop(h: &StateSpace, delays: &[usize], d: &[f64]) -> (Vec<f64>, Vec<f64>) {
    let n_max = delays.iter().copied().max().unwrap_or(1).max(1);
    let mut buf = crate::delay::VaryingDelay::new(n_max);
    let mut st = nanomotion_core::lti::SsStepper::new(h).expect("discrete H");
    let mut qs = Vec::with_capacity(delays.len());
    let mut vs = Vec::with_capacity(delays.len());
    let mut y = [0.0];
    for (k, &nk) in delays.iter().enumerate() {
        let v = buf.get(nk) + d.get(k).copied().unwrap_or(0.0);
        st.step(&[v], &mut y);
        buf.push(y[0]);
        qs.push(y[0]);
        vs.push(v);
    }
    (qs, vs)
}

/// The learning and robustness filters' combined delay l + q.
pub fn compensation(l: &Filter, q: &Filter) -> usize {
    l.preview_samples() + q.preview_samples()
}
