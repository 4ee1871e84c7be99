//! Fitting effect parameters by re-simulating the graph: an [`Evaluator`] owns a
//! built scheduler with the measured data attached and turns a parameter vector
//! into the residual `measured − model` of every compared output; [`levenberg_marquardt`]
//! minimises its sum of squares with a finite-difference Jacobian and returns the
//! parameters with their uncertainty from the final Jacobian.
//!
//! Nothing is parsed or allocated per sample inside a run: parameters are written
//! into the [`Tunable`](nanomotion_core::Tunable) blocks, the scheduler is reset and
//! stepped, and the compared logs are read in place. The measured columns are
//! read from the shared dataset (not copied per evaluator), and the optimiser
//! reuses its residual and Jacobian buffers from run to run, so a fit costs its
//! runs — O(N) each — and nothing that grows faster with the record.

use crate::PlfError;
use nanomotion_core::Scheduler;
use nanomotion_core::data::Dataset;
use nanomotion_core::graph::GraphSpec;
use std::sync::Arc;

/// The measured data as one or more records of the same rate: `all` is their
/// concatenation (sample `k` of the workflow indexes it), `parts` the records
/// themselves. A graph is run on each record from rest — no state carries
/// over from one record into the next — and the model outputs are laid end to
/// end in the same order.
#[derive(Debug, Clone)]
pub struct Records {
    /// The records end to end.
    pub all: Arc<Dataset>,
    /// The records, each run on its own.
    pub parts: Vec<Arc<Dataset>>,
}

impl Records {
    /// One record.
    pub fn one(data: &Arc<Dataset>) -> Self {
        Self {
            all: data.clone(),
            parts: vec![data.clone()],
        }
    }

    /// Several records end to end. They must have the same sample rate; the
    /// concatenation keeps the columns every record has.
    pub fn concat(parts: &[Dataset]) -> Result<Self, PlfError> {
        let first = parts
            .first()
            .ok_or_else(|| PlfError::Data("no record given".into()))?;
        for p in &parts[1..] {
            if (p.rate_hz() - first.rate_hz()).abs() > 1e-9 * first.rate_hz() {
                return Err(PlfError::Data(format!(
                    "{} is sampled at {} Hz but {} at {} Hz; give records of one rate (resample one of them)",
                    p.origin(),
                    p.rate_hz(),
                    first.origin(),
                    first.rate_hz()
                )));
            }
        }
        if parts.len() == 1 {
            return Ok(Self::one(&Arc::new(first.clone())));
        }
        let names: Vec<String> = first
            .names()
            .iter()
            .filter(|n| parts.iter().all(|p| p.column(n).is_some()))
            .cloned()
            .collect();
        let columns: Vec<(String, Vec<f64>)> = names
            .iter()
            .map(|n| {
                let v = parts
                    .iter()
                    .flat_map(|p| p.column(n).unwrap_or(&[]).iter().copied())
                    .collect();
                (n.clone(), v)
            })
            .collect();
        let origin = parts
            .iter()
            .map(|p| p.origin().to_string())
            .collect::<Vec<_>>()
            .join(" + ");
        let all = Dataset::from_columns(origin, first.rate_hz(), first.t0_s(), columns)
            .map_err(|e| PlfError::Data(e.to_string()))?;
        Ok(Self {
            all: Arc::new(all),
            parts: parts.iter().map(|p| Arc::new(p.clone())).collect(),
        })
    }

    /// Sample index (in `all`) where each record starts.
    pub fn starts(&self) -> Vec<usize> {
        self.parts
            .iter()
            .scan(0, |at, p| {
                let s = *at;
                *at += p.len();
                Some(s)
            })
            .collect()
    }
}

/// Where record `j` of records starting at `starts` (of `total` samples in
/// all) ends, cut at the first `n` samples.
fn record_end(starts: &[usize], j: usize, total: usize, n: usize) -> usize {
    starts.get(j + 1).copied().unwrap_or(total).min(n)
}

/// How a fitted parameter is moved by the optimiser.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Scale {
    /// θ = θ₀ + s·z: a signed parameter with typical size s.
    Linear(f64),
    /// θ = θ₀·e^z: a strictly positive parameter.
    Log,
    /// θ = lo·(hi/lo)^σ(z + z₀), σ the logistic function, z₀ such that θ(0) = θ₀
    /// (clamped a little inside the range): a positive parameter kept inside
    /// the range [lo, hi] where it means what its name says, so a fit finds
    /// the best value there instead of a better one outside that would be
    /// refused (a creep's time constant longer than the record is a ramp).
    LogWithin { lo: f64, hi: f64 },
}

impl Scale {
    /// θ(z) for start value `v0`.
    fn theta(self, v0: f64, z: f64) -> f64 {
        match self {
            Scale::Linear(s) => v0 + s * z,
            Scale::Log => v0 * z.exp(),
            Scale::LogWithin { lo, hi } => {
                let span = (hi / lo).ln();
                // Clamped: at σ = 1, lo·e^span can exceed hi by round-off.
                (lo * (span * logistic(z + within_offset(v0, lo, hi))).exp()).clamp(lo, hi)
            }
        }
    }

    /// dθ/dz for start value `v0`.
    fn dtheta(self, v0: f64, z: f64) -> f64 {
        match self {
            Scale::Linear(s) => s,
            Scale::Log => v0 * z.exp(),
            Scale::LogWithin { lo, hi } => {
                let span = (hi / lo).ln();
                let s = logistic(z + within_offset(v0, lo, hi));
                self.theta(v0, z) * span * s * (1.0 - s)
            }
        }
    }
}

fn logistic(x: f64) -> f64 {
    1.0 / (1.0 + (-x).exp())
}

/// z₀ of [`Scale::LogWithin`]: where `v0` sits between `lo` and `hi` on a log
/// axis, as a logit, its fraction kept within 1–99 %.
fn within_offset(v0: f64, lo: f64, hi: f64) -> f64 {
    let f = ((v0 / lo).ln() / (hi / lo).ln()).clamp(0.01, 0.99);
    (f / (1.0 - f)).ln()
}

/// One free parameter: parameter `index` of the tunable block `block`.
#[derive(Debug, Clone, PartialEq)]
pub struct FreeParam {
    /// The block's name.
    pub block: String,
    /// Index in the block's [`Tunable::params`](nanomotion_core::Tunable::params) vector.
    pub index: usize,
    /// How the optimiser moves it.
    pub scale: Scale,
}

/// A least-squares problem over optimiser coordinates `z`.
pub trait Problem {
    /// Parameter values for coordinates `z` (z = 0: the start values).
    fn theta(&self, z: &[f64]) -> Vec<f64>;
    /// dθ/dz at `z`, element-wise.
    fn dtheta_dz(&self, z: &[f64]) -> Vec<f64>;
    /// The weighted residuals over the first `n` samples, written into `out`
    /// (cleared first; its allocation is reused from run to run); `false` if the
    /// model refuses the parameters or diverges.
    fn weighted_residuals(&mut self, z: &[f64], n: usize, out: &mut Vec<f64>) -> bool;
}

fn theta_of(free: &[(Scale, f64)], z: &[f64]) -> Vec<f64> {
    free.iter()
        .zip(z)
        .map(|(&(scale, v0), &zi)| scale.theta(v0, zi))
        .collect()
}

fn dtheta_of(free: &[(Scale, f64)], z: &[f64]) -> Vec<f64> {
    free.iter()
        .zip(z)
        .map(|(&(scale, v0), &zi)| scale.dtheta(v0, zi))
        .collect()
}

/// One effect block run on its own on fixed input sequences (an effect on a
/// compared output does not change the rest of the graph, so its fit needs no
/// simulation of the graph).
pub struct BlockEvaluator {
    block: Box<dyn nanomotion_core::Block>,
    free: Vec<(usize, Scale, f64)>,
    inputs: Vec<Vec<f64>>,
    measured: Vec<f64>,
    weight: f64,
    dt: f64,
    skip: usize,
    /// Samples where a new record starts (the block restarts from rest).
    restarts: Vec<usize>,
    u_buf: Vec<f64>,
    /// Output of the last run.
    pub y: Vec<f64>,
}

impl BlockEvaluator {
    /// `block` with its port `u` fed by `inputs[0]` and port `s` (if any) by the
    /// rest, at sample rate `fs_hz`, compared with `measured`.
    pub fn new(
        block: Box<dyn nanomotion_core::Block>,
        free: &[(usize, Scale)],
        inputs: Vec<Vec<f64>>,
        measured: Vec<f64>,
        weight: f64,
        fs_hz: f64,
        skip: usize,
    ) -> Result<Self, PlfError> {
        let mut block = block;
        let p = block
            .tunable()
            .map(|t| t.params())
            .ok_or_else(|| PlfError::Model("effect block has no fittable parameters".into()))?;
        let free = free
            .iter()
            .map(|&(i, s)| (i, s, p.get(i).copied().unwrap_or(0.0)))
            .collect();
        let ctx = nanomotion_core::BuildContext::new("effect", 1.0 / fs_hz, 0);
        block
            .build(&ctx)
            .map_err(|e| PlfError::Model(e.to_string()))?;
        let width: usize = block.inputs().iter().map(|q| q.width).sum();
        if width != inputs.len() {
            return Err(PlfError::Model(format!(
                "effect block takes {width} input values, {} signals given",
                inputs.len()
            )));
        }
        Ok(Self {
            block,
            free,
            u_buf: vec![0.0; width],
            y: Vec::new(),
            inputs,
            measured,
            weight,
            dt: 1.0 / fs_hz,
            skip,
            restarts: Vec::new(),
        })
    }

    /// Restart the block from rest at these samples (where records of
    /// [`Records`] meet).
    pub fn with_restarts(mut self, starts: &[usize]) -> Self {
        self.restarts = starts.iter().copied().filter(|&k| k > 0).collect();
        self
    }

    fn free_scales(&self) -> Vec<(Scale, f64)> {
        self.free.iter().map(|&(_, s, v)| (s, v)).collect()
    }

    /// Run the block on the first `n` samples with coordinates `z`.
    pub fn run(&mut self, z: &[f64], n: usize) -> bool {
        let theta = theta_of(&self.free_scales(), z);
        let Some(t) = self.block.tunable_mut() else {
            return false;
        };
        let mut p = t.params();
        for (k, &(i, _, _)) in self.free.iter().enumerate() {
            p[i] = theta[k];
        }
        if t.set_params(&p).is_err() {
            return false;
        }
        let ctx = nanomotion_core::BuildContext::new("effect", self.dt, 0);
        if self.block.build(&ctx).is_err() {
            return false;
        }
        let n = n.min(self.measured.len());
        self.y.clear();
        self.y.resize(n, 0.0);
        let ft = self.block.direct_feedthrough();
        let mut out = [0.0];
        for k in 0..n {
            if self.restarts.contains(&k) && self.block.build(&ctx).is_err() {
                return false;
            }
            for (j, col) in self.inputs.iter().enumerate() {
                self.u_buf[j] = col[k];
            }
            let tick = nanomotion_core::Tick::new(k as u64, self.dt);
            self.block.output(tick, &self.u_buf, &mut out);
            if !ft {
                self.block.update(tick, &self.u_buf);
            }
            if !out[0].is_finite() {
                return false;
            }
            self.y[k] = out[0];
        }
        true
    }
}

impl Problem for BlockEvaluator {
    fn theta(&self, z: &[f64]) -> Vec<f64> {
        theta_of(&self.free_scales(), z)
    }
    fn dtheta_dz(&self, z: &[f64]) -> Vec<f64> {
        dtheta_of(&self.free_scales(), z)
    }
    fn weighted_residuals(&mut self, z: &[f64], n: usize, out: &mut Vec<f64>) -> bool {
        out.clear();
        if !self.run(z, n) {
            return false;
        }
        out.extend((self.skip..self.y.len()).map(|k| (self.measured[k] - self.y[k]) * self.weight));
        true
    }
}

/// A built graph with data, ready to be evaluated for many parameter vectors.
pub struct Evaluator {
    /// One built graph per record (see [`Records`]); the same blocks in each.
    scheds: Vec<Scheduler>,
    /// Sample (of the records end to end) where each record starts.
    starts: Vec<usize>,
    /// (execution index of block, parameter index, scale, start value).
    free: Vec<(usize, usize, Scale, f64)>,
    /// The record (shared, not copied) and the measured column of each output.
    data: Arc<Dataset>,
    columns: Vec<String>,
    /// Log samples per data sample, per compared output.
    decim: Vec<usize>,
    /// Normalisation of each output's residual (its measured standard deviation).
    weight: Vec<f64>,
    /// Base ticks per data sample.
    ticks_per_sample: u64,
    n_total: usize,
    /// Data samples at the start excluded from every cost (initial transient).
    skip: usize,
}

impl Evaluator {
    /// Build `spec` with `data` and prepare to vary `free`.
    pub fn new(
        spec: GraphSpec,
        data: &Arc<Dataset>,
        free: &[FreeParam],
        skip: usize,
    ) -> Result<Self, PlfError> {
        Self::over(spec, &Records::one(data), free, skip)
    }

    /// Build `spec` once per record of `records` and prepare to vary `free`;
    /// sample `k` is sample `k` of the records end to end.
    pub fn over(
        spec: GraphSpec,
        records: &Records,
        free: &[FreeParam],
        skip: usize,
    ) -> Result<Self, PlfError> {
        let data = &records.all;
        let base = spec.base_rate_hz;
        let ratio = base / data.rate_hz();
        let tps = ratio.round();
        if (ratio - tps).abs() > 1e-9 * ratio || tps < 1.0 {
            return Err(PlfError::Model(format!(
                "the graph's base rate {base} Hz is not an integer multiple of the data rate {} Hz",
                data.rate_hz()
            )));
        }
        let n_parts = records.parts.len();
        let mut spec = Some(spec);
        let mut scheds = Vec::with_capacity(n_parts);
        for (j, part) in records.parts.iter().enumerate() {
            let mut one = match (j + 1 == n_parts, spec.as_ref()) {
                (false, Some(s)) => crate::surgery::clone_spec(s)?,
                _ => spec
                    .take()
                    .expect("the graph is moved into the last record's run"),
            };
            if n_parts > 1 {
                one.duration_s = part.len() as f64 / part.rate_hz();
            }
            let (sched, _) = one
                .build_with_data(part.clone())
                .map_err(|e| PlfError::Model(e.to_string()))?;
            scheds.push(sched);
        }
        let sched = &scheds[0];
        let mut columns = Vec::new();
        let mut decim = Vec::new();
        let mut weight = Vec::new();
        let compares: Vec<(String, String)> = sched
            .compares()
            .map(|(s, c)| (s.to_string(), c.to_string()))
            .collect();
        if compares.is_empty() {
            return Err(PlfError::Model(
                "the graph has no `compare:` entries: pair a model output with a measured column"
                    .into(),
            ));
        }
        for (i, (signal, column)) in compares.iter().enumerate() {
            let col = data
                .require(column)
                .map_err(|e| PlfError::Data(e.to_string()))?;
            let (_, rate) = sched.compare_log(i).expect("compare index in range");
            let m = rate / data.rate_hz();
            let mr = m.round();
            if (m - mr).abs() > 1e-9 * m || mr < 1.0 {
                return Err(PlfError::Model(format!(
                    "compared signal {signal} runs at {rate} Hz, not an integer multiple of the data rate {} Hz",
                    data.rate_hz()
                )));
            }
            let m = crate::stats::mean(col);
            let sd = if col.is_empty() {
                0.0
            } else {
                (col.iter().map(|v| (v - m) * (v - m)).sum::<f64>() / col.len() as f64).sqrt()
            };
            weight.push(if sd > 0.0 { 1.0 / sd } else { 1.0 });
            columns.push(column.clone());
            decim.push(mr as usize);
        }
        let mut me = Self {
            scheds,
            starts: records.starts(),
            free: Vec::new(),
            data: data.clone(),
            columns,
            decim,
            weight,
            ticks_per_sample: tps as u64,
            n_total: data.len(),
            skip,
        };
        for f in free {
            let bi = me.scheds[0]
                .block_index(&f.block)
                .ok_or_else(|| PlfError::Model(format!("no block `{}` to fit", f.block)))?;
            let tun = me.scheds[0]
                .block_at_mut(bi)
                .and_then(|b| b.tunable_mut())
                .ok_or_else(|| {
                    PlfError::Model(format!("block `{}` has no fittable parameters", f.block))
                })?;
            let p = tun.params();
            let v = *p.get(f.index).ok_or_else(|| {
                PlfError::Model(format!("block `{}` has no parameter {}", f.block, f.index))
            })?;
            me.free.push((bi, f.index, f.scale, v));
        }
        Ok(me)
    }

    /// Number of free parameters.
    pub fn dim(&self) -> usize {
        self.free.len()
    }

    /// Number of compared outputs.
    pub fn outputs(&self) -> usize {
        self.columns.len()
    }

    /// Data samples in the record.
    pub fn len(&self) -> usize {
        self.n_total
    }

    /// Whether the record is empty.
    pub fn is_empty(&self) -> bool {
        self.n_total == 0
    }

    fn free_scales(&self) -> Vec<(Scale, f64)> {
        self.free.iter().map(|&(_, _, s, v)| (s, v)).collect()
    }

    /// Write the fitted values for `z` into the matching blocks of `spec` (a graph
    /// with the same block names), so it can be saved or run on its own.
    pub fn export(&self, z: &[f64], spec: &mut GraphSpec) -> Result<(), PlfError> {
        let theta = self.theta(z);
        for (k, &(bi, pi, _, _)) in self.free.iter().enumerate() {
            let name = &self.scheds[0].block_names()[bi];
            let b = spec
                .blocks
                .iter_mut()
                .find(|b| &b.name == name)
                .ok_or_else(|| {
                    PlfError::Model(format!("no block `{name}` in the graph to export to"))
                })?;
            let t = b
                .block
                .tunable_mut()
                .ok_or_else(|| PlfError::Model(format!("block `{name}` is not tunable")))?;
            let mut p = t.params();
            p[pi] = theta[k];
            t.set_params(&p)
                .map_err(|e| PlfError::Model(format!("block `{name}`: {e}")))?;
        }
        Ok(())
    }

    /// A logged signal (`block.port`, width 1) of the last run at the data
    /// rate (the records end to end).
    pub fn log_series(&self, name: &str) -> Option<Vec<f64>> {
        let mut out = Vec::new();
        for sched in &self.scheds {
            let (data, width, rate) = sched.log_view(name)?;
            if width != 1 {
                return None;
            }
            let m = (rate * self.ticks_per_sample as f64 / sched.base_rate_hz())
                .round()
                .max(1.0) as usize;
            out.extend(data.iter().step_by(m).copied());
        }
        Some(out)
    }

    /// The measured column of output `i`.
    pub fn measured(&self, i: usize) -> &[f64] {
        self.data
            .column(&self.columns[i])
            .expect("a column checked when the evaluator was built")
    }

    /// Weigh the residual of output `i` by `w[i]` instead of 1/σ of its measured
    /// column (the workflow weighs each output in units of its noise floor).
    pub fn set_weights(&mut self, w: &[f64]) {
        for (mine, &given) in self.weight.iter_mut().zip(w) {
            *mine = given;
        }
    }

    /// The weight (1/σ of the measured signal, unless set) of output `i`.
    pub fn weight(&self, i: usize) -> f64 {
        self.weight[i]
    }

    /// Write the parameters for `z` into the blocks. `false` if a block refuses them.
    fn apply(&mut self, z: &[f64]) -> bool {
        let theta = theta_of(&self.free_scales(), z);
        for sched in self.scheds.iter_mut() {
            for (k, &(bi, pi, _, _)) in self.free.iter().enumerate() {
                let Some(t) = sched.block_at_mut(bi).and_then(|b| b.tunable_mut()) else {
                    return false;
                };
                let mut p = t.params();
                p[pi] = theta[k];
                if t.set_params(&p).is_err() {
                    return false;
                }
            }
        }
        true
    }

    /// Run the first `n` data samples with parameters `z`; `false` if the
    /// parameters were refused, the graph could not restart, or an output is not
    /// finite.
    pub fn run(&mut self, z: &[f64], n: usize) -> bool {
        if !self.apply(z) {
            return false;
        }
        let n = n.min(self.n_total);
        let outputs = self.outputs();
        for (j, sched) in self.scheds.iter_mut().enumerate() {
            let start = self.starts[j];
            // Records past `n` are not run (their logs are not read).
            if start >= n {
                continue;
            }
            if sched.reset().is_err() {
                return false;
            }
            let end = record_end(&self.starts, j, self.n_total, n);
            sched.step_n((end - start) as u64 * self.ticks_per_sample);
            // A trial step may diverge: that is an answer ("reject this step"),
            // not an error to locate, so only the compared logs are scanned (no
            // replay, no warning).
            let finite = (0..outputs).all(|i| {
                sched
                    .compare_log(i)
                    .is_some_and(|(log, _)| log.iter().all(|v| v.is_finite()))
            });
            if !finite {
                return false;
            }
        }
        true
    }

    /// The record holding sample `k` and `k`'s index in it.
    #[inline]
    fn locate(&self, k: usize) -> (usize, usize) {
        let j = self.starts.partition_point(|&s| s <= k).saturating_sub(1);
        (j, k - self.starts[j])
    }

    /// The model output `i` at data sample `k` of the last run.
    #[inline]
    pub fn model(&self, i: usize, k: usize) -> f64 {
        let (j, local) = self.locate(k);
        let (log, _) = self.scheds[j].compare_log(i).expect("compare index");
        log.get(local * self.decim[i]).copied().unwrap_or(f64::NAN)
    }

    /// Residuals `measured − model` of output `i` over data samples `range`, from the last run.
    pub fn residual(&self, i: usize, range: std::ops::Range<usize>) -> Vec<f64> {
        let measured = self.measured(i);
        range.map(|k| measured[k] - self.model(i, k)).collect()
    }

    /// Model output `i` over `range`, from the last run.
    pub fn model_series(&self, i: usize, range: std::ops::Range<usize>) -> Vec<f64> {
        range.map(|k| self.model(i, k)).collect()
    }
}

impl Problem for Evaluator {
    fn theta(&self, z: &[f64]) -> Vec<f64> {
        theta_of(&self.free_scales(), z)
    }
    fn dtheta_dz(&self, z: &[f64]) -> Vec<f64> {
        dtheta_of(&self.free_scales(), z)
    }
    /// Weighted residual vector (all outputs, samples `skip..n`) for `z`, or `None`
    /// when the run fails.
    fn weighted_residuals(&mut self, z: &[f64], n: usize, out: &mut Vec<f64>) -> bool {
        out.clear();
        if !self.run(z, n) {
            return false;
        }
        out.reserve(self.outputs() * n.saturating_sub(self.skip));
        for i in 0..self.outputs() {
            // The logs and the column looked up once per output and record, not
            // per sample.
            let measured = self
                .data
                .column(&self.columns[i])
                .expect("a column checked when the evaluator was built");
            let (decim, weight) = (self.decim[i], self.weight[i]);
            for (j, sched) in self.scheds.iter().enumerate() {
                let (log, _) = sched.compare_log(i).expect("compare index");
                let start = self.starts[j];
                let end = record_end(&self.starts, j, self.n_total, n);
                let first = start.max(self.skip);
                for (k, m) in measured.iter().enumerate().take(end).skip(first) {
                    let model = log.get((k - start) * decim).copied().unwrap_or(f64::NAN);
                    let v = (m - model) * weight;
                    if !v.is_finite() {
                        return false;
                    }
                    out.push(v);
                }
            }
        }
        true
    }
}

/// Result of a fit.
#[derive(Debug, Clone, PartialEq)]
pub struct Fit {
    /// Optimiser coordinates of the optimum.
    pub z: Vec<f64>,
    /// Parameter values.
    pub theta: Vec<f64>,
    /// One standard deviation of each parameter, from σ²(JᵀJ)⁻¹ at the optimum
    /// (NaN where the Jacobian is rank deficient).
    pub std: Vec<f64>,
    /// Sum of squared weighted residuals at the optimum.
    pub cost: f64,
    /// Number of residuals.
    pub n: usize,
    /// Graph runs used.
    pub runs: usize,
}

/// Levenberg–Marquardt (Marquardt's diagonal scaling, Nielsen's damping update) on
/// the evaluator's weighted residuals over the first `n` data samples, from `z0`.
/// Steps whose run fails (refused parameters, divergence) are rejected like steps
/// that increase the cost. `None` if even `z0` cannot be run.
///
/// Why our own and not the `levenberg-marquardt` crate: every residual evaluation is
/// a simulation that may diverge for a trial step; here such a step is simply
/// rejected and the damping raised, and the run count is bounded.
pub fn levenberg_marquardt<P: Problem>(
    ev: &mut P,
    z0: &[f64],
    n: usize,
    max_iter: usize,
) -> Option<Fit> {
    let p = z0.len();
    let mut z = z0.to_vec();
    let mut r = Vec::new();
    if !ev.weighted_residuals(&z, n, &mut r) {
        return None;
    }
    let mut cost: f64 = r.iter().map(|v| v * v).sum();
    // Buffers of the record's length, allocated once per fit: a trial run's
    // residuals, a Jacobian column's, and Jᵀ.
    let (mut rn, mut rj) = (Vec::with_capacity(r.len()), Vec::with_capacity(r.len()));
    let mut jt = nalgebra::DMatrix::<f64>::zeros(p, r.len());
    let mut runs = 1;
    let mut lambda = 1e-3;
    let mut nu = 2.0;
    let h = 1e-6;
    let mut jac = nalgebra::DMatrix::<f64>::zeros(r.len(), p);
    let mut have_jac = false;
    for _ in 0..max_iter {
        if p == 0 {
            break;
        }
        // Forward-difference Jacobian.
        let mut ok = true;
        for j in 0..p {
            let mut zj = z.clone();
            zj[j] += h;
            runs += 1;
            if !ev.weighted_residuals(&zj, n, &mut rj) {
                ok = false;
                break;
            }
            for (dst, (a, b)) in jac.column_mut(j).iter_mut().zip(rj.iter().zip(&r)) {
                *dst = (a - b) / h;
            }
        }
        if !ok {
            break;
        }
        have_jac = true;
        jac.transpose_to(&mut jt);
        let jtj = &jt * &jac;
        let g = &jt * nalgebra::DVector::from_column_slice(&r);
        let mut improved = false;
        for _ in 0..12 {
            let mut a = jtj.clone();
            for i in 0..p {
                a[(i, i)] += lambda * jtj[(i, i)].max(1e-12);
            }
            let Some(step) = a.cholesky().map(|c| c.solve(&(-&g))) else {
                lambda *= nu;
                nu *= 2.0;
                continue;
            };
            let zn: Vec<f64> = z.iter().zip(step.iter()).map(|(a, b)| a + b).collect();
            runs += 1;
            if ev.weighted_residuals(&zn, n, &mut rn) {
                let cn: f64 = rn.iter().map(|v| v * v).sum();
                if cn < cost {
                    let rel = (cost - cn) / cost.max(1e-300);
                    z = zn;
                    std::mem::swap(&mut r, &mut rn);
                    cost = cn;
                    lambda = (lambda / 3.0).max(1e-12);
                    nu = 2.0;
                    improved = true;
                    if rel < 1e-9 {
                        return Some(finish(ev, z, cost, r.len(), runs, &jac, have_jac));
                    }
                    break;
                }
            }
            lambda *= nu;
            nu *= 2.0;
        }
        if !improved {
            break;
        }
    }
    Some(finish(ev, z, cost, r.len(), runs, &jac, have_jac))
}

fn finish<P: Problem>(
    ev: &P,
    z: Vec<f64>,
    cost: f64,
    n: usize,
    runs: usize,
    jac: &nalgebra::DMatrix<f64>,
    have_jac: bool,
) -> Fit {
    let p = z.len();
    let theta = ev.theta(&z);
    let dz = ev.dtheta_dz(&z);
    let mut std = vec![f64::NAN; p];
    if have_jac && n > p {
        // σ² (JᵀJ)⁻¹ through the eigen-decomposition JᵀJ = Q Λ Qᵀ, so that a
        // direction the data do not see (λ ≈ 0: a parameter without effect,
        // or two that trade off exactly) makes the σ of the parameters in it
        // infinite, and leaves the others' finite.
        let sigma2 = cost / (n - p) as f64;
        let eig = (jac.transpose() * jac).symmetric_eigen();
        let top = eig.eigenvalues.iter().copied().fold(0.0f64, f64::max);
        let tiny = top * 1e-12;
        for (i, s) in std.iter_mut().enumerate() {
            let (mut var, mut unseen) = (0.0, 0.0);
            for (k, &l) in eig.eigenvalues.iter().enumerate() {
                let q2 = eig.eigenvectors[(i, k)].powi(2);
                if l > tiny {
                    var += q2 / l;
                } else {
                    unseen += q2;
                }
            }
            *s = if top <= 0.0 || unseen > 1e-6 {
                f64::INFINITY
            } else {
                (sigma2 * var).sqrt() * dz[i].abs()
            };
        }
    }
    Fit {
        z,
        theta,
        std,
        cost,
        n,
        runs,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_bounded_log_scale_starts_at_its_value_stays_in_range_and_has_the_right_slope() {
        let (lo, hi) = (1e-3, 5.0);
        let s = Scale::LogWithin { lo, hi };
        // θ(0) is the start value wherever it lies inside (clamped to 1–99 %
        // of the log range at the ends).
        for v0 in [2e-3, 0.1, 1.0, 4.0] {
            assert!((s.theta(v0, 0.0) / v0 - 1.0).abs() < 1e-12, "{v0}");
        }
        let f = |v: f64| ((v / lo).ln() / (hi / lo).ln()).clamp(0.01, 0.99);
        let at_end = lo * (f(100.0) * (hi / lo).ln()).exp();
        assert!((s.theta(100.0, 0.0) / at_end - 1.0).abs() < 1e-12);
        // Any coordinate maps inside [lo, hi].
        for z in [-1e3, -30.0, -1.0, 0.0, 1.0, 30.0, 1e3] {
            let t = s.theta(0.1, z);
            assert!((lo..=hi).contains(&t), "z = {z}: {t}");
        }
        // dθ/dz against a central difference.
        for z in [-3.0, -0.5, 0.0, 0.7, 2.5] {
            let h = 1e-6;
            let fd = (s.theta(0.1, z + h) - s.theta(0.1, z - h)) / (2.0 * h);
            let an = s.dtheta(0.1, z);
            assert!(
                (an - fd).abs() <= 1e-7 * an.abs().max(1e-12),
                "z = {z}: {an} vs {fd}"
            );
        }
    }
}
