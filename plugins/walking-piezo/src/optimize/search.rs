//! Bounded global search with `argmin` — simulated annealing and particle swarm —
//! followed by a Nelder–Mead refinement, in resumable chunks.
//!
//! Each phase runs in chunks; a chunk is one complete `argmin` run started from the
//! phase's incumbent (the best point found so far) with its own seed derived from
//! the run seed, the phase and the chunk index. After every chunk the whole state of
//! the search is the small [`SearchState`] (incumbents as exact bit patterns,
//! evaluation counts), so a run stopped after any chunk and resumed from its state
//! gives the same bits as an uninterrupted one.
//!
//! - **Simulated annealing** (`argmin::solver::simulatedannealing`): exponential
//!   cooling from `temperature` over the whole phase (chunk c starts at
//!   T₀·0.02^{c/C}); a move perturbs 1–4 random coordinates by N(0, σ²) with
//!   σ = `step_v`·T/T₀ (at least 1 % of it), reflected into the bounds. The move's
//!   random numbers are a hash of (chunk seed, point, temperature), so a move is a
//!   pure function of its inputs; acceptance draws from the solver's seeded
//!   `Xoshiro256PlusPlus`.
//! - **Particle swarm** (`argmin::solver::particleswarm`): a swarm of `particles`
//!   around the incumbent (the incumbent itself plus points N(incumbent, `spread_v`²),
//!   clipped), seeded `Xoshiro256PlusPlus` for the velocity updates.
//! - **Nelder–Mead** (`argmin::solver::neldermead`): restarted from the incumbent
//!   each chunk with an axis simplex of edge `step_v`·2^{−c}; points outside the
//!   bounds are evaluated at their projection.
//!
//! SA and PSO both start from the same point; the refinement starts from the better
//! of the two (SA on ties).

use argmin::core::{CostFunction, Error as ArgminError, Executor};
use argmin::solver::neldermead::NelderMead;
use argmin::solver::particleswarm::{Particle, ParticleSwarm};
use argmin::solver::simulatedannealing::{Anneal, SATempFunc, SimulatedAnnealing};
use nalgebra::DVector;
use nanomotion_core::rng::{Rng, derive_seed, splitmix64};
use rand_xoshiro::Xoshiro256PlusPlus;
use rand_xoshiro::rand_core::SeedableRng;
use serde::{Deserialize, Serialize};
use std::cell::{Cell, RefCell};
use std::ops::ControlFlow;

/// Budget of the simulated annealing phase.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct SaBudget {
    /// Chunks (resumable units).
    pub chunks: u32,
    /// Iterations (one evaluation each) per chunk.
    pub iterations: u32,
    /// Initial temperature T₀ (cost units, µm/s).
    pub temperature: f64,
    /// Move size σ at T₀ (V).
    pub step_v: f64,
}

/// Budget of the particle swarm phase.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct PsoBudget {
    /// Chunks (resumable units).
    pub chunks: u32,
    /// Swarm iterations per chunk (`particles` evaluations each).
    pub iterations: u32,
    /// Particles.
    pub particles: u32,
    /// Spread of the initial swarm around the incumbent (V).
    pub spread_v: f64,
}

/// Budget of the Nelder–Mead refinement.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct LocalBudget {
    /// Chunks (restarts).
    pub chunks: u32,
    /// Iterations per chunk.
    pub iterations: u32,
    /// Simplex edge of the first chunk (V), halved each chunk.
    pub step_v: f64,
}

/// Budgets of all phases (a phase with 0 chunks is skipped).
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct Budget {
    /// Simulated annealing.
    pub sa: SaBudget,
    /// Particle swarm.
    pub pso: PsoBudget,
    /// Local refinement.
    pub local: LocalBudget,
}

impl Default for SaBudget {
    fn default() -> Self {
        Self {
            chunks: 10,
            iterations: 300,
            temperature: 2.0,
            step_v: 4.0,
        }
    }
}

impl Default for PsoBudget {
    fn default() -> Self {
        Self {
            chunks: 10,
            iterations: 15,
            particles: 20,
            spread_v: 6.0,
        }
    }
}

impl Default for LocalBudget {
    fn default() -> Self {
        Self {
            chunks: 3,
            iterations: 500,
            step_v: 2.0,
        }
    }
}

impl Budget {
    /// Scale every phase's iterations by `factor` (at least 1 iteration per chunk).
    pub fn scaled(mut self, factor: f64) -> Self {
        let s = |n: u32| ((f64::from(n) * factor).round().max(1.0)) as u32;
        self.sa.iterations = s(self.sa.iterations);
        self.pso.iterations = s(self.pso.iterations);
        self.local.iterations = s(self.local.iterations);
        self
    }
}

/// The phases, in order.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Phase {
    /// Simulated annealing.
    SimulatedAnnealing,
    /// Particle swarm.
    ParticleSwarm,
    /// Nelder–Mead refinement.
    Local,
}

impl Phase {
    /// Name used in seeds, files and progress.
    pub fn name(self) -> &'static str {
        match self {
            Phase::SimulatedAnnealing => "simulated_annealing",
            Phase::ParticleSwarm => "particle_swarm",
            Phase::Local => "local",
        }
    }
}

/// A point and its cost, stored as exact bit patterns (JSON numbers would not
/// round-trip every f64 through every parser); the decimal copies are for reading
/// and are rebuilt from the bits when a state is read.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(from = "IncumbentFile")]
pub struct Incumbent {
    /// Cost (decimal, informative).
    pub cost: f64,
    /// The point (decimal, informative).
    pub x: Vec<f64>,
    /// `cost.to_bits()`: authoritative.
    pub cost_bits: u64,
    /// `x[i].to_bits()`: authoritative.
    pub x_bits: Vec<u64>,
}

/// The stored form of an [`Incumbent`] (only the bit patterns are read).
#[derive(Deserialize)]
struct IncumbentFile {
    #[serde(rename = "cost")]
    _cost: serde::de::IgnoredAny,
    #[serde(rename = "x")]
    _x: serde::de::IgnoredAny,
    cost_bits: u64,
    x_bits: Vec<u64>,
}

impl From<IncumbentFile> for Incumbent {
    fn from(f: IncumbentFile) -> Self {
        let x: Vec<f64> = f.x_bits.iter().map(|b| f64::from_bits(*b)).collect();
        Self::new(&x, f64::from_bits(f.cost_bits))
    }
}

impl Incumbent {
    /// From a point and its cost.
    pub fn new(x: &[f64], cost: f64) -> Self {
        Self {
            cost,
            x: x.to_vec(),
            cost_bits: cost.to_bits(),
            x_bits: x.iter().map(|v| v.to_bits()).collect(),
        }
    }
    /// The exact point.
    pub fn point(&self) -> Vec<f64> {
        self.x_bits.iter().map(|b| f64::from_bits(*b)).collect()
    }
    /// The exact cost.
    pub fn exact_cost(&self) -> f64 {
        f64::from_bits(self.cost_bits)
    }
}

/// Progress of one phase.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct PhaseRecord {
    /// Which phase.
    pub phase: Phase,
    /// Chunks done.
    pub chunks_done: u32,
    /// Chunks planned.
    pub chunks: u32,
    /// Cost evaluations spent.
    pub evaluations: u64,
    /// Best point of this phase so far (its start point before the first chunk).
    pub best: Incumbent,
}

/// The complete, resumable state of a search.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SearchState {
    /// Run seed.
    pub seed: u64,
    /// The start point and its cost.
    pub start: Incumbent,
    /// One record per phase, in order.
    pub phases: Vec<PhaseRecord>,
}

impl SearchState {
    /// A fresh state: every phase at the start point.
    pub fn new(x0: &[f64], cost0: f64, budget: &Budget, seed: u64) -> Self {
        let start = Incumbent::new(x0, cost0);
        let rec = |phase, chunks| PhaseRecord {
            phase,
            chunks_done: 0,
            chunks,
            evaluations: 0,
            best: start.clone(),
        };
        Self {
            seed,
            phases: vec![
                rec(Phase::SimulatedAnnealing, budget.sa.chunks),
                rec(Phase::ParticleSwarm, budget.pso.chunks),
                rec(Phase::Local, budget.local.chunks),
            ],
            start,
        }
    }
    /// Every chunk of every phase done.
    pub fn finished(&self) -> bool {
        self.phases.iter().all(|p| p.chunks_done >= p.chunks)
    }
    /// The record of a phase.
    pub fn phase(&self, phase: Phase) -> &PhaseRecord {
        let i = phase as usize;
        &self.phases[i]
    }
    /// The best point of the whole search so far (the refinement's once it ran,
    /// else the better global phase, else the start).
    pub fn best(&self) -> &Incumbent {
        let mut best = &self.start;
        for p in &self.phases {
            if p.best.exact_cost() < best.exact_cost() {
                best = &p.best;
            }
        }
        best
    }
    /// Evaluations over all phases.
    pub fn evaluations(&self) -> u64 {
        self.phases.iter().map(|p| p.evaluations).sum()
    }
    /// The global phase whose best is lower (SA on ties).
    pub fn global_winner(&self) -> Phase {
        let sa = self.phase(Phase::SimulatedAnnealing).best.exact_cost();
        let pso = self.phase(Phase::ParticleSwarm).best.exact_cost();
        if pso < sa {
            Phase::ParticleSwarm
        } else {
            Phase::SimulatedAnnealing
        }
    }
}

/// Reported after every chunk.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Progress {
    /// Phase of the chunk just done.
    pub phase: Phase,
    /// Chunks done over all phases.
    pub chunks_done: u32,
    /// Chunks over all phases.
    pub chunks_total: u32,
    /// Evaluations so far.
    pub evaluations: u64,
    /// Best cost so far.
    pub best_cost: f64,
}

/// Why a search failed.
#[derive(Debug, thiserror::Error)]
pub enum SearchError {
    /// Inconsistent inputs (dimensions, bounds, budget).
    #[error("search setup: field `{field}`: {problem}")]
    Setup {
        /// The offending field.
        field: &'static str,
        /// What is wrong.
        problem: String,
    },
    /// The optimisation library reported an error.
    #[error("{phase} chunk {chunk}: {message}")]
    Solver {
        /// Phase name.
        phase: &'static str,
        /// Chunk index.
        chunk: u32,
        /// The library's message.
        message: String,
    },
}

/// The bounded problem handed to `argmin`: projects into the box, counts
/// evaluations and keeps the best evaluated point.
struct BoxProblem<'a> {
    cost: &'a dyn Fn(&[f64]) -> f64,
    lo: &'a [f64],
    hi: &'a [f64],
    seed: u64,
    step_v: f64,
    t0: f64,
    evals: Cell<u64>,
    best: RefCell<(Vec<f64>, f64)>,
}

impl BoxProblem<'_> {
    fn project(&self, x: &[f64]) -> Vec<f64> {
        x.iter()
            .zip(self.lo.iter().zip(self.hi))
            .map(|(v, (l, h))| if v.is_nan() { *l } else { v.clamp(*l, *h) })
            .collect()
    }
    fn eval(&self, x: &[f64]) -> f64 {
        let p = self.project(x);
        let c = (self.cost)(&p);
        let c = if c.is_nan() { f64::MAX } else { c };
        self.evals.set(self.evals.get() + 1);
        let mut b = self.best.borrow_mut();
        if c < b.1 {
            *b = (p, c);
        }
        c
    }
}

impl CostFunction for BoxProblem<'_> {
    type Param = DVector<f64>;
    type Output = f64;
    fn cost(&self, p: &Self::Param) -> Result<f64, ArgminError> {
        Ok(self.eval(p.as_slice()))
    }
}

impl Anneal for BoxProblem<'_> {
    type Param = DVector<f64>;
    type Output = DVector<f64>;
    type Float = f64;
    fn anneal(&self, p: &Self::Param, temp: f64) -> Result<Self::Param, ArgminError> {
        // The move's random numbers: a hash of (seed, point, temperature).
        let mut h = self.seed ^ temp.to_bits().rotate_left(17);
        for v in p.iter() {
            h ^= v.to_bits();
            splitmix64(&mut h);
            h = splitmix64(&mut h);
        }
        let mut r = Rng::new(h);
        let sigma = self.step_v * (temp / self.t0).clamp(0.01, 1.0);
        let mut q = p.clone();
        let n = q.len();
        let k = 1 + (r.next_u64() % 4) as usize;
        for _ in 0..k {
            let i = (r.next_u64() % n as u64) as usize;
            let (l, hi) = (self.lo[i], self.hi[i]);
            let mut v = q[i] + sigma * r.normal();
            // Reflect into [l, h] (twice covers any step below the width).
            for _ in 0..2 {
                if v < l {
                    v = 2.0 * l - v;
                }
                if v > hi {
                    v = 2.0 * hi - v;
                }
            }
            q[i] = v.clamp(l, hi);
        }
        Ok(q)
    }
}

fn check_setup(x0: &[f64], lo: &[f64], hi: &[f64], budget: &Budget) -> Result<(), SearchError> {
    let bad = |field, problem: String| Err(SearchError::Setup { field, problem });
    if x0.is_empty() || lo.len() != x0.len() || hi.len() != x0.len() {
        return bad(
            "bounds",
            format!(
                "start has {} values, bounds {} and {}",
                x0.len(),
                lo.len(),
                hi.len()
            ),
        );
    }
    if lo
        .iter()
        .zip(hi)
        .any(|(l, h)| !(l.is_finite() && h.is_finite() && l < h))
    {
        return bad(
            "bounds",
            "every lower bound must be finite and below its upper bound".into(),
        );
    }
    if x0
        .iter()
        .zip(lo.iter().zip(hi))
        .any(|(v, (l, h))| !(*v >= *l && *v <= *h))
    {
        return bad("start", "the start point must lie within the bounds".into());
    }
    let pos = |v: f64| v.is_finite() && v > 0.0;
    if budget.sa.chunks > 0
        && (budget.sa.iterations == 0 || !pos(budget.sa.temperature) || !pos(budget.sa.step_v))
    {
        return bad(
            "budget.sa",
            "iterations ≥ 1, temperature > 0 and step_v > 0 are needed".into(),
        );
    }
    if budget.pso.chunks > 0
        && (budget.pso.iterations == 0 || budget.pso.particles < 2 || !pos(budget.pso.spread_v))
    {
        return bad(
            "budget.pso",
            "iterations ≥ 1, particles ≥ 2 and spread_v > 0 are needed".into(),
        );
    }
    if budget.local.chunks > 0 && (budget.local.iterations == 0 || !pos(budget.local.step_v)) {
        return bad(
            "budget.local",
            "iterations ≥ 1 and step_v > 0 are needed".into(),
        );
    }
    Ok(())
}

/// Run (or resume) the search on `state` until it is finished or `on_chunk` breaks.
///
/// `cost` is evaluated only inside the box [`lo`, `hi`]; `on_chunk` is called after
/// every chunk with the updated state (write it to disk there) and the progress.
/// Returns whether the search finished.
pub fn run_search(
    cost: &dyn Fn(&[f64]) -> f64,
    lo: &[f64],
    hi: &[f64],
    budget: &Budget,
    state: &mut SearchState,
    on_chunk: &mut dyn FnMut(&SearchState, &Progress) -> ControlFlow<()>,
) -> Result<bool, SearchError> {
    let x0 = state.start.point();
    check_setup(&x0, lo, hi, budget)?;
    let total: u32 = state.phases.iter().map(|p| p.chunks).sum();
    for pi in 0..state.phases.len() {
        let phase = state.phases[pi].phase;
        while state.phases[pi].chunks_done < state.phases[pi].chunks {
            let chunk = state.phases[pi].chunks_done;
            // The refinement starts from the better global phase.
            let from = if phase == Phase::Local && chunk == 0 {
                state.phase(state.global_winner()).best.clone()
            } else {
                state.phases[pi].best.clone()
            };
            let seed = derive_seed(state.seed, &format!("{}/{chunk}", phase.name()));
            let (best, evals) = run_chunk(cost, lo, hi, budget, phase, chunk, seed, &from)?;
            let rec = &mut state.phases[pi];
            if best.1 < from.exact_cost() || (phase == Phase::Local && chunk == 0) {
                rec.best = if best.1 < from.exact_cost() {
                    Incumbent::new(&best.0, best.1)
                } else {
                    from
                };
            }
            rec.chunks_done += 1;
            rec.evaluations += evals;
            let done: u32 = state
                .phases
                .iter()
                .map(|p| p.chunks_done.min(p.chunks))
                .sum();
            let progress = Progress {
                phase,
                chunks_done: done,
                chunks_total: total,
                evaluations: state.evaluations(),
                best_cost: state.best().exact_cost(),
            };
            if on_chunk(state, &progress).is_break() {
                return Ok(state.finished());
            }
        }
    }
    Ok(true)
}

/// The best point and the evaluation count of the problem `argmin` hands back.
fn best_of(
    problem: Option<BoxProblem<'_>>,
    phase: Phase,
    chunk: u32,
) -> Result<((Vec<f64>, f64), u64), SearchError> {
    let p = problem.ok_or_else(|| SearchError::Solver {
        phase: phase.name(),
        chunk,
        message: "the problem was not returned".into(),
    })?;
    Ok((p.best.into_inner(), p.evals.get()))
}

#[allow(clippy::too_many_arguments)]
fn run_chunk(
    cost: &dyn Fn(&[f64]) -> f64,
    lo: &[f64],
    hi: &[f64],
    budget: &Budget,
    phase: Phase,
    chunk: u32,
    seed: u64,
    from: &Incumbent,
) -> Result<((Vec<f64>, f64), u64), SearchError> {
    let x = from.point();
    let c = from.exact_cost();
    let problem = BoxProblem {
        cost,
        lo,
        hi,
        seed,
        step_v: budget.sa.step_v,
        t0: budget.sa.temperature,
        evals: Cell::new(0),
        best: RefCell::new((x.clone(), c)),
    };
    let err = |e: ArgminError| SearchError::Solver {
        phase: phase.name(),
        chunk,
        message: e.to_string(),
    };
    let out = match phase {
        Phase::SimulatedAnnealing => {
            let b = budget.sa;
            let per_chunk = 0.02f64.powf(1.0 / f64::from(b.chunks.max(1)));
            let t_c = b.temperature * per_chunk.powi(chunk as i32);
            let factor = per_chunk.powf(1.0 / f64::from(b.iterations));
            let solver =
                SimulatedAnnealing::new_with_rng(t_c, Xoshiro256PlusPlus::seed_from_u64(seed))
                    .map_err(err)?
                    .with_temp_func(SATempFunc::Exponential(factor));
            let res = Executor::new(problem, solver)
                .configure(|s| {
                    s.param(DVector::from_vec(x))
                        .cost(c)
                        .max_iters(u64::from(b.iterations))
                })
                .run()
                .map_err(err)?;
            best_of(res.problem.problem, phase, chunk)?
        }
        Phase::ParticleSwarm => {
            let b = budget.pso;
            let mut r = Rng::new(seed);
            let n = x.len();
            let mut particles = vec![Particle::new(
                DVector::from_vec(x.clone()),
                c,
                DVector::zeros(n),
            )];
            for _ in 1..b.particles {
                let pos: Vec<f64> = x
                    .iter()
                    .enumerate()
                    .map(|(i, v)| (v + b.spread_v * r.normal()).clamp(lo[i], hi[i]))
                    .collect();
                let vel: Vec<f64> = (0..n).map(|_| 0.5 * b.spread_v * r.normal()).collect();
                let pc = problem.eval(&pos);
                particles.push(Particle::new(
                    DVector::from_vec(pos),
                    pc,
                    DVector::from_vec(vel),
                ));
            }
            let bounds = (
                DVector::from_column_slice(lo),
                DVector::from_column_slice(hi),
            );
            let solver = ParticleSwarm::new(bounds, b.particles as usize)
                .with_rng_generator(Xoshiro256PlusPlus::seed_from_u64(seed));
            let res = Executor::new(problem, solver)
                .configure(|s| s.population(particles).max_iters(u64::from(b.iterations)))
                .run()
                .map_err(err)?;
            best_of(res.problem.problem, phase, chunk)?
        }
        Phase::Local => {
            let b = budget.local;
            let h = b.step_v * 0.5f64.powi(chunk as i32);
            let mut simplex = vec![DVector::from_vec(x.clone())];
            for i in 0..x.len() {
                let mut v = x.clone();
                // Step inwards when the edge would leave the box.
                v[i] = if v[i] + h <= hi[i] {
                    v[i] + h
                } else {
                    v[i] - h
                };
                simplex.push(DVector::from_vec(v));
            }
            let solver = NelderMead::new(simplex)
                .with_sd_tolerance(1e-12)
                .map_err(err)?;
            let res = Executor::new(problem, solver)
                .configure(|s| s.max_iters(u64::from(b.iterations)))
                .run()
                .map_err(err)?;
            best_of(res.problem.problem, phase, chunk)?
        }
    };
    Ok(out)
}
