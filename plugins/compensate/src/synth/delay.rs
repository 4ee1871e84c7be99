//! `time_delay` → the user's loop re-tuned for the fitted delay.
//!
//! A pure delay d adds no gain and a phase lag of 360°·f·d at frequency f, so
//! at the loop's gain crossover f_c it takes 360°·f_c·d of the phase margin.
//! When the scored error drives a core `pid` (or `pi`), that controller is
//! re-tuned: its frequency scale is lowered by β (integrator zero
//! k_i/k_p → β·k_i/k_p, derivative zero k_p/k_d → β·k_p/k_d, derivative
//! filter f_d → β·f_d: the PID's zero/pole ratios are kept) and its gain set
//! by γ so that the new loop crosses over exactly at β·f_c,
//! γ = |C(β ω_c)| / (|C_β(β ω_c)|·|L(β ω_c)|) (L and C the user's loop and
//! controller, C_β the controller with the lowered frequency scale). On a
//! mass line (P ∝ 1/s²) that keeps the loop shape, L_new(jβω) = L(jω): the
//! margins without the delay stay those of the user's loop and the delay's
//! share 360°·β·f_c·d shrinks with β. The largest β whose loop **with the
//! delay** (the fitted block inserted where the diagnosis put it) the
//! stability gate finds stable, within the graph's `require:`, and with a
//! phase margin of at least the target (the user's margin without the delay
//! less [`MARGIN_GIVEN_UP_DEG`], or the gate's minimum if larger) is chosen —
//! the first of 60 geometric steps from 1 to 0.02 that passes, then 12
//! bisections towards the last that failed; every margin reported is the
//! gate's, computed on that loop (the loop through the controller).
//!
//! Off a mass line (a stage that is a spring below its resonance) the shape
//! is not kept: γ falls faster than β², and with it the integral action
//! γβk_i, so the re-tuned loop has less gain at low frequency and may track a
//! slow reference worse (docs/compensate.md). The validation judges it by the
//! rms of the error like every compensator.

use super::{Compensator, Edit, Outcome, controller_input, none, num};
use crate::named::{Placement, Where, source_of, split};
use crate::{CompError, LoopInfo, Options};
use nanomotion_core::graph::GraphSpec;
use nanomotion_core::{Block, BuildContext};
use nanomotion_plf::surgery::{self, Site};
use serde_json::{Value, json};
use std::f64::consts::TAU;

/// Phase margin (°) of the user's loop without the delay that the re-tune may
/// give up: a pure delay's lag 360°·f_c·d vanishes only as the crossover goes
/// to 0, so the margin the loop had is restored to within this.
pub const MARGIN_GIVEN_UP_DEG: f64 = 5.0;

/// Lowest frequency scale β tried (the crossover lowered 50-fold at most).
const LOWEST_SCALE: f64 = 0.02;

/// Grid points from β = 1 down to [`LOWEST_SCALE`], then bisection steps.
const GRID: usize = 60;
const BISECTIONS: usize = 12;

/// What the stability gate says of the first SISO loop of a graph.
#[derive(Debug, Clone)]
pub(crate) struct LoopFigures {
    /// Phase margin (°).
    pub phase_margin_deg: f64,
    /// Delay margin (s).
    pub delay_margin_s: f64,
    /// Gain crossover (Hz).
    pub crossover_hz: f64,
    /// Gain margin (dB).
    pub gain_margin_db: f64,
    /// Every schedule point of every loop stable.
    pub stable: bool,
    /// The graph passes the gate with its own `require:`.
    pub passes: bool,
    /// The `require:` phase margin of that loop, if any.
    pub required_phase_margin_deg: Option<f64>,
    /// The loop transfer where the gate broke the loop.
    pub loop_transfer: Option<nanomotion_core::lti::StateSpace>,
}

/// The gate's figures of the first SISO loop of `spec` with margins and a
/// gain crossover — the first such loop through block `through` when one
/// is — if any.
pub(crate) fn loop_figures(spec: &GraphSpec, through: Option<&str>) -> Option<LoopFigures> {
    let g = surgery::clone_spec(spec).ok()?;
    let require = g.require.clone().unwrap_or_default();
    let (sched, _) = g.build().ok()?;
    let report = nanomotion_core::gate::analyse(&sched, &require);
    let stable = report.loops.iter().all(|l| l.stable());
    let passes = report.passes();
    let has = |l: &&nanomotion_core::gate::LoopReport| {
        through.is_none_or(|b| l.blocks.iter().any(|x| x == b))
    };
    let mut loops: Vec<_> = report.loops.iter().filter(has).collect();
    loops.extend(report.loops.iter().filter(|l| !has(l)));
    loops.into_iter().find_map(|l| {
        let p = l.points.first()?;
        let m = p.margins.as_ref()?;
        m.gain_crossover_hz.is_finite().then(|| LoopFigures {
            phase_margin_deg: m.phase_margin_deg,
            delay_margin_s: m.delay_margin_s,
            crossover_hz: m.gain_crossover_hz,
            gain_margin_db: m.gain_margin_db,
            stable,
            passes,
            required_phase_margin_deg: require.bounds_for(Some(&l.name)).phase_margin_deg,
            loop_transfer: p.loop_transfer.clone(),
        })
    })
}

/// The user's loop with the fitted delay block (`params`) inserted where the
/// diagnosis put it: in series on the drive, or on the measured signal.
pub(crate) fn with_delay(
    controller: &GraphSpec,
    params: &Value,
    placement: &Placement,
    effect: &str,
    opts: &Options,
) -> Result<GraphSpec, CompError> {
    let no_place = |problem: String, fix: &str| CompError::NoPlace {
        graph: opts.controller_name.clone(),
        effect: effect.to_string(),
        problem,
        fix: fix.to_string(),
    };
    let site = match &placement.place {
        Where::Input { to } => Site::Input {
            from: source_of(controller, to)
                .ok_or_else(|| {
                    no_place(
                        format!("has no connection into `{to}`, where the delay enters"),
                        "drive the plant through the input named in the model you diagnosed",
                    )
                })?
                .to_string(),
            to: to.clone(),
        },
        Where::Output { signal } => Site::Sensor {
            compare: 0,
            signal: signal.clone(),
        },
        Where::Feedback { to, .. } => {
            return Err(no_place(
                format!(
                    "the delay enters as a force at `{to}`, not on the drive or the measurement"
                ),
                "give the model_augmented.yaml that `nanomotion diagnose` wrote",
            ));
        }
    };
    let mut g = crate::clone(controller, &opts.controller_name)?;
    let block = surgery::block_from_json(params.clone()).map_err(|e| CompError::Design {
        effect: effect.to_string(),
        problem: format!("the fitted delay block: {e}"),
    })?;
    surgery::insert(&mut g, "plf_time_delay", block, &site, &[], None).map_err(|e| {
        no_place(
            e.to_string(),
            "keep the plant's input and output as in the model you diagnosed",
        )
    })?;
    Ok(g)
}

/// Replace the parameters of block `name` of `spec` by `params` (a block map).
pub(crate) fn set_params(spec: &mut GraphSpec, name: &str, params: &Value) -> Result<(), String> {
    let b = spec
        .blocks
        .iter_mut()
        .find(|b| b.name == name)
        .ok_or_else(|| format!("has no controller block `{name}`"))?;
    b.block = surgery::block_from_json(params.clone()).map_err(|e| format!("`{name}`: {e}"))?;
    Ok(())
}

/// The controller `params` (a `pid` or `pi` map) with its frequency scale
/// times `beta` and its gain times `gamma`.
fn scaled(params: &Value, beta: f64, gamma: f64) -> Value {
    let mut p = params.clone();
    let f = |k: &str| params.get(k).and_then(Value::as_f64);
    if let Some(kp) = f("kp") {
        p["kp"] = json!(gamma * kp);
    }
    if let Some(ki) = f("ki") {
        p["ki"] = json!(gamma * beta * ki);
    }
    if let Some(kd) = f("kd") {
        p["kd"] = json!(gamma * kd / beta);
    }
    for k in ["derivative_cutoff_hz", "zero_hz"] {
        if let Some(v) = f(k) {
            p[k] = json!(beta * v);
        }
    }
    if let Some(t) = f("tracking_time_s") {
        p["tracking_time_s"] = json!(t / beta);
    }
    p
}

/// |C(e^{jωT})| of the controller block `params` at period `dt`.
fn controller_gain(params: &Value, dt: f64, w: f64) -> Option<f64> {
    let mut b: Box<dyn Block> = surgery::block_from_json(params.clone()).ok()?;
    b.build(&BuildContext::new("controller", dt, 0)).ok()?;
    let c = b.lti()?;
    Some(c.freqresp_siso_at(w).norm())
}

/// `time_delay`: the user's `pid`/`pi` re-tuned (see the [module
/// documentation](self)), or why not, with the phase the delay takes.
pub(super) fn time_delay(
    e: &crate::NamedEffect,
    params: &Value,
    placement: &Placement,
    controller: &GraphSpec,
    info: &LoopInfo,
    opts: &Options,
) -> Result<Outcome, CompError> {
    let d = num(params, "delay_s");
    if !(d.is_finite() && d >= 0.0) {
        return Err(CompError::Design {
            effect: e.effect.clone(),
            problem: format!(
                "the fitted delay_s = {d} is not a finite delay ≥ 0: give the model_augmented.yaml that `nanomotion diagnose` wrote"
            ),
        });
    }
    // The controller the scored error drives, if a block does.
    let driven = controller_input(e, controller, info, opts)
        .ok()
        .map(|to| split(&to).0.to_string());
    let through = driven.as_deref();
    let Some(nominal) = loop_figures(controller, through) else {
        return Ok(none(
            &e.effect,
            format!(
                "no compensator: the stability gate finds no SISO loop with a gain crossover in {}, so there is no crossover to re-tune; a delay of {d:.3e} s costs 360°·f·d of phase at frequency f (a Smith predictor needs a linear plant model in the loop)",
                opts.controller_name
            ),
            &[("delay_s", d)],
        ));
    };
    let (pm, fc, dm) = (
        nominal.phase_margin_deg,
        nominal.crossover_hz,
        nominal.delay_margin_s,
    );
    let delayed = with_delay(controller, params, placement, &e.effect, opts)?;
    let before = loop_figures(&delayed, through);
    let pm_d = before.as_ref().map_or(f64::NAN, |b| b.phase_margin_deg);
    let cost = 360.0 * fc * d;
    let mut figures = vec![
        ("delay_s", d),
        ("phase_margin_deg", pm),
        ("crossover_hz", fc),
        ("delay_margin_s", dm),
        ("phase_margin_left_deg", pm - cost),
        ("phase_margin_with_delay_deg", pm_d),
    ];
    let said = format!(
        "the delay of {d:.3e} s costs 360°·f_c·d = {cost:.1}° of your loop's {pm:.1}° phase margin at its {fc:.2} Hz crossover (the gate finds {pm_d:.1}° on the loop with it; delay margin {dm:.3e} s{})",
        if d >= dm {
            ": the loop is unstable with it"
        } else {
            ""
        }
    );
    let smith = "A Smith predictor (the controller around a nominal plant model P̂ and P̂·e^{−sd}) is not synthesised in this version: it needs a linear plant model in your graph and, on a stage whose model has an integrator or a lightly damped mode, it does not reject a disturbance at the plant input (the model's internal loop is open there)";
    let target = (pm - MARGIN_GIVEN_UP_DEG).max(
        nominal
            .required_phase_margin_deg
            .unwrap_or(f64::NEG_INFINITY),
    );
    figures.push(("target_phase_margin_deg", target));
    if before
        .as_ref()
        .is_some_and(|b| b.stable && b.passes && b.phase_margin_deg >= target)
    {
        return Ok(none(
            &e.effect,
            format!(
                "no re-tune needed: {said}, at least the target {target:.1}° (your margin less {MARGIN_GIVEN_UP_DEG}°, or the gate's minimum)"
            ),
            &figures,
        ));
    }
    let Some(spec) = driven
        .as_deref()
        .and_then(|n| controller.blocks.iter().find(|b| b.name == n))
    else {
        return Ok(none(
            &e.effect,
            format!(
                "no compensator: {said}. No controller block reads the scored error `{}`, and re-tuning needs the core `pid` or `pi` that does. {smith}",
                info.error
            ),
            &figures,
        ));
    };
    let name = spec.name.clone();
    let current = surgery::block_to_json(spec.block.as_ref());
    let ty = current
        .get("type")
        .and_then(Value::as_str)
        .unwrap_or("")
        .to_string();
    if ty != "pid" && ty != "pi" {
        return Ok(none(
            &e.effect,
            format!(
                "no compensator: {said}. Re-tuning needs the controller as a core `pid` or `pi`, and the error drives `{name}`, a `{ty}` block. Fix: write it as a core `pid` (kp, ki, kd, derivative_cutoff_hz) or `pi` reading `{}`, and `nanomotion compensate` lowers its crossover until the margin with the delay is back; or lower its crossover by hand to about {:.3} Hz (where 360°·f·d leaves the target {target:.1}° of your {pm:.1}°, if the margin without the delay stays as the crossover moves, as on a mass line). {smith}",
                info.error,
                (pm - target) / (360.0 * d)
            ),
            &figures,
        ));
    }
    // The loop transfer without the delay, for the gain that keeps the
    // crossover at β·f_c.
    let design_err = |problem: String| CompError::Design {
        effect: e.effect.clone(),
        problem,
    };
    let l0 = nominal.loop_transfer.clone().ok_or_else(|| {
        design_err("the stability gate formed no loop transfer of your loop".into())
    })?;
    let dt = 1.0 / surgery::rate_of(controller, &name).unwrap_or(controller.base_rate_hz);
    let wc = TAU * fc;
    let c_wc = |beta: f64| controller_gain(&current, dt, beta * wc);
    let candidate = |beta: f64| -> Option<(Value, LoopFigures)> {
        let w = beta * wc;
        let gamma = c_wc(beta)?
            / (controller_gain(&scaled(&current, beta, 1.0), dt, w)?
                * l0.freqresp_siso_at(w).norm());
        if !(gamma.is_finite() && gamma > 0.0) {
            return None;
        }
        let p = scaled(&current, beta, gamma);
        let mut g = surgery::clone_spec(&delayed).ok()?;
        set_params(&mut g, &name, &p).ok()?;
        let f = loop_figures(&g, through)?;
        Some((p, f))
    };
    let ok = |f: &LoopFigures| f.stable && f.passes && f.phase_margin_deg >= target;
    let ratio = LOWEST_SCALE.powf(1.0 / GRID as f64);
    let mut hi = 1.0; // fails
    let mut found = None;
    for k in 1..=GRID {
        let beta = ratio.powi(k as i32);
        match candidate(beta) {
            Some((p, f)) if ok(&f) => {
                found = Some((beta, p, f));
                break;
            }
            _ => hi = beta,
        }
    }
    let Some((mut beta, mut p, mut f)) = found else {
        return Ok(none(
            &e.effect,
            format!(
                "no compensator: {said}; lowering your `{name}`'s crossover down to {:.3} Hz ({LOWEST_SCALE} of it, gains scaled with the PID's zero/pole ratios kept) gives no loop with the delay that is stable with a phase margin of {target:.1}°. {smith}",
                LOWEST_SCALE * fc
            ),
            &figures,
        ));
    };
    let mut lo = beta;
    for _ in 0..BISECTIONS {
        let mid = (lo * hi).sqrt();
        match candidate(mid) {
            Some((q, g)) if ok(&g) => {
                (beta, p, f) = (mid, q, g);
                lo = mid;
            }
            _ => hi = mid,
        }
    }
    let gamma = p["kp"].as_f64().unwrap_or(f64::NAN) / current["kp"].as_f64().unwrap_or(f64::NAN);
    let mut design = figures.clone();
    design.extend([
        ("frequency_scale", beta),
        ("gain_scale", gamma),
        ("retuned_crossover_hz", f.crossover_hz),
        ("retuned_phase_margin_deg", f.phase_margin_deg),
        ("retuned_delay_margin_s", f.delay_margin_s),
        ("retuned_gain_margin_db", f.gain_margin_db),
    ]);
    for k in ["kp", "ki", "kd", "derivative_cutoff_hz", "zero_hz"] {
        if let Some(v) = p.get(k).and_then(Value::as_f64) {
            design.push((k, v));
        }
    }
    design.retain(|(_, v)| v.is_finite());
    Ok(Outcome::Compensator(Compensator {
        effect: e.effect.clone(),
        name: name.clone(),
        block: p,
        why: format!(
            "re-tune for the delay: no block inserted; your `{ty}` `{name}` gets its crossover lowered {:.2} Hz -> {:.2} Hz (frequency scale {beta:.3}, gain scale {gamma:.3e}, its zero/pole ratios kept), so the phase margin with the fitted {d:.3e} s delay is {:.1}° (target {target:.1}°: your loop's {pm:.1}° without the delay less {MARGIN_GIVEN_UP_DEG}°, or the gate's minimum), computed by the stability gate on your loop with the delay",
            fc, f.crossover_hz, f.phase_margin_deg
        ),
        place: format!(
            "the controller `{name}` itself ({}), which reads {}",
            if ty == "pid" {
                "kp, ki, kd, derivative_cutoff_hz"
            } else {
                "kp, zero_hz"
            },
            info.error
        ),
        design: design.iter().map(|(k, v)| (k.to_string(), *v)).collect(),
        note: Some(format!(
            "{said}. Judged like every compensator by the rms of the tracking error on your reference; a slower loop is more robust but may track a fast reference worse, and then it is dropped (keep it with --keep): the margin restored is in the design figures. {smith}"
        )),
        edit: Edit::Retune { block: name },
    }))
}
