//! Running independent fits on every core: a work queue over the items, with
//! each result landing in its item's slot, so the outcome never depends on
//! which thread took what or when.

use std::sync::Mutex;
use std::sync::atomic::{AtomicUsize, Ordering};

/// `f` applied to every item on `threads` workers (at most one per item),
/// results in item order. Items are taken longest-first by `cost` (a longest
/// task started last would leave the other cores idle at the end), ties in
/// item order. A panic in `f` panics the caller, once every worker has stopped.
pub fn map<T: Send, R: Send>(
    items: Vec<T>,
    threads: usize,
    cost: impl Fn(&T) -> f64,
    f: impl Fn(T) -> R + Sync,
) -> Vec<R> {
    let order = longest_first(&items, cost);
    let n = items.len();
    let inputs: Vec<Mutex<Option<T>>> = items.into_iter().map(|t| Mutex::new(Some(t))).collect();
    let slots: Vec<Mutex<Option<R>>> = (0..n).map(|_| Mutex::new(None)).collect();
    let next = AtomicUsize::new(0);
    std::thread::scope(|sc| {
        for _ in 0..threads.max(1).min(n) {
            let (order, inputs, slots, next, f) = (&order, &inputs, &slots, &next, &f);
            sc.spawn(move || {
                loop {
                    let k = next.fetch_add(1, Ordering::Relaxed);
                    let Some(&i) = order.get(k) else { break };
                    let item = inputs[i].lock().ok().and_then(|mut t| t.take());
                    if let Some(item) = item {
                        let r = f(item);
                        if let Ok(mut slot) = slots[i].lock() {
                            *slot = Some(r);
                        }
                    }
                }
            });
        }
    });
    slots
        .into_iter()
        .map(|s| {
            s.into_inner()
                .ok()
                .flatten()
                .expect("every item was mapped (a worker's panic is raised by the scope)")
        })
        .collect()
}

/// Item indices by decreasing `cost`, ties in item order.
pub fn longest_first<T>(items: &[T], cost: impl Fn(&T) -> f64) -> Vec<usize> {
    let costs: Vec<f64> = items.iter().map(cost).collect();
    let mut order: Vec<usize> = (0..items.len()).collect();
    order.sort_by(|&a, &b| costs[b].total_cmp(&costs[a]).then(a.cmp(&b)));
    order
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn results_land_in_item_order_whatever_the_threads() {
        let items: Vec<u64> = (0..37).collect();
        let cost = |x: &u64| (*x % 5) as f64;
        let one = map(items.clone(), 1, cost, |x| x * x);
        assert_eq!(one, items.iter().map(|x| x * x).collect::<Vec<_>>());
        for threads in [2, 3, 8] {
            assert_eq!(map(items.clone(), threads, cost, |x| x * x), one);
        }
        assert!(map(Vec::<u64>::new(), 2, cost, |x| x).is_empty());
    }

    #[test]
    #[should_panic]
    fn a_panic_in_a_task_panics_the_caller() {
        map(
            (0..8u64).collect(),
            2,
            |_| 1.0,
            |x| {
                assert!(x != 3, "item 3 fails");
                x
            },
        );
    }

    #[test]
    fn longest_first_orders_by_cost_then_index() {
        let c = [1.0, 3.0, 2.0, 3.0, 0.5];
        assert_eq!(longest_first(&c, |x| *x), vec![1, 3, 2, 0, 4]);
    }
}
