//! Control of the walking piezo stage (Sec. 2.4.2–2.4.3):
//!
//! - [`design_pi`]: the loop-shaped PI (2.10) C(s) = k_p(s + 2πf_i)/s on f_α from
//!   the stage position, designed on the linear model (2.7) discretised at the loop
//!   rate, with the driver's one-sample delay, and its margins from
//!   [`nanomotion_core::lti::stability_margins`] ([`loop_gain`], [`PiDesign`]);
//! - [`StepSizeFeedForward`] (block `walking_piezo_feedforward`): the amplitude
//!   A(t) and phase φ(t) of the waveforms from the reference velocity |ṙ|
//!   (2.11)–(2.12), to be paired with a gain-scheduled controller (2.13) (crate
//!   `nanomotion-gain-scheduling`).

use crate::linear::LinearStageParams;
use nalgebra::DMatrix;
use nanomotion_core::Params;
use nanomotion_core::block::check;
use nanomotion_core::blocks::control::Pi;
use nanomotion_core::lti::{C2dMethod, Margins, StateSpace, c2d, delay, series, stability_margins};
use nanomotion_core::{Block, BuildContext, Controller, ParamError, Tick, declared_block};
use serde::{Deserialize, Serialize};
use std::f64::consts::{FRAC_PI_2, FRAC_PI_4, TAU};

// ---------------------------------------------------------------------------
// PI design (2.10)
// ---------------------------------------------------------------------------

/// A PI design (2.10) and its margins.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PiDesign {
    /// Gain k_p (Hz of f_α per m of error).
    pub kp: f64,
    /// Integrator zero f_i (Hz).
    pub zero_hz: f64,
    /// Margins of the discrete loop gain ([`loop_gain`]).
    pub margins: Margins,
}

impl PiDesign {
    /// Gain crossover (bandwidth as defined in Sec. 2.4.2, |PC| = 0 dB) in Hz.
    pub fn crossover_hz(&self) -> f64 {
        self.margins.gain_crossover_rad_s / TAU
    }
    /// A core `pi` block with this design at period `dt` (s).
    pub fn controller(&self, dt: f64) -> Result<Pi, ParamError> {
        Pi::new(self.kp, self.zero_hz, dt)
    }
}

/// The discrete loop gain L(z) = C(z)·z⁻¹·P(z) at period `dt`: the core PI
/// (Tustin), one sample of driver delay (α is integrated under zero-order hold,
/// [`crate::driver`]) and the linear stage (2.7) from f_α to x_s by zero-order hold.
pub fn loop_gain(
    plant: &LinearStageParams,
    kp: f64,
    zero_hz: f64,
    dt: f64,
) -> Result<StateSpace, ParamError> {
    plant.validate()?;
    check::positive("dt", dt)?;
    let pc = plant.continuous();
    let p = StateSpace {
        c: DMatrix::from_row_slice(1, 3, &[0.0, 1.0, 0.0]),
        d: DMatrix::zeros(1, 1),
        ..pc
    };
    let lti = |e: nanomotion_core::lti::LtiError| {
        ParamError::new(
            "plant",
            format!("loop gain: {e}"),
            "check the plant and the rate",
        )
    };
    let pd = c2d(&p, dt, C2dMethod::Zoh).map_err(lti)?;
    let c = Pi::new(kp, zero_hz, dt)?.as_pid().state_space();
    let cd = series(&c, &delay(1, dt)).map_err(lti)?;
    series(&cd, &pd).map_err(lti)
}

/// Loop-shape the PI (2.10) on the linear model: the zero f_i = f_bw/tan(PM) gives
/// the phase margin `phase_margin_deg` for the double integrator of the low-frequency
/// plant c/s times the PI, and k_p puts the gain crossover of the *discrete* loop
/// ([`loop_gain`]) at `bandwidth_hz`. The margins are then computed on the discrete
/// loop. Thesis: ~10 Hz, PM 75° at 4 kHz.
///
/// ```
/// use walking_piezo::LinearStageParams;
/// use walking_piezo::control::design_pi;
/// let d = design_pi(&LinearStageParams::default(), 10.0, 75.0, 2.5e-4).unwrap();
/// assert!((d.crossover_hz() - 10.0).abs() < 1e-3);
/// assert!(d.margins.phase_margin_deg > 70.0);
/// ```
pub fn design_pi(
    plant: &LinearStageParams,
    bandwidth_hz: f64,
    phase_margin_deg: f64,
    dt: f64,
) -> Result<PiDesign, ParamError> {
    check::positive("bandwidth_hz", bandwidth_hz)?;
    check::in_range("phase_margin_deg", phase_margin_deg, 1.0, 89.0)?;
    check::positive("dt", dt)?;
    if bandwidth_hz >= 0.5 / dt {
        return Err(ParamError::new(
            "bandwidth_hz",
            format!("is {bandwidth_hz} Hz, at or above Nyquist {} Hz", 0.5 / dt),
            "give a bandwidth well below the Nyquist frequency",
        ));
    }
    let zero_hz = bandwidth_hz / phase_margin_deg.to_radians().tan();
    let l1 = loop_gain(plant, 1.0, zero_hz, dt)?;
    let kp = 1.0 / l1.freqresp_siso_at(TAU * bandwidth_hz).norm();
    let l = loop_gain(plant, kp, zero_hz, dt)?;
    let margins = stability_margins(&l)
        .map_err(|e| ParamError::new("plant", format!("margins: {e}"), "check the plant"))?;
    Ok(PiDesign {
        kp,
        zero_hz,
        margins,
    })
}

// ---------------------------------------------------------------------------
// Feed-forward (2.11)–(2.12)
// ---------------------------------------------------------------------------

/// Step-size feed-forward (2.11)–(2.12): from the reference velocity |ṙ| (m/s),
///
/// A = A_min + (A_max − A_min)·|ṙ|/v_max,   φ̄ = φ̄_min + (φ̄_max − φ̄_min)·|ṙ|/v_max,
///
/// both saturated to their ranges, and φ = φ̄ − π/2 the phase of (2.2) (φ̄ is the
/// phase *difference* between the two stacks of a leg). At |ṙ| = v_max the step is
/// the largest (A_max, φ̄_max = π/2, i.e. φ = 0); at rest it is the smallest.
///
/// Reading: the extracted (2.11) reads A = (A_max/v_max)|ṙ| + A_min, which would
/// reach A_max at v_max/2 and then saturate; we use the interpolation form that
/// spans [A_min, A_max] over [0, v_max] (the thesis's bounds are the same). The
/// extraction lost the value of φ̄_min ("π/2" for both bounds); we default to
/// φ̄_min = π/4, which halves the x-amplitude of the tip orbit (∝ sin(φ̄/2)).
///
/// ```
/// use walking_piezo::control::StepSizeFeedForward;
/// let ff = StepSizeFeedForward { v_max_m_s: 1e-3, ..Default::default() };
/// assert_eq!(ff.amplitude_phase(0.0), (23.0, std::f64::consts::FRAC_PI_4 - std::f64::consts::FRAC_PI_2));
/// assert_eq!(ff.amplitude_phase(-2e-3), (46.0, 0.0));
/// ```
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize, Params)]
#[serde(deny_unknown_fields)]
pub struct StepSizeFeedForward {
    /// v_max (m/s), the largest reference velocity of the move.
    #[param(positive)]
    pub v_max_m_s: f64,
    /// A_min (V); thesis 23 V.
    #[serde(default = "d_amin")]
    #[param(range(0.0, 46.0), at_most = amplitude_max_v)]
    pub amplitude_min_v: f64,
    /// A_max (V); thesis 46 V.
    #[serde(default = "d_amax")]
    #[param(range(0.0, 46.0))]
    pub amplitude_max_v: f64,
    /// φ̄_min (rad), the smallest phase difference.
    /// φ = φ̄ − π/2.
    #[serde(default = "d_pmin")]
    #[param(default_doc = "π/4")]
    #[param(at_most = phase_diff_max_rad)]
    pub phase_diff_min_rad: f64,
    /// φ̄_max (rad), the largest phase difference; thesis π/2.
    #[serde(default = "d_pmax")]
    #[param(default_doc = "π/2")]
    pub phase_diff_max_rad: f64,
}

fn d_amin() -> f64 {
    23.0
}
fn d_amax() -> f64 {
    46.0
}
fn d_pmin() -> f64 {
    FRAC_PI_4
}
fn d_pmax() -> f64 {
    FRAC_PI_2
}

impl Default for StepSizeFeedForward {
    fn default() -> Self {
        Self {
            v_max_m_s: 1e-3,
            amplitude_min_v: d_amin(),
            amplitude_max_v: d_amax(),
            phase_diff_min_rad: d_pmin(),
            phase_diff_max_rad: d_pmax(),
        }
    }
}

impl StepSizeFeedForward {
    /// Check the fields (typed errors naming them).
    pub fn validate(&self) -> Result<(), ParamError> {
        self.check_params()
    }
    /// (A (V), φ (rad)) for the reference velocity `r_dot` (m/s); a non-finite
    /// `r_dot` gives the smallest step.
    pub fn amplitude_phase(&self, r_dot: f64) -> (f64, f64) {
        let s = if r_dot.is_finite() {
            (r_dot.abs() / self.v_max_m_s).min(1.0)
        } else {
            0.0
        };
        let a = self.amplitude_min_v + (self.amplitude_max_v - self.amplitude_min_v) * s;
        let pd = self.phase_diff_min_rad + (self.phase_diff_max_rad - self.phase_diff_min_rad) * s;
        (a, pd - FRAC_PI_2)
    }
}

impl Controller for StepSizeFeedForward {
    /// `e` = [ṙ (m/s)], `u` = [A (V), φ (rad)].
    fn control(&mut self, e: &[f64], u: &mut [f64]) {
        let (a, p) = self.amplitude_phase(e[0]);
        u[0] = a;
        u[1] = p;
    }
    fn reset(&mut self) {}
}

/// `walking_piezo_feedforward`: step-size feed-forward (2.11)-(2.12): waveform
/// amplitude A and phase φ from the reference velocity |ṙ|.
///
/// Graph block `walking_piezo_feedforward`: input `r_dot` (1, m/s); outputs
/// `amplitude` (1, V) and `phase` (1, rad) for the driver's inputs, and `phase_diff`
/// (1, rad) = φ̄, a natural scheduling variable for K_φ (2.13).
#[derive(Debug, Clone, Default, Serialize, Deserialize, Params)]
#[serde(transparent)]
#[block(type_name = "walking_piezo_feedforward", role = Controller, ports = "r_dot (m/s) -> amplitude (V), phase (rad), phase_diff (rad)")]
pub struct StepSizeFeedForwardBlock {
    /// The parameters.
    pub params: StepSizeFeedForward,
}

#[declared_block]
impl Block for StepSizeFeedForwardBlock {
    fn build(&mut self, _ctx: &BuildContext) -> Result<(), ParamError> {
        self.params.validate()
    }
    fn output(&mut self, _tick: Tick, u: &[f64], y: &mut [f64]) {
        let (a, p) = self.params.amplitude_phase(u[0]);
        y[0] = a;
        y[1] = p;
        y[2] = p + FRAC_PI_2;
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::LinearStage;
    use nanomotion_core::Plant;
    use nanomotion_core::lti::feedback;

    const DT: f64 = 2.5e-4;

    #[test]
    fn pi_design_hits_the_bandwidth_with_the_thesis_margins() {
        let p = LinearStageParams::default();
        let d = design_pi(&p, 10.0, 75.0, DT).unwrap();
        assert!(
            (d.crossover_hz() - 10.0).abs() < 1e-6,
            "{}",
            d.crossover_hz()
        );
        // Zero at f_bw/tan 75°; the low-frequency loop kp·c·(s + ω_i)/s² then has
        // |L(jω_bw)| = 1, so kp ≈ ω_bw²/(c·|jω_bw + ω_i|) up to the delays and the
        // resonance's small gain at 10 Hz.
        assert!((d.zero_hz - 10.0 / 75f64.to_radians().tan()).abs() < 1e-12);
        let w = TAU * 10.0;
        let kp0 = w * w / (p.motor_constant_m * (w * w + (TAU * d.zero_hz).powi(2)).sqrt());
        assert!((d.kp / kp0 - 1.0).abs() < 0.01, "{} vs {kp0}", d.kp);
        // Phase margin: 75° less the loop's delays at 10 Hz (Tustin, ZOH, one
        // driver sample: about 1.5·ω·Δt ≈ 1.35°).
        let lag = (1.5 * w * DT).to_degrees();
        assert!(
            (d.margins.phase_margin_deg - (75.0 - lag)).abs() < 0.5,
            "{:?}",
            d.margins
        );
        // The lightly damped 575 Hz resonance limits the gain margin; the loop is
        // stable: every closed-loop pole inside the unit circle.
        assert!(d.margins.gain_margin > 1.0);
        let l = loop_gain(&p, d.kp, d.zero_hz, DT).unwrap();
        let one = StateSpace::gain(DMatrix::from_element(1, 1, 1.0), Some(DT));
        let t = feedback(&l, &one, -1.0).unwrap();
        assert!(t.poles().iter().all(|z| z.norm() < 1.0));
        // A bandwidth above Nyquist is refused, naming the field.
        assert_eq!(
            design_pi(&p, 1.0e4, 75.0, DT).unwrap_err().field,
            "bandwidth_hz"
        );
    }

    #[test]
    fn pi_on_the_linear_stage_tracks_a_ramp_without_steady_error() {
        // Type-2 loop (plant integrator + PI): zero steady-state error on a ramp.
        let p = LinearStageParams::default();
        let d = design_pi(&p, 10.0, 75.0, DT).unwrap();
        let mut c = d.controller(DT).unwrap();
        let mut stage = LinearStage::new(p, DT).unwrap();
        let v = 10e-6;
        let mut f_prev = 0.0; // one driver sample of delay
        let mut y = [0.0; 2];
        let mut e = 0.0;
        for k in 0..16_000 {
            stage.plant_output(&mut y);
            e = v * k as f64 * DT - y[0];
            let mut f = [0.0];
            c.control(&[e], &mut f);
            stage.advance(&[f_prev]);
            f_prev = f[0];
        }
        assert!(e.abs() < 1e-12, "{e}");
        // f_α settles at v/c.
        assert!((f_prev - v / LinearStageParams::default().motor_constant_m).abs() < 1e-6);
    }

    #[test]
    fn feedforward_2_11_2_12_closed_forms_and_validation() {
        let ff = StepSizeFeedForward {
            v_max_m_s: 2e-3,
            ..Default::default()
        };
        ff.validate().unwrap();
        assert_eq!(ff.amplitude_phase(0.0), (23.0, FRAC_PI_4 - FRAC_PI_2));
        let (a, p) = ff.amplitude_phase(-1e-3);
        assert!(
            (a - 34.5).abs() < 1e-12 && (p - (3.0 * FRAC_PI_4 / 2.0 - FRAC_PI_2)).abs() < 1e-12
        );
        assert_eq!(ff.amplitude_phase(5e-3), (46.0, 0.0));
        assert_eq!(ff.amplitude_phase(f64::NAN), (23.0, FRAC_PI_4 - FRAC_PI_2));
        let bad = StepSizeFeedForward {
            amplitude_min_v: 40.0,
            amplitude_max_v: 30.0,
            ..ff
        };
        assert_eq!(bad.validate().unwrap_err().field, "amplitude_min_v");
        let bad = StepSizeFeedForward {
            v_max_m_s: 0.0,
            ..ff
        };
        assert_eq!(bad.validate().unwrap_err().field, "v_max_m_s");
        let bad = StepSizeFeedForward {
            amplitude_max_v: 50.0,
            ..ff
        };
        assert_eq!(bad.validate().unwrap_err().field, "amplitude_max_v");
        let mut b: Box<dyn Block> = nanomotion_core::yaml::from_str(
            "type: walking_piezo_feedforward\nv_max_m_s: 0.002\n",
            "test",
        )
        .unwrap();
        b.build(&BuildContext::new("ff", DT, 0)).unwrap();
        let mut y = [0.0; 3];
        b.output(Tick::new(0, DT), &[2e-3], &mut y);
        assert_eq!(y, [46.0, 0.0, FRAC_PI_2]);
        let info = allocation_counter::measure(|| {
            for k in 0..1000 {
                b.output(Tick::new(k, DT), &[k as f64 * 1e-6], &mut y);
            }
        });
        assert_eq!(info.count_total, 0);
    }
}
