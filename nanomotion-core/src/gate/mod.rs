//! The stability gate: every feedback loop of a built graph analysed before the
//! first tick (`nanomotion check`, and `nanomotion run` before it runs).
//!
//! **Loops.** The loops are the strongly connected components of the block graph
//! (see `loops.rs`); nested loops of one component are analysed together.
//!
//! **Models.** Each block of a loop contributes its [`Block::linearisation`]
//! (the model it is *judged on*: a saturation or quantiser as gain 1, a PI with
//! output limits inside its limits, a gain-scheduled controller at each schedule
//! point — the report says so), else its exact [`Block::lti`]; inserted rate
//! transitions are identities (a hold or a sampler, see below). A block with
//! neither but with a slope range ([`Block::sector`]) is judged at its centre
//! slope (below). A block with none of these makes its loop *unproven*, named
//! in the report.
//!
//! **Slope ranges: the circle criterion.** A sector block promises that each
//! output channel moves by s·(its input's move) between samples, s ∈ [a, b];
//! with the rest of the loop LTI, the increments of every signal obey the loop
//! with the block replaced by a time-varying gain s_k. The loop is closed with
//! each sector block at k0 = (a + b)/2 (its poles, margins and norms are that
//! model's). If that is unstable the loop fails as unstable, naming the centre
//! slope. Else M, the transfer from signals added to the sector blocks' outputs to
//! their inputs, is read off the closed loop (each sector block's part has an
//! extra input added to its output and an extra output equal to its input, on the
//! port index `SECTOR_PORT` that no connection uses, so the interconnection leaves them
//! open), R = diag((b − a)/2) per channel, and ‖M R‖∞ < 1 ([`hinfnorm`]) proves
//! the loop for every slope history (small gain; [`CircleCheck`]); ‖M R‖∞ ≥ 1
//! leaves it unproven with the figure and a fix. Sufficient, not necessary; a
//! sector block must run at the analysis rate (a faster one: unproven, since the
//! perturbation channel is not lifted). An unproven loop that has analysed points
//! still fails on an unstable point or a missed bound, with or without
//! `allow_unproven`.
//!
//! **Rates.** A loop is analysed at its *slowest* rate, normally the controller's:
//! blocks at faster rates are first interconnected at their own rate, then
//! *lifted* exactly to the slower rate — their inputs come from slower blocks
//! through zero-order holds, so over one slow period they see a constant input
//! and x ← A^m x + Σ_{k<m} A^k B u is exact; their outputs are sampled at the slow
//! instants (the decimating rate transition). The slow-rate model therefore holds
//! every state of the loop and its poles decide stability exactly (they are the
//! eigenvalues of the monodromy matrix of the periodic multi-rate loop). Why not
//! lift to the fast rate: the slow blocks would make the fast model periodically
//! time-varying, so no single transfer function (and no margins) would exist.
//! Rates must be nested (each divides the next); otherwise the loop is unproven.
//! Margins are those of the slow-rate loop: inter-sample behaviour of the fast
//! part is not in them (it is in the poles).
//!
//! **Loop transfer.** The loop is broken at one connection between blocks of the
//! analysis rate — preferably a controller's output, else a plant's input — and
//! L = −(the transfer from a signal injected at the broken input to the returned
//! output), so that the closed loop is (I + L)⁻¹ whatever signs the `sum` blocks
//! carry. Reported per loop: closed-loop poles (eigenvalues of the closed
//! interconnection, not of L), gain, phase and modulus margins
//! ([`stability_margins`](crate::lti::stability_margins)), delay margin
//! PM/ω_c, ‖S‖∞ and ‖T‖∞ ([`hinfnorm`]) of S = (I + L)⁻¹ and T = L(I + L)⁻¹,
//! and the generalised Nyquist count: the winding number N of det(I + L(z))
//! along |z| = 1 (passing outside poles on the circle) with the open-loop
//! poles P outside it gives P − N closed-loop poles outside, a second
//! computation of stability. A MIMO break (a port wider than one) reports
//! the characteristic loci (eigenvalues of L(e^{jωT})) by their closest
//! approach to −1, and ‖S‖∞, ‖T‖∞; gain/phase/delay margins are SISO.
//!
//! ```
//! use nanomotion_core::{GraphSpec, gate};
//! let yaml = r#"
//! base_rate_hz: 1000
//! duration_s: 0.1
//! blocks:
//!   - { name: ref, type: constant, value: 1.0 }
//!   - { name: err, type: sum, signs: "+-" }
//!   - { name: k, type: gain, k: 0.5 }
//!   - { name: plant, type: transfer_function, num: [1.0], den: [1.0, -1.0], discrete: true }
//! connections:
//!   - { from: ref.y, to: err.in0 }
//!   - { from: plant.y, to: err.in1 }
//!   - { from: err.y, to: k.u }
//!   - { from: k.y, to: plant.u }
//! "#;
//! let spec = GraphSpec::from_yaml(yaml, "doc").unwrap();
//! let require = spec.require.clone().unwrap_or_default();
//! let (sched, _) = spec.build().unwrap();
//! let report = gate::analyse(&sched, &require);
//! assert_eq!(report.loops.len(), 1);
//! // L(z) = 0.5/(z − 1): closed-loop pole 1 − 0.5 = 0.5.
//! assert!((report.loops[0].points[0].spectral_radius - 0.5).abs() < 1e-12);
//! assert!(report.passes());
//! ```

mod assemble;
mod loops;

/// The criteria of learning blocks; defined beside the block contract
/// ([`crate::learning`]), since [`Block::learning`] returns its model.
pub use crate::learning;
pub use crate::learning::{LearningCheck, LearningModel};
pub use crate::require::{Bounds, Require};

use crate::block::{Block, Role, Sector};
use crate::lti::{Complex, FrequencyEvaluator, StateSpace, hinfnorm};
use crate::scheduler::{BlockWiring, Scheduler};
use assemble::{Edge, Part, compose, lift};
use nalgebra::DMatrix;
use std::fmt;

/// Most combinations of schedule points analysed per loop.
pub const MAX_POINTS: usize = 64;

/// Largest number of states of a loop whose margins, norms and Nyquist count
/// are computed (poles are always computed): 512, two full `state_space`
/// blocks. Each frequency point costs O(n²) (one Hessenberg reduction per
/// loop transfer), but each H∞ norm solves the dense 2n × 2n Hamiltonian
/// eigenvalue problem, O(n³), and the gate runs before every run of a sweep
/// (docs/performance.md, issue 29: 199 states in 0.6 s, 399 in 3.6 s on the
/// loaded 2-core machine).
pub const MAX_MARGIN_STATES: usize = 512;

/// Closed-loop poles with modulus above 1 − this are not counted as stable.
pub const STABILITY_TOLERANCE: f64 = 1e-9;

/// Margins of a SISO loop.
#[derive(Debug, Clone, PartialEq)]
pub struct SisoMargins {
    /// Gain margin (dB); +∞ when the phase never crosses −180°.
    pub gain_margin_db: f64,
    /// Phase margin (degrees); +∞ when |L| never crosses 1.
    pub phase_margin_deg: f64,
    /// Modulus margin min |1 + L(e^{jωT})| (= 1/‖S‖∞).
    pub modulus_margin: f64,
    /// Delay margin (s): PM/ω_c, the extra loop delay that brings the phase
    /// margin to 0; +∞ without a gain crossover.
    pub delay_margin_s: f64,
    /// Gain crossover (Hz), NaN if none.
    pub gain_crossover_hz: f64,
    /// Phase crossover (Hz), NaN if none.
    pub phase_crossover_hz: f64,
}

/// The generalised Nyquist count of a loop.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Nyquist {
    /// Counter-clockwise encirclements N of the origin by det(I + L(z)) as z goes
    /// once around |z| = 1 (just outside it, so poles on the circle count as
    /// inside).
    pub encirclements: i64,
    /// Open-loop poles P of L outside the unit circle.
    pub open_loop_unstable: usize,
    /// Closed-loop poles outside the unit circle by the Nyquist criterion: P − N.
    pub implied_unstable: i64,
}

/// The analysis of a loop at one combination of schedule points.
#[derive(Debug, Clone, PartialEq)]
pub struct PointAnalysis {
    /// The schedule points (`""` when no block has several).
    pub label: String,
    /// Closed-loop poles (z-plane, at the analysis rate).
    pub poles: Vec<Complex<f64>>,
    /// Largest pole modulus.
    pub spectral_radius: f64,
    /// All poles strictly inside the unit circle.
    pub stable: bool,
    /// Where the loop was broken (`from -> to`).
    pub break_at: String,
    /// Width of the broken connection (1: SISO).
    pub width: usize,
    /// SISO margins.
    pub margins: Option<SisoMargins>,
    /// ‖S‖∞ (+∞ if the loop is unstable); NaN if not computed.
    pub s_hinf: f64,
    /// ‖T‖∞ (+∞ if the loop is unstable); NaN if not computed.
    pub t_hinf: f64,
    /// Generalised Nyquist count.
    pub nyquist: Option<Nyquist>,
    /// MIMO: smallest |1 + λ_i(L(e^{jωT}))| over the characteristic loci.
    pub loci_min_distance: Option<f64>,
    /// The criteria of the learning blocks of the loop (evaluated with the loop
    /// closed without them).
    pub learning: Vec<LearningCheck>,
    /// Anything the analysis could not do, or cross-checks that disagreed.
    pub notes: Vec<String>,
    /// The loop transfer L at the break (negative feedback: the loop is
    /// (I + L)⁻¹), when it was formed.
    pub loop_transfer: Option<StateSpace>,
    /// The circle criterion over the slope ranges of the loop's sector blocks
    /// (when it has any and the loop at the centre slopes is stable).
    pub circle: Option<CircleCheck>,
}

impl PointAnalysis {
    /// A point nothing has been computed for yet: no poles, NaN measures,
    /// not stable (what an analysis that stops early reports).
    fn unanalysed() -> Self {
        Self {
            label: String::new(),
            poles: Vec::new(),
            spectral_radius: f64::NAN,
            stable: false,
            break_at: String::new(),
            width: 0,
            margins: None,
            s_hinf: f64::NAN,
            t_hinf: f64::NAN,
            nyquist: None,
            loci_min_distance: None,
            learning: Vec::new(),
            notes: Vec::new(),
            loop_transfer: None,
            circle: None,
        }
    }
}

/// The circle criterion (small-gain form) of a loop with sector blocks
/// ([`Block::sector`]) at one schedule point: M is the transfer of the loop
/// closed at the centre slopes from signals added to the sector blocks' outputs
/// to their inputs, R = diag(r_i) their slope radii. ‖M R‖∞ < 1 proves the loop
/// stable for every slope history in the ranges.
#[derive(Debug, Clone, PartialEq)]
pub struct CircleCheck {
    /// The sector blocks: name and slope range [lower, upper].
    pub blocks: Vec<(String, f64, f64)>,
    /// ‖M R‖∞.
    pub norm: f64,
    /// ‖M‖∞ (for the fix: ‖M‖∞ < 1/max r_i suffices).
    pub m_norm: f64,
}

impl CircleCheck {
    /// ‖M R‖∞ < 1: the loop is stable for every slope history.
    pub fn holds(&self) -> bool {
        self.norm < 1.0
    }
    /// The largest slope radius r = (upper − lower)/2.
    pub fn max_radius(&self) -> f64 {
        self.blocks
            .iter()
            .map(|(_, a, b)| 0.5 * (b - a))
            .fold(0.0, f64::max)
    }
    /// What to change when the criterion fails.
    pub fn fix(&self) -> String {
        format!(
            "lower the loop gain until ‖M‖∞ = {:.4} < 1/r = {:.4}, or narrow the slope range",
            self.m_norm,
            1.0 / self.max_radius()
        )
    }
    fn ranges(&self) -> String {
        self.blocks
            .iter()
            .map(|(n, a, b)| format!("[{}, {}] of `{n}`", fmt_g(*a), fmt_g(*b)))
            .collect::<Vec<_>>()
            .join(", ")
    }
}

impl fmt::Display for CircleCheck {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "circle criterion: ‖M R‖∞ = {:.4} {} 1 over slopes {}",
            self.norm,
            if self.holds() { "<" } else { "≥" },
            self.ranges()
        )
    }
}

/// A number to 6 significant digits, trailing zeros dropped (`0.4`, `1.5e-7`).
fn fmt_g(x: f64) -> String {
    if x == 0.0 || !x.is_finite() {
        return format!("{x}");
    }
    let trim = |s: &str| -> String {
        if s.contains('.') {
            s.trim_end_matches('0').trim_end_matches('.').to_string()
        } else {
            s.to_string()
        }
    };
    let mag = x.abs().log10().floor() as i32;
    if (-3..6).contains(&mag) {
        trim(&format!("{:.*}", (5 - mag).max(0) as usize, x))
    } else {
        let s = format!("{x:.5e}");
        let (mantissa, exp) = s.split_once('e').unwrap_or((&s, "0"));
        format!("{}e{exp}", trim(mantissa))
    }
}

/// The analysis of one loop.
#[derive(Debug, Clone, PartialEq)]
pub struct LoopReport {
    /// Short name: the `require.loops` key that selects it, else a controller of
    /// the loop, else its first block.
    pub name: String,
    /// The user blocks of the loop (inserted rate transitions left out), in
    /// execution order.
    pub blocks: Vec<String>,
    /// Analysis rate (Hz).
    pub rate_hz: f64,
    /// How the rates were handled.
    pub method: String,
    /// Blocks judged on a linearisation, with what it leaves out.
    pub linearised: Vec<String>,
    /// Why the loop could not be analysed (empty: it was).
    pub unproven: Vec<String>,
    /// One analysis per combination of schedule points.
    pub points: Vec<PointAnalysis>,
    /// Required bounds the loop misses, one line each.
    pub violations: Vec<String>,
    /// The reason an unproven loop may run (`allow_unproven`).
    pub allowed: Option<String>,
    /// The sector blocks of the loop ([`Block::sector`]), judged at their
    /// centre slopes: name, centre slope k0 and slope range [lower, upper].
    pub sectors: Vec<(String, f64, f64, f64)>,
}

impl LoopReport {
    /// The loop was analysed (proven: not unproven) and every schedule point is
    /// stable.
    pub fn stable(&self) -> bool {
        self.unproven.is_empty() && !self.points.is_empty() && self.points_hold()
    }
    /// Every analysed schedule point is stable and its learning criteria hold
    /// (true when no point was analysed).
    fn points_hold(&self) -> bool {
        self.points
            .iter()
            .all(|p| p.stable && p.learning.iter().all(LearningCheck::holds))
    }
    /// Stable and within every bound; or unproven with a reason to run, and then
    /// still no analysed point unstable and no bound missed (an unproven loop is
    /// allowed to run without a proof, not with a known instability).
    pub fn passes(&self) -> bool {
        if self.unproven.is_empty() {
            self.stable() && self.violations.is_empty()
        } else {
            self.allowed.is_some() && self.points_hold() && self.violations.is_empty()
        }
    }
    /// One line per reason the loop fails the gate.
    pub fn failures(&self) -> Vec<String> {
        let mut v = Vec::new();
        if !self.unproven.is_empty() && self.allowed.is_none() {
            // A failed circle criterion carries its own fix.
            let circle_only = self.unproven.iter().all(|u| u.starts_with(CIRCLE_PREFIX));
            let allow = "state why it may run with `require: { allow_unproven: \"reason\" }`";
            v.push(if circle_only {
                format!(
                    "loop `{}` is unproven: {}; or {allow}",
                    self.name,
                    self.unproven.join("; ")
                )
            } else {
                format!(
                    "loop `{}` is unproven: {} (fix: give the block a linear model or a slope range, or {allow})",
                    self.name,
                    self.unproven.join("; ")
                )
            });
        }
        for p in &self.points {
            if !p.stable {
                v.push(format!(
                    "loop `{}`{} is unstable: closed-loop pole of modulus {:.6} ≥ 1{}",
                    self.name,
                    at_label(&p.label),
                    p.spectral_radius,
                    self.at_centre_slopes()
                ));
            }
            for c in p.learning.iter().filter(|c| !c.holds()) {
                v.push(format!(
                    "loop `{}`{}: learning block `{}` violates {}: ‖Q(z^-l − T L_c)‖∞ = {:.4} ≥ bound {:.4} (convergence not guaranteed; fix: {})",
                    self.name,
                    at_label(&p.label),
                    c.block,
                    c.criterion(),
                    c.hinf,
                    c.bound,
                    c.fix()
                ));
            }
        }
        for s in &self.violations {
            v.push(format!("loop `{}`: {s}", self.name));
        }
        v
    }
}

impl LoopReport {
    /// `" at the centre slope k0 = … of `b` (slope range [a, b])"`, or `""`
    /// without sector blocks.
    fn at_centre_slopes(&self) -> String {
        if self.sectors.is_empty() {
            return String::new();
        }
        let v: Vec<String> = self
            .sectors
            .iter()
            .map(|(n, k0, a, b)| {
                format!(
                    "k0 = {} of `{n}` (slope range [{}, {}])",
                    fmt_g(*k0),
                    fmt_g(*a),
                    fmt_g(*b)
                )
            })
            .collect();
        format!(" at the centre slope {}", v.join(", "))
    }
}

/// How the `linearised` entry of a sector block says what it is judged on.
const CENTRE_SLOPE: &str = "judged at the centre slope";

/// How an unproven reason from a failed circle criterion starts.
const CIRCLE_PREFIX: &str = "circle criterion";

fn at_label(label: &str) -> String {
    if label.is_empty() {
        String::new()
    } else {
        format!(" at {label}")
    }
}

/// The gate's verdict on a graph.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct GateReport {
    /// One report per feedback loop.
    pub loops: Vec<LoopReport>,
    /// Problems with the `require:` section itself.
    pub errors: Vec<String>,
}

impl GateReport {
    /// Every loop passes and `require:` is valid.
    pub fn passes(&self) -> bool {
        self.errors.is_empty() && self.loops.iter().all(LoopReport::passes)
    }
    /// Every loop was analysed and is stable (no loop unproven).
    pub fn proven(&self) -> bool {
        self.loops.iter().all(|l| l.unproven.is_empty())
    }
    /// One line per failure, naming the loop and the bound.
    pub fn failures(&self) -> Vec<String> {
        let mut v = self.errors.clone();
        for l in &self.loops {
            v.extend(l.failures());
        }
        v
    }
    /// Unproven loops allowed through, with their reasons.
    pub fn allowed(&self) -> Vec<String> {
        self.loops
            .iter()
            .filter(|l| !l.unproven.is_empty())
            .filter_map(|l| {
                l.allowed
                    .as_ref()
                    .map(|r| format!("loop `{}` runs unproven: {r}", l.name))
            })
            .collect()
    }

    /// The verdict of a check (`nanomotion check`): `Err` with one line per
    /// failure (loop and bound) when the gate refuses.
    pub fn verdict(&self) -> Result<(), String> {
        if self.passes() {
            return Ok(());
        }
        Err(format!(
            "the stability gate refuses the graph:\n  {}",
            self.failures().join("\n  ")
        ))
    }

    /// The rule before a run, one text for every front end: `Err` with the
    /// refusal if the gate refuses and `allow` is false; else the lines to
    /// print in the run's report (unproven loops allowed by `require:`, and,
    /// with `allow`, the failures the run goes ahead despite). `front` spells
    /// the check and the escape hatch the way the caller's users write them.
    pub fn before_run(&self, allow: bool, front: &FrontEnd) -> Result<Vec<String>, String> {
        let mut lines: Vec<String> = self.allowed();
        if self.passes() {
            return Ok(lines);
        }
        if !allow {
            return Err(format!(
                "the stability gate refuses the graph (see {}; fix the loop, or run anyway with {}):\n  {}",
                front.check,
                front.allow,
                self.failures().join("\n  ")
            ));
        }
        lines.push(format!(
            "the stability gate refused this graph; running anyway because of {}:",
            front.allow
        ));
        lines.extend(self.failures().into_iter().map(|f| format!("  {f}")));
        Ok(lines)
    }
}

/// How a front end (the CLI, the Python package) names the check and the
/// escape hatch in the gate's refusal ([`GateReport::before_run`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct FrontEnd {
    /// The command that shows the loops, e.g. ``"`nanomotion check`"``.
    pub check: &'static str,
    /// The option that runs anyway, e.g. `"--allow-unproven"`.
    pub allow: &'static str,
}

impl FrontEnd {
    /// The command line: `nanomotion check`, `--allow-unproven`.
    pub const CLI: FrontEnd = FrontEnd {
        check: "`nanomotion check`",
        allow: "--allow-unproven",
    };
    /// The Python package: `nanomotion.check`, `allow_unproven=True`.
    pub const PYTHON: FrontEnd = FrontEnd {
        check: "nanomotion.check",
        allow: "allow_unproven=True",
    };
}

fn db(x: f64) -> f64 {
    20.0 * x.log10()
}

fn num(x: f64, prec: usize) -> String {
    if x.is_nan() {
        "-".into()
    } else if x.is_infinite() {
        if x > 0.0 { "inf".into() } else { "-inf".into() }
    } else {
        format!("{x:.prec$}")
    }
}

impl fmt::Display for GateReport {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        if self.loops.is_empty() {
            writeln!(f, "stability gate: no feedback loops")?;
        } else {
            writeln!(
                f,
                "stability gate: {} feedback loop{}",
                self.loops.len(),
                if self.loops.len() == 1 { "" } else { "s" }
            )?;
            writeln!(
                f,
                "  {:<14} {:>9} {:>8} {:>8} {:>8} {:>8} {:>8} {:>9}  verdict",
                "loop", "max|pole|", "GM dB", "PM deg", "|S| dB", "|T| dB", "DM ms", "N (P)"
            )?;
        }
        for l in &self.loops {
            if !l.unproven.is_empty() && l.points.is_empty() {
                writeln!(
                    f,
                    "  {:<14} {:>9} {:>8} {:>8} {:>8} {:>8} {:>8} {:>9}  {}",
                    l.name,
                    "-",
                    "-",
                    "-",
                    "-",
                    "-",
                    "-",
                    "-",
                    if l.allowed.is_some() {
                        "UNPROVEN, allowed"
                    } else {
                        "UNPROVEN"
                    }
                )?;
            }
            for p in &l.points {
                let (gm, pm, dm) = p.margins.as_ref().map_or(
                    ("-".to_string(), "-".to_string(), "-".to_string()),
                    |m| {
                        (
                            num(m.gain_margin_db, 1),
                            num(m.phase_margin_deg, 1),
                            num(m.delay_margin_s * 1e3, 3),
                        )
                    },
                );
                let nyq = p.nyquist.map_or("-".to_string(), |n| {
                    format!("{} ({})", n.encirclements, n.open_loop_unstable)
                });
                let verdict = if !p.stable {
                    "UNSTABLE"
                } else if !p.learning.iter().all(LearningCheck::holds) {
                    "LEARNING FAILS"
                } else if !l.violations.is_empty() {
                    "VIOLATES"
                } else if !l.unproven.is_empty() {
                    if l.allowed.is_some() {
                        "UNPROVEN, allowed"
                    } else {
                        "UNPROVEN"
                    }
                } else if p.circle.is_some() {
                    "ok (circle)"
                } else if l.linearised.is_empty() {
                    "ok"
                } else {
                    "ok (linearised)"
                };
                let name = if p.label.is_empty() {
                    l.name.clone()
                } else {
                    format!("{} @{}", l.name, p.label)
                };
                writeln!(
                    f,
                    "  {:<14} {:>9.6} {:>8} {:>8} {:>8} {:>8} {:>8} {:>9}  {}",
                    name,
                    p.spectral_radius,
                    gm,
                    pm,
                    num(db(p.s_hinf), 2),
                    num(db(p.t_hinf), 2),
                    dm,
                    nyq,
                    verdict
                )?;
            }
        }
        for l in &self.loops {
            writeln!(f, "  loop `{}`: {}", l.name, l.blocks.join(" -> "))?;
            writeln!(f, "    analysed at {} Hz; {}", l.rate_hz, l.method)?;
            if let Some(p) = l.points.first() {
                writeln!(f, "    broken at {}", p.break_at)?;
            }
            for n in &l.linearised {
                if n.contains(CENTRE_SLOPE) {
                    writeln!(f, "    {n}")?;
                } else {
                    writeln!(f, "    judged on its linearisation: {n}")?;
                }
            }
            for u in &l.unproven {
                writeln!(f, "    unproven: {u}")?;
            }
            if let Some(r) = &l.allowed {
                writeln!(f, "    allowed to run unproven: {r}")?;
            }
            for p in &l.points {
                // (A failed one is among the `unproven` lines.)
                if let Some(c) = p.circle.as_ref().filter(|c| c.holds()) {
                    writeln!(f, "    {c}{}", at_label(&p.label))?;
                }
                for c in &p.learning {
                    writeln!(f, "    {c}")?;
                }
                if let Some(d) = p.loci_min_distance {
                    writeln!(
                        f,
                        "    characteristic loci{}: closest approach to -1 is {d:.4}",
                        at_label(&p.label)
                    )?;
                }
                for n in &p.notes {
                    writeln!(f, "    note{}: {n}", at_label(&p.label))?;
                }
            }
            for v in &l.violations {
                writeln!(f, "    VIOLATED: {v}")?;
            }
        }
        for e in &self.errors {
            writeln!(f, "  error: {e}")?;
        }
        Ok(())
    }
}

/// The model(s) of one block: points, the linearisation note if any, and the
/// block's slope range if it is judged at its centre slope.
type BlockModels = (Vec<(String, StateSpace)>, Option<String>, Option<Sector>);

/// The port index of the two extra ports of a sector block's part (an input
/// added to its output, an output equal to its input): no connection uses it,
/// so [`compose`] leaves them open and the transfer M of the circle criterion
/// can be read off the closed loop.
const SECTOR_PORT: usize = usize::MAX;

fn block_models(block: &dyn Block, w: &BlockWiring) -> Result<BlockModels, String> {
    let in_w: usize = w.inputs.iter().map(|p| p.width).sum();
    let out_w: usize = w.outputs.iter().map(|p| p.width).sum();
    let (points, note) = if w.type_name == "rate_transition" {
        (
            vec![(
                String::new(),
                StateSpace::gain(DMatrix::identity(out_w, in_w), None),
            )],
            None,
        )
    } else if block.learning().is_some() {
        // Learning blocks: the loop is analysed without them (w = 0) and their
        // criterion is checked on top (`learning.rs`).
        (
            vec![(
                String::new(),
                StateSpace::gain(DMatrix::zeros(out_w, in_w), None),
            )],
            None,
        )
    } else if let Some(lin) = block.linearisation() {
        if lin.points.is_empty() {
            return Err(format!(
                "`{}` ({}) declares a linearisation without a model",
                w.name, w.type_name
            ));
        }
        (lin.points, Some(format!("`{}`: {}", w.name, lin.note)))
    } else if let Some(m) = block.lti() {
        (vec![(String::new(), m)], None)
    } else if let Some(s) = block.sector() {
        if !(s.lower.is_finite() && s.upper.is_finite() && s.lower <= s.upper) {
            return Err(format!(
                "`{}` ({}) declares the slope range [{}, {}], not a finite range with lower ≤ upper",
                w.name, w.type_name, s.lower, s.upper
            ));
        }
        if in_w != out_w {
            return Err(format!(
                "`{}` ({}) declares a slope range but has {in_w} inputs and {out_w} outputs; a slope range pairs each output channel with its own input channel, so the block must be square",
                w.name, w.type_name
            ));
        }
        let k0 = s.centre();
        let note = format!(
            "`{}`: {CENTRE_SLOPE} k0 = {} of its slope range [{}, {}] ({}); the circle criterion covers every slope in the range",
            w.name,
            fmt_g(k0),
            fmt_g(s.lower),
            fmt_g(s.upper),
            s.note
        );
        let model = StateSpace::gain(DMatrix::identity(out_w, in_w) * k0, None);
        return Ok((vec![(String::new(), model)], Some(note), Some(s)));
    } else {
        return Err(format!(
            "`{}` ({}) has no linear model and no slope range",
            w.name, w.type_name
        ));
    };
    for (_, m) in &points {
        if m.ninputs() != in_w || m.noutputs() != out_w {
            return Err(format!(
                "`{}` ({}): its model is {}×{} but the block has {} inputs and {} outputs",
                w.name,
                w.type_name,
                m.noutputs(),
                m.ninputs(),
                in_w,
                out_w
            ));
        }
        if m.nstates() > 0 {
            match m.dt {
                Some(dt) if (dt - w.dt).abs() <= 1e-9 * w.dt => {}
                other => {
                    return Err(format!(
                        "`{}` ({}): its model has period {other:?} s but the block runs every {} s",
                        w.name, w.type_name, w.dt
                    ));
                }
            }
        }
    }
    Ok((points, note, None))
}

/// The part of block `i` with model `m`; a sector block (`sector`) gets the two
/// extra ports [`SECTOR_PORT`]: y = k0·u + w_extra, z_extra = u.
fn part_of(i: usize, w: &BlockWiring, m: &StateSpace, sector: bool) -> Part {
    let mut part = Part {
        a: m.a.clone(),
        b: m.b.clone(),
        c: m.c.clone(),
        d: m.d.clone(),
        inputs: w
            .inputs
            .iter()
            .enumerate()
            .map(|(k, p)| ((i, k), p.width))
            .collect(),
        outputs: w
            .outputs
            .iter()
            .enumerate()
            .map(|(k, p)| ((i, k), p.width))
            .collect(),
    };
    if sector {
        // A static gain k0·I (n × n): D = [k0·I, I; I, 0].
        let n = m.ninputs();
        let mut d = DMatrix::zeros(2 * n, 2 * n);
        d.view_mut((0, 0), (n, n)).copy_from(&m.d);
        d.view_mut((0, n), (n, n)).fill_with_identity();
        d.view_mut((n, 0), (n, n)).fill_with_identity();
        part.b = DMatrix::zeros(0, 2 * n);
        part.c = DMatrix::zeros(2 * n, 0);
        part.d = d;
        part.inputs.push(((i, SECTOR_PORT), n));
        part.outputs.push(((i, SECTOR_PORT), n));
    }
    part
}

/// Analyse every feedback loop of `sched` against `require`.
pub fn analyse(sched: &Scheduler, require: &Require) -> GateReport {
    let wiring = sched.wiring();
    let mut report = GateReport::default();
    if let Err(e) = require.validate() {
        report.errors.push(e);
    }
    let n = wiring.len();
    // Block graphs with and without the connections into scheduling inputs
    // (`Port::scheduling`): loops are found without them; a connection whose
    // two ends only share a loop through it is named in the report.
    let mut succ = vec![Vec::new(); n];
    let mut succ_all = vec![Vec::new(); n];
    for (d, w) in wiring.iter().enumerate() {
        for (k, &(s, _)) in w.sources.iter().enumerate() {
            if s >= n {
                continue;
            }
            if !succ_all[s].contains(&d) {
                succ_all[s].push(d);
            }
            if !is_scheduling(w, k) && !succ[s].contains(&d) {
                succ[s].push(d);
            }
        }
    }
    let comps = loops::cyclic_components(&succ);
    let comps_all = loops::cyclic_components(&succ_all);
    let roles: Vec<Role> = (0..n)
        .map(|i| sched.block_at(i).map_or(Role::Math, |b| b.role()))
        .collect();
    let user = |i: usize| {
        !wiring[i]
            .name
            .starts_with(crate::scheduler::RATE_TRANSITION_PREFIX)
    };
    for members in &comps {
        let blocks: Vec<String> = members
            .iter()
            .filter(|&&i| user(i))
            .map(|&i| wiring[i].name.clone())
            .collect();
        let key = require
            .loops
            .keys()
            .find(|k| blocks.iter().any(|b| b == *k))
            .cloned();
        let name = key.clone().unwrap_or_else(|| {
            members
                .iter()
                .find(|&&i| {
                    user(i) && sched.block_at(i).map(|b| b.role()) == Some(Role::Controller)
                })
                .or_else(|| members.iter().find(|&&i| user(i)))
                .map_or_else(
                    || wiring[members[0]].name.clone(),
                    |&i| wiring[i].name.clone(),
                )
        });
        let bounds = require.bounds_for(key.as_deref());
        let mut lr = analyse_loop(sched, &wiring, &roles, members, name, blocks);
        lr.linearised
            .extend(scheduling_cuts(&wiring, members, &comps_all));
        if !lr.unproven.is_empty() {
            lr.allowed = bounds.allow_unproven.clone();
        }
        // Bounds hold for every analysed point, proven or not.
        lr.violations = check_bounds(&lr, &bounds);
        report.loops.push(lr);
    }
    for k in require.loops.keys() {
        if !report.loops.iter().any(|l| l.blocks.iter().any(|b| b == k)) {
            let known: Vec<String> = report.loops.iter().map(|l| l.blocks.join(", ")).collect();
            report.errors.push(format!(
                "require.loops.{k}: no feedback loop contains a block `{k}` (fix: name a block of a loop; loops: {})",
                if known.is_empty() {
                    "none".to_string()
                } else {
                    known.join(" | ")
                }
            ));
        }
    }
    report
}

/// Whether input `k` of a block is a scheduling input
/// ([`Port::scheduling`](crate::block::Port::scheduling)).
fn is_scheduling(w: &BlockWiring, k: usize) -> bool {
    w.inputs.get(k).is_some_and(|p| p.scheduling)
}

/// The connections into scheduling inputs of the loop `members` that were cut:
/// those whose two ends would otherwise share a loop (`comps_all`, the cyclic
/// components with every connection), one note each.
fn scheduling_cuts(
    wiring: &[BlockWiring],
    members: &[usize],
    comps_all: &[Vec<usize>],
) -> Vec<String> {
    let mut notes = Vec::new();
    for &d in members {
        let Some(whole) = comps_all.iter().find(|c| c.binary_search(&d).is_ok()) else {
            continue;
        };
        for (k, &(s, sp)) in wiring[d].sources.iter().enumerate() {
            if is_scheduling(&wiring[d], k) && whole.binary_search(&s).is_ok() {
                notes.push(format!(
                    "`{}`: `{}` is a scheduling input, not a signal path: the connection {} is cut and the loop is judged with it frozen (the block's own criterion covers its variation)",
                    wiring[d].name,
                    wiring[d].inputs[k].name,
                    edge_text(wiring, ((s, sp), (d, k)))
                ));
            }
        }
    }
    notes
}

fn check_bounds(lr: &LoopReport, b: &Bounds) -> Vec<String> {
    let mut v = Vec::new();
    for p in &lr.points {
        let at = at_label(&p.label);
        if !p.stable {
            continue;
        }
        let siso_only = |v: &mut Vec<String>, what: &str| {
            if p.width == 1 {
                v.push(format!(
                    "{what} required but the margins could not be computed{at} ({})",
                    p.notes.join("; ")
                ));
            } else {
                v.push(format!(
                    "{what} required but not evaluated{at} (the loop is broken at a {}-wide connection; gain, phase and delay margins are SISO: bound modulus_margin_db / max_t_db instead)",
                    p.width
                ));
            }
        };
        if let Some(req) = b.gain_margin_db {
            match &p.margins {
                Some(m) if m.gain_margin_db >= req => {}
                Some(m) => v.push(format!(
                    "gain margin {:.2} dB{at} < required {req} dB (gain_margin_db)",
                    m.gain_margin_db
                )),
                None => siso_only(&mut v, "gain_margin_db"),
            }
        }
        if let Some(req) = b.phase_margin_deg {
            match &p.margins {
                Some(m) if m.phase_margin_deg >= req => {}
                Some(m) => v.push(format!(
                    "phase margin {:.2} deg{at} < required {req} deg (phase_margin_deg)",
                    m.phase_margin_deg
                )),
                None => siso_only(&mut v, "phase_margin_deg"),
            }
        }
        if let Some(req) = b.delay_margin_s {
            match &p.margins {
                Some(m) if m.delay_margin_s >= req => {}
                Some(m) => v.push(format!(
                    "delay margin {:.4e} s{at} < required {req} s (delay_margin_s)",
                    m.delay_margin_s
                )),
                None => siso_only(&mut v, "delay_margin_s"),
            }
        }
        if let Some(req) = b.modulus_margin_db {
            let s = db(p.s_hinf);
            if s.is_nan() || s > req {
                v.push(format!(
                    "‖S‖∞ = {} dB{at} > allowed {req} dB (modulus_margin_db: the Nyquist curve comes within {:.4} of -1, needs {:.4})",
                    num(s, 2),
                    1.0 / p.s_hinf,
                    10f64.powf(-req / 20.0)
                ));
            }
        }
        if let Some(req) = b.max_t_db {
            let t = db(p.t_hinf);
            if t.is_nan() || t > req {
                v.push(format!(
                    "‖T‖∞ = {} dB{at} > allowed {req} dB (max_t_db)",
                    num(t, 2)
                ));
            }
        }
    }
    v
}

fn analyse_loop(
    sched: &Scheduler,
    wiring: &[BlockWiring],
    roles: &[Role],
    members: &[usize],
    name: String,
    blocks: Vec<String>,
) -> LoopReport {
    let mut lr = LoopReport {
        name,
        blocks,
        rate_hz: 0.0,
        method: String::new(),
        linearised: Vec::new(),
        unproven: Vec::new(),
        points: Vec::new(),
        violations: Vec::new(),
        allowed: None,
        sectors: Vec::new(),
    };
    // Models.
    let mut models: Vec<Vec<(String, StateSpace)>> = Vec::with_capacity(members.len());
    // Sector blocks: (execution index, slope range).
    let mut sectors: Vec<(usize, Sector)> = Vec::new();
    for &i in members {
        let Some(block) = sched.block_at(i) else {
            lr.unproven.push(format!("block {i} missing"));
            continue;
        };
        match block_models(block, &wiring[i]) {
            Ok((points, note, sector)) => {
                if let Some(n) = note {
                    lr.linearised.push(n);
                }
                if let Some(s) = sector {
                    lr.sectors
                        .push((wiring[i].name.clone(), s.centre(), s.lower, s.upper));
                    sectors.push((i, s));
                }
                models.push(points);
            }
            Err(e) => lr.unproven.push(e),
        }
    }
    // Rates.
    let mut periods: Vec<u64> = members.iter().map(|&i| wiring[i].period).collect();
    periods.sort_unstable();
    periods.dedup();
    let slow = *periods.last().expect("a loop has blocks");
    let slow_dt = members
        .iter()
        .find(|&&i| wiring[i].period == slow)
        .map(|&i| wiring[i].dt)
        .expect("some block runs at the slowest period");
    lr.rate_hz = 1.0 / slow_dt;
    if let Some(w) = periods.windows(2).find(|w| w[1] % w[0] != 0) {
        lr.unproven.push(format!(
            "its rates are not nested ({} Hz does not divide into {} Hz); the loop cannot be lifted to one rate",
            1.0 / (slow_dt * w[0] as f64 / slow as f64),
            1.0 / (slow_dt * w[1] as f64 / slow as f64)
        ));
    }
    lr.method = if periods.len() == 1 {
        "single rate".to_string()
    } else {
        let fast: Vec<String> = periods[..periods.len() - 1]
            .iter()
            .map(|&p| format!("{} Hz", 1.0 / (slow_dt * p as f64 / slow as f64)))
            .collect();
        format!(
            "blocks at {} lifted exactly to it (zero-order-hold inputs, sampled outputs)",
            fast.join(", ")
        )
    };
    // Learning blocks: at the analysis rate, SISO error and output, the error
    // coming from inside the loop.
    let mut learners: Vec<(usize, LearningModel)> = Vec::new();
    for &i in members {
        let Some(lm) = sched.block_at(i).and_then(|b| b.learning()) else {
            continue;
        };
        let w = &wiring[i];
        let ok_ports = w.inputs.get(lm.error_input).is_some_and(|p| p.width == 1)
            && w.outputs.get(lm.output).is_some_and(|p| p.width == 1);
        if !ok_ports {
            lr.unproven.push(format!(
                "learning block `{}`: its error input or learning output is not a port of width 1",
                w.name
            ));
        } else if w.period != slow {
            lr.unproven.push(format!(
                "learning block `{}` runs faster than the loop's slowest rate; its criterion is evaluated at the analysis rate only",
                w.name
            ));
        } else if members.binary_search(&w.sources[lm.error_input].0).is_err() {
            lr.unproven.push(format!(
                "learning block `{}`: its error input does not come from the loop",
                w.name
            ));
        } else {
            lr.linearised.push(format!(
                "`{}`: learning block: the loop is analysed with its output w = 0, and its convergence criterion with that loop's T",
                w.name
            ));
            learners.push((i, lm));
        }
    }
    for (i, _) in &sectors {
        if wiring[*i].period != slow {
            lr.unproven.push(format!(
                "sector block `{}` runs faster than the loop's analysis rate {} Hz; the circle criterion is computed at the analysis rate, where the slope could change between the samples it sees (run the block at the loop's slowest rate)",
                wiring[*i].name, lr.rate_hz
            ));
        }
    }
    if !lr.unproven.is_empty() {
        return lr;
    }
    // Connections inside the loop (not those into scheduling inputs: the loop
    // is judged with its scheduling variables frozen).
    let idx = |i: usize| members.binary_search(&i).ok();
    let mut edges: Vec<Edge> = Vec::new();
    for &d in members {
        for (k, &(s, sp)) in wiring[d].sources.iter().enumerate() {
            if idx(s).is_some() && !is_scheduling(&wiring[d], k) {
                edges.push(((s, sp), (d, k)));
            }
        }
    }
    // Schedule-point combinations (mixed radix).
    let radix: Vec<usize> = models.iter().map(Vec::len).collect();
    let total = radix
        .iter()
        .try_fold(1usize, |acc, &r| acc.checked_mul(r))
        .unwrap_or(usize::MAX);
    let count = total.min(MAX_POINTS);
    for combo in 0..count {
        let mut rest = combo;
        let mut choice = Vec::with_capacity(radix.len());
        for &r in &radix {
            choice.push(rest % r);
            rest /= r;
        }
        let label: Vec<String> = members
            .iter()
            .zip(&choice)
            .zip(&models)
            .filter(|((_, _), m)| m.len() > 1)
            .map(|((&i, &c), m)| format!("{}: {}", wiring[i].name, m[c].0))
            .collect();
        let mut point = analyse_point(
            wiring, roles, members, &models, &choice, &edges, &periods, slow_dt, &learners,
            &sectors,
        );
        point.label = label.join(", ");
        if point.stable && !sectors.is_empty() {
            let at = at_label(&point.label);
            match &point.circle {
                Some(c) if c.holds() => {}
                Some(c) => lr.unproven.push(format!("{c}{at} (fix: {})", c.fix())),
                None => lr.unproven.push(format!(
                    "{CIRCLE_PREFIX} not evaluated{at}: {}",
                    point.notes.join("; ")
                )),
            }
        }
        if combo == 0 && total > count {
            point.notes.push(format!(
                "only the first {count} of {total} combinations of schedule points analysed"
            ));
        }
        lr.points.push(point);
    }
    lr
}

fn edge_text(wiring: &[BlockWiring], e: Edge) -> String {
    let ((s, sp), (d, dp)) = e;
    format!(
        "{}.{} -> {}.{}",
        wiring[s].name, wiring[s].outputs[sp].name, wiring[d].name, wiring[d].inputs[dp].name
    )
}

#[allow(clippy::too_many_arguments)]
fn analyse_point(
    wiring: &[BlockWiring],
    roles: &[Role],
    members: &[usize],
    models: &[Vec<(String, StateSpace)>],
    choice: &[usize],
    edges: &[Edge],
    periods: &[u64],
    slow_dt: f64,
    learners: &[(usize, LearningModel)],
    sectors: &[(usize, Sector)],
) -> PointAnalysis {
    let mut out = PointAnalysis::unanalysed();
    // Level by level, fastest first: compose, then lift to the next rate. A
    // connection is closed at the level of its slower end (once: the lifted part
    // keeps the ports of the connections already closed inside it).
    let period_of = |i: usize| wiring[i].period;
    let edges_at = |p: u64| -> Vec<Edge> {
        edges
            .iter()
            .copied()
            .filter(|&((s, _), (d, _))| period_of(s).max(period_of(d)) == p)
            .collect()
    };
    let mut carried: Option<Part> = None;
    let mut top_parts: Vec<Part> = Vec::new();
    for (li, &p) in periods.iter().enumerate() {
        let mut parts: Vec<Part> = members
            .iter()
            .enumerate()
            .filter(|&(_, &i)| wiring[i].period == p)
            .map(|(j, &i)| {
                let sector = sectors.iter().any(|(b, _)| *b == i);
                part_of(i, &wiring[i], &models[j][choice[j]].1, sector)
            })
            .collect();
        if let Some(c) = carried.take() {
            parts.push(c);
        }
        if li + 1 == periods.len() {
            top_parts = parts;
        } else {
            match compose(&parts, &edges_at(p), None) {
                Ok(c) => carried = Some(lift(&c, periods[li + 1] / p)),
                Err(e) => {
                    out.notes.push(e);
                    return out;
                }
            }
        }
    }
    let slow = *periods.last().expect("non-empty");
    let top = edges_at(slow);
    let closed = match compose(&top_parts, &top, None) {
        Ok(c) => c,
        Err(e) => {
            out.notes.push(e);
            return out;
        }
    };
    out.poles = crate::lti::linalg::eigvals(&closed.a);
    out.spectral_radius = out.poles.iter().map(|p| p.norm()).fold(0.0, f64::max);
    out.stable = out.spectral_radius < 1.0 - STABILITY_TOLERANCE;
    if out.stable && !sectors.is_empty() {
        let n = closed.a.nrows();
        if n > MAX_MARGIN_STATES {
            out.notes.push(format!(
                "the loop has {n} states; the circle criterion is computed up to {MAX_MARGIN_STATES}"
            ));
        } else {
            match circle_check(&closed, wiring, sectors, slow_dt) {
                Ok(c) => out.circle = Some(c),
                Err(e) => out.notes.push(format!("{CIRCLE_PREFIX}: {e}")),
            }
            if !learners.is_empty() {
                out.notes.push(
                    "the learning criteria are evaluated at the centre slopes of the sector blocks only".into(),
                );
            }
        }
    }
    // Break: a top-level connection, preferably a controller's output.
    let score = |e: &Edge| -> i32 {
        let ((s, _), (d, _)) = *e;
        let (rs, rd) = (roles[s], roles[d]);
        if rs == Role::Controller {
            3
        } else if rd == Role::Plant {
            2
        } else if rd == Role::Controller {
            1
        } else {
            0
        }
    };
    if out.stable {
        for (b, lm) in learners {
            match learning_t(&closed, &top, wiring, *b, lm, slow_dt).and_then(|t| {
                learning::criterion(&wiring[*b].name, &t, lm).map_err(|e| e.to_string())
            }) {
                Ok(c) => out.learning.push(c),
                Err(e) => out.notes.push(format!(
                    "learning block `{}`: criterion not evaluated: {e}",
                    wiring[*b].name
                )),
            }
        }
    }
    let is_learner = |i: usize| learners.iter().any(|(b, _)| *b == i);
    let Some(brk) = top
        .iter()
        .copied()
        .filter(|e| !is_learner(e.0.0) && !is_learner(e.1.0))
        .max_by_key(|e| (score(e), std::cmp::Reverse(e.1)))
    else {
        out.notes
            .push("no connection at the analysis rate to break the loop at".into());
        return out;
    };
    out.break_at = edge_text(wiring, brk);
    let open = match compose(&top_parts, &top, Some(brk)) {
        Ok(o) => o,
        Err(e) => {
            out.notes.push(format!("opening the loop: {e}"));
            return out;
        }
    };
    let (yo, w) = open.output_offset(brk.0).expect("break source in the loop");
    let (uo, _) = open
        .input_offset(brk.1)
        .expect("break destination in the loop");
    out.width = w;
    let nx = open.a.nrows();
    if nx > MAX_MARGIN_STATES {
        out.notes.push(format!(
            "the loop has {nx} states; margins, norms and the Nyquist count are computed up to {MAX_MARGIN_STATES}"
        ));
        return out;
    }
    // L = −G from the injected input to the returned output.
    let l = match StateSpace::new(
        open.a.clone(),
        -open.b.columns(uo, w).into_owned(),
        open.c.rows(yo, w).into_owned(),
        -open.d.view((yo, uo), (w, w)).into_owned(),
        Some(slow_dt),
    ) {
        Ok(l) => l,
        Err(e) => {
            out.notes.push(format!("loop transfer: {e}"));
            return out;
        }
    };
    loop_measures(&l, &mut out);
    out.loop_transfer = Some(l);
    out
}

/// The circle criterion of the loop `closed` at the centre slopes (stable):
/// M from the extra inputs [`SECTOR_PORT`] (added to the sector blocks'
/// outputs) to the extra outputs (their inputs), R = diag(r_i); returns
/// ‖M R‖∞ and ‖M‖∞.
fn circle_check(
    closed: &Part,
    wiring: &[BlockWiring],
    sectors: &[(usize, Sector)],
    dt: f64,
) -> Result<CircleCheck, String> {
    let mut cols: Vec<(usize, f64)> = Vec::new();
    let mut rows: Vec<usize> = Vec::new();
    let mut blocks = Vec::new();
    for (i, s) in sectors {
        let (i, r) = (*i, s.radius());
        let (uo, w) = closed
            .input_offset((i, SECTOR_PORT))
            .ok_or("a sector block is not at the analysis rate")?;
        let (yo, _) = closed
            .output_offset((i, SECTOR_PORT))
            .ok_or("a sector block is not at the analysis rate")?;
        cols.extend((uo..uo + w).map(|c| (c, r)));
        rows.extend(yo..yo + w);
        blocks.push((wiring[i].name.clone(), s.lower, s.upper));
    }
    let n = closed.a.nrows();
    let (m, p) = (cols.len(), rows.len());
    let b = DMatrix::from_fn(n, m, |x, j| closed.b[(x, cols[j].0)]);
    let c = DMatrix::from_fn(p, n, |k, x| closed.c[(rows[k], x)]);
    let d = DMatrix::from_fn(p, m, |k, j| closed.d[(rows[k], cols[j].0)]);
    let scale = DMatrix::from_diagonal(&nalgebra::DVector::from_iterator(
        m,
        cols.iter().map(|&(_, r)| r),
    ));
    let mm = StateSpace::new(closed.a.clone(), b, c, d, Some(dt)).map_err(|e| e.to_string())?;
    let mr = StateSpace::new(
        mm.a.clone(),
        &mm.b * &scale,
        mm.c.clone(),
        &mm.d * &scale,
        Some(dt),
    )
    .map_err(|e| e.to_string())?;
    let m_norm = hinfnorm(&mm).map_err(|e| e.to_string())?.norm;
    let norm = hinfnorm(&mr).map_err(|e| e.to_string())?.norm;
    Ok(CircleCheck {
        blocks,
        norm,
        m_norm,
    })
}

/// T = −(transfer from the learning output w to the learning block's error
/// input e) of the loop closed without learning (w injected at every input it
/// feeds).
fn learning_t(
    closed: &Part,
    top: &[Edge],
    wiring: &[BlockWiring],
    b: usize,
    lm: &LearningModel,
    dt: f64,
) -> Result<StateSpace, String> {
    let src = wiring[b].sources[lm.error_input];
    let (row, _) = closed
        .output_offset(src)
        .ok_or("the error input's source is not at the analysis rate")?;
    let n = closed.a.nrows();
    let mut bcol = DMatrix::zeros(n, 1);
    let mut d = 0.0;
    let mut any = false;
    for &(from, to) in top {
        if from == (b, lm.output) {
            let (col, _) = closed
                .input_offset(to)
                .ok_or("the learning output feeds a block outside the analysis rate")?;
            bcol += closed.b.column(col);
            d += closed.d[(row, col)];
            any = true;
        }
    }
    if !any {
        return Err("the learning output w does not feed the loop".into());
    }
    StateSpace::new(
        closed.a.clone(),
        -bcol,
        closed.c.rows(row, 1).into_owned(),
        DMatrix::from_element(1, 1, -d),
        Some(dt),
    )
    .map_err(|e| e.to_string())
}

/// Margins, norms and Nyquist count of the loop transfer `l` (discrete).
fn loop_measures(l: &StateSpace, out: &mut PointAnalysis) {
    let w = l.ninputs();
    let dt = l.dt.expect("discrete loop");
    let eye = StateSpace::gain(DMatrix::identity(w, w), Some(dt));
    if out.stable {
        match crate::lti::feedback(&eye, l, -1.0).and_then(|s| hinfnorm(&s)) {
            Ok(h) => out.s_hinf = h.norm,
            Err(e) => out.notes.push(format!("‖S‖∞: {e}")),
        }
        match crate::lti::feedback(l, &eye, -1.0).and_then(|t| hinfnorm(&t)) {
            Ok(h) => out.t_hinf = h.norm,
            Err(e) => out.notes.push(format!("‖T‖∞: {e}")),
        }
    } else {
        out.s_hinf = f64::INFINITY;
        out.t_hinf = f64::INFINITY;
    }
    // `l` was built by `StateSpace::new`, so it is valid: one reduction for
    // the margins, the loci and the Nyquist count.
    let ev = FrequencyEvaluator::new(l);
    if w == 1 {
        match crate::lti::margins::margins_with(l, &ev) {
            Ok(m) => {
                let hz = |w: f64| w / (2.0 * std::f64::consts::PI);
                let dm = if m.gain_crossover_rad_s.is_finite() && m.phase_margin_deg.is_finite() {
                    m.phase_margin_deg.to_radians() / m.gain_crossover_rad_s
                } else {
                    f64::INFINITY
                };
                out.margins = Some(SisoMargins {
                    gain_margin_db: db(m.gain_margin),
                    phase_margin_deg: m.phase_margin_deg,
                    modulus_margin: m.modulus_margin,
                    delay_margin_s: dm,
                    gain_crossover_hz: hz(m.gain_crossover_rad_s),
                    phase_crossover_hz: hz(m.phase_crossover_rad_s),
                });
            }
            Err(e) => out.notes.push(format!("margins: {e}")),
        }
    } else {
        out.loci_min_distance = loci_min_distance(l, &ev);
    }
    let ny = nyquist_count(l, &ev);
    let cl_out = out
        .poles
        .iter()
        .filter(|p| p.norm() > NYQUIST_RADIUS)
        .count() as i64;
    if ny.implied_unstable != cl_out {
        out.notes.push(format!(
            "Nyquist count implies {} closed-loop poles outside the unit circle, the eigenvalues {cl_out} (modes hidden from the break point?)",
            ny.implied_unstable
        ));
    }
    out.nyquist = Some(ny);
}

/// The contour radius of the Nyquist count: just outside the unit circle, so
/// that open-loop poles on it (integrators) are passed on the outside.
const NYQUIST_RADIUS: f64 = 1.0 + 1e-9;

/// det(I + L(z)).
fn det_i_plus_l(l: &FrequencyEvaluator, z: Complex<f64>) -> Complex<f64> {
    let g = l.evalfr(z);
    let n = g.nrows();
    let m = DMatrix::<Complex<f64>>::identity(n, n) + g;
    if n == 1 { m[(0, 0)] } else { m.determinant() }
}

/// The Nyquist count of the loop transfer `l` (reduced to `ev`).
fn nyquist_count(l: &StateSpace, ev: &FrequencyEvaluator) -> Nyquist {
    let p_out = l
        .poles()
        .iter()
        .filter(|p| p.norm() > NYQUIST_RADIUS)
        .count();
    let f = |theta: f64| det_i_plus_l(ev, Complex::from_polar(NYQUIST_RADIUS, theta));
    // Arg increments, subdividing where the phase moves more than 0.5 rad.
    let n0 = 1024;
    let mut total = 0.0;
    let pi = std::f64::consts::PI;
    let mut prev_t = -pi;
    let mut prev = f(prev_t);
    for i in 1..=n0 {
        let t = -pi + 2.0 * pi * i as f64 / n0 as f64;
        let v = f(t);
        total += arg_increment(&f, prev_t, prev, t, v, 0);
        prev_t = t;
        prev = v;
    }
    let enc = (total / (2.0 * pi)).round() as i64;
    Nyquist {
        encirclements: enc,
        open_loop_unstable: p_out,
        implied_unstable: p_out as i64 - enc,
    }
}

fn arg_increment(
    f: &dyn Fn(f64) -> Complex<f64>,
    t0: f64,
    v0: Complex<f64>,
    t1: f64,
    v1: Complex<f64>,
    depth: u32,
) -> f64 {
    let d = (v1 / v0).arg();
    if d.abs() < 0.5 || depth >= 40 {
        return d;
    }
    let tm = 0.5 * (t0 + t1);
    let vm = f(tm);
    arg_increment(f, t0, v0, tm, vm, depth + 1) + arg_increment(f, tm, vm, t1, v1, depth + 1)
}

/// Closest approach to −1 of the characteristic loci of `l` (reduced to `ev`)
/// on a grid of 512 frequencies up to Nyquist.
fn loci_min_distance(l: &StateSpace, ev: &FrequencyEvaluator) -> Option<f64> {
    let dt = l.dt?;
    let wn = std::f64::consts::PI / dt;
    let grid: Vec<f64> = (0..512)
        .map(|i| wn * 10f64.powf(-5.0 + 5.0 * i as f64 / 511.0))
        .collect();
    let resp: Vec<_> = grid.iter().map(|&w| ev.at(w)).collect();
    let loci = crate::analysis::mimo::characteristic_loci(&resp).ok()?;
    loci.iter()
        .flatten()
        .map(|lam| (lam + Complex::new(1.0, 0.0)).norm())
        .reduce(f64::min)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn point(label: &str, stable: bool) -> PointAnalysis {
        PointAnalysis {
            label: label.into(),
            spectral_radius: if stable { 0.5 } else { 1.2 },
            stable,
            width: 1,
            ..PointAnalysis::unanalysed()
        }
    }

    /// Issue 25: a loop can be unproven (the circle criterion fails at one
    /// schedule point) and have an unstable point; `allow_unproven` lets the
    /// first run, never the second.
    #[test]
    fn an_allowed_unproven_loop_with_an_unstable_point_still_fails() {
        let mut l = LoopReport {
            name: "c".into(),
            blocks: vec!["c".into()],
            rate_hz: 1000.0,
            method: String::new(),
            linearised: Vec::new(),
            unproven: vec![format!("{CIRCLE_PREFIX}: ‖M R‖∞ = 1.2 ≥ 1")],
            points: vec![point("K = 1", true), point("K = 9", false)],
            violations: Vec::new(),
            allowed: Some("bench".into()),
            sectors: vec![("h".into(), 0.7, 0.4, 1.0)],
        };
        assert!(!l.passes() && !l.stable());
        let f = l.failures();
        assert_eq!(f.len(), 1, "{f:?}");
        assert!(f[0].contains("at K = 9 is unstable") && f[0].contains("k0 = 0.7 of `h`"));
        l.points[1].stable = true;
        assert!(l.passes() && !l.stable());
        l.violations.push("gain margin 1 dB < required 6 dB".into());
        assert!(!l.passes());
        l.allowed = None;
        l.violations.clear();
        assert!(!l.passes());
        assert!(l.failures()[0].contains("≥ 1; or state why it may run"));
    }

    #[test]
    fn numbers_are_printed_short() {
        assert_eq!(fmt_g(2.0 * 0.7 - 1.0), "0.4");
        assert_eq!(fmt_g(1.0), "1");
        assert_eq!(fmt_g(-0.35), "-0.35");
        assert_eq!(fmt_g(1.5e-7), "1.5e-7");
        assert_eq!(fmt_g(123456.0), "123456");
        assert_eq!(fmt_g(1.5e7), "1.5e7");
    }
}
