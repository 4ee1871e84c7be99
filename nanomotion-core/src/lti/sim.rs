//! Time-domain simulation of discrete state-space models: the allocation-free
//! [`SsStepper`] for real-time use, and whole-sequence helpers ([`lsim`],
//! [`step_response`], [`impulse`]).

use super::{LtiError, StateSpace};
use nalgebra::{DMatrix, DVector, DVectorView, DVectorViewMut};

/// Steps a discrete model x\[k+1\] = A x\[k\] + B u\[k\], y\[k\] = C x\[k\] + D u\[k\] with
/// preallocated buffers: [`output`](Self::output), [`update`](Self::update) and
/// [`step`](Self::step) never allocate.
///
/// ```
/// use nanomotion_core::lti::{SsStepper, StateSpace};
/// use nalgebra::DMatrix;
/// // y[k] = 0.5 y[k-1] + u[k-1]
/// let sys = StateSpace::new(
///     DMatrix::from_element(1, 1, 0.5), DMatrix::from_element(1, 1, 1.0),
///     DMatrix::from_element(1, 1, 1.0), DMatrix::zeros(1, 1), Some(1e-3)).unwrap();
/// let mut s = SsStepper::new(&sys).unwrap();
/// let ys: Vec<f64> = (0..3).map(|_| s.step_siso(1.0)).collect();
/// assert_eq!(ys, vec![0.0, 1.0, 1.5]);
/// ```
#[derive(Debug, Clone, PartialEq)]
pub struct SsStepper {
    a: DMatrix<f64>,
    b: DMatrix<f64>,
    c: DMatrix<f64>,
    d: DMatrix<f64>,
    feedthrough: bool,
    kernel: Kernel,
    x: DVector<f64>,
    x_next: DVector<f64>,
}

/// How a stepper computes: nalgebra's `gemv` in general; a single-input
/// single-output model of one to four states (a transfer-function block, a
/// filter section) with the same products and sums in the same order on
/// fixed-size arrays, which the compiler unrolls — the same bits at a third
/// of the instructions. The fixed-size kernels hold their own state.
#[derive(Debug, Clone, PartialEq)]
enum Kernel {
    General,
    Siso1(Siso<1>),
    Siso2(Siso<2>),
    Siso3(Siso<3>),
    Siso4(Siso<4>),
}

/// `$body` with `$k` bound to the fixed-size model, or `$general`.
macro_rules! on_kernel {
    ($kernel:expr, $k:ident => $body:expr, general => $general:expr) => {
        match $kernel {
            Kernel::Siso1($k) => $body,
            Kernel::Siso2($k) => $body,
            Kernel::Siso3($k) => $body,
            Kernel::Siso4($k) => $body,
            Kernel::General => $general,
        }
    };
}

/// A single-input single-output model of `N` states, and its state.
#[derive(Debug, Clone, PartialEq)]
struct Siso<const N: usize> {
    /// A, row by row.
    a: [[f64; N]; N],
    b: [f64; N],
    c: [f64; N],
    /// D, if the model has feed-through (else it is not added at all).
    d: Option<f64>,
    /// The state x\[k\].
    x: [f64; N],
}

impl<const N: usize> Siso<N> {
    fn new(sys: &StateSpace) -> Self {
        Self {
            a: std::array::from_fn(|i| std::array::from_fn(|j| sys.a[(i, j)])),
            b: std::array::from_fn(|i| sys.b[(i, 0)]),
            c: std::array::from_fn(|j| sys.c[(0, j)]),
            d: sys.has_feedthrough().then(|| sys.d[(0, 0)]),
            x: [0.0; N],
        }
    }

    /// y = C x (+ D u), as `gemv` sums it: `c₀x₀`, then `+ cⱼxⱼ`, then `+ d u`.
    #[inline(always)]
    #[allow(clippy::needless_range_loop)] // indices unroll; the sum's order is the point
    fn output(&self, u: &[f64]) -> f64 {
        let x = &self.x;
        let mut y = self.c[0] * x[0];
        for j in 1..N {
            y += self.c[j] * x[j];
        }
        match self.d {
            Some(d) => y + d * u[0],
            None => y,
        }
    }

    /// A x + B u, each row as `gemv` sums it: `aᵢ₀x₀`, then `+ aᵢⱼxⱼ`, then `+ bᵢu`
    /// (`gemv` writes `aᵢⱼxⱼ + ·`: the same sum, IEEE addition commutes).
    #[inline(always)]
    #[allow(clippy::needless_range_loop)] // indices unroll; the sum's order is the point
    fn update(&mut self, u: f64) {
        let x = &self.x;
        self.x = std::array::from_fn(|i| {
            let row = &self.a[i];
            let mut acc = row[0] * x[0];
            for j in 1..N {
                acc += row[j] * x[j];
            }
            acc + self.b[i] * u
        });
    }
}

impl SsStepper {
    /// A stepper for the discrete model `sys`, starting from x = 0.
    pub fn new(sys: &StateSpace) -> Result<Self, LtiError> {
        sys.validate()?;
        if sys.dt.is_none() {
            return Err(LtiError::Domain(
                "SsStepper needs a discrete model: discretise it with c2d first".into(),
            ));
        }
        let n = sys.nstates();
        let kernel = match (n, sys.ninputs(), sys.noutputs()) {
            (1, 1, 1) => Kernel::Siso1(Siso::new(sys)),
            (2, 1, 1) => Kernel::Siso2(Siso::new(sys)),
            (3, 1, 1) => Kernel::Siso3(Siso::new(sys)),
            (4, 1, 1) => Kernel::Siso4(Siso::new(sys)),
            _ => Kernel::General,
        };
        let kernel_general = kernel == Kernel::General;
        Ok(Self {
            kernel,
            a: sys.a.clone(),
            b: sys.b.clone(),
            c: sys.c.clone(),
            d: sys.d.clone(),
            feedthrough: sys.has_feedthrough(),
            // The general kernel's state (the fixed-size ones hold their own).
            x: DVector::zeros(if kernel_general { n } else { 0 }),
            x_next: DVector::zeros(if kernel_general { n } else { 0 }),
        })
    }

    /// Take the coefficients of `sys` — a model of the same dimensions, with
    /// feed-through only if this one has it — keeping the state x\[k\]: the
    /// next [`output`](Self::output) is C′x\[k\] + D′u\[k\]. Does not allocate.
    /// A model of other dimensions, a continuous one or one that would add
    /// feed-through (the caller orders its blocks by it) is refused and
    /// nothing changes.
    pub fn set_coefficients(&mut self, sys: &StateSpace) -> Result<(), LtiError> {
        let same = sys.a.shape() == self.a.shape()
            && sys.b.shape() == self.b.shape()
            && sys.c.shape() == self.c.shape()
            && sys.d.shape() == self.d.shape();
        if !same || sys.dt.is_none() || (sys.has_feedthrough() && !self.feedthrough) {
            return Err(LtiError::Dimension(format!(
                "new coefficients must keep the model's shape ({} states, {} inputs, {} outputs), be discrete and add no feed-through",
                self.nstates(),
                self.ninputs(),
                self.noutputs()
            )));
        }
        self.a.copy_from(&sys.a);
        self.b.copy_from(&sys.b);
        self.c.copy_from(&sys.c);
        self.d.copy_from(&sys.d);
        fn take<const N: usize>(k: &mut Siso<N>, sys: &StateSpace, feedthrough: bool) {
            let x = k.x;
            *k = Siso::new(sys);
            k.x = x;
            // D stays in the sum when the model has feed-through (a D′ of 0
            // adds 0·u).
            if feedthrough {
                k.d = Some(sys.d[(0, 0)]);
            }
        }
        let ft = self.feedthrough;
        match &mut self.kernel {
            Kernel::Siso1(k) => take(k, sys, ft),
            Kernel::Siso2(k) => take(k, sys, ft),
            Kernel::Siso3(k) => take(k, sys, ft),
            Kernel::Siso4(k) => take(k, sys, ft),
            Kernel::General => {}
        }
        Ok(())
    }

    /// Number of states.
    pub fn nstates(&self) -> usize {
        self.a.nrows()
    }
    /// Number of inputs.
    pub fn ninputs(&self) -> usize {
        self.b.ncols()
    }
    /// Number of outputs.
    pub fn noutputs(&self) -> usize {
        self.c.nrows()
    }
    /// Whether y\[k\] depends on u\[k\] (D ≠ 0).
    pub fn has_feedthrough(&self) -> bool {
        self.feedthrough
    }

    /// Write y = C x + D u of the current sample. `u` may be empty when the model
    /// has no feed-through. Does not allocate.
    ///
    /// # Panics
    /// If `y` is not `noutputs()` long, or `u` has the wrong length while D ≠ 0.
    #[inline(always)]
    pub fn output(&self, u: &[f64], y: &mut [f64]) {
        on_kernel!(&self.kernel, k => y[0] = k.output(u), general => self.output_general(u, y))
    }

    /// [`SsStepper::output`] by `gemv` (kept out of line: the fixed-size
    /// kernels are what callers inline).
    #[inline(never)]
    fn output_general(&self, u: &[f64], y: &mut [f64]) {
        let p = self.noutputs();
        let mut yv = DVectorViewMut::from_slice(y, p);
        if self.x.is_empty() {
            yv.fill(0.0);
        } else {
            yv.gemv(1.0, &self.c, &self.x, 0.0);
        }
        if self.feedthrough {
            let uv = DVectorView::from_slice(u, self.ninputs());
            yv.gemv(1.0, &self.d, &uv, 1.0);
        }
    }

    /// Advance the state: x ← A x + B u. Does not allocate.
    #[inline(always)]
    pub fn update(&mut self, u: &[f64]) {
        on_kernel!(&mut self.kernel, k => k.update(u[0]), general => self.update_general(u))
    }

    /// [`SsStepper::update`] by `gemv`.
    #[inline(never)]
    fn update_general(&mut self, u: &[f64]) {
        if self.x.is_empty() {
            return;
        }
        let uv = DVectorView::from_slice(u, self.ninputs());
        self.x_next.gemv(1.0, &self.a, &self.x, 0.0);
        self.x_next.gemv(1.0, &self.b, &uv, 1.0);
        std::mem::swap(&mut self.x, &mut self.x_next);
    }

    /// One full sample: [`output`](Self::output) then [`update`](Self::update).
    #[inline]
    pub fn step(&mut self, u: &[f64], y: &mut [f64]) {
        self.output(u, y);
        self.update(u);
    }

    /// One sample of a single-input single-output model.
    pub fn step_siso(&mut self, u: f64) -> f64 {
        let mut y = [0.0];
        self.step(&[u], &mut y);
        y[0]
    }

    /// Set the state to zero.
    pub fn reset(&mut self) {
        self.x_mut().fill(0.0);
    }

    /// The current state x\[k\].
    pub fn state(&self) -> &[f64] {
        on_kernel!(&self.kernel, k => &k.x, general => self.x.as_slice())
    }

    /// The current state, to overwrite.
    fn x_mut(&mut self) -> &mut [f64] {
        on_kernel!(&mut self.kernel, k => &mut k.x, general => self.x.as_mut_slice())
    }

    /// Overwrite the state.
    ///
    /// # Panics
    /// If `x` is not `nstates()` long.
    pub fn set_state(&mut self, x: &[f64]) {
        self.x_mut().copy_from_slice(x);
    }

    /// Set the state to the steady state for a constant input `u`:
    /// x = (I − A)⁻¹ B u (fails if A has an eigenvalue at 1, e.g. an
    /// integrator). Allocates; call at build time.
    pub fn set_steady_state(&mut self, u: &[f64]) -> Result<(), LtiError> {
        let n = self.nstates();
        let m = DMatrix::<f64>::identity(n, n) - &self.a;
        let rhs = &self.b * DVector::from_column_slice(u);
        let x = m
            .lu()
            .solve(&rhs)
            .ok_or_else(|| LtiError::Singular("I − A is singular (pole at z = 1)".into()))?;
        self.x_mut().copy_from_slice(x.as_slice());
        Ok(())
    }
}

/// Simulate a discrete model from zero state (or `x0`) for the input sequence `u`
/// (one row per sample, m columns); returns the outputs (one row per sample, p
/// columns). python-control `forced_response` for discrete systems.
pub fn lsim(
    sys: &StateSpace,
    u: &DMatrix<f64>,
    x0: Option<&[f64]>,
) -> Result<DMatrix<f64>, LtiError> {
    if u.ncols() != sys.ninputs() {
        return Err(LtiError::Dimension(format!(
            "u has {} columns, system has {} inputs",
            u.ncols(),
            sys.ninputs()
        )));
    }
    let mut s = SsStepper::new(sys)?;
    if let Some(x0) = x0 {
        if x0.len() != sys.nstates() {
            return Err(LtiError::Dimension(format!(
                "x0 has {} entries, system has {} states",
                x0.len(),
                sys.nstates()
            )));
        }
        s.set_state(x0);
    }
    let mut y = DMatrix::zeros(u.nrows(), sys.noutputs());
    let mut ui = vec![0.0; sys.ninputs()];
    let mut yi = vec![0.0; sys.noutputs()];
    for k in 0..u.nrows() {
        for (j, v) in ui.iter_mut().enumerate() {
            *v = u[(k, j)];
        }
        s.step(&ui, &mut yi);
        for (j, v) in yi.iter().enumerate() {
            y[(k, j)] = *v;
        }
    }
    Ok(y)
}

/// Simulate the (0, 0) channel of a discrete model for a scalar input sequence.
///
/// A model without outputs has no (0, 0) channel: a [`LtiError::Dimension`]
/// (one without inputs gives its zero-state output, zeros).
pub fn lsim_siso(sys: &StateSpace, u: &[f64]) -> Result<Vec<f64>, LtiError> {
    let mut s = SsStepper::new(sys)?;
    if sys.noutputs() == 0 {
        return Err(LtiError::Dimension(format!(
            "lsim_siso needs at least one output, the model is {}×{}",
            sys.noutputs(),
            sys.ninputs()
        )));
    }
    let mut uu = vec![0.0; sys.ninputs()];
    let mut y = vec![0.0; sys.noutputs()];
    Ok(u.iter()
        .map(|&v| {
            if let Some(u0) = uu.first_mut() {
                *u0 = v;
            }
            s.step(&uu, &mut y);
            y[0]
        })
        .collect())
}

/// Unit-step response (first input → first output) over `n` samples, from zero
/// state: y\[k\] for u\[k\] = 1, k ≥ 0.
pub fn step_response(sys: &StateSpace, n: usize) -> Result<Vec<f64>, LtiError> {
    lsim_siso(sys, &vec![1.0; n])
}

/// Unit-pulse response (first input → first output) over `n` samples: the
/// Markov parameters D, CB, CAB, ... (u\[0\] = 1, u\[k>0\] = 0).
pub fn impulse(sys: &StateSpace, n: usize) -> Result<Vec<f64>, LtiError> {
    let mut u = vec![0.0; n];
    if n > 0 {
        u[0] = 1.0;
    }
    lsim_siso(sys, &u)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::lti::TransferFunction;

    #[test]
    fn impulse_is_markov_parameters() {
        let tf =
            TransferFunction::new(vec![0.5, 0.2, 0.1], vec![1.0, -0.9, 0.2], Some(0.1)).unwrap();
        let sys = tf.to_ss().unwrap();
        let h = impulse(&sys, 6).unwrap();
        // Long division of num/den in z⁻¹: h0 = 0.5, h1 = 0.2 + 0.9·0.5, h_k = 0.9 h_{k-1} − 0.2 h_{k-2} (+ b_k)
        let mut want = vec![0.5, 0.2 + 0.45];
        want.push(0.1 + 0.9 * want[1] - 0.2 * want[0]);
        for k in 3..6 {
            want.push(0.9 * want[k - 1] - 0.2 * want[k - 2]);
        }
        for (a, b) in h.iter().zip(&want) {
            assert!((a - b).abs() < 1e-14, "{h:?} vs {want:?}");
        }
        let s = step_response(&sys, 400).unwrap();
        assert!((s[399] - tf.dcgain()).abs() < 1e-12);
    }

    #[test]
    fn stepper_does_not_allocate_and_matches_lsim() {
        let mut rng = crate::rng::Rng::new(5);
        let (n, m, p) = (4, 2, 3);
        let a = DMatrix::from_fn(n, n, |_, _| rng.uniform_in(-0.4, 0.4));
        let sys = StateSpace::new(
            a,
            DMatrix::from_fn(n, m, |_, _| rng.uniform_in(-1.0, 1.0)),
            DMatrix::from_fn(p, n, |_, _| rng.uniform_in(-1.0, 1.0)),
            DMatrix::from_fn(p, m, |_, _| rng.uniform_in(-1.0, 1.0)),
            Some(1e-3),
        )
        .unwrap();
        let u = DMatrix::from_fn(50, m, |_, _| rng.normal());
        let y = lsim(&sys, &u, None).unwrap();
        let mut s = SsStepper::new(&sys).unwrap();
        let mut yk = [0.0; 3];
        let mut uk = [0.0; 2];
        let mut x = DVector::<f64>::zeros(n);
        let info = allocation_counter::measure(|| {
            for k in 0..50 {
                uk[0] = u[(k, 0)];
                uk[1] = u[(k, 1)];
                s.step(&uk, &mut yk);
                for j in 0..p {
                    assert!((yk[j] - y[(k, j)]).abs() < 1e-14);
                }
            }
        });
        assert_eq!(info.count_total, 0, "SsStepper allocated");
        // Independent recursion with allocating nalgebra arithmetic.
        let mut last = DVector::zeros(p);
        for k in 0..50 {
            let uk = DVector::from_fn(m, |j, _| u[(k, j)]);
            last = &sys.c * &x + &sys.d * &uk;
            x = &sys.a * &x + &sys.b * &uk;
        }
        for j in 0..p {
            assert!((last[j] - y[(49, j)]).abs() < 1e-12);
        }
    }

    /// The fixed-size single-input single-output kernels give nalgebra
    /// `gemv`'s bits (the general path's recursion), signed zeros and
    /// cancellations included, with and without feed-through; MIMO shapes and
    /// five states take the general path.
    #[test]
    fn stepper_kernels_are_bit_for_bit_gemv() {
        use nalgebra::{DVectorView, DVectorViewMut};
        let mut rng = crate::rng::Rng::new(29);
        // Entries that round, cancel and give −0.0.
        let entry = |rng: &mut crate::rng::Rng| match rng.uniform_in(0.0, 4.0) as u32 {
            0 => 0.0,
            1 => -0.0,
            2 => rng.normal() * 1e-3,
            _ => rng.uniform_in(-0.45, 0.45),
        };
        let shapes = [
            (1, 1, 1),
            (2, 1, 1),
            (3, 1, 1),
            (4, 1, 1),
            (5, 1, 1),
            (2, 2, 3),
        ];
        for (n, m, p) in shapes {
            for feedthrough in [false, true] {
                let a = DMatrix::from_fn(n, n, |_, _| entry(&mut rng) / n as f64);
                let b = DMatrix::from_fn(n, m, |_, _| entry(&mut rng));
                let c = DMatrix::from_fn(p, n, |_, _| entry(&mut rng));
                let d = DMatrix::from_fn(p, m, |_, _| {
                    if feedthrough {
                        entry(&mut rng) + 0.5
                    } else {
                        0.0
                    }
                });
                let sys = StateSpace::new(a, b, c, d, Some(1e-3)).unwrap();
                let mut s = SsStepper::new(&sys).unwrap();
                let siso = (1..=4).contains(&n) && (m, p) == (1, 1);
                assert_eq!(s.kernel != Kernel::General, siso, "{n} states");
                let (mut x, mut x_next) = (DVector::<f64>::zeros(n), DVector::<f64>::zeros(n));
                let (mut y, mut y_gemv) = (vec![0.0; p], vec![0.0; p]);
                let bits = |v: &[f64]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
                for k in 0..200 {
                    let u: Vec<f64> = (0..m)
                        .map(|_| if k % 7 == 3 { -0.0 } else { rng.normal() })
                        .collect();
                    s.step(&u, &mut y);
                    let uv = DVectorView::from_slice(&u, m);
                    let mut yv = DVectorViewMut::from_slice(&mut y_gemv, p);
                    yv.gemv(1.0, &sys.c, &x, 0.0);
                    if sys.has_feedthrough() {
                        yv.gemv(1.0, &sys.d, &uv, 1.0);
                    }
                    x_next.gemv(1.0, &sys.a, &x, 0.0);
                    x_next.gemv(1.0, &sys.b, &uv, 1.0);
                    std::mem::swap(&mut x, &mut x_next);
                    assert_eq!(bits(&y), bits(&y_gemv), "y, {n} states, sample {k}");
                    assert_eq!(bits(s.state()), bits(x.as_slice()), "x, sample {k}");
                }
            }
        }
    }

    #[test]
    fn steady_state_initialisation() {
        let tf = TransferFunction::new(vec![0.3], vec![1.0, -0.7], Some(1.0)).unwrap();
        let mut s = SsStepper::new(&tf.to_ss().unwrap()).unwrap();
        s.set_steady_state(&[2.0]).unwrap();
        assert!((s.step_siso(2.0) - 2.0).abs() < 1e-14);
        assert!(
            SsStepper::new(
                &TransferFunction::new(vec![1.0], vec![1.0, 1.0], None)
                    .unwrap()
                    .to_ss()
                    .unwrap()
            )
            .is_err()
        );
    }
}
