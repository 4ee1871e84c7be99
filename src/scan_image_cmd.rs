//! `nanomotion scan-image RUN_DIR --image NAME=H,V,VALUE ...`: heat maps of logged
//! signals over the scan plane (e.g. topography and tracking error of an AFM raster
//! scan, Sec. 7.5) from a run folder's `signals.csv`.

use nanomotion::image_plot::{Image, draw_heat_map};
use std::path::{Path, PathBuf};

/// One requested image.
#[derive(Debug, Clone)]
pub struct ImageSpec {
    name: String,
    h: String,
    v: String,
    value: String,
    negate: bool,
}

/// Parse `NAME=H,V,VALUE` (VALUE may start with `-` to flip the sign, e.g. the
/// topography h = −z of a constant-force scan).
pub fn parse_spec(s: &str) -> Result<ImageSpec, String> {
    let fix = "write NAME=H_COLUMN,V_COLUMN,VALUE_COLUMN, e.g. topo=drc_stage.pos[1],drc_stage.pos[0],-drc_stage.pos[2]";
    let (name, cols) = s
        .split_once('=')
        .ok_or_else(|| format!("--image `{s}`: no `=` ({fix})"))?;
    let c: Vec<&str> = cols.split(',').map(str::trim).collect();
    if name.is_empty()
        || !name
            .chars()
            .all(|ch| ch.is_ascii_alphanumeric() || ch == '_' || ch == '-')
    {
        return Err(format!(
            "--image `{s}`: the name must be letters, digits, `_` or `-` ({fix})"
        ));
    }
    if c.len() != 3 || c.iter().any(|x| x.is_empty()) {
        return Err(format!("--image `{s}`: give three columns ({fix})"));
    }
    let (negate, value) = match c[2].strip_prefix('-') {
        Some(v) => (true, v.to_string()),
        None => (false, c[2].to_string()),
    };
    Ok(ImageSpec {
        name: name.to_string(),
        h: c[0].to_string(),
        v: c[1].to_string(),
        value,
        negate,
    })
}

/// Write one SVG per spec into `run_dir` (samples with t ≥ `from_s`; values shown in
/// nm relative to their mean, positions in µm).
pub fn run(
    run_dir: &Path,
    specs: &[ImageSpec],
    from_s: f64,
    pixels: (usize, usize),
) -> Result<(), String> {
    if specs.is_empty() {
        return Err("no --image given (fix: e.g. --image topo=drc_stage.pos[1],drc_stage.pos[0],-drc_stage.pos[2])".into());
    }
    let csv_path: PathBuf = run_dir.join("signals.csv");
    let mut rdr = csv::Reader::from_path(&csv_path).map_err(|e| {
        format!(
            "{}: {e} (fix: give the folder of a `nanomotion run`)",
            csv_path.display()
        )
    })?;
    let header: Vec<String> = rdr
        .headers()
        .map_err(|e| format!("{}: {e}", csv_path.display()))?
        .iter()
        .map(str::to_string)
        .collect();
    let col = |name: &str| {
        header.iter().position(|h| h == name).ok_or_else(|| {
            format!(
                "{}: no column `{name}` (columns: {}); log the signal in the graph's `log:`",
                csv_path.display(),
                header.join(", ")
            )
        })
    };
    let t_col = col("t_s")?;
    let mut cols = Vec::new();
    for s in specs {
        cols.push((col(&s.h)?, col(&s.v)?, col(&s.value)?));
    }
    let mut data: Vec<[Vec<f64>; 3]> = vec![Default::default(); specs.len()];
    for (line, rec) in rdr.records().enumerate() {
        let rec = rec.map_err(|e| format!("{}: {e}", csv_path.display()))?;
        let num = |j: usize| -> Result<f64, String> {
            rec.get(j)
                .and_then(|v| v.parse::<f64>().ok())
                .ok_or_else(|| {
                    format!(
                        "{}: row {}: column {} is not a number",
                        csv_path.display(),
                        line + 2,
                        header[j]
                    )
                })
        };
        if num(t_col)? < from_s {
            continue;
        }
        for (d, &(h, v, z)) in data.iter_mut().zip(&cols) {
            d[0].push(num(h)? * 1e6);
            d[1].push(num(v)? * 1e6);
            d[2].push(num(z)?);
        }
    }
    // The images appear in the run folder only when all are drawn.
    let folder = nanomotion::output::OutputFolder::add_to(run_dir).map_err(|e| e.to_string())?;
    for (s, d) in specs.iter().zip(&mut data) {
        let n = d[2].len().max(1) as f64;
        let mean = d[2].iter().sum::<f64>() / n;
        let sign = if s.negate { -1.0 } else { 1.0 };
        let vals: Vec<f64> = d[2].iter().map(|z| sign * (z - mean) * 1e9).collect();
        let rms = (vals.iter().map(|v| v * v).sum::<f64>() / n).sqrt();
        let img = Image::bin(&d[0], &d[1], &vals, pixels.0, pixels.1).ok_or_else(|| {
            format!(
                "image `{}`: no finite samples spanning a range after t = {from_s} s",
                s.name
            )
        })?;
        let path = folder.dir().join(format!("{}.svg", s.name));
        draw_heat_map(
            &img,
            &format!(
                "{}: {}{} over ({}, {}), rms {rms:.3} nm",
                s.name,
                if s.negate { "−" } else { "" },
                s.value,
                s.h,
                s.v
            ),
            &format!("{} (µm)", s.h),
            &format!("{} (µm)", s.v),
            "nm (mean removed)",
            &path,
        )
        .map_err(|e| e.to_string())?;
        say!(
            "wrote {} ({} samples, rms {rms:.3} nm)",
            run_dir.join(format!("{}.svg", s.name)).display(),
            d[2].len()
        );
    }
    folder.commit(None).map_err(|e| e.to_string())?;
    Ok(())
}
