//! `nanomotion synth CONFIG.yaml --out DIR`: the H∞ mixed-sensitivity design of
//! thesis Sec. 7.3.2 (library: `nanomotion_mimo::config`). Writes
//! `controller.yaml` (a `mimo_controller` block entry for a graph's `blocks:`),
//! `report.json` (γ, order, crossovers, margins, ‖S_o‖∞, ‖T_o‖∞, reduction,
//! decentralised comparison), `generalized_plant.json` (the continuous P of
//! (7.8) as `{"a","b","c","d","nmeas","ncon"}`, for checking γ with another
//! tool) and SVG plots of K, S_o, T_o, the characteristic loci and the (7.4) test.

use nanomotion::core::analysis::CMatrix;
use nanomotion::core::lti::{Complex, StateSpace};
use nanomotion::mimo::config::{GeneralizedPlantJson, SynthConfig, SynthResult, run};
use nanomotion::mimo::{decentral, synth};
use nanomotion::output::{Manifest, OutputFolder};
use nanomotion::plot::{Figure, Scale, Series, draw_svg, draw_svg_panels};
use serde::Serialize;
use std::f64::consts::TAU;
use std::path::Path;

/// Largest config file read (bytes).
const MAX_CONFIG_BYTES: u64 = 16 << 20;

#[derive(Serialize)]
struct BlockEntry<'a> {
    name: &'a str,
    #[serde(rename = "type")]
    type_: &'a str,
    rate_hz: f64,
    #[serde(flatten)]
    block: &'a nanomotion::mimo::MimoController,
}

fn db(v: f64) -> f64 {
    20.0 * v.max(1e-300).log10()
}

fn sv(m: &CMatrix) -> Vec<f64> {
    let mut s: Vec<f64> = m.singular_values().iter().copied().collect();
    s.sort_by(|a, b| b.total_cmp(a));
    s
}

fn responses(sys: &StateSpace, f: &[f64]) -> Vec<CMatrix> {
    f.iter()
        .map(|&ff| sys.evalfr(Complex::new(0.0, TAU * ff)))
        .collect()
}

/// Run the design of `config` into `out`.
pub fn synth(config: &Path, out: &Path, force: bool) -> Result<(), String> {
    let meta = std::fs::metadata(config).map_err(|e| format!("{}: {e}", config.display()))?;
    if meta.len() > MAX_CONFIG_BYTES {
        return Err(format!(
            "{}: {} bytes, above the {MAX_CONFIG_BYTES}-byte limit for a synthesis config",
            config.display(),
            meta.len()
        ));
    }
    let text = std::fs::read_to_string(config).map_err(|e| format!("{}: {e}", config.display()))?;
    let cfg =
        SynthConfig::from_yaml(&text, &config.display().to_string()).map_err(|e| e.to_string())?;
    // Checked before the synthesis; the files appear only when all are written
    // (a graph `include:`s controller.yaml: it is never left half-written).
    let folder = OutputFolder::prepare(out, force).map_err(|e| e.to_string())?;
    let r = run(&cfg).map_err(|e| format!("{}: {e}", config.display()))?;
    let stage = folder.dir();
    let write = |name: &str, text: String| -> Result<(), String> {
        let p = stage.join(name);
        std::fs::write(&p, text).map_err(|e| format!("{}: {e}", p.display()))
    };
    let entry = vec![BlockEntry {
        name: "controller",
        type_: "mimo_controller",
        rate_hz: cfg.rate_hz,
        block: &r.block,
    }];
    let yaml = nanomotion::core::yaml::to_string(&entry).map_err(|e| e.to_string())?;
    write(
        "controller.yaml",
        format!(
            "# H∞ controller from `nanomotion synth {}`: γ = {:.4}, order {}, discretised (Tustin) at {} Hz.\n# Include it in a graph's `blocks:` as `- include: controller.yaml` (path relative to the graph) or paste it; ports r[{}], y[{}] -> u[{}].\n{yaml}",
            config.display(),
            r.synthesis.gamma,
            r.discrete.nstates(),
            cfg.rate_hz,
            r.discrete.ninputs(),
            r.discrete.ninputs(),
            r.discrete.noutputs()
        ),
    )?;
    let report = r.report(cfg.rate_hz);
    write(
        "report.json",
        serde_json::to_string_pretty(&report).map_err(|e| e.to_string())?,
    )?;
    write(
        "generalized_plant.json",
        serde_json::to_string(&GeneralizedPlantJson::from_synthesis(&r.synthesis))
            .map_err(|e| e.to_string())?,
    )?;
    plots(&cfg, &r, stage)?;
    let config_name = config.display().to_string();
    folder
        .commit(Some(&Manifest {
            command: "synth",
            graph: &config_name,
            title: &None,
            stability_gate: &[],
        }))
        .map_err(|e| e.to_string())?;
    say!(
        "γ = {:.4} (bracket [{:.4}, {:.4}], ‖N‖∞ = {:.4}), controller order {}, synthesis {:.3} s",
        r.synthesis.gamma,
        r.synthesis.gamma_infeasible,
        r.synthesis.gamma,
        r.synthesis.closed_loop_norm,
        r.synthesis.controller.nstates(),
        r.synthesis_time_s
    );
    let fmt = |v: &[Option<f64>]| {
        v.iter()
            .map(|c| c.map_or("-".to_string(), |c| format!("{c:.1}")))
            .collect::<Vec<_>>()
            .join(", ")
    };
    say!(
        "MIMO: crossovers {{{}}} Hz, ‖S_o‖∞ = {:.2} dB, ‖T_o‖∞ = {:.2} dB, sampled loop spectral radius {:.6}",
        fmt(&r.loop_report.crossovers_hz),
        db(r.loop_report.s_o_hinf),
        db(r.loop_report.t_o_hinf),
        r.sampled_spectral_radius
    );
    if let Some(red) = &r.reduction {
        say!(
            "reduced to {} states: ‖K − K_r‖∞ = {:.3e} ≤ 2Σσ_tail = {:.3e}, closed loop stable: {}",
            red.order,
            red.error,
            red.error_bound,
            red.loop_report.stable
        );
    }
    if let Some(d) = &r.decentralised {
        say!(
            "decentralised (7.2): crossovers {{{}}} Hz, ‖S_o‖∞ = {:.2} dB, ‖N(K_d)‖∞ = {:.3}; (7.4) {} (max σ̄(T_d)·μ̄(E) = {:.3e}, μ bound gap ≤ {:.1e})",
            fmt(&d.loop_report.crossovers_hz),
            db(d.loop_report.s_o_hinf),
            d.weighted_norm,
            if d.condition_7_4_holds {
                "holds"
            } else {
                "FAILS"
            },
            d.worst_product,
            d.worst_mu_gap
        );
        for (band, a, b) in &d.s_o_offdiag_db {
            say!(
                "  max off-diagonal |S_o| in {:.0}–{:.0} Hz: H∞ {a:.1} dB, decentralised {b:.1} dB",
                band[0],
                band[1]
            );
        }
    }
    say!(
        "wrote controller.yaml, report.json, generalized_plant.json and plots into {}",
        out.display()
    );
    Ok(())
}

fn plots(cfg: &SynthConfig, r: &SynthResult, out: &Path) -> Result<(), String> {
    let f = &r.grid_hz;
    let g = &r.plant;
    let k = &r.synthesis.controller;
    let kf = responses(k, f);
    let gf = responses(g, f);
    let n = g.noutputs();
    let kd: Option<Vec<CMatrix>> = r.decentralised.as_ref().map(|d| {
        f.iter()
            .map(|&ff| decentral::response(&d.axes, ff))
            .collect()
    });
    let e = |p: &Path, e: nanomotion::plot::PlotError| format!("{}: {e}", p.display());
    let ax = ["x", "y", "z"];
    let name = |i: usize| ax.get(i).map_or(i.to_string(), |s| s.to_string());
    // K: singular values (MIMO) and |k_ii| (decentralised).
    let mut series = Vec::new();
    for i in 0..n.min(k.ninputs()) {
        series.push(Series {
            label: format!("σ{} (K)", i + 1),
            x: f.clone(),
            y: kf.iter().map(|m| db(sv(m)[i])).collect(),
        });
    }
    if let Some(kd) = &kd {
        for i in 0..n {
            series.push(Series {
                label: format!("|K_d,{}{}|", name(i), name(i)),
                x: f.clone(),
                y: kd.iter().map(|m| db(m[(i, i)].norm())).collect(),
            });
        }
    }
    let p = out.join("controller.svg");
    draw_svg(
        &Figure {
            title: "Controller: singular values of K (H∞) and diagonal of K_d (7.2)".into(),
            x_label: "f (Hz)".into(),
            y_label: "dB".into(),
            y_unit: None,
            x_scale: Scale::Log,
            series,
        },
        &p,
    )
    .map_err(|x| e(&p, x))?;
    // S_o and T_o: each element, MIMO vs decentralised (9 panels would be large:
    // one panel with diagonal, one with off-diagonal).
    let so = |kk: &[CMatrix]| -> Vec<(CMatrix, CMatrix)> {
        gf.iter()
            .zip(kk)
            .map(|(gm, km)| {
                let s = (CMatrix::identity(n, n) + gm * km)
                    .try_inverse()
                    .unwrap_or_else(|| CMatrix::zeros(n, n));
                let t = CMatrix::identity(n, n) - &s;
                (s, t)
            })
            .collect()
    };
    let mimo = so(&kf);
    let dec = kd.as_ref().map(|kd| so(kd));
    for (file, title, pick) in [
        (
            "sensitivity.svg",
            "Output sensitivity S_o = (I + GK)⁻¹",
            0usize,
        ),
        (
            "complementary_sensitivity.svg",
            "Complementary sensitivity T_o = GK(I + GK)⁻¹",
            1usize,
        ),
    ] {
        let mut panels = Vec::new();
        for off in [false, true] {
            let mut series = Vec::new();
            for (lab, set) in [("H∞", Some(&mimo)), ("decentralised", dec.as_ref())] {
                let Some(set) = set else { continue };
                for j in 0..n {
                    for i in 0..n {
                        if (i != j) != off {
                            continue;
                        }
                        series.push(Series {
                            label: format!("{lab} {}←{}", name(j), name(i)),
                            x: f.clone(),
                            y: set
                                .iter()
                                .map(|(s, t)| {
                                    db(if pick == 0 {
                                        s[(j, i)].norm()
                                    } else {
                                        t[(j, i)].norm()
                                    })
                                })
                                .collect(),
                        });
                    }
                }
            }
            panels.push(Figure {
                title: format!("{title}: {}", if off { "off-diagonal" } else { "diagonal" }),
                x_label: "f (Hz)".into(),
                y_label: "dB".into(),
                y_unit: None,
                x_scale: Scale::Log,
                series,
            });
        }
        let p = out.join(file);
        draw_svg_panels(&panels, &p).map_err(|x| e(&p, x))?;
    }
    // Characteristic loci of GK.
    let l: Vec<CMatrix> = gf.iter().zip(&kf).map(|(a, b)| a * b).collect();
    let loci = nanomotion::core::analysis::characteristic_loci(&l).map_err(|x| x.to_string())?;
    let mut series: Vec<Series> = loci
        .iter()
        .enumerate()
        .map(|(i, lc)| {
            let keep: Vec<&Complex<f64>> = lc.iter().filter(|z| z.norm() < 5.0).collect();
            Series {
                label: format!("λ{}(GK)", i + 1),
                x: keep.iter().map(|z| z.re).collect(),
                y: keep.iter().map(|z| z.im).collect(),
            }
        })
        .collect();
    let circle: Vec<f64> = (0..=100).map(|i| TAU * i as f64 / 100.0).collect();
    series.push(Series {
        label: "unit circle".into(),
        x: circle.iter().map(|t| t.cos()).collect(),
        y: circle.iter().map(|t| t.sin()).collect(),
    });
    let p = out.join("characteristic_loci.svg");
    draw_svg(
        &Figure {
            title: "Characteristic loci λ(GK(j2πf)) near −1 (|λ| < 5)".into(),
            x_label: "Re".into(),
            y_label: "Im".into(),
            y_unit: None,
            x_scale: Scale::Linear,
            series,
        },
        &p,
    )
    .map_err(|x| e(&p, x))?;
    // (7.4).
    if !r.condition_7_4.is_empty() {
        let c = &r.condition_7_4;
        let p = out.join("mu_test.svg");
        draw_svg(
            &Figure {
                title: "(7.4): σ̄(T_d) < 1/μ(E); μ bracketed by D-scaling (upper) and ρ(EU) (lower)"
                    .into(),
                x_label: "f (Hz)".into(),
                y_label: "dB".into(),
                y_unit: None,
                x_scale: Scale::Log,
                series: vec![
                    Series {
                        label: "σ̄(T_d)".into(),
                        x: f.clone(),
                        y: c.iter().map(|q| db(q.sigma_td)).collect(),
                    },
                    Series {
                        label: "1/μ̄(E) (upper bound of μ)".into(),
                        x: f.clone(),
                        y: c.iter().map(|q| -db(q.mu.upper)).collect(),
                    },
                    Series {
                        label: "1/μ̲(E) (lower bound of μ)".into(),
                        x: f.clone(),
                        y: c.iter().map(|q| -db(q.mu.lower)).collect(),
                    },
                ],
            },
            &p,
        )
        .map_err(|x| e(&p, x))?;
    }
    // σ̄(N) with γ.
    let nn = synth::direct_n_on_grid(g, k, &cfg.weights, f).map_err(|x| x.to_string())?;
    let p = out.join("weighted_closed_loop.svg");
    draw_svg(
        &Figure {
            title: format!("σ̄(N(j2πf)) of (7.9) and γ = {:.4}", r.synthesis.gamma),
            x_label: "f (Hz)".into(),
            y_label: "dB".into(),
            y_unit: None,
            x_scale: Scale::Log,
            series: vec![
                Series {
                    label: "σ̄(N)".into(),
                    x: f.clone(),
                    y: nn.iter().map(|v| db(*v)).collect(),
                },
                Series {
                    label: "γ".into(),
                    x: f.clone(),
                    y: vec![db(r.synthesis.gamma); f.len()],
                },
            ],
        },
        &p,
    )
    .map_err(|x| e(&p, x))?;
    Ok(())
}
