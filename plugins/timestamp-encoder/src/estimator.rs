//! `timestamp_estimator`: position, velocity and acceleration at the sample instant
//! from the encoder's event register, by the least-squares polynomial (8.1)–(8.4).
//!
//! At each sample t_c the valid register events (t_i, x_i) — optionally corrected by
//! a slit calibration table, x_i + ê[x_i mod len] (see the `hots` crate) — are fitted
//! by a polynomial of order m ([`crate::fit`]) and the polynomial and its first two
//! derivatives are evaluated at t_c. Outputs are in input units: x̂ = Δ·x̂_counts.
//!
//! **Fallback (Sec. 8.3), `fallback: thesis` (default).** The count c says the true
//! position lies in the cell [c, c + 1) counts, so the count's own estimate — the
//! thesis's quantized measurement x(t), with our half-count convention — is the cell
//! centre c + ½. If the extrapolated position leaves the band |x̂ − (c + ½)| ≤
//! `band_counts` (default 1 count, the thesis's rule), only the *position* is
//! replaced by the cell centre; the velocity and acceleration stay those of the fit
//! (status 1), as in the thesis's x̂′(t). If the fit itself fails (no finite
//! solution) the output is the cell centre with zero derivatives (status 1).
//!
//! **`fallback: zero_standstill`** (the rule this crate used before issue 18; not the
//! thesis's). Out of band: the cell centre *and* v̂ = â = 0. Standstill: if the newest
//! event is older than both `standstill_timeout_s` (default 10 ms, as the public
//! phobos `encoderhots` waits 10 ms before inserting a pseudo-event) and twice the
//! window's mean time per count (T / max(|x_1 − x_n|, 1)), the output is the cell
//! centre with zero velocity and acceleration (status 3). The second condition keeps
//! a slow but steady motion (events further apart than the timeout) from being
//! declared standstill. `standstill_timeout_s` is only used by this rule.
//!
//! **`fallback: pseudo_event`** (the public phobos `encoderhots` rule, SPEC §5). Out
//! of band as `thesis`. No standstill rule; instead, if the newest event is older than
//! `standstill_timeout_s` (default 10 ms; 0 disables), the fit is made through a
//! pseudo-event (t_c, x_1) — "now, at the newest event's position": no edge has been
//! crossed since, so the position is still that edge's — put in front of the
//! register, whose oldest event drops out (the register keeps n events; fewer if it
//! is not yet full). The pseudo-event is not stored: the next read builds it again
//! from the register it gets. A motion that has stopped thus drives v̂ and â toward 0
//! through the fit rather than by a switch (status 4 when the fit stays in band).
//!
//! With no event at all, under any rule: the cell centre, zero derivatives
//! (status 2).
//!
//! **Reversals.** Events keep their edge level whichever the direction, so a window
//! spanning a reversal holds a turning trajectory; an order m ≥ 2 follows it, m = 1
//! cannot (its error near the turn is of the order of the window's curvature). The
//! event rate drops near the turn, so the window grows and the truncation error with
//! it; the band catches what the fit cannot follow.
//!
//! Output `y` = [x̂, ẋ̂, ẍ̂] (units, units/s, units/s²); output `status` as above
//! (0 = fitted).

use crate::fit::{MAX_M, MAX_N, fit_events};
use nanomotion_core::Params;
use nanomotion_core::{Block, BuildContext, Estimator, ParamError, Port, Tick, declared_block};
use serde::{Deserialize, Serialize};

fn d_m() -> usize {
    2
}
fn d_n() -> usize {
    crate::encoder::DEFAULT_REGISTER_LEN
}
fn d_band() -> f64 {
    1.0
}
fn d_timeout() -> f64 {
    0.01
}

/// What the estimator does when the fit leaves the ±band around the count (Sec. 8.3).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize, Params)]
#[serde(rename_all = "snake_case")]
pub enum Fallback {
    /// The thesis's rule: the position is replaced by the count (cell centre),
    /// velocity and acceleration stay those of the fit. No standstill rule.
    #[default]
    Thesis,
    /// Position → cell centre and v̂ = â = 0 out of band, plus the standstill rule
    /// (no event for `standstill_timeout_s` and twice the window's time per count).
    ZeroStandstill,
    /// As `Thesis` out of band; after `standstill_timeout_s` without an event the
    /// fit includes a pseudo-event (now, newest event's position) in place of the
    /// oldest event (the public phobos `encoderhots` rule).
    PseudoEvent,
}

/// Why an estimate is what it is (the `status` output).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Status {
    /// The polynomial fit, within the band.
    Fitted = 0,
    /// The fit left the ±band around the count: cell centre; derivatives from the
    /// fit ([`Fallback::Thesis`]) or zero ([`Fallback::ZeroStandstill`]).
    OutOfBand = 1,
    /// No event yet: cell centre, zero derivatives.
    NoEvents = 2,
    /// No event for longer than the standstill timeout: cell centre, zeros
    /// ([`Fallback::ZeroStandstill`] only).
    Standstill = 3,
    /// Fitted through a pseudo-event (no event for the timeout), within the band
    /// ([`Fallback::PseudoEvent`] only).
    PseudoEvent = 4,
}

/// `timestamp_estimator`: time-stamping estimator (8.1)-(8.4): LS polynomial of order m
/// through the register's events, scaled time, extrapolated to the sample for x, v, a;
/// fallback outside ±band: thesis (x → count, v/a kept), zero_standstill (x → count, v
/// = a = 0, 10 ms standstill) or pseudo_event (thesis, plus a pseudo-event (now, newest
/// position) in the fit after 10 ms without an event).
///
/// The time-stamping estimator (8.1)–(8.4). Plain Rust:
///
/// ```
/// use timestamp_encoder::{TimestampEncoder, TimestampEstimator};
/// use nanomotion_core::{Estimator, Sensor};
/// let mut enc = TimestampEncoder::default();
/// enc.prepare(1).unwrap();
/// let mut est = TimestampEstimator::new(2, 5, enc.resolution()).unwrap();
/// let (mut reg, mut y) = (vec![0.0; enc.register_width()], [0.0; 3]);
/// for k in 0..=200 {
///     let t = k as f64 * 1e-3;
///     enc.measure(t, &[50.0 * t * t, 100.0 * t], &mut reg); // 100 rad/s², from rest
///     est.estimate(t, &reg, &mut y);
/// }
/// // At t = 0.2 s: x = 2 rad, v = 20 rad/s, a = 100 rad/s².
/// assert!((y[0] - 2.0).abs() < 1e-4 && (y[1] - 20.0).abs() < 0.01 && (y[2] - 100.0).abs() < 5.0, "{y:?}");
/// ```
#[derive(Debug, Clone, Serialize, Deserialize, Params)]
#[serde(deny_unknown_fields)]
#[block(type_name = "timestamp_estimator", role = Estimator, ports = "register[2+2n] -> y[3] = [x, v, a] (units, /s, /s²), status (0 fit, 1 out of band, 2 no events, 3 standstill, 4 fit through a pseudo-event)")]
pub struct TimestampEstimator {
    /// Polynomial order m (8.1), 0..=4, default 2.
    #[serde(default = "d_m")]
    #[param(size(0, MAX_M))]
    pub order: usize,
    /// Register length n (events) of the encoder feeding it, default 5; n > m.
    #[serde(default = "d_n")]
    #[param(size(1, MAX_N))]
    pub register_len: usize,
    /// Resolution Δ: units per count (2π/400 rad for the 100-line encoder).
    #[param(positive)]
    pub resolution: f64,
    /// Fallback band around the cell centre (counts), default 1 (Sec. 8.3).
    #[serde(default = "d_band")]
    #[param(positive)]
    pub band_counts: f64,
    /// What happens out of band: `thesis` (default), `zero_standstill` or
    /// `pseudo_event`.
    /// `thesis` (Sec. 8.3: position → count, v/a from the fit), `zero_standstill` (also v =
    /// a = 0, plus standstill) or `pseudo_event` (thesis, plus a pseudo-event (now, newest
    /// position) in the fit after the timeout).
    #[serde(default)]
    #[param(default_doc = "thesis")]
    pub fallback: Fallback,
    /// Minimum age of the newest event for standstill (s), default 0.01; 0
    /// disables. Used by `fallback: zero_standstill` and `pseudo_event` only (see
    /// the module documentation for the full rules).
    #[serde(default = "d_timeout")]
    #[param(non_negative)]
    pub standstill_timeout_s: f64,
    /// Slit calibration ê (counts) per edge, indexed by level mod its length
    /// (normally 4N); added to each event before the fit. Default none.
    #[serde(default)]
    #[param(finite)]
    pub edge_offsets_counts: Vec<f64>,
    #[serde(skip)]
    status: Option<Status>,
}

impl TimestampEstimator {
    /// An estimator of order `m` for a register of `n` events with resolution
    /// `resolution` (units per count), other parameters at their defaults.
    pub fn new(m: usize, n: usize, resolution: f64) -> Result<Self, ParamError> {
        let e = Self {
            order: m,
            register_len: n,
            resolution,
            band_counts: d_band(),
            fallback: Fallback::Thesis,
            standstill_timeout_s: d_timeout(),
            edge_offsets_counts: Vec::new(),
            status: None,
        };
        e.validate()?;
        Ok(e)
    }

    /// Check the parameters.
    pub fn validate(&self) -> Result<(), ParamError> {
        self.check_params()?;
        if self.register_len <= self.order {
            return Err(ParamError::new(
                "register_len",
                format!(
                    "n = {} ≤ m = {}: a least-squares fit needs n > m (8.4)",
                    self.register_len, self.order
                ),
                format!("give register_len ≥ {} or a lower order", self.order + 1),
            ));
        }
        Ok(())
    }

    /// Width of the `register` input: 2 + 2n.
    pub fn register_width(&self) -> usize {
        2 + 2 * self.register_len
    }

    /// The status of the last estimate.
    pub fn status(&self) -> Option<Status> {
        self.status
    }

    /// Estimate [x̂, ẋ̂, ẍ̂] (units) at `t_c` from a register
    /// `[c, n_valid, t_1, x_1, …]`; returns the status.
    pub fn estimate_from_register(&mut self, t_c: f64, reg: &[f64], out: &mut [f64]) -> Status {
        let c = reg[0];
        let n_valid = (reg[1].max(0.0) as usize)
            .min(self.register_len)
            .min((reg.len() - 2) / 2);
        let centre = c + 0.5;
        let mut ts = [0.0; MAX_N];
        let mut xs = [0.0; MAX_N];
        let len = self.edge_offsets_counts.len() as i64;
        for i in 0..n_valid {
            ts[i] = reg[2 + 2 * i];
            let x = reg[3 + 2 * i];
            xs[i] = if len > 0 {
                x + self.edge_offsets_counts[(x as i64).rem_euclid(len) as usize]
            } else {
                x
            };
        }
        let d = self.resolution;
        let zero = self.fallback == Fallback::ZeroStandstill;
        // Pseudo-event (t_c, x_1) in front of the register, the oldest dropped.
        let mut n_valid = n_valid;
        let pseudo = self.fallback == Fallback::PseudoEvent
            && n_valid > 0
            && self.standstill_timeout_s > 0.0
            && t_c - ts[0] > self.standstill_timeout_s;
        if pseudo {
            let kept = n_valid.min(self.register_len - 1);
            ts.copy_within(0..kept, 1);
            xs.copy_within(0..kept, 1);
            ts[0] = t_c;
            n_valid = kept + 1;
        }
        let status = if n_valid == 0 {
            Status::NoEvents
        } else if zero
            && self.standstill_timeout_s > 0.0
            && t_c - ts[0] > self.standstill_timeout_s
            && {
                let span = ts[0] - ts[n_valid - 1];
                let counts = (xs[0] - xs[n_valid - 1]).abs().max(1.0);
                t_c - ts[0] > 2.0 * span / counts
            }
        {
            Status::Standstill
        } else {
            match fit_events(&ts[..n_valid], &xs[..n_valid], self.order, t_c) {
                Some(f) if f.x.is_finite() && f.v.is_finite() && f.a.is_finite() => {
                    // x̂′ (Sec. 8.3): the fit if within ±band of the count, else the count.
                    let in_band = (f.x - centre).abs() <= self.band_counts;
                    out[0] = if in_band { f.x } else { centre } * d;
                    if in_band || !zero {
                        out[1] = f.v * d;
                        out[2] = f.a * d;
                        if in_band && pseudo {
                            Status::PseudoEvent
                        } else if in_band {
                            Status::Fitted
                        } else {
                            Status::OutOfBand
                        }
                    } else {
                        out[1] = 0.0;
                        out[2] = 0.0;
                        Status::OutOfBand
                    }
                }
                _ => {
                    out[..3].copy_from_slice(&[centre * d, 0.0, 0.0]);
                    Status::OutOfBand
                }
            }
        };
        if matches!(status, Status::NoEvents | Status::Standstill) {
            out[0] = centre * d;
            out[1] = 0.0;
            out[2] = 0.0;
        }
        self.status = Some(status);
        status
    }
}

impl Estimator for TimestampEstimator {
    /// `measurement` = the register, `estimate` = [x̂, ẋ̂, ẍ̂].
    fn estimate(&mut self, t: f64, measurement: &[f64], estimate: &mut [f64]) {
        self.estimate_from_register(t, measurement, estimate);
    }
}

#[declared_block]
impl Block for TimestampEstimator {
    fn inputs(&self) -> Vec<Port> {
        vec![Port::new("register", self.register_width())]
    }
    fn outputs(&self) -> Vec<Port> {
        vec![Port::new("y", 3), Port::new("status", 1)]
    }
    fn build(&mut self, _ctx: &BuildContext) -> Result<(), ParamError> {
        self.validate()?;
        self.status = None;
        Ok(())
    }
    fn output(&mut self, tick: Tick, u: &[f64], y: &mut [f64]) {
        let s = self.estimate_from_register(tick.t, u, &mut y[..3]);
        y[3] = s as u8 as f64;
    }
}
