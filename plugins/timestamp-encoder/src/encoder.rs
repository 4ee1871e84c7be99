//! `timestamp_encoder`: an optical incremental encoder with time-stamped events and
//! the hardware register of the last n events with skip σ (Sec. 8.2, 8.4).
//!
//! **Geometry.** `lines` slits per revolution (N; the thesis's HEDS encoder has 100),
//! read in quadrature: 4 edges (events) per slit period, so 4N counts per
//! revolution and a resolution Δ = `revolution`/(4N) (input units per count). The
//! count is c = ⌊·⌋ of the position in counts against the *actual* edge positions:
//! edge L (an integer level) sits at L + e_L counts, with e_L the sum of the
//! imperfections below. The count is c when p_c ≤ u < p_{c+1} (u = x/Δ).
//!
//! **Imperfections** (all in counts, per edge e_L, L taken modulo 4N):
//! - `slit_error_std_counts`: a random offset per slit, N(0, s²), seeded from the
//!   build seed, shared by the 4 edges of the slit (non-uniform slit spacing);
//! - `slit_errors_counts`: an explicit table, N values (per slit, applied to its 4
//!   edges) or 4N values (per edge), e.g. a measured profile;
//! - `eccentricity_counts`, `eccentricity_phase_rad`: a once-per-revolution
//!   sinusoid a·sin(2πL/(4N) + φ) (disc eccentricity);
//! - `quadrature_error_counts`: channel B's edges (L odd) shifted (photodiode
//!   misplacement between A and B);
//! - `duty_error_counts`: falling edges (L mod 4 ∈ {2, 3}) shifted (slit width).
//!
//! Every edge must stay strictly after its predecessor, or `build` fails.
//!
//! **Events.** Between two ticks the trajectory is the Hermite interpolant of the
//! samples at both ticks ([`crate::poly`]): linear for input `[x]`, cubic for
//! `[x, ẋ]`, quintic for `[x, ẋ, ẍ]` (`derivatives` = 0, 1, 2). Each crossed edge
//! level gives an event (t_k, x_k): the crossing time from root finding, stamped on
//! the clock as ⌊t f_clk⌋/f_clk (the counter value when the edge is latched; error
//! in (−1/f_clk, 0], never in the future of the read instant), and x_k = L, the
//! edge's nominal level in counts (the same for an up- and a down-crossing; the
//! count after it is L resp. L − 1). If more events occur in one tick than the
//! history holds (a jump), only the newest are timed; numbering stays exact.
//!
//! **Register** (output `register`, width 2 + 2n):
//! `[c, n_valid, t_1, x_1, t_2, x_2, …, t_n, x_n]` — the count c at the tick, the
//! number of valid entries, then events **newest first**: i = 1 is the newest event,
//! the rest follow (8.7) with skip σ. Times in s (absolute, clock-quantised), x in
//! counts. Invalid entries (fewer events than n so far) are 0. Output `x_q`: the
//! count as a position c·Δ (input units), what a plain counter reads.

use crate::poly::{MAX_DEG, Poly, roots_in, solve_monotone};
use crate::skip::{history_len, register_indices};
use nanomotion_core::Params;
use nanomotion_core::rng::Rng;
use nanomotion_core::{Block, BuildContext, ParamError, Port, Sensor, Tick, declared_block};
use serde::{Deserialize, Serialize};

/// Default clock of the event time-stamps: 20 MHz (50 ns), Sec. 8.5.
pub const DEFAULT_CLOCK_HZ: f64 = 20e6;
/// Register length of the thesis's hardware: five events.
pub const DEFAULT_REGISTER_LEN: usize = 5;
/// Largest register length n.
pub const MAX_REGISTER_LEN: usize = crate::fit::MAX_N;

/// Most slits per revolution (`lines`): 2^20 = 1 048 576 (4·2^20 edges of
/// slit-error table, 32 MiB).
pub const MAX_LINES: usize = 1 << 20;

/// `timestamp_encoder`: optical incremental encoder (Ch. 8): quadrature edges with slit
/// errors, events time-stamped on a 20 MHz clock by crossing detection, register of the
/// last n events with skip σ (8.5)-(8.7).
///
/// The time-stamping encoder. Build it (plain Rust: set fields, call
/// [`TimestampEncoder::prepare`]; graph: `type: timestamp_encoder`), then feed it
/// the true trajectory tick by tick.
///
/// ```
/// use timestamp_encoder::TimestampEncoder;
/// use nanomotion_core::Sensor;
/// let mut enc = TimestampEncoder { skip: 1, ..Default::default() };
/// enc.prepare(7).unwrap();
/// let w = 2.0; // rad/s, constant
/// let mut reg = vec![0.0; enc.register_width()];
/// for k in 0..=100 {
///     let t = k as f64 * 1e-3;
///     enc.measure(t, &[w * t, w], &mut reg);
/// }
/// // 0.2 rad at 400/(2π) counts per rad: count 12, five valid events.
/// assert_eq!(reg[0], 12.0);
/// assert_eq!(reg[1], 5.0);
/// // The newest event is edge 12, crossed at t = 12Δ/w (to the 50 ns clock).
/// let t12 = 12.0 * std::f64::consts::TAU / 400.0 / w;
/// assert!((reg[2] - t12).abs() <= 50e-9 && reg[3] == 12.0);
/// ```
#[derive(Debug, Clone, Serialize, Deserialize, Params)]
#[serde(default, deny_unknown_fields)]
#[block(type_name = "timestamp_encoder", role = Sensor, ports = "x[1+derivatives] -> register[2+2n] = [count, n_valid, t_1, x_1, …] newest first (s, counts), x_q (count·Δ)")]
pub struct TimestampEncoder {
    /// Slits per revolution N (-); 4N counts per revolution. Default 100.
    /// 1 ≤ N ≤ 2^20.
    #[param(size(1, MAX_LINES))]
    pub lines: usize,
    /// Input units per revolution (2π for rad, the default; a linear scale's length
    /// in m for a linear encoder).
    #[param(positive)]
    pub revolution: f64,
    /// Time-stamp clock f_clk (Hz), default 20 MHz (Sec. 8.5).
    #[param(positive)]
    pub clock_hz: f64,
    /// Register length n (events), default 5 (the thesis's hardware), at most 16.
    #[param(size(1, MAX_REGISTER_LEN))]
    pub register_len: usize,
    /// Skip σ (events skipped between stored ones), (8.5)–(8.7), default 0.
    /// The newest event is always kept.
    #[param(range(0, 1_000_000))]
    pub skip: i64,
    /// Derivatives provided on the input: 0 → `[x]`, 1 → `[x, ẋ]` (default),
    /// 2 → `[x, ẋ, ẍ]`; sets the interpolant between ticks (linear, cubic, quintic).
    #[param(size(0, 2))]
    pub derivatives: usize,
    /// Random per-slit spacing error, standard deviation (counts), seeded. Default 0.
    #[param(non_negative)]
    pub slit_error_std_counts: f64,
    /// Explicit edge errors (counts): N values (per slit) or 4N (per edge). Default none.
    #[param(finite)]
    pub slit_errors_counts: Vec<f64>,
    /// Eccentricity: amplitude of the once-per-revolution error (counts). Default 0.
    #[param(finite)]
    pub eccentricity_counts: f64,
    /// Eccentricity phase φ (rad). Default 0.
    #[param(finite)]
    pub eccentricity_phase_rad: f64,
    /// Shift of channel B's edges (counts): A/B photodiode misplacement. Default 0.
    #[param(finite)]
    pub quadrature_error_counts: f64,
    /// Shift of the falling edges (counts): slit width (duty-cycle) error. Default 0.
    #[param(finite)]
    pub duty_error_counts: f64,
    /// Run-time state (events, count); not a parameter. Public only so that
    /// `TimestampEncoder { skip: 2, ..Default::default() }` works.
    #[serde(skip)]
    pub state: EncoderState,
}

impl Default for TimestampEncoder {
    /// The defaults of every field (a graph file may leave any out).
    fn default() -> Self {
        Self {
            lines: 100,
            revolution: std::f64::consts::TAU,
            clock_hz: DEFAULT_CLOCK_HZ,
            register_len: DEFAULT_REGISTER_LEN,
            skip: 0,
            derivatives: 1,
            slit_error_std_counts: 0.0,
            slit_errors_counts: Vec::new(),
            eccentricity_counts: 0.0,
            eccentricity_phase_rad: 0.0,
            quadrature_error_counts: 0.0,
            duty_error_counts: 0.0,
            state: EncoderState::default(),
        }
    }
}

/// Run-time state of a [`TimestampEncoder`] (opaque).
#[derive(Debug, Clone, Default)]
pub struct EncoderState {
    ready: bool,
    /// e_L for L in 0..4N (counts).
    edges: Vec<f64>,
    counts_per_unit: f64,
    /// Ring of the last `cap` events: event k at k % cap.
    ring_t: Vec<f64>,
    ring_x: Vec<f64>,
    idx: Vec<u64>,
    /// Number of the newest event (0: none yet).
    k: u64,
    count: i64,
    started: bool,
    t_prev: f64,
    prev: [f64; 3],
}

impl TimestampEncoder {
    /// Validate the parameters, draw the seeded slit errors and allocate the event
    /// history. Called by [`Block::build`] with the block's seed.
    pub fn prepare(&mut self, seed: u64) -> Result<(), ParamError> {
        self.check_params()?;
        let n_lines = self.lines;
        let n4 = 4 * n_lines;
        let table = &self.slit_errors_counts;
        if !(table.is_empty() || table.len() == n_lines || table.len() == n4) {
            return Err(ParamError::new(
                "slit_errors_counts",
                format!("has {} values", table.len()),
                format!("give {n_lines} (one per slit) or {n4} (one per edge) values, or none"),
            ));
        }
        let mut rng = Rng::new(seed);
        let per_slit: Vec<f64> = (0..n_lines)
            .map(|_| self.slit_error_std_counts * rng.normal())
            .collect();
        let edges: Vec<f64> = (0..n4)
            .map(|l| {
                let mut e = per_slit[l / 4];
                if table.len() == n_lines {
                    e += table[l / 4];
                } else if table.len() == n4 {
                    e += table[l];
                }
                e += self.eccentricity_counts
                    * (std::f64::consts::TAU * l as f64 / n4 as f64 + self.eccentricity_phase_rad)
                        .sin();
                if l % 2 == 1 {
                    e += self.quadrature_error_counts;
                }
                if l % 4 >= 2 {
                    e += self.duty_error_counts;
                }
                e
            })
            .collect();
        for l in 0..n4 {
            let next = if l + 1 < n4 { edges[l + 1] } else { edges[0] };
            if 1.0 + next - edges[l] <= 0.0 {
                return Err(ParamError::new(
                    "slit_errors_counts",
                    format!(
                        "edge {} falls at or before edge {l}: the imperfections exceed a count",
                        (l + 1) % n4
                    ),
                    "keep the edge errors well below half a count",
                ));
            }
        }
        let cap = history_len(self.register_len, self.skip as usize);
        self.state = EncoderState {
            ready: true,
            edges,
            counts_per_unit: n4 as f64 / self.revolution,
            ring_t: vec![0.0; cap],
            ring_x: vec![0.0; cap],
            idx: vec![0; self.register_len],
            ..EncoderState::default()
        };
        Ok(())
    }

    /// Width of the `register` output: 2 + 2n.
    pub fn register_width(&self) -> usize {
        2 + 2 * self.register_len
    }
    /// Width of the input: 1 + `derivatives`.
    pub fn input_width(&self) -> usize {
        1 + self.derivatives
    }
    /// Resolution Δ: input units per count.
    pub fn resolution(&self) -> f64 {
        self.revolution / (4 * self.lines) as f64
    }
    /// The built edge errors e_L (counts), L = 0..4N (empty before `prepare`).
    pub fn edge_errors_counts(&self) -> &[f64] {
        &self.state.edges
    }
    /// The current count c.
    pub fn count(&self) -> i64 {
        self.state.count
    }
    /// Number of events so far (the newest event's number k).
    pub fn events_so_far(&self) -> u64 {
        self.state.k
    }
    /// Event number `k` (time s, level counts), if it is still in the history
    /// and the register can read it: with skip σ only the grid events
    /// k ≡ 1 (mod σ + 1) and the newest are timed (all of them for σ = 0).
    pub fn event(&self, k: u64) -> Option<(f64, f64)> {
        let cap = self.state.ring_t.len() as u64;
        let s1 = self.skip as u64 + 1;
        if k == 0 || k > self.state.k || k + cap <= self.state.k {
            return None;
        }
        if !(k - 1).is_multiple_of(s1) && k != self.state.k {
            return None;
        }
        let j = (k % cap) as usize;
        Some((self.state.ring_t[j], self.state.ring_x[j]))
    }

    fn edge_pos(&self, l: i64) -> f64 {
        let n4 = self.state.edges.len() as i64;
        l as f64 + self.state.edges[l.rem_euclid(n4) as usize]
    }

    /// The count c with p_c ≤ u < p_{c+1}.
    fn cell(&self, u: f64) -> i64 {
        let mut c = u.floor() as i64;
        while self.edge_pos(c) > u {
            c -= 1;
        }
        while self.edge_pos(c + 1) <= u {
            c += 1;
        }
        c
    }

    /// Number the next `count` events k + 1 … k + count and time those the
    /// register can ever read: the grid events k ≡ 1 (mod σ + 1) and the last one
    /// (the newest, if no event follows). `time_of(i)` gives the true time and
    /// level of the i-th (0-based). Work: at most n + 1 crossings timed however
    /// many edges are crossed (audit D9: all n(σ + 1) = 16 M were timed per tick).
    fn push_run(&mut self, count: i64, mut time_of: impl FnMut(&Self, i64) -> (f64, i64)) {
        if count <= 0 {
            return;
        }
        let s1 = self.skip as u64 + 1;
        let k0 = self.state.k;
        let last = k0 + count as u64;
        let mut k = k0 + 1 + (s1 - k0 % s1) % s1;
        while k <= last {
            let (t, level) = time_of(self, (k - k0 - 1) as i64);
            self.store(k, t, level);
            k += s1;
        }
        if !(last - 1).is_multiple_of(s1) {
            let (t, level) = time_of(self, count - 1);
            self.store(last, t, level);
        }
        self.state.k = last;
    }

    fn store(&mut self, k: u64, t_true: f64, level: i64) {
        let st = &mut self.state;
        let cap = st.ring_t.len() as u64;
        let j = (k % cap) as usize;
        st.ring_t[j] = (t_true * self.clock_hz).floor() / self.clock_hz;
        st.ring_x[j] = level as f64;
    }

    /// Advance to time `t` with the true trajectory sample `x` = [x, ẋ, ẍ][..1 +
    /// derivatives] (input units, per s): detect and stamp all edge crossings since
    /// the previous call. Non-finite samples and non-increasing times are ignored.
    pub fn advance(&mut self, t: f64, x: &[f64]) {
        assert!(
            self.state.ready,
            "TimestampEncoder: call prepare() (or build) first"
        );
        let w = self.input_width().min(x.len());
        if !t.is_finite() || w == 0 || x[..w].iter().any(|v| !v.is_finite()) {
            return;
        }
        let cpu = self.state.counts_per_unit;
        let mut cur = [0.0; 3];
        for (c, &v) in cur.iter_mut().zip(&x[..w]) {
            *c = v * cpu;
        }
        if !self.state.started {
            self.state.started = true;
            self.state.count = self.cell(cur[0]);
            self.state.t_prev = t;
            self.state.prev = cur;
            return;
        }
        let h = t - self.state.t_prev;
        if h <= 0.0 {
            return;
        }
        let p = Poly::hermite(&self.state.prev[..w], &cur[..w], h);
        let mut crit = [0.0; MAX_DEG];
        let nc = roots_in(&p.deriv(), 0.0, 1.0, &mut crit);
        let t0 = self.state.t_prev;
        let mut sa = 0.0;
        let mut ua = self.state.prev[0];
        let cap = self.state.ring_t.len() as i64;
        let ends = crit[..nc]
            .iter()
            .map(|&c| (c, p.eval(c)))
            .chain(std::iter::once((1.0, cur[0])));
        for (sb, ub) in ends {
            let c = self.state.count;
            if ub > ua {
                let c_new = self.cell(ub).max(c);
                let first = (c + 1).max(c_new - cap + 1);
                self.state.k += (first - c - 1) as u64;
                self.push_run(c_new - first + 1, |enc, i| {
                    let l = first + i;
                    let s = solve_monotone(&p, enc.edge_pos(l), sa, sb, true);
                    (t0 + s * h, l)
                });
                self.state.count = c_new;
            } else if ub < ua {
                let c_new = self.cell(ub).min(c);
                // Edges c, c−1, …, c_new + 1 are crossed downwards, in that order;
                // only the newest `cap` of them are timed.
                let total = c - c_new;
                let n_skipped = total - total.min(cap);
                self.state.k += n_skipped as u64;
                let top = c - n_skipped;
                self.push_run(total - n_skipped, |enc, i| {
                    let l = top - i;
                    let s = solve_monotone(&p, enc.edge_pos(l), sa, sb, false);
                    (t0 + s * h, l)
                });
                self.state.count = c_new;
            }
            sa = sb;
            ua = ub;
        }
        self.state.t_prev = t;
        self.state.prev = cur;
    }

    /// Write the register `[c, n_valid, t_1, x_1, …, t_n, x_n]` (newest first)
    /// into `reg` (length ≥ 2 + 2n).
    pub fn read_register(&mut self, reg: &mut [f64]) {
        let sigma = self.skip as u64;
        let n_valid = register_indices(self.state.k, sigma, &mut self.state.idx);
        reg[0] = self.state.count as f64;
        reg[1] = n_valid as f64;
        let cap = self.state.ring_t.len() as u64;
        for (i, &k) in self.state.idx.iter().enumerate() {
            let (t, x) = if i < n_valid {
                let j = (k % cap) as usize;
                (self.state.ring_t[j], self.state.ring_x[j])
            } else {
                (0.0, 0.0)
            };
            reg[2 + 2 * i] = t;
            reg[3 + 2 * i] = x;
        }
    }
}

impl Sensor for TimestampEncoder {
    /// `x` = [x, ẋ, ẍ][..1 + derivatives] at time `t`; `y` = the register.
    fn measure(&mut self, t: f64, x: &[f64], y: &mut [f64]) {
        self.advance(t, x);
        self.read_register(y);
    }
}

#[declared_block]
impl Block for TimestampEncoder {
    fn inputs(&self) -> Vec<Port> {
        vec![Port::new("x", self.input_width())]
    }
    fn outputs(&self) -> Vec<Port> {
        vec![
            Port::new("register", self.register_width()),
            Port::new("x_q", 1),
        ]
    }
    fn memory_bytes(&self) -> usize {
        self.planned_bytes(0.0).1
    }
    fn planned_bytes(&self, _dt: f64) -> (&'static str, usize) {
        // The per-slit (lines) and per-edge (4·lines) error tables `prepare`
        // fills.
        (
            "lines",
            self.lines.saturating_mul(5 * std::mem::size_of::<f64>()),
        )
    }
    fn build(&mut self, ctx: &BuildContext) -> Result<(), ParamError> {
        self.prepare(ctx.seed)
    }
    fn output(&mut self, tick: Tick, u: &[f64], y: &mut [f64]) {
        let w = self.register_width();
        self.advance(tick.t, u);
        self.read_register(&mut y[..w]);
        y[w] = self.state.count as f64 / self.state.counts_per_unit;
    }
}
