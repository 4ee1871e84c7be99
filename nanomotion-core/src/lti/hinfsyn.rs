//! H∞ output-feedback synthesis (continuous and discrete time) by the two-Riccati formulas of
//! Doyle, Glover, Khargonekar & Francis (1989) with γ-iteration, the generalised
//! plant of a mixed-sensitivity problem ([`augw`]) and the closed loop of a plant
//! and a controller ([`lft`]). SPEC §4 / thesis Ch. 7: the MIMO design
//! (7.5)–(7.12) is a mixed-sensitivity H∞ problem.
//!
//! The generalised plant P has inputs [w; u] and outputs [z; y]:
//!
//! ```text
//! ẋ = A x + B₁ w + B₂ u,   z = C₁ x + D₁₂ u,   y = C₂ x + D₂₁ w
//! ```
//!
//! Assumptions (checked, with a typed error naming the fix): D₁₂ of full column
//! rank, D₂₁ of full row rank, (A, B₂) stabilisable and (C₂, A) detectable,
//! and no invariant zeros of the two off-diagonal blocks on the imaginary axis
//! (otherwise the Riccati equations have no stabilising
//! solution at any γ). The cross terms D₁₂ᵀC₁ and B₁D₂₁ᵀ need not vanish.
//!
//! For a given γ a controller with ‖T_zw‖∞ < γ exists iff
//!
//! ```text
//! X: ÂₓᵀX + XÂₓ − X(B₂R₁⁻¹B₂ᵀ − γ⁻²B₁B₁ᵀ)X + C₁ᵀ(I − D₁₂R₁⁻¹D₁₂ᵀ)C₁ = 0,  Âₓ = A − B₂R₁⁻¹D₁₂ᵀC₁
//! Y: ÂᵧY + YÂᵧᵀ − Y(C₂ᵀR₂⁻¹C₂ − γ⁻²C₁ᵀC₁)Y + B₁(I − D₂₁ᵀR₂⁻¹D₂₁)B₁ᵀ = 0, Âᵧ = A − B₁D₂₁ᵀR₂⁻¹C₂
//! ```
//!
//! (R₁ = D₁₂ᵀD₁₂, R₂ = D₂₁D₂₁ᵀ) have stabilising solutions X, Y ⪰ 0 with
//! ρ(XY) < γ². The central controller is
//!
//! ```text
//! F = −R₁⁻¹(B₂ᵀX + D₁₂ᵀC₁),  L = −(YC₂ᵀ + B₁D₂₁ᵀ)R₂⁻¹,  Z = (I − γ⁻²YX)⁻¹
//! K: x̂' = (A + γ⁻²B₁B₁ᵀX + B₂F + ZL(C₂ + γ⁻²D₂₁B₁ᵀX)) x̂ − ZL y,  u = F x̂.
//! ```
//!
//! **General D.** D₂₂ ≠ 0 is removed by ȳ = y − D₂₂u (K = K₀(I + D₂₂K₀)⁻¹);
//! D₁₁ ≠ 0 (a biproper sensitivity weight; also needed by the thesis's (7.10)) by loop
//! shifting: a constant feed-through D_K = −D₁₂⁺D₁₁D₂₁⁺, then for each γ the
//! orthogonal Möbius map of Safonov, Limebeer & Chiang (1989) that sends
//! D̄₁₁/γ to 0 while preserving ‖·‖∞ < γ (γ > ‖D̄₁₁‖ is required; when
//! neither D₁₂ nor D₂₁ is square the least-squares D_K can be conservative
//! compared with Parrott's optimum).
//!
//! **Discrete time.** A discrete plant is mapped to continuous time by the
//! bilinear map s = (z − 1)/(z + 1), solved, and the controller mapped back.
//! The map preserves H∞ norms and stability **exactly** (it takes the unit
//! circle onto the imaginary axis), so nothing is approximated; the discrete
//! closed loop is re-verified with the discrete [`hinfnorm`].
//!
//! **Numerical limits.** Weights that make D₁₂ᵀD₁₂ or D₂₁D₂₁ᵀ tiny (≲ 1e-10
//! relative to the rest) or put Hamiltonian eigenvalues very near the axis
//! degrade γ; a returned controller still meets ‖T_zw‖∞ ≤ γ (checked).
//!
//! [`hinfsyn`] brackets γ from the data's own gain scale (never from γ = 1),
//! bisects to a relative tolerance, and returns the controller of the smallest
//! feasible γ whose closed loop passes the **independent** [`hinfnorm`] check
//! (near the optimum the Riccati tests can pass on round-off; then the next
//! verified γ is returned instead of an error) — a returned design always has
//! ‖T_zw‖∞ ≤ γ (checked).
//!
//! ```
//! use nalgebra::DMatrix;
//! use nanomotion_core::lti::{StateSpace, TransferFunction};
//! use nanomotion_core::lti::hinfsyn::{augw, hinfsyn, HinfSynOptions};
//! // G = 1/(s + 1); W1 = 10/(s + 0.01) on S, W2 = 0.1 on KS.
//! let g = TransferFunction::new(vec![1.0], vec![1.0, 1.0], None).unwrap().to_ss().unwrap();
//! let w1 = TransferFunction::new(vec![10.0], vec![1.0, 0.01], None).unwrap().to_ss().unwrap();
//! let w2 = StateSpace::gain(DMatrix::from_element(1, 1, 0.1), None);
//! let p = augw(&g, Some(&w1), Some(&w2), None).unwrap();
//! let syn = hinfsyn(&p, 1, 1, &HinfSynOptions::default()).unwrap();
//! assert!(syn.closed_loop_norm <= syn.gamma * (1.0 + 1e-6));
//! assert!(syn.closed_loop.is_stable());
//! ```

use super::discretise::{bilinear_c2d_unit, bilinear_d2c_unit};
use super::riccati::care_general;
use super::{LtiError, StateSpace, hinfnorm};
use nalgebra::DMatrix;

/// Options of [`hinfsyn`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct HinfSynOptions {
    /// Relative width of the final γ bracket (γ_hi − γ_lo)/γ_hi.
    pub gamma_rel_tol: f64,
    /// Largest γ tried before giving up (the problem is then infeasible: an
    /// assumption fails). The default, `f64::INFINITY`, sets no absolute
    /// bound: the search starts from the data's own gain scale
    /// ‖C₁‖‖B₁‖/‖A‖ + ‖D₁₁‖ (not from γ = 1) and stops 12 decades above it.
    pub gamma_max: f64,
}

impl Default for HinfSynOptions {
    fn default() -> Self {
        Self {
            gamma_rel_tol: 1e-4,
            gamma_max: f64::INFINITY,
        }
    }
}

/// Result of [`hinfsyn`].
#[derive(Debug, Clone, PartialEq)]
pub struct HinfSyn {
    /// The central controller at [`HinfSyn::gamma`] (inputs y, outputs u).
    pub controller: StateSpace,
    /// The γ the controller was built for (feasible end of the bracket).
    pub gamma: f64,
    /// The largest γ found infeasible (lower end of the bracket; 0 if none).
    pub gamma_infeasible: f64,
    /// Closed loop T_zw = F_l(P, K).
    pub closed_loop: StateSpace,
    /// ‖T_zw‖∞ by [`hinfnorm`] (≤ γ).
    pub closed_loop_norm: f64,
    /// The Riccati solutions X∞, Y∞ at γ.
    pub x: DMatrix<f64>,
    /// See [`HinfSyn::x`].
    pub y: DMatrix<f64>,
}

/// Partitioned matrices of a generalised plant (D₁₁ and D₂₂ handled outside).
struct Parts {
    a: DMatrix<f64>,
    b1: DMatrix<f64>,
    b2: DMatrix<f64>,
    c1: DMatrix<f64>,
    c2: DMatrix<f64>,
    d12: DMatrix<f64>,
    d21: DMatrix<f64>,
}

/// The plant after the γ-independent loop shifts: D₂₂ removed (ȳ = y − D₂₂u)
/// and the feed-through u = D_K y + ũ with D_K = −D₁₂⁺D₁₁D₂₁⁺ (least squares)
/// that leaves the smallest D̄₁₁ = D₁₁ + D₁₂D_KD₂₁ the data allow when D₁₂ or
/// D₂₁ is square.
struct Shifted {
    parts: Parts,
    d11: DMatrix<f64>,
    d22: DMatrix<f64>,
    dk: DMatrix<f64>,
}

fn pinv(m: &DMatrix<f64>) -> DMatrix<f64> {
    m.clone()
        .pseudo_inverse(1e-12 * m.norm().max(f64::MIN_POSITIVE))
        .unwrap_or_else(|_| DMatrix::zeros(m.ncols(), m.nrows()))
}

fn shifted(p: &StateSpace, ny: usize, nu: usize) -> Result<Shifted, LtiError> {
    let (n, ni, no) = (p.nstates(), p.ninputs(), p.noutputs());
    if nu == 0 || ny == 0 || nu >= ni || ny >= no {
        return Err(LtiError::Dimension(format!(
            "P has {ni} inputs and {no} outputs: ncon = {nu} and nmeas = {ny} must leave at least one w and one z"
        )));
    }
    let (nw, nz) = (ni - nu, no - ny);
    let d11 = p.d.view((0, 0), (nz, nw)).clone_owned();
    let d22 = p.d.view((nz, nw), (ny, nu)).clone_owned();
    let d12 = p.d.view((0, nw), (nz, nu)).clone_owned();
    let d21 = p.d.view((nz, 0), (ny, nw)).clone_owned();
    let rank = |m: &DMatrix<f64>| {
        let sv = m.clone().svd(false, false).singular_values;
        let top = sv.max();
        sv.iter().filter(|s| **s > 1e-10 * top.max(1e-300)).count()
    };
    if rank(&d12) < nu {
        return Err(LtiError::param(
            "p.d",
            "D12 (u → z) must have full column rank: weight every control input (W2 with a feed-through)",
        ));
    }
    if rank(&d21) < ny {
        return Err(LtiError::param(
            "p.d",
            "D21 (w → y) must have full row rank: every measurement needs noise or a reference from w",
        ));
    }
    let a = p.a.clone();
    let b1 = p.b.view((0, 0), (n, nw)).clone_owned();
    let b2 = p.b.view((0, nw), (n, nu)).clone_owned();
    let c1 = p.c.view((0, 0), (nz, n)).clone_owned();
    let c2 = p.c.view((nz, 0), (ny, n)).clone_owned();
    let dk = if d11.iter().all(|v| *v == 0.0) {
        DMatrix::zeros(nu, ny)
    } else {
        -(pinv(&d12) * &d11 * pinv(&d21))
    };
    Ok(Shifted {
        parts: Parts {
            a: &a + &b2 * &dk * &c2,
            b1: &b1 + &b2 * &dk * &d21,
            b2,
            c1: &c1 + &d12 * &dk * &c2,
            c2,
            d12: d12.clone(),
            d21: d21.clone(),
        },
        d11: &d11 + &d12 * &dk * &d21,
        d22,
        dk,
    })
}

/// Symmetric positive-definite square root (and None if not positive).
fn sqrt_pd(m: &DMatrix<f64>) -> Option<DMatrix<f64>> {
    let e = sym(m.clone()).symmetric_eigen();
    if e.eigenvalues.iter().any(|v| *v <= 0.0) {
        return None;
    }
    let d = DMatrix::from_diagonal(&e.eigenvalues.map(f64::sqrt));
    Some(&e.eigenvectors * d * e.eigenvectors.transpose())
}

/// For D̄₁₁ ≠ 0: the γ-dependent loop shift (Safonov, Limebeer & Chiang 1989)
/// that removes it. With Δ = D̄₁₁/γ (‖Δ‖ < 1) and the orthogonal matrix
/// Θ = [−Δ, (I − ΔΔᵀ)^½; (I − ΔᵀΔ)^½, Δᵀ], T̃ = F_l(Θ, T/γ) maps the open
/// unit ball onto itself with T = Δ ↦ 0, so ‖T‖∞ < γ ⇔ ‖T̃‖∞ < 1; T̃ is the
/// closed loop of the plant P̃ built here (D̃₁₁ = 0) with the same controller.
/// Returns P̃'s parts and its D̃₂₂ (in general ≠ 0), or None when ‖Δ‖ ≥ 1
/// (γ is then infeasible).
fn mobius_shift(s: &Shifted, gamma: f64) -> Option<(Parts, DMatrix<f64>)> {
    let p = &s.parts;
    let (nz, nw) = s.d11.shape();
    let delta = &s.d11 / gamma;
    let iz = DMatrix::<f64>::identity(nz, nz);
    let iw = DMatrix::<f64>::identity(nw, nw);
    let th12 = sqrt_pd(&(&iz - &delta * delta.transpose()))?;
    let th21 = sqrt_pd(&(&iw - delta.transpose() * &delta))?;
    let e = (&iw - delta.transpose() * &delta).try_inverse()?;
    let c1 = &p.c1 / gamma;
    let d12 = &p.d12 / gamma;
    let wx = &e * delta.transpose() * &c1;
    let ww = &e * &th21;
    let wu = &e * delta.transpose() * &d12;
    Some((
        Parts {
            a: &p.a + &p.b1 * &wx,
            b1: &p.b1 * &ww,
            b2: &p.b2 + &p.b1 * &wu,
            c1: &th12 * (&c1 + &delta * &wx),
            c2: &p.c2 + &p.d21 * &wx,
            d12: &th12 * (&d12 + &delta * &wu),
            d21: &p.d21 * &ww,
        },
        &p.d21 * &wu,
    ))
}

/// The controller for the plant with feed-through D₂₂ from the controller K₀
/// of the same plant with D₂₂ = 0 (ȳ = y − D₂₂u): K = K₀(I + D₂₂K₀)⁻¹.
fn undo_d22(k0: &StateSpace, d22: &DMatrix<f64>) -> Option<StateSpace> {
    if d22.iter().all(|v| *v == 0.0) {
        return Some(k0.clone());
    }
    let nu = k0.noutputs();
    let nmat = (DMatrix::<f64>::identity(nu, nu) + &k0.d * d22).try_inverse()?;
    let bd = &k0.b * d22 * &nmat;
    Some(StateSpace {
        a: &k0.a - &bd * &k0.c,
        b: &k0.b - &bd * &k0.d,
        c: &nmat * &k0.c,
        d: &nmat * &k0.d,
        dt: k0.dt,
    })
}

/// A controller with the X∞ and Y∞ it was built from.
type Design = (StateSpace, DMatrix<f64>, DMatrix<f64>);

/// A controller for the original plant at γ (all shifts undone), with the X∞
/// and Y∞ of the (shifted) problem, or None when γ is infeasible.
fn controller_at(s: &Shifted, gamma: f64) -> Option<Design> {
    let (k_bar, x, y) = if s.d11.iter().all(|v| *v == 0.0) {
        try_gamma(&s.parts, gamma)?
    } else {
        let (pt, d22t) = mobius_shift(s, gamma)?;
        let (k0, x, y) = try_gamma(&pt, 1.0)?;
        (undo_d22(&k0, &d22t)?, x, y)
    };
    let mut k = k_bar;
    k.d += &s.dk;
    Some((undo_d22(&k, &s.d22)?, x, y))
}

fn sym(m: DMatrix<f64>) -> DMatrix<f64> {
    (&m + m.transpose()) * 0.5
}

/// The central controller for γ, or None when the conditions fail at γ.
fn try_gamma(s: &Parts, gamma: f64) -> Option<(StateSpace, DMatrix<f64>, DMatrix<f64>)> {
    let n = s.a.nrows();
    let g2 = 1.0 / (gamma * gamma);
    let r1i = (s.d12.transpose() * &s.d12).try_inverse()?;
    let r2i = (&s.d21 * s.d21.transpose()).try_inverse()?;
    let ident_z = DMatrix::<f64>::identity(s.d12.nrows(), s.d12.nrows());
    let ident_w = DMatrix::<f64>::identity(s.d21.ncols(), s.d21.ncols());
    // X∞.
    let ax = &s.a - &s.b2 * &r1i * s.d12.transpose() * &s.c1;
    // Q of the X and Y equations, zeroed when it is round-off relative to its
    // own construction (C₁ᵀC₁, B₁B₁ᵀ): the usual y = e problems have Qy = 0
    // exactly, and the Riccati solver then returns X = 0 exactly.
    let exact_zero = |m: DMatrix<f64>, scale: f64| {
        if m.norm() <= 1e-13 * scale {
            DMatrix::zeros(m.nrows(), m.ncols())
        } else {
            m
        }
    };
    let qx = exact_zero(
        sym(s.c1.transpose() * (&ident_z - &s.d12 * &r1i * s.d12.transpose()) * &s.c1),
        (s.c1.transpose() * &s.c1).norm(),
    );
    let gx = sym(&s.b2 * &r1i * s.b2.transpose() - &s.b1 * s.b1.transpose() * g2);
    let (x, _) = care_general(&ax, &gx, &qx).ok()?;
    // Y∞ (the dual equation: transpose everything).
    let ay = &s.a - &s.b1 * s.d21.transpose() * &r2i * &s.c2;
    let qy = exact_zero(
        sym(&s.b1 * (&ident_w - s.d21.transpose() * &r2i * &s.d21) * s.b1.transpose()),
        (&s.b1 * s.b1.transpose()).norm(),
    );
    let gy = sym(s.c2.transpose() * &r2i * &s.c2 - s.c1.transpose() * &s.c1 * g2);
    let (y, _) = care_general(&ay.transpose(), &gy, &qy).ok()?;
    // X, Y ⪰ 0 and ρ(XY) < γ².
    let psd = |m: &DMatrix<f64>| {
        let e = m.clone().symmetric_eigen().eigenvalues;
        e.iter().all(|v| *v >= -1e-9 * m.norm())
    };
    if !psd(&x) || !psd(&y) {
        return None;
    }
    let rho = super::linalg::eigvals(&(&y * &x))
        .iter()
        .map(|l| l.norm())
        .fold(0.0, f64::max);
    if rho.is_nan() || rho >= gamma * gamma * (1.0 - 1e-9) {
        return None;
    }
    let f = -(&r1i * (s.b2.transpose() * &x + s.d12.transpose() * &s.c1));
    let l = -((&y * s.c2.transpose() + &s.b1 * s.d21.transpose()) * &r2i);
    let z = (DMatrix::identity(n, n) - &y * &x * g2).try_inverse()?;
    let zl = &z * &l;
    let ak = &s.a
        + &s.b1 * s.b1.transpose() * &x * g2
        + &s.b2 * &f
        + &zl * (&s.c2 + &s.d21 * s.b1.transpose() * &x * g2);
    let k = StateSpace {
        a: ak,
        b: -zl,
        c: f,
        d: DMatrix::zeros(s.b2.ncols(), s.c2.nrows()),
        dt: None,
    };
    Some((k, x, y))
}

/// H∞ synthesis by γ-iteration (see the [module docs](self)): `ny` measurements
/// (the last outputs of `p`) and `nu` controls (the last inputs).
pub fn hinfsyn(
    p: &StateSpace,
    ny: usize,
    nu: usize,
    opts: &HinfSynOptions,
) -> Result<HinfSyn, LtiError> {
    if !(opts.gamma_rel_tol > 0.0 && opts.gamma_rel_tol < 1.0) {
        return Err(LtiError::param(
            "gamma_rel_tol",
            "must be in (0, 1), e.g. 1e-4",
        ));
    }
    if opts.gamma_max.is_nan() || opts.gamma_max <= 0.0 {
        return Err(LtiError::param(
            "gamma_max",
            "must be positive (f64::INFINITY for no bound)",
        ));
    }
    p.validate()?;
    match p.dt {
        None => hinfsyn_continuous(p, ny, nu, opts),
        Some(dt) => {
            // The bilinear map s = (z − 1)/(z + 1) takes the unit circle onto
            // the imaginary axis and the open unit disc onto the open left half
            // plane, and commutes with interconnections: the continuous problem
            // has exactly the same attainable H∞ norms and the same stabilising
            // controllers (mapped back by z = (1 + s)/(1 − s)). No
            // approximation is involved; the discrete closed loop is checked
            // by the discrete hinfnorm.
            let pc = bilinear_d2c_unit(p)?;
            let syn = hinfsyn_continuous(&pc, ny, nu, opts)?;
            let controller = bilinear_c2d_unit(&syn.controller, dt)?;
            let closed_loop = lft(p, &controller, ny, nu)?;
            let norm = verified_norm(&closed_loop, syn.gamma)?;
            Ok(HinfSyn {
                controller,
                closed_loop,
                closed_loop_norm: norm,
                ..syn
            })
        }
    }
}

/// ‖T‖∞ by the independent [`hinfnorm`], or an error if T is unstable or the
/// norm exceeds γ.
fn verified_norm(cl: &StateSpace, gamma: f64) -> Result<f64, LtiError> {
    let norm = hinfnorm(cl)
        .map_err(|e| {
            LtiError::Singular(format!(
                "the γ = {gamma:.6e} controller does not stabilise the plant ({e})"
            ))
        })?
        .norm;
    if norm > gamma * (1.0 + 1e-6) {
        return Err(LtiError::Singular(format!(
            "the γ = {gamma:.6e} controller gives ‖T_zw‖∞ = {norm:.6e} > γ"
        )));
    }
    Ok(norm)
}

fn hinfsyn_continuous(
    p: &StateSpace,
    ny: usize,
    nu: usize,
    opts: &HinfSynOptions,
) -> Result<HinfSyn, LtiError> {
    let s = shifted(p, ny, nu)?;
    // Lower bound: ‖D̄₁₁‖₂, the largest singular value (the loop-shifted direct
    // term cannot be reduced). Not the Frobenius norm, which is larger for a
    // MIMO D̄₁₁ (√3·k_S for the thesis's 3-axis W_S) and would cut the γ search.
    let lb = s.d11.clone().singular_values().max();
    // A starting γ from the data, not from γ = 1: the gain scale
    // ‖C₁‖‖B₁‖/‖A‖ of the open loop w → z plus its direct term.
    let sp = &s.parts;
    let an = sp.a.norm();
    let scale = if an > 0.0 {
        sp.c1.norm() * sp.b1.norm() / an
    } else {
        sp.c1.norm() * sp.b1.norm()
    };
    let mut g0 = (scale + lb).max(2.0 * lb);
    if !(g0.is_finite() && g0 > 0.0) {
        g0 = (p.d.norm() + p.c.norm() + p.b.norm()).max(f64::MIN_POSITIVE);
    }
    let range = 1e12;
    let top = opts.gamma_max.min(g0 * range);
    let floor = (g0 / range).max(lb);
    let mut feasible: Vec<(f64, Design)> = Vec::new();
    let mut lo;
    let mut hi;
    match controller_at(&s, g0) {
        Some(k) => {
            hi = g0;
            feasible.push((g0, k));
            loop {
                let next = hi / 4.0;
                if next <= floor {
                    lo = floor;
                    break;
                }
                match controller_at(&s, next) {
                    Some(k) => {
                        hi = next;
                        feasible.push((next, k));
                    }
                    None => {
                        lo = next;
                        break;
                    }
                }
            }
        }
        None => {
            lo = g0;
            hi = g0;
            loop {
                hi *= 4.0;
                if hi > top {
                    return Err(LtiError::Singular(format!(
                        "no controller with ‖T_zw‖∞ < {top:.3e}: check that (A, B2) is stabilisable, (C2, A) detectable and that P12, P21 have no zeros on the imaginary axis (weights with poles on the axis: move them to −ε)"
                    )));
                }
                if let Some(k) = controller_at(&s, hi) {
                    feasible.push((hi, k));
                    break;
                }
                lo = hi;
            }
        }
    }
    while hi - lo > opts.gamma_rel_tol * hi {
        let mid = 0.5 * (lo + hi);
        match controller_at(&s, mid) {
            Some(k) => {
                hi = mid;
                feasible.push((mid, k));
            }
            None => lo = mid,
        }
    }
    // Every returned controller is verified by the independent hinfnorm; near
    // the optimum the Riccati conditions can pass on round-off, so the best
    // γ whose controller verifies is returned.
    feasible.sort_by(|a, b| a.0.total_cmp(&b.0));
    let mut last_err = None;
    for (gamma, (controller, x, y)) in feasible {
        let closed_loop = lft(p, &controller, ny, nu)?;
        match verified_norm(&closed_loop, gamma) {
            Ok(norm) => {
                return Ok(HinfSyn {
                    controller,
                    gamma,
                    gamma_infeasible: lo,
                    closed_loop,
                    closed_loop_norm: norm,
                    x,
                    y,
                });
            }
            Err(e) => last_err = Some(e),
        }
    }
    Err(last_err.unwrap_or_else(|| LtiError::Singular("no feasible γ".into())))
}

/// Lower linear fractional transformation F_l(P, K): the closed loop from w to z
/// when u = K y, for P with inputs [w; u] (the last `nu` are u) and outputs
/// [z; y] (the last `ny` are y). P may have a feed-through D₂₂ (then
/// I − D_K D₂₂ must be invertible: a well-posed loop).
pub fn lft(p: &StateSpace, k: &StateSpace, ny: usize, nu: usize) -> Result<StateSpace, LtiError> {
    p.validate()?;
    k.validate()?;
    if p.dt != k.dt {
        return Err(LtiError::SampleTime(p.dt, k.dt));
    }
    let (n, ni, no) = (p.nstates(), p.ninputs(), p.noutputs());
    if nu >= ni || ny >= no || k.ninputs() != ny || k.noutputs() != nu {
        return Err(LtiError::Dimension(format!(
            "lft: P is {no}×{ni}, K is {}×{} (must be nu × ny = {nu} × {ny})",
            k.noutputs(),
            k.ninputs()
        )));
    }
    let (nw, nz) = (ni - nu, no - ny);
    let a = &p.a;
    let b1 = p.b.view((0, 0), (n, nw));
    let b2 = p.b.view((0, nw), (n, nu));
    let c1 = p.c.view((0, 0), (nz, n));
    let c2 = p.c.view((nz, 0), (ny, n));
    let d11 = p.d.view((0, 0), (nz, nw));
    let d12 = p.d.view((0, nw), (nz, nu));
    let d21 = p.d.view((nz, 0), (ny, nw));
    let d22 = p.d.view((nz, nw), (ny, nu));
    let nk = k.nstates();
    // u = M(Ck xk + Dk C2 x + Dk D21 w), M = (I − Dk D22)⁻¹.
    let m = (DMatrix::<f64>::identity(nu, nu) - &k.d * d22)
        .try_inverse()
        .ok_or_else(|| {
            LtiError::Singular("lft: I − D_K D22 is singular (an ill-posed loop)".into())
        })?;
    let ux = &m * &k.d * c2;
    let uk = &m * &k.c;
    let uw = &m * &k.d * d21;
    // y = C2 x + D21 w + D22 u.
    let yx = c2 + d22 * &ux;
    let yk = d22 * &uk;
    let yw = d21 + d22 * &uw;
    let mut acl = DMatrix::zeros(n + nk, n + nk);
    acl.view_mut((0, 0), (n, n)).copy_from(&(a + b2 * &ux));
    acl.view_mut((0, n), (n, nk)).copy_from(&(b2 * &uk));
    acl.view_mut((n, 0), (nk, n)).copy_from(&(&k.b * &yx));
    acl.view_mut((n, n), (nk, nk))
        .copy_from(&(&k.a + &k.b * &yk));
    let mut bcl = DMatrix::zeros(n + nk, nw);
    bcl.view_mut((0, 0), (n, nw)).copy_from(&(b1 + b2 * &uw));
    bcl.view_mut((n, 0), (nk, nw)).copy_from(&(&k.b * &yw));
    let mut ccl = DMatrix::zeros(nz, n + nk);
    ccl.view_mut((0, 0), (nz, n)).copy_from(&(c1 + d12 * &ux));
    ccl.view_mut((0, n), (nz, nk)).copy_from(&(d12 * &uk));
    let dcl = d11 + d12 * &uw;
    Ok(StateSpace {
        a: acl,
        b: bcl,
        c: ccl,
        d: dcl,
        dt: p.dt,
    })
}

/// Generalised plant of the mixed-sensitivity problem ‖[W₁S; W₂KS; W₃T]‖∞ < γ
/// (MATLAB `augw`): inputs [w; u], outputs [z₁; z₂; z₃; y] with e = y = w − G u,
/// z₁ = W₁e, z₂ = W₂u, z₃ = W₃Gu. G is p×m; W₁ p×p, W₂ m×m, W₃ p×p (each
/// optional, at least one given). All continuous.
pub fn augw(
    g: &StateSpace,
    w1: Option<&StateSpace>,
    w2: Option<&StateSpace>,
    w3: Option<&StateSpace>,
) -> Result<StateSpace, LtiError> {
    g.validate()?;
    for w in [w1, w2, w3].into_iter().flatten() {
        w.validate()?;
    }
    let (p, m) = (g.noutputs(), g.ninputs());
    if w1.is_none() && w2.is_none() && w3.is_none() {
        return Err(LtiError::param("w1", "give at least one weight"));
    }
    for (name, w, size) in [("w1", w1, p), ("w2", w2, m), ("w3", w3, p)] {
        if let Some(w) = w {
            if w.dt != g.dt {
                return Err(LtiError::SampleTime(g.dt, w.dt));
            }
            if w.ninputs() != size || w.noutputs() != size {
                return Err(LtiError::Dimension(format!(
                    "`{name}` is {}×{}, expected {size}×{size}",
                    w.noutputs(),
                    w.ninputs()
                )));
            }
        }
    }
    let ng = g.nstates();
    let dims = [w1, w2, w3].map(|w| w.map_or(0, |w| w.nstates()));
    let outs = [w1, w2, w3].map(|w| w.map_or(0, |w| w.noutputs()));
    let n = ng + dims.iter().sum::<usize>();
    let nz: usize = outs.iter().sum();
    let (ni, no) = (p + m, nz + p);
    let mut a = DMatrix::zeros(n, n);
    let mut b = DMatrix::zeros(n, ni);
    let mut c = DMatrix::zeros(no, n);
    let mut d = DMatrix::zeros(no, ni);
    // G: ẋg = Ag xg + Bg u.
    a.view_mut((0, 0), (ng, ng)).copy_from(&g.a);
    b.view_mut((0, p), (ng, m)).copy_from(&g.b);
    // e = w − Cg xg − Dg u, as rows of (x, [w; u]).
    let mut e_c = DMatrix::zeros(p, n);
    e_c.view_mut((0, 0), (p, ng)).copy_from(&(-&g.c));
    let mut e_d = DMatrix::zeros(p, ni);
    e_d.view_mut((0, 0), (p, p))
        .copy_from(&DMatrix::identity(p, p));
    e_d.view_mut((0, p), (p, m)).copy_from(&(-&g.d));
    // Gu = Cg xg + Dg u.
    let mut gu_c = DMatrix::zeros(p, n);
    gu_c.view_mut((0, 0), (p, ng)).copy_from(&g.c);
    let mut gu_d = DMatrix::zeros(p, ni);
    gu_d.view_mut((0, p), (p, m)).copy_from(&g.d);
    // u as rows of (x, [w; u]).
    let u_c = DMatrix::zeros(m, n);
    let mut u_d = DMatrix::zeros(m, ni);
    u_d.view_mut((0, p), (m, m))
        .copy_from(&DMatrix::identity(m, m));
    let inputs = [(&e_c, &e_d), (&u_c, &u_d), (&gu_c, &gu_d)];
    let mut state = ng;
    let mut row = 0;
    for (i, w) in [w1, w2, w3].into_iter().enumerate() {
        let Some(w) = w else { continue };
        let (ic, id) = inputs[i];
        let nw = w.nstates();
        // ẋw = Aw xw + Bw v, z = Cw xw + Dw v, v = ic x + id [w; u].
        a.view_mut((state, state), (nw, nw)).copy_from(&w.a);
        let bw_ic = &w.b * ic;
        let cur = a.view((state, 0), (nw, n)) + bw_ic;
        a.view_mut((state, 0), (nw, n)).copy_from(&cur);
        b.view_mut((state, 0), (nw, ni)).copy_from(&(&w.b * id));
        let mut zc = &w.d * ic;
        let with_c = zc.view((0, state), (w.noutputs(), nw)) + &w.c;
        zc.view_mut((0, state), (w.noutputs(), nw))
            .copy_from(&with_c);
        c.view_mut((row, 0), (w.noutputs(), n)).copy_from(&zc);
        d.view_mut((row, 0), (w.noutputs(), ni))
            .copy_from(&(&w.d * id));
        state += nw;
        row += w.noutputs();
    }
    c.view_mut((nz, 0), (p, n)).copy_from(&e_c);
    d.view_mut((nz, 0), (p, ni)).copy_from(&e_d);
    Ok(StateSpace {
        a,
        b,
        c,
        d,
        dt: g.dt,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::lti::{Complex, TransferFunction, feedback, series};

    fn tf(num: &[f64], den: &[f64]) -> StateSpace {
        TransferFunction::new(num.to_vec(), den.to_vec(), None)
            .unwrap()
            .to_ss()
            .unwrap()
    }

    fn gain(k: f64) -> StateSpace {
        StateSpace::gain(DMatrix::from_element(1, 1, k), None)
    }

    #[test]
    fn augw_is_the_mixed_sensitivity_interconnection() {
        // Close the loop with a PI by lft and compare each channel with S, KS, T.
        let g = tf(&[2.0], &[1.0, 3.0, 2.0]);
        let w1 = tf(&[5.0], &[1.0, 0.1]);
        let w2 = tf(&[0.2, 0.1], &[1.0, 10.0]);
        let w3 = tf(&[1.0, 1.0], &[0.01, 1.0]); // biproper: D ≠ 0
        let p = augw(&g, Some(&w1), Some(&w2), Some(&w3)).unwrap();
        let k = tf(&[3.0, 1.5], &[1.0, 0.0]);
        let cl = lft(&p, &k, 1, 1).unwrap();
        let one = gain(1.0);
        let l = series(&k, &g).unwrap();
        let s = feedback(&one, &l, -1.0).unwrap();
        let ks = series(&s, &k).unwrap();
        let t = feedback(&l, &one, -1.0).unwrap();
        for w in [0.01, 0.3, 1.0, 7.0, 100.0] {
            let at = |sys: &StateSpace| sys.freqresp_siso_at(w);
            let got = cl.evalfr(Complex::new(0.0, w));
            let want = [at(&w1) * at(&s), at(&w2) * at(&ks), at(&w3) * at(&t)];
            for (i, want) in want.iter().enumerate() {
                assert!(
                    (got[(i, 0)] - want).norm() < 1e-9 * want.norm().max(1e-6),
                    "w = {w}, z{i}: {} vs {want}",
                    got[(i, 0)]
                );
            }
        }
    }

    /// One-block problem with a right-half-plane zero z of a stable G:
    /// inf_K ‖W₁S‖∞ = |W₁(z)| (interpolation: S(z) = 1 for every stabilising K;
    /// the infimum needs an improper S, so it is approached only as the weight
    /// W₂ = ε on KS vanishes). γ_opt(ε) must stay above the bound, fall as ε
    /// falls, and close in on it.
    #[test]
    fn rhp_zero_bound_is_approached() {
        let g = tf(&[-1.0, 1.0], &[1.0, 3.0, 2.0]); // (1 − s)/((s + 1)(s + 2)), z = 1
        let w1 = tf(&[2.0], &[1.0, 1.0]); // 2/(s + 1): |W₁(1)| = 1
        let bound = 1.0;
        let mut last = f64::INFINITY;
        // (Below ε ≈ 1e-5, D₁₂ᵀD₁₂ = ε² ≈ 1e-10 and the Riccati equations lose
        // accuracy: γ stops improving; see the module docs.)
        for eps in [1e-2, 1e-3, 1e-4, 1e-5] {
            let p = augw(&g, Some(&w1), Some(&gain(eps)), None).unwrap();
            let syn = hinfsyn(&p, 1, 1, &HinfSynOptions::default()).unwrap();
            println!("ε = {eps:e}: γ = {:.6}, bound {bound:.6}", syn.gamma);
            assert!(syn.gamma >= bound, "{} < {bound}", syn.gamma);
            assert!(syn.gamma < last, "ε = {eps}: {} ≥ {last}", syn.gamma);
            assert!(syn.closed_loop.is_stable());
            assert!(syn.closed_loop_norm <= syn.gamma * (1.0 + 1e-6));
            assert!(syn.closed_loop_norm >= syn.gamma_infeasible * (1.0 - 1e-6));
            last = syn.gamma;
        }
        assert!(last < 1.006 * bound, "{last} vs {bound}");
    }

    #[test]
    fn synthesis_beats_a_hand_tuned_pi_and_its_gamma_is_tight() {
        let g = tf(&[1.0], &[1.0, 0.2, 1.0]); // lightly damped resonance
        let w1 = tf(&[1.0], &[1.0, 0.001]);
        let w2 = gain(0.5);
        let p = augw(&g, Some(&w1), Some(&w2), None).unwrap();
        let opts = HinfSynOptions {
            gamma_rel_tol: 1e-6,
            ..Default::default()
        };
        let syn = hinfsyn(&p, 1, 1, &opts).unwrap();
        // A PI with integral action on the same generalised plant.
        let pi = tf(&[0.3, 0.2], &[1.0, 0.0]);
        let cl_pi = lft(&p, &pi, 1, 1).unwrap();
        let pi_norm = hinfnorm(&cl_pi).unwrap().norm;
        assert!(
            syn.closed_loop_norm < pi_norm,
            "{} vs PI {pi_norm}",
            syn.closed_loop_norm
        );
        // The bracket is tight and the achieved norm sits inside it.
        assert!(syn.gamma - syn.gamma_infeasible <= 1e-6 * syn.gamma);
        assert!(syn.closed_loop_norm >= syn.gamma_infeasible * (1.0 - 1e-5));
        assert!(syn.closed_loop_norm <= syn.gamma * (1.0 + 1e-6));
    }

    #[test]
    fn mimo_two_by_two_with_coupling() {
        // Two resonant axes with static coupling (the shape of (7.1)).
        let a = DMatrix::from_row_slice(
            4,
            4,
            &[
                0.0, 1.0, 0.0, 0.0, -1.0, -0.1, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, -1.2, -0.1,
            ],
        );
        let b = DMatrix::from_row_slice(4, 2, &[0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0]);
        let c = DMatrix::from_row_slice(2, 4, &[1.0, 0.0, 0.05, 0.0, -0.03, 0.0, 1.0, 0.0]);
        let g = StateSpace::new(a, b, c, DMatrix::zeros(2, 2), None).unwrap();
        let w1 = StateSpace::new(
            DMatrix::identity(2, 2) * -0.001,
            DMatrix::identity(2, 2),
            DMatrix::identity(2, 2) * 0.5,
            DMatrix::zeros(2, 2),
            None,
        )
        .unwrap();
        let w2 = StateSpace::gain(DMatrix::identity(2, 2) * 0.3, None);
        let p = augw(&g, Some(&w1), Some(&w2), None).unwrap();
        let syn = hinfsyn(&p, 2, 2, &HinfSynOptions::default()).unwrap();
        assert!(syn.closed_loop.is_stable());
        assert!(syn.closed_loop_norm <= syn.gamma * (1.0 + 1e-6));
        assert_eq!(
            (syn.controller.ninputs(), syn.controller.noutputs()),
            (2, 2)
        );
    }

    #[test]
    fn violated_assumptions_are_typed_errors() {
        let g = tf(&[1.0], &[1.0, 1.0]);
        // No weight on u: D12 = 0.
        let p = augw(&g, Some(&tf(&[1.0], &[1.0, 0.01])), None, None).unwrap();
        let e = hinfsyn(&p, 1, 1, &HinfSynOptions::default()).unwrap_err();
        assert!(e.to_string().contains("D12"), "{e}");
        // A weight with a pole on the axis (pure integrator) has no solution.
        let p = augw(&g, Some(&tf(&[1.0], &[1.0, 0.0])), Some(&gain(0.1)), None).unwrap();
        let e = hinfsyn(&p, 1, 1, &HinfSynOptions::default()).unwrap_err();
        assert!(e.to_string().contains("imaginary axis"), "{e}");
        let e = hinfsyn(
            &p,
            1,
            1,
            &HinfSynOptions {
                gamma_rel_tol: 0.0,
                ..Default::default()
            },
        )
        .unwrap_err();
        assert!(e.to_string().contains("gamma_rel_tol"), "{e}");
        assert!(matches!(
            hinfsyn(&p, 0, 1, &HinfSynOptions::default()),
            Err(LtiError::Dimension(_))
        ));
    }
}
