//! `creep`: piezo creep as a sum of first-order lags.

use super::{MAX_MAGNITUDE, check_bounded, check_len};
use nanomotion_core::Params;
use nanomotion_core::block::check;
use nanomotion_core::lti::StateSpace;
use nanomotion_core::nalgebra::DMatrix;
use nanomotion_core::{Block, BuildContext, ParamError, Tick, Tunable, declared_block};
use serde::{Deserialize, Serialize};

/// Most terms a `creep` block may have.
pub const MAX_TERMS: usize = 4;

/// One first-order term of [`Creep`].
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize, Params)]
#[serde(deny_unknown_fields)]
pub struct CreepTerm {
    /// Gain k_i (\[y\]/\[u\]).
    pub gain: f64,
    /// Time constant τ_i (s) > 0.
    pub tau_s: f64,
}

/// `creep`: PLF effect: piezo creep y = u + Σ k_i/(τ_i s + 1)·u (ZOH-exact, 1–4 terms;
/// a sum-of-exponentials approximation of the logarithmic creep); tunable [gain_1,
/// tau_1, ...].
///
/// ```text
/// y = u + Σ_i k_i·L_i(u),    L_i(s) = 1/(τ_i s + 1)
/// ```
///
/// with each L_i discretised exactly for a held input (ZOH):
/// x_{k+1} = e^{−dt/τ}x_k + (1 − e^{−dt/τ})u_k, L_i = x. The response to a step
/// of height A is A·(1 + Σ k_i(1 − e^{−t/τ_i})): a linear, sum-of-exponentials
/// approximation of piezo creep, whose measured step response grows with the
/// logarithm of time (time constants spread over decades approximate a log).
/// 1 to [`MAX_TERMS`] terms. The lags start at rest for a zero drive (x = 0), as
/// a `state_space` plant starts at zero state: a record whose drive begins at
/// u₀ ≠ 0 is a step to u₀ for the creep as for the plant. (Started at rest at
/// u₀ instead, a slow lag holds k·u₀ for the whole record — an offset the plant
/// never sees; on closed-loop records whose first drive is a spike this hid the
/// creep from every fit: tuning 66, 717, 1743, 2304 named nothing or another
/// effect.)
///
/// [`Tunable`] vector: `[gain_1, tau_1, gain_2, tau_2, ...]` (YAML
/// `terms[i].gain`, `terms[i].tau_s`).
#[derive(Debug, Clone, Serialize, Deserialize, Params)]
#[serde(deny_unknown_fields)]
#[block(type_name = "creep", role = Actuator, ports = "u -> y")]
pub struct Creep {
    /// The terms {gain, tau_s}.
    /// [{gain: k_i (unit of y per unit of u), tau_s: τ_i (s) > 0}].
    #[param(len(1, MAX_TERMS))]
    pub terms: Vec<CreepTerm>,
    #[serde(skip)]
    a: [f64; MAX_TERMS],
    #[serde(skip)]
    x: [f64; MAX_TERMS],
    /// The period it was built for (s); 0 before `build`.
    #[serde(skip)]
    dt: f64,
}

impl Creep {
    /// Creep with the given terms.
    pub fn new(terms: Vec<CreepTerm>) -> Self {
        Self {
            terms,
            a: [0.0; MAX_TERMS],
            x: [0.0; MAX_TERMS],
            dt: 0.0,
        }
    }

    /// Why these fitted terms are not creep as a diagnosis of a record `t_len_s`
    /// long sampled every `dt_s`, or `None`. Creep is the slow growth of a
    /// response after a change of the drive:
    /// - every time constant between one sample and the record's length (a lag
    ///   slower than the record is a ramp — a drift in disguise; one faster than
    ///   a sample is a gain);
    /// - a total creep Σ kᵢ in (0, 1]: the response grows, by at most as much
    ///   again (measured piezo creep is a few to 30 % per decade); a response that
    ///   shrinks is a relaxation or a low-frequency gain error;
    /// - a step response that never falls over the record:
    ///   Σ kᵢ/τᵢ·e^{−t/τᵢ} ≥ 0.
    pub fn implausible(&self, t_len_s: f64, dt_s: f64) -> Option<String> {
        let (lo, hi) = Self::time_constants(t_len_s, dt_s);
        for (i, t) in self.terms.iter().enumerate() {
            if !(t.tau_s >= lo && t.tau_s <= hi) {
                return Some(format!(
                    "terms[{i}].tau_s = {:.3e} s lies outside one sample to the record's length ({lo:.3e}–{hi:.3e} s)",
                    t.tau_s
                ));
            }
        }
        let total: f64 = self.terms.iter().map(|t| t.gain).sum();
        if !(total > 0.0 && total <= 1.0) {
            return Some(format!(
                "the total creep Σ k = {total:.3e} is not a growth of the response by 0–100 %"
            ));
        }
        let rate = |t: f64| -> f64 {
            self.terms
                .iter()
                .map(|c| c.gain / c.tau_s * (-t / c.tau_s).exp())
                .sum()
        };
        let scale = self
            .terms
            .iter()
            .map(|c| (c.gain / c.tau_s).abs())
            .fold(0.0, f64::max);
        let grid = 200;
        (0..=grid)
            .map(|k| dt_s * (t_len_s / dt_s).powf(k as f64 / grid as f64))
            .find(|&t| rate(t) < -1e-9 * scale)
            .map(|t| format!("the step response falls at t = {t:.3e} s: a relaxation, not creep"))
    }

    /// The time constants a creep can be told by in a record `t_len_s` long
    /// sampled every `dt_s`: one sample to the record's length (see
    /// [`Creep::implausible`]).
    pub fn time_constants(t_len_s: f64, dt_s: f64) -> (f64, f64) {
        (dt_s, t_len_s)
    }

    /// Each term's gain and time constant (their count is declared).
    fn check_terms(terms: &[CreepTerm]) -> Result<(), ParamError> {
        for (i, t) in terms.iter().enumerate() {
            check_bounded(&format!("terms[{i}].gain"), t.gain, MAX_MAGNITUDE)?;
            check::positive(&format!("terms[{i}].tau_s"), t.tau_s)?;
        }
        Ok(())
    }
}

#[declared_block]
impl Block for Creep {
    fn build(&mut self, ctx: &BuildContext) -> Result<(), ParamError> {
        self.check_params()?;
        Self::check_terms(&self.terms)?;
        check::positive("dt", ctx.dt)?;
        self.a = [0.0; MAX_TERMS];
        for (a, t) in self.a.iter_mut().zip(&self.terms) {
            *a = (-ctx.dt / t.tau_s).exp();
        }
        self.x = [0.0; MAX_TERMS];
        self.dt = ctx.dt;
        Ok(())
    }
    fn output(&mut self, _tick: Tick, u: &[f64], y: &mut [f64]) {
        let x = u[0];
        let n = self.terms.len().min(MAX_TERMS);
        let mut out = x;
        for i in 0..n {
            out += self.terms[i].gain * self.x[i];
            let a = self.a[i];
            self.x[i] = a * self.x[i] + (1.0 - a) * x;
        }
        y[0] = out;
    }
    /// The exact discrete model of [`Block::output`] (what the stability gate
    /// analyses): x⁺ = diag(a_i)x + (1 − a_i)u, y = Σ k_i x_i + u, from x = 0.
    fn lti(&self) -> Option<StateSpace> {
        if self.dt <= 0.0 {
            return None;
        }
        let n = self.terms.len().min(MAX_TERMS);
        let a = DMatrix::from_fn(n, n, |i, j| if i == j { self.a[i] } else { 0.0 });
        let b = DMatrix::from_fn(n, 1, |i, _| 1.0 - self.a[i]);
        let c = DMatrix::from_fn(1, n, |_, j| self.terms[j].gain);
        StateSpace::new(a, b, c, DMatrix::from_element(1, 1, 1.0), Some(self.dt)).ok()
    }
    fn tunable(&self) -> Option<&dyn Tunable> {
        Some(self)
    }
    fn tunable_mut(&mut self) -> Option<&mut dyn Tunable> {
        Some(self)
    }
}

impl Tunable for Creep {
    fn param_names(&self) -> Vec<String> {
        (0..self.terms.len())
            .flat_map(|i| [format!("terms[{i}].gain"), format!("terms[{i}].tau_s")])
            .collect()
    }
    fn params(&self) -> Vec<f64> {
        self.terms.iter().flat_map(|t| [t.gain, t.tau_s]).collect()
    }
    fn set_params(&mut self, p: &[f64]) -> Result<(), ParamError> {
        check_len(
            p,
            2 * self.terms.len(),
            "[gain_1, tau_1, gain_2, tau_2, ...]",
        )?;
        let next: Vec<CreepTerm> = p
            .chunks_exact(2)
            .map(|c| CreepTerm {
                gain: c[0],
                tau_s: c[1],
            })
            .collect();
        Self::check_terms(&next)?;
        self.terms = next;
        Ok(())
    }
}
