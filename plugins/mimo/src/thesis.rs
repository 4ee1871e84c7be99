//! The thesis-vs-ours figures of Sec. 7.3.2 (docs/mimo.md, "Thesis vs ours") as
//! plain data, for a reproduction report: γ, controller order, crossovers of
//! the diagonal loop gains of the H∞ and the decentralised (7.2) designs, each
//! next to the thesis's value. The thesis figures are quoted from its text
//! (γ_opt ≈ 0.91, order 17, {15.9, 13.4, 22.9} Hz, {16.7, 14.7, 25.4} Hz); ours
//! are computed here from the config.

use crate::config::{SynthConfig, run};
use crate::error::MimoError;
use crate::synth;
use serde::Serialize;

/// The thesis's γ_opt (Sec. 7.3.2).
pub const THESIS_GAMMA: f64 = 0.91;
/// The thesis's controller order.
pub const THESIS_ORDER: usize = 17;
/// Crossovers of the diagonal loop gains with the H∞ controller (Hz; x, y, z).
pub const THESIS_MIMO_CROSSOVERS_HZ: [f64; 3] = [15.9, 13.4, 22.9];
/// Crossovers with the decentralised controller (7.2) (Hz; x, y, z).
pub const THESIS_DECENTRALISED_CROSSOVERS_HZ: [f64; 3] = [16.7, 14.7, 25.4];

/// One compared figure.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Figure<T> {
    /// The thesis's value.
    pub thesis: T,
    /// Ours.
    pub ours: T,
}

/// The Sec. 7.3.2 comparison.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Sec73 {
    /// γ of the returned (verified) order-n design.
    pub gamma: Figure<f64>,
    /// Largest γ found infeasible by our bisection.
    pub gamma_infeasible: f64,
    /// γ of [`synth::synthesise_near_axis`] (verified), when asked for.
    pub gamma_near_axis: Option<f64>,
    /// Order of that design.
    pub order_near_axis: Option<usize>,
    /// Controller order.
    pub order: Figure<usize>,
    /// Crossovers of the diagonal loop gains, H∞ (Hz; NaN: no crossing).
    pub mimo_crossovers_hz: Figure<[f64; 3]>,
    /// Crossovers with the decentralised (7.2) controller (Hz; NaN if the
    /// config has no decentralised design).
    pub decentralised_crossovers_hz: Figure<[f64; 3]>,
    /// ‖S_o‖∞ in dB, H∞ and decentralised (the thesis bounds it by 6 dB).
    pub s_o_peak_db: [f64; 2],
}

fn three(v: &[Option<f64>]) -> [f64; 3] {
    let g = |i: usize| v.get(i).copied().flatten().unwrap_or(f64::NAN);
    [g(0), g(1), g(2)]
}

/// The comparison for a 3-axis config (the shipped one is
/// `examples/mimo/afm_synth.yaml`); `near_axis_safe_hz`: also run
/// [`synth::synthesise_near_axis`] with it (a few seconds).
pub fn sec_7_3(cfg: &SynthConfig, near_axis_safe_hz: Option<f64>) -> Result<Sec73, MimoError> {
    if cfg.weights.axes.len() != 3 {
        return Err(MimoError::param(
            "weights.axes",
            format!("has {} axes", cfg.weights.axes.len()),
            "the Sec. 7.3 comparison is for the 3-axis AFM",
        ));
    }
    let r = run(cfg)?;
    let near = match near_axis_safe_hz {
        None => None,
        Some(f) => Some(synth::synthesise_near_axis(&r.plant, &cfg.weights, f)?),
    };
    let dec = r
        .decentralised
        .as_ref()
        .map(|d| three(&d.loop_report.crossovers_hz))
        .unwrap_or([f64::NAN; 3]);
    let db = |v: f64| 20.0 * v.log10();
    Ok(Sec73 {
        gamma: Figure {
            thesis: THESIS_GAMMA,
            ours: r.synthesis.gamma,
        },
        gamma_infeasible: r.synthesis.gamma_infeasible,
        gamma_near_axis: near.as_ref().map(|s| s.gamma),
        order_near_axis: near.as_ref().map(|s| s.controller.nstates()),
        order: Figure {
            thesis: THESIS_ORDER,
            ours: r.synthesis.controller.nstates(),
        },
        mimo_crossovers_hz: Figure {
            thesis: THESIS_MIMO_CROSSOVERS_HZ,
            ours: three(&r.loop_report.crossovers_hz),
        },
        decentralised_crossovers_hz: Figure {
            thesis: THESIS_DECENTRALISED_CROSSOVERS_HZ,
            ours: dec,
        },
        s_o_peak_db: [
            db(r.loop_report.s_o_hinf),
            r.decentralised
                .as_ref()
                .map_or(f64::NAN, |d| db(d.loop_report.s_o_hinf)),
        ],
    })
}
