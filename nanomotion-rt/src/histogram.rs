//! Fixed-memory histograms of durations, recorded in the real-time thread.
//!
//! Log-linear buckets (as in HdrHistogram): values below 64 ns have one bucket
//! each; above, every power of two is split into 32 equal buckets, so a bucket is
//! at most 1/32 (3.1 %) of its lower edge wide. 1 920 buckets cover every `u64`
//! (15 KiB per histogram, allocated once). Recording is a leading-zero count, a
//! shift and an increment: no allocation, no branch on the data's range.
//!
//! A quantile is reported as the upper edge of the bucket holding it (capped by
//! the exact maximum), so it is never below the true value and at most 3.1 %
//! above it; minimum, maximum and mean are exact.

use serde::Serialize;

/// Sub-bucket bits: 2⁵ = 32 buckets per power of two.
const SUB_BITS: u32 = 5;
const SUB: u64 = 1 << SUB_BITS;
/// Values below this have a bucket each.
const LINEAR: u64 = 2 * SUB;
/// Buckets in all.
pub const BUCKETS: usize = (LINEAR + (63 - SUB_BITS as u64) * SUB) as usize;

/// Bucket of `v`.
#[inline]
fn index(v: u64) -> usize {
    if v < LINEAR {
        return v as usize;
    }
    let e = 63 - v.leading_zeros(); // ≥ 6
    let shift = e - SUB_BITS;
    let sub = v >> shift; // in [32, 64)
    (LINEAR + u64::from(e - SUB_BITS - 1) * SUB + (sub - SUB)) as usize
}

/// Lowest and highest value of bucket `i`.
fn bounds(i: usize) -> (u64, u64) {
    let i = i as u64;
    if i < LINEAR {
        return (i, i);
    }
    let j = i - LINEAR;
    let shift = j / SUB + 1;
    let sub = SUB + j % SUB;
    let lo = sub << shift;
    (lo, lo + ((1u64 << shift) - 1))
}

/// A histogram of durations in nanoseconds.
#[derive(Clone)]
pub struct Histogram {
    counts: Box<[u64]>,
    n: u64,
    sum: u128,
    min: u64,
    max: u64,
}

impl std::fmt::Debug for Histogram {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Histogram")
            .field("summary", &self.summary())
            .finish_non_exhaustive()
    }
}

impl Default for Histogram {
    fn default() -> Self {
        Self::new()
    }
}

/// Quantiles of a histogram (ns); `None` without samples.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Summary {
    /// Samples recorded.
    pub count: u64,
    /// Smallest value (exact).
    pub min_ns: Option<u64>,
    /// Mean (exact).
    pub mean_ns: Option<f64>,
    /// Median (upper bucket edge, ≤ 3.1 % high).
    pub p50_ns: Option<u64>,
    /// 99th percentile.
    pub p99_ns: Option<u64>,
    /// 99.9th percentile.
    pub p999_ns: Option<u64>,
    /// Largest value (exact).
    pub max_ns: Option<u64>,
}

impl Histogram {
    /// An empty histogram (the only allocation).
    pub fn new() -> Self {
        Self {
            counts: vec![0; BUCKETS].into_boxed_slice(),
            n: 0,
            sum: 0,
            min: u64::MAX,
            max: 0,
        }
    }

    /// Count one value. Allocation-free.
    #[inline]
    pub fn record(&mut self, ns: u64) {
        self.counts[index(ns)] += 1;
        self.n += 1;
        self.sum += u128::from(ns);
        self.min = self.min.min(ns);
        self.max = self.max.max(ns);
    }

    /// Forget every sample (keeps the memory).
    pub fn clear(&mut self) {
        self.counts.fill(0);
        self.n = 0;
        self.sum = 0;
        self.min = u64::MAX;
        self.max = 0;
    }

    /// Samples recorded.
    pub fn count(&self) -> u64 {
        self.n
    }

    /// Largest value, if any.
    pub fn max(&self) -> Option<u64> {
        (self.n > 0).then_some(self.max)
    }

    /// The `q`-quantile (0 < q ≤ 1): the smallest recorded bucket whose
    /// cumulative count reaches ⌈q·n⌉, reported as its upper edge (capped by the
    /// maximum). `None` without samples.
    pub fn quantile(&self, q: f64) -> Option<u64> {
        if self.n == 0 {
            return None;
        }
        let rank = ((q * self.n as f64).ceil() as u64).clamp(1, self.n);
        let mut seen = 0;
        for (i, &c) in self.counts.iter().enumerate() {
            seen += c;
            if seen >= rank {
                return Some(bounds(i).1.min(self.max));
            }
        }
        Some(self.max)
    }

    /// Count, extremes, mean and the p50/p99/p99.9 quantiles.
    pub fn summary(&self) -> Summary {
        let some = self.n > 0;
        Summary {
            count: self.n,
            min_ns: some.then_some(self.min),
            mean_ns: some.then(|| self.sum as f64 / self.n as f64),
            p50_ns: self.quantile(0.5),
            p99_ns: self.quantile(0.99),
            p999_ns: self.quantile(0.999),
            max_ns: self.max(),
        }
    }

    /// Non-empty buckets as `(lowest ns, highest ns, count)`, ascending.
    pub fn buckets(&self) -> Vec<(u64, u64, u64)> {
        self.counts
            .iter()
            .enumerate()
            .filter(|(_, c)| **c > 0)
            .map(|(i, &c)| {
                let (lo, hi) = bounds(i);
                (lo, hi, c)
            })
            .collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn buckets_tile_every_u64_without_gap_or_overlap() {
        assert_eq!(bounds(0), (0, 0));
        for i in 1..BUCKETS {
            assert_eq!(bounds(i).0, bounds(i - 1).1 + 1, "gap before bucket {i}");
        }
        assert_eq!(bounds(BUCKETS - 1).1, u64::MAX);
        for v in [0, 1, 63, 64, 65, 127, 128, 1000, 25_000, 1 << 40, u64::MAX] {
            let (lo, hi) = bounds(index(v));
            assert!(lo <= v && v <= hi, "{v} not in bucket {lo}..={hi}");
            // Relative width at most 1/32.
            assert!((hi - lo) as f64 <= lo as f64 / 32.0 + 1.0);
        }
    }

    #[test]
    fn quantiles_of_1_to_n_bracket_the_exact_order_statistics() {
        // Values 1..=100 000 ns: the q-quantile is ⌈q n⌉ exactly.
        let mut h = Histogram::new();
        let n = 100_000u64;
        for v in 1..=n {
            h.record(v);
        }
        for q in [0.5, 0.99, 0.999] {
            let exact = (q * n as f64).ceil() as u64;
            let got = h.quantile(q).unwrap();
            assert!(got >= exact, "q={q}: {got} < {exact}");
            assert!(
                got as f64 <= exact as f64 * (1.0 + 1.0 / 32.0),
                "q={q}: {got}"
            );
        }
        let s = h.summary();
        assert_eq!(s.min_ns, Some(1));
        assert_eq!(s.max_ns, Some(n));
        assert_eq!(s.mean_ns, Some((n + 1) as f64 / 2.0));
        assert_eq!(s.count, n);
    }

    #[test]
    fn an_empty_histogram_has_no_quantiles() {
        let s = Histogram::new().summary();
        assert_eq!(s.count, 0);
        assert_eq!(s.p50_ns, None);
        assert_eq!(s.max_ns, None);
    }

    #[test]
    fn recording_does_not_allocate() {
        let mut h = Histogram::new();
        let info = allocation_counter::measure(|| {
            for v in 0..10_000u64 {
                h.record(v * 7919);
            }
        });
        assert_eq!(info.count_total, 0);
    }
}
