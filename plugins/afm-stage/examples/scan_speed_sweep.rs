//! The Sec. 6.5 scan on the simulated stage (Fig. 6.11) and its speed sweep
//! (Table 6.4 style): rms and max x error for feedback only, + position FF (6.7)
//! and + hysteresis FF (6.6), and the y error that the x scan couples into y.
//!
//! `cargo run --release -p nanomotion-afm-stage --example scan_speed_sweep`

use afm_stage::control::{FeedForward, scan_experiment};
use afm_stage::experiments::{SWEEP_SPEEDS_UM_S, Sec65, speed_sweep};
use afm_stage::stage::AfmStage;

fn main() {
    let stage = AfmStage::default();
    let base = Sec65::new(&stage, 18.0, 7.2, 5000.0, 4).unwrap();
    println!(
        "extended model (6.4) identified on the stage's x hysteresis: accuracy {:.2} % (trace), {:.2} % (retrace)",
        base.fit_accuracy_percent[0], base.fit_accuracy_percent[1]
    );
    println!(
        "scan {:.2} .. {:.2} µm (±18 µm), controllers k = {:.3e} / {:.3e} V/(m s), f_LP = 60 Hz, 5 kHz; second period scored\n",
        base.setup.x_lo_um,
        base.setup.x_hi_um,
        base.setup.controllers[0].k,
        base.setup.controllers[1].k
    );
    let rows = speed_sweep(&stage, &base, &SWEEP_SPEEDS_UM_S).unwrap();
    let r72 = rows.iter().find(|r| r.speed_um_s == 7.2).unwrap();
    println!("Sec. 6.5, ±18 µm at 7.2 µm/s (Fig. 6.11):\n");
    println!("| | rms e_x (nm) | max e_x (nm) | max e_x imaging (nm) | rms e_y (nm) |");
    println!("|---|---|---|---|---|");
    for (name, r) in [
        ("feedback only", r72.feedback),
        ("+ position FF", r72.position_ff),
        ("+ hysteresis FF", r72.hysteresis_ff),
    ] {
        println!(
            "| {name} | {:.2} | {:.1} | {:.1} | {:.3} |",
            r.rms_x_nm, r.max_x_nm, r.max_x_imaging_nm, r.rms_y_nm
        );
    }
    let (vs_fb, vs_pos) = r72.reductions_percent();
    println!(
        "\nhysteresis FF: rms −{vs_fb:.0} % vs feedback only, −{vs_pos:.0} % vs position FF (thesis: −89 %, −43 %)\n"
    );
    println!(
        "Speed sweep (Table 6.4 style; rms over the whole second period, max in the imaging region):\n"
    );
    println!(
        "| speed (µm/s) | rms e_x FB | rms e_x +pos FF | rms e_x +hyst FF | max e_x FB | max e_x +pos FF | max e_x +hyst FF | rms e_y FB | hyst FF vs FB / vs pos FF |"
    );
    println!("|---|---|---|---|---|---|---|---|---|");
    for r in &rows {
        let (a, b) = r.reductions_percent();
        println!(
            "| {:.1} | {:.2} | {:.2} | {:.2} | {:.1} | {:.1} | {:.1} | {:.3} | −{a:.0} % / −{b:.0} % |",
            r.speed_um_s,
            r.feedback.rms_x_nm,
            r.position_ff.rms_x_nm,
            r.hysteresis_ff.rms_x_nm,
            r.feedback.max_x_imaging_nm,
            r.position_ff.max_x_imaging_nm,
            r.hysteresis_ff.max_x_imaging_nm,
            r.feedback.rms_y_nm,
        );
    }
    let mut decoupled = stage.clone();
    decoupled.static_coupling = [[0.0; 3]; 3];
    decoupled.dynamic_coupling = [[0.0; 3]; 3];
    println!("\ny error (feedback only) with and without the stage's cross-coupling:\n");
    println!("| speed (µm/s) | rms e_y coupled (nm) | rms e_y decoupled (nm) |");
    println!("|---|---|---|");
    for r in &rows {
        let d = scan_experiment(
            &decoupled,
            &base.with_speed(r.speed_um_s).setup,
            &FeedForward::None,
        )
        .unwrap();
        println!(
            "| {:.1} | {:.3} | {:.3} |",
            r.speed_um_s, r.feedback.rms_y_nm, d.rms_y_nm
        );
    }
}
