//! Parameter updates while the loop runs: `set ctrl.kp=1.2` from the terminal,
//! [`ParamSender::set`] from Rust.
//!
//! A block declares the parameters it can change between two ticks, keeping
//! its state, in its `#[block(live = "…")]`
//! ([`DeclaredBlock::LIVE_PARAMS`](nanomotion_core::block::DeclaredBlock::LIVE_PARAMS),
//! its [`Block::live_params`]); `nanomotion blocks` shows them per block and
//! [`live_params_by_type`](nanomotion_core::doc::live_params_by_type) lists
//! every registered block's (the list docs/realtime.md holds, by a test).
//! An update is resolved and judged **outside** the loop, by the
//! [`ParamSender`] on the caller's thread:
//!
//! 1. the path (`ctrl.kp` or `blocks.ctrl.kp`, the grammar of `--set`) to a
//!    row of the graph's table of live parameters ([`live_params`]);
//! 2. the value by the block's own validation: a copy of the block, with the
//!    parameters accepted so far and the new value, is built with the block's
//!    own build context; a refusal is the block's message;
//! 3. optionally ([`ParamSender::gated`]) by the stability gate on a copy of
//!    the graph that is never ticked: an update that makes a loop fail the
//!    gate where it passed before is refused with the gate's reason and the
//!    loop's margins with the values accepted so far. When the loop closes
//!    through a device that knows a model of its plant
//!    ([`ParamSender::gated_through`]), the copy is that loop — the graph
//!    joined with the device's plant and latency, as the gate judges it before
//!    the run ([`crate::through`]).
//!
//! What crosses into the loop is a [`ParamUpdate`] — the row and the `f64` —
//! through a wait-free single-producer/single-consumer ring ([`rtrb`]). The
//! loop takes every waiting update at the next tick boundary, before the
//! tick's device read, and calls the block's
//! [`set_live_param`](nanomotion_core::Block::set_live_param) (no allocation,
//! lock or look-up); the update is an [`Event::Param`](crate::Event::Param)
//! with the tick it took effect at (the first tick computed with it) and, when
//! recording, a sample of the recording's `param/BLOCK.PARAM` channel, which
//! [`replay`](crate::replay) applies before the same tick.
//!
//! ```
//! use nanomotion_core::GraphSpec;
//! use nanomotion_rt::{Event, LiveError, NoDevice, RealtimeRunner, RtConfig};
//! let yaml = "base_rate_hz: 1000\nduration_s: 0.01\nblocks:\n  - { name: one, type: constant, value: 1.0 }\n  - { name: k, type: gain, k: 2.0 }\nconnections:\n  - { from: one.y, to: k.u }\nlog: [k.y]\n";
//! let (sched, _) = GraphSpec::from_yaml(yaml, "doc.yaml").unwrap().build().unwrap();
//! let mut cfg = RtConfig::default();
//! cfg.allow_soft = true;
//! let mut runner = RealtimeRunner::new(sched, NoDevice, cfg).unwrap();
//! let mut sender = runner.param_sender().unwrap();
//! sender.set("k.k", 3.0).unwrap(); // before the run: takes effect at tick 0
//! assert!(matches!(sender.set("k.kk", 3.0), Err(LiveError::Path { .. })));
//! let mut applied = Vec::new();
//! runner.run(|e| if let Event::Param { tick, .. } = e { applied.push(tick) }).unwrap();
//! assert_eq!(applied, [0]);
//! let (y, _, _) = runner.scheduler().log_view("k.y").unwrap();
//! assert!(y.iter().all(|&v| v == 3.0));
//! ```

use crate::Device;
use crate::through::{ThroughError, joined_through_device};
use nanomotion_core::error::{GraphError, ParamError};
use nanomotion_core::gate::Require;
use nanomotion_core::gate::{self, GateReport, SisoMargins};
use nanomotion_core::overrides::{Override, Segment};
use nanomotion_core::{Block, BuildContext};
use nanomotion_core::{GraphSpec, Scheduler};

/// One parameter update on its way into the loop: a row of the graph's table
/// of live parameters ([`live_params`]) and the new value. Plain data: the
/// loop needs no string or look-up to apply it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ParamUpdate {
    /// Row of the table of live parameters.
    pub param: u32,
    /// The new value.
    pub value: f64,
}

/// A parameter of a built graph that can change while it runs.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct LiveParam {
    /// `BLOCK.PARAM`, e.g. `ctrl.kp`.
    pub path: String,
    /// The block's execution index.
    pub block: usize,
    /// The parameter's slot in the block's
    /// [`live_params`](nanomotion_core::Block::live_params).
    pub slot: usize,
    /// The parameter's name (`kp`).
    pub name: &'static str,
}

/// Every live parameter of `sched`: blocks in execution order, each block's
/// parameters in its own order. Row `i` is what [`ParamUpdate::param`] `= i`
/// means.
pub fn live_params(sched: &Scheduler) -> Vec<LiveParam> {
    let mut out = Vec::new();
    for (i, name) in sched.block_names().iter().enumerate() {
        let Some(b) = sched.block_at(i) else { continue };
        for (slot, p) in b.live_params().iter().enumerate() {
            out.push(LiveParam {
                path: format!("{name}.{p}"),
                block: i,
                slot,
                name: p,
            });
        }
    }
    out
}

/// Why a live update was refused. It never reached the loop.
#[derive(Debug, thiserror::Error)]
pub enum LiveError {
    /// The text is not `PATH=VALUE`.
    #[error("{0}")]
    Syntax(Box<GraphError>),
    /// The path names no live parameter.
    #[error("`{path}`: {problem} (fix: {fix})")]
    Path {
        /// The path as given.
        path: String,
        /// What is wrong with it.
        problem: String,
        /// How to fix it.
        fix: String,
    },
    /// The value is not a finite number.
    #[error("`{path}`: `{value}` is not a finite number (fix: give a number, e.g. `{path}=1.2`)")]
    NotANumber {
        /// The path.
        path: String,
        /// The value as given.
        value: String,
    },
    /// The block's own validation refused the value.
    #[error("`{path}` = {value} refused by block `{block}` ({type_name}): {source}")]
    Refused {
        /// The path.
        path: String,
        /// The value.
        value: f64,
        /// The block.
        block: String,
        /// Its type.
        type_name: String,
        /// The block's own message, field and fix.
        source: Box<ParamError>,
    },
    /// The stability gate passed with the current parameters and fails with
    /// the new value.
    #[error(
        "`{path}` = {value} refused by the stability gate{}: {}{} (fix: give a value with which the loop passes; `nanomotion check GRAPH` prints the margins of the graph as written)",
        through.as_ref().map_or(String::new(), |t| format!(" on {t}")),
        reasons.join("; "),
        margins_text(margins)
    )]
    Gate {
        /// The path.
        path: String,
        /// The value.
        value: f64,
        /// The gate's failures with the value, one per loop.
        reasons: Vec<String>,
        /// The margins, with the values accepted so far, of each loop the
        /// value makes fail (its first operating point; none for a loop
        /// without SISO margins).
        margins: Vec<(String, SisoMargins)>,
        /// `Some` when the loop judged closes through a device
        /// ([`ParamSender::gated_through`]): `the loop through device `NAME`
        /// with its latency of N ticks`.
        through: Option<String>,
    },
    /// The loop through the device cannot be joined or built for the gate
    /// ([`ParamSender::gated_through`]).
    #[error("the stability gate's copy of the loop through the device: {0}")]
    Through(Box<ThroughError>),
    /// More updates than the run takes.
    #[error(
        "`{path}`: {limit} updates already sent, the most one run takes (fix: raise RtConfig::max_param_updates, or start a new run)"
    )]
    Limit {
        /// The path.
        path: String,
        /// The limit.
        limit: usize,
    },
    /// The ring into the loop is full: the loop has not taken the updates
    /// already sent (it takes all of them at every tick boundary).
    #[error(
        "`{path}`: {slots} updates are waiting for the loop (fix: send again after a tick; the loop takes them at every tick boundary, so the ring fills only when the loop is not running)"
    )]
    Full {
        /// The path.
        path: String,
        /// Slots of the ring.
        slots: usize,
    },
    /// The loop is gone (the runner was dropped).
    #[error("`{path}`: the loop has ended; the update was not applied")]
    Closed {
        /// The path.
        path: String,
    },
    /// The gate's copy of the graph did not build
    /// ([`ParamSender::gated_spec`]).
    #[error("the stability gate's copy of the graph did not build: {0}")]
    Copy(Box<GraphError>),
    /// [`ParamSender::gated`] was given another graph.
    #[error(
        "the gate's copy of the graph is not the graph that runs (blocks {copy:?} vs {runs:?}) (fix: build the copy from the same file and overrides)"
    )]
    NotTheSameGraph {
        /// Blocks of the copy.
        copy: Vec<String>,
        /// Blocks of the graph that runs.
        runs: Vec<String>,
    },
}

/// `; with the values accepted so far loop `pi` had phase margin 76.16°,
/// delay margin 10.3669 ms` (nothing for no margins).
fn margins_text(margins: &[(String, SisoMargins)]) -> String {
    if margins.is_empty() {
        return String::new();
    }
    let each: Vec<String> = margins
        .iter()
        .map(|(name, m)| {
            format!(
                "loop `{name}` had phase margin {:.2}°, delay margin {:.4} ms",
                m.phase_margin_deg,
                m.delay_margin_s * 1e3
            )
        })
        .collect();
    format!("; with the values accepted so far {}", each.join(", "))
}

/// A block with live parameters, as the sender judges it: its parameters as
/// last accepted (serde form) and its build context.
struct Judge {
    name: String,
    type_name: String,
    params: serde_json::Value,
    ctx: BuildContext,
}

/// The stability gate on a copy of the graph that is never ticked: the graph
/// itself, or the loop it closes through a device.
struct Gate {
    shadow: Scheduler,
    require: Require,
    /// Block `i` of the graph that runs is block `index[i]` of the copy
    /// (`None`: a block without live parameters the copy need not hold).
    index: Vec<Option<usize>>,
    /// Each loop with the parameters accepted so far: whether it passed, and
    /// its margins (first operating point).
    accepted: Vec<(bool, Option<SisoMargins>)>,
    /// What the copy is, for the refusal, when it is a loop through a device.
    through: Option<String>,
}

impl Gate {
    /// Each loop of `report`: whether it passes, and its margins.
    fn verdicts(report: &GateReport) -> Vec<(bool, Option<SisoMargins>)> {
        report
            .loops
            .iter()
            .map(|l| {
                let margins = l.points.first().and_then(|p| p.margins.clone());
                (l.passes(), margins)
            })
            .collect()
    }

    /// Set live parameter `slot` of the running graph's block `block` to
    /// `value` on the copy.
    fn set(&mut self, block: usize, slot: usize, value: Option<f64>) {
        let at = self.index.get(block).copied().flatten();
        if let (Some(b), Some(v)) = (at.and_then(|i| self.shadow.block_at_mut(i)), value) {
            b.set_live_param(slot, v);
        }
    }
}

/// Sends live parameter updates into a [`RealtimeRunner`](crate::RealtimeRunner)'s
/// loop ([`RealtimeRunner::param_sender`](crate::RealtimeRunner::param_sender)).
/// Everything that can refuse happens here, on the caller's thread; it can be
/// moved to another thread (a terminal reader, a Python callback).
pub struct ParamSender {
    ring: rtrb::Producer<ParamUpdate>,
    slots: usize,
    table: Vec<LiveParam>,
    /// Block names, execution order.
    names: Vec<String>,
    /// One per block of the graph (execution order), `None` without live
    /// parameters.
    judges: Vec<Option<Judge>>,
    gate: Option<Gate>,
    sent: usize,
    limit: usize,
}

impl std::fmt::Debug for ParamSender {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("ParamSender")
            .field("params", &self.table)
            .field("gated", &self.gate.is_some())
            .field("sent", &self.sent)
            .finish_non_exhaustive()
    }
}

impl ParamSender {
    /// For the graph `sched` (as the loop will run it), sending into `ring`.
    pub(crate) fn new(sched: &Scheduler, ring: rtrb::Producer<ParamUpdate>, limit: usize) -> Self {
        let table = live_params(sched);
        let judges = (0..sched.block_names().len())
            .map(|i| {
                let b = sched.block_at(i)?;
                if b.live_params().is_empty() {
                    return None;
                }
                Some(Judge {
                    name: sched.block_names()[i].clone(),
                    type_name: b.typetag_name().to_string(),
                    params: serde_json::to_value(b).ok()?,
                    ctx: sched.build_context(i)?.clone(),
                })
            })
            .collect();
        Self {
            slots: ring.buffer().capacity(),
            ring,
            table,
            names: sched.block_names().to_vec(),
            judges,
            gate: None,
            sent: 0,
            limit,
        }
    }

    /// Judge every update by the stability gate too, on `copy` — the same
    /// graph built a second time, never ticked — against `require` (the
    /// graph's `require:` section): an update is refused when a loop that
    /// passes the gate with the parameters accepted so far fails it with the
    /// new value. (A loop that already fails, e.g. one run unproven, does not
    /// block updates; the gate has nothing to lose there.)
    /// The copy's live parameters are set to the values the loop runs with
    /// (those it was built with and the updates accepted so far).
    pub fn gated(self, copy: Scheduler, require: Require) -> Result<Self, LiveError> {
        if copy.block_names() != self.names.as_slice() {
            return Err(LiveError::NotTheSameGraph {
                copy: copy.block_names().to_vec(),
                runs: self.names.clone(),
            });
        }
        let index = (0..self.names.len()).map(Some).collect();
        Ok(self.gate_on(copy, require, index, None))
    }

    /// The gate on `copy`, block `i` of the graph that runs being block
    /// `index[i]` there.
    fn gate_on(
        mut self,
        copy: Scheduler,
        require: Require,
        index: Vec<Option<usize>>,
        through: Option<String>,
    ) -> Self {
        let mut g = Gate {
            shadow: copy,
            require,
            index,
            accepted: Vec::new(),
            through,
        };
        for row in &self.table {
            let value = self.judges[row.block]
                .as_ref()
                .and_then(|j| j.params[row.name].as_f64());
            g.set(row.block, row.slot, value);
        }
        g.accepted = Gate::verdicts(&gate::analyse(&g.shadow, &g.require));
        self.gate = Some(g);
        self
    }

    /// The gate of [`ParamSender::gated_spec`] where the loop closes through
    /// `device`: when the device has a
    /// [`plant_model`](crate::Device::plant_model), each update is judged on
    /// the loop through it — `spec` (the graph the loop runs, loaded again
    /// with the same overrides) joined with the device's plant and its
    /// declared [`latency_ticks`](crate::Device::latency_ticks)
    /// ([`joined_through_device`], the graph the gate judges before the run,
    /// [`crate::through`]) — against `spec`'s `require:`; a refusal names the
    /// device and its latency ([`LiveError::Gate`]'s `through`). Without a
    /// model it is [`ParamSender::gated_spec`]. `nanomotion rt` and Python's
    /// `rt_start` judge their updates this way, with or without a device.
    pub fn gated_through<D: Device + ?Sized>(
        self,
        spec: GraphSpec,
        device: &D,
    ) -> Result<Self, LiveError> {
        let through = |e: ThroughError| LiveError::Through(Box::new(e));
        let Some(plant) = device
            .plant_model()
            .map_err(|e| through(ThroughError::Model(e)))?
        else {
            return self.gated_spec(spec);
        };
        let require = spec.require.clone().unwrap_or_default();
        let latency = device.latency_ticks();
        let joined = joined_through_device(spec, plant, latency).map_err(through)?;
        let (copy, _) = joined
            .build()
            .map_err(|e| through(ThroughError::Build(Box::new(e))))?;
        // The controller's blocks keep their names in the joined graph; each
        // block with live parameters must be there, of the same type.
        let mut index = Vec::with_capacity(self.names.len());
        for (i, name) in self.names.iter().enumerate() {
            let Some(j) = &self.judges[i] else {
                index.push(None);
                continue;
            };
            let at = copy.block_names().iter().position(|n| n == name);
            match at.and_then(|k| copy.block_at(k).map(|b| (k, b))) {
                Some((k, b)) if b.typetag_name() == j.type_name => index.push(Some(k)),
                _ => {
                    return Err(LiveError::NotTheSameGraph {
                        copy: copy.block_names().to_vec(),
                        runs: self.names.clone(),
                    });
                }
            }
        }
        let on = format!(
            "the loop through device `{}` with its latency of {latency} tick{}",
            device.name(),
            if latency == 1 { "" } else { "s" }
        );
        Ok(self.gate_on(copy, require, index, Some(on)))
    }

    /// [`ParamSender::gated`] on a second build of `spec` — the graph the
    /// loop runs, loaded again with the same overrides — against its
    /// `require:` section. The copy is built without its logs, scores and
    /// comparisons (the gate reads blocks and wiring only). A graph that runs
    /// against a device: [`ParamSender::gated_through`].
    pub fn gated_spec(self, mut spec: GraphSpec) -> Result<Self, LiveError> {
        let require = spec.require.clone().unwrap_or_default();
        spec.log.clear();
        spec.score.clear();
        spec.compare.clear();
        let (copy, _) = spec.build().map_err(|e| LiveError::Copy(Box::new(e)))?;
        self.gated(copy, require)
    }

    /// The graph's live parameters (row `i` is [`ParamUpdate::param`] `= i`).
    pub fn params(&self) -> &[LiveParam] {
        &self.table
    }

    /// `BLOCK.PARAM` of row `param`.
    pub fn path(&self, param: u32) -> &str {
        self.table
            .get(param as usize)
            .map_or("?", |p| p.path.as_str())
    }

    /// Whether the stability gate judges updates ([`ParamSender::gated`]).
    pub fn is_gated(&self) -> bool {
        self.gate.is_some()
    }

    /// Apply `PATH=VALUE` (the grammar of `--set`: `ctrl.kp=1.2`,
    /// `blocks.ctrl.kp=1.2`, the value as YAML) at the loop's next tick
    /// boundary. Returns the update sent.
    pub fn set_text(&mut self, text: &str) -> Result<ParamUpdate, LiveError> {
        let o = Override::parse(text).map_err(|e| LiveError::Syntax(Box::new(e)))?;
        let value = match o.value.as_f64() {
            Some(v) if o.value.is_number() => v,
            _ => {
                return Err(LiveError::NotANumber {
                    path: o.path,
                    value: o.value.to_string(),
                });
            }
        };
        let param = self.resolve(&o.path, &o.segments.0)?;
        self.send(param, value)
    }

    /// Set live parameter `path` (`ctrl.kp` or `blocks.ctrl.kp`) to `value` at
    /// the loop's next tick boundary.
    pub fn set(&mut self, path: &str, value: f64) -> Result<(), LiveError> {
        let parsed = nanomotion_core::overrides::Path::parse(path)
            .map_err(|e| LiveError::Syntax(Box::new(e)))?;
        let param = self.resolve(path, &parsed.0)?;
        self.send(param, value).map(|_| ())
    }

    /// The row of the live parameter a parsed path names.
    fn resolve(&self, path: &str, segments: &[Segment]) -> Result<u32, LiveError> {
        let keys: Vec<&str> = segments
            .iter()
            .map(|s| match s {
                Segment::Key(k) => Some(k.as_str()),
                Segment::Index(_) => None,
            })
            .collect::<Option<_>>()
            .unwrap_or_default();
        let all = || {
            if self.table.is_empty() {
                format!(
                    "this graph has none (live are: {}); restart the run with `--set`",
                    nanomotion_core::doc::live_params_by_type()
                )
            } else {
                format!(
                    "live parameters of this graph: {}",
                    self.table
                        .iter()
                        .map(|p| p.path.as_str())
                        .collect::<Vec<_>>()
                        .join(", ")
                )
            }
        };
        let (block, param) = match keys.as_slice() {
            ["blocks", b, p] | [b, p] => (*b, *p),
            _ => {
                return Err(LiveError::Path {
                    path: path.into(),
                    problem: "is not BLOCK.PARAM".into(),
                    fix: all(),
                });
            }
        };
        let Some(bi) = self.names.iter().position(|n| n == block) else {
            return Err(LiveError::Path {
                path: path.into(),
                problem: format!("the graph has no block `{block}`"),
                fix: all(),
            });
        };
        match self
            .table
            .iter()
            .position(|p| p.block == bi && p.name == param)
        {
            Some(row) => Ok(row as u32),
            None => {
                let own: Vec<&str> = self
                    .table
                    .iter()
                    .filter(|p| p.block == bi)
                    .map(|p| p.name)
                    .collect();
                Err(LiveError::Path {
                    path: path.into(),
                    problem: if own.is_empty() {
                        format!(
                            "block `{block}` has no parameter that can change while the loop runs"
                        )
                    } else {
                        format!(
                            "`{param}` of block `{block}` cannot change while the loop runs (its live parameters: {})",
                            own.join(", ")
                        )
                    },
                    fix: format!(
                        "set it before the run with `--set blocks.{block}.{param}=VALUE`; {}",
                        all()
                    ),
                })
            }
        }
    }

    /// Judge `value` for row `param` and send it.
    fn send(&mut self, param: u32, value: f64) -> Result<ParamUpdate, LiveError> {
        let row = &self.table[param as usize];
        let path = row.path.clone();
        if !value.is_finite() {
            return Err(LiveError::NotANumber {
                path,
                value: value.to_string(),
            });
        }
        if self.sent >= self.limit {
            return Err(LiveError::Limit {
                path,
                limit: self.limit,
            });
        }
        let (block, slot, field) = (row.block, row.slot, row.name);
        let Some(judge) = self.judges.get(block).and_then(Option::as_ref) else {
            return Err(LiveError::Path {
                path,
                problem: "its block cannot be copied to judge the value".into(),
                fix: "set it before the run with `--set`".into(),
            });
        };
        // The block's own validation, on a copy with everything accepted so far.
        let old = judge.params[field].as_f64();
        let mut params = judge.params.clone();
        params[field] = serde_json::Value::from(value);
        let refused = |source: ParamError| LiveError::Refused {
            path: path.clone(),
            value,
            block: judge.name.clone(),
            type_name: judge.type_name.clone(),
            source: Box::new(source),
        };
        let mut copy: Box<dyn Block> = serde_json::from_value(params.clone()).map_err(|e| {
            refused(ParamError::new(
                field,
                format!("the block does not read {value}: {e}"),
                "give a value of the parameter's type",
            ))
        })?;
        copy.build(&judge.ctx).map_err(refused)?;
        // The gate, on its copy of the graph: the value is set there, and set
        // back unless the update is sent.
        let mut accepted = None;
        if let Some(g) = &mut self.gate {
            g.set(block, slot, Some(value));
            let report: GateReport = gate::analyse(&g.shadow, &g.require);
            let lost: Vec<_> = report
                .loops
                .iter()
                .zip(&g.accepted)
                .filter(|(l, (was, _))| *was && !l.passes())
                .collect();
            if !lost.is_empty() {
                let reasons = lost.iter().flat_map(|(l, _)| l.failures()).collect();
                let margins = lost
                    .iter()
                    .filter_map(|(l, (_, m))| m.clone().map(|m| (l.name.clone(), m)))
                    .collect();
                let through = g.through.clone();
                g.set(block, slot, old);
                return Err(LiveError::Gate {
                    path,
                    value,
                    reasons,
                    margins,
                    through,
                });
            }
            accepted = Some(Gate::verdicts(&report));
        }
        let update = ParamUpdate { param, value };
        if self.ring.push(update).is_err() {
            if let Some(g) = &mut self.gate {
                g.set(block, slot, old);
            }
            return Err(if self.ring.is_abandoned() {
                LiveError::Closed { path }
            } else {
                LiveError::Full {
                    path,
                    slots: self.slots,
                }
            });
        }
        if let (Some(g), Some(a)) = (&mut self.gate, accepted) {
            g.accepted = a;
        }
        if let Some(j) = &mut self.judges[block] {
            j.params = params;
        }
        self.sent += 1;
        Ok(update)
    }
}
