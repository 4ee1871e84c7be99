//! `nanomotion rc-check GRAPH.yaml`: evaluate the stability criteria of every RC
//! block of a graph before it runs.
//!
//! For each `repetitive_control`, `high_order_rc` and `dvrc` block, T(z) is taken
//! from its `t_model`, or from its `learning` filter when that is a ZPETC of T,
//! or else ([`rc_check_file`]) from the block's feedback loop in the graph, as the
//! stability gate of `nanomotion check` assembles it; the filters are built at
//! the block's rate and
//!
//! - `repetitive_control`: criterion (5.5) (fixed N);
//! - `dvrc`: criterion (5.9) for N_k ∈ \[n_min, n_max\], plus, when the lifted
//!   system (5.13)–(5.15) is small enough, its two independent checks: the joint
//!   spectral radius bound ([`lifted_check`], lifted dimension ≤ 24 and at most 4
//!   delays) and the LMIs (5.16) ([`lifted_lmi_check`], at most
//!   [`LIFTED_LMI_MAX_UNKNOWNS`] scalar unknowns). A skipped check is reported with
//!   its size and limit. A DVRC block counts as stable if (5.9) holds, or if S is
//!   stable and a lifted check proves stability for every N_k ∈ \[m, M\] ((5.9)
//!   is only sufficient);
//! - `high_order_rc`: the small-gain condition ‖H‖∞·Σ|w_i| < 1 (sufficient; W(z)
//!   has ‖W‖∞ = Σ|w_i|) for a disturbance that does not depend on the loop; the
//!   report adds [`HIGH_ORDER_NOTE`]: when the disturbance is periodic in a variable
//!   the loop itself moves (α of the walking piezo), the condition is no guarantee.
//!
//! ```
//! let yaml = r#"
//! base_rate_hz: 1000
//! duration_s: 0.1
//! blocks:
//!   - name: rc
//!     type: dvrc
//!     n_min: 20
//!     n_max: 30
//!     learning: {kind: zpetc, num: [0.5], den: [1.0, -0.5]}
//!     robustness: {kind: fir_lowpass, taps: 5, cutoff_hz: 50}
//! connections: []
//! "#;
//! let spec = nanomotion_core::GraphSpec::from_yaml(yaml, "doc").unwrap();
//! let report = dvrc::check::rc_check_graph(&spec);
//! assert_eq!(report.blocks.len(), 1);
//! assert!(report.all_hold(), "{report}");
//! ```

use crate::filters::{Filter, FilterSpec};
use crate::rc::{Dvrc, HighOrderRc, RepetitiveControl, TfModel};
use crate::stability::{
    LIFTED_LMI_MAX_UNKNOWNS, LiftedCheck, LiftedLmi, LiftedLmiOptions, LiftedVerdict, RcCriterion,
    lifted_check, lifted_lmi_check, lifted_lmi_unknowns, loop_h, rc_criterion,
};
use nanomotion_core::GraphSpec;
use nanomotion_core::lti::{StateSpace, TransferFunction};
use std::fmt;

/// The check of one RC block.
#[derive(Debug, Clone)]
pub struct BlockCheck {
    /// Block instance name.
    pub name: String,
    /// `type:` of the block.
    pub type_name: String,
    /// The criterion, or why it could not be evaluated.
    pub criterion: Result<RcCriterion, String>,
    /// High-order RC: Σ|w_i| (the criterion must hold with ‖H‖∞·Σ|w_i| < 1).
    pub weight_sum: Option<f64>,
    /// The lifted joint-spectral-radius check, for small DVRC cases.
    pub lifted: Option<LiftedCheck>,
    /// Why the joint-spectral-radius check was skipped (DVRC blocks only).
    pub lifted_skipped: Option<String>,
    /// The lifted LMI check (5.16) (DVRC blocks only).
    pub lifted_lmi: Option<LiftedLmiOutcome>,
}

/// What happened to the LMI check (5.16) of a DVRC block.
#[derive(Debug, Clone)]
pub enum LiftedLmiOutcome {
    /// Solved (feasible or not).
    Solved(LiftedLmi),
    /// Too large for the dense solver.
    Skipped {
        /// Lifted dimension n_H + M_D (M_D the largest delay of the delay block).
        dim: usize,
        /// Number of delays (P_N matrices).
        n_delays: usize,
        /// Scalar unknowns.
        unknowns: usize,
        /// The limit ([`LIFTED_LMI_MAX_UNKNOWNS`]).
        limit: usize,
    },
    /// Could not be set up (e.g. n_min ≤ l + q) or the solver failed.
    Failed(String),
}

impl fmt::Display for LiftedLmiOutcome {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            LiftedLmiOutcome::Solved(l) => write!(f, "{l}"),
            LiftedLmiOutcome::Skipped {
                dim,
                n_delays,
                unknowns,
                limit,
            } => write!(
                f,
                "lifted LMIs (5.16) skipped: too large ({n_delays} P_N of size {dim} = {unknowns} scalar unknowns > limit {limit}); small cases only, as in the thesis"
            ),
            LiftedLmiOutcome::Failed(e) => write!(f, "lifted LMIs (5.16) not evaluated: {e}"),
        }
    }
}

impl BlockCheck {
    /// Whether stability is guaranteed: the small-gain criterion holds, or (DVRC)
    /// S is stable and a lifted check proves stability for every N_k ∈ \[m, M\].
    pub fn holds(&self) -> bool {
        self.small_gain_holds() || self.lifted_proves()
    }

    /// The frequency-domain criterion: (5.5), (5.9), or ‖H‖∞·Σ|w_i| < 1.
    pub fn small_gain_holds(&self) -> bool {
        match (&self.criterion, self.weight_sum) {
            (Ok(c), None) => c.holds(),
            (Ok(c), Some(ws)) => c.s_stable && c.hinf * ws < 1.0,
            (Err(_), _) => false,
        }
    }

    /// S is stable and the LMIs (5.16) are feasible or the joint spectral radius
    /// is proved < 1 (DVRC blocks).
    pub fn lifted_proves(&self) -> bool {
        let s_stable = matches!(&self.criterion, Ok(c) if c.s_stable);
        let lmi = matches!(&self.lifted_lmi, Some(LiftedLmiOutcome::Solved(l)) if l.feasible());
        let jsr = matches!(&self.lifted, Some(l) if l.verdict == LiftedVerdict::Stable);
        s_stable && self.weight_sum.is_none() && (lmi || jsr)
    }
}

/// Result of [`rc_check_graph`].
#[derive(Debug, Clone, Default)]
pub struct RcCheckReport {
    /// One entry per RC block, in graph order.
    pub blocks: Vec<BlockCheck>,
}

impl RcCheckReport {
    /// True if there is at least one RC block and every one passes.
    pub fn all_hold(&self) -> bool {
        !self.blocks.is_empty() && self.blocks.iter().all(|b| b.holds())
    }
}

impl fmt::Display for RcCheckReport {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        if self.blocks.is_empty() {
            return writeln!(
                f,
                "no repetitive_control / high_order_rc / dvrc blocks in the graph"
            );
        }
        for b in &self.blocks {
            write!(f, "{} ({}): ", b.name, b.type_name)?;
            match &b.criterion {
                Ok(c) => {
                    writeln!(f, "{c}")?;
                    if let Some(ws) = b.weight_sum {
                        writeln!(
                            f,
                            "    high-order: ‖H‖∞·Σ|w_i| = {:.4} (must be < 1) → {}",
                            c.hinf * ws,
                            if b.holds() {
                                "stability guaranteed"
                            } else {
                                "NOT guaranteed"
                            }
                        )?;
                        writeln!(f, "    {HIGH_ORDER_NOTE}")?;
                    }
                    if let Some(l) = &b.lifted {
                        writeln!(f, "    {l}")?;
                    }
                    if let Some(why) = &b.lifted_skipped {
                        writeln!(f, "    {why}")?;
                    }
                    if let Some(l) = &b.lifted_lmi {
                        writeln!(f, "    {l}")?;
                    }
                    if !b.small_gain_holds() && b.lifted_proves() {
                        writeln!(
                            f,
                            "    → stability guaranteed by the lifted system although the small-gain criterion fails (it is only sufficient)"
                        )?;
                    }
                }
                Err(e) => writeln!(f, "cannot check: {e}")?,
            }
        }
        writeln!(
            f,
            "{}",
            if self.all_hold() {
                "all RC blocks: stability guaranteed"
            } else {
                "some RC block is NOT guaranteed stable"
            }
        )
    }
}

/// Printed under every `high_order_rc` block: what the small-gain condition does
/// not cover (docs/repetitive-control.md, "High-order RC and the α-feedback path").
pub const HIGH_ORDER_NOTE: &str = "note: ‖H‖∞·Σ|w_i| < 1 covers a disturbance that does not depend on the loop; when it is periodic in a variable the loop moves (the walking piezo's leg angle α = 2π∫f_α dt, f_α from u) the loop is not LTI and this is no guarantee: on the walking-piezo Table 5.1 loops high-order RC ends above no RC although it holds (docs/repetitive-control.md)";

/// T(z) of a block: its `t_model`, a ZPETC learning filter's T, or else the T
/// the stability gate assembled from the block's loop in the graph (`graph_t`).
fn t_of(
    t: Option<TfModel>,
    dt: f64,
    graph_t: Result<Option<&StateSpace>, &str>,
) -> Result<StateSpace, String> {
    let Some(t) = t else {
        return match graph_t {
            Ok(Some(t)) => Ok(t.clone()),
            Ok(None) => Err("no T(z): the block is in no stable feedback loop the stability gate could analyse (`nanomotion check` shows why); give `t_model: {num, den}` or a `learning: {kind: zpetc, ...}`".to_string()),
            Err(e) => Err(format!("no T(z): the graph could not be built to take T from its loop ({e}); give `t_model: {{num, den}}` or a `learning: {{kind: zpetc, ...}}`")),
        };
    };
    TransferFunction::new(t.num, t.den, Some(dt))
        .and_then(|tf| tf.to_ss_cascade())
        .map_err(|e| format!("t_model: {e}"))
}

/// The T(z) of every learning block of `spec`'s feedback loops, as the stability
/// gate assembles it (block name → T), or why the graph could not be built.
pub fn graph_loop_ts(
    spec: GraphSpec,
) -> Result<std::collections::BTreeMap<String, StateSpace>, String> {
    let require = spec.require.clone().unwrap_or_default();
    let built = if spec.reads_data() {
        spec.build_without_data()
    } else {
        spec.build()
    };
    let (sched, _) = built.map_err(|e| e.to_string())?;
    let report = nanomotion_core::gate::analyse(&sched, &require);
    Ok(report
        .loops
        .iter()
        .filter_map(|l| l.points.first())
        .flat_map(|p| p.learning.iter().map(|c| (c.block.clone(), c.t.clone())))
        .collect())
}

fn filters(l: &FilterSpec, q: &FilterSpec, dt: f64) -> Result<(Filter, Filter), String> {
    let lf = l.build_named("learning", dt).map_err(|e| e.to_string())?;
    let qf = q.build_named("robustness", dt).map_err(|e| e.to_string())?;
    Ok((lf, qf))
}

/// Largest lifted dimension (H states + delay-block states) for the automatic
/// joint-spectral-radius check.
const LIFTED_MAX_DIM: usize = 24;
/// Most delays (M − m + 1) for the automatic joint-spectral-radius check (the
/// branch and bound grows like delays^depth).
const LIFTED_MAX_DELAYS: usize = 4;

/// Check every RC block of `spec` (see the [module docs](self)); T(z) comes
/// from `t_model` or a ZPETC learning filter only (see [`rc_check_file`]).
pub fn rc_check_graph(spec: &GraphSpec) -> RcCheckReport {
    rc_check_graph_with(spec, Ok(&Default::default()))
}

/// [`rc_check_graph`] with the T(z) of the graph's loops ([`graph_loop_ts`]) for
/// blocks that have neither `t_model` nor a ZPETC learning filter.
pub fn rc_check_graph_with(
    spec: &GraphSpec,
    graph_ts: Result<&std::collections::BTreeMap<String, StateSpace>, &str>,
) -> RcCheckReport {
    let mut out = RcCheckReport::default();
    for b in &spec.blocks {
        let Ok(v) = serde_json::to_value(&b.block) else {
            continue;
        };
        let ty = v
            .get("type")
            .and_then(|t| t.as_str())
            .unwrap_or("")
            .to_string();
        if !matches!(ty.as_str(), "repetitive_control" | "high_order_rc" | "dvrc") {
            continue;
        }
        let mut body = v.clone();
        if let Some(o) = body.as_object_mut() {
            o.remove("type");
        }
        let dt = 1.0 / b.rate_hz.unwrap_or(spec.base_rate_hz);
        let graph_t = graph_ts.map(|m| m.get(&b.name));
        let mut check = BlockCheck {
            name: b.name.clone(),
            type_name: ty.clone(),
            criterion: Err(String::new()),
            weight_sum: None,
            lifted: None,
            lifted_skipped: None,
            lifted_lmi: None,
        };
        let res: Result<(), String> = (|| {
            match ty.as_str() {
                "repetitive_control" => {
                    let p: RepetitiveControl =
                        serde_json::from_value(body).map_err(|e| e.to_string())?;
                    let t = t_of(TfModel::resolve(&p.t_model, &p.learning), dt, graph_t)?;
                    let (l, q) = filters(&p.learning, &p.robustness, dt)?;
                    check.criterion = rc_criterion(&t, &l, &q, p.n, p.n).map_err(|e| e.to_string());
                }
                "high_order_rc" => {
                    let p: HighOrderRc = serde_json::from_value(body).map_err(|e| e.to_string())?;
                    let t = t_of(TfModel::resolve(&p.t_model, &p.learning), dt, graph_t)?;
                    let (l, q) = filters(&p.learning, &p.robustness, dt)?;
                    check.criterion = rc_criterion(&t, &l, &q, p.n, p.n).map_err(|e| e.to_string());
                    check.weight_sum = Some(p.weights.iter().map(|w| w.abs()).sum());
                }
                _ => {
                    let p: Dvrc = serde_json::from_value(body).map_err(|e| e.to_string())?;
                    let t = t_of(TfModel::resolve(&p.t_model, &p.learning), dt, graph_t)?;
                    let (l, q) = filters(&p.learning, &p.robustness, dt)?;
                    check.criterion =
                        rc_criterion(&t, &l, &q, p.n_min, p.n_max).map_err(|e| e.to_string());
                    let comp = crate::stability::compensation(&l, &q);
                    if p.n_min > comp {
                        let h = loop_h(&t, &l, &q).map_err(|e| e.to_string())?;
                        let (dmin, dmax) = (p.n_min - comp, p.n_max - comp);
                        let dim = h.nstates() + dmax;
                        let n_delays = dmax - dmin + 1;
                        if dim <= LIFTED_MAX_DIM && n_delays <= LIFTED_MAX_DELAYS {
                            check.lifted = Some(lifted_check(&h, dmin, dmax, 20_000));
                        } else {
                            check.lifted_skipped = Some(format!(
                                "lifted joint-spectral-radius check skipped: too large (lifted dimension {dim}, limit {LIFTED_MAX_DIM}; {n_delays} delays, limit {LIFTED_MAX_DELAYS})"
                            ));
                        }
                        let unknowns = lifted_lmi_unknowns(h.nstates(), dmin, dmax);
                        check.lifted_lmi = Some(if unknowns > LIFTED_LMI_MAX_UNKNOWNS {
                            LiftedLmiOutcome::Skipped {
                                dim,
                                n_delays,
                                unknowns,
                                limit: LIFTED_LMI_MAX_UNKNOWNS,
                            }
                        } else {
                            match lifted_lmi_check(&h, dmin, dmax, &LiftedLmiOptions::default()) {
                                Ok(r) => LiftedLmiOutcome::Solved(r),
                                Err(e) => LiftedLmiOutcome::Failed(e.to_string()),
                            }
                        });
                    } else {
                        let why = format!(
                            "n_min = {} ≤ l + q = {comp}: the delay block would need a delay < 1",
                            p.n_min
                        );
                        check.lifted_skipped = Some(format!("lifted checks skipped: {why}"));
                    }
                }
            }
            Ok(())
        })();
        if let Err(e) = res {
            check.criterion = Err(e);
        }
        out.blocks.push(check);
    }
    out
}

/// [`rc_check_graph`] on a YAML file (the error is boxed: `GraphError` is large),
/// with T(z) taken from the graph's loops, as `nanomotion check` assembles it,
/// for blocks without `t_model` or a ZPETC learning filter.
pub fn rc_check_file(
    path: &std::path::Path,
) -> Result<RcCheckReport, Box<nanomotion_core::GraphError>> {
    let spec = GraphSpec::from_file(path).map_err(Box::new)?;
    let ts = graph_loop_ts(GraphSpec::from_file(path).map_err(Box::new)?);
    Ok(rc_check_graph_with(
        &spec,
        ts.as_ref().map_err(String::as_str),
    ))
}

#[cfg(test)]
mod tests {
    use super::*;

    const GRAPH: &str = r#"
base_rate_hz: 1000
duration_s: 0.1
blocks:
  - name: ho
    type: high_order_rc
    n: 40
    learning: {kind: zpetc, num: [0.5], den: [1.0, -0.5]}
    robustness: {kind: fir_lowpass, taps: 5, cutoff_hz: 50}
  - name: rc
    type: repetitive_control
    n: 40
    learning: {kind: zpetc, num: [0.5], den: [1.0, -0.5]}
    robustness: {kind: fir_lowpass, taps: 5, cutoff_hz: 50}
connections: []
"#;

    /// The α-feedback note is printed once per high-order RC block, not for others.
    #[test]
    fn high_order_blocks_carry_the_alpha_feedback_note() {
        let spec = GraphSpec::from_yaml(GRAPH, "test").unwrap();
        let report = rc_check_graph(&spec);
        assert_eq!(report.blocks.len(), 2);
        let text = report.to_string();
        assert_eq!(text.matches(HIGH_ORDER_NOTE).count(), 1, "{text}");
        let ho_part = text.split("rc (repetitive_control)").next().unwrap();
        assert!(ho_part.contains(HIGH_ORDER_NOTE), "{text}");
    }
}
