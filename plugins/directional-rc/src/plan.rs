//! The DRC scan plan: estimation lines, then the raster scan (Sec. 7.4, Fig. 7.11).
//!
//! `drc_scan_plan` writes the scan references in the **sample frame**, relative to
//! the point where the DRC scan starts, so that a `frame_rotation` with the
//! estimated α (7.17) turns the whole plan about that point: the reference stays
//! continuous when α switches from 0 (estimation) to α̂ (DRC).
//!
//! With T the fast-axis period (samples N = T/t_s, a multiple of 4), A the
//! amplitude, Δx the line spacing and m the number of estimation lines:
//!
//! | periods | x_r | y_r | `line` | `rc_on` |
//! |---|---|---|---|---|
//! | 0 (settle) | 0 → x_0 = −(m − 1)Δx during 0.3 ≤ p < 0.7 | triangle | −1 | 0 |
//! | 1 … m | x_{i} = x_0 + iΔx in period i + 1, then → x_{i+1} during 0.3 ≤ p < 0.7 | triangle | i while p < ¼ (y_r: 0 → +A) | 0 |
//! | m + 1 … m + lead-in | v_slow·(t − t_0), t_0 = (m + 1)T | triangle | −1 | 0 |
//! | after | v_slow·(t − t_0) | triangle | −1 | 1 |
//!
//! p is the phase in the period, the triangle the one of the core's
//! `triangular_scan` (0 at p = 0 rising, +A at ¼, −A at ¾). The last estimation
//! line lies at x_r = 0, where the DRC scan starts; with m = 0 there is no
//! estimation phase (plain raster scan from t = 0 after the lead-in).
//!
//! ```
//! use nanomotion_core::{Block, BuildContext, Tick};
//! use nanomotion_directional_rc::plan::ScanPlan;
//! let mut p = ScanPlan::new(25e-6, 4.0, 125e-9, 4, 1e-6, 1);
//! p.build(&BuildContext::new("plan", 1e-3, 0)).unwrap();
//! let mut y = [0.0; 4];
//! // Period 2 (line 1), p = 0.1: x_r = −2 µm, y_r = 0.4 A, recording line 1.
//! p.output(Tick::new(8_400, 1e-3), &[], &mut y);
//! assert!((y[0] + 2e-6).abs() < 1e-18 && (y[1] - 10e-6).abs() < 1e-15);
//! assert_eq!((y[2], y[3]), (1.0, 0.0));
//! ```

use nanomotion_core::Params;
use nanomotion_core::block::check;
use nanomotion_core::{Block, BuildContext, ParamError, Port, Tick, declared_block};
use serde::{Deserialize, Serialize};

/// Largest number of estimation lines (also the `rotation_estimator`'s cap).
pub const MAX_LINES: usize = 16;

fn one() -> usize {
    1
}

/// `drc_scan_plan`: DRC scan plan in the sample frame: estimation lines (line index),
/// then the raster scan about the last line's start (rc_on after the lead-in).
///
/// Estimation lines, then the raster scan, in the sample frame.
/// See the [module docs](self).
#[derive(Debug, Clone, Serialize, Deserialize, Params)]
#[serde(deny_unknown_fields)]
#[block(type_name = "drc_scan_plan", role = Source, ports = "-> r[2] (x_r, y_r m), line (index or −1), rc_on (0/1)")]
pub struct ScanPlan {
    /// Fast-axis amplitude A (m): y_r between −A and +A.
    #[param(non_negative)]
    pub amplitude_m: f64,
    /// Fast-axis period T (s): one trace and one retrace; the RC period.
    /// A multiple of 4 samples.
    #[param(positive)]
    pub period_s: f64,
    /// Slow-axis speed during the scan (m/s).
    #[param(finite)]
    pub slow_velocity_m_s: f64,
    /// Estimation lines m (0, or 2 … 16).
    pub estimation_lines: usize,
    /// Spacing Δx of the estimation lines along x_r (m).
    #[param(finite)]
    pub line_spacing_m: f64,
    /// Periods of scan with `rc_on` = 0 after the estimation (default 1): the
    /// x/y loops settle after the frame switch before RC learns.
    #[serde(default = "one")]
    #[param(size(0, 1_000_000))]
    pub lead_in_periods: usize,
    #[serde(skip)]
    n: u64,
}

impl ScanPlan {
    /// A plan (unbuilt).
    pub fn new(
        amplitude_m: f64,
        period_s: f64,
        slow_velocity_m_s: f64,
        estimation_lines: usize,
        line_spacing_m: f64,
        lead_in_periods: usize,
    ) -> Self {
        Self {
            amplitude_m,
            period_s,
            slow_velocity_m_s,
            estimation_lines,
            line_spacing_m,
            lead_in_periods,
            n: 0,
        }
    }

    /// Samples per period N (after build).
    pub fn period_samples(&self) -> u64 {
        self.n
    }

    /// The base tick at which the DRC scan starts: (m + 1)·N, or 0 without
    /// estimation lines.
    pub fn scan_start_tick(&self) -> u64 {
        if self.estimation_lines == 0 {
            0
        } else {
            (self.estimation_lines as u64 + 1) * self.n
        }
    }

    /// Samples per estimation line (N/4).
    pub fn line_samples(&self) -> u64 {
        self.n / 4
    }

    /// (x_r, y_r, line, rc_on) at sample k.
    pub fn at(&self, k: u64) -> [f64; 4] {
        let n = self.n;
        let (per, j) = (k / n, k % n);
        let p = j as f64 / n as f64;
        let shape = if p < 0.25 {
            4.0 * p
        } else if p < 0.75 {
            2.0 - 4.0 * p
        } else {
            4.0 * p - 4.0
        };
        let y = self.amplitude_m * shape;
        let m = self.estimation_lines as u64;
        let k0 = self.scan_start_tick();
        if k >= k0 {
            let t = (k - k0) as f64 * self.period_s / n as f64;
            let on = (k - k0) / n >= self.lead_in_periods as u64;
            return [self.slow_velocity_m_s * t, y, -1.0, f64::from(u8::from(on))];
        }
        let dx = self.line_spacing_m;
        let x0 = -((m - 1) as f64) * dx;
        // Position of line i (period i + 1); period 0 moves from 0 to line 0.
        let (from, to) = if per == 0 {
            (0.0, x0)
        } else {
            let i = per - 1;
            let xi = x0 + i as f64 * dx;
            (xi, if i + 1 < m { xi + dx } else { xi })
        };
        let x = if p < 0.3 {
            from
        } else if p < 0.7 {
            from + (to - from) * (p - 0.3) / 0.4
        } else {
            to
        };
        let line = if per >= 1 && j < n / 4 {
            (per - 1) as f64
        } else {
            -1.0
        };
        [x, y, line, 0.0]
    }
}

#[declared_block]
impl Block for ScanPlan {
    fn outputs(&self) -> Vec<Port> {
        vec![
            Port::new("r", 2),
            Port::new("line", 1),
            Port::new("rc_on", 1),
        ]
    }
    fn build(&mut self, ctx: &BuildContext) -> Result<(), ParamError> {
        self.check_params()?;
        if self.estimation_lines == 1 || self.estimation_lines > MAX_LINES {
            return Err(ParamError::new(
                "estimation_lines",
                format!("is {}", self.estimation_lines),
                format!("give 0 (no estimation) or 2 … {MAX_LINES} lines"),
            ));
        }
        if self.estimation_lines > 0 && self.line_spacing_m == 0.0 {
            return Err(ParamError::new(
                "line_spacing_m",
                "is 0: all estimation lines at the same x",
                "give the slow-axis spacing of the lines, e.g. 1.0e-6",
            ));
        }
        let n = check::samples_of("period_s", self.period_s, ctx.dt, 1 << 40)?;
        if n < 4 || n % 4 != 0 || ((n as f64 * ctx.dt - self.period_s) / self.period_s).abs() > 1e-9
        {
            return Err(ParamError::new(
                "period_s",
                format!(
                    "is {} s = {} sample periods of {} s",
                    self.period_s,
                    self.period_s / ctx.dt,
                    ctx.dt
                ),
                "give a whole multiple of 4 sample periods (each quarter of the triangle is one line)",
            ));
        }
        self.n = n as u64;
        Ok(())
    }
    fn output(&mut self, tick: Tick, _u: &[f64], y: &mut [f64]) {
        y.copy_from_slice(&self.at(tick.k));
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn plan_is_continuous_and_records_each_line_once() {
        let mut p = ScanPlan::new(25e-6, 4.0, 125e-9, 4, 1e-6, 1);
        p.build(&BuildContext::new("p", 1e-3, 0)).unwrap();
        let n = p.period_samples();
        assert_eq!(n, 4000);
        let mut prev = p.at(0);
        let mut counts = [0usize; 4];
        let mut max_step = 0.0f64;
        for k in 1..(8 * n) {
            let y = p.at(k);
            max_step = max_step
                .max((y[0] - prev[0]).abs())
                .max((y[1] - prev[1]).abs());
            if y[2] >= 0.0 {
                counts[y[2] as usize] += 1;
                // Recording: constant x at the line's position, y rising.
                assert!((y[0] - (y[2] - 3.0) * 1e-6).abs() < 1e-18);
                assert!(y[1] >= 0.0 && y[1] < 25e-6);
            }
            // rc_on exactly from t_0 + T = 6 periods.
            assert_eq!(y[3] == 1.0, k >= 6 * n, "k = {k}");
            prev = y;
        }
        assert_eq!(counts, [1000; 4]);
        // Largest step per sample: the fast axis, 4A/N.
        assert!(
            max_step <= 4.0 * 25e-6 / n as f64 * (1.0 + 1e-12),
            "{max_step}"
        );
        // The scan starts at the last line's position (x_r = 0).
        assert_eq!(p.at(5 * n)[0], 0.0);
    }

    #[test]
    fn bad_parameters_name_the_field() {
        for (mut p, field) in [
            (
                ScanPlan::new(25e-6, 4.0, 1e-7, 1, 1e-6, 1),
                "estimation_lines",
            ),
            (
                ScanPlan::new(25e-6, 4.0, 1e-7, 17, 1e-6, 1),
                "estimation_lines",
            ),
            (ScanPlan::new(25e-6, 4.0, 1e-7, 4, 0.0, 1), "line_spacing_m"),
            (ScanPlan::new(25e-6, 4.0005, 1e-7, 4, 1e-6, 1), "period_s"),
            (ScanPlan::new(25e-6, f64::NAN, 1e-7, 4, 1e-6, 1), "period_s"),
        ] {
            let e = p.build(&BuildContext::new("p", 1e-3, 0)).unwrap_err();
            assert_eq!(e.field, field, "{e:?}");
        }
    }
}
