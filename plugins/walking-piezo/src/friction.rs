//! The x-direction model (4.7)–(4.10) and its dedicated time-stepping solver
//! (4.16)–(4.19).
//!
//! The stage (mass M_s) is driven only through set-valued Coulomb friction with
//! the two massless leg pairs (stiffness k_xi, damping d_xi, piezo force
//! F_xi = k_xi x_pi):
//!
//! M_s ẍ_s = λ1 + λ2 + F_ext,    k_xi x_i + d_xi ẋ_i = F_xi − λ_i,
//! λ_i ∈ μ_i F_Ni Sign(ẋ_i − ẋ_s)                                  (4.9), (4.10)
//!
//! (F_ext is an external force on the stage, e.g. gravity on a tilted stage — the
//! way the thesis measured μ; zero in the thesis's equations.)
//!
//! One step of length Δt: backward Euler (4.16) for given λ, and the friction law
//! in proximal-point form (4.18)–(4.19), solved by the fixed-point iteration
//! λ^{L+1} = prox_C(λ^L + r·g(λ^L)), g_i = (x_i,E − x_i,A)/Δt − ẋ_s,E the slip
//! velocity, C_i = [−μ_i F_Ni, μ_i F_Ni], until |λ^{L+1} − λ^L| < ε or the
//! iteration cap is hit — which is *reported*, never hidden.
//!
//! Sticking is exact in the sense of the set-valued law: at a converged interior
//! λ the slip is |g| < ε/r.
//!
//! Because g depends affinely on λ, g = a − Wλ with the constant symmetric
//! positive-definite W = diag(1/(d_xi + k_xi Δt)) + (Δt/M_s)·11ᵀ, the iteration is a
//! projected gradient method on a strictly convex quadratic over a box.
//!
//! **One r per contact.** Contact i uses r_i = r·s_i with s_i = tr W/(2W_ii)
//! (Jacobi scaling; the time-stepping literature allows an r_i per contact). Pairs
//! with equal legs have W₁₁ = W₂₂, s_i = 1 exactly and the scalar iteration of
//! (4.18). Pairs whose dampings differ by orders of magnitude make W badly
//! conditioned, and a single r then needs thousands of iterations; the scaling
//! makes the rate depend only on the coupling W₁₂/√(W₁₁W₂₂). The iteration
//! converges for 0 < r < 2/λ_max(S^½WS^½) ([`XCoefficients::max_r`]) and fastest
//! near r* = 2/(λ_min + λ_max) of that matrix = 2/tr W, the default
//! ([`XCoefficients::optimal_r`]).

/// Mechanical state of the x-model.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct XState {
    /// Stage position x_s (m).
    pub x_s: f64,
    /// Stage velocity ẋ_s (m/s).
    pub v_s: f64,
    /// Leg tip positions x_1, x_2 (m).
    pub x_leg: [f64; 2],
}

/// Constant coefficients of one step (depend on parameters and Δt only).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct XCoefficients {
    /// Step Δt (s).
    pub dt: f64,
    /// Stage mass M_s (kg).
    pub mass: f64,
    /// Leg stiffness k_x1, k_x2 (N/m).
    pub k: [f64; 2],
    /// Leg damping d_x1, d_x2 (N·s/m).
    pub d: [f64; 2],
}

impl XCoefficients {
    /// The matrix W of g = a − Wλ, as (W11, W12, W22).
    pub fn w(&self) -> (f64, f64, f64) {
        let tau = self.dt / self.mass;
        (
            1.0 / (self.d[0] + self.k[0] * self.dt) + tau,
            tau,
            1.0 / (self.d[1] + self.k[1] * self.dt) + tau,
        )
    }

    /// Eigenvalues (λ_min, λ_max) of W.
    pub fn w_eigenvalues(&self) -> (f64, f64) {
        let (a, b, c) = self.w();
        let m = 0.5 * (a + c);
        let r = (0.25 * (a - c) * (a - c) + b * b).sqrt();
        (m - r, m + r)
    }

    /// The per-contact factors s_i = tr W/(2W_ii) of r_i = r·s_i (both exactly 1
    /// for equal legs).
    pub fn contact_scale(&self) -> [f64; 2] {
        let (a, _, c) = self.w();
        let tr = a + c;
        [tr / (2.0 * a), tr / (2.0 * c)]
    }

    /// Eigenvalues (λ_min, λ_max) of the scaled S^½WS^½, S = diag(s_i): the
    /// matrix whose condition sets the iteration's rate.
    pub fn scaled_w_eigenvalues(&self) -> (f64, f64) {
        let (a, b, c) = self.w();
        let s = self.contact_scale();
        let (a, b, c) = (a * s[0], b * (s[0] * s[1]).sqrt(), c * s[1]);
        let m = 0.5 * (a + c);
        let r = (0.25 * (a - c) * (a - c) + b * b).sqrt();
        (m - r, m + r)
    }

    /// r* = 2/(λ_min + λ_max) of S^½WS^½ = 2/tr W (N·s/m), the fastest
    /// contraction of the fixed-point iteration for the linear part.
    pub fn optimal_r(&self) -> f64 {
        let (lo, hi) = self.w_eigenvalues();
        2.0 / (lo + hi)
    }

    /// Largest r (N·s/m) for which the iteration is guaranteed to converge.
    pub fn max_r(&self) -> f64 {
        2.0 / self.scaled_w_eigenvalues().1
    }
}

/// Settings of the fixed-point iteration.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FixedPointSettings {
    /// r > 0 of (4.18) (N·s/m).
    pub r: f64,
    /// Tolerance ε on |λ^{L+1} − λ^L| (N).
    pub tol_n: f64,
    /// Iteration cap.
    pub max_iter: u32,
}

/// Result of one x-step.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct XStep {
    /// State at the end of the step.
    pub state: XState,
    /// Friction forces λ1, λ2 on the stage (N).
    pub lambda: [f64; 2],
    /// Slip velocities g_i = ẋ_i − ẋ_s at the end of the step (m/s).
    pub slip: [f64; 2],
    /// Iterations used.
    pub iterations: u32,
    /// Last |λ^{L+1} − λ^L| (N).
    pub residual_n: f64,
    /// Whether the tolerance was met before the cap.
    pub converged: bool,
}

/// Evaluate (4.16) for given λ: leg velocities, stage velocity and slip.
#[inline]
fn evaluate(
    c: &XCoefficients,
    a: &XState,
    f_x: &[f64; 2],
    f_ext: f64,
    lam: &[f64; 2],
) -> ([f64; 2], f64, [f64; 2]) {
    let v_e = a.v_s + (lam[0] + lam[1] + f_ext) * c.dt / c.mass;
    // (x_i,E − x_i,A)/Δt with x_i,E = (d x_i,A + (F_xi − λ_i)Δt)/(d + kΔt), written
    // without the cancellation.
    let vl = [
        (f_x[0] - c.k[0] * a.x_leg[0] - lam[0]) / (c.d[0] + c.k[0] * c.dt),
        (f_x[1] - c.k[1] * a.x_leg[1] - lam[1]) / (c.d[1] + c.k[1] * c.dt),
    ];
    (vl, v_e, [vl[0] - v_e, vl[1] - v_e])
}

/// One step of the dedicated time-stepping solver (4.16)–(4.19).
///
/// `a`: state at t_A; `f_x`: piezo forces F_x1,2 = k_xi x_pi (N) (4.7)/(4.8);
/// `f_ext`: external force on the stage (N); `bound`: μ_i F_Ni ≥ 0 (N);
/// `lambda0`: initial estimate (the previous step's λ, step 3 of the scheme).
///
/// ```
/// use walking_piezo::friction::*;
/// let c = XCoefficients { dt: 25e-6, mass: 0.428, k: [5e6; 2], d: [100.0; 2] };
/// let set = FixedPointSettings { r: c.optimal_r(), tol_n: 1e-10, max_iter: 100 };
/// // Stage at rest, legs unloaded, pushed by 1 N against 0.2·55 N of friction on
/// // pair 1: it sticks (the leg takes the force elastically).
/// let s = step_x(&c, &XState::default(), &[0.0; 2], 1.0, &[11.0, 0.0], &[0.0; 2], &set);
/// assert!(s.converged);
/// assert!(s.slip[0].abs() < 1e-10 / set.r);
/// ```
pub fn step_x(
    c: &XCoefficients,
    a: &XState,
    f_x: &[f64; 2],
    f_ext: f64,
    bound: &[f64; 2],
    lambda0: &[f64; 2],
    s: &FixedPointSettings,
) -> XStep {
    let mut lam = [
        lambda0[0].clamp(-bound[0], bound[0]),
        lambda0[1].clamp(-bound[1], bound[1]),
    ];
    let scale = c.contact_scale();
    let r = [s.r * scale[0], s.r * scale[1]];
    let mut iterations = 0;
    let mut residual = f64::INFINITY;
    let mut converged = false;
    while iterations < s.max_iter {
        iterations += 1;
        let (_, _, g) = evaluate(c, a, f_x, f_ext, &lam);
        let next = [
            (lam[0] + r[0] * g[0]).clamp(-bound[0], bound[0]),
            (lam[1] + r[1] * g[1]).clamp(-bound[1], bound[1]),
        ];
        residual = (next[0] - lam[0]).abs().max((next[1] - lam[1]).abs());
        lam = next;
        // NaN residual fails this test and runs into the cap: reported.
        if residual < s.tol_n {
            converged = true;
            break;
        }
    }
    let (vl, v_e, g) = evaluate(c, a, f_x, f_ext, &lam);
    let state = XState {
        x_s: a.x_s + v_e * c.dt,
        v_s: v_e,
        x_leg: [a.x_leg[0] + vl[0] * c.dt, a.x_leg[1] + vl[1] * c.dt],
    };
    XStep {
        state,
        lambda: lam,
        slip: g,
        iterations,
        residual_n: residual,
        converged,
    }
}

/// Mechanical energy ½M_s ẋ_s² + Σ ½k_xi (x_i − x_pi)² of the x-model (J), with
/// x_pi = F_xi/k_xi the legs' free positions. Backward Euler with the set-valued
/// friction law never increases it at constant F_x and zero F_ext.
pub fn energy(c: &XCoefficients, s: &XState, f_x: &[f64; 2]) -> f64 {
    let legs: f64 = (0..2)
        .map(|i| {
            let dx = s.x_leg[i] - f_x[i] / c.k[i];
            0.5 * c.k[i] * dx * dx
        })
        .sum();
    0.5 * c.mass * s.v_s * s.v_s + legs
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    fn coeffs(dt: f64) -> XCoefficients {
        XCoefficients {
            dt,
            mass: 0.428,
            k: [4.98e6, 4.98e6],
            d: [100.0, 100.0],
        }
    }

    /// Exact solution of the box-constrained QP min ½λᵀWλ − aᵀλ over C by
    /// enumerating the nine active sets (a cross-check of the iteration).
    fn exact(c: &XCoefficients, a: &XState, f_x: &[f64; 2], f_ext: f64, b: &[f64; 2]) -> [f64; 2] {
        let (w11, w12, w22) = c.w();
        let (_, _, g0) = evaluate(c, a, f_x, f_ext, &[0.0, 0.0]);
        let av = g0; // g = a − Wλ
        let mut best = [0.0, 0.0];
        let mut best_f = f64::INFINITY;
        let obj = |l: [f64; 2]| {
            0.5 * (w11 * l[0] * l[0] + 2.0 * w12 * l[0] * l[1] + w22 * l[1] * l[1])
                - av[0] * l[0]
                - av[1] * l[1]
        };
        let choices = |bi: f64| [Some(-bi), Some(bi), None];
        for c1 in choices(b[0]) {
            for c2 in choices(b[1]) {
                let l = match (c1, c2) {
                    (Some(x), Some(y)) => [x, y],
                    (Some(x), None) => [x, ((av[1] - w12 * x) / w22).clamp(-b[1], b[1])],
                    (None, Some(y)) => [((av[0] - w12 * y) / w11).clamp(-b[0], b[0]), y],
                    (None, None) => {
                        let det = w11 * w22 - w12 * w12;
                        let l1 = (w22 * av[0] - w12 * av[1]) / det;
                        let l2 = (w11 * av[1] - w12 * av[0]) / det;
                        [l1.clamp(-b[0], b[0]), l2.clamp(-b[1], b[1])]
                    }
                };
                let f = obj(l);
                if f < best_f {
                    best_f = f;
                    best = l;
                }
            }
        }
        best
    }

    fn settings(c: &XCoefficients) -> FixedPointSettings {
        FixedPointSettings {
            r: c.optimal_r(),
            tol_n: 1e-11,
            max_iter: 500,
        }
    }

    #[test]
    fn rigid_surface_below_mu_fn_sticks_exactly() {
        // Legs that cannot move (huge damping) = a fixed frictional surface under
        // the stage; one pair in contact.
        let c = XCoefficients {
            dt: 25e-6,
            mass: 0.428,
            k: [4.98e6; 2],
            d: [1e15; 2],
        };
        let set = settings(&c);
        let bound = [0.2 * 55.0, 0.0];
        let mut st = XState::default();
        let mut lam = [0.0; 2];
        let n = 40_000; // 1 s
        for _ in 0..n {
            let s = step_x(&c, &st, &[0.0; 2], 0.9 * bound[0], &bound, &lam, &set);
            assert!(s.converged);
            st = s.state;
            lam = s.lambda;
        }
        // |v| per step is bounded by ε·Δt/M (λ within ε of −F) plus the leg's own
        // motion (F/d·Δt ≈ 1e-19 m per step): the stage stays put.
        let bound_x = n as f64 * c.dt * (set.tol_n * c.dt / c.mass + 11.0 / 1e15);
        assert!(st.x_s.abs() <= bound_x, "x_s = {} > {}", st.x_s, bound_x);
        assert!((lam[0] + 0.9 * bound[0]).abs() < 1e-9);
    }

    #[test]
    fn above_mu_fn_the_acceleration_is_exact() {
        for d in [1e15, 100.0] {
            let c = XCoefficients {
                dt: 25e-6,
                mass: 0.428,
                k: [4.98e6; 2],
                d: [d; 2],
            };
            let set = settings(&c);
            let bound = [0.2 * 30.0, 0.2 * 25.0];
            let f = 1.7 * (bound[0] + bound[1]);
            let mut st = XState::default();
            let mut lam = [0.0; 2];
            let mut v_prev = 0.0;
            for k in 0..4000 {
                let s = step_x(&c, &st, &[0.0; 2], f, &bound, &lam, &set);
                assert!(s.converged);
                if k > 400 {
                    // Both pairs slide backwards relative to the stage: λ = −μF_N.
                    let acc = (s.state.v_s - v_prev) / c.dt;
                    let expect = (f - bound[0] - bound[1]) / c.mass;
                    assert!(
                        (acc - expect).abs() < 1e-9 * expect,
                        "d = {d}: {acc} vs {expect}"
                    );
                    assert_eq!(s.lambda, [-bound[0], -bound[1]]);
                }
                v_prev = s.state.v_s;
                st = s.state;
                lam = s.lambda;
            }
        }
    }

    #[test]
    fn compliant_legs_stick_below_mu_fn_with_zero_slip() {
        let c = coeffs(25e-6);
        let set = settings(&c);
        let bound = [0.2 * 55.0, 0.0];
        let mut st = XState::default();
        let mut lam = [0.0; 2];
        let mut rel0 = None;
        for k in 0..20_000 {
            // Ramp F up to 0.8 μF_N over the first 0.1 s, then hold.
            let f = 0.8 * bound[0] * (k as f64 / 4000.0).min(1.0);
            let s = step_x(&c, &st, &[0.0; 2], f, &bound, &lam, &set);
            assert!(s.converged);
            assert!(
                s.slip[0].abs() <= set.tol_n / set.r * 1.0001,
                "slip {}",
                s.slip[0]
            );
            st = s.state;
            lam = s.lambda;
            // Stage and leg tip move together: the relative position never changes.
            let rel = st.x_leg[0] - st.x_s;
            let r0 = *rel0.get_or_insert(rel);
            assert!((rel - r0).abs() < (k + 1) as f64 * c.dt * set.tol_n / set.r * 1.0001 + 1e-22);
        }
        // At rest the leg carries the force elastically: λ = −F on the stage, so
        // k x_1 = −λ = F.
        assert!((st.x_leg[0] - 0.8 * bound[0] / c.k[0]).abs() < 1e-3 * 0.8 * bound[0] / c.k[0]);
    }

    /// Found by the property test below: pairs whose dampings differ 1000×
    /// (W₁₁/W₂₂ ≈ 1/500) needed ≈ 7000 iterations with one r; with an r per
    /// contact a handful, and the exact box-QP solution.
    #[test]
    fn very_unequal_legs_converge_with_an_r_per_contact() {
        let c = XCoefficients {
            dt: 1e-6,
            mass: 0.2,
            k: [1e6, 1e6],
            d: [989.7755895329329, 1.0],
        };
        let set = FixedPointSettings {
            r: c.optimal_r(),
            tol_n: 1e-10,
            max_iter: 500,
        };
        let b = [0.0, 0.452625830816647 * 55.0];
        let s = step_x(
            &c,
            &XState::default(),
            &[0.0; 2],
            -0.19375207252955423,
            &b,
            &[0.0; 2],
            &set,
        );
        assert!(s.converged && s.iterations < 10, "{s:?}");
        let ex = exact(&c, &XState::default(), &[0.0; 2], -0.19375207252955423, &b);
        assert!(
            (s.lambda[1] - ex[1]).abs() < 1e-9 && s.lambda[0] == 0.0,
            "{:?} vs {ex:?}",
            s.lambda
        );
        // Equal legs: the factors are exactly 1 (the scalar iteration of (4.18)).
        assert_eq!(coeffs(25e-6).contact_scale(), [1.0, 1.0]);
    }

    #[test]
    fn too_large_r_is_reported_not_hidden() {
        let c = coeffs(25e-6);
        let set = FixedPointSettings {
            r: 5.0 * c.max_r(),
            tol_n: 1e-10,
            max_iter: 50,
        };
        let s = step_x(
            &c,
            &XState::default(),
            &[1.0, -1.0],
            0.0,
            &[11.0, 11.0],
            &[0.0; 2],
            &set,
        );
        assert!(!s.converged);
        assert_eq!(s.iterations, 50);
        assert!(s.residual_n >= 1e-10);
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(300))]

        /// The iteration converges over the parameter ranges around Table 4.1 (whose
        /// printed values are lost: wide ranges around our defaults) and equals the
        /// exact solution of the box QP.
        #[test]
        fn converges_and_matches_exact(
            dt in 1e-6f64..1e-4, mass in 0.2f64..2.0, k1 in 1e6f64..5e7, k2 in 1e6f64..5e7,
            d1 in 1.0f64..2e3, d2 in 1.0f64..2e3, mu in 0.02f64..1.0, fn1 in 0.0f64..55.0,
            fx1 in -20.0f64..20.0, fx2 in -20.0f64..20.0, v in -1e-3f64..1e-3,
            x1 in -4e-6f64..4e-6, x2 in -4e-6f64..4e-6, fext in -5.0f64..5.0,
        ) {
            let c = XCoefficients { dt, mass, k: [k1, k2], d: [d1, d2] };
            let set = FixedPointSettings { r: c.optimal_r(), tol_n: 1e-10, max_iter: 500 };
            // The contraction factor (κ−1)/(κ+1) of the scaled S^½WS^½ bounds the
            // iterations needed.
            let (lmin, lmax) = c.scaled_w_eigenvalues();
            let rate = (lmax - lmin) / (lmax + lmin);
            let sc = c.contact_scale();
            let spread = sc[0].max(sc[1]) / sc[0].min(sc[1]);
            let a = XState { x_s: 0.0, v_s: v, x_leg: [x1, x2] };
            let b = [mu * fn1, mu * (55.0 - fn1)];
            let s = step_x(&c, &a, &[fx1, fx2], fext, &b, &[0.0; 2], &set);
            prop_assert!(s.converged, "{:?}", s);
            let predicted = ((set.tol_n / 200.0).ln() / rate.ln()).ceil().max(1.0) + 2.0;
            prop_assert!(f64::from(s.iterations) <= predicted, "{} > {}", s.iterations, predicted);
            let ex = exact(&c, &a, &[fx1, fx2], fext, &b);
            // Distance to the exact solution ≤ residual/(r·λ_min) in the norm
            // weighted by S⁻¹ (contraction bound); `spread` converts to max-norm.
            let tol = 10.0 * spread * set.tol_n / (set.r * lmin) + 1e-12 * (b[0] + b[1]);
            prop_assert!((s.lambda[0] - ex[0]).abs() < tol && (s.lambda[1] - ex[1]).abs() < tol,
                "{:?} vs {:?}", s.lambda, ex);
        }

        /// No energy creation: at constant piezo forces and no external force the
        /// energy never grows, whatever the state, contact forces and μ.
        #[test]
        fn no_energy_creation(
            dt in 1e-6f64..2.5e-4, d in 1.0f64..1e4, mu in 0.0f64..1.0, fn1 in 0.0f64..55.0,
            fx1 in -20.0f64..20.0, fx2 in -20.0f64..20.0, v in -1e-2f64..1e-2,
            x1 in -4e-6f64..4e-6, x2 in -4e-6f64..4e-6,
        ) {
            let c = XCoefficients { dt, mass: 0.428, k: [4.98e6, 3e6], d: [d, 2.0 * d] };
            let set = FixedPointSettings { r: c.optimal_r(), tol_n: 1e-12, max_iter: 500 };
            let mut st = XState { x_s: 0.0, v_s: v, x_leg: [x1, x2] };
            let b = [mu * fn1, mu * (55.0 - fn1)];
            let mut lam = [0.0; 2];
            let fx = [fx1, fx2];
            for _ in 0..50 {
                let e0 = energy(&c, &st, &fx);
                let s = step_x(&c, &st, &fx, 0.0, &b, &lam, &set);
                let e1 = energy(&c, &s.state, &fx);
                // Allowance: an interior λ within ε of the fixed point leaves a slip
                // |g| < ε/r, worth at most μF_N·ε/r·Δt of work; plus round-off.
                let slack = 2.0 * (b[0] + b[1]) * set.tol_n / set.r * dt + 1e-12 * e0 + 1e-30;
                prop_assert!(e1 <= e0 + slack, "{} -> {}", e0, e1);
                st = s.state;
                lam = s.lambda;
            }
        }
    }
}
