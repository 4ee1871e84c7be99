//! Table 2.2 and Table 2.3 of Merry (2009) in shape, on the simulated stage, from the
//! YAML example graphs `examples/walking_piezo_jogging.yaml` and
//! `examples/walking_piezo_ff_gs.yaml`:
//!
//! - jogging at 100 nm/s … 2 mm/s with sinusoidal (non-overlapping) vs asymmetric
//!   (overlapping, q = 1/3) waveforms: max |e| over the second half of the run;
//! - point-to-point moves of 100 nm … 1 mm with and without feed-forward (2.11)–(2.12)
//!   and gain scheduling (2.13): overshoot M_p and settling time t_s (time after the
//!   end of the move until |e| stays below the 5 nm encoder resolution).
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

fn main() {
    println!("Table 2.2 style: max |e| (nm) when jogging, second half of 2 s");
    println!(
        "{:>10} {:>16} {:>14} {:>10}",
        "v (m/s)", "non-overlapping", "overlapping", "reduction"
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
            let e = col(&logs, "err.y");
            e[e.len() / 2..].iter().fold(0.0f64, |m, x| m.max(x.abs()))
        };
        let (s, a) = (e("sinusoidal"), e("asymmetric"));
        println!(
            "{v:>10.0e} {:>16.2} {:>14.2} {:>9.0}%",
            s * 1e9,
            a * 1e9,
            100.0 * (1.0 - a / s)
        );
    }
    println!();
    println!("Table 2.3 style: point-to-point moves (minimum jerk, peak velocity 1.875 D/T)");
    println!(
        "{:>9} {:>12} {:>9} {:>12} {:>9}",
        "step (m)", "Mp no FF(nm)", "ts (s)", "Mp FF+GS(nm)", "ts (s)"
    );
    for d in [1e-7f64, 1e-6, 1e-5, 1e-4, 1e-3] {
        // Move time T grows with the step: T = max(0.2 s, D / 1 mm/s · 1.875).
        let t_move: f64 = (1.875 * d / 1e-3).max(0.2);
        let vmax = 1.875 * d / t_move;
        let total = 0.3 + t_move + 1.0;
        let m = |ff: bool| {
            let logs = run("walking_piezo_ff_gs.yaml", total, |t| {
                t.replace("target_m: 1.0e-4", &format!("target_m: {d:e}"))
                    .replace("duration_s: 1.0\n", &format!("duration_s: {t_move}\n"))
                    .replace(
                        "v_max_m_s: 1.875e-4",
                        &if ff {
                            format!("v_max_m_s: {vmax:e}")
                        } else {
                            NO_FF.to_string()
                        },
                    )
            });
            let x = col(&logs, "stage.x_s");
            let begin = (0.3 * 4000.0) as usize;
            let mp = (x[begin..].iter().fold(f64::MIN, |m, &v| m.max(v)) - d).max(0.0);
            let end = ((0.3 + t_move) * 4000.0) as usize;
            let last_out = x
                .iter()
                .enumerate()
                .rposition(|(_, v)| (v - d).abs() > 5e-9)
                .unwrap_or(0);
            let ts = if last_out < end {
                0.0
            } else {
                (last_out - end) as f64 / 4000.0
            };
            (mp, ts)
        };
        let ((mp0, ts0), (mp1, ts1)) = (m(false), m(true));
        println!(
            "{d:>9.0e} {:>12.1} {ts0:>9.3} {:>12.1} {ts1:>9.3}",
            mp0 * 1e9,
            mp1 * 1e9
        );
    }
}
