//! The skip option (8.5)–(8.7): which of the past events the register keeps.
//!
//! Events are numbered k = 1, 2, … in the order they happen (a direction reversal
//! does not restart the numbering). With skip σ the register keeps the events on the
//! grid k ≡ 1 (mod σ + 1) — σ events are skipped between two stored ones — and, as
//! the thesis chooses in Sec. 8.4.2, always the newest event k even when it is off
//! the grid, so the skip does not cost resolution or quadrature.

/// k_σ(k, i) of (8.5): the i-th newest grid event at or before event k,
/// k − mod(k − 1, σ + 1) − (i − 1)(σ + 1), with the floor modulus (8.6). May be ≤ 0
/// (no such event yet).
pub fn skip_index(k: i64, i: i64, sigma: i64) -> i64 {
    let s1 = sigma + 1;
    k - (k - 1).rem_euclid(s1) - (i - 1) * s1
}

/// The register K(k) of (8.7) for newest event `k` (≥ 1), register length
/// `out.len()` = n and skip `sigma`: newest first. Returns how many entries are valid
/// (index ≥ 1); the rest of `out` is left as 0.
///
/// ```
/// use timestamp_encoder::skip::register_indices;
/// let mut k = [0u64; 5];
/// // σ = 2: grid events 1, 4, 7, 10, …; the newest event 12 is kept.
/// assert_eq!(register_indices(12, 2, &mut k), 5);
/// assert_eq!(k, [12, 10, 7, 4, 1]);
/// // Newest on the grid: five grid events.
/// assert_eq!(register_indices(13, 2, &mut k), 5);
/// assert_eq!(k, [13, 10, 7, 4, 1]);
/// ```
pub fn register_indices(k: u64, sigma: u64, out: &mut [u64]) -> usize {
    out.fill(0);
    if k == 0 {
        return 0;
    }
    let (k, s) = (k as i64, sigma as i64);
    let on_grid = skip_index(k, 1, s) == k;
    let mut n = 0;
    for (slot, o) in out.iter_mut().enumerate() {
        let idx = if on_grid {
            skip_index(k, slot as i64 + 1, s)
        } else if slot == 0 {
            k
        } else {
            skip_index(k, slot as i64, s)
        };
        if idx < 1 {
            break;
        }
        *o = idx as u64;
        n += 1;
    }
    n
}

/// How many of the most recent events an event buffer must hold so that every
/// register entry is available: n(σ + 1).
pub fn history_len(n: usize, sigma: usize) -> usize {
    n * (sigma + 1)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The thesis's definition read literally: mod(x, y) = x − y⌊x/y⌋.
    fn k_sigma_literal(k: i64, i: i64, sigma: i64) -> i64 {
        let (x, y) = (k - 1, sigma + 1);
        let m = x - y * (x as f64 / y as f64).floor() as i64;
        k - m - (i - 1) * (sigma + 1)
    }

    #[test]
    fn skip_index_matches_literal_definition() {
        for sigma in 0..6 {
            for k in 1..60 {
                for i in 1..6 {
                    assert_eq!(skip_index(k, i, sigma), k_sigma_literal(k, i, sigma));
                }
            }
        }
    }

    #[test]
    fn register_keeps_newest_and_grid() {
        let mut out = [0u64; 5];
        for sigma in 0u64..7 {
            for k in 1u64..80 {
                let n = register_indices(k, sigma, &mut out);
                assert_eq!(out[0], k, "newest always kept");
                // Rest are on the grid, strictly decreasing, spaced σ + 1.
                for w in 1..n {
                    assert_eq!((out[w] - 1) % (sigma + 1), 0);
                    if w >= 2 {
                        assert_eq!(out[w - 1] - out[w], sigma + 1);
                    }
                    assert!(out[w] < out[w - 1]);
                    assert!(out[w] + history_len(5, sigma as usize) as u64 > k);
                }
                // Valid count: all n once enough events exist.
                if k as usize >= history_len(5, sigma as usize) {
                    assert_eq!(n, 5);
                }
            }
        }
        // σ = 0 is plain time-stamping: the last n events.
        assert_eq!(register_indices(9, 0, &mut out), 5);
        assert_eq!(out, [9, 8, 7, 6, 5]);
        assert_eq!(register_indices(3, 0, &mut out), 3);
        assert_eq!(out, [3, 2, 1, 0, 0]);
    }
}
