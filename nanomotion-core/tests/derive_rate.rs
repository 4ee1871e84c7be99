//! `#[param(below_nyquist)]`: a frequency checked against the block's rate by
//! `check_at_rate(dt)` (which `build()` calls after `check_params()`), said in
//! the listing, and refused from a graph file with the block, the field and the
//! fix named.

use nanomotion_core::GraphSpec;
use nanomotion_core::doc::Params;
use proptest::prelude::*;
use serde::{Deserialize, Serialize};

/// A filter with a corner and an optional pre-warp frequency.
#[derive(Debug, Clone, Serialize, Deserialize, Params)]
#[serde(deny_unknown_fields)]
struct Corner {
    /// Corner frequency (Hz).
    #[param(positive, below_nyquist)]
    corner_hz: f64,
    /// Pre-warp frequency (Hz).
    #[serde(default)]
    #[param(positive, below_nyquist)]
    prewarp_hz: Option<f64>,
}

#[test]
fn frequencies_are_checked_against_the_rate() {
    let c = |corner_hz, prewarp_hz| Corner {
        corner_hz,
        prewarp_hz,
    };
    // dt = 1 ms: Nyquist 500 Hz
    assert!(c(100.0, None).check_at_rate(1e-3).is_ok());
    assert!(c(100.0, Some(499.0)).check_at_rate(1e-3).is_ok());
    let e = c(500.0, None).check_at_rate(1e-3).unwrap_err();
    assert_eq!(
        (e.field.as_str(), e.problem.as_str(), e.fix.as_str()),
        (
            "corner_hz",
            "500 Hz is not below the Nyquist frequency 500 Hz of the block's rate",
            "lower the frequency or raise the block's rate"
        )
    );
    let e = c(100.0, Some(600.0)).check_at_rate(1e-3).unwrap_err();
    assert_eq!(e.field, "prewarp_hz");
    // the rate-free bounds stay in check_params; a rate check alone passes them
    assert!(c(-1.0, None).check_params().is_err());
    let docs = Corner::param_docs();
    assert_eq!(docs[0].bounds, ["> 0", "below Nyquist"]);
    assert_eq!(docs[1].bounds, ["> 0", "below Nyquist"]);
}

fn graph(rate_hz: f64, cutoff_hz: f64) -> String {
    format!(
        "base_rate_hz: {rate_hz}\nduration_s: 0.01\nblocks:\n  - {{ name: src, type: constant, value: 1.0 }}\n  - {{ name: lp, type: low_pass, cutoff_hz: {cutoff_hz:?} }}\nconnections:\n  - {{ from: src.y, to: lp.u }}\n"
    )
}

proptest! {
    /// A low-pass loaded from a graph file builds exactly when its cutoff is
    /// below half the base rate; otherwise the error names the block, the
    /// field and the fix.
    #[test]
    fn a_loaded_cutoff_is_below_nyquist_or_refused(
        rate in 100.0f64..10_000.0,
        fraction in 0.01f64..1.5,
    ) {
        let cutoff = (fraction * rate * 0.5 * 1e3).round() / 1e3;
        let spec = GraphSpec::from_yaml(&graph(rate, cutoff), "lp.yaml").unwrap();
        match spec.build() {
            Ok(_) => prop_assert!(cutoff < 0.5 * rate, "{cutoff} Hz at {rate} Hz was accepted"),
            Err(e) => {
                let text = e.to_string();
                prop_assert!(cutoff >= 0.5 * rate, "{text}");
                prop_assert!(
                    text.contains("block `lp` (type `low_pass`): field `cutoff_hz`")
                        && text.contains("lower the frequency or raise the block's rate"),
                    "{text}"
                );
            }
        }
    }
}
