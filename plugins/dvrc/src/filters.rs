//! Learning filters L(z) and robustness filters Q(z) of repetitive control (Sec. 5.2,
//! Fig. 5.1), all implementing [`LearningFilter`]:
//!
//! - [`FilterSpec::Zpetc`]: the ZPETC inverse of a model of the complementary
//!   sensitivity T(z) (core [`zpetc()`]), preview l = d + deg B_u;
//! - [`FilterSpec::FirLowpass`]: the linear-phase FIR low-pass Q(z) (core
//!   [`fir_lowpass`], Hamming window), q = (taps − 1)/2 samples delay;
//! - [`FilterSpec::Fir`] and [`FilterSpec::Iir`]: arbitrary filters from YAML, with
//!   the delay (preview) the user declares;
//! - [`FilterSpec::Identity`]: L = 1 or Q = 1.
//!
//! Every spec is *built* once at the block's sample period into a [`Filter`]
//! (allocation happens there); [`Filter::filter`] never allocates.
//!
//! ```
//! use dvrc::filters::FilterSpec;
//! use nanomotion_core::LearningFilter;
//! let q = FilterSpec::FirLowpass { taps: 11, cutoff_hz: 200.0 }.build(1.0 / 4000.0).unwrap();
//! assert_eq!(q.preview_samples(), 5);
//! let mut q = q;
//! // Unity DC gain: a constant comes out unchanged after the transient.
//! let y: Vec<f64> = (0..20).map(|_| q.filter(1.0)).collect();
//! assert!((y[19] - 1.0).abs() < 1e-12);
//! ```

use nalgebra::DMatrix;
use nanomotion_core::LearningFilter;
use nanomotion_core::Params;
use nanomotion_core::block::check;
use nanomotion_core::error::ParamError;
use nanomotion_core::lti::{
    Complex, LtiError, SsStepper, StateSpace, TransferFunction, fir_lowpass, fir2ss, zpetc,
};
use serde::{Deserialize, Serialize};

/// How a learning filter L(z) or robustness filter Q(z) is specified (YAML: a map
/// with `kind:`). Discrete coefficients are in **descending powers of z** at the
/// block's own rate.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, Params)]
#[serde(tag = "kind", rename_all = "snake_case", deny_unknown_fields)]
pub enum FilterSpec {
    /// L = Q = 1 (no filtering, no delay).
    Identity,
    /// ZPETC inverse L(z) ≈ T(z)⁻¹ of the discrete complementary sensitivity
    /// T(z) = num/den (Sec. 5.2, Tomizuka); preview l from the relative degree and
    /// the unstable zeros.
    Zpetc {
        /// Numerator of T(z), descending powers of z.
        num: Vec<f64>,
        /// Denominator of T(z), descending powers of z.
        den: Vec<f64>,
    },
    /// Linear-phase FIR low-pass Q(z) (windowed sinc, Hamming, unity DC gain) with
    /// `taps` (odd) coefficients: q = (taps − 1)/2 samples delay.
    FirLowpass {
        /// Number of taps (odd).
        #[param(size(1, MAX_FIR_TAPS))]
        taps: usize,
        /// −6 dB cut-off frequency (Hz), below Nyquist.
        cutoff_hz: f64,
    },
    /// Arbitrary FIR Σ b\[k\] z^-k with a declared delay (for a symmetric FIR:
    /// (len − 1)/2).
    Fir {
        /// Coefficients b\[0\], b\[1\], ...
        coefficients: Vec<f64>,
        /// Delay (Q: q) or preview (L: l) in samples that the memory loop
        /// compensates.
        #[serde(default)]
        #[param(size(0, nanomotion_core::block::MAX_BUFFER_VALUES))]
        delay: usize,
    },
    /// Arbitrary stable proper IIR num(z)/den(z), descending powers of z, with a
    /// declared delay/preview (samples).
    Iir {
        /// Numerator, descending powers of z.
        num: Vec<f64>,
        /// Denominator, descending powers of z.
        den: Vec<f64>,
        /// Delay (Q: q) or preview (L: l) in samples.
        #[serde(default)]
        #[param(size(0, nanomotion_core::block::MAX_BUFFER_VALUES))]
        delay: usize,
    },
}

fn lti_err(field: &str, e: LtiError) -> ParamError {
    ParamError::new(field, e.to_string(), "check the filter coefficients")
}

impl FilterSpec {
    /// The linear-phase FIR Q of the thesis: `taps` (odd) taps, cut-off `cutoff_hz`.
    pub fn q_fir(taps: usize, cutoff_hz: f64) -> Self {
        FilterSpec::FirLowpass { taps, cutoff_hz }
    }

    /// Build the runtime filter at sample period `dt` (s). `field` names the YAML
    /// field (`learning`, `robustness`) in errors.
    pub fn build_named(&self, field: &str, dt: f64) -> Result<Filter, ParamError> {
        check::positive("dt", dt)?;
        // the bounds declared on the variants' fields (`taps`, `delay`)
        self.check_params().map_err(|mut e| {
            e.field = format!("{field}.{}", e.field);
            e
        })?;
        match self {
            FilterSpec::Identity => Ok(Filter::fir(vec![1.0], 0, dt)),
            FilterSpec::Zpetc { num, den } => {
                check::all_finite(&format!("{field}.num"), num)?;
                check::all_finite(&format!("{field}.den"), den)?;
                let t = TransferFunction::new(num.clone(), den.clone(), Some(dt))
                    .map_err(|e| lti_err(field, e))?;
                let z = zpetc(&t).map_err(|e| lti_err(field, e))?;
                let ss = z.to_ss().map_err(|e| lti_err(field, e))?;
                Filter::from_ss(ss, z.preview).map_err(|e| lti_err(field, e))
            }
            FilterSpec::FirLowpass { taps, cutoff_hz } => {
                let h = fir_lowpass(*taps, *cutoff_hz, dt).map_err(|e| {
                    ParamError::new(
                        field,
                        e.to_string(),
                        "give an odd number of taps and a cut-off below Nyquist",
                    )
                })?;
                Ok(Filter::fir(h, (taps - 1) / 2, dt))
            }
            FilterSpec::Fir {
                coefficients,
                delay,
            } => {
                if coefficients.is_empty() {
                    return Err(ParamError::new(
                        format!("{field}.coefficients"),
                        "is empty",
                        "give at least one coefficient",
                    ));
                }
                check::size(
                    &format!("{field}.coefficients"),
                    coefficients.len(),
                    1,
                    MAX_FIR_TAPS,
                )?;
                check::all_finite(&format!("{field}.coefficients"), coefficients)?;
                Ok(Filter::fir(coefficients.clone(), *delay, dt))
            }
            FilterSpec::Iir { num, den, delay } => {
                check::all_finite(&format!("{field}.num"), num)?;
                check::all_finite(&format!("{field}.den"), den)?;
                let t = TransferFunction::new(num.clone(), den.clone(), Some(dt))
                    .map_err(|e| lti_err(field, e))?;
                let ss = t.to_ss_cascade().map_err(|e| lti_err(field, e))?;
                if !ss.is_stable() {
                    return Err(ParamError::new(
                        field,
                        "the IIR filter is unstable",
                        "give a denominator with all roots inside the unit circle",
                    ));
                }
                Filter::from_ss(ss, *delay).map_err(|e| lti_err(field, e))
            }
        }
    }

    /// [`build_named`](Self::build_named) with the field name `filter`.
    pub fn build(&self, dt: f64) -> Result<Filter, ParamError> {
        self.build_named("filter", dt)
    }
}

/// Most taps of an FIR learning or robustness filter (`fir_lowpass.taps`, the
/// length of `fir.coefficients`): 16 385. Each tap costs a multiply-add per
/// sample; the thesis's Q filters have about 100.
pub const MAX_FIR_TAPS: usize = 16_385;

/// Most taps of an FIR filter that gets an analysis model (a state-space model
/// of taps − 1 states, dense: (taps − 1)² × 8 bytes, 2 MiB here), for the
/// stability gate and `rc-check`: 513. Longer filters run, but have no model
/// (audit D4: a 16 385-tap filter cost 2 GiB and 16 s to build its model), so a
/// loop with one is unproven, and `rc-check` says which `taps` to lower.
pub const MAX_MODEL_TAPS: usize = 513;

/// FIR runtime: a doubled ring buffer so that the convolution is one contiguous
/// dot product (no wrap-around test in the inner loop).
#[derive(Debug, Clone)]
struct FirState {
    /// Taps reversed: `rev[j] = h[n − 1 − j]`.
    rev: Vec<f64>,
    /// 2n values; sample k is written at `pos` and `pos + n`.
    buf: Vec<f64>,
    pos: usize,
}

impl FirState {
    fn new(h: &[f64]) -> Self {
        let n = h.len();
        Self {
            rev: h.iter().rev().copied().collect(),
            buf: vec![0.0; 2 * n],
            pos: 0,
        }
    }
    #[inline]
    fn step(&mut self, x: f64) -> f64 {
        let n = self.rev.len();
        // Newest sample at index pos + n − 1 of the window buf[pos..pos + n].
        self.buf[self.pos] = x;
        self.buf[self.pos + n] = x;
        let win = &self.buf[self.pos + 1..self.pos + 1 + n];
        // win[n − 1] = x (newest), win[0] = oldest: y = Σ h[j] x[k − j] = Σ rev·win.
        let y = dot(&self.rev, win);
        self.pos += 1;
        if self.pos == n {
            self.pos = 0;
        }
        y
    }
    fn reset(&mut self) {
        self.buf.fill(0.0);
        self.pos = 0;
    }
}

/// Dot product in four independent accumulators (lets the compiler vectorise).
#[inline]
fn dot(a: &[f64], b: &[f64]) -> f64 {
    let n = a.len().min(b.len());
    let (a, b) = (&a[..n], &b[..n]);
    let mut acc = [0.0f64; 4];
    let chunks = n / 4;
    for i in 0..chunks {
        let j = 4 * i;
        acc[0] += a[j] * b[j];
        acc[1] += a[j + 1] * b[j + 1];
        acc[2] += a[j + 2] * b[j + 2];
        acc[3] += a[j + 3] * b[j + 3];
    }
    let mut s = (acc[0] + acc[1]) + (acc[2] + acc[3]);
    for j in 4 * chunks..n {
        s += a[j] * b[j];
    }
    s
}

// The state-space variant carries the small-model stepper's fixed arrays
// inline (no allocation, no indirection in the tick); a filter holds one.
#[allow(clippy::large_enum_variant)]
#[derive(Debug, Clone)]
enum Runtime {
    Fir(FirState),
    Ss(SsStepper),
}

/// A built learning/robustness filter: the causal realisation z^-l·L(z) (or Q(z)
/// with its q samples delay), its delay, and its exact discrete model for analysis.
#[derive(Debug, Clone)]
pub struct Filter {
    runtime: Runtime,
    delay: usize,
    /// The analysis model; `None` for an FIR filter of more than
    /// [`MAX_MODEL_TAPS`] taps.
    model: Option<StateSpace>,
    /// FIR taps, if the filter is FIR.
    taps: Option<Vec<f64>>,
    /// Sample period (s).
    dt: Option<f64>,
}

impl Filter {
    /// An FIR filter Σ h\[k\] z^-k with declared delay `delay` at period `dt` (s).
    pub fn fir(h: Vec<f64>, delay: usize, dt: f64) -> Self {
        Self {
            runtime: Runtime::Fir(FirState::new(&h)),
            delay,
            model: (h.len() <= MAX_MODEL_TAPS).then(|| fir2ss(&h, dt)),
            taps: Some(h),
            dt: Some(dt),
        }
    }

    /// A filter given by a discrete state-space model with declared delay/preview.
    pub fn from_ss(model: StateSpace, delay: usize) -> Result<Self, LtiError> {
        if !model.is_siso() {
            return Err(LtiError::Dimension("a learning filter must be SISO".into()));
        }
        Ok(Self {
            runtime: Runtime::Ss(SsStepper::new(&model)?),
            delay,
            dt: model.dt,
            model: Some(model),
            taps: None,
        })
    }

    /// The exact discrete model of the causal realisation that is run, or why
    /// there is none (an FIR filter of more than [`MAX_MODEL_TAPS`] taps).
    pub fn model(&self) -> Result<&StateSpace, LtiError> {
        self.model.as_ref().ok_or_else(|| {
            LtiError::Domain(format!(
                "the FIR filter has {} taps; stability is analysed for FIR filters of at most {MAX_MODEL_TAPS} taps (their model has taps − 1 states) (fix: lower `taps` to at most {MAX_MODEL_TAPS}, or give the filter as `iir`)",
                self.taps.as_ref().map_or(0, Vec::len)
            ))
        })
    }

    /// Heap bytes of the filter: taps, run-time buffer and analysis model.
    pub fn memory_bytes(&self) -> usize {
        let f = std::mem::size_of::<f64>();
        let taps = self.taps.as_ref().map_or(0, Vec::len);
        let model = self
            .model
            .as_ref()
            .map_or(0, |m| (m.a.len() + m.b.len() + m.c.len() + m.d.len()) * f);
        3 * taps * f + model
    }

    /// The FIR taps, if this is an FIR filter.
    pub fn taps(&self) -> Option<&[f64]> {
        self.taps.as_deref()
    }

    /// Frequency response of the causal realisation at `w_rad_s` (rad/s).
    pub fn freqresp_at(&self, w_rad_s: f64) -> Complex<f64> {
        match (&self.taps, self.dt) {
            (Some(h), Some(dt)) => {
                let zi = Complex::from_polar(1.0, -w_rad_s * dt);
                let mut acc = Complex::new(0.0, 0.0);
                for &c in h.iter().rev() {
                    acc = acc * zi + c;
                }
                acc
            }
            _ => self
                .model
                .as_ref()
                .map_or(Complex::new(f64::NAN, 0.0), |m| m.freqresp_siso_at(w_rad_s)),
        }
    }

    /// Unity-gain pass-through with no delay (L = 1).
    pub fn identity(dt: f64) -> Self {
        Self::fir(vec![1.0], 0, dt)
    }

    /// A static gain as a 1×1 model (helper for analysis).
    pub fn gain_model(k: f64, dt: f64) -> StateSpace {
        StateSpace::gain(DMatrix::from_element(1, 1, k), Some(dt))
    }
}

impl LearningFilter for Filter {
    fn preview_samples(&self) -> usize {
        self.delay
    }
    #[inline]
    fn filter(&mut self, x: f64) -> f64 {
        match &mut self.runtime {
            Runtime::Fir(f) => f.step(x),
            Runtime::Ss(s) => s.step_siso(x),
        }
    }
    fn reset(&mut self) {
        match &mut self.runtime {
            Runtime::Fir(f) => f.reset(),
            Runtime::Ss(s) => s.reset(),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use nanomotion_core::lti::lsim_siso;

    const DT: f64 = 1.0 / 4000.0;

    #[test]
    fn fir_runtime_matches_its_model_and_the_direct_convolution() {
        let h: Vec<f64> = (0..7).map(|k| (k as f64 * 0.7).sin() + 0.1).collect();
        let mut f = Filter::fir(h.clone(), 3, DT);
        let u: Vec<f64> = (0..40).map(|k| ((k * 7 % 11) as f64) - 5.0).collect();
        let y: Vec<f64> = u.iter().map(|&x| f.filter(x)).collect();
        let y_ss = lsim_siso(f.model().unwrap(), &u).unwrap();
        for k in 0..u.len() {
            let direct: f64 = (0..h.len())
                .filter(|&j| j <= k)
                .map(|j| h[j] * u[k - j])
                .sum();
            assert!((y[k] - direct).abs() < 1e-12, "k {k}");
            assert!((y[k] - y_ss[k]).abs() < 1e-12);
        }
        let w = 2.0 * std::f64::consts::PI * 300.0;
        assert!((f.freqresp_at(w) - f.model().unwrap().freqresp_siso_at(w)).norm() < 1e-12);
        assert_eq!(f.preview_samples(), 3);
    }

    #[test]
    fn specs_parse_from_yaml_and_build() {
        let q: FilterSpec =
            nanomotion_core::yaml::from_str("kind: fir_lowpass\ntaps: 101\ncutoff_hz: 220\n", "t")
                .unwrap();
        let f = q.build(DT).unwrap();
        assert_eq!(f.preview_samples(), 50);
        assert_eq!(f.taps().unwrap().len(), 101);
        // Linear phase: Q·e^{jωqT} real.
        let w = 2.0 * std::f64::consts::PI * 100.0;
        let g = f.freqresp_at(w) * Complex::from_polar(1.0, w * 50.0 * DT);
        assert!(g.im.abs() < 1e-12 && (g.re - 1.0).abs() < 0.05, "{g}");
        let l: FilterSpec = nanomotion_core::yaml::from_str(
            "kind: zpetc\nnum: [1.0, 0.5]\nden: [1.0, -1.2, 0.5, 0.0]\n",
            "t",
        )
        .unwrap();
        let lf = l.build(DT).unwrap();
        assert_eq!(lf.preview_samples(), 2);
        let iir: FilterSpec = nanomotion_core::yaml::from_str(
            "kind: iir\nnum: [0.5]\nden: [1.0, -0.5]\ndelay: 1\n",
            "t",
        )
        .unwrap();
        let mut f = iir.build(DT).unwrap();
        assert_eq!(f.preview_samples(), 1);
        assert_eq!(f.filter(1.0), 0.0);
        assert!((f.filter(0.0) - 0.5).abs() < 1e-15);
        let bad: FilterSpec =
            nanomotion_core::yaml::from_str("kind: iir\nnum: [1.0]\nden: [1.0, -1.5]\n", "t")
                .unwrap();
        assert!(bad.build(DT).is_err());
        let e = FilterSpec::FirLowpass {
            taps: 100,
            cutoff_hz: 10.0,
        }
        .build_named("robustness", DT)
        .unwrap_err();
        assert_eq!(e.field, "robustness");
    }
}
