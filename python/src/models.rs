//! Models from Python: the Coleman–Hodgdon hysteresis (thesis (6.3), core
//! `models::hysteresis`), its exact inverse feed-forward (6.6) on the extended
//! model (6.4) (afm-stage plugin), and the time-stamping estimator (8.1)–(8.4)
//! with the quadrature encoder of Ch. 8 (timestamp-encoder plugin).

use crate::errors::model_err;
use nanomotion::afm_stage::feedforward::HysteresisFeedForward as RustFf;
use nanomotion::afm_stage::hysteresis::{ExtendedBranch, ExtendedCh};
use nanomotion::core::models::hysteresis::{ChParams, ColemanHodgdon as RustCh, Direction};
use nanomotion::core::{Estimator, Sensor};
use nanomotion::timestamp_encoder::{Fallback, TimestampEncoder, TimestampEstimator as RustEst};
use numpy::ndarray::Array2;
use numpy::{PyArray1, PyArray2, PyReadonlyArray1, PyReadonlyArray2};
use pyo3::prelude::*;

fn slice<'a>(name: &str, a: &'a PyReadonlyArray1<'_, f64>) -> PyResult<&'a [f64]> {
    a.as_slice().map_err(|e| {
        model_err(format!(
            "`{name}` must be a contiguous 1-D float array: {e}"
        ))
    })
}

fn direction(s: &str) -> PyResult<Direction> {
    match s {
        "trace" => Ok(Direction::Trace),
        "retrace" => Ok(Direction::Retrace),
        other => Err(model_err(format!(
            "direction `{other}`: give \"trace\" (increasing input) or \"retrace\" (decreasing)"
        ))),
    }
}

/// Coleman–Hodgdon hysteresis dy/dt = α|du/dt|(b·u − y) + c·du/dt (6.3),
/// integrated exactly between samples; `retrace=(α, b, c)` makes it asymmetric
/// (trace parameters for increasing input, retrace for decreasing).
#[pyclass(module = "nanomotion._nanomotion", frozen)]
pub struct ColemanHodgdon {
    model: RustCh,
}

#[pymethods]
impl ColemanHodgdon {
    #[new]
    #[pyo3(signature = (alpha, b, c, retrace=None))]
    fn new(alpha: f64, b: f64, c: f64, retrace: Option<(f64, f64, f64)>) -> PyResult<Self> {
        let trace = ChParams::new(alpha, b, c);
        let retrace = retrace.map_or(trace, |(a, b, c)| ChParams::new(a, b, c));
        Ok(Self {
            model: RustCh::new(trace, retrace).map_err(model_err)?,
        })
    }

    /// Output y for the input sequence `u`, starting from output `y0` at input `u0`.
    #[pyo3(signature = (u, y0=0.0, u0=0.0))]
    fn simulate<'py>(
        &self,
        py: Python<'py>,
        u: PyReadonlyArray1<'py, f64>,
        y0: f64,
        u0: f64,
    ) -> PyResult<Bound<'py, PyArray1<f64>>> {
        let u = slice("u", &u)?;
        if let Some(k) = u.iter().position(|v| !v.is_finite()) {
            return Err(model_err(format!(
                "u[{k}] = {} is not finite (fix: give finite inputs)",
                u[k]
            )));
        }
        let mut m = self.model.clone();
        m.reset(y0, u0);
        Ok(PyArray1::from_vec(
            py,
            u.iter().map(|&v| m.step(v)).collect(),
        ))
    }

    /// The periodic orbit (closed form) under an input oscillating between
    /// `u_min` and `u_max`, evaluated at `u` on the `direction` branch ("trace"
    /// or "retrace").
    fn steady_loop<'py>(
        &self,
        py: Python<'py>,
        u: PyReadonlyArray1<'py, f64>,
        u_min: f64,
        u_max: f64,
        direction: &str,
    ) -> PyResult<Bound<'py, PyArray1<f64>>> {
        let dir = self::direction(direction)?;
        let l = self.model.steady_loop(u_min, u_max).map_err(model_err)?;
        let u = slice("u", &u)?;
        Ok(PyArray1::from_vec(
            py,
            u.iter().map(|&v| l.eval(v, dir)).collect(),
        ))
    }

    /// (α, b, c) of the trace and the retrace direction.
    #[getter]
    fn params(&self) -> ((f64, f64, f64), (f64, f64, f64)) {
        let (t, r) = (self.model.trace(), self.model.retrace());
        ((t.alpha, t.b, t.c), (r.alpha, r.b, r.c))
    }
}

/// The exact inverse hysteresis feed-forward (6.6): the voltage that puts the
/// extended Coleman–Hodgdon model (6.4) at a desired position, on the branch of
/// the present direction of motion (switched when the reference reverses).
/// Built from a `ColemanHodgdon` (then (6.4) equals (6.3)) or from the eight
/// (6.4) parameters per direction as JSON (`extended_json`, keys
/// `trace`/`retrace` with a_um_per_v … f_um). Each branch covers the
/// position range [x_lo, x_hi].
#[pyclass(module = "nanomotion._nanomotion")]
pub struct HysteresisInverse {
    ff: RustFf,
}

#[pymethods]
impl HysteresisInverse {
    #[new]
    #[pyo3(signature = (x_lo, x_hi, model=None, extended_json=None, standstill=0.0))]
    fn new(
        x_lo: f64,
        x_hi: f64,
        model: Option<PyRef<'_, ColemanHodgdon>>,
        extended_json: Option<&str>,
        standstill: f64,
    ) -> PyResult<Self> {
        let ext = match (model, extended_json) {
            (Some(m), None) => ExtendedCh::new(
                ExtendedBranch::from_ch(m.model.trace()),
                ExtendedBranch::from_ch(m.model.retrace()),
            )
            .map_err(model_err)?,
            (None, Some(j)) => {
                let e: ExtendedCh = serde_json::from_str(j)
                    .map_err(|e| model_err(format!("extended model: {e}")))?;
                ExtendedCh::new(e.trace, e.retrace).map_err(model_err)?
            }
            _ => {
                return Err(model_err(
                    "give either model= (a ColemanHodgdon) or extended= (the (6.4) parameters), not both or neither",
                ));
            }
        };
        let ff = RustFf::for_position_range(ext, x_lo, x_hi)
            .map_err(model_err)?
            .with_standstill(standstill);
        Ok(Self { ff })
    }

    /// Voltage for position `x` on the branch `direction`, with range and
    /// monotonicity checked (raises ModelError outside the invertible range).
    fn voltage(&self, x: f64, direction: &str) -> PyResult<f64> {
        self.ff
            .branch(self::direction(direction)?)
            .inverse_checked(x)
            .map_err(model_err)
    }

    /// Position of the model branch `direction` at voltage `v` (the forward map
    /// the inverse inverts).
    fn position(&self, v: f64, direction: &str) -> PyResult<f64> {
        Ok(self.ff.branch(self::direction(direction)?).eval(v))
    }

    /// (v_min, v_max) of the branch `direction`.
    fn voltage_range(&self, direction: &str) -> PyResult<(f64, f64)> {
        let b = self.ff.branch(self::direction(direction)?);
        Ok((b.v_m, b.v_max))
    }

    /// Feed-forward voltages for a reference sequence `x` (the block's tick by
    /// tick rule: direction from the reference's change, positions outside the
    /// range clamped and counted in `out_of_range`). Starts from a reset state.
    fn run<'py>(
        &mut self,
        py: Python<'py>,
        x: PyReadonlyArray1<'py, f64>,
    ) -> PyResult<Bound<'py, PyArray1<f64>>> {
        let x = slice("x", &x)?;
        self.ff.reset();
        Ok(PyArray1::from_vec(
            py,
            x.iter().map(|&v| self.ff.step(v)).collect(),
        ))
    }

    /// Samples of the last `run` that were outside the invertible range.
    #[getter]
    fn out_of_range(&self) -> u64 {
        self.ff.out_of_range_count()
    }
}

/// The time-stamping estimator (8.1)–(8.4): a least-squares polynomial of order
/// m through the register's events, evaluated at the sample instant for
/// position, velocity and acceleration, with the Sec. 8.3 fallback.
#[pyclass(module = "nanomotion._nanomotion")]
pub struct TimestampEstimator {
    est: RustEst,
}

#[pymethods]
impl TimestampEstimator {
    #[new]
    #[pyo3(signature = (resolution, order=2, register_len=5, band_counts=1.0, fallback="thesis", edge_offsets_counts=Vec::new()))]
    fn new(
        resolution: f64,
        order: usize,
        register_len: usize,
        band_counts: f64,
        fallback: &str,
        edge_offsets_counts: Vec<f64>,
    ) -> PyResult<Self> {
        let mut est = RustEst::new(order, register_len, resolution).map_err(model_err)?;
        est.band_counts = band_counts;
        est.fallback = match fallback {
            "thesis" => Fallback::Thesis,
            "zero_standstill" => Fallback::ZeroStandstill,
            other => {
                return Err(model_err(format!(
                    "fallback `{other}`: give \"thesis\" (Sec. 8.3) or \"zero_standstill\""
                )));
            }
        };
        est.edge_offsets_counts = edge_offsets_counts;
        est.validate().map_err(model_err)?;
        Ok(Self { est })
    }

    /// Width of a register row: 2 + 2n.
    #[getter]
    fn register_width(&self) -> usize {
        self.est.register_width()
    }

    /// Estimates at times `t` (N,) from registers (N, 2 + 2n), each row
    /// `[c, n_valid, t_1, x_1, …, t_n, x_n]` (newest event first, levels in
    /// counts): returns ((N, 3) array of [x̂, v̂, â] in units, (N,) status: 0
    /// fitted, 1 out of band, 2 no events, 3 standstill).
    #[allow(clippy::type_complexity)]
    fn estimate<'py>(
        &mut self,
        py: Python<'py>,
        t: PyReadonlyArray1<'py, f64>,
        registers: PyReadonlyArray2<'py, f64>,
    ) -> PyResult<(Bound<'py, PyArray2<f64>>, Bound<'py, PyArray1<u8>>)> {
        let t = slice("t", &t)?;
        let r = registers.as_array();
        let w = self.est.register_width();
        if r.ncols() != w || r.nrows() != t.len() {
            return Err(model_err(format!(
                "registers have shape ({}, {}), expected ({}, {w}) (one row of 2 + 2n = {w} values per time)",
                r.nrows(),
                r.ncols(),
                t.len()
            )));
        }
        let mut out = Array2::<f64>::zeros((t.len(), 3));
        let mut status = Vec::with_capacity(t.len());
        let mut row = vec![0.0; w];
        let mut y = [0.0; 3];
        for (k, &tk) in t.iter().enumerate() {
            for (j, v) in row.iter_mut().enumerate() {
                *v = r[(k, j)];
            }
            status.push(self.est.estimate_from_register(tk, &row, &mut y) as u8);
            for j in 0..3 {
                out[(k, j)] = y[j];
            }
        }
        Ok((
            PyArray2::from_owned_array(py, out),
            PyArray1::from_vec(py, status),
        ))
    }
}

/// A quadrature encoder with time-stamped events (Ch. 8) sampled along a known
/// trajectory, then the time-stamping estimator: `encoder_json` holds the
/// encoder's YAML/JSON parameters (lines, clock_hz, register_len, skip, slit
/// errors, …; `{}` for the defaults). `x`, `v` (and optionally `a`) are the
/// trajectory at the read times `t` (the encoder interpolates between reads).
/// Returns ((N, 3) estimates, (N,) status, (N,) count·Δ, (N, 2+2n) registers).
#[pyfunction]
#[pyo3(signature = (t, x, v, a=None, encoder_json="{}", order=2, fallback="thesis", seed=0))]
#[allow(clippy::type_complexity, clippy::too_many_arguments)]
fn timestamp_track<'py>(
    py: Python<'py>,
    t: PyReadonlyArray1<'py, f64>,
    x: PyReadonlyArray1<'py, f64>,
    v: PyReadonlyArray1<'py, f64>,
    a: Option<PyReadonlyArray1<'py, f64>>,
    encoder_json: &str,
    order: usize,
    fallback: &str,
    seed: u64,
) -> PyResult<(
    Bound<'py, PyArray2<f64>>,
    Bound<'py, PyArray1<u8>>,
    Bound<'py, PyArray1<f64>>,
    Bound<'py, PyArray2<f64>>,
)> {
    let (t, x, v) = (slice("t", &t)?, slice("x", &x)?, slice("v", &v)?);
    let a = match &a {
        Some(a) => Some(slice("a", a)?),
        None => None,
    };
    if x.len() != t.len() || v.len() != t.len() || a.is_some_and(|a| a.len() != t.len()) {
        return Err(model_err("t, x, v (and a) must have the same length"));
    }
    let mut enc: TimestampEncoder =
        serde_json::from_str(encoder_json).map_err(|e| model_err(format!("encoder: {e}")))?;
    enc.derivatives = if a.is_some() { 2 } else { 1 };
    enc.prepare(seed).map_err(model_err)?;
    let mut est = TimestampEstimator::new(
        enc.resolution(),
        order,
        enc.register_len,
        1.0,
        fallback,
        Vec::new(),
    )?;
    let w = enc.register_width();
    let n = t.len();
    let mut regs = Array2::<f64>::zeros((n, w));
    let mut out = Array2::<f64>::zeros((n, 3));
    let mut status = Vec::with_capacity(n);
    let mut count = Vec::with_capacity(n);
    let mut reg = vec![0.0; w];
    let mut y = [0.0; 3];
    for k in 0..n {
        let state = [x[k], v[k], a.map_or(0.0, |a| a[k])];
        enc.measure(t[k], &state[..1 + enc.derivatives], &mut reg);
        est.est.estimate(t[k], &reg, &mut y);
        status.push(est.est.status().map_or(2, |s| s as u8));
        count.push(enc.count() as f64 * enc.resolution());
        for j in 0..w {
            regs[(k, j)] = reg[j];
        }
        for j in 0..3 {
            out[(k, j)] = y[j];
        }
    }
    Ok((
        PyArray2::from_owned_array(py, out),
        PyArray1::from_vec(py, status),
        PyArray1::from_vec(py, count),
        PyArray2::from_owned_array(py, regs),
    ))
}

pub(crate) fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_class::<ColemanHodgdon>()?;
    m.add_class::<HysteresisInverse>()?;
    m.add_class::<TimestampEstimator>()?;
    m.add_function(wrap_pyfunction!(timestamp_track, m)?)?;
    Ok(())
}
