//! Decentralised control of Sec. 6.4 and the scanning experiment of Sec. 6.5.
//!
//! - [`IntegralLowPass`]: the controller (6.5) C(s) = k/s · 2πf_LP/(s + 2πf_LP),
//!   continuous model, Tustin-discretised allocation-free [`Controller`];
//! - [`loop_margins`]: bandwidth (cross-over), phase and gain margins, and the
//!   modulus margin max|S| of a SISO loop gain on a frequency grid;
//! - [`tune_for_modulus_margin`]: the largest k for which max|S| ≤ a bound (6 dB);
//! - [`decentralised_analysis`]: per-axis margins, characteristic loci of P·C
//!   (Fig. 6.8) and MIMO closed-loop stability;
//! - [`scan_experiment`]: the closed-loop triangular scan of Sec. 6.5 on the
//!   simulated stage with feedback only, + position feed-forward (6.7), or +
//!   hysteresis feed-forward (6.6).

use crate::error::AfmError;
use crate::feedforward::{HysteresisFeedForward, PositionFeedForward};
use crate::stage::{AfmStage, N_OUTPUTS};
use nalgebra::DMatrix;
use nanomotion_core::analysis::{CMatrix, characteristic_loci};
use nanomotion_core::lti::{C2dMethod, Complex, SsStepper, StateSpace, append, feedback, series};
use nanomotion_core::{Block, BuildContext, Controller, Plant};
use std::f64::consts::TAU;

/// The integral + first-order low-pass controller (6.5):
/// C(s) = k/s · 2πf_LP/(s + 2πf_LP).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct IntegralLowPass {
    /// Gain k (V/(m·s) for the stage: volts per metre of error per second).
    pub k: f64,
    /// Low-pass cut-off f_LP (Hz).
    pub f_lp_hz: f64,
}

impl IntegralLowPass {
    /// Continuous model: x₁' = e, x₂' = 2πf_LP(k x₁ − x₂), u = x₂.
    pub fn continuous(&self) -> StateSpace {
        let w = TAU * self.f_lp_hz;
        StateSpace::new(
            DMatrix::from_row_slice(2, 2, &[0.0, 0.0, self.k * w, -w]),
            DMatrix::from_row_slice(2, 1, &[1.0, 0.0]),
            DMatrix::from_row_slice(1, 2, &[0.0, 1.0]),
            DMatrix::zeros(1, 1),
            None,
        )
        .expect("consistent dimensions")
    }

    /// C(jω).
    pub fn freqresp(&self, w_rad_s: f64) -> Complex<f64> {
        let s = Complex::new(0.0, w_rad_s);
        let wl = TAU * self.f_lp_hz;
        self.k / s * wl / (s + wl)
    }

    /// A discrete (Tustin) controller at period `dt` (s).
    pub fn discrete(&self, dt: f64) -> Result<DiscreteController, AfmError> {
        if !(self.k.is_finite() && self.f_lp_hz > 0.0 && self.f_lp_hz < 0.5 / dt) {
            return Err(AfmError::param(
                "f_lp_hz",
                format!(
                    "{} Hz must be in (0, Nyquist) and k = {} finite",
                    self.f_lp_hz, self.k
                ),
            ));
        }
        let d = self
            .continuous()
            .c2d(dt, C2dMethod::TUSTIN)
            .map_err(|e| AfmError::param("controller", e.to_string()))?;
        let s = SsStepper::new(&d).map_err(|e| AfmError::param("controller", e.to_string()))?;
        Ok(DiscreteController { s })
    }
}

/// A discretised SISO controller (allocation-free).
#[derive(Debug, Clone)]
pub struct DiscreteController {
    s: SsStepper,
}

impl Controller for DiscreteController {
    fn control(&mut self, e: &[f64], u: &mut [f64]) {
        self.s.step(&e[..1], &mut u[..1]);
    }
    fn reset(&mut self) {
        self.s.reset();
    }
}

/// Margins of a SISO loop gain.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Margins {
    /// First cross-over |L| = 1 (Hz): the bandwidth f_BW of Sec. 6.4.
    pub bandwidth_hz: f64,
    /// Phase margin (deg) at the cross-over.
    pub phase_margin_deg: f64,
    /// Gain margin (dB) at the first −180° crossing (∞ if none on the grid).
    pub gain_margin_db: f64,
    /// Modulus margin max_f |S| (dB), S = 1/(1 + L).
    pub max_sensitivity_db: f64,
}

/// Margins of the loop gain samples `l` on the increasing grid `f_hz`.
pub fn loop_margins(f_hz: &[f64], l: &[Complex<f64>]) -> Margins {
    let mut bw = f64::NAN;
    let mut pm = f64::NAN;
    let mut gm = f64::INFINITY;
    let mut ms: f64 = 0.0;
    for i in 0..l.len() {
        ms = ms.max(1.0 / (1.0 + l[i]).norm());
        if i == 0 {
            continue;
        }
        if bw.is_nan() && l[i - 1].norm() >= 1.0 && l[i].norm() < 1.0 {
            // Interpolate in log |L|.
            let (a, b) = (l[i - 1].norm().ln(), l[i].norm().ln());
            let t = a / (a - b);
            bw = f_hz[i - 1] * (f_hz[i] / f_hz[i - 1]).powf(t);
            pm = 180.0 + l[i].arg().to_degrees();
            if pm > 180.0 {
                pm -= 360.0;
            }
        }
        // −180° crossing: imaginary part changes sign with negative real part.
        if gm.is_infinite()
            && l[i - 1].im.signum() != l[i].im.signum()
            && l[i].re < 0.0
            && l[i - 1].im < 0.0
        {
            gm = -20.0 * l[i].norm().log10();
        }
    }
    Margins {
        bandwidth_hz: bw,
        phase_margin_deg: pm,
        gain_margin_db: gm,
        max_sensitivity_db: 20.0 * ms.log10(),
    }
}

/// A logarithmic grid of `n` frequencies from `f0` to `f1` (Hz).
pub fn log_grid(f0: f64, f1: f64, n: usize) -> Vec<f64> {
    (0..n)
        .map(|i| f0 * (f1 / f0).powf(i as f64 / (n - 1) as f64))
        .collect()
}

/// Largest controller gain k of (6.5) with cut-off `f_lp_hz` for which the loop with
/// the SISO plant frequency response `p(f)` keeps max|S| ≤ `max_ms_db` (dB), by
/// bisection in log k.
pub fn tune_for_modulus_margin(
    f_hz: &[f64],
    p: &[Complex<f64>],
    f_lp_hz: f64,
    max_ms_db: f64,
) -> IntegralLowPass {
    let ms = |k: f64| {
        let c = IntegralLowPass { k, f_lp_hz };
        let l: Vec<Complex<f64>> = f_hz
            .iter()
            .zip(p)
            .map(|(f, p)| p * c.freqresp(TAU * f))
            .collect();
        loop_margins(f_hz, &l).max_sensitivity_db
    };
    // Bracket: the gain that puts the cross-over at the first frequency is safe.
    let mut lo = TAU * f_hz[0] / p[0].norm() * 1e-3;
    let mut hi = lo;
    while ms(hi) <= max_ms_db && hi < 1e30 {
        lo = hi;
        hi *= 2.0;
    }
    for _ in 0..60 {
        let mid = (lo * hi).sqrt();
        if ms(mid) <= max_ms_db {
            lo = mid
        } else {
            hi = mid
        }
    }
    IntegralLowPass { k: lo, f_lp_hz }
}

/// Result of [`decentralised_analysis`].
#[derive(Debug, Clone)]
pub struct DecentralisedReport {
    /// Margins of the diagonal loops P_ii C_i.
    pub margins: [Margins; 3],
    /// Characteristic loci λ_i(P(f)C(f)) on the grid (Fig. 6.8, left).
    pub loci: Vec<Vec<Complex<f64>>>,
    /// Largest distance between the loci and the nearest diagonal loop gain,
    /// relative to the return difference: max |λ − L_ii| / (1 + |L_ii|)
    /// (λ(PC) ≈ λ(diag PC) when the axes are decoupled).
    pub loci_vs_diagonal: f64,
    /// Whether the 3×3 closed loop with the decentralised controller is stable.
    pub closed_loop_stable: bool,
}

/// Analyse decentralised control of the continuous 3×3 plant `p` (V → m) with the
/// controllers `c` on the grid `f_hz`.
pub fn decentralised_analysis(
    p: &StateSpace,
    c: &[IntegralLowPass; 3],
    f_hz: &[f64],
) -> Result<DecentralisedReport, AfmError> {
    let err = |e: nanomotion_core::lti::LtiError| AfmError::param("plant", e.to_string());
    let mut l_all: Vec<CMatrix> = Vec::with_capacity(f_hz.len());
    let mut diag: [Vec<Complex<f64>>; 3] = Default::default();
    for &f in f_hz {
        let w = TAU * f;
        let g = p.evalfr(Complex::new(0.0, w));
        let cd = CMatrix::from_fn(3, 3, |i, j| {
            if i == j {
                c[i].freqresp(w)
            } else {
                Complex::new(0.0, 0.0)
            }
        });
        let l = &g * &cd;
        for (i, d) in diag.iter_mut().enumerate() {
            d.push(l[(i, i)]);
        }
        l_all.push(l);
    }
    let margins = [0, 1, 2].map(|i| loop_margins(f_hz, &diag[i]));
    let loci = characteristic_loci(&l_all).map_err(|e| AfmError::param("loci", e.to_string()))?;
    let mut dev: f64 = 0.0;
    for (k, _) in f_hz.iter().enumerate() {
        for locus in &loci {
            let d = (0..3)
                .map(|i| (locus[k] - diag[i][k]).norm() / (1.0 + diag[i][k].norm()))
                .fold(f64::INFINITY, f64::min);
            dev = dev.max(d);
        }
    }
    let cs = append(&c.map(|ci| ci.continuous())).map_err(err)?;
    let l = series(&cs, p).map_err(err)?;
    let eye = StateSpace::gain(DMatrix::identity(3, 3), None);
    let s = feedback(&eye, &l, -1.0).map_err(err)?;
    Ok(DecentralisedReport {
        margins,
        loci,
        loci_vs_diagonal: dev,
        closed_loop_stable: s.is_stable(),
    })
}

/// Feed-forward used in [`scan_experiment`].
#[derive(Debug, Clone)]
pub enum FeedForward {
    /// Feedback only.
    None,
    /// Position feed-forward (6.7) on x and y.
    Position(PositionFeedForward),
    /// Hysteresis feed-forward (6.6) on x; position feed-forward on y.
    Hysteresis(Box<HysteresisFeedForward>, PositionFeedForward),
}

/// The Sec. 6.5 scan: x follows a triangle between `x_lo_um` and `x_hi_um` at
/// `speed_um_s`, y is held at its initial position, z is driven with a constant
/// voltage; decentralised controllers on x and y at `fs_hz`.
#[derive(Debug, Clone)]
pub struct ScanSetup {
    /// Lower end of the scan (µm, stage x coordinate).
    pub x_lo_um: f64,
    /// Upper end of the scan (µm).
    pub x_hi_um: f64,
    /// Scan speed (µm/s).
    pub speed_um_s: f64,
    /// Number of full periods (trace + retrace); the last one is scored.
    pub periods: usize,
    /// Sample rate (Hz).
    pub fs_hz: f64,
    /// Voltage held on y and z (V).
    pub v_yz: f64,
    /// Controllers (6.5) for x and y.
    pub controllers: [IntegralLowPass; 2],
    /// Seed of the stage noise.
    pub seed: u64,
}

/// Errors of the last scored period of [`scan_experiment`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ScanResult {
    /// RMS tracking error in x (nm).
    pub rms_x_nm: f64,
    /// Max |e_x| (nm) over the whole period, turnarounds included.
    pub max_x_nm: f64,
    /// Max |e_x| (nm) in the imaging region: more than 10 % of a line time after
    /// each turnaround (where the thesis's hysteresis feed-forward rings).
    pub max_x_imaging_nm: f64,
    /// RMS of the y error (nm): the coupling of the x scan into y plus noise.
    pub rms_y_nm: f64,
    /// Input samples that were clipped.
    pub clipped: u64,
}

/// Run the Sec. 6.5 scan on `stage` (built here at `setup.fs_hz`).
pub fn scan_experiment(
    stage: &AfmStage,
    setup: &ScanSetup,
    ff: &FeedForward,
) -> Result<ScanResult, AfmError> {
    let dt = 1.0 / setup.fs_hz;
    let line_s = (setup.x_hi_um - setup.x_lo_um) / setup.speed_um_s;
    if !(line_s > 0.0) {
        return Err(AfmError::param(
            "x_hi_um",
            "scan range and speed must be positive",
        ));
    }
    let period_s = 2.0 * line_s;
    let mut st = stage.clone();
    // Start at the lower end: initial x voltage from the feed-forward (or the slope).
    let mut ff = ff.clone();
    let v0_x = match &mut ff {
        FeedForward::Hysteresis(h, _) => h.step(setup.x_lo_um),
        FeedForward::Position(p) => p.voltage(setup.x_lo_um),
        FeedForward::None => setup.x_lo_um / st.hysteresis[0].trace.b,
    }
    .clamp(st.v_min_v, st.v_max_v);
    st.initial_v = [v0_x, setup.v_yz, setup.v_yz];
    st.build(&BuildContext::new("stage", dt, setup.seed))
        .map_err(|e| AfmError::param(e.field.clone(), e.to_string()))?;
    let mut y = [0.0; N_OUTPUTS];
    st.plant_output(&mut y);
    let r_y = y[5]; // hold y where it starts (true position, m)
    let mut cx = setup.controllers[0].discrete(dt)?;
    let mut cy = setup.controllers[1].discrete(dt)?;
    // Feed-forward on y holds the initial voltage; the integrators start at zero.
    let ffy = setup.v_yz;
    let n = (setup.periods as f64 * period_s / dt).round() as usize;
    let scored_from = n - (period_s / dt).round() as usize;
    let (mut sx, mut mx, mut mxi, mut sy, mut ns) = (0.0, 0.0f64, 0.0f64, 0.0, 0usize);
    let (mut ux, mut uy) = ([0.0], [0.0]);
    for k in 0..n {
        let t = k as f64 * dt;
        let ph = (t / period_s).fract();
        let r_um = if ph < 0.5 {
            setup.x_lo_um + (setup.x_hi_um - setup.x_lo_um) * 2.0 * ph
        } else {
            setup.x_hi_um - (setup.x_hi_um - setup.x_lo_um) * 2.0 * (ph - 0.5)
        };
        st.plant_output(&mut y);
        let ex = r_um * 1e-6 - y[0];
        let ey = r_y - y[1];
        cx.control(&[ex], &mut ux);
        cy.control(&[ey], &mut uy);
        let (fx, fy) = match &mut ff {
            FeedForward::None => (v0_x, setup.v_yz),
            FeedForward::Position(p) => (p.voltage(r_um), ffy),
            FeedForward::Hysteresis(h, _) => (h.step(r_um), ffy),
        };
        st.advance(&[fx + ux[0], fy + uy[0], setup.v_yz]);
        if k >= scored_from {
            sx += ex * ex;
            mx = mx.max(ex.abs());
            if (ph * 2.0).fract() > 0.1 {
                mxi = mxi.max(ex.abs());
            }
            sy += ey * ey;
            ns += 1;
        }
    }
    Ok(ScanResult {
        rms_x_nm: (sx / ns as f64).sqrt() * 1e9,
        max_x_nm: mx * 1e9,
        max_x_imaging_nm: mxi * 1e9,
        rms_y_nm: (sy / ns as f64).sqrt() * 1e9,
        clipped: st.clip_count(),
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::hysteresis::{ColemanHodgdon, Direction};
    use crate::ident::{THESIS_RANGES_V, fit_extended, measure_loops};
    use nanomotion_core::analysis::{WelchOptions, frf_mimo_h1, rga};
    use nanomotion_core::rng::Rng;

    fn controllers(stage: &AfmStage) -> ([IntegralLowPass; 3], StateSpace) {
        // Small-signal plant with the mean hysteresis slope of a 36 V loop.
        let g = [0, 1, 2].map(|i| {
            let h = &stage.hysteresis[i].trace;
            0.5 * (h.b + h.c)
        });
        let p = stage.small_signal_model(g).unwrap();
        let f = log_grid(0.1, 2000.0, 1500);
        let c = [0, 1, 2].map(|i| {
            let pi: Vec<Complex<f64>> = f
                .iter()
                .map(|&ff| p.evalfr(Complex::new(0.0, TAU * ff))[(i, i)])
                .collect();
            tune_for_modulus_margin(&f, &pi, 60.0, 6.0)
        });
        (c, p)
    }

    #[test]
    fn integral_low_pass_matches_its_transfer_function() {
        let c = IntegralLowPass {
            k: 3.0,
            f_lp_hz: 50.0,
        };
        let m = c.continuous();
        for f in [0.5, 50.0, 700.0] {
            let w = TAU * f;
            assert!(
                (m.evalfr(Complex::new(0.0, w))[(0, 0)] - c.freqresp(w)).norm()
                    < 1e-12 * c.freqresp(w).norm()
            );
        }
        // Ramp response of the discrete controller: the integral of a unit error.
        let mut d = c.discrete(1e-4).unwrap();
        let mut u = [0.0];
        for _ in 0..20_000 {
            d.control(&[1.0], &mut u);
        }
        // After 2 s: k·(t − 1/ω_LP) for t ≫ 1/ω_LP.
        let want = 3.0 * (2.0 - 1.0 / (TAU * 50.0));
        assert!((u[0] - want).abs() < 1e-3 * want, "{} vs {want}", u[0]);
    }

    #[test]
    fn decentralised_design_meets_6_db_and_loci_match_diagonal() {
        let stage = AfmStage::default();
        let (c, p) = controllers(&stage);
        let f = log_grid(0.1, 2000.0, 1500);
        let rep = decentralised_analysis(&p, &c, &f).unwrap();
        assert!(rep.closed_loop_stable);
        for m in rep.margins {
            assert!(m.max_sensitivity_db <= 6.0 + 1e-6, "{m:?}");
            assert!(m.max_sensitivity_db > 5.9, "{m:?}");
            assert!(m.phase_margin_deg > 30.0, "{m:?}");
            assert!(m.bandwidth_hz > 1.0 && m.bandwidth_hz < 100.0, "{m:?}");
            eprintln!("margins: {m:?}");
        }
        // Weak coupling: the loci are within a few % of the diagonal loop gains.
        assert!(rep.loci_vs_diagonal < 0.1, "{}", rep.loci_vs_diagonal);
    }

    #[test]
    fn mimo_frf_and_rga_show_decoupling_below_100_hz() {
        // White noise (σ² = 0.5 V²) on all three inputs around 50 V, open loop.
        let mut s = AfmStage::default();
        s.initial_v = [50.0; 3];
        let fs = 5000.0;
        s.build(&BuildContext::new("s", 1.0 / fs, 2)).unwrap();
        let mut rng = Rng::new(9);
        let n = 1 << 17;
        let mut u = vec![vec![0.0; n]; 3];
        let mut yv = vec![vec![0.0; n]; 3];
        let mut y = [0.0; N_OUTPUTS];
        for k in 0..n {
            s.plant_output(&mut y);
            let v: Vec<f64> = (0..3).map(|_| 0.5f64.sqrt() * rng.normal()).collect();
            for i in 0..3 {
                u[i][k] = v[i];
                yv[i][k] = y[i];
            }
            s.advance(&[50.0 + v[0], 50.0 + v[1], 50.0 + v[2]]);
        }
        let ins: Vec<&[f64]> = u.iter().map(|x| x.as_slice()).collect();
        let outs: Vec<&[f64]> = yv.iter().map(|x| x.as_slice()).collect();
        let (f, h) = frf_mimo_h1(&ins, &outs, fs, &WelchOptions::new(2048)).unwrap();
        let mut db = Vec::new();
        for (k, fk) in f.iter().enumerate() {
            if *fk < 5.0 || *fk > 60.0 {
                continue;
            }
            let l = rga(&h[k]).unwrap();
            for i in 0..3 {
                assert!(
                    (l[(i, i)] - Complex::new(1.0, 0.0)).norm() < 0.1,
                    "f={fk}: {}",
                    l[(i, i)]
                );
            }
            // Off-diagonal x ↔ y relative to the diagonal.
            db.push(20.0 * (h[k][(1, 0)].norm() / h[k][(0, 0)].norm()).log10());
        }
        // The hysteresis distortion of the other axes leaks into the estimate of the
        // weak off-diagonal terms bin by bin; the median is about −40 dB.
        db.sort_by(f64::total_cmp);
        let med = db[db.len() / 2];
        assert!(
            db.len() > 10 && med < -35.0 && med > -45.0,
            "median {med} dB"
        );
        // Near the 400 Hz parasitic mode the axes are coupled: the RGA departs from I.
        let k400 = f.iter().position(|&x| x >= 395.0).unwrap();
        let dev = (0..3)
            .map(|i| (rga(&h[k400]).unwrap()[(i, i)] - Complex::new(1.0, 0.0)).norm())
            .fold(0.0, f64::max);
        assert!(dev > 0.1, "RGA at 400 Hz: {dev}");
    }

    #[test]
    fn hysteresis_ff_beats_position_ff_beats_feedback_only() {
        let stage = AfmStage::default();
        let (c, _) = controllers(&stage);
        // Identify (6.4) on the stage's x hysteresis (Sec. 6.3.2), then invert it.
        let hx =
            ColemanHodgdon::new(stage.hysteresis[0].trace, stage.hysteresis[0].retrace).unwrap();
        let (tr, re) = measure_loops(&hx, 50.0, &THESIS_RANGES_V, 61, 0.002, 3).unwrap();
        let (model, _, _) = fit_extended(&tr, &re).unwrap();
        // ±18 µm around the middle of the 50 V-centred loop, 7.2 µm/s.
        let mid = 0.5
            * (hx
                .steady_loop(30.0, 70.0)
                .unwrap()
                .eval(30.0, Direction::Trace)
                + hx.steady_loop(30.0, 70.0)
                    .unwrap()
                    .eval(70.0, Direction::Trace));
        let setup = ScanSetup {
            x_lo_um: mid - 18.0,
            x_hi_um: mid + 18.0,
            speed_um_s: 7.2,
            periods: 2,
            fs_hz: 5000.0,
            v_yz: 50.0,
            controllers: [c[0], c[1]],
            seed: 4,
        };
        let hff =
            HysteresisFeedForward::for_position_range(model, setup.x_lo_um, setup.x_hi_um).unwrap();
        let slope = (setup.x_hi_um - setup.x_lo_um)
            / (hff.branch(Direction::Trace).v_max - hff.branch(Direction::Trace).v_m);
        let v_mid = 0.5 * (hff.branch(Direction::Trace).v_max + hff.branch(Direction::Trace).v_m);
        let pff = PositionFeedForward::new(1.0 / slope, v_mid - mid / slope);
        let fb = scan_experiment(&stage, &setup, &FeedForward::None).unwrap();
        let pos = scan_experiment(&stage, &setup, &FeedForward::Position(pff)).unwrap();
        let hys =
            scan_experiment(&stage, &setup, &FeedForward::Hysteresis(Box::new(hff), pff)).unwrap();
        eprintln!("feedback only: {fb:?}\nposition FF:   {pos:?}\nhysteresis FF: {hys:?}");
        eprintln!(
            "hysteresis FF vs feedback only: {:.0} %, vs position FF: {:.0} %",
            100.0 * (1.0 - hys.rms_x_nm / fb.rms_x_nm),
            100.0 * (1.0 - hys.rms_x_nm / pos.rms_x_nm)
        );
        assert!(hys.rms_x_nm < pos.rms_x_nm && pos.rms_x_nm < fb.rms_x_nm);
        assert!(
            hys.max_x_imaging_nm < pos.max_x_imaging_nm
                && pos.max_x_imaging_nm < fb.max_x_imaging_nm
        );
        assert_eq!(fb.clipped + pos.clipped + hys.clipped, 0);
        // The x scan couples into y: without coupling the y error is smaller.
        let mut decoupled = AfmStage::default();
        decoupled.static_coupling = [[0.0; 3]; 3];
        decoupled.dynamic_coupling = [[0.0; 3]; 3];
        let fb0 = scan_experiment(&decoupled, &setup, &FeedForward::None).unwrap();
        eprintln!(
            "y error: coupled {:.3} nm, decoupled {:.3} nm",
            fb.rms_y_nm, fb0.rms_y_nm
        );
        assert!(
            fb.rms_y_nm > 1.05 * fb0.rms_y_nm,
            "{} vs {}",
            fb.rms_y_nm,
            fb0.rms_y_nm
        );
    }
}
