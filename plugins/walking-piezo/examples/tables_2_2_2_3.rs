//! Table 2.2 and Table 2.3 of Merry (2009) in shape, on the simulated stage, from the
//! YAML example graphs `examples/walking_piezo_jogging.yaml` and
//! `examples/walking_piezo_ff_gs.yaml`:
//!
//! - jogging at 100 nm/s … 2 mm/s with sinusoidal (non-overlapping) vs asymmetric
//!   (overlapping, q = 1/3) waveforms: max |e| over the second half of the run;
//! - point-to-point moves of 100 nm … 1 mm with and without feed-forward (2.11)–(2.12)
//!   and gain scheduling (2.13): overshoot M_p and settling time t_s (time after the
//!   end of the move until the encoder reading stays within one 5 nm count).
//!
//! Both graphs measure the stage through a 5 nm encoder (core `quantizer`, floor):
//! the thesis's errors include its resolution, so the measured columns are the
//! comparable ones; the true-position columns show what the quantisation hides.
//!
//! `cargo run --release -p nanomotion-walking-piezo --example tables_2_2_2_3`
use gain_scheduling as _;
use nanomotion_core::graph::GraphSpec;
use walking_piezo as _;

type Logs = Vec<(String, Vec<f64>)>;

/// "No FF": the feed-forward pinned at A_min = A_max = 46 V and φ̄_min = φ̄_max = π/2,
/// so A, φ and K(A, φ̄) = 1 stay constant before, during and after the move.
const NO_FF: &str =
    "v_max_m_s: 1.0\n    amplitude_min_v: 46.0\n    phase_diff_min_rad: 1.5707963267948966";

fn run(file: &str, duration_s: f64, edit: impl Fn(String) -> String) -> Logs {
    let path = format!("{}/../../examples/{file}", env!("CARGO_MANIFEST_DIR"));
    let text = edit(std::fs::read_to_string(path).expect("example file"));
    let mut spec: GraphSpec = nanomotion_core::yaml::from_str(&text, file).expect("graph");
    spec.duration_s = duration_s;
    let (mut sched, _report) = spec.build().expect("build");
    let res = sched.run(|_| {});
    res.logs
        .iter()
        .map(|l| (l.name.clone(), l.column(0)))
        .collect()
}

fn col<'a>(logs: &'a Logs, name: &str) -> &'a [f64] {
    &logs.iter().find(|l| l.0 == name).expect("log").1
}

/// Max |.| over the second half of a log.
fn max_abs_second_half(x: &[f64]) -> f64 {
    x[x.len() / 2..].iter().fold(0.0f64, |m, v| m.max(v.abs()))
}

/// Settling time t_s (s): time after the end of the move (sample `end`) until
/// |x − d| stays at or below `band`; 0 if it never leaves the band after `end`.
fn settling(x: &[f64], d: f64, end: usize, band: f64) -> f64 {
    let last_out = x.iter().rposition(|v| (v - d).abs() > band).unwrap_or(0);
    if last_out < end {
        0.0
    } else {
        (last_out + 1 - end) as f64 / 4000.0
    }
}

fn main() {
    println!("Table 2.2 style: max |e| (nm) when jogging, second half of 2 s");
    println!("  measured e = r - x_enc (5 nm encoder count, as in the thesis); true e = r - x_s");
    println!(
        "{:>10} {:>14} {:>14} {:>10} {:>14} {:>14}",
        "v (m/s)", "non-ovl meas", "overl meas", "reduction", "non-ovl true", "overl true"
    );
    for v in [1e-7, 1e-6, 1e-5, 1e-4, 1e-3, 2e-3] {
        let e = |shape: &str| {
            let logs = run("walking_piezo_jogging.yaml", 2.0, |t| {
                t.replace(
                    "{kind: asymmetric, overlap_q: 0.3333333333}",
                    &format!("{{kind: {shape}}}"),
                )
                .replace("velocity_m_s: 1.0e-4", &format!("velocity_m_s: {v:e}"))
            });
            let r = col(&logs, "ref.y");
            let e_true: Vec<f64> = r
                .iter()
                .zip(col(&logs, "stage.x_s"))
                .map(|(r, x)| r - x)
                .collect();
            (
                max_abs_second_half(col(&logs, "err.y")),
                max_abs_second_half(&e_true),
            )
        };
        let ((s, s_true), (a, a_true)) = (e("sinusoidal"), e("asymmetric"));
        println!(
            "{v:>10.0e} {:>14.2} {:>14.2} {:>9.0}% {:>14.2} {:>14.2}",
            s * 1e9,
            a * 1e9,
            100.0 * (1.0 - a / s),
            s_true * 1e9,
            a_true * 1e9
        );
    }
    println!();
    println!("Table 2.3 style: point-to-point moves (minimum jerk, peak velocity 1.875 D/T)");
    println!(
        "  with the 5 nm encoder in the loop (as in the thesis): Mp and ts from the count x_enc,"
    );
    println!("  ts = time after the move until |d - x_enc| stays <= 5 nm (one count);");
    println!("  ideal sensor (encoder bypassed, x_s fed back): ts until |d - x_s| stays <= 5 nm");
    println!(
        "{:>9} {:>6} | {:>8} {:>7} {:>8} {:>7} {:>6} {:>5} | {:>8} {:>7} {:>8} {:>7} {:>6} {:>5}",
        "step (m)",
        "T (s)",
        "Mp noFF",
        "ts",
        "Mp FFGS",
        "ts",
        "dMp",
        "dts",
        "Mp noFF",
        "ts",
        "Mp FFGS",
        "ts",
        "dMp",
        "dts"
    );
    // Move time T grows with the step: T = max(0.2 s, D / 1 mm/s · 1.875); the last
    // row is the example graph's own 0.1 mm move in T = 1 s (Fig. 2.17).
    let moves = [1e-7f64, 1e-6, 1e-5, 1e-4, 1e-3]
        .map(|d| (d, (1.875 * d / 1e-3).max(0.2)))
        .into_iter()
        .chain([(1e-4, 1.0)]);
    let pct = |a: f64, b: f64| {
        if a > 0.0 {
            format!("{:+.0}%", 100.0 * (b / a - 1.0))
        } else {
            "-".to_string()
        }
    };
    let mut tails = Vec::new();
    for (d, t_move) in moves {
        let vmax = 1.875 * d / t_move;
        let total = 0.3 + t_move + 1.0;
        let m = |ff: bool, encoder: bool| {
            let logs = run("walking_piezo_ff_gs.yaml", total, |t| {
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
            });
            // What the loop sees: the count, or the true position.
            let x = col(&logs, if encoder { "enc.y" } else { "stage.x_s" });
            let begin = (0.3 * 4000.0) as usize;
            let mp = (x[begin..].iter().fold(f64::MIN, |m, &v| m.max(v)) - d).max(0.0);
            let end = ((0.3 + t_move) * 4000.0) as usize;
            // One count; the margin keeps exact multiples of 5 nm inside the band.
            let ts = settling(x, d, end, 5e-9 * (1.0 + 1e-9));
            // The error d − x at the end of the move and 50/100/150 ms later.
            let tail = [0usize, 200, 400, 600].map(|k| d - x[(end + k).min(x.len() - 1)]);
            (mp, ts, tail)
        };
        let ((mp0, ts0, _), (mp1, ts1, _)) = (m(false, true), m(true, true));
        let ((mi0, ti0, tail0), (mi1, ti1, tail1)) = (m(false, false), m(true, false));
        tails.push((d, t_move, tail0, tail1));
        println!(
            "{d:>9.0e} {t_move:>6.3} | {:>8.1} {ts0:>7.3} {:>8.1} {ts1:>7.3} {:>6} {:>5} | {:>8.1} {ti0:>7.3} {:>8.1} {ti1:>7.3} {:>6} {:>5}",
            mp0 * 1e9,
            mp1 * 1e9,
            pct(mp0, mp1),
            pct(ts0, ts1),
            mi0 * 1e9,
            mi1 * 1e9,
            pct(mi0, mi1),
            pct(ti0, ti1),
        );
    }
    println!();
    println!(
        "Recovery after the move, ideal sensor: e = d - x_s (nm) at 0 / 50 / 100 / 150 ms after its end"
    );
    for (d, t_move, a, b) in tails {
        let f = |e: [f64; 4]| e.map(|v| format!("{:7.1}", v * 1e9)).join(" ");
        println!(
            "{d:>9.0e} T {t_move:.3} s   no FF: {}   FF+GS: {}",
            f(a),
            f(b)
        );
    }
    // The gain at the PI's output (u = K·C(e)) instead of its input: not bumpless,
    // the stored integral action is rescaled with K.
    for encoder in [true, false] {
        let logs = run("walking_piezo_ff_gs.yaml", 2.3, |t| {
            let t = t.replace(
                "controller: {type: pi, kp: 7.6704e6, zero_hz: 2.679}",
                "controller: {type: pi, kp: 7.6704e6, zero_hz: 2.679}\n    placement: output",
            );
            if encoder {
                t
            } else {
                t.replace("from: enc.y, to: err.in1", "from: stage.x_s, to: err.in1")
            }
        });
        let x = col(&logs, if encoder { "enc.y" } else { "stage.x_s" });
        let mp = x[1200..].iter().fold(f64::MIN, |m, &v| m.max(v)) - 1e-4;
        println!(
            "0.1 mm, T = 1 s, FF + GS with the gain at the PI's output ({}): Mp {:.1} nm",
            if encoder { "encoder" } else { "ideal sensor" },
            mp * 1e9
        );
    }
}
