//! Repetitive controllers as blocks that add to a feedback loop (Fig. 5.1): the RC
//! output w is added to the tracking error e at the input of the feedback
//! controller K, u = K(e + w).
//!
//! All three share one memory loop ([`MemoryLoop`]), realised exactly as the
//! interconnection of Fig. 5.2 that the stability proof of Sec. 5.4 is about:
//!
//! ```text
//!   w_k  = Σ_i w_i · q_{k − D_k − (i−1)N}      (delay block, D_k = N_k − q − l)
//!   x_k  = w_{k−l} + (z^-l L)(e)_k             (learning filter, preview l)
//!   q_k  = (Q x)_k                             (robustness filter, delay q)
//! ```
//!
//! With the weights (w_1) = (1) and a constant N this is (5.1):
//! M(z) = L(z)Q(z)z^-(N−l−q) / (1 − Q(z)z^-(N−q)) with L and Q the causal
//! realisations (delays l and q, as in the thesis). The loop seen by the delay block
//! is H(z) = Q(z)(z^-l − T(z)L(z)) = Q z^-l (1 − T L z^l), so
//! ‖H‖∞ = ‖Q(1 − T L z^l)‖∞ of (5.5)/(5.9).
//!
//! - [`RepetitiveControl`] (`repetitive_control`): standard RC, constant N (5.1);
//! - [`HighOrderRc`] (`high_order_rc`): W(z) = Σ w_i z^-(i−1)N, default
//!   (2, −1), i.e. W = 2 − z^-N (Sec. 5.5.4);
//! - [`Dvrc`] (`dvrc`): N_k = k − k*(α_k) from an input α (5.7)–(5.8), see
//!   [`crate::delay::AlphaDelay`] for stalls and reversals.
//!
//! No block has direct feed-through (w_k depends on past samples only, D_k ≥ 1), so
//! an RC block closes the loop of Fig. 5.1 without an algebraic loop. Nothing
//! allocates after `build`.

use crate::delay::{AlphaDelay, VaryingDelay};
use crate::filters::{Filter, FilterSpec};
use nanomotion_core::Params;
use nanomotion_core::block::{BuildContext, Tick, check};
use nanomotion_core::error::ParamError;
use nanomotion_core::{Block, Controller, LearningFilter, declared_block};
use serde::{Deserialize, Serialize};

/// The memory loop of Fig. 5.1/5.2 with an externally chosen delay N_k per sample.
///
/// ```
/// use dvrc::filters::Filter;
/// use dvrc::rc::MemoryLoop;
/// let dt = 1e-3;
/// // L = Q = 1, N = 4: w_k = w_{k−4} + e_{k−4} (the pure internal model 1/(1 − z^-4)).
/// let mut m = MemoryLoop::new(Filter::identity(dt), Filter::identity(dt), vec![1.0], 0, 4, 4).unwrap();
/// let mut w = vec![];
/// for k in 0..12 {
///     w.push(m.output(4));
///     m.update(if k == 1 { 1.0 } else { 0.0 });
/// }
/// assert_eq!(w, vec![0., 0., 0., 0., 0., 1., 0., 0., 0., 1., 0., 0.]);
/// ```
#[derive(Debug, Clone)]
pub struct MemoryLoop {
    l: Filter,
    q: Filter,
    weights: Vec<f64>,
    /// Period N of the high-order weights (samples); unused for one weight.
    n_period: usize,
    /// l + q.
    comp: usize,
    n_min: usize,
    n_max: usize,
    mem: VaryingDelay,
    wdel: VaryingDelay,
    w: f64,
}

impl MemoryLoop {
    /// A memory loop with learning filter `l` (preview l), robustness filter `q`
    /// (delay q), high-order `weights` (w_1, w_2, ...) spaced `n_period` samples,
    /// for delays N_k ∈ \[`n_min`, `n_max`\]. Needs n_min ≥ l + q + 1.
    pub fn new(
        l: Filter,
        q: Filter,
        weights: Vec<f64>,
        n_period: usize,
        n_min: usize,
        n_max: usize,
    ) -> Result<Self, ParamError> {
        check::buffer("n_max", n_max, 0, 1)?;
        check::buffer("n", n_period, 0, weights.len())?;
        let comp = l.preview_samples() + q.preview_samples();
        if n_min < comp + 1 {
            return Err(ParamError::new(
                "n_min",
                format!(
                    "the smallest repetitive delay {n_min} is not above l + q = {} + {} (the learning preview plus the Q delay)",
                    l.preview_samples(),
                    q.preview_samples()
                ),
                format!("give N ≥ {} samples, or shorten the Q filter", comp + 1),
            ));
        }
        if n_max < n_min {
            return Err(ParamError::new(
                "n_max",
                format!("n_max = {n_max} is below n_min = {n_min}"),
                "make n_max ≥ n_min",
            ));
        }
        if weights.is_empty() {
            return Err(ParamError::new(
                "weights",
                "is empty",
                "give at least one weight, e.g. [2, -1]",
            ));
        }
        check::all_finite("weights", &weights)?;
        if weights.len() > 1 && n_period == 0 {
            return Err(ParamError::new("n", "is 0", "give the period N in samples"));
        }
        let cap = n_max - comp + (weights.len() - 1) * n_period;
        let l_prev = l.preview_samples();
        Ok(Self {
            l,
            q,
            weights,
            n_period,
            comp,
            n_min,
            n_max,
            mem: VaryingDelay::new(cap),
            wdel: VaryingDelay::new(l_prev.max(1)),
            w: 0.0,
        })
    }

    /// Bytes held by the memory and preview delay lines and the two filters.
    pub fn memory_bytes(&self) -> usize {
        (self.mem.max_delay() + self.wdel.max_delay() + 2) * std::mem::size_of::<f64>()
            + self.l.memory_bytes()
            + self.q.memory_bytes()
    }

    /// Bytes the memory of a loop with delays up to `n_max` (and `weights`
    /// periods of `n_period`) and filters `learning`, `robustness` will hold, from
    /// the parameters alone (reserved before anything is allocated).
    pub fn planned_bytes(
        n_max: usize,
        n_period: usize,
        weights: usize,
        learning: &FilterSpec,
        robustness: &FilterSpec,
    ) -> usize {
        let f = std::mem::size_of::<f64>();
        let filter = |s: &FilterSpec| match s {
            FilterSpec::FirLowpass { taps, .. } => fir_bytes(*taps),
            FilterSpec::Fir { coefficients, .. } => fir_bytes(coefficients.len()),
            _ => 0,
        };
        n_max
            .saturating_add(weights.saturating_sub(1).saturating_mul(n_period))
            .saturating_mul(f)
            .saturating_add(filter(learning))
            .saturating_add(filter(robustness))
    }

    /// Phase 1: the RC output w_k for delay N_k (clamped to \[n_min, n_max\]).
    #[inline]
    pub fn output(&mut self, n_k: usize) -> f64 {
        let d = n_k.clamp(self.n_min, self.n_max) - self.comp;
        let w = if self.weights.len() == 1 {
            self.weights[0] * self.mem.get(d)
        } else {
            let mut s = 0.0;
            for (i, wi) in self.weights.iter().enumerate() {
                s += wi * self.mem.get(d + i * self.n_period);
            }
            s
        };
        self.w = w;
        w
    }

    /// Phase 2: advance with the tracking error e_k of this sample.
    #[inline]
    pub fn update(&mut self, e: f64) {
        let lp = self.l.preview_samples();
        let w_old = if lp == 0 { self.w } else { self.wdel.get(lp) };
        self.wdel.push(self.w);
        let x = w_old + self.l.filter(e);
        let qv = self.q.filter(x);
        self.mem.push(qv);
    }

    /// Clear all memories.
    pub fn reset(&mut self) {
        self.l.reset();
        self.q.reset();
        self.mem.reset();
        self.wdel.reset();
        self.w = 0.0;
    }

    /// The learning filter.
    pub fn learning(&self) -> &Filter {
        &self.l
    }
    /// The robustness filter.
    pub fn robustness(&self) -> &Filter {
        &self.q
    }
    /// Capacity of the ring buffer (samples).
    pub fn buffer_len(&self) -> usize {
        self.mem.max_delay() + 1
    }
}

fn default_identity() -> FilterSpec {
    FilterSpec::Identity
}

fn default_period() -> f64 {
    std::f64::consts::TAU
}

fn ho_weights() -> Vec<f64> {
    vec![2.0, -1.0]
}

/// A discrete SISO model T(z) = num/den (descending powers of z) given for the
/// stability check when the learning filter is not a ZPETC of T.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, Params)]
#[serde(deny_unknown_fields)]
pub struct TfModel {
    /// Numerator, descending powers of z.
    pub num: Vec<f64>,
    /// Denominator, descending powers of z.
    pub den: Vec<f64>,
}

impl TfModel {
    /// T(z) of `spec` if it is a ZPETC, else `self_model`.
    pub(crate) fn resolve<'a>(
        own: &'a Option<TfModel>,
        learning: &'a FilterSpec,
    ) -> Option<TfModel> {
        if let Some(t) = own {
            return Some(t.clone());
        }
        if let FilterSpec::Zpetc { num, den } = learning {
            return Some(TfModel {
                num: num.clone(),
                den: den.clone(),
            });
        }
        None
    }
}

/// Heap bytes of an FIR filter of `taps` taps: taps, run-time buffer and, up to
/// [`crate::filters::MAX_MODEL_TAPS`], its dense analysis model.
fn fir_bytes(taps: usize) -> usize {
    let f = std::mem::size_of::<f64>();
    let states = if taps <= crate::filters::MAX_MODEL_TAPS {
        taps.saturating_sub(1)
    } else {
        0
    };
    (3 * taps + states * states + 2 * states + 1) * f
}

/// What the stability gate needs of a built memory loop (`Block::learning`):
/// the filters as they are run and the delay range; `None` when a filter has no
/// analysis model (an FIR filter too long to analyse): the loop is then unproven.
fn learning_of(
    m: &MemoryLoop,
    n_min: usize,
    n_max: usize,
    weight_sum: Option<f64>,
) -> Option<nanomotion_core::gate::LearningModel> {
    Some(nanomotion_core::gate::LearningModel {
        l_causal: m.learning().model().ok()?.clone(),
        preview: m.learning().preview_samples(),
        q: m.robustness().model().ok()?.clone(),
        n_min,
        n_max,
        weight_sum,
        error_input: 0,
        output: 0,
    })
}

/// The plain-Rust sample methods (`step`, `output_w`, `learn`) and the
/// [`Controller`]/[`Block`] adapters shared by the constant-delay RC blocks
/// ([`RepetitiveControl`], [`HighOrderRc`]): both hold `n: usize` and
/// `core: Option<MemoryLoop>` and differ only in how `prepare` builds the loop.
macro_rules! fixed_delay_rc_adapters {
    ($ty:ident) => {
        impl $ty {
            /// One sample from plain Rust: returns w_k, then learns from e_k.
            ///
            /// An unbuilt block (neither [`Block::build`] nor a build-at-`dt`
            /// constructor called) has no memory: it returns 0.0 and learns nothing.
            pub fn step(&mut self, e: f64) -> f64 {
                let w = self.output_w();
                self.learn(e);
                w
            }
            /// Phase 1 of a sample in a closed loop: w_k (depends on the past only).
            /// 0.0 while the block is unbuilt.
            pub fn output_w(&mut self) -> f64 {
                let n = self.n;
                self.core.as_mut().map_or(0.0, |c| c.output(n))
            }
            /// Phase 2: learn from the error e_k of the same sample. Does nothing
            /// while the block is unbuilt.
            pub fn learn(&mut self, e: f64) {
                if let Some(c) = self.core.as_mut() {
                    c.update(e);
                }
            }
        }

        impl Controller for $ty {
            fn control(&mut self, e: &[f64], u: &mut [f64]) {
                u[0] = self.step(e[0]);
            }
            fn reset(&mut self) {
                if let Some(c) = self.core.as_mut() {
                    c.reset();
                }
            }
        }

        #[declared_block]
        impl Block for $ty {
            fn direct_feedthrough(&self) -> bool {
                false
            }
            fn build(&mut self, ctx: &BuildContext) -> Result<(), ParamError> {
                self.prepare(ctx.dt)
            }
            fn planned_bytes(&self, _dt: f64) -> (&'static str, usize) {
                ("n", self.planned_memory())
            }
            fn memory_bytes(&self) -> usize {
                self.core.as_ref().map_or(0, MemoryLoop::memory_bytes)
            }
            fn output(&mut self, _tick: Tick, _u: &[f64], y: &mut [f64]) {
                if let Some(c) = self.core.as_mut() {
                    y[0] = c.output(self.n);
                }
            }
            fn update(&mut self, _tick: Tick, u: &[f64]) {
                if let Some(c) = self.core.as_mut() {
                    c.update(u[0]);
                }
            }
            fn learning(&self) -> Option<nanomotion_core::gate::LearningModel> {
                self.learning_model()
            }
        }
    };
}

// ---------------------------------------------------------------------------------
// repetitive_control
// ---------------------------------------------------------------------------------

/// `repetitive_control`: standard repetitive control (5.1), constant delay N; add w to
/// e before K (Fig. 5.1).
///
/// Standard RC (5.1) with constant delay N. Input `e`
/// (tracking error), output `w` (added to e before K, Fig. 5.1).
#[derive(Debug, Clone, Serialize, Deserialize, Params)]
#[serde(deny_unknown_fields)]
#[block(type_name = "repetitive_control", role = Controller, ports = "e -> w")]
pub struct RepetitiveControl {
    /// Repetitive delay N (samples at the block's rate) = P_α/T_s; see
    /// [`crate::estimate_period_samples`] to find it from a measured error.
    pub n: usize,
    /// Learning filter L (default identity).
    #[serde(default = "default_identity")]
    #[param(default_doc = "identity")]
    pub learning: FilterSpec,
    /// Robustness filter Q (default identity).
    #[serde(default = "default_identity")]
    #[param(default_doc = "identity")]
    pub robustness: FilterSpec,
    /// T(z) for `nanomotion rc-check` when `learning` is not a ZPETC (optional).
    #[serde(default)]
    pub t_model: Option<TfModel>,
    #[serde(skip)]
    core: Option<MemoryLoop>,
}

impl RepetitiveControl {
    /// Bytes the built block will hold, from its parameters.
    fn planned_memory(&self) -> usize {
        MemoryLoop::planned_bytes(self.n, 0, 1, &self.learning, &self.robustness)
    }
    /// The gate's view: (5.5) with N fixed.
    fn learning_model(&self) -> Option<nanomotion_core::gate::LearningModel> {
        learning_of(self.core.as_ref()?, self.n, self.n, None)
    }
    /// Standard RC with delay `n`, learning `l` and robustness `q`; call
    /// [`Block::build`] (or use [`RepetitiveControl::built`]).
    pub fn new(n: usize, learning: FilterSpec, robustness: FilterSpec) -> Self {
        Self {
            n,
            learning,
            robustness,
            t_model: None,
            core: None,
        }
    }
    /// [`new`](Self::new) and build at period `dt` (s).
    pub fn built(
        n: usize,
        learning: FilterSpec,
        robustness: FilterSpec,
        dt: f64,
    ) -> Result<Self, ParamError> {
        let mut s = Self::new(n, learning, robustness);
        s.prepare(dt)?;
        Ok(s)
    }
    fn prepare(&mut self, dt: f64) -> Result<(), ParamError> {
        let l = self.learning.build_named("learning", dt)?;
        let q = self.robustness.build_named("robustness", dt)?;
        let core = MemoryLoop::new(l, q, vec![1.0], 0, self.n, self.n).map_err(|mut e| {
            if e.field == "n_min" || e.field == "n_max" {
                e.field = "n".into();
            }
            e
        })?;
        self.core = Some(core);
        Ok(())
    }
    /// The memory loop (after build).
    pub fn memory_loop(&self) -> Option<&MemoryLoop> {
        self.core.as_ref()
    }
}

fixed_delay_rc_adapters!(RepetitiveControl);

// ---------------------------------------------------------------------------------
// high_order_rc
// ---------------------------------------------------------------------------------

/// `high_order_rc`: high-order repetitive control, W(z) = Σ w_i z^-(i-1)N in the memory
/// loop (Sec. 5.5.4).
///
/// High-order RC, W(z) = Σ w_i z^-(i−1)N inside the memory loop
/// (Sec. 5.5.4; default W = 2 − z^-N, the optimal second-order weights).
#[derive(Debug, Clone, Serialize, Deserialize, Params)]
#[serde(deny_unknown_fields)]
#[block(type_name = "high_order_rc", role = Controller, ports = "e -> w")]
pub struct HighOrderRc {
    /// Repetitive delay N (samples).
    pub n: usize,
    /// Weights (w_1, ..., w_nHO), Σ w_i = 1 for a unit DC gain (default [2, −1]).
    #[serde(default = "ho_weights")]
    #[param(default_doc = "[2, -1]")]
    pub weights: Vec<f64>,
    /// Learning filter L (default identity).
    #[serde(default = "default_identity")]
    #[param(default_doc = "identity")]
    pub learning: FilterSpec,
    /// Robustness filter Q (default identity).
    #[serde(default = "default_identity")]
    #[param(default_doc = "identity")]
    pub robustness: FilterSpec,
    /// T(z) for `nanomotion rc-check` when `learning` is not a ZPETC (optional).
    #[serde(default)]
    pub t_model: Option<TfModel>,
    #[serde(skip)]
    core: Option<MemoryLoop>,
}

impl HighOrderRc {
    /// Bytes the built block will hold, from its parameters.
    fn planned_memory(&self) -> usize {
        MemoryLoop::planned_bytes(
            self.n,
            self.n,
            self.weights.len(),
            &self.learning,
            &self.robustness,
        )
    }
    /// The gate's view: the small-gain condition with Σ|w_i|.
    fn learning_model(&self) -> Option<nanomotion_core::gate::LearningModel> {
        let ws = self.weights.iter().map(|w| w.abs()).sum();
        learning_of(self.core.as_ref()?, self.n, self.n, Some(ws))
    }
    /// High-order RC with W = 2 − z^-N.
    pub fn new(n: usize, learning: FilterSpec, robustness: FilterSpec) -> Self {
        Self {
            n,
            weights: ho_weights(),
            learning,
            robustness,
            t_model: None,
            core: None,
        }
    }
    fn prepare(&mut self, dt: f64) -> Result<(), ParamError> {
        let l = self.learning.build_named("learning", dt)?;
        let q = self.robustness.build_named("robustness", dt)?;
        let core = MemoryLoop::new(l, q, self.weights.clone(), self.n, self.n, self.n).map_err(
            |mut e| {
                if e.field == "n_min" || e.field == "n_max" {
                    e.field = "n".into();
                }
                e
            },
        )?;
        self.core = Some(core);
        Ok(())
    }
    /// Build at period `dt` (s) from plain Rust.
    pub fn build_dt(&mut self, dt: f64) -> Result<(), ParamError> {
        self.prepare(dt)
    }
}

fixed_delay_rc_adapters!(HighOrderRc);

// ---------------------------------------------------------------------------------
// dvrc
// ---------------------------------------------------------------------------------

/// `dvrc`: delay-varying repetitive control (5.7)-(5.8): memory delay N_k = k - k*(α_k)
/// follows the repetitive variable α.
///
/// Delay-varying repetitive control (Sec. 5.3): the memory-loop delay
/// follows the repetitive variable α (input port `alpha`, e.g. the walking driver's
/// leg angle with P_α = 2π), N_k = k − k*(α_k) (5.7)–(5.8), limited to
/// \[n_min, n_max\] = \[m, M\] (the range (5.9) must hold for). Outputs `w` and the
/// delay `n` in use (samples, as a number).
///
/// The ring buffer is preallocated for n_max; a tick does not allocate. With α = t
/// (P_α = N·T_s, n_init = N) it is bit-for-bit [`RepetitiveControl`].
#[derive(Debug, Clone, Serialize, Deserialize, Params)]
#[serde(deny_unknown_fields)]
// α is the variable the disturbance is periodic in (Sec. 5.3), a scheduling
// input: it only sets the delay N_k, which (5.9) covers over [m, M]; the gate
// judges the loop with it frozen.
#[block(type_name = "dvrc", role = Controller, ports = "e, alpha [scheduling] -> w, n")]
pub struct Dvrc {
    /// Repetitive period P_α in units of α (default 2π rad).
    #[serde(default = "default_period")]
    #[param(positive, default_doc = "2π")]
    pub period_alpha: f64,
    /// Smallest delay m (samples).
    #[param(at_least_one)]
    pub n_min: usize,
    /// Largest (worst-case) delay M (samples): sizes the ring buffer.
    pub n_max: usize,
    /// Delay used until α has advanced by one period (default n_max).
    #[serde(default)]
    #[param(default_doc = "n_max")]
    pub n_init: Option<usize>,
    /// Learning filter L (default identity).
    #[serde(default = "default_identity")]
    #[param(default_doc = "identity")]
    pub learning: FilterSpec,
    /// Robustness filter Q (default identity).
    #[serde(default = "default_identity")]
    #[param(default_doc = "identity")]
    pub robustness: FilterSpec,
    /// T(z) for `nanomotion rc-check` when `learning` is not a ZPETC (optional).
    #[serde(default)]
    pub t_model: Option<TfModel>,
    #[serde(skip)]
    core: Option<(MemoryLoop, AlphaDelay)>,
}

impl Dvrc {
    /// DVRC with P_α = `period_alpha`, N_k ∈ \[`n_min`, `n_max`\].
    pub fn new(
        period_alpha: f64,
        n_min: usize,
        n_max: usize,
        learning: FilterSpec,
        robustness: FilterSpec,
    ) -> Self {
        Self {
            period_alpha,
            n_min,
            n_max,
            n_init: None,
            learning,
            robustness,
            t_model: None,
            core: None,
        }
    }
    /// Set the start-up delay.
    pub fn with_n_init(mut self, n_init: usize) -> Self {
        self.n_init = Some(n_init);
        self
    }
    fn prepare(&mut self, dt: f64) -> Result<(), ParamError> {
        self.check_params()?;
        let n_init = self.n_init.unwrap_or(self.n_max);
        if n_init < self.n_min || n_init > self.n_max {
            return Err(ParamError::new(
                "n_init",
                format!(
                    "{n_init} is outside [n_min, n_max] = [{}, {}]",
                    self.n_min, self.n_max
                ),
                "give a start-up delay between n_min and n_max",
            ));
        }
        let l = self.learning.build_named("learning", dt)?;
        let q = self.robustness.build_named("robustness", dt)?;
        let m = MemoryLoop::new(l, q, vec![1.0], 0, self.n_min, self.n_max)?;
        let a = AlphaDelay::new(self.period_alpha, self.n_min, self.n_max, n_init);
        self.core = Some((m, a));
        Ok(())
    }
    /// Build at period `dt` (s) from plain Rust.
    pub fn build_dt(&mut self, dt: f64) -> Result<(), ParamError> {
        self.prepare(dt)
    }
    /// One sample from plain Rust: α_k in, (w_k, N_k) out; then learns from e_k.
    ///
    /// An unbuilt block (no [`Block::build`] or [`build_dt`](Self::build_dt)) has
    /// no memory: it returns (0.0, start-up delay `n_init`, default `n_max`) and
    /// learns nothing.
    #[inline]
    pub fn step(&mut self, e: f64, alpha: f64) -> (f64, usize) {
        let r = self.output_w(alpha);
        self.learn(e);
        r
    }
    /// Phase 1 of a sample in a closed loop: record α_k, return (w_k, N_k); w_k
    /// depends on past errors only. (0.0, `n_init` or `n_max`) while unbuilt.
    #[inline]
    pub fn output_w(&mut self, alpha: f64) -> (f64, usize) {
        match self.core.as_mut() {
            Some((m, a)) => {
                let n = a.next(alpha);
                (m.output(n), n)
            }
            None => (0.0, self.n_init.unwrap_or(self.n_max)),
        }
    }
    /// Phase 2: learn from the error e_k of the same sample (call once after
    /// each [`output_w`](Self::output_w)). Does nothing while unbuilt.
    #[inline]
    pub fn learn(&mut self, e: f64) {
        if let Some((m, _)) = self.core.as_mut() {
            m.update(e);
        }
    }
    /// The memory loop (after build).
    pub fn memory_loop(&self) -> Option<&MemoryLoop> {
        self.core.as_ref().map(|c| &c.0)
    }
}

impl Controller for Dvrc {
    /// `e = [e, α]`, `u = [w]`.
    fn control(&mut self, e: &[f64], u: &mut [f64]) {
        u[0] = self.step(e[0], e[1]).0;
    }
    fn reset(&mut self) {
        if let Some((m, a)) = self.core.as_mut() {
            m.reset();
            a.reset();
        }
    }
}

#[declared_block]
impl Block for Dvrc {
    /// α_k is needed for w_k (N_k depends on α_k), so the block has feed-through
    /// from `alpha`; w never depends on e_k. The scheduler treats the block as
    /// having feed-through: α must not depend on w within the same sample (it
    /// comes from the drive waveform, one sample behind the controller).
    fn direct_feedthrough(&self) -> bool {
        true
    }
    fn build(&mut self, ctx: &BuildContext) -> Result<(), ParamError> {
        self.prepare(ctx.dt)
    }
    fn planned_bytes(&self, _dt: f64) -> (&'static str, usize) {
        (
            "n_max",
            MemoryLoop::planned_bytes(self.n_max, 0, 1, &self.learning, &self.robustness)
                .saturating_add(self.n_max.saturating_add(1).saturating_mul(8)),
        )
    }
    fn memory_bytes(&self) -> usize {
        self.core.as_ref().map_or(0, |(m, _)| {
            m.memory_bytes() + (self.n_max + 1) * std::mem::size_of::<f64>()
        })
    }
    fn output(&mut self, _tick: Tick, u: &[f64], y: &mut [f64]) {
        let (w, n) = self.step(u[0], u[1]);
        y[0] = w;
        y[1] = n as f64;
    }
    fn learning(&self) -> Option<nanomotion_core::gate::LearningModel> {
        let (m, _) = self.core.as_ref()?;
        learning_of(m, self.n_min, self.n_max, None)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn unbuilt_blocks_output_zero_and_do_not_panic() {
        let mut rc = RepetitiveControl::new(8, FilterSpec::Identity, FilterSpec::Identity);
        assert_eq!(rc.step(1.0), 0.0);
        let mut ho = HighOrderRc::new(8, FilterSpec::Identity, FilterSpec::Identity);
        assert_eq!(ho.step(1.0), 0.0);
        let mut dv = Dvrc::new(1.0, 4, 12, FilterSpec::Identity, FilterSpec::Identity);
        assert_eq!(dv.step(1.0, 0.0), (0.0, 12));
        let mut dv = dv.with_n_init(6);
        assert_eq!(dv.step(1.0, 0.0), (0.0, 6));
    }

    /// `period_alpha` > 0 and `n_min` ≥ 1 are declared on the fields: both
    /// `build_dt` and the schema use the declaration.
    #[test]
    fn dvrc_bounds_are_declared_on_the_fields() {
        let dvrc = |p: f64, n_min: usize| {
            Dvrc::new(p, n_min, 12, FilterSpec::Identity, FilterSpec::Identity)
        };
        for (p, n_min, field) in [
            (0.0, 4, "period_alpha"),
            (-1.0, 4, "period_alpha"),
            (f64::NAN, 4, "period_alpha"),
            (1.0, 0, "n_min"),
        ] {
            let e = dvrc(p, n_min).build_dt(1e-3).unwrap_err();
            assert_eq!(e.field, field, "{e}");
        }
        dvrc(1.0, 4).build_dt(1e-3).unwrap();
        let docs = Dvrc::param_docs();
        assert_eq!(docs[0].name, "period_alpha");
        assert_eq!(docs[0].schema["exclusiveMinimum"], 0);
        assert_eq!(docs[0].default.as_deref(), Some("2π"));
        assert_eq!(docs[1].name, "n_min");
        assert_eq!(docs[1].schema["minimum"], 1);
    }
}
