//! Measured records from outside the project put in the shape `diagnose` reads
//! (one time base, named columns in SI units), by the conditioning their own
//! authors describe — nothing fitted, nothing tuned.
//!
//! - [`rack_pinion`]: the rack-and-pinion axis of Mnich's friction rig
//!   (`../shared/data/friction_rack_pinion`, from KonradMnich/friction-identification):
//!   a load cell's force at 2 kHz and the servo drive's speed log at 1.5 kHz,
//!   two loggers joined on one clock.

use nanomotion_core::data::{DataError, Dataset};
use std::path::Path;

/// The load cell's coefficient (N/V) and the sign that makes a push along the
/// motion positive (the dataset's `acquisition.m`).
const LOAD_CELL_N_PER_V: f64 = -200.0;
/// The drive's speed log in rpm to the rack's velocity in m/s, sign included
/// (the pinion moves 20 mm a turn; `acquisition.m`).
const M_PER_S_PER_RPM: f64 = -20.0 / 1000.0 / 60.0;
/// The load cell's logger lags the drive's by 4 ms (`conditioning.m`'s
/// `time_shift`): its times are moved forward by this much.
const LOAD_CELL_LAG_S: f64 = 0.004;
/// The load cell is tared on its first samples, taken at rest.
const TARE_SAMPLES: usize = 10;

/// The rack-and-pinion record of `dir` (`a3NI.csv`: load cell and drive input
/// at 2 kHz; `a3MR.csv`: the servo drive's speed log) joined as the dataset's
/// author joins them: the load cell tared on its first samples and scaled to
/// newtons, the speed scaled to m/s, the 4 ms between the loggers taken out,
/// the speed interpolated linearly onto the load cell's 2 kHz grid where both
/// loggers ran. Columns: `force_n` (the force that pushes the rack), `velocity_m_s`
/// and `position_m` (the velocity integrated by the trapezoidal rule from 0 at
/// the first sample), at 2 kHz from t = 0. No filtering: `diagnose` weighs the
/// noise itself.
///
/// # Errors
/// A missing or unreadable file, a malformed header or row, a non-finite value,
/// a time column that does not increase, or loggers that never overlap — each
/// naming the file, the row and the fix.
pub fn rack_pinion(dir: &Path) -> Result<Dataset, DataError> {
    let ni_path = dir.join("a3NI.csv");
    let mr_path = dir.join("a3MR.csv");
    let ni = read_rows(&ni_path, 4, 4)?;
    let mr = read_rows(&mr_path, 5, 2)?;
    let ni_origin = ni_path.display().to_string();
    let mr_origin = mr_path.display().to_string();
    if ni.len() < 2 * TARE_SAMPLES {
        return Err(DataError::new(
            &ni_origin,
            format!("has {} rows", ni.len()),
            format!(
                "give at least {} samples (the first {TARE_SAMPLES} tare the load cell)",
                2 * TARE_SAMPLES
            ),
        ));
    }
    let (t_ni, volts): (Vec<f64>, Vec<f64>) =
        ni.iter().map(|r| (r[0] + LOAD_CELL_LAG_S, r[1])).unzip();
    // The drive logs its time in milliseconds.
    let (t_mr, rpm): (Vec<f64>, Vec<f64>) = mr.iter().map(|r| (r[0] / 1000.0, r[1])).unzip();
    increasing(&t_ni, &ni_origin, 4)?;
    increasing(&t_mr, &mr_origin, 5)?;
    // The mean step of the logged times (the times carry the shift, not the step).
    let dt = (ni[ni.len() - 1][0] - ni[0][0]) / (ni.len() - 1) as f64;
    if let Some(k) = t_ni
        .windows(2)
        .position(|w| ((w[1] - w[0]) - dt).abs() > 0.01 * dt)
    {
        return Err(DataError::new(
            &ni_origin,
            format!(
                "the step {} s differs from the first, {dt} s",
                t_ni[k + 1] - t_ni[k]
            ),
            "give the load cell's record as logged, uniformly sampled",
        )
        .at_row(4 + k + 2));
    }
    let tare = volts[..TARE_SAMPLES].iter().sum::<f64>() / TARE_SAMPLES as f64;
    let mut force = Vec::new();
    let mut velocity = Vec::new();
    let mut j = 0;
    for (&t, &v) in t_ni.iter().zip(&volts) {
        if t < t_mr[0] || t > t_mr[t_mr.len() - 1] {
            continue;
        }
        while t_mr[j + 1] < t {
            j += 1;
        }
        let w = (t - t_mr[j]) / (t_mr[j + 1] - t_mr[j]);
        force.push(LOAD_CELL_N_PER_V * (v - tare));
        velocity.push(M_PER_S_PER_RPM * ((1.0 - w) * rpm[j] + w * rpm[j + 1]));
    }
    if force.len() < 2 {
        return Err(DataError::new(
            format!("{ni_origin} and {mr_origin}"),
            "the two loggers' times do not overlap",
            "give the two files of one run",
        ));
    }
    let mut position = Vec::with_capacity(velocity.len());
    let mut x = 0.0;
    for (k, v) in velocity.iter().enumerate() {
        if k > 0 {
            x += 0.5 * (velocity[k - 1] + v) * dt;
        }
        position.push(x);
    }
    Dataset::from_columns(
        format!("{} joined with {}", ni_origin, mr_origin),
        1.0 / dt,
        0.0,
        vec![
            ("force_n".into(), force),
            ("velocity_m_s".into(), velocity),
            ("position_m".into(), position),
        ],
    )
}

/// The numeric rows of a logger's CSV after `header` lines, each with at least
/// `width` leading numbers (a byte-order mark and trailing columns allowed).
fn read_rows(path: &Path, header: usize, width: usize) -> Result<Vec<Vec<f64>>, DataError> {
    let origin = path.display().to_string();
    let text = nanomotion_core::data::read_text_capped_data(path).map_err(|e| {
        DataError::new(
            &origin,
            format!("cannot be read: {e}"),
            "check the path (the dataset is in ../shared/data/friction_rack_pinion)",
        )
    })?;
    let mut rows = Vec::new();
    for (i, line) in text.lines().enumerate().skip(header) {
        if line.trim().is_empty() {
            continue;
        }
        let row: Result<Vec<f64>, _> = line
            .split(',')
            .take(width)
            .map(|f| f.trim().parse::<f64>())
            .collect();
        match row {
            Ok(r) if r.len() == width && r.iter().all(|v| v.is_finite()) => rows.push(r),
            _ => {
                return Err(DataError::new(
                    &origin,
                    format!(
                        "is not {width} finite numbers: `{}`",
                        line.chars().take(80).collect::<String>()
                    ),
                    format!(
                        "give the logger's file as exported ({header} header lines, then numbers)"
                    ),
                )
                .at_row(i + 1));
            }
        }
    }
    if rows.len() < 2 {
        return Err(DataError::new(
            &origin,
            "has fewer than two samples",
            "give the logger's whole file",
        ));
    }
    Ok(rows)
}

/// Times must increase from row to row (`first_row`: the file's line of the first).
fn increasing(t: &[f64], origin: &str, first_row: usize) -> Result<(), DataError> {
    match t.windows(2).position(|w| w[1] <= w[0]) {
        Some(k) => Err(DataError::new(
            origin,
            format!("time {} s does not follow {} s", t[k + 1], t[k]),
            "give the rows in time order, each at a new time",
        )
        .at_row(first_row + k + 2)),
        None => Ok(()),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn write(dir: &Path, ni: &str, mr: &str) {
        std::fs::create_dir_all(dir).unwrap();
        std::fs::write(dir.join("a3NI.csv"), ni).unwrap();
        std::fs::write(dir.join("a3MR.csv"), mr).unwrap();
    }

    const NI_HEAD: &str = "\u{feff}Timestamp,x,Timestamp,x\nInterval,0.0005,Interval,0.0005\nChannel name,\"Force\",Channel name,\"Input 1\"\nUnit,\"V\",Unit,\"V\"\n";
    const MR_HEAD: &str = "Axis1\nNumber of sampling data,4\nSampling time interval(ms),1\nTime,Analog 1\nms,Servo motor speed\n";

    /// A known ramp in both loggers: the force is tared and scaled, the speed
    /// interpolated across the 4 ms shift, the position its trapezoidal integral.
    #[test]
    fn the_rack_loggers_are_joined_tared_scaled_and_integrated() {
        let dir = std::env::temp_dir().join(format!("nm_rack_{}", std::process::id()));
        // Load cell: 0.1 V at rest for 10 samples, then 0.6 V; 0.5 ms apart.
        let mut ni = NI_HEAD.to_string();
        for k in 0..40 {
            let v = if k < 10 { 0.1 } else { 0.6 };
            ni += &format!("{},{v},{},0\n", k as f64 * 0.0005, k as f64 * 0.0005);
        }
        // Drive: the speed rises 1 rpm per ms (rpm = −t_ms: the rack moves forward).
        let mut mr = MR_HEAD.to_string();
        for k in 0..30 {
            mr += &format!("{}.0,{},0\n", k, -(k as f64));
        }
        write(&dir, &ni, &mr);
        let d = rack_pinion(&dir).unwrap();
        assert!((d.rate_hz() - 2000.0).abs() < 1e-9, "{}", d.rate_hz());
        let f = d.column("force_n").unwrap();
        let v = d.column("velocity_m_s").unwrap();
        let x = d.column("position_m").unwrap();
        // Every load-cell sample (shifted to 4–23.5 ms) lies inside the drive's 0–29 ms.
        assert_eq!(f.len(), 40);
        assert!(f[..10].iter().all(|f| f.abs() < 1e-12));
        assert!(f[10..].iter().all(|f| (f - (-200.0 * 0.5)).abs() < 1e-9));
        for (k, v) in v.iter().enumerate() {
            let t_ms = 4.0 + 0.5 * k as f64;
            // rpm(t) = −t_ms, scaled by −20/60000 m/s per rpm.
            assert!((v - t_ms * 20.0 / 60000.0).abs() < 1e-12, "{k}: {v}");
        }
        // A velocity linear in time integrates exactly by the trapezoidal rule.
        let last = x.len() - 1;
        let t_end = 0.0005 * last as f64;
        let v0 = 4.0 * 20.0 / 60000.0;
        let slope = 1000.0 * 20.0 / 60000.0; // m/s per s
        assert!((x[last] - (v0 * t_end + 0.5 * slope * t_end * t_end)).abs() < 1e-12);
        std::fs::remove_dir_all(&dir).ok();
    }

    #[test]
    fn a_malformed_rack_row_or_a_missing_file_is_named() {
        let dir = std::env::temp_dir().join(format!("nm_rack_bad_{}", std::process::id()));
        let mut ni = NI_HEAD.to_string();
        for k in 0..30 {
            ni += &format!("{},0.1,{},0\n", k as f64 * 0.0005, k as f64 * 0.0005);
        }
        ni += "0.015,abc,0.015,0\n";
        write(&dir, &ni, &format!("{MR_HEAD}0,0,0\n1,0,0\n"));
        let e = rack_pinion(&dir).unwrap_err().to_string();
        assert!(
            e.contains("a3NI.csv") && e.contains("35") && e.contains("abc"),
            "{e}"
        );
        // The load cell's file repaired, the drive's missing.
        std::fs::write(dir.join("a3NI.csv"), ni.replace("abc", "0.1")).unwrap();
        std::fs::remove_file(dir.join("a3MR.csv")).unwrap();
        let e = rack_pinion(&dir).unwrap_err().to_string();
        assert!(
            e.contains("a3MR.csv") && e.contains("cannot be read"),
            "{e}"
        );
        std::fs::remove_dir_all(&dir).ok();
    }
}
