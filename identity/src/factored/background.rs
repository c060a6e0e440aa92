//! What a track carries if the truth lies outside its group's table: its
//! leak λ (how likely that is) and one independent distribution over
//! identities ([`crate::factored`], "What cuts lose").
//!
//! The track's marginals are (1 − λ)·table + λ·row. Both components follow
//! every event as Bayes' rule and the mixing kernel say: a read
//! multiplies its likelihood into the row and reweighs λ by how well the
//! table and the row explained it; a mix mixes the two tracks' rows and
//! leaks, (1 − s)·a + s·b, the kernel's effect on a product's marginals
//! (the product forgets the pair's correlation, as the belief matrix's
//! rows do). The row ignores that identities are exclusive, which makes
//! it diffuse rather than confident.
//!
//! A row is stored sparsely: one probability shared by every identity not
//! listed, and the listed ones, so memory grows with the reads and mixes a
//! track took part in, not with N.

use crate::sparse_marginals::IdentityRow;
use idmesh_belief::BeliefError;
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;

/// Listed entries closer than this to the shared probability are dropped.
const NEGLIGIBLE: f64 = 1e-12;

/// One track's leak and background distribution over `n` identities.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Background {
    /// The probability that the track's identity lies outside its group's
    /// table: the weight of this row in the track's marginals.
    leak: f64,
    /// The probability of each identity not in `listed`.
    shared: f64,
    listed: BTreeMap<u32, f64>,
}

impl Background {
    /// Every one of `n` identities alike.
    pub(crate) fn uniform(n: usize) -> Self {
        Background {
            leak: 0.0,
            shared: 1.0 / n.max(1) as f64,
            listed: BTreeMap::new(),
        }
    }

    /// A row read from outside the process (a leader's transfer): its
    /// leak, the probability shared by unlisted identities, and the
    /// listed ones; every number a probability.
    pub fn from_parts(
        leak: f64,
        shared: f64,
        listed: impl IntoIterator<Item = (u32, f64)>,
    ) -> Result<Self, BeliefError> {
        let listed: BTreeMap<u32, f64> = listed.into_iter().collect();
        let bad = [leak, shared]
            .into_iter()
            .chain(listed.values().copied())
            .find(|p| !(0.0..=1.0).contains(p));
        if let Some(p) = bad {
            return Err(BeliefError::BadComponent {
                detail: format!("a background row with a probability of {p}"),
            });
        }
        Ok(Background {
            leak,
            shared,
            listed,
        })
    }

    /// The probability of each identity not listed.
    pub fn shared(&self) -> f64 {
        self.shared
    }

    /// The identities listed, with their probabilities, in order.
    pub fn listed_entries(&self) -> impl Iterator<Item = (u32, f64)> + '_ {
        self.listed.iter().map(|(&i, &p)| (i, p))
    }

    /// Surely identity `i`.
    pub(crate) fn certain(i: u32) -> Self {
        Background {
            leak: 0.0,
            shared: 0.0,
            listed: BTreeMap::from([(i, 1.0)]),
        }
    }

    /// P(the track carries identity `i`).
    pub(crate) fn probability(&self, i: u32) -> f64 {
        self.listed.get(&i).copied().unwrap_or(self.shared)
    }

    /// The probability that the track's identity lies outside its
    /// group's table.
    pub fn leak(&self) -> f64 {
        self.leak
    }

    /// A cut or a dropped link ruled out assignments that put an identity
    /// from elsewhere on this track with probability `q`: that mass leaks.
    pub(crate) fn lose(&mut self, q: f64) {
        let q = q.clamp(0.0, 1.0);
        self.leak = 1.0 - (1.0 - self.leak) * (1.0 - q);
    }

    /// Bayes' rule for a read of `i` with likelihood `right` if the track
    /// carries i, `wrong` otherwise, on the row and on the leak: the read
    /// was `table` likely under the group's table (needed only while the
    /// track leaks), and under this row as likely as the row says. A read
    /// the row cannot explain (likelihood 0) leaves the row alone, and says
    /// so (false). The
    /// row is renormalized over its `n` identities as it goes: a read of
    /// small likelihood divides by it, and would otherwise magnify the
    /// rounding of earlier steps until the row no longer summed to one.
    pub fn read(&mut self, n: usize, i: u32, right: f64, wrong: f64, table: Option<f64>) -> bool {
        let p = self.probability(i);
        let total = self.total(n);
        let weighed = right * p + wrong * (total - p).max(0.0);
        let evidence = weighed / total;
        if !(evidence > 0.0 && evidence.is_finite()) {
            return false;
        }
        if let Some(table) = table.filter(|_| self.leak > 0.0) {
            let total = self.leak * evidence + (1.0 - self.leak) * table;
            if total > 0.0 && total.is_finite() {
                self.leak = self.leak * evidence / total;
            }
        }
        let scale = wrong / weighed;
        self.shared *= scale;
        self.listed.values_mut().for_each(|q| *q *= scale);
        self.listed.insert(i, p * right / weighed);
        self.prune();
        true
    }

    /// Σ_i P(i) over `n` identities: one, up to rounding.
    fn total(&self, n: usize) -> f64 {
        let listed: f64 = self.listed.values().sum();
        listed + self.shared * n.saturating_sub(self.listed.len()) as f64
    }

    /// A read on the row alone ([`Self::read`] without a table), and where
    /// the row rules the read out and the read is sure (no wrong read has
    /// any likelihood), the row believes it: identity `i` with
    /// certainty. The last resort of [`super::repair`].
    pub(crate) fn read_or_believe(&mut self, n: usize, i: u32, right: f64, wrong: f64) {
        if !self.read(n, i, right, wrong, None) {
            let leak = self.leak;
            *self = Background::certain(i);
            self.leak = leak;
        }
    }

    /// The mix of rows `a` and `b` with swap `s`: a gets (1 − s)·a + s·b,
    /// b gets (1 − s)·b + s·a.
    pub fn mix(a: &mut Background, b: &mut Background, s: f64) {
        let mixed = |x: &Background, y: &Background| {
            let mut listed = BTreeMap::new();
            for &i in x.listed.keys().chain(y.listed.keys()) {
                listed.insert(i, (1.0 - s) * x.probability(i) + s * y.probability(i));
            }
            // The target on the track was x's with 1 − s, y's with s:
            // its leak comes along.
            Background {
                leak: (1.0 - s) * x.leak + s * y.leak,
                shared: (1.0 - s) * x.shared + s * y.shared,
                listed,
            }
        };
        let (new_a, new_b) = (mixed(a, b), mixed(b, a));
        *a = new_a;
        *b = new_b;
        a.prune();
        b.prune();
    }

    /// The track's row of the table's marginals becomes the track's:
    /// (1 − leak)·table + leak·this row, over the identities either lists;
    /// every other one has this row's shared probability times the leak.
    pub(crate) fn mix_into(&self, table: IdentityRow) -> IdentityRow {
        let leak = self.leak;
        if leak <= 0.0 {
            return table;
        }
        let mut mixed: Vec<(u32, f64)> = table
            .listed
            .iter()
            .map(|&(i, p)| (i, (1.0 - leak) * p + leak * self.probability(i)))
            .collect();
        mixed.extend(
            self.listed_entries()
                .filter(|&(i, _)| table.listed.binary_search_by_key(&i, |x| x.0).is_err())
                .map(|(i, q)| (i, leak * q)),
        );
        IdentityRow::collect(leak * self.shared, mixed)
    }

    /// Listed entries within [`NEGLIGIBLE`] of the shared probability need
    /// no entry.
    fn prune(&mut self) {
        let shared = self.shared;
        self.listed.retain(|_, q| (*q - shared).abs() > NEGLIGIBLE);
    }

    /// Identities listed (the row's memory).
    pub(crate) fn listed(&self) -> usize {
        self.listed.len()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn dense(r: &Background, n: usize) -> Vec<f64> {
        (0..n as u32).map(|i| r.probability(i)).collect()
    }

    #[test]
    fn reads_and_mixes_follow_bayes_and_the_kernel_on_dense_rows() {
        let n = 5;
        let (mut a, mut b) = (Background::uniform(n), Background::certain(3));
        // A read of 2 at accuracy 0.9 on a uniform row: 0.9 against
        // 0.025 for each of the four others.
        a.read(n, 2, 0.9, 0.025, None);
        assert_eq!(a.leak(), 0.0, "nothing leaked, nothing to weigh");
        let want: Vec<f64> = (0..n).map(|i| if i == 2 { 0.9 } else { 0.025 }).collect();
        for (p, q) in dense(&a, n).iter().zip(&want) {
            assert!((p - q).abs() < 1e-12);
        }
        Background::mix(&mut a, &mut b, 0.25);
        let (da, db) = (dense(&a, n), dense(&b, n));
        for i in 0..n {
            let certain = if i == 3 { 1.0 } else { 0.0 };
            assert!((da[i] - (0.75 * want[i] + 0.25 * certain)).abs() < 1e-12);
            assert!((db[i] - (0.75 * certain + 0.25 * want[i])).abs() < 1e-12);
        }
        assert!((da.iter().sum::<f64>() - 1.0).abs() < 1e-12);
        assert!((db.iter().sum::<f64>() - 1.0).abs() < 1e-12);
    }

    #[test]
    fn a_read_weighs_the_leak_by_how_well_each_side_explained_it() {
        let mut r = Background::uniform(4);
        r.lose(0.2);
        assert!((r.leak() - 0.2).abs() < 1e-15);
        // A read of 0 at 0.7 (wrong reads 0.1 each): the row explains it
        // with 0.7/4 + 3·0.1/4 = 0.25, the table (which rules 0 out) with
        // 0.1.
        r.read(4, 0, 0.7, 0.1, Some(0.1));
        let want = 0.2 * 0.25 / (0.2 * 0.25 + 0.8 * 0.1);
        assert!((r.leak() - want).abs() < 1e-15);
        // Mixing carries the leak with the target.
        let mut other = Background::certain(3);
        Background::mix(&mut r, &mut other, 0.25);
        assert!((r.leak() - 0.75 * want).abs() < 1e-15);
        assert!((other.leak() - 0.25 * want).abs() < 1e-15);
        // The track's marginals: (1 − leak)·table + leak·row.
        let row = other.mix_into(IdentityRow::from_dense(&[0.0, 1.0, 0.0, 0.0]));
        let leak = other.leak();
        let want = |i: u32| f64::from(i == 1) * (1.0 - leak) + leak * other.probability(i);
        for i in 0..4 {
            assert!((row.probability(i) - want(i)).abs() < 1e-15, "identity {i}");
        }
        assert!((row.total(4) - 1.0).abs() < 1e-12);
    }

    #[test]
    fn a_read_no_identity_explains_changes_nothing_and_rows_stay_sparse() {
        let mut r = Background::certain(1);
        r.read(4, 0, 0.9, 0.0, Some(0.5));
        assert_eq!(r, Background::certain(1));
        // Mixing two uniform rows lists nothing.
        let (mut a, mut b) = (Background::uniform(1000), Background::uniform(1000));
        Background::mix(&mut a, &mut b, 0.5);
        assert_eq!((a.listed(), b.listed()), (0, 0));
    }
}
