//! The simulated 3-DOF metrological AFM stage (Sec. 6.2, Fig. 6.2; model (7.1)).
//!
//! Signal path per sample k, for the axes i ∈ {x, y, z}:
//!
//! 1. the drive voltage V_i is clipped to [`v_min_v`, `v_max_v`] (clipping is
//!    reported on the `saturated` output and counted);
//! 2. a piezo-stack hysteresis h_i = H_i(V_i) (asymmetric Coleman–Hodgdon operator,
//!    µm) — the "true" hysteresis that the extended model (6.4) is later fitted to;
//! 3. linear dynamics, continuous-time and discretised exactly (ZOH) at the block's
//!    rate: a diagonal 2nd-order mode per axis (resonances 124/126 Hz of Ch. 7 for
//!    x/y), static coupling S (≈ −40 dB) through the diagonal modes and dynamic
//!    coupling D through a parasitic mode (default 400 Hz), so that
//!    P_ji(s) = (δ_ji + S_ji) G_i(s) + D_ji G_c(s);
//! 4. interferometer outputs: position + bounded noise (Table 6.1: ±5/±4/±2 nm),
//!    quantised to 0.15 nm;
//! 5. cantilever deflection for constant-force imaging: δ = z + h_s(x, y) − z_contact,
//!    with the sample topography h_s a grating of steps that is a function of the
//!    in-plane position (so that a rotated sample matters), 0.05 nm resolution,
//!    ±0.15 nm noise.
//!
//! The reading of Table 6.1's lost zeros is ours: interferometer resolution
//! 0.15 nm; head resolution 0.05 nm with noise bound ±0.15 nm.

use crate::error::AfmError;
use crate::hysteresis::{CH_NAMES_UM_V, ChParams, ColemanHodgdon};
use nalgebra::DMatrix;
use nanomotion_core::Params;
use nanomotion_core::block::check;
use nanomotion_core::lti::{C2dMethod, SsStepper, StateSpace};
use nanomotion_core::rng::Rng;
use nanomotion_core::{Block, BuildContext, ParamError, Plant, Tick, declared_block};
use serde::{Deserialize, Serialize};
use std::f64::consts::TAU;

/// Number of outputs of [`AfmStage`] in [`Plant::plant_output`] order:
/// pos\[3\], deflection\[1\], true_pos\[3\], saturated\[3\].
pub const N_OUTPUTS: usize = 10;

/// Hysteresis of one axis: trace and retrace Coleman–Hodgdon sets (µm, V).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct AxisHysteresis {
    /// Parameters for increasing voltage.
    pub trace: ChParams,
    /// Parameters for decreasing voltage.
    pub retrace: ChParams,
}

/// Sample topography h_s(x, y) (m).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize, Params)]
#[serde(deny_unknown_fields, rename_all = "snake_case")]
pub enum Topography {
    /// A flat sample.
    Flat,
    /// A line grating of rectangular steps: height `height_m` where
    /// frac((x cos θ + y sin θ − offset_m)/pitch_m) < duty, else 0.
    Grating {
        /// Pitch (m).
        #[param(positive)]
        pitch_m: f64,
        /// Step height (m).
        #[param(finite)]
        height_m: f64,
        /// Fraction of a pitch that is raised.
        #[param(range(0.0, 1.0))]
        duty: f64,
        /// Rotation θ of the grating lines' normal from the x-axis (rad).
        #[param(finite)]
        angle_rad: f64,
        /// Shift of the pattern along its normal (m).
        #[serde(default)]
        #[param(finite)]
        offset_m: f64,
    },
}

impl Topography {
    /// Height (m) at in-plane position (x, y) (m).
    pub fn height(&self, x: f64, y: f64) -> f64 {
        match *self {
            Topography::Flat => 0.0,
            Topography::Grating {
                pitch_m,
                height_m,
                duty,
                angle_rad,
                offset_m,
            } => {
                let s = (x * angle_rad.cos() + y * angle_rad.sin() - offset_m) / pitch_m;
                if s - s.floor() < duty { height_m } else { 0.0 }
            }
        }
    }
}

/// `afm_stage`: 3-DOF metrological AFM stage (Ch. 6-7): piezo hysteresis, 2nd-order
/// modes, static+dynamic coupling, interferometers (Table 6.1), cantilever deflection
/// over a grating.
///
/// The 3-DOF metrological AFM stage (see the [module docs](self)).
///
/// ```
/// use afm_stage::stage::AfmStage;
/// use nanomotion_core::{Block, BuildContext, Plant};
/// let mut s = AfmStage::default();
/// s.build(&BuildContext::new("stage", 1e-4, 7)).unwrap();
/// let mut y = [0.0; afm_stage::stage::N_OUTPUTS];
/// for _ in 0..20_000 { s.advance(&[50.0, 0.0, 0.0]); }
/// s.plant_output(&mut y);
/// // x follows the virgin hysteresis curve: bV − k(1 − e^{−αV}) = 50 − 10(1 − e^{−1.5}) µm.
/// let want = 50.0 - 10.0 * (1.0 - (-1.5f64).exp());
/// assert!((y[4] * 1e6 - want).abs() < 1e-6);
/// ```
#[derive(Debug, Clone, Serialize, Deserialize, Params)]
#[serde(default, deny_unknown_fields)]
#[block(type_name = "afm_stage", role = Plant, ports = "v[3] (V) \"on the x, y, z piezo stacks\" -> pos[3] (m) \"by the interferometers\", deflection (m) \"of the cantilever\", true_pos[3] (m) \"without noise\", saturated[3] \"1 where the last input was clipped\"")]
pub struct AfmStage {
    /// Lowest drive voltage (V); lower inputs are clipped and reported.
    #[param(at_most = v_max_v)]
    pub v_min_v: f64,
    /// Highest drive voltage (V).
    pub v_max_v: f64,
    /// Per-axis hysteresis [x, y, z] (Coleman–Hodgdon trace/retrace sets, µm and V).
    /// Each axis: {trace: {alpha_per_v, b_um_per_v, u_um_per_v}, retrace: {...}}
    /// (Coleman–Hodgdon, (6.3)).
    #[param(default_doc = "asymmetric, ~1 µm/V x/y, 0.2 µm/V z")]
    pub hysteresis: [AxisHysteresis; 3],
    /// Resonance of each diagonal mode (Hz); Ch. 7: 124 Hz (x), 126 Hz (y).
    #[param(default_doc = "[124, 126, 350]")]
    pub resonance_hz: [f64; 3],
    /// Relative damping ζ of each diagonal mode (-).
    #[param(positive, default_doc = "[0.05, 0.05, 0.05]")]
    pub damping: [f64; 3],
    /// Static coupling S (row = output j, column = input i; diagonal ignored), (-).
    /// 3×3, row-major.
    #[param(finite, default_doc = "≈0.005")]
    pub static_coupling: [[f64; 3]; 3],
    /// Dynamic coupling D through the parasitic mode (row = output, column = input), (-).
    #[param(finite, default_doc = "≈0.005 (static + dynamic ≈ −40 dB at DC)")]
    pub dynamic_coupling: [[f64; 3]; 3],
    /// Parasitic mode frequency (Hz).
    #[param(positive)]
    pub parasitic_hz: f64,
    /// Parasitic mode damping (-).
    #[param(positive)]
    pub parasitic_damping: f64,
    /// Interferometer resolution per axis (m), Table 6.1: 0.15 nm.
    #[param(non_negative)]
    pub resolution_m: [f64; 3],
    /// Interferometer noise bound per axis (m), Table 6.1: ±5, ±4, ±2 nm. The noise is
    /// Gaussian with σ = bound/3, truncated at the bound.
    #[param(non_negative)]
    pub noise_bound_m: [f64; 3],
    /// Cantilever deflection resolution (m).
    #[param(non_negative)]
    pub deflection_resolution_m: f64,
    /// Cantilever deflection noise bound (m).
    #[param(non_negative)]
    pub deflection_noise_bound_m: f64,
    /// Sample topography.
    #[param(nested, default_doc = "grating 10 µm pitch, 20 nm steps")]
    pub topography: Topography,
    /// Stage z position at which the tip touches a zero-height sample (m).
    #[param(finite)]
    pub contact_z_m: f64,
    /// Initial drive voltages (V), reached along the virgin curve from 0 V.
    #[param(default_doc = "[0, 0, 0]")]
    pub initial_v: [f64; 3],
    #[serde(skip)]
    rt: Option<Runtime>,
}

#[derive(Debug, Clone)]
struct Runtime {
    hyst: [ColemanHodgdon; 3],
    dyn_: SsStepper,
    h_um: [f64; 3],
    pos_m: [f64; 3],
    noise: [f64; 4],
    saturated: [f64; 3],
    clip_count: u64,
    rng: Rng,
}

impl Default for AfmStage {
    /// The Ch. 6–7 stage (a graph file may leave any field out).
    fn default() -> Self {
        Self {
            v_min_v: 0.0,
            v_max_v: 100.0,
            hysteresis: [
                AxisHysteresis {
                    trace: ChParams::new(0.03, 1.0, 0.7),
                    retrace: ChParams::new(0.045, 0.93, 0.62),
                },
                AxisHysteresis {
                    trace: ChParams::new(0.032, 0.98, 0.69),
                    retrace: ChParams::new(0.043, 0.92, 0.61),
                },
                AxisHysteresis {
                    trace: ChParams::new(0.03, 0.2, 0.14),
                    retrace: ChParams::new(0.045, 0.186, 0.124),
                },
            ],
            resonance_hz: [124.0, 126.0, 350.0],
            damping: [0.05, 0.05, 0.05],
            static_coupling: [
                [0.0, 0.005, 0.003],
                [0.005, 0.0, 0.003],
                [0.002, 0.002, 0.0],
            ],
            dynamic_coupling: [
                [0.0, 0.005, 0.002],
                [0.005, 0.0, 0.002],
                [0.002, 0.002, 0.0],
            ],
            parasitic_hz: 400.0,
            parasitic_damping: 0.02,
            resolution_m: [0.15e-9; 3],
            noise_bound_m: [5e-9, 4e-9, 2e-9],
            deflection_resolution_m: 0.05e-9,
            deflection_noise_bound_m: 0.15e-9,
            topography: Topography::Grating {
                pitch_m: 10e-6,
                height_m: 20e-9,
                duty: 0.5,
                angle_rad: 0.0,
                offset_m: 0.0,
            },
            contact_z_m: 10e-6,
            initial_v: [0.0; 3],
            rt: None,
        }
    }
}

fn quantise(x: f64, q: f64) -> f64 {
    if q > 0.0 { (x / q).round() * q } else { x }
}

fn bounded_noise(rng: &mut Rng, bound: f64) -> f64 {
    if bound <= 0.0 {
        return 0.0;
    }
    (bound / 3.0 * rng.normal()).clamp(-bound, bound)
}

impl AfmStage {
    /// The stage without any measurement noise (for analysis and tests).
    pub fn noiseless() -> Self {
        Self {
            noise_bound_m: [0.0; 3],
            deflection_noise_bound_m: 0.0,
            ..Self::default()
        }
    }

    /// Continuous-time linear part (12 states): from the hysteresis outputs
    /// h\[3\] (µm) to the positions \[3\] (m).
    pub fn linear_model(&self) -> Result<StateSpace, AfmError> {
        let mut a = DMatrix::zeros(12, 12);
        let mut b = DMatrix::zeros(12, 3);
        let mut c = DMatrix::zeros(3, 12);
        let wc = TAU * self.parasitic_hz;
        for i in 0..3 {
            let w = TAU * self.resonance_hz[i];
            for (k, (ww, z)) in [(w, self.damping[i]), (wc, self.parasitic_damping)]
                .into_iter()
                .enumerate()
            {
                let o = 6 * k + 2 * i; // diagonal modes in 0..6, parasitic modes in 6..12
                a[(o, o + 1)] = 1.0;
                a[(o + 1, o)] = -ww * ww;
                a[(o + 1, o + 1)] = -2.0 * z * ww;
                b[(o + 1, i)] = ww * ww;
            }
            for j in 0..3 {
                let s = if i == j {
                    1.0
                } else {
                    self.static_coupling[j][i]
                };
                c[(j, 2 * i)] = 1e-6 * s;
                if i != j {
                    c[(j, 6 + 2 * i)] = 1e-6 * self.dynamic_coupling[j][i];
                }
            }
        }
        StateSpace::new(a, b, c, DMatrix::zeros(3, 3), None)
            .map_err(|e| AfmError::param("dynamics", e.to_string()))
    }

    /// Small-signal model from the voltages (V) to the positions (m) around a
    /// hysteresis sensitivity `gain_um_per_v` per axis.
    pub fn small_signal_model(&self, gain_um_per_v: [f64; 3]) -> Result<StateSpace, AfmError> {
        let mut m = self.linear_model()?;
        for i in 0..3 {
            for r in 0..m.b.nrows() {
                m.b[(r, i)] *= gain_um_per_v[i];
            }
        }
        Ok(m)
    }

    /// Total number of input samples that were clipped (any axis).
    pub fn clip_count(&self) -> u64 {
        self.rt.as_ref().map_or(0, |r| r.clip_count)
    }

    /// Present hysteresis outputs h (µm).
    pub fn hysteresis_output_um(&self) -> [f64; 3] {
        self.rt.as_ref().map_or([0.0; 3], |r| r.h_um)
    }

    fn validate(&self) -> Result<(), ParamError> {
        self.check_params()?;
        if self.v_min_v == self.v_max_v {
            return Err(ParamError::new(
                "v_max_v",
                "equals v_min_v",
                "give a voltage range of non-zero width",
            ));
        }
        const AX: [&str; 3] = ["x", "y", "z"];
        for i in 0..3 {
            self.hysteresis[i]
                .trace
                .validate_as(&format!("hysteresis[{i}].trace."), &CH_NAMES_UM_V)?;
            self.hysteresis[i]
                .retrace
                .validate_as(&format!("hysteresis[{i}].retrace."), &CH_NAMES_UM_V)?;
            check::positive(
                &format!("resonance_hz[{i}] ({})", AX[i]),
                self.resonance_hz[i],
            )?;
            check::in_range(
                &format!("initial_v[{i}]"),
                self.initial_v[i],
                self.v_min_v,
                self.v_max_v,
            )?;
        }
        Ok(())
    }

    /// Build for sample period `dt` (s) and seed: the same as [`Block::build`].
    fn make_runtime(&self, ctx: &BuildContext) -> Result<Runtime, ParamError> {
        self.validate()?;
        check::positive("dt", ctx.dt)?;
        let nyq = 0.5 / ctx.dt;
        for (i, f) in self.resonance_hz.iter().enumerate() {
            if *f >= nyq {
                return Err(ParamError::new(
                    format!("resonance_hz[{i}]"),
                    format!("{f} Hz is above the Nyquist frequency {nyq} Hz of the block's rate"),
                    "run the stage at a higher rate_hz",
                ));
            }
        }
        let model = self.linear_model()?;
        let d = model.c2d(ctx.dt, C2dMethod::Zoh).map_err(|e| {
            ParamError::new("dynamics", e.to_string(), "check resonance_hz and damping")
        })?;
        let mut dyn_ = SsStepper::new(&d)
            .map_err(|e| ParamError::new("dynamics", e.to_string(), "check the parameters"))?;
        let mut hyst = [0usize, 1, 2].map(|i| {
            ColemanHodgdon::new(self.hysteresis[i].trace, self.hysteresis[i].retrace)
                .expect("validated above")
        });
        let mut h_um = [0.0; 3];
        for i in 0..3 {
            hyst[i].reset(0.0, 0.0);
            h_um[i] = hyst[i].step(self.initial_v[i]);
        }
        dyn_.set_steady_state(&h_um)
            .map_err(|e| ParamError::new("dynamics", e.to_string(), "check the damping"))?;
        let mut pos = [0.0; 3];
        dyn_.output(&h_um, &mut pos);
        let mut rt = Runtime {
            hyst,
            dyn_,
            h_um,
            pos_m: pos,
            noise: [0.0; 4],
            saturated: [0.0; 3],
            clip_count: 0,
            rng: Rng::new(ctx.seed),
        };
        draw_noise(self.noise_bound_m, self.deflection_noise_bound_m, &mut rt);
        Ok(rt)
    }
}

/// Draw the measurement noise of the next output.
fn draw_noise(bounds: [f64; 3], defl_bound: f64, rt: &mut Runtime) {
    for (i, b) in bounds.iter().enumerate() {
        rt.noise[i] = bounded_noise(&mut rt.rng, *b);
    }
    rt.noise[3] = bounded_noise(&mut rt.rng, defl_bound);
}

impl Plant for AfmStage {
    /// pos\[3\], deflection, true_pos\[3\], saturated\[3\] (see [`N_OUTPUTS`]).
    fn plant_output(&self, y: &mut [f64]) {
        let Some(rt) = self.rt.as_ref() else {
            y[..N_OUTPUTS].fill(0.0);
            return;
        };
        for i in 0..3 {
            y[i] = quantise(rt.pos_m[i] + rt.noise[i], self.resolution_m[i]);
            y[4 + i] = rt.pos_m[i];
            y[7 + i] = rt.saturated[i];
        }
        let p = rt.pos_m;
        let defl = p[2] + self.topography.height(p[0], p[1]) - self.contact_z_m;
        y[3] = quantise(defl + rt.noise[3], self.deflection_resolution_m);
    }

    fn advance(&mut self, u: &[f64]) {
        let (vmin, vmax) = (self.v_min_v, self.v_max_v);
        let Some(rt) = self.rt.as_mut() else { return };
        let mut clipped = false;
        for i in 0..3 {
            let v = if u[i].is_nan() { vmin } else { u[i] };
            let vc = v.clamp(vmin, vmax);
            rt.saturated[i] = if vc != u[i] { 1.0 } else { 0.0 };
            clipped |= vc != u[i];
            rt.h_um[i] = rt.hyst[i].step(vc);
        }
        if clipped {
            rt.clip_count += 1;
        }
        let h = rt.h_um;
        rt.dyn_.update(&h);
        let mut pos = [0.0; 3];
        rt.dyn_.output(&h, &mut pos);
        rt.pos_m = pos;
        draw_noise(self.noise_bound_m, self.deflection_noise_bound_m, rt);
    }
}

#[declared_block]
impl Block for AfmStage {
    fn direct_feedthrough(&self) -> bool {
        false
    }
    fn build(&mut self, ctx: &BuildContext) -> Result<(), ParamError> {
        self.rt = Some(self.make_runtime(ctx)?);
        Ok(())
    }
    fn output(&mut self, _tick: Tick, _u: &[f64], y: &mut [f64]) {
        self.plant_output(y);
    }
    fn update(&mut self, _tick: Tick, u: &[f64]) {
        self.advance(u);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use nanomotion_core::lti::Complex;

    const DT: f64 = 1e-4;

    fn built(s: AfmStage, seed: u64) -> AfmStage {
        let mut s = s;
        s.build(&BuildContext::new("stage", DT, seed)).unwrap();
        s
    }

    #[test]
    fn declared_bounds_name_the_topography_and_per_axis_fields() {
        let err = |s: AfmStage| {
            let e = s
                .clone()
                .build(&BuildContext::new("stage", DT, 0))
                .unwrap_err();
            (e.field, e.problem)
        };
        let mut s = AfmStage {
            topography: Topography::Grating {
                pitch_m: 10e-6,
                height_m: 20e-9,
                duty: 1.5,
                angle_rad: 0.0,
                offset_m: 0.0,
            },
            ..AfmStage::default()
        };
        assert_eq!(
            err(s.clone()),
            ("topography.duty".into(), "is 1.5, outside [0, 1]".into())
        );
        s.topography = Topography::Grating {
            pitch_m: 0.0,
            height_m: 20e-9,
            duty: 0.5,
            angle_rad: 0.0,
            offset_m: f64::NAN,
        };
        assert_eq!(err(s.clone()).0, "topography.pitch_m");
        s.topography = Topography::Flat;
        s.damping[2] = -0.1;
        assert_eq!(
            err(s.clone()),
            ("damping[2]".into(), "is -0.1, must be > 0".into())
        );
        s.damping[2] = 0.05;
        s.dynamic_coupling[1][2] = f64::INFINITY;
        assert_eq!(err(s.clone()).0, "dynamic_coupling[1][2]");
        s.dynamic_coupling[1][2] = 0.0;
        s.noise_bound_m[0] = -1e-9;
        assert_eq!(err(s.clone()).0, "noise_bound_m[0]");
        s.noise_bound_m[0] = 1e-9;
        assert!(s.build(&BuildContext::new("stage", DT, 0)).is_ok());
    }

    #[test]
    fn static_response_is_hysteresis_times_coupling() {
        let mut s = built(AfmStage::noiseless(), 0);
        let mut y = [0.0; N_OUTPUTS];
        for _ in 0..20_000 {
            s.advance(&[40.0, 20.0, 10.0]);
        }
        s.plant_output(&mut y);
        // Independent computation: virgin curves bV − k(1 − e^{−αV}).
        let h: Vec<f64> = (0..3)
            .map(|i| {
                let p = s.hysteresis[i].trace;
                let v = [40.0, 20.0, 10.0][i];
                p.b * v - p.k() * (1.0 - (-p.alpha * v).exp())
            })
            .collect();
        for j in 0..3 {
            let mut want = 0.0;
            for i in 0..3 {
                let g = if i == j {
                    1.0
                } else {
                    s.static_coupling[j][i] + s.dynamic_coupling[j][i]
                };
                want += g * h[i] * 1e-6;
            }
            assert!(
                (y[4 + j] - want).abs() < 1e-12,
                "axis {j}: {} vs {want}",
                y[4 + j]
            );
            // Noiseless: the interferometer reads the quantised true position.
            assert!((y[j] - want).abs() <= 0.075e-9 + 1e-18);
        }
    }

    #[test]
    fn coupling_is_minus_40_db_below_100_hz_and_resonances_sit_where_asked() {
        let s = AfmStage::default();
        let m = s.linear_model().unwrap();
        for f in [1.0, 10.0, 50.0] {
            let g = m.evalfr(Complex::new(0.0, TAU * f));
            for j in 0..3 {
                for i in 0..3 {
                    if i != j {
                        let db = 20.0 * (g[(j, i)].norm() / g[(i, i)].norm()).log10();
                        assert!(db < -35.0 && db > -55.0, "f={f}: P{j}{i} at {db} dB");
                    }
                }
            }
        }
        // Peak of |P_xx| at ≈124 Hz (ω_peak = ω√(1−2ζ²)).
        let peak = (1000..1400)
            .map(|k| k as f64 * 0.1)
            .max_by(|a, b| {
                let ga = m.evalfr(Complex::new(0.0, TAU * a))[(0, 0)].norm();
                let gb = m.evalfr(Complex::new(0.0, TAU * b))[(0, 0)].norm();
                ga.partial_cmp(&gb).unwrap()
            })
            .unwrap();
        let want = 124.0 * (1.0f64 - 2.0 * 0.05 * 0.05).sqrt();
        assert!((peak - want).abs() < 0.2, "{peak} vs {want}");
    }

    #[test]
    fn noise_is_bounded_seeded_and_quantised() {
        let mut a = built(AfmStage::default(), 3);
        let mut b = built(AfmStage::default(), 3);
        let mut c = built(AfmStage::default(), 4);
        let (mut ya, mut yb, mut yc) = ([0.0; N_OUTPUTS], [0.0; N_OUTPUTS], [0.0; N_OUTPUTS]);
        let mut max_err = [0.0f64; 3];
        let mut differs = false;
        let mut sq = [0.0; 3];
        let n = 20_000;
        for _ in 0..n {
            a.plant_output(&mut ya);
            b.plant_output(&mut yb);
            c.plant_output(&mut yc);
            assert_eq!(ya.map(f64::to_bits), yb.map(f64::to_bits));
            differs |= ya[0] != yc[0];
            for i in 0..3 {
                let e = ya[i] - ya[4 + i];
                max_err[i] = max_err[i].max(e.abs());
                sq[i] += e * e;
                let q = ya[i] / 0.15e-9;
                assert!((q - q.round()).abs() < 1e-6);
            }
            for s in [&mut a, &mut b, &mut c] {
                s.advance(&[10.0, 10.0, 10.0]);
            }
        }
        assert!(differs);
        for i in 0..3 {
            let bound = a.noise_bound_m[i];
            assert!(
                max_err[i] <= bound + 0.075e-9 + 1e-18,
                "axis {i}: {}",
                max_err[i]
            );
            // σ = bound/3 (plus quantisation variance q²/12, and a ~0.3 % truncation loss).
            let rms = (sq[i] / n as f64).sqrt();
            let want = ((bound / 3.0).powi(2) + 0.15e-9f64.powi(2) / 12.0).sqrt();
            assert!(
                (rms / want - 1.0).abs() < 0.03,
                "axis {i}: rms {rms} want {want}"
            );
        }
    }

    #[test]
    fn deflection_follows_the_grating_and_rotation_matters() {
        let mut s = AfmStage::noiseless();
        s.contact_z_m = 0.0;
        let mut s = built(s, 0);
        let g = AfmStage::default().topography;
        assert_eq!(g.height(2e-6, 0.0), 20e-9);
        assert_eq!(g.height(7e-6, 0.0), 0.0);
        let rot = Topography::Grating {
            pitch_m: 10e-6,
            height_m: 20e-9,
            duty: 0.5,
            angle_rad: std::f64::consts::FRAC_PI_2,
            offset_m: 0.0,
        };
        assert_eq!(rot.height(7e-6, 2e-6), 20e-9);
        // Move x to ~2.9 µm (inside a raised stripe), z to ~1.1 µm.
        let mut y = [0.0; N_OUTPUTS];
        for _ in 0..20_000 {
            s.advance(&[3.0, 0.0, 6.0]);
        }
        s.plant_output(&mut y);
        let want = y[6] + s.topography.height(y[4], y[5]);
        assert!((y[3] - want).abs() <= 0.025e-9 + 1e-18);
        assert!(s.topography.height(y[4], y[5]) > 0.0);
    }

    #[test]
    fn clipping_is_reported_and_nan_is_safe() {
        let mut s = built(AfmStage::noiseless(), 0);
        let mut y = [0.0; N_OUTPUTS];
        s.advance(&[150.0, -5.0, f64::NAN]);
        s.plant_output(&mut y);
        assert_eq!(&y[7..10], &[1.0, 1.0, 1.0]);
        assert_eq!(s.clip_count(), 1);
        assert!(y.iter().all(|v| v.is_finite()));
        assert_eq!(s.hysteresis_output_um()[1], 0.0);
        s.advance(&[50.0, 5.0, 5.0]);
        s.plant_output(&mut y);
        assert_eq!(&y[7..10], &[0.0, 0.0, 0.0]);
        assert_eq!(s.clip_count(), 1);
    }

    #[test]
    fn bad_parameters_name_the_field() {
        let err = |s: AfmStage| {
            let mut s = s;
            s.build(&BuildContext::new("s", DT, 0)).unwrap_err().field
        };
        assert_eq!(
            err(AfmStage {
                v_max_v: -1.0,
                ..AfmStage::default()
            }),
            "v_min_v"
        );
        assert_eq!(
            err(AfmStage {
                resonance_hz: [124.0, 126.0, 6000.0],
                ..AfmStage::default()
            }),
            "resonance_hz[2]"
        );
        let mut h = AfmStage::default().hysteresis;
        h[1].retrace.alpha = -1.0;
        assert_eq!(
            err(AfmStage {
                hysteresis: h,
                ..AfmStage::default()
            }),
            "hysteresis[1].retrace.alpha_per_v"
        );
        assert_eq!(
            err(AfmStage {
                parasitic_damping: f64::NAN,
                ..AfmStage::default()
            }),
            "parasitic_damping"
        );
        let yaml = "type: afm_stage\nbogus: 1\n";
        assert!(nanomotion_core::yaml::from_str::<Box<dyn Block>>(yaml, "t").is_err());
    }

    #[test]
    fn yaml_round_trip_and_no_allocation_in_ticks() {
        let yaml = "type: afm_stage\nresonance_hz: [124, 126, 400]\ntopography: flat\n";
        let mut b: Box<dyn Block> = nanomotion_core::yaml::from_str(yaml, "t").unwrap();
        b.build(&BuildContext::new("s", DT, 1)).unwrap();
        assert!(!b.direct_feedthrough());
        assert_eq!(
            b.outputs().iter().map(|p| p.width).sum::<usize>(),
            N_OUTPUTS
        );
        let mut y = [0.0; N_OUTPUTS];
        let info = allocation_counter::measure(|| {
            for k in 0..10_000u64 {
                let t = Tick::new(k, DT);
                let v = 50.0 + 40.0 * (k as f64 * 1e-3).sin();
                b.output(t, &[v, v, v], &mut y);
                b.update(t, &[v, v, v]);
            }
        });
        assert_eq!(info.count_total, 0);
    }
}
