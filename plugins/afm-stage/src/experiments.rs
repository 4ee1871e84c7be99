//! Ready-made experiments on the simulated stage (Secs. 6.2, 6.4 and 6.5):
//!
//! - [`decentralised_controllers`]: the (6.5) controllers tuned for a 6 dB modulus
//!   margin on the stage's small-signal model (Table 6.3);
//! - [`Sec65`]: the ±18 µm scan of Sec. 6.5 with the extended model (6.4)
//!   identified on the stage's x hysteresis (Sec. 6.3.2), its inverse (6.6) and the
//!   position feed-forward (6.7); [`Sec65::compare`] runs feedback only, + position
//!   FF and + hysteresis FF (Fig. 6.11), [`speed_sweep`] repeats that at several
//!   scan speeds (Table 6.4 style);
//! - [`closed_loop_identification`]: MIMO FRF identification with white noise
//!   injected at every plant input while the decentralised controllers close the
//!   loops (Fig. 2.8 in MIMO form, G = GS·S⁻¹), next to the naive open-loop H1
//!   estimate from the same closed-loop data, which is biased.

use crate::control::{
    FeedForward, IntegralLowPass, ScanResult, ScanSetup, log_grid, scan_experiment,
    tune_for_modulus_margin,
};
use crate::error::AfmError;
use crate::feedforward::{HysteresisFeedForward, PositionFeedForward};
use crate::hysteresis::{ChParams, ColemanHodgdon, Direction};
use crate::ident::{THESIS_RANGES_V, fit_extended, measure_loops};
use crate::stage::{AfmStage, N_OUTPUTS};
use nanomotion_core::analysis::{
    CMatrix, SpectralMatrix, WelchOptions, frf_mimo_closed_loop, frf_mimo_h1,
};
use nanomotion_core::lti::{Complex, StateSpace};
use nanomotion_core::rng::Rng;
use nanomotion_core::{Block, BuildContext, Controller, Plant};
use std::f64::consts::TAU;

/// `stage` with its hysteresis replaced by pure gains (µm/V): u = b makes the
/// Coleman–Hodgdon operator x = bV exactly (from the virgin state), so that the
/// stage's linear model `small_signal_model(gains)` is exact. For testing
/// identification methods against a known plant.
pub fn linearised(stage: &AfmStage, gains: [f64; 3]) -> AfmStage {
    let mut s = stage.clone();
    for (h, g) in s.hysteresis.iter_mut().zip(gains) {
        let p = ChParams::new(h.trace.alpha, g, g);
        h.trace = p;
        h.retrace = p;
    }
    s
}

/// Per-axis small-signal hysteresis gain (µm/V) used for control design: the mean
/// of the initial slope u and the anhysteretic slope b of the trace set.
pub fn design_gains(stage: &AfmStage) -> [f64; 3] {
    [0, 1, 2].map(|i| {
        let h = &stage.hysteresis[i].trace;
        0.5 * (h.b + h.c)
    })
}

/// The decentralised controllers (6.5) with f_LP = `f_lp_hz`, each tuned for
/// max|S_ii| = 6 dB on the diagonal of the small-signal model
/// (`stage.small_signal_model(gains)`), and that model.
pub fn decentralised_controllers(
    stage: &AfmStage,
    gains: [f64; 3],
    f_lp_hz: f64,
) -> Result<([IntegralLowPass; 3], StateSpace), AfmError> {
    let p = stage.small_signal_model(gains)?;
    let f = log_grid(0.1, 2000.0, 1500);
    let c = [0, 1, 2].map(|i| {
        let pi: Vec<Complex<f64>> = f
            .iter()
            .map(|&ff| p.evalfr(Complex::new(0.0, TAU * ff))[(i, i)])
            .collect();
        tune_for_modulus_margin(&f, &pi, f_lp_hz, 6.0)
    });
    Ok((c, p))
}

/// The Sec. 6.5 scan experiment, ready to run: setup, identified hysteresis
/// feed-forward and position feed-forward.
#[derive(Debug, Clone)]
pub struct Sec65 {
    /// Scan setup (range, speed, controllers, rate, seed).
    pub setup: ScanSetup,
    /// Inverse (6.6) of the extended model identified on the stage's x hysteresis.
    pub hysteresis_ff: HysteresisFeedForward,
    /// Position feed-forward (6.7): the inverse mean slope of the identified loop.
    pub position_ff: PositionFeedForward,
    /// Accuracy (%) of the identified model, trace and retrace ([`crate::ident::FitReport`]).
    pub fit_accuracy_percent: [f64; 2],
}

/// Errors of the three variants of one scan.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Comparison {
    /// Scan speed (µm/s).
    pub speed_um_s: f64,
    /// Feedback only.
    pub feedback: ScanResult,
    /// Feedback + position feed-forward (6.7).
    pub position_ff: ScanResult,
    /// Feedback + hysteresis feed-forward (6.6).
    pub hysteresis_ff: ScanResult,
}

impl Comparison {
    /// RMS reduction (%) of the hysteresis FF vs feedback only and vs position FF.
    pub fn reductions_percent(&self) -> (f64, f64) {
        let h = self.hysteresis_ff.rms_x_nm;
        (
            100.0 * (1.0 - h / self.feedback.rms_x_nm),
            100.0 * (1.0 - h / self.position_ff.rms_x_nm),
        )
    }
}

impl Sec65 {
    /// Build the experiment on `stage`: identify (6.4) on the stage's x hysteresis
    /// (reversal curves V_R ∈ {2 … 100} V centred at 50 V, 2 nm measurement noise),
    /// centre a ±`half_range_um` scan on the middle of the 50 V-centred ±20 V loop,
    /// tune the controllers for 6 dB (f_LP = 60 Hz) and scan at `speed_um_s`.
    pub fn new(
        stage: &AfmStage,
        half_range_um: f64,
        speed_um_s: f64,
        fs_hz: f64,
        seed: u64,
    ) -> Result<Self, AfmError> {
        let hx = ColemanHodgdon::new(stage.hysteresis[0].trace, stage.hysteresis[0].retrace)?;
        let (tr, re) = measure_loops(&hx, 50.0, &THESIS_RANGES_V, 61, 0.002, 3)?;
        let (model, rep_t, rep_r) = fit_extended(&tr, &re)?;
        let lp = hx.steady_loop(30.0, 70.0)?;
        let mid = 0.5 * (lp.eval(30.0, Direction::Trace) + lp.eval(70.0, Direction::Trace));
        let (c, _) = decentralised_controllers(stage, design_gains(stage), 60.0)?;
        let setup = ScanSetup {
            x_lo_um: mid - half_range_um,
            x_hi_um: mid + half_range_um,
            speed_um_s,
            periods: 2,
            fs_hz,
            v_yz: 50.0,
            controllers: [c[0], c[1]],
            seed,
        };
        let hff = HysteresisFeedForward::for_position_range(model, setup.x_lo_um, setup.x_hi_um)?;
        let tb = hff.branch(Direction::Trace);
        let slope = (setup.x_hi_um - setup.x_lo_um) / (tb.v_max - tb.v_m);
        let v_mid = 0.5 * (tb.v_max + tb.v_m);
        let pff = PositionFeedForward::new(1.0 / slope, v_mid - mid / slope);
        Ok(Self {
            setup,
            hysteresis_ff: hff,
            position_ff: pff,
            fit_accuracy_percent: [rep_t.accuracy_percent, rep_r.accuracy_percent],
        })
    }

    /// The same experiment at another scan speed.
    pub fn with_speed(&self, speed_um_s: f64) -> Self {
        let mut s = self.clone();
        s.setup.speed_um_s = speed_um_s;
        s
    }

    /// Run feedback only, + position FF and + hysteresis FF on `stage`.
    pub fn compare(&self, stage: &AfmStage) -> Result<Comparison, AfmError> {
        let fb = scan_experiment(stage, &self.setup, &FeedForward::None)?;
        let pos = scan_experiment(stage, &self.setup, &FeedForward::Position(self.position_ff))?;
        let hys = scan_experiment(
            stage,
            &self.setup,
            &FeedForward::Hysteresis(Box::new(self.hysteresis_ff.clone()), self.position_ff),
        )?;
        Ok(Comparison {
            speed_um_s: self.setup.speed_um_s,
            feedback: fb,
            position_ff: pos,
            hysteresis_ff: hys,
        })
    }
}

/// The Sec. 6.5 comparison at each of `speeds_um_s` (Table 6.4 style).
pub fn speed_sweep(
    stage: &AfmStage,
    base: &Sec65,
    speeds_um_s: &[f64],
) -> Result<Vec<Comparison>, AfmError> {
    speeds_um_s
        .iter()
        .map(|&v| base.with_speed(v).compare(stage))
        .collect()
}

/// Scan speeds of our Table 6.4 (µm/s): 7.2 µm/s of Sec. 6.5 halved twice and
/// doubled twice. The thesis's own speed column is lost in the text extraction;
/// 28.8 µm/s also brackets the 25 µm/s of the Ch. 7 scans.
pub const SWEEP_SPEEDS_UM_S: [f64; 5] = [1.8, 3.6, 7.2, 14.4, 28.8];

/// Closed-loop identification experiment: white noise w_i of standard deviation
/// `noise_std_v` (V) added to every plant input, independent per input, while
/// `controllers` hold the stage at the position it takes for the voltages `v0`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ClosedLoopIdentSetup {
    /// Operating voltages (V), also the constant feed-forward.
    pub v0: [f64; 3],
    /// Injected noise standard deviation per input (V).
    pub noise_std_v: f64,
    /// Decentralised controllers (6.5).
    pub controllers: [IntegralLowPass; 3],
    /// Sample rate (Hz).
    pub fs_hz: f64,
    /// Number of samples.
    pub n_samples: usize,
    /// Welch segment length.
    pub segment_len: usize,
    /// Seed of the stage noise (the injected noise uses `seed + 1`).
    pub seed: u64,
}

/// Result of [`closed_loop_identification`].
#[derive(Debug, Clone)]
pub struct ClosedLoopFrf {
    /// Bin frequencies (Hz).
    pub freq_hz: Vec<f64>,
    /// Closed-loop estimate G = (GS)·S⁻¹ per bin (3 × 3, m/V): S the FRF from the
    /// injected noises to the plant inputs, GS to the measured positions.
    pub closed_loop: Vec<CMatrix>,
    /// Naive open-loop H1 estimate from the plant inputs to the measured positions
    /// of the same closed-loop data (biased towards −1/C where the measurement
    /// noise fed back by the controller dominates the plant input).
    pub naive: Vec<CMatrix>,
    /// Coherence between w_i and the plant input i, per axis: 1/(1 + r) with
    /// r = |C|²Φ_n/Φ_w for a SISO loop, low where the fed-back sensor noise swamps
    /// the injection (there Ŝ, and so Ĝ, is uncertain).
    pub coherence_u: [Vec<f64>; 3],
    /// Coherence between w_i and the measured position i, per axis.
    pub coherence_y: [Vec<f64>; 3],
    /// Variance of the interferometer error (measured − true position) per axis (m²).
    pub sensor_noise_var_m2: [f64; 3],
    /// Input samples that were clipped.
    pub clipped: u64,
}

/// Run the closed-loop identification experiment on `stage` (see
/// [`ClosedLoopIdentSetup`]) and estimate the plant both ways.
pub fn closed_loop_identification(
    stage: &AfmStage,
    setup: &ClosedLoopIdentSetup,
) -> Result<ClosedLoopFrf, AfmError> {
    let dt = 1.0 / setup.fs_hz;
    let mut st = stage.clone();
    st.initial_v = setup.v0;
    st.build(&BuildContext::new("stage", dt, setup.seed))
        .map_err(|e| AfmError::param(e.field.clone(), e.to_string()))?;
    let mut c: Vec<_> = setup
        .controllers
        .iter()
        .map(|c| c.discrete(dt))
        .collect::<Result<_, _>>()?;
    let mut y = [0.0; N_OUTPUTS];
    st.plant_output(&mut y);
    let r = [y[4], y[5], y[6]];
    let n = setup.n_samples;
    let mut w = vec![vec![0.0; n]; 3];
    let mut v = vec![vec![0.0; n]; 3];
    let mut ym = vec![vec![0.0; n]; 3];
    let mut noise_sq = [0.0; 3];
    let mut rng = Rng::new(setup.seed.wrapping_add(1));
    let mut u = [0.0];
    let mut vk = [0.0; 3];
    for k in 0..n {
        st.plant_output(&mut y);
        for i in 0..3 {
            c[i].control(&[r[i] - y[i]], &mut u);
            let wi = setup.noise_std_v * rng.normal();
            vk[i] = setup.v0[i] + u[0] + wi;
            w[i][k] = wi;
            v[i][k] = vk[i] - setup.v0[i];
            ym[i][k] = y[i];
            noise_sq[i] += (y[i] - y[4 + i]).powi(2);
        }
        st.advance(&vk);
    }
    let err = |e: nanomotion_core::analysis::AnalysisError| AfmError::param("frf", e.to_string());
    let opts = WelchOptions::new(setup.segment_len);
    let ws: Vec<&[f64]> = w.iter().map(|x| x.as_slice()).collect();
    let vs: Vec<&[f64]> = v.iter().map(|x| x.as_slice()).collect();
    let ys: Vec<&[f64]> = ym.iter().map(|x| x.as_slice()).collect();
    let (f, g_cl) = frf_mimo_closed_loop(&ws, &vs, &ys, setup.fs_hz, &opts).map_err(err)?;
    let (_, g_naive) = frf_mimo_h1(&vs, &ys, setup.fs_hz, &opts).map_err(err)?;
    let coh = |a: &[f64], b: &[f64]| {
        SpectralMatrix::compute(&[a, b], setup.fs_hz, &opts)
            .map(|s| s.coherence(0, 1))
            .map_err(err)
    };
    let coherence_u = [coh(ws[0], vs[0])?, coh(ws[1], vs[1])?, coh(ws[2], vs[2])?];
    let coherence_y = [coh(ws[0], ys[0])?, coh(ws[1], ys[1])?, coh(ws[2], ys[2])?];
    Ok(ClosedLoopFrf {
        freq_hz: f,
        closed_loop: g_cl,
        naive: g_naive,
        coherence_u,
        coherence_y,
        sensor_noise_var_m2: noise_sq.map(|s| s / n as f64),
        clipped: st.clip_count(),
    })
}

/// The asymptotic value of the naive (direct, H1) estimate of a SISO plant P from
/// closed-loop data with injected input noise of density Φ_w and white sensor noise
/// of density Φ_n fed back through the controller C:
/// Ĝ = (P − r/C)/(1 + r), r = |C|²Φ_n/Φ_w. It tends to P where the injection
/// dominates (r → 0) and to −1/C where the fed-back sensor noise does (r → ∞).
pub fn naive_closed_loop_estimate(
    p: Complex<f64>,
    c: Complex<f64>,
    noise_ratio_n_over_w: f64,
) -> Complex<f64> {
    let r = c.norm_sqr() * noise_ratio_n_over_w;
    (p - r / c) / (1.0 + r)
}

#[cfg(test)]
mod tests {
    use super::*;
    use nanomotion_core::lti::C2dMethod;

    #[test]
    fn naive_estimate_limits_and_linearised_stage_is_linear() {
        let p = Complex::new(0.8, -0.3);
        let c = Complex::new(2.0, -5.0);
        assert!((naive_closed_loop_estimate(p, c, 0.0) - p).norm() < 1e-15);
        let far = naive_closed_loop_estimate(p, c, 1e12);
        assert!((far + 1.0 / c).norm() < 1e-9);
        // x = bV exactly, for any voltage path, on every axis.
        let gains = [0.85, 0.84, 0.17];
        let mut s = linearised(&AfmStage::default(), gains);
        s.build(&BuildContext::new("s", 1e-4, 0)).unwrap();
        let mut rng = Rng::new(5);
        for _ in 0..1000 {
            let v = [0, 1, 2].map(|_| rng.uniform_in(0.0, 100.0));
            s.advance(&v);
            let h = s.hysteresis_output_um();
            for i in 0..3 {
                assert!((h[i] - gains[i] * v[i]).abs() < 1e-9 * gains[i] * 100.0);
            }
        }
    }

    #[test]
    fn closed_loop_frf_recovers_the_linear_model_and_the_naive_estimate_is_biased() {
        let gains = [0.85, 0.84, 0.17];
        let stage = linearised(&AfmStage::default(), gains);
        let (c, p) = decentralised_controllers(&stage, gains, 60.0).unwrap();
        let fs = 5000.0;
        let setup = ClosedLoopIdentSetup {
            v0: [50.0; 3],
            noise_std_v: 0.05,
            controllers: c,
            fs_hz: fs,
            n_samples: 1 << 20,
            segment_len: 1 << 14,
            seed: 11,
        };
        let id = closed_loop_identification(&stage, &setup).unwrap();
        assert_eq!(id.clipped, 0);
        // The known model, discretised as the simulation runs it (ZOH, y_k = C x_k),
        // and the discrete controllers the loop actually used.
        let pd = p.c2d(1.0 / fs, C2dMethod::Zoh).unwrap();
        let cd: Vec<StateSpace> = c
            .iter()
            .map(|ci| ci.continuous().c2d(1.0 / fs, C2dMethod::TUSTIN).unwrap())
            .collect();
        let phi_w = setup.noise_std_v.powi(2);
        let mut cl_err = Vec::new();
        let (mut max_naive_bias, mut max_naive_vs_theory) = (0.0f64, [0.0f64; 3]);
        for (k, &f) in id.freq_hz.iter().enumerate() {
            if f == 0.0 || f > 300.0 {
                continue;
            }
            let z = Complex::from_polar(1.0, TAU * f / fs);
            let g = pd.evalfr(z);
            let near_mode = (100.0..160.0).contains(&f);
            for i in 0..3 {
                let gii = g[(i, i)];
                // Away from the resonances, where the coherences are good.
                if !near_mode && id.coherence_u[i][k].min(id.coherence_y[i][k]) > 0.9 {
                    cl_err.push((id.closed_loop[k][(i, i)] - gii).norm() / gii.norm());
                }
                // Naive estimate vs its closed-form limit (white sensor noise). The
                // first bin is skipped: the Hann window leaks the removed mean into it.
                if k >= 2 && f < 2.0 {
                    let ci = cd[i].evalfr(z)[(0, 0)];
                    let want =
                        naive_closed_loop_estimate(gii, ci, id.sensor_noise_var_m2[i] / phi_w);
                    let bias = (id.naive[k][(i, i)] - gii).norm() / gii.norm();
                    max_naive_bias = max_naive_bias.max(bias);
                    // Relative to the larger of |P| and |1/C| (the two limits).
                    let scale = gii.norm().max(1.0 / ci.norm());
                    max_naive_vs_theory[i] =
                        max_naive_vs_theory[i].max((id.naive[k][(i, i)] - want).norm() / scale);
                }
            }
        }
        cl_err.sort_by(f64::total_cmp);
        let (med_cl, worst_cl) = (cl_err[cl_err.len() / 2], cl_err[cl_err.len() - 1]);
        eprintln!(
            "closed loop, diagonal: median error {med_cl:.4}, worst {worst_cl:.4} over {} bins; naive: bias up to {max_naive_bias:.2}, off its closed form by at most {max_naive_vs_theory:.3?}",
            cl_err.len()
        );
        // Coherence γ² ≥ 0.9 and ~200 averaged segments: a standard error of about
        // √((1 − γ²)/(2Kγ²)) ≤ 2.5 % per estimated FRF, so a few % per bin.
        assert!(cl_err.len() > 500);
        assert!(med_cl < 0.02, "{med_cl}");
        assert!(worst_cl < 0.12, "{worst_cl}");
        // Below 2 Hz the integrators feed the sensor noise back into the plant
        // input: the naive estimate is far from P and where its closed form says.
        assert!(max_naive_bias > 0.3, "{max_naive_bias}");
        // The closed form is SISO; the loop is MIMO and the bins are 0.3 Hz wide
        // against a 1/f² controller gain: agreement to ~10 % of the limits.
        assert!(
            max_naive_vs_theory.iter().all(|&e| e < 0.15),
            "{max_naive_vs_theory:?}"
        );

        // Off-diagonal terms (−40 dB) need more injection for a usable SNR.
        let setup = ClosedLoopIdentSetup {
            noise_std_v: 0.5,
            n_samples: 1 << 19,
            ..setup
        };
        let id = closed_loop_identification(&stage, &setup).unwrap();
        let mut off = Vec::new();
        for (k, &f) in id.freq_hz.iter().enumerate() {
            if (5.0..60.0).contains(&f) {
                let g = pd.evalfr(Complex::from_polar(1.0, TAU * f / fs));
                for i in 0..3 {
                    for j in 0..3 {
                        if i != j {
                            off.push(
                                (id.closed_loop[k][(j, i)] - g[(j, i)]).norm() / g[(j, i)].norm(),
                            );
                        }
                    }
                }
            }
        }
        off.sort_by(f64::total_cmp);
        let med_off = off[off.len() / 2];
        eprintln!("closed loop, off-diagonal (5-60 Hz): median relative error {med_off:.3}");
        assert!(med_off < 0.1, "{med_off}");
    }

    #[test]
    fn speed_sweep_hysteresis_ff_best_at_every_speed_and_errors_grow_with_speed() {
        let stage = AfmStage::default();
        let base = Sec65::new(&stage, 18.0, 7.2, 5000.0, 4).unwrap();
        let rows = speed_sweep(&stage, &base, &SWEEP_SPEEDS_UM_S).unwrap();
        for r in &rows {
            eprintln!(
                "{:5.1} µm/s: rms x {:7.2} {:7.2} {:7.2} nm, max x {:7.1} {:7.1} {:7.1} nm, rms y {:.3} {:.3} {:.3} nm",
                r.speed_um_s,
                r.feedback.rms_x_nm,
                r.position_ff.rms_x_nm,
                r.hysteresis_ff.rms_x_nm,
                r.feedback.max_x_nm,
                r.position_ff.max_x_nm,
                r.hysteresis_ff.max_x_nm,
                r.feedback.rms_y_nm,
                r.position_ff.rms_y_nm,
                r.hysteresis_ff.rms_y_nm
            );
            assert!(r.hysteresis_ff.rms_x_nm < r.position_ff.rms_x_nm);
            assert!(r.position_ff.rms_x_nm < r.feedback.rms_x_nm);
            assert!(r.hysteresis_ff.max_x_imaging_nm < r.position_ff.max_x_imaging_nm);
            assert!(r.position_ff.max_x_imaging_nm < r.feedback.max_x_imaging_nm);
            for v in [r.feedback, r.position_ff, r.hysteresis_ff] {
                assert_eq!(v.clipped, 0);
            }
        }
        for w in rows.windows(2) {
            for (a, b) in [
                (w[0].feedback, w[1].feedback),
                (w[0].position_ff, w[1].position_ff),
                (w[0].hysteresis_ff, w[1].hysteresis_ff),
            ] {
                assert!(b.rms_x_nm > a.rms_x_nm, "{a:?} -> {b:?}");
            }
            // Max errors: with feed-forward the low speeds are at the noise bound
            // (max over noise) and the hysteresis FF's max is the turnaround ringing,
            // so only the feedback-only max is a clean function of the speed.
            assert!(w[1].feedback.max_x_imaging_nm > w[0].feedback.max_x_imaging_nm);
            // The x scan couples into y: the y error grows with the speed too.
            assert!(w[1].feedback.rms_y_nm > w[0].feedback.rms_y_nm);
        }
        // ... and it is the coupling: without it the fastest scan leaves y at noise level.
        let mut decoupled = stage.clone();
        decoupled.static_coupling = [[0.0; 3]; 3];
        decoupled.dynamic_coupling = [[0.0; 3]; 3];
        let fast = base.with_speed(SWEEP_SPEEDS_UM_S[SWEEP_SPEEDS_UM_S.len() - 1]);
        let r0 = scan_experiment(&decoupled, &fast.setup, &FeedForward::None).unwrap();
        let r1 = rows[rows.len() - 1].feedback;
        eprintln!(
            "fastest scan, y rms: coupled {:.3} nm, decoupled {:.3} nm",
            r1.rms_y_nm, r0.rms_y_nm
        );
        assert!(r1.rms_y_nm > 1.2 * r0.rms_y_nm);
    }
}
