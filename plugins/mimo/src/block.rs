//! `mimo_controller`: a MIMO state-space controller of any order and widths,
//! run by the scheduler at its rate, fed by vector ports:
//!
//! ```text
//! e = s ⊙ (r − y),   u = clamp(C x + D e + u₀),   x ← A x + B e
//! ```
//!
//! with `error_scale` s (e.g. 10⁹ when the controller was designed in nm and the
//! sensors give m) and the operating point `u_offset` u₀. The model is discrete
//! at the block's rate (`dt_s` must equal it) or continuous (discretised by
//! Tustin at build). At build the state basis is changed to the real Schur form
//! of A (an orthogonal similarity: same input–output behaviour, better
//! conditioned than the realisation a synthesis returns), and [A | B] and [C | D]
//! are stored by rows, so that a tick is n + m contiguous dot products with
//! z = [x; e] (four partial sums each, which the compiler vectorises); a tick
//! allocates nothing.

use crate::error::MimoError;
use nalgebra::DMatrix;
use nanomotion_core::Params;
use nanomotion_core::lti::{C2dMethod, StateSpace, c2d};
use nanomotion_core::{Block, BuildContext, ParamError, Port, Tick, declared_block};
use serde::{Deserialize, Serialize};

/// Largest controller order accepted (states).
pub const MAX_STATES: usize = 256;
/// Largest number of inputs or outputs.
pub const MAX_WIDTH: usize = 64;

/// A controller model as lists of rows (the form `nanomotion synth` writes).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ControllerModel {
    /// A (n × n).
    pub a: Vec<Vec<f64>>,
    /// B (n × p): p measured errors.
    pub b: Vec<Vec<f64>>,
    /// C (m × n): m control outputs.
    pub c: Vec<Vec<f64>>,
    /// D (m × p).
    pub d: Vec<Vec<f64>>,
    /// Sample period (s) of a discrete model; absent for a continuous one.
    #[serde(default)]
    pub dt_s: Option<f64>,
}

fn rows(m: &DMatrix<f64>) -> Vec<Vec<f64>> {
    (0..m.nrows())
        .map(|i| m.row(i).iter().copied().collect())
        .collect()
}

impl ControllerModel {
    /// From a state-space model.
    pub fn from_ss(k: &StateSpace) -> Self {
        Self {
            a: rows(&k.a),
            b: rows(&k.b),
            c: rows(&k.c),
            d: rows(&k.d),
            dt_s: k.dt,
        }
    }

    /// (states, inputs p, outputs m) from the row lists.
    pub fn dims(&self) -> (usize, usize, usize) {
        let p = self.d.first().map_or(0, |r| r.len());
        (self.a.len(), p, self.d.len())
    }

    /// To a checked state-space model.
    pub fn to_ss(&self) -> Result<StateSpace, MimoError> {
        let (n, p, m) = self.dims();
        if n > MAX_STATES || p > MAX_WIDTH || m > MAX_WIDTH || p == 0 || m == 0 {
            return Err(MimoError::param(
                "model",
                format!("{n} states, {p} inputs, {m} outputs"),
                format!(
                    "give 0–{MAX_STATES} states and 1–{MAX_WIDTH} inputs and outputs (D is m × p and sets the widths)"
                ),
            ));
        }
        let mat =
            |name: &str, r: &[Vec<f64>], nr: usize, nc: usize| -> Result<DMatrix<f64>, MimoError> {
                if r.len() != nr || r.iter().any(|row| row.len() != nc) {
                    return Err(MimoError::param(
                        format!("model.{name}"),
                        format!("is not {nr} × {nc}"),
                        "A is n×n, B n×p, C m×n, D m×p (lists of rows)",
                    ));
                }
                if r.iter().flatten().any(|v| !v.is_finite()) {
                    return Err(MimoError::param(
                        format!("model.{name}"),
                        "has a non-finite entry",
                        "give finite numbers",
                    ));
                }
                Ok(DMatrix::from_fn(nr, nc, |i, j| r[i][j]))
            };
        let a = mat("a", &self.a, n, n)?;
        let b = mat("b", &self.b, n, p)?;
        let c = mat("c", &self.c, m, n)?;
        let d = mat("d", &self.d, m, p)?;
        if let Some(dt) = self.dt_s {
            crate::error::positive("model.dt_s", dt)?;
        }
        StateSpace::new(a, b, c, d, self.dt_s).map_err(MimoError::lti("model"))
    }
}

#[derive(Debug, Clone, Default)]
struct Runtime {
    n: usize,
    p: usize,
    m: usize,
    /// Row-major [A | B] (n × (n + p)) in the real Schur basis of A: the next
    /// state is one contiguous dot product per row with z = [x; e].
    ab: Vec<f64>,
    /// Row-major [C | D] (m × (n + p)): u = [C | D] z (+ u₀).
    cd: Vec<f64>,
    /// z = [x; e]: the state, then this sample's errors.
    z: Vec<f64>,
    /// Next state.
    xn: Vec<f64>,
    /// Same as [`Block::direct_feedthrough`]: then the state advances in `output`.
    feedthrough: bool,
}

/// `mimo_controller`: MIMO state-space controller (any order and widths; Ch. 7 H∞
/// design): e = s⊙(r − y), u = C x + D e + u0, x ← A x + B e; discrete at the block's
/// rate or continuous (Tustin).
///
/// `mimo_controller` (see the [module docs](self)).
#[derive(Debug, Clone, Serialize, Deserialize, Params)]
#[serde(deny_unknown_fields)]
#[block(type_name = "mimo_controller", role = Controller, ports = "r[p], y[p] -> u[m]")]
pub struct MimoController {
    /// The controller (inputs: errors, outputs: controls).
    /// {a, b, c, d: lists of rows, dt_s: sample period of a discrete model (absent:
    /// continuous)}; `nanomotion synth` writes it.
    pub model: ControllerModel,
    /// Per-input scale s of the error (default 1).
    /// E.g. 1e9 for a controller in nm on sensors in m.
    #[serde(default)]
    #[param(default_doc = "1")]
    pub error_scale: Vec<f64>,
    /// Per-output operating point u₀ added to the controller output (default 0).
    #[serde(default)]
    #[param(default_doc = "0")]
    pub u_offset: Vec<f64>,
    /// Lower output limit (all outputs), optional.
    #[serde(default)]
    pub u_min: Option<f64>,
    /// Upper output limit (all outputs), optional.
    #[serde(default)]
    pub u_max: Option<f64>,
    #[serde(skip)]
    rt: Option<Runtime>,
    /// The discrete model from (r, y) to u at the block's period, set at build
    /// (for the stability gate).
    #[serde(skip)]
    loop_model: Option<StateSpace>,
}

impl MimoController {
    /// A block running `k` (discrete at the block's rate, or continuous).
    pub fn new(k: &StateSpace) -> Self {
        Self {
            model: ControllerModel::from_ss(k),
            error_scale: Vec::new(),
            u_offset: Vec::new(),
            u_min: None,
            u_max: None,
            loop_model: None,
            rt: None,
        }
    }

    /// The controller state (after build; in the Schur basis).
    pub fn state(&self) -> &[f64] {
        self.rt.as_ref().map_or(&[], |r| &r.z[..r.n])
    }

    /// The controller from the stacked inputs (r, y) to u at period `dt`:
    /// u = C x + D s⊙(r − y), x ← A x + B s⊙(r − y), limits and u₀ left out.
    pub fn discrete_loop_model(&self, dt: f64) -> Result<StateSpace, MimoError> {
        let k = self.model.to_ss()?;
        let kd = match k.dt {
            Some(_) => k,
            None => c2d(&k, dt, C2dMethod::TUSTIN).map_err(MimoError::lti("model (Tustin)"))?,
        };
        let p = kd.ninputs();
        let s = DMatrix::from_fn(p, p, |i, j| {
            if i != j {
                0.0
            } else if self.error_scale.is_empty() {
                1.0
            } else {
                self.error_scale[i]
            }
        });
        let (bs, ds) = (&kd.b * &s, &kd.d * &s);
        let b = DMatrix::from_fn(kd.nstates(), 2 * p, |i, j| {
            if j < p { bs[(i, j)] } else { -bs[(i, j - p)] }
        });
        let d = DMatrix::from_fn(kd.noutputs(), 2 * p, |i, j| {
            if j < p { ds[(i, j)] } else { -ds[(i, j - p)] }
        });
        StateSpace::new(kd.a.clone(), b, kd.c.clone(), d, kd.dt)
            .map_err(MimoError::lti("controller loop model"))
    }

    fn make_runtime(&self, ctx: &BuildContext) -> Result<Runtime, MimoError> {
        let k = self.model.to_ss()?;
        crate::error::positive("dt", ctx.dt)?;
        let kd = match k.dt {
            Some(dt) => {
                if (dt - ctx.dt).abs() > 1e-9 * ctx.dt {
                    return Err(MimoError::param(
                        "model.dt_s",
                        format!("is {dt} s, the block runs every {} s", ctx.dt),
                        "set the block's rate_hz to 1/dt_s, or synthesise at the block's rate",
                    ));
                }
                k
            }
            None => c2d(&k, ctx.dt, C2dMethod::TUSTIN).map_err(MimoError::lti("model (Tustin)"))?,
        };
        let (n, p, m) = (kd.nstates(), kd.ninputs(), kd.noutputs());
        for (name, v, len) in [
            ("error_scale", &self.error_scale, p),
            ("u_offset", &self.u_offset, m),
        ] {
            if !v.is_empty() && v.len() != len {
                return Err(MimoError::param(
                    name,
                    format!("has {} entries, the controller has {len}", v.len()),
                    format!("give {len} numbers, or leave it out"),
                ));
            }
            if v.iter().any(|x| !x.is_finite()) {
                return Err(MimoError::param(
                    name,
                    "has a non-finite entry",
                    "give finite numbers",
                ));
            }
        }
        if let (Some(lo), Some(hi)) = (self.u_min, self.u_max)
            && !(lo < hi)
        {
            return Err(MimoError::param(
                "u_min",
                format!("{lo} is not below u_max {hi}"),
                "give u_min < u_max",
            ));
        }
        // Real Schur basis: A = U T Uᵀ.
        let (t, u) = if n > 0 {
            let s = nalgebra::linalg::Schur::try_new(kd.a.clone(), f64::EPSILON, 10_000 * n)
                .ok_or_else(|| {
                    MimoError::param("model.a", "Schur form did not converge", "check A")
                })?;
            let (u, t) = s.unpack();
            (t, u)
        } else {
            (DMatrix::zeros(0, 0), DMatrix::zeros(0, 0))
        };
        let b = u.transpose() * &kd.b;
        let c = &kd.c * &u;
        // Quasi-triangular T: entries below the first subdiagonal are round-off
        // zeros of the Schur form; store them as exact zeros.
        let w = n + p;
        let mut ab = Vec::with_capacity(n * w);
        for i in 0..n {
            for j in 0..n {
                ab.push(if i > j + 1 { 0.0 } else { t[(i, j)] });
            }
            for j in 0..p {
                ab.push(b[(i, j)]);
            }
        }
        let mut cd = Vec::with_capacity(m * w);
        for i in 0..m {
            for j in 0..n {
                cd.push(c[(i, j)]);
            }
            for j in 0..p {
                cd.push(kd.d[(i, j)]);
            }
        }
        Ok(Runtime {
            n,
            p,
            m,
            ab,
            cd,
            z: vec![0.0; w],
            xn: vec![0.0; n],
            feedthrough: self.direct_feedthrough(),
        })
    }
}

impl Runtime {
    /// x ← A x + B e with the errors of this sample: one dot product per row of
    /// [A | B] with z = [x; e].
    #[inline]
    fn advance(&mut self) {
        let w = self.n + self.p;
        for (xi, row) in self.xn.iter_mut().zip(self.ab.chunks_exact(w)) {
            *xi = dot(row, &self.z);
        }
        self.z[..self.n].copy_from_slice(&self.xn);
    }

    #[inline]
    fn errors(&mut self, scale: &[f64], r: &[f64], y: &[f64]) {
        let (n, p) = (self.n, self.p);
        for (i, ei) in self.z[n..n + p].iter_mut().enumerate() {
            let s = if scale.is_empty() { 1.0 } else { scale[i] };
            *ei = s * (r[i] - y[i]);
        }
    }
}

/// Σ aᵢbᵢ with four independent partial sums (no serial dependency chain).
#[inline]
fn dot(a: &[f64], b: &[f64]) -> f64 {
    let (a4, b4) = (a.chunks_exact(4), b.chunks_exact(4));
    let (ra, rb) = (a4.remainder(), b4.remainder());
    let mut acc = [0.0f64; 4];
    for (x, y) in a4.zip(b4) {
        acc[0] += x[0] * y[0];
        acc[1] += x[1] * y[1];
        acc[2] += x[2] * y[2];
        acc[3] += x[3] * y[3];
    }
    let tail: f64 = ra.iter().zip(rb).map(|(x, y)| x * y).sum();
    (acc[0] + acc[1]) + (acc[2] + acc[3]) + tail
}

#[declared_block]
impl Block for MimoController {
    fn inputs(&self) -> Vec<Port> {
        let (_, p, _) = self.model.dims();
        vec![Port::new("r", p), Port::new("y", p)]
    }
    fn outputs(&self) -> Vec<Port> {
        let (_, _, m) = self.model.dims();
        vec![Port::new("u", m)]
    }
    fn direct_feedthrough(&self) -> bool {
        self.model.d.iter().flatten().any(|v| *v != 0.0) || self.model.dt_s.is_none()
    }
    fn build(&mut self, ctx: &BuildContext) -> Result<(), ParamError> {
        self.rt = Some(self.make_runtime(ctx)?);
        self.loop_model = self.discrete_loop_model(ctx.dt).ok();
        Ok(())
    }
    /// Without output limits: the controller from (r, y) to u, discrete at the
    /// block's period (B and D scaled by ±s; the offset u₀ does not change
    /// stability).
    fn lti(&self) -> Option<StateSpace> {
        if self.u_min.is_some() || self.u_max.is_some() {
            return None;
        }
        self.loop_model.clone()
    }
    /// With output limits: the same model, judged inside the limits.
    fn linearisation(&self) -> Option<nanomotion_core::block::Linearisation> {
        if self.u_min.is_none() && self.u_max.is_none() {
            return None;
        }
        Some(nanomotion_core::block::Linearisation::single(
            self.loop_model.clone()?,
            format!(
                "output limits [{}, {}] ignored: judged inside them",
                self.u_min.unwrap_or(f64::NEG_INFINITY),
                self.u_max.unwrap_or(f64::INFINITY)
            ),
        ))
    }
    fn output(&mut self, _tick: Tick, u: &[f64], y: &mut [f64]) {
        let Some(rt) = self.rt.as_mut() else {
            y.fill(0.0);
            return;
        };
        let p = rt.p;
        rt.errors(&self.error_scale, &u[..p], &u[p..2 * p]);
        let m = rt.m;
        let y = &mut y[..m];
        if self.u_offset.is_empty() {
            y.fill(0.0);
        } else {
            y.copy_from_slice(&self.u_offset);
        }
        let w = rt.n + p;
        for (yi, row) in y.iter_mut().zip(rt.cd.chunks_exact(w)) {
            *yi += dot(row, &rt.z);
        }
        for yi in y.iter_mut() {
            if let Some(lo) = self.u_min {
                *yi = yi.max(lo);
            }
            if let Some(hi) = self.u_max {
                *yi = yi.min(hi);
            }
        }
        if rt.feedthrough {
            rt.advance();
        }
    }
    fn update(&mut self, _tick: Tick, u: &[f64]) {
        // Blocks with feed-through advance in `output` (the scheduler calls
        // `update` only for blocks without it).
        if self.rt.as_ref().is_some_and(|r| !r.feedthrough) {
            let Some(rt) = self.rt.as_mut() else { return };
            let p = rt.p;
            rt.errors(&self.error_scale, &u[..p], &u[p..2 * p]);
            rt.advance();
        }
    }
    fn memory_bytes(&self) -> usize {
        self.rt.as_ref().map_or(0, |r| {
            8 * (r.ab.len() + r.cd.len() + r.z.len() + r.xn.len())
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use nanomotion_core::lti::SsStepper;

    fn random_discrete(n: usize, p: usize, m: usize, seed: u64, dt: f64) -> StateSpace {
        let mut r = nanomotion_core::rng::Rng::new(seed);
        let mut a = DMatrix::from_fn(n, n, |_, _| r.normal());
        let rho = nanomotion_core::lti::linalg::eigvals(&a)
            .iter()
            .map(|l| l.norm())
            .fold(0.0, f64::max);
        a /= 1.1 * rho;
        StateSpace::new(
            a,
            DMatrix::from_fn(n, p, |_, _| r.normal()),
            DMatrix::from_fn(m, n, |_, _| r.normal()),
            DMatrix::from_fn(m, p, |_, _| r.normal()),
            Some(dt),
        )
        .unwrap()
    }

    #[test]
    fn schur_basis_runs_the_same_input_output_map_as_the_model() {
        let dt = 1e-3;
        let k = random_discrete(9, 3, 2, 1, dt);
        let mut blk = MimoController::new(&k);
        blk.error_scale = vec![2.0, 1.0, 0.5];
        blk.u_offset = vec![10.0, -1.0];
        blk.build(&BuildContext::new("k", dt, 0)).unwrap();
        let mut reference = SsStepper::new(&k).unwrap();
        let mut rng = nanomotion_core::rng::Rng::new(4);
        for t in 0..200 {
            let inp: Vec<f64> = (0..6).map(|_| rng.normal()).collect();
            let e: Vec<f64> = (0..3)
                .map(|i| [2.0, 1.0, 0.5][i] * (inp[i] - inp[3 + i]))
                .collect();
            let mut want = [0.0; 2];
            reference.output(&e, &mut want);
            reference.update(&e);
            let mut got = [0.0; 2];
            let tick = Tick::new(t as u64, dt);
            // As the scheduler does: update only without feed-through.
            blk.output(tick, &inp, &mut got);
            if !blk.direct_feedthrough() {
                blk.update(tick, &inp);
            }
            for i in 0..2 {
                let w = want[i] + [10.0, -1.0][i];
                assert!(
                    (got[i] - w).abs() < 1e-9 * (1.0 + w.abs()),
                    "t {t}: {} vs {w}",
                    got[i]
                );
            }
        }
    }

    #[test]
    fn bad_parameters_are_named() {
        let k = random_discrete(3, 2, 2, 2, 1e-3);
        let mut blk = MimoController::new(&k);
        let e = blk
            .build(&BuildContext::new("k", 2e-3, 0))
            .unwrap_err()
            .to_string();
        assert!(e.contains("dt_s"), "{e}");
        blk.error_scale = vec![1.0];
        let e = blk
            .build(&BuildContext::new("k", 1e-3, 0))
            .unwrap_err()
            .to_string();
        assert!(e.contains("error_scale"), "{e}");
        let mut blk = MimoController::new(&k);
        blk.model.a[1].pop();
        let e = blk
            .build(&BuildContext::new("k", 1e-3, 0))
            .unwrap_err()
            .to_string();
        assert!(e.contains("model.a"), "{e}");
    }
}
