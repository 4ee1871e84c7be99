//! Transfer functions: construction, evaluation, poles and zeros, zero-pole-gain
//! form, and realisations as state space (controllable canonical `tf2ss`, or the
//! better-conditioned cascade of first/second-order sections).

use super::linalg::{poly_from_roots, poly_trim, polyval, roots, split_conjugates};
use super::ss::series;
use super::{Complex, LtiError, SosSection, StateSpace, TransferFunction};
use nalgebra::DMatrix;

impl TransferFunction {
    /// num/den in descending powers of s (`dt = None`) or z (`dt = Some(T)`, T in
    /// s). Leading zeros are trimmed; fails on non-finite coefficients, a zero
    /// denominator or an improper ratio (more zeros than poles).
    pub fn new(num: Vec<f64>, den: Vec<f64>, dt: Option<f64>) -> Result<Self, LtiError> {
        if num.iter().chain(&den).any(|v| !v.is_finite()) {
            return Err(LtiError::param("num/den", "coefficients must be finite"));
        }
        if num.is_empty() {
            return Err(LtiError::param("num", "numerator is empty"));
        }
        let den = poly_trim(&den);
        if den == [0.0] {
            return Err(LtiError::param("den", "denominator is zero"));
        }
        let num = poly_trim(&num);
        if num.len() > den.len() {
            return Err(LtiError::Improper {
                num: num.len() - 1,
                den: den.len() - 1,
            });
        }
        if let Some(t) = dt
            && !(t.is_finite() && t > 0.0)
        {
            return Err(LtiError::param(
                "dt",
                format!("sample period {t} s must be finite and > 0"),
            ));
        }
        Ok(Self { num, den, dt })
    }

    /// [`TransferFunction::new`] from borrowed coefficient slices (descending
    /// powers), so that arrays and slices need no `vec!`.
    ///
    /// ```
    /// use nanomotion_core::lti::TransferFunction;
    /// let g = TransferFunction::from_slices(&[1.0], &[1.0, 2.0, 1.0], None).unwrap();
    /// assert_eq!(g.dcgain(), 1.0);
    /// assert!(TransferFunction::from_slices(&[1.0, 0.0, 0.0], &[1.0, 1.0], None).is_err());
    /// ```
    pub fn from_slices(num: &[f64], den: &[f64], dt: Option<f64>) -> Result<Self, LtiError> {
        Self::new(num.to_vec(), den.to_vec(), dt)
    }

    /// The transfer function at a complex point `x` (s or z).
    pub fn eval(&self, x: Complex<f64>) -> Complex<f64> {
        polyval(&self.num, x) / polyval(&self.den, x)
    }

    /// Frequency response at angular frequencies `w_rad_s` (rad/s): s = jω, or
    /// z = e^{jωT} for discrete models.
    pub fn freqresp(&self, w_rad_s: &[f64]) -> Vec<Complex<f64>> {
        w_rad_s
            .iter()
            .map(|&w| {
                let x = match self.dt {
                    None => Complex::new(0.0, w),
                    Some(t) => Complex::from_polar(1.0, w * t),
                };
                self.eval(x)
            })
            .collect()
    }

    /// Poles: roots of the denominator (companion-matrix eigenvalues).
    pub fn poles(&self) -> Vec<Complex<f64>> {
        roots(&self.den)
    }

    /// Zeros: roots of the numerator (companion-matrix eigenvalues).
    pub fn zeros(&self) -> Vec<Complex<f64>> {
        roots(&self.num)
    }

    /// High-frequency gain k of the zero-pole-gain form
    /// k·∏(x − zᵢ)/∏(x − pᵢ): the ratio of the leading coefficients.
    pub fn zpk_gain(&self) -> f64 {
        let n = poly_trim(&self.num);
        let d = poly_trim(&self.den);
        n[0] / d[0]
    }

    /// Steady-state gain: G(0) (continuous) or G(1) (discrete).
    pub fn dcgain(&self) -> f64 {
        let x = if self.dt.is_some() { 1.0 } else { 0.0 };
        self.eval(Complex::new(x, 0.0)).re
    }

    /// Controllable-canonical state-space realisation (python-control
    /// `tf2ss`). Fine for low orders; for high orders prefer
    /// [`TransferFunction::to_ss_cascade`].
    pub fn to_ss(&self) -> Result<StateSpace, LtiError> {
        tf2ss(self)
    }

    /// Realisation as a series cascade of real first- and second-order sections
    /// built from the poles and zeros, each section in controllable canonical form
    /// with unit-order coefficients. Much better conditioned than one
    /// high-order companion form (SPEC §1).
    pub fn to_ss_cascade(&self) -> Result<StateSpace, LtiError> {
        zpk2ss(&self.zeros(), &self.poles(), self.zpk_gain(), self.dt)
    }
}

/// Controllable canonical form of a proper SISO transfer function
/// (python-control/scipy `tf2ss` layout: A's first row is −a₁..−aₙ, B = e₁).
pub fn tf2ss(tf: &TransferFunction) -> Result<StateSpace, LtiError> {
    let den = poly_trim(&tf.den);
    let num = poly_trim(&tf.num);
    if den == [0.0] {
        return Err(LtiError::param("den", "denominator is zero"));
    }
    let n = den.len() - 1;
    if num.len() > den.len() {
        return Err(LtiError::Improper {
            num: num.len() - 1,
            den: n,
        });
    }
    let a0 = den[0];
    let a: Vec<f64> = den.iter().map(|v| v / a0).collect();
    let mut b = vec![0.0; n + 1];
    for (i, v) in num.iter().enumerate() {
        b[n + 1 - num.len() + i] = v / a0;
    }
    let d = b[0];
    let mut am = DMatrix::zeros(n, n);
    for j in 0..n {
        am[(0, j)] = -a[j + 1];
    }
    for i in 1..n {
        am[(i, i - 1)] = 1.0;
    }
    let mut bm = DMatrix::zeros(n, 1);
    if n > 0 {
        bm[(0, 0)] = 1.0;
    }
    let cm = DMatrix::from_fn(1, n, |_, j| b[j + 1] - a[j + 1] * d);
    Ok(StateSpace {
        a: am,
        b: bm,
        c: cm,
        d: DMatrix::from_element(1, 1, d),
        dt: tf.dt,
    })
}

/// Transfer function from zeros, poles and gain k: k·∏(x − zᵢ)/∏(x − pᵢ)
/// (python-control `zpk`). Complex zeros and poles must come in conjugate pairs;
/// this is not checked (an unpaired root loses its imaginary part): use
/// [`zpk_checked`] for user data.
pub fn zpk(
    zeros: &[Complex<f64>],
    poles: &[Complex<f64>],
    gain: f64,
    dt: Option<f64>,
) -> TransferFunction {
    let num: Vec<f64> = poly_from_roots(zeros).iter().map(|c| c * gain).collect();
    TransferFunction {
        num,
        den: poly_from_roots(poles),
        dt,
    }
}

/// Checked [`zpk`]: finite roots and gain, and every complex zero and pole
/// paired with its conjugate (to 1e-9 relative); an unpaired complex root is a
/// [`LtiError::Parameter`] instead of a silently dropped imaginary part.
pub fn zpk_checked(
    zeros: &[Complex<f64>],
    poles: &[Complex<f64>],
    gain: f64,
    dt: Option<f64>,
) -> Result<TransferFunction, LtiError> {
    if !gain.is_finite() {
        return Err(LtiError::param("gain", "must be finite"));
    }
    for (name, roots) in [("zeros", zeros), ("poles", poles)] {
        if roots
            .iter()
            .any(|z| !(z.re.is_finite() && z.im.is_finite()))
        {
            return Err(LtiError::param(name, "must be finite"));
        }
        let tol = |z: Complex<f64>| 1e-9 * (1.0 + z.norm());
        let mut used = vec![false; roots.len()];
        for i in 0..roots.len() {
            let z = roots[i];
            if used[i] || z.im.abs() <= tol(z) {
                continue;
            }
            let partner = (0..roots.len())
                .find(|&j| j != i && !used[j] && (roots[j] - z.conj()).norm() <= tol(z));
            match partner {
                Some(j) => {
                    used[i] = true;
                    used[j] = true;
                }
                None => {
                    return Err(LtiError::param(
                        name,
                        format!(
                            "the complex root {} {:+}i has no conjugate partner: a real transfer function needs conjugate pairs",
                            z.re, z.im
                        ),
                    ));
                }
            }
        }
    }
    TransferFunction::new(
        poly_from_roots(zeros).iter().map(|c| c * gain).collect(),
        poly_from_roots(poles),
        dt,
    )
}

/// One real section num(x)/den(x) of degree ≤ 2 (descending powers, den monic).
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct Section {
    pub num: Vec<f64>,
    pub den: Vec<f64>,
}

/// Group conjugate-paired zeros and poles into real sections of degree ≤ 2 with
/// numerator degree ≤ denominator degree; each complex zero pair goes with the
/// nearest complex-capable (second-order) section, real zeros fill what is left.
/// The gain is not included.
pub(crate) fn pair_sections(
    zeros: &[Complex<f64>],
    poles: &[Complex<f64>],
) -> Result<Vec<Section>, LtiError> {
    if zeros.len() > poles.len() {
        return Err(LtiError::Improper {
            num: zeros.len(),
            den: poles.len(),
        });
    }
    let tol = 1e-9;
    let (mut preal, pcplx) = split_conjugates(poles, tol);
    let (zreal, zcplx) = split_conjugates(zeros, tol);
    // Pole groups: each complex pair, then real poles two by two.
    struct Group {
        poles: Vec<Complex<f64>>,
        zeros: Vec<Complex<f64>>,
    }
    let mut groups: Vec<Group> = pcplx
        .iter()
        .map(|&p| Group {
            poles: vec![p, p.conj()],
            zeros: vec![],
        })
        .collect();
    preal.sort_by(|a, b| {
        b.abs()
            .partial_cmp(&a.abs())
            .unwrap_or(std::cmp::Ordering::Equal)
    });
    for ch in preal.chunks(2) {
        groups.push(Group {
            poles: ch.iter().map(|&r| Complex::new(r, 0.0)).collect(),
            zeros: vec![],
        });
    }
    let dist = |g: &Group, z: Complex<f64>| {
        g.poles
            .iter()
            .map(|p| (p - z).norm())
            .fold(f64::INFINITY, f64::min)
    };
    for &z in &zcplx {
        let best = groups
            .iter()
            .enumerate()
            .filter(|(_, g)| g.poles.len() == 2 && g.zeros.is_empty())
            .min_by(|a, b| {
                dist(a.1, z)
                    .partial_cmp(&dist(b.1, z))
                    .unwrap_or(std::cmp::Ordering::Equal)
            })
            .map(|(i, _)| i)
            .ok_or_else(|| {
                LtiError::Dimension("cannot pair complex zeros with second-order sections".into())
            })?;
        groups[best].zeros = vec![z, z.conj()];
    }
    for &r in &zreal {
        let z = Complex::new(r, 0.0);
        let best = groups
            .iter()
            .enumerate()
            .filter(|(_, g)| g.zeros.len() < g.poles.len())
            .min_by(|a, b| {
                dist(a.1, z)
                    .partial_cmp(&dist(b.1, z))
                    .unwrap_or(std::cmp::Ordering::Equal)
            })
            .map(|(i, _)| i)
            .ok_or_else(|| LtiError::Dimension("cannot pair real zeros with sections".into()))?;
        groups[best].zeros.push(z);
    }
    Ok(groups
        .iter()
        .map(|g| Section {
            num: poly_from_roots(&g.zeros),
            den: poly_from_roots(&g.poles),
        })
        .collect())
}

/// State space from zeros, poles and gain as a cascade of real first/second-order
/// sections (well conditioned for high orders).
pub fn zpk2ss(
    zeros: &[Complex<f64>],
    poles: &[Complex<f64>],
    gain: f64,
    dt: Option<f64>,
) -> Result<StateSpace, LtiError> {
    let sections = pair_sections(zeros, poles)?;
    let mut sys = StateSpace::gain(DMatrix::from_element(1, 1, gain), dt);
    for s in sections {
        let part = tf2ss(&TransferFunction {
            num: s.num,
            den: s.den,
            dt,
        })?;
        sys = series(&sys, &part)?;
    }
    Ok(sys)
}

/// Second-order sections (scipy `sos` layout, in z⁻¹) of a discrete transfer
/// function given by its zeros, poles and gain (scipy `zpk2sos`). The gain is put
/// in the first section.
pub fn zpk2sos(
    zeros: &[Complex<f64>],
    poles: &[Complex<f64>],
    gain: f64,
) -> Result<Vec<SosSection>, LtiError> {
    let sections = pair_sections(zeros, poles)?;
    let mut out = Vec::with_capacity(sections.len().max(1));
    for s in sections {
        // num(z)/den(z), deg den = 1 or 2; divide both by z^deg(den).
        let dd = s.den.len() - 1;
        let mut b = [0.0; 3];
        let mut a = [0.0; 3];
        for (i, v) in s.den.iter().enumerate() {
            a[i] = *v;
        }
        let off = dd + 1 - s.num.len();
        for (i, v) in s.num.iter().enumerate() {
            b[off + i] = *v;
        }
        out.push([b[0], b[1], b[2], a[0], a[1], a[2]]);
    }
    if out.is_empty() {
        out.push([1.0, 0.0, 0.0, 1.0, 0.0, 0.0]);
    }
    for v in &mut out[0][0..3] {
        *v *= gain;
    }
    Ok(out)
}

/// Second-order sections of a discrete transfer function (scipy `tf2sos`), via
/// its zeros and poles.
pub fn tf2sos(tf: &TransferFunction) -> Result<Vec<SosSection>, LtiError> {
    if tf.dt.is_none() {
        return Err(LtiError::Domain(
            "tf2sos needs a discrete transfer function".into(),
        ));
    }
    let num = poly_trim(&tf.num);
    let den = poly_trim(&tf.den);
    if num.len() > den.len() {
        return Err(LtiError::Improper {
            num: num.len() - 1,
            den: den.len() - 1,
        });
    }
    // Fewer zeros than poles: the sections get leading zero coefficients
    // (pure delays), see `zpk2sos`.
    zpk2sos(&tf.zeros(), &tf.poles(), tf.zpk_gain())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn new_trims_and_rejects() {
        let tf = TransferFunction::new(vec![0.0, 1.0], vec![1.0, 2.0], None).unwrap();
        assert_eq!(tf.num, vec![1.0]);
        assert!(matches!(
            TransferFunction::new(vec![1.0, 0.0, 0.0], vec![1.0, 1.0], None),
            Err(LtiError::Improper { .. })
        ));
        assert!(TransferFunction::new(vec![1.0], vec![0.0], None).is_err());
        assert!(TransferFunction::new(vec![f64::NAN], vec![1.0], None).is_err());
    }

    #[test]
    fn tf2ss_matches_evaluation() {
        let tf =
            TransferFunction::new(vec![2.0, 3.0, 5.0], vec![1.0, 0.7, 4.0, 1.5], None).unwrap();
        let ss = tf.to_ss().unwrap();
        let cas = tf.to_ss_cascade().unwrap();
        let biproper =
            TransferFunction::new(vec![2.0, 3.0, 5.0], vec![4.0, 0.7, 4.0], Some(0.01)).unwrap();
        let ssb = biproper.to_ss().unwrap();
        for &w in &[0.0, 0.2, 1.0, 2.0, 10.0, 1e3] {
            let x = Complex::new(0.0, w);
            assert!(
                (ss.evalfr(x)[(0, 0)] - tf.eval(x)).norm() < 1e-10 * tf.eval(x).norm().max(1.0)
            );
            assert!(
                (cas.evalfr(x)[(0, 0)] - tf.eval(x)).norm() < 1e-10 * tf.eval(x).norm().max(1.0)
            );
            let z = Complex::from_polar(1.0, w * 0.01);
            assert!((ssb.evalfr(z)[(0, 0)] - biproper.eval(z)).norm() < 1e-12);
        }
        // Round trip ss2tf(tf2ss(tf)) = tf.
        let back = ss.to_tf().unwrap();
        for (a, b) in back.den.iter().zip(&tf.den) {
            assert!((a - b).abs() < 1e-12);
        }
        for (a, b) in back.num.iter().zip([0.0, 2.0, 3.0, 5.0]) {
            assert!((a - b).abs() < 1e-12);
        }
    }

    #[test]
    fn poles_zeros_and_zpk() {
        let tf = zpk(
            &[Complex::new(-1.0, 2.0), Complex::new(-1.0, -2.0)],
            &[
                Complex::new(-0.5, 0.0),
                Complex::new(-3.0, 0.0),
                Complex::new(-2.0, 0.0),
            ],
            4.0,
            None,
        );
        assert_eq!(tf.num.len(), 3);
        assert!((tf.num[0] - 4.0).abs() < 1e-15 && (tf.num[2] - 20.0).abs() < 1e-12);
        let mut p: Vec<f64> = tf.poles().iter().map(|z| z.re).collect();
        p.sort_by(|a, b| a.partial_cmp(b).unwrap());
        assert!((p[0] + 3.0).abs() < 1e-10 && (p[2] + 0.5).abs() < 1e-10);
        let z = tf.zeros();
        assert!(
            z.iter()
                .all(|z| (z.re + 1.0).abs() < 1e-10 && (z.im.abs() - 2.0).abs() < 1e-10)
        );
        assert!((tf.zpk_gain() - 4.0).abs() < 1e-15);
        assert!((tf.dcgain() - 4.0 * 5.0 / 3.0).abs() < 1e-12);
    }

    #[test]
    fn tf2sos_matches_polynomial() {
        // Discrete: z^-1 (0.2 z² + 0.1) / ((z² − 1.2 z + 0.72)(z − 0.5))
        let tf = TransferFunction::new(
            vec![0.2, 0.0, 0.1],
            vec![1.0, -1.7, 1.32, -0.36],
            Some(1e-3),
        )
        .unwrap();
        let sos = tf2sos(&tf).unwrap();
        assert_eq!(sos.len(), 2);
        for &w in &[0.0, 100.0, 1000.0, 3000.0] {
            let z = Complex::from_polar(1.0, w * 1e-3);
            let zi = 1.0 / z;
            let h: Complex<f64> = sos
                .iter()
                .map(|s| (s[0] + s[1] * zi + s[2] * zi * zi) / (s[3] + s[4] * zi + s[5] * zi * zi))
                .product();
            assert!((h - tf.eval(z)).norm() < 1e-10);
        }
    }
}
