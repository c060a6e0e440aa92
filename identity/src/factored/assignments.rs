//! The table of one group's distribution over its k! assignments, stored
//! sparsely or densely, whichever takes fewer bytes.
//!
//! Why: a group of k tracks has k! assignments (362,880 at k = 9), but
//! mixes reach only the assignments a chain of swaps leads to and cuts
//! condition most of the rest away. On random-waypoint crowds 99.6–99.8%
//! of the entries of groups of 7 tracks or more are exactly 0, so dense
//! tables spent nearly all of the belief's memory on zeros (227 MB at the
//! peak of a 10,000-track stream of 3n events, against 3.5 MB stored
//! this way). A sparse table keeps only the assignments of non-zero
//! probability, by rank (in increasing order) with their probabilities:
//! 12 bytes an entry against 8 bytes an assignment for a dense one, so a
//! table is dense exactly when 12·support ≥ 8·k! (two thirds of the
//! assignments possible or more) — a group that has mixed thoroughly,
//! where the dense mixing rule is also the faster one.
//!
//! Every operation that builds a table produces (rank, probability)
//! entries and [`Assignments::from_sorted`] picks the representation;
//! exact zeros are dropped and nothing else is (no threshold), so the
//! numbers are those of the dense code: sums are taken in the same order
//! (by source rank into a target rank, then by target rank), bit for bit.

use idmesh_belief::BeliefError;

/// A distribution over the assignments of a group, by Lehmer rank.
///
/// The number of assignments (k!) is the group's, passed where needed: a
/// sparse table does not know it.
#[derive(Debug, Clone, serde::Serialize, serde::Deserialize)]
pub(crate) enum Assignments {
    /// `probs[r]` for every rank r < k!.
    Dense(Vec<f64>),
    /// The assignments of non-zero probability: `ranks` strictly
    /// increasing, `probs[i]` the probability of rank `ranks[i]`.
    Sparse { ranks: Vec<u32>, probs: Vec<f64> },
}

impl PartialEq for Assignments {
    /// The same distribution, however stored.
    fn eq(&self, other: &Self) -> bool {
        self.entries().eq(other.entries())
    }
}

/// True when a table of `support` non-zero entries among `count`
/// assignments takes no more bytes dense (8 a assignment) than sparse (12
/// an entry).
pub(crate) fn prefers_dense(support: usize, count: usize) -> bool {
    12 * support >= 8 * count
}

impl Assignments {
    /// The table of `entries`, sorted by rank with no rank twice, among
    /// `count` assignments; zeros are dropped. Callers build the entries
    /// from ranks of a table of `count` permutations.
    pub(crate) fn from_sorted(count: usize, entries: Vec<(u32, f64)>) -> Self {
        debug_assert!(entries.windows(2).all(|w| w[0].0 < w[1].0));
        debug_assert!(entries.last().is_none_or(|e| (e.0 as usize) < count));
        let support = entries.iter().filter(|e| e.1 != 0.0).count();
        if prefers_dense(support, count) {
            let mut probs = vec![0.0; count];
            for (r, p) in entries {
                probs[r as usize] = p;
            }
            return Assignments::Dense(probs);
        }
        // Exact capacities: the stored size is what the belief reports.
        let mut ranks = Vec::with_capacity(support);
        let mut probs = Vec::with_capacity(support);
        for (r, p) in entries.into_iter().filter(|e| e.1 != 0.0) {
            ranks.push(r);
            probs.push(p);
        }
        Assignments::Sparse { ranks, probs }
    }

    /// The table of a dense vector of probabilities by rank.
    pub(crate) fn from_dense(probs: Vec<f64>) -> Self {
        let mut table = Assignments::Dense(probs);
        table.settle();
        table
    }

    /// Switches to the representation of fewer bytes (after an update in
    /// place changed the support).
    pub(crate) fn settle(&mut self) {
        let count = match self {
            Assignments::Dense(probs) => probs.len(),
            Assignments::Sparse { .. } => return,
        };
        if !prefers_dense(self.support(), count) {
            let entries = self.entries().collect();
            *self = Assignments::from_sorted(count, entries);
        }
    }

    /// Stores the table densely whatever its support (the reference
    /// representation of the tests).
    #[cfg(test)]
    pub(crate) fn densify(&mut self, count: usize) {
        if let Assignments::Sparse { ranks, probs } = self {
            let mut dense = vec![0.0; count];
            for (&r, &p) in ranks.iter().zip(probs.iter()) {
                dense[r as usize] = p;
            }
            *self = Assignments::Dense(dense);
        }
    }

    /// Whether the table is stored densely.
    #[cfg(test)]
    pub(crate) fn is_dense(&self) -> bool {
        matches!(self, Assignments::Dense(_))
    }

    /// The assignments of non-zero probability, (rank, probability) in
    /// increasing rank.
    pub(crate) fn entries(&self) -> Entries<'_> {
        match self {
            Assignments::Dense(probs) => Entries::Dense(probs.iter().enumerate()),
            Assignments::Sparse { ranks, probs } => Entries::Sparse(ranks.iter().zip(probs.iter())),
        }
    }

    /// The number of assignments of non-zero probability.
    pub(crate) fn support(&self) -> usize {
        match self {
            Assignments::Dense(probs) => probs.iter().filter(|&&p| p != 0.0).count(),
            Assignments::Sparse { ranks, .. } => ranks.len(),
        }
    }

    /// P(assignment of rank `rank`); 0 for one not listed or out of range.
    pub(crate) fn get(&self, rank: u32) -> f64 {
        match self {
            Assignments::Dense(probs) => probs.get(rank as usize).copied().unwrap_or(0.0),
            Assignments::Sparse { ranks, probs } => {
                ranks.binary_search(&rank).map_or(0.0, |i| probs[i])
            }
        }
    }

    /// The heap bytes of the table as stored (by capacity).
    pub(crate) fn heap_bytes(&self) -> usize {
        match self {
            Assignments::Dense(probs) => 8 * probs.capacity(),
            Assignments::Sparse { ranks, probs } => 4 * ranks.capacity() + 8 * probs.capacity(),
        }
    }

    /// Checks a table read from outside the process against `count`
    /// assignments: ranks in range and strictly increasing, probabilities
    /// finite and non-negative (listed ones positive), summing to one.
    pub(crate) fn check(&self, count: usize) -> Result<(), BeliefError> {
        let bad = |detail: String| Err(BeliefError::BadComponent { detail });
        match self {
            Assignments::Dense(probs) => {
                if probs.len() != count {
                    return bad(format!(
                        "{} probabilities for {count} assignments",
                        probs.len()
                    ));
                }
            }
            Assignments::Sparse { ranks, probs } => {
                if ranks.len() != probs.len() {
                    return bad(format!(
                        "{} ranks and {} probabilities",
                        ranks.len(),
                        probs.len()
                    ));
                }
                check_ranks(ranks.iter().copied(), count)?;
                if probs.contains(&0.0) {
                    return bad("a listed assignment of probability 0".into());
                }
            }
        }
        check_probabilities(self.entries().map(|e| e.1))
    }
}

/// Ranks below `count` and strictly increasing, or an error naming the
/// first that is not.
pub(crate) fn check_ranks(
    ranks: impl IntoIterator<Item = u32>,
    count: usize,
) -> Result<(), BeliefError> {
    let mut last: Option<u32> = None;
    for r in ranks {
        if r as usize >= count {
            return Err(BeliefError::BadComponent {
                detail: format!("an assignment of rank {r} among {count}"),
            });
        }
        if let Some(before) = last.filter(|&before| before >= r) {
            return Err(BeliefError::BadComponent {
                detail: format!("assignment ranks not strictly increasing: {r} after {before}"),
            });
        }
        last = Some(r);
    }
    Ok(())
}

/// Probabilities finite, non-negative, summing to one within 1e-6.
pub(crate) fn check_probabilities(probs: impl IntoIterator<Item = f64>) -> Result<(), BeliefError> {
    let mut total = 0.0;
    for p in probs {
        if !(p.is_finite() && p >= 0.0) {
            return Err(BeliefError::BadComponent {
                detail: format!("a probability that is negative or not finite ({p})"),
            });
        }
        total += p;
    }
    if (total - 1.0).abs() > 1e-6 {
        return Err(BeliefError::BadComponent {
            detail: format!("probabilities summing to {total}"),
        });
    }
    Ok(())
}

/// Sorts `entries` by rank (stably: entries of one rank keep the order
/// they were produced in) and sums the entries of each rank in that
/// order — the order in which the dense code added them into its slot.
pub(crate) fn accumulate(mut entries: Vec<(u32, f64)>) -> Vec<(u32, f64)> {
    if !entries.is_sorted_by_key(|e| e.0) {
        entries.sort_by_key(|e| e.0);
    }
    entries.dedup_by(|later, first| {
        if later.0 == first.0 {
            first.1 += later.1;
            true
        } else {
            false
        }
    });
    entries
}

/// The probability of `rank` among sorted `entries` (0 if absent).
pub(crate) fn lookup(entries: &[(u32, f64)], rank: u32) -> f64 {
    entries
        .binary_search_by_key(&rank, |e| e.0)
        .map_or(0.0, |i| entries[i].1)
}

/// The entries of a table: (rank, probability) of non-zero probability,
/// in increasing rank.
pub(crate) enum Entries<'a> {
    Dense(std::iter::Enumerate<std::slice::Iter<'a, f64>>),
    Sparse(std::iter::Zip<std::slice::Iter<'a, u32>, std::slice::Iter<'a, f64>>),
}

impl Iterator for Entries<'_> {
    type Item = (u32, f64);

    fn next(&mut self) -> Option<(u32, f64)> {
        match self {
            Entries::Dense(it) => it.find(|e| *e.1 != 0.0).map(|(r, &p)| (r as u32, p)),
            Entries::Sparse(it) => it.next().map(|(&r, &p)| (r, p)),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_representation_is_the_smaller() {
        // 3 of 6 non-zero: 36 bytes sparse against 48 dense.
        let sparse = Assignments::from_sorted(6, vec![(0, 0.5), (2, 0.0), (3, 0.25), (5, 0.25)]);
        assert!(!sparse.is_dense());
        assert_eq!(sparse.support(), 3);
        assert_eq!(sparse.get(3), 0.25);
        assert_eq!(sparse.get(2), 0.0);
        // 4 of 6: 48 bytes either way, dense.
        let dense = Assignments::from_sorted(6, vec![(0, 0.25), (1, 0.25), (3, 0.25), (5, 0.25)]);
        assert!(dense.is_dense());
        assert_eq!(dense.entries().collect::<Vec<_>>()[2], (3, 0.25));
        let mut forced = sparse.clone();
        forced.densify(6);
        assert!(forced.is_dense() && forced == sparse);
        assert!(sparse.check(6).is_ok() && dense.check(6).is_ok());
        assert!(sparse.check(3).is_err(), "rank 5 among 3");
    }

    #[test]
    fn accumulating_sums_in_production_order() {
        let merged = accumulate(vec![(3, 0.1), (1, 0.2), (3, 0.3), (1, 0.4)]);
        assert_eq!(merged, vec![(1, 0.2 + 0.4), (3, 0.1 + 0.3)]);
        assert_eq!(lookup(&merged, 3), 0.1 + 0.3);
        assert_eq!(lookup(&merged, 2), 0.0);
    }
}
