//! A small allocation-free stepper for a discrete state-space model
//! x[k+1] = A x[k] + B u[k], y[k] = C x[k] (strictly proper, as plant models are).
//!
//! Private to this crate; the core's `lti` module is growing its own stepper and
//! this one can be replaced by it.

use nanomotion_core::lti::StateSpace;

/// Row-major copy of a strictly proper discrete model with preallocated scratch.
#[derive(Debug, Clone, Default)]
pub(crate) struct DiscreteStepper {
    n: usize,
    m: usize,
    p: usize,
    a: Vec<f64>,
    b: Vec<f64>,
    c: Vec<f64>,
    x: Vec<f64>,
    scratch: Vec<f64>,
}

impl DiscreteStepper {
    /// Copy the matrices of `sys` (which must have D = 0); state starts at zero.
    pub(crate) fn new(sys: &StateSpace) -> Self {
        let (n, m, p) = (sys.nstates(), sys.ninputs(), sys.noutputs());
        debug_assert!(
            sys.d.iter().all(|v| *v == 0.0),
            "stepper needs a strictly proper model"
        );
        let row_major = |mat: &nalgebra::DMatrix<f64>| {
            let mut v = Vec::with_capacity(mat.len());
            for i in 0..mat.nrows() {
                for j in 0..mat.ncols() {
                    v.push(mat[(i, j)]);
                }
            }
            v
        };
        Self {
            n,
            m,
            p,
            a: row_major(&sys.a),
            b: row_major(&sys.b),
            c: row_major(&sys.c),
            x: vec![0.0; n],
            scratch: vec![0.0; n],
        }
    }

    /// y = C x.
    pub(crate) fn output(&self, y: &mut [f64]) {
        for (i, yi) in y.iter_mut().enumerate().take(self.p) {
            let row = &self.c[i * self.n..(i + 1) * self.n];
            *yi = row.iter().zip(&self.x).map(|(c, x)| c * x).sum();
        }
    }

    /// x ← A x + B u.
    pub(crate) fn advance(&mut self, u: &[f64]) {
        for i in 0..self.n {
            let ra = &self.a[i * self.n..(i + 1) * self.n];
            let rb = &self.b[i * self.m..(i + 1) * self.m];
            let ax: f64 = ra.iter().zip(&self.x).map(|(a, x)| a * x).sum();
            let bu: f64 = rb.iter().zip(u).map(|(b, u)| b * u).sum();
            self.scratch[i] = ax + bu;
        }
        std::mem::swap(&mut self.x, &mut self.scratch);
    }

    /// Set the state to zero.
    pub(crate) fn reset(&mut self) {
        self.x.iter_mut().for_each(|v| *v = 0.0);
    }

    /// The state vector.
    #[cfg(test)]
    pub(crate) fn state(&self) -> &[f64] {
        &self.x
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::DMatrix;

    #[test]
    fn steps_a_scalar_system() {
        // x[k+1] = 0.5 x + u, y = 2x: impulse response 0, 2, 1, 0.5, ...
        let sys = StateSpace::new(
            DMatrix::from_element(1, 1, 0.5),
            DMatrix::from_element(1, 1, 1.0),
            DMatrix::from_element(1, 1, 2.0),
            DMatrix::zeros(1, 1),
            Some(1.0),
        )
        .unwrap();
        let mut s = DiscreteStepper::new(&sys);
        let mut y = [0.0];
        let mut out = Vec::new();
        for k in 0..4 {
            s.output(&mut y);
            out.push(y[0]);
            s.advance(&[if k == 0 { 1.0 } else { 0.0 }]);
        }
        assert_eq!(out, vec![0.0, 2.0, 1.0, 0.5]);
        s.reset();
        assert_eq!(s.state(), &[0.0]);
    }
}
