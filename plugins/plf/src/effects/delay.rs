//! `time_delay`: y(t) = u(t − τ) with fractional delays.

use super::check_len;
use nanomotion_core::Params;
use nanomotion_core::block::check;
use nanomotion_core::blocks::linear::MAX_DENSE_DELAY_STATES;
use nanomotion_core::lti::StateSpace;
use nanomotion_core::nalgebra::DMatrix;
use nanomotion_core::{Block, BuildContext, ParamError, Tick, Tunable, declared_block};
use serde::{Deserialize, Serialize};

/// Largest delay buffer (samples) a `time_delay` may allocate.
pub const MAX_DELAY_SAMPLES: f64 = 1e6;

/// The shortest delay a sampled record shows as a delay, in periods of the
/// record: half a sample. That much is the phase lag ωT/2 of the
/// zero-order hold itself, and how a model reads and holds its samples
/// (when within the period a value is taken, how the drive is held) moves
/// its response by as much; a shorter fitted delay is a phase correction of
/// the model's form or sampling, not evidence of a transport delay.
pub const MIN_RESOLVED_DELAY_SAMPLES: f64 = 0.5;

/// `time_delay`: PLF effect: y(t) = u(t − delay_s), fractional delays by linear
/// interpolation, samples before the start = first input; tunable `delay_s`.
///
/// Y(t) = u(t − τ), τ = `delay_s`. With τ/dt = n + f (n integer,
/// 0 ≤ f < 1) the output is the linear interpolation (1 − f)·u_{k−n} + f·u_{k−n−1}
/// (exact for integer delays and for ramps). The samples before the start are the
/// first input. The buffer holds `max_delay_s` (fixed when built, at most
/// [`MAX_DELAY_SAMPLES`] samples), so τ can be refitted in [0, max_delay_s] without
/// reallocating. Direct feed-through (τ may be below one sample).
///
/// [`Tunable`] vector: `[delay_s]`.
#[derive(Debug, Clone, Serialize, Deserialize, Params)]
#[serde(deny_unknown_fields)]
#[block(type_name = "time_delay", role = Math, ports = "u -> y")]
pub struct TimeDelay {
    /// Delay τ (s), 0 ≤ τ ≤ `max_delay_s`.
    pub delay_s: f64,
    /// Longest delay the buffer holds (s), ≥ 0.
    /// Fixed when built; at most 10⁶ samples.
    pub max_delay_s: f64,
    #[serde(skip)]
    buf: Vec<f64>,
    #[serde(skip)]
    pos: usize,
    #[serde(skip)]
    n: usize,
    #[serde(skip)]
    frac: f64,
    #[serde(skip)]
    started: bool,
    /// The period it was built for (s); 0 before `build`.
    #[serde(skip)]
    dt: f64,
}

impl TimeDelay {
    /// A delay of `delay_s` with room for `max_delay_s`.
    pub fn new(delay_s: f64, max_delay_s: f64) -> Self {
        Self {
            delay_s,
            max_delay_s,
            buf: Vec::new(),
            pos: 0,
            n: 0,
            frac: 0.0,
            started: false,
            dt: 0.0,
        }
    }

    fn check_delay(delay_s: f64, max_delay_s: f64) -> Result<(), ParamError> {
        check::non_negative("max_delay_s", max_delay_s)?;
        check::in_range("delay_s", delay_s, 0.0, max_delay_s)
    }

    /// The ring buffer's length for `max_delay_s` at period `dt`:
    /// ⌈max_delay_s/dt⌉ + 2 samples, or `Err` naming `max_delay_s` when that is
    /// more than [`MAX_DELAY_SAMPLES`]. [`Block::build`] allocates it and
    /// [`Block::planned_bytes`] declares it (one formula).
    fn buffer_len(max_delay_s: f64, dt: f64) -> Result<usize, ParamError> {
        let samples = (max_delay_s / dt).ceil();
        if samples.is_nan() || samples > MAX_DELAY_SAMPLES {
            return Err(ParamError::new(
                "max_delay_s",
                format!(
                    "{max_delay_s} s is {samples:e} samples at dt = {dt} s, more than the {MAX_DELAY_SAMPLES:e} allowed"
                ),
                "give a shorter max_delay_s or run the block at a lower rate",
            ));
        }
        Ok(samples.max(0.0) as usize + 2)
    }

    /// τ/dt split into whole samples and a fraction; values within 1e-9 of an
    /// integer count as that integer (so 3·dt is exactly 3 samples).
    fn split(delay_s: f64, dt: f64) -> (usize, f64) {
        let x = delay_s / dt;
        let r = x.round();
        if (x - r).abs() <= 1e-9 * r.max(1.0) {
            (r as usize, 0.0)
        } else {
            let n = x.floor();
            (n as usize, x - n)
        }
    }

    /// Why this delay is not a transport delay a record sampled every `dt_s`
    /// shows, or `None`: shorter than [`MIN_RESOLVED_DELAY_SAMPLES`] periods.
    pub fn implausible(&self, dt_s: f64) -> Option<String> {
        let samples = self.delay_s / dt_s;
        (samples < MIN_RESOLVED_DELAY_SAMPLES).then(|| {
            format!(
                "a delay of {samples:.2} samples is less than the {MIN_RESOLVED_DELAY_SAMPLES} sample by which the model's sampling and hold alone move its response: a phase correction, not a transport delay"
            )
        })
    }
}

#[declared_block]
impl Block for TimeDelay {
    fn build(&mut self, ctx: &BuildContext) -> Result<(), ParamError> {
        Self::check_delay(self.delay_s, self.max_delay_s)?;
        check::positive("dt", ctx.dt)?;
        let len = Self::buffer_len(self.max_delay_s, ctx.dt)?;
        let (n, frac) = Self::split(self.delay_s, ctx.dt);
        if n + 1 >= len {
            return Err(ParamError::new(
                "delay_s",
                "does not fit the buffer of max_delay_s",
                "give delay_s ≤ max_delay_s",
            ));
        }
        self.buf.clear();
        self.buf.resize(len, 0.0);
        self.pos = 0;
        self.n = n;
        self.frac = frac;
        self.started = false;
        self.dt = ctx.dt;
        Ok(())
    }
    /// The exact model of [`Block::output`]: y_k = (1 − f)·u_{k−n} + f·u_{k−n−1}
    /// (τ = (n + f)·dt), a shift register of the last n (+1 if f > 0) inputs,
    /// up to [`MAX_DENSE_DELAY_STATES`] states like the core's `delay` (a
    /// longer delay has none: its loop stays unproven).
    fn lti(&self) -> Option<StateSpace> {
        let states = self.n + usize::from(self.frac > 0.0);
        if self.dt <= 0.0 || states > MAX_DENSE_DELAY_STATES {
            return None;
        }
        // x_j = u_{k−j}, j = 1..=states; coefficient of u_{k−j} in y: taps[j].
        let mut taps = vec![0.0; states + 1];
        taps[self.n] += 1.0 - self.frac;
        if self.frac > 0.0 {
            taps[self.n + 1] += self.frac;
        }
        let a = DMatrix::from_fn(states, states, |i, j| if i == j + 1 { 1.0 } else { 0.0 });
        let b = DMatrix::from_fn(states, 1, |i, _| if i == 0 { 1.0 } else { 0.0 });
        let c = DMatrix::from_fn(1, states, |_, j| taps[j + 1]);
        let d = DMatrix::from_element(1, 1, taps[0]);
        StateSpace::new(a, b, c, d, Some(self.dt)).ok()
    }
    fn planned_bytes(&self, dt: f64) -> (&'static str, usize) {
        // Out of range: left to `build`'s message.
        let len = Self::buffer_len(self.max_delay_s, dt).unwrap_or(0);
        ("max_delay_s", len * std::mem::size_of::<f64>())
    }
    fn memory_bytes(&self) -> usize {
        self.buf.len() * std::mem::size_of::<f64>()
    }
    fn output(&mut self, _tick: Tick, u: &[f64], y: &mut [f64]) {
        let len = self.buf.len();
        if len == 0 {
            y[0] = 0.0;
            return;
        }
        if !self.started {
            self.buf.iter_mut().for_each(|b| *b = u[0]);
            self.started = true;
        }
        self.pos = (self.pos + 1) % len;
        self.buf[self.pos] = u[0];
        let i0 = (self.pos + len - self.n) % len;
        let a = self.buf[i0];
        y[0] = if self.frac == 0.0 {
            a
        } else {
            let b = self.buf[(i0 + len - 1) % len];
            a + self.frac * (b - a)
        };
    }
    fn tunable(&self) -> Option<&dyn Tunable> {
        Some(self)
    }
    fn tunable_mut(&mut self) -> Option<&mut dyn Tunable> {
        Some(self)
    }
}

impl Tunable for TimeDelay {
    fn param_names(&self) -> Vec<String> {
        vec!["delay_s".into()]
    }
    fn params(&self) -> Vec<f64> {
        vec![self.delay_s]
    }
    fn set_params(&mut self, p: &[f64]) -> Result<(), ParamError> {
        check_len(p, 1, "[delay_s]")?;
        Self::check_delay(p[0], self.max_delay_s)?;
        self.delay_s = p[0];
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Refused below half a period of the record, kept from there on, at
    /// any sample rate.
    #[test]
    fn a_delay_is_resolved_from_half_a_sample() {
        for dt in [1e-4, 2e-3] {
            let delay = |samples: f64| TimeDelay::new(samples * dt, 10.0 * dt);
            let short = delay(0.49).implausible(dt).expect("0.49 samples refused");
            assert!(short.contains("0.49 samples"), "{short}");
            assert_eq!(delay(MIN_RESOLVED_DELAY_SAMPLES).implausible(dt), None);
            assert_eq!(delay(0.71).implausible(dt), None);
        }
    }
}
