//! The time-varying memory-loop delay of DVRC (Sec. 5.3): a preallocated ring
//! buffer read at a varying delay ([`VaryingDelay`], the block v_k = q_{k−N_k} of
//! (5.10b)/(5.11)) and the estimator of N_k = k − k*(α_k) from the repetitive
//! variable α ((5.7)–(5.8), [`AlphaDelay`]).
//!
//! # Behaviour of [`AlphaDelay`] (the definition the code implements)
//!
//! At sample k, with window W_k = {l : max(0, k − M) ≤ l ≤ k − m},
//!
//! k*(α_k) = argmin_{l ∈ W_k} (α_l − α_k + P_α)², ties to the most recent l,
//!
//! i.e. (5.7) restricted to the admissible delays, so that N_k = k − k* ∈ [m, M]
//! always (the range the stability criterion (5.9) is evaluated for). In addition:
//!
//! - **start-up**: until α has advanced by one period since the first sample
//!   (α_k ≥ α_0 + P_α) there is no past sample one period back; N_k = `n_init`.
//!   Once primed it stays primed.
//! - **α stalls** (α_k = α_{k−1}): the target α_k − P_α stands still, k* stays,
//!   so N_k grows by one per sample until it reaches M and is then held at M
//!   (k* = k − M, the oldest sample kept). Once the stall has lasted so long that
//!   the whole window holds the stalled value, all samples tie and the most recent
//!   wins: N_k = m until α moves again (the disturbance, periodic in α, is then
//!   constant, so any sample is as good).
//! - **α reverses** (velocity changes sign): (5.7) is applied literally, over the
//!   window: the past sample whose α is closest to α_k − P_α. While any decrease of
//!   α lies inside the last M samples the search is a full scan of the window
//!   (O(M − m)); otherwise (α non-decreasing over the window) it is an amortised
//!   O(1) forward search from the previous k*, which gives the identical result
//!   (tested against the scan). Going backwards, α_k − P_α lies *ahead* on the
//!   current stroke, so once the forward samples have left the window the
//!   closest admissible sample is the newest one and N_k = m: the learning is not
//!   meaningful during a reversal (the thesis leaves non-monotone α to future
//!   work), but N_k stays in \[m, M\], so (5.9) still guarantees stability.
//! - **non-finite α** (NaN, ±∞) is replaced by the last finite value (a stall).
//!
//! With α = t (α_k = k·T_s, P_α = N·T_s) and `n_init` = N, N_k = N for every k:
//! DVRC is then bit-for-bit standard RC.

/// A delay line y_k = x_{k−d_k} with d_k ∈ \[0, capacity − 1\] chosen per sample;
/// preallocated, never allocates. History before the first sample is zero (the
/// zero initial state used in Theorem 8).
#[derive(Debug, Clone)]
pub struct VaryingDelay {
    buf: Vec<f64>,
    /// Index where the next sample is written.
    head: usize,
}

impl VaryingDelay {
    /// A delay line for delays up to `max_delay` samples.
    pub fn new(max_delay: usize) -> Self {
        Self {
            buf: vec![0.0; max_delay + 1],
            head: 0,
        }
    }

    /// Largest delay that can be read.
    pub fn max_delay(&self) -> usize {
        self.buf.len() - 1
    }

    /// x_{k−d}, where k is the sample that the next [`push`](Self::push) writes;
    /// d ≥ 1 reads stored samples (d = 0 is not stored yet and reads the value that
    /// will be overwritten: use d ≥ 1).
    ///
    /// # Panics
    /// If `d > max_delay()`.
    #[inline]
    pub fn get(&self, d: usize) -> f64 {
        let n = self.buf.len();
        assert!(d < n, "delay {d} above the capacity {}", n - 1);
        let i = if self.head >= d {
            self.head - d
        } else {
            self.head + n - d
        };
        self.buf[i]
    }

    /// Store sample k (and advance to k + 1).
    #[inline]
    pub fn push(&mut self, x: f64) {
        self.buf[self.head] = x;
        self.head += 1;
        if self.head == self.buf.len() {
            self.head = 0;
        }
    }

    /// Zero the history.
    pub fn reset(&mut self) {
        self.buf.fill(0.0);
        self.head = 0;
    }
}

/// Estimates the DVRC delay N_k = k − k*(α_k) of (5.7)–(5.8) from the repetitive
/// variable α; see the [module docs](self) for the exact behaviour.
#[derive(Debug, Clone)]
pub struct AlphaDelay {
    period: f64,
    n_min: usize,
    n_max: usize,
    n_init: usize,
    /// α_{k−M..k} in a ring of M + 1.
    alpha: Vec<f64>,
    /// Sample index k of the next call.
    k: u64,
    /// k* of the previous sample (absolute index).
    prev_star: u64,
    /// Index of the latest sample with α_j < α_{j−1} (or none).
    last_decrease: Option<u64>,
    alpha0: f64,
    last_alpha: f64,
    primed: bool,
    last_n: usize,
}

impl AlphaDelay {
    /// P_α = `period` (units of α, e.g. 2π rad), N_k ∈ \[`n_min`, `n_max`\] samples,
    /// `n_init` used until α has advanced one period. Requires 1 ≤ n_min ≤ n_init ≤
    /// n_max and a finite period > 0 (checked by the blocks; here clamped).
    pub fn new(period: f64, n_min: usize, n_max: usize, n_init: usize) -> Self {
        let n_min = n_min.max(1);
        let n_max = n_max.max(n_min);
        Self {
            period,
            n_min,
            n_max,
            n_init: n_init.clamp(n_min, n_max),
            alpha: vec![0.0; n_max + 1],
            k: 0,
            prev_star: 0,
            last_decrease: None,
            alpha0: 0.0,
            last_alpha: 0.0,
            primed: false,
            last_n: n_init.clamp(n_min, n_max),
        }
    }

    /// Bounds \[m, M\].
    pub fn bounds(&self) -> (usize, usize) {
        (self.n_min, self.n_max)
    }

    /// Forget the history (back to start-up).
    pub fn reset(&mut self) {
        self.alpha.fill(0.0);
        self.k = 0;
        self.prev_star = 0;
        self.last_decrease = None;
        self.primed = false;
        self.last_n = self.n_init;
    }

    /// The delay of the previous call.
    pub fn last(&self) -> usize {
        self.last_n
    }

    #[inline]
    fn a(&self, l: u64) -> f64 {
        self.alpha[(l % self.alpha.len() as u64) as usize]
    }

    /// Record α_k of this sample and return N_k. Never allocates.
    pub fn next(&mut self, alpha_k: f64) -> usize {
        let k = self.k;
        let a = if alpha_k.is_finite() {
            alpha_k
        } else if k == 0 {
            0.0
        } else {
            self.last_alpha
        };
        if k == 0 {
            self.alpha0 = a;
        } else if a < self.last_alpha {
            self.last_decrease = Some(k);
        }
        let len = self.alpha.len() as u64;
        self.alpha[(k % len) as usize] = a;
        self.last_alpha = a;
        self.k += 1;
        if !self.primed && a >= self.alpha0 + self.period {
            self.primed = true;
        }
        let n = if !self.primed || k < self.n_min as u64 {
            self.n_init.min(self.n_max)
        } else {
            let lo = k.saturating_sub(self.n_max as u64);
            let hi = k - self.n_min as u64;
            let target = a - self.period;
            let monotone = match self.last_decrease {
                None => true,
                Some(j) => j <= lo,
            };
            let star = if monotone && self.prev_star <= hi {
                let mut p = self.prev_star.max(lo);
                let mut fp = (self.a(p) - target).abs();
                while p < hi {
                    let fq = (self.a(p + 1) - target).abs();
                    if fq <= fp {
                        p += 1;
                        fp = fq;
                    } else {
                        break;
                    }
                }
                p
            } else {
                self.scan(lo, hi, target)
            };
            self.prev_star = star;
            (k - star) as usize
        };
        self.last_n = n;
        n
    }

    /// Full scan of the window: argmin |α_l − target|, ties to the latest l.
    fn scan(&self, lo: u64, hi: u64, target: f64) -> u64 {
        // The window is at most two contiguous pieces of the ring; scan newest to
        // oldest with a strict `<` so ties go to the most recent sample.
        let len = self.alpha.len() as u64;
        let mut best = hi;
        let mut fb = f64::INFINITY;
        let mut top = hi; // absolute index of the newest unscanned sample
        loop {
            let ring_top = (top % len) as usize;
            let count = (top - lo + 1).min(ring_top as u64 + 1) as usize;
            let seg = &self.alpha[ring_top + 1 - count..=ring_top];
            for (j, &v) in seg.iter().enumerate().rev() {
                let f = (v - target).abs();
                if f < fb {
                    fb = f;
                    best = top - (seg.len() - 1 - j) as u64;
                }
            }
            if top < lo + count as u64 {
                break;
            }
            top -= count as u64;
        }
        best
    }

    /// Reference implementation of (5.7)–(5.8) over a whole α record (allocates;
    /// for tests and analysis): the same rules as [`next`](Self::next), by brute
    /// force.
    pub fn reference(
        alpha: &[f64],
        period: f64,
        n_min: usize,
        n_max: usize,
        n_init: usize,
    ) -> Vec<usize> {
        let n_min = n_min.max(1);
        let n_max = n_max.max(n_min);
        let n_init = n_init.clamp(n_min, n_max);
        let mut out = Vec::with_capacity(alpha.len());
        let mut clean = Vec::with_capacity(alpha.len());
        let mut primed = false;
        for (k, &raw) in alpha.iter().enumerate() {
            let a = if raw.is_finite() {
                raw
            } else {
                clean.last().copied().unwrap_or(0.0)
            };
            clean.push(a);
            if a >= clean[0] + period {
                primed = true;
            }
            if !primed || k < n_min {
                out.push(n_init);
                continue;
            }
            let lo = k.saturating_sub(n_max);
            let hi = k - n_min;
            let target = a - period;
            let mut best = hi;
            let mut fb = f64::INFINITY;
            for l in (lo..=hi).rev() {
                let f = (clean[l] - target).abs();
                if f < fb {
                    fb = f;
                    best = l;
                }
            }
            out.push(k - best);
        }
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ring_buffer_reads_past_samples() {
        let mut d = VaryingDelay::new(5);
        for k in 0..20 {
            if k >= 3 {
                assert_eq!(d.get(3), (k - 3) as f64);
            } else {
                assert_eq!(d.get(3), 0.0);
            }
            if k >= 5 {
                assert_eq!(d.get(5), (k - 5) as f64);
            }
            d.push(k as f64);
        }
    }

    #[test]
    fn alpha_equal_time_gives_the_constant_period() {
        let dt = 2.5e-4;
        let n = 37;
        let mut a = AlphaDelay::new(n as f64 * dt, 20, 60, n);
        for k in 0..500u64 {
            assert_eq!(a.next(k as f64 * dt), n, "k {k}");
        }
    }

    #[test]
    fn stall_grows_the_delay_up_to_n_max_then_holds_it() {
        // α = k/10 (P = 1: N = 10), then stalls at sample 100 for 30 samples.
        let mut alpha: Vec<f64> = (0..100).map(|k| k as f64 / 10.0).collect();
        alpha.extend(std::iter::repeat_n(9.9, 30));
        alpha.extend((0..50).map(|k| 9.9 + (k + 1) as f64 / 10.0));
        let mut est = AlphaDelay::new(1.0, 5, 20, 10);
        let got: Vec<usize> = alpha.iter().map(|&x| est.next(x)).collect();
        assert_eq!(got, AlphaDelay::reference(&alpha, 1.0, 5, 20, 10));
        assert_eq!(got[99], 10);
        // During the stall: 11, 12, ... up to 20, then 20.
        assert_eq!(got[100], 11);
        assert_eq!(got[108], 19);
        assert_eq!(got[109], 20);
        assert_eq!(got[118], 20);
        // From sample 119 the whole window [k − M, k − m] holds the stalled value:
        // all samples tie and the most recent wins.
        assert_eq!(got[119], 5);
        assert_eq!(got[129], 5);
        // After the stall the window still holds the stalled samples; back to 10
        // once the stall has passed by one period.
        assert_eq!(got[179], 10);
    }

    #[test]
    fn reversal_follows_the_literal_definition() {
        // Up for 100 samples, then down (velocity sign change), then up again.
        let mut alpha: Vec<f64> = (0..100).map(|k| k as f64 / 10.0).collect();
        alpha.extend((0..60).map(|k| 9.9 - (k + 1) as f64 / 20.0));
        alpha.extend((0..80).map(|k| 6.9 + (k + 1) as f64 / 10.0));
        let mut est = AlphaDelay::new(1.0, 2, 40, 10);
        let got: Vec<usize> = alpha.iter().map(|&x| est.next(x)).collect();
        assert_eq!(got, AlphaDelay::reference(&alpha, 1.0, 2, 40, 10));
        for &n in &got {
            assert!((2..=40).contains(&n));
        }
        // Going down, α_k − P_α lies ahead in the descent and the rising samples
        // have left the window: the closest admissible sample is the most recent
        // one, N_k = m (documented: the learning is meaningless while α reverses,
        // but N_k stays in [m, M], so (5.9) still guarantees stability).
        assert_eq!(got[100 + 45], 2);
        // NaN is a stall.
        let mut est = AlphaDelay::new(1.0, 2, 40, 10);
        for k in 0..50 {
            est.next(k as f64 / 10.0);
        }
        assert_eq!(est.next(f64::NAN), 11);
    }
}
