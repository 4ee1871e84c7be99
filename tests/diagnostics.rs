//! Issue 13 item 14: library diagnostics go through `tracing` (no ad-hoc prints):
//! a subscriber sees the waveform optimisation's progress and the graph
//! compiler's notes; without one, nothing is printed.

use std::io::Write;
use std::ops::ControlFlow;
use std::sync::{Arc, Mutex};

#[derive(Clone, Default)]
struct Capture(Arc<Mutex<Vec<u8>>>);

impl Write for Capture {
    fn write(&mut self, buf: &[u8]) -> std::io::Result<usize> {
        self.0.lock().unwrap().extend_from_slice(buf);
        Ok(buf.len())
    }
    fn flush(&mut self) -> std::io::Result<()> {
        Ok(())
    }
}

#[test]
fn optimisation_progress_and_build_notes_are_tracing_events() {
    use nanomotion::walking_piezo::optimize::{OptimizeConfig, Prepared, optimize};
    nanomotion::link_plugins();
    let cap = Capture::default();
    let writer = cap.clone();
    let subscriber = tracing_subscriber::fmt()
        .with_max_level(tracing::Level::DEBUG)
        .with_ansi(false)
        .with_writer(move || writer.clone())
        .finish();
    tracing::subscriber::with_default(subscriber, || {
        let mut cfg = OptimizeConfig::from_yaml(
            "objective: model\nseed: 5\namplitude_v: 24.0\nsimulation: {warmup_cycles: 1, cycles: 1}\nbudget:\n  sa: {chunks: 1, iterations: 5}\n  pso: {chunks: 1, iterations: 1, particles: 4}\n  local: {chunks: 1, iterations: 5}\n",
            "test",
        )
        .unwrap();
        cfg.seed = 5;
        let p = Prepared::new(&cfg).unwrap();
        let o = optimize(&p, None, &mut |_| ControlFlow::Continue(())).unwrap();
        assert!(o.finished);
        let spec = nanomotion::core::graph::GraphSpec::from_yaml(
            "base_rate_hz: 1000\nduration_s: 0.01\nblocks:\n  - { name: a, type: constant, value: 1.0, rate_hz: 100 }\n  - { name: g, type: gain, k: 2 }\nconnections:\n  - { from: a.y, to: g.u }\n",
            "t.yaml",
        )
        .unwrap();
        spec.build().unwrap();
    });
    let text = String::from_utf8(cap.0.lock().unwrap().clone()).unwrap();
    // One event per chunk of each of the three phases, with the phase named.
    assert_eq!(
        text.matches("waveform optimisation chunk done").count(),
        3,
        "{text}"
    );
    for phase in ["simulated_annealing", "particle_swarm", "local"] {
        assert!(text.contains(&format!("phase=\"{phase}\"")), "{text}");
    }
    // The compiler's rate-transition note (info) and its build summary (debug).
    assert!(text.contains("rt:a:y:g"), "{text}");
    assert!(text.contains("graph built"), "{text}");
}
