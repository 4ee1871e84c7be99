//! Ch. 2 on the simulated walking piezo stage: Table 2.2 (jogging with
//! non-overlapping vs overlapping tip trajectories) and Table 2.3 (point-to-point
//! moves with and without feed-forward and gain scheduling), both with the 5 nm
//! encoder in the loop. The computation is the walking-piezo plugin's
//! [`walking_piezo::thesis::tables`] (run by its example `tables_2_2_2_3` too).
//! Quick and full mode are the same runs (they take a few seconds).

use super::{Mode, Report, ReproduceError, Row, Verdict};

use walking_piezo::thesis::tables;

const COMMAND: &str = "cargo run --release -p nanomotion-walking-piezo --example tables_2_2_2_3";

fn err(id: &str) -> impl Fn(String) -> ReproduceError + '_ {
    move |message| ReproduceError {
        id: id.to_string(),
        message,
    }
}

fn nm(x: f64) -> String {
    format!("{:.1} nm", x * 1e9)
}

/// The thesis's Table 2.2 as read (the extraction dropped zeros: "± 15 / ± 5"
/// at 10 µm/s is read 150 / 50 nm, consistent with its 67 %): (v, non-overlapping
/// text, overlapping text, overlapping max |e| (m) as read, reduction (%)).
const THESIS_2_2: [(f64, &str, &str, f64, f64); 5] = [
    (1e-6, "±6 nm", "< 5 nm", 5e-9, 92.0),
    (1e-5, "±15(0) nm", "±5(0) nm", 50e-9, 67.0),
    (1e-4, "±4(00) nm", "±2(00) nm", 200e-9, 50.0),
    (1e-3, "±85(0) nm", "±35(0) nm", 350e-9, 59.0),
    (2e-3, "±125(0) nm", "±4(00) nm", 400e-9, 68.0),
];

/// Table 2.2: max |e| when jogging, sinusoidal vs asymmetric waveforms.
pub fn table_2_2(mode: Mode) -> Result<Report, ReproduceError> {
    let id = "table_2_2";
    let rows_ours = tables::table_2_2().map_err(err(id))?;
    let mut rows = Vec::new();
    let find = |v: f64| {
        rows_ours
            .iter()
            .find(|r| (r.v / v - 1.0).abs() < 1e-9)
            .copied()
            .ok_or_else(|| err(id)(format!("no run at {v:e} m/s")))
    };
    let r7 = find(1e-7)?;
    let both_below = r7.measured_sinusoidal <= 5e-9 && r7.measured_asymmetric <= 5e-9;
    rows.push(Row {
        quantity: "100 nm/s: max |e|, non-overlapping / overlapping (measured)".into(),
        thesis: "< 5 nm / < 5 nm".into(),
        ours: format!(
            "{} / {}",
            nm(r7.measured_sinusoidal),
            nm(r7.measured_asymmetric)
        ),
        verdict: if both_below {
            Verdict::Matches
        } else {
            Verdict::Deviates
        },
        reason: format!(
            "rule: both within one 5 nm count; ours {:.2} and {:.2} nm",
            r7.measured_sinusoidal * 1e9,
            r7.measured_asymmetric * 1e9
        ),
    });
    for (v, t_non, t_ovl, t_ovl_m, t_red) in THESIS_2_2 {
        let r = find(v)?;
        let red = 100.0 * (1.0 - r.measured_asymmetric / r.measured_sinusoidal);
        let verdict = Verdict::by_ratio(t_red, red, 0.25, 3.0);
        let why = if red < 0.0 {
            format!(
                "the overlapping waveforms are worse here: {:.2} vs {:.2} nm measured ({:.2} vs {:.2} nm true); \
                 below one step per run the loaded legs track by bending and the asymmetric waveform's steeper flanks bend them faster than the 10 Hz loop follows",
                r.measured_asymmetric * 1e9,
                r.measured_sinusoidal * 1e9,
                r.true_asymmetric * 1e9,
                r.true_sinusoidal * 1e9
            )
        } else {
            format!(
                "reduction {red:.0} % vs the thesis's {t_red:.0} %; measured {:.1} → {:.1} nm",
                r.measured_sinusoidal * 1e9,
                r.measured_asymmetric * 1e9
            )
        };
        rows.push(Row {
            quantity: format!("{v:e} m/s: reduction of max |e| by the overlapping waveforms"),
            thesis: format!("{t_non} → {t_ovl}, {t_red:.0} %"),
            ours: format!(
                "{} → {}, {red:.0} %",
                nm(r.measured_sinusoidal),
                nm(r.measured_asymmetric)
            ),
            verdict,
            reason: format!(
                "rule: within 25 % of the thesis's reduction = matches, same sign within a factor 3 = shape; {why}"
            ),
        });
        if v >= 1e-5 {
            rows.push(Row {
                quantity: format!("{v:e} m/s: max |e| with the overlapping waveforms"),
                thesis: format!("{t_ovl} (read {})", nm(t_ovl_m)),
                ours: nm(r.measured_asymmetric),
                verdict: Verdict::by_ratio(t_ovl_m, r.measured_asymmetric, 0.25, 3.0),
                reason: format!(
                    "rule: within 25 % = matches, factor 3 = shape; the thesis's lost zeros read so that its reduction holds; ours {:.1} nm measured ({:.1} nm true)",
                    r.measured_asymmetric * 1e9,
                    r.true_asymmetric * 1e9
                ),
            });
        }
    }
    Ok(Report {
        id: id.into(),
        title: "Table 2.2 — jogging with non-overlapping vs overlapping tip trajectories".into(),
        section: "Sec. 2.4.1".into(),
        command: COMMAND.into(),
        mode,
        rows,
        notes: vec![
            "PI at 10 Hz (2.10), A = 46 V, φ = 0, 5 nm encoder in the loop (measured e = r − x_enc); max |e| over the second half of a 2 s run. Quick and full are the same runs.".into(),
            "The simulated stage walks 8.08 µm per cycle with the sinusoidal and 7.00 µm with the asymmetric waveforms at A = 46 V and 10 Hz; the thesis's \"maximum step size of 4 µm\" is one pair's stroke √2·c_x·A = 4.20 µm, two per cycle (docs/walking-piezo.md, \"Step per drive cycle\").".into(),
        ],
    })
}

/// Table 2.3: overshoot and settling time with and without FF + GS.
pub fn table_2_3(mode: Mode) -> Result<Report, ReproduceError> {
    let id = "table_2_3";
    let t = tables::table_2_3().map_err(err(id))?;
    let row = |d: f64, t_move: f64| {
        t.rows
            .iter()
            .find(|r| (r.d / d - 1.0).abs() < 1e-9 && (r.t_move - t_move).abs() < 1e-9)
            .copied()
            .ok_or_else(|| err(id)(format!("no move of {d:e} m in {t_move} s")))
    };
    let pct = |a: f64, b: f64| 100.0 * (b / a - 1.0);
    let mut rows = Vec::new();
    let r = row(1e-7, 0.2)?;
    let [n, f] = r.encoder;
    rows.push(Row {
        quantity: "100 nm move (below a step): M_p no FF / FF + GS".into(),
        thesis: "< 5 nm / < 5 nm (\"no effect\")".into(),
        ours: format!("{} / {}", nm(n.mp), nm(f.mp)),
        verdict: if n.mp < 5e-9 && f.mp < 5e-9 {
            Verdict::Matches
        } else {
            Verdict::Deviates
        },
        reason: format!(
            "rule: both below one 5 nm count; ours {:.1} / {:.1} nm: (2.11) takes A from 23 V at rest to 46 V and back during the move and the sticking legs drag the stage with them — in the model the amplitude change is a real disturbance below a step",
            n.mp * 1e9,
            f.mp * 1e9
        ),
    });
    for (d, t_move, label) in [
        (1e-5, 0.2, "10 µm, T = 0.2 s"),
        (1e-4, 0.2, "0.1 mm, T = 0.2 s"),
        (1e-3, 1.875, "1 mm, T = 1.875 s"),
        (1e-4, 1.0, "0.1 mm, T = 1 s (Fig. 2.17)"),
    ] {
        let r = row(d, t_move)?;
        let [n, f] = r.encoder;
        let red = pct(n.mp, f.mp);
        rows.push(Row {
            quantity: format!("{label}: change of M_p by FF + GS"),
            thesis: if t_move == 1.0 {
                "≈ −96 % (435 → 19 nm)".into()
            } else {
                "≈ −96 %".into()
            },
            ours: format!("{:+.0} % ({} → {})", red, nm(n.mp), nm(f.mp)),
            verdict: Verdict::by_ratio(-96.0, red, 0.1, 3.0),
            reason: format!(
                "rule: within 10 % of −96 % = matches, same sign within a factor 3 = shape; the simulated overshoot is mostly the type-2 loop's acceleration lag, which the step-size FF only partly removes (the thesis's came with the last 4 µm step of the real stage); ideal sensor {:+.0} %",
                pct(r.ideal[0].mp, r.ideal[1].mp)
            ),
        });
    }
    for (d, t_move, label, thesis) in [
        (1e-6, 0.2, "1 µm, T = 0.2 s", -67.0),
        (1e-4, 0.2, "0.1 mm, T = 0.2 s", -33.0),
        (1e-4, 1.0, "0.1 mm, T = 1 s (Fig. 2.17)", -33.0),
    ] {
        let r = row(d, t_move)?;
        let [n, f] = r.encoder;
        let ch = pct(n.ts, f.ts);
        rows.push(Row {
            quantity: format!("{label}: change of t_s by FF + GS"),
            thesis: format!("{thesis:.0} %"),
            ours: format!("{ch:+.0} % ({:.3} → {:.3} s)", n.ts, f.ts),
            verdict: Verdict::by_ratio(thesis, ch, 0.25, 3.0),
            reason: format!(
                "rule: within 25 % of the thesis's change = matches, same sign within a factor 3 = shape; t_s = time after the move until the encoder count stays within 5 nm of D; after the move the FF + GS loop closes the remaining error more slowly (K ≈ 3.7 at rest was identified on walking motion), so t_s follows the overshoot only where its reduction is large; ideal sensor {:+.0} % ({:.3} → {:.3} s)",
                pct(r.ideal[0].ts, r.ideal[1].ts),
                r.ideal[0].ts,
                r.ideal[1].ts
            ),
        });
    }
    Ok(Report {
        id: id.into(),
        title: "Table 2.3 — point-to-point moves with and without FF + GS".into(),
        section: "Sec. 2.4.3, 2.5".into(),
        command: COMMAND.into(),
        mode,
        rows,
        notes: vec![
            "Minimum-jerk moves of D in T = max(0.2 s, 1.875 D/(1 mm/s)) and the example graph's 0.1 mm move in T = 1 s; \"no FF\" pins A = 46 V, φ̄ = π/2 (K = 1); the 5 nm encoder is in the loop. The thesis's Table 2.3 values were lost in the extraction except the 100 nm row; its text gives ≈ −96 % overshoot and −67 % / −33 % settling time (1 µm / 0.1 mm). Quick and full are the same runs.".into(),
            format!(
                "With the scheduled gain at the PI's output instead of its input the 0.1 mm, T = 1 s overshoot is {:.1} nm (encoder): the reduction comes from the bumpless input placement.",
                t.output_placement_mp[0] * 1e9
            ),
        ],
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn check(r: &Report, min_rows: usize) {
        assert!(r.rows.len() >= min_rows, "{r:?}");
        for row in &r.rows {
            assert!(
                !row.ours.contains("NaN") && !row.ours.contains("inf"),
                "{row:?}"
            );
            assert!(
                !row.reason.is_empty() && row.reason.contains("rule"),
                "{row:?}"
            );
        }
        assert!(r.command.contains("tables_2_2_2_3"));
    }

    #[test]
    fn table_2_2_quick_rows_follow_their_rule() {
        let r = table_2_2(Mode::Quick).unwrap();
        check(&r, 10);
        // The 100 nm/s row: the verdict is the rule applied to the numbers shown.
        let ours = tables::table_2_2().unwrap();
        let r7 = ours[0];
        assert_eq!(
            r.rows[0].verdict == Verdict::Matches,
            r7.measured_sinusoidal <= 5e-9 && r7.measured_asymmetric <= 5e-9
        );
        // Every reduction row: recompute the verdict from the two runs.
        for (v, .., t_red) in THESIS_2_2 {
            let o = ours.iter().find(|o| o.v == v).unwrap();
            let red = 100.0 * (1.0 - o.measured_asymmetric / o.measured_sinusoidal);
            assert!(red.is_finite());
            let row = r
                .rows
                .iter()
                .find(|x| x.quantity.starts_with(&format!("{v:e} m/s: reduction")))
                .unwrap();
            assert_eq!(row.verdict, Verdict::by_ratio(t_red, red, 0.25, 3.0));
        }
    }

    #[test]
    fn table_2_3_quick_rows_follow_their_rule() {
        let r = table_2_3(Mode::Quick).unwrap();
        check(&r, 8);
        // Overshoot and settling rows: the verdict is the rule applied to the
        // change shown first in `ours` ("−64 % (…)").
        for row in &r.rows {
            let thesis = if row.quantity.contains("change of M_p") {
                -96.0
            } else if row.quantity.contains("1 µm, T = 0.2 s: change of t_s") {
                -67.0
            } else if row.quantity.contains("change of t_s") {
                -33.0
            } else {
                continue;
            };
            let tol = if thesis == -96.0 { 0.1 } else { 0.25 };
            let ch: f64 = row.ours.split(' ').next().unwrap().parse().unwrap();
            assert!(ch.is_finite());
            // `ours` is rounded to whole percent: accept either side of a boundary.
            let lo = Verdict::by_ratio(thesis, ch - 0.5, tol, 3.0);
            let hi = Verdict::by_ratio(thesis, ch + 0.5, tol, 3.0);
            assert!(row.verdict == lo || row.verdict == hi, "{row:?}");
        }
    }
}
