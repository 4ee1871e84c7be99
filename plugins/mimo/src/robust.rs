//! Robustness of decentralised control, thesis (7.3)–(7.4), and the generalised
//! Nyquist criterion by characteristic loci.
//!
//! The couplings are an output-multiplicative perturbation of the diagonal plant
//! G_d = diag(G): E = (G − G_d) G_d⁻¹ (7.3). With G and (I + G_d K_d)⁻¹ stable,
//! the MIMO loop is stable if, for all ω (7.4),
//!
//! ```text
//! σ̄(T_d(jω)) < μ_{T_d}(E(jω))⁻¹,   T_d = G_d K_d (I + G_d K_d)⁻¹,
//! ```
//!
//! μ with respect to the diagonal structure of T_d (complex scalars
//! δ₁ … δ_n). μ is bracketed: the **upper bound** inf_D σ̄(D E D⁻¹) over positive
//! diagonal D (minimised in log d, a convex function, by Nelder–Mead from the
//! Osborne-balanced start); the **lower bound** max_U ρ(E U) over diagonal
//! unitary U (every U gives a valid lower bound: μ(E) = max_U ρ(EU) for this
//! structure), searched over the phases. For n ≤ 3 complex scalar blocks the
//! upper bound is exact (Doyle 1982), so the gap measures the search.

use crate::error::MimoError;
use crate::optim::nelder_mead;
use nanomotion_core::analysis::CMatrix;
use nanomotion_core::lti::Complex;
use serde::Serialize;

/// Lower and upper bounds of μ for the diagonal (complex scalar) structure.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct MuBounds {
    /// max over the searched diagonal unitary U of ρ(M U).
    pub lower: f64,
    /// min over the searched positive diagonal D of σ̄(D M D⁻¹).
    pub upper: f64,
}

fn sigma_max(m: &CMatrix) -> f64 {
    m.singular_values().iter().copied().fold(0.0, f64::max)
}

fn spectral_radius(m: &CMatrix) -> f64 {
    nanomotion_core::analysis::mimo::eigenvalues(m)
        .map(|e| e.iter().map(|l| l.norm()).fold(0.0, f64::max))
        .unwrap_or(f64::NAN)
}

/// μ bounds of the square matrix `m` for diagonal complex perturbations (see the
/// [module docs](self)).
pub fn mu_diagonal(m: &CMatrix) -> MuBounds {
    let n = m.nrows();
    if n == 0 {
        return MuBounds {
            lower: 0.0,
            upper: 0.0,
        };
    }
    if n == 1 {
        let v = m[(0, 0)].norm();
        return MuBounds { lower: v, upper: v };
    }
    // Upper bound: D = diag(1, e^{x_1}, …).
    let scaled = |x: &[f64]| {
        let d: Vec<f64> = std::iter::once(1.0)
            .chain(x.iter().map(|v| v.exp()))
            .collect();
        CMatrix::from_fn(n, n, |i, j| m[(i, j)] * (d[i] / d[j]))
    };
    // Osborne start: d_i ∝ sqrt(col norm / row norm) of the off-diagonal part.
    let mut x0 = vec![0.0; n - 1];
    for _ in 0..20 {
        let ms = scaled(&x0);
        for i in 1..n {
            let (mut r, mut c) = (0.0, 0.0);
            for j in 0..n {
                if j != i {
                    r += ms[(i, j)].norm_sqr();
                    c += ms[(j, i)].norm_sqr();
                }
            }
            if r > 0.0 && c > 0.0 {
                x0[i - 1] += 0.25 * (c / r).ln();
            }
        }
    }
    let mut f = |x: &[f64]| sigma_max(&scaled(x));
    let (_, upper) = nelder_mead(&mut f, &x0, 0.5, 1e-12, 2000);
    let upper = upper.min(sigma_max(m));
    // Lower bound: U = diag(1, e^{jφ_1}, …); coarse grid then simplex.
    let rot = |phi: &[f64]| {
        let u: Vec<Complex<f64>> = std::iter::once(Complex::new(1.0, 0.0))
            .chain(phi.iter().map(|p| Complex::from_polar(1.0, *p)))
            .collect();
        CMatrix::from_fn(n, n, |i, j| m[(i, j)] * u[j])
    };
    let mut g = |phi: &[f64]| -spectral_radius(&rot(phi));
    let steps = 12usize;
    let mut best = (vec![0.0; n - 1], g(&vec![0.0; n - 1]));
    if n <= 4 {
        let total = steps.pow((n - 1) as u32);
        for code in 0..total {
            let mut c = code;
            let phi: Vec<f64> = (0..n - 1)
                .map(|_| {
                    let k = c % steps;
                    c /= steps;
                    std::f64::consts::TAU * k as f64 / steps as f64
                })
                .collect();
            let v = g(&phi);
            if v < best.1 {
                best = (phi, v);
            }
        }
    }
    let (_, lower) = nelder_mead(&mut g, &best.0, 0.3, 1e-12, 2000);
    let lower = (-lower).max(-best.1);
    MuBounds {
        lower,
        upper: upper.max(lower),
    }
}

/// One frequency of the (7.4) test.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct DecentralisedPoint {
    /// Frequency (Hz).
    pub f_hz: f64,
    /// σ̄(T_d(jω)).
    pub sigma_td: f64,
    /// μ bounds of E(jω).
    pub mu: MuBounds,
}

impl DecentralisedPoint {
    /// (7.4) holds with the μ upper bound (sufficient): σ̄(T_d) μ̄ < 1.
    pub fn holds(&self) -> bool {
        self.sigma_td * self.mu.upper < 1.0
    }
}

/// The (7.4) test on FRFs: `g[k]` the full plant (measured or modelled),
/// `kd[k]` the diagonal controller, at `f_hz[k]`. G_d is the diagonal of `g`.
pub fn decentralised_test(
    f_hz: &[f64],
    g: &[CMatrix],
    kd: &[CMatrix],
) -> Result<Vec<DecentralisedPoint>, MimoError> {
    if g.len() != f_hz.len() || kd.len() != f_hz.len() {
        return Err(MimoError::param(
            "frf",
            "lengths differ",
            "give G and K_d on the same grid",
        ));
    }
    let mut out = Vec::with_capacity(f_hz.len());
    for k in 0..f_hz.len() {
        let n = g[k].nrows();
        let gd = CMatrix::from_fn(n, n, |i, j| {
            if i == j {
                g[k][(i, i)]
            } else {
                Complex::new(0.0, 0.0)
            }
        });
        let gdi = gd.clone().try_inverse().ok_or_else(|| {
            MimoError::param(
                "frf",
                format!("G_d is singular at {} Hz", f_hz[k]),
                "drop that bin",
            )
        })?;
        let e = (&g[k] - &gd) * gdi;
        let l = &gd * &kd[k];
        let s = (CMatrix::identity(n, n) + &l)
            .try_inverse()
            .ok_or_else(|| MimoError::param("controller", "I + G_d K_d singular", "check K_d"))?;
        let t = l * s;
        out.push(DecentralisedPoint {
            f_hz: f_hz[k],
            sigma_td: sigma_max(&t),
            mu: mu_diagonal(&e),
        });
    }
    Ok(out)
}

/// The generalised Nyquist count: net counter-clockwise encirclements of the
/// origin by det(I + L(jω)) for ω from −∞ to ∞, from L on a positive-frequency
/// grid (the negative half is the mirror image for real systems). The MIMO loop
/// is stable iff this equals the number of open-loop right-half-plane poles.
/// The grid must start low enough and end high enough that det(I + L) is
/// nearly real and positive at both ends, and be fine enough that the phase
/// changes by less than π between bins.
pub fn nyquist_encirclements(l: &[CMatrix]) -> Result<i64, MimoError> {
    let mut total = 0.0;
    let mut prev: Option<Complex<f64>> = None;
    for m in l {
        let n = m.nrows();
        let d = (CMatrix::identity(n, n) + m).determinant();
        if !(d.norm() > 0.0) || !d.re.is_finite() {
            return Err(MimoError::param(
                "loop",
                "det(I + L) is 0 or not finite on the grid",
                "the loop passes through −1: not stable",
            ));
        }
        if let Some(p) = prev {
            total += (d / p).arg();
        }
        prev = Some(d);
    }
    Ok((2.0 * total / std::f64::consts::TAU).round() as i64)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn c(re: f64, im: f64) -> Complex<f64> {
        Complex::new(re, im)
    }

    #[test]
    fn mu_of_rank_one_and_diagonal_matrices_is_known() {
        // Rank one M = a bᴴ: μ = Σ|a_i b_i| for the diagonal structure.
        let a = [c(1.0, 0.5), c(-0.3, 0.2), c(0.7, -1.0)];
        let b = [c(0.2, 0.1), c(1.0, -0.4), c(-0.5, 0.3)];
        let m = CMatrix::from_fn(3, 3, |i, j| a[i] * b[j].conj());
        let want: f64 = (0..3).map(|i| (a[i] * b[i].conj()).norm()).sum();
        let mu = mu_diagonal(&m);
        assert!((mu.lower - want).abs() < 1e-6 * want, "{mu:?} vs {want}");
        assert!((mu.upper - want).abs() < 1e-4 * want, "{mu:?} vs {want}");
        // Diagonal M: μ = max |m_ii|.
        let d = CMatrix::from_fn(3, 3, |i, j| {
            if i == j {
                c(i as f64 + 1.0, 1.0)
            } else {
                c(0.0, 0.0)
            }
        });
        let mu = mu_diagonal(&d);
        assert!((mu.upper - 10f64.sqrt()).abs() < 1e-9 && (mu.lower - 10f64.sqrt()).abs() < 1e-9);
    }

    #[test]
    fn bounds_bracket_and_sit_below_sigma_max() {
        let mut r = nanomotion_core::rng::Rng::new(5);
        for _ in 0..10 {
            let m = CMatrix::from_fn(3, 3, |_, _| c(r.normal(), r.normal()));
            let mu = mu_diagonal(&m);
            assert!(mu.lower <= mu.upper * (1.0 + 1e-9));
            assert!(mu.upper <= sigma_max(&m) * (1.0 + 1e-12));
            assert!(mu.lower >= spectral_radius(&m) * (1.0 - 1e-12));
            // Three scalar blocks: the D-scaling bound is exact (Doyle 1982).
            assert!(mu.upper - mu.lower < 1e-3 * mu.upper, "{mu:?}");
        }
    }

    #[test]
    fn nyquist_counts_a_first_order_loop() {
        // L = k/(s + 1): no encirclement for k > −1; one for k < −1 (unstable pole of S).
        let f: Vec<f64> = (0..2000).map(|i| 1e-3 * 1.01f64.powi(i)).collect();
        for (k, want) in [(5.0, 0), (-3.0, 1)] {
            let l: Vec<CMatrix> = f
                .iter()
                .map(|&w| CMatrix::from_element(1, 1, c(k, 0.0) / c(1.0, w)))
                .collect();
            let n = nyquist_encirclements(&l).unwrap();
            // det(1 + L) = (s + 1 + k)/(s + 1): a zero in the RHP for k < −1
            // gives one clockwise turn.
            assert_eq!(n.abs(), want, "k = {k}: {n}");
        }
    }
}
