//! SVG figures of the Ch. 3 reproductions (`walking_piezo::thesis_ch3`): Fig. 3.8
//! (FRF against the number of layers), Fig. 3.9 (FRF over a drive cycle), Figs.
//! 3.11/3.13 (tip trajectories) and 3.12/3.14 (time signals and errors): the full
//! Lagrange model driven by the waveforms (1 kHz drive, RK4 at 0.1 µs) against the
//! static map (3.26)–(3.29).
//!
//! Run: `cargo run --example thesis_ch3_figures [-- OUT_DIR]`
//! (default `docs/figures/ch3`).

use nanomotion::plot::{Figure, Scale, Series, draw_svg, draw_svg_panels};
use nanomotion::walking_piezo::thesis_ch3::*;
use std::path::PathBuf;

fn frf_panels(curves: &[FrfCurves], freqs: &[f64], title: &str) -> Vec<Figure> {
    let names = ["x ← u1", "x ← u2", "y ← u1", "y ← u2"];
    [0, 2]
        .into_iter()
        .map(|ch| Figure {
            title: format!("{title}: |H| {}", names[ch]),
            x_label: "f (Hz)".into(),
            y_label: "|H| (dB re 1 nm/V)".into(),
            y_unit: None,
            x_scale: Scale::Log,
            series: curves
                .iter()
                .map(|c| Series {
                    label: c.label.clone(),
                    x: freqs.to_vec(),
                    y: c.db[ch].clone(),
                })
                .collect(),
        })
        .collect()
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let out = PathBuf::from(
        std::env::args()
            .nth(1)
            .unwrap_or_else(|| "docs/figures/ch3".into()),
    );
    std::fs::create_dir_all(&out)?;
    let freqs = log_grid(1e3, 1e6, 300);
    draw_svg_panels(
        &frf_panels(&fig_3_8(&freqs)?, &freqs, "Fig. 3.8, n_m = 2 … 10"),
        &out.join("fig_3_8_frf_layers.svg"),
    )?;
    for (wave, name) in [
        (Ch3Waveform::Sinusoidal, "sinusoidal"),
        (Ch3Waveform::Asymmetric, "asymmetric"),
    ] {
        let curves = fig_3_9_frf(wave, 8, &freqs)?;
        draw_svg_panels(
            &frf_panels(&curves, &freqs, &format!("Fig. 3.9, {name}, n_m = 6")),
            &out.join(format!("fig_3_9_frf_cycle_{name}.svg")),
        )?;
        let (c, _) = dynamic_tip(wave, 1e3, 1e-7, 500)?;
        let um = |v: &[f64]| v.iter().map(|x| x * 1e6).collect::<Vec<f64>>();
        let fig = if wave == Ch3Waveform::Sinusoidal {
            ("3.11", "3.12")
        } else {
            ("3.13", "3.14")
        };
        draw_svg(
            &Figure {
                title: format!("Fig. {}: tip trajectory, {name} waveform", fig.0),
                x_label: "x (µm)".into(),
                y_label: "y (µm)".into(),
                y_unit: None,
                x_scale: Scale::Linear,
                series: vec![
                    Series {
                        label: "full Lagrange model (3.11), driven at 1 kHz".into(),
                        x: um(&c.x_model),
                        y: um(&c.y_model),
                    },
                    Series {
                        label: "static map (3.26)–(3.29)".into(),
                        x: um(&c.x_static),
                        y: um(&c.y_static),
                    },
                ],
            },
            &out.join(format!("fig_{}_tip_{name}.svg", fig.0.replace('.', "_"))),
        )?;
        let mut panels = Vec::new();
        for (axis, model, stat) in [
            ("x", &c.x_model, &c.x_static),
            ("y", &c.y_model, &c.y_static),
        ] {
            panels.push(Figure {
                title: format!("Fig. {}: {axis}, {name} waveform", fig.1),
                x_label: "t (s)".into(),
                y_label: axis.into(),
                y_unit: Some("m".into()),
                x_scale: Scale::Linear,
                series: vec![
                    Series {
                        label: "full model".into(),
                        x: c.t_s.clone(),
                        y: model.clone(),
                    },
                    Series {
                        label: "static map".into(),
                        x: c.t_s.clone(),
                        y: stat.clone(),
                    },
                ],
            });
            panels.push(Figure {
                title: format!("e_{axis} = full model − static map"),
                x_label: "t (s)".into(),
                y_label: format!("e_{axis}"),
                y_unit: Some("m".into()),
                x_scale: Scale::Linear,
                series: vec![Series {
                    label: format!("e_{axis}"),
                    x: c.t_s.clone(),
                    y: model.iter().zip(stat).map(|(a, b)| a - b).collect(),
                }],
            });
        }
        draw_svg_panels(
            &panels,
            &out.join(format!("fig_{}_time_{name}.svg", fig.1.replace('.', "_"))),
        )?;
    }
    println!("wrote the Ch. 3 figures to {}", out.display());
    Ok(())
}
