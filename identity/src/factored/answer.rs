//! The factored identity belief's marginals, row by row
//! ([`SparseMarginals`]): each real track's row of its group's marginals
//! (through the links of its tree, [`super::links`]) and, when the track
//! leaks, its background row ([`super::background`]) mixed in. A row lists
//! the identities of the track's group, of the groups linked to it through
//! a port the track may carry, and of its background row; every other
//! identity has the background's shared probability times the leak. The
//! work is the groups' tables and the rows' listed entries, never N².

use super::{links, FactoredIdentity};
use crate::sparse_marginals::{IdentityRow, SparseMarginals};
use idmesh_belief::BeliefError;

impl FactoredIdentity {
    /// The marginals of the groups and links alone, leaks left out: a
    /// doubly stochastic matrix, the belief's when nothing was lost.
    #[cfg(test)]
    pub(crate) fn table_marginals(&self) -> Result<crate::filter::Marginals, BeliefError> {
        let n = self.n;
        Ok(self
            .table_entries()?
            .into_iter()
            .map(|entries| IdentityRow::collect(0.0, entries).dense(n))
            .collect())
    }

    /// Each real track's (identity, probability) under the tables and
    /// links, an identity possibly more than once (a star spread over
    /// what its partner carries).
    fn table_entries(&self) -> Result<Vec<Vec<(u32, f64)>>, BeliefError> {
        let n = self.n;
        let mut bp = links::Messages::new(self);
        let local: Vec<Vec<Vec<f64>>> = (0..self.groups.len())
            .map(|g| bp.group_marginals(g))
            .collect::<Result<_, _>>()?;
        let mut table: Vec<Vec<(u32, f64)>> = vec![Vec::new(); n];
        for (group, lm) in self.groups.iter().zip(&local) {
            for (j, row) in lm.iter().enumerate() {
                let t = group.tracks[j] as usize;
                if t >= n {
                    continue;
                }
                let entries = &mut table[t];
                self.spread_row(
                    group,
                    row,
                    |h| local.get(h).map(Vec::as_slice),
                    |i, p| {
                        if p != 0.0 {
                            entries.push((i as u32, p));
                        }
                    },
                );
            }
        }
        Ok(table)
    }

    /// Track t carries identity i with (1 − λ_t)·table + λ_t·background
    /// (see the module docs of [`super`]).
    pub fn sparse_marginals(&self) -> Result<SparseMarginals, BeliefError> {
        let table = self.table_entries()?;
        let rows = table
            .into_iter()
            .zip(&self.backgrounds)
            .map(|(entries, background)| background.mix_into(IdentityRow::collect(0.0, entries)))
            .collect();
        SparseMarginals::new(rows)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::assignment::most_likely_assignment;
    use crate::filter::IdentityFilter;
    use crate::workload::{generate, IdentityWorkloadSpec};
    use crate::FactoredIdentityOptions;

    /// Σ_t ln p[t][π(t)].
    fn score(p: &[Vec<f64>], assignment: &[u32]) -> f64 {
        assignment
            .iter()
            .enumerate()
            .map(|(t, &i)| p[t][i as usize].ln())
            .sum()
    }

    /// Above the dense limit, with cuts and leaks (every entry of a
    /// leaking row positive): the rows are the dense marginals — the
    /// tables' with each leaking row mixed in — and the assignment over
    /// them is as likely as the dense Hungarian's.
    #[test]
    fn rows_equal_the_dense_marginals_and_the_assignment_is_the_densest_best() {
        let n = 240;
        let spec = IdentityWorkloadSpec {
            tracks: n,
            events: 3 * n,
            mix_share: 0.6,
            swap: 0.5,
            accuracy: 0.9,
            neighbourhood: 12,
            seed: 4,
        };
        let work = generate(&spec).unwrap();
        let options = FactoredIdentityOptions {
            max_group: 5,
            ..FactoredIdentityOptions::default()
        };
        let mut belief = FactoredIdentity::from_assignment(&work.initial, options).unwrap();
        for e in &work.events {
            belief.apply(e).unwrap();
        }
        assert!(belief.split_stats().lossy_cuts > 0, "the stream must cut");
        let rows = belief.sparse_marginals().unwrap();
        // (1 − λ)·table + λ·row, entry by entry.
        let mut dense = belief.table_marginals().unwrap();
        for (row, background) in dense.iter_mut().zip(&belief.backgrounds) {
            let leak = background.leak();
            for (i, p) in row.iter_mut().enumerate() {
                *p = (1.0 - leak) * *p + leak * background.probability(i as u32);
            }
        }
        let leaking = belief.backgrounds.iter().filter(|b| b.leak() > 0.0).count();
        assert!(leaking > 0);
        for (t, (got, want)) in rows.dense().iter().zip(&dense).enumerate() {
            for (i, (g, w)) in got.iter().zip(want).enumerate() {
                assert!((g - w).abs() < 1e-12, "p[{t}][{i}]: {g} vs {w}");
            }
        }
        assert!(
            rows.listed() < n * n / 4,
            "{} entries listed",
            rows.listed()
        );
        let best = rows.most_likely().unwrap();
        let want = most_likely_assignment(&dense).unwrap();
        let (got, want) = (score(&dense, &best), score(&dense, &want));
        assert!(
            (got - want).abs() < 1e-9 * want.abs().max(1.0),
            "{got} vs {want}"
        );
    }
}
