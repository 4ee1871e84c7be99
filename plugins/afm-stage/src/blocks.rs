//! Graph blocks of the standalone hysteresis models: `coleman_hodgdon` (the
//! differential model, exact per sample) and `extended_coleman_hodgdon` (6.4) on a
//! fixed voltage range. (The plant is `afm_stage`, the feed-forwards are
//! `hysteresis_feedforward` and `position_feedforward`.)

use crate::hysteresis::{CH_NAMES_UM_V, ChParams, ColemanHodgdon, Direction, ExtendedCh};
use nanomotion_core::Params;
use nanomotion_core::{Actuator, Block, BuildContext, ParamError, Sector, Tick, declared_block};
use serde::{Deserialize, Serialize};

/// `coleman_hodgdon`: Coleman–Hodgdon piezo hysteresis dx/dt = α|V̇|(bV − x) + uV̇
/// (6.3), exact per sample, optional asymmetric retrace set.
///
/// Piezo hysteresis x = H(V) by the Coleman–Hodgdon ODE
/// dx/dt = α|V̇|(bV − x) + uV̇, integrated exactly per sample, with optional
/// separate retrace parameters. Input `v` (V), output `x` (µm). Slope range
/// ([`Block::sector`]): the model's ([`ColemanHodgdon::sector`]), [min(2u − b,
/// b), max(2u − b, b)] µm/V when symmetric; none when the retrace b differs.
#[derive(Debug, Clone, Serialize, Deserialize, Params)]
#[serde(deny_unknown_fields)]
#[block(type_name = "coleman_hodgdon", role = Actuator, ports = "v (V) -> x (µm)")]
pub struct ColemanHodgdonBlock {
    /// Parameters for increasing voltage (α in 1/V, b and u in µm/V).
    /// {alpha_per_v (1/V), b_um_per_v, u_um_per_v (µm/V)}, also spelled {alpha, b, c} (the
    /// core model's names).
    pub trace: ChParams,
    /// Parameters for decreasing voltage (default: the trace set).
    #[serde(default)]
    #[param(default_doc = "= trace")]
    pub retrace: Option<ChParams>,
    /// Initial voltage (V), reached along the virgin curve from x = 0 at 0 V.
    #[serde(default)]
    #[param(finite)]
    pub initial_v: f64,
    #[serde(skip)]
    h: Option<ColemanHodgdon>,
}

impl ColemanHodgdonBlock {
    /// A symmetric block.
    pub fn new(p: ChParams) -> Self {
        Self {
            trace: p,
            retrace: None,
            initial_v: 0.0,
            h: None,
        }
    }
}

impl Actuator for ColemanHodgdonBlock {
    fn drive(&mut self, command: &[f64], drive: &mut [f64]) {
        drive[0] = match self.h.as_mut() {
            Some(h) if command[0].is_finite() => h.step(command[0]),
            Some(h) => h.position(),
            None => 0.0,
        };
    }
}

#[declared_block]
impl Block for ColemanHodgdonBlock {
    fn build(&mut self, _ctx: &BuildContext) -> Result<(), ParamError> {
        self.check_params()?;
        let retrace = self.retrace.unwrap_or(self.trace);
        self.trace.validate_as("trace.", &CH_NAMES_UM_V)?;
        retrace.validate_as("retrace.", &CH_NAMES_UM_V)?;
        let mut h = ColemanHodgdon::new(self.trace, retrace)?;
        h.step(self.initial_v);
        self.h = Some(h);
        Ok(())
    }
    fn output(&mut self, _tick: Tick, u: &[f64], y: &mut [f64]) {
        self.drive(u, y);
    }
    fn sector(&self) -> Option<Sector> {
        // From the built state: x = 0 at 0 V moved to `initial_v` along the
        // virgin curve, inside the model's band.
        self.h.as_ref()?.sector()
    }
}

/// `extended_coleman_hodgdon`: extended asymmetric Coleman–Hodgdon model (6.4) on a
/// fixed voltage range, trace/retrace by the sign of ΔV.
///
/// The extended asymmetric model (6.4) on the fixed
/// range [v_min_v, v_max_v]; the branch follows the sign of ΔV and is kept at
/// standstill. Input `v` (V), output `x` (µm). No slope range: a reversal inside
/// the range switches from one fixed branch to the other, a jump of x for an
/// arbitrarily small ΔV (the branches meet only at V_m and V_M).
#[derive(Debug, Clone, Serialize, Deserialize, Params)]
#[serde(deny_unknown_fields)]
#[block(type_name = "extended_coleman_hodgdon", role = Actuator, ports = "v (V) -> x (µm)")]
pub struct ExtendedChBlock {
    /// The model (6.4): `trace` and `retrace` parameter sets.
    /// Each set: {a_um_per_v, b_um_per_v, c_per_v, u_um_per_v, alpha_per_v, d_um_per_v2,
    /// e_um_per_v, f_um}.
    pub model: ExtendedCh,
    /// V_m (V).
    #[param(at_most = v_max_v)]
    pub v_min_v: f64,
    /// V_M (V).
    pub v_max_v: f64,
    #[serde(skip)]
    state: Option<(Direction, f64)>,
}

#[declared_block]
impl Block for ExtendedChBlock {
    fn build(&mut self, _ctx: &BuildContext) -> Result<(), ParamError> {
        self.model.trace.validate("model.trace.")?;
        self.model.retrace.validate("model.retrace.")?;
        self.check_params()?;
        if self.v_min_v == self.v_max_v {
            return Err(ParamError::new(
                "v_max_v",
                "equals v_min_v (V_R = 0)",
                "give V_M > V_m",
            ));
        }
        self.state = Some((Direction::Trace, self.v_min_v));
        Ok(())
    }
    fn output(&mut self, _tick: Tick, u: &[f64], y: &mut [f64]) {
        let Some((dir, last)) = self.state.as_mut() else {
            y[0] = 0.0;
            return;
        };
        let v = if u[0].is_finite() {
            u[0].clamp(self.v_min_v, self.v_max_v)
        } else {
            *last
        };
        if v > *last {
            *dir = Direction::Trace;
        } else if v < *last {
            *dir = Direction::Retrace;
        }
        *last = v;
        y[0] = self
            .model
            .eval(v, self.v_min_v, self.v_max_v, *dir)
            .unwrap_or(0.0);
    }
    fn sector(&self) -> Option<Sector> {
        // None: the switch between the two fixed branches at a reversal is a
        // jump of x for an arbitrarily small ΔV (see the type's docs).
        None
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::hysteresis::ch_closed_loop;

    const DT: f64 = 1e-4;

    fn yaml(text: &str) -> Box<dyn Block> {
        nanomotion_core::yaml::from_str::<Box<dyn Block>>(text, "test").unwrap()
    }

    #[test]
    fn blocks_reproduce_the_closed_loop_and_do_not_allocate() {
        let mut ch = yaml(
            "type: coleman_hodgdon\ntrace: {alpha_per_v: 0.03, b_um_per_v: 1.0, u_um_per_v: 0.7}\n",
        );
        ch.build(&BuildContext::new("h", DT, 0)).unwrap();
        let mut ext = yaml(
            "type: extended_coleman_hodgdon\nv_min_v: 0\nv_max_v: 100\nmodel:\n  trace: {a_um_per_v: 0, b_um_per_v: 1.0, c_per_v: 0, u_um_per_v: 0.7, alpha_per_v: 0.03, d_um_per_v2: 0, e_um_per_v: 0, f_um: 0}\n  retrace: {a_um_per_v: 0, b_um_per_v: 1.0, c_per_v: 0, u_um_per_v: 0.7, alpha_per_v: 0.03, d_um_per_v2: 0, e_um_per_v: 0, f_um: 0}\n",
        );
        ext.build(&BuildContext::new("e", DT, 0)).unwrap();
        let p = ChParams::new(0.03, 1.0, 0.7);
        let (mut y1, mut y2) = ([0.0], [0.0]);
        let mut worst: f64 = 0.0;
        let info = allocation_counter::measure(|| {
            for k in 0..10_000u64 {
                // 1 s triangle 0 → 100 → 0 V; after 4 periods the ODE is on its loop.
                let ph = (k % 2000) as f64 / 2000.0;
                let (v, dir) = if ph < 0.5 {
                    (200.0 * ph, Direction::Trace)
                } else {
                    (200.0 * (1.0 - ph), Direction::Retrace)
                };
                let t = Tick::new(k, DT);
                ch.output(t, &[v], &mut y1);
                ext.output(t, &[v], &mut y2);
                if k >= 8000 && ph != 0.0 && ph != 0.5 {
                    let want = ch_closed_loop(&p, v, 0.0, 100.0, dir);
                    worst = worst.max((y1[0] - want).abs()).max((y2[0] - want).abs());
                }
            }
        });
        assert_eq!(info.count_total, 0);
        assert!(worst < 1e-6, "{worst}");
        let mut bad = yaml(
            "type: coleman_hodgdon\ntrace: {alpha_per_v: -1, b_um_per_v: 1.0, u_um_per_v: 0.7}\n",
        );
        assert_eq!(
            bad.build(&BuildContext::new("h", DT, 0)).unwrap_err().field,
            "trace.alpha_per_v"
        );
        let mut bad = yaml(
            "type: extended_coleman_hodgdon\nv_min_v: 5\nv_max_v: 5\nmodel:\n  trace: {a_um_per_v: 0, b_um_per_v: 1.0, c_per_v: 0, u_um_per_v: 0.7, alpha_per_v: 0.03, d_um_per_v2: 0, e_um_per_v: 0, f_um: 0}\n  retrace: {a_um_per_v: 0, b_um_per_v: 1.0, c_per_v: 0, u_um_per_v: 0.7, alpha_per_v: 0.03, d_um_per_v2: 0, e_um_per_v: 0, f_um: 0}\n",
        );
        assert_eq!(
            bad.build(&BuildContext::new("e", DT, 0)).unwrap_err().field,
            "v_max_v"
        );
    }

    /// Issue 25: the `coleman_hodgdon` block declares the model's slope range
    /// [2u − b, b] (u < b), every sample of a random input keeps Δx/ΔV in it and
    /// reaches both ends; `extended_coleman_hodgdon` declares none, and indeed
    /// a reversal inside its range jumps (|Δx/ΔV| beyond any bound).
    #[test]
    fn coleman_hodgdon_block_keeps_its_slope_range_and_the_extended_model_has_none() {
        let mut ch = yaml(
            "type: coleman_hodgdon\ntrace: {alpha_per_v: 0.03, b_um_per_v: 1.0, u_um_per_v: 0.7}\ninitial_v: 20\n",
        );
        ch.build(&BuildContext::new("h", DT, 0)).unwrap();
        let s = ch.sector().unwrap();
        assert!(
            (s.lower - 0.4).abs() < 1e-12 && (s.upper - 1.0).abs() < 1e-12,
            "{s:?}"
        );
        let mut rng = nanomotion_core::rng::Rng::new(3);
        let (mut v, mut dir, mut x) = (20.0, 1.0, [0.0]);
        ch.output(Tick::new(0, DT), &[v], &mut x);
        let (mut lo, mut hi) = (f64::INFINITY, f64::NEG_INFINITY);
        for k in 1..20_000u64 {
            if rng.uniform() < 0.02 {
                dir = -dir;
            }
            let dv = dir * 10f64.powf(rng.uniform_in(-3.0, 1.5));
            let x0 = x[0];
            v += dv;
            ch.output(Tick::new(k, DT), &[v], &mut x);
            let r = (x[0] - x0) / dv;
            let rounding = 1e-14 * (x0.abs() + x[0].abs()) / dv.abs();
            assert!(
                r >= 0.4 - rounding - 1e-9 && r <= 1.0 + rounding + 1e-9,
                "{r}"
            );
            lo = lo.min(r);
            hi = hi.max(r);
        }
        assert!(
            (lo - 0.4).abs() < 0.02 && (hi - 1.0).abs() < 0.02,
            "[{lo}, {hi}]"
        );
        let mut ext = yaml(
            "type: extended_coleman_hodgdon\nv_min_v: 0\nv_max_v: 100\nmodel:\n  trace: {a_um_per_v: 0, b_um_per_v: 1.0, c_per_v: 0, u_um_per_v: 0.7, alpha_per_v: 0.03, d_um_per_v2: 0, e_um_per_v: 0, f_um: 0}\n  retrace: {a_um_per_v: 0, b_um_per_v: 1.0, c_per_v: 0, u_um_per_v: 0.7, alpha_per_v: 0.03, d_um_per_v2: 0, e_um_per_v: 0, f_um: 0}\n",
        );
        ext.build(&BuildContext::new("e", DT, 0)).unwrap();
        assert!(ext.sector().is_none());
        let mut y = [0.0];
        ext.output(Tick::new(0, DT), &[50.0], &mut y);
        let up = y[0];
        ext.output(Tick::new(1, DT), &[50.0 - 1e-6], &mut y);
        assert!(((y[0] - up) / 1e-6).abs() > 1e3, "{up} -> {}", y[0]);
    }

    #[test]
    fn feedforward_blocks_from_yaml_do_not_allocate() {
        let mut ff = yaml(
            "type: hysteresis_feedforward\nrange: {position: {x_min_m: 27.0e-6, x_max_m: 63.0e-6}}\nmodel:\n  trace: {a_um_per_v: 0, b_um_per_v: 1.0, c_per_v: 0, u_um_per_v: 0.7, alpha_per_v: 0.03, d_um_per_v2: 0, e_um_per_v: 0, f_um: 0}\n  retrace: {a_um_per_v: 0, b_um_per_v: 1.0, c_per_v: 0, u_um_per_v: 0.7, alpha_per_v: 0.03, d_um_per_v2: 0, e_um_per_v: 0, f_um: 0}\n",
        );
        ff.build(&BuildContext::new("ff", DT, 0)).unwrap();
        let mut pf = yaml("type: position_feedforward\ngain_v_per_um: 1.1\n");
        pf.build(&BuildContext::new("pf", DT, 0)).unwrap();
        let (mut y, mut y2) = ([0.0; 3], [0.0]);
        let info = allocation_counter::measure(|| {
            for k in 0..10_000u64 {
                let r = 45e-6 + 18e-6 * (k as f64 * 1e-3).sin();
                ff.output(Tick::new(k, DT), &[r], &mut y);
                pf.output(Tick::new(k, DT), &[r], &mut y2);
            }
        });
        assert_eq!(info.count_total, 0);
        assert!(y[0].is_finite() && y[2] == 0.0);
        let mut bad = yaml(
            "type: hysteresis_feedforward\nrange: {voltage: {v_min_v: 10, v_max_v: 0}}\nmodel:\n  trace: {a_um_per_v: 0, b_um_per_v: 1.0, c_per_v: 0, u_um_per_v: 0.7, alpha_per_v: 0.03, d_um_per_v2: 0, e_um_per_v: 0, f_um: 0}\n  retrace: {a_um_per_v: 0, b_um_per_v: 1.0, c_per_v: 0, u_um_per_v: 0.7, alpha_per_v: 0.03, d_um_per_v2: 0, e_um_per_v: 0, f_um: 0}\n",
        );
        assert_eq!(
            bad.build(&BuildContext::new("ff", DT, 0))
                .unwrap_err()
                .field,
            "range.v_min_v"
        );
    }
}
