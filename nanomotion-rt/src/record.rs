//! Record a run's hardware samples as MCAP, and replay them through a graph.
//!
//! One MCAP channel per signal — `hw_input/NAME` and `hw_output/NAME` — with
//! JSON messages `{"tick": k, "value": v, "bits": "<16 hex digits>"}` under a
//! JSON Schema, the unit and direction in the channel metadata, `log_time` the
//! tick's wake-up time on CLOCK_MONOTONIC. Foxglove and PlotJuggler plot
//! `value`; [`read_mcap`] takes the exact `bits`, so a replay compares outputs
//! bit for bit.
//!
//! Live parameter updates ([`crate::live`]) have a channel per live parameter,
//! `param/BLOCK.PARAM`, with the same messages: `tick` is the first tick
//! computed with the new value, `log_time` that tick's wake-up time (the last
//! tick's for an update that arrived after it); the `nanomotion` metadata
//! record lists the live parameters (`live_params`, comma-separated).
//!
//! A simulated run (`nanomotion run --record`) is recorded the same way by a
//! [`SimRecorder`]: the `hw_input`/`hw_output` signals taken from the run's
//! logs, `log_time` the simulated time of the tick.
//!
//! [`Recording::to_dataset`] reads a recording as measured data (a column per
//! channel); [`load_dataset`] reads a `.mcap` recording or a data file, for
//! `nanomotion diagnose MODEL RUN.mcap` and `run`/`check --data RUN.mcap`.
//!
//! [`replay`] feeds the recorded inputs into the `hw_input` blocks of a freshly
//! built graph, tick by tick, applies the recorded live parameter updates
//! before the ticks they took effect at, and compares every `hw_output` sample with the
//! recording. A graph is deterministic (seeded), so the same graph reproduces
//! the recorded outputs exactly; any difference names its first tick and
//! channel.

use crate::Channel;
use crate::device::{HW_INPUT, HW_OUTPUT};
use crate::live::live_params;
use crate::runner::{ParamChange, Recording, hw_blocks};
use nanomotion_core::Scheduler;
use nanomotion_core::graph::GraphSpec;
use nanomotion_core::scheduler::LogChunk;
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;
use std::path::Path;

/// Channel kind of live parameter updates (`param/BLOCK.PARAM`).
const PARAM: &str = "param";

/// Schema name of a sample message.
const SCHEMA: &str = "nanomotion.HwSample";
const SCHEMA_JSON: &str = r#"{"type":"object","title":"nanomotion.HwSample","properties":{"tick":{"type":"integer","description":"loop tick"},"value":{"type":"number","description":"the sample, in the channel's unit (metadata `unit`)"},"bits":{"type":"string","description":"IEEE-754 bits of value, 16 hex digits (exact)"}},"required":["tick","value","bits"]}"#;

/// Reading or writing a recording failed.
#[derive(Debug, thiserror::Error)]
pub enum RecordError {
    /// File or MCAP error.
    #[error("{path}: {message}")]
    File {
        /// The file.
        path: String,
        /// What went wrong.
        message: String,
    },
    /// The file is MCAP but not a nanomotion recording, or is inconsistent.
    #[error("{path}: {message} (fix: record with `nanomotion rt GRAPH --record --out DIR`)")]
    Content {
        /// The file.
        path: String,
        /// What is wrong.
        message: String,
    },
    /// The graph does not have the recorded channels.
    #[error("{0}")]
    Graph(String),
    /// The recording cannot be read as uniformly sampled data.
    #[error(transparent)]
    Data(#[from] nanomotion_core::data::DataError),
}

#[derive(Serialize, Deserialize)]
struct Sample {
    tick: u64,
    value: Option<f64>,
    bits: String,
}

/// Write `rec` to `path` (the file is complete or absent: written beside it and
/// renamed).
pub fn write_mcap(path: &Path, rec: &Recording) -> Result<(), RecordError> {
    let err = |m: String| RecordError::File {
        path: path.display().to_string(),
        message: m,
    };
    let tmp = path.with_extension("mcap.partial");
    let file = std::fs::File::create(&tmp).map_err(|e| err(e.to_string()))?;
    let result = (|| -> Result<(), mcap::McapError> {
        let mut w = mcap::WriteOptions::new()
            .compression(None)
            .profile("")
            .create(std::io::BufWriter::new(file))?;
        let schema = w.add_schema(SCHEMA, "jsonschema", SCHEMA_JSON.as_bytes())?;
        let mut channel = |kind: &str, c: &Channel, rate: f64| {
            let mut meta = BTreeMap::new();
            meta.insert("direction".to_string(), kind.to_string());
            meta.insert("rate_hz".to_string(), format!("{rate}"));
            if let Some(u) = &c.unit {
                meta.insert("unit".to_string(), u.clone());
            }
            w.add_channel(schema, &format!("{kind}/{}", c.name), "json", &meta)
        };
        let ins: Vec<u16> = rec
            .inputs
            .iter()
            .map(|c| channel(HW_INPUT, c, rec.rate_hz))
            .collect::<Result<_, _>>()?;
        let outs: Vec<u16> = rec
            .outputs
            .iter()
            .map(|c| channel(HW_OUTPUT, c, rec.rate_hz))
            .collect::<Result<_, _>>()?;
        let params: Vec<u16> = rec
            .params
            .iter()
            .map(|p| channel(PARAM, &Channel::new(p, None), rec.rate_hz))
            .collect::<Result<_, _>>()?;
        let mut meta = BTreeMap::new();
        meta.insert("rate_hz".to_string(), format!("{}", rec.rate_hz));
        meta.insert("ticks".to_string(), rec.ticks().to_string());
        if let Some(t) = &rec.title {
            meta.insert("title".to_string(), t.clone());
        }
        meta.insert("live_params".to_string(), rec.params.join(","));
        w.write_metadata(&mcap::records::Metadata {
            name: "nanomotion".into(),
            metadata: meta,
        })?;
        let mut put = |id: u16, k: usize, t: u64, v: f64| {
            let data = serde_json::to_vec(&Sample {
                tick: k as u64,
                value: v.is_finite().then_some(v),
                bits: format!("{:016x}", v.to_bits()),
            })
            .expect("a sample serialises");
            w.write_to_known_channel(
                &mcap::records::MessageHeader {
                    channel_id: id,
                    sequence: k as u32,
                    log_time: t,
                    publish_time: t,
                },
                &data,
            )
        };
        let (ni, no) = (rec.inputs.len(), rec.outputs.len());
        for (k, &t) in rec.t_ns.iter().enumerate() {
            for (i, &id) in ins.iter().enumerate() {
                put(id, k, t, rec.input_values[k * ni + i])?;
            }
            for (i, &id) in outs.iter().enumerate() {
                put(id, k, t, rec.output_values[k * no + i])?;
            }
        }
        // Updates: `sequence` is the order applied (several may share a tick).
        for (seq, u) in rec.param_changes.iter().enumerate() {
            let Some(&id) = params.get(u.param as usize) else {
                continue;
            };
            let t = rec
                .t_ns
                .get(u.tick as usize)
                .or(rec.t_ns.last())
                .copied()
                .unwrap_or(0);
            let data = serde_json::to_vec(&Sample {
                tick: u.tick,
                value: Some(u.value),
                bits: format!("{:016x}", u.value.to_bits()),
            })
            .expect("a sample serialises");
            w.write_to_known_channel(
                &mcap::records::MessageHeader {
                    channel_id: id,
                    sequence: seq as u32,
                    log_time: t,
                    publish_time: t,
                },
                &data,
            )?;
        }
        w.finish()?;
        Ok(())
    })();
    match result {
        Ok(()) => std::fs::rename(&tmp, path).map_err(|e| err(e.to_string())),
        Err(e) => {
            let _ = std::fs::remove_file(&tmp);
            Err(err(e.to_string()))
        }
    }
}

/// Read a recording written by [`write_mcap`].
pub fn read_mcap(path: &Path) -> Result<Recording, RecordError> {
    let p = path.display().to_string();
    let bytes = std::fs::read(path).map_err(|e| RecordError::File {
        path: p.clone(),
        message: e.to_string(),
    })?;
    let content = |m: String| RecordError::Content {
        path: p.clone(),
        message: m,
    };
    let mut rec = Recording::default();
    let mut ticks = None;
    for m in mcap::read::LinearReader::new(&bytes).map_err(|e| content(e.to_string()))? {
        if let mcap::records::Record::Metadata(md) = m.map_err(|e| content(e.to_string()))?
            && md.name == "nanomotion"
        {
            rec.rate_hz = md
                .metadata
                .get("rate_hz")
                .and_then(|r| r.parse().ok())
                .ok_or_else(|| content("metadata `rate_hz` missing".into()))?;
            ticks = md
                .metadata
                .get("ticks")
                .and_then(|t| t.parse::<usize>().ok());
            rec.title = md.metadata.get("title").cloned();
            rec.params = md
                .metadata
                .get("live_params")
                .map(|l| {
                    l.split(',')
                        .filter(|p| !p.is_empty())
                        .map(str::to_string)
                        .collect()
                })
                .unwrap_or_default();
        }
    }
    let ticks = ticks.ok_or_else(|| content("no `nanomotion` metadata record".into()))?;
    // Channel id -> (is input, index); live parameter channel id -> row.
    let mut index: BTreeMap<u16, (bool, usize)> = BTreeMap::new();
    let mut param_rows: BTreeMap<u16, usize> = BTreeMap::new();
    let mut samples: Vec<(bool, usize, u64, u64, f64)> = Vec::new();
    let mut changes: Vec<(u32, ParamChange)> = Vec::new();
    let bits_of = |topic: &str, s: &Sample| {
        u64::from_str_radix(&s.bits, 16)
            .map(f64::from_bits)
            .map_err(|e| content(format!("{topic} tick {}: bits `{}`: {e}", s.tick, s.bits)))
    };
    for m in mcap::MessageStream::new(&bytes).map_err(|e| content(e.to_string()))? {
        let m = m.map_err(|e| content(e.to_string()))?;
        let ch = &m.channel;
        if let Some(name) = ch.topic.strip_prefix("param/") {
            let row = match param_rows.get(&ch.id) {
                Some(&r) => r,
                None => {
                    let r = rec.params.iter().position(|p| p == name).ok_or_else(|| {
                        content(format!(
                            "channel `{}` is not among the live parameters the metadata lists ({})",
                            ch.topic,
                            rec.params.join(", ")
                        ))
                    })?;
                    param_rows.insert(ch.id, r);
                    r
                }
            };
            let s: Sample = serde_json::from_slice(&m.data)
                .map_err(|e| content(format!("{} message {}: {e}", ch.topic, m.sequence)))?;
            let value = bits_of(&ch.topic, &s)?;
            changes.push((
                m.sequence,
                ParamChange {
                    tick: s.tick,
                    param: row as u32,
                    value,
                },
            ));
            continue;
        }
        let (is_in, i) = match index.get(&ch.id) {
            Some(&x) => x,
            None => {
                let (kind, name) = ch
                    .topic
                    .split_once('/')
                    .ok_or_else(|| content(format!("topic `{}` is not KIND/NAME", ch.topic)))?;
                let c = Channel {
                    name: name.into(),
                    unit: ch.metadata.get("unit").cloned(),
                };
                let x = match kind {
                    HW_INPUT => {
                        rec.inputs.push(c);
                        (true, rec.inputs.len() - 1)
                    }
                    HW_OUTPUT => {
                        rec.outputs.push(c);
                        (false, rec.outputs.len() - 1)
                    }
                    other => return Err(content(format!("unknown channel kind `{other}`"))),
                };
                index.insert(ch.id, x);
                x
            }
        };
        let s: Sample = serde_json::from_slice(&m.data)
            .map_err(|e| content(format!("{} message {}: {e}", ch.topic, m.sequence)))?;
        let value = bits_of(&ch.topic, &s)?;
        samples.push((is_in, i, s.tick, m.log_time, value));
    }
    changes.sort_by_key(|(seq, _)| *seq);
    rec.param_changes = changes.into_iter().map(|(_, c)| c).collect();
    let (ni, no) = (rec.inputs.len(), rec.outputs.len());
    rec.t_ns = vec![0; ticks];
    rec.input_values = vec![f64::NAN; ticks * ni];
    rec.output_values = vec![f64::NAN; ticks * no];
    let mut seen = vec![0u32; ticks * (ni + no)];
    for (is_in, i, k, t, v) in samples {
        let k = k as usize;
        if k >= ticks {
            return Err(content(format!(
                "sample of tick {k} beyond the {ticks} ticks recorded"
            )));
        }
        rec.t_ns[k] = t;
        if is_in {
            rec.input_values[k * ni + i] = v;
            seen[k * (ni + no) + i] += 1;
        } else {
            rec.output_values[k * no + i] = v;
            seen[k * (ni + no) + ni + i] += 1;
        }
    }
    if let Some(j) = seen.iter().position(|&c| c != 1) {
        return Err(content(format!(
            "tick {} has {} samples of one channel, expected 1",
            j / (ni + no).max(1),
            seen[j]
        )));
    }
    Ok(rec)
}

/// The result of a replay.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct ReplayReport {
    /// Ticks replayed.
    pub ticks: usize,
    /// Output samples compared.
    pub compared: usize,
    /// Output samples whose bits differ.
    pub mismatches: usize,
    /// The first difference: (tick, channel, recorded, replayed).
    pub first: Option<(usize, String, f64, f64)>,
}

/// Replay `rec` through `sched` (freshly built, at the recorded rate, at least
/// as long as the recording) and compare every output sample bit for bit.
pub fn replay(sched: &mut Scheduler, rec: &Recording) -> Result<ReplayReport, RecordError> {
    if sched.base_rate_hz() != rec.rate_hz {
        return Err(RecordError::Graph(format!(
            "the graph runs at {} Hz, the recording at {} Hz (fix: replay with the graph that was recorded, or `--set base_rate_hz={}`)",
            sched.base_rate_hz(),
            rec.rate_hz,
            rec.rate_hz
        )));
    }
    let (hw_in, hw_out) = hw_blocks(sched);
    let find = |list: &[Channel], name: &str, kind: &str| {
        list.iter().position(|c| c.name == name).ok_or_else(|| {
            RecordError::Graph(format!(
                "block `{name}` ({kind}) has no recorded channel (recorded: {})",
                list.iter()
                    .map(|c| c.name.as_str())
                    .collect::<Vec<_>>()
                    .join(", ")
            ))
        })
    };
    let id = |name: &str| {
        sched
            .signal_id(&format!("{name}.y"))
            .ok_or_else(|| RecordError::Graph(format!("signal {name}.y not found")))
    };
    let ins = hw_in
        .iter()
        .map(|(n, _)| Ok((find(&rec.inputs, n, HW_INPUT)?, id(n)?)))
        .collect::<Result<Vec<_>, RecordError>>()?;
    let outs = hw_out
        .iter()
        .map(|(n, _)| Ok((find(&rec.outputs, n, HW_OUTPUT)?, id(n)?, n.clone())))
        .collect::<Result<Vec<_>, RecordError>>()?;
    // The recorded live parameters, resolved once: (block, slot) per row.
    let table = live_params(sched);
    let slots = rec
        .params
        .iter()
        .map(|p| {
            table
                .iter()
                .find(|l| &l.path == p)
                .map(|l| (l.block, l.slot))
                .ok_or_else(|| {
                    RecordError::Graph(format!(
                        "the recording changed `{p}` while running, which is not a live parameter of this graph (fix: replay with the graph that was recorded)"
                    ))
                })
        })
        .collect::<Result<Vec<_>, RecordError>>()?;
    let mut changes = rec.param_changes.iter().peekable();
    let (ni, no) = (rec.inputs.len(), rec.outputs.len());
    let mut report = ReplayReport {
        ticks: rec.ticks(),
        compared: 0,
        mismatches: 0,
        first: None,
    };
    for k in 0..rec.ticks() {
        while let Some(c) = changes.next_if(|c| c.tick <= k as u64) {
            let (block, slot) = *slots.get(c.param as usize).ok_or_else(|| {
                RecordError::Graph(format!(
                    "tick {}: update of live parameter {} of {}",
                    c.tick,
                    c.param,
                    rec.params.len()
                ))
            })?;
            if let Some(b) = sched.block_at_mut(block) {
                b.set_live_param(slot, c.value);
            }
        }
        for &(i, sid) in &ins {
            sched.write(sid, &rec.input_values[k * ni + i..k * ni + i + 1]);
        }
        sched.tick();
        for (i, sid, name) in &outs {
            let got = sched.read(*sid)[0];
            let want = rec.output_values[k * no + i];
            report.compared += 1;
            if got.to_bits() != want.to_bits() {
                report.mismatches += 1;
                if report.first.is_none() {
                    report.first = Some((k, name.clone(), want, got));
                }
            }
        }
    }
    Ok(report)
}

/// The log entries (`NAME.y`) of every `hw_input` and `hw_output` block of
/// `spec`, in graph order: what a [`SimRecorder`] needs logged.
pub fn hw_log_names(spec: &GraphSpec) -> Vec<String> {
    spec.blocks
        .iter()
        .filter(|b| matches!(b.block.typetag_name(), HW_INPUT | HW_OUTPUT))
        .map(|b| format!("{}.y", b.name))
        .collect()
}

/// Collects the hardware samples of a simulated run from its log chunks
/// ([`Scheduler::run_streamed`]) into a [`Recording`] for [`write_mcap`]: each
/// `hw_input` and `hw_output` block's `y` on every base tick, at simulated time
/// `k·T`. Without a device, a `hw_input` block holds 0, so what is recorded is
/// the graph's response to zero inputs — and [`replay`] reproduces it bit for bit.
#[derive(Debug)]
pub struct SimRecorder {
    rec: Recording,
    /// Log names of the inputs, then of the outputs.
    logs: Vec<String>,
    /// Samples of each, in the order of `logs`.
    values: Vec<Vec<f64>>,
}

impl SimRecorder {
    /// For `sched`, built from a spec whose `log:` holds [`hw_log_names`].
    /// Refuses a graph without `hw_input`/`hw_output` blocks, a hw block not at
    /// the base rate (a recording holds one sample per base tick) and one that
    /// is not logged.
    pub fn new(sched: &Scheduler) -> Result<Self, RecordError> {
        let (ins, outs) = hw_blocks(sched);
        if ins.is_empty() && outs.is_empty() {
            return Err(RecordError::Graph(
                "nothing to record: the graph has no hw_input or hw_output block (fix: record a controller or plant graph, e.g. examples/realtime/quickstart_controller.yaml, or leave out --record)".into(),
            ));
        }
        for w in sched.wiring() {
            if matches!(w.type_name.as_str(), HW_INPUT | HW_OUTPUT) && w.period != 1 {
                return Err(RecordError::Graph(format!(
                    "block `{}` ({}) runs every {} base ticks; a recording holds one sample per base tick (fix: leave out its `rate_hz`)",
                    w.name, w.type_name, w.period
                )));
            }
        }
        let channel = |(name, unit): &(String, Option<String>)| Channel {
            name: name.clone(),
            unit: unit.clone(),
        };
        let logs: Vec<String> = ins
            .iter()
            .chain(&outs)
            .map(|(n, _)| format!("{n}.y"))
            .collect();
        if let Some(missing) = logs.iter().find(|l| sched.log_view(l).is_none()) {
            return Err(RecordError::Graph(format!(
                "`{missing}` is not logged (fix: add it to `log:`; `hw_log_names` lists what a recording needs)"
            )));
        }
        Ok(Self {
            rec: Recording {
                title: sched.result().title,
                rate_hz: sched.base_rate_hz(),
                inputs: ins.iter().map(channel).collect(),
                outputs: outs.iter().map(channel).collect(),
                ..Recording::default()
            },
            values: vec![Vec::new(); logs.len()],
            logs,
        })
    }

    /// Take the hw samples out of one batch of log chunks.
    pub fn take(&mut self, chunks: &[LogChunk<'_>]) {
        for c in chunks {
            if let Some(i) = self.logs.iter().position(|l| l == c.name) {
                self.values[i].extend_from_slice(c.data);
            }
        }
    }

    /// The recording: every base tick that every channel has a sample of.
    pub fn finish(self) -> Recording {
        let Self {
            mut rec, values, ..
        } = self;
        let n = values.iter().map(Vec::len).min().unwrap_or(0);
        let ni = rec.inputs.len();
        let period_ns = 1.0e9 / rec.rate_hz;
        rec.t_ns = (0..n)
            .map(|k| (k as f64 * period_ns).round() as u64)
            .collect();
        for k in 0..n {
            rec.input_values.extend(values[..ni].iter().map(|v| v[k]));
            rec.output_values.extend(values[ni..].iter().map(|v| v[k]));
        }
        rec
    }
}

impl Recording {
    /// The recording as measured data ([`Dataset`](nanomotion_core::data::Dataset)):
    /// one column per channel, named like it (the inputs, then the outputs),
    /// sample k at `t = k·T` from 0. `origin` (the file) prefixes errors.
    ///
    /// Refused, naming the tick and the fix, when the samples are not on the
    /// loop's grid: when tick k did not wake nearest to `t₀ + k·T` (a deadline
    /// was skipped, or the tick woke more than half a period late), the data is
    /// not uniformly sampled and would mislead a fit. So are a recording of
    /// fewer than [`MIN_SAMPLES`](nanomotion_core::data::MIN_SAMPLES) ticks, a
    /// non-finite sample and a channel name used twice (by the dataset itself).
    pub fn to_dataset(&self, origin: &str) -> Result<nanomotion_core::data::Dataset, RecordError> {
        use nanomotion_core::data::{DataError, Dataset, MIN_SAMPLES};
        if self.ticks() < MIN_SAMPLES {
            return Err(DataError::new(
                origin,
                format!(
                    "holds {} ticks, fewer than the {MIN_SAMPLES} a dataset needs",
                    self.ticks()
                ),
                "record a longer run",
            )
            .into());
        }
        let period_ns = 1.0e9 / self.rate_hz;
        if let Some(&t0) = self.t_ns.first() {
            for (k, &t) in self.t_ns.iter().enumerate() {
                let slot = ((t as f64 - t0 as f64) / period_ns).round();
                if slot != k as f64 {
                    return Err(DataError::new(
                        origin,
                        format!(
                            "tick {k} woke at {:.1} µs, nearest to grid slot {slot}, not {k}: the loop skipped deadlines or woke more than half a period (T = {:.1} µs) late, so the samples are not uniform in time",
                            (t as f64 - t0 as f64) * 1e-3,
                            period_ns * 1e-3
                        ),
                        "record a run without overruns (`nanomotion rt ... --max-overruns 0 --record`; see docs/realtime.md for a CPU of its own), or use the part before this tick",
                    )
                    .into());
                }
            }
        }
        let column = |values: &[f64], j: usize, width: usize| -> Vec<f64> {
            values
                .iter()
                .skip(j)
                .step_by(width.max(1))
                .copied()
                .collect()
        };
        let (ni, no) = (self.inputs.len(), self.outputs.len());
        let columns = self
            .inputs
            .iter()
            .enumerate()
            .map(|(j, c)| (c.name.clone(), column(&self.input_values, j, ni)))
            .chain(
                self.outputs
                    .iter()
                    .enumerate()
                    .map(|(j, c)| (c.name.clone(), column(&self.output_values, j, no))),
            )
            .collect();
        Ok(Dataset::from_columns(origin, self.rate_hz, 0.0, columns)?)
    }
}

/// Measured data from `path`: a recording (`.mcap`, [`Recording::to_dataset`])
/// or a data file ([`Dataset::from_file_with_rate`](nanomotion_core::data::Dataset::from_file_with_rate):
/// CSV, `.mat`). A sample rate given for a recording must be the recorded one.
pub fn load_dataset(
    path: &Path,
    rate_hz: Option<f64>,
) -> Result<nanomotion_core::data::Dataset, RecordError> {
    let is_mcap = path
        .extension()
        .and_then(|e| e.to_str())
        .is_some_and(|e| e.eq_ignore_ascii_case("mcap"));
    if !is_mcap {
        return Ok(nanomotion_core::data::Dataset::from_file_with_rate(
            path, rate_hz,
        )?);
    }
    let rec = read_mcap(path)?;
    if let Some(r) = rate_hz
        && r != rec.rate_hz
    {
        return Err(RecordError::Content {
            path: path.display().to_string(),
            message: format!(
                "recorded at {} Hz, but a rate of {r} Hz was given (leave the rate out: a recording carries its own)",
                rec.rate_hz
            ),
        });
    }
    rec.to_dataset(&path.display().to_string())
}
