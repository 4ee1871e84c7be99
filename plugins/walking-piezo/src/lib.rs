//! # nanomotion-walking-piezo
//!
//! Plant models of a nano-motion stage driven by a **walking piezo motor** (a
//! Piezo LEGS–type actuator: four bimorph legs working in two pairs that walk a
//! drive strip by friction), after R.J.E. Merry, *Performance-driven control of
//! nano-motion systems*, PhD thesis, TU Eindhoven, 2009, Chapters 2–4 and 5.5.
//!
//! From simplest to richest:
//!
//! | model | thesis | Rust type | block `type:` |
//! |---|---|---|---|
//! | linear stage, f_α → x_s | (2.3)–(2.8) | [`LinearStage`] | `walking_piezo_linear` |
//! | switched linear stage, u1..u4 → x_s | (2.3)–(2.4) with the pair switch | [`SwitchedStage`] | `walking_piezo_switched` |
//! | fitted stage, f_α → x_s | (5.31), 3-sample delay | [`FittedStage`] | `walking_piezo_fitted` |
//! | leg kinematics u → tips | (4.2) (= (2.1) with equal coefficients) | [`LegKinematics`] | `walking_piezo_legs` |
//! | nonlinear stage, u1..u4 → x_s, legs, normal forces, slip | (4.2)–(4.19) | [`WalkingPiezoStage`] | `walking_piezo_stage` |
//! | sinusoidal drive waveforms | (2.2) | [`SinusoidalWaveform`] | `walking_waveform` |
//! | driver: f_α → α, u1..u4; sinusoidal, asymmetric (exact, Fourier), rhombic, free waveforms | (2.2), (2.9), (4.21)–(4.22) | [`WaveformDriver`] | `walking_piezo_driver` |
//! | PI design (2.10) on the linear model, margins | Sec. 2.4.2 | [`design_pi`] | (core `pi`) |
//! | step-size feed-forward A, φ from the reference speed | (2.11)–(2.12) | [`StepSizeFeedForward`] | `walking_piezo_feedforward` |
//! | gain variation with A, φ̄ by closed-loop FRF | Sec. 2.5.1, Fig. 2.14 | [`gain_id::identify_operating_point`] | — |
//! | Ch. 3 leg model: n_m lumped layers, Lagrange, linearisation, c_x, c_y | (3.5)–(3.29) | [`leg_model::LegModel`] | — |
//! | identification: particle swarm + Nelder–Mead on (4.20) | Sec. 4.4.1 | [`identify::identify`] | — |
//! | waveform optimisation: objectives (4.23)–(4.25), SA / PSO (argmin) + Nelder–Mead, resumable | Sec. 4.5 | [`optimize::optimize`] | — (`nanomotion optimize-waveform`) |
//!
//! The nonlinear model is the heart: massless legs, a stage mass driven only by
//! **set-valued Coulomb friction** λ ∈ μF_N Sign(v_rel) whose normal forces come
//! from one-sided nonlinear contact springs sharing the preload, solved by the
//! thesis's **dedicated time-stepping scheme**: backward Euler plus a fixed-point
//! iteration on the friction forces with the proximal point onto [−μF_N, μF_N]
//! ([`friction`]). It sticks truly (zero slip at non-zero friction), reports every
//! step whose iteration hits its cap, refuses non-finite inputs, and draws a
//! seeded, slowly varying μ ([`variation`]) so the stage steps irregularly, as
//! the real one does.
//!
//! Everything is usable from plain Rust (the types implement
//! [`nanomotion_core::Plant`] / [`nanomotion_core::Source`]) and, by linking this
//! crate, from YAML graphs.
//!
//! ```
//! use walking_piezo::{SinusoidalWaveform, StageParams, WalkingPiezoStage};
//! let wave = SinusoidalWaveform { f_alpha_hz: 20.0, ..Default::default() };
//! let dt = 25e-6; // the thesis's step
//! let mut stage = WalkingPiezoStage::new(StageParams::default(), dt, 7).unwrap();
//! for k in 0..4000 {
//!     stage.step(&wave.voltages(wave.alpha(k as f64 * dt)), 0.0).unwrap();
//! }
//! // 0.1 s at 20 Hz: two cycles of a few µm each.
//! let x = stage.signals().x_s;
//! assert!(x > 3e-6 && x < 30e-6, "{x}");
//! ```
//!
//! Closed loop: `examples/walking_piezo_jogging.yaml` (PI on f_α, asymmetric
//! waveforms) and `examples/walking_piezo_ff_gs.yaml` (feed-forward and gain
//! scheduling, needs the `gain-scheduling` plugin); `cargo run --release -p
//! nanomotion-walking-piezo --example tables_2_2_2_3` (Tables 2.2 and 2.3 in shape),
//! `--example gain_scheduling_id` (Fig. 2.14, (2.13)), `--example pi_design`.
//!
//! Examples: `examples/walking_piezo_open_loop.yaml` (repository root: the
//! open-loop stage of Sec. 4.4 with sinusoidal waveforms, stage position, leg tips
//! and slip as in Fig. 4.7), `cargo run -p nanomotion-walking-piezo --example
//! ch3_frf` (Table 3.2: gain and first resonance of the Ch. 3 leg model against the
//! number of layers n_m, and the FRF H_ru of Fig. 3.8), and `cargo run --release -p
//! nanomotion-walking-piezo --example identify_stage` (Table 4.2 style: identify
//! unequal leg coefficients from simulated records, validate on unseen waveforms).
//!
//! Values the extracted thesis text lost (its digit 0 dropped; Table 4.1 empty) are
//! named parameters with documented, physically reasoned defaults; see
//! [`StageParams`].

pub mod contact;
pub mod control;
pub mod driver;
pub mod friction;
pub mod gain_id;
pub mod identify;
pub mod kinematics;
pub mod leg_model;
pub mod linear;
pub mod optimize;
pub mod records;
pub mod stage;
pub mod thesis;
pub mod thesis_ch3;
pub mod thesis_table_4_2;
pub mod variation;
pub mod waveform;

pub use control::{PiDesign, StepSizeFeedForward, StepSizeFeedForwardBlock, design_pi, loop_gain};
pub use driver::{
    DriveError, DriverParams, Fourier4, WaveformDriver, WaveformDriverBlock, WaveformShape,
};
pub use kinematics::{LegKinematics, LegKinematicsBlock, LegTips};
pub use linear::{
    FittedStage, FittedStageBlock, FittedStageParams, LinearStage, LinearStageBlock,
    LinearStageParams, MAX_FITTED_DELAY_MODEL_SAMPLES, MAX_FITTED_DELAY_SAMPLES, SwitchedStage,
    SwitchedStageBlock, SwitchedStageParams,
};
pub use stage::{
    StageCounters, StageParams, StageSignals, StepError, StepReport, WalkingPiezoStage,
    WalkingPiezoStageBlock,
};
pub use waveform::{SinusoidalWaveform, WalkingWaveformBlock};
