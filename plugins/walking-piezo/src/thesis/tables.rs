//! Table 2.2 and Table 2.3 of Merry (2009) on the simulated stage, from the YAML
//! example graphs `examples/walking_piezo_jogging.yaml` and
//! `examples/walking_piezo_ff_gs.yaml` (repository root, compiled in). Called by
//! the example `tables_2_2_2_3` and by `nanomotion reproduce table_2_2 table_2_3`;
//! the caller must link the `gain-scheduling` plugin (the FF + GS graph uses its
//! `gain_scheduled` block; without it [`table_2_3`] is an error saying so).
//!
//! Both graphs measure the stage through a 5 nm encoder (core `quantizer`,
//! floor): the thesis's errors include its resolution.

use nanomotion_core::graph::GraphSpec;

const JOGGING_YAML: &str = include_str!("../../../../examples/walking_piezo_jogging.yaml");
const FF_GS_YAML: &str = include_str!("../../../../examples/walking_piezo_ff_gs.yaml");

/// The loop's sample rate (Hz) in both graphs.
pub const RATE_HZ: f64 = 4000.0;

/// "No FF": the feed-forward pinned at A_min = A_max = 46 V and φ̄_min = φ̄_max = π/2,
/// so A, φ and K(A, φ̄) = 1 stay constant before, during and after the move.
const NO_FF: &str =
    "v_max_m_s: 1.0\n    amplitude_min_v: 46.0\n    phase_diff_min_rad: 1.5707963267948966";

type Logs = Vec<(String, Vec<f64>)>;

/// Run a graph text (after `edit`) for `duration_s`; the logs by name.
fn run(
    name: &str,
    yaml: &str,
    duration_s: f64,
    edit: impl Fn(String) -> String,
) -> Result<Logs, String> {
    let text = edit(yaml.to_string());
    let mut spec: GraphSpec =
        nanomotion_core::yaml::from_str(&text, name).map_err(|e| format!("{name}: {e}"))?;
    spec.duration_s = duration_s;
    let (mut sched, _report) = spec.build().map_err(|e| {
        format!("{name}: {e} (the FF + GS graph needs the gain-scheduling plugin linked)")
    })?;
    let res = sched.run(|_| {});
    Ok(res
        .logs
        .iter()
        .map(|l| (l.name.clone(), l.column(0)))
        .collect())
}

fn col<'a>(logs: &'a Logs, name: &str) -> Result<&'a [f64], String> {
    logs.iter()
        .find(|l| l.0 == name)
        .map(|l| l.1.as_slice())
        .ok_or_else(|| format!("log `{name}` missing from the example graph"))
}

/// Max |.| over the second half of a log.
fn max_abs_second_half(x: &[f64]) -> f64 {
    x[x.len() / 2..].iter().fold(0.0f64, |m, v| m.max(v.abs()))
}

/// Settling time t_s (s): time after the end of the move (sample `end`) until
/// |x − d| stays at or below `band`; 0 if it never leaves the band after `end`.
pub fn settling(x: &[f64], d: f64, end: usize, band: f64) -> f64 {
    let last_out = x.iter().rposition(|v| (v - d).abs() > band).unwrap_or(0);
    if last_out < end {
        0.0
    } else {
        (last_out + 1 - end) as f64 / RATE_HZ
    }
}

/// One velocity of Table 2.2: max |e| over the second half of a 2 s run (m).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Table22Row {
    /// Reference velocity (m/s).
    pub v: f64,
    /// Measured e = r − x_enc, sinusoidal (non-overlapping) waveforms.
    pub measured_sinusoidal: f64,
    /// Measured, asymmetric (overlapping, q = 1/3) waveforms.
    pub measured_asymmetric: f64,
    /// True e = r − x_s, sinusoidal.
    pub true_sinusoidal: f64,
    /// True, asymmetric.
    pub true_asymmetric: f64,
}

/// The velocities of Table 2.2 (m/s).
pub const TABLE_2_2_VELOCITIES: [f64; 6] = [1e-7, 1e-6, 1e-5, 1e-4, 1e-3, 2e-3];

/// Table 2.2: jogging at each velocity with both waveforms, PI at 10 Hz, 2 s.
pub fn table_2_2() -> Result<Vec<Table22Row>, String> {
    TABLE_2_2_VELOCITIES
        .iter()
        .map(|&v| {
            let e = |shape: &str| -> Result<(f64, f64), String> {
                let logs = run("walking_piezo_jogging.yaml", JOGGING_YAML, 2.0, |t| {
                    t.replace(
                        "{kind: asymmetric, overlap_q: 0.3333333333}",
                        &format!("{{kind: {shape}}}"),
                    )
                    .replace("velocity_m_s: 1.0e-4", &format!("velocity_m_s: {v:e}"))
                })?;
                let r = col(&logs, "ref.y")?;
                let e_true: Vec<f64> = r
                    .iter()
                    .zip(col(&logs, "stage.x_s")?)
                    .map(|(r, x)| r - x)
                    .collect();
                Ok((
                    max_abs_second_half(col(&logs, "err.y")?),
                    max_abs_second_half(&e_true),
                ))
            };
            let ((s, s_true), (a, a_true)) = (e("sinusoidal")?, e("asymmetric")?);
            Ok(Table22Row {
                v,
                measured_sinusoidal: s,
                measured_asymmetric: a,
                true_sinusoidal: s_true,
                true_asymmetric: a_true,
            })
        })
        .collect()
}

/// Overshoot M_p (m), settling time t_s (s) and the error d − x at 0 / 50 / 100 /
/// 150 ms after the end of the move (m), of one variant of one move.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MoveResult {
    pub mp: f64,
    pub ts: f64,
    pub tail: [f64; 4],
}

/// One move of Table 2.3: no FF vs FF + GS, with the encoder and with an ideal sensor.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Table23Row {
    /// Move size D (m).
    pub d: f64,
    /// Move time T (s).
    pub t_move: f64,
    /// Encoder in the loop: no FF, FF + GS.
    pub encoder: [MoveResult; 2],
    /// Ideal sensor (x_s fed back): no FF, FF + GS.
    pub ideal: [MoveResult; 2],
}

/// Table 2.3 and the gain-placement check.
#[derive(Debug, Clone, PartialEq)]
pub struct Table23 {
    /// Minimum-jerk moves: 100 nm … 1 mm in T = max(0.2 s, 1.875 D/(1 mm/s)),
    /// and the example graph's own 0.1 mm move in T = 1 s (last row).
    pub rows: Vec<Table23Row>,
    /// M_p (m) of the 0.1 mm, T = 1 s move with the scheduled gain at the PI's
    /// output: [encoder, ideal sensor].
    pub output_placement_mp: [f64; 2],
}

/// Table 2.3: point-to-point moves with and without FF (2.11)–(2.12) + GS (2.13).
pub fn table_2_3() -> Result<Table23, String> {
    let moves = [1e-7f64, 1e-6, 1e-5, 1e-4, 1e-3]
        .map(|d| (d, (1.875 * d / 1e-3).max(0.2)))
        .into_iter()
        .chain([(1e-4, 1.0)]);
    let mut rows = Vec::new();
    for (d, t_move) in moves {
        let vmax = 1.875 * d / t_move;
        let total = 0.3 + t_move + 1.0;
        let m = |ff: bool, encoder: bool| -> Result<MoveResult, String> {
            let logs = run("walking_piezo_ff_gs.yaml", FF_GS_YAML, total, |t| {
                let t = t
                    .replace("target_m: 1.0e-4", &format!("target_m: {d:e}"))
                    .replace("duration_s: 1.0\n", &format!("duration_s: {t_move}\n"))
                    .replace(
                        "v_max_m_s: 1.875e-4",
                        &if ff {
                            format!("v_max_m_s: {vmax:e}")
                        } else {
                            NO_FF.to_string()
                        },
                    );
                if encoder {
                    t
                } else {
                    t.replace("from: enc.y, to: err.in1", "from: stage.x_s, to: err.in1")
                }
            })?;
            // What the loop sees: the count, or the true position.
            let x = col(&logs, if encoder { "enc.y" } else { "stage.x_s" })?;
            let begin = (0.3 * RATE_HZ) as usize;
            let mp = (x[begin..].iter().fold(f64::MIN, |m, &v| m.max(v)) - d).max(0.0);
            let end = ((0.3 + t_move) * RATE_HZ) as usize;
            // One count; the margin keeps exact multiples of 5 nm inside the band.
            let ts = settling(x, d, end, 5e-9 * (1.0 + 1e-9));
            let tail = [0usize, 200, 400, 600].map(|k| d - x[(end + k).min(x.len() - 1)]);
            Ok(MoveResult { mp, ts, tail })
        };
        rows.push(Table23Row {
            d,
            t_move,
            encoder: [m(false, true)?, m(true, true)?],
            ideal: [m(false, false)?, m(true, false)?],
        });
    }
    // The gain at the PI's output (u = K·C(e)) instead of its input: not bumpless,
    // the stored integral action is rescaled with K.
    let mut output_placement_mp = [0.0; 2];
    for (i, encoder) in [true, false].into_iter().enumerate() {
        let logs = run("walking_piezo_ff_gs.yaml", FF_GS_YAML, 2.3, |t| {
            let t = t.replace(
                "controller: {type: pi, kp: 7.6704e6, zero_hz: 2.679}",
                "controller: {type: pi, kp: 7.6704e6, zero_hz: 2.679}\n    placement: output",
            );
            if encoder {
                t
            } else {
                t.replace("from: enc.y, to: err.in1", "from: stage.x_s, to: err.in1")
            }
        })?;
        let x = col(&logs, if encoder { "enc.y" } else { "stage.x_s" })?;
        output_placement_mp[i] = x[1200..].iter().fold(f64::MIN, |m, &v| m.max(v)) - 1e-4;
    }
    Ok(Table23 {
        rows,
        output_placement_mp,
    })
}
