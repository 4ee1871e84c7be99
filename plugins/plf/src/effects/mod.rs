//! Effect blocks of the PLF vocabulary.
//!
//! One registered block type per [`Effect`]: the signal being modified enters on
//! input port `u` (width 1) and leaves on output port `y` (width 1); blocks that need
//! a second signal (a scheduling variable, usually the plant's position) read it on
//! input port `s`. All blocks are unit-agnostic (u may be V, N, m, ...), validate
//! every parameter in [`build`](nanomotion_core::Block::build) with a
//! [`ParamError`] naming the field and the fix, never allocate in `output`/`update`,
//! reset all state in `build`, and are [`Tunable`](nanomotion_core::Tunable) so the
//! workflow can fit them (`set_params`, then the scheduler's `reset`).
//!
//! | effect | block type | module |
//! |---|---|---|
//! | `hysteresis` | `hysteresis` (Coleman–Hodgdon); also `bouc_wen`, `prandtl_ishlinskii` | [`hysteresis`], [`bouc_wen`], [`prandtl_ishlinskii`] |
//! | `friction` | `friction` | [`friction`] |
//! | `time_delay` | `time_delay` | [`delay`] |
//! | `repetitive_disturbance` | `repetitive_disturbance` | [`repetitive`] |
//! | `position_dependent_gain` | `position_dependent_gain` | [`gain`] |
//! | `quantization` | `quantizer` (core) | [`nanomotion_core::blocks::sensors::Quantizer`] |
//! | `unmodeled_resonance` | `unmodeled_resonance` | [`resonance`] |
//! | `drift` | `drift` | [`drift`] |
//! | `creep` | `creep` | [`creep`] |
//! | `axis_coupling` | `axis_coupling` | [`coupling`] |
//! | `encoder_slit_error` | `encoder_slit_error` | [`slit`] |
//! | `saturation` | `saturation` (core) | [`nanomotion_core::blocks::math::Saturation`] |
//! | `backlash` | `backlash` | [`backlash`] |

//!
//! **Slope ranges for the stability gate** ([`Block::sector`](nanomotion_core::Block::sector):
//! between two samples Δy = s·Δu with s in a declared range, which lets the gate
//! prove or refuse a loop through the block by the circle criterion). Given
//! where a bound genuinely holds for every finite input sequence:
//! `hysteresis` (Coleman–Hodgdon: [min(2c − b, b), max(2c − b, b)]; none for a
//! `retrace` set with a different b), `bouc_wen` (`linear` + [0, max(a, 2aβ/(β+γ))]
//! for a > 0, β + γ > 0; none for a non-saturating loop), `prandtl_ishlinskii`
//! ([min a_j, max a_j] of its branch slopes), `backlash` ([0, 1]).
//! None for the others, because none exists: `friction` reads the velocity Δu/dt,
//! so y changes when u stops (Δu = 0, Δy ≠ 0); `drift` and
//! `repetitive_disturbance` add a signal of time that moves when u does not;
//! `encoder_slit_error` jumps by a slit's error at a slit edge however small Δu
//! is; `position_dependent_gain` has two inputs (variable `signal`) or, with
//! variable `input`, a polynomial gain whose slope u·g'(u) + g(u) grows with |u|
//! (unless the gain is constant).
//! `creep`, `time_delay` and `unmodeled_resonance` are linear (dynamic), not
//! static slopes: they give their LTI models (`Block::lti`; `time_delay` up to
//! 512 samples, like the core's `delay`), as does `axis_coupling`.

use nanomotion_core::ParamError;

pub mod backlash;
pub mod bouc_wen;
pub mod coupling;
pub mod creep;
pub mod delay;
pub mod drift;
pub mod friction;
pub mod gain;
pub mod hysteresis;
pub mod prandtl_ishlinskii;
pub mod repetitive;
pub mod resonance;
pub mod slit;

pub use backlash::Backlash;
pub use bouc_wen::BoucWen;
pub use coupling::AxisCoupling;
pub use creep::{Creep, CreepTerm};
pub use delay::TimeDelay;
pub use drift::Drift;
pub use friction::Friction;
pub use gain::{GainVariable, PositionDependentGain};
pub use hysteresis::Hysteresis;
pub use prandtl_ishlinskii::{Play, PrandtlIshlinskii};
pub use repetitive::{PhaseVariable, RepetitiveDisturbance};
pub use resonance::UnmodeledResonance;
pub use slit::EncoderSlitError;

/// The vocabulary of performance-limiting effects the workflow can name.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum Effect {
    /// Rate-independent input–output loop (Coleman–Hodgdon, Sec. 6.3).
    Hysteresis,
    /// Coulomb + Stribeck + viscous friction force from a position signal.
    Friction,
    /// A pure (fractional) time delay.
    TimeDelay,
    /// A disturbance periodic in time or in a signal (position).
    RepetitiveDisturbance,
    /// A gain that depends on a scheduling signal (position).
    PositionDependentGain,
    /// Finite resolution (the core's `quantizer`).
    Quantization,
    /// An unmodelled pole–zero pair (resonance / anti-resonance).
    UnmodeledResonance,
    /// Offset + linear (+ quadratic) drift in time.
    Drift,
    /// Piezo creep (sum of first-order lags).
    Creep,
    /// Cross-axis coupling.
    AxisCoupling,
    /// Per-slit line-position errors of an optical encoder (Ch. 8–9).
    EncoderSlitError,
    /// Hard limits (the core's `saturation`).
    Saturation,
    /// Play / backlash operator.
    Backlash,
}

impl Effect {
    /// Every effect, in vocabulary order.
    pub const ALL: [Effect; 13] = [
        Effect::Hysteresis,
        Effect::Friction,
        Effect::TimeDelay,
        Effect::RepetitiveDisturbance,
        Effect::PositionDependentGain,
        Effect::Quantization,
        Effect::UnmodeledResonance,
        Effect::Drift,
        Effect::Creep,
        Effect::AxisCoupling,
        Effect::EncoderSlitError,
        Effect::Saturation,
        Effect::Backlash,
    ];

    /// The vocabulary name (as reported by `nanomotion diagnose`).
    pub fn name(self) -> &'static str {
        match self {
            Effect::Hysteresis => "hysteresis",
            Effect::Friction => "friction",
            Effect::TimeDelay => "time_delay",
            Effect::RepetitiveDisturbance => "repetitive_disturbance",
            Effect::PositionDependentGain => "position_dependent_gain",
            Effect::Quantization => "quantization",
            Effect::UnmodeledResonance => "unmodeled_resonance",
            Effect::Drift => "drift",
            Effect::Creep => "creep",
            Effect::AxisCoupling => "axis_coupling",
            Effect::EncoderSlitError => "encoder_slit_error",
            Effect::Saturation => "saturation",
            Effect::Backlash => "backlash",
        }
    }

    /// The effect called `name` (exactly as [`Effect::name`] spells it).
    pub fn from_name(name: &str) -> Option<Effect> {
        Self::ALL.into_iter().find(|e| e.name() == name)
    }

    /// The registered block type (`type:` in YAML) that models the effect.
    pub fn block_type(self) -> &'static str {
        self.block_types()[0]
    }

    /// Every registered block type that models the effect, [`Effect::block_type`]
    /// first: hysteresis has three (Coleman–Hodgdon, Bouc–Wen,
    /// Prandtl–Ishlinskii), the others one.
    pub fn block_types(self) -> &'static [&'static str] {
        match self {
            Effect::Hysteresis => &["hysteresis", "bouc_wen", "prandtl_ishlinskii"],
            Effect::Quantization => &["quantizer"],
            Effect::Friction => &["friction"],
            Effect::TimeDelay => &["time_delay"],
            Effect::RepetitiveDisturbance => &["repetitive_disturbance"],
            Effect::PositionDependentGain => &["position_dependent_gain"],
            Effect::UnmodeledResonance => &["unmodeled_resonance"],
            Effect::Drift => &["drift"],
            Effect::Creep => &["creep"],
            Effect::AxisCoupling => &["axis_coupling"],
            Effect::EncoderSlitError => &["encoder_slit_error"],
            Effect::Saturation => &["saturation"],
            Effect::Backlash => &["backlash"],
        }
    }

    /// Whether the block needs input port `s` (a second signal) in its default
    /// form: `position_dependent_gain` (scheduling signal), `axis_coupling` (the
    /// other axes). `repetitive_disturbance` is periodic in time by default (port
    /// `s` only with `variable: signal`).
    pub fn needs_signal(self) -> bool {
        matches!(self, Effect::PositionDependentGain | Effect::AxisCoupling)
    }
}

impl std::fmt::Display for Effect {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

/// `p` must have `n` values; `order` names them for the error.
pub(crate) fn check_len(p: &[f64], n: usize, order: &str) -> Result<(), ParamError> {
    if p.len() == n {
        Ok(())
    } else {
        Err(ParamError::new(
            "params",
            format!("{} values given, {n} expected", p.len()),
            format!("give {order}"),
        ))
    }
}

/// `value` finite with |value| ≤ `limit` (keeps products and powers finite).
pub(crate) fn check_bounded(field: &str, value: f64, limit: f64) -> Result<(), ParamError> {
    nanomotion_core::block::check::finite(field, value)?;
    if value.abs() <= limit {
        Ok(())
    } else {
        Err(ParamError::new(
            field,
            format!("is {value}, beyond ±{limit:e}"),
            format!("give a value of magnitude ≤ {limit:e}"),
        ))
    }
}

/// The magnitude bound of every gain/coefficient parameter: generous for any unit,
/// small enough that sums and products of a few of them stay finite.
pub(crate) const MAX_MAGNITUDE: f64 = 1e100;

#[cfg(test)]
mod declared_lengths {
    use super::*;
    use nanomotion_core::doc::Params;
    use nanomotion_core::{Block, BuildContext};

    fn refused(mut b: impl Block) -> (String, String) {
        let e = b.build(&BuildContext::new("effect", 1e-3, 0)).unwrap_err();
        (e.field, e.problem)
    }

    /// The effects' list lengths are declared (`len`): each refuses an empty
    /// list and one too long by name, and says its bound in the listing.
    #[test]
    fn each_list_length_is_refused_by_name_and_listed() {
        let gain = |c: Vec<f64>| PositionDependentGain::new(0.0, 1.0, c);
        let slit = |e: Vec<f64>| EncoderSlitError::new(1e-3, 0.0, e);
        let term = CreepTerm {
            gain: 0.1,
            tau_s: 1.0,
        };
        let creep = |n: usize| Creep::new(vec![term; n]);
        assert_eq!(refused(gain(vec![])), ("coeffs".into(), "is empty".into()));
        assert_eq!(
            refused(gain(vec![0.1; gain::MAX_ORDER + 1])).1,
            "has 9 entries, must have 1 to 8 entries"
        );
        assert_eq!(refused(slit(vec![])).0, "errors");
        assert_eq!(
            refused(slit(vec![0.0; slit::MAX_SLITS + 1])).1,
            "has 4097 entries, must have 1 to 4096 entries"
        );
        assert_eq!(refused(AxisCoupling::new(vec![])).0, "coupling");
        assert_eq!(
            refused(AxisCoupling::new(vec![0.1; coupling::MAX_COUPLED + 1])).1,
            "has 9 entries, must have 1 to 8 entries"
        );
        assert_eq!(refused(creep(0)), ("terms".into(), "is empty".into()));
        assert_eq!(refused(creep(creep::MAX_TERMS + 1)).0, "terms");
        // what passes builds; the other bounds are still checked
        assert!(
            gain(vec![0.1])
                .build(&BuildContext::new("g", 1e-3, 0))
                .is_ok()
        );
        assert!(creep(4).build(&BuildContext::new("c", 1e-3, 0)).is_ok());
        assert_eq!(
            refused(PositionDependentGain::new(0.0, 0.0, vec![0.1])).0,
            "scale"
        );
        assert_eq!(
            refused(EncoderSlitError::new(-1.0, 0.0, vec![0.0])).0,
            "pitch"
        );
        let words = |docs: Vec<nanomotion_core::ParamDoc>, n: &str| {
            docs.into_iter().find(|p| p.name == n).unwrap().bounds
        };
        assert_eq!(words(Creep::param_docs(), "terms"), ["1 to 4 entries"]);
        assert_eq!(
            words(EncoderSlitError::param_docs(), "errors"),
            ["1 to 4096 entries"]
        );
    }
}
