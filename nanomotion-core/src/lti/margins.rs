//! Classical stability margins of a SISO loop gain L (python-control's
//! `stability_margins`): gain margin, phase margin and modulus margin with the
//! frequencies where they occur.
//!
//! The loop is judged from its frequency response on a dense logarithmic grid;
//! every crossing found on the grid is refined by bisection (to ~1e-12 relative in
//! ω), and the modulus margin's minimum by golden-section search. For a discrete
//! loop the grid ends at the Nyquist frequency π/T, which is itself checked as a
//! phase crossover (a real, negative L at Nyquist is common after ZOH).

use super::{Complex, FrequencyEvaluator, LtiError, StateSpace};

/// Stability margins of a loop gain L.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Margins {
    /// Gain margin (absolute, not dB): 1/|L| at the phase crossover nearest to
    /// instability; `f64::INFINITY` when the phase never crosses −180°.
    pub gain_margin: f64,
    /// Phase margin (degrees) at the gain crossover with the smallest margin;
    /// `f64::INFINITY` when |L| never crosses 1.
    pub phase_margin_deg: f64,
    /// Modulus margin min_ω |1 + L| = 1/‖S‖∞ (the distance of the Nyquist curve
    /// to −1).
    pub modulus_margin: f64,
    /// Phase crossover frequency (rad/s) of the gain margin (NaN if none).
    pub phase_crossover_rad_s: f64,
    /// Gain crossover frequency (rad/s) of the phase margin (NaN if none).
    pub gain_crossover_rad_s: f64,
    /// Frequency (rad/s) of the modulus margin.
    pub modulus_rad_s: f64,
}

impl Margins {
    /// Gain margin in dB.
    pub fn gain_margin_db(&self) -> f64 {
        20.0 * self.gain_margin.log10()
    }
}

/// Frequency range worth looking at: a few decades around the poles and zeros,
/// ending at Nyquist for a discrete loop.
fn grid_range(l: &StateSpace) -> (f64, f64) {
    let mut mags: Vec<f64> = Vec::new();
    for p in l.poles() {
        let w = match l.dt {
            Some(dt) => (p.ln() / dt).norm(),
            None => p.norm(),
        };
        if w.is_finite() && w > 1e-12 {
            mags.push(w);
        }
    }
    let lo = mags.iter().copied().fold(f64::INFINITY, f64::min);
    let hi = mags.iter().copied().fold(0.0, f64::max);
    let (mut w_lo, mut w_hi) = if mags.is_empty() {
        (1e-3, 1e3)
    } else {
        (lo * 1e-3, hi * 1e3)
    };
    if let Some(dt) = l.dt {
        w_hi = std::f64::consts::PI / dt;
        w_lo = w_lo.min(w_hi * 1e-7);
    }
    if w_hi <= w_lo {
        w_hi = w_lo * 1e6;
    }
    (w_lo, w_hi)
}

/// Stability margins of the SISO loop gain `l` (continuous or discrete).
///
/// ```
/// use nanomotion_core::lti::{TransferFunction, stability_margins};
/// // L(s) = 2/(s+1)³: phase crossover at ω = √3 where |L| = 2/8, so GM = 4.
/// let l = TransferFunction::new(vec![2.0], vec![1.0, 3.0, 3.0, 1.0], None).unwrap().to_ss().unwrap();
/// let m = stability_margins(&l).unwrap();
/// assert!((m.gain_margin - 4.0).abs() < 1e-8);
/// assert!((m.phase_crossover_rad_s - 3f64.sqrt()).abs() < 1e-8);
/// ```
pub fn stability_margins(l: &StateSpace) -> Result<Margins, LtiError> {
    l.validate()?;
    if !l.is_siso() {
        return Err(LtiError::Dimension(format!(
            "stability margins need a SISO loop gain, got {} outputs × {} inputs",
            l.noutputs(),
            l.ninputs()
        )));
    }
    margins_with(l, &l.frequency_evaluator()?)
}

/// [`stability_margins`] of a valid SISO `l` whose frequency evaluator `ev`
/// is at hand (the stability gate shares one with the Nyquist count).
pub(crate) fn margins_with(l: &StateSpace, ev: &FrequencyEvaluator) -> Result<Margins, LtiError> {
    let (w_lo, w_hi) = grid_range(l);
    let n = 4000usize;
    let ratio = (w_hi / w_lo).ln();
    let grid: Vec<f64> = (0..n)
        .map(|i| w_lo * (ratio * i as f64 / (n - 1) as f64).exp())
        .collect();
    let eval = |w: f64| ev.siso_at(w);
    let resp: Vec<Complex<f64>> = grid.iter().map(|&w| eval(w)).collect();
    if resp.iter().any(|c| !c.re.is_finite() || !c.im.is_finite()) {
        return Err(LtiError::Domain("the loop gain is not finite on the imaginary axis / unit circle (pole on it); shift it slightly or remove it".into()));
    }
    // Bisection on log ω of a sign change of f.
    let refine = |mut a: f64, mut b: f64, f: &dyn Fn(f64) -> f64| {
        let fa0 = f(a);
        for _ in 0..80 {
            let m = (a * b).sqrt();
            if (f(m) > 0.0) == (fa0 > 0.0) {
                a = m;
            } else {
                b = m;
            }
        }
        (a * b).sqrt()
    };

    // Gain crossovers: |L| − 1 changes sign.
    let gain = |w: f64| eval(w).norm() - 1.0;
    let mut pm = f64::INFINITY;
    let mut wgc = f64::NAN;
    for i in 1..n {
        let (g0, g1) = (resp[i - 1].norm() - 1.0, resp[i].norm() - 1.0);
        if g0 == 0.0 || (g0 > 0.0) != (g1 > 0.0) {
            let w = refine(grid[i - 1], grid[i], &gain);
            let phase = eval(w).arg().to_degrees(); // (−180, 180]
            let margin = 180.0 + phase;
            let margin = if margin > 180.0 {
                margin - 360.0
            } else {
                margin
            };
            if margin.abs() < pm.abs() {
                pm = margin;
                wgc = w;
            }
        }
    }

    // Phase crossovers: Im L changes sign while Re L < 0.
    let imag = |w: f64| eval(w).im;
    let mut gm = f64::INFINITY;
    let mut wpc = f64::NAN;
    let mut consider = |w: f64, c: Complex<f64>| {
        if c.re < 0.0 {
            let g = 1.0 / c.norm();
            // The margin nearest to instability is the one closest to 1 in log terms.
            if (g.ln()).abs() < (gm.ln()).abs() {
                gm = g;
                wpc = w;
            }
        }
    };
    for i in 1..n {
        let (a, b) = (resp[i - 1].im, resp[i].im);
        if (a > 0.0) != (b > 0.0) && (resp[i - 1].re < 0.0 || resp[i].re < 0.0) {
            let w = refine(grid[i - 1], grid[i], &imag);
            consider(w, eval(w));
        }
    }
    if l.dt.is_some() {
        // At Nyquist the response of a real discrete system is real.
        let c = resp[n - 1];
        if c.im.abs() <= 1e-9 * c.norm().max(1e-300) {
            consider(grid[n - 1], c);
        }
    }

    // Modulus margin: min |1 + L|, grid then golden section around the minimum.
    let dist = |w: f64| (eval(w) + Complex::new(1.0, 0.0)).norm();
    let (imin, _) = resp
        .iter()
        .map(|c| (c + Complex::new(1.0, 0.0)).norm())
        .enumerate()
        .fold(
            (0, f64::INFINITY),
            |(bi, bv), (i, v)| if v < bv { (i, v) } else { (bi, bv) },
        );
    let (mut a, mut b) = (
        grid[imin.saturating_sub(1)].ln(),
        grid[(imin + 1).min(n - 1)].ln(),
    );
    let gr = (5f64.sqrt() - 1.0) / 2.0;
    for _ in 0..100 {
        let c = b - gr * (b - a);
        let d = a + gr * (b - a);
        if dist(c.exp()) < dist(d.exp()) {
            b = d;
        } else {
            a = c;
        }
    }
    let wm = ((a + b) / 2.0).exp();
    let (mut sm, mut wms) = (dist(wm), wm);
    let grid_min = dist(grid[imin]);
    if grid_min < sm {
        sm = grid_min;
        wms = grid[imin];
    }

    Ok(Margins {
        gain_margin: gm,
        phase_margin_deg: pm,
        modulus_margin: sm,
        phase_crossover_rad_s: wpc,
        gain_crossover_rad_s: wgc,
        modulus_rad_s: wms,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::lti::{TransferFunction, feedback, hinfnorm};
    use nalgebra::DMatrix;

    fn ss(num: &[f64], den: &[f64], dt: Option<f64>) -> StateSpace {
        TransferFunction::new(num.to_vec(), den.to_vec(), dt)
            .unwrap()
            .to_ss()
            .unwrap()
    }

    #[test]
    fn integrator_with_lag_phase_margin_closed_form() {
        // L = 1/(s(s+1)): ω_c² = (√5 − 1)/2, PM = 90° − atan(ω_c), no phase crossover.
        let m = stability_margins(&ss(&[1.0], &[1.0, 1.0, 0.0], None)).unwrap();
        let wc = ((5f64.sqrt() - 1.0) / 2.0).sqrt();
        assert!((m.gain_crossover_rad_s - wc).abs() < 1e-9 * wc);
        assert!((m.phase_margin_deg - (90.0 - wc.atan().to_degrees())).abs() < 1e-7);
        assert!(m.gain_margin.is_infinite());
    }

    #[test]
    fn third_order_lag_gain_and_phase_margin_closed_form() {
        // L = 2/(s+1)³: ω_pc = √3, GM = 8/2; (1+ω²)^{3/2} = 2 at the gain crossover.
        let m = stability_margins(&ss(&[2.0], &[1.0, 3.0, 3.0, 1.0], None)).unwrap();
        assert!((m.gain_margin - 4.0).abs() < 1e-9);
        assert!((m.gain_margin_db() - 20.0 * 4f64.log10()).abs() < 1e-9);
        let wc = (2f64.powf(2.0 / 3.0) - 1.0).sqrt();
        assert!((m.gain_crossover_rad_s - wc).abs() < 1e-9);
        assert!((m.phase_margin_deg - (180.0 - 3.0 * wc.atan().to_degrees())).abs() < 1e-7);
    }

    #[test]
    fn modulus_margin_equals_inverse_sensitivity_peak() {
        // Independent: ‖S‖∞ from the Hamiltonian H∞ norm of S = 1/(1 + L).
        for (num, den) in [
            (vec![2.0], vec![1.0, 3.0, 3.0, 1.0]),
            (vec![5.0, 1.0], vec![1.0, 0.8, 2.0, 0.0]),
        ] {
            let l = ss(&num, &den, None);
            let one = StateSpace::gain(DMatrix::identity(1, 1), None);
            let s = feedback(&one, &l, -1.0).unwrap();
            let ms = hinfnorm(&s).unwrap().norm;
            let m = stability_margins(&l).unwrap();
            assert!(
                (m.modulus_margin - 1.0 / ms).abs() < 1e-6 / ms,
                "{} vs {}",
                m.modulus_margin,
                1.0 / ms
            );
        }
    }

    #[test]
    fn discrete_integrator_margins_closed_form() {
        // L(z) = kT/(z − 1): |e^{jθ} − 1| = 2 sin(θ/2) = kT at crossover,
        // PM = 90° − θ/2; at Nyquist L = −kT/2, so GM = 2/(kT).
        let (k, t) = (2.0 * std::f64::consts::PI * 10.0, 1e-3);
        let m = stability_margins(&ss(&[k * t], &[1.0, -1.0], Some(t))).unwrap();
        let theta = 2.0 * (k * t / 2.0).asin();
        assert!((m.gain_crossover_rad_s - theta / t).abs() < 1e-8 * theta / t);
        assert!((m.phase_margin_deg - (90.0 - theta.to_degrees() / 2.0)).abs() < 1e-7);
        assert!((m.gain_margin - 2.0 / (k * t)).abs() < 1e-9 * m.gain_margin);
        assert!((m.phase_crossover_rad_s - std::f64::consts::PI / t).abs() < 1e-9 / t);
    }

    #[test]
    fn unstable_margin_is_negative_phase_margin() {
        // L = 10/(s+1)³ is unstable in closed loop (GM = 0.8 < 1): PM < 0 and GM < 1.
        let m = stability_margins(&ss(&[10.0], &[1.0, 3.0, 3.0, 1.0], None)).unwrap();
        assert!((m.gain_margin - 0.8).abs() < 1e-9);
        assert!(m.phase_margin_deg < 0.0);
    }
}
