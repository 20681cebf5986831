//! How many workers the identification uses, and the one parallel map it
//! runs on them.
//!
//! Work is shared out at two levels: the blocks of one fit (experiments or
//! segments, [`crate::problem`]) and the candidate refits of a diagnosis
//! round ([`crate::diagnose`]). Both go through [`par_map`], which returns
//! the results in index order whatever thread computed them, so a run on
//! one worker and a run on N compute the same numbers and combine them in
//! the same order: the report is the same byte for byte.
//!
//! The worker count is, in order: [`set_threads`] (the CLI's `--threads`),
//! the `PLANTC_THREADS` environment variable, the machine's available
//! parallelism. Inside a worker a nested [`par_map`] runs inline: the
//! candidates already fill the cores, and one level of threads does not
//! oversubscribe them.

use std::cell::Cell;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::Mutex;

/// The worker count set by [`set_threads`] (0: not set).
static THREADS: AtomicUsize = AtomicUsize::new(0);

thread_local! {
    /// Whether this thread is a worker of a [`par_map`].
    static IN_WORKER: Cell<bool> = const { Cell::new(false) };
}

/// Use `n` workers from now on (`n` >= 1; 0 goes back to the default).
pub fn set_threads(n: usize) {
    THREADS.store(n, Ordering::Relaxed);
}

/// The worker count: [`set_threads`], else `PLANTC_THREADS` (a positive
/// integer; anything else is ignored), else the available parallelism.
pub fn threads() -> usize {
    match THREADS.load(Ordering::Relaxed) {
        0 => std::env::var("PLANTC_THREADS")
            .ok()
            .and_then(|s| s.trim().parse::<usize>().ok())
            .filter(|&n| n > 0)
            .unwrap_or_else(|| std::thread::available_parallelism().map_or(1, |n| n.get())),
        n => n,
    }
}

/// How many workers a [`par_map`] of `count` items called here would use
/// (1 inside a worker: nested maps run inline).
pub fn workers_for(count: usize) -> usize {
    if IN_WORKER.with(Cell::get) {
        1
    } else {
        threads().min(count).max(1)
    }
}

/// `f(i)` for `i` in `0..count` on up to [`threads`] workers; the results
/// in index order. On one worker (or inside another map's worker) the
/// calls run inline, in order, on this thread.
pub fn par_map<T: Send>(count: usize, f: impl Fn(usize) -> T + Sync) -> Vec<T> {
    // (never stopped: every item is computed)
    par_map_until(count, f, |_| false)
        .into_iter()
        .map(|v| v.expect("every item was computed"))
        .collect()
}

/// [`par_map`] that may stop early: `f(i)` for `i` in `0..count`, taken in
/// index order by whichever worker is free (a long item does not hold the
/// others back, as fixed batches would), until a result satisfies `stop`;
/// from then on no worker takes an item past the first such index (the
/// ones already running are finished). The results in index order, `None`
/// for an item not computed. Every item up to the first that stops is
/// computed, so a caller that walks the list in order and stops there
/// finds each result it needs; what was computed beyond it (at most the
/// items in flight) is the price of the wall time. On one worker the items
/// run inline, in order, up to the first that stops.
pub fn par_map_until<T: Send>(
    count: usize,
    f: impl Fn(usize) -> T + Sync,
    stop: impl Fn(&T) -> bool + Sync,
) -> Vec<Option<T>> {
    let workers = workers_for(count);
    if workers <= 1 {
        let mut out: Vec<Option<T>> = (0..count).map(|_| None).collect();
        for (i, slot) in out.iter_mut().enumerate() {
            let v = f(i);
            let done = stop(&v);
            *slot = Some(v);
            if done {
                break;
            }
        }
        return out;
    }
    let next = AtomicUsize::new(0);
    // the first index whose result stops (count: none yet)
    let first_stop = AtomicUsize::new(count);
    let slots: Vec<Mutex<Option<T>>> = (0..count).map(|_| Mutex::new(None)).collect();
    std::thread::scope(|s| {
        for _ in 0..workers {
            s.spawn(|| {
                IN_WORKER.with(|w| w.set(true));
                loop {
                    let i = next.fetch_add(1, Ordering::SeqCst);
                    if i >= count || i > first_stop.load(Ordering::SeqCst) {
                        break;
                    }
                    let v = f(i);
                    if stop(&v) {
                        first_stop.fetch_min(i, Ordering::SeqCst);
                    }
                    if let Ok(mut slot) = slots[i].lock() {
                        *slot = Some(v);
                    }
                }
            });
        }
    });
    slots
        .into_iter()
        .map(|m| m.into_inner().ok().flatten())
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn an_early_stop_computes_every_item_up_to_it_and_none_far_beyond() {
        // item 3 stops: 0..=3 are computed whatever the worker count; past
        // it only items already taken when it finished may be (the items
        // past it are slow, so item 3, taken before them, has finished by
        // the time any of them has: at most one per other worker)
        let slow = |i: usize| {
            if i > 3 {
                std::thread::sleep(std::time::Duration::from_millis(30));
            }
            i * i
        };
        let out = par_map_until(40, slow, |v| *v == 9);
        for (i, v) in out.iter().enumerate().take(4) {
            assert_eq!(*v, Some(i * i));
        }
        let beyond = out[4..].iter().filter(|v| v.is_some()).count();
        assert!(beyond < threads(), "{beyond} items computed past the stop");
        // no stop: all of them
        let all = par_map_until(9, |i| i + 1, |_| false);
        assert_eq!(all, (1..=9).map(Some).collect::<Vec<_>>());
    }

    #[test]
    fn results_come_in_index_order_and_nested_maps_run_inline() {
        let outer = par_map(7, |i| {
            let inner_workers = workers_for(4);
            let inner = par_map(3, |j| 10 * i + j);
            (inner_workers, inner)
        });
        for (i, (w, inner)) in outer.iter().enumerate() {
            assert_eq!(inner, &vec![10 * i, 10 * i + 1, 10 * i + 2]);
            // inside a worker (when there are several) nested maps are inline
            if workers_for(7) > 1 {
                assert_eq!(*w, 1);
            }
        }
    }
}
