//! Scheduling inputs (`Port::scheduling`) and the stability gate (issue 28).
//!
//! A learning block indexed by a phase α (a DVRC, thesis Sec. 5.3) reads α only to
//! choose where in its memory it is: α is the variable the disturbance is periodic
//! in, not a signal path. When α is computed in the loop — α = 2π∫f_α, an
//! integrator of the controller's output, as for the walking piezo's leg angle —
//! the integrator's pole at z = 1 is in the loop's block graph only through that
//! input. Marked as a scheduling input, the connection is cut: the loop is judged
//! on the rest (closed form below) and the learning criterion is evaluated with
//! that loop's T. The same integrator on an ordinary input is still refused with
//! its pole at 1.

use nalgebra::DMatrix;
use nanomotion_core::gate::{self, GateReport, LearningModel};
use nanomotion_core::lti::StateSpace;
use nanomotion_core::{Block, BuildContext, GraphSpec, ParamError, Port, Tick};
use serde::{Deserialize, Serialize};
use std::f64::consts::PI;

/// A phase-indexed memory: α mod 2π picks one of `slots` bins; w = m[bin], and
/// the bin learns m ← q·(m + e). With α advancing 2π/`slots` per sample it is a
/// standard RC of delay N = `slots` (Q = q, L = 1); as α's speed varies within
/// [2π/`n_max`, 2π/`n_min`] per sample the delay back to the same bin varies in
/// [`n_min`, `n_max`], which the declared learning model states.
#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
struct PhaseMemory {
    slots: usize,
    q: f64,
    n_min: usize,
    n_max: usize,
    /// Whether `alpha` is declared a scheduling input (the point of the test).
    alpha_scheduling: bool,
    #[serde(skip)]
    memory: Vec<f64>,
    #[serde(skip)]
    bin: usize,
    #[serde(skip)]
    dt: f64,
}

#[typetag::serde(name = "test_phase_memory")]
impl Block for PhaseMemory {
    fn inputs(&self) -> Vec<Port> {
        let alpha = Port::new("alpha", 1);
        vec![
            Port::new("e", 1),
            if self.alpha_scheduling {
                alpha.scheduling_input()
            } else {
                alpha
            },
        ]
    }
    fn outputs(&self) -> Vec<Port> {
        vec![Port::new("w", 1)]
    }
    /// w_k needs α_k (the bin), not e_k.
    fn direct_feedthrough(&self) -> bool {
        true
    }
    fn build(&mut self, ctx: &BuildContext) -> Result<(), ParamError> {
        if self.slots == 0 {
            return Err(ParamError::new("slots", "0", "give at least one slot"));
        }
        self.memory = vec![0.0; self.slots];
        self.dt = ctx.dt;
        Ok(())
    }
    fn output(&mut self, _t: Tick, u: &[f64], y: &mut [f64]) {
        let phase = u[1].rem_euclid(2.0 * PI) / (2.0 * PI);
        self.bin = ((phase * self.slots as f64) as usize).min(self.slots - 1);
        y[0] = self.memory[self.bin];
        self.memory[self.bin] = self.q * (self.memory[self.bin] + u[0]);
    }
    fn learning(&self) -> Option<LearningModel> {
        Some(LearningModel {
            l_causal: StateSpace::gain(DMatrix::from_element(1, 1, 1.0), Some(self.dt)),
            preview: 0,
            q: StateSpace::gain(DMatrix::from_element(1, 1, self.q), Some(self.dt)),
            n_min: self.n_min,
            n_max: self.n_max,
            weight_sum: None,
            error_input: 0,
            output: 0,
        })
    }
}

/// Fig. 5.1 around P = 1/(z − 1), K = `kc`: err = r − y, u = K(err + w); the
/// memory's α = 2π∫f_α with f_α = u / 2π (forward Euler, α_{k+1} = α_k + dt·2π f_α,k),
/// an integrator of the controller's output.
fn loop_with_alpha_integrator(kc: f64, q: f64, scheduling: bool) -> String {
    format!(
        r#"base_rate_hz: 1000
duration_s: 2.0
blocks:
  - {{ name: ref, type: constant, value: 1.0 }}
  - {{ name: err, type: sum, signs: "+-" }}
  - {{ name: comp, type: test_phase_memory, slots: 50, q: {q}, n_min: 45, n_max: 55, alpha_scheduling: {scheduling} }}
  - {{ name: csum, type: sum, signs: "++" }}
  - {{ name: pi, type: gain, k: {kc} }}
  - {{ name: plant, type: transfer_function, num: [1.0], den: [1.0, -1.0], discrete: true }}
  - {{ name: alpha, type: transfer_function, num: [0.006283185307179587], den: [1.0, -1.0], discrete: true }}
connections:
  - {{ from: ref.y, to: err.in0 }}
  - {{ from: plant.y, to: err.in1 }}
  - {{ from: err.y, to: comp.e }}
  - {{ from: alpha.y, to: comp.alpha }}
  - {{ from: err.y, to: csum.in0 }}
  - {{ from: comp.w, to: csum.in1 }}
  - {{ from: csum.y, to: pi.u }}
  - {{ from: pi.y, to: plant.u }}
  - {{ from: pi.y, to: alpha.u }}
log: [plant.y, alpha.y]
"#
    )
}

fn analyse(yaml: &str) -> GateReport {
    let spec = GraphSpec::from_yaml(yaml, "test").unwrap();
    let require = spec.require.clone().unwrap_or_default();
    let (sched, _) = spec.build().unwrap();
    gate::analyse(&sched, &require)
}

#[test]
fn an_integrator_reaching_the_loop_only_through_a_scheduling_input_is_not_judged() {
    let (kc, q) = (0.4, 0.2);
    let r = analyse(&loop_with_alpha_integrator(kc, q, true));
    assert!(r.passes(), "{r}");
    assert_eq!(r.loops.len(), 1, "{r}");
    let l = &r.loops[0];
    // The α integrator is not part of the loop.
    assert!(!l.blocks.iter().any(|b| b == "alpha"), "{:?}", l.blocks);
    assert!(l.blocks.iter().any(|b| b == "comp"), "{:?}", l.blocks);
    let p = &l.points[0];
    // With w = 0: err = −y, y⁺ = y + kc·err: one pole, 1 − kc (the plant's
    // integrator closed; nothing else of the loop has a state).
    assert_eq!(p.poles.len(), 1, "{:?}", p.poles);
    assert!((p.spectral_radius - (1.0 - kc)).abs() < 1e-12, "{r}");
    // (5.9) with T = kc/(z − 1 + kc), L = 1, Q = q: H = q·S, S = (z − 1)/(z − 1 + kc)
    // peaks at z = −1 with 2/(2 − kc); bound 1/√(M − m + 1) = 1/√11.
    let c = &p.learning[0];
    assert!((c.hinf - q * 2.0 / (2.0 - kc)).abs() < 1e-9, "{c}");
    assert!((c.bound - 1.0 / 11f64.sqrt()).abs() < 1e-15);
    assert!(c.holds(), "{c}");
    // The report names the cut connection.
    let text = r.to_string();
    assert!(
        text.contains("`alpha` is a scheduling input") && text.contains("alpha.y -> comp.alpha"),
        "{text}"
    );
}

#[test]
fn the_same_integrator_on_an_ordinary_input_is_refused_with_its_pole_at_one() {
    let r = analyse(&loop_with_alpha_integrator(0.4, 0.2, false));
    assert!(!r.passes(), "{r}");
    let l = &r.loops[0];
    assert!(l.blocks.iter().any(|b| b == "alpha"), "{:?}", l.blocks);
    let p = &l.points[0];
    // Poles: 1 − kc (the plant closed) and 1 (the α integrator, which the
    // learning block's w = 0 leaves open).
    assert!((p.spectral_radius - 1.0).abs() < 1e-12, "{r}");
    assert!(
        p.poles
            .iter()
            .any(|z| (z.re - 0.6).abs() < 1e-12 && z.im.abs() < 1e-12),
        "{:?}",
        p.poles
    );
    assert!(
        r.failures()
            .iter()
            .any(|f| f.contains("closed-loop pole of modulus 1.000000")),
        "{:?}",
        r.failures()
    );
    assert!(!r.to_string().contains("scheduling input"));
}

#[test]
fn a_scheduling_input_fed_from_outside_the_loop_adds_no_note() {
    // α from a ramp outside the loop: nothing to cut inside it, the verdict and
    // the report are those of an ordinary input.
    let yaml = loop_with_alpha_integrator(0.4, 0.2, true).replace(
        "{ from: pi.y, to: alpha.u }",
        "{ from: ref.y, to: alpha.u }",
    );
    let plain = loop_with_alpha_integrator(0.4, 0.2, false).replace(
        "{ from: pi.y, to: alpha.u }",
        "{ from: ref.y, to: alpha.u }",
    );
    let (r, r0) = (analyse(&yaml), analyse(&plain));
    assert!(r.passes(), "{r}");
    assert_eq!(r.to_string(), r0.to_string());
}

#[test]
fn the_memory_runs_with_a_computed_phase_and_converges() {
    // The graph the gate accepted, run: the memory sees α advance by
    // 2π·dt·u per sample; the tracking error of the constant reference settles.
    let spec = GraphSpec::from_yaml(&loop_with_alpha_integrator(0.4, 0.2, true), "t").unwrap();
    let (mut sched, _) = spec.build().unwrap();
    let y = sched.run(|_| {}).logs[0].data.clone();
    assert!(y.iter().all(|v| v.is_finite()));
    assert!((y[y.len() - 1] - 1.0).abs() < 1e-9, "{}", y[y.len() - 1]);
}
