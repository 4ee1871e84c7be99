//! Simulation harness: an encoder and an estimator on a known trajectory, read at a
//! fixed rate, with rms errors against the truth. Used for the brute-force check of
//! the error model, the calibration tests and the Sec. 8.5 comparison
//! ([`sec8_5`]), which also scores every method against the thesis's reference — a
//! 5000-line encoder filtered forward-backward by a 5th-order 50 Hz Butterworth
//! low-pass ([`reference_encoder`]).

use nanomotion_core::ParamError;
use timestamp_encoder::{Fallback, Status, TimestampEncoder, TimestampEstimator};

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

/// Rms of `est − reference` over the samples with `t ≥ settle_s` and index ≥
/// `first` (units, units/s, units/s²). Samples beyond either slice are ignored.
pub fn rms_errors(
    t: &[f64],
    est: &[[f64; 3]],
    reference: &[[f64; 3]],
    settle_s: f64,
    first: usize,
) -> Errors {
    rms_errors_where(t, est, reference, settle_s, first, |_| true)
}

/// [`rms_errors`] over the samples `i` for which `keep(i)` also holds.
pub fn rms_errors_where(
    t: &[f64],
    est: &[[f64; 3]],
    reference: &[[f64; 3]],
    settle_s: f64,
    first: usize,
    keep: impl Fn(usize) -> bool,
) -> Errors {
    let mut s = [0.0; 3];
    let mut n = 0usize;
    for (i, (&ti, (e, r))) in t.iter().zip(est.iter().zip(reference)).enumerate() {
        if i < first || ti < settle_s || !keep(i) {
            continue;
        }
        for j in 0..3 {
            s[j] += (e[j] - r[j]).powi(2);
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

impl Run {
    /// Rms errors of the estimates after `settle_s`, against the truth.
    pub fn errors(&self, settle_s: f64) -> Errors {
        rms_errors(&self.t, &self.est, &self.truth, settle_s, 0)
    }

    /// Rms errors of the estimates after `settle_s` against `reference` (one
    /// [x, v, a] per read, e.g. [`reference_encoder`]).
    pub fn errors_against(&self, reference: &[[f64; 3]], settle_s: f64) -> Errors {
        rms_errors(&self.t, &self.est, reference, settle_s, 0)
    }

    /// Plain differencing of the count at the read rate: x = c·Δ + Δ/2, v by the
    /// backward difference, a by the second backward difference (causal, as a
    /// controller would compute them). The first two entries are incomplete.
    pub fn differencing(&self, resolution: f64) -> Vec<[f64; 3]> {
        let c = &self.count_pos;
        (0..c.len())
            .map(|i| {
                let x = c[i] + 0.5 * resolution;
                if i < 2 {
                    return [x, 0.0, 0.0];
                }
                let dt = self.t[i] - self.t[i - 1];
                [
                    x,
                    (c[i] - c[i - 1]) / dt,
                    (c[i] - 2.0 * c[i - 1] + c[i - 2]) / (dt * dt),
                ]
            })
            .collect()
    }

    /// Rms errors of plain differencing ([`Run::differencing`]) against the truth.
    pub fn differencing_errors(&self, settle_s: f64, resolution: f64) -> Errors {
        rms_errors(
            &self.t,
            &self.differencing(resolution),
            &self.truth,
            settle_s,
            2,
        )
    }
}

/// The thesis's reference of Sec. 8.5: a fine encoder (`lines`, 5000 in the thesis)
/// on the same motion, its count read at `read_hz`, the count position c·Δ + Δ/2
/// filtered **anti-causally** (forward-backward, zero phase) by a 5th-order
/// Butterworth low-pass at `cutoff_hz` (50 Hz) — `nanomotion_core::lti::butter_lowpass`
/// and `nanomotion_core::analysis::filtfilt_sos` (scipy `sosfiltfilt` semantics). The
/// velocity and acceleration are the **central differences of the filtered
/// position**, (x_{k+1} − x_{k−1})/(2h) and (x_{k+1} − 2x_k + x_{k−1})/h² (also
/// zero phase; one-sided at the two ends). The reference encoder is ideal (no slit
/// errors): the 5000-line disc's errors are 50× smaller in angle than a 100-line
/// disc's for the same error in counts, and the thesis treats it as exact up to its
/// filtering. Returns [x, v, a] per read, in the trajectory's units.
pub fn reference_encoder(
    lines: usize,
    cutoff_hz: f64,
    read_hz: f64,
    duration_s: f64,
    traj: impl Fn(f64) -> [f64; 3],
) -> Result<Vec<[f64; 3]>, ParamError> {
    let enc = TimestampEncoder {
        lines,
        ..Default::default()
    };
    let run = simulate(&enc, 1, &[], read_hz, duration_s, 0, false, traj)?;
    let d = enc.resolution();
    let h = 1.0 / read_hz;
    let sos = nanomotion_core::lti::butter_lowpass(5, cutoff_hz, h).map_err(|e| {
        ParamError::new(
            "cutoff_hz",
            e.to_string(),
            "give a cut-off below half the read rate",
        )
    })?;
    let raw: Vec<f64> = run.count_pos.iter().map(|c| c + 0.5 * d).collect();
    let x = nanomotion_core::analysis::filtfilt_sos(&sos, &raw);
    let n = x.len();
    if n < 3 {
        return Err(ParamError::new(
            "duration_s",
            format!("{duration_s} s gives {n} reads"),
            "give at least three reads",
        ));
    }
    Ok((0..n)
        .map(|i| {
            let k = i.clamp(1, n - 2);
            let v = (x[k + 1] - x[k - 1]) / (2.0 * h);
            let a = (x[k + 1] - 2.0 * x[k] + x[k - 1]) / (h * h);
            // One-sided at the ends: the central value of the neighbour, moved by
            // one step of the next derivative.
            let v = v + (i as f64 - k as f64) * h * a;
            [x[i], v, a]
        })
        .collect())
}

/// Run `encoder` (parameters set, not yet prepared) with an order-`order`
/// estimator (optionally with a calibration table `edge_offsets_counts`) on the
/// trajectory `traj(t) = [x, v, a]` for `duration_s`, reading at `read_hz`. The
/// encoder is fed the trajectory at each read (quintic interpolation between
/// reads, so its events are exact). `keep_events` records every event. The
/// estimator uses the thesis's fallback ([`Fallback::Thesis`]); see
/// [`simulate_with_fallback`].
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
    simulate_with_fallback(
        encoder,
        order,
        edge_offsets_counts,
        Fallback::Thesis,
        read_hz,
        duration_s,
        seed,
        keep_events,
        traj,
    )
}

/// [`simulate`] with the estimator's out-of-band rule `fallback`.
#[allow(clippy::too_many_arguments)]
pub fn simulate_with_fallback(
    encoder: &TimestampEncoder,
    order: usize,
    edge_offsets_counts: &[f64],
    fallback: Fallback,
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
    est.fallback = fallback;
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
    /// The skip σ of a time-stamping row (`None` for the other rows).
    pub skip: Option<i64>,
    /// Errors against the true trajectory.
    pub errors: Errors,
    /// Errors against the 5000-line reference encoder ([`reference_encoder`]);
    /// `None` for the reference's own row.
    pub vs_reference: Option<Errors>,
    /// Errors against the truth over the moving reads only (|ẋ| ≥
    /// [`SEC85_MOVING_SPEED`], away from the turning points).
    pub moving: Errors,
    /// Errors against the reference over the moving reads only (`None` for the
    /// reference's own row).
    pub moving_vs_reference: Option<Errors>,
}

/// Speed threshold of the "moving" error window of the Sec. 8.5 comparison
/// (rad/s, ≈ 20 % of the peak speed π² rad/s): near the turning points the edges
/// stop for tens of ms and the extrapolation leaves the ±1-count band: the
/// estimator's out-of-band rule (and under `zero_standstill` its standstill rule)
/// takes over and can dominate the rms errors; the moving window shows the fit
/// itself. Judged on the true velocity.
pub const SEC85_MOVING_SPEED: f64 = 2.0;

/// Read rate of the Sec. 8.5 runs (Hz).
pub const SEC85_READ_HZ: f64 = 1e3;
/// Length of the Sec. 8.5 runs (s); errors are taken over [`SEC85_SETTLE_S`, this].
pub const SEC85_DURATION_S: f64 = 2.1;
/// Start of the error window of the Sec. 8.5 runs (s).
pub const SEC85_SETTLE_S: f64 = 0.1;
/// Lines of the Sec. 8.5 reference encoder.
pub const SEC85_REFERENCE_LINES: usize = 5000;
/// Cut-off of the reference's 5th-order forward-backward Butterworth (Hz).
pub const SEC85_REFERENCE_CUTOFF_HZ: f64 = 50.0;

/// The Sec. 8.5 motion: x = (π/2) sin(2π t) rad, as [x, ẋ, ẍ].
pub fn sec8_5_motion(t: f64) -> [f64; 3] {
    sinusoid(SEC85_AMPLITUDE, t)
}

/// Amplitude A of the Sec. 8.5 motion shown in Figs. 8.7–8.8 (rad).
pub const SEC85_AMPLITUDE: f64 = std::f64::consts::FRAC_PI_2;

/// Amplitudes of the amplitude variation ([`sec8_5_amplitude`], rad). The thesis
/// varies A in r(t) = A sin(2π f t) ("the influence of varying amplitudes on the
/// estimations is investigated") but its values did not survive extraction; these
/// are ours: A = π/8 … π, i.e. 25 … 200 counts of amplitude on the 100-line disc.
pub const SEC85_AMPLITUDES: [f64; 4] = [
    std::f64::consts::FRAC_PI_8,
    std::f64::consts::FRAC_PI_4,
    std::f64::consts::FRAC_PI_2,
    std::f64::consts::PI,
];

/// x = A sin(2π t) rad (f = 1 Hz, as Sec. 8.5), as [x, ẋ, ẍ] at `t`.
pub fn sinusoid(amplitude: f64, t: f64) -> [f64; 3] {
    let w = std::f64::consts::TAU;
    [
        amplitude * (w * t).sin(),
        amplitude * w * (w * t).cos(),
        -amplitude * w * w * (w * t).sin(),
    ]
}

/// The Sec. 8.5 reference: [`reference_encoder`] with 5000 lines and the 50 Hz
/// filter on [`sec8_5_motion`], one [x, v, a] per 1 kHz read from t = 0. It is run
/// 0.1 s longer than the compared runs so that the end transient of the
/// forward-backward filter falls outside the error window.
pub fn sec8_5_reference() -> Result<Vec<[f64; 3]>, ParamError> {
    sec8_5_reference_at(SEC85_AMPLITUDE)
}

/// [`sec8_5_reference`] on x = A sin(2π t) with A = `amplitude` (rad).
pub fn sec8_5_reference_at(amplitude: f64) -> Result<Vec<[f64; 3]>, ParamError> {
    reference_encoder(
        SEC85_REFERENCE_LINES,
        SEC85_REFERENCE_CUTOFF_HZ,
        SEC85_READ_HZ,
        SEC85_DURATION_S + 0.1,
        move |t| sinusoid(amplitude, t),
    )
}

/// The skips of the Sec. 8.5 comparison, σ ∈ {0, 1, 2, 3, 4, 5, 10, 20}.
pub const SEC85_SKIPS: [i64; 8] = [0, 1, 2, 3, 4, 5, 10, 20];

/// Check that `reference` covers the Sec. 8.5 run (one `[x, v, a]` per 1 kHz
/// read; `made_by` names the function that makes it) and build the encoder with
/// the slit errors.
fn sec85_setup(
    slit_errors_counts: &[f64],
    reference: &[[f64; 3]],
    made_by: &str,
) -> Result<TimestampEncoder, ParamError> {
    let reads = (SEC85_DURATION_S * SEC85_READ_HZ).round() as usize + 1;
    if reference.len() < reads {
        return Err(ParamError::new(
            "reference",
            format!("has {} reads, the runs {reads}", reference.len()),
            format!("give one [x, v, a] per 1 kHz read over the run ({made_by})"),
        ));
    }
    Ok(TimestampEncoder {
        slit_errors_counts: slit_errors_counts.to_vec(),
        ..Default::default()
    })
}

/// The time-stamping rows of the Sec. 8.5 comparison (m = 2, n = 5, each skip of
/// [`SEC85_SKIPS`]) on x = A sin(2π t) with A = `amplitude`, the estimator's
/// out-of-band rule `fallback`, scored as [`sec8_5_with_reference`] against the
/// truth and against `reference` (one [x, v, a] per 1 kHz read, normally
/// [`sec8_5_reference_at`] of the same amplitude). The moving window scales with
/// the amplitude: |ẋ| ≥ [`SEC85_MOVING_SPEED`] · A/(π/2), the same 20 % of the peak
/// speed.
pub fn sec8_5_amplitude(
    slit_errors_counts: &[f64],
    amplitude: f64,
    fallback: Fallback,
    reference: &[[f64; 3]],
) -> Result<Vec<Sec85Row>, ParamError> {
    nanomotion_core::block::check::positive("amplitude", amplitude)?;
    let (hz, dur, settle) = (SEC85_READ_HZ, SEC85_DURATION_S, SEC85_SETTLE_S);
    let base = sec85_setup(slit_errors_counts, reference, "sec8_5_reference_at")?;
    let speed = SEC85_MOVING_SPEED * amplitude / SEC85_AMPLITUDE;
    let traj = move |t| sinusoid(amplitude, t);
    let mut rows = Vec::with_capacity(SEC85_SKIPS.len());
    for sigma in SEC85_SKIPS {
        let enc = TimestampEncoder {
            skip: sigma,
            ..base.clone()
        };
        let run = simulate_with_fallback(&enc, 2, &[], fallback, hz, dur, 0, false, traj)?;
        let (t, truth, est) = (&run.t, &run.truth, &run.est);
        let moving = |i: usize| truth[i][1].abs() >= speed;
        rows.push(Sec85Row {
            method: format!("time-stamping m=2 n=5 σ={sigma}"),
            skip: Some(sigma),
            errors: rms_errors(t, est, truth, settle, 0),
            vs_reference: Some(rms_errors(t, est, reference, settle, 0)),
            moving: rms_errors_where(t, est, truth, settle, 0, moving),
            moving_vs_reference: Some(rms_errors_where(t, est, reference, settle, 0, moving)),
        });
    }
    Ok(rows)
}

/// The Sec. 8.5 experiment on simulation: a 100-line encoder on a rotating mass
/// following x = (π/2) sin(2π t) rad, read at 1 kHz, 20 MHz clock, m = 2, n = 5,
/// for plain differencing, each skip σ ∈ {0, 1, 2, 3, 4, 5, 10, 20}, and HOTS
/// (optimised (m, n, σ) for velocity) with a slit calibration learned from a
/// separate constant-speed run. `slit_errors_counts` are per-slit (100) or
/// per-edge (400) errors (empty: an ideal encoder). Errors are taken over 2 s after
/// 0.1 s, against the true trajectory and against `reference` (one [x, v, a] per
/// read, normally [`sec8_5_reference`], whose own row — errors against the truth —
/// comes first), over all reads and over the moving reads ([`SEC85_MOVING_SPEED`]).
/// Plain differencing is on the count of the same 100-line encoder. The
/// estimators use the thesis's out-of-band rule ([`Fallback::Thesis`]); see
/// [`sec8_5_with_fallback`].
pub fn sec8_5_with_reference(
    slit_errors_counts: &[f64],
    reference: &[[f64; 3]],
) -> Result<Vec<Sec85Row>, ParamError> {
    sec8_5_with_fallback(slit_errors_counts, reference, Fallback::Thesis)
}

/// [`sec8_5_with_reference`] with the estimators' out-of-band rule `fallback`
/// (time-stamping rows and HOTS; the calibration run is unaffected: it never
/// leaves the band).
pub fn sec8_5_with_fallback(
    slit_errors_counts: &[f64],
    reference: &[[f64; 3]],
    fallback: Fallback,
) -> Result<Vec<Sec85Row>, ParamError> {
    use crate::model::{ErrorModel, Grid, Target, optimise, sinusoid_samples};
    let traj = sec8_5_motion;
    let (hz, dur, settle) = (SEC85_READ_HZ, SEC85_DURATION_S, SEC85_SETTLE_S);
    let base = sec85_setup(slit_errors_counts, reference, "sec8_5_reference")?;
    let r0 = simulate(&base, 2, &[], hz, dur, 0, false, traj)?;
    let t = &r0.t;
    let truth = &r0.truth;
    let moving = |i: usize| truth[i][1].abs() >= SEC85_MOVING_SPEED;
    let row_of = |method: String, est: &[[f64; 3]], first: usize| Sec85Row {
        method,
        skip: None,
        errors: rms_errors(t, est, truth, settle, first),
        vs_reference: Some(rms_errors(t, est, reference, settle, first)),
        moving: rms_errors_where(t, est, truth, settle, first, moving),
        moving_vs_reference: Some(rms_errors_where(t, est, reference, settle, first, moving)),
    };
    let row = |method: String, run: &Run| row_of(method, &run.est, 0);
    let mut rows = vec![Sec85Row {
        method: format!(
            "reference: {SEC85_REFERENCE_LINES} lines, filtfilt 5th-order {SEC85_REFERENCE_CUTOFF_HZ} Hz"
        ),
        skip: None,
        errors: rms_errors(t, reference, truth, settle, 0),
        vs_reference: None,
        moving: rms_errors_where(t, reference, truth, settle, 0, moving),
        moving_vs_reference: None,
    }];
    let diff = r0.differencing(base.resolution());
    rows.push(row_of("differencing".into(), &diff, 2));
    rows.extend(sec8_5_amplitude(
        slit_errors_counts,
        SEC85_AMPLITUDE,
        fallback,
        reference,
    )?);
    // HOTS: calibrate on a separate run (2 rev/s, 20 revolutions), then choose
    // (m, n, σ) from the calibrated error model (residual edge errors ≈ 0: the
    // clock and truncation remain) for the thesis's hardware (n = 5).
    let mut cal_enc = base.clone();
    cal_enc.register_len = 16;
    let wc = 2.0 * std::f64::consts::TAU;
    let cal_run = simulate(&cal_enc, 2, &[], hz, 10.0, 0, true, move |t| {
        [wc * t, wc, 0.0]
    })?;
    let (te, le): (Vec<f64>, Vec<f64>) = cal_run.events.iter().copied().unzip();
    let cal = crate::SlitCalibration::learn(&te, &le, 400, 2, 800).map_err(|e| {
        ParamError::new(
            "slit_errors_counts",
            e.to_string(),
            "give a calibratable encoder",
        )
    })?;
    let model = ErrorModel::white(cal.residual_rms_counts, base.clock_hz);
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
    let run = simulate_with_fallback(
        &enc,
        best.order,
        &cal.edge_offsets_counts,
        fallback,
        hz,
        dur,
        0,
        false,
        traj,
    )?;
    rows.push(row(
        format!(
            "HOTS + calibration (m={} n={} σ={})",
            best.order, best.register_len, best.skip
        ),
        &run,
    ));
    Ok(rows)
}

/// The best skip of the time-stamping rows of `rows` (those with a `skip`) by
/// `score` (smaller is better; e.g. `|r| r.errors.v`, all reads against the truth),
/// and its change against σ = 0 in percent (negative: better than no skip).
/// `None` if `rows` has no σ = 0 row.
pub fn best_skip(rows: &[Sec85Row], score: impl Fn(&Sec85Row) -> f64) -> Option<(i64, f64)> {
    let zero = score(rows.iter().find(|r| r.skip == Some(0))?);
    let (sigma, best) = rows
        .iter()
        .filter_map(|r| Some((r.skip?, score(r))))
        .min_by(|a, b| a.1.total_cmp(&b.1))?;
    Some((sigma, 100.0 * (best / zero - 1.0)))
}

/// Where the US Digital E2 slit-error profile is, relative to the workspace root
/// (the project's shared data, read in place, not copied into the repository).
pub const E2_PROFILE_FROM_WORKSPACE: &str =
    "../shared/data/usdigital_e2_slit_errors/us_digital_e2_100cpr_tick_errors.csv";

/// Per-slit errors (counts) of a slit-error profile CSV such as the US Digital E2
/// one: a header line, then one line per slit whose third column is the angle
/// error in revolutions (× 400 counts per revolution for the 100-line disc).
pub fn read_slit_profile(path: &std::path::Path) -> Result<Vec<f64>, ParamError> {
    let text = std::fs::read_to_string(path).map_err(|e| {
        ParamError::new(
            "slit_errors_counts",
            format!("cannot read `{}`: {e}", path.display()),
            "give the path of the slit-error CSV (shared data: ../shared/data/usdigital_e2_slit_errors/)",
        )
    })?;
    text.lines()
        .skip(1)
        .enumerate()
        .filter(|(_, l)| !l.trim().is_empty())
        .map(|(i, l)| {
            l.split(',')
                .nth(2)
                .and_then(|v| v.trim().parse::<f64>().ok())
                .filter(|v| v.is_finite())
                .map(|v| v * 400.0)
                .ok_or_else(|| {
                    ParamError::new(
                        "slit_errors_counts",
                        format!(
                            "`{}` line {}: no finite third column",
                            path.display(),
                            i + 2
                        ),
                        "give lines `slit,angle,error_rev` with a numeric error",
                    )
                })
        })
        .collect()
}

/// [`sec8_5_with_reference`] with the reference computed here
/// ([`sec8_5_reference`]); compute the reference once when running several
/// encoders.
pub fn sec8_5(slit_errors_counts: &[f64]) -> Result<Vec<Sec85Row>, ParamError> {
    sec8_5_with_reference(slit_errors_counts, &sec8_5_reference()?)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn reference_encoder_follows_a_ramp_to_its_quantisation() {
        // x = w t at 3 rad/s: 9549 counts/s on the 5000-line disc. The filtered
        // count stays within the quantisation cell's rms Δ/√12 of the line (the
        // filter has unit DC gain and zero phase, so a ramp passes unchanged and
        // only the quantisation noise is left, reduced by the filter); the mean
        // of the central differences telescopes to the net displacement over the
        // window, so the mean velocity is exact to ~Δ/(window).
        let w = 3.0;
        let r = reference_encoder(5000, 50.0, 1e3, 1.0, |t| [w * t, w, 0.0]).unwrap();
        let d = std::f64::consts::TAU / 20_000.0;
        let inner = &r[100..901];
        let ex = inner
            .iter()
            .enumerate()
            .map(|(i, y)| (y[0] - w * (i + 100) as f64 * 1e-3).powi(2))
            .sum::<f64>();
        let ex = (ex / inner.len() as f64).sqrt();
        assert!(
            ex < d / 12f64.sqrt(),
            "x rms {ex:e} vs Δ/√12 {:e}",
            d / 12f64.sqrt()
        );
        let mean_v = inner.iter().map(|y| y[1]).sum::<f64>() / inner.len() as f64;
        assert!((mean_v - w).abs() < 4.0 * d / 0.8, "mean v {mean_v}");
        let ev =
            (inner.iter().map(|y| (y[1] - w).powi(2)).sum::<f64>() / inner.len() as f64).sqrt();
        let ea = (inner.iter().map(|y| y[2].powi(2)).sum::<f64>() / inner.len() as f64).sqrt();
        eprintln!(
            "ramp: x rms {ex:e} rad, v rms {ev:e} rad/s, a rms {ea:e} rad/s², mean v {mean_v}"
        );
        assert!(ev < 0.01 * w, "v rms {ev}");
        // Too short a record is a typed error.
        assert!(reference_encoder(5000, 50.0, 1e3, 1e-3, |t| [t, 1.0, 0.0]).is_err());
        assert!(reference_encoder(5000, 600.0, 1e3, 1.0, |t| [t, 1.0, 0.0]).is_err());
    }
}
