//! Table 5.1-style comparison (issue 7 item 5) on the *nonlinear* walking piezo
//! stage with a rough drive strip: `WaveformDriver` with the asymmetric waveforms
//! (q = 1/3) driving `WalkingPiezoStage` (10 sub-steps of 25 µs per 4 kHz sample,
//! seeded μ variation, unequal pairs, seeded strip height profile). The design
//! follows the thesis (Sec. 5.5): closed-loop FRF of the stage (Fig. 2.8) →
//! fitted model → PI (50 Hz), L = ZPETC of T and one 101-tap Q for all RC
//! variants such that (5.9) holds for the delay ranges N(α) measured in runs
//! without RC (Fig. 5.7). DVRC takes α from the driver. No ripple is added: the
//! error is the model's stepping. Also: the high-order RC divergence of the
//! nominal design, isolated on the linear model, and the sensitivity to the
//! strip roughness. See docs/repetitive-control.md.
//!
//! Run: `cargo run --release -p nanomotion-dvrc --example table_5_1_nonlinear`

use dvrc::stability::rc_criterion;
use nanomotion::experiments::{table51, table51_nonlinear};
use nanomotion_core::LearningFilter;
use nanomotion_core::analysis::{WelchOptions, psd_welch};
use std::f64::consts::TAU;
use table51::{Rc, Setup, Velocity, setup};
use table51_nonlinear::*;

fn main() {
    let quick = std::env::args().any(|a| a == "--quick");
    let nominal = setup();
    let t = nonlinear_table(quick);
    let p = stage_params_with(STRIP_RMS_M);
    println!(
        "Stage: defaults with c_x × {:.4} = {:.2} nm/V (the thesis's Ch. 5 step {:.3} µm per cycle: 10 µm/s at 1.98 Hz), \
         strip profile σ_h = {:.0} nm, correlation {:.1} µm, leg pitch {:.1} mm, seed {SEED}",
        t.c_x_scale,
        p.c_x_m_v[0] * 1e9,
        CH5_STEP_M * 1e6,
        p.strip_height_rms_m * 1e9,
        p.strip_height_corr_m * 1e6,
        p.strip_leg_pitch_m * 1e3
    );
    // 1. Irregular stepping, open loop, at the 10 µm/s drive frequency.
    for (name, (m, sd, mn, mx)) in [("flat strip", t.steps_flat), ("rough strip", t.steps_rough)] {
        println!(
            "{name}: open-loop step per cycle at 1.98 Hz {:.4} µm, sd {:.4} µm ({:.2} %), range [{:.3}, {:.3}] µm",
            m * 1e6,
            sd * 1e6,
            100.0 * sd / m,
            mn * 1e6,
            mx * 1e6
        );
    }
    // 2. Identification (Fig. 2.8) with the nominal PI, 10 µm/s, 30 Hz rms noise.
    let (fit, frf, s, q, fc, spread) = (t.fit, &t.frf, &t.design, &t.q, t.q_cutoff_hz, t.spread);
    println!(
        "identified (5.31) structure, 5–300 Hz: c = {:.3} µm/cycle, delay {} samples (nominal model: c = {:.3}, 3 samples), rel. fit error {:.1} %",
        fit.c * 1e6,
        fit.delay,
        nominal.c_m_per_cycle * 1e6,
        100.0 * fit.rel_err
    );
    let mg = margins(s);
    println!(
        "PI on the identified model: k_p = {:.4e} Hz/m, crossover {:.1} Hz, PM {:.1}°, GM {:.1} dB, modulus margin {:.2}",
        s.kp,
        mg.gain_crossover_rad_s / TAU,
        mg.phase_margin_deg,
        20.0 * mg.gain_margin.log10(),
        mg.modulus_margin
    );
    // 3. The table.
    println!(
        "Q: 101 taps, cut-off {fc:.1} Hz, designed on the identified model for M − m = {spread}"
    );
    println!(
        "| reference | N(α) without RC (samples) | N (RC) | [m, M] | (5.9) margin (dB) | none (nm) | RC (nm) | high-order RC (nm) | DVRC (nm) | N_k seen by DVRC |"
    );
    println!("|---|---|---|---|---|---|---|---|---|---|");
    for r in &t.rows {
        let nc: u64 = r.out.iter().map(|o| o.nonconverged).sum();
        println!(
            "| {} | {:.0} … {:.0} | {} | [{}, {}] | {:+.2} | {:.3} | {:.3} | {:.3} | {:.3} | {} … {} |{}",
            r.name,
            r.periods.1,
            r.periods.2,
            r.plan.n_fixed,
            r.plan.m,
            r.plan.mm,
            r.margin_db,
            r.out[0].rms * 1e9,
            r.out[1].rms * 1e9,
            r.out[2].rms * 1e9,
            r.out[3].rms * 1e9,
            r.out[3].seen.0,
            r.out[3].seen.1,
            if nc > 0 {
                format!(" ({nc} non-converged sub-steps)")
            } else {
                String::new()
            }
        );
    }
    // What part of each error is periodic in α (removable by RC in α in
    // principle) and what is not, over the last quarter.
    println!(
        "\n| reference | controller | rms (nm) | α-periodic part (nm) | rest (nm) |\n|---|---|---|---|---|"
    );
    for r in &t.rows {
        let Some(split) = r.split else { continue };
        for (wname, (tot, per, rest)) in ["none", "RC", "high-order RC", "DVRC"].iter().zip(split) {
            println!(
                "| {} | {wname} | {:.3} | {:.3} | {:.3} |",
                r.name,
                tot * 1e9,
                per * 1e9,
                rest * 1e9
            );
        }
    }
    if quick {
        return;
    }
    let plans: Vec<Plan> = t.rows.iter().map(|r| r.plan).collect();
    let comp = s.l.preview_samples() + 50 + 1;
    let (s, q, frf) = (s.clone(), q.clone(), frf.clone());
    let worst = plans.iter().max_by_key(|pl| pl.mm - pl.m).unwrap();
    println!(
        "criterion on the identified model: {}",
        rc_criterion(&s.t, &s.l, &q, worst.m, worst.mm).unwrap()
    );
    let (hm, fm) = criterion_on_measured(&s, &q, &frf, 1000.0);
    println!(
        "on the measured FRF (bins ≤ 1 kHz, coherence ≥ 0.8): max |Q(1 − T̂ L z^l)| = {hm:.4} at {fm:.0} Hz \
         (bound for M − m = {spread}: {:.4}; standard RC needs < 1, W = 2 − z^-N needs < 1/3)",
        1.0 / ((spread + 1) as f64).sqrt()
    );

    // 4. High-order RC with the nominal design (L from (5.31) with c = 7.91 µm and
    //    3 samples delay, Q for M − m = 14040 as before): the criterion on the
    //    measured FRF, and growth with the run length.
    let (q_old, fc_old) = q_for(&nominal, 14040);
    let (ho, fo) = criterion_on_measured(&nominal, &q_old, &frf, 1000.0);
    println!(
        "\nnominal design (Q {fc_old:.1} Hz): max |Q(1 − T̂ L z^l)| on the measured FRF = {ho:.4} at {fo:.0} Hz → 3·{ho:.3} = {:.2} (W = 2 − z^-N: small gain needs < 1); identified design: 3·{hm:.3} = {:.2}",
        3.0 * ho,
        3.0 * hm
    );
    let v10 = Velocity::Constant(1e-5);
    let pl_old = plan_from_step(t.steps_flat.0, v10, 56, 0.25);
    println!(
        "flat strip, 10 µm/s:\n| run length (s) | high-order RC, nominal design (nm) | high-order RC, identified design (nm) | RC, nominal design (nm) |"
    );
    println!("|---|---|---|---|");
    // Same flat-strip stage for both designs (the original finding).
    let pl_flat = plan_from_periods(period_range(&stage_params(), &s, v10, 30.0), comp, PAD);
    for dur in [20.0, 40.0, 80.0] {
        let a = run_plan(
            &stage_params(),
            &nominal,
            &q_old,
            pl_old,
            v10,
            Rc::HighOrder,
            dur,
        );
        let b = run_plan(&stage_params(), &s, &q, pl_flat, v10, Rc::HighOrder, dur);
        let c = run_plan(
            &stage_params(),
            &nominal,
            &q_old,
            pl_old,
            v10,
            Rc::Standard,
            dur,
        );
        println!(
            "| {dur} | {:.3} | {:.3} | {:.3} |",
            a.rms * 1e9,
            b.rms * 1e9,
            c.rms * 1e9
        );
    }
    // Where the growing error of the nominal high-order RC sits in frequency.
    {
        let dur = 80.0;
        let steps = (dur / DT) as usize;
        let mut es = Vec::new();
        run_plan_traced(
            &stage_params(),
            &nominal,
            &q_old,
            pl_old,
            v10,
            Rc::HighOrder,
            dur,
            |k, e, _| {
                if k >= steps * 3 / 4 {
                    es.push(e);
                }
            },
        );
        let psd = psd_welch(&es, 1.0 / DT, &WelchOptions::new(4000)).unwrap();
        let (mut fpk, mut spk) = (0.0, 0.0);
        for (f, d) in psd.freq_hz.iter().zip(&psd.density) {
            if *f > 2.0 && *d > spk {
                (fpk, spk) = (*f, *d);
            }
        }
        println!(
            "nominal high-order RC, 80 s: error PSD peak at {fpk:.0} Hz; {:.1} % of the mean square in 100–200 Hz",
            100.0 * psd.band_mean_square(100.0, 200.0) / psd.mean_square()
        );
    }
    // Isolation on the *linear* model: plant = (5.31) with the identified c and
    // delay, ripple d(α) of the linear table; L and Q of the nominal design.
    let plant = Setup {
        g: fit.model(),
        c_m_per_cycle: fit.c,
        ..setup()
    };
    println!(
        "linear plant = identified model, nominal L and Q (0.1 mm/s, ripple of the linear table):"
    );
    for dur in [5.0, 10.0, 20.0] {
        let (ho, _) = table51::run_mixed(
            &plant,
            &nominal,
            &q_old,
            Velocity::Constant(1e-4),
            Rc::HighOrder,
            dur,
        );
        let (rc, _) = table51::run_mixed(
            &plant,
            &nominal,
            &q_old,
            Velocity::Constant(1e-4),
            Rc::Standard,
            dur,
        );
        println!(
            "  {dur} s: high-order RC {:.3} nm, RC {:.3} nm",
            ho * 1e9,
            rc * 1e9
        );
    }

    // 5. Sensitivity to the strip roughness (10 µm/s, 60 s, same L and Q; each
    //    strip gets its own [m, M] from its own run without RC).
    println!(
        "\n| σ_h (10 µm/s) | N(α) without RC | none (nm) | RC (nm) | high-order RC (nm) | DVRC (nm) | N_k seen by DVRC | (5.9) margin (dB) |"
    );
    println!("|---|---|---|---|---|---|---|---|");
    for rms in [0.0, 50e-9, STRIP_RMS_M, 200e-9, 300e-9] {
        let pp = stage_params_with(rms);
        let r = period_range(&pp, &s, v10, 60.0);
        let pl = plan_from_periods(r, comp, PAD);
        let c = rc_criterion(&s.t, &s.l, &q, pl.m, pl.mm).unwrap();
        let out: Vec<Outcome> = [Rc::None, Rc::Standard, Rc::HighOrder, Rc::Dvrc]
            .iter()
            .map(|&w| run_plan(&pp, &s, &q, pl, v10, w, 60.0))
            .collect();
        println!(
            "| {:.0} nm | {:.0} … {:.0} | {:.3} | {:.3} | {:.3} | {:.3} | {} … {} | {:+.2} |",
            rms * 1e9,
            r.1,
            r.2,
            out[0].rms * 1e9,
            out[1].rms * 1e9,
            out[2].rms * 1e9,
            out[3].rms * 1e9,
            out[3].seen.0,
            out[3].seen.1,
            c.margin_db()
        );
    }
    // 6. Unequal leg pairs (the other source of irregularity the thesis names):
    //    pair 2's c_x, c_y scaled, same strip, L and Q.
    println!(
        "\n| pair 2 coefficients (σ_h = 100 nm, 10 µm/s) | N(α) without RC | none (nm) | RC (nm) | high-order RC (nm) | DVRC (nm) | α-periodic part none / RC / DVRC (nm) |"
    );
    println!("|---|---|---|---|---|---|---|");
    for factor in [1.0, 0.97, 0.9] {
        let pp = stage_params_unequal(STRIP_RMS_M, factor);
        let r = period_range(&pp, &s, v10, 60.0);
        let pl = plan_from_periods(r, comp, PAD);
        let steps = (60.0 / DT) as usize;
        let mut per = [0.0; 4];
        let out: Vec<Outcome> = [Rc::None, Rc::Standard, Rc::HighOrder, Rc::Dvrc]
            .iter()
            .enumerate()
            .map(|(i, &w)| {
                let (mut es, mut als) = (Vec::new(), Vec::new());
                let o = run_plan_traced(&pp, &s, &q, pl, v10, w, 60.0, |k, e, a| {
                    if k >= steps * 3 / 4 {
                        es.push(e);
                        als.push(a);
                    }
                });
                per[i] = alpha_periodic_split(&es, &als, 256).1;
                o
            })
            .collect();
        println!(
            "| × {factor} | {:.0} … {:.0} | {:.3} | {:.3} | {:.3} | {:.3} | {:.3} / {:.3} / {:.3} |",
            r.1,
            r.2,
            out[0].rms * 1e9,
            out[1].rms * 1e9,
            out[2].rms * 1e9,
            out[3].rms * 1e9,
            per[0] * 1e9,
            per[1] * 1e9,
            per[3] * 1e9
        );
    }
}
