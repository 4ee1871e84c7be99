//! Feedback controllers: `pid` and `pi` (the thesis's PI on the drive frequency
//! f_α, (2.10)). Input `e` (error), output `u` (control action). Both implement
//! [`Controller`].
//!
//! # The discrete PID
//!
//! The continuous controller, with the derivative low-pass filtered at
//! ω_d = 2π·`derivative_cutoff_hz`:
//!
//! C(s) = k_p + k_i/s + k_d·s/(1 + s/ω_d)
//!
//! is discretised term by term at the block's period T, by **Tustin** (default,
//! s ← (2/T)(z−1)/(z+1)) or **backward Euler** (s ← (z−1)/(Tz)):
//!
//! | term | Tustin | backward Euler |
//! |---|---|---|
//! | k_i/s | k_i·T/2·(z+1)/(z−1) | k_i·T·z/(z−1) |
//! | k_d·s/(1+s/ω_d) | β(z−1)/(z−α), α = (2−ω_dT)/(2+ω_dT), β = 2k_dω_d/(2+ω_dT) | α = 1/(1+ω_dT), β = k_dω_d/(1+ω_dT) |
//!
//! realised with two states, x_i (integrator) and x_d (derivative filter):
//!
//! ```text
//! v[k]    = k_p e + (x_i + g e) + (x_d + β e)        g = k_iT/2 (Tustin) or k_iT (BE)
//! u[k]    = clamp(v[k], output_min, output_max)
//! x_d    ← α x_d + β(α − 1) e
//! x_i    ← x_i + k_iT e   (+ anti-windup)
//! ```
//!
//! which is exactly the model [`Block::lti`] returns (valid while u is not
//! saturated).
//!
//! # Anti-windup
//!
//! When the output saturates, `clamping` (default; conditional integration) stops
//! the integrator while the error would drive it further into the limit;
//! `back_calculation` feeds the excess back into the integrator,
//! x_i ← x_i + k_iT e + (T/T_t)(u − v), with tracking time T_t (`tracking_time_s`,
//! default √(T_i·T_d) with T_i = k_p/k_i, T_d = k_d/k_p, or T_i for a PI; never
//! below T); `none` integrates regardless.
//!
//! ```
//! use nanomotion_core::Controller;
//! use nanomotion_core::blocks::control::Pid;
//! // PI with k_p = 2, k_i = 100 /s at 4 kHz, Tustin: step response u[k] = 2 + 100·T·(k + ½).
//! let mut c = Pid::new(2.0, 100.0, 0.0, None, 1.0 / 4000.0).unwrap();
//! let mut u = [0.0];
//! c.control(&[1.0], &mut u);
//! assert!((u[0] - (2.0 + 100.0 / 4000.0 * 0.5)).abs() < 1e-12);
//! ```

use crate::block::check;
use crate::lti::StateSpace;
use crate::{Block, BuildContext, Controller, ParamError, Params, Tick, declared_block};
use nalgebra::DMatrix;
use serde::{Deserialize, Serialize};
use std::f64::consts::TAU;

/// How [`Pid`] discretises its integrator and derivative filter.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize, Params)]
#[serde(rename_all = "snake_case")]
pub enum PidDiscretisation {
    /// Bilinear transform s ← (2/T)(z−1)/(z+1): keeps the frequency response
    /// shape (warped); the default.
    #[default]
    Tustin,
    /// Backward Euler s ← (z−1)/(Tz): never rings, even with a derivative cut-off
    /// close to Nyquist.
    BackwardEuler,
}

/// Anti-windup scheme of [`Pid`], active only when `output_min`/`output_max` are given.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize, Params)]
#[serde(rename_all = "snake_case")]
pub enum AntiWindup {
    /// Integrate regardless of saturation (shows windup; for comparison).
    None,
    /// Conditional integration: hold the integrator while saturated and the error
    /// pushes further into the limit. The default.
    #[default]
    Clamping,
    /// Back-calculation with tracking time `tracking_time_s`.
    BackCalculation,
}

/// Coefficients derived in `build`.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
struct Coeffs {
    dt: f64,
    /// Integrator feed-through g (k_iT/2 or k_iT) and input gain k_iT.
    gi_d: f64,
    gi_b: f64,
    /// Derivative filter pole α and gain β.
    alpha: f64,
    beta: f64,
    /// Output limits (±∞ when absent).
    lo: f64,
    hi: f64,
    /// Back-calculation gain T/T_t.
    kb: f64,
}

/// `pid`: PID controller kp + ki/s + kd·s/(1 + s/ω_d) with filtered derivative,
/// Tustin or backward Euler, output limits and anti-windup.
///
/// See the [module documentation](self) for the exact discrete equations.
#[derive(Debug, Clone, Default, Serialize, Deserialize, Params)]
#[serde(deny_unknown_fields)]
#[block(type_name = "pid", role = Controller, ports = "e -> u", live = "kp, ki, kd")]
pub struct Pid {
    /// Proportional gain k_p (unit of u per unit of e).
    #[param(finite)]
    pub kp: f64,
    /// Integral gain k_i (unit of u per unit of e per second).
    #[serde(default)]
    #[param(finite)]
    pub ki: f64,
    /// Derivative gain k_d (unit of u per unit of e, times seconds).
    #[serde(default)]
    #[param(finite)]
    pub kd: f64,
    /// Cut-off f_d (Hz) of the derivative low-pass k_d·s/(1 + s/(2πf_d)); required
    /// when k_d ≠ 0, below the Nyquist frequency.
    #[serde(default)]
    pub derivative_cutoff_hz: Option<f64>,
    /// Discretisation of the integrator and derivative filter.
    #[serde(default)]
    pub discretisation: PidDiscretisation,
    /// Lower output limit (unit of u).
    #[serde(default)]
    #[param(finite)]
    pub output_min: Option<f64>,
    /// Upper output limit (unit of u).
    #[serde(default)]
    #[param(finite)]
    pub output_max: Option<f64>,
    /// Anti-windup scheme, active when a limit is given.
    #[serde(default)]
    pub anti_windup: AntiWindup,
    /// Tracking time T_t of back-calculation (s), at least one sample period.
    #[serde(default)]
    #[param(positive, default_doc = "√(T_i·T_d), or T_i without a derivative")]
    pub tracking_time_s: Option<f64>,
    #[serde(skip)]
    c: Coeffs,
    #[serde(skip)]
    xi: f64,
    #[serde(skip)]
    xd: f64,
}

impl Pid {
    /// A PID without output limits, ready to run at period `dt` (s).
    pub fn new(
        kp: f64,
        ki: f64,
        kd: f64,
        derivative_cutoff_hz: Option<f64>,
        dt: f64,
    ) -> Result<Self, ParamError> {
        let mut p = Self {
            kp,
            ki,
            kd,
            derivative_cutoff_hz,
            ..Self::default()
        };
        p.prepare(dt)?;
        Ok(p)
    }

    /// The same controller with output limits `[output_min, output_max]` and an
    /// anti-windup scheme, re-prepared at period `dt` (s).
    pub fn with_limits(
        mut self,
        output_min: f64,
        output_max: f64,
        anti_windup: AntiWindup,
        dt: f64,
    ) -> Result<Self, ParamError> {
        self.output_min = Some(output_min);
        self.output_max = Some(output_max);
        self.anti_windup = anti_windup;
        self.prepare(dt)?;
        Ok(self)
    }

    /// Validate, derive the coefficients for period `dt` and clear the state.
    fn prepare(&mut self, dt: f64) -> Result<(), ParamError> {
        self.derive(dt)?;
        self.reset();
        Ok(())
    }

    /// Set live parameter `slot` (`kp`, `ki`, `kd`) and re-derive the
    /// coefficients at the prepared period, keeping the state x_i, x_d. A
    /// value the block refuses leaves it unchanged. No allocation unless the
    /// value is refused (callers validate first).
    fn retune(&mut self, slot: usize, value: f64) {
        let keep = self.clone();
        match slot {
            0 => self.kp = value,
            1 => self.ki = value,
            2 => self.kd = value,
            _ => return,
        }
        if self.derive(keep.c.dt).is_err() {
            *self = keep;
        }
    }

    /// Validate and derive the coefficients for period `dt`; the state is left
    /// as it is.
    fn derive(&mut self, dt: f64) -> Result<(), ParamError> {
        if !(dt.is_finite() && dt > 0.0) {
            return Err(ParamError::new(
                "rate_hz",
                format!("sample period {dt} s is not positive"),
                "give a positive rate",
            ));
        }
        self.check_params()?;
        let lo = self.output_min.unwrap_or(f64::NEG_INFINITY);
        let hi = self.output_max.unwrap_or(f64::INFINITY);
        if lo > hi {
            return Err(ParamError::new(
                "output_min",
                format!("output_min = {lo} is larger than output_max = {hi}"),
                "make output_min ≤ output_max",
            ));
        }
        let nyquist = 0.5 / dt;
        let (alpha, beta) = if self.kd == 0.0 {
            (0.0, 0.0)
        } else {
            let Some(fd) = self.derivative_cutoff_hz else {
                return Err(ParamError::new(
                    "derivative_cutoff_hz",
                    "is missing while kd ≠ 0",
                    "give the derivative low-pass cut-off in Hz (e.g. 5–10× the bandwidth)",
                ));
            };
            check::positive("derivative_cutoff_hz", fd)?;
            if fd >= nyquist {
                return Err(ParamError::new(
                    "derivative_cutoff_hz",
                    format!("{fd} Hz is not below the Nyquist frequency {nyquist} Hz"),
                    "lower the cut-off or raise the block's rate",
                ));
            }
            let wt = TAU * fd * dt;
            let wd = TAU * fd;
            match self.discretisation {
                PidDiscretisation::Tustin => {
                    ((2.0 - wt) / (2.0 + wt), 2.0 * self.kd * wd / (2.0 + wt))
                }
                PidDiscretisation::BackwardEuler => (1.0 / (1.0 + wt), self.kd * wd / (1.0 + wt)),
            }
        };
        let gi_b = self.ki * dt;
        let gi_d = match self.discretisation {
            PidDiscretisation::Tustin => gi_b / 2.0,
            PidDiscretisation::BackwardEuler => gi_b,
        };
        let tt = match self.tracking_time_s {
            Some(tt) => {
                if tt < dt {
                    return Err(ParamError::new(
                        "tracking_time_s",
                        format!("{tt} s is shorter than the sample period {dt} s"),
                        "give a tracking time of at least one sample period",
                    ));
                }
                tt
            }
            None => {
                let ti = if self.ki != 0.0 && self.kp != 0.0 {
                    (self.kp / self.ki).abs()
                } else {
                    dt
                };
                let td = if self.kp != 0.0 {
                    (self.kd / self.kp).abs()
                } else {
                    0.0
                };
                (if td > 0.0 { (ti * td).sqrt() } else { ti }).max(dt)
            }
        };
        self.c = Coeffs {
            dt,
            gi_d,
            gi_b,
            alpha,
            beta,
            lo,
            hi,
            kb: dt / tt,
        };
        Ok(())
    }

    /// One sample: error `e` in, saturated control action out.
    pub fn step(&mut self, e: f64) -> f64 {
        let c = self.c;
        let v = self.kp * e + (self.xi + c.gi_d * e) + (self.xd + c.beta * e);
        let u = if v > c.hi {
            c.hi
        } else if v < c.lo {
            c.lo
        } else {
            v
        };
        self.xd = c.alpha * self.xd + c.beta * (c.alpha - 1.0) * e;
        let di = c.gi_b * e;
        self.xi += match self.anti_windup {
            AntiWindup::None => di,
            AntiWindup::Clamping => {
                if (v > c.hi && di > 0.0) || (v < c.lo && di < 0.0) {
                    0.0
                } else {
                    di
                }
            }
            AntiWindup::BackCalculation => di + c.kb * (u - v),
        };
        u
    }

    /// The unsaturated discrete controller e → u as a state-space model (only the
    /// states in use: x_i if k_i ≠ 0, x_d if k_d ≠ 0).
    pub fn state_space(&self) -> StateSpace {
        let c = self.c;
        let mut a = Vec::new();
        let mut b = Vec::new();
        if self.ki != 0.0 {
            a.push(1.0);
            b.push(c.gi_b);
        }
        if self.kd != 0.0 {
            a.push(c.alpha);
            b.push(c.beta * (c.alpha - 1.0));
        }
        let n = a.len();
        StateSpace {
            a: DMatrix::from_diagonal(&nalgebra::DVector::from_vec(a)),
            b: DMatrix::from_column_slice(n, 1, &b),
            c: DMatrix::from_element(1, n, 1.0),
            d: DMatrix::from_element(1, 1, self.kp + c.gi_d + c.beta),
            dt: Some(c.dt),
        }
    }
}

impl Controller for Pid {
    fn control(&mut self, e: &[f64], u: &mut [f64]) {
        u[0] = self.step(e[0]);
    }
    fn reset(&mut self) {
        self.xi = 0.0;
        self.xd = 0.0;
    }
}

#[declared_block]
impl Block for Pid {
    fn build(&mut self, ctx: &BuildContext) -> Result<(), ParamError> {
        self.prepare(ctx.dt)
    }
    fn output(&mut self, _tick: Tick, u: &[f64], y: &mut [f64]) {
        self.control(u, y);
    }
    fn set_live_param(&mut self, slot: usize, value: f64) {
        self.retune(slot, value);
    }
    fn lti(&self) -> Option<StateSpace> {
        Some(self.state_space())
    }
    fn linearisation(&self) -> Option<crate::block::Linearisation> {
        limits_linearisation(self.state_space(), self.output_min, self.output_max)
    }
}

// ---------------------------------------------------------------------------------
// pi
// ---------------------------------------------------------------------------------

/// `pi`: the PI controller of (2.10) in the thesis's zero form
/// C(s) = k_p·(s + 2π f_i)/s = k_p + k_p·2π f_i / s, with output limits and
/// anti-windup.
///
/// With integrator zero f_i = `zero_hz` (Ch. 2 loop-shapes the walking-piezo loop
/// to ~10 Hz bandwidth on the drive frequency f_α; Ch. 5 to ~50 Hz). Realised as a
/// [`Pid`] with k_i = k_p·2π f_i and k_d = 0 (same discretisation, limits and
/// anti-windup).
#[derive(Debug, Clone, Serialize, Deserialize, Params)]
#[serde(deny_unknown_fields)]
#[block(type_name = "pi", role = Controller, ports = "e -> u", live = "kp, zero_hz")]
pub struct Pi {
    /// Gain k_p (unit of u per unit of e; for f_α in Hz per m of error).
    #[param(finite)]
    kp: f64,
    /// Integrator zero f_i (Hz); 0 gives a P controller.
    #[param(non_negative)]
    zero_hz: f64,
    /// Discretisation of the integrator.
    #[serde(default)]
    discretisation: PidDiscretisation,
    /// Lower output limit (unit of u).
    #[serde(default)]
    output_min: Option<f64>,
    /// Upper output limit (unit of u).
    #[serde(default)]
    output_max: Option<f64>,
    /// Anti-windup scheme, active when a limit is given.
    #[serde(default)]
    anti_windup: AntiWindup,
    /// Tracking time T_t of back-calculation (s).
    #[serde(default)]
    #[param(default_doc = "T_i = 1/(2π·zero_hz)")]
    tracking_time_s: Option<f64>,
    #[serde(skip)]
    pid: Pid,
    /// The period the controller was last prepared for (s).
    #[serde(skip)]
    dt: f64,
}

impl Pi {
    /// C(s) = kp·(s + 2π·zero_hz)/s at period `dt` (s), without limits.
    pub fn new(kp: f64, zero_hz: f64, dt: f64) -> Result<Self, ParamError> {
        let mut p = Self {
            kp,
            zero_hz,
            discretisation: PidDiscretisation::Tustin,
            output_min: None,
            output_max: None,
            anti_windup: AntiWindup::Clamping,
            tracking_time_s: None,
            pid: Pid::default(),
            dt,
        };
        p.prepare(dt)?;
        Ok(p)
    }

    /// The same controller with output limits `[output_min, output_max]` and an
    /// anti-windup scheme, re-prepared (the fields are private so that a limit
    /// can never be set without taking effect).
    pub fn with_limits(
        mut self,
        output_min: f64,
        output_max: f64,
        anti_windup: AntiWindup,
    ) -> Result<Self, ParamError> {
        self.output_min = Some(output_min);
        self.output_max = Some(output_max);
        self.anti_windup = anti_windup;
        self.prepare(self.dt)?;
        Ok(self)
    }

    /// The same controller with another discretisation, re-prepared.
    pub fn with_discretisation(mut self, d: PidDiscretisation) -> Result<Self, ParamError> {
        self.discretisation = d;
        self.prepare(self.dt)?;
        Ok(self)
    }

    /// The same controller with back-calculation tracking time `t_s` (s),
    /// re-prepared.
    pub fn with_tracking_time(mut self, t_s: f64) -> Result<Self, ParamError> {
        self.tracking_time_s = Some(t_s);
        self.prepare(self.dt)?;
        Ok(self)
    }

    /// Gain k_p.
    pub fn kp(&self) -> f64 {
        self.kp
    }
    /// Integrator zero f_i (Hz).
    pub fn zero_hz(&self) -> f64 {
        self.zero_hz
    }
    /// Output limits (lower, upper), if set.
    pub fn output_limits(&self) -> (Option<f64>, Option<f64>) {
        (self.output_min, self.output_max)
    }

    fn prepare(&mut self, dt: f64) -> Result<(), ParamError> {
        self.dt = dt;
        self.check_params()?;
        let ki = self.kp * TAU * self.zero_hz;
        if !ki.is_finite() {
            return Err(ParamError::new(
                "kp",
                format!(
                    "kp = {:e} with zero_hz = {:e} gives an integral gain kp·2π·zero_hz = {ki:e}, not a finite number",
                    self.kp, self.zero_hz
                ),
                "give a smaller kp or zero_hz",
            ));
        }
        self.pid = Pid {
            kp: self.kp,
            ki: self.kp * TAU * self.zero_hz,
            discretisation: self.discretisation,
            output_min: self.output_min,
            output_max: self.output_max,
            anti_windup: self.anti_windup,
            tracking_time_s: self.tracking_time_s,
            ..Pid::default()
        };
        self.pid.prepare(dt)
    }

    /// The equivalent [`Pid`].
    pub fn as_pid(&self) -> &Pid {
        &self.pid
    }
}

impl Controller for Pi {
    fn control(&mut self, e: &[f64], u: &mut [f64]) {
        u[0] = self.pid.step(e[0]);
    }
    fn reset(&mut self) {
        self.pid.reset();
    }
}

#[declared_block]
impl Block for Pi {
    fn build(&mut self, ctx: &BuildContext) -> Result<(), ParamError> {
        self.prepare(ctx.dt)
    }
    fn output(&mut self, _tick: Tick, u: &[f64], y: &mut [f64]) {
        self.control(u, y);
    }
    /// k_p or f_i changed, the integrator's value kept (bumpless at zero error).
    fn set_live_param(&mut self, slot: usize, value: f64) {
        let keep = self.clone();
        match slot {
            0 => self.kp = value,
            1 => self.zero_hz = value,
            _ => return,
        }
        // The inner PID's gains follow (k_i = k_p·2π f_i); its state stays.
        self.pid.kp = self.kp;
        self.pid.ki = self.kp * TAU * self.zero_hz;
        if !self.pid.ki.is_finite() || self.pid.derive(self.dt).is_err() {
            *self = keep;
        }
    }
    fn lti(&self) -> Option<StateSpace> {
        Some(self.pid.state_space())
    }
    fn linearisation(&self) -> Option<crate::block::Linearisation> {
        limits_linearisation(self.pid.state_space(), self.output_min, self.output_max)
    }
}

/// The note of a PID/PI judged without its output limits, if it has any.
fn limits_linearisation(
    model: StateSpace,
    lo: Option<f64>,
    hi: Option<f64>,
) -> Option<crate::block::Linearisation> {
    if lo.is_none() && hi.is_none() {
        return None;
    }
    let lo = lo.unwrap_or(f64::NEG_INFINITY);
    let hi = hi.unwrap_or(f64::INFINITY);
    Some(crate::block::Linearisation::single(
        model,
        format!(
            "output limits [{lo}, {hi}] ignored: judged inside them (saturation as gain 1, anti-windup inactive)"
        ),
    ))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::lti::Complex;

    const DT: f64 = 2.5e-4; // 4 kHz

    fn built(text: &str) -> Box<dyn Block> {
        let mut b: Box<dyn Block> = crate::yaml::from_str(text, "test").unwrap();
        b.build(&BuildContext::new("c", DT, 0)).unwrap();
        b
    }

    fn build_err(text: &str) -> String {
        let mut b: Box<dyn Block> = crate::yaml::from_str(text, "test").unwrap();
        b.build(&BuildContext::new("c", DT, 0)).unwrap_err().field
    }

    /// Simulate a discrete state-space model (own loop, independent of the block).
    fn simulate(ss: &StateSpace, u: &[f64]) -> Vec<f64> {
        let mut x = nalgebra::DVector::zeros(ss.a.nrows());
        u.iter()
            .map(|&uk| {
                let uk = nalgebra::DVector::from_element(1, uk);
                let y = (&ss.c * &x + &ss.d * &uk)[0];
                x = &ss.a * &x + &ss.b * &uk;
                y
            })
            .collect()
    }

    /// H(z) = C(zI − A)⁻¹B + D of a SISO model.
    fn eval_z(ss: &StateSpace, z: Complex<f64>) -> Complex<f64> {
        let n = ss.a.nrows();
        let a = ss.a.map(|v| Complex::new(v, 0.0));
        let m = DMatrix::from_diagonal_element(n, n, z) - a;
        let b = ss.b.map(|v| Complex::new(v, 0.0));
        let x = m.lu().solve(&b).unwrap();
        let c = ss.c.map(|v| Complex::new(v, 0.0));
        (c * x)[(0, 0)] + ss.d[(0, 0)]
    }

    fn run(b: &mut dyn Block, e: &[f64]) -> Vec<f64> {
        e.iter()
            .enumerate()
            .map(|(k, &ek)| {
                let mut y = [0.0];
                b.output(Tick::new(k as u64, DT), &[ek], &mut y);
                y[0]
            })
            .collect()
    }

    #[test]
    fn lti_is_the_continuous_pid_under_the_substitution() {
        // For any z, the discrete model must equal C(s) at s = (2/T)(z−1)/(z+1)
        // (Tustin) or s = (z−1)/(Tz) (backward Euler), term by term exactly.
        let (kp, ki, kd, fd) = (3.0, 400.0, 2e-3, 800.0);
        let wd = TAU * fd;
        let cont = |s: Complex<f64>| kp + ki / s + kd * s / (1.0 + s / wd);
        for (method, subst) in [
            (
                "tustin",
                Box::new(|z: Complex<f64>| (z - 1.0) / (z + 1.0) * (2.0 / DT))
                    as Box<dyn Fn(_) -> _>,
            ),
            (
                "backward_euler",
                Box::new(|z: Complex<f64>| (z - 1.0) / (z * DT)),
            ),
        ] {
            let text = format!(
                "type: pid\nkp: {kp}\nki: {ki}\nkd: {kd}\nderivative_cutoff_hz: {fd}\ndiscretisation: {method}\n"
            );
            let ss = built(&text).lti().unwrap();
            assert_eq!(ss.dt, Some(DT));
            assert_eq!(ss.a.nrows(), 2);
            for z in [
                Complex::new(0.3, 0.8),
                Complex::from_polar(1.0, 0.05),
                Complex::new(-0.5, 0.1),
                Complex::new(2.0, -1.0),
            ] {
                let (hd, hc) = (eval_z(&ss, z), cont(subst(z)));
                assert!(
                    (hd - hc).norm() < 1e-9 * hc.norm(),
                    "{method} at z = {z}: {hd} vs {hc}"
                );
            }
        }
    }

    #[test]
    fn a_live_gain_change_keeps_the_integrator() {
        // PI (Tustin) on a unit step, k_p changed before sample K: the
        // integrator keeps k_i1·T·K, so u[K+j] = k_p2 + k_i1 T K + k_i2 T (j + ½)
        // (k_i = k_p·2π f_i); before K, u[k] = k_p1 + k_i1 T (k + ½).
        let (kp1, kp2, fi, big_k) = (1.5, 4.0, 30.0, 100);
        let (ki1, ki2) = (kp1 * TAU * fi, kp2 * TAU * fi);
        let mut b = built(&format!("type: pi\nkp: {kp1}\nzero_hz: {fi}\n"));
        assert_eq!(b.live_params(), ["kp", "zero_hz"]);
        let before = run(b.as_mut(), &vec![1.0; big_k]);
        b.set_live_param(0, kp2);
        let after = run(b.as_mut(), &[1.0; 50]);
        for (k, &u) in before.iter().enumerate() {
            let expect = kp1 + ki1 * DT * (k as f64 + 0.5);
            assert!(
                (u - expect).abs() < 1e-12 * expect,
                "k = {k}: {u} vs {expect}"
            );
        }
        for (j, &u) in after.iter().enumerate() {
            let expect = kp2 + ki1 * DT * big_k as f64 + ki2 * DT * (j as f64 + 0.5);
            assert!(
                (u - expect).abs() < 1e-12 * expect,
                "K + {j}: {u} vs {expect}"
            );
        }
        // The same change on a PID (slot 0 = kp): only the proportional term moves.
        let mut p = built("type: pid\nkp: 1.5\nki: 200\n");
        let u0 = run(p.as_mut(), &[1.0; 10]);
        p.set_live_param(0, 2.5);
        let u1 = run(p.as_mut(), &[1.0]);
        let expect = u0[9] + 1.0 + 200.0 * DT;
        assert!(
            (u1[0] - expect).abs() < 1e-12 * expect,
            "{} vs {expect}",
            u1[0]
        );
        // A refused value (the block's own validation, here a non-finite k_i)
        // leaves the block as it was.
        p.set_live_param(1, f64::INFINITY);
        let u2 = run(p.as_mut(), &[1.0]);
        let expect = u1[0] + 200.0 * DT;
        assert!(
            (u2[0] - expect).abs() < 1e-12 * expect,
            "{} vs {expect}",
            u2[0]
        );
    }

    #[test]
    fn step_response_matches_closed_form() {
        // Tustin: u[k] = k_p + k_i T (k + ½) + β α^k; backward Euler:
        // u[k] = k_p + k_i T (k + 1) + β α^k (the filtered-derivative step is β α^k
        // for H(z) = β(z − 1)/(z − α)).
        let (kp, ki, kd, fd) = (1.5, 200.0, 1e-3, 500.0);
        let wt = TAU * fd * DT;
        let wd = TAU * fd;
        let n = 400;
        let step = vec![1.0; n];
        for (method, alpha, beta, half) in [
            (
                "tustin",
                (2.0 - wt) / (2.0 + wt),
                2.0 * kd * wd / (2.0 + wt),
                0.5,
            ),
            (
                "backward_euler",
                1.0 / (1.0 + wt),
                kd * wd / (1.0 + wt),
                1.0,
            ),
        ] {
            let text = format!(
                "type: pid\nkp: {kp}\nki: {ki}\nkd: {kd}\nderivative_cutoff_hz: {fd}\ndiscretisation: {method}\n"
            );
            let mut b = built(&text);
            let u = run(b.as_mut(), &step);
            for (k, &uk) in u.iter().enumerate() {
                let expect = kp + ki * DT * (k as f64 + half) + beta * alpha.powi(k as i32);
                assert!(
                    (uk - expect).abs() < 1e-11 * expect.abs(),
                    "{method} k = {k}: {uk} vs {expect}"
                );
            }
            // Final derivative kick decays: at k = 400 the derivative is gone.
            assert!(beta * alpha.powi(n as i32) < 1e-12);
        }
    }

    #[test]
    fn lti_matches_simulation_of_the_block() {
        let text = "type: pid\nkp: 0.7\nki: 50\nkd: 5.0e-4\nderivative_cutoff_hz: 300\noutput_min: -100\noutput_max: 100\n";
        let mut b = built(text);
        let ss = b.lti().unwrap();
        let mut rng = crate::rng::Rng::new(3);
        let e: Vec<f64> = (0..2000).map(|_| rng.normal()).collect();
        let y_block = run(b.as_mut(), &e);
        let y_model = simulate(&ss, &e);
        assert!(y_block.iter().all(|v| v.abs() < 100.0), "not saturated");
        for (k, (a, m)) in y_block.iter().zip(&y_model).enumerate() {
            assert!((a - m).abs() < 1e-9, "k = {k}: {a} vs {m}");
        }
        // After a rebuild the block starts again from rest.
        b.build(&BuildContext::new("c", DT, 0)).unwrap();
        assert_eq!(run(b.as_mut(), &e[..50]), y_block[..50].to_vec());
    }

    /// Closed loop around a first-order lag τ = 0.1 s with |u| ≤ 1.5 and a
    /// setpoint step to 1.4 (u saturates for a long time). Returns (overshoot,
    /// time to stay within 1 % of the setpoint).
    fn windup_run(anti_windup: AntiWindup) -> (f64, f64) {
        let mut c = Pid::new(2.0, 40.0, 0.0, None, DT)
            .unwrap()
            .with_limits(-1.5, 1.5, anti_windup, DT)
            .unwrap();
        let a = (-DT / 0.1f64).exp();
        let (r, mut y) = (1.4, 0.0);
        let n = (3.0 / DT) as usize;
        let mut ys = Vec::with_capacity(n);
        for _ in 0..n {
            let mut u = [0.0];
            c.control(&[r - y], &mut u);
            assert!((-1.5..=1.5).contains(&u[0]));
            ys.push(y);
            y = a * y + (1.0 - a) * u[0];
        }
        let overshoot = ys.iter().fold(0.0f64, |m, &v| m.max(v - r));
        let last_out = ys.iter().rposition(|&v| (v - r).abs() > 0.01 * r).unwrap();
        assert!(last_out < n - 100, "settles within the run");
        (overshoot, (last_out + 1) as f64 * DT)
    }

    #[test]
    fn anti_windup_recovers_faster_than_none() {
        // Observed: none overshoots 0.10 and settles in 1.2 s; clamping 0.008 and
        // 0.27 s; back-calculation 0.02 and 0.38 s.
        let (os_none, ts_none) = windup_run(AntiWindup::None);
        let (os_clamp, ts_clamp) = windup_run(AntiWindup::Clamping);
        let (os_back, ts_back) = windup_run(AntiWindup::BackCalculation);
        assert!(os_none > 0.05, "windup overshoots: {os_none}");
        assert!(os_clamp < 0.2 * os_none, "clamping {os_clamp} vs {os_none}");
        assert!(
            os_back < 0.3 * os_none,
            "back-calculation {os_back} vs {os_none}"
        );
        assert!(
            ts_clamp < 0.5 * ts_none,
            "clamping settles {ts_clamp} s vs {ts_none} s"
        );
        assert!(
            ts_back < 0.5 * ts_none,
            "back-calculation settles {ts_back} s vs {ts_none} s"
        );
    }

    #[test]
    fn pi_is_the_zero_form_of_2_10() {
        // kp·(s + 2π f_i)/s: gain kp·√2 at f_i, phase −45° (continuous); the
        // Tustin version matches at s = (2/T)(z−1)/(z+1).
        let (kp, fi) = (0.8, 10.0);
        let mut pi = built("type: pi\nkp: 0.8\nzero_hz: 10\n");
        let ss = pi.lti().unwrap();
        let wi = TAU * fi;
        for f in [1.0, 10.0, 100.0, 1000.0] {
            let z = Complex::from_polar(1.0, TAU * f * DT);
            let s = (z - 1.0) / (z + 1.0) * (2.0 / DT);
            let hc = (s + wi) / s * kp;
            assert!((eval_z(&ss, z) - hc).norm() < 1e-10 * hc.norm());
        }
        let z = Complex::from_polar(1.0, wi * DT);
        let h = eval_z(&ss, z);
        assert!(
            (h.norm() / (kp * 2f64.sqrt()) - 1.0).abs() < 1e-3,
            "|C(f_i)| = {}",
            h.norm()
        );
        assert!(
            (h.arg().to_degrees() + 45.0).abs() < 0.1,
            "phase {}",
            h.arg().to_degrees()
        );
        // Same as the pid with ki = kp·2π f_i.
        let mut pid = Pid::new(kp, kp * wi, 0.0, None, DT).unwrap();
        let e: Vec<f64> = (0..100).map(|k| (k as f64 * 0.1).sin()).collect();
        let y = run(pi.as_mut(), &e);
        let y2: Vec<f64> = e.iter().map(|&ek| pid.step(ek)).collect();
        assert_eq!(y, y2);
        // Plain-Rust constructor and reset.
        let mut p = Pi::new(kp, fi, DT).unwrap();
        let mut u = [0.0];
        for _ in 0..10 {
            p.control(&[1.0], &mut u);
        }
        p.reset();
        p.control(&[1.0], &mut u);
        assert!((u[0] - (kp + kp * wi * DT / 2.0)).abs() < 1e-12);
        assert_eq!(p.as_pid().ki, kp * wi);
    }

    #[test]
    fn validation_names_the_field() {
        assert_eq!(build_err("type: pid\nkp: .nan\n"), "kp");
        assert_eq!(
            build_err("type: pid\nkp: 1\nkd: 1\n"),
            "derivative_cutoff_hz"
        );
        assert_eq!(
            build_err("type: pid\nkp: 1\nkd: 1\nderivative_cutoff_hz: 2000\n"),
            "derivative_cutoff_hz"
        );
        assert_eq!(
            build_err("type: pid\nkp: 1\nkd: 1\nderivative_cutoff_hz: -5\n"),
            "derivative_cutoff_hz"
        );
        assert_eq!(
            build_err("type: pid\nkp: 1\noutput_min: 2\noutput_max: 1\n"),
            "output_min"
        );
        assert_eq!(
            build_err("type: pid\nkp: 1\noutput_max: .inf\n"),
            "output_max"
        );
        assert_eq!(
            build_err("type: pid\nkp: 1\nki: 1\ntracking_time_s: 1.0e-6\n"),
            "tracking_time_s"
        );
        assert_eq!(build_err("type: pi\nkp: 1\nzero_hz: -1\n"), "zero_hz");
        assert!(
            crate::yaml::from_str::<Box<dyn Block>>("type: pid\nkp: 1\nanti_windup: magic\n", "t")
                .is_err()
        );
        // The quickstart example's PI (as a pid) builds and limits f_α.
        let mut q = built(
            "type: pid\nkp: 7.85e7\nki: 4.93e9\nkd: 0.0\noutput_min: -2000.0\noutput_max: 2000.0\n",
        );
        assert_eq!(run(q.as_mut(), &[1.0]), vec![2000.0]);
        // kd = 0 needs no cut-off; a P controller has no states.
        let p = built("type: pid\nkp: 2\n");
        let ss = p.lti().unwrap();
        assert_eq!((ss.a.nrows(), ss.d[(0, 0)]), (0, 2.0));
    }

    #[test]
    fn ticks_do_not_allocate() {
        for text in [
            "type: pid\nkp: 1\nki: 10\nkd: 1.0e-3\nderivative_cutoff_hz: 100\noutput_min: -1\noutput_max: 1\nanti_windup: back_calculation\n",
            "type: pi\nkp: 1\nzero_hz: 10\noutput_max: 1\n",
        ] {
            let mut b = built(text);
            let mut y = [0.0];
            let info = allocation_counter::measure(|| {
                for k in 0..1000 {
                    b.output(Tick::new(k, DT), &[(k as f64).sin()], &mut y);
                }
            });
            assert_eq!(info.count_total, 0, "{text}");
            assert!(y[0].is_finite());
        }
    }
}
