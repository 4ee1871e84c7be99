//! The y-direction model (4.11)–(4.15): massless legs (stiffness k_y, damping d_y)
//! between a massless motor housing loaded by the constant preload F_p and the
//! drive strip, with one-sided nonlinear contact springs (4.4)/(4.15)
//!
//! F_c(s) = 2 (s/q1)^(1/q2) for s ≥ 0, 0 for s < 0,
//!
//! where s is the penetration of a pair's tip into the strip (the factor 2: one
//! model leg stands for a pair). The contact forces share the preload (4.14),
//! F_c1 + F_c2 = F_p, and are the normal forces F_N1,2 of the friction model.
//!
//! Coordinates: y points from the housing towards the strip; the tip of pair i is
//! at s_i = h + e_i with h the housing position and e_i the leg's length change.
//! Each leg obeys k_y e_i + d_y ė_i = k_y y_pi − F_ci (the piezo force
//! F_yi = k_y y_pi of (4.11)/(4.12) against the contact force), so (4.13).
//!
//! Backward Euler in e_i turns one step into: find f1 ∈ [0, F_p] (f2 = F_p − f1)
//! such that both legs see the same housing position. The residual is monotone in
//! f1, so a bracketed Newton iteration always converges; the complementarity cases
//! (one pair lifted off) are detected at the bracket ends.

use nanomotion_core::ParamError;
use nanomotion_core::block::check;

/// The contact law (4.4)/(4.15) of one leg pair.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ContactLaw {
    /// q1 (m·N^−q2): deformation scale.
    pub q1: f64,
    /// q2 (−): exponent; thesis 0.75.
    pub q2: f64,
}

impl ContactLaw {
    /// Check q1 > 0 and 0 < q2 ≤ 1 (a softening-to-stiffening contact).
    pub fn validate(&self) -> Result<(), ParamError> {
        check::positive("contact_q1", self.q1)?;
        check::positive("contact_q2", self.q2)?;
        check::in_range("contact_q2", self.q2, 1e-3, 1.0)
    }
    /// Pair contact force F_c(s) (N) at penetration `s` (m), (4.15).
    pub fn force(&self, s: f64) -> f64 {
        if s <= 0.0 {
            return 0.0;
        }
        let x = s / self.q1;
        // x^(1/q2); the thesis's q2 = 0.75 gives x^(4/3) = (∛x)⁴ without powf.
        let p = if self.q2 == 0.75 {
            let c = x.cbrt();
            let c2 = c * c;
            c2 * c2
        } else {
            x.powf(1.0 / self.q2)
        };
        2.0 * p
    }
    /// Penetration at pair force `f` ≥ 0 (the inverse of [`ContactLaw::force`]).
    pub fn penetration(&self, f: f64) -> f64 {
        if f <= 0.0 {
            return 0.0;
        }
        let x = 0.5 * f;
        // x^q2; q2 = 0.75 gives √x·√√x without powf.
        let p = if self.q2 == 0.75 {
            let r = x.sqrt();
            r * r.sqrt()
        } else {
            x.powf(self.q2)
        };
        self.q1 * p
    }
    /// Tangent stiffness dF_c/ds (N/m) at penetration `s`.
    pub fn stiffness(&self, s: f64) -> f64 {
        if s > 0.0 {
            self.force(s) / (self.q2 * s)
        } else {
            0.0
        }
    }
}

/// Solution of one backward-Euler step of the y-model.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct YSolution {
    /// Normal (contact) forces F_N1, F_N2 (N); they sum to F_p.
    pub f_n: [f64; 2],
    /// Leg length changes e_1, e_2 (m).
    pub e: [f64; 2],
    /// Tip penetrations s_1, s_2 (m); negative: lifted off by that much.
    pub s: [f64; 2],
    /// Housing position h (m).
    pub h: f64,
    /// Newton/bisection iterations used.
    pub iterations: u32,
}

/// One backward-Euler step of the y-model (4.13)–(4.15).
///
/// `k`, `d`: leg stiffness (N/m) and damping (N·s/m) per pair; `y_p`: free tip
/// extensions (4.2) at the end of the step; `e_a`: leg length changes at the start;
/// `dt`: step (s); `f1_guess`: warm start for F_N1.
///
/// ```
/// use walking_piezo::contact::{ContactLaw, solve_y};
/// let law = ContactLaw { q1: 1.5e-8, q2: 0.75 };
/// // Equal legs, equal extension: the preload splits evenly.
/// let s = solve_y(&law, 55.0, [1.6e8; 2], [5e3; 2], [1e-6; 2], [0.0; 2], 25e-6, 0.0);
/// assert!((s.f_n[0] - 27.5).abs() < 1e-9 && (s.f_n[1] - 27.5).abs() < 1e-9);
/// ```
#[allow(clippy::too_many_arguments)]
pub fn solve_y(
    law: &ContactLaw,
    f_p: f64,
    k: [f64; 2],
    d: [f64; 2],
    y_p: [f64; 2],
    e_a: [f64; 2],
    dt: f64,
    f1_guess: f64,
) -> YSolution {
    // K_i (s_i − h) + F_ci = R_i with K_i = k_i + d_i/Δt, R_i = k_i y_pi + d_i e_iA/Δt.
    let kk = [k[0] + d[0] / dt, k[1] + d[1] / dt];
    let r = [
        k[0] * y_p[0] + d[0] * e_a[0] / dt,
        k[1] * y_p[1] + d[1] * e_a[1] / dt,
    ];
    // With both in contact: h = S(f_i) − (R_i − f_i)/K_i for i = 1, 2; residual
    // φ(f1) = [S(f1) − (R1 − f1)/K1] − [S(f2) − (R2 − f2)/K2], increasing in f1.
    let s_fp = law.penetration(f_p);
    let lin = |f1: f64| (f1 - r[0]) / kk[0] - (f_p - f1 - r[1]) / kk[1];
    let mut iterations = 0;
    let f1 = if lin(0.0) - s_fp >= 0.0 {
        0.0
    } else if s_fp + lin(f_p) <= 0.0 {
        f_p
    } else {
        let (mut lo, mut hi) = (0.0, f_p);
        let mut x = f1_guess;
        if !(x > 0.0 && x < f_p) {
            x = 0.5 * f_p;
        }
        let tol = 1e-13 * f_p;
        let dlin = 1.0 / kk[0] + 1.0 / kk[1];
        loop {
            iterations += 1;
            let (s1, s2) = (law.penetration(x), law.penetration(f_p - x));
            let v = s1 - s2 + lin(x);
            if v > 0.0 {
                hi = x;
            } else if v < 0.0 {
                lo = x;
            } else {
                break x;
            }
            // dS/df = q2·S/f.
            let dv = law.q2 * (s1 / x + s2 / (f_p - x)) + dlin;
            let mut nx = x - v / dv;
            if !(nx > lo && nx < hi) {
                nx = 0.5 * (lo + hi);
            }
            if (nx - x).abs() <= tol || hi - lo <= tol || iterations >= 200 {
                break nx;
            }
            x = nx;
        }
    };
    let f_n = [f1, f_p - f1];
    let e = [(r[0] - f_n[0]) / kk[0], (r[1] - f_n[1]) / kk[1]];
    // h from a pair in contact (the more loaded one, for accuracy).
    let i = if f_n[0] >= f_n[1] { 0 } else { 1 };
    let h = law.penetration(f_n[i]) - e[i];
    YSolution {
        f_n,
        e,
        s: [h + e[0], h + e[1]],
        h,
        iterations,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    const LAW: ContactLaw = ContactLaw {
        q1: 1.5e-8,
        q2: 0.75,
    };

    #[test]
    fn law_and_inverse_agree() {
        for f in [0.1, 1.0, 27.5, 55.0] {
            let s = LAW.penetration(f);
            assert!((LAW.force(s) - f).abs() < 1e-12 * f);
            // Stiffness is the derivative.
            let h = s * 1e-6;
            let num = (LAW.force(s + h) - LAW.force(s - h)) / (2.0 * h);
            assert!((LAW.stiffness(s) - num).abs() < 1e-6 * num);
        }
        assert_eq!(LAW.force(-1e-9), 0.0);
    }

    #[test]
    fn one_pair_lifts_off_when_the_other_is_much_longer() {
        // Pair 1 extended by 2 µm more than pair 2: it carries all the preload.
        let s = solve_y(
            &LAW,
            55.0,
            [1.575e8; 2],
            [5e3; 2],
            [2e-6, 0.0],
            [0.0; 2],
            1.0,
            27.5,
        );
        assert_eq!(s.f_n, [55.0, 0.0]);
        assert!(s.s[1] < 0.0);
        // Static (dt large): pair 1 compressed by F_p/k_y, penetration S(F_p).
        assert!((s.s[0] - LAW.penetration(55.0)).abs() < 1e-15);
    }

    proptest! {
        #[test]
        fn equations_hold(yp1 in -3e-6f64..3e-6, yp2 in -3e-6f64..3e-6, ea1 in -1e-6f64..1e-6,
                          ea2 in -1e-6f64..1e-6, dt in 1e-6f64..1e-3, fp in 1.0f64..200.0) {
            let (k, d) = ([1.575e8, 1.2e8], [5e3, 2e3]);
            let s = solve_y(&LAW, fp, k, d, [yp1, yp2], [ea1, ea2], dt, 0.3 * fp);
            // (4.14): the contact forces carry the preload.
            prop_assert!((s.f_n[0] + s.f_n[1] - fp).abs() < 1e-12 * fp);
            for i in 0..2 {
                // Contact law / complementarity: force from penetration, or lifted off.
                if s.f_n[i] > 1e-9 * fp {
                    prop_assert!((LAW.force(s.s[i]) - s.f_n[i]).abs() < 1e-8 * fp, "{:?}", s);
                } else {
                    prop_assert!(s.s[i] <= 1e-15, "{:?}", s);
                }
                // Backward-Euler leg equation (4.13).
                let ya = [yp1, yp2][i];
                let ea = [ea1, ea2][i];
                let res = k[i] * s.e[i] + d[i] * (s.e[i] - ea) / dt - (k[i] * ya - s.f_n[i]);
                prop_assert!(res.abs() < 1e-9 * fp, "{res}");
            }
        }
    }
}
