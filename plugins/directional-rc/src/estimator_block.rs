//! `rotation_estimator`: the rotation estimate (7.18)–(7.21) inside a graph.
//!
//! It records the measured height `z` of each estimation line while the plan's
//! `line` input holds the line's index (see [`crate::plan`]), with the line's
//! slow-axis position x (the plan's `r[0]` at its first sample), its start y0
//! (`r[1]` there) and its sample spacing dy = (y_last − y0)/(samples − 1). When the
//! last line (index `lines − 1`) ends, the estimate runs **once, inside that tick's
//! update phase**: [`estimate_rotation_in`] on the recorded lines in a
//! [`Workspace`] built with the block — the same computation as the offline
//! [`estimate_rotation`](crate::estimate::estimate_rotation), bit for bit, without
//! allocating. Its cost is O(pairs · n · L) multiply-adds (n samples per line, L
//! lags): for four lines of 5 000 samples at ±22 lags 1.2 ms (6 sample periods at
//! 5 kHz), for 20 000 samples at ±82 lags 16 ms (320 sample periods at 20 kHz)
//! (`cargo bench -p nanomotion-directional-rc --bench drc_step`,
//! docs/performance.md). In a simulation
//! this only costs wall time; on a real-time target the tick overruns once, at the
//! end of the estimation phase, while the scan is between phases (the plan's
//! lead-in keeps RC off then).
//!
//! Outputs (from the state: no direct feed-through):
//!
//! - `alpha`: 0 until the estimate exists, then α̂ (rad) — connect it to the
//!   `alpha` inputs of the `frame_rotation` blocks (`alpha_input: true`);
//! - `sigma`: its standard error (rad), 0 before;
//! - `status`: 0 estimating, 1 estimate valid, −c when the estimate failed with
//!   code c ([`EstimateError::code`]: 1 too few lines, 2 a line too short for the
//!   lag window, 3 non-finite data, 4 different spacings, 5 zero spacing, 6 two
//!   lines at the same x, 7 a flat line, 8 ambiguous (repeating structure), 9 weak
//!   correlation, 10 peak at the window edge, 11 bad option, 12 a line longer than
//!   the buffers, 13 a line index ≥ `lines` while the lines are recorded; lines
//!   flagged after line `lines − 1` has ended are ignored).
//!
//! On failure `on_failure: stop` (default) makes `alpha` NaN: the run stops with
//! the non-finite error naming this block's `alpha` port and the tick, and the
//! logged `status` gives the reason; `on_failure: plain_rc` keeps α = 0 (the scan
//! goes on as standard RC). [`RotationEstimator::outcome`] gives the full result
//! (with the error's message) from Rust.
//!
//! Buffers: `lines` × (`max_line_s`/t_s + 2) samples, bounded by
//! [`MAX_LINES`] lines and the core's
//! `MAX_BUFFER_VALUES`, allocated in `build`.

use crate::estimate::{
    Combined, EstimateError, EstimatorOptions, LineRef, Workspace, estimate_rotation_in,
};
use crate::plan::MAX_LINES;
use nanomotion_core::Params;
use nanomotion_core::block::check;
use nanomotion_core::{Block, BuildContext, ParamError, Port, Tick, declared_block};
use serde::{Deserialize, Serialize};

/// What to output for α when the estimate fails.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, Default, Params)]
#[serde(rename_all = "snake_case")]
pub enum OnFailure {
    /// α = NaN: the run stops with a located non-finite error.
    #[default]
    Stop,
    /// α = 0: the scan continues as standard RC.
    PlainRc,
}

fn max_angle() -> f64 {
    EstimatorOptions::default().max_angle_rad
}
fn min_corr() -> f64 {
    EstimatorOptions::default().min_correlation
}
fn alias() -> f64 {
    EstimatorOptions::default().alias_level
}

/// `rotation_estimator`: DRC rotation estimate (7.18)–(7.21) in a graph: records the
/// estimation lines (line index from drc_scan_plan), estimates α once when the last
/// line ends (one tick, preallocated), outputs α for frame_rotation.
///
/// See the [module docs](self).
#[derive(Debug, Clone, Serialize, Deserialize, Params)]
#[serde(deny_unknown_fields)]
#[block(type_name = "rotation_estimator", role = Estimator, ports = "z, line, r[2] -> alpha (rad), sigma (rad), status (0 estimating, 1 valid, −code failed)")]
pub struct RotationEstimator {
    /// Number of estimation lines (2 … 16); the estimate runs when line
    /// `lines − 1` ends.
    #[param(size(2, MAX_LINES))]
    pub lines: usize,
    /// Longest line recorded (s): the buffers hold `max_line_s`/t_s + 2 samples
    /// per line. The plan's lines last a quarter period.
    #[param(positive)]
    pub max_line_s: f64,
    /// Largest |α| admitted (rad), default 0.1.
    #[serde(default = "max_angle")]
    #[param(range(> 0, < 1.5), hint = "e.g. 0.1")]
    pub max_angle_rad: f64,
    /// Smallest acceptable correlation peak, default 0.5.
    #[serde(default = "min_corr")]
    #[param(range(> 0, < 1), hint = "e.g. 0.5")]
    pub min_correlation: f64,
    /// Autocorrelation level of a repeat (alias check), default 0.5.
    #[serde(default = "alias")]
    #[param(range(> 0.25, < 1), hint = "e.g. 0.5")]
    pub alias_level: f64,
    /// `stop` (α = NaN, default) or `plain_rc` (α = 0) on failure.
    #[serde(default)]
    #[param(default_doc = "stop")]
    pub on_failure: OnFailure,
    #[serde(skip)]
    state: Option<State>,
}

#[derive(Debug, Clone)]
struct State {
    cap: usize,
    z: Vec<f64>,
    len: [usize; MAX_LINES],
    x: [f64; MAX_LINES],
    y0: [f64; MAX_LINES],
    y_last: [f64; MAX_LINES],
    overflow: Option<EstimateError>,
    current: Option<usize>,
    ws: Workspace,
    outcome: Option<Result<Combined, EstimateError>>,
    y: [f64; 3],
}

impl RotationEstimator {
    /// An estimator for `lines` lines of at most `max_line_s` seconds (unbuilt),
    /// with the default options and `on_failure: stop`.
    pub fn new(lines: usize, max_line_s: f64) -> Self {
        let o = EstimatorOptions::default();
        Self {
            lines,
            max_line_s,
            max_angle_rad: o.max_angle_rad,
            min_correlation: o.min_correlation,
            alias_level: o.alias_level,
            on_failure: OnFailure::Stop,
            state: None,
        }
    }

    fn options(&self) -> EstimatorOptions {
        EstimatorOptions {
            max_angle_rad: self.max_angle_rad,
            min_correlation: self.min_correlation,
            alias_level: self.alias_level,
        }
    }

    /// The estimate once it ran: `Ok` with α̂ and its uncertainty, or the error.
    pub fn outcome(&self) -> Option<Result<Combined, EstimateError>> {
        self.state.as_ref().and_then(|s| s.outcome.clone())
    }

    /// The recorded lines (x, y0, dy, z), as the estimator saw them (after build).
    pub fn recorded_lines(&self) -> Vec<(f64, f64, f64, Vec<f64>)> {
        let Some(s) = &self.state else {
            return Vec::new();
        };
        (0..self.lines)
            .map(|i| {
                let l = s.line(i);
                (l.x_m, l.y0_m, l.dy_m, l.z_m.to_vec())
            })
            .collect()
    }

    /// Record one sample (plain Rust; the block's update phase).
    pub fn record(&mut self, z: f64, line: f64, x: f64, y: f64) {
        let lines = self.lines;
        let o = self.options();
        let on_failure = self.on_failure;
        let Some(s) = self.state.as_mut() else {
            return;
        };
        if s.outcome.is_some() {
            return;
        }
        let now = if line >= 0.0 {
            Some(line.round() as usize)
        } else {
            None
        };
        // The last line ended: estimate once.
        if s.current == Some(lines - 1) && now != s.current {
            s.finish(lines, &o, on_failure);
            return;
        }
        s.current = now;
        let Some(i) = now else { return };
        if i >= lines {
            s.overflow.get_or_insert(EstimateError::TooManyLines {
                lines: i + 1,
                max: lines,
            });
            return;
        }
        let n = s.len[i];
        if n == s.cap {
            s.overflow.get_or_insert(EstimateError::TooLong {
                line: i,
                len: n + 1,
                max: s.cap,
            });
            return;
        }
        if n == 0 {
            s.x[i] = x;
            s.y0[i] = y;
        }
        s.y_last[i] = y;
        s.z[i * s.cap + n] = z;
        s.len[i] = n + 1;
    }
}

/// Line `i` of the buffers: heights, x and y0 at its first sample, and
/// dy = (y_last − y0)/(n − 1).
fn line_ref<'a>(z: &'a [f64], n: usize, x: f64, y0: f64, y_last: f64) -> LineRef<'a> {
    LineRef {
        x_m: x,
        y0_m: y0,
        dy_m: if n >= 2 {
            (y_last - y0) / (n - 1) as f64
        } else {
            0.0
        },
        z_m: &z[..n],
    }
}

impl State {
    fn line(&self, i: usize) -> LineRef<'_> {
        line_ref(
            &self.z[i * self.cap..],
            self.len[i],
            self.x[i],
            self.y0[i],
            self.y_last[i],
        )
    }

    fn finish(&mut self, lines: usize, o: &EstimatorOptions, on_failure: OnFailure) {
        let result = match self.overflow.clone() {
            Some(e) => Err(e),
            None => {
                let mut refs = [LineRef::default(); MAX_LINES];
                for (i, r) in refs.iter_mut().enumerate().take(lines) {
                    *r = line_ref(
                        &self.z[i * self.cap..],
                        self.len[i],
                        self.x[i],
                        self.y0[i],
                        self.y_last[i],
                    );
                }
                estimate_rotation_in(&refs[..lines], o, &mut self.ws)
            }
        };
        self.y = match &result {
            Ok(c) => [c.alpha_rad, c.std_error_rad, 1.0],
            Err(e) => [
                match on_failure {
                    OnFailure::Stop => f64::NAN,
                    OnFailure::PlainRc => 0.0,
                },
                0.0,
                -f64::from(e.code()),
            ],
        };
        self.outcome = Some(result);
    }
}

#[declared_block]
impl Block for RotationEstimator {
    fn inputs(&self) -> Vec<Port> {
        vec![Port::new("z", 1), Port::new("line", 1), Port::new("r", 2)]
    }
    fn outputs(&self) -> Vec<Port> {
        vec![
            Port::new("alpha", 1),
            Port::new("sigma", 1),
            Port::new("status", 1),
        ]
    }
    fn direct_feedthrough(&self) -> bool {
        false
    }
    fn build(&mut self, ctx: &BuildContext) -> Result<(), ParamError> {
        self.check_params()?;
        let cap = check::samples_of("max_line_s", self.max_line_s, ctx.dt, 1 << 24)? + 2;
        check::buffer("max_line_s", cap, 8, self.lines)?;
        self.state = Some(State {
            cap,
            z: vec![0.0; cap * self.lines],
            len: [0; MAX_LINES],
            x: [0.0; MAX_LINES],
            y0: [0.0; MAX_LINES],
            y_last: [0.0; MAX_LINES],
            overflow: None,
            current: None,
            ws: Workspace::new(self.lines, cap),
            outcome: None,
            y: [0.0; 3],
        });
        Ok(())
    }
    fn planned_bytes(&self, dt: f64) -> (&'static str, usize) {
        // The line store (lines × samples per line) and the estimator's
        // workspace (about four values per sample), from `max_line_s`.
        let samples = (self.max_line_s / dt).ceil();
        let bytes = if samples.is_finite() && samples >= 0.0 {
            let cap = samples.min(usize::MAX as f64 / 64.0) as usize + 2;
            cap.saturating_mul(self.lines.saturating_add(4))
                .saturating_mul(8)
        } else {
            0
        };
        ("max_line_s", bytes)
    }
    fn memory_bytes(&self) -> usize {
        self.state.as_ref().map_or(0, |s| {
            s.z.capacity() * std::mem::size_of::<f64>() + s.ws.memory_bytes()
        })
    }
    fn output(&mut self, _tick: Tick, _u: &[f64], y: &mut [f64]) {
        if let Some(s) = &self.state {
            y.copy_from_slice(&s.y);
        }
    }
    fn update(&mut self, _tick: Tick, u: &[f64]) {
        self.record(u[0], u[1], u[2], u[3]);
    }
}
