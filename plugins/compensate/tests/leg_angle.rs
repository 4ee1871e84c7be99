//! Toward Table 5.1 (thesis Ch. 5): a disturbance periodic in the walking
//! stage's leg angle α, with α = 2π∫f_α computed in the user's loop (an
//! integrator of the PI's output, as the driver computes it), compensated by
//! delay-varying RC on α — then the compensated loop run on the nonlinear
//! walking stage (driver + `walking_piezo_stage`, rough strip) it is meant for.
//!
//! The loop is the Table 5.1 design of docs/repetitive-control.md, "Table 5.1 on
//! the nonlinear walking piezo stage", (c): the identified stage (5.31) with
//! c = 5.079 µm per cycle and no delay, the PI k_p(s + 2π·5 Hz)/s with
//! k_p = 2π·50 Hz/c, 4 kHz, 10 µm/s.
//!
//! In all but the last test the effect is written into the augmented model
//! here, not named by `diagnose` (the last,
//! `from_a_record_diagnose_names_the_leg_angle_dip_and_compensate_puts_a_dvrc_on_alpha`,
//! starts from a record and `diagnose --phase alpha.y`). It is the take-over
//! velocity dip of the linear Table 5.1 model (depth 0.5, half-width π/8 at
//! α ≡ 0 and π) at the loop's mean f_α, as the additive drive disturbance
//! −f̄·(δ(α) − mean δ) periodic in α that a fit of `repetitive_disturbance`
//! (variable: signal, s = α) would give: its Fourier coefficients are computed
//! below by quadrature.

mod support;

use nanomotion_compensate::{
    DELAY_MARGIN_MEASURED, DELAY_SPREAD_UNMEASURED, MeasuredSignal, Options, compensate, named,
};
use nanomotion_core::graph::{BlockSpec, Connection, GraphSpec};
use nanomotion_plf::surgery;
use std::f64::consts::{PI, TAU};
use walking_piezo::records::{LegAngleLoop, TakeOver};

const RATE: f64 = 4000.0;
/// Reference velocity (m/s).
const V: f64 = 1e-5;
/// The identified step per cycle (m): `cargo run --release -p nanomotion-dvrc
/// --example table_5_1_nonlinear`, design step 2.
const C: f64 = 5.079e-6;
/// Run length at constant velocity (s).
const DURATION: f64 = 40.0;
/// Harmonics of the dip kept.
const H: usize = 32;

/// The take-over dip δ(α) of the linear Table 5.1 model: raised cosines of
/// depth 0.5 and half-width π/8 centred on α ≡ 0 and π.
const TABLE_5_1_DIP: TakeOver = TakeOver {
    per_cycle: 2,
    depth: 0.5,
    half_width_rad: PI / 8.0,
};

/// (mean, cos_h, sin_h) of the Table 5.1 dip δ over one period 2π, h = 1..=H.
fn dip_fourier() -> (f64, Vec<f64>, Vec<f64>) {
    take_over_fourier(&TABLE_5_1_DIP)
}

/// (mean, cos_h, sin_h) of `t`'s δ over one period 2π, h = 1..=H, by the
/// midpoint rule.
fn take_over_fourier(t: &TakeOver) -> (f64, Vec<f64>, Vec<f64>) {
    let n = 1 << 16;
    let (mut mean, mut a, mut b) = (0.0, vec![0.0; H], vec![0.0; H]);
    for i in 0..n {
        let x = TAU * (i as f64 + 0.5) / n as f64;
        let d = t.dip(x);
        mean += d / n as f64;
        for h in 0..H {
            let hx = (h + 1) as f64 * x;
            a[h] += 2.0 * d * hx.cos() / n as f64;
            b[h] += 2.0 * d * hx.sin() / n as f64;
        }
    }
    (mean, a, b)
}

fn stage_block() -> String {
    format!("{{ name: stage, type: walking_piezo_fitted, gain_m_per_cycle: {C:e}, delay_s: 0.0 }}")
}

fn pi_block() -> String {
    format!(
        "{{ name: pi, type: pi, kp: {:e}, zero_hz: 5.0 }}",
        TAU * 50.0 / C
    )
}

fn alpha_block() -> String {
    // α_{k+1} = α_k + 2π T_s f_α,k (rad).
    format!(
        "{{ name: alpha, type: transfer_function, num: [{:e}], den: [1.0, -1.0], discrete: true }}",
        TAU / RATE
    )
}

/// The user's loop on the nominal (identified) stage.
/// The reference of a Table 5.1 row.
#[derive(Debug, Clone, Copy, PartialEq)]
enum Reference {
    /// 10 µm/s, 40 s, scored from 30 s.
    Constant,
    /// 10 µm/s·(1 + 0.5 sin 0.2πt), 100 s, scored from 75 s (the table's
    /// last row).
    Sinusoidal,
}

impl Reference {
    fn duration(self) -> f64 {
        match self {
            Reference::Constant => DURATION,
            Reference::Sinusoidal => 100.0,
        }
    }
    fn from(self) -> f64 {
        0.75 * self.duration()
    }
    /// The blocks making `ref.y`: v t, plus A(1 − cos ωt) with A = 0.5 v/ω
    /// for the sinusoidal velocity (ω = 0.2π rad/s).
    fn blocks(self) -> String {
        match self {
            Reference::Constant => {
                format!("  - {{ name: ref, type: constant_velocity, velocity_m_s: {V:e} }}\n")
            }
            Reference::Sinusoidal => {
                let w = 0.2 * PI;
                let a = 0.5 * V / w;
                format!(
                    "  - {{ name: ramp, type: constant_velocity, velocity_m_s: {V:e} }}\n  - {{ name: wave, type: sinusoid, amplitude: {a:e}, frequency_hz: 0.1, phase_rad: {:?}, offset: {a:e} }}\n  - {{ name: ref, type: sum, signs: \"++\" }}\n",
                    -0.5 * PI
                )
            }
        }
    }
    fn connections(self) -> &'static str {
        match self {
            Reference::Constant => "",
            Reference::Sinusoidal => {
                "  - { from: ramp.y, to: ref.in0 }\n  - { from: wave.y, to: ref.in1 }\n"
            }
        }
    }
}

/// The user's loop on the nominal (identified) stage tracking `r`.
fn controller_for(r: Reference) -> GraphSpec {
    GraphSpec::from_yaml(
        &format!(
            "title: PI on f_alpha, Table 5.1 design\nbase_rate_hz: {RATE}\nduration_s: {}\nblocks:\n{}  - {{ name: err, type: sum, signs: \"+-\" }}\n  - {}\n  - {}\n  - {}\nconnections:\n{}  - {{ from: ref.y, to: err.in0 }}\n  - {{ from: stage.x_s, to: err.in1 }}\n  - {{ from: err.y, to: pi.e }}\n  - {{ from: pi.u, to: stage.f_alpha }}\n  - {{ from: pi.u, to: alpha.u }}\nscore:\n  - {{ signal: err.y, from_s: {} }}\n",
            r.duration(),
            r.blocks(),
            pi_block(),
            stage_block(),
            alpha_block(),
            r.connections(),
            r.from()
        ),
        "controller.yaml",
    )
    .unwrap()
}

/// The augmented model: the identified stage driven by the record's drive,
/// α computed from it, and the dip's drive disturbance periodic in α.
fn augmented() -> GraphSpec {
    let (_, a, b) = dip_fourier();
    let f_bar = V / C;
    let cos: Vec<f64> = a.iter().map(|v| -f_bar * v).collect();
    let sin: Vec<f64> = b.iter().map(|v| -f_bar * v).collect();
    GraphSpec::from_yaml(
        &format!(
            "base_rate_hz: {RATE}\nduration_s: 1.0\nblocks:\n  - {{ name: drive, type: constant, value: {f_bar} }}\n  - {}\n  - {{ name: plf_repetitive_disturbance, type: repetitive_disturbance, period: {TAU:?}, variable: signal, cos: {cos:?}, sin: {sin:?} }}\n  - {}\nconnections:\n  - {{ from: drive.y, to: alpha.u }}\n  - {{ from: drive.y, to: plf_repetitive_disturbance.u }}\n  - {{ from: alpha.y, to: plf_repetitive_disturbance.s }}\n  - {{ from: plf_repetitive_disturbance.y, to: stage.f_alpha }}\n",
            alpha_block(),
            stage_block()
        ),
        "model_augmented.yaml",
    )
    .unwrap()
}

/// `spec` with the identified stage replaced by the nonlinear one: the
/// asymmetric-waveform driver (overlap 1/3) and `walking_piezo_stage` with
/// c_x = 46.40 nm/V (the Table 5.1 stage: 5.05 µm per cycle on a flat strip)
/// on a 100 nm rms strip, 10 sub-steps. α stays the loop's own integrator.
fn on_walking_stage(spec: &GraphSpec) -> GraphSpec {
    let mut g = surgery::clone_spec(spec).unwrap();
    g.blocks.retain(|b| b.name != "stage");
    let block = |v| surgery::block_from_json(v).unwrap();
    g.blocks.push(BlockSpec {
        name: "driver".into(),
        rate_hz: None,
        block: block(serde_json::json!({"type": "walking_piezo_driver",
            "shape": {"kind": "asymmetric", "overlap_q": 1.0 / 3.0}})),
    });
    g.blocks.push(BlockSpec {
        name: "wstage".into(),
        rate_hz: None,
        block: block(
            serde_json::json!({"type": "walking_piezo_stage", "substeps": 10,
            "strip_height_rms_m": 1e-7, "c_x_m_v": [46.40e-9, 46.40e-9, 46.40e-9, 46.40e-9]}),
        ),
    });
    for c in &mut g.connections {
        if c.from == "stage.x_s" {
            c.from = "wstage.x_s".into();
        }
        if c.to == "stage.f_alpha" {
            c.to = "driver.f_alpha".into();
        }
    }
    g.connections.push(Connection {
        from: "driver.u".into(),
        to: "wstage.u".into(),
    });
    g
}

/// Run `spec` logging `signals`; the first score's rms and the logs.
fn run(spec: &GraphSpec, signals: &[&str]) -> (f64, Vec<Vec<f64>>) {
    let mut g = surgery::clone_spec(spec).unwrap();
    g.log = signals.iter().map(|s| s.to_string()).collect();
    let (mut s, _) = g.build().expect("the loop builds");
    let r = s.run(|_| {});
    let logs = signals
        .iter()
        .map(|n| {
            r.logs
                .iter()
                .find(|l| l.name == *n)
                .expect("logged")
                .data
                .clone()
        })
        .collect();
    (r.scores[0].rms, logs)
}

/// For every sample k of `alpha` from `from`, the fractional number of samples
/// back to the latest time α was α_k − 2π (the latest j with α_j ≤ α_k − 2π,
/// then linear interpolation between j and j + 1): (smallest, largest).
fn delay_back(alpha: &[f64], from: usize) -> (f64, f64) {
    let (mut lo, mut hi) = (f64::INFINITY, 0.0f64);
    for k in from..alpha.len() {
        let target = alpha[k] - TAU;
        let mut j = k;
        while j > 0 && alpha[j - 1] > target {
            j -= 1;
        }
        if j == 0 {
            continue;
        }
        // α_{j−1} ≤ target < α_j.
        let a = j - 1;
        let frac = (target - alpha[a]) / (alpha[a + 1] - alpha[a]);
        let d = k as f64 - (a as f64 + frac);
        lo = lo.min(d);
        hi = hi.max(d);
    }
    (lo, hi)
}

/// What one design gives: the report's design figures, and on the walking
/// stage the rms before and after, the α period (per sample, last quarter)
/// with the DVRC, and the N_k it used.
struct Case {
    compensated: GraphSpec,
    design: std::collections::BTreeMap<String, f64>,
    before: f64,
    after: f64,
    period: (f64, f64),
    n_seen: (f64, f64),
}

impl Case {
    /// The walking stage's α period stays inside the design's [m, M] (and,
    /// with `n_off_the_ends`, N_k never sits at its ends), and the error
    /// shrinks.
    fn assert_inside_and_better(&self, n_off_the_ends: bool) {
        let d = &self.design;
        assert!(
            d["n_min"] <= self.period.0.floor() && self.period.1.ceil() <= d["n_max"],
            "{:?}",
            self.period
        );
        if n_off_the_ends {
            assert!(d["n_min"] < self.n_seen.0 && self.n_seen.1 < d["n_max"]);
        }
        assert!(
            self.after < self.before,
            "{:e} -> {:e}",
            self.before,
            self.after
        );
    }
}

/// α recorded from your loop (PI only) on the walking stage tracking `r`,
/// from 10 s on.
fn measured_alpha(r: Reference) -> Vec<f64> {
    let (_, logs) = run(&on_walking_stage(&controller_for(r)), &["alpha.y"]);
    logs[0][(10.0 * RATE) as usize..].to_vec()
}

/// [`case`] with the default margin and `record` as the measured α.
fn case_with_record(record: Vec<f64>, r: Reference) -> Case {
    case(
        None,
        vec![MeasuredSignal {
            signal: "alpha.y".into(),
            rate_hz: RATE,
            values: record,
            origin: "the α record".into(),
        }],
        r,
    )
}

/// Compensate the leg-angle disturbance with `delay_margin` = `given` (`None`:
/// the default), check the design against its closed forms, and run both
/// loops on the walking stage.
fn case(given: Option<f64>, measured: Vec<MeasuredSignal>, reference: Reference) -> Case {
    // Link the walking-piezo blocks (registered by name).
    let _ = walking_piezo::driver::DriverParams::default();
    let aug = augmented();
    let effects = named::from_graph(&aug);
    assert_eq!(effects.len(), 1, "{effects:?}");
    let with_record = !measured.is_empty();
    let opts = Options {
        delay_margin: given,
        measured,
        ..Options::default()
    };
    let out = compensate(&aug, &controller_for(reference), &effects, &opts).unwrap();
    let r = &out.report;
    eprintln!("{}", serde_json::to_string_pretty(r).unwrap());
    let c = &r.compensators[0];
    assert_eq!(c.type_name, "dvrc");
    assert_eq!(c.design["period"], TAU);
    // The nominal loop's delay: one α period at f̄ = v/c, c/(v T_s) = 2031.6
    // samples.
    let n_nominal = C / (V / RATE);
    let d = &c.design;
    // The margin: as given, else the default for what was measured.
    let margin = d["delay_margin"];
    assert_eq!(
        margin,
        given.unwrap_or(if with_record {
            DELAY_MARGIN_MEASURED
        } else {
            DELAY_SPREAD_UNMEASURED
        })
    );
    // Without a record the report says that its validation cannot judge the
    // range.
    assert_eq!(c.note.is_some(), !with_record, "{c:?}");
    assert!(
        d["delay_nominal_min"] <= n_nominal.ceil() && n_nominal.floor() <= d["delay_nominal_max"],
        "{d:?}"
    );
    // The range: both loops' ranges, widened by the margin.
    let get = |k: &str| d.get(k).copied();
    let lo = d["delay_nominal_min"]
        .min(d["delay_diagnosed_min"])
        .min(get("delay_measured_min").unwrap_or(f64::INFINITY));
    let hi = d["delay_nominal_max"]
        .max(d["delay_diagnosed_max"])
        .max(get("delay_measured_max").unwrap_or(0.0));
    assert_eq!(d["n_min"], ((lo * (1.0 - margin)).floor() - 1.0).max(0.0));
    assert_eq!(d["n_max"], (hi * (1.0 + margin)).ceil() + 1.0);
    // (5.9) for that range, with its bound 1/√(M − m + 1).
    assert!(d["criterion_5_9_hinf"] < d["criterion_5_9_bound"], "{d:?}");
    assert!(
        (d["criterion_5_9_bound"] - 1.0 / (d["n_max"] - d["n_min"] + 1.0).sqrt()).abs() < 1e-12
    );
    // The gate accepts the loop with α integrated from the PI's output (the
    // dvrc's `alpha` is a scheduling input), and on the augmented model the
    // DVRC removes the disturbance's error.
    assert!(r.gate.passes, "{:?}", r.gate);
    assert!(c.kept, "{c:?}");
    // What `nanomotion check` prints for the written graph: one loop without
    // the α integrator (the cut named), judged by (5.9) with the figure the
    // design reported.
    let spec = surgery::clone_spec(&out.compensated).unwrap();
    let require = spec.require.clone().unwrap_or_default();
    let (sched, _) = spec.build().unwrap();
    let gate = nanomotion_core::gate::analyse(&sched, &require);
    eprintln!("{gate}");
    assert!(gate.passes() && gate.loops.len() == 1, "{gate}");
    assert!(!gate.loops[0].blocks.iter().any(|b| b == "alpha"));
    assert!(gate.to_string().contains(&format!(
        "the connection alpha.y -> {}.alpha is cut",
        c.block
    )));
    let lc = &gate.loops[0].points[0].learning[0];
    assert!(
        (lc.hinf - d["criterion_5_9_hinf"]).abs() < 1e-9 * lc.hinf,
        "{lc}"
    );
    assert_eq!((lc.n_min as f64, lc.n_max as f64), (d["n_min"], d["n_max"]));
    assert!(r.cut_percent > 85.0, "{}", r.cut_percent);

    // On the nonlinear walking stage (the truth this design is for).
    let n_block = format!("{}.n", c.block);
    let (before, _) = run(&on_walking_stage(&controller_for(reference)), &["alpha.y"]);
    let (after, logs) = run(&on_walking_stage(&out.compensated), &["alpha.y", &n_block]);
    let from = (reference.from() * RATE) as usize;
    let period = delay_back(&logs[0], from);
    let n_seen = logs[1][from..]
        .iter()
        .fold((f64::INFINITY, 0.0f64), |(a, b), &v| (a.min(v), b.max(v)));
    eprintln!(
        "{reference:?} velocity, delay_margin {margin}: walking stage, rms of err.y from {} s: PI only {before:.4e} m, with DVRC {after:.4e} m ({:.1} % cut); \
         alpha period with DVRC (samples, per sample, last quarter) {:.1} .. {:.1}; N_k seen by the DVRC {} .. {}; [m, M] = [{}, {}]",
        reference.from(),
        100.0 * (1.0 - after / before),
        period.0,
        period.1,
        n_seen.0,
        n_seen.1,
        d["n_min"],
        d["n_max"],
    );
    Case {
        compensated: surgery::clone_spec(&out.compensated).unwrap(),
        design: d.clone(),
        before,
        after,
        period,
        n_seen,
    }
}

/// The default without a record: the range widened by the thesis's measured
/// spread of N(α) at 10 µm/s (Fig. 5.7: [2026, 2209] samples, 9.0 %), which
/// neither model shows. The walking stage's α period stays inside it, N_k never
/// sits at its ends, and the error shrinks.
#[test]
fn a_disturbance_periodic_in_the_leg_angle_is_compensated_by_dvrc_on_alpha() {
    let c = case(None, Vec::new(), Reference::Constant);
    c.assert_inside_and_better(true);
    // The written graph (on the identified stage, as written) on the wall
    // clock, its first 2 s bit for bit as offline.
    support::first_seconds_run_on_the_wall_clock_as_offline(
        &c.compensated,
        &[
            "comp_repetitive_disturbance.w",
            "comp_repetitive_disturbance.n",
        ],
        2.0,
    );
}

/// ±2 % around the models' delays alone (the old default) is too narrow for
/// the walking stage's α period: it leaves the range, N_k is pinned at the
/// range's ends, and the error grows — which the validation on the augmented
/// model cannot show (there the DVRC is kept; its note says so).
#[test]
fn two_percent_around_the_models_alone_is_too_narrow_for_the_walking_stage() {
    let c = case(Some(0.02), Vec::new(), Reference::Constant);
    let d = &c.design;
    assert!(
        c.period.0 < d["n_min"] || d["n_max"] < c.period.1,
        "{:?}",
        c.period
    );
    assert!(c.n_seen.0 == d["n_min"] || c.n_seen.1 == d["n_max"]);
    assert!(c.after > c.before, "{:e} -> {:e}", c.before, c.after);
}

/// The thesis's way (Fig. 5.7): α recorded from your loop on the stage without
/// RC, its delays added to the range, then the default ±2 %. The design's
/// measured delays agree with an independent (interpolated) reading of the
/// record, the α period with the DVRC stays inside [m, M] and the error
/// shrinks.
#[test]
fn the_range_from_a_measured_alpha_record_covers_the_walking_stage() {
    let _ = walking_piezo::driver::DriverParams::default();
    // The record: your loop (PI only) on the walking stage, from 10 s on.
    let record = measured_alpha(Reference::Constant);
    let (d_lo, d_hi) = delay_back(&record, 0);
    let c = case_with_record(record, Reference::Constant);
    let d = &c.design;
    eprintln!(
        "measured record: delays {:.1} .. {:.1} (interpolated {d_lo:.2} .. {d_hi:.2})",
        d["delay_measured_min"], d["delay_measured_max"]
    );
    // The design's integer delay k − j (j the last sample at or below
    // α_k − 2π) is the interpolated delay rounded up.
    assert!(d_lo <= d["delay_measured_min"] && d["delay_measured_min"] < d_lo + 1.0);
    assert!(d_hi <= d["delay_measured_max"] && d["delay_measured_max"] < d_hi + 1.0);
    c.assert_inside_and_better(true);
}

/// Table 5.1's last row, 10 µm/s·(1 + 0.5 sin 0.2πt) for 100 s, where the α
/// period swings with the velocity and a fixed-N memory is wrong most of the
/// time: the range from your loop's motion, with a measured α record (PI only,
/// from 10 s) and the default ±2 %. The α period with the DVRC stays inside
/// [m, M] and the error shrinks.
#[test]
fn at_the_sinusoidal_velocity_the_dvrc_follows_the_alpha_period() {
    let _ = walking_piezo::driver::DriverParams::default();
    let r = Reference::Sinusoidal;
    let c = case_with_record(measured_alpha(r), r);
    c.assert_inside_and_better(false);
}

/// The truth of a [`LegAngleLoop`] record as a graph: `spec` (your loop, or
/// the compensated one) with the stage driven by f_α·(1 − (δ(α) − δ̄)), the
/// record generator's multiplicative take-over dip, δ − δ̄ by its first H
/// harmonics (a `repetitive_disturbance` on a constant 1, periodic in your
/// loop's `alpha.y`, times the drive in a `product`).
fn with_take_over(spec: &GraphSpec, t: &TakeOver) -> GraphSpec {
    let mut g = surgery::clone_spec(spec).unwrap();
    let (_, a, b) = take_over_fourier(t);
    let neg = |v: &[f64]| v.iter().map(|x| -x).collect::<Vec<f64>>();
    let block = |v| surgery::block_from_json(v).unwrap();
    for (name, v) in [
        (
            "truth_one",
            serde_json::json!({"type": "constant", "value": 1.0}),
        ),
        (
            "truth_gain",
            serde_json::json!({"type": "repetitive_disturbance", "period": TAU,
                "variable": "signal", "cos": neg(&a), "sin": neg(&b)}),
        ),
        ("truth_drive", serde_json::json!({"type": "product"})),
    ] {
        g.blocks.push(BlockSpec {
            name: name.into(),
            rate_hz: None,
            block: block(v),
        });
    }
    let into_stage = g
        .connections
        .iter_mut()
        .find(|c| c.to == "stage.f_alpha")
        .expect("the loop drives stage.f_alpha");
    let drive = std::mem::replace(&mut into_stage.from, "truth_drive.y".into());
    for (from, to) in [
        (drive.as_str(), "truth_drive.in0"),
        ("truth_gain.y", "truth_drive.in1"),
        ("truth_one.y", "truth_gain.u"),
        ("alpha.y", "truth_gain.s"),
    ] {
        g.connections.push(Connection {
            from: from.into(),
            to: to.into(),
        });
    }
    g
}

/// Issue #28 end to end, with no hand-written compensator: a record of your
/// loop (PI only) on a stage whose velocity dips at the legs' take-overs —
/// periodic in the leg angle α, hidden (the nominal is the identified stage
/// alone) — goes through `diagnose` with the leg angle declared
/// (`Options::phase`, `--phase alpha.y`), which names a disturbance on the
/// drive periodic in α and fits its period, then through `compensate`, which
/// puts a DVRC on α into your loop. The figures are the run's own: the error
/// cut on the augmented model (the report's) and on the truth (the record's
/// multiplicative dip, run in your loop). Two records: the Table 5.1 dip (two
/// take-overs per cycle, 10 µm/s swinging ±50 % at 0.5 Hz) and one the
/// search was not built on (one take-over per cycle, shallower and wider, at
/// 7 µm/s swinging ±30 % at 0.7 Hz, another seed); your loop tracks a
/// constant 10 µm/s (the Table 5.1 design).
#[test]
fn from_a_record_diagnose_names_the_leg_angle_dip_and_compensate_puts_a_dvrc_on_alpha() {
    let _ = walking_piezo::driver::DriverParams::default();
    let other = TakeOver {
        per_cycle: 1,
        depth: 0.3,
        half_width_rad: PI / 5.0,
    };
    // The record's δ̄ in closed form is δ's mean by quadrature.
    for t in [TABLE_5_1_DIP, other] {
        assert!((take_over_fourier(&t).0 - t.mean()).abs() < 1e-9, "{t:?}");
    }
    for (t, v, swing, seed) in [
        (TABLE_5_1_DIP, V, (0.5, 0.5), 1),
        (other, 7e-6, (0.3, 0.7), 5),
    ] {
        let l = LegAngleLoop {
            gain_m_per_cycle: C,
            velocity_m_s: v,
            velocity_swing: Some(swing),
            duration_s: 4.0,
            take_over: Some(t),
            drive_delay_samples: 0,
            noise_m: 1e-9,
            seed,
        };
        let data = l.record().unwrap();
        let nominal = GraphSpec::from_yaml(&l.nominal_yaml(), "nominal.yaml").unwrap();
        let opts = nanomotion_plf::diagnose::Options {
            phase: Some("alpha.y".into()),
            ..Default::default()
        };
        let rep = nanomotion_plf::diagnose(&nominal, &data, &opts).unwrap();
        eprintln!(
            "{t:?} at {v:e} m/s: diagnose found {:?} (held-out cut {:.1} %)",
            rep.found, rep.holdout_cut_percent
        );
        assert_eq!(
            rep.found.first().map(String::as_str),
            Some("repetitive_disturbance"),
            "{}",
            rep.stopped_because
        );
        // Your loop: the Table 5.1 PI at 10 µm/s.
        let controller = controller_for(Reference::Constant);
        let effects = named::from_report(&rep);
        let out = compensate(
            rep.augmented.as_ref().unwrap(),
            &controller,
            &effects,
            &Options::default(),
        )
        .unwrap();
        let r = &out.report;
        let c = r
            .compensators
            .iter()
            .find(|c| c.effect == "repetitive_disturbance")
            .expect("the disturbance is compensated");
        // A DVRC on α, with the period the diagnosis fitted: 2π per take-over
        // spacing, 2π/per_cycle.
        assert_eq!(c.type_name, "dvrc");
        let spacing = TAU / t.per_cycle as f64;
        assert!(
            (c.design["period"] / spacing - 1.0).abs() < 0.01,
            "{:?}",
            c.design
        );
        assert!(
            out.compensated
                .connections
                .iter()
                .any(|k| k.from == "alpha.y" && k.to == format!("{}.alpha", c.block))
        );
        // The loop's own delay per period, (period/2π)·c/(v T_s) samples, is
        // inside [m, M], and (5.9) holds for it.
        let n = spacing / TAU * C / (V / RATE);
        assert!(
            c.design["n_min"] <= n && n <= c.design["n_max"],
            "{n} {:?}",
            c.design
        );
        assert!(c.design["criterion_5_9_hinf"] < c.design["criterion_5_9_bound"]);
        assert!(r.gate.passes && c.kept, "{c:?}");
        // The error cut on the augmented model (the report's figure) and on
        // the truth: your loop before and after, the record's dip in it.
        let (before, _) = run(&with_take_over(&controller, &t), &[]);
        let (after, _) = run(&with_take_over(&out.compensated, &t), &[]);
        let truth_cut = 100.0 * (1.0 - after / before);
        eprintln!(
            "  DVRC on alpha.y: period {:.4} rad, [m, M] = [{}, {}], Q cut-off {:.0} Hz, (5.9) {:.4} < {:.4}; augmented model: rms of err.y from {} s {:.4e} -> {:.4e} m ({:.1} % cut); truth: {before:.4e} -> {after:.4e} m ({truth_cut:.1} % cut); your loop on the nominal plant {:.4e} m",
            c.design["period"],
            c.design["n_min"],
            c.design["n_max"],
            c.design.get("q_cutoff_hz").copied().unwrap_or(f64::NAN),
            c.design["criterion_5_9_hinf"],
            c.design["criterion_5_9_bound"],
            r.from_s,
            r.before.rms,
            r.after.rms,
            r.cut_percent,
            r.nominal.rms,
        );
        for k in &r.compensators {
            eprintln!(
                "  {} -> {} `{}`: rms cut alone {:.1} %, kept {}; {}",
                k.effect,
                k.type_name,
                k.block,
                k.cut_percent,
                k.kept,
                k.note.as_deref().unwrap_or("")
            );
        }
        // For comparison only (not asserted: its take-over is not the
        // record's): the nonlinear walking stage of the tests above.
        let (w_before, _) = run(&on_walking_stage(&controller), &[]);
        let (w_after, _) = run(&on_walking_stage(&out.compensated), &[]);
        eprintln!(
            "  nonlinear walking stage: PI only {w_before:.4e} m, with this DVRC {w_after:.4e} m ({:.1} % cut)",
            100.0 * (1.0 - w_after / w_before)
        );
        assert!(r.cut_percent > 50.0, "{}", r.cut_percent);
        assert!(truth_cut > 50.0, "{before:e} -> {after:e}");
    }
}
