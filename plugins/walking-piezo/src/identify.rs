//! Identification of the Ch. 4 model parameters from stage data (Sec. 4.4.1, (4.20)).
//!
//! The thesis records the stage position x (encoder) and the housing position y
//! (capacitive sensor) over periods of several waveforms at one drive frequency,
//! averages over periods, removes the means (relative sensors) and minimises
//!
//! f(P) = Σ_w [ rms(r̄_w − r̂_w(P)) + |r̄_w(t_0) − r̂_w(P, t_0)| ],  r = {x, y}   (4.20)
//!
//! over P ⊂ {d_x, d_y, c_x1..4, c_y1..4, μ} with a particle swarm (the global
//! method that worked best in the thesis) followed by local refinement — the
//! y-parameters first, then x.
//!
//! Optimisers: our own particle swarm and Nelder–Mead on the unit box (parameters
//! mapped linearly to their bounds), drawing from `nanomotion_core::rng::Rng`. We
//! do not use `argmin`'s swarm because its random numbers come from `rand`, whose
//! streams change between versions, and identification results must be
//! reproducible bit for bit from a seed (the reason `rng.rs` exists); the two
//! optimisers are ~100 lines.

use crate::stage::{StageParams, WalkingPiezoStage};
use crate::waveform::SinusoidalWaveform;
use nanomotion_core::ParamError;
use nanomotion_core::rng::Rng;

/// A parameter to identify.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum IdParam {
    /// d_x of both pairs (N·s/m).
    DampingX,
    /// d_y of both pairs (N·s/m).
    DampingY,
    /// c_x of stack 0..=3 (m/V).
    Cx(usize),
    /// c_y of stack 0..=3 (m/V).
    Cy(usize),
    /// Nominal μ (−).
    Mu,
}

impl IdParam {
    /// Set this parameter in `p`.
    pub fn set(self, p: &mut StageParams, v: f64) {
        match self {
            IdParam::DampingX => p.leg_damping_x_ns_m = [v; 2],
            IdParam::DampingY => p.leg_damping_y_ns_m = [v; 2],
            IdParam::Cx(i) => p.c_x_m_v[i] = v,
            IdParam::Cy(i) => p.c_y_m_v[i] = v,
            IdParam::Mu => p.mu = v,
        }
    }
    /// Read this parameter from `p`.
    pub fn get(self, p: &StageParams) -> f64 {
        match self {
            IdParam::DampingX => p.leg_damping_x_ns_m[0],
            IdParam::DampingY => p.leg_damping_y_ns_m[0],
            IdParam::Cx(i) => p.c_x_m_v[i],
            IdParam::Cy(i) => p.c_y_m_v[i],
            IdParam::Mu => p.mu,
        }
    }
}

/// One recorded experiment: a waveform at a drive frequency, and the measured
/// period-averaged, mean-removed stage (x) and housing (y) positions over one
/// period, sampled every `dt` from the start of the period.
#[derive(Debug, Clone, PartialEq)]
pub struct Record {
    /// The waveform (with its drive frequency).
    pub waveform: SinusoidalWaveform,
    /// Sample period (s).
    pub dt: f64,
    /// x̄ over one period (m), mean removed.
    pub x: Vec<f64>,
    /// ȳ over one period (m), mean removed.
    pub y: Vec<f64>,
}

/// How a record is simulated (and averaged).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Protocol {
    /// Periods run before recording (settling).
    pub settle_periods: usize,
    /// Periods averaged.
    pub periods: usize,
    /// Simulation step (s).
    pub dt: f64,
}

/// Simulate `waveform` on a stage with parameters `p` (seed for its μ variation)
/// and return the period average (x̄, ȳ), means removed: exactly what (4.20)
/// compares. The stage drifts by one step per period; the average is taken of
/// the position relative to the start of each period.
pub fn simulate_record(
    p: &StageParams,
    waveform: &SinusoidalWaveform,
    proto: &Protocol,
    seed: u64,
) -> Result<Record, ParamError> {
    let mut s = WalkingPiezoStage::new(p.clone(), proto.dt, seed)?;
    let per = (1.0 / (waveform.f_alpha_hz.abs() * proto.dt))
        .round()
        .max(1.0) as usize;
    let mut x = vec![0.0; per];
    let mut y = vec![0.0; per];
    let mut k = 0usize;
    let t = |k: usize| k as f64 * proto.dt;
    for _ in 0..proto.settle_periods * per {
        let _ = s.step(&waveform.voltages(waveform.alpha(t(k))), 0.0);
        k += 1;
    }
    for _ in 0..proto.periods {
        let x0 = s.signals().x_s;
        for j in 0..per {
            let sig = s.signals();
            x[j] += sig.x_s - x0;
            y[j] += sig.y_h;
            let _ = s.step(&waveform.voltages(waveform.alpha(t(k))), 0.0);
            k += 1;
        }
    }
    let n = proto.periods.max(1) as f64;
    for v in [&mut x, &mut y] {
        v.iter_mut().for_each(|e| *e /= n);
        let mean = v.iter().sum::<f64>() / v.len() as f64;
        v.iter_mut().for_each(|e| *e -= mean);
    }
    Ok(Record {
        waveform: *waveform,
        dt: proto.dt,
        x,
        y,
    })
}

/// Which signals (4.20) compares.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Channels {
    /// Housing position only (the thesis's first stage).
    Y,
    /// Stage position only (second stage).
    X,
    /// Both.
    Both,
}

/// rms(a − b) + |a(t_0) − b(t_0)|, the terms of (4.20).
fn term(a: &[f64], b: &[f64]) -> f64 {
    let n = a.len().min(b.len());
    if n == 0 {
        return 0.0;
    }
    let rms = (a.iter().zip(b).map(|(u, v)| (u - v) * (u - v)).sum::<f64>() / n as f64).sqrt();
    rms + (a[0] - b[0]).abs()
}

/// The objective (4.20) of parameters `p` against `records`.
pub fn objective(p: &StageParams, records: &[Record], proto: &Protocol, channels: Channels) -> f64 {
    let mut f = 0.0;
    for r in records {
        match simulate_record(p, &r.waveform, proto, 0) {
            Ok(m) => {
                if channels != Channels::Y {
                    f += term(&r.x, &m.x);
                }
                if channels != Channels::X {
                    f += term(&r.y, &m.y);
                }
            }
            Err(_) => return f64::INFINITY,
        }
    }
    f
}

/// Settings of the two-phase optimisation.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct OptimiserSettings {
    /// Particles of the swarm.
    pub particles: usize,
    /// Swarm iterations.
    pub swarm_iterations: usize,
    /// Nelder–Mead evaluations (local refinement).
    pub local_evaluations: usize,
    /// Seed of the swarm.
    pub seed: u64,
}

impl Default for OptimiserSettings {
    fn default() -> Self {
        Self {
            particles: 16,
            swarm_iterations: 20,
            local_evaluations: 150,
            seed: 1,
        }
    }
}

/// Result of a minimisation on the unit box.
#[derive(Debug, Clone, PartialEq)]
pub struct Minimum {
    /// Arg-min in unit coordinates.
    pub z: Vec<f64>,
    /// Objective value.
    pub f: f64,
    /// Objective evaluations used.
    pub evaluations: usize,
}

/// Particle swarm (inertia 0.72, acceleration 1.49/1.49) on [0, 1]^n.
pub fn particle_swarm(
    n: usize,
    f: &mut dyn FnMut(&[f64]) -> f64,
    s: &OptimiserSettings,
) -> Minimum {
    let mut rng = Rng::new(s.seed);
    let np = s.particles.max(2);
    let mut x: Vec<Vec<f64>> = (0..np)
        .map(|_| (0..n).map(|_| rng.uniform()).collect())
        .collect();
    let mut v: Vec<Vec<f64>> = (0..np)
        .map(|_| (0..n).map(|_| 0.1 * (rng.uniform() - 0.5)).collect())
        .collect();
    let mut pbest = x.clone();
    let mut pf: Vec<f64> = x.iter().map(|p| f(p)).collect();
    let mut evaluations = np;
    let mut g = (0..np)
        .min_by(|&a, &b| pf[a].total_cmp(&pf[b]))
        .unwrap_or(0);
    for _ in 0..s.swarm_iterations {
        for i in 0..np {
            for d in 0..n {
                let (r1, r2) = (rng.uniform(), rng.uniform());
                v[i][d] = (0.72 * v[i][d]
                    + 1.49 * r1 * (pbest[i][d] - x[i][d])
                    + 1.49 * r2 * (pbest[g][d] - x[i][d]))
                    .clamp(-0.25, 0.25);
                x[i][d] = (x[i][d] + v[i][d]).clamp(0.0, 1.0);
            }
            let fx = f(&x[i]);
            evaluations += 1;
            if fx < pf[i] {
                pf[i] = fx;
                pbest[i] = x[i].clone();
                if fx < pf[g] {
                    g = i;
                }
            }
        }
    }
    Minimum {
        z: pbest[g].clone(),
        f: pf[g],
        evaluations,
    }
}

/// Nelder–Mead from `z0` (initial simplex step `step`), clamped to [0, 1]^n.
pub fn nelder_mead(
    z0: &[f64],
    step: f64,
    f: &mut dyn FnMut(&[f64]) -> f64,
    max_evaluations: usize,
) -> Minimum {
    let n = z0.len();
    let clamp = |z: Vec<f64>| {
        z.into_iter()
            .map(|v| v.clamp(0.0, 1.0))
            .collect::<Vec<f64>>()
    };
    let mut simplex: Vec<(Vec<f64>, f64)> = Vec::with_capacity(n + 1);
    simplex.push((z0.to_vec(), f(z0)));
    for d in 0..n {
        let mut z = z0.to_vec();
        z[d] = if z[d] + step <= 1.0 {
            z[d] + step
        } else {
            z[d] - step
        };
        let fz = f(&z);
        simplex.push((z, fz));
    }
    let mut evaluations = n + 1;
    while evaluations < max_evaluations {
        simplex.sort_by(|a, b| a.1.total_cmp(&b.1));
        let best = simplex[0].1;
        let worst = simplex[n].1;
        if (worst - best).abs() <= 1e-12 * best.abs().max(1e-300) {
            break;
        }
        let centroid: Vec<f64> = (0..n)
            .map(|d| simplex[..n].iter().map(|p| p.0[d]).sum::<f64>() / n as f64)
            .collect();
        let along = |t: f64| {
            clamp(
                (0..n)
                    .map(|d| centroid[d] + t * (simplex[n].0[d] - centroid[d]))
                    .collect(),
            )
        };
        let xr = along(-1.0);
        let fr = f(&xr);
        evaluations += 1;
        if fr < simplex[0].1 {
            let xe = along(-2.0);
            let fe = f(&xe);
            evaluations += 1;
            simplex[n] = if fe < fr { (xe, fe) } else { (xr, fr) };
        } else if fr < simplex[n - 1].1 {
            simplex[n] = (xr, fr);
        } else {
            let xc = if fr < simplex[n].1 {
                along(-0.5)
            } else {
                along(0.5)
            };
            let fc = f(&xc);
            evaluations += 1;
            if fc < simplex[n].1.min(fr) {
                simplex[n] = (xc, fc);
            } else {
                // Shrink towards the best.
                let b = simplex[0].0.clone();
                for p in simplex.iter_mut().skip(1) {
                    let z = clamp((0..n).map(|d| b[d] + 0.5 * (p.0[d] - b[d])).collect());
                    let fz = f(&z);
                    *p = (z, fz);
                }
                evaluations += n;
            }
        }
    }
    simplex.sort_by(|a, b| a.1.total_cmp(&b.1));
    let (z, f) = simplex.swap_remove(0);
    Minimum { z, f, evaluations }
}

/// Result of [`identify`].
#[derive(Debug, Clone, PartialEq)]
pub struct Identified {
    /// The base parameters with the identified values set.
    pub params: StageParams,
    /// Objective after the swarm.
    pub cost_global: f64,
    /// Objective after local refinement.
    pub cost: f64,
    /// Objective evaluations (simulations of all records).
    pub evaluations: usize,
}

/// Identify `which` (each with bounds `[lo, hi]`) in `base` from `records` by
/// minimising (4.20) on `channels`: particle swarm, then Nelder–Mead. The model
/// used for identification has no μ variation (a constant μ per the thesis).
pub fn identify(
    base: &StageParams,
    which: &[(IdParam, f64, f64)],
    records: &[Record],
    proto: &Protocol,
    channels: Channels,
    settings: &OptimiserSettings,
) -> Result<Identified, ParamError> {
    for (i, &(_, lo, hi)) in which.iter().enumerate() {
        nanomotion_core::block::check::ordered(
            &format!("bounds[{i}].lo"),
            lo,
            &format!("bounds[{i}].hi"),
            hi,
        )?;
    }
    let base = base.clone().without_mu_variation();
    base.validate(proto.dt)?;
    let to_params = |z: &[f64]| {
        let mut p = base.clone();
        for (k, &(id, lo, hi)) in which.iter().enumerate() {
            id.set(&mut p, lo + (hi - lo) * z[k]);
        }
        p
    };
    let mut f = |z: &[f64]| objective(&to_params(z), records, proto, channels);
    tracing::info!(
        target: "walking_piezo::identify",
        parameters = which.len(),
        records = records.len(),
        particles = settings.particles,
        iterations = settings.swarm_iterations,
        "identification: particle swarm"
    );
    let global = particle_swarm(which.len(), &mut f, settings);
    tracing::info!(
        target: "walking_piezo::identify",
        cost = global.f,
        evaluations = global.evaluations,
        "identification: swarm done; Nelder–Mead refinement"
    );
    let local = nelder_mead(&global.z, 0.05, &mut f, settings.local_evaluations);
    let best = if local.f <= global.f { &local } else { &global };
    tracing::info!(
        target: "walking_piezo::identify",
        cost = best.f,
        evaluations = global.evaluations + local.evaluations,
        "identification done"
    );
    Ok(Identified {
        params: to_params(&best.z),
        cost_global: global.f,
        cost: best.f,
        evaluations: global.evaluations + local.evaluations,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn optimisers_find_the_minimum_of_a_quadratic() {
        let target = [0.3, 0.7, 0.55];
        let mut f = |z: &[f64]| {
            z.iter()
                .zip(&target)
                .map(|(a, b)| (a - b) * (a - b))
                .sum::<f64>()
        };
        let g = particle_swarm(
            3,
            &mut f,
            &OptimiserSettings {
                particles: 20,
                swarm_iterations: 40,
                local_evaluations: 0,
                seed: 4,
            },
        );
        assert!(g.f < 1e-3, "{g:?}");
        let l = nelder_mead(&g.z, 0.05, &mut f, 400);
        assert!(l.f < 1e-12, "{l:?}");
        // Same seed, same result.
        let g2 = particle_swarm(
            3,
            &mut f,
            &OptimiserSettings {
                particles: 20,
                swarm_iterations: 40,
                local_evaluations: 0,
                seed: 4,
            },
        );
        assert_eq!(g, g2);
    }

    #[test]
    fn term_is_rms_plus_start_mismatch() {
        assert_eq!(term(&[1.0, 1.0], &[0.0, 0.0]), 2.0);
        assert_eq!(term(&[0.0, 2.0], &[0.0, 0.0]), 2f64.sqrt());
    }
}
