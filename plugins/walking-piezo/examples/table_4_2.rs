//! Table 4.2 (Sec. 4.4) on simulation: strokes and rms model errors per waveform
//! at 10 Hz of the Ch. 4 model identified from waveforms 1–5
//! (`walking_piezo::thesis_table_4_2`).
//!
//! `cargo run -p nanomotion-walking-piezo --example table_4_2 [-- --quick]`

use walking_piezo::thesis_table_4_2::table_4_2;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let quick = std::env::args().any(|a| a == "--quick");
    let t0 = std::time::Instant::now();
    let t = table_4_2(quick)?;
    println!(
        "identified in {:.1} s ({} evaluations), records averaged over {} periods",
        t0.elapsed().as_secs_f64(),
        t.evaluations,
        t.periods
    );
    println!("            c_x1..4 (nm/V)                  c_y1..4 (nm/V)                mu");
    let fmt = |a: [f64; 4]| a.map(|v| format!("{v:6.2}")).join(" ");
    println!(
        "truth      {}   {}   {:.3}",
        fmt(t.truth.0),
        fmt(t.truth.1),
        t.truth.2
    );
    println!(
        "identified {}   {}   {:.3}",
        fmt(t.identified.0),
        fmt(t.identified.1),
        t.identified.2
    );
    println!(
        "\n{:>2} {:<22} {:>6} {:>11} {:>11} {:>11} {:>11} {:>13}",
        "w",
        "type",
        "use",
        "stroke x um",
        "rms e_x nm",
        "stroke y um",
        "rms e_y nm",
        "nominal e_x nm"
    );
    for r in &t.rows {
        println!(
            "{:>2} {:<22} {:>6} {:>11.3} {:>11.2} {:>11.3} {:>11.2} {:>13.1}",
            r.waveform.w,
            r.waveform.name,
            if r.waveform.identification {
                "ident"
            } else {
                "valid"
            },
            r.stroke.0 * 1e6,
            r.rms_error.0 * 1e9,
            r.stroke.1 * 1e6,
            r.rms_error.1 * 1e9,
            r.rms_error_nominal.0 * 1e9
        );
    }
    println!(
        "\naccuracy 1 - mean rms(e)/mean rms(signal): x {:.2} %, y {:.2} % (thesis: 93 % / 80 %)",
        100.0 * t.accuracy.0,
        100.0 * t.accuracy.1
    );
    Ok(())
}
