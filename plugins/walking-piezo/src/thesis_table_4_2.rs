//! Table 4.2 (Sec. 4.4) on simulation: strokes and rms model errors of the
//! identified Ch. 4 model per waveform at 10 Hz, waveforms 1–5 used for the
//! identification (4.20), 6–9 for validation.
//!
//! The "measurement" is the simulated stage with hidden, unequal per-stack
//! coefficients c_x1..4, c_y1..4, a seeded slowly varying μ and 1.6 nm rms white
//! noise on the housing signal y (the thesis's capacitive-sensor noise bound); the
//! records are averaged over periods and mean-removed, as in the thesis. The model
//! is identified from waveforms 1–5 (y-parameters first, then x; particle swarm +
//! Nelder–Mead of [`crate::identify`]) and compared with every record.
//!
//! Waveforms: 1 sinusoidal, 2 asymmetric (Fourier fit (2.9), q = 1/3), 3 rhombic
//! (90°), 9 rhombic with 45° phase shift are the thesis's; its "manually obtained"
//! alternatives 4, 5 (identification) and 6, 7, 8 (validation) are not given in the
//! text — ours are the Fourier-fitted asymmetric waveform with other overlaps q.

use crate::driver::{DriverParams, WaveformDriver, WaveformShape};
use crate::identify::{OptimiserSettings, nelder_mead, particle_swarm};
use crate::stage::{StageParams, WalkingPiezoStage};
use nanomotion_core::ParamError;
use nanomotion_core::rng::Rng;
use serde::{Deserialize, Serialize};
use std::f64::consts::{FRAC_PI_4, TAU};

/// Drive frequency of Table 4.2 (Hz).
pub const F_DRIVE_HZ: f64 = 10.0;
/// rms noise of the housing (capacitive) sensor (m), Sec. 4.4.2.
pub const Y_SENSOR_NOISE_M: f64 = 1.6e-9;

/// One waveform of the table.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Waveform {
    /// Number w = 1 … 9.
    pub w: usize,
    /// Description.
    pub name: String,
    /// Shape of the driver.
    pub shape: WaveformShape,
    /// Phase φ (rad) between the voltages of a pair beyond the nominal π/2.
    pub phase_rad: f64,
    /// Used for identification (else validation).
    pub identification: bool,
}

/// The nine waveforms (see the module doc for our stand-ins of 4–8).
pub fn waveforms() -> Vec<Waveform> {
    let asym = |q: f64| WaveformShape::AsymmetricFourier { overlap_q: q };
    let mk = |w, name: &str, shape, phase_rad, identification| Waveform {
        w,
        name: name.into(),
        shape,
        phase_rad,
        identification,
    };
    vec![
        mk(1, "sinusoidal", WaveformShape::Sinusoidal, 0.0, true),
        mk(2, "asymmetric q = 1/3", asym(1.0 / 3.0), 0.0, true),
        mk(3, "rhombic 90°", WaveformShape::Rhombic, 0.0, true),
        mk(4, "asymmetric q = 0.25", asym(0.25), 0.0, true),
        mk(5, "asymmetric q = 0.45", asym(0.45), 0.0, true),
        mk(6, "asymmetric q = 0.30", asym(0.30), 0.0, false),
        mk(7, "asymmetric q = 0.40", asym(0.40), 0.0, false),
        mk(8, "asymmetric q = 0.20", asym(0.20), 0.0, false),
        mk(9, "rhombic 45°", WaveformShape::Rhombic, -FRAC_PI_4, false),
    ]
}

/// Period-averaged, mean-removed record of one waveform.
#[derive(Debug, Clone, PartialEq)]
pub struct Record {
    /// x̄: stage position relative to the start of each period (m).
    pub x: Vec<f64>,
    /// ȳ: housing position (m).
    pub y: Vec<f64>,
}

/// How records are made: the same protocol as the Ch. 4 identification.
pub use crate::identify::Protocol;

/// Simulate `wave` at 10 Hz on a stage with parameters `p` (μ-variation seed
/// `seed`); `noise_seed` adds the y-sensor noise (None: noise-free model output).
pub fn simulate_record(
    p: &StageParams,
    wave: &Waveform,
    proto: &Protocol,
    seed: u64,
    noise_seed: Option<u64>,
) -> Result<Record, ParamError> {
    let driver = WaveformDriver::new(
        DriverParams {
            shape: wave.shape.clone(),
            phase_rad: wave.phase_rad,
            ..DriverParams::default()
        },
        proto.dt,
    )?;
    let mut s = WalkingPiezoStage::new(p.clone(), proto.dt, seed)?;
    let per = (1.0 / (F_DRIVE_HZ * proto.dt)).round().max(1.0) as usize;
    let volts = |k: usize| {
        let alpha = TAU * F_DRIVE_HZ * k as f64 * proto.dt;
        driver.voltages(alpha, 46.0, wave.phase_rad)
    };
    let mut noise = noise_seed.map(Rng::new);
    let (mut x, mut y) = (vec![0.0; per], vec![0.0; per]);
    let mut k = 0usize;
    for _ in 0..proto.settle_periods * per {
        let _ = s.step(&volts(k), 0.0);
        k += 1;
    }
    for _ in 0..proto.periods {
        let x0 = s.signals().x_s;
        for j in 0..per {
            let sig = s.signals();
            x[j] += sig.x_s - x0;
            y[j] += sig.y_h
                + noise
                    .as_mut()
                    .map_or(0.0, |r| Y_SENSOR_NOISE_M * r.normal());
            let _ = s.step(&volts(k), 0.0);
            k += 1;
        }
    }
    let n = proto.periods.max(1) as f64;
    for v in [&mut x, &mut y] {
        v.iter_mut().for_each(|e| *e /= n);
        let mean = v.iter().sum::<f64>() / v.len() as f64;
        v.iter_mut().for_each(|e| *e -= mean);
    }
    Ok(Record { x, y })
}

fn rms_diff(a: &[f64], b: &[f64]) -> f64 {
    let n = a.len().min(b.len()).max(1);
    (a.iter().zip(b).map(|(u, v)| (u - v).powi(2)).sum::<f64>() / n as f64).sqrt()
}

/// One row of Table 4.2.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Row42 {
    /// The waveform.
    pub waveform: Waveform,
    /// Stroke (max − min) of the measured x̄ and ȳ (m).
    pub stroke: (f64, f64),
    /// rms(ē_x), rms(ē_y) of the identified model (m).
    pub rms_error: (f64, f64),
    /// The same for the nominal model (Ch. 5's equal coefficients, nominal μ) (m).
    pub rms_error_nominal: (f64, f64),
}

/// Table 4.2 on simulation.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Table42 {
    /// One row per waveform.
    pub rows: Vec<Row42>,
    /// Hidden c_x1..4, c_y1..4 (nm/V) and μ of the "measured" stage.
    pub truth: ([f64; 4], [f64; 4], f64),
    /// Identified c_x1..4, c_y1..4 (nm/V) and μ.
    pub identified: ([f64; 4], [f64; 4], f64),
    /// Accuracy 1 − mean rms(e)/mean rms(signal) over all waveforms, x and y.
    pub accuracy: (f64, f64),
    /// Objective evaluations of the identification.
    pub evaluations: usize,
    /// Periods averaged per record.
    pub periods: usize,
}

/// The hidden "true" stage: unequal legs (second pair weaker, asymmetric within a
/// pair, as Table 4.1 reports), μ = 0.25 with the default seeded variation.
pub fn truth() -> StageParams {
    StageParams {
        c_x_m_v: [66.0e-9, 63.0e-9, 60.0e-9, 58.0e-9],
        c_y_m_v: [31.0e-9, 29.0e-9, 28.5e-9, 27.5e-9],
        mu: 0.25,
        ..StageParams::default()
    }
}

/// Run Table 4.2: `quick` averages 3 periods and uses a smaller optimiser budget,
/// else 20 periods (the thesis's) and the default budget.
pub fn table_4_2(quick: bool) -> Result<Table42, ParamError> {
    let proto = Protocol {
        settle_periods: 1,
        periods: if quick { 3 } else { 20 },
        dt: 50e-6,
    };
    let model_proto = Protocol {
        settle_periods: 1,
        periods: 1,
        dt: proto.dt,
    };
    let settings = if quick {
        OptimiserSettings {
            particles: 8,
            swarm_iterations: 5,
            local_evaluations: 40,
            seed: 1,
        }
    } else {
        OptimiserSettings::default()
    };
    let truth = truth();
    let waves = waveforms();
    let measured: Vec<Record> = waves
        .iter()
        .map(|w| simulate_record(&truth, w, &proto, 11, Some(100 + w.w as u64)))
        .collect::<Result<_, _>>()?;
    let base = StageParams::default().without_mu_variation();
    let ident: Vec<usize> = (0..waves.len())
        .filter(|&i| waves[i].identification)
        .collect();
    // (4.20): rms + start-point term, summed over the identification waveforms.
    let cost = |p: &StageParams, y_axis: bool| -> f64 {
        let mut f = 0.0;
        for &i in &ident {
            match simulate_record(p, &waves[i], &model_proto, 0, None) {
                Ok(m) => {
                    let (a, b) = if y_axis {
                        (&measured[i].y, &m.y)
                    } else {
                        (&measured[i].x, &m.x)
                    };
                    f += rms_diff(a, b) + (a[0] - b[0]).abs();
                }
                Err(_) => return f64::INFINITY,
            }
        }
        f
    };
    let mut evaluations = 0;
    let mut stage = base.clone();
    // y first: c_y1..4 in [20, 40] nm/V.
    {
        let to = |z: &[f64]| {
            let mut p = stage.clone();
            for (c, zi) in p.c_y_m_v.iter_mut().zip(z) {
                *c = 20e-9 + 20e-9 * zi;
            }
            p
        };
        let mut f = |z: &[f64]| cost(&to(z), true);
        let g = particle_swarm(4, &mut f, &settings);
        let l = nelder_mead(&g.z, 0.05, &mut f, settings.local_evaluations);
        evaluations += g.evaluations + l.evaluations;
        stage = to(if l.f <= g.f { &l.z } else { &g.z });
    }
    // then x: c_x1..4 in [45, 85] nm/V and μ in [0.05, 0.6].
    {
        let to = |z: &[f64]| {
            let mut p = stage.clone();
            for (c, zi) in p.c_x_m_v.iter_mut().zip(z) {
                *c = 45e-9 + 40e-9 * zi;
            }
            p.mu = 0.05 + 0.55 * z[4];
            p
        };
        let mut f = |z: &[f64]| cost(&to(z), false);
        let g = particle_swarm(5, &mut f, &settings);
        let l = nelder_mead(&g.z, 0.05, &mut f, settings.local_evaluations);
        evaluations += g.evaluations + l.evaluations;
        stage = to(if l.f <= g.f { &l.z } else { &g.z });
    }
    let stroke = |v: &[f64]| {
        v.iter().cloned().fold(f64::MIN, f64::max) - v.iter().cloned().fold(f64::MAX, f64::min)
    };
    let rms = |v: &[f64]| rms_diff(v, &vec![0.0; v.len()]);
    let mut rows = Vec::new();
    let (mut ex, mut ey, mut sx, mut sy) = (0.0, 0.0, 0.0, 0.0);
    for (w, r) in waves.iter().zip(&measured) {
        let m = simulate_record(&stage, w, &model_proto, 0, None)?;
        let n = simulate_record(&base, w, &model_proto, 0, None)?;
        let e = (rms_diff(&r.x, &m.x), rms_diff(&r.y, &m.y));
        ex += e.0;
        ey += e.1;
        sx += rms(&r.x);
        sy += rms(&r.y);
        rows.push(Row42 {
            waveform: w.clone(),
            stroke: (stroke(&r.x), stroke(&r.y)),
            rms_error: e,
            rms_error_nominal: (rms_diff(&r.x, &n.x), rms_diff(&r.y, &n.y)),
        });
    }
    let nm = |a: [f64; 4]| a.map(|v| v * 1e9);
    Ok(Table42 {
        rows,
        truth: (nm(truth.c_x_m_v), nm(truth.c_y_m_v), truth.mu),
        identified: (nm(stage.c_x_m_v), nm(stage.c_y_m_v), stage.mu),
        accuracy: (1.0 - ex / sx, 1.0 - ey / sy),
        evaluations,
        periods: proto.periods,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn identified_model_recovers_the_hidden_legs_and_beats_the_nominal_one() {
        let t = table_4_2(true).unwrap();
        assert_eq!(t.rows.len(), 9);
        // c_y from the housing signal: each stack within 3 % of the hidden value.
        for i in 0..4 {
            let (id, tr) = (t.identified.1[i], t.truth.1[i]);
            assert!((id - tr).abs() < 0.03 * tr, "c_y{}: {id} vs {tr}", i + 1);
        }
        // Every waveform, seen or unseen: the identified model's x error is a
        // fraction of the nominal (equal-coefficient) model's.
        for r in &t.rows {
            assert!(r.rms_error.0 < 0.3 * r.rms_error_nominal.0, "{r:?}");
            assert!(r.stroke.0 > 1e-6 && r.stroke.1 > 0.1e-6, "{r:?}");
        }
        assert!(t.accuracy.0 > 0.9 && t.accuracy.0 < 1.0);
        assert!(t.accuracy.1 > 0.5 && t.accuracy.1 < 1.0);
    }

    #[test]
    fn sensor_noise_is_seeded_and_only_on_y() {
        let w = &waveforms()[0];
        let p = Protocol {
            settle_periods: 0,
            periods: 1,
            dt: 50e-6,
        };
        let clean = simulate_record(&truth(), w, &p, 3, None).unwrap();
        let a = simulate_record(&truth(), w, &p, 3, Some(9)).unwrap();
        let b = simulate_record(&truth(), w, &p, 3, Some(9)).unwrap();
        assert_eq!(a, b);
        assert_eq!(a.x, clean.x);
        let d = rms_diff(&a.y, &clean.y);
        // 1.6 nm white noise, mean removed: rms within 20 % over 2000 samples.
        assert!((d - Y_SENSOR_NOISE_M).abs() < 0.2 * Y_SENSOR_NOISE_M, "{d}");
    }
}
