//! Sec. 8.5 in shape (not numbers): skip against no skip with and without slit
//! errors, differencing far worse, HOTS + calibration best.

use hots::sim::{Sec85Row, sec8_5};
use nanomotion_core::rng::Rng;

fn get<'a>(rows: &'a [Sec85Row], prefix: &str) -> &'a Sec85Row {
    rows.iter().find(|r| r.method.starts_with(prefix)).unwrap()
}

#[test]
fn skip_helps_with_slit_errors_and_hurts_without() {
    let mut rng = Rng::new(5);
    let slits: Vec<f64> = (0..100).map(|_| 0.05 * rng.normal()).collect();
    let rows = sec8_5(&slits).unwrap();
    for r in &rows {
        eprintln!(
            "{:45} x {:.5} v {:.4} a {:.3}",
            r.method, r.errors.x, r.errors.v, r.errors.a
        );
    }
    let s0 = get(&rows, "time-stamping m=2 n=5 σ=0").errors;
    let skips: Vec<_> = rows
        .iter()
        .filter(|r| r.method.starts_with("time-stamping") && !r.method.ends_with("σ=0"))
        .collect();
    let best_v = skips
        .iter()
        .map(|r| r.errors.v)
        .fold(f64::INFINITY, f64::min);
    let best_a = skips
        .iter()
        .map(|r| r.errors.a)
        .fold(f64::INFINITY, f64::min);
    assert!(
        best_v < 0.8 * s0.v,
        "velocity: best skip {best_v} vs no skip {}",
        s0.v
    );
    assert!(
        best_a < 0.5 * s0.a,
        "acceleration: best skip {best_a} vs no skip {}",
        s0.a
    );
    assert!(get(&rows, "differencing").errors.v > 10.0 * s0.v);
    let hots = get(&rows, "HOTS").errors;
    assert!(hots.v < best_v && hots.a < best_a);

    let ideal = sec8_5(&[]).unwrap();
    let i0 = get(&ideal, "time-stamping m=2 n=5 σ=0").errors;
    for r in ideal
        .iter()
        .filter(|r| r.method.starts_with("time-stamping"))
    {
        assert!(
            r.errors.v >= i0.v && r.errors.a >= i0.a,
            "without slit errors a skip only adds truncation error: {}",
            r.method
        );
    }
    assert!(get(&ideal, "time-stamping m=2 n=5 σ=20").errors.v > 5.0 * i0.v);
}
