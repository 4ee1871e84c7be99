//! SVG plots (plotters' SVG backend: no fonts or system libraries needed).

use plotters::prelude::*;
use std::path::Path;

/// One curve of a plot.
#[derive(Debug, Clone)]
pub struct Series {
    /// Legend label.
    pub label: String,
    /// Abscissa.
    pub x: Vec<f64>,
    /// Ordinate.
    pub y: Vec<f64>,
}

/// Axis scaling.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Scale {
    /// Linear axis.
    Linear,
    /// Logarithmic axis (non-positive values are dropped).
    Log,
}

/// A plot to draw.
#[derive(Debug, Clone)]
pub struct Figure {
    /// Title on top.
    pub title: String,
    /// Label of the x axis, with unit.
    pub x_label: String,
    /// Label of the y axis (without the unit when `y_unit` is given).
    pub y_label: String,
    /// Unit of the y values (SI, e.g. `m`): the axis is then drawn in an
    /// engineering prefix of it (`nm`, `µm/s`) instead of a `×1e-9` factor.
    pub y_unit: Option<String>,
    /// Scaling of the x axis.
    pub x_scale: Scale,
    /// The curves.
    pub series: Vec<Series>,
}

/// Errors while drawing.
#[derive(Debug, thiserror::Error)]
#[error("cannot draw `{path}`: {message}")]
pub struct PlotError {
    /// File being written.
    pub path: String,
    /// What went wrong.
    pub message: String,
}

/// Keep at most about `2·buckets` points, preserving each bucket's minimum and
/// maximum so that peaks stay visible (an SVG of a million points is useless).
pub fn decimate_min_max(x: &[f64], y: &[f64], buckets: usize) -> (Vec<f64>, Vec<f64>) {
    let n = x.len().min(y.len());
    if n <= 2 * buckets || buckets == 0 {
        return (x[..n].to_vec(), y[..n].to_vec());
    }
    let mut xo = Vec::with_capacity(2 * buckets + 2);
    let mut yo = Vec::with_capacity(2 * buckets + 2);
    for b in 0..buckets {
        let lo = b * n / buckets;
        let hi = ((b + 1) * n / buckets).max(lo + 1);
        let (mut imin, mut imax) = (lo, lo);
        for i in lo..hi {
            if y[i] < y[imin] {
                imin = i;
            }
            if y[i] > y[imax] {
                imax = i;
            }
        }
        let (a, c) = if imin <= imax {
            (imin, imax)
        } else {
            (imax, imin)
        };
        xo.push(x[a]);
        yo.push(y[a]);
        if c != a {
            xo.push(x[c]);
            yo.push(y[c]);
        }
    }
    (xo, yo)
}

/// SI prefix of 10^exponent (exponent a multiple of 3 in [−18, 18]).
fn si_prefix(exponent: i32) -> Option<&'static str> {
    Some(match exponent {
        -18 => "a",
        -15 => "f",
        -12 => "p",
        -9 => "n",
        -6 => "µ",
        -3 => "m",
        0 => "",
        3 => "k",
        6 => "M",
        9 => "G",
        12 => "T",
        _ => return None,
    })
}

/// The y-axis label for values divided by 10^exponent: `label (nm)` when the
/// unit takes a prefix (a plain unit such as `m`, `m/s`, `V`, `Hz`, `N`),
/// else `label (×1e-9 unit)`.
pub fn axis_label(label: &str, unit: Option<&str>, exponent: i32) -> String {
    let prefixable = |u: &str| {
        !u.is_empty()
            && u.chars().next().is_some_and(|c| c.is_alphabetic())
            && !u.contains(['²', '³', '^', ' ', '·', '*'])
            && !matches!(u, "count" | "counts" | "%" | "-" | "1" | "kg" | "dB")
    };
    match (unit, si_prefix(exponent)) {
        (Some(u), _) if exponent == 0 => format!("{label} ({u})"),
        (Some(u), Some(p)) if prefixable(u) => format!("{label} ({p}{u})"),
        (Some(u), _) => format!("{label} (×1e{exponent} {u})"),
        (None, _) if exponent == 0 => label.to_string(),
        (None, _) => format!("{label} (×1e{exponent})"),
    }
}

const COLORS: [RGBColor; 6] = [
    RGBColor(31, 119, 180),
    RGBColor(214, 39, 40),
    RGBColor(44, 160, 44),
    RGBColor(255, 127, 14),
    RGBColor(148, 103, 189),
    RGBColor(23, 190, 207),
];

/// Draw `fig` into an SVG file at `path` (800 × 450 px).
pub fn draw_svg(fig: &Figure, path: &Path) -> Result<(), PlotError> {
    draw_svg_panels(std::slice::from_ref(fig), path)
}

/// Draw `figs` stacked top to bottom into one SVG file at `path` (800 px wide,
/// 450 px for one panel, 320 px per panel for several).
pub fn draw_svg_panels(figs: &[Figure], path: &Path) -> Result<(), PlotError> {
    let err = |m: String| PlotError {
        path: path.display().to_string(),
        message: m,
    };
    let height = if figs.len() <= 1 {
        450
    } else {
        320 * figs.len() as u32
    };
    let root = SVGBackend::new(path, (800, height)).into_drawing_area();
    root.fill(&WHITE).map_err(|e| err(e.to_string()))?;
    let areas = root.split_evenly((figs.len().max(1), 1));
    for (fig, area) in figs.iter().zip(&areas) {
        draw_on(fig, area, path)?;
    }
    root.present().map_err(|e| err(e.to_string()))?;
    Ok(())
}

/// The data rectangle `(x_min, x_max, y_min, y_max)` of labelled point series, or
/// `None` when there is no finite point.
pub fn data_bounds(series: &[(String, Vec<(f64, f64)>)]) -> Option<(f64, f64, f64, f64)> {
    let (mut x0, mut x1, mut y0, mut y1) = (
        f64::INFINITY,
        f64::NEG_INFINITY,
        f64::INFINITY,
        f64::NEG_INFINITY,
    );
    for &(x, y) in series.iter().flat_map(|(_, p)| p.iter()) {
        x0 = x0.min(x);
        x1 = x1.max(x);
        y0 = y0.min(y);
        y1 = y1.max(y);
    }
    (x0.is_finite() && y0.is_finite()).then_some((x0, x1, y0, y1))
}

/// Draw `fig` on one drawing area of an SVG being written to `path`.
fn draw_on(
    fig: &Figure,
    root: &DrawingArea<SVGBackend<'_>, plotters::coord::Shift>,
    path: &Path,
) -> Result<(), PlotError> {
    let err = |m: String| PlotError {
        path: path.display().to_string(),
        message: m,
    };
    let keep = |v: f64, scale: Scale| v.is_finite() && (scale == Scale::Linear || v > 0.0);
    let series: Vec<(String, Vec<(f64, f64)>)> = fig
        .series
        .iter()
        .map(|s| {
            let (x, y) = decimate_min_max(&s.x, &s.y, 1500);
            let pts = x
                .into_iter()
                .zip(y)
                .filter(|&(a, b)| keep(a, fig.x_scale) && b.is_finite())
                .collect();
            (s.label.clone(), pts)
        })
        .collect();
    // Plot tiny quantities (m², nm) in engineering units so the axis gets ticks:
    // y is divided by 10^e (e a multiple of 3) and the label says so.
    let y_max = series
        .iter()
        .flat_map(|(_, p)| p.iter())
        .fold(0.0f64, |m, &(_, y)| m.max(y.abs()));
    let exponent = if y_max > 0.0 && y_max.is_finite() {
        (y_max.log10() / 3.0).floor() as i32 * 3
    } else {
        0
    };
    let scale = 10f64.powi(-exponent);
    let series: Vec<(String, Vec<(f64, f64)>)> = series
        .into_iter()
        .map(|(l, p)| (l, p.into_iter().map(|(x, y)| (x, y * scale)).collect()))
        .collect();
    let y_label = axis_label(&fig.y_label, fig.y_unit.as_deref(), exponent);
    // A logarithmic y axis where positive data spans more than two decades
    // (spectra, cumulative PSDs on a log frequency axis).
    let y_log = fig.x_scale == Scale::Log && {
        let ys = series.iter().flat_map(|(_, p)| p.iter().map(|&(_, y)| y));
        let (lo, hi, all_pos) = ys.fold((f64::INFINITY, 0.0f64, true), |(lo, hi, ok), y| {
            (lo.min(y), hi.max(y), ok && y > 0.0)
        });
        all_pos && hi > 0.0 && hi / lo > 100.0
    };
    let Some((x0, mut x1, y0, y1)) = data_bounds(&series) else {
        return Err(err("nothing finite to plot".into()));
    };
    if x1 <= x0 {
        x1 = x0 + if fig.x_scale == Scale::Log { x0 } else { 1.0 };
    }
    let pad = if y1 > y0 {
        0.05 * (y1 - y0)
    } else {
        y0.abs().max(1e-12) * 0.1
    };
    let (y0, y1) = if y_log {
        (y0 / 1.2, y1 * 1.2)
    } else {
        (y0 - pad, y1 + pad)
    };

    macro_rules! body {
        ($chart:expr) => {{
            let mut chart = $chart;
            chart
                .configure_mesh()
                .x_desc(fig.x_label.as_str())
                .y_desc(y_label.as_str())
                .y_label_formatter(&|v| {
                    if y_log {
                        format!("{v:.2e}")
                    } else {
                        format!("{v:.3}")
                    }
                })
                .draw()
                .map_err(|e| err(e.to_string()))?;
            for (i, (label, pts)) in series.iter().enumerate() {
                let color = COLORS[i % COLORS.len()];
                chart
                    .draw_series(LineSeries::new(pts.iter().copied(), color.stroke_width(1)))
                    .map_err(|e| err(e.to_string()))?
                    .label(label.as_str())
                    .legend(move |(x, y)| {
                        PathElement::new(vec![(x, y), (x + 16, y)], color.stroke_width(2))
                    });
            }
            if !series.is_empty() {
                chart
                    .configure_series_labels()
                    .position(if fig.x_scale == Scale::Log {
                        SeriesLabelPosition::UpperLeft
                    } else {
                        SeriesLabelPosition::UpperRight
                    })
                    .background_style(WHITE.mix(0.8))
                    .border_style(BLACK)
                    .draw()
                    .map_err(|e| err(e.to_string()))?;
            }
        }};
    }
    let mut builder = ChartBuilder::on(root);
    builder
        .caption(fig.title.as_str(), ("sans-serif", 18))
        .margin(12)
        .x_label_area_size(40)
        .y_label_area_size(80);
    match (fig.x_scale, y_log) {
        (Scale::Linear, _) => body!(
            builder
                .build_cartesian_2d(x0..x1, y0..y1)
                .map_err(|e| err(e.to_string()))?
        ),
        (Scale::Log, false) => body!(
            builder
                .build_cartesian_2d((x0..x1).log_scale(), y0..y1)
                .map_err(|e| err(e.to_string()))?
        ),
        (Scale::Log, true) => body!(
            builder
                .build_cartesian_2d((x0..x1).log_scale(), (y0..y1).log_scale())
                .map_err(|e| err(e.to_string()))?
        ),
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn decimation_keeps_extremes() {
        let x: Vec<f64> = (0..100_000).map(|i| i as f64).collect();
        let mut y = vec![0.0; 100_000];
        y[54_321] = 7.0;
        y[99] = -3.0;
        let (xd, yd) = decimate_min_max(&x, &y, 100);
        assert!(xd.len() <= 200);
        assert!(yd.contains(&7.0) && yd.contains(&-3.0));
        assert!(xd.windows(2).all(|w| w[0] < w[1]), "x stays sorted");
    }

    #[test]
    fn axes_use_engineering_prefixes_of_the_unit() {
        assert_eq!(axis_label("stage.y", Some("m"), -9), "stage.y (nm)");
        assert_eq!(axis_label("v", Some("m/s"), -6), "v (µm/s)");
        assert_eq!(axis_label("f", Some("Hz"), 3), "f (kHz)");
        assert_eq!(axis_label("y", Some("m"), 0), "y (m)");
        // Powers and counts take no prefix (n(m²) is not (nm)²).
        assert_eq!(axis_label("p", Some("m²"), -18), "p (×1e-18 m²)");
        assert_eq!(axis_label("c", Some("count"), 3), "c (×1e3 count)");
        assert_eq!(axis_label("e", None, -9), "e (×1e-9)");
    }

    #[test]
    fn svg_is_written() {
        let dir = std::env::temp_dir().join(format!("nm-plot-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let p = dir.join("a.svg");
        let fig = Figure {
            title: "t".into(),
            x_label: "time (s)".into(),
            y_label: "y".into(),
            y_unit: Some("m".into()),
            x_scale: Scale::Log,
            series: vec![Series {
                label: "s".into(),
                x: vec![0.0, 1.0, 10.0],
                y: vec![1.0, 2.0, 3.0],
            }],
        };
        draw_svg(&fig, &p).unwrap();
        let text = std::fs::read_to_string(&p).unwrap();
        assert!(text.starts_with("<svg") && text.contains("<polyline"));
        std::fs::remove_dir_all(dir).ok();
    }
}
