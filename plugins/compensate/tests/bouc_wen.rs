//! A Bouc–Wen hysteresis on the drive → its exact inverse before the actuator.
//!
//! The augmented model: a stage (mass–spring–damper, 20 Hz, ζ = 0.3) behind a
//! Bouc–Wen loop y = linear·u + z on its drive, as `diagnose` writes it. The
//! user's loop: a PI on the nominal stage tracking a 2 Hz sine. With the inverse
//! before the actuator the pair inverse → Bouc–Wen is the identity to rounding,
//! so the compensated loop on the augmented model must track exactly as the
//! user's loop does on the nominal stage — a figure computed without the
//! effect, not taken from the code under test.

mod support;

use nanomotion_core::graph::GraphSpec;

/// The Bouc–Wen loop the diagnosis fitted (a loop of half the stroke's width,
/// a linear part of 0.6).
const BW: &str = "type: bouc_wen, a: 0.5, beta: 4.0, gamma: 1.0, linear: 0.6";

fn augmented() -> GraphSpec {
    support::map_on_the_drive(BW)
}

/// Before: the user's loop on the plant as diagnosed; after: the inverse and
/// the loop cancel, so the loop tracks as on the nominal stage, and what the
/// effect adds to the error is gone to rounding.
#[test]
fn a_bouc_wen_loop_on_the_drive_is_cancelled_by_its_inverse() {
    let r = support::inverse_cancels_the_map(BW, "bouc_wen_inverse", 1e-12);
    let c = &r.compensators[0];
    // Slope bounds of the loop: linear + [0, max(a, 2aβ/(β + γ))] = [0.6, 1.4].
    assert_eq!(c.design["slope_min"], 0.6);
    assert!((c.design["slope_max"] - (0.6 + 2.0 * 0.5 * 4.0 / 5.0)).abs() < 1e-15);
}

#[test]
fn a_loop_without_a_linear_part_gets_no_inverse_and_says_why() {
    let text = {
        let aug = augmented();
        let mut t = nanomotion_core::yaml::to_string(&aug).unwrap();
        t = t.replace("linear: 0.6", "linear: 0.0");
        t
    };
    let aug = GraphSpec::from_yaml(&text, "model_augmented.yaml").unwrap();
    let out = support::compensate_augmented(&aug, &support::pi_loop_behind(None));
    let r = &out.report;
    assert!(
        r.compensators.is_empty() || r.compensators.iter().all(|c| !c.kept),
        "{r:?}"
    );
    let why = serde_json::to_string(r).unwrap();
    assert!(why.contains("has no inverse"), "{why}");
}
