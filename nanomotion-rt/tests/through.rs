//! The stability gate on the loop closed through a device, with the device's
//! declared latency as a delay in it (`nanomotion_rt::through`).

use nanomotion_core::GraphSpec;
use nanomotion_core::gate::{self, FrontEnd, GateReport, SisoMargins};
use nanomotion_rt::through::{ThroughError, before_run_through, joined_through_device};
use nanomotion_rt::{
    Channel, Device, DeviceError, LiveError, ParamSender, PlantInfo, RealtimeRunner, RtConfig,
    ShmDevice, ShmPlant,
};
use std::time::Duration;

const EXAMPLES: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/../examples");

fn spec(file: &str) -> GraphSpec {
    nanomotion_rt::link_blocks();
    GraphSpec::from_file(format!("{EXAMPLES}/{file}")).unwrap()
}

fn controller() -> GraphSpec {
    spec("realtime/quickstart_controller.yaml")
}

fn plant() -> GraphSpec {
    spec("realtime/quickstart_plant.yaml")
}

/// The gate on the split quickstart joined with `latency` controller ticks.
fn joined_gate(latency: u32) -> GateReport {
    let require = controller().require.unwrap_or_default();
    let (sched, _) = joined_through_device(controller(), plant(), latency)
        .unwrap()
        .build()
        .unwrap();
    gate::analyse(&sched, &require)
}

fn margins(r: &GateReport) -> SisoMargins {
    assert_eq!(r.loops.len(), 1, "{r}");
    r.loops[0].points[0].margins.clone().unwrap()
}

/// The controller's sample period (s).
const T: f64 = 1.0 / 4000.0;

#[test]
fn the_split_quickstart_joined_without_latency_is_the_quickstart_to_the_gate() {
    let joined = joined_gate(0);
    let (single, _) = spec("quickstart.yaml").build().unwrap();
    let single = gate::analyse(&single, &Default::default());
    assert!(joined.passes() && single.passes(), "{joined}\n{single}");
    let (j, s) = (margins(&joined), margins(&single));
    // The plant's encoder runs at 40 kHz in the split graph and at 4 kHz in
    // the quickstart; sampled at the PI's instants (and judged at its
    // linearisation, gain 1) it is the same loop.
    let close = |a: f64, b: f64| (a - b).abs() <= 1e-6 * b.abs();
    assert!(close(j.phase_margin_deg, s.phase_margin_deg), "{j:?} {s:?}");
    assert!(close(j.gain_margin_db, s.gain_margin_db), "{j:?} {s:?}");
    assert!(close(j.delay_margin_s, s.delay_margin_s), "{j:?} {s:?}");
    assert!(
        close(j.gain_crossover_hz, s.gain_crossover_hz),
        "{j:?} {s:?}"
    );
    let (pj, ps) = (&joined.loops[0].points[0], &single.loops[0].points[0]);
    assert!(close(pj.spectral_radius, ps.spectral_radius));
    // The loop is the controller's (`pi`) and holds the plant's blocks.
    assert_eq!(joined.loops[0].name, "pi");
    assert!(
        joined.loops[0].blocks.contains(&"plant_stage".to_string()),
        "{:?}",
        joined.loops[0].blocks
    );
}

#[test]
fn a_latency_that_eats_the_phase_margin_is_refused_and_one_tick_less_passes() {
    // The margins the gate reports without latency decide: a delay of n
    // controller ticks takes 360°·f_c·n·T of phase at the gain crossover f_c
    // (|z^-n| = 1 leaves f_c where it is), so the loop stays stable while
    // n·T < the delay margin PM/ω_c and loses it beyond.
    let m0 = margins(&joined_gate(0));
    let critical = m0.delay_margin_s / T;
    assert!(critical > 2.0 && critical.fract() > 1e-6, "{m0:?}");
    let (eats_most, eats_all) = (critical.floor() as u32, critical.ceil() as u32);
    for n in [1, eats_most] {
        let r = joined_gate(n);
        assert!(r.passes(), "latency {n}: {r}");
        let m = margins(&r);
        let lost = 360.0 * m0.gain_crossover_hz * f64::from(n) * T;
        assert!(
            (m.phase_margin_deg - (m0.phase_margin_deg - lost)).abs() < 1e-6,
            "latency {n}: PM {} vs {} − {lost}",
            m.phase_margin_deg,
            m0.phase_margin_deg
        );
        assert!((m.gain_crossover_hz - m0.gain_crossover_hz).abs() < 1e-9 * m0.gain_crossover_hz);
        assert!((m.delay_margin_s - (m0.delay_margin_s - f64::from(n) * T)).abs() < 1e-9);
    }
    let r = joined_gate(eats_all);
    assert!(!r.passes(), "latency {eats_all}: {r}");
    assert!(
        r.failures()[0].starts_with("loop `pi` is unstable: closed-loop pole of modulus"),
        "{:?}",
        r.failures()
    );
}

/// A device that drives the quickstart's stage (its plant graph as the
/// model) with a declared latency; the gate asks nothing else of it.
struct Modelled {
    latency: u32,
    channels: (Vec<Channel>, Vec<Channel>),
}

impl Modelled {
    fn new(latency: u32) -> Self {
        Self {
            latency,
            channels: (
                vec![Channel::new("position", Some("m"))],
                vec![Channel::new("drive", Some("Hz"))],
            ),
        }
    }
}

impl Device for Modelled {
    fn name(&self) -> &str {
        "modelled"
    }
    fn inputs(&self) -> &[Channel] {
        &self.channels.0
    }
    fn outputs(&self) -> &[Channel] {
        &self.channels.1
    }
    fn read(&mut self, _now_ns: u64, _inputs: &mut [f64]) -> Result<(), DeviceError> {
        Ok(())
    }
    fn write(&mut self, _now_ns: u64, _outputs: &[f64]) -> Result<(), DeviceError> {
        Ok(())
    }
    fn latency_ticks(&self) -> u32 {
        self.latency
    }
    fn plant_model(&self) -> Result<Option<GraphSpec>, DeviceError> {
        Ok(Some(plant()))
    }
}

#[test]
fn before_a_run_the_gate_judges_the_loop_with_the_devices_latency() {
    let m0 = margins(&joined_gate(0));
    let eats_all = (m0.delay_margin_s / T).ceil() as u32;
    // Latency 0: the margins of the quickstart, named with the device.
    let lines = before_run_through(controller(), &Modelled::new(0), false, &FrontEnd::CLI).unwrap();
    assert_eq!(
        lines,
        [format!(
            "loop `pi` closed through device `modelled` with its latency of 0 ticks (0.0 µs): phase margin {:.2}°, delay margin {:.4} ms ({:.2} ticks)",
            m0.phase_margin_deg,
            m0.delay_margin_s * 1e3,
            m0.delay_margin_s / T
        )]
    );
    // A latency that eats the margin: refused before the run, with the fix;
    // run anyway only when allowed, and then the report says so.
    match before_run_through(
        controller(),
        &Modelled::new(eats_all),
        false,
        &FrontEnd::CLI,
    ) {
        Err(e @ ThroughError::Refused(_)) => {
            let text = e.to_string();
            assert!(
                text.starts_with(&format!(
                    "the loop through device `modelled` with its latency of {eats_all} ticks: the stability gate refuses the graph (see `nanomotion check`; fix the loop, or run anyway with --allow-unproven):\n  loop `pi` is unstable"
                )),
                "{text}"
            );
        }
        other => panic!("{other:?}"),
    }
    let lines = before_run_through(
        controller(),
        &Modelled::new(eats_all),
        true,
        &FrontEnd::PYTHON,
    )
    .unwrap();
    assert!(lines[0].ends_with(" — fails"), "{lines:?}");
    assert!(
        lines[1].contains("running anyway because of allow_unproven=True"),
        "{lines:?}"
    );
    // A device without a model: nothing to judge, nothing said.
    let lines = before_run_through(
        controller(),
        &nanomotion_rt::NoDevice,
        false,
        &FrontEnd::CLI,
    )
    .unwrap();
    assert!(lines.is_empty());
}

/// The quickstart plant's channels served under `name`, with `graph` in the
/// descriptor.
fn serve(name: &str, graph: serde_json::Value) -> ShmPlant {
    let info = PlantInfo {
        title: None,
        rate_hz: 40000.0,
        to_plant: vec![Channel::new("drive", Some("Hz"))],
        from_plant: vec![Channel::new("position", Some("m"))],
        graph: Some(graph),
    };
    ShmPlant::serve(name, info, Duration::from_secs(5)).unwrap()
}

#[test]
fn a_served_plant_shares_its_graph_and_the_shm_device_declares_one_tick() {
    let name = format!("test-through-{}", std::process::id());
    let _plant = serve(&name, serde_json::to_value(plant()).unwrap());
    let dev = ShmDevice::connect(&name, Duration::from_secs(1), Duration::from_secs(5)).unwrap();
    assert_eq!(dev.latency_ticks(), 1);
    let model = dev
        .plant_model()
        .unwrap()
        .expect("the served plant's graph");
    assert_eq!(
        serde_json::to_value(&model).unwrap(),
        serde_json::to_value(plant()).unwrap()
    );
    let m1 = margins(&joined_gate(1));
    let lines = before_run_through(controller(), &dev, false, &FrontEnd::CLI).unwrap();
    assert_eq!(
        lines,
        [format!(
            "loop `pi` closed through device `shm:{name}` with its latency of 1 tick (250.0 µs): phase margin {:.2}°, delay margin {:.4} ms ({:.2} ticks)",
            m1.phase_margin_deg,
            m1.delay_margin_s * 1e3,
            m1.delay_margin_s / T
        )]
    );
}

#[test]
fn a_channel_without_a_partner_is_named_with_the_fix() {
    let mut p = plant();
    p.blocks.retain(|b| b.name != "position");
    p.connections.retain(|c| !c.to.starts_with("position."));
    match joined_through_device(controller(), p, 1) {
        Err(e @ ThroughError::Unmatched { .. }) => assert_eq!(
            e.to_string(),
            "channel `position`: the controller's hw_input block has no partner in the plant graph (fix: give the plant graph a `hw_output` block named `position`)"
        ),
        other => panic!("{other:?}"),
    }
}

#[test]
fn a_plant_graph_too_large_for_the_descriptor_is_served_without_it() {
    // The descriptor holds 8 KiB: the channels always, the graph if it fits.
    let name = format!("test-through-large-{}", std::process::id());
    let plant = serve(&name, serde_json::Value::String("x".repeat(9000)));
    assert_eq!(plant.info().graph, None);
    let dev = ShmDevice::connect(&name, Duration::from_secs(1), Duration::from_secs(5)).unwrap();
    assert_eq!(dev.info().to_plant, [Channel::new("drive", Some("Hz"))]);
    assert!(dev.plant_model().unwrap().is_none());
    // No model: nothing judged, nothing said.
    let lines = before_run_through(controller(), &dev, false, &FrontEnd::CLI).unwrap();
    assert!(lines.is_empty());
}

/// The split quickstart's controller with the PI's k_p set to `kp`.
fn controller_with_kp(kp: f64) -> GraphSpec {
    let set = nanomotion_core::Override::parse(&format!("blocks.pi.kp={kp}")).unwrap();
    nanomotion_rt::link_blocks();
    GraphSpec::from_file_with_overrides(
        format!("{EXAMPLES}/realtime/quickstart_controller.yaml"),
        &[set],
    )
    .unwrap()
}

/// The gate on the controller with `kp` joined with the plant and `latency`.
fn joined_gate_with_kp(kp: f64, latency: u32) -> GateReport {
    let (sched, _) = joined_through_device(controller_with_kp(kp), plant(), latency)
        .unwrap()
        .build()
        .unwrap();
    gate::analyse(&sched, &Default::default())
}

/// `graph` built to run 20 ticks against `device` (soft), and the sender of
/// its live updates, not yet gated.
fn soft_runner<D: Device>(graph: GraphSpec, device: D) -> (RealtimeRunner<D>, ParamSender) {
    let (sched, _) = graph.build().unwrap();
    let cfg = RtConfig {
        allow_soft: true,
        ticks: Some(20),
        ..RtConfig::default()
    };
    let mut r = RealtimeRunner::new(sched, device, cfg).unwrap();
    let sender = r.param_sender().unwrap();
    (r, sender)
}

/// The controller run against `device`, and the sender of its live updates
/// judged on the loop through the device.
fn through_runner<D: Device>(device: D) -> (RealtimeRunner<D>, ParamSender) {
    let (r, sender) = soft_runner(controller(), device);
    let sender = sender.gated_through(controller(), r.device()).unwrap();
    (r, sender)
}

#[test]
fn a_live_update_is_judged_on_the_loop_through_the_device_with_its_latency() {
    // The loop gain is proportional to k_p (k_i = k_p·2π f_i), so the gain
    // margin the gate reports gives the k_p at which the loop through the
    // device goes unstable: 9.5e7 with no latency (GM 9.65 dB), 1.77e8 with one
    // tick (GM 15.0 dB: the tick moves the phase crossover from 565 Hz to
    // 517 Hz, where the stage's gain is lower). A k_p between the two is
    // stable through the device with its tick and not without; ten times the
    // design's is unstable with either.
    let kp0 = 3.1416e7;
    let critical = |latency| kp0 * 10f64.powf(margins(&joined_gate(latency)).gain_margin_db / 20.0);
    let (c0, c1) = (critical(0), critical(1));
    assert!(c0 < c1, "{c0} {c1}");
    let (between, high) = ((c0 * c1).sqrt(), 10.0 * kp0);
    assert!(!joined_gate_with_kp(between, 0).passes());
    assert!(joined_gate_with_kp(between, 1).passes());
    let refused = joined_gate_with_kp(high, 1);
    assert!(!refused.passes(), "{refused}");

    // The controller graph alone has no loop: its gate has nothing to judge.
    let (_r, alone) = soft_runner(controller(), Modelled::new(1));
    let mut alone = alone.gated_spec(controller()).unwrap();
    alone.set("pi.kp", high).unwrap();

    // Through the device with its one tick: refused, naming the parameter,
    // the device and its latency, the gate's failures on the joined loop and
    // the margins the loop had with the values accepted so far.
    let (_r, mut sender) = through_runner(Modelled::new(1));
    assert!(sender.is_gated());
    let before = margins(&joined_gate(1));
    let e = sender.set("pi.kp", high).unwrap_err();
    let text = e.to_string();
    match e {
        LiveError::Gate {
            path,
            reasons,
            margins,
            through,
            ..
        } => {
            assert_eq!(path, "pi.kp");
            assert_eq!(reasons, refused.failures());
            assert!(
                reasons[0].starts_with("loop `pi` is unstable"),
                "{reasons:?}"
            );
            assert_eq!(margins, [("pi".to_string(), before.clone())]);
            assert_eq!(
                through.as_deref(),
                Some("the loop through device `modelled` with its latency of 1 tick")
            );
            assert!(
                text.starts_with(&format!(
                    "`pi.kp` = {high} refused by the stability gate on the loop through device `modelled` with its latency of 1 tick: loop `pi` is unstable"
                )),
                "{text}"
            );
            assert!(
                text.contains(&format!(
                    "; with the values accepted so far loop `pi` had phase margin {:.2}°, delay margin {:.4} ms (fix: ",
                    before.phase_margin_deg,
                    before.delay_margin_s * 1e3
                )),
                "{text}"
            );
        }
        other => panic!("{other:?}"),
    }
    // Through the device with its one tick the value between holds; without
    // latency the same value is refused, naming the device's 0 ticks.
    sender.set("pi.kp", between).unwrap();
    let (_r, mut sender) = through_runner(Modelled::new(0));
    match sender.set("pi.kp", between) {
        Err(LiveError::Gate {
            reasons, through, ..
        }) => {
            assert_eq!(reasons, joined_gate_with_kp(between, 0).failures());
            assert_eq!(
                through.as_deref(),
                Some("the loop through device `modelled` with its latency of 0 ticks")
            );
        }
        other => panic!("{other:?}"),
    }

    // A stable change is applied, and the loop's PI is then the one built
    // with it, to the bit; the gate judges the next change from there.
    let (mut r, mut sender) = through_runner(Modelled::new(1));
    sender.set("pi.kp", 6.0e7).unwrap();
    let report = r.run(|_| {}).unwrap();
    assert_eq!(report.param_updates, 1);
    let (fresh, _) = controller_with_kp(6.0e7).build().unwrap();
    assert_eq!(r.scheduler().lti_of("pi"), fresh.lti_of("pi"));
    let accepted = margins(&joined_gate_with_kp(6.0e7, 1));
    match sender.set("pi.kp", high) {
        Err(LiveError::Gate { margins, .. }) => {
            assert_eq!(margins, [("pi".to_string(), accepted)])
        }
        other => panic!("{other:?}"),
    }
}

#[test]
fn a_device_without_a_plant_model_leaves_live_updates_to_the_graphs_own_gate() {
    // NoDevice has no model: `gated_through` is `gated_spec`.
    let (r, sender) = soft_runner(spec("quickstart.yaml"), nanomotion_rt::NoDevice);
    let mut sender = sender
        .gated_through(spec("quickstart.yaml"), r.device())
        .unwrap();
    match sender.set("pi.kp", 3.1416e8) {
        Err(LiveError::Gate { through, .. }) => assert_eq!(through, None),
        other => panic!("{other:?}"),
    }
}
