//! Simulation harness: an encoder and an estimator on a known trajectory, read at a
//! fixed rate, with rms errors against the truth. Used for the brute-force check of
//! the error model, the calibration tests and the Sec. 8.5 comparison.

use nanomotion_core::ParamError;
use timestamp_encoder::{Status, TimestampEncoder, TimestampEstimator};

/// A run: time, truth and estimates at each read (units of the trajectory).
#[derive(Debug, Clone, Default)]
pub struct Run {
    /// Read times (s).
    pub t: Vec<f64>,
    /// True [x, v, a].
    pub truth: Vec<[f64; 3]>,
    /// Estimated [x̂, v̂, â].
    pub est: Vec<[f64; 3]>,
    /// The count as a position c·Δ at each read.
    pub count_pos: Vec<f64>,
    /// Reads whose estimate fell back to the count.
    pub fallbacks: usize,
    /// All events (t_k, level) of the run, in order.
    pub events: Vec<(f64, f64)>,
}

/// Rms errors of a run (units, units/s, units/s²).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Errors {
    /// rms position error.
    pub x: f64,
    /// rms velocity error.
    pub v: f64,
    /// rms acceleration error.
    pub a: f64,
}

impl Run {
    /// Rms errors of the estimates after `settle_s`.
    pub fn errors(&self, settle_s: f64) -> Errors {
        let mut s = [0.0; 3];
        let mut n = 0usize;
        for (i, &t) in self.t.iter().enumerate() {
            if t < settle_s {
                continue;
            }
            for (j, sj) in s.iter_mut().enumerate() {
                *sj += (self.est[i][j] - self.truth[i][j]).powi(2);
            }
            n += 1;
        }
        let n = n.max(1) as f64;
        Errors {
            x: (s[0] / n).sqrt(),
            v: (s[1] / n).sqrt(),
            a: (s[2] / n).sqrt(),
        }
    }

    /// Rms errors of plain differencing of the count at the read rate: x = c·Δ + Δ/2,
    /// v by backward difference, a by the second backward difference.
    pub fn differencing_errors(&self, settle_s: f64, resolution: f64) -> Errors {
        let mut s = [0.0; 3];
        let mut n = 0usize;
        for i in 2..self.t.len() {
            if self.t[i] < settle_s {
                continue;
            }
            let dt = self.t[i] - self.t[i - 1];
            let x = self.count_pos[i] + 0.5 * resolution;
            let v = (self.count_pos[i] - self.count_pos[i - 1]) / dt;
            let a = (self.count_pos[i] - 2.0 * self.count_pos[i - 1] + self.count_pos[i - 2])
                / (dt * dt);
            s[0] += (x - self.truth[i][0]).powi(2);
            s[1] += (v - self.truth[i][1]).powi(2);
            s[2] += (a - self.truth[i][2]).powi(2);
            n += 1;
        }
        let n = n.max(1) as f64;
        Errors {
            x: (s[0] / n).sqrt(),
            v: (s[1] / n).sqrt(),
            a: (s[2] / n).sqrt(),
        }
    }
}

/// Run `encoder` (parameters set, not yet prepared) with an order-`order`
/// estimator (optionally with a calibration table `edge_offsets_counts`) on the
/// trajectory `traj(t) = [x, v, a]` for `duration_s`, reading at `read_hz`. The
/// encoder is fed the trajectory at each read (quintic interpolation between
/// reads, so its events are exact). `keep_events` records every event.
#[allow(clippy::too_many_arguments)]
pub fn simulate(
    encoder: &TimestampEncoder,
    order: usize,
    edge_offsets_counts: &[f64],
    read_hz: f64,
    duration_s: f64,
    seed: u64,
    keep_events: bool,
    traj: impl Fn(f64) -> [f64; 3],
) -> Result<Run, ParamError> {
    let mut enc = encoder.clone();
    enc.derivatives = 2;
    enc.prepare(seed)?;
    let mut est = TimestampEstimator::new(order, enc.register_len, enc.resolution())?;
    est.edge_offsets_counts = edge_offsets_counts.to_vec();
    est.validate()?;
    let mut reg = vec![0.0; enc.register_width()];
    let ticks = (duration_s * read_hz).round() as usize;
    let mut run = Run::default();
    let mut seen = 0;
    for k in 0..=ticks {
        let t = k as f64 / read_hz;
        let tr = traj(t);
        enc.advance(t, &tr);
        enc.read_register(&mut reg);
        let mut y = [0.0; 3];
        if est.estimate_from_register(t, &reg, &mut y) != Status::Fitted {
            run.fallbacks += 1;
        }
        if keep_events {
            for e in seen + 1..=enc.events_so_far() {
                if let Some(ev) = enc.event(e) {
                    run.events.push(ev);
                }
            }
            seen = enc.events_so_far();
        }
        run.t.push(t);
        run.truth.push(tr);
        run.est.push(y);
        run.count_pos.push(enc.count() as f64 * enc.resolution());
    }
    Ok(run)
}

/// One row of the Sec. 8.5 comparison (rms errors in rad, rad/s, rad/s²).
#[derive(Debug, Clone)]
pub struct Sec85Row {
    /// What was run.
    pub method: String,
    /// Errors against the true trajectory.
    pub errors: Errors,
}

/// The Sec. 8.5 experiment on simulation: a 100-line encoder on a rotating mass
/// following x = (π/2) sin(2π t) rad, read at 1 kHz, 20 MHz clock, m = 2, n = 5,
/// for plain differencing, each skip σ ∈ {0, 1, 2, 3, 4, 5, 10, 20}, and HOTS
/// (optimised (m, n, σ) for velocity) with a slit calibration learned from a
/// separate constant-speed run. `slit_errors_counts` are per-slit (100) or
/// per-edge (400) errors (empty: an ideal encoder). Errors are taken over 2 s after
/// 0.1 s, against the true trajectory.
pub fn sec8_5(slit_errors_counts: &[f64]) -> Result<Vec<Sec85Row>, ParamError> {
    use crate::model::{ErrorModel, Grid, Target, optimise, sinusoid_samples};
    let (a, w) = (std::f64::consts::FRAC_PI_2, std::f64::consts::TAU);
    let traj = move |t: f64| {
        [
            a * (w * t).sin(),
            a * w * (w * t).cos(),
            -a * w * w * (w * t).sin(),
        ]
    };
    let base = TimestampEncoder {
        slit_errors_counts: slit_errors_counts.to_vec(),
        ..Default::default()
    };
    let mut rows = Vec::new();
    let r0 = simulate(&base, 2, &[], 1e3, 2.1, 0, false, traj)?;
    rows.push(Sec85Row {
        method: "differencing".into(),
        errors: r0.differencing_errors(0.1, base.resolution()),
    });
    for sigma in [0i64, 1, 2, 3, 4, 5, 10, 20] {
        let enc = TimestampEncoder {
            skip: sigma,
            ..base.clone()
        };
        let run = simulate(&enc, 2, &[], 1e3, 2.1, 0, false, traj)?;
        rows.push(Sec85Row {
            method: format!("time-stamping m=2 n=5 σ={sigma}"),
            errors: run.errors(0.1),
        });
    }
    // HOTS: calibrate on a separate run (2 rev/s, 20 revolutions), then choose
    // (m, n, σ) from the calibrated error model (residual edge errors ≈ 0: the
    // clock and truncation remain) for the thesis's hardware (n = 5).
    let mut cal_enc = base.clone();
    cal_enc.register_len = 16;
    let wc = 2.0 * w;
    let cal_run = simulate(&cal_enc, 2, &[], 1e3, 10.0, 0, true, move |t| {
        [wc * t, wc, 0.0]
    })?;
    let (t, l): (Vec<f64>, Vec<f64>) = cal_run.events.iter().copied().unzip();
    let cal = crate::SlitCalibration::learn(&t, &l, 400, 2, 800).map_err(|e| {
        ParamError::new(
            "slit_errors_counts",
            e.to_string(),
            "give a calibratable encoder",
        )
    })?;
    let model = ErrorModel::white(cal.residual_rms_counts, enc_clock(&base));
    let best = optimise(
        &Grid::thesis_hardware(),
        Target::Velocity,
        &model,
        &sinusoid_samples(100.0, 1.0, 1000),
    )[0]
    .0;
    let enc = TimestampEncoder {
        skip: best.skip as i64,
        register_len: best.register_len,
        ..base.clone()
    };
    let run = simulate(
        &enc,
        best.order,
        &cal.edge_offsets_counts,
        1e3,
        2.1,
        0,
        false,
        traj,
    )?;
    rows.push(Sec85Row {
        method: format!(
            "HOTS + calibration (m={} n={} σ={})",
            best.order, best.register_len, best.skip
        ),
        errors: run.errors(0.1),
    });
    Ok(rows)
}

fn enc_clock(e: &TimestampEncoder) -> f64 {
    e.clock_hz
}
