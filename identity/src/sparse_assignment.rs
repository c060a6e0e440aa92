//! The assignment problem on a sparse cost matrix: the least-cost
//! one-to-one assignment of rows to columns using only the listed entries.
//!
//! A block of a crowd's information matrix is large (9,590 tracks at
//! n = 10,000) but sparse: a track can carry only the identities of the
//! people it has met, tens and not thousands. The dense Hungarian algorithm
//! ([`super::assignment`]) is O(k³) whatever the pattern (about two minutes
//! on that block); this is the same shortest-augmenting-path method with
//! Dijkstra's algorithm over the listed entries only, and with a heap, so
//! one augmentation costs O(m log k) for the m entries it reaches, and most
//! reach few (Jonker and Volgenant's sparse form, without their
//! initialization heuristics).
//!
//! Duals: row potentials u and column potentials v with
//! c\[r\]\[c\] − u\[r\] − v\[c\] ≥ 0 on every listed entry and = 0 on the
//! matched ones; each augmentation keeps both, so the final matching is
//! optimal (complementary slackness).

use std::cmp::Ordering;
use std::collections::BinaryHeap;

/// A row's listed entries: (column, cost), costs finite.
pub(crate) type SparseRow = Vec<(u32, f64)>;

/// The least-cost perfect matching of the k × k sparse matrix `rows` (row
/// r may go only to a column it lists): `result[r]` = the column of row r.
/// `None` when no perfect matching uses listed entries only.
pub(crate) fn sparse_min_cost_assignment(rows: &[SparseRow]) -> Option<Vec<u32>> {
    Matching::solve(rows).map(|m| m.assignment())
}

/// The least-cost perfect matching of a k × k matrix whose row r costs
/// `rest[r]` at every column it does not list (∞: row r may take only the
/// columns it lists) — a marginal matrix stored sparsely, one probability
/// shared by every identity a track does not list.
///
/// Exact, by column generation: solve over the listed entries, then check
/// the duals against the unlisted ones — row r's cheapest unlisted column
/// in reduced cost is the one of largest potential v\[c\] it does not list,
/// found by walking the columns in order of v. A violated one joins the
/// row's entries and the matching is repaired: the row is unmatched, its
/// potential lowered until every entry of it is feasible, and one
/// augmentation matches it again. When nothing is violated the duals are
/// feasible for the whole matrix, so the matching is optimal on it.
/// `None` when the listed entries hold no perfect matching (a marginal
/// matrix's positive entries always do: a doubly stochastic matrix's
/// support holds a permutation).
pub(crate) fn sparse_min_cost_assignment_with_rest(
    rows: &[SparseRow],
    rest: &[f64],
) -> Option<Vec<u32>> {
    let k = rows.len();
    if rest.len() != k || rest.iter().any(|x| x.is_nan() || *x == f64::NEG_INFINITY) {
        return None;
    }
    let mut rows: Vec<SparseRow> = rows.to_vec();
    for row in &mut rows {
        row.sort_by_key(|&(c, _)| c);
        row.dedup_by_key(|&mut (c, _)| c);
    }
    let mut matching = Matching::solve(&rows)?;
    let mut by_potential: Vec<usize> = (0..k).collect();
    loop {
        by_potential.sort_by(|&a, &b| matching.v[b].total_cmp(&matching.v[a]).then(a.cmp(&b)));
        let mut violated = Vec::new();
        for (r, row) in rows.iter_mut().enumerate() {
            if !rest[r].is_finite() {
                continue;
            }
            let unlisted = by_potential
                .iter()
                .copied()
                .find(|&c| row.binary_search_by_key(&(c as u32), |&(x, _)| x).is_err());
            let Some(c) = unlisted else { continue };
            let reduced = rest[r] - matching.u[r] - matching.v[c];
            // Rounding leaves reduced costs a hair below 0 on ties.
            if reduced < -1e-12 * (1.0 + rest[r].abs()) {
                let at = row.partition_point(|&(x, _)| (x as usize) < c);
                row.insert(at, (c as u32, rest[r]));
                violated.push(r);
            }
        }
        if violated.is_empty() {
            return Some(matching.assignment());
        }
        for &r in &violated {
            matching.release(r, &rows);
        }
        for &r in &violated {
            if !matching.rematch(r, &rows) {
                return None;
            }
        }
    }
}

/// A perfect matching with its dual potentials: c − u\[r\] − v\[c\] ≥ 0 on
/// every listed entry, = 0 on the matched ones.
struct Matching {
    u: Vec<f64>,
    v: Vec<f64>,
    /// column → row
    row_of: Vec<usize>,
    /// row → column
    col_of: Vec<usize>,
    search: Search,
}

impl Matching {
    fn solve(rows: &[SparseRow]) -> Option<Self> {
        let k = rows.len();
        if rows
            .iter()
            .flatten()
            .any(|&(c, x)| c as usize >= k || !x.is_finite())
        {
            return None;
        }
        // Column reduction makes u = 0 feasible: v[c] = the least cost in c.
        let mut v = vec![f64::INFINITY; k];
        for &(c, x) in rows.iter().flatten() {
            v[c as usize] = v[c as usize].min(x);
        }
        if v.iter().any(|x| !x.is_finite()) {
            return None; // a column nobody can take
        }
        let mut matching = Matching {
            u: vec![0.0; k],
            v,
            row_of: vec![NONE; k],
            col_of: vec![NONE; k],
            search: Search::new(k),
        };
        for start in 0..k {
            if !matching.rematch(start, rows) {
                return None;
            }
        }
        Some(matching)
    }

    /// Matches the free row `start` by one shortest augmenting path.
    fn rematch(&mut self, start: usize, rows: &[SparseRow]) -> bool {
        let Matching {
            u,
            v,
            row_of,
            col_of,
            search,
        } = self;
        search.augment(start, rows, u, v, row_of, col_of)
    }

    /// Unmatches row `r` and lowers its potential until every entry of it
    /// (new ones included) has a reduced cost ≥ 0.
    fn release(&mut self, r: usize, rows: &[SparseRow]) {
        let c = self.col_of[r];
        if c != NONE {
            self.row_of[c] = NONE;
            self.col_of[r] = NONE;
        }
        let least = rows[r]
            .iter()
            .map(|&(c, x)| x - self.v[c as usize])
            .fold(f64::INFINITY, f64::min);
        self.u[r] = self.u[r].min(least);
    }

    fn assignment(&self) -> Vec<u32> {
        self.col_of.iter().map(|&c| c as u32).collect()
    }
}

const NONE: usize = usize::MAX;

/// The scratch space of one Dijkstra search, reset only where it was used.
struct Search {
    dist: Vec<f64>,
    /// The row from which a column was reached.
    from: Vec<usize>,
    done: Vec<bool>,
    /// Columns whose `dist` was set, to reset them.
    touched: Vec<usize>,
    /// Columns finalized, in order.
    finalized: Vec<usize>,
    heap: BinaryHeap<Candidate>,
}

impl Search {
    fn new(k: usize) -> Self {
        Search {
            dist: vec![f64::INFINITY; k],
            from: vec![NONE; k],
            done: vec![false; k],
            touched: Vec::new(),
            finalized: Vec::new(),
            heap: BinaryHeap::new(),
        }
    }

    /// One shortest augmenting path from the free row `start`; false when
    /// no free column can be reached.
    fn augment(
        &mut self,
        start: usize,
        rows: &[SparseRow],
        u: &mut [f64],
        v: &mut [f64],
        row_of: &mut [usize],
        col_of: &mut [usize],
    ) -> bool {
        self.relax(start, 0.0, rows, u, v);
        let mut reached = None;
        while let Some(Candidate { dist, column }) = self.heap.pop() {
            if self.done[column] || dist > self.dist[column] {
                continue;
            }
            self.done[column] = true;
            self.finalized.push(column);
            let row = row_of[column];
            if row == NONE {
                reached = Some((column, dist));
                break;
            }
            // The matched edge back to `row` has reduced cost 0.
            self.relax(row, dist, rows, u, v);
        }
        let found = reached.is_some();
        if let Some((free, total)) = reached {
            // Potentials: every finalized column (and the row matched to
            // it) moves by how much shorter than `total` its path was, so
            // reduced costs stay ≥ 0 and the path's become 0.
            for &c in &self.finalized {
                let slack = total - self.dist[c];
                if slack > 0.0 {
                    v[c] -= slack;
                    if row_of[c] != NONE {
                        u[row_of[c]] += slack;
                    }
                }
            }
            u[start] += total;
            // Flip the path.
            let mut column = free;
            loop {
                let row = self.from[column];
                let previous = col_of[row];
                row_of[column] = row;
                col_of[row] = column;
                if row == start {
                    break;
                }
                column = previous;
            }
        }
        for &c in &self.touched {
            self.dist[c] = f64::INFINITY;
            self.from[c] = NONE;
            self.done[c] = false;
        }
        self.touched.clear();
        self.finalized.clear();
        self.heap.clear();
        found
    }

    /// Offers every column of `row`, reached at distance `base`.
    fn relax(&mut self, row: usize, base: f64, rows: &[SparseRow], u: &[f64], v: &[f64]) {
        for &(c, cost) in &rows[row] {
            let c = c as usize;
            if self.done[c] {
                continue;
            }
            // Rounding can make a reduced cost a hair below 0.
            let reduced = (cost - u[row] - v[c]).max(0.0);
            let d = base + reduced;
            if d < self.dist[c] {
                if self.dist[c] == f64::INFINITY {
                    self.touched.push(c);
                }
                self.dist[c] = d;
                self.from[c] = row;
                self.heap.push(Candidate { dist: d, column: c });
            }
        }
    }
}

/// A heap entry: the least distance first, then the lowest column (so the
/// search, and so the answer among equal-cost ones, is deterministic).
#[derive(Debug, Clone, Copy, PartialEq)]
struct Candidate {
    dist: f64,
    column: usize,
}

impl Eq for Candidate {}

impl Ord for Candidate {
    fn cmp(&self, other: &Self) -> Ordering {
        other
            .dist
            .total_cmp(&self.dist)
            .then_with(|| other.column.cmp(&self.column))
    }
}

impl PartialOrd for Candidate {
    fn partial_cmp(&self, other: &Self) -> Option<Ordering> {
        Some(self.cmp(other))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::assignment::min_cost_assignment;
    use rand::{Rng, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    /// A random sparse k × k matrix with a hidden perfect matching, so
    /// one always exists.
    fn random_rows(rng: &mut ChaCha8Rng, k: usize, per_row: usize) -> Vec<SparseRow> {
        let mut hidden: Vec<u32> = (0..k as u32).collect();
        for i in (1..k).rev() {
            hidden.swap(i, rng.gen_range(0..=i));
        }
        (0..k)
            .map(|r| {
                let mut cols = vec![hidden[r]];
                for _ in 1..per_row {
                    cols.push(rng.gen_range(0..k as u32));
                }
                cols.sort_unstable();
                cols.dedup();
                cols.into_iter()
                    .map(|c| (c, rng.gen_range(0.0..10.0)))
                    .collect()
            })
            .collect()
    }

    /// The k × k matrix of `rows` with row r's unlisted entries at
    /// `rest[r]`, or far above any listed path where that is ∞.
    fn dense_cost(rows: &[SparseRow], rest: &[f64]) -> Vec<f64> {
        let k = rows.len();
        let mut cost = vec![0.0; k * k];
        for r in 0..k {
            let fill = if rest[r].is_finite() { rest[r] } else { 1e6 };
            cost[r * k..(r + 1) * k].fill(fill);
            for &(c, x) in &rows[r] {
                cost[r * k + c as usize] = x;
            }
        }
        cost
    }

    /// `got` is a permutation as cheap as the dense Hungarian's on `cost`.
    fn assert_least_cost(got: &[u32], cost: &[f64], what: &str) {
        let k = got.len();
        let total = |a: &[u32]| -> f64 {
            a.iter()
                .enumerate()
                .map(|(r, &c)| cost[r * k + c as usize])
                .sum()
        };
        let mut seen = vec![false; k];
        for &c in got {
            assert!(
                !std::mem::replace(&mut seen[c as usize], true),
                "{what}: a permutation"
            );
        }
        let dense = min_cost_assignment(k, cost);
        assert!(
            (total(got) - total(&dense)).abs() < 1e-9,
            "{what}: {} against the dense {}",
            total(got),
            total(&dense)
        );
    }

    #[test]
    fn equals_the_dense_hungarian_on_random_sparse_matrices() {
        let mut rng = ChaCha8Rng::seed_from_u64(3);
        for k in 1..40 {
            for _ in 0..10 {
                let per_row = 1 + rng.gen_range(0..5);
                let rows = random_rows(&mut rng, k, per_row);
                let sparse = sparse_min_cost_assignment(&rows).expect("a matching exists");
                let cost = dense_cost(&rows, &vec![f64::INFINITY; k]);
                assert_least_cost(&sparse, &cost, &format!("k = {k}"));
            }
        }
    }

    #[test]
    fn with_rest_equals_the_dense_hungarian_on_the_whole_matrix() {
        let mut rng = ChaCha8Rng::seed_from_u64(7);
        for k in 1..30 {
            for _ in 0..20 {
                let per_row = 1 + rng.gen_range(0..4);
                let rows = random_rows(&mut rng, k, per_row);
                // Rests around the listed costs, so that some unlisted
                // entries beat listed ones; some rows take listed only.
                let rest: Vec<f64> = (0..k)
                    .map(|_| match rng.gen_range(0..4) {
                        0 => f64::INFINITY,
                        _ => rng.gen_range(0.0..12.0),
                    })
                    .collect();
                let got = sparse_min_cost_assignment_with_rest(&rows, &rest)
                    .expect("the listed entries hold a matching");
                assert_least_cost(&got, &dense_cost(&rows, &rest), &format!("k = {k}"));
            }
        }
    }

    #[test]
    fn no_perfect_matching_is_none() {
        // Rows 0 and 1 both want only column 0.
        let rows = vec![vec![(0, 1.0)], vec![(0, 2.0)], vec![(1, 0.0), (2, 0.0)]];
        assert_eq!(sparse_min_cost_assignment(&rows), None);
        // A column out of range, a non-finite cost.
        assert_eq!(sparse_min_cost_assignment(&[vec![(1, 0.0)]]), None);
        assert_eq!(sparse_min_cost_assignment(&[vec![(0, f64::NAN)]]), None);
        assert_eq!(sparse_min_cost_assignment(&[]), Some(vec![]));
    }

    #[test]
    fn ten_thousand_rows_of_thirty_entries() {
        let mut rng = ChaCha8Rng::seed_from_u64(5);
        let rows = random_rows(&mut rng, 10_000, 30);
        let a = sparse_min_cost_assignment(&rows).expect("a matching exists");
        let mut seen = vec![false; a.len()];
        for &c in &a {
            assert!(!std::mem::replace(&mut seen[c as usize], true));
        }
    }
}
