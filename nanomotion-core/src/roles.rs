//! Role traits: the typed Rust API of blocks, usable without any graph.
//!
//! A concrete type (a PI controller, an encoder, a plant model) implements its role
//! trait for direct use from Rust and [`Block`](crate::Block) for use in graphs; the
//! `Block` implementation is a thin adapter onto the role trait.
//!
//! All methods take and fill slices so that multi-input multi-output blocks (the 3-DOF
//! AFM stage, an H∞ controller) use the same traits as scalar ones; none of them may
//! allocate.

/// Produces a signal from time alone: references, disturbances, noise.
///
/// ```
/// use nanomotion_core::Source;
/// struct Ramp { slope: f64 }
/// impl Source for Ramp {
///     fn sample(&mut self, t: f64, y: &mut [f64]) { y[0] = self.slope * t; }
/// }
/// let mut r = Ramp { slope: 2.0 };
/// let mut y = [0.0];
/// r.sample(0.5, &mut y);
/// assert_eq!(y, [1.0]);
/// ```
pub trait Source {
    /// Write the signal value at time `t` (s) into `y`.
    fn sample(&mut self, t: f64, y: &mut [f64]);
}

/// Computes a control action from an error (or from reference and measurement).
///
/// ```
/// use nanomotion_core::Controller;
/// struct P(f64);
/// impl Controller for P {
///     fn control(&mut self, e: &[f64], u: &mut [f64]) { u[0] = self.0 * e[0]; }
///     fn reset(&mut self) {}
/// }
/// let mut c = P(3.0);
/// let mut u = [0.0];
/// c.control(&[2.0], &mut u);
/// assert_eq!(u, [6.0]);
/// ```
pub trait Controller {
    /// One sample: error `e` in, control action `u` out.
    fn control(&mut self, e: &[f64], u: &mut [f64]);
    /// Forget all state (integrators, filter memories).
    fn reset(&mut self);
}

/// Turns a command (e.g. the drive frequency f_α of a walking piezo motor) into the
/// physical drive signals (e.g. the four leg voltages u1..u4).
///
/// ```
/// use nanomotion_core::Actuator;
/// struct Amp { gain: f64, max_v: f64 }
/// impl Actuator for Amp {
///     fn drive(&mut self, cmd: &[f64], out: &mut [f64]) {
///         out[0] = (self.gain * cmd[0]).clamp(-self.max_v, self.max_v);
///     }
/// }
/// let mut a = Amp { gain: 10.0, max_v: 46.0 };
/// let mut v = [0.0];
/// a.drive(&[10.0], &mut v);
/// assert_eq!(v, [46.0]);
/// ```
pub trait Actuator {
    /// One sample: command in, drive signals out.
    fn drive(&mut self, command: &[f64], drive: &mut [f64]);
}

/// A simulated physical system, stepped at a fixed period chosen when it is built
/// (it may sub-step internally).
///
/// The output of sample k depends on the state only (no direct feed-through), so a
/// plant breaks algebraic loops: read [`Plant::plant_output`], then
/// [`Plant::advance`] with the input of sample k.
///
/// ```
/// use nanomotion_core::Plant;
/// /// x[k+1] = x[k] + dt·u[k]
/// struct Integrator { x: f64, dt: f64 }
/// impl Plant for Integrator {
///     fn plant_output(&self, y: &mut [f64]) { y[0] = self.x; }
///     fn advance(&mut self, u: &[f64]) { self.x += self.dt * u[0]; }
/// }
/// let mut p = Integrator { x: 0.0, dt: 0.1 };
/// p.advance(&[1.0]);
/// let mut y = [0.0];
/// p.plant_output(&mut y);
/// assert!((y[0] - 0.1).abs() < 1e-15);
/// ```
pub trait Plant {
    /// Outputs (measurable and internal signals) of the current state.
    fn plant_output(&self, y: &mut [f64]);
    /// Advance the state by one period with input `u` held constant.
    fn advance(&mut self, u: &[f64]);
}

/// Measures the true physical quantity `x` at time `t`, with the sensor's
/// imperfections (quantisation, noise, slit errors, time-stamps).
///
/// ```
/// use nanomotion_core::Sensor;
/// struct Quantiser { lsb: f64 }
/// impl Sensor for Quantiser {
///     fn measure(&mut self, _t: f64, x: &[f64], y: &mut [f64]) {
///         y[0] = (x[0] / self.lsb).round() * self.lsb;
///     }
/// }
/// let mut q = Quantiser { lsb: 0.5 };
/// let mut y = [0.0];
/// q.measure(0.0, &[1.3], &mut y);
/// assert_eq!(y, [1.5]);
/// ```
pub trait Sensor {
    /// One sample of the measurement.
    fn measure(&mut self, t: f64, x: &[f64], y: &mut [f64]);
}

/// Reconstructs quantities (position, velocity, acceleration) from measurements.
///
/// ```
/// use nanomotion_core::Estimator;
/// /// Backward-difference velocity.
/// struct Diff { last: f64, dt: f64 }
/// impl Estimator for Diff {
///     fn estimate(&mut self, _t: f64, m: &[f64], est: &mut [f64]) {
///         est[0] = m[0];
///         est[1] = (m[0] - self.last) / self.dt;
///         self.last = m[0];
///     }
/// }
/// let mut d = Diff { last: 0.0, dt: 0.5 };
/// let mut e = [0.0; 2];
/// d.estimate(0.5, &[1.0], &mut e);
/// assert_eq!(e, [1.0, 2.0]);
/// ```
pub trait Estimator {
    /// One sample: measurement in, estimates out.
    fn estimate(&mut self, t: f64, measurement: &[f64], estimate: &mut [f64]);
}

/// A learning filter of repetitive or iterative learning control: L(z) or Q(z) of
/// (5.1), possibly non-causal with a preview of `l` samples. The filter is realised
/// causally as z^-l·L(z); the memory loop compensates the `l` samples.
///
/// ```
/// use nanomotion_core::LearningFilter;
/// /// L(z) = z (one sample preview), realised as z^-1·z = 1.
/// struct OneAhead;
/// impl LearningFilter for OneAhead {
///     fn preview_samples(&self) -> usize { 1 }
///     fn filter(&mut self, x: f64) -> f64 { x }
///     fn reset(&mut self) {}
/// }
/// let mut l = OneAhead;
/// assert_eq!(l.preview_samples(), 1);
/// assert_eq!(l.filter(2.5), 2.5);
/// ```
pub trait LearningFilter {
    /// The preview `l` (samples) that the causal realisation delays by.
    fn preview_samples(&self) -> usize;
    /// One sample of the causal realisation z^-l·L(z).
    fn filter(&mut self, x: f64) -> f64;
    /// Clear the filter memory.
    fn reset(&mut self);
}
