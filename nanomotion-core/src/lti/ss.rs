//! State-space operations: construction, interconnection (`series`, `parallel`,
//! `feedback`, `append`), poles and stability, frequency response, delays as states,
//! balancing.

use super::linalg::{balance, eigvals, poly_from_roots, solve_complex};
use super::{Complex, LtiError, StateSpace, TransferFunction};
use nalgebra::DMatrix;
use std::f64::consts::PI;

fn same_dt(a: Option<f64>, b: Option<f64>) -> bool {
    match (a, b) {
        (None, None) => true,
        (Some(x), Some(y)) => (x - y).abs() <= 1e-12 * x.abs().max(y.abs()),
        _ => false,
    }
}

/// The common sample period of two systems (static gains adopt the other's).
fn common_dt(s1: &StateSpace, s2: &StateSpace) -> Result<Option<f64>, LtiError> {
    if same_dt(s1.dt, s2.dt) {
        Ok(s1.dt)
    } else if s1.nstates() == 0 && s1.dt.is_none() {
        Ok(s2.dt)
    } else if s2.nstates() == 0 && s2.dt.is_none() {
        Ok(s1.dt)
    } else {
        Err(LtiError::SampleTime(s1.dt, s2.dt))
    }
}

/// s = jω for a continuous model (`dt` = `None`), z = e^{jωT} for a discrete
/// one: where angular frequency `w_rad_s` (rad/s) is evaluated.
pub(crate) fn frequency_point(dt: Option<f64>, w_rad_s: f64) -> Complex<f64> {
    match dt {
        None => Complex::new(0.0, w_rad_s),
        Some(t) => Complex::from_polar(1.0, w_rad_s * t),
    }
}

fn to_complex(m: &DMatrix<f64>) -> DMatrix<Complex<f64>> {
    m.map(|v| Complex::new(v, 0.0))
}

fn check_parts(
    a: &DMatrix<f64>,
    b: &DMatrix<f64>,
    c: &DMatrix<f64>,
    d: &DMatrix<f64>,
    dt: Option<f64>,
) -> Result<(), LtiError> {
    let n = a.nrows();
    if a.ncols() != n {
        return Err(LtiError::Dimension(format!(
            "A is {}×{}, must be square",
            a.nrows(),
            a.ncols()
        )));
    }
    if b.nrows() != n {
        return Err(LtiError::Dimension(format!(
            "B has {} rows, A has {n}",
            b.nrows()
        )));
    }
    if c.ncols() != n {
        return Err(LtiError::Dimension(format!(
            "C has {} columns, A has {n} rows",
            c.ncols()
        )));
    }
    if d.nrows() != c.nrows() || d.ncols() != b.ncols() {
        return Err(LtiError::Dimension(format!(
            "D is {}×{}, must be {}×{} (outputs × inputs)",
            d.nrows(),
            d.ncols(),
            c.nrows(),
            b.ncols()
        )));
    }
    if let Some(t) = dt
        && !(t.is_finite() && t > 0.0)
    {
        return Err(LtiError::param(
            "dt",
            format!("sample period {t} s must be finite and > 0"),
        ));
    }
    for (name, m) in [("a", a), ("b", b), ("c", c), ("d", d)] {
        if let Some(k) = m.iter().position(|v| !v.is_finite()) {
            return Err(LtiError::param(
                name,
                format!(
                    "entry ({}, {}) is {} (entries must be finite)",
                    k % m.nrows().max(1),
                    k / m.nrows().max(1),
                    m.as_slice()[k]
                ),
            ));
        }
    }
    Ok(())
}

/// The common length of `rows` (`None` for no rows), or the first row whose
/// length differs from the first row's.
fn row_width<R: AsRef<[f64]>>(matrix: &'static str, rows: &[R]) -> Result<Option<usize>, LtiError> {
    let Some(first) = rows.first() else {
        return Ok(None);
    };
    let expected = first.as_ref().len();
    match rows.iter().position(|r| r.as_ref().len() != expected) {
        Some(row) => Err(LtiError::RaggedRows {
            matrix,
            row,
            len: rows[row].as_ref().len(),
            expected,
        }),
        None => Ok(Some(expected)),
    }
}

/// A matrix from rows of equal length `width`.
fn rows_to_matrix<R: AsRef<[f64]>>(rows: &[R], width: usize) -> DMatrix<f64> {
    DMatrix::from_fn(rows.len(), width, |i, j| rows[i].as_ref()[j])
}

impl StateSpace {
    /// A state-space model, checking that the dimensions of A (n×n), B (n×m),
    /// C (p×n) and D (p×m) fit and that `dt` (s), if given, is positive.
    pub fn new(
        a: DMatrix<f64>,
        b: DMatrix<f64>,
        c: DMatrix<f64>,
        d: DMatrix<f64>,
        dt: Option<f64>,
    ) -> Result<Self, LtiError> {
        check_parts(&a, &b, &c, &d, dt)?;
        Ok(Self { a, b, c, d, dt })
    }

    /// A model from plain rows, without building nalgebra matrices: A (n×n),
    /// B (n×m), C (p×n), D (p×m) as slices of rows (`&[Vec<f64>]`,
    /// `&[&[f64]]`, `&[[f64; N]]`, ...), `dt` in seconds or `None` for
    /// continuous time.
    ///
    /// Rows of unequal length within one matrix are a
    /// [`LtiError::RaggedRows`] naming the matrix and the row; shapes that do
    /// not fit together are a [`LtiError::Dimension`], non-finite entries a
    /// [`LtiError::Parameter`] (the checks of [`StateSpace::new`]). An empty
    /// `d` is the p×m zero matrix (python-control's `D = 0`). Without states
    /// (`a` empty) the number of inputs is taken from the rows of `d` and the
    /// number of outputs from `d` when `c` is empty; [`StateSpace::gain`] is
    /// the plainer way to build a static gain.
    ///
    /// ```
    /// use nanomotion_core::lti::{LtiError, StateSpace};
    /// let a = vec![vec![0.0, 1.0], vec![-2.0, -3.0]];
    /// let sys = StateSpace::from_rows(&a, &[[0.0], [1.0]], &[[1.0, 0.0]], &[] as &[[f64; 1]], None)
    ///     .unwrap();
    /// assert_eq!(sys.d.shape(), (1, 1));
    /// let ragged = vec![vec![0.0, 1.0], vec![-2.0]];
    /// let e = StateSpace::from_rows(&ragged, &[[0.0], [1.0]], &[[1.0, 0.0]], &[[0.0]], None)
    ///     .unwrap_err();
    /// assert!(matches!(e, LtiError::RaggedRows { matrix: "a", row: 1, len: 1, expected: 2 }));
    /// ```
    pub fn from_rows<RA, RB, RC, RD>(
        a: &[RA],
        b: &[RB],
        c: &[RC],
        d: &[RD],
        dt: Option<f64>,
    ) -> Result<Self, LtiError>
    where
        RA: AsRef<[f64]>,
        RB: AsRef<[f64]>,
        RC: AsRef<[f64]>,
        RD: AsRef<[f64]>,
    {
        let wa = row_width("a", a)?;
        let wb = row_width("b", b)?;
        let wc = row_width("c", c)?;
        let wd = row_width("d", d)?;
        let n = a.len();
        let m = match (wb, wd) {
            (Some(m), _) => m,
            (None, Some(m)) if n == 0 => m,
            _ => 0,
        };
        let p = if c.is_empty() && n == 0 {
            d.len()
        } else {
            c.len()
        };
        let am = rows_to_matrix(a, wa.unwrap_or(0));
        let bm = rows_to_matrix(b, wb.unwrap_or(m));
        let cm = if c.is_empty() {
            DMatrix::zeros(p, n)
        } else {
            rows_to_matrix(c, wc.unwrap_or(n))
        };
        let dm = if d.is_empty() {
            DMatrix::zeros(p, m)
        } else {
            rows_to_matrix(d, wd.unwrap_or(m))
        };
        Self::new(am, bm, cm, dm, dt)
    }

    /// Re-checks the invariants of [`StateSpace::new`] (fitting dimensions,
    /// finite entries, positive finite `dt`) on a model whose public fields may
    /// have been set directly. The toolkit's fallible operations call it, so a
    /// hand-built inconsistent model gives a typed error instead of a panic
    /// inside nalgebra.
    pub fn validate(&self) -> Result<(), LtiError> {
        check_parts(&self.a, &self.b, &self.c, &self.d, self.dt)
    }

    /// A static gain y = D u (no states).
    pub fn gain(d: DMatrix<f64>, dt: Option<f64>) -> Self {
        let (p, m) = d.shape();
        Self {
            a: DMatrix::zeros(0, 0),
            b: DMatrix::zeros(0, m),
            c: DMatrix::zeros(p, 0),
            d,
            dt,
        }
    }

    /// Number of states n.
    pub fn nstates(&self) -> usize {
        self.a.nrows()
    }
    /// Number of inputs m.
    pub fn ninputs(&self) -> usize {
        self.b.ncols()
    }
    /// Number of outputs p.
    pub fn noutputs(&self) -> usize {
        self.c.nrows()
    }
    /// Whether the model is discrete-time.
    pub fn is_discrete(&self) -> bool {
        self.dt.is_some()
    }
    /// Whether the model has one input and one output.
    pub fn is_siso(&self) -> bool {
        self.ninputs() == 1 && self.noutputs() == 1
    }
    /// Whether any output depends on the input of the same instant (D ≠ 0).
    pub fn has_feedthrough(&self) -> bool {
        self.d.iter().any(|&v| v != 0.0)
    }

    /// Poles: the eigenvalues of A (rad/s for continuous, z-plane for discrete).
    /// A hand-built model whose A is not square or has a non-finite entry gives
    /// NaN poles (one per row of A; [`StateSpace::try_poles`] gives an error).
    pub fn poles(&self) -> Vec<Complex<f64>> {
        self.try_poles()
            .unwrap_or_else(|_| vec![Complex::new(f64::NAN, f64::NAN); self.a.nrows()])
    }

    /// Poles (see [`StateSpace::poles`]), or the error of
    /// [`StateSpace::validate`] for an inconsistent model.
    pub fn try_poles(&self) -> Result<Vec<Complex<f64>>, LtiError> {
        self.validate()?;
        Ok(eigvals(&self.a))
    }

    /// Asymptotic stability: all poles strictly inside the unit circle (discrete)
    /// or strictly in the left half plane (continuous). A model without states is
    /// stable; an inconsistent hand-built model (see [`StateSpace::validate`])
    /// is not.
    pub fn is_stable(&self) -> bool {
        let Ok(p) = self.try_poles() else {
            return false;
        };
        match self.dt {
            Some(_) => p.iter().all(|z| z.norm() < 1.0),
            None => p.iter().all(|s| s.re < 0.0),
        }
    }

    /// The transfer matrix G(x) = C (xI − A)⁻¹ B + D at a complex point `x`
    /// (x = s for continuous, x = z for discrete models). Entries are infinite
    /// (NaN) at a pole. An inconsistent hand-built model (see
    /// [`StateSpace::validate`]) gives a NaN matrix of C's rows × B's columns
    /// ([`StateSpace::try_evalfr`] gives the error).
    pub fn evalfr(&self, x: Complex<f64>) -> DMatrix<Complex<f64>> {
        if self.validate().is_err() {
            return DMatrix::from_element(
                self.noutputs(),
                self.ninputs(),
                Complex::new(f64::NAN, f64::NAN),
            );
        }
        self.evalfr_valid(x)
    }

    /// The transfer matrix at `x` (see [`StateSpace::evalfr`]), or the error of
    /// [`StateSpace::validate`] for an inconsistent model.
    pub fn try_evalfr(&self, x: Complex<f64>) -> Result<DMatrix<Complex<f64>>, LtiError> {
        self.validate()?;
        Ok(self.evalfr_valid(x))
    }

    fn evalfr_valid(&self, x: Complex<f64>) -> DMatrix<Complex<f64>> {
        let n = self.nstates();
        let mut g = to_complex(&self.d);
        if n == 0 {
            return g;
        }
        let mut m = self.a.map(|v| Complex::new(-v, 0.0));
        for i in 0..n {
            m[(i, i)] += x;
        }
        match solve_complex(m, &to_complex(&self.b)) {
            Some(sol) => {
                g += to_complex(&self.c) * sol;
                g
            }
            None => DMatrix::from_element(
                self.noutputs(),
                self.ninputs(),
                Complex::new(f64::NAN, f64::NAN),
            ),
        }
    }

    /// The point of the s- or z-plane where frequency `w_rad_s` (rad/s) is
    /// evaluated: s = jω (continuous) or z = e^{jωT} (discrete).
    pub fn frequency_point(&self, w_rad_s: f64) -> Complex<f64> {
        frequency_point(self.dt, w_rad_s)
    }

    /// Frequency response G(jω) (continuous) or G(e^{jωT}) (discrete) at the
    /// angular frequencies `w_rad_s` (rad/s): one p×m complex matrix per frequency.
    /// NaN matrices for an inconsistent hand-built model (see
    /// [`StateSpace::evalfr`]; [`StateSpace::try_freqresp`] gives the error).
    /// (A dense LU per point; for many points of a large model,
    /// [`StateSpace::frequency_evaluator`] costs O(n²) per point.)
    pub fn freqresp(&self, w_rad_s: &[f64]) -> Vec<DMatrix<Complex<f64>>> {
        w_rad_s
            .iter()
            .map(|&w| self.evalfr(self.frequency_point(w)))
            .collect()
    }

    /// Frequency response at `w_rad_s` (rad/s) (see [`StateSpace::freqresp`]),
    /// or the error of [`StateSpace::validate`] for an inconsistent model.
    pub fn try_freqresp(&self, w_rad_s: &[f64]) -> Result<Vec<DMatrix<Complex<f64>>>, LtiError> {
        self.validate()?;
        Ok(self.freqresp(w_rad_s))
    }

    /// SISO frequency response at one angular frequency `w_rad_s` (rad/s); for a
    /// MIMO model, the (0, 0) entry (use [`StateSpace::try_freqresp_siso`] for
    /// an error instead); NaN for a model without inputs or outputs and for an
    /// inconsistent hand-built model.
    pub fn freqresp_siso_at(&self, w_rad_s: f64) -> Complex<f64> {
        self.evalfr(self.frequency_point(w_rad_s))
            .get((0, 0))
            .copied()
            .unwrap_or(Complex::new(f64::NAN, f64::NAN))
    }

    /// SISO frequency response at the angular frequencies `w_rad_s` (rad/s); for a
    /// MIMO model, the (0, 0) entry (NaN as for
    /// [`StateSpace::freqresp_siso_at`]).
    pub fn freqresp_siso(&self, w_rad_s: &[f64]) -> Vec<Complex<f64>> {
        w_rad_s.iter().map(|&w| self.freqresp_siso_at(w)).collect()
    }

    /// Checked SISO frequency response at `w_rad_s` (rad/s): a
    /// [`LtiError::Dimension`] for a MIMO model instead of its (0, 0) entry,
    /// the error of [`StateSpace::validate`] for an inconsistent one.
    pub fn try_freqresp_siso(&self, w_rad_s: &[f64]) -> Result<Vec<Complex<f64>>, LtiError> {
        self.require_siso("try_freqresp_siso")?;
        Ok(self.freqresp_siso(w_rad_s))
    }

    /// Checked SISO Bode data (see [`StateSpace::bode`]): a
    /// [`LtiError::Dimension`] for a MIMO model.
    pub fn try_bode(&self, w_rad_s: &[f64]) -> Result<(Vec<f64>, Vec<f64>), LtiError> {
        self.require_siso("try_bode")?;
        Ok(self.bode(w_rad_s))
    }

    fn require_siso(&self, what: &str) -> Result<(), LtiError> {
        self.validate()?;
        if self.is_siso() {
            Ok(())
        } else {
            Err(LtiError::Dimension(format!(
                "{what} needs a SISO model, this one is {}×{} (use freqresp for the matrix response)",
                self.noutputs(),
                self.ninputs()
            )))
        }
    }

    /// SISO Bode data at `w_rad_s` (rad/s): magnitudes (absolute, not dB) and
    /// phases (rad, unwrapped along the frequency vector), as python-control's
    /// `bode(..., plot=False)`.
    pub fn bode(&self, w_rad_s: &[f64]) -> (Vec<f64>, Vec<f64>) {
        let g = self.freqresp_siso(w_rad_s);
        let mag = g.iter().map(|z| z.norm()).collect();
        (
            mag,
            unwrap_phase(&g.iter().map(|z| z.arg()).collect::<Vec<_>>()),
        )
    }

    /// Steady-state (DC) gain: G(0) continuous, G(1) discrete (NaN for an
    /// inconsistent hand-built model, as [`StateSpace::evalfr`]).
    pub fn dcgain(&self) -> DMatrix<Complex<f64>> {
        self.evalfr(self.dc_point())
    }

    /// Steady-state gain (see [`StateSpace::dcgain`]), or the error of
    /// [`StateSpace::validate`] for an inconsistent model.
    pub fn try_dcgain(&self) -> Result<DMatrix<Complex<f64>>, LtiError> {
        self.try_evalfr(self.dc_point())
    }

    fn dc_point(&self) -> Complex<f64> {
        if self.dt.is_some() {
            Complex::new(1.0, 0.0)
        } else {
            Complex::new(0.0, 0.0)
        }
    }

    /// The same system with A balanced by a diagonal similarity transform
    /// (see [`balance`]): same transfer function, better
    /// conditioned matrices. An inconsistent hand-built model (see
    /// [`StateSpace::validate`]) is returned unchanged.
    pub fn balanced(&self) -> StateSpace {
        if self.validate().is_err() {
            return self.clone();
        }
        let (a, d) = balance(&self.a);
        let mut b = self.b.clone();
        let mut c = self.c.clone();
        for i in 0..self.nstates() {
            b.row_mut(i).scale_mut(1.0 / d[i]);
            c.column_mut(i).scale_mut(d[i]);
        }
        StateSpace {
            a,
            b,
            c,
            d: self.d.clone(),
            dt: self.dt,
        }
    }

    /// The system preceded by a delay of `d` samples on every input,
    /// G(z)·z^-d, with the delay realised as states (discrete models only).
    pub fn with_input_delay(&self, d: usize) -> Result<StateSpace, LtiError> {
        let dt = self.dt.ok_or_else(|| {
            LtiError::Domain("input delay in samples needs a discrete model".into())
        })?;
        let del = append(&vec![delay(d, dt); self.ninputs()])?;
        series(&del, self)
    }

    /// The system followed by a delay of `d` samples on every output,
    /// z^-d·G(z), with the delay realised as states (discrete models only).
    pub fn with_output_delay(&self, d: usize) -> Result<StateSpace, LtiError> {
        let dt = self.dt.ok_or_else(|| {
            LtiError::Domain("output delay in samples needs a discrete model".into())
        })?;
        let del = append(&vec![delay(d, dt); self.noutputs()])?;
        series(self, &del)
    }

    /// SISO transfer function of the model (python-control `ss2tf`), for low
    /// and moderate orders: den = det(xI − A) from the eigenvalues; the numerator
    /// from the frequency response (discrete: interpolated on a circle around
    /// the poles; continuous: det(xI − A + BC) − det(xI − A) + D·den on the
    /// balanced realisation). High orders lose accuracy in the coefficients
    /// (keep those as state space).
    pub fn to_tf(&self) -> Result<TransferFunction, LtiError> {
        ss2tf(self)
    }

    /// Multiply by a scalar gain `k` (on the output).
    pub fn scaled(&self, k: f64) -> StateSpace {
        StateSpace {
            a: self.a.clone(),
            b: self.b.clone(),
            c: &self.c * k,
            d: &self.d * k,
            dt: self.dt,
        }
    }
}

/// Unwrap a phase sequence (rad) so that consecutive values differ by less than π.
pub fn unwrap_phase(phase: &[f64]) -> Vec<f64> {
    let mut out = Vec::with_capacity(phase.len());
    let mut offset = 0.0;
    for (i, &p) in phase.iter().enumerate() {
        if i > 0 {
            let prev = phase[i - 1];
            let mut dp = p - prev;
            while dp > PI {
                dp -= 2.0 * PI;
                offset -= 2.0 * PI;
            }
            while dp < -PI {
                dp += 2.0 * PI;
                offset += 2.0 * PI;
            }
        }
        out.push(p + offset);
    }
    out
}

/// SISO state space to transfer function (python-control `ss2tf`); see
/// [`StateSpace::to_tf`].
///
/// The numerator of a **discrete** model is interpolated from its exact values
/// num(z_k) = G(z_k)·den(z_k) at n + 1 points z_k = ρ e^{i(2πk + ½)/(n+1)} on a
/// circle of radius ρ = 1.25·max(1, max|λ(A)|) (an inverse DFT): G(z_k) comes from a
/// pivoted linear solve, which does not care how the states are scaled. The
/// determinant identity C adj(xI − A) B = det(xI − A + BC) − det(xI − A) used for
/// continuous models cancels two nearly equal polynomials and loses everything
/// when B and C weigh different states (a closed loop of a PI and a stage model
/// at 4 kHz lost its whole numerator that way; test
/// `ss2tf_survives_bad_state_scaling`).
pub fn ss2tf(sys: &StateSpace) -> Result<TransferFunction, LtiError> {
    sys.validate()?;
    if !sys.is_siso() {
        return Err(LtiError::Dimension("ss2tf needs a SISO system".into()));
    }
    let d = sys.d[(0, 0)];
    if sys.b.norm() == 0.0 || sys.c.norm() == 0.0 || sys.nstates() == 0 {
        return Ok(TransferFunction {
            num: vec![d],
            den: vec![1.0],
            dt: sys.dt,
        });
    }
    let bal = sys.balanced();
    let n = bal.nstates();
    let poles = eigvals(&bal.a);
    if poles.iter().any(|p| !p.re.is_finite() || !p.im.is_finite()) {
        return Err(LtiError::Singular(
            "ss2tf: the eigenvalues of A did not converge".into(),
        ));
    }
    let den = poly_from_roots(&poles);
    let mut num = if bal.dt.is_some() {
        numerator_on_circle(&bal, &poles, &den)?
    } else {
        numerator_by_determinants(&bal, &den)
    };
    // The leading coefficients should vanish up to the relative degree but
    // carry round-off: fix them from the Markov parameters h₀ = D,
    // h_k = C A^{k−1} B. With den monic, num[k] = h_k for the first non-zero h_k
    // and num[j] = 0 before it.
    let scale = num.iter().map(|v| v.abs()).fold(0.0, f64::max);
    let mut first = (d != 0.0).then_some((0, d));
    let mut akb = bal.b.clone(); // A^{k−1} B
    for k in 1..=n {
        if first.is_some() {
            break;
        }
        if k > 1 {
            akb = &bal.a * akb;
        }
        let h = (&bal.c * &akb)[(0, 0)];
        if h.abs() > 1e-9 * scale {
            first = Some((k, h));
        }
    }
    match first {
        Some((k, h)) => {
            num.iter_mut().take(k).for_each(|v| *v = 0.0);
            num[k] = h;
        }
        // All Markov parameters vanish: the transfer function is zero.
        None => num.iter_mut().for_each(|v| *v = 0.0),
    }
    Ok(TransferFunction {
        num,
        den,
        dt: sys.dt,
    })
}

/// Numerator coefficients (descending powers, length n + 1) of a discrete SISO
/// model from num(z_k) = G(z_k)·den(z_k) on a circle outside every pole.
fn numerator_on_circle(
    sys: &StateSpace,
    poles: &[Complex<f64>],
    den: &[f64],
) -> Result<Vec<f64>, LtiError> {
    let n = sys.nstates();
    let m = n + 1;
    let rho = 1.25 * poles.iter().map(|p| p.norm()).fold(1.0, f64::max);
    let eval_den = |z: Complex<f64>| {
        den.iter()
            .fold(Complex::new(0.0, 0.0), |acc, &c| acc * z + c)
    };
    // Angles offset by half a step so that no point lies on the real axis.
    let angle = |k: usize| 2.0 * PI * (k as f64 + 0.5) / m as f64;
    let mut values = Vec::with_capacity(m);
    for k in 0..m {
        let z = Complex::from_polar(rho, angle(k));
        let g = sys.evalfr(z)[(0, 0)];
        if !(g.re.is_finite() && g.im.is_finite()) {
            return Err(LtiError::Singular(format!(
                "ss2tf: G(z) is singular at z = {z} (|z| = {rho:.3e}, outside every pole)"
            )));
        }
        values.push(g * eval_den(z));
    }
    // values[k] = Σ_j a_j z_k^j with a_j the coefficient of z^j:
    // a_j ρ^j e^{ijπ/m} = (1/m) Σ_k values[k] e^{−2πijk/m}.
    let mut ascending = vec![0.0; m];
    for (j, a) in ascending.iter_mut().enumerate() {
        let mut acc = Complex::new(0.0, 0.0);
        for (k, v) in values.iter().enumerate() {
            acc += v * Complex::from_polar(1.0, -angle(k) * j as f64);
        }
        *a = acc.re / (m as f64 * rho.powi(j as i32));
    }
    ascending.reverse();
    Ok(ascending)
}

/// Numerator coefficients (descending) of a continuous SISO model:
/// C adj(sI − A) B + D·den = det(sI − A + BC) − det(sI − A) + D·den, with B and C
/// scaled to the size of A so that the difference is not lost to round-off.
fn numerator_by_determinants(sys: &StateSpace, den: &[f64]) -> Vec<f64> {
    let (nb, nc) = (sys.b.norm(), sys.c.norm());
    let gamma = sys.a.norm().max(1.0);
    // det(sI − A + γ b̂ĉ) − det(sI − A) = γ ĉ adj(sI − A) b̂ (matrix determinant
    // lemma), b̂ = B/‖B‖, ĉ = C/‖C‖.
    let bc = (&sys.b / nb) * (&sys.c / nc) * gamma;
    let p1 = poly_from_roots(&eigvals(&(&sys.a - bc)));
    let gain = nb * nc / gamma;
    let d = sys.d[(0, 0)];
    p1.iter()
        .zip(den)
        .map(|(x, y)| (x - y) * gain + d * y)
        .collect()
}

/// Series connection: `sys1` followed by `sys2`, i.e. G = G₂·G₁ (python-control
/// `series(sys1, sys2)`). Outputs of `sys1` feed the inputs of `sys2`.
pub fn series(sys1: &StateSpace, sys2: &StateSpace) -> Result<StateSpace, LtiError> {
    sys1.validate()?;
    sys2.validate()?;
    let dt = common_dt(sys1, sys2)?;
    if sys1.noutputs() != sys2.ninputs() {
        return Err(LtiError::Dimension(format!(
            "series: first system has {} outputs, second has {} inputs",
            sys1.noutputs(),
            sys2.ninputs()
        )));
    }
    let (n1, n2) = (sys1.nstates(), sys2.nstates());
    let n = n1 + n2;
    let mut a = DMatrix::zeros(n, n);
    a.view_mut((0, 0), (n1, n1)).copy_from(&sys1.a);
    a.view_mut((n1, n1), (n2, n2)).copy_from(&sys2.a);
    a.view_mut((n1, 0), (n2, n1))
        .copy_from(&(&sys2.b * &sys1.c));
    let mut b = DMatrix::zeros(n, sys1.ninputs());
    b.view_mut((0, 0), (n1, sys1.ninputs())).copy_from(&sys1.b);
    b.view_mut((n1, 0), (n2, sys1.ninputs()))
        .copy_from(&(&sys2.b * &sys1.d));
    let mut c = DMatrix::zeros(sys2.noutputs(), n);
    c.view_mut((0, 0), (sys2.noutputs(), n1))
        .copy_from(&(&sys2.d * &sys1.c));
    c.view_mut((0, n1), (sys2.noutputs(), n2))
        .copy_from(&sys2.c);
    let d = &sys2.d * &sys1.d;
    Ok(StateSpace { a, b, c, d, dt })
}

/// Parallel connection G = G₁ + G₂ (same inputs, outputs added).
pub fn parallel(sys1: &StateSpace, sys2: &StateSpace) -> Result<StateSpace, LtiError> {
    sys1.validate()?;
    sys2.validate()?;
    let dt = common_dt(sys1, sys2)?;
    if sys1.ninputs() != sys2.ninputs() || sys1.noutputs() != sys2.noutputs() {
        return Err(LtiError::Dimension(
            "parallel: systems must have equal input and output counts".into(),
        ));
    }
    let (n1, n2) = (sys1.nstates(), sys2.nstates());
    let (p, m) = (sys1.noutputs(), sys1.ninputs());
    let mut a = DMatrix::zeros(n1 + n2, n1 + n2);
    a.view_mut((0, 0), (n1, n1)).copy_from(&sys1.a);
    a.view_mut((n1, n1), (n2, n2)).copy_from(&sys2.a);
    let mut b = DMatrix::zeros(n1 + n2, m);
    b.view_mut((0, 0), (n1, m)).copy_from(&sys1.b);
    b.view_mut((n1, 0), (n2, m)).copy_from(&sys2.b);
    let mut c = DMatrix::zeros(p, n1 + n2);
    c.view_mut((0, 0), (p, n1)).copy_from(&sys1.c);
    c.view_mut((0, n1), (p, n2)).copy_from(&sys2.c);
    Ok(StateSpace {
        a,
        b,
        c,
        d: &sys1.d + &sys2.d,
        dt,
    })
}

/// Block-diagonal stacking of systems (python-control `append`): inputs and
/// outputs are concatenated, no interconnection.
pub fn append(systems: &[StateSpace]) -> Result<StateSpace, LtiError> {
    for s in systems {
        s.validate()?;
    }
    let Some(first) = systems.first() else {
        return Ok(StateSpace::gain(DMatrix::zeros(0, 0), None));
    };
    let mut dt = first.dt;
    for s in systems {
        if !same_dt(s.dt, dt) {
            if dt.is_none()
                && s.dt.is_some()
                && systems
                    .iter()
                    .all(|x| x.dt.is_none() || same_dt(x.dt, s.dt))
            {
                dt = s.dt;
            } else {
                return Err(LtiError::SampleTime(dt, s.dt));
            }
        }
    }
    let n: usize = systems.iter().map(|s| s.nstates()).sum();
    let m: usize = systems.iter().map(|s| s.ninputs()).sum();
    let p: usize = systems.iter().map(|s| s.noutputs()).sum();
    let (mut a, mut b, mut c, mut d) = (
        DMatrix::zeros(n, n),
        DMatrix::zeros(n, m),
        DMatrix::zeros(p, n),
        DMatrix::zeros(p, m),
    );
    let (mut i, mut j, mut k) = (0, 0, 0);
    for s in systems {
        let (ns, ms, ps) = (s.nstates(), s.ninputs(), s.noutputs());
        a.view_mut((i, i), (ns, ns)).copy_from(&s.a);
        b.view_mut((i, j), (ns, ms)).copy_from(&s.b);
        c.view_mut((k, i), (ps, ns)).copy_from(&s.c);
        d.view_mut((k, j), (ps, ms)).copy_from(&s.d);
        i += ns;
        j += ms;
        k += ps;
    }
    Ok(StateSpace { a, b, c, d, dt })
}

/// Feedback interconnection (python-control `feedback(sys1, sys2, sign)`):
/// y = G₁ e, e = r + sign·G₂ y, so that r ↦ y is (I − sign·G₁G₂)⁻¹G₁; `sign =
/// -1.0` is negative feedback, (I + G₁G₂)⁻¹G₁. Fails if I − sign·D₁D₂ is singular
/// (an algebraic loop).
pub fn feedback(sys1: &StateSpace, sys2: &StateSpace, sign: f64) -> Result<StateSpace, LtiError> {
    sys1.validate()?;
    sys2.validate()?;
    let dt = common_dt(sys1, sys2)?;
    let (p1, m1) = (sys1.noutputs(), sys1.ninputs());
    if sys2.ninputs() != p1 || sys2.noutputs() != m1 {
        return Err(LtiError::Dimension(format!(
            "feedback: G2 must be {m1}×{p1} (inputs of G1 × outputs of G1), is {}×{}",
            sys2.noutputs(),
            sys2.ninputs()
        )));
    }
    let (n1, n2) = (sys1.nstates(), sys2.nstates());
    let n = n1 + n2;
    // (I − s D1 D2) y = C1 x1 + s D1 C2 x2 + D1 r
    let e_mat = DMatrix::identity(p1, p1) - &sys1.d * &sys2.d * sign;
    let e_inv = e_mat.try_inverse().ok_or_else(|| {
        LtiError::Singular("feedback: I − sign·D1·D2 is singular (algebraic loop)".into())
    })?;
    let mut cx = DMatrix::zeros(p1, n);
    cx.view_mut((0, 0), (p1, n1)).copy_from(&sys1.c);
    cx.view_mut((0, n1), (p1, n2))
        .copy_from(&(&sys1.d * &sys2.c * sign));
    let cy = &e_inv * cx;
    let dy = &e_inv * &sys1.d;
    // e = r + s (C2 x2 + D2 y)
    let mut ce = &sys2.d * &cy * sign;
    {
        let mut v = ce.view_mut((0, n1), (m1, n2));
        v += &sys2.c * sign;
    }
    let de = DMatrix::identity(m1, m1) + &sys2.d * &dy * sign;
    let mut a = DMatrix::zeros(n, n);
    a.view_mut((0, 0), (n1, n1)).copy_from(&sys1.a);
    a.view_mut((n1, n1), (n2, n2)).copy_from(&sys2.a);
    {
        let mut top = a.view_mut((0, 0), (n1, n));
        top += &sys1.b * &ce;
    }
    {
        let mut bot = a.view_mut((n1, 0), (n2, n));
        bot += &sys2.b * &cy;
    }
    let mut b = DMatrix::zeros(n, m1);
    b.view_mut((0, 0), (n1, m1)).copy_from(&(&sys1.b * &de));
    b.view_mut((n1, 0), (n2, m1)).copy_from(&(&sys2.b * &dy));
    Ok(StateSpace {
        a,
        b,
        c: cy,
        d: dy,
        dt,
    })
}

/// A pure delay z^-d of `d` samples at period `dt` (s), SISO, realised as a shift
/// register of `d` states (x₁\[k+1\] = u\[k\], xᵢ\[k+1\] = xᵢ₋₁\[k\], y = x_d); d = 0 is
/// the unit gain.
pub fn delay(d: usize, dt: f64) -> StateSpace {
    if d == 0 {
        return StateSpace::gain(DMatrix::from_element(1, 1, 1.0), Some(dt));
    }
    let mut a = DMatrix::zeros(d, d);
    for i in 1..d {
        a[(i, i - 1)] = 1.0;
    }
    let mut b = DMatrix::zeros(d, 1);
    b[(0, 0)] = 1.0;
    let mut c = DMatrix::zeros(1, d);
    c[(0, d - 1)] = 1.0;
    StateSpace {
        a,
        b,
        c,
        d: DMatrix::zeros(1, 1),
        dt: Some(dt),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn c(re: f64, im: f64) -> Complex<f64> {
        Complex::new(re, im)
    }

    /// First-order continuous lowpass a/(s+a).
    fn lowpass(a: f64) -> StateSpace {
        StateSpace::new(
            DMatrix::from_element(1, 1, -a),
            DMatrix::from_element(1, 1, 1.0),
            DMatrix::from_element(1, 1, a),
            DMatrix::zeros(1, 1),
            None,
        )
        .unwrap()
    }

    #[test]
    fn dimension_checks() {
        let e = StateSpace::new(
            DMatrix::zeros(2, 2),
            DMatrix::zeros(1, 1),
            DMatrix::zeros(1, 2),
            DMatrix::zeros(1, 1),
            None,
        );
        assert!(matches!(e, Err(LtiError::Dimension(_))));
        let e = StateSpace::new(
            DMatrix::zeros(0, 0),
            DMatrix::zeros(0, 1),
            DMatrix::zeros(1, 0),
            DMatrix::zeros(1, 1),
            Some(-1.0),
        );
        assert!(e.is_err());
    }

    #[test]
    fn evalfr_matches_closed_form() {
        let g = lowpass(3.0);
        for &w in &[0.0, 0.5, 3.0, 100.0] {
            let got = g.freqresp_siso_at(w);
            let want = c(3.0, 0.0) / c(3.0, w);
            assert!((got - want).norm() < 1e-14);
        }
        assert!((g.dcgain()[(0, 0)].re - 1.0).abs() < 1e-15);
        assert!(g.is_stable());
        assert!(!lowpass(-1.0).is_stable());
    }

    #[test]
    fn series_parallel_feedback_match_transfer_algebra() {
        let g1 = lowpass(2.0);
        let g2 = StateSpace::new(
            DMatrix::from_row_slice(2, 2, &[0.0, 1.0, -4.0, -0.4]),
            DMatrix::from_row_slice(2, 1, &[0.0, 1.0]),
            DMatrix::from_row_slice(1, 2, &[1.0, 0.5]),
            DMatrix::from_element(1, 1, 0.3),
            None,
        )
        .unwrap();
        let s = series(&g1, &g2).unwrap();
        let p = parallel(&g1, &g2).unwrap();
        let fneg = feedback(&g1, &g2, -1.0).unwrap();
        let fpos = feedback(&g2, &g1, 1.0).unwrap();
        for &w in &[0.0, 0.3, 1.9, 2.0, 7.0, 50.0] {
            let a = g1.freqresp_siso_at(w);
            let b = g2.freqresp_siso_at(w);
            assert!((s.freqresp_siso_at(w) - a * b).norm() < 1e-12);
            assert!((p.freqresp_siso_at(w) - (a + b)).norm() < 1e-12);
            assert!((fneg.freqresp_siso_at(w) - a / (1.0 + a * b)).norm() < 1e-12);
            assert!((fpos.freqresp_siso_at(w) - b / (1.0 - b * a)).norm() < 1e-12);
        }
        // D1·D2 = 1 with positive feedback is an algebraic loop.
        let one = StateSpace::gain(DMatrix::from_element(1, 1, 1.0), None);
        assert!(matches!(
            feedback(&one, &one, 1.0),
            Err(LtiError::Singular(_))
        ));
    }

    #[test]
    fn mimo_feedback_matches_matrix_formula() {
        let mut rng = crate::rng::Rng::new(3);
        let mut rnd = |r, c| DMatrix::from_fn(r, c, |_, _| rng.uniform_in(-1.0, 1.0));
        let g1 = StateSpace::new(rnd(3, 3), rnd(3, 2), rnd(2, 3), rnd(2, 2), Some(0.1)).unwrap();
        let g2 =
            StateSpace::new(rnd(2, 2), rnd(2, 2), rnd(2, 2), rnd(2, 2) * 0.2, Some(0.1)).unwrap();
        let f = feedback(&g1, &g2, -1.0).unwrap();
        for &w in &[0.1, 2.0, 20.0] {
            let a = g1.freqresp(&[w])[0].clone();
            let b = g2.freqresp(&[w])[0].clone();
            let want = (DMatrix::identity(2, 2) + &a * &b).try_inverse().unwrap() * &a;
            assert!((f.freqresp(&[w])[0].clone() - want).camax() < 1e-10);
        }
    }

    #[test]
    fn delay_is_z_to_the_minus_d() {
        let dt = 1e-3;
        for d in 0..5 {
            let s = delay(d, dt);
            assert_eq!(s.nstates(), d);
            assert_eq!(s.has_feedthrough(), d == 0);
            for &w in &[1.0, 100.0, 2000.0] {
                let want = Complex::from_polar(1.0, -(d as f64) * w * dt);
                assert!((s.freqresp_siso_at(w) - want).norm() < 1e-12);
            }
        }
        let g = StateSpace::new(
            DMatrix::from_element(1, 1, 0.5),
            DMatrix::from_element(1, 1, 1.0),
            DMatrix::from_element(1, 1, 1.0),
            DMatrix::zeros(1, 1),
            Some(dt),
        )
        .unwrap();
        let gi = g.with_input_delay(3).unwrap();
        let go = g.with_output_delay(2).unwrap();
        assert_eq!(gi.nstates(), 4);
        for &w in &[10.0, 700.0] {
            let base = g.freqresp_siso_at(w);
            assert!(
                (gi.freqresp_siso_at(w) - base * Complex::from_polar(1.0, -3.0 * w * dt)).norm()
                    < 1e-12
            );
            assert!(
                (go.freqresp_siso_at(w) - base * Complex::from_polar(1.0, -2.0 * w * dt)).norm()
                    < 1e-12
            );
        }
        assert!(lowpass(1.0).with_input_delay(1).is_err());
    }

    /// ss2tf against the state-space frequency response on seeded random
    /// systems of order 1–8, discrete and continuous, in their own coordinates and
    /// after a badly scaled change of state coordinates x' = S x (S = diag of
    /// 10^k, |k| ≤ 5), which must not change the transfer function.
    #[test]
    fn ss2tf_survives_bad_state_scaling() {
        let mut rng = crate::rng::Rng::new(2009);
        let mut worst: f64 = 0.0;
        for case in 0..60 {
            let n = 1 + case % 8;
            let discrete = case % 2 == 0;
            let a = DMatrix::from_fn(n, n, |_, _| rng.uniform_in(-1.0, 1.0));
            // Discrete: spectral radius ≤ 0.95; continuous: shift to Re λ < 0.
            let rho = eigvals(&a).iter().map(|l| l.norm()).fold(0.0, f64::max);
            let a = if discrete {
                &a * (0.95 / rho.max(1e-3))
            } else {
                &a - DMatrix::identity(n, n) * (rho + 0.2)
            };
            let sys = StateSpace::new(
                a,
                DMatrix::from_fn(n, 1, |_, _| rng.uniform_in(-1.0, 1.0)),
                DMatrix::from_fn(1, n, |_, _| rng.uniform_in(-1.0, 1.0)),
                DMatrix::from_element(
                    1,
                    1,
                    if case % 3 == 0 {
                        0.0
                    } else {
                        rng.uniform_in(-1.0, 1.0)
                    },
                ),
                discrete.then_some(0.01),
            )
            .unwrap();
            let sc: Vec<f64> = (0..n)
                .map(|_| 10f64.powf(rng.uniform_in(-5.0, 5.0)))
                .collect();
            let mut bad = sys.clone();
            for i in 0..n {
                for j in 0..n {
                    bad.a[(i, j)] = sys.a[(i, j)] * sc[i] / sc[j];
                }
                bad.b[(i, 0)] = sys.b[(i, 0)] * sc[i];
                bad.c[(0, i)] = sys.c[(0, i)] / sc[i];
            }
            let w_max = if discrete { PI / 0.01 } else { 100.0 };
            for g in [&sys, &bad] {
                let tf = g.to_tf().unwrap();
                for k in 0..25 {
                    let w = w_max * (k as f64 + 0.5) / 25.0;
                    let want = sys.freqresp_siso_at(w);
                    let got = tf.freqresp(&[w])[0];
                    // Relative to the size of the response (a zero near the
                    // axis leaves an absolute error of the coefficients' size).
                    let size = want.norm().max(1e-3 * sys.c.norm() * sys.b.norm());
                    let err = (got - want).norm() / size;
                    worst = worst.max(err);
                    assert!(
                        err < 1e-6,
                        "case {case} (n = {n}, discrete {discrete}): {got} vs {want}"
                    );
                }
            }
        }
        assert!(worst < 1e-6, "{worst:e}");
    }

    #[test]
    fn ss2tf_matches_freqresp() {
        let g = StateSpace::new(
            DMatrix::from_row_slice(2, 2, &[0.0, 1.0, -4.0, -0.4]),
            DMatrix::from_row_slice(2, 1, &[0.0, 1.0]),
            DMatrix::from_row_slice(1, 2, &[1.0, 0.5]),
            DMatrix::from_element(1, 1, 0.3),
            None,
        )
        .unwrap();
        let tf = g.to_tf().unwrap();
        // (0.3 s² + 0.62 s + 2.2)/(s² + 0.4 s + 4)
        let want_num = [0.3, 0.5 + 0.12, 1.0 + 1.2];
        for (x, y) in tf.num.iter().zip(want_num) {
            assert!((x - y).abs() < 1e-12, "{:?}", tf.num);
        }
        for (x, y) in tf.den.iter().zip([1.0, 0.4, 4.0]) {
            assert!((x - y).abs() < 1e-12);
        }
    }

    #[test]
    fn bode_unwraps_phase() {
        let g = series(
            &lowpass(1.0),
            &series(&lowpass(1.0), &lowpass(1.0)).unwrap(),
        )
        .unwrap();
        let w: Vec<f64> = (0..200)
            .map(|i| 10f64.powf(-2.0 + 4.0 * i as f64 / 199.0))
            .collect();
        let (mag, ph) = g.bode(&w);
        assert!((mag[0] - 1.0).abs() < 1e-3);
        // Three poles: phase tends to -3π/2 without jumps.
        assert!((ph[199] + 1.5 * PI).abs() < 0.05, "{}", ph[199]);
        assert!(ph.windows(2).all(|p| (p[1] - p[0]).abs() < 0.5));
        let balanced = g.balanced();
        assert!((balanced.freqresp_siso_at(0.7) - g.freqresp_siso_at(0.7)).norm() < 1e-13);
    }
}
