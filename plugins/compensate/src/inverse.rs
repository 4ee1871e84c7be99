//! `hysteresis_inverse`: the exact inverse of the Coleman–Hodgdon operator, placed
//! before the actuator so that the hysteresis the diagnosis named cancels.
//!
//! Along a monotone piece of the input the Coleman–Hodgdon model (6.3) has the
//! closed form (the core's [`ColemanHodgdon::step`]) from its last turning point
//! (u₀, y₀), with k = (b − c)/α:
//!
//! ```text
//! increasing u:  y(u) = b·u − k + (y₀ − b·u₀ + k)·e^{−α(u − u₀)}
//! decreasing u:  y(u) = b·u + k + (y₀ − b·u₀ − k)·e^{+α(u − u₀)}
//! ```
//!
//! Both are of the form y = p₁u + p₂e^{s(u − u_ref)} + p₄ that afm-stage's
//! [`Branch`] inverts exactly with the Lambert W function (6.6). The thesis applies
//! (6.6) to the steady loop between fixed turning voltages (a periodic scan); here
//! the branch is re-anchored at every reversal of the wanted output, so any
//! wanted output w(t) is inverted: the block keeps the operator's state (its last
//! input and output), starts a new branch from it when w reverses, and outputs
//! u = branch⁻¹(w). Fed into a Coleman–Hodgdon operator with the same parameters
//! (started, as the plf effect block is, on the anhysteretic line), the pair is
//! the identity to rounding (tested).
//!
//! [`ColemanHodgdon::step`]: nanomotion_core::models::hysteresis::ColemanHodgdon::step

use afm_stage::hysteresis::Branch;
use nanomotion_core::block::{Linearisation, check};
use nanomotion_core::lti::StateSpace;
use nanomotion_core::models::hysteresis::{ChParams, Direction};
use nanomotion_core::{Block, BuildContext, ParamError, Params, Tick, declared_block};
use serde::{Deserialize, Serialize};

/// `hysteresis_inverse`: exact inverse of the Coleman–Hodgdon operator (6.3) by
/// the Lambert-W branch inverse (6.6), re-anchored at every reversal of the wanted
/// output; before the actuator. Input `u`: the wanted output w; output `y`: the
/// input to give the operator; output `state`: the unreachable samples so far.
///
/// u = H⁻¹(w) for the Coleman–Hodgdon operator H with parameters `alpha`, `b`,
/// `c` (and `retrace` for decreasing input), the same fields as the plf
/// `hysteresis` effect block. `u` is the output the actuator should produce, `y`
/// the input to give it (the ports of an effect block, so graph surgery places
/// it like one). A wanted output the branch cannot reach (a non-monotone branch:
/// the state far off the anhysteretic line) holds the last input and is counted
/// on output `state`.
#[derive(Debug, Clone, Serialize, Deserialize, Params)]
#[serde(deny_unknown_fields)]
#[block(type_name = "hysteresis_inverse", role = Controller, ports = "u -> y, state")]
pub struct HysteresisInverse {
    /// α (1/\[u\]) of the operator to invert.
    #[param(positive)]
    pub alpha: f64,
    /// b (\[y\]/\[u\]), anhysteretic slope.
    #[param(positive)]
    pub b: f64,
    /// c (\[y\]/\[u\]), slope right after a reversal.
    #[param(positive)]
    pub c: f64,
    /// {alpha, b, c} for decreasing input (asymmetric operator), each > 0.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    #[param(default_doc = "= trace")]
    pub retrace: Option<ChParams>,
    #[serde(skip)]
    state: Option<State>,
}

#[derive(Debug, Clone, Copy)]
struct State {
    /// Last input u and output y of the operator being inverted.
    u: f64,
    y: f64,
    /// Branch in use and its direction.
    branch: Option<(Direction, Branch)>,
    /// Wanted outputs that could not be reached.
    unreachable: u64,
}

impl HysteresisInverse {
    /// The inverse of the symmetric operator (α, b, c).
    pub fn new(alpha: f64, b: f64, c: f64) -> Self {
        Self {
            alpha,
            b,
            c,
            retrace: None,
            state: None,
        }
    }

    /// The inverse of an asymmetric operator.
    pub fn with_retrace(mut self, retrace: ChParams) -> Self {
        self.retrace = Some(retrace);
        self
    }

    fn trace(&self) -> ChParams {
        ChParams::new(self.alpha, self.b, self.c)
    }

    fn params(&self, dir: Direction) -> ChParams {
        match dir {
            Direction::Trace => self.trace(),
            Direction::Retrace => self.retrace.unwrap_or(self.trace()),
        }
    }

    /// The branch of direction `dir` through the turning point (u₀, y₀).
    fn branch(p: ChParams, dir: Direction, u0: f64, y0: f64) -> Branch {
        let k = (p.b - p.c) / p.alpha;
        let (p2, s, p4) = match dir {
            Direction::Trace => (y0 - p.b * u0 + k, -p.alpha, -k),
            Direction::Retrace => (y0 - p.b * u0 - k, p.alpha, k),
        };
        Branch {
            dir,
            p1: p.b,
            p2,
            s,
            v_ref: u0,
            p4,
            v_m: u0,
            v_max: u0,
        }
    }

    /// One sample: the input that makes the operator output `w`. No allocation.
    pub fn step(&mut self, w: f64) -> f64 {
        let b = self.b;
        let Some(st) = self.state.as_mut() else {
            return 0.0;
        };
        if !w.is_finite() {
            st.unreachable += 1;
            return st.u;
        }
        if st.branch.is_none() && st.unreachable == 0 && st.u.is_nan() {
            // First sample: start on the anhysteretic line, as the operator does.
            st.u = w / b;
            st.y = w;
            return st.u;
        }
        let dw = w - st.y;
        if dw == 0.0 {
            return st.u;
        }
        let dir = if dw > 0.0 {
            Direction::Trace
        } else {
            Direction::Retrace
        };
        let branch = match st.branch {
            Some((d, br)) if d == dir => br,
            _ => {
                let p = match dir {
                    Direction::Trace => ChParams::new(self.alpha, self.b, self.c),
                    Direction::Retrace => self
                        .retrace
                        .unwrap_or(ChParams::new(self.alpha, self.b, self.c)),
                };
                let br = Self::branch(p, dir, st.u, st.y);
                st.branch = Some((dir, br));
                br
            }
        };
        let u = branch.inverse(w);
        // The branch must move the input the same way as the output (slope > 0).
        let moves_right = match dir {
            Direction::Trace => u >= st.u,
            Direction::Retrace => u <= st.u,
        };
        if !u.is_finite() || !moves_right {
            st.unreachable += 1;
            return st.u;
        }
        st.u = u;
        st.y = w;
        u
    }

    /// Wanted outputs that could not be reached so far.
    pub fn unreachable_count(&self) -> u64 {
        self.state.map_or(0, |s| s.unreachable)
    }
}

#[declared_block]
impl Block for HysteresisInverse {
    fn build(&mut self, _ctx: &BuildContext) -> Result<(), ParamError> {
        self.check_params()?;
        // k = (b − c)/α finite; the retrace set's slopes must be positive too.
        self.trace().validate("")?;
        if let Some(r) = self.retrace {
            r.validate("retrace.")?;
            check::positive("retrace.b", r.b)?;
            check::positive("retrace.c", r.c)?;
        }
        self.state = Some(State {
            u: f64::NAN,
            y: 0.0,
            branch: None,
            unreachable: 0,
        });
        Ok(())
    }
    fn output(&mut self, _tick: Tick, u: &[f64], y: &mut [f64]) {
        y[0] = self.step(u[0]);
        y[1] = self.unreachable_count() as f64;
    }
    /// Small-signal gains of the inverse: 1/c right after a reversal and 1/b
    /// on the anhysteretic line (per direction), the two ends of its slope.
    fn linearisation(&self) -> Option<Linearisation> {
        let mut points = Vec::new();
        for dir in [Direction::Trace, Direction::Retrace] {
            if dir == Direction::Retrace && self.retrace.is_none() {
                continue;
            }
            let p = self.params(dir);
            for (label, slope) in [("after a reversal", p.c), ("on the line", p.b)] {
                let g = nalgebra::DMatrix::from_row_slice(2, 1, &[1.0 / slope, 0.0]);
                points.push((
                    format!("{} {label}: gain 1/{slope:.4e}", dir.as_str()),
                    StateSpace::gain(g, None),
                ));
            }
        }
        Some(Linearisation {
            points,
            note: "inverse hysteresis judged at the two ends of its small-signal gain (1/c after a reversal, 1/b on the anhysteretic line)".into(),
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use nanomotion_core::models::hysteresis::ColemanHodgdon;

    /// H(H⁻¹(w)) = w for a wanted output with reversals at many amplitudes,
    /// symmetric and asymmetric, with the operator integrated by the core's exact
    /// stepper (an independent implementation of the same model).
    #[test]
    fn the_inverse_cancels_the_operator() {
        let trace = ChParams::new(0.03, 1.0, 0.7);
        for retrace in [None, Some(ChParams::new(0.045, 0.93, 0.72))] {
            let mut inv = HysteresisInverse::new(trace.alpha, trace.b, trace.c);
            if let Some(r) = retrace {
                inv = inv.with_retrace(r);
            }
            inv.build(&BuildContext::new("inv", 1e-3, 0)).unwrap();
            let mut h = ColemanHodgdon::new(trace, retrace.unwrap_or(trace)).unwrap();
            let mut worst: f64 = 0.0;
            for k in 0..20_000 {
                let t = k as f64 * 1e-3;
                let w = 40.0
                    + 15.0 * (2.0 * std::f64::consts::PI * 0.3 * t).sin()
                    + 4.0 * (2.0 * std::f64::consts::PI * 2.1 * t).sin();
                let u = inv.step(w);
                if k == 0 {
                    h.reset(trace.b * u, u);
                }
                let y = h.step(u);
                worst = worst.max((y - w).abs());
            }
            assert!(worst < 1e-9, "max |H(H⁻¹(w)) − w| = {worst:e}");
            assert_eq!(inv.unreachable_count(), 0);
        }
    }

    /// Real-time discipline: no allocation per tick.
    #[test]
    fn ticks_do_not_allocate() {
        let mut inv = HysteresisInverse::new(0.03, 1.0, 0.7);
        inv.build(&BuildContext::new("inv", 1e-3, 0)).unwrap();
        let mut y = [0.0; 2];
        let info = allocation_counter::measure(|| {
            for k in 0..10_000u64 {
                let w = 30.0 * (k as f64 * 1e-3).sin();
                inv.output(Tick::new(k, 1e-3), &[w], &mut y);
            }
        });
        assert_eq!(info.count_total, 0, "{info:?}");
    }

    #[test]
    fn a_non_positive_slope_is_refused_by_name() {
        let mut inv = HysteresisInverse::new(0.03, 1.0, -0.1);
        let e = inv.build(&BuildContext::new("inv", 1e-3, 0)).unwrap_err();
        assert_eq!(e.field, "c");
        for (alpha, b, c, field) in [(0.0, 1.0, 0.7, "alpha"), (0.03, f64::NAN, 0.7, "b")] {
            let mut inv = HysteresisInverse::new(alpha, b, c);
            let e = inv.build(&BuildContext::new("inv", 1e-3, 0)).unwrap_err();
            assert_eq!(e.field, field, "{e}");
        }
        let mut inv =
            HysteresisInverse::new(0.03, 1.0, 0.7).with_retrace(ChParams::new(0.04, 1.0, 0.0));
        let e = inv.build(&BuildContext::new("inv", 1e-3, 0)).unwrap_err();
        assert_eq!(e.field, "retrace.c");
    }

    /// The derived listing keeps what the hand-written one said: the three
    /// slopes required and > 0, `retrace` optional and defaulting to the trace set.
    #[test]
    fn the_listing_is_derived_from_the_parameter_struct() {
        let doc = nanomotion_core::block::block_docs()
            .into_iter()
            .find(|d| d.type_name == "hysteresis_inverse")
            .expect("registered");
        let params = doc.param_docs();
        let names: Vec<&str> = params.iter().map(|p| p.name).collect();
        assert_eq!(names, ["alpha", "b", "c", "retrace"]);
        for p in &params[..3] {
            assert!(p.required, "{}", p.name);
            assert_eq!(p.bounds, ["> 0"], "{}", p.name);
            assert_eq!(p.schema["exclusiveMinimum"], 0, "{}", p.name);
        }
        assert!(!params[3].required);
        assert_eq!(params[3].default.as_deref(), Some("= trace"));
        assert!(
            doc.summary
                .starts_with("exact inverse of the Coleman–Hodgdon operator")
        );
        assert!(doc.ports.contains("state"));
    }
}
