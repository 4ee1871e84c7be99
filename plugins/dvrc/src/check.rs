//! `nanomotion rc-check GRAPH.yaml`: evaluate the stability criteria of every RC
//! block of a graph before it runs.
//!
//! For each `repetitive_control`, `high_order_rc` and `dvrc` block, T(z) is taken
//! from its `t_model`, or from its `learning` filter when that is a ZPETC of T;
//! the filters are built at the block's rate and
//!
//! - `repetitive_control`: criterion (5.5) (fixed N);
//! - `dvrc`: criterion (5.9) for N_k ∈ \[n_min, n_max\], plus the lifted check
//!   (5.13)–(5.16) when the case is small;
//! - `high_order_rc`: the small-gain condition ‖H‖∞·Σ|w_i| < 1 (sufficient; W(z)
//!   has ‖W‖∞ = Σ|w_i|).
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
use crate::stability::{LiftedCheck, RcCriterion, lifted_check, loop_h, rc_criterion};
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
    /// The lifted check, for small DVRC cases.
    pub lifted: Option<LiftedCheck>,
}

impl BlockCheck {
    /// Whether stability is guaranteed.
    pub fn holds(&self) -> bool {
        match (&self.criterion, self.weight_sum) {
            (Ok(c), None) => c.holds(),
            (Ok(c), Some(ws)) => c.s_stable && c.hinf * ws < 1.0,
            (Err(_), _) => false,
        }
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
                    }
                    if let Some(l) = &b.lifted {
                        writeln!(f, "    {l}")?;
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

fn t_of(t: Option<TfModel>, dt: f64) -> Result<StateSpace, String> {
    let t = t.ok_or_else(|| {
        "no T(z): give `t_model: {num, den}` or a `learning: {kind: zpetc, ...}`".to_string()
    })?;
    TransferFunction::new(t.num, t.den, Some(dt))
        .and_then(|tf| tf.to_ss_cascade())
        .map_err(|e| format!("t_model: {e}"))
}

fn filters(l: &FilterSpec, q: &FilterSpec, dt: f64) -> Result<(Filter, Filter), String> {
    let lf = l.build_named("learning", dt).map_err(|e| e.to_string())?;
    let qf = q.build_named("robustness", dt).map_err(|e| e.to_string())?;
    Ok((lf, qf))
}

/// Largest lifted case (delay-block states + H states) checked automatically.
const LIFTED_MAX_DIM: usize = 24;

/// Check every RC block of `spec` (see the [module docs](self)).
pub fn rc_check_graph(spec: &GraphSpec) -> RcCheckReport {
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
        let mut check = BlockCheck {
            name: b.name.clone(),
            type_name: ty.clone(),
            criterion: Err(String::new()),
            weight_sum: None,
            lifted: None,
        };
        let res: Result<(), String> = (|| {
            match ty.as_str() {
                "repetitive_control" => {
                    let p: RepetitiveControl =
                        serde_json::from_value(body).map_err(|e| e.to_string())?;
                    let t = t_of(TfModel::resolve(&p.t_model, &p.learning), dt)?;
                    let (l, q) = filters(&p.learning, &p.robustness, dt)?;
                    check.criterion = rc_criterion(&t, &l, &q, p.n, p.n).map_err(|e| e.to_string());
                }
                "high_order_rc" => {
                    let p: HighOrderRc = serde_json::from_value(body).map_err(|e| e.to_string())?;
                    let t = t_of(TfModel::resolve(&p.t_model, &p.learning), dt)?;
                    let (l, q) = filters(&p.learning, &p.robustness, dt)?;
                    check.criterion = rc_criterion(&t, &l, &q, p.n, p.n).map_err(|e| e.to_string());
                    check.weight_sum = Some(p.weights.iter().map(|w| w.abs()).sum());
                }
                _ => {
                    let p: Dvrc = serde_json::from_value(body).map_err(|e| e.to_string())?;
                    let t = t_of(TfModel::resolve(&p.t_model, &p.learning), dt)?;
                    let (l, q) = filters(&p.learning, &p.robustness, dt)?;
                    check.criterion =
                        rc_criterion(&t, &l, &q, p.n_min, p.n_max).map_err(|e| e.to_string());
                    let comp = crate::stability::compensation(&l, &q);
                    if p.n_min > comp {
                        let h = loop_h(&t, &l, &q).map_err(|e| e.to_string())?;
                        let (dmin, dmax) = (p.n_min - comp, p.n_max - comp);
                        if h.nstates() + dmax <= LIFTED_MAX_DIM && dmax - dmin <= 3 {
                            check.lifted = Some(lifted_check(&h, dmin, dmax, 20_000));
                        }
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

/// [`rc_check_graph`] on a YAML file (the error is boxed: `GraphError` is large).
pub fn rc_check_file(
    path: &std::path::Path,
) -> Result<RcCheckReport, Box<nanomotion_core::GraphError>> {
    Ok(rc_check_graph(
        &GraphSpec::from_file(path).map_err(Box::new)?,
    ))
}
