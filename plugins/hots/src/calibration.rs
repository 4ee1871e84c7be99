//! Slit-error calibration: a per-edge correction table learned from motion data.
//!
//! **Model.** Edge L (level in counts) physically sits at L + e_{L mod 4N}. A run
//! gives events (t_k, L_k); the true position at t_k is that edge's position, so
//!
//! L_k + e_{L_k mod 4N} = x(t_k),
//!
//! with x(t) a smooth motion. The run is cut into segments of `segment_events`
//! events, each with its own polynomial of degree `degree` in scaled time
//! (τ ∈ [−1, 1] over the segment), and all segments share the 4N offsets e. A
//! segment must cover at least 1.5 revolutions: if segments ended exactly at the
//! edge-index wrap, each segment's polynomial could absorb any smooth trend of the
//! table (we hit this degeneracy; such segments are refused). The unknowns (4N + segments·(degree + 1)) are estimated jointly by least squares
//! (normal equations, Cholesky, with the constraint Σe = 0 — a common offset is
//! indistinguishable from the motion — added as a penalty row). The run should
//! cover each edge several times (tens of revolutions at near-constant velocity,
//! or a free spin-down); its speed variations must be slow compared with a segment.
//!
//! **Use.** The table [`SlitCalibration::edge_offsets_counts`] is ê; the estimator
//! corrects each event to x_k + ê[x_k mod 4N] before the fit
//! (`TimestampEstimator::edge_offsets_counts`). Edge indices must refer to the
//! disc's own zero: the count must be referenced to the index pulse (in the
//! simulation, count 0 is the disc's zero).

use nalgebra::{DMatrix, DVector};
use serde::{Deserialize, Serialize};
use std::fmt;

/// A learned per-edge correction table, storable with serde (JSON/YAML).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SlitCalibration {
    /// ê_L (counts), L = 0..4N: estimated edge position minus nominal.
    pub edge_offsets_counts: Vec<f64>,
    /// Rms of the fit residual on the calibration run (counts).
    pub residual_rms_counts: f64,
    /// Events used.
    pub events: usize,
}

/// Why a calibration failed.
#[derive(Debug, Clone, PartialEq)]
pub enum CalibrationError {
    /// A parameter is out of range (which, and why).
    Param(&'static str, String),
    /// Some edge never occurs in the run, so its offset is unknown.
    EdgeNotSeen(usize),
    /// The normal equations are singular (run too short or too irregular).
    Singular,
}

impl fmt::Display for CalibrationError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::Param(field, why) => write!(f, "calibration parameter `{field}`: {why}"),
            Self::EdgeNotSeen(l) => write!(
                f,
                "edge {l} never occurs in the run: record at least one full revolution (better tens)"
            ),
            Self::Singular => write!(
                f,
                "the calibration equations are singular: use a longer run, a lower degree or longer segments"
            ),
        }
    }
}

impl std::error::Error for CalibrationError {}

impl SlitCalibration {
    /// Learn the table for an encoder with `counts_per_rev` = 4N edges from the
    /// events (`times` s, `levels` counts) of one run. `segment_events` events share
    /// one motion polynomial of degree `degree`.
    ///
    /// ```
    /// use hots::SlitCalibration;
    /// // A 4-count "encoder" with edge errors e = [0.1, −0.05, 0.0, −0.05] turning
    /// // at exactly 1000 counts/s: events at (L + e_L)/1000.
    /// let e = [0.1, -0.05, 0.0, -0.05];
    /// let levels: Vec<f64> = (1..400).map(|l| l as f64).collect();
    /// let times: Vec<f64> = levels.iter().map(|&l| (l + e[l as usize % 4]) / 1000.0).collect();
    /// let cal = SlitCalibration::learn(&times, &levels, 4, 2, 100).unwrap();
    /// assert!(SlitCalibration::learn(&times, &levels, 4, 2, 5).is_err()); // < 1.5 revolutions
    /// for (a, b) in cal.edge_offsets_counts.iter().zip(e) {
    ///     assert!((a - b).abs() < 1e-9);
    /// }
    /// ```
    pub fn learn(
        times: &[f64],
        levels: &[f64],
        counts_per_rev: usize,
        degree: usize,
        segment_events: usize,
    ) -> Result<Self, CalibrationError> {
        let n = times.len().min(levels.len());
        if counts_per_rev < 2 {
            return Err(CalibrationError::Param(
                "counts_per_rev",
                format!("is {counts_per_rev}, need ≥ 2"),
            ));
        }
        if degree > 8 {
            return Err(CalibrationError::Param(
                "degree",
                format!("is {degree}, use ≤ 8"),
            ));
        }
        if segment_events <= degree + 1 {
            return Err(CalibrationError::Param(
                "segment_events",
                format!("is {segment_events}, need > degree + 1"),
            ));
        }
        if 2 * segment_events < 3 * counts_per_rev {
            return Err(CalibrationError::Param(
                "segment_events",
                format!(
                    "is {segment_events}, less than 1.5 revolutions ({} events): a segment must contain an edge-index wrap, or a per-segment polynomial can absorb any smooth trend of the table",
                    3 * counts_per_rev / 2
                ),
            ));
        }
        if times[..n]
            .iter()
            .chain(&levels[..n])
            .any(|v| !v.is_finite())
        {
            return Err(CalibrationError::Param(
                "events",
                "contain non-finite values".into(),
            ));
        }
        let n4 = counts_per_rev;
        let mut seen = vec![false; n4];
        for &l in &levels[..n] {
            seen[(l as i64).rem_euclid(n4 as i64) as usize] = true;
        }
        if let Some(l) = seen.iter().position(|s| !s) {
            return Err(CalibrationError::EdgeNotSeen(l));
        }
        let n_seg = n.div_ceil(segment_events);
        let p = degree + 1;
        let dim = n4 + n_seg * p;
        // Unknowns: [e_0..e_{4N−1}, c_{s,0..degree} per segment]; row:
        // −e_L + Σ c_j τ^j = L. Scale the polynomial columns per segment.
        let mut ata = DMatrix::<f64>::zeros(dim, dim);
        let mut atb = DVector::<f64>::zeros(dim);
        let mut row = vec![0.0; p];
        let mut seg_info = Vec::with_capacity(n_seg);
        for s in 0..n_seg {
            let lo = s * segment_events;
            let hi = ((s + 1) * segment_events).min(n);
            let (t0, t1) = (times[lo], times[hi - 1]);
            let mid = 0.5 * (t0 + t1);
            let half = (0.5 * (t1 - t0)).max(1e-12);
            seg_info.push((lo, hi, mid, half));
            for k in lo..hi {
                let tau = (times[k] - mid) / half;
                let mut pw = 1.0;
                for r in row.iter_mut() {
                    *r = pw;
                    pw *= tau;
                }
                let li = (levels[k] as i64).rem_euclid(n4 as i64) as usize;
                let base = n4 + s * p;
                ata[(li, li)] += 1.0;
                atb[li] -= levels[k];
                for a in 0..p {
                    ata[(li, base + a)] -= row[a];
                    ata[(base + a, li)] -= row[a];
                    atb[base + a] += row[a] * levels[k];
                    for b in 0..p {
                        ata[(base + a, base + b)] += row[a] * row[b];
                    }
                }
            }
        }
        // Penalty row Σe = 0 (weight 1).
        for i in 0..n4 {
            for j in 0..n4 {
                ata[(i, j)] += 1.0;
            }
        }
        let sol = ata
            .clone()
            .cholesky()
            .ok_or(CalibrationError::Singular)?
            .solve(&atb);
        if sol.iter().any(|v| !v.is_finite()) {
            return Err(CalibrationError::Singular);
        }
        let e: Vec<f64> = sol.as_slice()[..n4].to_vec();
        // Residual rms.
        let mut ss = 0.0;
        for (s, &(lo, hi, mid, half)) in seg_info.iter().enumerate() {
            for k in lo..hi {
                let tau = (times[k] - mid) / half;
                let mut x = 0.0;
                let mut pw = 1.0;
                for j in 0..p {
                    x += sol[n4 + s * p + j] * pw;
                    pw *= tau;
                }
                let li = (levels[k] as i64).rem_euclid(n4 as i64) as usize;
                ss += (levels[k] + e[li] - x).powi(2);
            }
        }
        Ok(Self {
            edge_offsets_counts: e,
            residual_rms_counts: (ss / n as f64).sqrt(),
            events: n,
        })
    }

    /// The corrected position of an event at `level` (counts).
    pub fn correct(&self, level: f64) -> f64 {
        let n4 = self.edge_offsets_counts.len() as i64;
        level + self.edge_offsets_counts[(level as i64).rem_euclid(n4) as usize]
    }
}
