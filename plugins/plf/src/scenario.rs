//! A scenario distribution as wide as users' stages, for judging the workflow
//! on data it was not built against (issue 24 §1).
//!
//! [`generate`](crate::generate) is the *development* generator: one
//! second-order stage at 2 kHz, open loop, one excitation, white noise, an exact
//! nominal model. The workflow was tuned on it. This module draws records from
//! independent **families** — each record is labelled with one value of every
//! dimension:
//!
//! | dimension | values |
//! |---|---|
//! | plant | `stage2` (mass–spring–damper), `free_mass` (mass and viscous damping: an integrator), `lag_stage` (stage behind an amplifier pole), `two_mode` (stage with a second, modelled mode), `first_order` (a lag: thermal or amplifier-limited actuator) |
//! | loop | `open`, `pd`, `pid` (a discrete controller on the measured position, in the nominal graph too) |
//! | excitation | `multisine`, `sine`, `triangle`, `steps`, `random` (the drive in open loop, the reference in closed loop) |
//! | noise | `white`, `ar1`, `pink` (AR(1) terms over four decades), `band` (a band around 30–300 Hz) |
//! | nominal | `exact`, `near` (parameters off by ≤ 3 %), `off` (≤ 10 %) |
//! | rate | 500 Hz – 10 kHz; units m, µm, nm for the position and N or V for the drive |
//!
//! and each effect is simulated in physical forms that are **not** the blocks
//! the workflow fits: Prandtl–Ishlinskii and Bouc–Wen (n = 2) hysteresis; Dahl,
//! LuGre and Stribeck friction on the mass; creep as a logarithm in time (eight
//! lags over four decades); thermal (exponential) and ramp drift; fractional and
//! time-varying delays; an attached mass as the unmodelled resonance; a force
//! periodic in time, and a cogging force periodic in position; hard and soft
//! (tanh) saturation; gear play; encoder rounding and slit errors; a drive gain
//! that varies with position. Singles, pairs and effect-free records.
//!
//! **Split by family** ([`Family::split`]): the workflow may be tuned only on
//! records whose plant is `stage2` or `lag_stage`, excitation `multisine`,
//! `sine` or `steps`, and noise `white` or `ar1` ([`Split::Tune`]); a record
//! with a plant, an excitation or a noise outside those ([`Split::HeldOut`],
//! about 88 % of the draws) is only ever scored. Loops, nominal errors, rates
//! and units are drawn alike in both. Everything is seeded: [`draw`] with the
//! same seed gives the same bits.

use crate::generate::Record;
use nanomotion_core::data::{DataError, Dataset};
use nanomotion_core::rng::Rng;
use std::f64::consts::PI;

/// The effects a scenario can hide (vocabulary names), and the pairs.
pub const EFFECTS: [&str; 12] = [
    "hysteresis",
    "friction",
    "creep",
    "drift",
    "time_delay",
    "unmodeled_resonance",
    "repetitive_disturbance",
    "saturation",
    "backlash",
    "quantization",
    "encoder_slit_error",
    "position_dependent_gain",
];

/// Pairs of effects hidden together.
pub const PAIRS: [(&str, &str); 4] = [
    ("hysteresis", "creep"),
    ("friction", "time_delay"),
    ("hysteresis", "drift"),
    ("friction", "quantization"),
];

/// The family labels of a record (see the module docs).
#[derive(Debug, Clone, PartialEq)]
pub struct Family {
    /// Plant family.
    pub plant: &'static str,
    /// `open`, `pd` or `pid`.
    pub loop_kind: &'static str,
    /// Excitation family.
    pub excitation: &'static str,
    /// Noise family.
    pub noise: &'static str,
    /// `exact`, `near` or `off`.
    pub nominal: &'static str,
    /// Sample rate (Hz).
    pub rate_hz: f64,
    /// Position unit of the data (`m`, `um`, `nm`).
    pub unit: &'static str,
}

/// Which side of the tuning split a record is on (see the module docs).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Split {
    /// Families the workflow may be tuned on.
    Tune,
    /// Families only ever scored.
    HeldOut,
}

/// The plants, excitations and noises of the tuning split.
pub const TUNE_PLANTS: [&str; 2] = ["stage2", "lag_stage"];
/// Excitations of the tuning split.
pub const TUNE_EXCITATIONS: [&str; 3] = ["multisine", "sine", "steps"];
/// Noises of the tuning split.
pub const TUNE_NOISES: [&str; 2] = ["white", "ar1"];

impl Family {
    /// The side of the tuning split this family is on.
    pub fn split(&self) -> Split {
        if TUNE_PLANTS.contains(&self.plant)
            && TUNE_EXCITATIONS.contains(&self.excitation)
            && TUNE_NOISES.contains(&self.noise)
        {
            Split::Tune
        } else {
            Split::HeldOut
        }
    }
}

/// A drawn scenario: the record and its family.
#[derive(Debug, Clone)]
pub struct Scenario {
    /// The record (nominal model, data, hidden effects, truth in words).
    pub record: Record,
    /// Its family labels.
    pub family: Family,
}

fn pick<T: Copy>(rng: &mut Rng, xs: &[T]) -> T {
    xs[((rng.uniform() * xs.len() as f64) as usize).min(xs.len() - 1)]
}

fn log_uniform(rng: &mut Rng, lo: f64, hi: f64) -> f64 {
    (rng.uniform_in(lo.ln(), hi.ln())).exp()
}

/// The hidden effects of scenario `seed`: one in nine records is effect-free,
/// one in six a pair, the rest one effect each.
fn hidden_of(rng: &mut Rng) -> Vec<&'static str> {
    let r = rng.uniform();
    if r < 1.0 / 9.0 {
        vec![]
    } else if r < 1.0 / 9.0 + 1.0 / 6.0 {
        let (a, b) = pick(rng, &PAIRS);
        vec![a, b]
    } else {
        vec![pick(rng, &EFFECTS)]
    }
}

/// One effect in one of its physical forms (normalised units: the stroke and
/// the drive are of order 1).
#[derive(Debug, Clone)]
enum Form {
    /// y = (1 − h)u + Σ wᵢ·playᵢ(u), thresholds rᵢ = i·R/8.
    PrandtlIshlinskii { h: f64, r: [f64; 8], w: [f64; 8] },
    /// ż = A·u̇ − β|u̇||z|z − γ u̇ z² (n = 2), y = (1 − h)u + h·z.
    BoucWen2 { h: f64, beta: f64, gamma: f64 },
    /// dF/dx = σ(1 − F/Fc·sgn ẋ): presliding friction.
    Dahl { fc: f64, sigma: f64 },
    /// LuGre (bristles without damping): ż = v − σ₀|v|z/g(v), F = σ₀z.
    LuGre { fc: f64, fs: f64, vs: f64, s0: f64 },
    /// Static Stribeck friction with viscous part, tanh-smoothed.
    Stribeck {
        fc: f64,
        fs: f64,
        vs: f64,
        fv: f64,
        veps: f64,
    },
    /// Log creep: eight lags at τ = 10^(−2…1.5) s, gains γ/8.
    LogCreep { gamma: f64 },
    /// Output drift d·(1 − e^{−t/τ}) + offset.
    ThermalDrift { d: f64, tau: f64, offset: f64 },
    /// Output drift offset + rate·t.
    RampDrift { offset: f64, rate: f64 },
    /// Drive delayed by d(t) = d₀ + a·sin(2π f t) samples (a = 0: fixed).
    Delay { d0: f64, a: f64, f: f64 },
    /// A mass μ·m attached by a spring at ω_r, damping ζ_r (plant state).
    AttachedMass { mu: f64, fr: f64, zr: f64 },
    /// A force periodic in time (independent of the drive).
    PeriodicForce {
        f: f64,
        amps: [f64; 3],
        phases: [f64; 3],
    },
    /// A cogging force periodic in position.
    Cogging { pitch: f64, amp: f64, phase: f64 },
    /// Drive limited to [lo, hi] (hard) or smoothly (tanh).
    Saturation { lo: f64, hi: f64, soft: bool },
    /// Gear play of width w on the drive.
    Play { w: f64 },
    /// Position rounded to the lsb q (normalised).
    Rounding { q: f64 },
    /// Rounding plus per-slit edge errors (normalised), periodic over the slits.
    Slits { q: f64, errors: Vec<f64> },
    /// Drive gain 1 + g₁x + g₂x².
    PositionGain { g1: f64, g2: f64 },
}

impl Form {
    fn describe(&self) -> String {
        match self {
            Form::PrandtlIshlinskii { h, .. } => {
                format!("Prandtl–Ishlinskii input hysteresis (8 plays, share {h:.2})")
            }
            Form::BoucWen2 { h, .. } => format!("Bouc–Wen n = 2 input hysteresis (share {h:.2})"),
            Form::Dahl { fc, .. } => format!("Dahl friction Fc = {fc:.3}"),
            Form::LuGre { fc, fs, .. } => format!("LuGre friction Fc = {fc:.3}, Fs = {fs:.3}"),
            Form::Stribeck { fc, fs, fv, .. } => {
                format!("Stribeck friction Fc = {fc:.3}, Fs = {fs:.3}, Fv = {fv:.3}")
            }
            Form::LogCreep { gamma } => format!("logarithmic creep {gamma:.3} over four decades"),
            Form::ThermalDrift { d, tau, .. } => {
                format!("thermal drift {d:.3} with τ = {tau:.2} s")
            }
            Form::RampDrift { rate, .. } => format!("ramp drift {rate:.3e}/s"),
            Form::Delay { d0, a, .. } => format!("drive delay {d0:.2} samples (varying ±{a:.2})"),
            Form::AttachedMass { mu, fr, zr } => {
                format!("attached mass μ = {mu:.2} at {fr:.1} Hz, ζ = {zr:.3}")
            }
            Form::PeriodicForce { f, .. } => format!("force periodic in time at {f:.3} Hz"),
            Form::Cogging { pitch, .. } => {
                format!("cogging force of pitch {pitch:.3} (stroke units)")
            }
            Form::Saturation { lo, hi, soft } => format!(
                "{} drive saturation [{lo:.2}, {hi:.2}]",
                if *soft { "soft" } else { "hard" }
            ),
            Form::Play { w } => format!("gear play {w:.3}"),
            Form::Rounding { q } => format!("position rounded to {q:.2e} (stroke units)"),
            Form::Slits { errors, .. } => format!("slit errors over {} slits", errors.len()),
            Form::PositionGain { g1, g2 } => format!("drive gain 1 + {g1:.3}x + {g2:.3}x²"),
        }
    }
}

fn draw_form(rng: &mut Rng, effect: &str, fs: f64, t_len: f64, f0: f64) -> Form {
    match effect {
        "hysteresis" => {
            if rng.uniform() < 0.5 {
                let mut w = [0.0; 8];
                let mut r = [0.0; 8];
                let big = rng.uniform_in(0.4, 1.0);
                for i in 0..8 {
                    r[i] = big * (i + 1) as f64 / 8.0;
                    w[i] = rng.uniform_in(0.5, 1.5) / (i + 1) as f64;
                }
                let s: f64 = w.iter().sum();
                w.iter_mut().for_each(|x| *x /= s);
                Form::PrandtlIshlinskii {
                    h: rng.uniform_in(0.15, 0.4),
                    r,
                    w,
                }
            } else {
                Form::BoucWen2 {
                    h: rng.uniform_in(0.15, 0.4),
                    beta: rng.uniform_in(1.0, 4.0),
                    gamma: rng.uniform_in(-0.5, 1.0),
                }
            }
        }
        "friction" => {
            let fc = rng.uniform_in(0.05, 0.2);
            match pick(rng, &[0, 1, 2]) {
                0 => Form::Dahl {
                    fc,
                    sigma: fc * log_uniform(rng, 50.0, 500.0),
                },
                1 => Form::LuGre {
                    fc,
                    fs: fc * rng.uniform_in(1.1, 1.6),
                    vs: log_uniform(rng, 0.01, 0.1) * f0,
                    s0: fc * log_uniform(rng, 50.0, 500.0),
                },
                _ => Form::Stribeck {
                    fc,
                    fs: fc * rng.uniform_in(1.0, 1.6),
                    vs: log_uniform(rng, 0.01, 0.1) * f0,
                    fv: 0.0,
                    veps: 0.002 * f0,
                },
            }
        }
        "creep" => Form::LogCreep {
            gamma: rng.uniform_in(0.05, 0.2),
        },
        "drift" => {
            if rng.uniform() < 0.5 {
                Form::ThermalDrift {
                    d: rng.uniform_in(0.05, 0.2),
                    tau: t_len * rng.uniform_in(0.3, 3.0),
                    offset: rng.uniform_in(-0.05, 0.05),
                }
            } else {
                Form::RampDrift {
                    offset: rng.uniform_in(-0.05, 0.05),
                    rate: rng.uniform_in(0.05, 0.2) / t_len,
                }
            }
        }
        "time_delay" => Form::Delay {
            d0: rng.uniform_in(0.4, 3.0) * (fs / 2000.0).max(1.0),
            a: if rng.uniform() < 0.5 {
                0.0
            } else {
                rng.uniform_in(0.1, 0.3)
            },
            f: rng.uniform_in(0.1, 1.0),
        },
        "unmodeled_resonance" => Form::AttachedMass {
            mu: rng.uniform_in(0.1, 0.4),
            fr: (f0 * rng.uniform_in(3.0, 8.0)).min(0.2 * fs),
            zr: log_uniform(rng, 0.01, 0.05),
        },
        "repetitive_disturbance" => {
            if rng.uniform() < 0.5 {
                Form::PeriodicForce {
                    f: log_uniform(rng, 3.0 / t_len.min(10.0) + 2.0, 0.05 * fs),
                    amps: [
                        rng.uniform_in(0.03, 0.1),
                        rng.uniform_in(0.0, 0.04),
                        rng.uniform_in(0.0, 0.02),
                    ],
                    phases: [
                        rng.uniform_in(0.0, 2.0 * PI),
                        rng.uniform_in(0.0, 2.0 * PI),
                        rng.uniform_in(0.0, 2.0 * PI),
                    ],
                }
            } else {
                Form::Cogging {
                    pitch: rng.uniform_in(0.05, 0.3),
                    amp: rng.uniform_in(0.03, 0.1),
                    phase: rng.uniform_in(0.0, 2.0 * PI),
                }
            }
        }
        "saturation" => {
            let hi = rng.uniform_in(0.55, 0.85);
            Form::Saturation {
                lo: -hi * rng.uniform_in(0.9, 1.1),
                hi,
                soft: rng.uniform() < 0.5,
            }
        }
        "backlash" => Form::Play {
            w: rng.uniform_in(0.03, 0.1),
        },
        "quantization" => Form::Rounding {
            q: 2.0 / log_uniform(rng, 100.0, 1000.0),
        },
        "encoder_slit_error" => {
            let slits = pick(rng, &[64usize, 100, 128, 250, 500]);
            let q = 2.0 / log_uniform(rng, 150.0, 600.0);
            let errors = (0..slits).map(|_| 0.3 * q * rng.normal()).collect();
            Form::Slits { q, errors }
        }
        _ => Form::PositionGain {
            g1: rng.uniform_in(0.05, 0.15) * if rng.uniform() < 0.5 { -1.0 } else { 1.0 },
            g2: rng.uniform_in(-0.1, 0.1),
        },
    }
}

/// The linear plant in normalised form: the main mass m₁ = 1/ω₀² with
/// stiffness k (1, or 0 for a free mass) and damping c, an optional amplifier
/// lag, an optional modelled second mode, and the unmodelled attached mass.
#[derive(Debug, Clone, Copy)]
struct Plant {
    kind: &'static str,
    w0: f64,
    zeta: f64,
    /// Amplifier (or first-order plant) time constant (s).
    tau: f64,
    /// Modelled second mode: (mass ratio, ω, ζ).
    mode: Option<(f64, f64, f64)>,
}

impl Plant {
    fn m1(&self) -> f64 {
        1.0 / (self.w0 * self.w0)
    }
    fn k(&self) -> f64 {
        if self.kind == "free_mass" { 0.0 } else { 1.0 }
    }
    fn c(&self) -> f64 {
        2.0 * self.zeta * self.m1() * self.w0
    }
    /// (A, B, C) of the linear part with `extra` attached masses (μ, ω, ζ).
    /// States: x, v, [fa], [x₂, v₂]…; B the drive; the force on the main mass
    /// enters the v row with 1/m₁.
    fn matrices(&self, extra: &[(f64, f64, f64)]) -> (Vec<Vec<f64>>, Vec<f64>, Vec<f64>) {
        if self.kind == "first_order" {
            return (vec![vec![-1.0 / self.tau]], vec![1.0 / self.tau], vec![1.0]);
        }
        let lag = self.kind == "lag_stage";
        let modes: Vec<(f64, f64, f64)> = self
            .mode
            .iter()
            .copied()
            .chain(extra.iter().copied())
            .collect();
        let n = 2 + usize::from(lag) + 2 * modes.len();
        let mut a = vec![vec![0.0; n]; n];
        let mut b = vec![0.0; n];
        let m1 = self.m1();
        a[0][1] = 1.0;
        a[1][0] = -self.k() / m1;
        a[1][1] = -self.c() / m1;
        if lag {
            a[1][2] = 1.0 / m1;
            a[2][2] = -1.0 / self.tau;
            b[2] = 1.0 / self.tau;
        } else {
            b[1] = 1.0 / m1;
        }
        let base = 2 + usize::from(lag);
        for (j, &(mu, w, z)) in modes.iter().enumerate() {
            let (i, m2) = (base + 2 * j, mu * m1);
            let (k12, c12) = (m2 * w * w, 2.0 * z * m2 * w);
            a[i][i + 1] = 1.0;
            a[i + 1][i] = -k12 / m2;
            a[i + 1][i + 1] = -c12 / m2;
            a[i + 1][0] = k12 / m2;
            a[i + 1][1] = c12 / m2;
            a[1][0] -= k12 / m1;
            a[1][1] -= c12 / m1;
            a[1][i] += k12 / m1;
            a[1][i + 1] += c12 / m1;
        }
        let mut c = vec![0.0; n];
        c[0] = 1.0;
        (a, b, c)
    }
}

fn yaml_matrix(m: &[Vec<f64>]) -> String {
    let rows: Vec<String> = m
        .iter()
        .map(|r| {
            format!(
                "[{}]",
                r.iter()
                    .map(|v| format!("{v:?}"))
                    .collect::<Vec<_>>()
                    .join(", ")
            )
        })
        .collect();
    format!("[{}]", rows.join(", "))
}

/// The excitation, normalised to a peak of 1.
fn excitation(rng: &mut Rng, kind: &str, n: usize, fs: f64) -> Vec<f64> {
    let t_len = n as f64 / fs;
    let raw: Vec<f64> = match kind {
        "sine" | "triangle" => {
            let f = rng
                .uniform_in(4.0 / t_len, (10.0f64).max(5.0 / t_len))
                .min(0.02 * fs);
            let ph = rng.uniform_in(0.0, 1.0);
            (0..n)
                .map(|k| {
                    let c = (f * k as f64 / fs + ph).fract();
                    if kind == "sine" {
                        (2.0 * PI * c).sin()
                    } else {
                        4.0 * (c - 0.5).abs() - 1.0
                    }
                })
                .collect()
        }
        "steps" => {
            let mut level = 0.0;
            let mut next = 0usize;
            (0..n)
                .map(|k| {
                    if k >= next {
                        level = rng.uniform_in(-1.0, 1.0);
                        next = k + (rng.uniform_in(0.1, 0.5) * fs) as usize;
                    }
                    level
                })
                .collect()
        }
        "random" => {
            let a = (-2.0 * PI * rng.uniform_in(3.0, 30.0) / fs).exp();
            let mut s = 0.0;
            (0..n)
                .map(|_| {
                    s = a * s + (1.0 - a) * rng.normal();
                    s
                })
                .collect()
        }
        _ => {
            let slow: Vec<(f64, f64)> = (0..5)
                .map(|_| {
                    (
                        rng.uniform_in(1.0 / t_len, 2.0),
                        rng.uniform_in(0.0, 2.0 * PI),
                    )
                })
                .collect();
            let fast: Vec<(f64, f64)> = (0..30)
                .map(|_| (rng.uniform_in(3.0, 0.1 * fs), rng.uniform_in(0.0, 2.0 * PI)))
                .collect();
            (0..n)
                .map(|k| {
                    let t = k as f64 / fs;
                    slow.iter()
                        .map(|(f, p)| (2.0 * PI * f * t + p).sin())
                        .sum::<f64>()
                        + 0.5
                            * fast
                                .iter()
                                .map(|(f, p)| (2.0 * PI * f * t + p).sin())
                                .sum::<f64>()
                            / (fast.len() as f64).sqrt()
                })
                .collect()
        }
    };
    let peak = raw
        .iter()
        .fold(0.0f64, |m, v| m.max(v.abs()))
        .max(f64::MIN_POSITIVE);
    raw.iter().map(|v| v / peak).collect()
}

/// Measurement noise of unit rms in the family's colour.
fn noise(rng: &mut Rng, kind: &str, n: usize, fs: f64) -> Vec<f64> {
    let raw: Vec<f64> = match kind {
        "ar1" => {
            let phi = rng.uniform_in(0.8, 0.98);
            let mut s = 0.0;
            (0..n)
                .map(|_| {
                    s = phi * s + rng.normal();
                    s
                })
                .collect()
        }
        "pink" => {
            let phis = [0.5f64, 0.95, 0.995, 0.9995];
            let mut s = [0.0; 4];
            (0..n)
                .map(|_| {
                    let mut y = 0.0;
                    for (j, p) in phis.iter().enumerate() {
                        s[j] = p * s[j] + (1.0 - p * p).sqrt() * rng.normal();
                        y += s[j];
                    }
                    y + rng.normal()
                })
                .collect()
        }
        "band" => {
            let f = rng.uniform_in(30.0, 300.0f64.min(0.3 * fs));
            let (r, w) = (0.98, 2.0 * PI * f / fs);
            let (mut y1, mut y2) = (0.0, 0.0);
            (0..n)
                .map(|_| {
                    let y = 2.0 * r * w.cos() * y1 - r * r * y2 + rng.normal();
                    y2 = y1;
                    y1 = y;
                    y + 2.0 * rng.normal()
                })
                .collect()
        }
        _ => (0..n).map(|_| rng.normal()).collect(),
    };
    let rms = (raw.iter().map(|v| v * v).sum::<f64>() / n as f64)
        .sqrt()
        .max(f64::MIN_POSITIVE);
    raw.iter().map(|v| v / rms).collect()
}

/// The hidden effects and family labels of scenario `seed`, without simulating
/// it (cheap: for choosing records by family).
pub fn labels(seed: u64) -> (Vec<&'static str>, Family) {
    labels_from(&mut scenario_rng(seed))
}

fn scenario_rng(seed: u64) -> Rng {
    Rng::new(seed ^ 0x5ce4_a710)
}

fn labels_from(rng: &mut Rng) -> (Vec<&'static str>, Family) {
    let hidden = hidden_of(rng);
    let mut plant_kind = pick(
        rng,
        &[
            "stage2",
            "free_mass",
            "lag_stage",
            "two_mode",
            "first_order",
        ],
    );
    // A lag has no force balance: friction, play and resonances need a mass.
    if plant_kind == "first_order"
        && hidden.iter().any(|e| {
            matches!(
                *e,
                "friction" | "unmodeled_resonance" | "repetitive_disturbance"
            )
        })
    {
        plant_kind = "lag_stage";
    }
    let mut loop_kind = pick(rng, &["open", "open", "pd", "pid"]);
    if plant_kind == "free_mass" && loop_kind == "open" {
        loop_kind = "pd";
    }
    let excitation_kind = pick(rng, &["multisine", "sine", "triangle", "steps", "random"]);
    let noise_kind = pick(rng, &["white", "ar1", "pink", "band"]);
    let nominal_kind = pick(rng, &["exact", "near", "off"]);
    let fs = pick(rng, &[500.0, 1000.0, 2000.0, 5000.0, 10000.0]);
    let unit = pick(rng, &["m", "um", "nm"]);
    (
        hidden,
        Family {
            plant: plant_kind,
            loop_kind,
            excitation: excitation_kind,
            noise: noise_kind,
            nominal: nominal_kind,
            rate_hz: fs,
            unit,
        },
    )
}

/// Draw scenario `seed` (either side of the split; see [`Family::split`]).
pub fn draw(seed: u64) -> Result<Scenario, DataError> {
    draw_with(seed, false).map(|(s, _)| s)
}

/// How visible the hidden effects of a scenario are: the rms of what they
/// change in the compared signals (the position; in a closed loop also the
/// drive, whichever shows more) over the rms of the noise in the same signal,
/// from the same record simulated without the effects, with and without its
/// noise. Below about 1 an effect hides in the noise (effect-free records: 0).
#[derive(Debug, Clone, PartialEq)]
pub struct Visibility {
    /// Over the whole record.
    pub whole: f64,
    /// Over the part `diagnose` holds out by default (its last
    /// [`Options::holdout`](crate::diagnose::Options::holdout) share), the only
    /// part that decides a name: an effect that acts only in the start-up
    /// transient (a drive that saturates on the first step) is whole-record
    /// visible and held-out invisible.
    pub held_out: f64,
    /// Over the held-out part, of what the nominal's own parameters cannot
    /// take: the nominal calibration alone (`diagnose` with
    /// `max_effects = 0`) fitted to the record with its effects and to the
    /// record without them, both with the noise scaled by 10⁻³; the mean
    /// square the effects leave over what the calibration leaves without
    /// them, over the noise's. A linear effect at one frequency (a mode under
    /// a single tone is a gain and a phase there) or an attached mass below
    /// its resonance (a heavier stage) is whole-record visible and taken by
    /// the calibration: no record can tell it from a nominal that is off.
    pub calibrated: f64,
    /// [`Visibility::calibrated`] of each hidden effect alone, the others
    /// kept: the record with every effect against the record without this
    /// one, both quiet and calibrated. Where two effects are hidden this is
    /// what "where the effect allows it" asks of each name (a hysteresis
    /// whose loop a drift's ramp swamps); one hidden effect: its
    /// `calibrated`. An estimate: the calibration also bends to the other
    /// effect, and the difference of the two mean squares assumes the
    /// effects' residuals uncorrelated (a negative difference counts as 0).
    pub per_effect: Vec<(String, f64)>,
}

/// The [`Visibility`] of scenario `seed`'s hidden effects.
pub fn visibility(seed: u64) -> Result<Visibility, DataError> {
    draw_with(seed, true).map(|(_, v)| {
        v.unwrap_or(Visibility {
            whole: 0.0,
            held_out: 0.0,
            calibrated: 0.0,
            per_effect: Vec::new(),
        })
    })
}

/// The noise of the quiet records [`Visibility::calibrated`] is measured on,
/// relative to the record's: small enough to leave the model error alone,
/// not zero so that every noise floor `diagnose` estimates is finite.
const QUIET_NOISE: f64 = 1e-3;

fn draw_with(
    seed: u64,
    with_visibility: bool,
) -> Result<(Scenario, Option<Visibility>), DataError> {
    let mut rng = scenario_rng(seed);
    let (hidden, family) = labels_from(&mut rng);
    let (plant_kind, loop_kind, excitation_kind) =
        (family.plant, family.loop_kind, family.excitation);
    let (noise_kind, nominal_kind, fs, unit) =
        (family.noise, family.nominal, family.rate_hz, family.unit);
    let unit_scale = match unit {
        "um" => 1e6,
        "nm" => 1e9,
        _ => 1.0,
    };
    // 2–8 s, at most 12 000 samples (1.2 s at 10 kHz): the evaluation of
    // hundreds of records must run in minutes; `diagnose` on long records is
    // measured in docs/performance.md.
    let t_len = rng.uniform_in(2.0, 8.0).min(12_000.0 / fs).max(1000.0 / fs);
    let n = (t_len * fs).round() as usize;
    let t_len = n as f64 / fs;
    let f0 = log_uniform(&mut rng, 5.0, (0.03 * fs).min(150.0));
    let w0 = 2.0 * PI * f0;
    let plant = Plant {
        kind: plant_kind,
        w0,
        zeta: log_uniform(&mut rng, 0.02, 0.3),
        tau: if plant_kind == "first_order" {
            1.0 / (2.0 * PI * log_uniform(&mut rng, 2.0, 0.03 * fs))
        } else {
            1.0 / (w0 * rng.uniform_in(6.0, 15.0))
        },
        mode: (plant_kind == "two_mode").then(|| {
            (
                rng.uniform_in(0.1, 0.5),
                w0 * rng.uniform_in(3.0, 6.0),
                log_uniform(&mut rng, 0.01, 0.05),
            )
        }),
    };
    let forms: Vec<(&str, Form)> = hidden
        .iter()
        .map(|e| (*e, draw_form(&mut rng, e, fs, t_len, f0)))
        .collect();
    // The nominal model: the same structure with parameters off by ≤ 3 or 10 %.
    let err = match nominal_kind {
        "near" => 0.03,
        "off" => 0.10,
        _ => 0.0,
    };
    let off = |r: &mut Rng| 1.0 + err * r.uniform_in(-1.0, 1.0);
    let nom = Plant {
        w0: plant.w0 * off(&mut rng),
        zeta: plant.zeta * off(&mut rng),
        tau: plant.tau * off(&mut rng),
        mode: plant.mode.map(|(mu, w, z)| (mu, w * off(&mut rng), z)),
        ..plant
    };
    let nominal_gain = off(&mut rng);
    // Scales: stroke (m) and drive (N or V per normalised force unit).
    let stroke_m = log_uniform(&mut rng, 1e-7, 1e-3);
    let y_scale = stroke_m * unit_scale;
    let u_scale = log_uniform(&mut rng, 0.1, 100.0);
    let sigma = log_uniform(&mut rng, 3e-4, 3e-3);
    let r = excitation(&mut rng, excitation_kind, n, fs);
    let meas_noise = noise(&mut rng, noise_kind, n, fs);
    let closed = loop_kind != "open";
    // Controller on the normalised loop: closed-loop poles at ω_cl, ζ = 0.7.
    let w_cl = if plant_kind == "first_order" {
        1.0 / plant.tau
    } else {
        w0 * rng.uniform_in(1.5, 3.0)
    }
    .min(2.0 * PI * fs / 40.0);
    let (kp, kd, ki) = if plant_kind == "first_order" {
        (
            2.0,
            0.0,
            if loop_kind == "pid" {
                2.0 * w_cl / 5.0
            } else {
                0.0
            },
        )
    } else {
        let m1 = plant.m1();
        let kp = (m1 * w_cl * w_cl - plant.k()).max(0.5);
        let kd = (1.4 * m1 * w_cl - plant.c()).max(0.0);
        (
            kp,
            kd,
            if loop_kind == "pid" {
                kp * w_cl / 10.0
            } else {
                0.0
            },
        )
    };
    // Discrete controller in data units: e in y units, u in drive units.
    let g = u_scale / y_scale;
    let (num, den) = if loop_kind == "pid" {
        (
            vec![
                g * (kp + ki / fs + kd * fs),
                -g * (kp + 2.0 * kd * fs),
                g * kd * fs,
            ],
            vec![1.0, -1.0, 0.0],
        )
    } else {
        (vec![g * (kp + kd * fs), -g * kd * fs], vec![1.0, 0.0])
    };
    // Simulate (a closure: the effect-free runs of `visibility` share it).
    let oversample = ((200_000.0 / fs).round() as usize).clamp(4, 40);
    let dt = 1.0 / (fs * oversample as f64);
    let simulate = |forms_in: &[(&str, Form)],
                    noise_gain: f64|
     -> Result<(Vec<f64>, Vec<f64>), DataError> {
        let forms: Vec<(&str, Form)> = forms_in.to_vec();
        let extra: Vec<(f64, f64, f64)> = forms
            .iter()
            .filter_map(|(_, f)| match f {
                Form::AttachedMass { mu, fr, zr } => Some((*mu, 2.0 * PI * fr, *zr)),
                _ => None,
            })
            .collect();
        let (a, b, c) = plant.matrices(&extra);
        let dim = a.len();
        let mut s = vec![0.0; dim];
        let mut u_data = Vec::with_capacity(n);
        let mut y_data = Vec::with_capacity(n);
        let mut ctrl_e = [0.0f64; 3];
        let mut ctrl_u = [0.0f64; 2];
        let mut hist: Vec<f64> = Vec::new(); // the drive at fine steps (delays)
        let mut plays = [0.0f64; 8];
        let mut z_bw = 0.0f64;
        let mut prev_in = 0.0;
        let mut play = 0.0f64;
        let mut creep = [0.0f64; 8];
        let creep_tau: Vec<f64> = (0..8)
            .map(|i| 10f64.powf(-2.0 + 3.5 * i as f64 / 7.0))
            .collect();
        let mut fric_z = 0.0;
        for k in 0..n {
            let t = k as f64 / fs;
            // Measure at t_k.
            let x = c.iter().zip(&s).map(|(ci, si)| ci * si).sum::<f64>();
            let mut ym = x;
            for (_, f) in &forms {
                ym = match f {
                    Form::ThermalDrift { d, tau, offset } => {
                        ym + offset + d * (1.0 - (-t / tau).exp())
                    }
                    Form::RampDrift { offset, rate } => ym + offset + rate * t,
                    Form::Rounding { q } => q * (ym / q).round(),
                    Form::Slits { q, errors } => {
                        let i = (ym / q).round();
                        q * i + errors[(i as i64).rem_euclid(errors.len() as i64) as usize]
                    }
                    _ => ym,
                };
            }
            let y_meas = y_scale * (ym + noise_gain * sigma * meas_noise[k]);
            y_data.push(y_meas);
            // The drive (data units).
            let u = if closed {
                let e = y_scale * r[k] - y_meas;
                ctrl_e = [e, ctrl_e[0], ctrl_e[1]];
                let mut u = num.iter().zip(&ctrl_e).map(|(b, e)| b * e).sum::<f64>();
                if den.len() == 3 {
                    u -= den[1] * ctrl_u[0];
                }
                ctrl_u = [u, ctrl_u[0]];
                u
            } else {
                u_scale * r[k]
            };
            u_data.push(u);
            let un = u / u_scale;
            for _ in 0..oversample {
                // Input-side effects in series, on the normalised drive.
                let mut f = un;
                let du = f - prev_in;
                prev_in = f;
                for (_, form) in &forms {
                    f = match form {
                        Form::PrandtlIshlinskii { h, r, w } => {
                            let mut y = 0.0;
                            for i in 0..8 {
                                plays[i] = plays[i].clamp(f - r[i], f + r[i]);
                                y += w[i] * plays[i];
                            }
                            (1.0 - h) * f + h * y
                        }
                        Form::BoucWen2 { h, beta, gamma } => {
                            // Explicit steps small enough for the loop's rate.
                            let pieces = (beta.max(gamma.abs()) * du.abs() * z_bw.abs().max(1.0)
                                / 0.05)
                                .ceil()
                                .clamp(1.0, 1e5);
                            let d = du / pieces;
                            for _ in 0..pieces as usize {
                                z_bw += d
                                    - beta * d.abs() * z_bw.abs() * z_bw
                                    - gamma * d * z_bw * z_bw;
                            }
                            (1.0 - h) * f + h * z_bw
                        }
                        Form::LogCreep { gamma } => {
                            let mut y = f;
                            for i in 0..8 {
                                creep[i] += (f - creep[i]) * (1.0 - (-dt / creep_tau[i]).exp());
                                y += gamma / 8.0 * creep[i];
                            }
                            y
                        }
                        Form::Delay { d0, a, f: fd } => {
                            hist.push(f);
                            let d = (d0 + a * (2.0 * PI * fd * t).sin()) * oversample as f64;
                            let pos = hist.len() as f64 - 1.0 - d;
                            if pos <= 0.0 {
                                hist[0]
                            } else {
                                let i = pos.floor() as usize;
                                let fr = pos - i as f64;
                                let v =
                                    hist[i] * (1.0 - fr) + hist[(i + 1).min(hist.len() - 1)] * fr;
                                if hist.len() > 64 * oversample {
                                    hist.drain(..hist.len() - 32 * oversample);
                                }
                                v
                            }
                        }
                        Form::Saturation { lo, hi, soft } => {
                            if *soft {
                                let (m, h) = (0.5 * (hi + lo), 0.5 * (hi - lo));
                                m + h * ((f - m) / h).tanh()
                            } else {
                                f.clamp(*lo, *hi)
                            }
                        }
                        Form::Play { w } => {
                            play = play.clamp(f - w / 2.0, f + w / 2.0);
                            play
                        }
                        Form::PositionGain { g1, g2 } => {
                            let x = s[0];
                            f * (1.0 + g1 * x + g2 * x * x)
                        }
                        _ => f,
                    };
                }
                // The presliding state of Dahl and LuGre friction relaxes far faster
                // than the mechanics: advanced exactly over the sub-step for the
                // velocity at its start, dz/dt = λ(z_eq − z), then held.
                let v0 = s.get(1).copied().unwrap_or(0.0);
                for (_, form) in &forms {
                    let (z_eq, lambda) = match form {
                        Form::Dahl { fc, sigma } => (fc * v0.signum(), sigma * v0.abs() / fc),
                        Form::LuGre {
                            fc,
                            fs: fst,
                            vs,
                            s0,
                        } => {
                            let gv = fc + (fst - fc) * (-(v0 / vs).powi(2)).exp();
                            (gv * v0.signum() / s0, s0 * v0.abs() / gv)
                        }
                        _ => continue,
                    };
                    fric_z = z_eq + (fric_z - z_eq) * (-lambda * dt).exp();
                }
                // RK4 on the linear states, the friction state held.
                let z = fric_z;
                let deriv = |st: &[f64]| -> Vec<f64> {
                    let (x, v) = (st[0], st.get(1).copied().unwrap_or(0.0));
                    let mut force = 0.0;
                    for (_, form) in &forms {
                        match form {
                            Form::Dahl { .. } => force -= z,
                            Form::LuGre { s0, .. } => force -= s0 * z,
                            Form::Stribeck {
                                fc,
                                fs: fst,
                                vs,
                                fv,
                                veps,
                            } => {
                                force -= (fc + (fst - fc) * (-(v / vs).powi(2)).exp())
                                    * (v / veps).tanh()
                                    + fv * v;
                            }
                            Form::PeriodicForce {
                                f: fp,
                                amps,
                                phases,
                            } => {
                                force += (0..3)
                                    .map(|h| {
                                        amps[h]
                                            * (2.0 * PI * (h + 1) as f64 * fp * t + phases[h]).sin()
                                    })
                                    .sum::<f64>();
                            }
                            Form::Cogging { pitch, amp, phase } => {
                                force += amp * (2.0 * PI * x / pitch + phase).sin()
                            }
                            _ => {}
                        }
                    }
                    let mut d = vec![0.0; st.len()];
                    for i in 0..st.len() {
                        d[i] =
                            a[i].iter().zip(st).map(|(aij, sj)| aij * sj).sum::<f64>() + b[i] * f;
                    }
                    if st.len() > 1 {
                        d[1] += force / plant.m1();
                    } else {
                        d[0] += force * b[0];
                    }
                    d
                };
                let add = |p: &[f64], q: &[f64], h: f64| -> Vec<f64> {
                    p.iter().zip(q).map(|(a, b)| a + h * b).collect()
                };
                let k1 = deriv(&s);
                let k2 = deriv(&add(&s, &k1, 0.5 * dt));
                let k3 = deriv(&add(&s, &k2, 0.5 * dt));
                let k4 = deriv(&add(&s, &k3, dt));
                for i in 0..dim {
                    s[i] += dt / 6.0 * (k1[i] + 2.0 * k2[i] + 2.0 * k3[i] + k4[i]);
                }
            }
            if !s.iter().all(|v| v.is_finite() && v.abs() < 1e6) {
                return Err(DataError::new(
                    "scenario",
                    format!("scenario {seed} diverged at sample {k} ({plant:?}, {forms:?})"),
                    "draw another seed",
                ));
            }
        }
        Ok((u_data, y_data))
    };
    let (u_data, y_data) = simulate(&forms, 1.0)?;
    let visibility = if with_visibility {
        // The record's forms with those not `kept(j)` taken out (slit
        // errors: the encoder's rounding kept, as in the nominal).
        let without = |kept: &dyn Fn(usize) -> bool| -> Vec<(&str, Form)> {
            forms
                .iter()
                .enumerate()
                .filter_map(|(j, (e, f))| match f {
                    _ if kept(j) => Some((*e, f.clone())),
                    Form::Slits { q, .. } => Some((*e, Form::Rounding { q: *q })),
                    _ => None,
                })
                .collect()
        };
        // The same record without its effects, with and without the noise.
        let effect_free = without(&|_| false);
        let (u0, y0) = simulate(&effect_free, 1.0)?;
        let (uq, yq) = simulate(&effect_free, 0.0)?;
        // From sample `from` on.
        let ratio = |from: usize, with: &[f64], without: &[f64], quiet: &[f64]| {
            let rms = |a: &[f64], b: &[f64]| {
                let (a, b) = (&a[from..], &b[from..]);
                (a.iter().zip(b).map(|(x, y)| (x - y) * (x - y)).sum::<f64>() / a.len() as f64)
                    .sqrt()
            };
            rms(with, without) / rms(without, quiet).max(f64::MIN_POSITIVE)
        };
        let of_part = |from: usize| {
            let v = ratio(from, &y_data, &y0, &yq);
            if closed {
                v.max(ratio(from, &u_data, &u0, &uq))
            } else {
                v
            }
        };
        let holdout = crate::diagnose::Options::default().holdout;
        let held_out_from =
            (((1.0 - holdout) * y_data.len() as f64).round() as usize).min(n.saturating_sub(1));
        let noise_rms = |a: &[f64], b: &[f64]| {
            let (a, b) = (&a[held_out_from..], &b[held_out_from..]);
            (a.iter().zip(b).map(|(x, y)| (x - y) * (x - y)).sum::<f64>() / a.len() as f64)
                .sqrt()
                .max(f64::MIN_POSITIVE)
        };
        Some((
            Visibility {
                whole: of_part(0),
                held_out: of_part(held_out_from),
                calibrated: 0.0,
                per_effect: Vec::new(),
            },
            // The quiet records (with and without the effects; where two or
            // more are hidden, without each one in turn) and the held-out
            // noise rms per compared output (y; u in a closed loop).
            (
                simulate(&forms, QUIET_NOISE)?,
                simulate(&effect_free, QUIET_NOISE)?,
                [noise_rms(&y0, &yq), noise_rms(&u0, &uq)],
                if forms.len() > 1 {
                    (0..forms.len())
                        .map(|i| {
                            let but = without(&|j| j != i);
                            Ok((forms[i].0.to_string(), simulate(&but, QUIET_NOISE)?))
                        })
                        .collect::<Result<Vec<_>, DataError>>()?
                } else {
                    Vec::new()
                },
            ),
        ))
    } else {
        None
    };
    // The nominal graph.
    let (na, nb, nc) = nom.matrices(&[]);
    let nb: Vec<Vec<f64>> = nb
        .iter()
        .map(|v| vec![v * nominal_gain / u_scale])
        .collect();
    let nc = vec![nc.iter().map(|v| v * y_scale).collect::<Vec<f64>>()];
    let slit = forms.iter().find_map(|(_, f)| match f {
        Form::Slits { q, .. } => Some(q * y_scale),
        _ => None,
    });
    let mut blocks = String::new();
    let mut conns = String::new();
    let plant_out = if let Some(q) = slit {
        blocks += &format!("  - {{ name: encoder, type: quantizer, lsb: {q:?} }}\n");
        conns += "  - { from: plant.y, to: encoder.u }\n";
        "encoder.y"
    } else {
        "plant.y"
    };
    blocks += &format!(
        "  - {{ name: plant, type: state_space, a: {}, b: {}, c: {}, discretisation: zoh }}\n",
        yaml_matrix(&na),
        yaml_matrix(&nb),
        yaml_matrix(&nc)
    );
    let columns_of = |u: Vec<f64>, y: Vec<f64>| {
        let mut c = Vec::new();
        if closed {
            c.push((
                "r".to_string(),
                r.iter().map(|v| v * y_scale).collect::<Vec<f64>>(),
            ));
        }
        c.push(("u".to_string(), u));
        c.push(("y".to_string(), y));
        c
    };
    if closed {
        blocks += "  - { name: reference, type: data_column, column: r }\n  - { name: error, type: sum, signs: \"+-\" }\n";
        blocks += &format!(
            "  - {{ name: controller, type: transfer_function, discrete: true, num: [{}], den: [{}] }}\n",
            num.iter()
                .map(|v| format!("{v:?}"))
                .collect::<Vec<_>>()
                .join(", "),
            den.iter()
                .map(|v| format!("{v:?}"))
                .collect::<Vec<_>>()
                .join(", ")
        );
        conns += &format!(
            "  - {{ from: reference.y, to: error.in0 }}\n  - {{ from: {plant_out}, to: error.in1 }}\n  - {{ from: error.y, to: controller.u }}\n  - {{ from: controller.y, to: plant.u }}\n"
        );
    } else {
        blocks += "  - { name: drive, type: data_column, column: u }\n";
        conns += "  - { from: drive.y, to: plant.u }\n";
    }
    let columns = columns_of(u_data, y_data);
    let mut compare = format!("  - {{ signal: {plant_out}, column: y }}\n");
    if closed {
        compare += "  - { signal: controller.y, column: u }\n";
    }
    let nominal_yaml = format!(
        "title: scenario {seed} ({plant_kind}, {loop_kind}, {excitation_kind}, {noise_kind} noise, nominal {nominal_kind})\nbase_rate_hz: {fs:?}\nduration_s: {t_len:?}\nblocks:\n{blocks}connections:\n{conns}compare:\n{compare}"
    );
    let data = Dataset::from_columns(format!("scenario {seed}"), fs, 0.0, columns)?;
    let visibility = match visibility {
        None => None,
        Some((mut v, ((uw, yw), (ue, ye), noise, without_each))) => {
            // Held-out mean square per output after the calibration alone.
            let calibrated_ms = |u: Vec<f64>, y: Vec<f64>| -> Result<Vec<f64>, DataError> {
                let quiet = Dataset::from_columns(
                    format!("scenario {seed}, quiet"),
                    fs,
                    0.0,
                    columns_of(u, y),
                )?;
                let spec =
                    nanomotion_core::graph::GraphSpec::from_yaml(&nominal_yaml, "scenario.yaml")
                        .map_err(|e| {
                            DataError::new(
                                "scenario",
                                e.to_string(),
                                "a bug: the nominal graph must load",
                            )
                        })?;
                let opts = crate::diagnose::Options {
                    max_effects: 0,
                    threads: 1,
                    ..Default::default()
                };
                let report = crate::diagnose::diagnose(&spec, &quiet, &opts).map_err(|e| {
                    DataError::new(
                        "scenario",
                        e.to_string(),
                        "a bug: calibration of a scenario must run",
                    )
                })?;
                Ok(report
                    .final_scores
                    .per_output
                    .iter()
                    .map(|o| o.holdout_rms * o.holdout_rms)
                    .collect())
            };
            if !forms.is_empty() {
                let with = calibrated_ms(uw, yw)?;
                // What the calibrated record with every effect leaves beyond
                // the one without `without`'s, over the noise.
                let beyond = |without: &[f64]| {
                    with.iter()
                        .zip(without)
                        .zip(noise)
                        .map(|((w, wo), sigma)| (w - wo).max(0.0).sqrt() / sigma)
                        .fold(0.0, f64::max)
                };
                v.calibrated = beyond(&calibrated_ms(ue, ye)?);
                v.per_effect = if without_each.is_empty() {
                    forms
                        .iter()
                        .map(|(e, _)| (e.to_string(), v.calibrated))
                        .collect()
                } else {
                    without_each
                        .into_iter()
                        .map(|(e, (u, y))| Ok((e, beyond(&calibrated_ms(u, y)?))))
                        .collect::<Result<_, DataError>>()?
                };
            }
            Some(v)
        }
    };
    let truth = if forms.is_empty() {
        "no hidden effect".to_string()
    } else {
        forms
            .iter()
            .map(|(e, f)| format!("{e}: {}", f.describe()))
            .collect::<Vec<_>>()
            .join("; ")
    };
    Ok((
        Scenario {
            record: Record {
                nominal_yaml,
                data,
                hidden: hidden.iter().map(|e| e.to_string()).collect(),
                truth,
            },
            family,
        },
        visibility,
    ))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn scenarios_are_deterministic_and_cover_the_families() {
        let a = draw(3).unwrap();
        let b = draw(3).unwrap();
        assert_eq!(a.record.nominal_yaml, b.record.nominal_yaml);
        assert_eq!(a.record.data.column("y"), b.record.data.column("y"));
        let mut plants = std::collections::BTreeSet::new();
        let mut loops = std::collections::BTreeSet::new();
        for seed in 0..60 {
            let s = draw(seed).unwrap();
            plants.insert(s.family.plant);
            loops.insert(s.family.loop_kind);
            assert!(
                s.record
                    .data
                    .column("y")
                    .unwrap()
                    .iter()
                    .all(|v| v.is_finite())
            );
        }
        assert_eq!(plants.len(), 5, "{plants:?}");
        assert_eq!(loops.len(), 3, "{loops:?}");
    }

    #[test]
    fn visibility_is_zero_without_an_effect_and_leaves_the_record_unchanged() {
        // Effect-free: the record without its effects is the record itself,
        // so what the effects change is exactly zero.
        for seed in (0..40).filter(|&s| labels(s).0.is_empty()).take(3) {
            let v = visibility(seed).unwrap();
            assert_eq!((v.whole, v.held_out), (0.0, 0.0), "seed {seed}");
        }
        // With effects: computing the visibility draws the same record.
        let seed = (0..40).find(|&s| !labels(s).0.is_empty()).unwrap();
        let (with, v) = draw_with(seed, true).unwrap();
        let plain = draw(seed).unwrap();
        assert_eq!(with.record.data.column("y"), plain.record.data.column("y"));
        assert!(
            v.as_ref().is_some_and(|v| v.whole.is_finite()
                && v.whole > 0.0
                && v.held_out.is_finite()
                && v.held_out >= 0.0),
            "{v:?}"
        );
        // One entry per hidden effect, in the record's order; one effect
        // alone is the record's calibrated visibility.
        let v = v.unwrap();
        let names: Vec<&str> = v.per_effect.iter().map(|(e, _)| e.as_str()).collect();
        assert_eq!(names, labels(seed).0, "{v:?}");
        assert!(v.per_effect.iter().all(|(_, x)| x.is_finite() && *x >= 0.0));
        if names.len() == 1 {
            assert_eq!(v.per_effect[0].1, v.calibrated);
        }
    }

    #[test]
    fn the_nominal_model_of_an_effect_free_exact_record_explains_it_to_the_noise() {
        // A record with nothing hidden and an exact nominal: the nominal graph's
        // output matches the data to the noise level (the simulation and the
        // graph agree), in open and closed loop.
        let (mut checked, mut closed) = (0, 0);
        for seed in 0..2000 {
            let (hidden, family) = labels(seed);
            if !hidden.is_empty() || family.nominal != "exact" || family.noise != "white" {
                continue;
            }
            let s = draw(seed).unwrap();
            assert_eq!(s.family, family);
            let spec = nanomotion_core::graph::GraphSpec::from_yaml(
                &s.record.nominal_yaml,
                "scenario.yaml",
            )
            .unwrap();
            let data = std::sync::Arc::new(s.record.data.clone());
            let mut ev = crate::fit::Evaluator::new(spec, &data, &[], 0).unwrap();
            assert!(ev.run(&[], data.len()));
            let r = ev.residual(0, 0..data.len());
            let y = data.column("y").unwrap();
            let ry = (r.iter().map(|v| v * v).sum::<f64>() / r.len() as f64).sqrt();
            let yy = (y.iter().map(|v| v * v).sum::<f64>() / y.len() as f64).sqrt();
            // The noise is 0.03–0.3 % of the stroke (more where a loop feeds it back).
            assert!(
                ry < 0.02 * yy,
                "seed {seed} {:?}: residual rms {ry:.3e} vs signal {yy:.3e}",
                s.family
            );
            checked += 1;
            closed += usize::from(s.family.loop_kind != "open");
            if checked == 8 {
                break;
            }
        }
        assert!(
            checked == 8 && closed >= 2,
            "{checked} records checked, {closed} in closed loop"
        );
    }
}
