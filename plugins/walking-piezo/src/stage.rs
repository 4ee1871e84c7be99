//! The Ch. 4 nonlinear stage model: leg kinematics (4.2), the y-model with
//! one-sided nonlinear contacts sharing the preload (4.11)–(4.15), and the x-model
//! with set-valued Coulomb friction (4.7)–(4.10), advanced by the dedicated
//! time-stepping scheme of Sec. 4.3.4:
//!
//! 1. take the state at t_A and the piezo forces from the voltages (4.2), (4.7);
//! 2. solve the y-model for the normal forces F_N1,2 ([`crate::contact`]);
//! 3. start from the previous step's friction forces;
//! 4. fixed-point iteration with the proximal point (4.18)–(4.19)
//!    ([`crate::friction`]).
//!
//! The friction coefficient varies (seeded) per pair, along the strip and in time
//! ([`crate::variation`]). With the default parameters the loaded pair never
//! reaches its friction limit, so that variation does not change the step. The
//! optional drive-strip height profile (`strip_height_rms_m`, off by default,
//! [`crate::variation::StripProfile`]) shifts each pair's contact (hence the
//! preload split and the take-over point) and tilts its contact normal (hence
//! where a pair slips), so the step per α cycle varies from cycle to cycle as on
//! the real stage ("roughness of the drive strip, contamination", Sec. 4.4).
//!
//! [`WalkingPiezoStage`] is the plain Rust model; [`WalkingPiezoStageBlock`] is the
//! graph block `walking_piezo_stage`.

use crate::contact::{ContactLaw, YSolution, solve_y};
use crate::friction::{FixedPointSettings, XCoefficients, XState, step_x};
use crate::kinematics::{C_X_M_PER_V, C_Y_M_PER_V, LegKinematics};
use crate::variation::{MuVariation, MuVariationParams, StripProfile, StripProfileParams};
use nanomotion_core::Params;
use nanomotion_core::block::check;
use nanomotion_core::{Block, BuildContext, ParamError, Plant, Tick, declared_block};
use serde::{Deserialize, Serialize};
use std::f64::consts::PI;
use thiserror::Error;

// ---------------------------------------------------------------------------
// Parameters
// ---------------------------------------------------------------------------

/// Parameters of the nonlinear stage. Defaults are the thesis's values where the
/// text gives them (Sec. 4.4.1, Ch. 5); Table 4.1's identified values (dampings,
/// per-stack coefficients, μ) and q1 lost their digits in the text, so those
/// defaults are physically reasoned and marked as such.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, Params)]
#[serde(default, deny_unknown_fields)]
pub struct StageParams {
    /// Stage mass M_s (kg); thesis: 0.428 kg (weighed).
    #[param(positive)]
    pub stage_mass_kg: f64,
    /// Leg stiffness k_x1, k_x2 (N/m); thesis: from M_s and the 543 Hz resonance,
    /// k_x = 4π²M_s·543² = 4.98·10⁶ N/m.
    #[param(positive)]
    pub leg_stiffness_x_n_m: [f64; 2],
    /// Leg damping d_x1, d_x2 (N·s/m). Table 4.1 value lost; default 100 N·s/m
    /// (ζ ≈ 0.03 at the 543 Hz mode).
    #[param(non_negative)]
    pub leg_damping_x_ns_m: [f64; 2],
    /// Leg stiffness k_y1, k_y2 (N/m); thesis: EA/L = 70 GPa·9 mm²/4 mm.
    #[param(positive)]
    pub leg_stiffness_y_n_m: [f64; 2],
    /// Leg damping d_y1, d_y2 (N·s/m). Table 4.1 value lost; default 5000 N·s/m
    /// ("the damping in the piezo legs is very high", time constant ≈ 30 µs).
    #[param(non_negative)]
    pub leg_damping_y_ns_m: [f64; 2],
    /// Bending coefficients c_x1..c_x4 (m/V) of (4.2); default 64.5 nm/V (Ch. 5).
    pub c_x_m_v: [f64; 4],
    /// Extension coefficients c_y1..c_y4 (m/V) of (4.2); default 29.8 nm/V (Ch. 5).
    pub c_y_m_v: [f64; 4],
    /// Preload F_p (N); thesis: 55 N.
    #[param(positive)]
    pub preload_n: f64,
    /// Contact law q1 (m·N^−q2) of (4.4). Thesis value lost; default 1.5·10⁻⁸, a
    /// deformation of ≈ 0.1 µm per pair at half the preload (Fig. 4.3 scale).
    pub contact_q1: f64,
    /// Contact law exponent q2 (−) of (4.4); thesis: 0.75.
    pub contact_q2: f64,
    /// Nominal friction coefficient μ (−). Table 4.1 value lost; default 0.2
    /// (holding force μF_p ≈ 11 N).
    #[param(non_negative)]
    pub mu: f64,
    /// Relative standard deviation of the per-pair μ difference.
    #[param(non_negative)]
    pub mu_pair_rel: f64,
    /// Relative standard deviation of μ along the drive strip.
    #[param(non_negative)]
    pub mu_spatial_rel: f64,
    /// Correlation length of μ along the strip (m).
    #[param(positive)]
    pub mu_spatial_corr_m: f64,
    /// Relative standard deviation of μ in time.
    #[param(non_negative)]
    pub mu_temporal_rel: f64,
    /// Correlation time of μ in time (s).
    #[param(positive)]
    pub mu_temporal_tau_s: f64,
    /// rms height σ_h (m) of the drive strip's surface profile (roughness and
    /// waviness, seeded; [`crate::variation::StripProfile`]). Default 0: a flat
    /// strip, the model as identified in Ch. 4. A height h under a pair shifts
    /// its contact by h (penetration s = housing + leg − h), which moves the
    /// preload split between the pairs and the take-over point; the slope h'
    /// tilts the contact normal (x-force −F_N·h' on the stage, reacted on the
    /// leg), which decides when a pair slips on a steep spot. So the step per α
    /// cycle varies from cycle to cycle.
    #[param(non_negative)]
    pub strip_height_rms_m: f64,
    /// Correlation length of the strip profile (m); default 2 µm, a fraction of
    /// a step (≈ 7 µm per cycle), so each touch-down lands on a fresh height.
    #[param(positive)]
    pub strip_height_corr_m: f64,
    /// Pitch of the four legs A, B, C, D along the strip (m); default 2 mm. The
    /// pair {A, D} sees the mean height under A and D, {B, C} under B and C.
    #[param(non_negative)]
    pub strip_leg_pitch_m: f64,
    /// Internal sub-steps per block period (the thesis's Δt = 25 µs is one step at
    /// 40 kHz, or 10 sub-steps at 4 kHz).
    #[param(range(1, MAX_SUBSTEPS), hint = "or raise the block's rate_hz")]
    pub substeps: u32,
    /// r of (4.18) (N·s/m); leave out for r* = 2/(λ_min(W) + λ_max(W)), the
    /// fastest; must be below 2/λ_max(W).
    #[serde(skip_serializing_if = "Option::is_none")]
    #[param(default_doc = "optimal r* = 2/(λ_min+λ_max)")]
    pub prox_r: Option<f64>,
    /// Tolerance ε on |λ^{L+1} − λ^L| (N).
    #[param(positive)]
    pub tol_n: f64,
    /// Iteration cap of the fixed-point iteration; hitting it is counted and
    /// reported.
    #[param(range(1, MAX_ITER), hint = "e.g. 200")]
    pub max_iter: u32,
    /// Add an input port `f_ext` (N): an external force on the stage.
    pub external_force_input: bool,
}

/// Most internal sub-steps per block period of `walking_piezo_stage`: 1000.
pub const MAX_SUBSTEPS: u32 = 1000;
/// Most fixed-point iterations per sub-step of `walking_piezo_stage`: 100 000.
pub const MAX_ITER: u32 = 100_000;

impl Default for StageParams {
    /// The defaults of every field (a graph file may leave any out).
    fn default() -> Self {
        let k_x = 4.0 * PI * PI * 0.428 * 543.0 * 543.0;
        Self {
            stage_mass_kg: 0.428,
            leg_stiffness_x_n_m: [k_x, k_x],
            leg_damping_x_ns_m: [100.0; 2],
            leg_stiffness_y_n_m: [70e9 * 9e-6 / 4e-3; 2],
            leg_damping_y_ns_m: [5e3; 2],
            c_x_m_v: [C_X_M_PER_V; 4],
            c_y_m_v: [C_Y_M_PER_V; 4],
            preload_n: 55.0,
            contact_q1: 1.5e-8,
            contact_q2: 0.75,
            mu: 0.2,
            mu_pair_rel: 0.1,
            mu_spatial_rel: 0.1,
            mu_spatial_corr_m: 20e-6,
            mu_temporal_rel: 0.05,
            mu_temporal_tau_s: 0.5,
            strip_height_rms_m: 0.0,
            strip_height_corr_m: 2e-6,
            strip_leg_pitch_m: 2e-3,
            substeps: 1,
            prox_r: None,
            tol_n: 1e-10,
            max_iter: 200,
            external_force_input: false,
        }
    }
}

impl StageParams {
    /// The same parameters with a constant, equal μ for both pairs (no seeded
    /// variation): the deterministic nominal model.
    pub fn without_mu_variation(mut self) -> Self {
        self.mu_pair_rel = 0.0;
        self.mu_spatial_rel = 0.0;
        self.mu_temporal_rel = 0.0;
        self
    }

    /// The leg kinematics (4.2) of these parameters.
    pub fn kinematics(&self) -> LegKinematics {
        LegKinematics {
            c_x_m_v: self.c_x_m_v,
            c_y_m_v: self.c_y_m_v,
        }
    }

    /// The contact law (4.4).
    pub fn contact_law(&self) -> ContactLaw {
        ContactLaw {
            q1: self.contact_q1,
            q2: self.contact_q2,
        }
    }

    /// Coefficients of one x-step at the sub-step `dt_sub` (s).
    pub fn x_coefficients(&self, dt_sub: f64) -> XCoefficients {
        XCoefficients {
            dt: dt_sub,
            mass: self.stage_mass_kg,
            k: self.leg_stiffness_x_n_m,
            d: self.leg_damping_x_ns_m,
        }
    }

    /// Validate every parameter for a block period `dt` (s); the error names the
    /// field and the fix.
    pub fn validate(&self, dt: f64) -> Result<(), ParamError> {
        check::positive("dt", dt)?;
        self.check_params()?;
        self.kinematics().validate()?;
        self.contact_law().validate()?;
        let xc = self.x_coefficients(dt / f64::from(self.substeps));
        if let Some(r) = self.prox_r {
            check::positive("prox_r", r)?;
            let max = xc.max_r();
            if r >= max {
                return Err(ParamError::new(
                    "prox_r",
                    format!(
                        "r = {r} N·s/m makes the fixed-point iteration diverge: it needs r < 2/λ_max(W) = {max:.4e} at this step"
                    ),
                    format!(
                        "give r < {max:.4e}, or leave prox_r out for the optimal r* = {:.4e}",
                        xc.optimal_r()
                    ),
                ));
            }
        }
        Ok(())
    }
}

// ---------------------------------------------------------------------------
// Rust API
// ---------------------------------------------------------------------------

/// What one [`WalkingPiezoStage::step`] did.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct StepReport {
    /// Largest number of fixed-point iterations over the sub-steps.
    pub iterations: u32,
    /// Largest final |λ^{L+1} − λ^L| over the sub-steps (N).
    pub residual_n: f64,
    /// Largest number of y-solver iterations over the sub-steps.
    pub y_iterations: u32,
}

/// Why a step is not trustworthy.
#[derive(Debug, Clone, Copy, PartialEq, Error)]
pub enum StepError {
    /// An input was NaN or infinite; the step was **not** taken (state held).
    #[error("input {index} is {value}, not finite: step refused, state held")]
    NonFiniteInput {
        /// Index in [u1, u2, u3, u4, f_ext].
        index: usize,
        /// The value.
        value: f64,
    },
    /// The fixed-point iteration hit its cap; the step **was** taken with the last
    /// iterate, which misses the friction law by `residual_n`.
    #[error(
        "friction fixed-point iteration did not converge in {iterations} iterations (residual {residual_n:e} N > tolerance): step taken with the last iterate; lower prox_r or the step, or raise max_iter"
    )]
    NotConverged {
        /// Iterations used.
        iterations: u32,
        /// Final |λ^{L+1} − λ^L| (N).
        residual_n: f64,
    },
    /// The step produced a non-finite state (absurd inputs); the step was **not**
    /// taken (state held).
    #[error("the step produced a non-finite state: step refused, state held")]
    NonFiniteState,
}

/// Counters kept by the model.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct StageCounters {
    /// Steps taken.
    pub steps: u64,
    /// Sub-steps whose fixed-point iteration hit the cap.
    pub nonconverged: u64,
    /// Steps refused for non-finite inputs or state.
    pub faults: u64,
}

/// Every signal of the model at the current state (all SI units).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct StageSignals {
    /// Stage position x_s (m).
    pub x_s: f64,
    /// Stage velocity ẋ_s (m/s).
    pub v_s: f64,
    /// Leg tip x positions x_1, x_2 (m).
    pub x_leg: [f64; 2],
    /// Leg tip penetration into the strip s_1, s_2 (m), negative when lifted off.
    pub y_leg: [f64; 2],
    /// Housing position h (m), towards the strip.
    pub y_h: f64,
    /// Normal forces F_N1, F_N2 (N).
    pub f_n: [f64; 2],
    /// Friction forces λ1, λ2 on the stage (N).
    pub friction: [f64; 2],
    /// Slip velocities ẋ_i − ẋ_s (m/s).
    pub slip: [f64; 2],
    /// Friction coefficients μ1, μ2 of the last step.
    pub mu: [f64; 2],
}

/// Width of [`Plant::plant_output`] of [`WalkingPiezoStage`].
pub const OUTPUT_WIDTH: usize = 20;

/// The nonlinear walking piezo stage (Ch. 4), stepped at a fixed period.
///
/// ```
/// use walking_piezo::{StageParams, WalkingPiezoStage};
/// let p = StageParams::default().without_mu_variation();
/// let mut stage = WalkingPiezoStage::new(p, 25e-6, 1).unwrap();
/// // Hold pair 1 extended, pair 2 retracted: pair 1 carries the whole preload.
/// for _ in 0..100 { stage.step(&[40.0, 40.0, 0.0, 0.0], 0.0).unwrap(); }
/// let s = stage.signals();
/// assert_eq!(s.f_n, [55.0, 0.0]);
/// ```
#[derive(Debug, Clone)]
pub struct WalkingPiezoStage {
    params: StageParams,
    dt_sub: f64,
    kin: LegKinematics,
    law: ContactLaw,
    xc: XCoefficients,
    fp: FixedPointSettings,
    mu_var: MuVariation,
    strip: Option<StripProfile>,
    strip_z: [f64; 2],
    strip_f: [f64; 2],
    seed: u64,
    x: XState,
    y: YSolution,
    lambda: [f64; 2],
    slip: [f64; 2],
    mu: [f64; 2],
    counters: StageCounters,
    last: StepReport,
}

impl WalkingPiezoStage {
    /// Validate `params` and set up a model stepped every `dt` (s), with seeded μ
    /// variation from `seed`. Starts at rest at zero voltage, in static
    /// equilibrium.
    pub fn new(params: StageParams, dt: f64, seed: u64) -> Result<Self, ParamError> {
        params.validate(dt)?;
        let dt_sub = dt / f64::from(params.substeps);
        let xc = params.x_coefficients(dt_sub);
        let fp = FixedPointSettings {
            r: params.prox_r.unwrap_or_else(|| xc.optimal_r()),
            tol_n: params.tol_n,
            max_iter: params.max_iter,
        };
        let mu_var = MuVariation::new(Self::mu_params(&params), dt_sub, seed);
        let strip = Self::strip_profile(&params, seed);
        let mut s = Self {
            kin: params.kinematics(),
            law: params.contact_law(),
            xc,
            fp,
            mu_var,
            strip,
            strip_z: [0.0; 2],
            strip_f: [0.0; 2],
            seed,
            dt_sub,
            params,
            x: XState::default(),
            y: YSolution::default(),
            lambda: [0.0; 2],
            slip: [0.0; 2],
            mu: [0.0; 2],
            counters: StageCounters::default(),
            last: StepReport::default(),
        };
        s.reset();
        Ok(s)
    }

    /// The strip profile of `p`, or `None` for a flat strip.
    fn strip_profile(p: &StageParams, seed: u64) -> Option<StripProfile> {
        (p.strip_height_rms_m > 0.0).then(|| {
            StripProfile::new(
                StripProfileParams {
                    rms_m: p.strip_height_rms_m,
                    corr_m: p.strip_height_corr_m,
                    leg_pitch_m: p.strip_leg_pitch_m,
                },
                seed,
            )
        })
    }

    /// Strip heights (m) under the pairs with the x-state `x` (0 on a flat strip).
    #[inline]
    fn heights_at(strip: &Option<StripProfile>, x: &XState) -> [f64; 2] {
        match strip {
            Some(sp) => sp.pair_heights([x.x_leg[0] - x.x_s, x.x_leg[1] - x.x_s]),
            None => [0.0; 2],
        }
    }

    /// The y-solve (4.13)–(4.15) on a strip whose surface under pair i is set back
    /// by `z[i]`: with e'_i = e_i − z_i the penetration is s_i = h + e'_i and
    /// k e' + d(e' − (e_A − z))/Δt = k(y_p − z) − F_c, i.e. the flat-strip solve
    /// with y_p − z and e_A − z; the leg lengths e = e' + z are stored.
    #[allow(clippy::too_many_arguments)]
    fn solve_y_on_strip(
        law: &ContactLaw,
        p: &StageParams,
        y_p: [f64; 2],
        e_a: [f64; 2],
        z: [f64; 2],
        dt: f64,
        f1_guess: f64,
        flat: bool,
    ) -> YSolution {
        if flat {
            return solve_y(
                law,
                p.preload_n,
                p.leg_stiffness_y_n_m,
                p.leg_damping_y_ns_m,
                y_p,
                e_a,
                dt,
                f1_guess,
            );
        }
        let mut y = solve_y(
            law,
            p.preload_n,
            p.leg_stiffness_y_n_m,
            p.leg_damping_y_ns_m,
            [y_p[0] - z[0], y_p[1] - z[1]],
            [e_a[0] - z[0], e_a[1] - z[1]],
            dt,
            f1_guess,
        );
        y.e = [y.e[0] + z[0], y.e[1] + z[1]];
        y
    }

    fn mu_params(p: &StageParams) -> MuVariationParams {
        MuVariationParams {
            mu: p.mu,
            pair_rel: p.mu_pair_rel,
            spatial_rel: p.mu_spatial_rel,
            spatial_corr_m: p.mu_spatial_corr_m,
            temporal_rel: p.mu_temporal_rel,
            temporal_tau_s: p.mu_temporal_tau_s,
        }
    }

    /// Back to rest at zero voltage (static equilibrium), same seed.
    pub fn reset(&mut self) {
        let p = &self.params;
        // Static equilibrium of the y-model at u = 0 (infinite step: no damping),
        // on the strip heights under the legs at rest.
        self.x = XState::default();
        self.strip_z = Self::heights_at(&self.strip, &self.x);
        self.strip_f = [0.0; 2];
        self.y = Self::solve_y_on_strip(
            &self.law,
            p,
            [0.0; 2],
            [0.0; 2],
            self.strip_z,
            f64::INFINITY,
            0.5 * p.preload_n,
            self.strip.is_none(),
        );
        self.lambda = [0.0; 2];
        self.slip = [0.0; 2];
        self.mu_var = MuVariation::new(Self::mu_params(p), self.dt_sub, self.seed);
        self.mu = [
            p.mu * self.mu_var.pair_scale()[0],
            p.mu * self.mu_var.pair_scale()[1],
        ];
        self.counters = StageCounters::default();
        self.last = StepReport::default();
    }

    /// The parameters.
    pub fn params(&self) -> &StageParams {
        &self.params
    }
    /// The sub-step Δt (s).
    pub fn dt_sub(&self) -> f64 {
        self.dt_sub
    }
    /// The r of (4.18) in use (N·s/m).
    pub fn prox_r(&self) -> f64 {
        self.fp.r
    }
    /// The x-model state.
    pub fn x_state(&self) -> XState {
        self.x
    }
    /// The y-model solution of the last step.
    pub fn y_state(&self) -> YSolution {
        self.y
    }
    /// Counters (steps, non-converged sub-steps, refused steps).
    pub fn counters(&self) -> StageCounters {
        self.counters
    }
    /// Report of the last step.
    pub fn last_report(&self) -> StepReport {
        self.last
    }
    /// Strip heights (m) under pair 1 and pair 2 used in the last sub-step (0 on
    /// a flat strip, `strip_height_rms_m` = 0).
    pub fn strip_heights(&self) -> [f64; 2] {
        self.strip_z
    }
    /// x-forces (N) on the stage from the tilted strip surface under pair 1 and
    /// pair 2 in the last sub-step, −F_Ni·h'(p_i) (0 on a flat strip).
    pub fn strip_forces(&self) -> [f64; 2] {
        self.strip_f
    }
    /// The drive-strip profile, if `strip_height_rms_m` > 0.
    pub fn strip_profile_model(&self) -> Option<&StripProfile> {
        self.strip.as_ref()
    }

    /// All signals at the current state.
    pub fn signals(&self) -> StageSignals {
        StageSignals {
            x_s: self.x.x_s,
            v_s: self.x.v_s,
            x_leg: self.x.x_leg,
            y_leg: self.y.s,
            y_h: self.y.h,
            f_n: self.y.f_n,
            friction: self.lambda,
            slip: self.slip,
            mu: self.mu,
        }
    }

    /// Advance one period with voltages `u` = [u1..u4] (V) and external force
    /// `f_ext` (N) held constant.
    ///
    /// A non-finite input or state refuses the step (state held) and is counted;
    /// a fixed-point iteration that hits its cap is counted and returned as
    /// [`StepError::NotConverged`] — the step is then taken with the last iterate.
    pub fn step(&mut self, u: &[f64; 4], f_ext: f64) -> Result<StepReport, StepError> {
        for (index, &value) in u.iter().chain(std::iter::once(&f_ext)).enumerate() {
            if !value.is_finite() {
                self.counters.faults += 1;
                return Err(StepError::NonFiniteInput { index, value });
            }
        }
        let saved = (
            self.x,
            self.y,
            self.lambda,
            self.slip,
            self.mu,
            self.strip_z,
            self.strip_f,
        );
        let p = &self.params;
        let tips = self.kin.tips(u);
        let f_x = [
            p.leg_stiffness_x_n_m[0] * tips.x[0],
            p.leg_stiffness_x_n_m[1] * tips.x[1],
        ];
        let mut report = StepReport::default();
        let mut worst: Option<(u32, f64)> = None;
        for _ in 0..p.substeps {
            // Step 2: normal forces at t_E, on the strip heights under the tips
            // at t_A (strip coordinates as for μ).
            self.strip_z = Self::heights_at(&self.strip, &self.x);
            self.y = Self::solve_y_on_strip(
                &self.law,
                p,
                tips.y,
                self.y.e,
                self.strip_z,
                self.dt_sub,
                self.y.f_n[0],
                self.strip.is_none(),
            );
            // μ at the strip coordinates under the tips.
            self.mu = self
                .mu_var
                .next([self.x.x_leg[0] - self.x.x_s, self.x.x_leg[1] - self.x.x_s]);
            let bound = [self.mu[0] * self.y.f_n[0], self.mu[1] * self.y.f_n[1]];
            // On a rough strip the contact normal of pair i is tilted by the
            // local slope h'(p_i): its x-component −F_Ni·h' acts on the stage and,
            // reacted, on the leg (first order in the slope). While the pair
            // sticks it only shifts λ; it decides *when* the pair slips
            // (|λ| reaches μF_Ni, the friction cone tilted by the slope).
            let (f_x_eff, f_ext_eff) = match &self.strip {
                Some(sp) => {
                    let sl = sp
                        .pair_slopes([self.x.x_leg[0] - self.x.x_s, self.x.x_leg[1] - self.x.x_s]);
                    self.strip_f = [-self.y.f_n[0] * sl[0], -self.y.f_n[1] * sl[1]];
                    (
                        [f_x[0] - self.strip_f[0], f_x[1] - self.strip_f[1]],
                        f_ext + self.strip_f[0] + self.strip_f[1],
                    )
                }
                None => (f_x, f_ext),
            };
            // Steps 3–4: fixed point from the previous λ.
            let s = step_x(
                &self.xc,
                &self.x,
                &f_x_eff,
                f_ext_eff,
                &bound,
                &self.lambda,
                &self.fp,
            );
            self.x = s.state;
            self.lambda = s.lambda;
            self.slip = s.slip;
            report.iterations = report.iterations.max(s.iterations);
            report.residual_n = report.residual_n.max(s.residual_n);
            report.y_iterations = report.y_iterations.max(self.y.iterations);
            if !s.converged {
                self.counters.nonconverged += 1;
                worst = Some((s.iterations, s.residual_n));
            }
        }
        let finite = self.x.x_s.is_finite()
            && self.x.v_s.is_finite()
            && self
                .x
                .x_leg
                .iter()
                .chain(&self.lambda)
                .chain(&self.y.e)
                .all(|v| v.is_finite())
            && self.y.h.is_finite();
        if !finite {
            (
                self.x,
                self.y,
                self.lambda,
                self.slip,
                self.mu,
                self.strip_z,
                self.strip_f,
            ) = saved;
            self.counters.faults += 1;
            return Err(StepError::NonFiniteState);
        }
        self.counters.steps += 1;
        self.last = report;
        match worst {
            None => Ok(report),
            Some((iterations, residual_n)) => Err(StepError::NotConverged {
                iterations,
                residual_n,
            }),
        }
    }
}

impl Plant for WalkingPiezoStage {
    /// `y` (width [`OUTPUT_WIDTH`]) = `x_s, v_s, x_leg[2], y_leg[2], y_h, f_n[2],
    /// friction[2], slip[2], mu[2], iterations, nonconverged, faults, steps,
    /// y_iterations`.
    fn plant_output(&self, y: &mut [f64]) {
        let s = self.signals();
        y[0] = s.x_s;
        y[1] = s.v_s;
        y[2..4].copy_from_slice(&s.x_leg);
        y[4..6].copy_from_slice(&s.y_leg);
        y[6] = s.y_h;
        y[7..9].copy_from_slice(&s.f_n);
        y[9..11].copy_from_slice(&s.friction);
        y[11..13].copy_from_slice(&s.slip);
        y[13..15].copy_from_slice(&s.mu);
        y[15] = f64::from(self.last.iterations);
        y[16] = self.counters.nonconverged as f64;
        y[17] = self.counters.faults as f64;
        y[18] = self.counters.steps as f64;
        y[19] = f64::from(self.last.y_iterations);
    }
    /// `u` = [u1, u2, u3, u4] (V) or [u1..u4, f_ext (N)]. Errors are counted (see
    /// [`WalkingPiezoStage::counters`]); use [`WalkingPiezoStage::step`] to get them.
    ///
    /// # Panics
    /// If `u` has fewer than 4 elements.
    fn advance(&mut self, u: &[f64]) {
        let f_ext = if u.len() > 4 { u[4] } else { 0.0 };
        let _ = self.step(&[u[0], u[1], u[2], u[3]], f_ext);
    }
}

// ---------------------------------------------------------------------------
// Graph block
// ---------------------------------------------------------------------------

/// `walking_piezo_stage`: walking piezo stage, Ch. 4 nonlinear model: set-valued
/// friction, one-sided contacts, preload sharing, dedicated time-stepping solver
/// (4.16)-(4.19).
///
/// Graph block `walking_piezo_stage`: the nonlinear model of Ch. 4; its
/// ports are those its `#[block(ports = …)]` declares (`f_ext` with
/// `external_force_input: true`).
#[derive(Debug, Clone, Default, Serialize, Deserialize, Params)]
#[serde(transparent)]
#[block(
    type_name = "walking_piezo_stage",
    role = Plant,
    ports = "u[4] (V), f_ext (N) if external_force_input -> x_s, v_s, x_legs[2], y_legs[2], y_h, f_n[2], friction[2], slip[2], mu[2], iterations \"of the last step\", nonconverged \"sub-steps that hit the cap, cumulative\", faults \"refused steps, cumulative\""
)]
pub struct WalkingPiezoStageBlock {
    /// The parameters.
    pub params: StageParams,
    #[serde(skip)]
    sim: Option<WalkingPiezoStage>,
}

impl WalkingPiezoStageBlock {
    /// A block with these parameters (build it before stepping).
    pub fn new(params: StageParams) -> Self {
        Self { params, sim: None }
    }
    /// The model, once built.
    pub fn model(&self) -> Option<&WalkingPiezoStage> {
        self.sim.as_ref()
    }
}

#[declared_block]
impl Block for WalkingPiezoStageBlock {
    fn direct_feedthrough(&self) -> bool {
        false
    }
    fn build(&mut self, ctx: &BuildContext) -> Result<(), ParamError> {
        self.sim = Some(WalkingPiezoStage::new(
            self.params.clone(),
            ctx.dt,
            ctx.seed,
        )?);
        Ok(())
    }
    fn output(&mut self, _tick: Tick, _u: &[f64], y: &mut [f64]) {
        if let Some(s) = &self.sim {
            let mut all = [0.0; OUTPUT_WIDTH];
            s.plant_output(&mut all);
            y.copy_from_slice(&all[..18]);
        }
    }
    fn update(&mut self, _tick: Tick, u: &[f64]) {
        if let Some(s) = &mut self.sim {
            s.advance(u);
        }
    }
}
