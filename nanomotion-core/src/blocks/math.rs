//! Arithmetic and routing blocks: `gain`, `sum`, `product`, `saturation`, `deadzone`,
//! `mux`, `demux`.
//!
//! All of them are memoryless (direct feed-through, no state). The linear ones
//! (`gain`, `sum`, `mux`, `demux`) report their static [`StateSpace`] (no states,
//! D matrix only) through [`Block::lti`], so loop analysis sees through them.
//!
//! ```
//! use nanomotion_core::blocks::math::{Gain, Sum};
//! let g = Gain::new(2.0);
//! let mut y = [0.0];
//! g.apply(&[1.5], &mut y);
//! assert_eq!(y, [3.0]);
//!
//! let s = Sum::new("+-").unwrap();           // r − y
//! s.apply(&[5.0, 2.0], &mut y);
//! assert_eq!(y, [3.0]);
//! ```

use crate::block::check;
use crate::doc::Params;
use crate::lti::StateSpace;
use crate::{Block, BuildContext, ParamError, Tick, declared_block};
use nalgebra::DMatrix;
use serde::{Deserialize, Serialize};

fn one() -> usize {
    1
}

fn two() -> usize {
    2
}

/// A memoryless system y = D u as a [`StateSpace`] without states; discrete with
/// period `dt` if the block was built (`dt > 0`).
pub(crate) fn static_ss(d: DMatrix<f64>, dt: f64) -> StateSpace {
    let (p, m) = d.shape();
    StateSpace {
        a: DMatrix::zeros(0, 0),
        b: DMatrix::zeros(0, m),
        c: DMatrix::zeros(p, 0),
        d,
        dt: (dt > 0.0).then_some(dt),
    }
}

// ---------------------------------------------------------------------------------
// gain
// ---------------------------------------------------------------------------------

/// `gain`: y = k·u, element-wise on a vector of width `n`.
#[derive(Debug, Clone, Serialize, Deserialize, Params)]
#[serde(deny_unknown_fields)]
#[block(type_name = "gain", role = Math, ports = "u[width] -> y[width]", live = "k")]
pub struct Gain {
    /// Gain k (unit of y per unit of u).
    #[param(finite)]
    pub k: f64,
    /// Signal width n.
    #[serde(default = "one")]
    #[param(width)]
    pub width: usize,
    #[serde(skip)]
    dt: f64,
}

impl Gain {
    /// A scalar gain `k`.
    pub fn new(k: f64) -> Self {
        Self::with_width(k, 1)
    }
    /// A gain `k` applied to each of `n` channels.
    pub fn with_width(k: f64, n: usize) -> Self {
        Self {
            k,
            width: n,
            dt: 0.0,
        }
    }
    /// y = k·u.
    pub fn apply(&self, u: &[f64], y: &mut [f64]) {
        if let ([u0], [y0]) = (u, &mut *y) {
            // The common scalar gain, without the loop's set-up.
            *y0 = self.k * u0;
            return;
        }
        for (yi, ui) in y.iter_mut().zip(u) {
            *yi = self.k * ui;
        }
    }
}

#[declared_block]
impl Block for Gain {
    fn build(&mut self, ctx: &BuildContext) -> Result<(), ParamError> {
        self.check_params()?;
        self.dt = ctx.dt;
        Ok(())
    }
    fn output(&mut self, _tick: Tick, u: &[f64], y: &mut [f64]) {
        self.apply(u, y);
    }
    fn set_live_param(&mut self, slot: usize, value: f64) {
        if slot == 0 {
            self.k = value;
        }
    }
    fn lti(&self) -> Option<StateSpace> {
        Some(static_ss(
            DMatrix::identity(self.width, self.width) * self.k,
            self.dt,
        ))
    }
}

// ---------------------------------------------------------------------------------
// sum
// ---------------------------------------------------------------------------------

/// `sum`: y = Σᵢ sᵢ·inᵢ with signs sᵢ = ±1 given as a string (`"+-"` gives
/// y = in0 − in1, the error r − y of a feedback loop).
#[derive(Debug, Clone, Serialize, Deserialize, Params)]
#[serde(deny_unknown_fields)]
#[block(type_name = "sum", role = Math, ports = "in{i}[width] for i in 0..len(signs) -> y[width] [unit of in0]")]
pub struct Sum {
    /// One `+` or `-` per input, in port order (`in0`, `in1`, ...).
    #[param(schema = "signs_schema")]
    pub signs: String,
    /// Width n of every input and of the output.
    #[serde(default = "one")]
    #[param(width)]
    pub width: usize,
    #[serde(skip)]
    gains: Vec<f64>,
    #[serde(skip)]
    dt: f64,
}

/// The schema of `signs`: 1 to [`MAX_PORTS`] characters `+`/`-`.
fn signs_schema() -> serde_json::Value {
    serde_json::json!({ "type": "string", "pattern": format!("^[+-]{{1,{MAX_PORTS}}}$") })
}

impl Sum {
    /// A scalar sum with the given signs, e.g. `"+-"`.
    pub fn new(signs: &str) -> Result<Self, ParamError> {
        Self::with_width(signs, 1)
    }
    /// A sum of vectors of width `n`.
    pub fn with_width(signs: &str, n: usize) -> Result<Self, ParamError> {
        let mut s = Self {
            signs: signs.to_string(),
            width: n,
            gains: Vec::new(),
            dt: 0.0,
        };
        s.parse()?;
        Ok(s)
    }
    fn parse(&mut self) -> Result<(), ParamError> {
        self.check_params()?;
        check::size("signs", self.signs.chars().count(), 0, MAX_PORTS)?;
        let mut gains = Vec::with_capacity(self.signs.len());
        for (i, c) in self.signs.chars().enumerate() {
            gains.push(match c {
                '+' => 1.0,
                '-' => -1.0,
                _ => {
                    return Err(ParamError::new(
                        "signs",
                        format!("character {i} is `{c}`"),
                        "use only `+` and `-`, one per input, e.g. \"+-\"",
                    ));
                }
            });
        }
        if gains.is_empty() {
            return Err(ParamError::new(
                "signs",
                "is empty",
                "give one `+` or `-` per input, e.g. \"+-\"",
            ));
        }
        self.gains = gains;
        Ok(())
    }
    /// y = Σᵢ sᵢ·inᵢ; `u` holds the inputs concatenated (width n each).
    #[inline]
    pub fn apply(&self, u: &[f64], y: &mut [f64]) {
        if self.width == 1
            && let ([g0, g1], [u0, u1], [y0]) = (self.gains.as_slice(), u, &mut *y)
        {
            // The common `r − y`, unrolled: the same products summed by the
            // same `sum` as below. (It compiles to one 16-byte load of `u`,
            // which stalls on the scheduler's two 8-byte stores of the
            // gathered inputs: docs/performance.md.)
            *y0 = [g0 * u0, g1 * u1].into_iter().sum();
            return;
        }
        self.apply_any(u, y);
    }

    /// [`Sum::apply`] for any number of inputs and width.
    #[inline(never)]
    fn apply_any(&self, u: &[f64], y: &mut [f64]) {
        let n = self.width;
        if n == 1 {
            // Scalar fast path.
            y[0] = u.iter().zip(&self.gains).map(|(ui, g)| g * ui).sum();
            return;
        }
        y.fill(0.0);
        for (input, &g) in u.chunks_exact(n.max(1)).zip(&self.gains) {
            for (yi, ui) in y.iter_mut().zip(input) {
                *yi += g * ui;
            }
        }
    }
}

#[declared_block]
impl Block for Sum {
    fn build(&mut self, ctx: &BuildContext) -> Result<(), ParamError> {
        self.parse()?;
        self.dt = ctx.dt;
        Ok(())
    }
    fn output(&mut self, _tick: Tick, u: &[f64], y: &mut [f64]) {
        self.apply(u, y);
    }
    fn lti(&self) -> Option<StateSpace> {
        let n = self.width;
        let mut d = DMatrix::zeros(n, n * self.gains.len());
        for (j, &g) in self.gains.iter().enumerate() {
            for i in 0..n {
                d[(i, j * n + i)] = g;
            }
        }
        Some(static_ss(d, self.dt))
    }
}

// ---------------------------------------------------------------------------------
// product
// ---------------------------------------------------------------------------------

/// `product`: element-wise product y = in0·in1·…  of `factors` inputs of width `n`.
#[derive(Debug, Clone, Serialize, Deserialize, Params)]
#[serde(deny_unknown_fields)]
#[block(type_name = "product", role = Math, ports = "in{i}[width] for i in 0..factors -> y[width]")]
pub struct Product {
    /// Number of inputs multiplied.
    #[serde(default = "two")]
    #[param(size(1, MAX_PORTS))]
    pub factors: usize,
    /// Width n of every input and of the output.
    #[serde(default = "one")]
    #[param(width)]
    pub width: usize,
}

impl Product {
    /// The product of `factors` inputs of width `n`.
    pub fn new(factors: usize, n: usize) -> Self {
        Self { factors, width: n }
    }
    /// y = Π inᵢ element-wise; `u` holds the inputs concatenated.
    pub fn apply(&self, u: &[f64], y: &mut [f64]) {
        y.fill(1.0);
        for input in u.chunks_exact(self.width.max(1)) {
            for (yi, ui) in y.iter_mut().zip(input) {
                *yi *= ui;
            }
        }
    }
}

#[declared_block]
impl Block for Product {
    fn output(&mut self, _tick: Tick, u: &[f64], y: &mut [f64]) {
        self.apply(u, y);
    }
}

// ---------------------------------------------------------------------------------
// saturation
// ---------------------------------------------------------------------------------

/// `saturation`: y = min(max(u, lower), upper), element-wise; with `sharpness`
/// p, the smooth limit of an amplifier y = m + h·x/(1 + |x|^p)^{1/p}.
///
/// Hard (no `sharpness`): the clamp. Smooth: x = (u − m)/h with m, h the middle
/// and half-width of [lower, upper]; slope 1 at m, monotone for every p > 0,
/// `lower` and `upper` are approached, never reached (at u = upper the output
/// is m + h/2^{1/p}); p = 2 is the algebraic sigmoid, close to a tanh at
/// p ≈ 2.5, and the clamp is the limit p → ∞.
/// A NaN input passes as NaN (it is never hidden by the clamp).
/// [`Tunable`](crate::Tunable) parameter vector: `[lower, upper]`, then
/// `[sharpness]` when it is set.
#[derive(Debug, Clone, Serialize, Deserialize, Params)]
#[serde(deny_unknown_fields)]
#[block(type_name = "saturation", role = Math, ports = "u[width] -> y[width] [unit of u]", live = "lower, upper")]
pub struct Saturation {
    /// Lower limit (unit of u).
    #[param(at_most = upper)]
    pub lower: f64,
    /// Upper limit (unit of u), ≥ `lower`.
    pub upper: f64,
    /// Sharpness p of a smooth limit (> 0; omitted: the hard clamp).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    #[param(positive, default_doc = "hard clamp")]
    pub sharpness: Option<f64>,
    /// Signal width n.
    #[serde(default = "one")]
    #[param(width)]
    pub width: usize,
}

impl Saturation {
    /// A scalar saturation to `[lower, upper]`, e.g. the leg voltages `[0, 46]` V.
    pub fn new(lower: f64, upper: f64) -> Self {
        Self {
            lower,
            upper,
            sharpness: None,
            width: 1,
        }
    }
    /// One value limited to `[lower, upper]`: clamped, or the smooth limit of
    /// sharpness p.
    pub fn clamp(&self, u: f64) -> f64 {
        let Some(p) = self.sharpness else {
            return if u < self.lower {
                self.lower
            } else if u > self.upper {
                self.upper
            } else {
                u
            };
        };
        let (m, h) = (
            0.5 * (self.lower + self.upper),
            0.5 * (self.upper - self.lower),
        );
        if h <= 0.0 {
            return if u.is_nan() { u } else { m };
        }
        let x = (u - m) / h;
        // x/(1 + |x|^p)^{1/p}, written so that no power overflows.
        let limited = if x.abs() <= 1.0 {
            x / (1.0 + x.abs().powf(p)).powf(1.0 / p)
        } else {
            x.signum() / (1.0 + x.abs().powf(-p)).powf(1.0 / p)
        };
        m + h * limited
    }
    /// y = clamp(u) element-wise.
    pub fn apply(&self, u: &[f64], y: &mut [f64]) {
        for (yi, &ui) in y.iter_mut().zip(u) {
            *yi = self.clamp(ui);
        }
    }
}

#[declared_block]
impl Block for Saturation {
    fn output(&mut self, _tick: Tick, u: &[f64], y: &mut [f64]) {
        self.apply(u, y);
    }
    /// The limits (a drive's voltage or current limit tightened or relaxed
    /// while the stage moves); the sender's copy of the block refuses a
    /// `lower` above `upper` before it reaches the loop.
    fn set_live_param(&mut self, slot: usize, value: f64) {
        match slot {
            0 => self.lower = value,
            1 => self.upper = value,
            _ => {}
        }
    }
    fn linearisation(&self) -> Option<crate::block::Linearisation> {
        Some(crate::block::Linearisation::single(
            StateSpace::gain(nalgebra::DMatrix::identity(self.width, self.width), None),
            format!(
                "saturation to [{}, {}] judged as gain 1 (valid while the signal stays inside)",
                self.lower, self.upper
            ),
        ))
    }
    fn tunable(&self) -> Option<&dyn crate::Tunable> {
        Some(self)
    }
    fn tunable_mut(&mut self) -> Option<&mut dyn crate::Tunable> {
        Some(self)
    }
}

impl crate::Tunable for Saturation {
    fn param_names(&self) -> Vec<String> {
        let mut v: Vec<String> = vec!["lower".into(), "upper".into()];
        if self.sharpness.is_some() {
            v.push("sharpness".into());
        }
        v
    }
    fn params(&self) -> Vec<f64> {
        let mut v = vec![self.lower, self.upper];
        v.extend(self.sharpness);
        v
    }
    fn set_params(&mut self, p: &[f64]) -> Result<(), ParamError> {
        let want = 2 + usize::from(self.sharpness.is_some());
        if p.len() != want {
            return Err(ParamError::new(
                "params",
                format!("{} values given", p.len()),
                if want == 2 {
                    "give [lower, upper]"
                } else {
                    "give [lower, upper, sharpness]"
                },
            ));
        }
        let mut next = self.clone();
        next.lower = p[0];
        next.upper = p[1];
        next.sharpness = p.get(2).copied();
        next.check_params()?;
        *self = next;
        Ok(())
    }
}

// ---------------------------------------------------------------------------------
// deadzone
// ---------------------------------------------------------------------------------

/// `deadzone`: y = 0 inside `[lower, upper]`, y = u − upper above it and
/// y = u − lower below it (continuous, slope 1 outside the zone), element-wise.
/// Slope range ([`Block::sector`]) [0, 1]: between two samples y moves by a part
/// of u's move, in its direction.
#[derive(Debug, Clone, Serialize, Deserialize, Params)]
#[serde(deny_unknown_fields)]
#[block(type_name = "deadzone", role = Math, ports = "u[width] -> y[width] [unit of u]")]
pub struct Deadzone {
    /// Start of the dead zone (unit of u).
    #[param(at_most = upper)]
    pub lower: f64,
    /// End of the dead zone (unit of u), ≥ `lower`.
    pub upper: f64,
    /// Signal width n.
    #[serde(default = "one")]
    #[param(width)]
    pub width: usize,
}

impl Deadzone {
    /// A scalar dead zone `[lower, upper]`.
    pub fn new(lower: f64, upper: f64) -> Self {
        Self {
            lower,
            upper,
            width: 1,
        }
    }
    /// The dead-zone map of one value.
    pub fn map(&self, u: f64) -> f64 {
        if u > self.upper {
            u - self.upper
        } else if u < self.lower {
            u - self.lower
        } else if u.is_nan() {
            u
        } else {
            0.0
        }
    }
}

#[declared_block]
impl Block for Deadzone {
    fn output(&mut self, _tick: Tick, u: &[f64], y: &mut [f64]) {
        for (yi, &ui) in y.iter_mut().zip(u) {
            *yi = self.map(ui);
        }
    }
    fn sector(&self) -> Option<crate::Sector> {
        // Continuous, slope 0 inside the zone and 1 outside: every chord's
        // slope lies in [0, 1].
        Some(crate::Sector::new(
            0.0,
            1.0,
            "dead zone: 0 inside, 1 outside",
        ))
    }
}

// ---------------------------------------------------------------------------------
// mux / demux
// ---------------------------------------------------------------------------------

/// Most input ports of `sum`, `product`, `mux` and output ports of `demux`: 256.
pub const MAX_PORTS: usize = 256;

/// The concatenated width of `widths` (each declared 1 to
/// [`MAX_WIDTH`](crate::block::MAX_WIDTH), at most [`MAX_PORTS`] of them, checked
/// before) is a port's width too.
fn check_total_width(widths: &[usize]) -> Result<(), ParamError> {
    let total: usize = widths.iter().sum();
    check::width("widths (sum)", total)
}

/// A selection matrix: identity of size Σ widths (mux and demux only reorder
/// nothing: both are the identity on the concatenated vector).
fn identity_ss(widths: &[usize], dt: f64) -> StateSpace {
    let n: usize = widths.iter().sum();
    static_ss(DMatrix::identity(n, n), dt)
}

/// The `impl Block` of `mux` and `demux` (each with its `widths` and `dt`):
/// both are the identity on the concatenated vector — they differ in their
/// declared ports only — checked as their declared bounds and
/// [`check_total_width`].
macro_rules! concatenation_block {
    ($block:ident) => {
        #[declared_block]
        impl Block for $block {
            fn build(&mut self, ctx: &BuildContext) -> Result<(), ParamError> {
                self.check_params()?;
                check_total_width(&self.widths)?;
                self.dt = ctx.dt;
                Ok(())
            }
            fn output(&mut self, _tick: Tick, u: &[f64], y: &mut [f64]) {
                y.copy_from_slice(u);
            }
            fn lti(&self) -> Option<StateSpace> {
                Some(identity_ss(&self.widths, self.dt))
            }
        }
    };
}

/// `mux`: concatenates inputs `in0`, `in1`, ... (widths from `widths`) into one
/// vector `y`.
#[derive(Debug, Clone, Serialize, Deserialize, Params)]
#[serde(deny_unknown_fields)]
#[block(type_name = "mux", role = Math, ports = "in{i}[widths[i]] for i in 0..len(widths) -> y[Σwidths]")]
pub struct Mux {
    /// Width of each input, in port order, e.g. [1, 1, 1].
    #[param(len(1, MAX_PORTS), width, hint = "one width per port, e.g. [1, 1]")]
    pub widths: Vec<usize>,
    #[serde(skip)]
    dt: f64,
}

impl Mux {
    /// A mux of inputs with the given widths.
    pub fn new(widths: Vec<usize>) -> Self {
        Self { widths, dt: 0.0 }
    }
}

concatenation_block!(Mux);

/// `demux`: splits the input `u` into outputs `y0`, `y1`, ... (widths from `widths`).
#[derive(Debug, Clone, Serialize, Deserialize, Params)]
#[serde(deny_unknown_fields)]
#[block(type_name = "demux", role = Math, ports = "u[Σwidths] -> y{i}[widths[i]] for i in 0..len(widths)")]
pub struct Demux {
    /// Width of each output, in port order, e.g. [1, 1, 1].
    #[param(len(1, MAX_PORTS), width, hint = "one width per port, e.g. [1, 1]")]
    pub widths: Vec<usize>,
    #[serde(skip)]
    dt: f64,
}

impl Demux {
    /// A demux into outputs with the given widths.
    pub fn new(widths: Vec<usize>) -> Self {
        Self { widths, dt: 0.0 }
    }
}

concatenation_block!(Demux);

#[cfg(test)]
mod tests {
    use super::*;
    use crate::Port;

    fn ctx() -> BuildContext {
        BuildContext::new("t", 1e-3, 0)
    }

    fn run(b: &mut dyn Block, u: &[f64]) -> Vec<f64> {
        let w: usize = b.outputs().iter().map(|p| p.width).sum();
        let mut y = vec![0.0; w];
        b.output(Tick::new(0, 1e-3), u, &mut y);
        y
    }

    /// y = D u from the block's static lti() model.
    fn lti_apply(b: &dyn Block, u: &[f64]) -> Vec<f64> {
        let ss = b.lti().unwrap();
        assert_eq!(ss.a.nrows(), 0);
        assert_eq!(ss.dt, Some(1e-3));
        (&ss.d * nalgebra::DVector::from_column_slice(u))
            .iter()
            .copied()
            .collect()
    }

    #[test]
    fn gain_scales_each_channel_and_lti_agrees() {
        let mut g = Gain::with_width(-2.5, 3);
        g.build(&ctx()).unwrap();
        let u = [1.0, -4.0, 0.2];
        assert_eq!(run(&mut g, &u), vec![-2.5, 10.0, -0.5]);
        assert_eq!(lti_apply(&g, &u), vec![-2.5, 10.0, -0.5]);
        assert_eq!(Gain::new(f64::NAN).build(&ctx()).unwrap_err().field, "k");
        assert_eq!(
            Gain::with_width(1.0, 0).build(&ctx()).unwrap_err().field,
            "width"
        );
    }

    #[test]
    fn sum_applies_signs_per_port() {
        let mut s = Sum::with_width("+-+", 2).unwrap();
        s.build(&ctx()).unwrap();
        let names: Vec<String> = s.inputs().into_iter().map(|p| p.name).collect();
        assert_eq!(names, ["in0", "in1", "in2"]);
        let u = [1.0, 2.0, 10.0, 20.0, 100.0, 200.0];
        assert_eq!(run(&mut s, &u), vec![91.0, 182.0]);
        assert_eq!(lti_apply(&s, &u), vec![91.0, 182.0]);
        let e = Sum::new("+x").unwrap_err();
        assert_eq!(e.field, "signs");
        assert!(e.problem.contains("character 1"));
        assert_eq!(Sum::new("").unwrap_err().field, "signs");
    }

    #[test]
    fn product_multiplies_elementwise() {
        let mut p = Product::new(3, 2);
        p.build(&ctx()).unwrap();
        assert_eq!(
            run(&mut p, &[1.0, 2.0, 3.0, 4.0, 5.0, -6.0]),
            vec![15.0, -48.0]
        );
    }

    /// The smooth limit against its closed form: y(m) = m, slope 1 at m,
    /// y(upper) = m + h/2^{1/p}, odd about m, monotone, within [lower, upper]
    /// (reached only in round-off) even for inputs whose |x|^p overflows, and
    /// the clamp as p grows.
    #[test]
    fn a_smooth_saturation_follows_its_closed_form() {
        let (lower, upper, p) = (-1.0, 3.0, 2.5);
        let (m, h) = (1.0, 2.0);
        let mut s = Saturation::new(lower, upper);
        s.sharpness = Some(p);
        s.build(&ctx()).unwrap();
        assert_eq!(s.clamp(m), m);
        let d = 1e-6;
        assert!(((s.clamp(m + d) - s.clamp(m - d)) / (2.0 * d) - 1.0).abs() < 1e-9);
        assert!((s.clamp(upper) - (m + h / 2f64.powf(1.0 / p))).abs() < 1e-12);
        for x in [0.3, 1.7, 40.0] {
            let (hi, lo) = (s.clamp(m + x * h), s.clamp(m - x * h));
            assert!((hi - m + (lo - m)).abs() < 1e-12, "odd about m at x = {x}");
            let closed = m + h * x / (1.0 + x.powf(p)).powf(1.0 / p);
            assert!((hi - closed).abs() < 1e-12, "x = {x}: {hi} vs {closed}");
        }
        let ys: Vec<f64> = (0..400).map(|k| s.clamp(-20.0 + 0.1 * k as f64)).collect();
        assert!(ys.windows(2).all(|w| w[1] > w[0]), "monotone");
        for u in [1e300, -1e300] {
            let y = s.clamp(u);
            assert!(y.is_finite() && y >= lower && y <= upper, "{u:e} -> {y}");
        }
        s.sharpness = Some(200.0);
        assert!((s.clamp(2.0) - 2.0).abs() < 1e-4 && (s.clamp(5.0) - upper).abs() < 1e-4);
        assert!(s.clamp(f64::NAN).is_nan());
        // Tunable: the sharpness is the third parameter, checked like the field.
        use crate::Tunable;
        assert_eq!(s.param_names(), ["lower", "upper", "sharpness"]);
        s.set_params(&[0.0, 2.0, 3.0]).unwrap();
        assert_eq!(s.params(), vec![0.0, 2.0, 3.0]);
        assert_eq!(
            s.set_params(&[0.0, 2.0, -1.0]).unwrap_err().field,
            "sharpness"
        );
        assert_eq!(s.set_params(&[0.0, 2.0]).unwrap_err().field, "params");
        assert_eq!(
            s.params(),
            vec![0.0, 2.0, 3.0],
            "a refused vector changes nothing"
        );
    }

    #[test]
    fn saturation_clamps_and_passes_nan() {
        let mut s = Saturation::new(0.0, 46.0);
        s.build(&ctx()).unwrap();
        assert_eq!(run(&mut s, &[-3.0]), vec![0.0]);
        assert_eq!(run(&mut s, &[12.5]), vec![12.5]);
        assert_eq!(run(&mut s, &[99.0]), vec![46.0]);
        assert!(run(&mut s, &[f64::NAN])[0].is_nan());
        assert_eq!(
            Saturation::new(1.0, 0.0).build(&ctx()).unwrap_err().field,
            "lower"
        );
        assert_eq!(
            Saturation::new(0.0, f64::INFINITY)
                .build(&ctx())
                .unwrap_err()
                .field,
            "upper"
        );
    }

    #[test]
    fn live_limits_take_effect_at_the_next_sample() {
        let mut s = Saturation::new(0.0, 46.0);
        s.build(&ctx()).unwrap();
        assert_eq!(s.live_params(), ["lower", "upper"]);
        assert_eq!(run(&mut s, &[40.0]), vec![40.0]);
        s.set_live_param(1, 30.0);
        assert_eq!(run(&mut s, &[40.0]), vec![30.0]);
        s.set_live_param(0, -5.0);
        assert_eq!(run(&mut s, &[-9.0]), vec![-5.0]);
        // A slot out of range changes nothing.
        s.set_live_param(2, 1.0);
        assert_eq!((s.lower, s.upper), (-5.0, 30.0));
        // The same as a block built with those limits.
        let mut built = Saturation::new(-5.0, 30.0);
        built.build(&ctx()).unwrap();
        for u in [-40.0, -5.0, 0.3, 29.9, 31.0] {
            assert_eq!(run(&mut s, &[u]), run(&mut built, &[u]), "u = {u}");
        }
    }

    #[test]
    fn deadzone_is_continuous_with_unit_slope() {
        let mut d = Deadzone::new(-1.0, 2.0);
        d.build(&ctx()).unwrap();
        for (u, y) in [
            (-3.0, -2.0),
            (-1.0, 0.0),
            (0.5, 0.0),
            (2.0, 0.0),
            (5.0, 3.0),
        ] {
            assert_eq!(run(&mut d, &[u]), vec![y], "u = {u}");
        }
        assert_eq!(
            Deadzone::new(3.0, 2.0).build(&ctx()).unwrap_err().field,
            "lower"
        );
    }

    #[test]
    fn mux_then_demux_is_identity() {
        let mut m = Mux::new(vec![1, 2]);
        let mut d = Demux::new(vec![2, 1]);
        m.build(&ctx()).unwrap();
        d.build(&ctx()).unwrap();
        assert_eq!(m.outputs(), vec![Port::new("y", 3)]);
        assert_eq!(d.outputs(), vec![Port::new("y0", 2), Port::new("y1", 1)]);
        let y = run(&mut m, &[1.0, 2.0, 3.0]);
        assert_eq!(run(&mut d, &y), vec![1.0, 2.0, 3.0]);
        assert_eq!(lti_apply(&m, &[4.0, 5.0, 6.0]), vec![4.0, 5.0, 6.0]);
        assert_eq!(Mux::new(vec![]).build(&ctx()).unwrap_err().field, "widths");
        assert_eq!(
            Demux::new(vec![1, 0]).build(&ctx()).unwrap_err().field,
            "widths[1]"
        );
    }

    /// The ports each block declares: names, widths from `width`/`widths`,
    /// one input per sign or factor, and the unit passed through where the
    /// output is in its input's unit.
    #[test]
    fn declared_ports_follow_the_parameters() {
        let same = |n: usize| (Port::new("u", n), Port::new("y", n).unit_of_input(0));
        let g = Gain::with_width(2.0, 3);
        assert_eq!(
            (g.inputs(), g.outputs()),
            (vec![Port::new("u", 3)], vec![Port::new("y", 3)])
        );
        let mut sat = Saturation::new(0.0, 1.0);
        sat.width = 2;
        let mut dz = Deadzone::new(0.0, 1.0);
        dz.width = 2;
        for b in [&sat as &dyn Block, &dz] {
            let (u, y) = same(2);
            assert_eq!((b.inputs(), b.outputs()), (vec![u], vec![y]));
        }
        let s = Sum::with_width("+-+", 2).unwrap();
        let ins: Vec<Port> = (0..3).map(|i| Port::new(format!("in{i}"), 2)).collect();
        assert_eq!(s.inputs(), ins);
        assert_eq!(s.outputs(), vec![Port::new("y", 2).unit_of_input(0)]);
        let p = Product::new(3, 2);
        assert_eq!(p.inputs(), ins);
        assert_eq!(p.outputs(), vec![Port::new("y", 2)]);
        let m = Mux::new(vec![1, 4]);
        assert_eq!(m.inputs(), vec![Port::new("in0", 1), Port::new("in1", 4)]);
        let d = Demux::new(vec![1, 4]);
        assert_eq!(d.inputs(), vec![Port::new("u", 5)]);
        // unchecked widths that overflow a sum give no panic (build refuses them)
        let huge = Mux::new(vec![usize::MAX, 2]);
        assert_eq!(huge.outputs()[0].width, usize::MAX);
        assert_eq!(
            Demux::new(vec![usize::MAX, 2]).inputs()[0].width,
            usize::MAX
        );
    }

    #[test]
    fn library_blocks_are_registered_and_documented() {
        let names = [
            "gain",
            "sum",
            "product",
            "saturation",
            "deadzone",
            "mux",
            "demux", // math
            "pid",
            "pi", // control
            "constant",
            "step",
            "constant_velocity",
            "sinusoid",
            "triangular_scan",
            "point_to_point",
            "white_noise", // sources
            "quantizer",
            "measurement_noise", // sensors
        ];
        // Ask typetag for its registry with an unknown tag (as
        // `block::registered_types` does, with a tag the YAML parser accepts).
        let err = crate::yaml::from_str::<Box<dyn Block>>("type: no_such_block_zz\n", "probe")
            .unwrap_err();
        let types = crate::block::parse_expected_list(&err.to_string());
        let docs = crate::block::block_docs();
        for name in names {
            assert!(
                types.iter().any(|t| t == name),
                "`{name}` not registered with typetag"
            );
            let doc = docs
                .iter()
                .find(|d| d.type_name == name)
                .unwrap_or_else(|| panic!("`{name}` has no BlockDoc"));
            assert!(!doc.summary.is_empty() && !doc.ports.is_empty());
        }
    }

    #[test]
    fn blocks_load_from_yaml() {
        let b: Box<dyn Block> = crate::yaml::from_str("type: sum\nsigns: \"+-\"\n", "t").unwrap();
        assert_eq!(b.inputs().len(), 2);
        let e = crate::yaml::from_str::<Box<dyn Block>>("type: gain\nk: 1\nkk: 2\n", "t");
        assert!(e.is_err(), "unknown fields are rejected");
    }
}
