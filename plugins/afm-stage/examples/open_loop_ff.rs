//! The open-loop hysteresis feed-forward experiment of Sec. 6.5 (Fig. 6.10) on the
//! simulated stage: the graph `examples/afm_hysteresis_ff_open_loop.yaml` (inverse
//! (6.6) of the identified extended Coleman–Hodgdon model, no feedback), and the same
//! graph with the feed-forward replaced by the position feed-forward (6.7) — a
//! straight line through the loop, i.e. no hysteresis compensation — and by a constant
//! voltage (no feed-forward at all). x error e_x = r_x − x (interferometer) over the
//! second scan period; "imaging" excludes the first 10 % of each line after a
//! turnaround.
//!
//! `cargo run --release -p nanomotion-afm-stage --example open_loop_ff`
use afm_stage::experiments::Sec65;
use afm_stage::stage::AfmStage;
use nanomotion_core::GraphSpec;

const GRAPH: &str = "afm_hysteresis_ff_open_loop.yaml";

/// (max |e_x|, rms e_x, max |e_x| in the imaging region, mean e_x), all in m, of the graph
/// with its `ff` block replaced by `ff_block` (None: as shipped).
fn run(ff_block: Option<&str>, decoupled: bool) -> (f64, f64, f64, f64) {
    let path = format!("{}/../../examples/{GRAPH}", env!("CARGO_MANIFEST_DIR"));
    let mut text = std::fs::read_to_string(path).expect("example graph");
    if decoupled {
        // The stage without its x/y/z cross-coupling (static and dynamic).
        let zero = "[[0.0, 0.0, 0.0], [0.0, 0.0, 0.0], [0.0, 0.0, 0.0]]";
        text = text.replace(
            "    initial_v: [48.8, 50.0, 50.0]\n",
            &format!(
                "    initial_v: [48.8, 50.0, 50.0]\n    static_coupling: {zero}\n    dynamic_coupling: {zero}\n"
            ),
        );
    }
    if let Some(b) = ff_block {
        let (i, j) = (
            text.find("  - name: ff\n").expect("ff block"),
            text.find("  - name: v_yz").expect("v_yz block"),
        );
        text.replace_range(i..j, b);
        text = text.replace(", ff.state]", "]");
    }
    let spec = GraphSpec::from_yaml(&text, GRAPH).expect("graph");
    let (mut sched, _report) = spec.build().expect("build");
    let res = sched.run(|_| {});
    let s = &res.scores[0];
    let log = |name: &str| res.logs.iter().find(|l| l.name == name).expect("log");
    let (r, pos) = (log("ref.y"), log("stage.pos"));
    // Second period (10 s at 5 kHz), two lines of 5 s; skip 0.5 s after each turn.
    let (r, n, line) = (r.column(0), r.len(), 25_000usize);
    let max_img = (n / 2..n)
        .filter(|k| (k - n / 2) % line >= line / 10)
        .fold(0.0f64, |m, k| m.max((r[k] - pos.data[3 * k]).abs()));
    (s.max_abs, s.rms, max_img, s.mean)
}

fn main() {
    let sec = Sec65::new(&AfmStage::default(), 18.0, 7.2, 5000.0, 4).expect("Sec65");
    let p = sec.position_ff;
    println!(
        "open loop, ±18 µm at 7.2 µm/s, x error over the second scan period (Fig. 6.10; thesis max |e_x| = 0.2941 µm)"
    );
    println!(
        "| feed-forward | max abs e_x (µm) | rms e_x (nm) | max abs e_x imaging (µm) | mean e_x (nm) | rms e_x − mean (nm) |"
    );
    println!("|---|---|---|---|---|---|");
    let pos = format!(
        "  - name: ff\n    type: position_feedforward\n    gain_v_per_um: {:e}\n    offset_v: {:e}\n",
        p.gain_v_per_um, p.offset_v
    );
    // No feed-forward: the voltage of the scan centre, held.
    let v_mid = p.voltage(48.77);
    let none = format!(
        "  - name: ff\n    type: position_feedforward\n    gain_v_per_um: 0.0\n    offset_v: {v_mid:e}\n"
    );
    for (name, block, decoupled) in [
        ("hysteresis (6.6)", None, false),
        (
            &*format!("position (6.7), K = {:.4} V/µm", p.gain_v_per_um),
            Some(pos.as_str()),
            false,
        ),
        (
            &*format!("none ({v_mid:.2} V held)"),
            Some(none.as_str()),
            false,
        ),
        ("hysteresis (6.6), stage without cross-coupling", None, true),
        (
            "position (6.7), stage without cross-coupling",
            Some(pos.as_str()),
            true,
        ),
    ] {
        let (max, rms, img, mean) = run(block, decoupled);
        println!(
            "| {name} | {:.4} | {:.1} | {:.4} | {:.1} | {:.1} |",
            max * 1e6,
            rms * 1e9,
            img * 1e6,
            mean * 1e9,
            (rms * rms - mean * mean).max(0.0).sqrt() * 1e9
        );
    }
}
