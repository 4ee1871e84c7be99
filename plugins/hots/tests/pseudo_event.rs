//! `fallback: pseudo_event` (the public phobos `encoderhots` rule) of the HOTS
//! estimator on a constructed register: after the timeout without an event, the fit
//! goes through a pseudo-event (now, newest event's position) in place of the oldest
//! event. Checked against the closed-form least-squares line through those points.

use hots::HotsEstimator;
use nanomotion_core::{Block, BuildContext, Estimator};
use timestamp_encoder::{Fallback, Status};

/// The closed-form LS line x = x̄ + s (t − t̄), s = Σ(t − t̄)(x − x̄)/Σ(t − t̄)²,
/// evaluated at `tc`: (x(tc), s).
fn ls_line(points: &[(f64, f64)], tc: f64) -> (f64, f64) {
    let n = points.len() as f64;
    let tm = points.iter().map(|p| p.0).sum::<f64>() / n;
    let xm = points.iter().map(|p| p.1).sum::<f64>() / n;
    let sxy: f64 = points.iter().map(|p| (p.0 - tm) * (p.1 - xm)).sum();
    let sxx: f64 = points.iter().map(|p| (p.0 - tm).powi(2)).sum();
    let s = sxy / sxx;
    (xm + s * (tc - tm), s)
}

fn estimator(fallback: &str, timeout: f64) -> HotsEstimator {
    let mut h: HotsEstimator = serde_json::from_value(serde_json::json!({
        "order": 1, "register_len": 3, "resolution": 0.5,
        "fallback": fallback, "standstill_timeout_s": timeout,
    }))
    .unwrap();
    h.build(&BuildContext::new("hots_estimator", 1e3, 0))
        .unwrap();
    h
}

fn close(a: f64, b: f64) -> bool {
    (a - b).abs() <= 1e-9 * b.abs().max(1.0)
}

#[test]
fn pseudo_event_fit_matches_the_closed_form_line() {
    let d = 0.5;
    // Edges 2, 3, 4 crossed at 2, 3, 4 ms (1000 counts/s), newest first; count 4.
    let full = [4.0, 3.0, 4e-3, 4.0, 3e-3, 3.0, 2e-3, 2.0];
    // Only two events stored yet (register not full): the pseudo-event is added.
    let partial = [4.0, 2.0, 4e-3, 4.0, 3e-3, 3.0, 0.0, 0.0];
    let mut y = [0.0; 3];

    // 5 ms after the newest event (< 10 ms): no pseudo-event; the line through the
    // three events extrapolates to 9 counts, out of the ±1 band around 4.5: the
    // position falls back to the cell centre, v̂ stays the fit's (thesis rule).
    let mut h = estimator("pseudo_event", 0.01);
    h.estimate(9e-3, &full, &mut y);
    assert!(close(y[0], 4.5 * d) && close(y[1], 1000.0 * d), "{y:?}");

    // 20 ms after it: the fit is through (24 ms, 4), (4 ms, 4), (3 ms, 3) — the
    // oldest event (2 ms, 2) dropped out.
    let tc = 24e-3;
    let (x, s) = ls_line(&[(tc, 4.0), (4e-3, 4.0), (3e-3, 3.0)], tc);
    assert!((x - 4.5).abs() < 1.0, "in band: {x}");
    for reg in [&full, &partial] {
        let mut h = estimator("pseudo_event", 0.01);
        let mut out = [0.0; 4];
        h.output(
            nanomotion_core::Tick {
                k: 24,
                t: tc,
                dt: 1e-3,
            },
            reg,
            &mut out,
        );
        assert!(close(out[0], x * d), "{out:?} vs x {x}");
        assert!(close(out[1], s * d), "{out:?} vs v {s}");
        assert_eq!(out[2], 0.0, "a line has no curvature");
        assert_eq!(out[3], Status::PseudoEvent as u8 as f64);
    }
    // s = 11/421 counts/ms by hand: Σ(t − t̄)(x − x̄) = 66/9, Σ(t − t̄)² = 2526/9 (ms).
    assert!(close(s, 11.0 / 421.0 * 1e3), "{s}");

    // The thesis rule at the same instant: the line through the events, x̂ out of
    // band → cell centre, v̂ = 1000 counts/s; zero_standstill: standstill, zeros.
    let mut h = estimator("thesis", 0.01);
    h.estimate(tc, &full, &mut y);
    assert!(close(y[0], 4.5 * d) && close(y[1], 1000.0 * d), "{y:?}");
    let mut h = estimator("zero_standstill", 0.01);
    h.estimate(tc, &full, &mut y);
    assert_eq!(y, [4.5 * d, 0.0, 0.0]);
    // Timeout 0 disables the pseudo-event: the thesis rule's output.
    let mut h = estimator("pseudo_event", 0.0);
    h.estimate(tc, &full, &mut y);
    assert!(close(y[0], 4.5 * d) && close(y[1], 1000.0 * d), "{y:?}");
}

#[test]
fn pseudo_event_is_a_named_option_and_a_typo_is_an_error() {
    assert_eq!(
        estimator("pseudo_event", 0.01).fallback,
        Fallback::PseudoEvent
    );
    let bad: Result<HotsEstimator, _> = serde_json::from_value(serde_json::json!({
        "resolution": 0.5, "fallback": "pseudo_events",
    }));
    let e = bad.unwrap_err().to_string();
    assert!(e.contains("pseudo_event"), "{e}");
}

/// The pseudo-event is built on the stack: no heap allocation in the tick.
#[test]
fn pseudo_event_tick_does_not_allocate() {
    let reg = [4.0, 3.0, 4e-3, 4.0, 3e-3, 3.0, 2e-3, 2.0];
    let mut h = estimator("pseudo_event", 0.01);
    let mut out = [0.0; 4];
    let tick = nanomotion_core::Tick {
        k: 24,
        t: 24e-3,
        dt: 1e-3,
    };
    h.output(tick, &reg, &mut out);
    let info = allocation_counter::measure(|| {
        for _ in 0..100 {
            h.output(tick, &reg, &mut out);
        }
    });
    assert_eq!(info.count_total, 0, "{info:?}");
    assert_eq!(out[3], Status::PseudoEvent as u8 as f64);
}
