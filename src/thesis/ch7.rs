//! Sec. 7.4–7.5: directional repetitive control on the simulated AFM — the grating's
//! rotation estimated from four lines (7.18)–(7.21), then RC along the actuator axes
//! against DRC along the sample's (Table 7.3, Fig. 7.17(a)). The computation needs
//! three plugins (afm-stage, dvrc, directional-rc), so it is the facade's
//! [`crate::experiments::directional_rc`], which the example and its test run too.

use super::{Mode, Report, ReproduceError, Row, Verdict, fail, sig};

use crate::experiments::directional_rc as drc_sim;

/// Title of the experiment.
pub const TITLE: &str =
    "Sec. 7.4–7.5 — directional RC on the AFM: rotation estimate, RC vs DRC (Table 7.3)";
const ID: &str = "sec_7_5";

/// Verdict tolerances: ±10 %, shape within a factor 2 of the same sign.
const REL_TOL: f64 = 0.1;
const SHAPE: f64 = 2.0;

fn tol() -> String {
    super::tolerance_text(REL_TOL, SHAPE)
}

fn config(mode: Mode, alpha_rad: f64, drc: bool) -> drc_sim::Config {
    let (fs_hz, iterations, q_cutoff_hz, q_taps) = match mode {
        Mode::Quick => (5e3, 15, None, 21),
        Mode::Full => (20e3, 15, Some(500.0), 101),
    };
    drc_sim::Config {
        fs_hz,
        iterations,
        alpha_rad,
        drc,
        rc: true,
        seed: 7,
        q_cutoff_hz,
        q_taps,
        noiseless: false,
        unquantized: false,
        linear_z: false,
        image_every: 0,
    }
}

/// Runs the experiment for α = 0.022 and 0.015 rad, 15 iterations: Quick — 5 kHz,
/// 21-tap Q at the (7.16) design cut-off (seconds); Full — 20 kHz, 101-tap Q at
/// 500 Hz (the docs' table, minutes).
pub fn run(mode: Mode) -> Result<Report, ReproduceError> {
    // (α, thesis RC at k = 15, thesis DRC reduction %)
    let alphas = [(0.022, 10.4, -44.0), (0.015, 8.71, -33.0)];
    let mut rows = Vec::new();
    let mut per_k = Vec::new();
    for (alpha, thesis_rc, thesis_red) in alphas {
        let rc = drc_sim::run(&config(mode, alpha, false));
        let drc = drc_sim::run(&config(mode, alpha, true));
        let est = drc
            .estimate
            .as_ref()
            .ok_or_else(|| fail(ID, "the DRC run returned no rotation estimate"))?;
        let (Some(&e_rc), Some(&e_drc)) = (rc.rms_nm.last(), drc.rms_nm.last()) else {
            return Err(fail(ID, "no iteration was run"));
        };
        let k = rc.rms_nm.len();
        per_k.push(format!(
            "α = {alpha} rad, rms e_z per iteration k = 1 … {k}: RC {} nm; DRC {} nm (Q cut-off {:.0} Hz, criterion (7.16) {}).",
            rc.rms_nm.iter().map(|v| sig(*v, 3)).collect::<Vec<_>>().join(", "),
            drc.rms_nm.iter().map(|v| sig(*v, 3)).collect::<Vec<_>>().join(", "),
            rc.q_cutoff_hz,
            if rc.criterion.holds() { "holds" } else { "fails" }
        ));
        let v = Verdict::by_ratio(alpha, est.alpha_rad, REL_TOL, SHAPE);
        rows.push(Row {
            quantity: format!("estimated rotation α̂, hidden α = {alpha} rad (Sec. 7.4)"),
            thesis: format!("{alpha} rad"),
            ours: format!("{} ± {} rad", sig(est.alpha_rad, 3), sig(est.std_error_rad, 2)),
            verdict: v,
            reason: format!(
                "error {:.2e} rad = {:.1} reported σ ({}, i.e. ±{:.1e} rad; the estimator's own stated tolerance is 2e-3 rad and 4σ). The thesis's α is itself an estimate on its sample; ours is scored against the rotation the simulation hides.",
                est.alpha_rad - alpha,
                (est.alpha_rad - alpha).abs() / est.std_error_rad,
                tol(),
                REL_TOL * alpha
            ),
        });
        let ratio = |o: f64, t: f64| format!("ours/thesis = {:.2} ({})", o / t, tol());
        rows.push(Row {
            quantity: format!("RC, rms e_z at the last iteration (k = {k}), α = {alpha} rad"),
            thesis: format!("{thesis_rc} nm (k = 15)"),
            ours: format!("{} nm", sig(e_rc, 3)),
            verdict: Verdict::by_ratio(thesis_rc, e_rc, REL_TOL, SHAPE),
            reason: format!(
                "{}. Our errors are about ten times smaller: the simulated AFM has only the interferometer/deflection noise and the modelled dynamics, not the real AFM's non-repetitive disturbances (vibration, drift, tip–sample interaction) the thesis names; nothing is added to approach its nanometres.",
                ratio(e_rc, thesis_rc)
            ),
        });
        if alpha == 0.022 {
            rows.push(Row {
                quantity: format!("DRC, rms e_z at the last iteration (k = {k}), α = {alpha} rad"),
                thesis: "5.86 nm (k = 15)".into(),
                ours: format!("{} nm", sig(e_drc, 3)),
                verdict: Verdict::by_ratio(5.86, e_drc, REL_TOL, SHAPE),
                reason: format!("{}. As the RC row: no non-repetitive disturbances beyond the sensor noise are simulated.", ratio(e_drc, 5.86)),
            });
        }
        let red = 100.0 * (e_drc / e_rc - 1.0);
        rows.push(Row {
            quantity: format!("DRC vs RC at the last iteration, α = {alpha} rad"),
            thesis: format!("{thesis_red:+.0} %").replace('-', "−"),
            ours: format!("{red:+.0} %").replace('-', "−"),
            verdict: Verdict::by_ratio(thesis_red, red, REL_TOL, SHAPE),
            reason: format!(
                "{}. DRC lets RC learn the grating, whose edges move by 500 nm·tan α per scan period along the actuator axes (plain RC cannot).",
                ratio(red, thesis_red),
            ),
        });
    }
    let mut notes = vec![
        "Simulated AFM (afm-stage) with a 10 µm-pitch, 20 nm grating rotated by α; fast axis y ±25 µm at 25 µm/s (period 4 s), slow axis 125 nm/s, z at constant deflection; RC on z with L = ZPETC of the model T_z and a linear-phase FIR Q; one lead-in period without RC, then iterations k = 1 … (k = 1: memory still empty). DRC estimates α from four lines 1 µm apart, then maps the scan by R(α̂). Seed 7.".into(),
        match mode {
            Mode::Quick => "Quick mode: f_s = 5 kHz (the thesis: 20 kHz), a 21-tap Q at the cut-off (7.16) admits with a 5 % margin on the model (the 101-tap Q of the 5 kHz line of docs/directional-rc.md, `cargo run --release --example directional_rc 15 5000`, gives RC 1.034 / 0.784 nm and DRC 0.226 / 0.282 nm at k = 15; its cut-off search costs ~30 s). The full run (`nanomotion reproduce sec_7_5`, minutes): 20 kHz, Q at 500 Hz (our reading of the thesis's \"5 Hz\") — the docs' table.".into(),
            Mode::Full => "Full mode: f_s = 20 kHz, 101-tap Q at 500 Hz (our reading of the thesis's \"5 Hz\") — the docs/directional-rc.md table.".into(),
        },
    ];
    notes.extend(per_k);
    Ok(Report {
        id: ID.into(),
        title: TITLE.into(),
        section: "Sec. 7.4–7.5".into(),
        command: match mode {
            Mode::Quick => {
                "nanomotion reproduce sec_7_5 --quick (per-iteration figures in the notes)"
            }
            Mode::Full => "cargo run --release --example directional_rc 15 20000 500",
        }
        .into(),
        mode,
        rows,
        notes,
    })
}
