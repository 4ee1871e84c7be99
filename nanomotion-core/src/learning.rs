//! Learning blocks in loops: the convergence criteria of repetitive control
//! (thesis Sec. 5.2.1, 5.3.2), evaluated from the T of the loop the block sits in.
//!
//! A learning block (standard RC, high-order RC, DVRC) adds w = memory(e) to the
//! loop. With w removed, the rest of the loop gives T(z) = −(transfer from w to
//! e) — for Fig. 5.1, u = K(e + w), e = −y: T = PK/(1 + PK). The memory loop then
//! sees (Fig. 5.2, (5.10a))
//!
//! H(z) = Q(z)·(z^{−l} − T(z)·L_c(z)),   L_c = z^{−l}·L the causal learning filter,
//!
//! and the criteria are: the loop without learning is stable (condition (a)) and
//!
//! - (5.5), fixed delay N: ‖H‖∞ < 1;
//! - (5.9), delay N_k ∈ \[m, M\] (DVRC, Corollary 7): ‖H‖∞ < 1/√(M − m + 1);
//! - high-order RC with weights w_i: ‖H‖∞·Σ|w_i| < 1 (small gain; W(z) has
//!   ‖W‖∞ = Σ|w_i|).
//!
//! All are sufficient conditions, evaluated with the exact [`hinfnorm`].

use crate::lti::{LtiError, StateSpace, delay, hinfnorm, parallel, series};
use std::fmt;

/// What a learning block exposes to the gate ([`crate::Block::learning`]).
#[derive(Debug, Clone, PartialEq)]
pub struct LearningModel {
    /// The causal learning filter L_c = z^{−l}·L as it is run (discrete, SISO).
    pub l_causal: StateSpace,
    /// Its preview l (samples) compensated by the memory.
    pub preview: usize,
    /// The robustness filter Q as it is run (with its delay).
    pub q: StateSpace,
    /// Smallest memory delay m (samples); N for a fixed delay.
    pub n_min: usize,
    /// Largest memory delay M (samples); N for a fixed delay.
    pub n_max: usize,
    /// High-order RC: Σ|w_i| of the weights.
    pub weight_sum: Option<f64>,
    /// Index of the input port carrying the error e.
    pub error_input: usize,
    /// Index of the output port carrying the learning output w.
    pub output: usize,
}

/// H(z) = Q(z)(z^{−l} − T(z) L_c(z)) (Fig. 5.2): the map the memory delay sees.
pub fn loop_h(
    t: &StateSpace,
    l_causal: &StateSpace,
    preview: usize,
    q: &StateSpace,
) -> Result<StateSpace, LtiError> {
    let dt =
        t.dt.ok_or_else(|| LtiError::Domain("T(z) must be discrete".into()))?;
    let tl = series(l_causal, t)?;
    let zl = delay(preview, dt);
    let inner = parallel(&zl, &tl.scaled(-1.0))?;
    series(&inner, q)
}

/// The criterion of one learning block.
#[derive(Debug, Clone, PartialEq)]
pub struct LearningCheck {
    /// The block.
    pub block: String,
    /// ‖Q(z^{−l} − T L_c)‖∞.
    pub hinf: f64,
    /// Where it peaks (Hz).
    pub peak_hz: f64,
    /// The bound on ‖H‖∞: 1 (5.5), 1/√(M − m + 1) (5.9), 1/Σ|w_i| (high order).
    pub bound: f64,
    /// m.
    pub n_min: usize,
    /// M.
    pub n_max: usize,
    /// Σ|w_i| for a high-order RC.
    pub weight_sum: Option<f64>,
    /// The T(z) the criterion used (the loop closed without learning, from the
    /// learning output w to minus the error e): what L is designed from.
    pub t: StateSpace,
    /// ‖Q‖∞: what ‖H‖∞ tends to as the learning gain goes to 0. When it is at or
    /// above the bound, lowering the learning gain cannot satisfy the criterion.
    pub q_hinf: f64,
}

impl LearningCheck {
    /// ‖H‖∞ below the bound.
    pub fn holds(&self) -> bool {
        self.hinf < self.bound
    }
    /// What to change when the criterion fails: with ‖Q‖∞ at or above the bound
    /// lowering the learning gain cannot help (H → Q as L → 0).
    pub fn fix(&self) -> String {
        if self.q_hinf >= self.bound {
            format!(
                "lowering the learning gain cannot help (as it goes to 0, ‖H‖∞ goes to ‖Q‖∞ = {:.4}, at or above the bound): make L a closer inverse of T where |Q| is large, lower the Q cut-off, or narrow [n_min, n_max]",
                self.q_hinf
            )
        } else {
            "lower the learning gain or the Q cut-off, or narrow [n_min, n_max]".to_string()
        }
    }
    /// Which criterion.
    pub fn criterion(&self) -> &'static str {
        if self.weight_sum.is_some() {
            "small gain ‖H‖∞·Σ|w_i| < 1"
        } else if self.n_min == self.n_max {
            "(5.5)"
        } else {
            "(5.9)"
        }
    }
}

impl fmt::Display for LearningCheck {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let range = if self.n_min == self.n_max {
            format!("N = {}", self.n_min)
        } else {
            format!("N ∈ [{}, {}]", self.n_min, self.n_max)
        };
        write!(
            f,
            "learning block `{}`: {} with {range}: ‖Q(z^-l − T L_c)‖∞ = {:.4} at {:.1} Hz, bound {:.4}, margin {:+.2} dB → {}",
            self.block,
            self.criterion(),
            self.hinf,
            self.peak_hz,
            self.bound,
            20.0 * (self.bound / self.hinf).log10(),
            if self.holds() {
                "convergence guaranteed"
            } else {
                "NOT guaranteed"
            }
        )
    }
}

/// Evaluate the criterion of `model` (block `name`) with the loop's `t`, which
/// must be stable (checked by the caller: condition (a)).
pub fn criterion(
    name: &str,
    t: &StateSpace,
    model: &LearningModel,
) -> Result<LearningCheck, LtiError> {
    if model.n_max < model.n_min {
        return Err(LtiError::Parameter {
            name: "n_max",
            problem: format!("{} < n_min = {}", model.n_max, model.n_min),
        });
    }
    let h = loop_h(t, &model.l_causal, model.preview, &model.q)?;
    let r = hinfnorm(&h)?;
    let q_hinf = hinfnorm(&model.q)?.norm;
    let mut bound = 1.0 / ((model.n_max - model.n_min + 1) as f64).sqrt();
    if let Some(ws) = model.weight_sum {
        bound = 1.0 / ws;
    }
    Ok(LearningCheck {
        block: name.to_string(),
        hinf: r.norm,
        peak_hz: r.peak_rad_s / (2.0 * std::f64::consts::PI),
        bound,
        n_min: model.n_min,
        n_max: model.n_max,
        weight_sum: model.weight_sum,
        t: t.clone(),
        q_hinf,
    })
}
