//! Analysis helpers from Python: Welch PSD, cumulative PSD, H1 FRF, and LTI
//! models (`Lti`) with frequency response, poles, H∞ norm and stability margins.
//! Thin wrappers of `nanomotion_core::analysis` and `nanomotion_core::lti`;
//! frequencies of estimates in Hz, of model responses in rad/s (the core's
//! conventions, named `_hz` / `_rad_s`).

use crate::errors::analysis_err;
use nanomotion::core::analysis::{self, Detrend, WelchOptions, Window};
use nanomotion::core::lti::{self, StateSpace, TransferFunction};
use nanomotion::core::nalgebra::DMatrix;
use numpy::ndarray::Array3;
use numpy::{Complex64, PyArray1, PyArray3, PyReadonlyArray1, PyReadonlyArray2};
use pyo3::prelude::*;
use pyo3::types::PyDict;

fn slice<'a>(name: &str, a: &'a PyReadonlyArray1<'_, f64>) -> PyResult<&'a [f64]> {
    a.as_slice().map_err(|e| {
        analysis_err(format!(
            "`{name}` must be a contiguous 1-D float array: {e}"
        ))
    })
}

fn welch_options(
    segment_len: usize,
    overlap: f64,
    window: &str,
    detrend: &str,
) -> PyResult<WelchOptions> {
    let window: Window = serde_json::from_value(serde_json::Value::String(window.into()))
        .map_err(|e| analysis_err(format!("window: {e}")))?;
    let detrend: Detrend = serde_json::from_value(serde_json::Value::String(detrend.into()))
        .map_err(|e| analysis_err(format!("detrend: {e}")))?;
    Ok(WelchOptions::new(segment_len)
        .with_overlap(overlap)
        .with_window(window)
        .with_detrend(detrend))
}

/// One-sided Welch PSD (scipy's `welch(..., scaling='density')` conventions):
/// returns (f_hz, S in unit²/Hz).
#[pyfunction]
#[pyo3(signature = (x, fs_hz, segment_len=1024, overlap=0.5, window="hann", detrend="mean"))]
#[allow(clippy::type_complexity)]
fn psd_welch<'py>(
    py: Python<'py>,
    x: PyReadonlyArray1<'py, f64>,
    fs_hz: f64,
    segment_len: usize,
    overlap: f64,
    window: &str,
    detrend: &str,
) -> PyResult<(Bound<'py, PyArray1<f64>>, Bound<'py, PyArray1<f64>>)> {
    let opts = welch_options(segment_len, overlap, window, detrend)?;
    let p = analysis::psd_welch(slice("x", &x)?, fs_hz, &opts).map_err(analysis_err)?;
    Ok((
        PyArray1::from_vec(py, p.freq_hz),
        PyArray1::from_vec(py, p.density),
    ))
}

/// Cumulative PSD C(f_k) = Σ_{i≤k} S(f_i) Δf (unit²) of `x`; its end value is
/// the mean square of the detrended signal. With `segment_len=None` the
/// segments of `nanomotion run`'s `cumulative_psd.svg` (Hann, 50 %, the whole
/// record up to 2¹⁶ samples), else Welch with these options. Returns (f_hz, C).
#[pyfunction]
#[pyo3(signature = (x, fs_hz, segment_len=None, overlap=0.5, window="hann", detrend="mean"))]
#[allow(clippy::type_complexity)]
fn cumulative_psd<'py>(
    py: Python<'py>,
    x: PyReadonlyArray1<'py, f64>,
    fs_hz: f64,
    segment_len: Option<usize>,
    overlap: f64,
    window: &str,
    detrend: &str,
) -> PyResult<(Bound<'py, PyArray1<f64>>, Bound<'py, PyArray1<f64>>)> {
    let x = slice("x", &x)?;
    if !(fs_hz.is_finite() && fs_hz > 0.0) {
        return Err(analysis_err(format!(
            "invalid parameter `fs_hz`: {fs_hz} must be finite and > 0"
        )));
    }
    let (f, c) = match segment_len {
        None => {
            if x.is_empty() {
                return Err(analysis_err(
                    "signal too short: the cumulative PSD needs at least one sample",
                ));
            }
            nanomotion::output::cumulative_psd(x, fs_hz)
        }
        Some(l) => {
            let opts = welch_options(l, overlap, window, detrend)?;
            let p = analysis::psd_welch(x, fs_hz, &opts).map_err(analysis_err)?;
            let c = p.cumulative();
            (p.freq_hz, c)
        }
    };
    Ok((PyArray1::from_vec(py, f), PyArray1::from_vec(py, c)))
}

/// Open-loop H1 FRF estimate Ĥ = S_yu/S_uu with the coherence: returns (f_hz,
/// H complex, γ²).
#[pyfunction]
#[pyo3(signature = (u, y, fs_hz, segment_len=1024, overlap=0.5, window="hann", detrend="mean"))]
#[allow(clippy::type_complexity, clippy::too_many_arguments)]
fn frf_h1<'py>(
    py: Python<'py>,
    u: PyReadonlyArray1<'py, f64>,
    y: PyReadonlyArray1<'py, f64>,
    fs_hz: f64,
    segment_len: usize,
    overlap: f64,
    window: &str,
    detrend: &str,
) -> PyResult<(
    Bound<'py, PyArray1<f64>>,
    Bound<'py, PyArray1<Complex64>>,
    Bound<'py, PyArray1<f64>>,
)> {
    let opts = welch_options(segment_len, overlap, window, detrend)?;
    let h =
        analysis::frf_h1(slice("u", &u)?, slice("y", &y)?, fs_hz, &opts).map_err(analysis_err)?;
    Ok((
        PyArray1::from_vec(py, h.freq_hz),
        PyArray1::from_vec(py, h.response),
        PyArray1::from_vec(py, h.coherence),
    ))
}

/// A linear time-invariant model (state space inside; continuous when `dt` is
/// None, discrete with period `dt` seconds otherwise). Build with `Lti.tf` or
/// `Lti.ss`.
#[pyclass(module = "nanomotion._nanomotion", frozen)]
pub struct Lti {
    sys: StateSpace,
}

fn matrix(name: &str, a: &PyReadonlyArray2<'_, f64>) -> PyResult<DMatrix<f64>> {
    let v = a.as_array();
    let (r, c) = v.dim();
    if v.iter().any(|x| !x.is_finite()) {
        return Err(analysis_err(format!(
            "invalid parameter `{name}`: entries must be finite"
        )));
    }
    Ok(DMatrix::from_fn(r, c, |i, j| v[(i, j)]))
}

#[pymethods]
impl Lti {
    /// Transfer function num/den, coefficients in descending powers of s (or z
    /// when `dt` is given), as python-control and MATLAB write them.
    #[staticmethod]
    #[pyo3(signature = (num, den, dt=None))]
    fn tf(num: Vec<f64>, den: Vec<f64>, dt: Option<f64>) -> PyResult<Self> {
        let tf = TransferFunction::new(num, den, dt).map_err(analysis_err)?;
        Ok(Self {
            sys: tf.to_ss().map_err(analysis_err)?,
        })
    }

    /// State space x' = A x + B u, y = C x + D u.
    #[staticmethod]
    #[pyo3(signature = (a, b, c, d, dt=None))]
    fn ss(
        a: PyReadonlyArray2<'_, f64>,
        b: PyReadonlyArray2<'_, f64>,
        c: PyReadonlyArray2<'_, f64>,
        d: PyReadonlyArray2<'_, f64>,
        dt: Option<f64>,
    ) -> PyResult<Self> {
        let sys = StateSpace::new(
            matrix("a", &a)?,
            matrix("b", &b)?,
            matrix("c", &c)?,
            matrix("d", &d)?,
            dt,
        )
        .map_err(analysis_err)?;
        Ok(Self { sys })
    }

    /// Sample period (s), None for continuous time.
    #[getter]
    fn dt(&self) -> Option<f64> {
        self.sys.dt
    }

    /// (outputs, inputs, states).
    #[getter]
    fn shape(&self) -> (usize, usize, usize) {
        (self.sys.noutputs(), self.sys.ninputs(), self.sys.nstates())
    }

    /// Frequency response at `w_rad_s` (rad/s; z = e^{jωT} when discrete):
    /// shape (N,) for a SISO model, (N, outputs, inputs) otherwise.
    fn freqresp<'py>(
        &self,
        py: Python<'py>,
        w_rad_s: PyReadonlyArray1<'py, f64>,
    ) -> PyResult<Bound<'py, PyAny>> {
        let w = slice("w_rad_s", &w_rad_s)?;
        let g = self.sys.try_freqresp(w).map_err(analysis_err)?;
        if self.sys.is_siso() {
            let v: Vec<Complex64> = g.iter().map(|m| m[(0, 0)]).collect();
            return Ok(PyArray1::from_vec(py, v).into_any());
        }
        let (p, m) = (self.sys.noutputs(), self.sys.ninputs());
        let a = Array3::from_shape_fn((w.len(), p, m), |(k, i, j)| g[k][(i, j)]);
        Ok(PyArray3::from_owned_array(py, a).into_any())
    }

    /// Poles (complex), s-plane or z-plane.
    fn poles<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyArray1<Complex64>>> {
        Ok(PyArray1::from_vec(
            py,
            self.sys.try_poles().map_err(analysis_err)?,
        ))
    }

    /// Whether every pole is in the open left half plane (inside the unit circle).
    fn is_stable(&self) -> bool {
        self.sys.is_stable()
    }

    /// H∞ norm and the frequency (rad/s) of its peak: (norm, peak_rad_s).
    /// Raises AnalysisError for an unstable model.
    fn hinfnorm(&self) -> PyResult<(f64, f64)> {
        let h = lti::hinfnorm(&self.sys).map_err(analysis_err)?;
        Ok((h.norm, h.peak_rad_s))
    }

    /// Stability margins of this SISO loop gain L: dict of gain_margin (absolute),
    /// gain_margin_db, phase_margin_deg, modulus_margin (= 1/‖S‖∞) and the
    /// crossover frequencies in rad/s.
    fn margins<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        let m = lti::stability_margins(&self.sys).map_err(analysis_err)?;
        let d = PyDict::new(py);
        d.set_item("gain_margin", m.gain_margin)?;
        d.set_item("gain_margin_db", m.gain_margin_db())?;
        d.set_item("phase_margin_deg", m.phase_margin_deg)?;
        d.set_item("modulus_margin", m.modulus_margin)?;
        d.set_item("phase_crossover_rad_s", m.phase_crossover_rad_s)?;
        d.set_item("gain_crossover_rad_s", m.gain_crossover_rad_s)?;
        d.set_item("modulus_rad_s", m.modulus_rad_s)?;
        Ok(d)
    }

    /// Series connection `other · self` (self first).
    fn series(&self, other: &Lti) -> PyResult<Lti> {
        Ok(Lti {
            sys: lti::series(&self.sys, &other.sys).map_err(analysis_err)?,
        })
    }

    /// Feedback connection self/(1 − sign·other·self) (sign −1: negative feedback).
    #[pyo3(signature = (other, sign=-1.0))]
    fn feedback(&self, other: &Lti, sign: f64) -> PyResult<Lti> {
        Ok(Lti {
            sys: lti::feedback(&self.sys, &other.sys, sign).map_err(analysis_err)?,
        })
    }

    fn __repr__(&self) -> String {
        format!(
            "Lti({} outputs, {} inputs, {} states, dt={:?})",
            self.sys.noutputs(),
            self.sys.ninputs(),
            self.sys.nstates(),
            self.sys.dt
        )
    }
}

pub(crate) fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_function(wrap_pyfunction!(psd_welch, m)?)?;
    m.add_function(wrap_pyfunction!(cumulative_psd, m)?)?;
    m.add_function(wrap_pyfunction!(frf_h1, m)?)?;
    m.add_class::<Lti>()?;
    Ok(())
}
