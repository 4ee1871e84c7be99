//! The plant trajectory between two ticks as a polynomial in normalised time, and
//! its level crossings.
//!
//! Between the previous tick t₀ and the current tick t₁ = t₀ + h the encoder knows the
//! position (and, if the plant provides them, velocity and acceleration) at both ends.
//! It interpolates with the Hermite polynomial u(s), s = (t − t₀)/h ∈ [0, 1], that
//! matches all of them:
//!
//! | input | interpolant | exact for trajectories of degree |
//! |---|---|---|
//! | x | linear | ≤ 1 |
//! | x, ẋ | cubic Hermite | ≤ 3 |
//! | x, ẋ, ẍ | quintic Hermite | ≤ 5 |
//!
//! Crossings are found without sampling: the real roots of u′ in (0, 1) split [0, 1]
//! into monotone pieces ([`roots_in`], recursively on the derivatives, so at most
//! five pieces); on a monotone piece each edge level is crossed at most once and its
//! time is found by safeguarded Newton iteration ([`solve_monotone`]) to ~1e-15 in s.

/// Highest polynomial degree handled (quintic Hermite).
pub const MAX_DEG: usize = 5;

/// A polynomial c₀ + c₁s + … + c_d s^d of degree d ≤ 5, on the stack.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Poly {
    /// Coefficients in ascending powers; entries above `deg` are zero.
    pub c: [f64; MAX_DEG + 1],
    /// Degree d (the leading coefficient may be zero only when d = 0).
    pub deg: usize,
}

impl Poly {
    /// The polynomial with ascending coefficients `c` (at most 6), trimmed of exact
    /// zero leading coefficients.
    pub fn new(c: &[f64]) -> Self {
        let mut p = Poly {
            c: [0.0; MAX_DEG + 1],
            deg: 0,
        };
        p.c[..c.len()].copy_from_slice(c);
        p.deg = c.len().saturating_sub(1);
        p.trim();
        p
    }

    fn trim(&mut self) {
        while self.deg > 0 && self.c[self.deg] == 0.0 {
            self.deg -= 1;
        }
    }

    /// Value at `s` (Horner).
    pub fn eval(&self, s: f64) -> f64 {
        let mut y = self.c[self.deg];
        for j in (0..self.deg).rev() {
            y = y * s + self.c[j];
        }
        y
    }

    /// The derivative d/ds.
    pub fn deriv(&self) -> Poly {
        let mut d = Poly {
            c: [0.0; MAX_DEG + 1],
            deg: self.deg.saturating_sub(1),
        };
        for j in 1..=self.deg {
            d.c[j - 1] = j as f64 * self.c[j];
        }
        d.trim();
        d
    }

    /// Hermite interpolant on s ∈ [0, 1] of a trajectory sampled at both ends of an
    /// interval of length `h`: `a` and `b` hold [x, ẋ, ẍ] (the first 1, 2 or 3, same
    /// length) at the start and the end. Derivatives are per unit of time; they are
    /// scaled by h (and h²) to the normalised time s.
    pub fn hermite(a: &[f64], b: &[f64], h: f64) -> Poly {
        let dx = b[0] - a[0];
        match a.len().min(b.len()) {
            0 | 1 => Poly::new(&[a[0], dx]),
            2 => {
                let (d0, d1) = (a[1] * h, b[1] * h);
                Poly::new(&[a[0], d0, 3.0 * dx - 2.0 * d0 - d1, -2.0 * dx + d0 + d1])
            }
            _ => {
                let (d0, d1) = (a[1] * h, b[1] * h);
                let (a0, a1) = (a[2] * h * h, b[2] * h * h);
                Poly::new(&[
                    a[0],
                    d0,
                    0.5 * a0,
                    10.0 * dx - 6.0 * d0 - 4.0 * d1 - 1.5 * a0 + 0.5 * a1,
                    -15.0 * dx + 8.0 * d0 + 7.0 * d1 + 1.5 * a0 - a1,
                    6.0 * dx - 3.0 * d0 - 3.0 * d1 - 0.5 * a0 + 0.5 * a1,
                ])
            }
        }
    }
}

/// The real roots of `p` in the open interval (lo, hi), ascending, written to `out`;
/// returns how many. A root of even multiplicity that touches zero without a sign
/// change is found only if `p` is exactly zero there (it is a critical point, not a
/// crossing, which is all the encoder needs).
pub fn roots_in(p: &Poly, lo: f64, hi: f64, out: &mut [f64; MAX_DEG]) -> usize {
    match p.deg {
        0 => 0,
        1 => {
            let r = -p.c[0] / p.c[1];
            if r > lo && r < hi {
                out[0] = r;
                1
            } else {
                0
            }
        }
        _ => {
            let mut crit = [0.0; MAX_DEG];
            let nc = roots_in(&p.deriv(), lo, hi, &mut crit);
            let mut n = 0;
            let mut a = lo;
            let mut fa = p.eval(lo);
            let ends = crit[..nc]
                .iter()
                .map(|&c| (c, true))
                .chain(std::iter::once((hi, false)));
            for (b, interior) in ends {
                let fb = p.eval(b);
                if fa * fb < 0.0 {
                    let inc = fb > fa;
                    out[n] = solve_monotone(p, 0.0, a, b, inc);
                    n += 1;
                } else if fb == 0.0 && interior && n < MAX_DEG && (n == 0 || out[n - 1] < b) {
                    out[n] = b;
                    n += 1;
                }
                a = b;
                fa = fb;
            }
            n
        }
    }
}

/// The s in [a, b] where the monotone `p` equals `level` (`increasing` says which
/// way it runs). Safeguarded Newton: a Newton step that leaves the bracket is
/// replaced by bisection; stops when the step is below 1e-15 (relative) or the value
/// is hit exactly. If `level` is outside [p(a), p(b)] the nearer end is returned.
pub fn solve_monotone(p: &Poly, level: f64, a: f64, b: f64, increasing: bool) -> f64 {
    let sign = if increasing { 1.0 } else { -1.0 };
    let f = |s: f64| sign * (p.eval(s) - level);
    if f(a) >= 0.0 {
        return a;
    }
    if f(b) <= 0.0 {
        return b;
    }
    let d = p.deriv();
    let (mut lo, mut hi) = (a, b);
    let mut s = 0.5 * (a + b);
    for _ in 0..200 {
        let fs = f(s);
        if fs == 0.0 {
            return s;
        }
        if fs < 0.0 {
            lo = s;
        } else {
            hi = s;
        }
        let df = sign * d.eval(s);
        let mut next = s - fs / df;
        if !(next > lo && next < hi) {
            next = 0.5 * (lo + hi);
        }
        if (next - s).abs() <= 1e-15 * s.abs().max(1.0) || hi - lo <= 1e-15 * s.abs().max(1.0) {
            return next;
        }
        s = next;
    }
    s
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn hermite_matches_end_values_and_derivatives() {
        let (a, b, h) = ([0.3, -1.2, 4.0], [1.1, 2.5, -3.0], 0.25);
        for len in 1..=3 {
            let p = Poly::hermite(&a[..len], &b[..len], h);
            assert!((p.eval(0.0) - a[0]).abs() < 1e-14);
            assert!((p.eval(1.0) - b[0]).abs() < 1e-14);
            if len >= 2 {
                let d = p.deriv();
                assert!((d.eval(0.0) / h - a[1]).abs() < 1e-12);
                assert!((d.eval(1.0) / h - b[1]).abs() < 1e-12);
            }
            if len == 3 {
                let dd = p.deriv().deriv();
                assert!((dd.eval(0.0) / (h * h) - a[2]).abs() < 1e-11);
                assert!((dd.eval(1.0) / (h * h) - b[2]).abs() < 1e-11);
            }
        }
    }

    #[test]
    fn hermite_is_exact_for_polynomials_of_its_degree() {
        // x(t) = 1 − 2t + 0.5t² + 3t³ − t⁴ + 0.7t⁵ on [0.4, 0.9].
        let c = [1.0, -2.0, 0.5, 3.0, -1.0, 0.7];
        let x = Poly::new(&c);
        let (v, acc) = (x.deriv(), x.deriv().deriv());
        let (t0, t1) = (0.4, 0.9);
        let at = |t: f64| [x.eval(t), v.eval(t), acc.eval(t)];
        let p5 = Poly::hermite(&at(t0), &at(t1), t1 - t0);
        let cubic = Poly::new(&c[..4]);
        let atc = |t: f64| [cubic.eval(t), cubic.deriv().eval(t)];
        let p3 = Poly::hermite(&atc(t0), &atc(t1), t1 - t0);
        for i in 0..=10 {
            let s = i as f64 / 10.0;
            let t = t0 + s * (t1 - t0);
            assert!((p5.eval(s) - x.eval(t)).abs() < 1e-13);
            assert!((p3.eval(s) - cubic.eval(t)).abs() < 1e-13);
        }
    }

    #[test]
    fn roots_of_a_product_are_found() {
        // (s − 0.1)(s − 0.35)(s − 0.6)(s − 0.8)(s − 0.95)
        let r = [0.1, 0.35, 0.6, 0.8, 0.95];
        let mut c = [1.0, 0.0, 0.0, 0.0, 0.0, 0.0];
        for (deg, &ri) in r.iter().enumerate() {
            let mut n = [0.0; 6];
            for j in 0..=deg {
                n[j + 1] += c[j];
                n[j] -= ri * c[j];
            }
            c = n;
        }
        let p = Poly::new(&c);
        let mut out = [0.0; MAX_DEG];
        let n = roots_in(&p, 0.0, 1.0, &mut out);
        assert_eq!(n, 5);
        for (a, b) in out.iter().zip(r) {
            assert!((a - b).abs() < 1e-13, "{out:?}");
        }
        assert_eq!(roots_in(&p, 0.36, 0.59, &mut out), 0);
        assert_eq!(
            roots_in(&Poly::new(&[1.0, 0.0, 1.0]), -5.0, 5.0, &mut out),
            0
        );
    }
}
