//! A Prandtl–Ishlinskii hysteresis on the drive → its inverse, another
//! Prandtl–Ishlinskii operator, before the actuator.
//!
//! The augmented model: a stage (mass–spring–damper, 20 Hz, ζ = 0.3) behind a
//! Prandtl–Ishlinskii loop on its drive, as `diagnose` writes it (its plays'
//! ratios fitted). The user's loop: a PI on the nominal stage tracking a 2 Hz
//! sine. The inverse before the actuator makes the pair the identity to
//! rounding, so the compensated loop on the augmented model must track as the
//! user's loop does on the nominal stage — a figure computed without the
//! effect, not taken from the code under test.

mod support;

use nanomotion_core::graph::GraphSpec;

/// A loop that steepens and then saturates (a negative last weight): branch
/// slopes 0.6, 0.75, 0.9, 0.85 — all positive, so it has an inverse (and
/// below 1: the loop on the diagnosed plant has less gain than the user
/// designed for, and tracks worse).
const PI_LOOP: &str = "type: prandtl_ishlinskii, linear: 0.6, plays: [{ radius: 0.02, weight: 0.15 }, { radius: 0.08, weight: 0.15 }, { radius: 0.2, weight: -0.05 }]";

fn augmented(pi_loop: &str) -> GraphSpec {
    support::map_on_the_drive(pi_loop)
}

#[test]
fn a_prandtl_ishlinskii_loop_on_the_drive_is_cancelled_by_its_inverse() {
    let r = support::inverse_cancels_the_map(PI_LOOP, "prandtl_ishlinskii", 1e-9);
    let c = &r.compensators[0];
    // The fitted loop's branch slopes: 0.6, 0.75, 0.9, 0.85.
    assert!((c.design["slope_min"] - 0.6).abs() < 1e-15);
    assert!((c.design["slope_max"] - 0.9).abs() < 1e-12);
}

#[test]
fn a_loop_whose_branch_turns_back_gets_no_inverse_and_says_why() {
    // Slopes 0.6, 0.75, 0.9, −0.1: the last branch turns back.
    let turning = PI_LOOP.replace("weight: -0.05", "weight: -1.0");
    let out = support::compensate_augmented(&augmented(&turning), &support::pi_loop_behind(None));
    let r = &out.report;
    assert!(
        r.compensators.is_empty() || r.compensators.iter().all(|c| !c.kept),
        "{r:?}"
    );
    let why = serde_json::to_string(r).unwrap();
    assert!(why.contains("stops or turns back"), "{why}");
}
