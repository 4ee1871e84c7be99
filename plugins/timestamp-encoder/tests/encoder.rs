//! Encoder events, register and estimator against closed forms.

use nanomotion_core::{Block, BuildContext, Estimator, Sensor, Tick};
use std::f64::consts::{FRAC_PI_2, PI, TAU};
use timestamp_encoder::skip::register_indices;
use timestamp_encoder::{Fallback, Status, TimestampEncoder, TimestampEstimator};

const CLOCK: f64 = 50e-9;

/// Collect every event (t, level) of a run, newest-last.
fn run_events(
    enc: &mut TimestampEncoder,
    ticks: usize,
    dt: f64,
    traj: impl Fn(f64) -> [f64; 3],
) -> Vec<(f64, f64)> {
    let w = enc.input_width();
    let mut reg = vec![0.0; enc.register_width()];
    let mut out = Vec::new();
    let mut seen = 0;
    for k in 0..=ticks {
        let t = k as f64 * dt;
        enc.measure(t, &traj(t)[..w], &mut reg);
        for e in seen + 1..=enc.events_so_far() {
            out.push(enc.event(e).expect("history holds every event of one tick"));
        }
        seen = enc.events_so_far();
    }
    out
}

#[test]
fn crossing_times_of_a_cubic_with_reversals_are_exact_to_the_clock() {
    // x(t) = 3t − 12t² + 10t³ (rad): turns at t ≈ 0.173 and 0.627 s.
    let x = |t: f64| 3.0 * t - 12.0 * t * t + 10.0 * t * t * t;
    let v = |t: f64| 3.0 - 24.0 * t + 30.0 * t * t;
    let mut enc = TimestampEncoder {
        register_len: 16,
        ..Default::default()
    };
    enc.prepare(0).unwrap();
    let d = enc.resolution();
    let ev = run_events(&mut enc, 1000, 1e-3, |t| [x(t), v(t), 0.0]);
    assert_eq!(ev.len(), 137, "13 up, 37 down, 87 up");
    let (mut up, mut down) = (0, 0);
    for (i, &(ts, level)) in ev.iter().enumerate() {
        // The true crossing: bisection on x(t) − LΔ in the monotone branch around ts.
        let target = level * d;
        let (mut lo, mut hi) = (ts - 2e-6, ts + 2e-6);
        let s = (x(hi) - x(lo)).signum();
        if s > 0.0 {
            up += 1
        } else {
            down += 1
        }
        for _ in 0..100 {
            let mid = 0.5 * (lo + hi);
            if s * (x(mid) - target) < 0.0 {
                lo = mid
            } else {
                hi = mid
            }
        }
        let t_true = 0.5 * (lo + hi);
        let err = t_true - ts;
        assert!(
            (-1e-12..CLOCK + 1e-12).contains(&err),
            "event {i}: level {level}, stamp {ts}, true {t_true}"
        );
        assert!(
            (ts * 20e6 - (ts * 20e6).round()).abs() < 1e-3,
            "on the 20 MHz grid"
        );
    }
    assert_eq!((up, down), (100, 37));
    // The final count is the cell of the final position.
    assert_eq!(enc.count(), (x(1.0) / d).floor() as i64);
}

#[test]
fn crossing_times_of_a_sinusoid_match_arcsin() {
    // Sec. 8.5's motion: x = (π/2) sin(2π t) rad, quintic interpolation at 1 kHz.
    let (a, w) = (FRAC_PI_2, TAU);
    let mut enc = TimestampEncoder {
        derivatives: 2,
        register_len: 16,
        ..Default::default()
    };
    enc.prepare(0).unwrap();
    let d = enc.resolution();
    let traj = |t: f64| {
        [
            a * (w * t).sin(),
            a * w * (w * t).cos(),
            -a * w * w * (w * t).sin(),
        ]
    };
    let ev = run_events(&mut enc, 2000, 1e-3, traj);
    // π/2 rad = 100 counts; per period 100 up, 200 down, 100 up: 800 events in two
    // periods, less the edges at exactly ±100 counts that the peaks only touch.
    assert!((796..=800).contains(&ev.len()), "{}", ev.len());
    let mut worst: f64 = 0.0;
    for &(ts, level) in &ev {
        let y = (level * d / a).clamp(-1.0, 1.0);
        let base = y.asin() / w;
        let cands = [
            base,
            0.5 - base,
            1.0 + base,
            1.5 - base,
            2.0 + base,
            2.5 - base,
        ];
        let t_true = cands
            .iter()
            .copied()
            .min_by(|p, q| (p - ts).abs().total_cmp(&(q - ts).abs()))
            .unwrap();
        let err = t_true - ts;
        // Near the turning points the crossing is ill-conditioned (|ẋ| → 0): allow
        // the interpolation error δx/|ẋ| with δx ~ 1e-13 rad.
        let vel = (a * w * (w * t_true).cos()).abs();
        let tol = 1e-12 + 1e-13 / vel.max(1e-12);
        assert!(
            err > -tol && err < CLOCK + tol,
            "level {level}: err {err:e}"
        );
        worst = worst.max(err);
    }
    assert!(
        worst > 0.5 * CLOCK,
        "the clock quantisation shows: {worst:e}"
    );
}

#[test]
fn slit_errors_move_the_edges() {
    // Constant velocity: edge L crosses at (L + e_L)Δ/w.
    let table: Vec<f64> = (0..400)
        .map(|l| 0.1 * ((l * 7919) % 13) as f64 / 13.0 - 0.05)
        .collect();
    let mut enc = TimestampEncoder {
        register_len: 16,
        slit_errors_counts: table,
        quadrature_error_counts: 0.03,
        duty_error_counts: -0.02,
        eccentricity_counts: 0.05,
        slit_error_std_counts: 0.02,
        ..Default::default()
    };
    enc.prepare(3).unwrap();
    let e = enc.edge_errors_counts().to_vec();
    let d = enc.resolution();
    let w = 3.0;
    let ev = run_events(&mut enc, 2500, 1e-3, |t| [0.1 + w * t, w, 0.0]);
    assert_eq!(ev.len(), 477, "7.5 rad at 400/2π counts per rad");
    for &(ts, level) in &ev {
        let l = level as i64;
        let t_true = ((l as f64 + e[l.rem_euclid(400) as usize]) * d - 0.1) / w;
        assert!((0.0..CLOCK + 1e-12).contains(&(t_true - ts)), "level {l}");
    }
    // The composition of the error sources: quadrature on odd edges.
    let mut plain = TimestampEncoder {
        quadrature_error_counts: 0.03,
        ..Default::default()
    };
    plain.prepare(0).unwrap();
    assert_eq!(plain.edge_errors_counts()[1], 0.03);
    assert_eq!(plain.edge_errors_counts()[2], 0.0);
}

#[test]
fn register_follows_the_skip_rule() {
    for sigma in [0i64, 1, 2, 3, 5, 10] {
        let mut enc = TimestampEncoder {
            skip: sigma,
            ..Default::default()
        };
        enc.prepare(0).unwrap();
        let mut reg = vec![0.0; enc.register_width()];
        let d = enc.resolution();
        let mut idx = [0u64; 5];
        for k in 0..=400 {
            let t = k as f64 * 1e-3;
            // Starts exactly on edge 0: event j is the crossing of level j.
            enc.measure(t, &[0.7 * t, 0.7], &mut reg);
            let n = register_indices(enc.events_so_far(), sigma as u64, &mut idx);
            assert_eq!(reg[0], ((0.7 * t) / d + 1e-9).floor(), "count");
            assert_eq!(reg[1] as usize, n);
            for i in 0..n {
                assert_eq!(
                    reg[3 + 2 * i],
                    idx[i] as f64,
                    "σ {sigma}, tick {k}, entry {i}"
                );
                let t_edge = idx[i] as f64 * d / 0.7;
                assert!((t_edge - reg[2 + 2 * i]).abs() < CLOCK + 1e-12);
            }
            for i in n..5 {
                assert_eq!((reg[2 + 2 * i], reg[3 + 2 * i]), (0.0, 0.0));
            }
        }
    }
}

#[test]
fn a_jump_keeps_the_count_and_numbering_exact() {
    let mut enc = TimestampEncoder::default();
    enc.prepare(0).unwrap();
    let mut reg = vec![0.0; enc.register_width()];
    let d = enc.resolution();
    enc.measure(0.0, &[0.0, 0.0], &mut reg);
    enc.measure(1e-3, &[1e5 * d + 0.5 * d, 0.0], &mut reg);
    assert_eq!(enc.count(), 100_000);
    assert_eq!(enc.events_so_far(), 100_000);
    assert_eq!(reg[3], 100_000.0);
    assert_eq!(reg[5], 99_999.0);
    // Back down.
    enc.measure(2e-3, &[-3.5 * d, 0.0], &mut reg);
    assert_eq!(enc.count(), -4);
    assert_eq!(enc.events_so_far(), 200_004);
    assert_eq!(
        reg[3], -3.0,
        "the newest edge crossed downwards is level −3"
    );
    // Non-finite input is ignored.
    enc.measure(3e-3, &[f64::NAN, 0.0], &mut reg);
    assert_eq!(enc.count(), -4);
}

#[test]
fn estimator_recovers_a_quadratic_trajectory() {
    // Ideal encoder, x = 0.3 + 2t + 1.5t² (rad): the events lie on an order-2
    // polynomial up to the 50 ns stamps, so m = 2 recovers it to ~v·50 ns.
    let mut enc = TimestampEncoder {
        derivatives: 2,
        ..Default::default()
    };
    enc.prepare(0).unwrap();
    let mut est = TimestampEstimator::new(2, 5, enc.resolution()).unwrap();
    let (mut reg, mut y) = (vec![0.0; 12], [0.0; 3]);
    let d = enc.resolution();
    for k in 0..=1000 {
        let t = k as f64 * 1e-3;
        let tr = [0.3 + 2.0 * t + 1.5 * t * t, 2.0 + 3.0 * t, 3.0];
        enc.measure(t, &tr, &mut reg);
        est.estimate(t, &reg, &mut y);
        if k > 50 {
            // Five events exist after ~40 ms.
            assert_eq!(est.status(), Some(Status::Fitted));
            // Clock error ≤ v·50 ns ≈ 2.5e-7 rad ≈ 1.6e-5 counts.
            assert!(
                (y[0] - tr[0]).abs() < 0.002 * d,
                "x at {t}: {}",
                (y[0] - tr[0]) / d
            );
            assert!(
                (y[1] - tr[1]).abs() < 2e-3 * tr[1],
                "v at {t}: {} vs {}",
                y[1],
                tr[1]
            );
            assert!(
                (y[2] - tr[2]).abs() < 0.3,
                "a at {t}: {} vs {}",
                y[2],
                tr[2]
            );
        }
    }
}

/// A hand-built register: the five levels 0..4 crossed by p(t) = v0 t + ½ a0 t²
/// (counts, s), newest first, count `c`. Times solve p(t_L) = L in closed form.
fn quadratic_register(v0: f64, a0: f64, c: f64) -> Vec<f64> {
    let mut reg = vec![c, 5.0];
    for level in (0..5).rev() {
        let l = level as f64;
        reg.push((-v0 + (v0 * v0 + 2.0 * a0 * l).sqrt()) / a0);
        reg.push(l);
    }
    reg
}

#[test]
fn fallback_rules_on_a_constructed_register() {
    // Events exactly on p(t) = v0 t + ½ a0 t² (counts); m = 2, n = 5 fits p exactly,
    // so the fit's x̂, v̂, â at t_c are p(t_c), p'(t_c) = v0 + a0 t_c, p'' = a0.
    // The count says 4 (cell centre 4.5, band ±1): p(t_c) = 5 is in band, p(t_c) = 6
    // is 1.5 counts out.
    let (v0, a0, d) = (1000.0, 1e5, 0.5);
    let reg = quadratic_register(v0, a0, 4.0);
    let t_at = |x: f64| (-v0 + (v0 * v0 + 2.0 * a0 * x).sqrt()) / a0;
    let close = |a: f64, b: f64| (a - b).abs() <= 1e-7 * b.abs().max(1.0);
    for fallback in [Fallback::Thesis, Fallback::ZeroStandstill] {
        let mut est = TimestampEstimator::new(2, 5, d).unwrap();
        est.fallback = fallback;
        let mut y = [0.0; 3];
        // In band: the fit, under both rules.
        let tc = t_at(5.0);
        assert_eq!(est.estimate_from_register(tc, &reg, &mut y), Status::Fitted);
        assert!(close(y[0], 5.0 * d), "{fallback:?} {y:?}");
        assert!(close(y[1], (v0 + a0 * tc) * d), "{fallback:?} {y:?}");
        assert!(close(y[2], a0 * d), "{fallback:?} {y:?}");
        // Out of band: position = the count's cell centre under both rules.
        let tc = t_at(6.0);
        assert_eq!(
            est.estimate_from_register(tc, &reg, &mut y),
            Status::OutOfBand
        );
        assert_eq!(y[0], 4.5 * d, "{fallback:?}");
        match fallback {
            // Sec. 8.3: only x̂ is replaced; v̂, â are the fit's.
            Fallback::Thesis => {
                assert!(close(y[1], (v0 + a0 * tc) * d), "{y:?}");
                assert!(close(y[2], a0 * d), "{y:?}");
            }
            Fallback::ZeroStandstill => assert_eq!([y[1], y[2]], [0.0, 0.0]),
            Fallback::PseudoEvent => unreachable!("tested in the hots crate"),
        }
        // 20 ms after the newest event (window span 3.4 ms): standstill only under
        // the zero_standstill rule; the thesis rule still extrapolates (far out of
        // band: x = centre, v̂ and â from the fit).
        let t_new = reg[2];
        let tc = t_new + 0.02;
        let s = est.estimate_from_register(tc, &reg, &mut y);
        assert_eq!(y[0], 4.5 * d);
        match fallback {
            Fallback::Thesis => {
                assert_eq!(s, Status::OutOfBand);
                assert!(close(y[1], (v0 + a0 * tc) * d), "{y:?}");
            }
            Fallback::ZeroStandstill => {
                assert_eq!(s, Status::Standstill);
                assert_eq!([y[1], y[2]], [0.0, 0.0]);
            }
            Fallback::PseudoEvent => unreachable!("tested in the hots crate"),
        }
    }
    // YAML: the default is the thesis's rule; the other is named; a typo is an error.
    let est: Box<dyn Block> =
        nanomotion_core::yaml::from_str("type: timestamp_estimator\nresolution: 1\n", "t").unwrap();
    assert!(format!("{est:?}").contains("fallback: Thesis"));
    let est: Box<dyn Block> = nanomotion_core::yaml::from_str(
        "type: timestamp_estimator\nresolution: 1\nfallback: zero_standstill\n",
        "t",
    )
    .unwrap();
    assert!(format!("{est:?}").contains("fallback: ZeroStandstill"));
    assert!(
        nanomotion_core::yaml::from_str::<Box<dyn Block>>(
            "type: timestamp_estimator\nresolution: 1\nfallback: zero\n",
            "t"
        )
        .is_err()
    );
}

#[test]
fn standstill_and_reversal() {
    let mut enc = TimestampEncoder::default();
    enc.prepare(0).unwrap();
    let d = enc.resolution();
    // The zero-and-standstill rule (the thesis's rule has no standstill state).
    let mut est = TimestampEstimator::new(2, 5, d).unwrap();
    est.fallback = Fallback::ZeroStandstill;
    let (mut reg, mut y) = (vec![0.0; 12], [0.0; 3]);
    // No events yet.
    enc.measure(0.0, &[0.25 * d, 0.0], &mut reg);
    est.estimate(0.0, &reg, &mut y);
    assert_eq!(est.status(), Some(Status::NoEvents));
    assert_eq!(y, [0.5 * d, 0.0, 0.0]);
    // Move at 1 rad/s for 0.1 s, then stop dead (x held, v = 0).
    let stop = 0.1 + 0.3 * d;
    let mut statuses = Vec::new();
    for k in 1..=200 {
        let t = k as f64 * 1e-3;
        let (x, v) = if t < 0.1 {
            (0.3 * d + t, 1.0)
        } else {
            (stop, 0.0)
        };
        enc.measure(t, &[x, v], &mut reg);
        est.estimate(t, &reg, &mut y);
        statuses.push(est.status().unwrap());
        let err = (y[0] - x) / d;
        // Never worse than the count's own cell, whatever the status.
        assert!(
            err.abs() <= 1.0 + 1e-9,
            "t {t}: err {err} counts, {:?}",
            est.status()
        );
        if t > 0.1 + 0.04 {
            assert_eq!(est.status(), Some(Status::Standstill), "t {t}");
            assert_eq!(y[1], 0.0);
            assert!((y[0] - x).abs() <= 0.5 * d);
        }
        if (0.05..0.099).contains(&t) {
            assert_eq!(est.status(), Some(Status::Fitted));
            assert!((y[1] - 1.0).abs() < 1e-3);
        }
    }
    // Reversal of x = (π/2) sin(2πt) at t = 0.25 s: the order-2 fit follows the turn.
    let mut enc = TimestampEncoder::default();
    enc.prepare(0).unwrap();
    let mut est = TimestampEstimator::new(2, 5, d).unwrap();
    let mut worst: f64 = 0.0;
    for k in 0..=500 {
        let t = k as f64 * 1e-3;
        let tr = [FRAC_PI_2 * (TAU * t).sin(), PI * PI * (TAU * t).cos()];
        enc.measure(t, &tr, &mut reg);
        est.estimate(t, &reg, &mut y);
        if k > 5 {
            worst = worst.max((y[0] - tr[0]).abs() / d);
            assert!((y[0] - tr[0]).abs() <= 1.0 * d);
        }
    }
    assert!(
        worst < 0.5,
        "worst position error around the reversals {worst} counts"
    );
}

#[test]
fn blocks_from_yaml_validate_and_run() {
    let enc: Box<dyn Block> = nanomotion_core::yaml::from_str(
        "type: timestamp_encoder\nlines: 100\nskip: 3\nregister_len: 5\nslit_error_std_counts: 0.02\n",
        "t",
    )
    .unwrap();
    let est: Box<dyn Block> = nanomotion_core::yaml::from_str(
        "type: timestamp_estimator\norder: 2\nregister_len: 5\nresolution: 0.015707963267948967\n",
        "t",
    )
    .unwrap();
    let (mut enc, mut est) = (enc, est);
    enc.build(&BuildContext::new("enc", 1e-3, 5)).unwrap();
    est.build(&BuildContext::new("est", 1e-3, 6)).unwrap();
    assert_eq!(enc.inputs()[0].width, 2);
    assert_eq!(enc.outputs()[0].width, 12);
    assert_eq!(est.inputs()[0].width, 12);
    let (mut ey, mut sy) = ([0.0; 13], [0.0; 4]);
    let mut last = [0.0; 3];
    let info = allocation_counter::measure(|| {
        for k in 0..10_000u64 {
            let tick = Tick::new(k, 1e-3);
            let t = tick.t;
            let u = [FRAC_PI_2 * (TAU * t).sin(), PI * PI * (TAU * t).cos()];
            enc.output(tick, &u, &mut ey);
            est.output(tick, &ey[..12], &mut sy);
            last.copy_from_slice(&sy[..3]);
        }
    });
    assert_eq!(info.count_total, 0, "no allocation in 10 000 ticks");
    assert!(last.iter().all(|v| v.is_finite()));
    // Typed errors naming the field.
    let err = |text: &str| {
        let mut b: Box<dyn Block> = nanomotion_core::yaml::from_str(text, "t").unwrap();
        b.build(&BuildContext::new("b", 1e-3, 0)).unwrap_err().field
    };
    assert_eq!(err("type: timestamp_encoder\nskip: -1\n"), "skip");
    assert_eq!(err("type: timestamp_encoder\nclock_hz: 0\n"), "clock_hz");
    assert_eq!(err("type: timestamp_encoder\nlines: 0\n"), "lines");
    assert_eq!(
        err("type: timestamp_encoder\nregister_len: 0\n"),
        "register_len"
    );
    assert_eq!(
        err("type: timestamp_encoder\nregister_len: 17\n"),
        "register_len"
    );
    assert_eq!(
        err("type: timestamp_encoder\nrevolution: -1\n"),
        "revolution"
    );
    assert_eq!(
        err("type: timestamp_encoder\nderivatives: 3\n"),
        "derivatives"
    );
    assert_eq!(
        err("type: timestamp_encoder\nslit_errors_counts: [0.1, 0.2]\n"),
        "slit_errors_counts"
    );
    assert_eq!(
        err("type: timestamp_encoder\nquadrature_error_counts: 0.7\nduty_error_counts: 0.7\n"),
        "slit_errors_counts"
    );
    assert_eq!(
        err("type: timestamp_encoder\neccentricity_counts: .nan\n"),
        "eccentricity_counts"
    );
    assert_eq!(
        err("type: timestamp_estimator\nresolution: 1\norder: 2\nregister_len: 2\n"),
        "register_len"
    );
    assert_eq!(
        err("type: timestamp_estimator\nresolution: 1\norder: 5\nregister_len: 8\n"),
        "order"
    );
    assert_eq!(
        err("type: timestamp_estimator\nresolution: 0\n"),
        "resolution"
    );
    assert_eq!(
        err("type: timestamp_estimator\nresolution: 1\nband_counts: -1\n"),
        "band_counts"
    );
    assert!(
        nanomotion_core::yaml::from_str::<Box<dyn Block>>("type: timestamp_encoder\nskp: 1\n", "t")
            .is_err()
    );
    assert!(TimestampEstimator::new(2, 2, 1.0).is_err());
    // Bounds declared on the estimator's fields (one declaration for build() and
    // the schema).
    assert_eq!(
        err("type: timestamp_estimator\nresolution: 1\nregister_len: 17\n"),
        "register_len"
    );
    assert_eq!(
        err("type: timestamp_estimator\nresolution: 1\nstandstill_timeout_s: -0.1\n"),
        "standstill_timeout_s"
    );
    assert_eq!(
        err("type: timestamp_estimator\nresolution: 1\nedge_offsets_counts: [0.1, .nan]\n"),
        "edge_offsets_counts[1]"
    );
    assert_eq!(
        TimestampEstimator::new(5, 8, 1.0).unwrap_err().field,
        "order"
    );
    use nanomotion_core::doc::Params;
    let docs = TimestampEstimator::param_docs();
    let schema = |name: &str| docs.iter().find(|p| p.name == name).unwrap().schema.clone();
    assert_eq!(schema("order")["maximum"], 4);
    assert_eq!(schema("register_len")["minimum"], 1);
    assert_eq!(schema("register_len")["maximum"], 16);
    assert_eq!(schema("resolution")["exclusiveMinimum"], 0);
    let docs = TimestampEncoder::param_docs();
    let derivatives = docs.iter().find(|p| p.name == "derivatives").unwrap();
    assert_eq!(derivatives.schema["maximum"], 2);
    let register_len = docs.iter().find(|p| p.name == "register_len").unwrap();
    assert_eq!(register_len.schema["maximum"], 16);
}

#[test]
fn determinism_of_seeded_slit_errors() {
    let make = |seed| {
        let mut e = TimestampEncoder {
            slit_error_std_counts: 0.05,
            ..Default::default()
        };
        e.prepare(seed).unwrap();
        e.edge_errors_counts().to_vec()
    };
    assert_eq!(make(4), make(4));
    assert_ne!(make(4), make(5));
    let e = make(4);
    // Shared by the four edges of a slit.
    assert_eq!(e[4], e[7]);
    let rms = (e.iter().map(|v| v * v).sum::<f64>() / 400.0).sqrt();
    assert!((0.035..0.065).contains(&rms), "{rms}");
}

/// Audit D9: with `lines: 2^20`, `register_len: 16`, `skip: 10^6` every tick timed
/// the last 16 M edge crossings (0.5 s per tick); only the n + 1 the register can
/// read are timed now.
#[test]
fn the_work_per_tick_is_bounded_by_the_register_not_the_skip() {
    let mut enc = TimestampEncoder {
        lines: 1 << 20,
        register_len: 16,
        skip: 1_000_000,
        derivatives: 0,
        ..Default::default()
    };
    enc.prepare(0).unwrap();
    let mut reg = vec![0.0; enc.register_width()];
    let start = std::time::Instant::now();
    for k in 0..=50 {
        let t = k as f64 * 1e-3;
        let x = 1000.0 * (TAU * 10.0 * t).sin();
        enc.measure(t, &[x], &mut reg);
    }
    assert!(enc.events_so_far() > 100_000_000, "{}", enc.events_so_far());
    assert!(
        start.elapsed().as_secs_f64() < 2.0,
        "{:?} for 50 ticks",
        start.elapsed()
    );
}

proptest::proptest! {
    /// The register with skip σ reads the same events (times and levels) as an
    /// encoder that times every crossing (σ = 0, a history of n(σ + 1)).
    #[test]
    fn skipping_the_timing_of_unread_events_changes_no_register(
        sigma in 0i64..4,
        n in 1usize..5,
        amp in 0.5f64..40.0,
        f in 1.0f64..30.0,
    ) {
        let n = n.min(16 / (sigma as usize + 1)).max(1);
        let mut a = TimestampEncoder { skip: sigma, register_len: n, derivatives: 0, ..Default::default() };
        let mut b = TimestampEncoder { skip: 0, register_len: n * (sigma as usize + 1), derivatives: 0, ..Default::default() };
        a.prepare(0).unwrap();
        b.prepare(0).unwrap();
        let mut ra = vec![0.0; a.register_width()];
        let mut rb = vec![0.0; b.register_width()];
        let mut idx = vec![0u64; n];
        for k in 0..=300 {
            let t = k as f64 * 1e-3;
            let x = [amp * (TAU * f * t).sin()];
            a.measure(t, &x, &mut ra);
            b.measure(t, &x, &mut rb);
            proptest::prop_assert_eq!(a.events_so_far(), b.events_so_far());
            let valid = register_indices(a.events_so_far(), sigma as u64, &mut idx);
            proptest::prop_assert_eq!(ra[1] as usize, valid);
            for i in 0..valid {
                let (tb, lb) = b.event(idx[i]).unwrap();
                proptest::prop_assert_eq!((ra[2 + 2 * i], ra[3 + 2 * i]), (tb, lb), "tick {}, entry {}", k, i);
            }
        }
    }
}

/// Issue 25 (class 3): the encoder declares its error tables (5 values per
/// line) before it is built, so a graph of many encoders with the most lines
/// is refused naming `lines` before any table is allocated (110 × 40 MiB >
/// 4 GiB).
#[test]
fn encoder_tables_are_declared_and_many_large_encoders_are_refused_before_allocating() {
    let text = |lines: usize| format!("type: timestamp_encoder\nlines: {lines}\n");
    let mut b: Box<dyn Block> = nanomotion_core::yaml::from_str(&text(100), "t").unwrap();
    assert_eq!(b.planned_bytes(1e-3), ("lines", 100 * 5 * 8));
    b.build(&BuildContext::new("enc", 1e-3, 1)).unwrap();
    assert_eq!(b.memory_bytes(), b.planned_bytes(1e-3).1);
    let mut yaml = String::from("base_rate_hz: 1000\nduration_s: 0.01\nblocks:\n");
    for i in 0..110 {
        yaml.push_str(&format!(
            "  - {{ name: e{i}, type: timestamp_encoder, lines: {} }}\n",
            timestamp_encoder::encoder::MAX_LINES
        ));
    }
    let e = nanomotion_core::graph::GraphSpec::from_yaml(&yaml, "encoders.yaml")
        .unwrap()
        .build()
        .expect_err("refused")
        .to_string();
    assert!(
        e.contains("field `lines`") && e.contains("block `e102`"),
        "{e}"
    );
    assert!(e.contains("checked before anything is allocated"), "{e}");
}

/// `skip` (an i64) is bounded by its declaration (`range(0, 1_000_000)`, #26):
/// both ends refused outside with the same words, the schema an integer in
/// [0, 10⁶]; `fallback` lists its choices.
#[test]
fn skip_is_a_declared_integer_bound_and_fallback_lists_its_choices() {
    use nanomotion_core::doc::Params;
    for (text, problem) in [
        (
            "type: timestamp_encoder\nskip: -1\n",
            "is -1, outside the allowed range [0, 1000000]",
        ),
        (
            "type: timestamp_encoder\nskip: 1000001\n",
            "is 1000001, outside the allowed range [0, 1000000]",
        ),
    ] {
        let mut b: Box<dyn Block> = nanomotion_core::yaml::from_str(text, "t").unwrap();
        let e = b.build(&BuildContext::new("b", 1e-3, 0)).unwrap_err();
        assert_eq!((e.field.as_str(), e.problem.as_str()), ("skip", problem));
        assert_eq!(e.fix, "give a whole number in [0, 1000000]");
    }
    let docs = TimestampEncoder::param_docs();
    let skip = docs.iter().find(|p| p.name == "skip").unwrap();
    assert_eq!(skip.schema["type"], "integer");
    assert_eq!(skip.schema["minimum"], 0);
    assert_eq!(skip.schema["maximum"], 1_000_000);
    let docs = TimestampEstimator::param_docs();
    let fallback = docs.iter().find(|p| p.name == "fallback").unwrap();
    let listed: Vec<String> = fallback.schema["enum"]
        .as_array()
        .unwrap()
        .iter()
        .map(|v| v.as_str().unwrap().to_string())
        .collect();
    for n in &listed {
        let _: Fallback = nanomotion_core::yaml::from_str(n, "t").unwrap();
    }
    assert!(nanomotion_core::yaml::from_str::<Fallback>("Thesis", "t").is_err());
    assert_eq!(listed, ["thesis", "zero_standstill", "pseudo_event"]);
}
