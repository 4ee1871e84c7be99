//! Zero-phase-error tracking controller (ZPETC, Tomizuka 1987): the stable
//! approximate inverse used as learning filter L of repetitive control (SPEC §3,
//! Sec. 5.2 of the thesis).
//!
//! For a discrete SISO model T(z) = z^-d B(z⁻¹)/A(z⁻¹) with B = B_s·B_u (B_u holds
//! the zeros on or outside the unit circle, monic in z⁻¹),
//!
//! L(z) = z^d A(z⁻¹) B_u(z) / (B_s(z⁻¹) B_u(1)²),
//!
//! where B_u(z) is B_u with z⁻¹ replaced by z (coefficients reversed). Then
//! T·L = B_u(z⁻¹)B_u(z)/B_u(1)² = |B_u(e^{jωT})|²/B_u(1)²: real (zero phase) at
//! every frequency and 1 at DC; T·L = 1 if T has no unstable zeros. L is
//! non-causal with a preview of l = d + deg B_u samples and realised as the causal
//! filter z^-l·L(z).

use super::linalg::{poly_from_roots, poly_trim, roots};
use super::sim::SsStepper;
use super::{Complex, LtiError, StateSpace, TransferFunction};
use crate::roles::LearningFilter;

/// A ZPETC learning filter: `filter` is the causal part z^-l·L(z), `preview` the
/// preview l in samples.
#[derive(Debug, Clone, PartialEq)]
pub struct Zpetc {
    /// The causal filter z^-l·L(z), discrete, in descending powers of z.
    pub filter: TransferFunction,
    /// Preview l = d + deg B_u (samples).
    pub preview: usize,
    /// The plant's zeros treated as unstable (|z| ≥ 1 − 1e-6), in z.
    pub unstable_zeros: Vec<Complex<f64>>,
}

impl Zpetc {
    /// Frequency response of the non-causal L(e^{jωT}) = filter·e^{jωlT} at
    /// `w_rad_s` (rad/s).
    pub fn freqresp(&self, w_rad_s: &[f64]) -> Vec<Complex<f64>> {
        let t = self.filter.dt.unwrap_or(1.0);
        self.filter
            .freqresp(w_rad_s)
            .into_iter()
            .zip(w_rad_s)
            .map(|(g, &w)| g * Complex::from_polar(1.0, w * t * self.preview as f64))
            .collect()
    }

    /// State-space realisation of the causal filter z^-l·L(z) (section cascade).
    pub fn to_ss(&self) -> Result<StateSpace, LtiError> {
        self.filter.to_ss_cascade()
    }

    /// An allocation-free runtime implementing [`LearningFilter`].
    pub fn runtime(&self) -> Result<ZpetcFilter, LtiError> {
        Ok(ZpetcFilter {
            stepper: SsStepper::new(&self.to_ss()?)?,
            preview: self.preview,
        })
    }
}

/// Runs a [`Zpetc`] filter sample by sample (the causal z^-l·L(z)).
#[derive(Debug, Clone)]
pub struct ZpetcFilter {
    stepper: SsStepper,
    preview: usize,
}

impl LearningFilter for ZpetcFilter {
    fn preview_samples(&self) -> usize {
        self.preview
    }
    fn filter(&mut self, x: f64) -> f64 {
        self.stepper.step_siso(x)
    }
    fn reset(&mut self) {
        self.stepper.reset();
    }
}

/// Zeros with |z| ≥ 1 − this count as unstable (on or outside the unit circle).
const UNIT_CIRCLE_TOL: f64 = 1e-6;

/// ZPETC of a discrete SISO transfer function (see the [module docs](self)).
pub fn zpetc(plant: &TransferFunction) -> Result<Zpetc, LtiError> {
    if plant.dt.is_none() {
        return Err(LtiError::Domain("ZPETC needs a discrete model".into()));
    }
    let den = poly_trim(&plant.den);
    let mut num = poly_trim(&plant.num);
    if num == [0.0] {
        return Err(LtiError::param(
            "num",
            "the plant is zero and cannot be inverted",
        ));
    }
    if num.len() > den.len() {
        return Err(LtiError::Improper {
            num: num.len() - 1,
            den: den.len() - 1,
        });
    }
    let d = den.len() - num.len();
    // In z⁻¹ the same coefficient lists are ascending powers; trailing zeros of
    // the numerator (zeros at z = 0) only lower its degree in z⁻¹.
    while num.len() > 1 && num.last() == Some(&0.0) {
        num.pop();
    }
    let zeros = roots(&num);
    let (unstable, stable): (Vec<Complex<f64>>, Vec<Complex<f64>>) = zeros
        .iter()
        .partition(|z| z.norm() >= 1.0 - UNIT_CIRCLE_TOL);
    let b0 = num[0];
    let bu = poly_from_roots(&unstable); // ascending in z⁻¹, bu[0] = 1
    let bs: Vec<f64> = poly_from_roots(&stable).iter().map(|c| c * b0).collect();
    let bu1: f64 = bu.iter().sum();
    if bu1.abs() < 1e-12 {
        return Err(LtiError::Singular(
            "the plant has a zero at z = 1 (B_u(1) = 0): no DC inverse".into(),
        ));
    }
    let bu_rev: Vec<f64> = bu.iter().rev().copied().collect();
    let n_poly: Vec<f64> = super::linalg::polymul(&den, &bu_rev)
        .iter()
        .map(|c| c / (bu1 * bu1))
        .collect();
    let d_poly = bs;
    // Ascending-in-z⁻¹ lists → descending in z: pad the shorter at the end.
    let q = n_poly.len().max(d_poly.len());
    let mut fnum = n_poly.clone();
    fnum.resize(q, 0.0);
    let mut fden = d_poly.clone();
    fden.resize(q, 0.0);
    let preview = d + (bu.len() - 1);
    Ok(Zpetc {
        filter: TransferFunction {
            num: fnum,
            den: fden,
            dt: plant.dt,
        },
        preview,
        unstable_zeros: unstable,
    })
}

/// ZPETC of a discrete SISO state-space model (through its transfer function;
/// for low and moderate orders).
pub fn zpetc_ss(plant: &StateSpace) -> Result<Zpetc, LtiError> {
    let tf = plant.to_tf()?;
    // Drop numerically-zero leading numerator coefficients (relative degree).
    let scale = tf.num.iter().map(|v| v.abs()).fold(0.0, f64::max);
    let mut num = tf.num.clone();
    while num.len() > 1 && num[0].abs() <= 1e-12 * scale {
        num.remove(0);
    }
    zpetc(&TransferFunction {
        num,
        den: tf.den,
        dt: tf.dt,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::lti::{C2dMethod, lsim_siso};
    use std::f64::consts::PI;

    /// Check that T·L is real, non-negative and 1 at DC; returns max |T·L − 1|.
    fn check_zero_phase(plant: &TransferFunction, z: &Zpetc) -> f64 {
        let dt = plant.dt.unwrap();
        // Start just above DC: plants with integrators are infinite at z = 1.
        let w: Vec<f64> = (0..400)
            .map(|i| PI / dt * (i as f64 + 0.05) / 400.0)
            .collect();
        let t = plant.freqresp(&w);
        let l = z.freqresp(&w);
        let mut dev: f64 = 0.0;
        for (i, (a, b)) in t.iter().zip(&l).enumerate() {
            let tl = a * b;
            assert!(
                tl.im.abs() < 1e-9 * tl.norm().max(1.0),
                "phase at {}: {tl}",
                w[i]
            );
            assert!(tl.re > -1e-9, "{tl}");
            if i == 0 {
                assert!((tl.re - 1.0).abs() < 1e-6, "DC {tl}");
            }
            dev = dev.max((tl - 1.0).norm());
        }
        dev
    }

    #[test]
    fn minimum_phase_plant_is_inverted_exactly() {
        // T = z^-2 (1 + 0.5 z⁻¹)/(1 − 1.2 z⁻¹ + 0.5 z⁻²) = (z + 0.5)/(z (z² − 1.2 z + 0.5)).
        let plant =
            TransferFunction::new(vec![1.0, 0.5], vec![1.0, -1.2, 0.5, 0.0], Some(1e-3)).unwrap();
        let z = zpetc(&plant).unwrap();
        assert_eq!(z.preview, 2);
        assert!(z.unstable_zeros.is_empty());
        assert!(check_zero_phase(&plant, &z) < 1e-10);
        // Simulated: T then z^-l L reproduces the input delayed by l.
        let u: Vec<f64> = (0..60)
            .map(|k| ((k as f64) * 0.3).sin() + if k > 10 { 1.0 } else { 0.0 })
            .collect();
        let y = lsim_siso(&plant.to_ss().unwrap(), &u).unwrap();
        let mut f = z.runtime().unwrap();
        let out: Vec<f64> = y.iter().map(|&v| f.filter(v)).collect();
        for k in 2..60 {
            assert!((out[k] - u[k - 2]).abs() < 1e-10, "k={k}");
        }
    }

    #[test]
    fn unstable_zeros_give_zero_phase_and_unit_dc() {
        // ZOH of 1/s² (zero exactly at −1) with one extra sample delay.
        let dt = 1e-3;
        let p = TransferFunction::new(vec![1.0], vec![1.0, 0.0, 0.0], None)
            .unwrap()
            .c2d(dt, C2dMethod::Zoh)
            .unwrap();
        let p = p.with_output_delay(1).unwrap().to_tf().unwrap();
        let z = zpetc(&p).unwrap();
        assert_eq!(z.unstable_zeros.len(), 1);
        assert_eq!(z.preview, 2 + 1);
        let dev = check_zero_phase(&p, &z);
        assert!(
            dev > 0.5,
            "gain must drop to 0 at Nyquist (zero at −1), deviation {dev}"
        );
        // Non-minimum-phase zero outside the unit circle, plus a stable one.
        let plant = TransferFunction::new(
            crate::lti::linalg::polymul(&[1.0, -1.5], &[1.0, 0.3]),
            vec![1.0, -1.5, 0.7, 0.0],
            Some(dt),
        )
        .unwrap();
        let z = zpetc(&plant).unwrap();
        assert_eq!(z.unstable_zeros.len(), 1);
        assert!((z.unstable_zeros[0].re - 1.5).abs() < 1e-12);
        assert_eq!(z.preview, 1 + 1);
        check_zero_phase(&plant, &z);
        assert!(z.to_ss().unwrap().is_stable());
        // Third-order ZOH plant: zeros ≈ −3.73 (unstable) and −0.27 (stable).
        let p3 = TransferFunction::new(vec![1.0], vec![1.0, 1.0, 0.0, 0.0], None)
            .unwrap()
            .c2d(0.5, C2dMethod::Zoh)
            .unwrap();
        let tf3 = p3.to_tf().unwrap();
        let z3 = zpetc(&tf3).unwrap();
        assert_eq!(z3.unstable_zeros.len(), 1);
        assert!(
            (z3.unstable_zeros[0].re + 3.0).abs() < 1.0,
            "{:?}",
            z3.unstable_zeros
        );
        check_zero_phase(&tf3, &z3);
        // From state space (a plant without integrators).
        let p4 = TransferFunction::new(vec![1.0], vec![1.0, 2.0, 2.0, 1.0], None)
            .unwrap()
            .c2d(0.5, C2dMethod::Zoh)
            .unwrap();
        let z4 = zpetc_ss(&p4).unwrap();
        assert_eq!(z4.unstable_zeros.len(), 1);
        check_zero_phase(&p4.to_tf().unwrap(), &z4);
        assert!(zpetc(&TransferFunction::new(vec![1.0], vec![1.0, 1.0], None).unwrap()).is_err());
    }
}
