//! A tiny work-sharing parallel map on scoped threads: the pipeline's
//! stages are embarrassingly parallel over time slots (or sensors), the
//! machine has 2 cores, and a dependency-free helper is all that needs.
//! Items are handed out one at a time from a shared counter, so uneven
//! items balance; results come back in input order, so output never
//! depends on the number of threads.

use std::sync::atomic::{AtomicUsize, Ordering};

/// `f` over `items` on up to `threads` threads (the caller's thread is one
/// of them), results in input order.
pub(crate) fn par_map<T: Sync, R: Send>(
    items: &[T],
    threads: usize,
    f: impl Fn(&T) -> R + Sync,
) -> Vec<R> {
    par_map_progress(items, threads, f, &mut |_| {})
}

/// As [`par_map`], calling `progress(done)` on the caller's thread (which
/// is the only one allowed to touch a `&mut dyn FnMut` hook) after each
/// item it finishes, with the number of items finished by all threads.
pub(crate) fn par_map_progress<T: Sync, R: Send>(
    items: &[T],
    threads: usize,
    f: impl Fn(&T) -> R + Sync,
    progress: &mut dyn FnMut(usize),
) -> Vec<R> {
    let threads = threads.max(1).min(items.len().max(1));
    let next = AtomicUsize::new(0);
    let done = AtomicUsize::new(0);
    let work = |report: &mut dyn FnMut(usize)| {
        let mut out = Vec::new();
        loop {
            let i = next.fetch_add(1, Ordering::Relaxed);
            if i >= items.len() {
                break;
            }
            out.push((i, f(&items[i])));
            let d = done.fetch_add(1, Ordering::Relaxed) + 1;
            report(d);
        }
        out
    };
    let mut parts: Vec<Vec<(usize, R)>> = std::thread::scope(|scope| {
        let helpers: Vec<_> = (1..threads)
            .map(|_| scope.spawn(|| work(&mut |_| {})))
            .collect();
        let mut parts = vec![work(progress)];
        for h in helpers {
            match h.join() {
                Ok(part) => parts.push(part),
                // Re-raise a worker's panic on the caller's thread.
                Err(payload) => std::panic::resume_unwind(payload),
            }
        }
        parts
    });
    let mut slots: Vec<Option<R>> = (0..items.len()).map(|_| None).collect();
    for part in parts.drain(..) {
        for (i, r) in part {
            slots[i] = Some(r);
        }
    }
    slots
        .into_iter()
        .map(|r| r.expect("every item is mapped exactly once"))
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn maps_in_order_on_any_number_of_threads() {
        let items: Vec<u64> = (0..1000).collect();
        for threads in [1, 2, 3] {
            let mut last = 0;
            let out = par_map_progress(&items, threads, |x| x * x, &mut |d| {
                assert!(d > last);
                last = d;
            });
            assert_eq!(out, items.iter().map(|x| x * x).collect::<Vec<_>>());
        }
        assert!(par_map(&Vec::<u8>::new(), 2, |x| *x).is_empty());
    }
}
