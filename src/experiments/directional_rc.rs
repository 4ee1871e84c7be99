//! The Sec. 7.5 experiment on the simulated AFM (run by the example
//! `examples/directional_rc/main.rs`, the test `tests/directional_rc_example.rs` and
//! `nanomotion reproduce sec_7_5`): a grating rotated by α under the stage,
//! fast axis y ±25 µm at 25 µm/s (period 4 s), slow axis x at 125 nm/s, z held at
//! constant deflection at f_s = 20 kHz, RC on z with N = 80 000 samples.
//!
//! - controllers: the (6.5) integral + low-pass of `afm_stage` per axis, tuned for a
//!   6 dB modulus margin (the same K on x and y, so Rᵀ K R = K);
//! - RC on z (`dvrc::rc::RepetitiveControl`, (7.13)): L = ZPETC of the model
//!   T_z = P_z K_z/(1 + P_z K_z) (diagonal z mode only), Q a linear-phase
//!   FIR (101 taps in the example) whose cut-off `dvrc::design_q_cutoff` picks for criterion (7.16) with a 5 %
//!   margin;
//! - RC: the scan planned along the actuator axes (α̂ = 0);
//! - both: one lead-in scan period with RC off (the start-up transients of the x/y
//!   loops are not repetitive), then RC from iteration k = 1 (whose error is the
//!   feedback loop's: the memory is still empty);
//! - DRC: four estimation lines along y at x_c + {0, 1, 2, 3} µm first, α̂ from
//!   [`estimate_rotation`] (7.18)–(7.21), then the same scan planned along the
//!   sample's axes and mapped by R(α̂) (7.17) (references, errors and controller
//!   outputs through `FrameRotation`).

use crate::afm_stage::control::IntegralLowPass;
use crate::afm_stage::experiments::{decentralised_controllers, design_gains};
use crate::afm_stage::stage::{AfmStage, N_OUTPUTS, Topography};
use crate::core::lti::{C2dMethod, StateSpace, TransferFunction, feedback, series};
use crate::core::nalgebra::DMatrix;
use crate::core::{Block, BuildContext, Controller, Plant};
use crate::directional_rc::estimate::{
    EstimatorOptions, LineScan, RotationEstimate, estimate_rotation,
};
use crate::directional_rc::frame::{Direction, FrameRotation};
use crate::dvrc::filters::FilterSpec;
use crate::dvrc::rc::RepetitiveControl;
use crate::dvrc::stability::RcCriterion;
use std::f64::consts::{FRAC_PI_2, TAU};

/// Fast-axis amplitude (m): ±25 µm.
pub const AMPLITUDE_M: f64 = 25e-6;
/// Fast-axis period (s): 2·50 µm at 25 µm/s.
pub const PERIOD_S: f64 = 4.0;
/// Slow-axis speed (m/s).
pub const SLOW_M_S: f64 = 125e-9;
/// Estimation lines and their spacing (m).
pub const EST_LINES: usize = 4;
/// Spacing of the estimation lines along x (m).
pub const EST_DX_M: f64 = 1e-6;

/// One run.
#[derive(Debug, Clone)]
pub struct Config {
    /// Sample rate (Hz); the thesis: 20 kHz.
    pub fs_hz: f64,
    /// Scan periods (RC iterations k = 1 …).
    pub iterations: usize,
    /// True rotation of the grating under the stage (rad).
    pub alpha_rad: f64,
    /// DRC (estimate α, rotate) or plain RC.
    pub drc: bool,
    /// RC on (false: feedback only).
    pub rc: bool,
    /// Seed of the stage noise.
    pub seed: u64,
    /// Q cut-off (Hz); `None`: the largest that criterion (7.16) admits on the
    /// model with a 5 % margin (`dvrc::design_q_cutoff`).
    pub q_cutoff_hz: Option<f64>,
    /// Taps of the linear-phase FIR Q (odd); the example uses 101.
    pub q_taps: usize,
    /// Switch off the interferometer and deflection noise (diagnosis).
    pub noiseless: bool,
    /// Switch off the interferometer and deflection quantisation (diagnosis).
    pub unquantized: bool,
    /// A linear z piezo (diagnosis): b = c = the design slope (b + c)/2 on trace
    /// and retrace, so the Coleman–Hodgdon operator is y = slope·u.
    pub linear_z: bool,
    /// Keep every n-th sample for images (0: none).
    pub image_every: usize,
}

/// What a run gives.
#[derive(Debug, Clone)]
pub struct Outcome {
    /// rms e_z per iteration (nm), k = 1 …
    pub rms_nm: Vec<f64>,
    /// The rotation estimate (DRC).
    pub estimate: Option<RotationEstimate>,
    /// Criterion (7.16) with the designed Q.
    pub criterion: RcCriterion,
    /// Q cut-off (Hz).
    pub q_cutoff_hz: f64,
    /// (7.16) with T_z at the z piezo's smallest and largest small-signal slope.
    pub criterion_slopes: [RcCriterion; 2],
    /// rms of the RC output w per iteration (nm, as a z error equivalent).
    pub w_rms_nm: Vec<f64>,
    /// rms of e_z above 1 kHz per iteration (nm), from a Welch PSD.
    pub ez_hf_nm: Vec<f64>,
    /// rms of w above 1 kHz per iteration (nm).
    pub w_hf_nm: Vec<f64>,
    /// Drive samples the stage clipped to its voltage range (all axes, whole run).
    pub clips: u64,
    /// rms of the z controller output u_z per iteration (V).
    pub uz_rms_v: Vec<f64>,
    /// Image samples (x_a, y_a, z measured, e_z), all m.
    pub image: Vec<[f64; 4]>,
    /// Integral gains k of the (6.5) controllers x, y, z (V/(m·s)), f_LP = 60 Hz.
    pub k_gains: [f64; 3],
    /// T_z(z) numerator and denominator (descending powers of z).
    pub t_num_den: (Vec<f64>, Vec<f64>),
    /// Start position x_c, y_c and the contact z (m).
    pub start_m: [f64; 3],
}

/// The triangle of `triangular_scan`: 0 at t = 0 rising, +A at T/4, −A at 3T/4.
fn triangle(t: f64) -> f64 {
    let p = (t / PERIOD_S).fract();
    AMPLITUDE_M
        * if p < 0.25 {
            4.0 * p
        } else if p < 0.75 {
            2.0 - 4.0 * p
        } else {
            4.0 * p - 4.0
        }
}

/// The grating of `afm_stage` with its lines along the sample's x_r (normal along
/// y_r), rotated by α: angle of the normal π/2 + α.
pub fn grating(alpha_rad: f64) -> Topography {
    Topography::Grating {
        pitch_m: 10e-6,
        height_m: 20e-9,
        duty: 0.5,
        angle_rad: FRAC_PI_2 + alpha_rad,
        offset_m: 0.3e-6,
    }
}

/// Discrete model of the z complementary sensitivity T_z (diagonal z mode and K_z).
fn t_z(stage: &AfmStage, g: f64, kz: &StateSpace, dt: f64) -> StateSpace {
    let w = TAU * stage.resonance_hz[2];
    let z = stage.damping[2];
    let p = StateSpace::new(
        DMatrix::from_row_slice(2, 2, &[0.0, 1.0, -w * w, -2.0 * z * w]),
        DMatrix::from_row_slice(2, 1, &[0.0, w * w * g * 1e-6]),
        DMatrix::from_row_slice(1, 2, &[1.0, 0.0]),
        DMatrix::zeros(1, 1),
        None,
    )
    .unwrap()
    .c2d(dt, C2dMethod::Zoh)
    .unwrap();
    let one = StateSpace::new(
        DMatrix::zeros(0, 0),
        DMatrix::zeros(0, 1),
        DMatrix::zeros(1, 0),
        DMatrix::from_element(1, 1, 1.0),
        Some(dt),
    )
    .unwrap();
    feedback(&series(kz, &p).unwrap(), &one, -1.0).unwrap()
}

/// The simulated AFM, its controllers and the RC design of a configuration.
pub struct Setup {
    /// Sample time (s).
    pub dt: f64,
    /// The stage, built, at its start.
    pub stage: AfmStage,
    /// Design slopes (µm/V) of x, y, z.
    pub gains: [f64; 3],
    /// The (6.5) controllers (plain Rust, discrete).
    pub c: [IntegralLowPass; 3],
    /// Model T_z (discrete).
    pub t: StateSpace,
    /// T_z as a transfer function.
    pub tf: TransferFunction,
    /// L = ZPETC(T_z).
    pub l_spec: FilterSpec,
    /// L built.
    pub l: crate::dvrc::Filter,
    /// Q design.
    pub q: crate::dvrc::stability::QDesign,
    /// (7.16) at the z piezo's slope range.
    pub criterion_slopes: [RcCriterion; 2],
    /// RC period N (samples).
    pub n: usize,
    /// Start x, y (m).
    pub start: [f64; 2],
}

/// Build the stage, the controllers and the RC design of `cfg`.
pub fn setup(cfg: &Config) -> Setup {
    let dt = 1.0 / cfg.fs_hz;
    let mut stage = AfmStage::default();
    stage.topography = grating(cfg.alpha_rad);
    stage.initial_v = [50.0; 3];
    if cfg.linear_z {
        let h = stage.hysteresis[2].trace;
        let g = 0.5 * (h.b + h.c);
        for p in [
            &mut stage.hysteresis[2].trace,
            &mut stage.hysteresis[2].retrace,
        ] {
            p.b = g;
            p.c = g;
        }
    }
    if cfg.unquantized {
        stage.resolution_m = [0.0; 3];
        stage.deflection_resolution_m = 0.0;
    }
    if cfg.noiseless {
        stage.noise_bound_m = [0.0; 3];
        stage.deflection_noise_bound_m = 0.0;
    }
    // Contact where z starts: build once to read the start position.
    let mut y = [0.0; N_OUTPUTS];
    {
        let mut s = stage.clone();
        s.build(&BuildContext::new("stage", dt, cfg.seed)).unwrap();
        s.plant_output(&mut y);
    }
    let (x_c, y_c) = (y[4], y[5]);
    stage.contact_z_m = y[6] + stage.topography.height(x_c, y_c);
    stage
        .build(&BuildContext::new("stage", dt, cfg.seed))
        .unwrap();
    let gains = design_gains(&stage);
    let (c, _) = decentralised_controllers(&stage, gains, 60.0).unwrap();
    let kz_ss = c[2].continuous().c2d(dt, C2dMethod::TUSTIN).unwrap();

    // RC design: L = ZPETC(T_z), Q by criterion (7.16).
    let t = t_z(&stage, gains[2], &kz_ss, dt);
    let tf: TransferFunction = t.to_tf().unwrap();
    let l_spec = FilterSpec::Zpetc {
        num: tf.num.clone(),
        den: tf.den.clone(),
    };
    let l = l_spec.build(dt).unwrap();
    let taps = cfg.q_taps;
    let n = (PERIOD_S / dt).round() as usize;
    let q_built = |q: &crate::dvrc::stability::QDesign| {
        crate::dvrc::Filter::fir(q.taps.clone(), (taps - 1) / 2, dt)
    };
    let q = match cfg.q_cutoff_hz {
        None => crate::dvrc::design_q_cutoff(&t, &l, taps, 0, 0.05).unwrap(),
        Some(fc) => {
            let h = crate::core::lti::fir_lowpass(taps, fc, dt).unwrap();
            let qf = crate::dvrc::Filter::fir(h.clone(), (taps - 1) / 2, dt);
            crate::dvrc::stability::QDesign {
                cutoff_hz: fc,
                taps: h,
                criterion: crate::dvrc::rc_criterion(&t, &l, &qf, n, n).unwrap(),
            }
        }
    };
    // (7.16) with the z piezo's true small-signal slopes: the Coleman–Hodgdon
    // operator's slope runs from u (at a reversal) to b (far from one); the design
    // used their mean.
    let hz = stage.hysteresis[2].trace;
    let criterion_slopes = [hz.c, hz.b].map(|g| {
        let tg = t_z(&stage, g, &kz_ss, dt);
        crate::dvrc::rc_criterion(&tg, &l, &q_built(&q), n, n).unwrap()
    });
    Setup {
        dt,
        stage,
        gains,
        c,
        t,
        tf,
        l_spec,
        l,
        q,
        criterion_slopes,
        n,
        start: [x_c, y_c],
    }
}

/// Run one scan.
pub fn run(cfg: &Config) -> Outcome {
    let Setup {
        dt,
        mut stage,
        gains,
        c,
        t: _,
        tf,
        l_spec,
        l: _,
        q,
        criterion_slopes,
        n,
        start: [x_c, y_c],
    } = setup(cfg);
    let taps = cfg.q_taps;
    let mut y = [0.0; N_OUTPUTS];
    let mut kx = c[0].discrete(dt).unwrap();
    let mut ky = c[1].discrete(dt).unwrap();
    let mut kz = c[2].discrete(dt).unwrap();
    let mut rc = RepetitiveControl::built(
        n,
        l_spec,
        FilterSpec::Fir {
            coefficients: q.taps.clone(),
            delay: (taps - 1) / 2,
        },
        dt,
    )
    .unwrap();

    let v0 = 50.0;
    let drive = |st: &mut AfmStage, r_a: [f64; 2], u_s: [f64; 2], to_a: &FrameRotation, uz: f64| {
        let u_a = to_a.apply(u_s);
        // Feed-forward: the design slope (µm/V) around the start voltage.
        let ffx = v0 + (r_a[0] - x_c) * 1e6 / gains[0];
        let ffy = v0 + (r_a[1] - y_c) * 1e6 / gains[1];
        st.advance(&[ffx + u_a[0], ffy + u_a[1], v0 + uz]);
    };

    // Phase 1 (DRC): estimation lines along the actuator y.
    let mut estimate = None;
    let mut x_start = x_c;
    let ident = FrameRotation::new(0.0, Direction::ToActuator, 2);
    let (mut ux, mut uy, mut uz) = ([0.0], [0.0], [0.0]);
    if cfg.drc {
        let periods = EST_LINES + 1;
        let total = (periods as f64 * PERIOD_S / dt).round() as usize;
        let mut lines: Vec<Vec<f64>> = vec![Vec::new(); EST_LINES];
        let mut y0 = f64::NAN;
        for k in 0..total {
            let tk = k as f64 * dt;
            let per = (tk / PERIOD_S).floor() as usize;
            let p = (tk / PERIOD_S).fract();
            // Line i is recorded in period i + 1 (p < 1/4: 0 → +A); x moves to the
            // next line during 0.3 ≤ p < 0.7 of that period.
            let line = per.saturating_sub(1);
            let mut xr = x_c + line.min(EST_LINES - 1) as f64 * EST_DX_M;
            if per >= 1 && line + 1 < EST_LINES && (0.3..0.7).contains(&p) {
                xr += EST_DX_M * (p - 0.3) / 0.4;
            } else if per >= 1 && line + 1 < EST_LINES && p >= 0.7 {
                xr += EST_DX_M;
            }
            let r_a = [xr, y_c + triangle(tk)];
            stage.plant_output(&mut y);
            if per >= 1 && p < 0.25 {
                if lines[line].is_empty() {
                    y0 = r_a[1] - y_c;
                }
                lines[line].push(y[2]);
            }
            kx.control(&[r_a[0] - y[0]], &mut ux);
            ky.control(&[r_a[1] - y[1]], &mut uy);
            kz.control(&[-y[3]], &mut uz);
            drive(&mut stage, r_a, [ux[0], uy[0]], &ident, uz[0]);
        }
        let scans: Vec<LineScan> = lines
            .into_iter()
            .enumerate()
            .map(|(i, z)| {
                LineScan::new(
                    i as f64 * EST_DX_M,
                    y0,
                    AMPLITUDE_M * 4.0 / PERIOD_S * dt,
                    z,
                )
            })
            .collect();
        let e = estimate_rotation(&scans, &EstimatorOptions::default()).unwrap();
        x_start = x_c + (EST_LINES - 1) as f64 * EST_DX_M;
        estimate = Some(e);
    }
    let alpha_hat = estimate.as_ref().map_or(0.0, |e| e.alpha_rad);
    let to_a = FrameRotation::new(alpha_hat, Direction::ToActuator, 2);
    let to_s = FrameRotation::new(alpha_hat, Direction::ToSample, 2);

    // Phase 2: the scan with RC on z, planned in the sample frame. One lead-in
    // period without RC (start-up transients of the x/y loops are not repetitive;
    // RC would learn them), then RC from iteration k = 1.
    let mut rms = Vec::with_capacity(cfg.iterations);
    let (mut w_rms, mut ez_hf, mut w_hf) = (Vec::new(), Vec::new(), Vec::new());
    let (mut ez_rec, mut w_rec) = (Vec::with_capacity(n), Vec::with_capacity(n));
    let (mut uz_acc, mut uz_rms) = (0.0, Vec::new());
    let hf = |x: &[f64]| {
        let p = crate::core::analysis::psd_welch(
            x,
            1.0 / dt,
            &crate::core::analysis::WelchOptions::new(4096),
        )
        .unwrap();
        let s: f64 = p
            .freq_hz
            .iter()
            .zip(&p.density)
            .filter(|(f, _)| **f > 1000.0)
            .map(|(_, d)| d * p.df_hz)
            .sum();
        s.sqrt() * 1e9
    };
    let mut image = Vec::new();
    let (mut acc, mut cnt) = (0.0, 0usize);
    let mut w = [0.0];
    for k in 0..(cfg.iterations + 1) * n {
        let rc_on = cfg.rc && k >= n;
        let tk = k as f64 * dt;
        let r_s = [SLOW_M_S * tk, triangle(tk)];
        let d = to_a.apply(r_s);
        let r_a = [x_start + d[0], y_c + d[1]];
        stage.plant_output(&mut y);
        let e_s = to_s.apply([r_a[0] - y[0], r_a[1] - y[1]]);
        kx.control(&[e_s[0]], &mut ux);
        ky.control(&[e_s[1]], &mut uy);
        let e_z = -y[3];
        w[0] = if rc_on { rc.output_w() } else { 0.0 };
        kz.control(&[e_z + w[0]], &mut uz);
        if rc_on {
            rc.learn(e_z);
        }
        drive(&mut stage, r_a, [ux[0], uy[0]], &to_a, uz[0]);
        if k < n {
            continue;
        }
        acc += e_z * e_z;
        cnt += 1;
        ez_rec.push(e_z);
        w_rec.push(w[0]);
        uz_acc += uz[0] * uz[0];
        if cnt == n {
            rms.push((acc / n as f64).sqrt() * 1e9);
            acc = 0.0;
            cnt = 0;
            w_rms.push((w_rec.iter().map(|v| v * v).sum::<f64>() / n as f64).sqrt() * 1e9);
            ez_hf.push(hf(&ez_rec));
            w_hf.push(hf(&w_rec));
            ez_rec.clear();
            w_rec.clear();
            uz_rms.push((uz_acc / n as f64).sqrt());
            uz_acc = 0.0;
        }
        if cfg.image_every > 0 && k % cfg.image_every == 0 {
            image.push([y[0], y[1], y[2], e_z]);
        }
    }
    Outcome {
        rms_nm: rms,
        w_rms_nm: w_rms,
        ez_hf_nm: ez_hf,
        w_hf_nm: w_hf,
        clips: stage.clip_count(),
        uz_rms_v: uz_rms,
        estimate,
        criterion: q.criterion,
        q_cutoff_hz: q.cutoff_hz,
        criterion_slopes,
        image,
        k_gains: [c[0].k, c[1].k, c[2].k],
        t_num_den: (tf.num.clone(), tf.den.clone()),
        start_m: [x_c, y_c, stage.contact_z_m],
    }
}

/// The learning criterion (7.16) with the loop the simulation really closes:
/// white noise w (std `w_std_m`, seeded) is injected where RC adds its output
/// (before K_z) while the DRC scan runs with RC off; T from w to −e_z is estimated
/// by Welch H1 (segments of `segment` samples), and |Q(1 − T L z^l)| is evaluated
/// with that T and with the model T_z at the same frequencies.
pub struct LoopCheck {
    /// Frequencies (Hz).
    pub f_hz: Vec<f64>,
    /// Measured T (complex) and its coherence.
    pub t_meas: Vec<crate::core::nalgebra::Complex<f64>>,
    /// Coherence of the estimate.
    pub coherence: Vec<f64>,
    /// Model T_z at the same frequencies.
    pub t_model: Vec<crate::core::nalgebra::Complex<f64>>,
    /// |Q(1 − T L z^l)| with the measured T.
    pub crit_meas: Vec<f64>,
    /// The same with the model.
    pub crit_model: Vec<f64>,
    /// Q cut-off (Hz).
    pub q_cutoff_hz: f64,
    /// Drive samples clipped by the stage.
    pub clips: u64,
}

/// See [`LoopCheck`].
pub fn loop_check(
    cfg: &Config,
    w_std_m: f64,
    periods: usize,
    segment: usize,
    flat: bool,
) -> LoopCheck {
    use crate::core::LearningFilter;
    use crate::core::analysis::{WelchOptions, frf_h1};
    use crate::core::nalgebra::Complex;
    let Setup {
        dt,
        mut stage,
        gains,
        c,
        t,
        l,
        q,
        n,
        start: [x_c, y_c],
        ..
    } = setup(cfg);
    if flat {
        // No topography: e_z = −T w (+ noise, hysteresis) only.
        if let Topography::Grating { height_m, .. } = &mut stage.topography {
            *height_m = 0.0;
        }
    }
    let mut kx = c[0].discrete(dt).unwrap();
    let mut ky = c[1].discrete(dt).unwrap();
    let mut kz = c[2].discrete(dt).unwrap();
    let to_a = FrameRotation::new(cfg.alpha_rad, Direction::ToActuator, 2);
    let to_s = FrameRotation::new(cfg.alpha_rad, Direction::ToSample, 2);
    let mut rng = crate::core::rng::Rng::new(cfg.seed ^ 0x5eed);
    let mut y = [0.0; N_OUTPUTS];
    let (mut ux, mut uy, mut uz) = ([0.0], [0.0], [0.0]);
    let v0 = 50.0;
    let total = (periods + 1) * n;
    let (mut ws, mut es) = (
        Vec::with_capacity(periods * n),
        Vec::with_capacity(periods * n),
    );
    for k in 0..total {
        let tk = k as f64 * dt;
        let d = to_a.apply([SLOW_M_S * tk, triangle(tk)]);
        let r_a = [x_c + d[0], y_c + d[1]];
        stage.plant_output(&mut y);
        let e_s = to_s.apply([r_a[0] - y[0], r_a[1] - y[1]]);
        kx.control(&[e_s[0]], &mut ux);
        ky.control(&[e_s[1]], &mut uy);
        let e_z = -y[3];
        let w = if k >= n { w_std_m * rng.normal() } else { 0.0 };
        kz.control(&[e_z + w], &mut uz);
        let u_a = to_a.apply([ux[0], uy[0]]);
        let ffx = v0 + (r_a[0] - x_c) * 1e6 / gains[0];
        let ffy = v0 + (r_a[1] - y_c) * 1e6 / gains[1];
        stage.advance(&[ffx + u_a[0], ffy + u_a[1], v0 + uz[0]]);
        if k >= n {
            ws.push(w);
            es.push(-e_z);
        }
    }
    let fs = 1.0 / dt;
    let h = frf_h1(&ws, &es, fs, &WelchOptions::new(segment)).unwrap();
    let qf = crate::dvrc::Filter::fir(q.taps.clone(), (cfg.q_taps - 1) / 2, dt);
    let lp = l.preview_samples() as f64;
    let crit = |tv: Complex<f64>, f: f64| {
        let w = TAU * f;
        let tl = tv * l.freqresp_at(w) * Complex::from_polar(1.0, w * dt * lp);
        (qf.freqresp_at(w) * (Complex::new(1.0, 0.0) - tl)).norm()
    };
    let t_model: Vec<Complex<f64>> = h
        .freq_hz
        .iter()
        .map(|&f| t.freqresp_siso_at(TAU * f))
        .collect();
    let crit_meas = h
        .freq_hz
        .iter()
        .zip(&h.response)
        .map(|(&f, &tv)| crit(tv, f))
        .collect();
    let crit_model = h
        .freq_hz
        .iter()
        .zip(&t_model)
        .map(|(&f, &tv)| crit(tv, f))
        .collect();
    LoopCheck {
        f_hz: h.freq_hz.clone(),
        t_meas: h.response.clone(),
        coherence: h.coherence.clone(),
        t_model,
        crit_meas,
        crit_model,
        q_cutoff_hz: q.cutoff_hz,
        clips: stage.clip_count(),
    }
}
