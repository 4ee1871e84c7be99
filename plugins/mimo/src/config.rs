//! The `nanomotion synth CONFIG.yaml` design: plant, weights and control rate
//! read from YAML; synthesis, verification, reduction, discretisation, the
//! comparison with a decentralised (7.2) controller and the (7.4) test, as one
//! serialisable [`SynthResult`]. The CLI (facade crate) writes the files and
//! plots.
//!
//! ```yaml
//! plant:                      # (7.1): diagonal second-order terms, constant couplings
//!   coupled:
//!     diagonal: [{gain: 850, f_hz: 124, damping: 0.05}, ...]
//!     coupling: [[0, 8.5, 2.6], [8.5, 0, 2.6], [0.7, 0.7, 0]]
//! # or  plant: {state_space: {a: [[..]], b: .., c: .., d: ..}}
//! weights: {k_s: 0.5, c: 0.5, k_t: 0.5, alpha_t: 10, beta_t: 0.7,
//!           axes: [{f_s1_hz: 8, f_s2_hz: 8, f_s3_hz: 1.0e-6, f_t_hz: 45}, ...]}
//! rate_hz: 20000
//! near_axis_safe_hz: 1.0e-3   # optional: synth::synthesise_near_axis
//! reduce_to: 12               # optional: balanced truncation of K
//! decentralised:              # optional: (7.2) for comparison
//!   axes: [{integrators: 2, lead_zero_hz: 5, lead_pole_hz: 45, lowpass_hz: 120, lowpass_damping: 0.5}, ...]
//!   crossover_hz: [16.7, null, 25.4]
//!   share: [[1, 0]]           # axis 1 takes axis 0's gain
//! controller_block: {error_scale: [1.0e9, 1.0e9, 1.0e9], u_offset: [50, 50, 50]}
//! ```

use crate::block::ControllerModel;
use crate::decentral::{self, LoopShapedAxis};
use crate::error::MimoError;
use crate::plant::CoupledPlant;
use crate::robust::{DecentralisedPoint, decentralised_test};
use crate::synth::{self, LoopReport, Synthesis};
use crate::weights::MixedSensitivityWeights;
use nalgebra::DMatrix;
use nanomotion_core::analysis::CMatrix;
use nanomotion_core::lti::{Complex, StateSpace};
use serde::{Deserialize, Serialize};
use std::f64::consts::TAU;
use std::time::Instant;

/// The plant of a synthesis config.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case", deny_unknown_fields)]
pub enum PlantSpec {
    /// The (7.1) structure.
    Coupled(CoupledPlant),
    /// Any continuous state-space model (lists of rows).
    StateSpace {
        /// A (n × n).
        a: Vec<Vec<f64>>,
        /// B (n × m).
        b: Vec<Vec<f64>>,
        /// C (p × n).
        c: Vec<Vec<f64>>,
        /// D (p × m).
        d: Vec<Vec<f64>>,
    },
}

/// The optional decentralised comparison.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct DecentralisedSpec {
    /// Per-axis shapes of (7.2).
    pub axes: Vec<LoopShapedAxis>,
    /// Crossover target per axis (Hz); null: take the gain from `share`.
    pub crossover_hz: Vec<Option<f64>>,
    /// Pairs [to, from]: axis `to` uses axis `from`'s gain.
    #[serde(default)]
    pub share: Vec<[usize; 2]>,
}

/// Options of the written controller block.
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct BlockOptions {
    /// `error_scale` of the block.
    #[serde(default)]
    pub error_scale: Vec<f64>,
    /// `u_offset` of the block.
    #[serde(default)]
    pub u_offset: Vec<f64>,
    /// `u_min` of the block.
    #[serde(default)]
    pub u_min: Option<f64>,
    /// `u_max` of the block.
    #[serde(default)]
    pub u_max: Option<f64>,
}

fn default_grid() -> [f64; 2] {
    [0.1, 5000.0]
}
fn default_points() -> usize {
    600
}

/// A synthesis config (see the [module docs](self)).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SynthConfig {
    /// The plant.
    pub plant: PlantSpec,
    /// The weights (7.10)–(7.12).
    pub weights: MixedSensitivityWeights,
    /// Control rate (Hz): the controller is discretised by Tustin at this rate.
    pub rate_hz: f64,
    /// Tustin pre-warp frequency (Hz), optional.
    #[serde(default)]
    pub prewarp_hz: Option<f64>,
    /// Optional: solve with the W_S poles below this frequency (Hz) moved up
    /// to it and move the controller's near-integrators back exactly
    /// ([`synth::synthesise_near_axis`]); reaches the optimal γ for the
    /// thesis's 2π·10⁻⁶ rad/s near-integrator (order + the moved poles).
    #[serde(default)]
    pub near_axis_safe_hz: Option<f64>,
    /// Order of the balanced truncation of K, optional.
    #[serde(default)]
    pub reduce_to: Option<usize>,
    /// Decentralised (7.2) comparison, optional.
    #[serde(default)]
    pub decentralised: Option<DecentralisedSpec>,
    /// Options of the written controller block.
    #[serde(default)]
    pub controller_block: BlockOptions,
    /// Frequency range of the reports and plots (Hz).
    #[serde(default = "default_grid")]
    pub grid_hz: [f64; 2],
    /// Number of grid points.
    #[serde(default = "default_points")]
    pub grid_points: usize,
}

impl SynthConfig {
    /// Parse YAML; errors carry the file name, line and column.
    pub fn from_yaml(text: &str, origin: &str) -> Result<Self, MimoError> {
        nanomotion_core::yaml::from_str(text, origin).map_err(|e| {
            MimoError::param(
                origin,
                e.to_string(),
                "see docs/mimo.md for the config format",
            )
        })
    }

    /// The continuous plant.
    pub fn plant_ss(&self) -> Result<StateSpace, MimoError> {
        match &self.plant {
            PlantSpec::Coupled(p) => p.to_ss(),
            PlantSpec::StateSpace { a, b, c, d } => ControllerModel {
                a: a.clone(),
                b: b.clone(),
                c: c.clone(),
                d: d.clone(),
                dt_s: None,
            }
            .to_ss()
            .map_err(|e| match e {
                MimoError::Param { name, problem, fix } => MimoError::Param {
                    name: name.replace("model.", "plant.state_space."),
                    problem,
                    fix,
                },
                other => other,
            }),
        }
    }
}

/// Reduction result.
#[derive(Debug, Clone, Serialize)]
pub struct Reduction {
    /// Kept states.
    pub order: usize,
    /// Hankel singular values of the controller's stable part.
    pub hankel_singular_values: Vec<f64>,
    /// 2 Σ_{i>r} σ_i.
    pub error_bound: f64,
    /// ‖K − K_r‖∞ achieved.
    pub error: f64,
    /// The loop with K_r.
    pub loop_report: LoopReport,
}

/// The decentralised comparison.
#[derive(Debug, Clone, Serialize)]
pub struct DecentralisedResult {
    /// The tuned shapes (with gains).
    pub axes: Vec<LoopShapedAxis>,
    /// Its loop on the plant.
    pub loop_report: LoopReport,
    /// ‖N‖∞ of K_d on the same generalised plant (for comparison with γ).
    pub weighted_norm: f64,
    /// Whether (7.4) holds at every grid frequency.
    pub condition_7_4_holds: bool,
    /// Largest σ̄(T_d) μ̄(E) on the grid (< 1 for (7.4)).
    pub worst_product: f64,
    /// Largest gap μ̄ − μ̲ relative to μ̄ on the grid.
    pub worst_mu_gap: f64,
    /// Largest off-diagonal |S_o| (dB) in the bands of [`OFFDIAG_BANDS_HZ`]:
    /// (band, H∞, decentralised).
    pub s_o_offdiag_db: Vec<([f64; 2], f64, f64)>,
}

/// Bands (Hz) of the off-diagonal output-sensitivity comparison: around the
/// bandwidth, where (7.1) is accurate, and above it (Fig. 7.10).
pub const OFFDIAG_BANDS_HZ: [[f64; 2]; 3] = [[1.0, 30.0], [30.0, 200.0], [200.0, 2000.0]];

/// Everything a synthesis produces.
#[derive(Debug, Clone)]
pub struct SynthResult {
    /// The synthesis with its checks.
    pub synthesis: Synthesis,
    /// The plant used.
    pub plant: StateSpace,
    /// Loop report of the continuous controller.
    pub loop_report: LoopReport,
    /// The controller discretised at the rate.
    pub discrete: StateSpace,
    /// Spectral radius of the sampled loop.
    pub sampled_spectral_radius: f64,
    /// Reduction, if asked for.
    pub reduction: Option<Reduction>,
    /// Decentralised comparison, if asked for.
    pub decentralised: Option<DecentralisedResult>,
    /// (7.4) per frequency, if a decentralised controller was given.
    pub condition_7_4: Vec<DecentralisedPoint>,
    /// The frequency grid (Hz).
    pub grid_hz: Vec<f64>,
    /// Synthesis wall time (s).
    pub synthesis_time_s: f64,
    /// The block written to controller.yaml.
    pub block: crate::block::MimoController,
}

/// Run the whole design of `cfg`.
pub fn run(cfg: &SynthConfig) -> Result<SynthResult, MimoError> {
    crate::error::positive("rate_hz", cfg.rate_hz)?;
    let [f0, f1] = cfg.grid_hz;
    crate::error::positive("grid_hz[0]", f0)?;
    if !(f1 > f0) || !f1.is_finite() {
        return Err(MimoError::param(
            "grid_hz",
            format!("[{f0}, {f1}]"),
            "give [low, high] with high > low",
        ));
    }
    if !(10..=100_000).contains(&cfg.grid_points) {
        return Err(MimoError::param(
            "grid_points",
            format!("{}", cfg.grid_points),
            "give 10 to 100000",
        ));
    }
    let g = cfg.plant_ss()?;
    let grid = synth::log_grid(f0, f1, cfg.grid_points);
    let t0 = Instant::now();
    let syn = match cfg.near_axis_safe_hz {
        None => synth::synthesise(&g, &cfg.weights)?,
        Some(f) => synth::synthesise_near_axis(&g, &cfg.weights, f)?,
    };
    let synthesis_time_s = t0.elapsed().as_secs_f64();
    let loop_report = synth::loop_report(&g, &syn.controller, &grid)?;
    let (discrete, rho) = synth::discretise(&g, &syn.controller, cfg.rate_hz, cfg.prewarp_hz)?;
    let reduction = match cfg.reduce_to {
        None => None,
        Some(r) => {
            let (red, err) = synth::reduce(&syn.controller, r)?;
            let lr = synth::loop_report(&g, &red.reduced, &grid)?;
            Some(Reduction {
                order: r,
                hankel_singular_values: red.hankel_singular_values,
                error_bound: red.error_bound,
                error: err,
                loop_report: lr,
            })
        }
    };
    let (decentralised, condition_7_4) = match &cfg.decentralised {
        None => (None, Vec::new()),
        Some(d) => {
            let n = g.noutputs();
            if d.axes.len() != n {
                return Err(MimoError::param(
                    "decentralised.axes",
                    format!("has {} axes, the plant {n}", d.axes.len()),
                    "give one per plant output",
                ));
            }
            for [to, from] in &d.share {
                if *to >= n || *from >= n {
                    return Err(MimoError::param(
                        "decentralised.share",
                        format!("[{to}, {from}]"),
                        format!("axes are 0..{n}"),
                    ));
                }
            }
            let mut axes = d.axes.clone();
            let gd = |i: usize, f: f64| g.evalfr(Complex::new(0.0, TAU * f))[(i, i)];
            let share: Vec<(usize, usize)> = d.share.iter().map(|p| (p[0], p[1])).collect();
            decentral::tune_gains(&mut axes, &gd, &d.crossover_hz, &share)?;
            let kd = decentral::controller(&axes)?;
            let lr = synth::loop_report(&g, &kd, &grid)?;
            let wn = synth::weighted_norm(&syn.generalized_plant, &kd, syn.nmeas, syn.ncon)?;
            let gf: Vec<CMatrix> = grid
                .iter()
                .map(|&f| g.evalfr(Complex::new(0.0, TAU * f)))
                .collect();
            let kf: Vec<CMatrix> = grid
                .iter()
                .map(|&f| decentral::response(&axes, f))
                .collect();
            let pts = decentralised_test(&grid, &gf, &kf)?;
            let worst = pts
                .iter()
                .map(|p| p.sigma_td * p.mu.upper)
                .fold(0.0, f64::max);
            let gap = pts
                .iter()
                .map(|p| {
                    if p.mu.upper > 0.0 {
                        (p.mu.upper - p.mu.lower) / p.mu.upper
                    } else {
                        0.0
                    }
                })
                .fold(0.0, f64::max);
            let db = |v: f64| 20.0 * v.max(1e-300).log10();
            let mut s_o_offdiag_db = Vec::new();
            for band in OFFDIAG_BANDS_HZ {
                let a = synth::offdiag_sensitivity(&g, &syn.controller, &grid, band)?;
                let b = synth::offdiag_sensitivity(&g, &kd, &grid, band)?;
                s_o_offdiag_db.push((band, db(a), db(b)));
            }
            (
                Some(DecentralisedResult {
                    axes,
                    loop_report: lr,
                    weighted_norm: wn,
                    condition_7_4_holds: pts.iter().all(|p| p.holds()),
                    worst_product: worst,
                    worst_mu_gap: gap,
                    s_o_offdiag_db,
                }),
                pts,
            )
        }
    };
    let mut block = crate::block::MimoController::new(&discrete);
    block.error_scale = cfg.controller_block.error_scale.clone();
    block.u_offset = cfg.controller_block.u_offset.clone();
    block.u_min = cfg.controller_block.u_min;
    block.u_max = cfg.controller_block.u_max;
    // The block must build at the rate (catches a bad error_scale/u_offset now).
    let mut probe = block.clone();
    nanomotion_core::Block::build(
        &mut probe,
        &nanomotion_core::BuildContext::new("controller", 1.0 / cfg.rate_hz, 0),
    )
    .map_err(|e| MimoError::param("controller_block", e.to_string(), "fix the block options"))?;
    Ok(SynthResult {
        synthesis: syn,
        plant: g,
        loop_report,
        discrete,
        sampled_spectral_radius: rho,
        reduction,
        decentralised,
        condition_7_4,
        grid_hz: grid,
        synthesis_time_s,
        block,
    })
}

/// The generalised plant as JSON-ready `{"a","b","c","d","nmeas","ncon"}`.
#[derive(Debug, Clone, Serialize)]
pub struct GeneralizedPlantJson {
    /// A.
    pub a: Vec<Vec<f64>>,
    /// B = [B₁ B₂].
    pub b: Vec<Vec<f64>>,
    /// C = [C₁; C₂].
    pub c: Vec<Vec<f64>>,
    /// D.
    pub d: Vec<Vec<f64>>,
    /// Number of measurements (last outputs).
    pub nmeas: usize,
    /// Number of controls (last inputs).
    pub ncon: usize,
}

impl GeneralizedPlantJson {
    /// From a synthesis.
    pub fn from_synthesis(s: &Synthesis) -> Self {
        let r = |m: &DMatrix<f64>| {
            (0..m.nrows())
                .map(|i| m.row(i).iter().copied().collect())
                .collect()
        };
        let p = &s.generalized_plant;
        Self {
            a: r(&p.a),
            b: r(&p.b),
            c: r(&p.c),
            d: r(&p.d),
            nmeas: s.nmeas,
            ncon: s.ncon,
        }
    }
}

/// The report.json content.
#[derive(Debug, Clone, Serialize)]
pub struct Report {
    /// γ of the returned controller.
    pub gamma: f64,
    /// Largest infeasible γ of the bisection.
    pub gamma_infeasible: f64,
    /// ‖N‖∞ of the closed loop (Hamiltonian iteration).
    pub closed_loop_norm: f64,
    /// σ̄(N) at the peak rebuilt from frequency responses.
    pub direct_norm_at_peak: f64,
    /// Peak frequency of ‖N‖ (Hz).
    pub peak_hz: f64,
    /// Controller order.
    pub order: usize,
    /// Control rate (Hz).
    pub rate_hz: f64,
    /// Spectral radius of the sampled loop (< 1: stable).
    pub sampled_spectral_radius: f64,
    /// Continuous loop: crossovers, margins, ‖S_o‖∞, ‖T_o‖∞.
    pub mimo: LoopReport,
    /// Balanced truncation, if asked for.
    pub reduction: Option<Reduction>,
    /// The decentralised comparison, if asked for.
    pub decentralised: Option<DecentralisedResult>,
    /// Synthesis time (s).
    pub synthesis_time_s: f64,
}

impl SynthResult {
    /// The report.json content.
    pub fn report(&self, rate_hz: f64) -> Report {
        Report {
            gamma: self.synthesis.gamma,
            gamma_infeasible: self.synthesis.gamma_infeasible,
            closed_loop_norm: self.synthesis.closed_loop_norm,
            direct_norm_at_peak: self.synthesis.direct_norm_at_peak,
            peak_hz: self.synthesis.peak_hz,
            order: self.synthesis.controller.nstates(),
            rate_hz,
            sampled_spectral_radius: self.sampled_spectral_radius,
            mimo: self.loop_report.clone(),
            reduction: self.reduction.clone(),
            decentralised: self.decentralised.clone(),
            synthesis_time_s: self.synthesis_time_s,
        }
    }
}
