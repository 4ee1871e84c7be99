//! Heat maps of scanned quantities over the scan plane (x, y → value), e.g. the
//! topography and the tracking error of an AFM raster scan (`nanomotion
//! scan-image`, Sec. 7.5). Samples are binned on a regular grid (mean per cell);
//! cells without samples stay blank.

use crate::plot::PlotError;
use plotters::prelude::*;
use std::path::Path;

/// A binned image: `values[row * nx + col]` is the mean of the samples in that cell
/// (NaN where none fell).
#[derive(Debug, Clone, PartialEq)]
pub struct Image {
    /// Columns (horizontal axis).
    pub nx: usize,
    /// Rows (vertical axis).
    pub ny: usize,
    /// Horizontal range (min, max).
    pub h_range: (f64, f64),
    /// Vertical range (min, max).
    pub v_range: (f64, f64),
    /// Cell means, row-major from the bottom row.
    pub values: Vec<f64>,
}

impl Image {
    /// Bin samples (h, v, value) on an `nx` × `ny` grid spanning their range.
    /// Non-finite samples are skipped. `None` if no finite sample or a flat range.
    pub fn bin(h: &[f64], v: &[f64], val: &[f64], nx: usize, ny: usize) -> Option<Self> {
        let ok = |i: usize| h[i].is_finite() && v[i].is_finite() && val[i].is_finite();
        let n = h.len().min(v.len()).min(val.len());
        let idx: Vec<usize> = (0..n).filter(|&i| ok(i)).collect();
        if idx.is_empty() || nx == 0 || ny == 0 {
            return None;
        }
        let range = |a: &[f64]| {
            idx.iter().fold((f64::MAX, f64::MIN), |(lo, hi), &i| {
                (lo.min(a[i]), hi.max(a[i]))
            })
        };
        let (hr, vr) = (range(h), range(v));
        if !(hr.1 > hr.0 && vr.1 > vr.0) {
            return None;
        }
        let mut sum = vec![0.0; nx * ny];
        let mut cnt = vec![0u32; nx * ny];
        for &i in &idx {
            let c = (((h[i] - hr.0) / (hr.1 - hr.0)) * nx as f64).min(nx as f64 - 1.0) as usize;
            let r = (((v[i] - vr.0) / (vr.1 - vr.0)) * ny as f64).min(ny as f64 - 1.0) as usize;
            sum[r * nx + c] += val[i];
            cnt[r * nx + c] += 1;
        }
        let values = sum
            .iter()
            .zip(&cnt)
            .map(|(s, &c)| if c > 0 { s / c as f64 } else { f64::NAN })
            .collect();
        Some(Self {
            nx,
            ny,
            h_range: hr,
            v_range: vr,
            values,
        })
    }

    /// (min, max) of the finite cell values.
    pub fn value_range(&self) -> (f64, f64) {
        self.values
            .iter()
            .filter(|v| v.is_finite())
            .fold((f64::MAX, f64::MIN), |(lo, hi), &v| (lo.min(v), hi.max(v)))
    }

    /// The `p`-th and (1 − `p`)-th quantiles of the finite cell values (the colour
    /// range: a few extreme cells, e.g. error spikes at edges, do not wash out the
    /// rest; cells beyond are drawn in the end colours).
    pub fn robust_range(&self, p: f64) -> (f64, f64) {
        let mut v: Vec<f64> = self
            .values
            .iter()
            .copied()
            .filter(|v| v.is_finite())
            .collect();
        if v.is_empty() {
            return (0.0, 1.0);
        }
        v.sort_by(f64::total_cmp);
        let q = |f: f64| v[((v.len() - 1) as f64 * f).round() as usize];
        (q(p), q(1.0 - p))
    }
}

/// Viridis-like colour map at t ∈ [0, 1] (five stops, linear in between).
pub fn colour(t: f64) -> RGBColor {
    const STOPS: [(f64, f64, f64); 5] = [
        (68.0, 1.0, 84.0),
        (59.0, 82.0, 139.0),
        (33.0, 145.0, 140.0),
        (94.0, 201.0, 98.0),
        (253.0, 231.0, 37.0),
    ];
    let t = if t.is_finite() {
        t.clamp(0.0, 1.0)
    } else {
        0.0
    } * 4.0;
    let i = (t.floor() as usize).min(3);
    let f = t - i as f64;
    let (a, b) = (STOPS[i], STOPS[i + 1]);
    let mix = |x: f64, y: f64| (x + (y - x) * f).round() as u8;
    RGBColor(mix(a.0, b.0), mix(a.1, b.1), mix(a.2, b.2))
}

/// Font size of axis and colour-bar labels in plotters' units (its SVG backend
/// writes font-size = size/1.24 px: 20 → 16.1 px, readable at the SVG's natural
/// size of 1000 × 520; plotters' default 12 gave 9.7 px).
pub const LABEL_SIZE: u32 = 20;

/// Decimals of the colour-bar tick labels for a value span: enough to tell about
/// five ticks apart (the first significant digit of a tick step ≈ span/5).
pub fn bar_decimals(span: f64) -> usize {
    if !(span.is_finite() && span > 0.0) {
        return 0;
    }
    (-(span / 5.0).log10().floor()).clamp(0.0, 12.0) as usize
}

/// A colour-bar tick label with `decimals` decimals, without a negative zero.
pub fn tick_label(v: f64, decimals: usize) -> String {
    let s = format!("{v:.decimals$}");
    if s.trim_start_matches('-')
        .chars()
        .all(|c| c == '0' || c == '.')
    {
        s.trim_start_matches('-').to_string()
    } else {
        s
    }
}

/// Draw `img` as an SVG heat map with a colour bar spanning the 1 %–99 % quantiles
/// of the cell values.
pub fn draw_heat_map(
    img: &Image,
    title: &str,
    h_label: &str,
    v_label: &str,
    value_label: &str,
    path: &Path,
) -> Result<(), PlotError> {
    let err = |e: &dyn std::fmt::Display| PlotError {
        path: path.display().to_string(),
        message: e.to_string(),
    };
    let root = SVGBackend::new(path, (1000, 520)).into_drawing_area();
    root.fill(&WHITE).map_err(|e| err(&e))?;
    let (main, bar) = root.split_horizontally(810);
    let (lo, hi) = img.robust_range(0.01);
    let span = if hi > lo { hi - lo } else { 1.0 };
    let mut chart = ChartBuilder::on(&main)
        .caption(title, ("sans-serif", 18))
        .margin(10)
        .x_label_area_size(50)
        .y_label_area_size(70)
        .build_cartesian_2d(img.h_range.0..img.h_range.1, img.v_range.0..img.v_range.1)
        .map_err(|e| err(&e))?;
    chart
        .configure_mesh()
        .disable_mesh()
        .x_desc(h_label)
        .y_desc(v_label)
        .label_style(("sans-serif", LABEL_SIZE))
        .axis_desc_style(("sans-serif", LABEL_SIZE))
        .draw()
        .map_err(|e| err(&e))?;
    let (dh, dv) = (
        (img.h_range.1 - img.h_range.0) / img.nx as f64,
        (img.v_range.1 - img.v_range.0) / img.ny as f64,
    );
    chart
        .draw_series((0..img.ny).flat_map(|r| {
            (0..img.nx).filter_map(move |c| {
                let v = img.values[r * img.nx + c];
                v.is_finite().then(|| {
                    let (h0, v0) = (img.h_range.0 + c as f64 * dh, img.v_range.0 + r as f64 * dv);
                    Rectangle::new(
                        [(h0, v0), (h0 + dh, v0 + dv)],
                        colour((v - lo) / span).filled(),
                    )
                })
            })
        }))
        .map_err(|e| err(&e))?;
    // Colour bar.
    let mut cb = ChartBuilder::on(&bar)
        .margin_top(40)
        .margin_bottom(60)
        .margin_right(10)
        .y_label_area_size(0)
        .right_y_label_area_size(90)
        .caption(value_label, ("sans-serif", LABEL_SIZE))
        .build_cartesian_2d(0.0..1.0, lo..lo + span)
        .map_err(|e| err(&e))?;
    let decimals = bar_decimals(span);
    cb.configure_mesh()
        .disable_mesh()
        .disable_x_axis()
        .y_labels(6)
        .y_label_style(("sans-serif", LABEL_SIZE))
        .y_label_formatter(&|v| tick_label(*v, decimals))
        .draw()
        .map_err(|e| err(&e))?;
    let steps = 64;
    cb.draw_series((0..steps).map(|i| {
        let a = lo + span * i as f64 / steps as f64;
        let b = lo + span * (i + 1) as f64 / steps as f64;
        Rectangle::new(
            [(0.0, a), (1.0, b)],
            colour((i as f64 + 0.5) / steps as f64).filled(),
        )
    }))
    .map_err(|e| err(&e))?;
    root.present().map_err(|e| err(&e))?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn binning_averages_per_cell() {
        // Four samples in a 2×2 grid; two fall in the same cell.
        let h = [0.0, 1.0, 0.1, 1.0];
        let v = [0.0, 0.0, 0.1, 1.0];
        let z = [1.0, 2.0, 3.0, 4.0];
        let img = Image::bin(&h, &v, &z, 2, 2).unwrap();
        assert_eq!(img.values[0], 2.0); // (0,0) and (0.1,0.1)
        assert_eq!(img.values[1], 2.0);
        assert!(img.values[2].is_nan());
        assert_eq!(img.values[3], 4.0);
        assert_eq!(img.value_range(), (2.0, 4.0));
        assert!(Image::bin(&[1.0], &[1.0], &[1.0], 2, 2).is_none());
        assert_eq!(img.robust_range(0.0), (2.0, 4.0));
    }

    #[test]
    fn colour_bar_labels_are_large_and_distinct() {
        assert_eq!(bar_decimals(20.0), 0); // step 4 → "−8", "−4", …
        assert_eq!(bar_decimals(2.0), 1); // step 0.4
        assert_eq!(bar_decimals(0.05), 2); // step 0.01
        assert_eq!(bar_decimals(f64::NAN), 0);
        assert_eq!(tick_label(-1e-17, 1), "0.0");
        assert_eq!(tick_label(-0.25, 1), "-0.2");
        let h: Vec<f64> = (0..400).map(|i| (i % 20) as f64).collect();
        let v: Vec<f64> = (0..400).map(|i| (i / 20) as f64).collect();
        let z: Vec<f64> = (0..400).map(|i| (i % 20) as f64 * 0.1 - 1.0).collect();
        let img = Image::bin(&h, &v, &z, 20, 20).unwrap();
        let path = std::env::temp_dir().join(format!("nm_heat_{}.svg", std::process::id()));
        draw_heat_map(&img, "t", "h", "v", "z (nm)", &path).unwrap();
        let svg = std::fs::read_to_string(&path).unwrap();
        let _ = std::fs::remove_file(&path);
        // The bar's caption and tick labels (range −1 … 0.9 at 1 %/99 %): one
        // decimal, at least 16 px.
        let labels: Vec<&str> = svg
            .split("<text")
            .skip(1)
            .filter(|t| {
                let size = t
                    .split("font-size=\"")
                    .nth(1)
                    .and_then(|r| r.split('"').next());
                size.and_then(|v| v.parse::<f64>().ok())
                    .is_some_and(|px| px >= 16.0)
            })
            .filter_map(|t| Some(t.split('>').nth(1)?.split('<').next()?.trim()))
            .collect();
        for want in ["z (nm)", "-0.5", "0.0", "0.5"] {
            assert!(labels.contains(&want), "{labels:?}");
        }
    }

    #[test]
    fn colour_map_ends() {
        assert_eq!(colour(0.0), RGBColor(68, 1, 84));
        assert_eq!(colour(1.0), RGBColor(253, 231, 37));
        assert_eq!(colour(f64::NAN), colour(0.0));
    }
}
