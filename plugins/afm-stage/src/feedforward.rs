//! Feed-forward of Sec. 6.4: the exact inverse of the extended hysteresis model
//! (6.6) with trace/retrace switching at standstill (Fig. 6.9), and the plain
//! position feed-forward (6.7) it is compared with.
//!
//! Both take the reference position in metres (the unit of the core's reference
//! sources) and produce a voltage in V; the hysteresis model works in µm, so
//! x_µm = 10⁶·r_m.

use crate::error::{AfmError, finite};
use crate::hysteresis::{Branch, Direction, ExtendedCh};
use nanomotion_core::Params;
use nanomotion_core::{Block, BuildContext, Controller, ParamError, Tick, declared_block};
use serde::{Deserialize, Serialize};

/// Solve for the voltage range [V_m, V_M] on which branch `dir` of `model` runs from
/// `x_lo` to `x_hi` (µm): branch(V_m) = x_lo and branch(V_M) = x_hi, by Newton's
/// method with a finite-difference Jacobian from the guess x/b.
pub fn voltage_range_for(
    model: &ExtendedCh,
    dir: Direction,
    x_lo: f64,
    x_hi: f64,
) -> Result<(f64, f64), AfmError> {
    finite("x_lo", x_lo)?;
    finite("x_hi", x_hi)?;
    if x_hi <= x_lo {
        return Err(AfmError::param(
            "x_hi",
            format!("{x_hi} ≤ x_lo = {x_lo}: the position range must be positive"),
        ));
    }
    let b = model.params(dir).b_um_per_v;
    if !(b > 0.0) {
        return Err(AfmError::param(
            "b_um_per_v",
            format!("is {b}, must be > 0 for an invertible model"),
        ));
    }
    let resid = |vm: f64, vx: f64| -> Option<[f64; 2]> {
        let br = model.branch(dir, vm, vx).ok()?;
        Some([br.eval(vm) - x_lo, br.eval(vx) - x_hi])
    };
    let (mut vm, mut vx) = (x_lo / b, x_hi / b);
    let scale = (x_hi - x_lo).abs();
    for _ in 0..100 {
        let Some(r) = resid(vm, vx) else { break };
        if r[0].abs().max(r[1].abs()) < 1e-12 * scale.max(1.0) {
            return Ok((vm, vx));
        }
        let h = 1e-6 * (vx - vm).abs().max(1e-3);
        let (Some(a1), Some(a0), Some(b1), Some(b0)) = (
            resid(vm + h, vx),
            resid(vm - h, vx),
            resid(vm, vx + h),
            resid(vm, vx - h),
        ) else {
            break;
        };
        let j = [
            [(a1[0] - a0[0]) / (2.0 * h), (b1[0] - b0[0]) / (2.0 * h)],
            [(a1[1] - a0[1]) / (2.0 * h), (b1[1] - b0[1]) / (2.0 * h)],
        ];
        let det = j[0][0] * j[1][1] - j[0][1] * j[1][0];
        if !(det.abs() > 0.0) || !det.is_finite() {
            break;
        }
        let d0 = (j[1][1] * r[0] - j[0][1] * r[1]) / det;
        let d1 = (-j[1][0] * r[0] + j[0][0] * r[1]) / det;
        // Damped step that keeps V_M > V_m.
        let mut lam = 1.0;
        while lam > 1e-6 && (vx - lam * d1) <= (vm - lam * d0) {
            lam *= 0.5;
        }
        vm -= lam * d0;
        vx -= lam * d1;
    }
    Err(AfmError::Fit(format!(
        "no voltage range found for the {} branch to cover [{x_lo}, {x_hi}] µm",
        dir.as_str()
    )))
}

/// Inverse hysteresis feed-forward (6.6) with model switching at standstill (Fig. 6.9).
///
/// The trace inverse is used while the reference increases, the retrace inverse
/// while it decreases; at standstill (|Δr| ≤ `standstill_um`) the last branch is
/// kept, so the switch happens at the turnaround. Each branch runs on its own
/// voltage range, chosen so that it covers the position range exactly
/// ([`voltage_range_for`]); with asymmetric models the voltage jumps at the switch,
/// as in the thesis (Sec. 6.5.1).
///
/// ```
/// use afm_stage::feedforward::HysteresisFeedForward;
/// use afm_stage::hysteresis::{ChParams, ExtendedBranch, ExtendedCh, Direction};
/// let m = ExtendedCh::symmetric(ExtendedBranch::from_ch(&ChParams::new(0.03, 1.0, 0.7))).unwrap();
/// let mut ff = HysteresisFeedForward::for_position_range(m, 20.0, 60.0).unwrap();
/// let v = ff.voltage(35.0).unwrap();
/// let br = ff.branch(Direction::Trace);
/// assert!((br.eval(v) - 35.0).abs() < 1e-9);
/// ```
#[derive(Debug, Clone, PartialEq)]
pub struct HysteresisFeedForward {
    model: ExtendedCh,
    trace: Branch,
    retrace: Branch,
    dir: Direction,
    last_x: Option<f64>,
    standstill_um: f64,
    out_of_range: u64,
}

impl HysteresisFeedForward {
    /// Both branches on the same voltage range [v_m, v_max] (V).
    pub fn for_voltage_range(model: ExtendedCh, v_m: f64, v_max: f64) -> Result<Self, AfmError> {
        let trace = model.branch(Direction::Trace, v_m, v_max)?;
        let retrace = model.branch(Direction::Retrace, v_m, v_max)?;
        Self::from_branches(model, trace, retrace)
    }

    /// Each branch on the voltage range that makes it cover [x_lo, x_hi] (µm).
    pub fn for_position_range(model: ExtendedCh, x_lo: f64, x_hi: f64) -> Result<Self, AfmError> {
        let (a, b) = voltage_range_for(&model, Direction::Trace, x_lo, x_hi)?;
        let (c, d) = voltage_range_for(&model, Direction::Retrace, x_lo, x_hi)?;
        let trace = model.branch(Direction::Trace, a, b)?;
        let retrace = model.branch(Direction::Retrace, c, d)?;
        Self::from_branches(model, trace, retrace)
    }

    fn from_branches(model: ExtendedCh, trace: Branch, retrace: Branch) -> Result<Self, AfmError> {
        trace.check_monotone()?;
        retrace.check_monotone()?;
        Ok(Self {
            model,
            trace,
            retrace,
            dir: Direction::Trace,
            last_x: None,
            standstill_um: 0.0,
            out_of_range: 0,
        })
    }

    /// Reference changes of at most `eps_um` (µm per sample) count as standstill.
    pub fn with_standstill(mut self, eps_um: f64) -> Self {
        self.standstill_um = eps_um.abs();
        self
    }

    /// The model.
    pub fn model(&self) -> &ExtendedCh {
        &self.model
    }

    /// The branch used for direction `dir`.
    pub fn branch(&self, dir: Direction) -> &Branch {
        match dir {
            Direction::Trace => &self.trace,
            Direction::Retrace => &self.retrace,
        }
    }

    /// Present direction.
    pub fn direction(&self) -> Direction {
        self.dir
    }

    /// Force the direction (e.g. before the first sample of a retrace).
    pub fn set_direction(&mut self, dir: Direction) {
        self.dir = dir;
    }

    /// How many samples were outside the invertible range (and clamped).
    pub fn out_of_range_count(&self) -> u64 {
        self.out_of_range
    }

    /// Voltage for position `x_um` on the present branch, with typed errors.
    pub fn voltage(&self, x_um: f64) -> Result<f64, AfmError> {
        self.branch(self.dir).inverse_checked(x_um)
    }

    /// One sample: update the direction from the change of `x_um` (switch only
    /// after standstill, i.e. when the motion reverses), return the voltage. A
    /// position outside the range is clamped to it and counted. No allocation.
    pub fn step(&mut self, x_um: f64) -> f64 {
        if let Some(last) = self.last_x {
            let dx = x_um - last;
            if dx > self.standstill_um {
                self.dir = Direction::Trace;
            } else if dx < -self.standstill_um {
                self.dir = Direction::Retrace;
            }
        }
        self.last_x = Some(x_um);
        let br = *self.branch(self.dir);
        let (lo, hi) = br.range();
        let tol = 1e-9 * (hi - lo);
        let x = if x_um.is_nan() {
            self.out_of_range += 1;
            lo
        } else if x_um < lo - tol || x_um > hi + tol {
            self.out_of_range += 1;
            x_um.clamp(lo, hi)
        } else {
            x_um.clamp(lo, hi)
        };
        br.inverse(x).clamp(br.v_m, br.v_max)
    }

    /// Forget the direction history.
    pub fn reset(&mut self) {
        self.dir = Direction::Trace;
        self.last_x = None;
        self.out_of_range = 0;
    }
}

// ---------------------------------------------------------------------------------
// Blocks
// ---------------------------------------------------------------------------------

fn default_standstill() -> f64 {
    0.0
}

/// How the feed-forward's voltage range is chosen.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize, Params)]
#[serde(deny_unknown_fields, rename_all = "snake_case")]
pub enum FfRange {
    /// Both branches on [v_min_v, v_max_v] (V).
    Voltage {
        /// V_m (V).
        #[param(at_most = v_max_v)]
        v_min_v: f64,
        /// V_M (V).
        v_max_v: f64,
    },
    /// Each branch on the voltage range that covers [x_min_m, x_max_m] (m).
    Position {
        /// Lowest reference position (m).
        #[param(at_most = x_max_m)]
        x_min_m: f64,
        /// Highest reference position (m).
        x_max_m: f64,
    },
}

/// `hysteresis_feedforward`: inverse extended Coleman–Hodgdon hysteresis feed-forward
/// (6.6) with trace/retrace switching at standstill (Fig. 6.9).
///
/// Inverse extended Coleman–Hodgdon model (6.6) with
/// trace/retrace switching at standstill (Fig. 6.9). Input `r` (m), outputs `v` (V)
/// and `state` = [direction (+1 trace, −1 retrace), out-of-range samples so far].
#[derive(Debug, Clone, Serialize, Deserialize, Params)]
#[serde(deny_unknown_fields)]
#[block(type_name = "hysteresis_feedforward", role = Controller, ports = "r (m) -> v (V), state[2] \"direction ±1, out-of-range count\"")]
pub struct HysteresisFeedForwardBlock {
    /// The identified model (6.4): `trace` and `retrace` parameter sets (µm, V).
    /// Each set: {a_um_per_v, b_um_per_v, c_per_v, u_um_per_v, alpha_per_v, d_um_per_v2,
    /// e_um_per_v, f_um}.
    pub model: ExtendedCh,
    /// Voltage range, given directly or through the position range it must cover.
    #[param(nested)]
    pub range: FfRange,
    /// Reference steps of at most this size (m per sample) count as standstill.
    #[serde(default = "default_standstill")]
    #[param(non_negative)]
    pub standstill_m: f64,
    #[serde(skip)]
    ff: Option<HysteresisFeedForward>,
}

impl HysteresisFeedForwardBlock {
    /// A block for `model` on `range`.
    pub fn new(model: ExtendedCh, range: FfRange) -> Self {
        Self {
            model,
            range,
            standstill_m: 0.0,
            ff: None,
        }
    }
}

impl Controller for HysteresisFeedForwardBlock {
    fn control(&mut self, r: &[f64], v: &mut [f64]) {
        v[0] = match self.ff.as_mut() {
            Some(ff) => ff.step(r[0] * 1e6),
            None => 0.0,
        };
    }
    fn reset(&mut self) {
        if let Some(ff) = self.ff.as_mut() {
            ff.reset();
        }
    }
}

#[declared_block]
impl Block for HysteresisFeedForwardBlock {
    fn build(&mut self, _ctx: &BuildContext) -> Result<(), ParamError> {
        self.check_params()?;
        self.model.trace.validate("model.trace.")?;
        self.model.retrace.validate("model.retrace.")?;
        let ff = match self.range {
            // v_min_v ≤ v_max_v, x_min_m ≤ x_max_m: declared (`at_most`), checked above
            FfRange::Voltage { v_min_v, v_max_v } => {
                HysteresisFeedForward::for_voltage_range(self.model, v_min_v, v_max_v)
            }
            FfRange::Position { x_min_m, x_max_m } => {
                HysteresisFeedForward::for_position_range(self.model, x_min_m * 1e6, x_max_m * 1e6)
            }
        }
        .map_err(|e| {
            ParamError::new(
                "range",
                e.to_string(),
                "choose a range on which the model is strictly increasing",
            )
        })?;
        self.ff = Some(ff.with_standstill(self.standstill_m * 1e6));
        Ok(())
    }
    fn output(&mut self, _tick: Tick, u: &[f64], y: &mut [f64]) {
        self.control(&u[..1], &mut y[..1]);
        if let Some(ff) = &self.ff {
            y[1] = match ff.direction() {
                Direction::Trace => 1.0,
                Direction::Retrace => -1.0,
            };
            y[2] = ff.out_of_range_count() as f64;
        }
    }
}

/// `position_feedforward`: position feed-forward (6.7): v = K·r + V0.
///
/// Position feed-forward (6.7): V = K·r + V₀.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize, Params)]
#[serde(deny_unknown_fields)]
#[block(type_name = "position_feedforward", role = Controller, ports = "r (m) -> v (V)")]
pub struct PositionFeedForward {
    /// K (V/µm): inverse of the stage sensitivity.
    #[param(finite)]
    pub gain_v_per_um: f64,
    /// V₀ (V): voltage at r = 0.
    #[serde(default)]
    #[param(finite)]
    pub offset_v: f64,
}

impl PositionFeedForward {
    /// V = K·r + V₀ with K in V/µm.
    pub fn new(gain_v_per_um: f64, offset_v: f64) -> Self {
        Self {
            gain_v_per_um,
            offset_v,
        }
    }
    /// Voltage for position `x_um` (µm).
    pub fn voltage(&self, x_um: f64) -> f64 {
        self.gain_v_per_um * x_um + self.offset_v
    }
}

impl Controller for PositionFeedForward {
    fn control(&mut self, r: &[f64], v: &mut [f64]) {
        v[0] = self.voltage(r[0] * 1e6);
    }
    fn reset(&mut self) {}
}

#[declared_block]
impl Block for PositionFeedForward {
    fn output(&mut self, _tick: Tick, u: &[f64], y: &mut [f64]) {
        self.control(u, y);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::hysteresis::ExtendedBranch;
    use proptest::prelude::*;

    fn model() -> ExtendedCh {
        ExtendedCh::new(
            ExtendedBranch {
                a_um_per_v: 0.15,
                b_um_per_v: 1.0,
                c_per_v: -0.03,
                u_um_per_v: 0.7,
                alpha_per_v: 0.03,
                d_um_per_v2: 2e-4,
                e_um_per_v: -0.02,
                f_um: 0.3,
            },
            ExtendedBranch {
                a_um_per_v: 0.1,
                b_um_per_v: 0.95,
                c_per_v: -0.04,
                u_um_per_v: 0.6,
                alpha_per_v: 0.045,
                d_um_per_v2: -1e-4,
                e_um_per_v: 0.01,
                f_um: -0.2,
            },
        )
        .unwrap()
    }

    /// `standstill_m` ≥ 0 is declared on the field: `build()` refuses a negative
    /// or non-finite value by name, and the schema carries the bound.
    #[test]
    fn a_negative_standstill_is_refused_by_name() {
        let ctx = BuildContext::new("ff", 1e-4, 0);
        let range = FfRange::Position {
            x_min_m: 25e-6,
            x_max_m: 61e-6,
        };
        for bad in [-1e-9, f64::NAN] {
            let mut b = HysteresisFeedForwardBlock::new(model(), range);
            b.standstill_m = bad;
            let e = b.build(&ctx).unwrap_err();
            assert_eq!(e.field, "standstill_m", "{e}");
        }
        HysteresisFeedForwardBlock::new(model(), range)
            .build(&ctx)
            .unwrap();
        let docs = HysteresisFeedForwardBlock::param_docs();
        let s = docs.iter().find(|p| p.name == "standstill_m").unwrap();
        assert_eq!(s.schema["minimum"], 0);
        assert_eq!(s.bounds, ["≥ 0"]);
    }

    #[test]
    fn position_range_is_covered_exactly() {
        let ff = HysteresisFeedForward::for_position_range(model(), 25.0, 61.0).unwrap();
        for dir in [Direction::Trace, Direction::Retrace] {
            let (lo, hi) = ff.branch(dir).range();
            assert!(
                (lo - 25.0).abs() < 1e-9 && (hi - 61.0).abs() < 1e-9,
                "{dir:?}: {lo} {hi}"
            );
        }
        assert!(HysteresisFeedForward::for_position_range(model(), 5.0, 5.0).is_err());
    }

    #[test]
    fn switches_at_turnaround_only() {
        let mut ff = HysteresisFeedForward::for_position_range(model(), 25.0, 61.0).unwrap();
        let up: Vec<f64> = (0..=36).map(|k| 25.0 + k as f64).collect();
        for &x in &up {
            let v = ff.step(x);
            assert_eq!(ff.direction(), Direction::Trace);
            assert!((ff.branch(Direction::Trace).eval(v) - x).abs() < 1e-9);
        }
        // Standstill at the top keeps the trace branch.
        ff.step(61.0);
        assert_eq!(ff.direction(), Direction::Trace);
        let v = ff.step(60.0);
        assert_eq!(ff.direction(), Direction::Retrace);
        assert!((ff.branch(Direction::Retrace).eval(v) - 60.0).abs() < 1e-9);
        // Outside the range: clamped and counted, never NaN.
        let v = ff.step(1e4);
        assert!(v.is_finite());
        let v = ff.step(f64::NAN);
        assert!(v.is_finite());
        assert_eq!(ff.out_of_range_count(), 2);
        assert!(matches!(ff.voltage(1e4), Err(AfmError::OutOfRange { .. })));
    }

    #[test]
    fn position_feedforward_is_affine() {
        let mut p = PositionFeedForward::new(1.1, 2.0);
        let mut v = [0.0];
        p.control(&[10e-6], &mut v);
        assert!((v[0] - 13.0).abs() < 1e-12);
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(256))]
        /// model(inverse(x)) = x over the whole invertible range, for random models
        /// and ranges.
        #[test]
        fn model_of_inverse_is_identity(
            b in 0.5f64..2.0, frac_u in 0.2f64..0.95, alpha in 0.005f64..0.2,
            a_frac in 0.0f64..0.3, c in -0.1f64..0.0, d in -1e-3f64..1e-3, e in -0.1f64..0.1, f in -2.0f64..2.0,
            v_m in -20.0f64..50.0, v_r in 2.0f64..100.0, s in 0.0f64..=1.0, trace in any::<bool>()
        ) {
            let br = ExtendedBranch {
                a_um_per_v: a_frac * b, b_um_per_v: b, c_per_v: c, u_um_per_v: frac_u * b,
                alpha_per_v: alpha, d_um_per_v2: d, e_um_per_v: e, f_um: f,
            };
            let m = ExtendedCh::symmetric(br).unwrap();
            let dir = if trace { Direction::Trace } else { Direction::Retrace };
            let branch = m.branch(dir, v_m, v_m + v_r).unwrap();
            if branch.check_monotone().is_ok() {
                let (lo, hi) = branch.range();
                let x = lo + s * (hi - lo);
                let v = branch.inverse_checked(x).unwrap();
                prop_assert!(v >= v_m - 1e-9 && v <= v_m + v_r + 1e-9);
                let back = branch.eval(v);
                prop_assert!((back - x).abs() <= 1e-9 * (1.0 + x.abs()), "x {} back {}", x, back);
            }
        }
    }
}
