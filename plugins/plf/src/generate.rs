//! Synthetic "measured" records with a hidden effect, for validating the workflow
//! on data whose truth is known (and for users to see what each effect looks
//! like before they trust the workflow on their own stage).
//!
//! The truth is simulated **independently of the effect blocks** the workflow
//! fits: a continuous second-order stage m·ẍ + c·ẋ + k·x = F integrated by RK4
//! at 20× the data rate, with each effect written out in its own physical form
//! (a Bouc–Wen operator for hysteresis, Stribeck friction, a sum of three creep
//! time constants, a second mass for the resonance, ...), so the workflow never
//! fits the exact model that made the data. The nominal graph is the exact
//! stage without the effect; measurement noise is white and Gaussian.

use nanomotion_core::data::{DataError, Dataset};
use nanomotion_core::rng::Rng;
use std::f64::consts::PI;

/// A generated record.
#[derive(Debug, Clone)]
pub struct Record {
    /// The nominal model graph (YAML): the stage without the hidden effect.
    pub nominal_yaml: String,
    /// The "measured" data: columns `u` (force) and `y` (position), `y2` for two axes.
    pub data: Dataset,
    /// The hidden effects (vocabulary names).
    pub hidden: Vec<String>,
    /// The truth in words, with its drawn parameters.
    pub truth: String,
}

/// Sample rate of the generated data (Hz).
pub const RATE_HZ: f64 = 2000.0;
const OVERSAMPLE: usize = 20;

/// The stage: natural frequency f0 (Hz), damping ζ, mass m (kg).
#[derive(Debug, Clone, Copy)]
struct Stage {
    f0: f64,
    zeta: f64,
    m: f64,
}

impl Stage {
    fn k(&self) -> f64 {
        self.m * (2.0 * PI * self.f0).powi(2)
    }
    fn c(&self) -> f64 {
        2.0 * self.zeta * self.m * 2.0 * PI * self.f0
    }
    fn yaml_block(&self, name: &str) -> String {
        format!(
            "  - {{ name: {name}, type: state_space, a: [[0.0, 1.0], [{:?}, {:?}]], b: [[0.0], [{:?}]], c: [[1.0, 0.0]], discretisation: zoh }}\n",
            -self.k() / self.m,
            -self.c() / self.m,
            1.0 / self.m
        )
    }
}

/// The drive: slow large strokes (reversals for hysteresis, friction, backlash)
/// plus a band-limited multisine up to 300 Hz (for delays and resonances).
fn drive(rng: &mut Rng, n: usize, amplitude: f64) -> Vec<f64> {
    let slow: Vec<(f64, f64, f64)> = (0..6)
        .map(|_| {
            (
                rng.uniform_in(0.15, 2.0),
                rng.uniform_in(0.0, 2.0 * PI),
                rng.uniform_in(0.5, 1.0),
            )
        })
        .collect();
    let fast: Vec<(f64, f64)> = (0..40)
        .map(|_| (rng.uniform_in(3.0, 300.0), rng.uniform_in(0.0, 2.0 * PI)))
        .collect();
    let raw: Vec<f64> = (0..n)
        .map(|k| {
            let t = k as f64 / RATE_HZ;
            let s: f64 = slow
                .iter()
                .map(|(f, p, a)| a * (2.0 * PI * f * t + p).sin())
                .sum();
            let q: f64 = fast
                .iter()
                .map(|(f, p)| (2.0 * PI * f * t + p).sin())
                .sum::<f64>()
                / (fast.len() as f64).sqrt();
            s + 0.5 * q
        })
        .collect();
    let peak = raw.iter().fold(0.0f64, |m, v| m.max(v.abs()));
    raw.iter().map(|v| amplitude * v / peak).collect()
}

/// What is hidden, with its drawn parameters (filled by [`second_order`]).
enum Truth {
    None,
    Hysteresis {
        beta: f64,
        gamma: f64,
        h: f64,
    },
    Friction {
        fc: f64,
        fs: f64,
        vs: f64,
        veps: f64,
    },
    Delay {
        fine_steps: usize,
    },
    Repetitive {
        f: f64,
        amps: [f64; 3],
        phases: [f64; 3],
    },
    PositionGain {
        g: f64,
        center: f64,
        scale: f64,
    },
    Quantization {
        q: f64,
    },
    Resonance {
        fp: f64,
        zp: f64,
        fz: f64,
        zz: f64,
    },
    Drift {
        a: f64,
        b: f64,
        c: f64,
    },
    Creep {
        gains: [f64; 3],
        taus: [f64; 3],
    },
    SlitError {
        q: f64,
        errors: Vec<f64>,
    },
    Saturation {
        lo: f64,
        hi: f64,
    },
    Backlash {
        w: f64,
    },
}

/// A single-axis record on a second-order stage with `hidden` (a vocabulary name,
/// or `"none"`), seeded. `coloured_noise` adds a low-pass coloured component to the
/// white measurement noise (for false-alarm tests).
pub fn second_order(
    hidden: &str,
    seed: u64,
    n: usize,
    coloured_noise: bool,
) -> Result<Record, DataError> {
    let mut rng = Rng::new(seed ^ 0x005e_ed0f_91a7);
    let stage = Stage {
        f0: rng.uniform_in(20.0, 60.0),
        zeta: rng.uniform_in(0.03, 0.15),
        m: rng.uniform_in(0.2, 2.0),
    };
    let x_amp = 1e-6; // 1 µm strokes
    let f_amp = stage.k() * x_amp;
    let u = drive(&mut rng, n, f_amp);
    let (ulo, uhi) = u
        .iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), &v| {
            (a.min(v), b.max(v))
        });
    let ru = uhi - ulo;
    let draw = |name: &str, rng: &mut Rng| -> Result<Truth, DataError> {
        Ok(match name {
            "none" => Truth::None,
            "hysteresis" => Truth::Hysteresis {
                beta: rng.uniform_in(2.0, 6.0) / ru,
                gamma: rng.uniform_in(-1.0, 1.0) / ru,
                h: rng.uniform_in(0.25, 0.5),
            },
            "friction" => {
                let fc = rng.uniform_in(0.04, 0.1) * f_amp;
                Truth::Friction {
                    fc,
                    fs: fc * rng.uniform_in(1.0, 1.5),
                    vs: rng.uniform_in(0.5, 2.0) * x_amp,
                    veps: 0.01 * x_amp,
                }
            }
            "time_delay" => Truth::Delay {
                fine_steps: (rng.uniform_in(1.0, 4.0) * OVERSAMPLE as f64).round() as usize,
            },
            "repetitive_disturbance" => Truth::Repetitive {
                f: rng.uniform_in(5.0, 40.0),
                amps: [
                    rng.uniform_in(0.1, 0.2) * x_amp,
                    rng.uniform_in(0.0, 0.08) * x_amp,
                    rng.uniform_in(0.0, 0.05) * x_amp,
                ],
                phases: [
                    rng.uniform_in(0.0, 2.0 * PI),
                    rng.uniform_in(0.0, 2.0 * PI),
                    rng.uniform_in(0.0, 2.0 * PI),
                ],
            },
            "position_dependent_gain" => Truth::PositionGain {
                g: rng.uniform_in(0.2, 0.4) * if rng.uniform() < 0.5 { -1.0 } else { 1.0 },
                center: 0.0,
                scale: x_amp,
            },
            "quantization" => Truth::Quantization {
                q: rng.uniform_in(0.15, 0.3) * x_amp,
            },
            "unmodeled_resonance" => {
                let fp = rng.uniform_in(70.0, 150.0);
                Truth::Resonance {
                    fp,
                    zp: rng.uniform_in(0.01, 0.04),
                    fz: fp * rng.uniform_in(0.6, 0.8),
                    zz: rng.uniform_in(0.01, 0.04),
                }
            }
            "drift" => Truth::Drift {
                a: rng.uniform_in(-0.1, 0.1) * x_amp,
                b: rng.uniform_in(0.02, 0.05)
                    * x_amp
                    * if rng.uniform() < 0.5 { -1.0 } else { 1.0 },
                c: rng.uniform_in(-0.002, 0.002) * x_amp,
            },
            "creep" => Truth::Creep {
                gains: [
                    rng.uniform_in(0.06, 0.12),
                    rng.uniform_in(0.06, 0.12),
                    rng.uniform_in(0.05, 0.1),
                ],
                taus: [0.05, 0.5, 5.0],
            },
            "encoder_slit_error" => {
                let q = 0.05 * x_amp;
                let nn = [8usize, 12, 16, 20][(rng.uniform() * 4.0) as usize % 4];
                Truth::SlitError {
                    q,
                    errors: (0..nn).map(|_| rng.normal() * 0.5 * q).collect(),
                }
            }
            "saturation" => {
                let f = rng.uniform_in(0.6, 0.8);
                Truth::Saturation {
                    lo: ulo * f,
                    hi: uhi * f,
                }
            }
            "backlash" => Truth::Backlash {
                w: rng.uniform_in(0.05, 0.12) * ru,
            },
            other => {
                return Err(DataError::new(
                    "generator",
                    format!("no single-axis generator for `{other}`"),
                    "use one of the vocabulary names (axis_coupling: two_axis)",
                ));
            }
        })
    };
    let mut truths = Vec::new();
    for name in hidden.split('+') {
        truths.push(draw(name.trim(), &mut rng)?);
    }
    let (k, c, m) = (stage.k(), stage.c(), stage.m);
    let dt = 1.0 / (RATE_HZ * OVERSAMPLE as f64);
    // States: x, v, Bouc–Wen z, creep filters, resonance filter.
    let mut x = 0.0;
    let mut v = 0.0;
    let mut z = u[0];
    let mut creep = [0.0f64; 3];
    let mut play = u[0];
    let mut delay_line = vec![u[0]; OVERSAMPLE * 8 + 1];
    let mut res = [0.0f64; 2]; // second-order filter state of the resonance
    // Each input-side effect's previous input (Bouc–Wen integrates its own
    // input's increments).
    let mut prev_in = vec![u[0]; truths.len()];
    let mut y = Vec::with_capacity(n);
    let mut noise_state = 0.0;
    let sigma = 0.01 * x_amp;
    for (kk, &uk) in u.iter().enumerate() {
        // Sample at t_k (before this interval's input acts).
        let mut meas_x = x;
        for truth in &truths {
            if let Truth::Resonance { fp, zp, fz, zz } = truth {
                // y = (ωp²/ωz²)(r̈ + 2ζz ωz ṙ + ωz² r), r̈ + 2ζp ωp ṙ + ωp² r = x.
                let (wp, wz) = (2.0 * PI * fp, 2.0 * PI * fz);
                let rdd = x - 2.0 * zp * wp * res[1] - wp * wp * res[0];
                meas_x = (wp * wp / (wz * wz)) * (rdd + 2.0 * zz * wz * res[1] + wz * wz * res[0]);
            }
        }
        let t = kk as f64 / RATE_HZ;
        let mut ym = meas_x;
        for truth in &truths {
            ym = match truth {
                Truth::Repetitive { f, amps, phases } => {
                    ym + (0..3)
                        .map(|h| amps[h] * (2.0 * PI * (h + 1) as f64 * f * t + phases[h]).sin())
                        .sum::<f64>()
                }
                Truth::Quantization { q } => q * (ym / q).round(),
                Truth::Drift { a, b, c } => ym + a + b * t + c * t * t,
                Truth::SlitError { q, errors } => {
                    let idx = (ym / q).round();
                    q * idx + errors[(idx as i64).rem_euclid(errors.len() as i64) as usize]
                }
                _ => ym,
            };
        }
        noise_state = 0.98 * noise_state + rng.normal() * (1.0 - 0.98f64 * 0.98).sqrt();
        ym += sigma * rng.normal()
            + if coloured_noise {
                3.0 * sigma * noise_state
            } else {
                0.0
            };
        y.push(ym);
        // Integrate the interval [t_k, t_k+1) with u held.
        for _ in 0..OVERSAMPLE {
            // Input-side effects, in series in the order named: each acts on the
            // output of the one before (the drive for the first).
            let mut f = uk;
            for (truth, prev) in truths.iter().zip(prev_in.iter_mut()) {
                let input = f;
                let du = input - *prev;
                *prev = input;
                f = match truth {
                    Truth::Hysteresis { beta, gamma, h } => {
                        z += du - beta * du.abs() * z - gamma * du * z.abs();
                        (1.0 - h) * input + h * z
                    }
                    Truth::Delay { fine_steps } => {
                        delay_line.rotate_right(1);
                        delay_line[0] = input;
                        delay_line[*fine_steps]
                    }
                    Truth::PositionGain { g, center, scale } => {
                        f * (1.0 + g * (x - center) / scale)
                    }
                    Truth::Creep { gains, taus } => {
                        let mut s = input;
                        for i in 0..3 {
                            creep[i] += (input - creep[i]) * (1.0 - (-dt / taus[i]).exp());
                            s += gains[i] * creep[i];
                        }
                        s
                    }
                    Truth::Saturation { lo, hi } => input.clamp(*lo, *hi),
                    Truth::Backlash { w } => {
                        if input - play > w / 2.0 {
                            play = input - w / 2.0;
                        } else if play - input > w / 2.0 {
                            play = input + w / 2.0;
                        }
                        play
                    }
                    _ => f,
                };
            }
            let friction = |v: f64| -> f64 {
                truths
                    .iter()
                    .map(|truth| match truth {
                        Truth::Friction { fc, fs, vs, veps } => {
                            (fc + (fs - fc) * (-(v / vs).powi(2)).exp()) * (v / veps).tanh()
                        }
                        _ => 0.0,
                    })
                    .sum::<f64>()
            };
            // RK4 on (x, v, r, ṙ) with f held (friction evaluated inside; r is the
            // resonance filter's state, driven by x).
            let (wp, zp) = truths
                .iter()
                .find_map(|t| match t {
                    Truth::Resonance { fp, zp, .. } => Some((2.0 * PI * fp, *zp)),
                    _ => None,
                })
                .unwrap_or((0.0, 0.0));
            let deriv = |s: [f64; 4]| -> [f64; 4] {
                [
                    s[1],
                    (f - k * s[0] - c * s[1] - friction(s[1])) / m,
                    s[3],
                    s[0] - 2.0 * zp * wp * s[3] - wp * wp * s[2],
                ]
            };
            let s0 = [x, v, res[0], res[1]];
            let add = |a: [f64; 4], b: [f64; 4], h: f64| {
                [
                    a[0] + h * b[0],
                    a[1] + h * b[1],
                    a[2] + h * b[2],
                    a[3] + h * b[3],
                ]
            };
            let k1 = deriv(s0);
            let k2 = deriv(add(s0, k1, 0.5 * dt));
            let k3 = deriv(add(s0, k2, 0.5 * dt));
            let k4 = deriv(add(s0, k3, dt));
            let mut s1 = s0;
            for i in 0..4 {
                s1[i] += dt / 6.0 * (k1[i] + 2.0 * k2[i] + 2.0 * k3[i] + k4[i]);
            }
            x = s1[0];
            v = s1[1];
            res = [s1[2], s1[3]];
        }
    }
    let slit = truths.iter().find_map(|t| match t {
        Truth::SlitError { q, .. } => Some(*q),
        _ => None,
    });
    let nominal_yaml = format!(
        "title: second-order stage (nominal, no {hidden})\nbase_rate_hz: {RATE_HZ}\nduration_s: {}\nblocks:\n  - {{ name: drive, type: data_column, column: u }}\n{}{}connections:\n  - {{ from: drive.y, to: stage.u }}\n{}compare:\n  - {{ signal: {}, column: y }}\n",
        n as f64 / RATE_HZ,
        stage.yaml_block("stage"),
        slit.map(|q| format!("  - {{ name: encoder, type: quantizer, lsb: {q:?} }}\n"))
            .unwrap_or_default(),
        if slit.is_some() {
            "  - { from: stage.y, to: encoder.u }\n"
        } else {
            ""
        },
        if slit.is_some() {
            "encoder.y"
        } else {
            "stage.y"
        },
    );
    let describe = |truth: &Truth| match truth {
        Truth::None => "no hidden effect".to_string(),
        Truth::Hysteresis { beta, gamma, h } => {
            format!("Bouc–Wen input hysteresis β = {beta:.3e}, γ = {gamma:.3e}, share {h:.2}")
        }
        Truth::Friction { fc, fs, vs, .. } => {
            format!("Stribeck friction Fc = {fc:.3e} N, Fs = {fs:.3e} N, vs = {vs:.2e} m/s")
        }
        Truth::Delay { fine_steps } => format!(
            "input delay {:.2} samples",
            *fine_steps as f64 / OVERSAMPLE as f64
        ),
        Truth::Repetitive { f, .. } => {
            format!("periodic output disturbance at {f:.3} Hz, 3 harmonics")
        }
        Truth::PositionGain { g, .. } => format!("drive gain 1 + {g:.3}·x/1 µm"),
        Truth::Quantization { q } => format!("output quantised to {q:.3e} m"),
        Truth::Resonance { fp, fz, .. } => {
            format!("output resonance {fp:.1} Hz with anti-resonance {fz:.1} Hz")
        }
        Truth::Drift { b, .. } => format!("output drift {b:.3e} m/s (+ offset, curvature)"),
        Truth::Creep { gains, .. } => format!("input creep, gains {gains:.3?} at 0.05/0.5/5 s"),
        Truth::SlitError { errors, .. } => {
            format!("{} slit errors of σ {:.2} lsb", errors.len(), 0.5)
        }
        Truth::Saturation { lo, hi } => format!("drive saturation [{lo:.3e}, {hi:.3e}] N"),
        Truth::Backlash { w } => format!("drive backlash width {w:.3e} N"),
    };
    let truth_text = truths.iter().map(describe).collect::<Vec<_>>().join("; ");
    let data = Dataset::from_columns(
        "generated",
        RATE_HZ,
        0.0,
        vec![("u".into(), u), ("y".into(), y)],
    )?;
    Ok(Record {
        nominal_yaml,
        data,
        hidden: if hidden == "none" {
            vec![]
        } else {
            vec![hidden.to_string()]
        },
        truth: truth_text,
    })
}

/// A two-axis record (`u`, `u2` drives; `y`, `y2` positions) of two independent
/// second-order stages whose measured first axis sees the second one through a
/// hidden static coupling y = x₁ + κ·x₂ (`axis_coupling`), or no coupling
/// (`"none"`), seeded.
pub fn two_axis(hidden: &str, seed: u64, n: usize) -> Result<Record, DataError> {
    let mut rng = Rng::new(seed ^ 0x2a_c0de);
    let stages = [
        Stage {
            f0: rng.uniform_in(20.0, 60.0),
            zeta: rng.uniform_in(0.03, 0.15),
            m: rng.uniform_in(0.2, 2.0),
        },
        Stage {
            f0: rng.uniform_in(20.0, 60.0),
            zeta: rng.uniform_in(0.03, 0.15),
            m: rng.uniform_in(0.2, 2.0),
        },
    ];
    let kappa = match hidden {
        "none" => 0.0,
        "axis_coupling" => {
            rng.uniform_in(0.05, 0.15) * if rng.uniform() < 0.5 { -1.0 } else { 1.0 }
        }
        other => {
            return Err(DataError::new(
                "generator",
                format!("no two-axis generator for `{other}`"),
                "use axis_coupling or none",
            ));
        }
    };
    let x_amp = 1e-6;
    let dt = 1.0 / (RATE_HZ * OVERSAMPLE as f64);
    let mut us = Vec::new();
    let mut xs = Vec::new();
    for st in &stages {
        let u = drive(&mut rng, n, st.k() * x_amp);
        let (k, c, m) = (st.k(), st.c(), st.m);
        let (mut x, mut v) = (0.0, 0.0);
        let mut xk = Vec::with_capacity(n);
        for &uk in &u {
            xk.push(x);
            for _ in 0..OVERSAMPLE {
                let acc = |x: f64, v: f64| (uk - k * x - c * v) / m;
                let (k1x, k1v) = (v, acc(x, v));
                let (k2x, k2v) = (
                    v + 0.5 * dt * k1v,
                    acc(x + 0.5 * dt * k1x, v + 0.5 * dt * k1v),
                );
                let (k3x, k3v) = (
                    v + 0.5 * dt * k2v,
                    acc(x + 0.5 * dt * k2x, v + 0.5 * dt * k2v),
                );
                let (k4x, k4v) = (v + dt * k3v, acc(x + dt * k3x, v + dt * k3v));
                x += dt / 6.0 * (k1x + 2.0 * k2x + 2.0 * k3x + k4x);
                v += dt / 6.0 * (k1v + 2.0 * k2v + 2.0 * k3v + k4v);
            }
        }
        us.push(u);
        xs.push(xk);
    }
    let sigma = 0.01 * x_amp;
    let y1: Vec<f64> = (0..n)
        .map(|k| xs[0][k] + kappa * xs[1][k] + sigma * rng.normal())
        .collect();
    let y2: Vec<f64> = (0..n).map(|k| xs[1][k] + sigma * rng.normal()).collect();
    let nominal_yaml = format!(
        "title: two-axis stage (nominal, axes independent)\nbase_rate_hz: {RATE_HZ}\nduration_s: {}\nblocks:\n  - {{ name: drive_x, type: data_column, column: u }}\n  - {{ name: drive_y, type: data_column, column: u2 }}\n{}{}connections:\n  - {{ from: drive_x.y, to: stage_x.u }}\n  - {{ from: drive_y.y, to: stage_y.u }}\ncompare:\n  - {{ signal: stage_x.y, column: y }}\n  - {{ signal: stage_y.y, column: y2 }}\n",
        n as f64 / RATE_HZ,
        stages[0].yaml_block("stage_x"),
        stages[1].yaml_block("stage_y"),
    );
    let u2 = us.pop().expect("two drives");
    let u1 = us.pop().expect("two drives");
    let data = Dataset::from_columns(
        "generated",
        RATE_HZ,
        0.0,
        vec![
            ("u".into(), u1),
            ("u2".into(), u2),
            ("y".into(), y1),
            ("y2".into(), y2),
        ],
    )?;
    Ok(Record {
        nominal_yaml,
        data,
        hidden: if kappa == 0.0 {
            vec![]
        } else {
            vec!["axis_coupling".into()]
        },
        truth: format!("y = x1 + {kappa:.4}·x2"),
    })
}
