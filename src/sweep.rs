//! Parameter studies over a graph (`nanomotion sweep SWEEP.yaml`): grid, random,
//! Latin-hypercube and Monte-Carlo designs over graph parameters named by dotted
//! path ([`nanomotion_core::overrides`]), run in parallel, gathered into one
//! results table (CSV and Parquet) with plots, resumable.
//!
//! The pieces, usable without the command (the Python package drives them):
//! 1. [`Study::from_file`] reads a study file (format: `docs/sweep.md`);
//! 2. [`Study::plan`] expands it into the deterministic [`Plan`]: one
//!    [`PlannedRun`] (index, parameter values, seed) per run, serialisable to JSON;
//!    the same file always gives the same plan, bit for bit;
//! 3. [`Study::run_one`] runs one planned run into a [`Row`] (its scores and wall
//!    time, or its error; never a panic), [`Study::run_chunk`] runs several on a
//!    rayon pool;
//! 4. [`RowStore`] keeps finished rows in `rows.jsonl` (append-only, keyed by run
//!    index and the plan's hash) so that a study resumes where it stopped;
//! 5. [`write_results`] writes `results.csv`, `results.parquet` and the SVG plots.
//!
//! [`run_study`] does all of it, as the command does.

use nanomotion_core::GraphError;
use nanomotion_core::graph::GraphSpec;
use nanomotion_core::overrides::Override;
use nanomotion_core::rng::{Rng, splitmix64};
use serde::{Deserialize, Serialize};
use serde_json::Value;
use std::io::Write as _;
use std::path::{Path, PathBuf};

/// Largest number of runs a study may plan.
pub const MAX_RUNS: usize = 10_000_000;

/// Name of the append-only file of finished rows in the output folder.
pub const ROWS_FILE: &str = "rows.jsonl";

/// Everything that stops a study (a failed run is a [`Row`] with its error, not this).
#[derive(Debug, thiserror::Error)]
pub enum SweepError {
    /// The study file is wrong.
    #[error("{origin}: {problem} (fix: {fix})")]
    Study {
        /// The study file.
        origin: String,
        /// What is wrong.
        problem: String,
        /// How to fix it.
        fix: String,
    },
    /// The graph does not load, or a parameter path does not fit it.
    #[error("{origin}: {source}")]
    Graph {
        /// The study file.
        origin: String,
        /// The graph's error.
        #[source]
        source: Box<GraphError>,
    },
    /// The output folder holds rows of a different study.
    #[error(
        "{dir}: holds {rows} finished rows of a different study (plan hash {found}, this study's is {expected}): the study file or its graph changed (fix: use another --out, or rerun with --restart to discard those rows)"
    )]
    Changed {
        /// The output folder.
        dir: String,
        /// Rows of the other study.
        rows: usize,
        /// Their hash.
        found: String,
        /// This study's hash.
        expected: String,
    },
    /// A file could not be read or written.
    #[error("{path}: {source}")]
    Io {
        /// The file.
        path: String,
        /// The error.
        #[source]
        source: std::io::Error,
    },
    /// The Parquet table could not be written or read.
    #[error("{path}: parquet: {message}")]
    Parquet {
        /// The file.
        path: String,
        /// The error.
        message: String,
    },
    /// A plot could not be drawn.
    #[error(transparent)]
    Plot(#[from] crate::plot::PlotError),
    /// The output folder cannot be used (another sweep writes it, a folder of
    /// the user's), or Ctrl-C stopped the study.
    #[error(transparent)]
    Output(#[from] crate::output::OutputError),
}

fn io_err(path: &Path) -> impl FnOnce(std::io::Error) -> SweepError + '_ {
    move |source| SweepError::Io {
        path: path.display().to_string(),
        source,
    }
}

/// The design of a study.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Kind {
    /// Every combination of every parameter's `values` (or `range` with `steps`).
    Grid,
    /// `runs` independent uniform draws in each parameter's `values`/`range`
    /// (distributions are drawn from as given).
    Random,
    /// `runs` points, each parameter's range cut into `runs` equal-probability
    /// strata and each stratum used exactly once.
    LatinHypercube,
    /// `runs` independent draws from each parameter's distribution (`normal`,
    /// `lognormal`, `uniform`, or a `values` list / `range`), e.g. plant variations.
    MonteCarlo,
}

impl Kind {
    /// The name written in study files.
    pub fn as_str(self) -> &'static str {
        match self {
            Kind::Grid => "grid",
            Kind::Random => "random",
            Kind::LatinHypercube => "latin-hypercube",
            Kind::MonteCarlo => "monte-carlo",
        }
    }
}

/// What the stability gate does in a sweep.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum GateMode {
    /// Analyse every run's loops, write the verdict into the `gate` column and run
    /// anyway (`--allow-unproven` semantics): a study maps where loops fail.
    #[default]
    Record,
    /// A run the gate refuses is not simulated: its row holds the refusal as error.
    Refuse,
    /// No analysis (faster; the `gate` column is empty).
    Off,
}

impl GateMode {
    /// The name written in study files.
    pub fn as_str(self) -> &'static str {
        match self {
            GateMode::Record => "record",
            GateMode::Refuse => "refuse",
            GateMode::Off => "off",
        }
    }
}

/// A normal distribution.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Normal {
    /// Mean.
    pub mean: f64,
    /// Standard deviation (≥ 0).
    pub std: f64,
}

/// A log-normal distribution: `median · exp(sigma · z)`, z standard normal.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct LogNormal {
    /// Median (> 0).
    pub median: f64,
    /// Standard deviation of the logarithm (≥ 0).
    pub sigma: f64,
}

/// One parameter of a study as written: a path and exactly one of `values`,
/// `range` (with `steps` for a grid, `log: true` for a logarithmic spacing),
/// `uniform`, `normal`, `lognormal`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ParamSpec {
    /// Dotted path into the graph (`blocks.pi.kp`).
    pub path: String,
    /// The values to use (grid: each; random/Monte-Carlo: one at random).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub values: Option<Vec<Value>>,
    /// `[low, high]`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub range: Option<[f64; 2]>,
    /// Grid points across `range` (≥ 2, ends included).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub steps: Option<usize>,
    /// Space `range` logarithmically (both ends > 0).
    #[serde(default)]
    pub log: bool,
    /// Uniform in `[low, high]` (same as `range`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub uniform: Option<[f64; 2]>,
    /// Normal distribution.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub normal: Option<Normal>,
    /// Log-normal distribution.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub lognormal: Option<LogNormal>,
}

/// A study file.
#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct StudyFile {
    /// Optional title (plots).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub title: Option<String>,
    /// The graph file, relative to the study file's folder.
    pub graph: String,
    /// The design.
    pub study: Kind,
    /// Number of design points (random, latin-hypercube, monte-carlo).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub runs: Option<usize>,
    /// Seed of the sampling (default 0).
    #[serde(default)]
    pub seed: u64,
    /// Overrides applied to every run (`duration_s: 0.5`).
    #[serde(default)]
    pub set: serde_json::Map<String, Value>,
    /// The varied parameters.
    #[serde(default)]
    pub parameters: Vec<ParamSpec>,
    /// Graph seeds: `graph` (default: the graph's own seed), `per-run` (a
    /// different seed per run, from the study seed and the run index) or a list
    /// (every design point runs once with each seed).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub seeds: Option<Value>,
    /// The stability gate: `record` (default), `refuse` or `off`.
    #[serde(default)]
    pub gate: GateMode,
}

/// A parameter's design, validated (as stored in `plan.json`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
enum Dim {
    Values(Vec<Value>),
    Range {
        lo: f64,
        hi: f64,
        steps: Option<usize>,
        log: bool,
    },
    Normal(Normal),
    #[serde(rename = "lognormal")]
    LogNormal(LogNormal),
}

impl Dim {
    /// The value at probability `u` ∈ (0, 1) (inverse CDF).
    fn at(&self, u: f64) -> Value {
        match self {
            Dim::Values(v) => v[((u * v.len() as f64) as usize).min(v.len() - 1)].clone(),
            Dim::Range { lo, hi, log, .. } => Value::from(if *log {
                lo * (hi / lo).powf(u)
            } else {
                lo + u * (hi - lo)
            }),
            Dim::Normal(n) => Value::from(n.mean + n.std * normal_quantile(u)),
            Dim::LogNormal(l) => Value::from(l.median * (l.sigma * normal_quantile(u)).exp()),
        }
    }

    /// The number of grid points, if this dimension has them.
    fn grid_len(&self) -> Option<usize> {
        match self {
            Dim::Values(v) => Some(v.len()),
            Dim::Range { steps: Some(n), .. } => Some(*n),
            _ => None,
        }
    }

    /// Grid point `k` (< [`Dim::grid_len`]), computed on demand.
    fn grid_at(&self, k: usize) -> Value {
        match self {
            Dim::Values(v) => v[k].clone(),
            Dim::Range {
                lo,
                hi,
                steps: Some(n),
                log,
            } => {
                let f = k as f64 / (*n - 1) as f64;
                Value::from(if *log {
                    lo * (hi / lo).powf(f)
                } else {
                    lo + f * (hi - lo)
                })
            }
            other => other.at(0.5),
        }
    }

    /// Whether every value of this dimension is a number.
    fn numeric(&self) -> bool {
        match self {
            Dim::Values(v) => v.iter().all(Value::is_number),
            _ => true,
        }
    }
}

/// Φ⁻¹(p), the standard normal quantile, by Acklam's rational approximation
/// refined with one Halley step on Φ (relative error below 1e-13 on (0, 1)).
pub fn normal_quantile(p: f64) -> f64 {
    const A: [f64; 6] = [
        -3.969_683_028_665_376e1,
        2.209_460_984_245_205e2,
        -2.759_285_104_469_687e2,
        1.383_577_518_672_69e2,
        -3.066_479_806_614_716e1,
        2.506_628_277_459_239,
    ];
    const B: [f64; 5] = [
        -5.447_609_879_822_406e1,
        1.615_858_368_580_409e2,
        -1.556_989_798_598_866e2,
        6.680_131_188_771_972e1,
        -1.328_068_155_288_572e1,
    ];
    const C: [f64; 6] = [
        -7.784_894_002_430_293e-3,
        -3.223_964_580_411_365e-1,
        -2.400_758_277_161_838,
        -2.549_732_539_343_734,
        4.374_664_141_464_968,
        2.938_163_982_698_783,
    ];
    const D: [f64; 4] = [
        7.784_695_709_041_462e-3,
        3.224_671_290_700_398e-1,
        2.445_134_137_142_996,
        3.754_408_661_907_416,
    ];
    if p <= 0.0 {
        return f64::NEG_INFINITY;
    }
    if p >= 1.0 {
        return f64::INFINITY;
    }
    let tail = |q: f64| {
        (((((C[0] * q + C[1]) * q + C[2]) * q + C[3]) * q + C[4]) * q + C[5])
            / ((((D[0] * q + D[1]) * q + D[2]) * q + D[3]) * q + 1.0)
    };
    let x = if p < 0.02425 {
        tail((-2.0 * p.ln()).sqrt())
    } else if p > 1.0 - 0.02425 {
        -tail((-2.0 * (1.0 - p).ln()).sqrt())
    } else {
        let q = p - 0.5;
        let r = q * q;
        (((((A[0] * r + A[1]) * r + A[2]) * r + A[3]) * r + A[4]) * r + A[5]) * q
            / (((((B[0] * r + B[1]) * r + B[2]) * r + B[3]) * r + B[4]) * r + 1.0)
    };
    // Halley refinement: e = Φ(x) − p with Φ(x) = erfc(−x/√2)/2.
    let e = 0.5 * erfc(-x / std::f64::consts::SQRT_2) - p;
    let u = e * (2.0 * std::f64::consts::PI).sqrt() * (x * x / 2.0).exp();
    x - u / (1.0 + x * u / 2.0)
}

/// The complementary error function (W. J. Cody's rational approximations,
/// relative error below 1e-15), for the normal CDF.
pub fn erfc(x: f64) -> f64 {
    if x < 0.0 {
        return 2.0 - erfc(-x);
    }
    if x < 0.468_75 {
        return 1.0 - erf_small(x);
    }
    let (p, q): (&[f64], &[f64]) = if x < 4.0 {
        (
            &[
                5.641_884_969_886_701e-1,
                8.883_149_794_388_376,
                6.611_919_063_714_163e1,
                2.986_351_381_974_001e2,
                8.819_522_212_417_69e2,
                1.712_047_612_634_070_7e3,
                2.051_078_377_826_071_6e3,
                1.230_339_354_797_997_2e3,
                2.153_115_354_744_038_3e-8,
            ],
            &[
                1.574_492_611_070_983_5e1,
                1.176_939_508_913_125e2,
                5.371_811_018_620_099e2,
                1.621_389_574_566_690_3e3,
                3.290_799_235_733_459_6e3,
                4.362_619_090_143_247e3,
                3.439_367_674_143_721_6e3,
                1.230_339_354_803_749_5e3,
            ],
        )
    } else {
        let z = 1.0 / (x * x);
        let p = [
            3.053_266_349_612_323_4e-1,
            3.603_448_999_498_044_5e-1,
            1.257_817_261_112_292_5e-1,
            1.608_378_514_874_227_5e-2,
            6.587_491_615_298_378e-4,
            1.631_538_713_730_709_7e-2,
        ];
        let q = [
            2.568_520_192_289_822,
            1.872_952_849_923_460_4,
            5.279_051_029_514_285e-1,
            6.051_834_131_244_132e-2,
            2.335_204_976_268_691_8e-3,
        ];
        let mut num = p[5] * z;
        let mut den = z;
        for i in 0..4 {
            num = (num + p[i]) * z;
            den = (den + q[i]) * z;
        }
        let r = z * (num + p[4]) / (den + q[4]);
        let r = (1.0 / std::f64::consts::PI.sqrt() - r) / x;
        return r * (-x * x).exp();
    };
    let mut num = p[8] * x;
    let mut den = x;
    for i in 0..7 {
        num = (num + p[i]) * x;
        den = (den + q[i]) * x;
    }
    (num + p[7]) / (den + q[7]) * (-x * x).exp()
}

fn erf_small(x: f64) -> f64 {
    const A: [f64; 5] = [
        3.161_123_743_870_565_6,
        1.138_641_541_510_501_6e2,
        3.774_852_376_853_02e2,
        3.209_377_589_138_469_5e3,
        1.857_777_061_846_031_5e-1,
    ];
    const B: [f64; 4] = [
        2.360_129_095_234_412e1,
        2.440_246_379_344_441_7e2,
        1.282_616_526_077_372_3e3,
        2.844_236_833_439_171e3,
    ];
    let z = x * x;
    let mut num = A[4] * z;
    let mut den = z;
    for i in 0..3 {
        num = (num + A[i]) * z;
        den = (den + B[i]) * z;
    }
    x * (num + A[3]) / (den + B[3])
}

/// How graph seeds are chosen.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
enum Seeds {
    Graph,
    PerRun,
    List(Vec<u64>),
}

/// One run of a plan.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct PlannedRun {
    /// Position in the plan (0-based), the run's key.
    pub index: usize,
    /// The varied parameters' values, in the study's order.
    pub parameters: Vec<Override>,
    /// The graph seed, or `None` for the graph's own.
    pub seed: Option<u64>,
}

/// The deterministic run plan of a study: its definition (designs, seeds,
/// size), from which each run is generated on demand ([`Plan::run`]), so a
/// plan of millions of runs costs no more memory than its study file.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Plan {
    /// Hash of the plan, the graph file's text, the fixed overrides and the gate
    /// mode (16 hex digits): rows computed under another hash are not reused.
    pub study_hash: String,
    /// The design.
    pub kind: Kind,
    /// The varied parameters' paths (the table's parameter columns).
    pub parameters: Vec<String>,
    /// Number of runs (design points × seeds).
    pub size: usize,
    /// Seed of the sampling.
    pub seed: u64,
    /// Each parameter's design, validated.
    designs: Vec<Dim>,
    /// The graph seeds.
    seeds: Seeds,
}

impl Plan {
    /// Number of runs.
    pub fn len(&self) -> usize {
        self.size
    }

    /// Whether the plan has no runs.
    pub fn is_empty(&self) -> bool {
        self.size == 0
    }

    /// Seeds per design point.
    fn seeds_per_point(&self) -> usize {
        match &self.seeds {
            Seeds::List(s) => s.len(),
            _ => 1,
        }
    }

    /// Run `index`, generated from the definition (`None` past the end): the
    /// same index always gives the same run, bit for bit.
    pub fn run(&self, index: usize) -> Option<PlannedRun> {
        if index >= self.size {
            return None;
        }
        let per = self.seeds_per_point();
        let (point, s) = (index / per, index % per);
        let points = self.size / per;
        let values: Vec<Value> = match self.kind {
            Kind::Grid => {
                // Mixed radix, the first parameter outermost.
                let mut rest = point;
                let mut v: Vec<Value> = self
                    .designs
                    .iter()
                    .rev()
                    .map(|d| {
                        let n = d.grid_len().unwrap_or(1).max(1);
                        let k = rest % n;
                        rest /= n;
                        d.grid_at(k)
                    })
                    .collect();
                v.reverse();
                v
            }
            Kind::Random | Kind::MonteCarlo => {
                let mut rng = Rng::new(mix(self.seed, point as u64));
                self.designs
                    .iter()
                    .map(|d| d.at(open_uniform(&mut rng)))
                    .collect()
            }
            Kind::LatinHypercube => {
                let mut rng = Rng::new(mix(self.seed, point as u64));
                self.designs
                    .iter()
                    .enumerate()
                    .map(|(k, d)| {
                        let key = mix(self.seed ^ 0x4C48_5300, k as u64);
                        let stratum = permuted(point as u64, points as u64, key);
                        d.at((stratum as f64 + open_uniform(&mut rng)) / points as f64)
                    })
                    .collect()
            }
        };
        let seed = match &self.seeds {
            Seeds::PerRun => {
                let mut x = self.seed ^ (index as u64).wrapping_mul(0x9E37_79B9_7F4A_7C15);
                Some(splitmix64(&mut x) >> 1)
            }
            Seeds::List(list) => Some(list[s]),
            Seeds::Graph => None,
        };
        let parameters = self
            .parameters
            .iter()
            .zip(values)
            .map(|(p, value)| Override {
                path: p.clone(),
                segments: nanomotion_core::overrides::Path::parse(p)
                    .expect("checked when the study was loaded"),
                value,
            })
            .collect();
        Some(PlannedRun {
            index,
            parameters,
            seed,
        })
    }

    /// Every run, in order, generated one at a time.
    pub fn runs(&self) -> impl Iterator<Item = PlannedRun> + '_ {
        (0..self.size).filter_map(|i| self.run(i))
    }

    /// Whether parameter `k` only takes numbers.
    fn numeric(&self, k: usize) -> bool {
        self.designs.get(k).is_some_and(Dim::numeric)
    }
}

/// A 64-bit mix of a seed and a counter (splitmix64 of their combination).
fn mix(seed: u64, k: u64) -> u64 {
    let mut x = seed ^ k.wrapping_mul(0xD1B5_4A32_D192_ED03);
    splitmix64(&mut x)
}

/// Position of `i` in a pseudo-random permutation of 0..n chosen by `key`: a
/// four-round Feistel network on the smallest even number of bits covering n,
/// cycle-walked back into 0..n (a bijection of 0..n, computed without storing
/// the permutation).
fn permuted(i: u64, n: u64, key: u64) -> u64 {
    if n <= 1 {
        return 0;
    }
    let bits = (64 - (n - 1).leading_zeros()).max(2);
    let half = bits.div_ceil(2);
    let mask = (1u64 << half) - 1;
    let mut x = i;
    loop {
        let (mut l, mut r) = (x >> half, x & mask);
        for round in 0..4u64 {
            let f = mix(key ^ round.wrapping_mul(0x9E37_79B9), r) & mask;
            (l, r) = (r, l ^ f);
        }
        x = (l << half) | r;
        if x < n {
            return x;
        }
    }
}

/// One score of a run (as `nanomotion run` prints it).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ScoreValue {
    /// The scored signal (`block.port`).
    pub signal: String,
    /// Root mean square.
    pub rms: f64,
    /// Largest absolute value.
    pub max_abs: f64,
    /// Mean.
    pub mean: f64,
    /// Unit, if known.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub unit: Option<String>,
}

/// The outcome of one run: a row of the results table.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Row {
    /// The plan's hash ([`Plan::study_hash`]).
    pub study: String,
    /// The run's index in the plan.
    pub index: usize,
    /// The varied parameters' values.
    pub parameters: Vec<Override>,
    /// The graph seed the run used (`None` if the graph did not load).
    pub seed: Option<u64>,
    /// The scores (empty when the run failed).
    pub scores: Vec<ScoreValue>,
    /// Wall time of building, checking and simulating (s).
    pub wall_s: f64,
    /// The stability gate's verdict (`pass`, or `refused: …`; `None` when off).
    pub gate: Option<String>,
    /// Why the run failed, if it did.
    pub error: Option<String>,
}

/// A loaded study: the file, its graph and the fixed overrides.
#[derive(Debug, Clone)]
pub struct Study {
    /// The study as written.
    pub file: StudyFile,
    /// Where it was read from (error messages).
    pub origin: String,
    /// The graph file, resolved.
    pub graph_path: PathBuf,
    graph_text: String,
    fixed: Vec<Override>,
    dims: Vec<Dim>,
    seeds: Seeds,
    size: usize,
}

/// Largest study file read: 16 MiB.
const MAX_STUDY_BYTES: u64 = 16 << 20;

impl Study {
    /// Read a study file; its `graph:` resolves against the file's folder.
    pub fn from_file(path: impl AsRef<Path>) -> Result<Self, SweepError> {
        let path = path.as_ref();
        let text = nanomotion_core::graph::read_text_capped(path, MAX_STUDY_BYTES)
            .map_err(io_err(path))?;
        let dir = path
            .parent()
            .filter(|p| !p.as_os_str().is_empty())
            .unwrap_or(Path::new("."));
        Self::from_yaml(&text, &path.display().to_string(), dir)
    }

    /// Parse a study from YAML text; `origin` names it in errors, `dir` is the
    /// folder `graph:` is relative to.
    pub fn from_yaml(text: &str, origin: &str, dir: &Path) -> Result<Self, SweepError> {
        let file: StudyFile =
            nanomotion_core::yaml::from_str(text, origin).map_err(|e| SweepError::Study {
                origin: origin.into(),
                problem: e.to_string(),
                fix: "see docs/sweep.md for the study format".into(),
            })?;
        let bad = |problem: String, fix: &str| SweepError::Study {
            origin: origin.into(),
            problem,
            fix: fix.into(),
        };
        let graph_path = dir.join(&file.graph);
        let graph_text = nanomotion_core::graph::read_text_capped(
            &graph_path,
            nanomotion_core::graph::MAX_GRAPH_FILE_BYTES,
        )
        .map_err(io_err(&graph_path))?;
        let mut fixed = Vec::new();
        for (path, value) in &file.set {
            fixed.push(
                Override::new(path, value.clone()).map_err(|source| SweepError::Graph {
                    origin: origin.into(),
                    source: Box::new(source),
                })?,
            );
        }
        let mut dims = Vec::new();
        for p in &file.parameters {
            let chosen = [
                p.values.is_some(),
                p.range.is_some(),
                p.uniform.is_some(),
                p.normal.is_some(),
                p.lognormal.is_some(),
            ]
            .iter()
            .filter(|x| **x)
            .count();
            let what = "give exactly one of `values`, `range` (with `steps` for a grid), `uniform`, `normal`, `lognormal`";
            if chosen != 1 {
                return Err(bad(
                    format!("parameter `{}` gives {chosen} designs", p.path),
                    what,
                ));
            }
            let finite = |xs: &[f64]| xs.iter().all(|x| x.is_finite());
            let dim = if let Some(v) = &p.values {
                if v.is_empty() {
                    return Err(bad(
                        format!("parameter `{}` has an empty `values` list", p.path),
                        "list at least one value",
                    ));
                }
                Dim::Values(v.clone())
            } else if let Some([lo, hi]) = p.range.or(p.uniform) {
                if !finite(&[lo, hi]) || hi < lo || (p.log && lo <= 0.0) {
                    return Err(bad(
                        format!("parameter `{}` has the range [{lo}, {hi}]", p.path),
                        "give finite [low, high] with low ≤ high (both > 0 with `log: true`)",
                    ));
                }
                if let Some(n) = p.steps
                    && n < 2
                {
                    return Err(bad(
                        format!("parameter `{}` has steps: {n}", p.path),
                        "give at least 2 steps (the ends are included), or use `values: [x]`",
                    ));
                }
                Dim::Range {
                    lo,
                    hi,
                    steps: p.steps,
                    log: p.log,
                }
            } else if let Some(n) = p.normal {
                if !finite(&[n.mean, n.std]) || n.std < 0.0 {
                    return Err(bad(
                        format!(
                            "parameter `{}`: normal {{ mean: {}, std: {} }}",
                            p.path, n.mean, n.std
                        ),
                        "give a finite mean and a finite std ≥ 0",
                    ));
                }
                Dim::Normal(n)
            } else if let Some(l) = p.lognormal {
                if !finite(&[l.median, l.sigma]) || l.median <= 0.0 || l.sigma < 0.0 {
                    return Err(bad(
                        format!(
                            "parameter `{}`: lognormal {{ median: {}, sigma: {} }}",
                            p.path, l.median, l.sigma
                        ),
                        "give a finite median > 0 and a finite sigma ≥ 0",
                    ));
                }
                Dim::LogNormal(l)
            } else {
                unreachable!("one design was checked to be present")
            };
            if file.study == Kind::Grid && dim.grid_len().is_none() {
                return Err(bad(
                    format!("parameter `{}` has no grid points", p.path),
                    "a grid needs `values` or `range` with `steps`; distributions belong in a `monte-carlo` or `random` study",
                ));
            }
            if p.steps.is_some() && file.study != Kind::Grid {
                return Err(bad(
                    format!("parameter `{}` has `steps`, which only a grid uses", p.path),
                    "remove `steps`, or make the study a `grid`",
                ));
            }
            dims.push(dim);
        }
        if file.study != Kind::Grid {
            match file.runs {
                Some(n) if (1..=MAX_RUNS).contains(&n) => {}
                _ => {
                    return Err(bad(
                        format!("a {} study needs `runs`", file.study.as_str()),
                        &format!("give runs: N with 1 ≤ N ≤ {MAX_RUNS}"),
                    ));
                }
            }
        } else if file.runs.is_some() {
            return Err(bad(
                "a grid has no `runs` (its size is the product of the parameters' points)".into(),
                "remove `runs`",
            ));
        }
        let seeds = match &file.seeds {
            None => Seeds::Graph,
            Some(Value::String(s)) if s == "graph" => Seeds::Graph,
            Some(Value::String(s)) if s == "per-run" => Seeds::PerRun,
            Some(Value::Array(a)) if !a.is_empty() && a.iter().all(Value::is_u64) => {
                Seeds::List(a.iter().filter_map(Value::as_u64).collect())
            }
            Some(other) => {
                return Err(bad(
                    format!("`seeds: {other}` is not understood"),
                    "write `seeds: graph` (the graph's seed), `seeds: per-run` or a list of non-negative integers `seeds: [1, 2, 3]`",
                ));
            }
        };
        refuse_duplicate_paths(&file, text, origin)?;
        let size = plan_size(&file, &dims, &seeds, origin)?;
        let study = Study {
            origin: origin.into(),
            graph_path,
            graph_text,
            fixed,
            dims,
            seeds,
            size,
            file,
        };
        study.check_graph()?;
        Ok(study)
    }

    /// The graph loads with the fixed overrides and each parameter's path fits it
    /// (tried with a value of its design): a wrong path stops the study at once.
    fn check_graph(&self) -> Result<(), SweepError> {
        let graph_err = |source| SweepError::Graph {
            origin: self.origin.clone(),
            source: Box::new(source),
        };
        let spec = GraphSpec::from_file_with_overrides(&self.graph_path, &self.fixed)
            .map_err(graph_err)?;
        if !spec.compare.is_empty() {
            return Err(SweepError::Study {
                origin: self.origin.clone(),
                problem: format!(
                    "the graph {} compares signals with measured data (`compare:`), which a sweep does not load",
                    self.graph_path.display()
                ),
                fix: "sweep a graph without `compare:` (use `score:` for what to measure)".into(),
            });
        }
        let mut probe = Vec::new();
        for (p, d) in self.file.parameters.iter().zip(&self.dims) {
            probe.push(Override::new(&p.path, d.at(0.5)).map_err(graph_err)?);
        }
        GraphSpec::from_file_with_overrides(&self.graph_path, &probe).map_err(graph_err)?;
        Ok(())
    }

    /// The deterministic plan: the same study file (and graph) gives the same
    /// plan, bit for bit, on every machine. Only its definition is built; runs
    /// are generated on demand ([`Plan::run`]).
    pub fn plan(&self) -> Plan {
        let mut plan = Plan {
            study_hash: String::new(),
            kind: self.file.study,
            parameters: self
                .file
                .parameters
                .iter()
                .map(|p| p.path.clone())
                .collect(),
            size: self.size,
            seed: self.file.seed,
            designs: self.dims.clone(),
            seeds: self.seeds.clone(),
        };
        let mut h = Fnv::default();
        h.write(serde_json::to_string(&plan).unwrap_or_default().as_bytes());
        h.write(self.graph_text.as_bytes());
        h.write(
            serde_json::to_string(&self.fixed)
                .unwrap_or_default()
                .as_bytes(),
        );
        h.write(self.file.gate.as_str().as_bytes());
        plan.study_hash = format!("{:016x}", h.0);
        plan
    }

    /// Run one planned run: build the graph with the fixed and the run's
    /// overrides, check it with the gate (see [`GateMode`]), simulate it (no
    /// files) and collect its scores. Every failure, a panic included, becomes
    /// the row's `error`.
    pub fn run_one(&self, plan: &Plan, run: &PlannedRun) -> Row {
        let start = std::time::Instant::now();
        let mut row = Row {
            study: plan.study_hash.clone(),
            index: run.index,
            parameters: run.parameters.clone(),
            seed: None,
            scores: Vec::new(),
            wall_s: 0.0,
            gate: None,
            error: None,
        };
        let outcome = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| {
            self.simulate(run, &mut row)
        }));
        match outcome {
            Ok(Ok(())) => {}
            Ok(Err(e)) => row.error = Some(e),
            Err(panic) => {
                let what = panic
                    .downcast_ref::<&str>()
                    .map(|s| s.to_string())
                    .or_else(|| panic.downcast_ref::<String>().cloned())
                    .unwrap_or_else(|| "unknown panic".into());
                row.scores.clear();
                row.error = Some(format!(
                    "the run panicked: {what} (a bug in a block: please report it with this row's parameters)"
                ));
            }
        }
        row.wall_s = start.elapsed().as_secs_f64();
        row
    }

    fn simulate(&self, run: &PlannedRun, row: &mut Row) -> Result<(), String> {
        let mut set = self.fixed.clone();
        set.extend(run.parameters.iter().cloned());
        if let Some(s) = run.seed {
            set.push(Override::new("seed", s).map_err(|e| e.to_string())?);
        }
        let spec = GraphSpec::from_file_with_overrides(&self.graph_path, &set)
            .map_err(|e| e.to_string())?;
        row.seed = Some(spec.seed);
        let require = spec.require.clone().unwrap_or_default();
        let (mut sched, _) = spec.build_streamed(None).map_err(|e| e.to_string())?;
        if self.file.gate != GateMode::Off {
            let report = nanomotion_core::gate::analyse(&sched, &require);
            if report.passes() {
                row.gate = Some("pass".into());
            } else {
                let refused = format!("refused: {}", report.failures().join("; "));
                row.gate = Some(refused.clone());
                if self.file.gate == GateMode::Refuse {
                    return Err(format!("the stability gate {refused}"));
                }
            }
        }
        let result = sched
            .run_streamed(|_| Ok::<(), std::convert::Infallible>(()), |_| {})
            .unwrap_or_else(|e| match e {});
        sched.check_finite().map_err(|e| e.to_string())?;
        for s in &result.scores {
            if !(s.rms.is_finite() && s.max_abs.is_finite() && s.mean.is_finite()) {
                return Err(format!("score of `{}` is not finite", s.signal));
            }
            row.scores.push(ScoreValue {
                signal: s.signal.clone(),
                rms: s.rms,
                max_abs: s.max_abs,
                mean: s.mean,
                unit: s.unit.clone(),
            });
        }
        Ok(())
    }

    /// Run the plan's runs `indices` on a pool of `jobs` threads (0: all cores;
    /// more than the cores is capped, see [`capped_jobs`]), calling `on_row` as
    /// each finishes (from the worker threads). The rows come back in the order
    /// of `indices`. An index outside the plan is an error row. After Ctrl-C
    /// ([`crate::output::signals`]) no more runs start: fewer rows come back.
    pub fn run_chunk(
        &self,
        plan: &Plan,
        indices: &[usize],
        jobs: usize,
        on_row: impl Fn(&Row) + Sync,
    ) -> Vec<Row> {
        use rayon::prelude::*;
        let work = || {
            indices
                .par_iter()
                .filter_map(|&i| {
                    // Ctrl-C: start no more runs (the finished ones are kept).
                    if crate::output::signals::interrupted().is_some() {
                        return None;
                    }
                    let row = match plan.run(i) {
                        Some(run) => self.run_one(plan, &run),
                        None => Row {
                            study: plan.study_hash.clone(),
                            index: i,
                            parameters: Vec::new(),
                            seed: None,
                            scores: Vec::new(),
                            wall_s: 0.0,
                            gate: None,
                            error: Some(format!(
                                "run {i} is not in the plan, which has {} runs",
                                plan.len()
                            )),
                        },
                    };
                    on_row(&row);
                    Some(row)
                })
                .collect()
        };
        match rayon::ThreadPoolBuilder::new()
            .num_threads(capped_jobs(jobs).0)
            .build()
        {
            Ok(pool) => pool.install(work),
            Err(_) => work(),
        }
    }
}

/// The 1-based lines of `text` where `key` (a parameter path) is written: as
/// the value of `path:`, or as a key of `set:` (`key:`).
fn lines_naming(text: &str, key: &str) -> Vec<usize> {
    let path_char = |c: char| c.is_alphanumeric() || matches!(c, '.' | '_' | '[' | ']' | '-');
    let mut out = Vec::new();
    for (n, line) in text.lines().enumerate() {
        let hit = line.match_indices(key).any(|(at, _)| {
            let before = line[..at].trim_end_matches(['"', '\'']);
            let after = line[at + key.len()..].trim_start_matches(['"', '\'']);
            let whole = !before.ends_with(path_char) && !after.starts_with(path_char);
            whole && (before.trim_end().ends_with("path:") || after.trim_start().starts_with(':'))
        });
        if hit {
            out.push(n + 1);
        }
    }
    out
}

/// A parameter path given twice (two `parameters:` entries, or a parameter that
/// `set:` also fixes) is refused, naming both lines: only one value would be
/// used, and the table would show both.
fn refuse_duplicate_paths(file: &StudyFile, text: &str, origin: &str) -> Result<(), SweepError> {
    use nanomotion_core::overrides::Path as OPath;
    let parsed: Vec<Option<OPath>> = file
        .parameters
        .iter()
        .map(|p| OPath::parse(&p.path).ok())
        .collect();
    let where_ = |key: &str, nth: usize, entry: String| match lines_naming(text, key).get(nth) {
        Some(l) => format!("line {l}"),
        None => entry,
    };
    for j in 0..parsed.len() {
        for i in 0..j {
            if parsed[i].is_some() && parsed[i] == parsed[j] {
                let (a, b) = (&file.parameters[i].path, &file.parameters[j].path);
                let same = usize::from(a == b);
                return Err(SweepError::Study {
                    origin: origin.into(),
                    problem: format!(
                        "parameter `{b}` is given twice: {} (`{a}`) and {} (`{b}`); only the second value would be used",
                        where_(a, 0, format!("parameters entry {}", i + 1)),
                        where_(b, same, format!("parameters entry {}", j + 1)),
                    ),
                    fix: "give each path once (list several values in one entry: `values: [...]`)"
                        .into(),
                });
            }
        }
        for key in file.set.keys() {
            if parsed[j].is_some() && OPath::parse(key).ok() == parsed[j] {
                let b = &file.parameters[j].path;
                return Err(SweepError::Study {
                    origin: origin.into(),
                    problem: format!(
                        "`{b}` is both fixed by `set:` ({}) and varied ({}); the varied value would silently win",
                        where_(key, 0, "in `set:`".into()),
                        where_(
                            b,
                            usize::from(key == b),
                            format!("parameters entry {}", j + 1)
                        ),
                    ),
                    fix: format!("remove `{key}` from `set:` or the parameter entry"),
                });
            }
        }
    }
    Ok(())
}

/// The number of runs of a study, refused above [`MAX_RUNS`] before anything
/// is allocated, naming the parameter (or setting) to lower.
fn plan_size(
    file: &StudyFile,
    dims: &[Dim],
    seeds: &Seeds,
    origin: &str,
) -> Result<usize, SweepError> {
    let per = match seeds {
        Seeds::List(s) => s.len(),
        _ => 1,
    };
    let too_many = |problem: String, fix: String| SweepError::Study {
        origin: origin.into(),
        problem,
        fix,
    };
    let points = match file.study {
        Kind::Grid => {
            let mut n: Option<usize> = Some(1);
            let mut largest: Option<(usize, usize)> = None;
            for (k, d) in dims.iter().enumerate() {
                let len = d.grid_len().unwrap_or(1);
                n = n.and_then(|n| n.checked_mul(len));
                if largest.is_none_or(|(_, l)| len > l) {
                    largest = Some((k, len));
                }
            }
            match (n, largest) {
                (Some(n), _) if n.checked_mul(per).is_some_and(|t| t <= MAX_RUNS) => n,
                (n, Some((k, len))) => {
                    let p = &file.parameters[k];
                    let what = if p.steps.is_some() { "steps" } else { "values" };
                    return Err(too_many(
                        format!(
                            "the grid has {} runs ({}{}), more than the {MAX_RUNS} a study may plan",
                            n.and_then(|n| n.checked_mul(per))
                                .map_or_else(|| "more than 2^64".to_string(), |t| t.to_string()),
                            dims.iter()
                                .map(|d| d.grid_len().unwrap_or(1).to_string())
                                .collect::<Vec<_>>()
                                .join(" × "),
                            if per > 1 {
                                format!(" × {per} seeds")
                            } else {
                                String::new()
                            },
                        ),
                        format!(
                            "lower `{what}` of parameter `{}` ({len} points), or split the study",
                            p.path
                        ),
                    ));
                }
                (_, None) => 1,
            }
        }
        _ => file.runs.unwrap_or(0),
    };
    match points.checked_mul(per) {
        Some(t) if t <= MAX_RUNS => Ok(t),
        _ => Err(too_many(
            format!(
                "{points} runs × {per} seeds is more than the {MAX_RUNS} runs a study may plan"
            ),
            "lower `runs`, or list fewer `seeds`".into(),
        )),
    }
}

/// `jobs` as used (0: all cores), capped at the machine's cores: more threads
/// than cores only slow the runs down. Returns the count and, when capped, a
/// note saying so.
pub fn capped_jobs(jobs: usize) -> (usize, Option<String>) {
    let cores = std::thread::available_parallelism().map_or(1, usize::from);
    match jobs {
        0 => (cores, None),
        j if j > cores => (
            cores,
            Some(format!(
                "--jobs {j} is more than the {cores} core(s) of this machine: using {cores}"
            )),
        ),
        j => (j, None),
    }
}

/// FNV-1a, 64 bits: a hash that is the same on every machine and Rust version.
struct Fnv(u64);

impl Default for Fnv {
    fn default() -> Self {
        Fnv(0xCBF2_9CE4_8422_2325)
    }
}

impl Fnv {
    fn write(&mut self, bytes: &[u8]) {
        for b in bytes {
            self.0 ^= u64::from(*b);
            self.0 = self.0.wrapping_mul(0x0000_0100_0000_01B3);
        }
        // Separate fields: "ab"+"c" ≠ "a"+"bc".
        self.0 ^= 0xFF;
        self.0 = self.0.wrapping_mul(0x0000_0100_0000_01B3);
    }
}

/// A uniform draw in the open interval (0, 1): inverse CDFs stay finite.
fn open_uniform(rng: &mut Rng) -> f64 {
    ((rng.next_u64() >> 11) as f64 + 0.5) * (1.0 / (1u64 << 53) as f64)
}

/// The append-only file of finished rows (`rows.jsonl`, one JSON [`Row`] per
/// line) in a study's output folder.
pub struct RowStore {
    path: PathBuf,
    file: std::sync::Mutex<std::fs::File>,
}

impl RowStore {
    /// Open (or create) the store in `dir` for `plan`, returning the finished rows
    /// it holds (by index, first occurrence kept). Rows of another plan are an
    /// error ([`SweepError::Changed`]) unless `restart`, which discards them. A
    /// half-written last line (a killed run) is dropped.
    pub fn open(dir: &Path, plan: &Plan, restart: bool) -> Result<(Self, Vec<Row>), SweepError> {
        std::fs::create_dir_all(dir).map_err(io_err(dir))?;
        let path = dir.join(ROWS_FILE);
        let mut rows: Vec<Row> = Vec::new();
        if path.exists() && !restart {
            let text = std::fs::read_to_string(&path).map_err(io_err(&path))?;
            // Keep whole lines only.
            let whole = match text.rfind('\n') {
                Some(end) => &text[..=end],
                None => "",
            };
            if whole.len() != text.len() {
                std::fs::OpenOptions::new()
                    .write(true)
                    .open(&path)
                    .and_then(|f| f.set_len(whole.len() as u64))
                    .map_err(io_err(&path))?;
            }
            let mut seen = vec![false; plan.len()];
            let mut other: Option<(String, usize)> = None;
            for line in whole.lines().filter(|l| !l.trim().is_empty()) {
                let Ok(row) = serde_json::from_str::<Row>(line) else {
                    tracing::warn!("{}: skipping an unreadable line", path.display());
                    continue;
                };
                if row.study != plan.study_hash {
                    let o = other.get_or_insert((row.study.clone(), 0));
                    o.1 += 1;
                    continue;
                }
                if row.index < seen.len() && !seen[row.index] {
                    seen[row.index] = true;
                    rows.push(row);
                }
            }
            if let Some((found, n)) = other {
                return Err(SweepError::Changed {
                    dir: dir.display().to_string(),
                    rows: n,
                    found,
                    expected: plan.study_hash.clone(),
                });
            }
        } else if path.exists() {
            std::fs::remove_file(&path).map_err(io_err(&path))?;
        }
        let file = std::fs::OpenOptions::new()
            .create(true)
            .append(true)
            .open(&path)
            .map_err(io_err(&path))?;
        rows.sort_by_key(|r| r.index);
        Ok((
            RowStore {
                path,
                file: std::sync::Mutex::new(file),
            },
            rows,
        ))
    }

    /// Append one finished row (one line, written at once and flushed).
    pub fn append(&self, row: &Row) -> Result<(), SweepError> {
        let mut line = serde_json::to_string(row).map_err(|e| SweepError::Io {
            path: self.path.display().to_string(),
            source: std::io::Error::other(e),
        })?;
        line.push('\n');
        let mut f = self
            .file
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner);
        f.write_all(line.as_bytes())
            .and_then(|()| f.flush())
            .map_err(io_err(&self.path))
    }
}

/// The columns of the results table, in order.
#[derive(Debug, Clone, PartialEq)]
pub struct Columns {
    /// Parameter paths.
    pub parameters: Vec<String>,
    /// Scored signals, in the order they first appear.
    pub signals: Vec<String>,
    /// Whether each parameter column holds numbers only.
    pub numeric: Vec<bool>,
}

impl Columns {
    /// The columns of `rows` (sorted by index) of `plan`.
    pub fn of(plan: &Plan, rows: &[Row]) -> Self {
        let mut signals: Vec<String> = Vec::new();
        for r in rows {
            for s in &r.scores {
                if !signals.contains(&s.signal) {
                    signals.push(s.signal.clone());
                }
            }
        }
        let numeric = (0..plan.parameters.len())
            .map(|k| plan.numeric(k))
            .collect();
        Columns {
            parameters: plan.parameters.clone(),
            signals,
            numeric,
        }
    }

    /// The header of `results.csv`: `index, seed, <parameters>, <signal>.rms,
    /// <signal>.max_abs, <signal>.mean ..., wall_s, gate, error`.
    pub fn header(&self) -> Vec<String> {
        let mut h = vec!["index".to_string(), "seed".to_string()];
        h.extend(self.parameters.iter().cloned());
        for s in &self.signals {
            for m in ["rms", "max_abs", "mean"] {
                h.push(format!("{s}.{m}"));
            }
        }
        h.extend(["wall_s", "gate", "error"].map(String::from));
        h
    }
}

fn value_text(v: &Value) -> String {
    match v {
        Value::Number(n) => match n.as_f64() {
            Some(x) if n.is_f64() => format!("{x:e}"),
            _ => n.to_string(),
        },
        Value::String(s) => s.clone(),
        other => other.to_string(),
    }
}

fn score_of<'a>(r: &'a Row, signal: &str) -> Option<&'a ScoreValue> {
    r.scores.iter().find(|s| s.signal == signal)
}

/// Write `results.csv`, `results.parquet`, `plan.json` and the plots into `dir`
/// from `rows` (any order; one per index), atomically: staged in a hidden
/// folder inside `dir` and renamed in when all are written, with the manifest
/// last ([`crate::output::OutputFolder::add_to`]; `rows.jsonl` stays). Returns
/// the files written.
pub fn write_results(
    dir: &Path,
    study: &Study,
    plan: &Plan,
    rows: &[Row],
) -> Result<Vec<PathBuf>, SweepError> {
    let folder = crate::output::OutputFolder::add_to(dir)?;
    write_results_into(folder.dir(), study, plan, rows)?;
    Ok(folder.commit(Some(&crate::output::Manifest {
        command: "sweep",
        graph: &study.origin,
        title: &study.file.title,
        stability_gate: &[],
    }))?)
}

fn write_results_into(
    dir: &Path,
    study: &Study,
    plan: &Plan,
    rows: &[Row],
) -> Result<Vec<PathBuf>, SweepError> {
    let mut rows: Vec<&Row> = rows.iter().collect();
    rows.sort_by_key(|r| r.index);
    let owned: Vec<Row> = rows.iter().map(|r| (*r).clone()).collect();
    let cols = Columns::of(plan, &owned);
    let mut files = Vec::new();

    // plan.json
    let plan_path = dir.join("plan.json");
    let text = serde_json::to_string_pretty(plan).map_err(|e| SweepError::Io {
        path: plan_path.display().to_string(),
        source: std::io::Error::other(e),
    })?;
    std::fs::write(&plan_path, text).map_err(io_err(&plan_path))?;
    files.push(plan_path);

    // results.csv
    let csv_path = dir.join("results.csv");
    let csv_err = |e: csv::Error| SweepError::Io {
        path: csv_path.display().to_string(),
        source: std::io::Error::other(e),
    };
    let mut w = csv::Writer::from_path(&csv_path).map_err(csv_err)?;
    w.write_record(cols.header()).map_err(csv_err)?;
    for r in &owned {
        let mut rec = vec![
            r.index.to_string(),
            r.seed.map(|s| s.to_string()).unwrap_or_default(),
        ];
        for k in 0..cols.parameters.len() {
            rec.push(
                r.parameters
                    .get(k)
                    .map(|o| value_text(&o.value))
                    .unwrap_or_default(),
            );
        }
        for s in &cols.signals {
            match score_of(r, s) {
                Some(v) => rec.extend([v.rms, v.max_abs, v.mean].map(|x| format!("{x:e}"))),
                None => rec.extend([String::new(), String::new(), String::new()]),
            }
        }
        rec.push(format!("{:e}", r.wall_s));
        rec.push(r.gate.clone().unwrap_or_default());
        rec.push(r.error.clone().unwrap_or_default());
        w.write_record(&rec).map_err(csv_err)?;
    }
    w.flush().map_err(io_err(&csv_path))?;
    files.push(csv_path);

    let pq = dir.join("results.parquet");
    write_parquet(&pq, &cols, &owned)?;
    files.push(pq);

    files.extend(write_plots(dir, study, plan, &cols, &owned)?);
    Ok(files)
}

fn write_parquet(path: &Path, cols: &Columns, rows: &[Row]) -> Result<(), SweepError> {
    use parquet::basic::{LogicalType, Repetition, Type as Physical};
    use parquet::data_type::{ByteArray, ByteArrayType, DoubleType, Int64Type};
    use parquet::file::writer::SerializedFileWriter;
    use parquet::schema::types::Type;
    use std::sync::Arc;
    let perr = |e: parquet::errors::ParquetError| SweepError::Parquet {
        path: path.display().to_string(),
        message: e.to_string(),
    };
    enum Col {
        Long(Vec<Option<i64>>),
        Double(Vec<Option<f64>>),
        Text(Vec<Option<String>>),
    }
    let mut columns: Vec<(String, Col)> = vec![
        (
            "index".into(),
            Col::Long(rows.iter().map(|r| Some(r.index as i64)).collect()),
        ),
        (
            "seed".into(),
            // Seeds are u64; Parquet INT64 holds them as the same 64 bits.
            Col::Long(rows.iter().map(|r| r.seed.map(|s| s as i64)).collect()),
        ),
    ];
    for (k, name) in cols.parameters.iter().enumerate() {
        let vals = rows.iter().map(|r| r.parameters.get(k).map(|o| &o.value));
        let col = if cols.numeric[k] {
            Col::Double(vals.map(|v| v.and_then(Value::as_f64)).collect())
        } else {
            Col::Text(vals.map(|v| v.map(value_text)).collect())
        };
        columns.push((name.clone(), col));
    }
    for s in &cols.signals {
        for (m, get) in [
            ("rms", (|v: &ScoreValue| v.rms) as fn(&ScoreValue) -> f64),
            ("max_abs", |v| v.max_abs),
            ("mean", |v| v.mean),
        ] {
            columns.push((
                format!("{s}.{m}"),
                Col::Double(rows.iter().map(|r| score_of(r, s).map(get)).collect()),
            ));
        }
    }
    columns.push((
        "wall_s".into(),
        Col::Double(rows.iter().map(|r| Some(r.wall_s)).collect()),
    ));
    columns.push((
        "gate".into(),
        Col::Text(rows.iter().map(|r| r.gate.clone()).collect()),
    ));
    columns.push((
        "error".into(),
        Col::Text(rows.iter().map(|r| r.error.clone()).collect()),
    ));
    let fields = columns
        .iter()
        .map(|(name, c)| {
            let (phys, logical) = match c {
                Col::Long(_) => (Physical::INT64, None),
                Col::Double(_) => (Physical::DOUBLE, None),
                Col::Text(_) => (Physical::BYTE_ARRAY, Some(LogicalType::String)),
            };
            Type::primitive_type_builder(name, phys)
                .with_repetition(Repetition::OPTIONAL)
                .with_logical_type(logical)
                .build()
                .map(Arc::new)
        })
        .collect::<Result<Vec<_>, _>>()
        .map_err(perr)?;
    let schema = Arc::new(
        Type::group_type_builder("results")
            .with_fields(fields)
            .build()
            .map_err(perr)?,
    );
    let file = std::fs::File::create(path).map_err(io_err(path))?;
    let mut writer = SerializedFileWriter::new(file, schema, Default::default()).map_err(perr)?;
    let mut group = writer.next_row_group().map_err(perr)?;
    for (_, c) in &columns {
        let Some(mut cw) = group.next_column().map_err(perr)? else {
            break;
        };
        fn split<T: Clone>(v: &[Option<T>]) -> (Vec<T>, Vec<i16>) {
            let defs = v.iter().map(|x| i16::from(x.is_some())).collect();
            (v.iter().flatten().cloned().collect(), defs)
        }
        match c {
            Col::Long(v) => {
                let (vals, defs) = split(v);
                cw.typed::<Int64Type>()
                    .write_batch(&vals, Some(&defs), None)
                    .map_err(perr)?;
            }
            Col::Double(v) => {
                let (vals, defs) = split(v);
                cw.typed::<DoubleType>()
                    .write_batch(&vals, Some(&defs), None)
                    .map_err(perr)?;
            }
            Col::Text(v) => {
                let (vals, defs) = split(v);
                let vals: Vec<ByteArray> =
                    vals.iter().map(|s| ByteArray::from(s.as_str())).collect();
                cw.typed::<ByteArrayType>()
                    .write_batch(&vals, Some(&defs), None)
                    .map_err(perr)?;
            }
        }
        cw.close().map_err(perr)?;
    }
    group.close().map_err(perr)?;
    writer.close().map_err(perr)?;
    Ok(())
}

/// The SVG plots: for each numeric parameter, every score's rms against it
/// (`scatter_<path>.svg`); for a Monte-Carlo study, a histogram of each score's
/// rms (`hist_<signal>.svg`). Failed runs are left out.
fn write_plots(
    dir: &Path,
    study: &Study,
    plan: &Plan,
    cols: &Columns,
    rows: &[Row],
) -> Result<Vec<PathBuf>, SweepError> {
    let ok: Vec<&Row> = rows.iter().filter(|r| r.error.is_none()).collect();
    let mut files = Vec::new();
    if ok.is_empty() || cols.signals.is_empty() {
        return Ok(files);
    }
    let title = study
        .file
        .title
        .clone()
        .unwrap_or_else(|| format!("{} study of {}", plan.kind.as_str(), study.file.graph));
    let unit_of = |s: &str| {
        ok.iter()
            .find_map(|r| score_of(r, s).and_then(|v| v.unit.clone()))
    };
    for (k, name) in cols.parameters.iter().enumerate() {
        if !cols.numeric[k] {
            continue;
        }
        let series: Vec<(String, Vec<(f64, f64)>)> = cols
            .signals
            .iter()
            .map(|s| {
                let pts = ok
                    .iter()
                    .filter_map(|r| {
                        let x = r.parameters.get(k)?.value.as_f64()?;
                        Some((x, score_of(r, s)?.rms))
                    })
                    .collect();
                (format!("{s} rms"), pts)
            })
            .collect();
        let unit = cols.signals.first().and_then(|s| unit_of(s));
        let path = dir.join(format!("scatter_{}.svg", crate::output::file_stem(name)));
        draw_scatter(&path, &title, name, unit.as_deref(), &series)?;
        files.push(path);
    }
    if plan.kind == Kind::MonteCarlo {
        for s in &cols.signals {
            let xs: Vec<f64> = ok
                .iter()
                .filter_map(|r| Some(score_of(r, s)?.rms))
                .collect();
            let path = dir.join(format!("hist_{}.svg", crate::output::file_stem(s)));
            draw_histogram(
                &path,
                &title,
                &format!("{s} rms"),
                unit_of(s).as_deref(),
                &xs,
            )?;
            files.push(path);
        }
    }
    Ok(files)
}

fn plot_err(path: &Path) -> impl Fn(String) -> crate::plot::PlotError + '_ {
    move |message| crate::plot::PlotError {
        path: path.display().to_string(),
        message,
    }
}

/// Engineering exponent (multiple of 3) of the largest |value|.
fn eng_exponent(max_abs: f64) -> i32 {
    if max_abs > 0.0 && max_abs.is_finite() {
        (max_abs.log10() / 3.0).floor() as i32 * 3
    } else {
        0
    }
}

fn draw_scatter(
    path: &Path,
    title: &str,
    x_name: &str,
    unit: Option<&str>,
    series: &[(String, Vec<(f64, f64)>)],
) -> Result<(), SweepError> {
    use plotters::prelude::*;
    let err = plot_err(path);
    let Some((x0, x1, y0, y1)) = crate::plot::data_bounds(series) else {
        return Ok(());
    };
    let ey = eng_exponent(y0.abs().max(y1.abs()));
    let sy = 10f64.powi(-ey);
    let (y0, y1) = (y0 * sy, y1 * sy);
    let pad = |a: f64, b: f64| {
        if b > a {
            0.05 * (b - a)
        } else {
            a.abs().max(1e-12) * 0.1
        }
    };
    let (px, py) = (pad(x0, x1), pad(y0, y1));
    let root = SVGBackend::new(path, (800, 450)).into_drawing_area();
    root.fill(&WHITE).map_err(|e| err(e.to_string()))?;
    let mut chart = ChartBuilder::on(&root)
        .caption(title, ("sans-serif", 18))
        .margin(12)
        .x_label_area_size(40)
        .y_label_area_size(80)
        .build_cartesian_2d((x0 - px)..(x1 + px), (y0 - py)..(y1 + py))
        .map_err(|e| err(e.to_string()))?;
    chart
        .configure_mesh()
        .x_desc(x_name)
        .y_desc(crate::plot::axis_label("score rms", unit, ey))
        .x_label_formatter(&|v| format!("{v:.3e}"))
        .draw()
        .map_err(|e| err(e.to_string()))?;
    for (i, (label, pts)) in series.iter().enumerate() {
        let color = Palette99::pick(i).to_rgba();
        chart
            .draw_series(
                pts.iter()
                    .map(|&(x, y)| Circle::new((x, y * sy), 3, color.filled())),
            )
            .map_err(|e| err(e.to_string()))?
            .label(label.as_str())
            .legend(move |(x, y)| Circle::new((x + 8, y), 4, color.filled()));
    }
    chart
        .configure_series_labels()
        .background_style(WHITE.mix(0.8))
        .border_style(BLACK)
        .draw()
        .map_err(|e| err(e.to_string()))?;
    root.present().map_err(|e| err(e.to_string()))?;
    Ok(())
}

fn draw_histogram(
    path: &Path,
    title: &str,
    name: &str,
    unit: Option<&str>,
    xs: &[f64],
) -> Result<(), SweepError> {
    use plotters::prelude::*;
    let err = plot_err(path);
    let (lo, hi) = xs
        .iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), &x| {
            (a.min(x), b.max(x))
        });
    if !lo.is_finite() {
        return Ok(());
    }
    let e = eng_exponent(lo.abs().max(hi.abs()));
    let s = 10f64.powi(-e);
    let (lo, hi) = (lo * s, if hi > lo { hi * s } else { lo * s + 1.0 });
    let bins = ((xs.len() as f64).sqrt().ceil() as usize).clamp(1, 50);
    let width = (hi - lo) / bins as f64;
    let mut counts = vec![0usize; bins];
    for &x in xs {
        let k = (((x * s - lo) / width) as usize).min(bins - 1);
        counts[k] += 1;
    }
    let top = counts.iter().copied().max().unwrap_or(1) as f64 * 1.1;
    let root = SVGBackend::new(path, (800, 450)).into_drawing_area();
    root.fill(&WHITE).map_err(|e| err(e.to_string()))?;
    let mut chart = ChartBuilder::on(&root)
        .caption(format!("{title}: {} runs", xs.len()), ("sans-serif", 18))
        .margin(12)
        .x_label_area_size(40)
        .y_label_area_size(60)
        .build_cartesian_2d(lo..hi, 0.0..top)
        .map_err(|e| err(e.to_string()))?;
    chart
        .configure_mesh()
        .x_desc(crate::plot::axis_label(name, unit, e))
        .y_desc("runs")
        .draw()
        .map_err(|e| err(e.to_string()))?;
    chart
        .draw_series(counts.iter().enumerate().map(|(k, &c)| {
            let a = lo + k as f64 * width;
            Rectangle::new([(a, 0.0), (a + width, c as f64)], BLUE.mix(0.6).filled())
        }))
        .map_err(|e| err(e.to_string()))?;
    root.present().map_err(|e| err(e.to_string()))?;
    Ok(())
}

/// What [`run_study`] did.
#[derive(Debug, Clone, PartialEq)]
pub struct Summary {
    /// Runs in the plan.
    pub planned: usize,
    /// Rows found finished in the output folder (not recomputed).
    pub resumed: usize,
    /// Runs computed now.
    pub computed: usize,
    /// Rows with an error.
    pub failed: usize,
    /// Files written.
    pub files: Vec<PathBuf>,
    /// Wall time of the computed runs (s).
    pub wall_s: f64,
}

/// Options of [`run_study`].
#[derive(Debug, Clone, Default)]
pub struct RunOptions {
    /// Worker threads (0: all cores).
    pub jobs: usize,
    /// Discard finished rows of this folder (also those of another study).
    pub restart: bool,
    /// Stop after computing this many runs (the rest stay for a later resume).
    pub limit: Option<usize>,
    /// Show a progress bar on stderr.
    pub progress: bool,
}

/// Plan the study, resume from `out`'s finished rows, run the rest in parallel
/// (each finished row appended to `rows.jsonl` at once), then write the table
/// and plots.
pub fn run_study(study: &Study, out: &Path, opts: &RunOptions) -> Result<Summary, SweepError> {
    let plan = study.plan();
    // A folder of the user's is not written into; a second sweep into the same
    // folder is refused while this one runs.
    crate::output::refuse_foreign(out, &[ROWS_FILE], "empty it")?;
    let lock = crate::output::FolderLock::acquire(out)?;
    let result = run_locked(study, &plan, out, opts);
    if result.is_err() && lock.created_folder() {
        // Nothing finished: leave no folder behind (the lock removes it).
        let rows = out.join(ROWS_FILE);
        if std::fs::metadata(&rows).is_ok_and(|m| m.len() == 0) {
            let _ = std::fs::remove_file(rows);
        }
    }
    result
}

fn run_locked(
    study: &Study,
    plan: &Plan,
    out: &Path,
    opts: &RunOptions,
) -> Result<Summary, SweepError> {
    let (store, done) = RowStore::open(out, plan, opts.restart)?;
    let mut finished = vec![false; plan.len()];
    for r in &done {
        finished[r.index] = true;
    }
    let todo: Vec<usize> = (0..plan.len())
        .filter(|i| !finished[*i])
        .take(opts.limit.unwrap_or(usize::MAX))
        .collect();
    drop(finished);
    let bar = if opts.progress {
        let b = indicatif::ProgressBar::new(todo.len() as u64);
        b.set_style(
            indicatif::ProgressStyle::with_template(
                "{spinner} {pos}/{len} runs [{bar:40}] {per_sec} (eta {eta}) {msg}",
            )
            .expect("static template")
            .progress_chars("=> "),
        );
        b
    } else {
        indicatif::ProgressBar::hidden()
    };
    let write_error: std::sync::Mutex<Option<SweepError>> = std::sync::Mutex::new(None);
    let start = std::time::Instant::now();
    let new_rows = study.run_chunk(plan, &todo, opts.jobs, |row| {
        if let Err(e) = store.append(row) {
            let mut slot = write_error
                .lock()
                .unwrap_or_else(std::sync::PoisonError::into_inner);
            slot.get_or_insert(e);
        }
        if row.error.is_some() {
            bar.set_message("(some runs failed: see the error column)");
        }
        bar.inc(1);
    });
    let wall_s = start.elapsed().as_secs_f64();
    bar.finish_and_clear();
    if let Some(e) = write_error
        .into_inner()
        .unwrap_or_else(std::sync::PoisonError::into_inner)
    {
        return Err(e);
    }
    if let Some(signal) = crate::output::signals::interrupted() {
        // The finished rows are in rows.jsonl: the next run resumes there.
        return Err(crate::output::OutputError::Interrupted { signal }.into());
    }
    let resumed = done.len();
    let computed = new_rows.len();
    let mut rows = done;
    rows.extend(new_rows);
    rows.sort_by_key(|r| r.index);
    let failed = rows.iter().filter(|r| r.error.is_some()).count();
    let files = write_results(out, study, plan, &rows)?;
    Ok(Summary {
        planned: plan.len(),
        resumed,
        computed,
        failed,
        files,
        wall_s,
    })
}

/// Read a `results.parquet` back as rows of optional text cells (numbers in
/// the CSV's notation), with the header: for checking the table round trip and
/// for callers without a Parquet reader.
pub fn read_parquet_table(path: &Path) -> Result<(Vec<String>, Vec<Vec<String>>), SweepError> {
    use parquet::file::reader::{FileReader, SerializedFileReader};
    use parquet::record::Field;
    let perr = |e: parquet::errors::ParquetError| SweepError::Parquet {
        path: path.display().to_string(),
        message: e.to_string(),
    };
    let file = std::fs::File::open(path).map_err(io_err(path))?;
    let reader = SerializedFileReader::new(file).map_err(perr)?;
    let header: Vec<String> = reader
        .metadata()
        .file_metadata()
        .schema_descr()
        .columns()
        .iter()
        .map(|c| c.name().to_string())
        .collect();
    let mut out = Vec::new();
    for row in reader.get_row_iter(None).map_err(perr)? {
        let row = row.map_err(perr)?;
        out.push(
            row.get_column_iter()
                .map(|(name, f)| match f {
                    Field::Null => String::new(),
                    Field::Long(x) if name == "seed" => (*x as u64).to_string(),
                    Field::Long(x) => x.to_string(),
                    Field::Double(x) => format!("{x:e}"),
                    Field::Str(s) => s.clone(),
                    other => other.to_string(),
                })
                .collect(),
        );
    }
    Ok((header, out))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Textbook quantiles of the standard normal.
    #[test]
    fn normal_quantile_matches_tables() {
        for (p, z) in [
            (0.5, 0.0),
            (0.975, 1.959_963_984_540_054),
            (0.95, 1.644_853_626_951_472_2),
            (0.841_344_746_068_542_9, 1.0),
            (0.001, -3.090_232_306_167_813_5),
            (1e-10, -6.361_340_902_404_056),
        ] {
            let got = normal_quantile(p);
            assert!(
                (got - z).abs() < 1e-12 * z.abs().max(1.0),
                "p {p}: {got} vs {z}"
            );
        }
    }

    /// erfc against closed values: erfc(0) = 1, erfc(1), erfc(3), and the symmetry.
    #[test]
    fn erfc_matches_known_values() {
        assert_eq!(erfc(0.0), 1.0);
        for (x, v) in [
            (0.3, 0.671_373_240_540_872_6),
            (1.0, 0.157_299_207_050_285_13),
            (3.0, 2.209_049_699_858_544e-5),
            (5.0, 1.537_459_794_428_035e-12),
        ] {
            assert!((erfc(x) - v).abs() < 1e-13 * v, "{x}: {}", erfc(x));
            assert!((erfc(-x) - (2.0 - v)).abs() < 1e-15);
        }
    }

    #[test]
    fn permuted_is_a_permutation_of_every_size() {
        for (n, key) in [(1u64, 1u64), (2, 2), (3, 3), (17, 4), (1000, 5), (4097, 6)] {
            let mut p: Vec<u64> = (0..n).map(|i| permuted(i, n, key)).collect();
            p.sort_unstable();
            assert_eq!(p, (0..n).collect::<Vec<_>>(), "n {n}");
        }
        // Another key, another order.
        let a: Vec<u64> = (0..100).map(|i| permuted(i, 100, 1)).collect();
        let b: Vec<u64> = (0..100).map(|i| permuted(i, 100, 2)).collect();
        assert_ne!(a, b);
    }
}
