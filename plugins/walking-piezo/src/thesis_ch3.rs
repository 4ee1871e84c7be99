//! Thesis Ch. 3 reproductions on the leg model ([`crate::leg_model`]): Table 3.2
//! (layers n_m), Fig. 3.8 (FRF against n_m), Fig. 3.9 (the FRF over a drive cycle,
//! waveforms (3.24)–(3.25)), Figs. 3.11–3.14 (the static map (3.26)–(3.29) against
//! the tip trajectory — on simulation the full, dynamic Lagrange model (3.11)
//! driven by the waveforms takes the place of the measurement) and the gap between
//! the physical coefficients (3.28)–(3.29) and Ch. 5's c_x = 64.5, c_y = 29.8 nm/V.
//!
//! Every function returns plain numbers (serialisable) so that the examples, the
//! tests and `nanomotion reproduce` print and compare the same figures.

use crate::driver::Fourier4;
use crate::leg_model::{LegModel, LegModelParams};
use nalgebra::Complex;
use nanomotion_core::ParamError;
use serde::{Deserialize, Serialize};
use std::f64::consts::{FRAC_PI_2, PI, TAU};

/// The thesis's equilibrium input of Fig. 3.8 / Table 3.2: u1 = 2.2 V, u2 = 44.2 V.
pub const TABLE_3_2_EQUILIBRIUM_V: (f64, f64) = (2.2, 44.2);
/// The layer counts of Table 3.2.
pub const TABLE_3_2_LAYERS: [usize; 5] = [2, 4, 6, 8, 10];
/// Ch. 5's bending coefficient c_x (5.29) (m/V), from the motor's data (thesis ref. 155).
pub const CH5_C_X_M_V: f64 = 64.5e-9;
/// Ch. 5's extension coefficient c_y (5.29) (m/V).
pub const CH5_C_Y_M_V: f64 = 29.8e-9;
/// Waveform amplitude of (3.24)–(3.25): A = Ā = 46 V.
pub const AMPLITUDE_V: f64 = 46.0;

fn leg(n_m: usize) -> Result<LegModel, ParamError> {
    LegModel::new(LegModelParams {
        n_m,
        ..Default::default()
    })
}

// ---------------------------------------------------------------------------
// Table 3.2 and Fig. 3.8
// ---------------------------------------------------------------------------

/// One row of Table 3.2: H_x,u1 of the n_m-layer model about u = (2.2, 44.2) V.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct LayerRow {
    /// Number of layers n_m.
    pub n_m: usize,
    /// Steady-state gain |H_x,u1(0)| in dB re 1 nm/V.
    pub gain_x_u1_db: f64,
    /// The same in nm/V.
    pub gain_x_u1_nm_v: f64,
    /// |H_y,u1(0)| in nm/V.
    pub gain_y_u1_nm_v: f64,
    /// First resonance of H_x,u1 (kHz).
    pub f_res_khz: f64,
}

/// Table 3.2 for n_m ∈ {2, 4, 6, 8, 10}.
pub fn table_3_2() -> Result<Vec<LayerRow>, ParamError> {
    let (u1, u2) = TABLE_3_2_EQUILIBRIUM_V;
    TABLE_3_2_LAYERS
        .iter()
        .map(|&n_m| {
            let l = leg(n_m)?;
            let g = l.static_gain(u1, u2);
            Ok(LayerRow {
                n_m,
                gain_x_u1_db: 20.0 * (g[(0, 0)] * 1e9).abs().log10(),
                gain_x_u1_nm_v: g[(0, 0)] * 1e9,
                gain_y_u1_nm_v: g[(1, 0)] * 1e9,
                f_res_khz: l.first_resonance_hz(u1, u2) / 1e3,
            })
        })
        .collect()
}

/// Magnitudes (dB re 1 nm/V) of the four channels of H_ru(jω) (3.15) on a
/// frequency grid.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct FrfCurves {
    /// What the curve is (e.g. "n_m = 6" or "α = 0.17 rad").
    pub label: String,
    /// |H_x,u1|, |H_x,u2|, |H_y,u1|, |H_y,u2| (dB), one value per frequency.
    pub db: [Vec<f64>; 4],
}

/// Logarithmic frequency grid from `f0` to `f1` Hz with `n` points.
pub fn log_grid(f0: f64, f1: f64, n: usize) -> Vec<f64> {
    (0..n)
        .map(|k| f0 * (f1 / f0).powf(k as f64 / (n.max(2) - 1) as f64))
        .collect()
}

fn frf_db(l: &LegModel, u1: f64, u2: f64, freqs_hz: &[f64], label: String) -> FrfCurves {
    let ss = l.linearize(u1, u2);
    let mut db: [Vec<f64>; 4] = Default::default();
    for &f in freqs_hz {
        let h = ss.evalfr(Complex::new(0.0, TAU * f));
        for (ch, (r, c)) in [(0, 0), (0, 1), (1, 0), (1, 1)].into_iter().enumerate() {
            db[ch].push(20.0 * (h[(r, c)].norm() * 1e9).log10());
        }
    }
    FrfCurves { label, db }
}

/// Fig. 3.8: H_ru(jω) of the n_m-layer models about u = (2.2, 44.2) V.
pub fn fig_3_8(freqs_hz: &[f64]) -> Result<Vec<FrfCurves>, ParamError> {
    let (u1, u2) = TABLE_3_2_EQUILIBRIUM_V;
    TABLE_3_2_LAYERS
        .iter()
        .map(|&n_m| Ok(frf_db(&leg(n_m)?, u1, u2, freqs_hz, format!("n_m = {n_m}"))))
        .collect()
}

// ---------------------------------------------------------------------------
// Waveforms (3.24)–(3.25)
// ---------------------------------------------------------------------------

/// The two waveforms of Sec. 3.5.1.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Ch3Waveform {
    /// (3.24): u_1,2 = A/2 sin(α + ψ_1,2) + A/2, ψ1 = 0, ψ2 = π/2.
    Sinusoidal,
    /// (3.25): the 4th-order Fourier series (2.9) of the asymmetric waveform
    /// (overlap q = 1/3), coefficients from the exact construction
    /// ([`Fourier4::asymmetric`]), same phases.
    Asymmetric,
}

impl Ch3Waveform {
    /// Name for tables.
    pub fn as_str(self) -> &'static str {
        match self {
            Ch3Waveform::Sinusoidal => "sinusoidal (3.24)",
            Ch3Waveform::Asymmetric => "asymmetric (3.25)",
        }
    }
}

/// Voltages (u1, u2) of a waveform as functions of α (and their α-derivatives).
#[derive(Debug, Clone, Copy)]
pub struct Ch3Drive {
    wave: Ch3Waveform,
    fourier: Fourier4,
}

impl Ch3Drive {
    /// The drive of `wave` with A = Ā = 46 V.
    pub fn new(wave: Ch3Waveform) -> Self {
        Self {
            wave,
            fourier: Fourier4::asymmetric(1.0 / 3.0),
        }
    }

    fn channel(&self, th: f64) -> (f64, f64) {
        let h = 0.5 * AMPLITUDE_V;
        match self.wave {
            Ch3Waveform::Sinusoidal => (h * th.sin() + h, h * th.cos()),
            Ch3Waveform::Asymmetric => {
                let f = &self.fourier;
                let mut d = 0.0;
                for k in 1..5 {
                    let kf = k as f64;
                    let (s, c) = (kf * th).sin_cos();
                    d += kf * (f.b[k] * c - f.a[k] * s);
                }
                (f.eval(th), d)
            }
        }
    }

    /// (u1, u2) (V) at angle α (rad).
    pub fn voltages(&self, alpha: f64) -> (f64, f64) {
        (self.channel(alpha).0, self.channel(alpha + FRAC_PI_2).0)
    }

    /// (du1/dα, du2/dα) (V/rad).
    pub fn slopes(&self, alpha: f64) -> (f64, f64) {
        (self.channel(alpha).1, self.channel(alpha + FRAC_PI_2).1)
    }
}

// ---------------------------------------------------------------------------
// Fig. 3.9: the linearised dynamics over a drive cycle
// ---------------------------------------------------------------------------

/// The static gains and the first resonance of (3.15) (n_m = 6) at each α of a
/// cycle, q_e from the waveform's voltages (3.23).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct CycleVariation {
    /// The waveform.
    pub waveform: Ch3Waveform,
    /// α_k = kπ/36 (rad), k = 0 … 72 (the thesis's grid).
    pub alpha_rad: Vec<f64>,
    /// |H_x,u1(0)|, |H_x,u2(0)|, |H_y,u1(0)|, |H_y,u2(0)| (nm/V) per α.
    pub gain_nm_v: [Vec<f64>; 4],
    /// First resonance of H_x,u1 (kHz) per α.
    pub f_res_khz: Vec<f64>,
    /// (max − min)/mean of each gain over the cycle.
    pub gain_spread: [f64; 4],
    /// Lowest and highest first resonance over the cycle (kHz).
    pub f_res_range_khz: (f64, f64),
}

/// Fig. 3.9: gains and first resonance of the n_m = 6 model over α ∈ [0, 2π] in
/// steps of π/36.
pub fn fig_3_9(wave: Ch3Waveform) -> Result<CycleVariation, ParamError> {
    let l = leg(6)?;
    let drive = Ch3Drive::new(wave);
    let alpha_rad: Vec<f64> = (0..=72).map(|k| k as f64 * PI / 36.0).collect();
    let mut gain_nm_v: [Vec<f64>; 4] = Default::default();
    let mut f_res_khz = Vec::new();
    for &a in &alpha_rad {
        let (u1, u2) = drive.voltages(a);
        let g = l.static_gain(u1, u2);
        for (ch, (r, c)) in [(0, 0), (0, 1), (1, 0), (1, 1)].into_iter().enumerate() {
            gain_nm_v[ch].push(g[(r, c)].abs() * 1e9);
        }
        f_res_khz.push(l.first_resonance_hz(u1, u2) / 1e3);
    }
    let spread = |v: &[f64]| {
        let (lo, hi) = min_max(v);
        (hi - lo) / (v.iter().sum::<f64>() / v.len() as f64)
    };
    let gain_spread = [0, 1, 2, 3].map(|ch| spread(&gain_nm_v[ch]));
    let f_res_range_khz = min_max(&f_res_khz);
    Ok(CycleVariation {
        waveform: wave,
        alpha_rad,
        gain_nm_v,
        f_res_khz,
        gain_spread,
        f_res_range_khz,
    })
}

/// FRF curves of Fig. 3.9 at `n_alpha` equally spaced α over a cycle.
pub fn fig_3_9_frf(
    wave: Ch3Waveform,
    n_alpha: usize,
    freqs_hz: &[f64],
) -> Result<Vec<FrfCurves>, ParamError> {
    let l = leg(6)?;
    let drive = Ch3Drive::new(wave);
    Ok((0..n_alpha)
        .map(|k| {
            let a = TAU * k as f64 / n_alpha as f64;
            let (u1, u2) = drive.voltages(a);
            frf_db(&l, u1, u2, freqs_hz, format!("α = {a:.2} rad"))
        })
        .collect())
}

fn min_max(v: &[f64]) -> (f64, f64) {
    v.iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), &x| {
            (a.min(x), b.max(x))
        })
}

// ---------------------------------------------------------------------------
// Figs. 3.11–3.14: the static map against the full model
// ---------------------------------------------------------------------------

/// A tip trajectory over one drive cycle: the full Lagrange model (3.11) (the
/// "measurement") against the static linearised map (3.26)–(3.29), both shifted so
/// that their minima coincide, as in the thesis.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct TipComparison {
    /// The waveform.
    pub waveform: Ch3Waveform,
    /// Drive frequency of the full model's run (Hz).
    pub f_drive_hz: f64,
    /// Time over one cycle (s).
    pub t_s: Vec<f64>,
    /// Full model, x and y (m), minimum at 0.
    pub x_model: Vec<f64>,
    /// See `x_model`.
    pub y_model: Vec<f64>,
    /// Static map x̃ = c_x(u1 − u2), ỹ = c_y(u1 + u2) (m), minimum at 0.
    pub x_static: Vec<f64>,
    /// See `x_static`.
    pub y_static: Vec<f64>,
    /// Stroke (max − min) of the full model's x and y (m).
    pub stroke: (f64, f64),
    /// rms(e_x), rms(e_y), e = full − static (m).
    pub rms_error: (f64, f64),
    /// "Accuracy" 1 − rms(e)/rms(signal − its mean), x and y (our reading of the
    /// thesis's 77 %/90 %, 87 %/85 %).
    pub accuracy: (f64, f64),
}

fn rms(v: &[f64]) -> f64 {
    (v.iter().map(|e| e * e).sum::<f64>() / v.len().max(1) as f64).sqrt()
}

fn shift_min(v: &mut [f64]) {
    let lo = min_max(v).0;
    v.iter_mut().for_each(|e| *e -= lo);
}

fn compare(
    waveform: Ch3Waveform,
    f_drive_hz: f64,
    t_s: Vec<f64>,
    mut xm: Vec<f64>,
    mut ym: Vec<f64>,
    mut xs: Vec<f64>,
    mut ys: Vec<f64>,
) -> TipComparison {
    for v in [&mut xm, &mut ym, &mut xs, &mut ys] {
        shift_min(v);
    }
    let err = |a: &[f64], b: &[f64]| -> Vec<f64> { a.iter().zip(b).map(|(p, q)| p - q).collect() };
    let centred_rms = |v: &[f64]| {
        let m = v.iter().sum::<f64>() / v.len() as f64;
        rms(&v.iter().map(|e| e - m).collect::<Vec<_>>())
    };
    let (ex, ey) = (rms(&err(&xm, &xs)), rms(&err(&ym, &ys)));
    let stroke = |v: &[f64]| {
        let (lo, hi) = min_max(v);
        hi - lo
    };
    TipComparison {
        waveform,
        f_drive_hz,
        stroke: (stroke(&xm), stroke(&ym)),
        rms_error: (ex, ey),
        accuracy: (1.0 - ex / centred_rms(&xm), 1.0 - ey / centred_rms(&ym)),
        t_s,
        x_model: xm,
        y_model: ym,
        x_static: xs,
        y_static: ys,
    }
}

/// The quasi-static comparison: the full model's tip at its static equilibrium
/// g(q_e(u)) (exact nonlinear output (3.12), arcsin and rotations kept) against
/// the linear map, `samples` points over one cycle at `f_drive_hz`. Valid where
/// the drive is far below the first resonance; [`dynamic_tip`] checks that.
pub fn quasi_static_tip(
    wave: Ch3Waveform,
    f_drive_hz: f64,
    samples: usize,
) -> Result<TipComparison, ParamError> {
    let l = leg(6)?;
    let drive = Ch3Drive::new(wave);
    let (cx, cy) = l.static_coefficients();
    let n = samples.max(2);
    let (mut t, mut xm, mut ym, mut xs, mut ys) = (vec![], vec![], vec![], vec![], vec![]);
    for k in 0..n {
        let a = TAU * k as f64 / n as f64;
        let (u1, u2) = drive.voltages(a);
        let tip = l.tip(&l.equilibrium(u1, u2));
        t.push(a / (TAU * f_drive_hz));
        xm.push(tip[0]);
        ym.push(tip[1]);
        xs.push(cx * (u1 - u2));
        ys.push(cy * (u1 + u2));
    }
    Ok(compare(wave, f_drive_hz, t, xm, ym, xs, ys))
}

/// The full dynamic Lagrange model (3.11), n_m = 6, driven by the waveform at
/// `f_drive_hz` (α = 2πf t): started on the quasi-static solution (q_e(u(0)),
/// q̇_e), one cycle run to settle, the next compared (`samples` points) with the
/// static map, RK4 at `dt` s. The second element is the rms difference between
/// the dynamic and the quasi-static tip, relative to the quasi-static rms signal
/// (x, y): the legs' own dynamics at this drive frequency.
pub fn dynamic_tip(
    wave: Ch3Waveform,
    f_drive_hz: f64,
    dt: f64,
    samples: usize,
) -> Result<(TipComparison, (f64, f64)), ParamError> {
    if !(f_drive_hz.is_finite() && f_drive_hz > 0.0) {
        return Err(ParamError::new(
            "f_drive_hz",
            format!("is {f_drive_hz}"),
            "give a positive drive frequency",
        ));
    }
    if !(dt.is_finite() && dt > 0.0 && dt <= 2e-7) {
        return Err(ParamError::new(
            "dt",
            format!("is {dt} s; RK4 must resolve the ≈ 1 MHz top mode"),
            "give 0 < dt ≤ 2e-7 s",
        ));
    }
    let l = leg(6)?;
    let drive = Ch3Drive::new(wave);
    let w = TAU * f_drive_hz;
    let u = |t: f64| drive.voltages(w * t);
    let (u1, u2) = u(0.0);
    let (s1, s2) = drive.slopes(0.0);
    let q0 = l.equilibrium(u1, u2);
    let qd0 = l.equilibrium_rate(s1 * w, s2 * w);
    let period = 1.0 / f_drive_hz;
    let per_cycle = (period / dt).round() as usize;
    let dt = period / per_cycle as f64;
    let every = (per_cycle / samples.max(2)).max(1);
    let (mut t, mut xm, mut ym) = (vec![], vec![], vec![]);
    let mut k = 0usize;
    l.simulate_driven(&q0, &qd0, 0.0, dt, 2 * per_cycle, u, |tk, q| {
        if k >= per_cycle && k < 2 * per_cycle && (k - per_cycle).is_multiple_of(every) {
            let tip = l.tip(q);
            t.push(tk - period);
            xm.push(tip[0]);
            ym.push(tip[1]);
        }
        k += 1;
    });
    let (cx, cy) = l.static_coefficients();
    let (mut xs, mut ys, mut xq, mut yq) = (vec![], vec![], vec![], vec![]);
    for &tk in &t {
        let (u1, u2) = u(tk);
        xs.push(cx * (u1 - u2));
        ys.push(cy * (u1 + u2));
        let tip = l.tip(&l.equilibrium(u1, u2));
        xq.push(tip[0]);
        yq.push(tip[1]);
    }
    let rel = |a: &[f64], b: &[f64]| {
        let mb = b.iter().sum::<f64>() / b.len() as f64;
        let ma = a.iter().sum::<f64>() / a.len() as f64;
        let d: Vec<f64> = a.iter().zip(b).map(|(p, q)| (p - ma) - (q - mb)).collect();
        rms(&d) / rms(&b.iter().map(|e| e - mb).collect::<Vec<_>>())
    };
    let dyn_rel = (rel(&xm, &xq), rel(&ym, &yq));
    Ok((compare(wave, f_drive_hz, t, xm, ym, xs, ys), dyn_rel))
}

/// The legs' dynamic deviation predicted by the linearised model (3.15) about the
/// cycle's mean voltages (an independent check of [`dynamic_tip`]): the waveform's
/// harmonics U_k (k = 1 … 8, by DFT of 64 samples per cycle) through
/// H(jkω) − H(0), relative to their static image H(0)U_k, rms over the harmonics,
/// (x, y).
pub fn predicted_dynamic_deviation(wave: Ch3Waveform, f_hz: f64) -> Result<(f64, f64), ParamError> {
    let l = leg(6)?;
    let drive = Ch3Drive::new(wave);
    const N: usize = 64;
    let u: Vec<(f64, f64)> = (0..N)
        .map(|j| drive.voltages(TAU * j as f64 / N as f64))
        .collect();
    let mean = (
        u.iter().map(|v| v.0).sum::<f64>() / N as f64,
        u.iter().map(|v| v.1).sum::<f64>() / N as f64,
    );
    let ss = l.linearize(mean.0, mean.1);
    let h0 = ss.evalfr(Complex::new(0.0, 0.0));
    let (mut dev, mut sig) = ([0.0f64; 2], [0.0f64; 2]);
    for k in 1..=8 {
        let mut uk = [Complex::new(0.0, 0.0); 2];
        for (j, v) in u.iter().enumerate() {
            let e = Complex::from_polar(1.0 / N as f64, -TAU * (k * j) as f64 / N as f64);
            uk[0] += e * v.0;
            uk[1] += e * v.1;
        }
        let hk = ss.evalfr(Complex::new(0.0, TAU * f_hz * k as f64));
        for r in 0..2 {
            let d = (hk[(r, 0)] - h0[(r, 0)]) * uk[0] + (hk[(r, 1)] - h0[(r, 1)]) * uk[1];
            let s0 = h0[(r, 0)] * uk[0] + h0[(r, 1)] * uk[1];
            dev[r] += d.norm_sqr();
            sig[r] += s0.norm_sqr();
        }
    }
    Ok(((dev[0] / sig[0]).sqrt(), (dev[1] / sig[1]).sqrt()))
}

// ---------------------------------------------------------------------------
// (3.28)–(3.29) against Ch. 5
// ---------------------------------------------------------------------------

/// The physical coefficients and what separates them from Ch. 5's.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct CoefficientGap {
    /// c_x, c_y of (3.28)–(3.29), n_m = 6 (nm/V).
    pub c_x_nm_v: f64,
    /// See `c_x_nm_v`.
    pub c_y_nm_v: f64,
    /// Ch. 5's c_x, c_y (nm/V).
    pub ch5_nm_v: (f64, f64),
    /// Ours / Ch. 5's, x and y.
    pub ratio: (f64, f64),
    /// c_x with one model layer per piezo element (n_m = n_t = 96) (nm/V): the
    /// lumping factor (n_m − 1)/n_m of the tip at the top layer's centre of mass.
    pub c_x_n_t_layers_nm_v: f64,
    /// K_a/(K_a + K_p): the preload springs' share (c_y = n_t d33/2 · K_a/k).
    pub preload_factor: f64,
    /// The d33 (pm/V) that would give Ch. 5's c_y with our K_a/k (material).
    pub d33_for_ch5_c_y_pm_v: f64,
    /// Our d33 (pm/V).
    pub d33_pm_v: f64,
    /// c_x/c_y: ours (n_m = 6), ours at n_m = n_t, Ch. 5's — the geometry
    /// L(n_m − 1)/(2c n_m), independent of the material.
    pub ratio_x_over_y: (f64, f64, f64),
}

/// (3.28)–(3.29) for the default leg against Ch. 5.
pub fn coefficient_gap() -> Result<CoefficientGap, ParamError> {
    let l = leg(6)?;
    let (cx, cy) = l.static_coefficients();
    let p = l.params().clone();
    let full = LegModel::new(LegModelParams {
        n_m: p.n_t,
        ..p.clone()
    })?;
    let (cx_full, _) = full.static_coefficients();
    let preload_factor = l.k_a / l.k;
    let d33_needed = 2.0 * CH5_C_Y_M_V / (p.n_t as f64 * preload_factor);
    Ok(CoefficientGap {
        c_x_nm_v: cx * 1e9,
        c_y_nm_v: cy * 1e9,
        ch5_nm_v: (CH5_C_X_M_V * 1e9, CH5_C_Y_M_V * 1e9),
        ratio: (cx / CH5_C_X_M_V, cy / CH5_C_Y_M_V),
        c_x_n_t_layers_nm_v: cx_full * 1e9,
        preload_factor,
        d33_for_ch5_c_y_pm_v: d33_needed * 1e12,
        d33_pm_v: p.d33 * 1e12,
        ratio_x_over_y: (cx / cy, cx_full / cy, CH5_C_X_M_V / CH5_C_Y_M_V),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn asymmetric_slopes_are_the_derivative_of_the_voltages() {
        for wave in [Ch3Waveform::Sinusoidal, Ch3Waveform::Asymmetric] {
            let d = Ch3Drive::new(wave);
            for k in 0..12 {
                let a = 0.5 * k as f64;
                let h = 1e-6;
                let (p1, p2) = d.voltages(a + h);
                let (m1, m2) = d.voltages(a - h);
                let (s1, s2) = d.slopes(a);
                assert!(((p1 - m1) / (2.0 * h) - s1).abs() < 1e-5 * AMPLITUDE_V);
                assert!(((p2 - m2) / (2.0 * h) - s2).abs() < 1e-5 * AMPLITUDE_V);
            }
        }
        // (3.24) spans [0, 46] V.
        let (lo, hi) = (0..360)
            .map(|k| {
                Ch3Drive::new(Ch3Waveform::Sinusoidal)
                    .voltages(k as f64 * PI / 180.0)
                    .0
            })
            .fold((f64::MAX, f64::MIN), |(a, b), x| (a.min(x), b.max(x)));
        assert!(lo.abs() < 1e-9 && (hi - 46.0).abs() < 1e-9);
    }

    #[test]
    fn quasi_static_map_describes_the_model_to_round_off_of_the_rotations() {
        for wave in [Ch3Waveform::Sinusoidal, Ch3Waveform::Asymmetric] {
            let c = quasi_static_tip(wave, 1.0, 360).unwrap();
            // The only nonlinearity left at rest is the output map g(q): layer
            // rotations of β ≲ 1e-3 rad, so the static map holds to ≲ 1e-3.
            assert!(c.accuracy.0 > 0.999 && c.accuracy.0 < 1.0, "{c:?}");
            assert!(c.accuracy.1 > 0.999 && c.accuracy.1 < 1.0);
            // Strokes of the order of c·ΔU: x ≈ c_x·max|u1 − u2| range.
            let (cx, _) = leg(6).unwrap().static_coefficients();
            assert!(c.stroke.0 > cx * 40.0 && c.stroke.0 < cx * 2.0 * 46.0);
        }
    }

    #[test]
    fn driven_lagrange_model_follows_the_linearised_prediction() {
        // Two independent computations of the legs' dynamic deviation from the
        // static map: RK4 on the nonlinear (3.11) and the harmonics through the
        // linearised (3.15).
        for wave in [Ch3Waveform::Sinusoidal, Ch3Waveform::Asymmetric] {
            let (c, dev) = dynamic_tip(wave, 5e3, 1e-7, 200).unwrap();
            let p = predicted_dynamic_deviation(wave, 5e3).unwrap();
            assert!(
                (dev.0 - p.0).abs() < 0.15 * p.0,
                "{wave:?}: {dev:?} vs {p:?}"
            );
            assert!(
                (dev.1 - p.1).abs() < 0.15 * p.1,
                "{wave:?}: {dev:?} vs {p:?}"
            );
            assert!(c.accuracy.0 > 0.99);
            // Quadratic in f far below the resonance: 10 Hz is 2.5e5× smaller.
            let p10 = predicted_dynamic_deviation(wave, 10.0).unwrap();
            assert!(p10.0 < 1e-6, "{p10:?}");
        }
        assert!(dynamic_tip(Ch3Waveform::Sinusoidal, 5e3, 1e-6, 10).is_err());
    }

    #[test]
    fn fig_3_9_x_gains_of_both_stacks_vary_alike() {
        let v = fig_3_9(Ch3Waveform::Sinusoidal).unwrap();
        assert_eq!(v.alpha_rad.len(), 73);
        let [xu1, xu2, yu1, yu2] = v.gain_spread;
        assert!(xu1 > 0.0 && (xu1 - xu2).abs() < 0.05 * xu1);
        assert!(yu1 > 0.0 && (yu1 - yu2).abs() < 0.05 * yu1);
        assert!(v.f_res_range_khz.1 / v.f_res_range_khz.0 < 1.01);
    }

    #[test]
    fn coefficient_gap_is_lumping_and_material() {
        let g = coefficient_gap().unwrap();
        // Lumping: c_x(n_m)/c_x(n_t) = ((n_m − 1)/n_m)/((n_t − 1)/n_t).
        assert!((g.c_x_nm_v / g.c_x_n_t_layers_nm_v - (5.0 / 6.0) / (95.0 / 96.0)).abs() < 1e-9);
        // c_y = n_t d33/2 · K_a/k, so the d33 for Ch. 5's c_y scales with the ratio.
        assert!((g.d33_for_ch5_c_y_pm_v / g.d33_pm_v - 1.0 / g.ratio.1).abs() < 1e-9);
        assert!(g.preload_factor > 0.99 && g.preload_factor < 1.0);
    }
}
