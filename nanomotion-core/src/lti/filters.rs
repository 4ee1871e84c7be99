//! Filter design and second-order-section tools: linear-phase FIR low-pass
//! ([`fir_lowpass`]), Butterworth low-pass as second-order sections
//! ([`butter_lowpass`], [`butter_lowpass_into`]), the Tustin image of one
//! continuous section ([`tustin_section`]), SOS simulation ([`SosCascade`]) and
//! conversion ([`sos2ss`], [`sos_realise_into`], [`ss2sos`], [`sos_freqresp`],
//! [`fir2ss`]).

use super::discretise::tustin_k;
use super::tf::tf2sos;
use super::{Complex, LtiError, SosSection, StateSpace};
use nalgebra::DMatrix;
use std::f64::consts::PI;

/// Linear-phase FIR low-pass filter by the window method (windowed sinc,
/// Hamming window), normalised to unity DC gain.
///
/// `n_taps` must be odd (≥ 1), so that the filter is symmetric with an integer
/// group delay q = (n_taps − 1)/2 samples (the q of the thesis's Q filters,
/// Sec. 5.2); `cutoff_hz` (Hz) is the −6 dB frequency, between 0 and the Nyquist
/// frequency 1/(2·dt); `dt` is the sample period (s). Returns the taps h[0..n]:
/// Q(z) = Σ h\[k\] z^-k.
pub fn fir_lowpass(n_taps: usize, cutoff_hz: f64, dt: f64) -> Result<Vec<f64>, LtiError> {
    if n_taps == 0 || n_taps.is_multiple_of(2) {
        return Err(LtiError::param(
            "n_taps",
            format!("{n_taps} must be odd (linear phase with an integer delay)"),
        ));
    }
    if !(dt.is_finite() && dt > 0.0) {
        return Err(LtiError::param("dt", format!("{dt} s must be > 0")));
    }
    let nyq = 0.5 / dt;
    if !(cutoff_hz.is_finite() && cutoff_hz > 0.0 && cutoff_hz < nyq) {
        return Err(LtiError::param(
            "cutoff_hz",
            format!("{cutoff_hz} Hz must be in (0, {nyq}) Hz"),
        ));
    }
    if n_taps == 1 {
        return Ok(vec![1.0]);
    }
    let fc = cutoff_hz * dt; // cycles per sample
    let q = (n_taps - 1) as f64 / 2.0;
    let mut h: Vec<f64> = (0..n_taps)
        .map(|k| {
            let t = k as f64 - q;
            let sinc = if t == 0.0 {
                2.0 * fc
            } else {
                (2.0 * PI * fc * t).sin() / (PI * t)
            };
            let w = 0.54 - 0.46 * (2.0 * PI * k as f64 / (n_taps - 1) as f64).cos();
            sinc * w
        })
        .collect();
    let sum: f64 = h.iter().sum();
    for v in &mut h {
        *v /= sum;
    }
    // Enforce exact symmetry against rounding.
    for k in 0..n_taps / 2 {
        let m = 0.5 * (h[k] + h[n_taps - 1 - k]);
        h[k] = m;
        h[n_taps - 1 - k] = m;
    }
    Ok(h)
}

/// State-space realisation of an FIR filter Σ h\[k\] z^-k at period `dt` (s): a
/// shift register of len − 1 states, D = h\[0\].
pub fn fir2ss(h: &[f64], dt: f64) -> StateSpace {
    let n = h.len().saturating_sub(1);
    let mut a = DMatrix::zeros(n, n);
    for i in 1..n {
        a[(i, i - 1)] = 1.0;
    }
    let mut b = DMatrix::zeros(n, 1);
    if n > 0 {
        b[(0, 0)] = 1.0;
    }
    let c = DMatrix::from_fn(1, n, |_, j| h[j + 1]);
    let d = DMatrix::from_element(1, 1, h.first().copied().unwrap_or(0.0));
    StateSpace {
        a,
        b,
        c,
        d,
        dt: Some(dt),
    }
}

/// Digital Butterworth low-pass of order `order` (≥ 1) with −3 dB frequency
/// `cutoff_hz` (Hz, below Nyquist) at sample period `dt` (s), as second-order
/// sections (scipy `butter(order, fc, output='sos', fs=1/dt)`); the sections of
/// [`butter_lowpass_into`] in a vector.
pub fn butter_lowpass(order: usize, cutoff_hz: f64, dt: f64) -> Result<Vec<SosSection>, LtiError> {
    let mut sos = vec![[0.0; 6]; order.div_ceil(2)];
    butter_lowpass_into(order, cutoff_hz, dt, &mut sos)?;
    Ok(sos)
}

/// [`butter_lowpass`] written into `out` (at least ⌈order/2⌉ sections; the
/// first ⌈order/2⌉ are written, their number returned). Does not allocate
/// unless it refuses: a filter block re-designs itself with it between two
/// ticks when its corner changes.
///
/// Analog prototype poles ωₐ·e^{jπ(2k+n+1)/(2n)} with the pre-warped cutoff
/// ωₐ = (2/T)·tan(π f_c T), mapped by the bilinear transform; all zeros at z = −1.
/// Each section has unity DC gain, so the cascade has too; odd orders end with a
/// first-order section (b₂ = a₂ = 0).
pub fn butter_lowpass_into(
    order: usize,
    cutoff_hz: f64,
    dt: f64,
    out: &mut [SosSection],
) -> Result<usize, LtiError> {
    if order == 0 {
        return Err(LtiError::param("order", "must be ≥ 1"));
    }
    if !(dt.is_finite() && dt > 0.0) {
        return Err(LtiError::param("dt", format!("{dt} s must be > 0")));
    }
    let nyq = 0.5 / dt;
    if !(cutoff_hz.is_finite() && cutoff_hz > 0.0 && cutoff_hz < nyq) {
        return Err(LtiError::param(
            "cutoff_hz",
            format!("{cutoff_hz} Hz must be in (0, {nyq}) Hz"),
        ));
    }
    let sections = order.div_ceil(2);
    let Some(out) = out.get_mut(..sections) else {
        return Err(LtiError::param(
            "sos",
            format!(
                "{} sections given, order {order} needs {sections}",
                out.len()
            ),
        ));
    };
    let wa = 2.0 / dt * (PI * cutoff_hz * dt).tan();
    let n = order as f64;
    let bilinear = |p: Complex<f64>| (1.0 + p * (dt / 2.0)) / (1.0 - p * (dt / 2.0));
    for (k, s) in out.iter_mut().enumerate().take(order / 2) {
        let theta = PI * (2.0 * k as f64 + n + 1.0) / (2.0 * n);
        let pz = bilinear(Complex::from_polar(wa, theta));
        let a1 = -2.0 * pz.re;
        let a2 = pz.norm_sqr();
        let g = (1.0 + a1 + a2) / 4.0;
        *s = [g, 2.0 * g, g, 1.0, a1, a2];
    }
    if order % 2 == 1 {
        let pz = bilinear(Complex::new(-wa, 0.0)).re;
        let g = (1.0 - pz) / 2.0;
        out[sections - 1] = [g, g, 0.0, 1.0, -pz, 0.0];
    }
    Ok(sections)
}

/// The bilinear (Tustin) image of one continuous section
/// N(s)/D(s) = (n₂s² + n₁s + n₀)/(d₂s² + d₁s + d₀) (`num`, `den`: highest power
/// first) at sample period `dt` (s): s = k·(1 − z⁻¹)/(1 + z⁻¹), k = 2/T or,
/// pre-warped at `prewarp_hz` (below Nyquist), the k of [`c2d`](super::c2d)'s
/// Tustin. Normalised to a₀ = 1. A first-order section (n₂ = d₂ = 0) gives
/// b₂ = a₂ = 0 and b₀ = n₁k + n₀, b₁ = n₀ − n₁k over a₀ = d₁k + d₀,
/// a₁ = d₀ − d₁k; a second-order one b₀ = n₂k² + n₁k + n₀, b₁ = 2(n₀ − n₂k²),
/// b₂ = n₂k² − n₁k + n₀ (and the same for a). Closed form, allocation-free
/// unless it refuses; a D(s) whose a₀ vanishes gives non-finite coefficients,
/// which [`sos_realise_into`] refuses.
pub fn tustin_section(
    num: [f64; 3],
    den: [f64; 3],
    dt: f64,
    prewarp_hz: Option<f64>,
) -> Result<SosSection, LtiError> {
    let k = tustin_k(prewarp_hz, dt)?;
    let first_order = num[0] == 0.0 && den[0] == 0.0;
    let map = |[p2, p1, p0]: [f64; 3]| {
        if first_order {
            [p1 * k + p0, p0 - p1 * k, 0.0]
        } else {
            let k2 = p2 * k * k;
            [k2 + p1 * k + p0, 2.0 * (p0 - k2), k2 - p1 * k + p0]
        }
    };
    let (b, a) = (map(num), map(den));
    Ok([
        b[0] / a[0],
        b[1] / a[0],
        b[2] / a[0],
        1.0,
        a[1] / a[0],
        a[2] / a[0],
    ])
}

/// Frequency response of an SOS cascade at `w_rad_s` (rad/s), period `dt` (s).
pub fn sos_freqresp(sos: &[SosSection], dt: f64, w_rad_s: &[f64]) -> Vec<Complex<f64>> {
    w_rad_s
        .iter()
        .map(|&w| {
            let zi = Complex::from_polar(1.0, -w * dt);
            sos.iter()
                .map(|s| (s[0] + zi * (s[1] + zi * s[2])) / (s[3] + zi * (s[4] + zi * s[5])))
                .product()
        })
        .collect()
}

/// Series state-space realisation of an SOS cascade at period `dt` (s), each
/// section in direct form II transposed (see [`sos_realise_into`]); a cascade
/// ending with a first-order section (b₂ = a₂ = 0) gives it one state.
pub fn sos2ss(sos: &[SosSection], dt: f64) -> Result<StateSpace, LtiError> {
    let last_first_order = sos.last().is_some_and(|s| s[2] == 0.0 && s[5] == 0.0);
    let n = 2 * sos.len() - usize::from(last_first_order);
    let mut sys = StateSpace {
        a: DMatrix::zeros(n, n),
        b: DMatrix::zeros(n, 1),
        c: DMatrix::zeros(1, n),
        d: DMatrix::zeros(1, 1),
        dt: Some(dt),
    };
    sos_realise_into(sos, &mut sys)?;
    Ok(sys)
}

/// Write the series realisation of the cascade `sos` into `sys` (a discrete
/// 1×1 model of 2·len states, or 2·len − 1 when the last section is
/// first-order, b₂ = a₂ = 0), overwriting A, B, C and D; nothing else changes
/// and nothing is allocated unless it refuses (a section with a₀ = 0 or a
/// non-finite coefficient, or a model of other dimensions: `sys` is then left
/// as it was). The state of section i is its direct-form-II-transposed delay
/// line (z₀, z₁) (scipy `sosfilt`, [`SosCascade`]): with v its input,
/// y = b₀v + z₀, z₀ ← −a₁z₀ + z₁ + (b₁ − a₁b₀)v, z₁ ← −a₂z₀ + (b₂ − a₂b₀)v
/// (coefficients over a₀), and v of section i + 1 is y of section i. A filter
/// block whose corner changes re-derives its model with this, keeping the
/// delay lines.
pub fn sos_realise_into(sos: &[SosSection], sys: &mut StateSpace) -> Result<(), LtiError> {
    let n = sys.a.nrows();
    let last_first_order = n + 1 == 2 * sos.len();
    let shape_ok = (n == 2 * sos.len() || last_first_order)
        && sys.a.shape() == (n, n)
        && sys.b.shape() == (n, 1)
        && sys.c.shape() == (1, n)
        && sys.d.shape() == (1, 1)
        && sys.dt.is_some();
    if !shape_ok {
        return Err(LtiError::Dimension(format!(
            "{} sections do not fit a {}×{} discrete model of {n} states",
            sos.len(),
            sys.noutputs(),
            sys.ninputs()
        )));
    }
    if let Some(bad) = sos
        .iter()
        .position(|s| s[3] == 0.0 || s.iter().any(|x| !x.is_finite()))
    {
        return Err(LtiError::param(
            "sos",
            format!("section {bad} needs finite coefficients and a0 ≠ 0"),
        ));
    }
    if last_first_order && sos.last().is_some_and(|s| s[2] != 0.0 || s[5] != 0.0) {
        return Err(LtiError::param(
            "sos",
            "the last section has one state but b2 or a2 ≠ 0",
        ));
    }
    sys.a.fill(0.0);
    sys.b.fill(0.0);
    sys.c.fill(0.0);
    // C and D express the input v of the section being written in the states
    // of the sections before it and in u: v₁ = u.
    sys.d[(0, 0)] = 1.0;
    let mut o = 0; // first state of the section
    for (i, s) in sos.iter().enumerate() {
        let [b0, b1, b2, _, a1, a2] = s.map(|x| x / s[3]);
        let states = if last_first_order && i + 1 == sos.len() {
            1
        } else {
            2
        };
        // B of the section (v → z) and its rows of A.
        let bs = [b1 - a1 * b0, b2 - a2 * b0];
        let ars = [[-a1, 1.0], [-a2, 0.0]];
        for (r, (b, row)) in bs.iter().zip(&ars).enumerate().take(states) {
            for j in 0..o {
                sys.a[(o + r, j)] = b * sys.c[(0, j)];
            }
            for (j, a) in row.iter().enumerate().take(states) {
                sys.a[(o + r, o + j)] = *a;
            }
            sys.b[(o + r, 0)] = b * sys.d[(0, 0)];
        }
        // The section's output y = b₀v + z₀ is the next section's input.
        for j in 0..o {
            sys.c[(0, j)] *= b0;
        }
        sys.c[(0, o)] = 1.0;
        sys.d[(0, 0)] *= b0;
        o += states;
    }
    Ok(())
}

/// Second-order sections of a discrete SISO state-space model (via its transfer
/// function; for low and moderate orders).
pub fn ss2sos(sys: &StateSpace) -> Result<Vec<SosSection>, LtiError> {
    tf2sos(&sys.to_tf()?)
}

/// Runs an SOS cascade sample by sample in direct form II transposed (scipy
/// `sosfilt`); allocation-free after construction.
#[derive(Debug, Clone, PartialEq)]
pub struct SosCascade {
    /// Sections normalised to a0 = 1.
    sos: Vec<SosSection>,
    /// Two delay-line values per section.
    state: Vec<[f64; 2]>,
}

impl SosCascade {
    /// A cascade of `sos` (each section normalised by its a0), zero state.
    pub fn new(sos: &[SosSection]) -> Result<Self, LtiError> {
        let mut v = Vec::with_capacity(sos.len());
        for s in sos {
            if s[3] == 0.0 || s.iter().any(|x| !x.is_finite()) {
                return Err(LtiError::param(
                    "sos",
                    "each section needs finite coefficients and a0 ≠ 0",
                ));
            }
            let a0 = s[3];
            v.push([s[0] / a0, s[1] / a0, s[2] / a0, 1.0, s[4] / a0, s[5] / a0]);
        }
        Ok(Self {
            state: vec![[0.0; 2]; v.len()],
            sos: v,
        })
    }

    /// One sample in, one sample out.
    pub fn step(&mut self, x: f64) -> f64 {
        let mut v = x;
        for (s, z) in self.sos.iter().zip(self.state.iter_mut()) {
            let y = s[0] * v + z[0];
            z[0] = s[1] * v - s[4] * y + z[1];
            z[1] = s[2] * v - s[5] * y;
            v = y;
        }
        v
    }

    /// Filter a whole sequence from the current state.
    pub fn filter(&mut self, x: &[f64]) -> Vec<f64> {
        x.iter().map(|&v| self.step(v)).collect()
    }

    /// Clear the delay lines.
    pub fn reset(&mut self) {
        for z in &mut self.state {
            *z = [0.0; 2];
        }
    }

    /// The (normalised) sections.
    pub fn sections(&self) -> &[SosSection] {
        &self.sos
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::lti::lsim_siso;

    #[test]
    fn fir_is_symmetric_unity_dc_and_attenuates() {
        let dt = 1.0 / 4000.0;
        let h = fir_lowpass(51, 200.0, dt).unwrap();
        assert_eq!(h.len(), 51);
        for k in 0..51 {
            assert_eq!(h[k], h[50 - k]);
        }
        assert!((h.iter().sum::<f64>() - 1.0).abs() < 1e-14);
        let ss = fir2ss(&h, dt);
        // Linear phase: H(e^{jωT}) e^{jωqT} is real.
        for &f in &[5.0, 20.0, 40.0] {
            let w = 2.0 * PI * f;
            let g = ss.freqresp_siso_at(w) * Complex::from_polar(1.0, w * 25.0 * dt);
            assert!(g.im.abs() < 1e-12, "{g}");
            assert!((g.re - 1.0).abs() < 0.02, "passband {f}: {g}");
        }
        // Hamming stop band: below −50 dB well past the transition band.
        for f in (600..2000).step_by(50) {
            let g = ss.freqresp_siso_at(2.0 * PI * f as f64).norm();
            assert!(20.0 * g.log10() < -50.0, "{f} Hz: {g}");
        }
        // −6 dB near the cutoff.
        let gc = ss.freqresp_siso_at(2.0 * PI * 200.0).norm();
        assert!((gc - 0.5).abs() < 0.03, "{gc}");
        assert!(fir_lowpass(50, 200.0, dt).is_err());
        assert!(fir_lowpass(51, 2500.0, dt).is_err());
    }

    #[test]
    fn butterworth_is_maximally_flat_with_3db_at_cutoff() {
        let dt = 1.0 / 4000.0;
        for order in 1..=8 {
            let fc = 300.0;
            let sos = butter_lowpass(order, fc, dt).unwrap();
            assert_eq!(sos.len(), order.div_ceil(2));
            let g = |f: f64| sos_freqresp(&sos, dt, &[2.0 * PI * f])[0].norm();
            assert!((g(0.0) - 1.0).abs() < 1e-14);
            assert!((g(fc) - 0.5f64.sqrt()).abs() < 1e-12, "order {order}");
            // Digital Butterworth: |H|² = 1/(1 + (tan(πfT)/tan(π fc T))^{2n}).
            for &f in &[10.0, 100.0, 250.0, 500.0, 1500.0] {
                let r = (PI * f * dt).tan() / (PI * fc * dt).tan();
                let want = 1.0 / (1.0 + r.powi(2 * order as i32)).sqrt();
                assert!((g(f) - want).abs() < 1e-12, "order {order} f {f}");
            }
            // Zero at Nyquist.
            assert!(g(1999.999) < 1e-3);
        }
        assert!(butter_lowpass(0, 10.0, dt).is_err());
        assert!(butter_lowpass(2, 2000.0, dt).is_err());
    }

    #[test]
    fn the_realisations_state_is_the_cascades_delay_lines() {
        // 5th order: two biquads and a first-order section (5 states).
        let dt = 1e-3;
        let sos = butter_lowpass(5, 40.0, dt).unwrap();
        let mut sys = sos2ss(&sos, dt).unwrap();
        let mut stepper = crate::lti::SsStepper::new(&sys).unwrap();
        let mut casc = SosCascade::new(&sos).unwrap();
        let mut rng = crate::rng::Rng::new(3);
        for _ in 0..200 {
            let u = rng.normal();
            let y = stepper.step_siso(u);
            assert!((y - casc.step(u)).abs() < 1e-12);
            let z: Vec<f64> = casc.state.iter().flatten().copied().take(5).collect();
            for (a, b) in stepper.state().iter().zip(&z) {
                assert!((a - b).abs() < 1e-12, "{a} {b}");
            }
        }
        // Refusals leave the model as it was: too few sections, a0 = 0, a
        // last section with one state but b2 ≠ 0.
        let kept = sys.clone();
        assert!(sos_realise_into(&sos[..2], &mut sys).is_err());
        let mut zero_a0 = sos.clone();
        zero_a0[1][3] = 0.0;
        assert!(sos_realise_into(&zero_a0, &mut sys).is_err());
        let mut second = sos.clone();
        second[2][2] = 0.1;
        assert!(sos_realise_into(&second, &mut sys).is_err());
        assert_eq!(sys, kept);
        // A model of the same shape takes a new design in place.
        let other = butter_lowpass(5, 90.0, dt).unwrap();
        sos_realise_into(&other, &mut sys).unwrap();
        assert_eq!(sys, sos2ss(&other, dt).unwrap());
    }

    #[test]
    fn sos_cascade_state_space_and_frequency_response_agree() {
        let dt = 1e-3;
        let sos = butter_lowpass(5, 40.0, dt).unwrap();
        let ss = sos2ss(&sos, dt).unwrap();
        assert_eq!(ss.nstates(), 5);
        let mut casc = SosCascade::new(&sos).unwrap();
        let mut rng = crate::rng::Rng::new(1);
        let u: Vec<f64> = (0..500).map(|_| rng.normal()).collect();
        let y1 = casc.filter(&u);
        let y2 = lsim_siso(&ss, &u).unwrap();
        for (a, b) in y1.iter().zip(&y2) {
            assert!((a - b).abs() < 1e-12);
        }
        let w = [1.0, 100.0, 300.0, 1000.0];
        for (a, b) in sos_freqresp(&sos, dt, &w).iter().zip(ss.freqresp_siso(&w)) {
            assert!((a - b).norm() < 1e-12);
        }
        // Round trip through ss2sos.
        let back = ss2sos(&ss).unwrap();
        for (a, b) in sos_freqresp(&back, dt, &w).iter().zip(ss.freqresp_siso(&w)) {
            assert!((a - b).norm() < 1e-9, "{a} {b}");
        }
        // Impulse response of the cascade vs pulse through DF2T by hand (first section).
        casc.reset();
        let s = casc.sections()[0];
        let h0 = casc.step(1.0);
        assert!(h0 > 0.0 && (h0 - s[0] * sos[1][0] * sos[2][0]).abs() < 1e-15);
    }
}
