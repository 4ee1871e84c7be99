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

/// Most pixels along one side of an image: 2000.
pub const MAX_PIXELS_SIDE: usize = 2000;
/// Most pixels of an image (each is an SVG rectangle): 10⁶.
pub const MAX_PIXELS: usize = 1_000_000;

/// Check `--pixels` and `--from-s` before anything is read or allocated (audit
/// D19: `--pixels 100000 100000` aborted allocating 80 GB; `--from-s nan` was 0).
pub fn check_options(from_s: f64, pixels: (usize, usize)) -> Result<(), String> {
    let (nh, nv) = pixels;
    if !(1..=MAX_PIXELS_SIDE).contains(&nh)
        || !(1..=MAX_PIXELS_SIDE).contains(&nv)
        || nh * nv > MAX_PIXELS
    {
        return Err(format!(
            "--pixels {nh} {nv}: each side must be 1 to {MAX_PIXELS_SIDE} and the image at most {MAX_PIXELS} pixels (fix: lower --pixels, e.g. the default 200 40)"
        ));
    }
    if !from_s.is_finite() {
        return Err(format!(
            "--from-s {from_s}: not a finite time (fix: give seconds from the run's start, e.g. --from-s 0.5)"
        ));
    }
    Ok(())
}

/// A column of a run's CSV: `name` as logged, with its unit if the header
/// carries one (`stage.y (m)`).
fn matches_column(header: &str, name: &str) -> Option<Option<String>> {
    if header == name {
        return Some(None);
    }
    let unit = header
        .strip_prefix(name)?
        .strip_prefix(" (")?
        .strip_suffix(')')?;
    Some(Some(unit.to_string()))
}

/// The CSV files of a run folder: `signals.csv` (one rate) or one
/// `signals_<rate>hz.csv` per rate (a multi-rate run), with their headers.
fn run_csvs(run_dir: &Path) -> Result<Vec<(PathBuf, Vec<String>)>, String> {
    let mut paths = vec![run_dir.join("signals.csv")];
    if !paths[0].is_file() {
        let entries = std::fs::read_dir(run_dir).map_err(|e| {
            format!(
                "{}: {e} (fix: give the folder of a `nanomotion run`)",
                run_dir.display()
            )
        })?;
        paths = entries
            .filter_map(Result::ok)
            .map(|e| e.path())
            .filter(|p| {
                p.file_name()
                    .and_then(|n| n.to_str())
                    .is_some_and(|n| n.starts_with("signals_") && n.ends_with("hz.csv"))
            })
            .collect();
        paths.sort();
    }
    if paths.is_empty() {
        return Err(format!(
            "{}: no signals.csv or signals_<rate>hz.csv (fix: give the folder of a `nanomotion run` that wrote files)",
            run_dir.display()
        ));
    }
    paths
        .into_iter()
        .map(|p| {
            let mut rdr =
                csv::Reader::from_path(&p).map_err(|e| format!("{}: {e}", p.display()))?;
            let header = rdr
                .headers()
                .map_err(|e| format!("{}: {e}", p.display()))?
                .iter()
                .map(str::to_string)
                .collect();
            Ok((p, header))
        })
        .collect()
}

/// One axis of an image: its column in the CSV, unit, scale and label.
struct Axis {
    column: usize,
    scale: f64,
    unit: String,
}

impl Axis {
    /// Metres (or no unit: a position in m, as the scan blocks log) are shown
    /// in `metre_unit` (µm for positions, nm for values); any other unit as is.
    fn new(column: usize, unit: Option<String>, metre_unit: &str, metre_scale: f64) -> Self {
        match unit.as_deref() {
            None | Some("m") => Self {
                column,
                scale: metre_scale,
                unit: metre_unit.to_string(),
            },
            Some(u) => Self {
                column,
                scale: 1.0,
                unit: u.to_string(),
            },
        }
    }
}

/// Write one SVG per spec into `run_dir` (samples with t ≥ `from_s`; values shown
/// relative to their mean, in nm when they are in metres, positions in µm). The
/// three columns of an image must be in one CSV file (logged at one rate); names
/// may be given with or without their unit (`stage.y` or `stage.y (m)`).
pub fn run(
    run_dir: &Path,
    specs: &[ImageSpec],
    from_s: f64,
    pixels: (usize, usize),
) -> Result<(), String> {
    if specs.is_empty() {
        return Err("no --image given (fix: e.g. --image topo=drc_stage.pos[1],drc_stage.pos[0],-drc_stage.pos[2])".into());
    }
    check_options(from_s, pixels)?;
    let files = run_csvs(run_dir)?;
    // The images appear in the run folder only when all are drawn.
    let folder = nanomotion::output::OutputFolder::add_to(run_dir).map_err(|e| e.to_string())?;
    for s in specs {
        // The file holding all three columns.
        let find = |name: &str| -> Vec<(usize, usize, Option<String>)> {
            files
                .iter()
                .enumerate()
                .flat_map(|(f, (_, header))| {
                    header
                        .iter()
                        .enumerate()
                        .filter_map(move |(j, h)| matches_column(h, name).map(|u| (f, j, u)))
                })
                .collect()
        };
        let (hs, vs, zs) = (find(&s.h), find(&s.v), find(&s.value));
        for (name, found) in [(&s.h, &hs), (&s.v, &vs), (&s.value, &zs)] {
            if found.is_empty() {
                let all: Vec<String> = files
                    .iter()
                    .map(|(p, h)| format!("{}: {}", p.display(), h.join(", ")))
                    .collect();
                return Err(format!(
                    "image `{}`: no column `{name}` (columns: {}); log the signal in the graph's `log:`",
                    s.name,
                    all.join("; ")
                ));
            }
        }
        let Some(&(f, hj, ref hu)) = hs
            .iter()
            .find(|(f, ..)| vs.iter().any(|v| v.0 == *f) && zs.iter().any(|z| z.0 == *f))
        else {
            return Err(format!(
                "image `{}`: `{}`, `{}` and `{}` are logged at different rates ({}, {}, {}) (fix: log the three from blocks of one rate)",
                s.name,
                s.h,
                s.v,
                s.value,
                files[hs[0].0].0.display(),
                files[vs[0].0].0.display(),
                files[zs[0].0].0.display()
            ));
        };
        let (_, vj, vu) = vs.iter().find(|v| v.0 == f).cloned().expect("checked");
        let (_, zj, zu) = zs.iter().find(|z| z.0 == f).cloned().expect("checked");
        let (path, header) = &files[f];
        let h = Axis::new(hj, hu.clone(), "µm", 1e6);
        let v = Axis::new(vj, vu, "µm", 1e6);
        let z = Axis::new(zj, zu, "nm", 1e9);
        draw_one(
            run_dir,
            folder.dir(),
            s,
            path,
            header,
            [&h, &v, &z],
            from_s,
            pixels,
        )?;
    }
    folder.commit(None).map_err(|e| e.to_string())?;
    Ok(())
}

/// Read the three columns of one image from `csv_path` and draw it.
#[allow(clippy::too_many_arguments)]
fn draw_one(
    run_dir: &Path,
    out_dir: &Path,
    s: &ImageSpec,
    csv_path: &Path,
    header: &[String],
    [h, v, z]: [&Axis; 3],
    from_s: f64,
    pixels: (usize, usize),
) -> Result<(), String> {
    let mut rdr = csv::Reader::from_path(csv_path).map_err(|e| {
        format!(
            "{}: {e} (fix: give the folder of a `nanomotion run`)",
            csv_path.display()
        )
    })?;
    let t_col = header
        .iter()
        .position(|c| c == "t_s")
        .ok_or_else(|| format!("{}: no column `t_s`", csv_path.display()))?;
    let mut d: [Vec<f64>; 3] = Default::default();
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
        for (out, a) in d.iter_mut().zip([h, v, z]) {
            out.push(num(a.column)? * a.scale);
        }
    }
    let n = d[2].len().max(1) as f64;
    let mean = d[2].iter().sum::<f64>() / n;
    let sign = if s.negate { -1.0 } else { 1.0 };
    let vals: Vec<f64> = d[2].iter().map(|x| sign * (x - mean)).collect();
    let rms = (vals.iter().map(|v| v * v).sum::<f64>() / n).sqrt();
    let img = Image::bin(&d[0], &d[1], &vals, pixels.0, pixels.1).ok_or_else(|| {
        format!(
            "image `{}`: no finite samples spanning a range after t = {from_s} s",
            s.name
        )
    })?;
    let path = out_dir.join(format!("{}.svg", s.name));
    let unit = &z.unit;
    draw_heat_map(
        &img,
        &format!(
            "{}: {}{} over ({}, {}), rms {rms:.3} {unit}",
            s.name,
            if s.negate { "−" } else { "" },
            s.value,
            s.h,
            s.v
        ),
        &format!("{} ({})", s.h, h.unit),
        &format!("{} ({})", s.v, v.unit),
        &format!("{unit} (mean removed)"),
        &path,
    )
    .map_err(|e| e.to_string())?;
    say!(
        "wrote {} ({} samples, rms {rms:.3} {unit})",
        run_dir.join(format!("{}.svg", s.name)).display(),
        d[2].len()
    );
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Audit D20: a column had to be typed with its unit (`"mode.y (m)"`), and a
    /// value in volts was labelled (and scaled) as nm.
    #[test]
    fn columns_match_without_their_unit_and_keep_it() {
        assert_eq!(
            matches_column("mode.y (m)", "mode.y"),
            Some(Some("m".into()))
        );
        assert_eq!(matches_column("mode.y (m)", "mode.y (m)"), Some(None));
        assert_eq!(matches_column("mode.y", "mode.y"), Some(None));
        assert_eq!(matches_column("mode.yy (m)", "mode.y"), None);
        assert_eq!(
            matches_column("pos[1] (m)", "pos[1]"),
            Some(Some("m".into()))
        );
        let volts = Axis::new(3, Some("V".into()), "nm", 1e9);
        assert_eq!((volts.scale, volts.unit.as_str()), (1.0, "V"));
        let metres = Axis::new(3, Some("m".into()), "nm", 1e9);
        assert_eq!((metres.scale, metres.unit.as_str()), (1e9, "nm"));
    }

    /// Audit D19: `--pixels 100000 100000` aborted allocating 80 GB.
    #[test]
    fn pixels_and_start_time_are_bounded() {
        assert!(check_options(0.0, (200, 40)).is_ok());
        assert!(check_options(0.0, (MAX_PIXELS_SIDE, MAX_PIXELS / MAX_PIXELS_SIDE)).is_ok());
        assert!(check_options(0.0, (100_000, 100_000)).is_err());
        assert!(check_options(0.0, (MAX_PIXELS_SIDE, MAX_PIXELS_SIDE)).is_err());
        assert!(check_options(0.0, (0, 40)).is_err());
        assert!(check_options(f64::NAN, (200, 40)).is_err());
    }
}
