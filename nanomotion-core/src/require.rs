//! The `require:` section of a graph: bounds every feedback loop must meet, for
//! the whole graph and per loop.

use crate::Params;
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;

/// Bounds on one loop (or, at the top of `require:`, on every loop). Every
/// field is optional; an absent bound is not checked. Stability itself is
/// always required.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize, Params)]
#[serde(deny_unknown_fields)]
pub struct Bounds {
    /// Smallest gain margin (dB): 1/|L| at every phase crossover.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub gain_margin_db: Option<f64>,
    /// Smallest phase margin (degrees).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub phase_margin_deg: Option<f64>,
    /// Modulus margin as the largest allowed ‖S‖∞ in dB: `6` means ‖S‖∞ ≤ 6 dB,
    /// i.e. the Nyquist curve stays at least 10^(−6/20) = 0.50 away from −1.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub modulus_margin_db: Option<f64>,
    /// Smallest delay margin (s): the extra loop delay that would destabilise
    /// the loop, PM/ω_c.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub delay_margin_s: Option<f64>,
    /// Largest allowed ‖T‖∞ (dB).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub max_t_db: Option<f64>,
    /// Let loops that cannot be analysed (a block without a linear model) run,
    /// with this reason, which the report prints. Never lets an unstable loop run.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub allow_unproven: Option<String>,
}

/// The `require:` section: bounds for every loop, and per loop (keyed by the
/// name of any block of the loop) bounds that replace them field by field.
///
/// ```yaml
/// require:
///   phase_margin_deg: 30
///   modulus_margin_db: 6
///   loops:
///     pi: { phase_margin_deg: 45 }
/// ```
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize, Params)]
#[serde(deny_unknown_fields)]
pub struct Require {
    /// Smallest gain margin (dB) of every loop ([`Bounds::gain_margin_db`]).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub gain_margin_db: Option<f64>,
    /// Smallest phase margin (degrees) of every loop ([`Bounds::phase_margin_deg`]).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub phase_margin_deg: Option<f64>,
    /// Largest allowed ‖S‖∞ (dB) of every loop ([`Bounds::modulus_margin_db`]).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub modulus_margin_db: Option<f64>,
    /// Smallest delay margin (s) of every loop ([`Bounds::delay_margin_s`]).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub delay_margin_s: Option<f64>,
    /// Largest allowed ‖T‖∞ (dB) of every loop ([`Bounds::max_t_db`]).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub max_t_db: Option<f64>,
    /// Let loops that cannot be analysed run, with this reason
    /// ([`Bounds::allow_unproven`]); here it applies to every loop.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub allow_unproven: Option<String>,
    /// Per-loop bounds, keyed by the name of a block in the loop.
    #[serde(default, skip_serializing_if = "BTreeMap::is_empty")]
    pub loops: BTreeMap<String, Bounds>,
}

impl Require {
    /// The graph-wide bounds.
    pub fn graph_bounds(&self) -> Bounds {
        Bounds {
            gain_margin_db: self.gain_margin_db,
            phase_margin_deg: self.phase_margin_deg,
            modulus_margin_db: self.modulus_margin_db,
            delay_margin_s: self.delay_margin_s,
            max_t_db: self.max_t_db,
            allow_unproven: self.allow_unproven.clone(),
        }
    }

    /// Bounds of a loop: the per-loop entry (if `key` names one) over the
    /// graph-wide bounds.
    pub fn bounds_for(&self, key: Option<&str>) -> Bounds {
        let g = self.graph_bounds();
        let Some(l) = key.and_then(|k| self.loops.get(k)) else {
            return g;
        };
        Bounds {
            gain_margin_db: l.gain_margin_db.or(g.gain_margin_db),
            phase_margin_deg: l.phase_margin_deg.or(g.phase_margin_deg),
            modulus_margin_db: l.modulus_margin_db.or(g.modulus_margin_db),
            delay_margin_s: l.delay_margin_s.or(g.delay_margin_s),
            max_t_db: l.max_t_db.or(g.max_t_db),
            allow_unproven: l.allow_unproven.clone().or(g.allow_unproven),
        }
    }

    /// Every bound finite (and the reasons non-empty); an error names the field.
    pub fn validate(&self) -> Result<(), String> {
        let check = |place: &str, b: &Bounds| -> Result<(), String> {
            for (name, v) in [
                ("gain_margin_db", b.gain_margin_db),
                ("phase_margin_deg", b.phase_margin_deg),
                ("modulus_margin_db", b.modulus_margin_db),
                ("delay_margin_s", b.delay_margin_s),
                ("max_t_db", b.max_t_db),
            ] {
                if let Some(v) = v
                    && !v.is_finite()
                {
                    return Err(format!(
                        "{place}{name} is {v}; give a finite number (or leave the bound out)"
                    ));
                }
            }
            if let Some(r) = &b.allow_unproven
                && r.trim().is_empty()
            {
                return Err(format!(
                    "{place}allow_unproven is empty; say why the loop may run unproven"
                ));
            }
            Ok(())
        };
        check("require.", &self.graph_bounds())?;
        for (k, b) in &self.loops {
            check(&format!("require.loops.{k}."), b)?;
        }
        Ok(())
    }
}
