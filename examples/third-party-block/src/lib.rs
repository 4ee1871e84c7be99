//! A block defined **outside** nanomotion, usable from YAML by linking alone.
//!
//! This crate depends only on `nanomotion-core`, `serde` and `typetag`. It defines
//! [`MovingAverage`] and registers it under `type: moving_average`; its
//! `#[derive(Params)]` puts it in `nanomotion blocks` and `nanomotion schema`. A program that
//! links this crate (e.g. `use third_party_block as _;`) can load graphs that use it;
//! nothing in nanomotion had to change.
//!
//! ```
//! use third_party_block::MovingAverage;
//! let mut ma = MovingAverage::new(4);
//! let ys: Vec<f64> = [4.0, 4.0, 4.0, 4.0, 8.0].iter().map(|&x| ma.push(x)).collect();
//! assert_eq!(ys, vec![1.0, 2.0, 3.0, 4.0, 5.0]);
//! ```

use nanomotion_core::block::check;
use nanomotion_core::{Block, BuildContext, ParamError, Params, Tick, declared_block};
use serde::{Deserialize, Serialize};

/// Moving average over the last `window` samples (example of a third-party
/// block; zeros before the start): `y[k] = (1/n) Σ_{i=0}^{n-1} u[k-i]`.
#[derive(Debug, Clone, Serialize, Deserialize, Params)]
#[serde(deny_unknown_fields)]
#[block(type_name = "moving_average", role = Math, ports = "u -> y")]
pub struct MovingAverage {
    /// Number of samples averaged, n ≥ 1 (at most 2^24).
    pub window: usize,
    #[serde(skip)]
    ring: Vec<f64>,
    #[serde(skip)]
    head: usize,
    #[serde(skip)]
    sum: f64,
}

impl MovingAverage {
    /// A moving average over `window` samples.
    pub fn new(window: usize) -> Self {
        let mut m = Self {
            window,
            ring: Vec::new(),
            head: 0,
            sum: 0.0,
        };
        m.ring = vec![0.0; window.max(1)];
        m
    }

    /// Push one sample, get the average of the last `window`.
    pub fn push(&mut self, x: f64) -> f64 {
        let old = std::mem::replace(&mut self.ring[self.head], x);
        self.head = (self.head + 1) % self.ring.len();
        // Recompute the sum exactly once per cycle so rounding cannot drift.
        if self.head == 0 {
            self.sum = self.ring.iter().sum();
        } else {
            self.sum += x - old;
        }
        self.sum / self.ring.len() as f64
    }
}

#[declared_block]
impl Block for MovingAverage {
    fn build(&mut self, _ctx: &BuildContext) -> Result<(), ParamError> {
        // A size that allocates: bounded before the allocation, like every block's.
        check::buffer("window", self.window, 1, 1)?;
        self.ring = vec![0.0; self.window];
        self.head = 0;
        self.sum = 0.0;
        Ok(())
    }
    fn output(&mut self, _t: Tick, u: &[f64], y: &mut [f64]) {
        y[0] = self.push(u[0]);
    }
    fn memory_bytes(&self) -> usize {
        self.ring.len() * std::mem::size_of::<f64>()
    }
    /// Declared before `build` so the graph compiler can refuse a graph of
    /// many long windows before any is allocated.
    fn planned_bytes(&self, _dt: f64) -> (&'static str, usize) {
        (
            "window",
            self.window.saturating_mul(std::mem::size_of::<f64>()),
        )
    }
}
