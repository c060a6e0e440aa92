//! Running the grid — every (scenario, method, seed) cell — on a few worker
//! threads (`std::thread::scope`), with results in the order of the cells
//! whatever order they finish in, so that the output is deterministic (up
//! to the measured times).

use super::methods::Method;
use super::scenarios::Trace;
use super::score::{score, Score};
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::Mutex;

/// One cell of the grid: a method on a trace.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct Cell {
    /// Index into the traces.
    pub trace: usize,
    pub method: Method,
    /// Seed of a randomized method.
    pub seed: u64,
}

/// `f(i, &items[i])` for every item on `workers` threads; results in item
/// order. Items are taken in the order `visit` gives (longest first balances
/// the load), each by the first idle worker. `done(finished, total)` is
/// called after each item.
pub(crate) fn parallel_map<T, R, F>(
    items: &[T],
    visit: &[usize],
    workers: usize,
    f: F,
    done: &(dyn Fn(usize, usize) + Sync),
) -> Vec<R>
where
    T: Sync,
    R: Send,
    F: Fn(usize, &T) -> R + Sync,
{
    debug_assert_eq!(visit.len(), items.len());
    let next = AtomicUsize::new(0);
    let finished = AtomicUsize::new(0);
    let results: Mutex<Vec<Option<R>>> = Mutex::new((0..items.len()).map(|_| None).collect());
    std::thread::scope(|scope| {
        for _ in 0..workers.max(1).min(items.len().max(1)) {
            scope.spawn(|| loop {
                let slot = next.fetch_add(1, Ordering::Relaxed);
                let Some(&i) = visit.get(slot) else { break };
                let r = f(i, &items[i]);
                results.lock().expect("no worker panicked")[i] = Some(r);
                let count = finished.fetch_add(1, Ordering::Relaxed) + 1;
                done(count, items.len());
            });
        }
    });
    results
        .into_inner()
        .expect("no worker panicked")
        .into_iter()
        .map(|r| r.expect("every item ran"))
        .collect()
}

/// A rough cost of a cell, to run the long ones first.
fn cost(cell: &Cell, traces: &[Trace]) -> f64 {
    let t = &traces[cell.trace];
    let n = t.field.tracks as f64;
    let events = t.steps.len() as f64;
    let per_event = match cell.method {
        Method::Exact => {
            let k = t.field.red.known().unwrap_or(t.field.tracks / 2);
            (0..k).fold(1.0, |acc, i| acc * (n - i as f64) / (i + 1) as f64)
        }
        Method::Order(j) => n.powi(j as i32),
        Method::Threshold(b) => b as f64 * n * 0.5,
        Method::Overcomplete(b) | Method::Distributed(b) => b as f64 * n * 2.0,
        Method::Particles(p) => p as f64 * 2.0,
        Method::Factored | Method::FactoredLocal | Method::Deployed(_) => n * n,
    };
    per_event * events
}

/// Scores every cell on `workers` threads; scores in cell order.
pub fn run(
    cells: &[Cell],
    traces: &[Trace],
    workers: usize,
    done: &(dyn Fn(usize, usize) + Sync),
) -> Vec<Score> {
    let mut visit: Vec<usize> = (0..cells.len()).collect();
    let costs: Vec<f64> = cells.iter().map(|c| cost(c, traces)).collect();
    visit.sort_by(|&a, &b| costs[b].total_cmp(&costs[a]).then(a.cmp(&b)));
    parallel_map(
        cells,
        &visit,
        workers,
        |_, cell| score(cell.method, &traces[cell.trace], cell.seed),
        done,
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn results_come_back_in_item_order() {
        let items: Vec<u64> = (0..50).collect();
        let visit: Vec<usize> = (0..50).rev().collect();
        let out = parallel_map(
            &items,
            &visit,
            3,
            |i, &x| {
                std::thread::sleep(std::time::Duration::from_micros(50 * (x % 7)));
                (i, x * x)
            },
            &|_, _| {},
        );
        assert_eq!(
            out,
            (0..50).map(|x| (x as usize, x * x)).collect::<Vec<_>>()
        );
        let none: Vec<u8> = parallel_map(&[] as &[u8], &[], 2, |_, &x| x, &|_, _| {});
        assert!(none.is_empty());
    }
}
