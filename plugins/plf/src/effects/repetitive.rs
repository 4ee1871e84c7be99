//! `repetitive_disturbance`: a Fourier series periodic in time or in a signal.

use super::{MAX_MAGNITUDE, check_bounded, check_len};
use nanomotion_core::Params;
use nanomotion_core::{Block, BuildContext, ParamError, Port, Tick, Tunable, declared_block};
use serde::{Deserialize, Serialize};
use std::f64::consts::TAU;

/// Most harmonics a `repetitive_disturbance` may have.
pub const MAX_HARMONICS: usize = 64;

/// What the disturbance is periodic in.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize, Params)]
#[serde(rename_all = "snake_case")]
pub enum PhaseVariable {
    /// Time: φ = t/period (period in s).
    #[default]
    Time,
    /// The signal on port `s` (usually position): φ = (s − origin)/period (period
    /// in the unit of s).
    Signal,
}

/// `repetitive_disturbance`: PLF effect: y = u + Σ_h (cos_h cos 2πhφ + sin_h sin 2πhφ),
/// φ = t/period or (s − origin)/period; tunable [period, cos.., sin..].
///
/// ```text
/// y = u + Σ_{h=1..H} (cos_h·cos(2πhφ) + sin_h·sin(2πhφ))
/// ```
///
/// with φ = t/period (`variable: time`, the default) or φ = (s − origin)/period
/// (`variable: signal`, reading port `s`): a disturbance repeating every period in
/// time (e.g. a scan frequency, mains) or every period of position (e.g. a
/// drive-rod or grating pitch). 1 ≤ H ≤ [`MAX_HARMONICS`].
///
/// [`Tunable`] vector: `[period, cos[0..H], sin[0..H]]` (cos_1..cos_H, then
/// sin_1..sin_H).
#[derive(Debug, Clone, Serialize, Deserialize, Params)]
#[serde(deny_unknown_fields)]
#[block(type_name = "repetitive_disturbance", role = Source, ports = "u (, s) -> y")]
pub struct RepetitiveDisturbance {
    /// Period (s for `time`, unit of s for `signal`).
    #[param(positive)]
    pub period: f64,
    /// `time` (default) or `signal`.
    #[serde(default)]
    #[param(default_doc = "time")]
    pub variable: PhaseVariable,
    /// Origin of the phase for `signal` (unit of s), default 0.
    #[serde(default)]
    pub origin: f64,
    /// Cosine amplitudes of harmonics 1..H (\[u\]).
    #[param(len(1, MAX_HARMONICS))]
    pub cos: Vec<f64>,
    /// Sine amplitudes of harmonics 1..H (\[u\]).
    #[param(same_len = cos)]
    pub sin: Vec<f64>,
}

impl RepetitiveDisturbance {
    /// A disturbance periodic in time.
    pub fn in_time(period_s: f64, cos: Vec<f64>, sin: Vec<f64>) -> Self {
        Self {
            period: period_s,
            variable: PhaseVariable::Time,
            origin: 0.0,
            cos,
            sin,
        }
    }

    /// A disturbance periodic in the signal on port `s`.
    pub fn in_signal(period: f64, origin: f64, cos: Vec<f64>, sin: Vec<f64>) -> Self {
        Self {
            period,
            variable: PhaseVariable::Signal,
            origin,
            cos,
            sin,
        }
    }

    /// The disturbance at phase φ (in periods).
    pub fn disturbance(&self, phi: f64) -> f64 {
        let f = phi - phi.floor();
        let mut d = 0.0;
        for (h, (c, s)) in self.cos.iter().zip(&self.sin).enumerate() {
            let a = TAU * (h + 1) as f64 * f;
            d += c * a.cos() + s * a.sin();
        }
        d
    }

    fn check_all(&self) -> Result<(), ParamError> {
        // period > 0, 1 to 64 cosine terms and as many sine terms: declared
        self.check_params()?;
        check_bounded("origin", self.origin, MAX_MAGNITUDE)?;
        for (name, v) in [("cos", &self.cos), ("sin", &self.sin)] {
            for (i, x) in v.iter().enumerate() {
                check_bounded(&format!("{name}[{i}]"), *x, MAX_MAGNITUDE)?;
            }
        }
        Ok(())
    }
}

#[declared_block]
impl Block for RepetitiveDisturbance {
    fn inputs(&self) -> Vec<Port> {
        match self.variable {
            PhaseVariable::Time => vec![Port::new("u", 1)],
            PhaseVariable::Signal => vec![Port::new("u", 1), Port::new("s", 1)],
        }
    }
    fn outputs(&self) -> Vec<Port> {
        vec![Port::new("y", 1)]
    }
    fn build(&mut self, _ctx: &BuildContext) -> Result<(), ParamError> {
        self.check_all()
    }
    fn output(&mut self, tick: Tick, u: &[f64], y: &mut [f64]) {
        let phi = match self.variable {
            PhaseVariable::Time => tick.t / self.period,
            PhaseVariable::Signal => (u[1] - self.origin) / self.period,
        };
        y[0] = u[0] + self.disturbance(phi);
    }
    fn tunable(&self) -> Option<&dyn Tunable> {
        Some(self)
    }
    fn tunable_mut(&mut self) -> Option<&mut dyn Tunable> {
        Some(self)
    }
}

impl Tunable for RepetitiveDisturbance {
    fn param_names(&self) -> Vec<String> {
        let mut v = vec!["period".to_string()];
        v.extend((0..self.cos.len()).map(|i| format!("cos[{i}]")));
        v.extend((0..self.sin.len()).map(|i| format!("sin[{i}]")));
        v
    }
    fn params(&self) -> Vec<f64> {
        let mut v = vec![self.period];
        v.extend_from_slice(&self.cos);
        v.extend_from_slice(&self.sin);
        v
    }
    fn set_params(&mut self, p: &[f64]) -> Result<(), ParamError> {
        let h = self.cos.len();
        check_len(p, 1 + 2 * h, "[period, cos[0..H], sin[0..H]]")?;
        let mut next = self.clone();
        next.period = p[0];
        next.cos.copy_from_slice(&p[1..1 + h]);
        next.sin.copy_from_slice(&p[1 + h..]);
        next.check_all()?;
        *self = next;
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn err(d: &mut RepetitiveDisturbance) -> (String, String) {
        let e = d.build(&BuildContext::new("rep", 1e-3, 0)).unwrap_err();
        (e.field, e.problem)
    }

    #[test]
    fn declared_bounds_refuse_bad_harmonics_and_periods_by_name() {
        let mut d = RepetitiveDisturbance::in_time(0.01, vec![1.0, 0.5], vec![0.0]);
        assert_eq!(
            err(&mut d),
            ("sin".into(), "has 1 entry, cos has 2 entries".into())
        );
        let mut d = RepetitiveDisturbance::in_time(0.01, vec![], vec![]);
        assert_eq!(err(&mut d), ("cos".into(), "is empty".into()));
        let n = MAX_HARMONICS + 1;
        let mut d = RepetitiveDisturbance::in_time(0.01, vec![0.0; n], vec![0.0; n]);
        assert_eq!(
            err(&mut d),
            (
                "cos".into(),
                format!("has {n} entries, must have 1 to {MAX_HARMONICS} entries")
            )
        );
        let mut d = RepetitiveDisturbance::in_time(0.01, vec![1.0], vec![0.0]);
        assert!(d.build(&BuildContext::new("rep", 1e-3, 0)).is_ok());
        // a fitter's step to a period ≤ 0 is refused, the block unchanged
        let e = d.set_params(&[-0.01, 1.0, 0.0]).unwrap_err();
        assert_eq!(e.field, "period");
        assert_eq!(d.params(), [0.01, 1.0, 0.0]);
        d.set_params(&[0.02, 2.0, 1.0]).unwrap();
        assert_eq!(d.params(), [0.02, 2.0, 1.0]);
        // the listing says the bounds
        let docs = RepetitiveDisturbance::param_docs();
        let bounds = |n: &str| docs.iter().find(|p| p.name == n).unwrap().bounds.clone();
        assert_eq!(bounds("cos"), ["1 to 64 entries"]);
        assert_eq!(bounds("sin"), ["as many entries as cos"]);
    }
}
