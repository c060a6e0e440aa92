//! What a track carries if the truth lies outside its group's table: one
//! independent distribution over identities per track, the fallback of a
//! group's leak ([`crate::identity::factored`], "What cuts lose").
//!
//! A cut conditions its group on the event E it keeps and so rules out the
//! assignments outside E; a dropped link rules out what crossed it. Left
//! out, that mass makes the belief certain of tables that are sometimes
//! wrong (on random-waypoint traces of 100 tracks, a twelfth of the truth
//! lines put the true identity at probability 0). Instead each group keeps
//! the mass it lost as a leak λ and the belief on its tracks is the
//! mixture (1 − λ)·table + λ·background, the background a product of one
//! distribution per track. Both components follow every event as Bayes'
//! rule and the mixing kernel say: a read multiplies its likelihood into
//! both and reweighs λ by how well each explained it; a mix mixes the two
//! tracks' background rows, (1 − s)·r_a + s·r_b, the kernel's effect on a
//! product's marginals (the product forgets the pair's correlation, as the
//! belief matrix's rows do). The background thus ignores that identities
//! are exclusive, which makes it diffuse rather than confident.
//!
//! A row is stored sparsely: one probability shared by every identity not
//! listed, and the listed ones, so memory grows with the reads and mixes a
//! track took part in, not with N.

use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;

/// Listed entries closer than this to the shared probability are dropped.
const NEGLIGIBLE: f64 = 1e-12;

/// One track's background distribution over `n` identities.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Background {
    /// The probability of each identity not in `listed`.
    shared: f64,
    listed: BTreeMap<u32, f64>,
}

impl Background {
    /// Every one of `n` identities alike.
    pub fn uniform(n: usize) -> Self {
        Background {
            shared: 1.0 / n.max(1) as f64,
            listed: BTreeMap::new(),
        }
    }

    /// Surely identity `i`.
    pub fn certain(i: u32) -> Self {
        Background {
            shared: 0.0,
            listed: BTreeMap::from([(i, 1.0)]),
        }
    }

    /// P(the track carries identity `i`).
    pub fn probability(&self, i: u32) -> f64 {
        self.listed.get(&i).copied().unwrap_or(self.shared)
    }

    /// Bayes' rule for a read of `i` with likelihood `right` if the track
    /// carries i, `wrong` otherwise; returns the read's likelihood under
    /// the row before it (what [`crate::identity::factored`] weighs the
    /// leak by). A read the row cannot explain (likelihood 0) changes
    /// nothing.
    pub fn read(&mut self, i: u32, right: f64, wrong: f64) -> f64 {
        let p = self.probability(i);
        let evidence = right * p + wrong * (1.0 - p);
        if !(evidence > 0.0 && evidence.is_finite()) {
            return evidence;
        }
        let scale = wrong / evidence;
        self.shared *= scale;
        self.listed.values_mut().for_each(|q| *q *= scale);
        self.listed.insert(i, p * right / evidence);
        self.prune();
        evidence
    }

    /// The mix of rows `a` and `b` with swap `s`: a gets (1 − s)·a + s·b,
    /// b gets (1 − s)·b + s·a.
    pub fn mix(a: &mut Background, b: &mut Background, s: f64) {
        let mixed = |x: &Background, y: &Background| {
            let mut listed = BTreeMap::new();
            for &i in x.listed.keys().chain(y.listed.keys()) {
                listed.insert(i, (1.0 - s) * x.probability(i) + s * y.probability(i));
            }
            Background {
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

    /// Adds `weight` × this row to a dense row of n identities.
    pub fn add_to(&self, row: &mut [f64], weight: f64) {
        if self.shared != 0.0 {
            row.iter_mut().for_each(|p| *p += weight * self.shared);
        }
        for (&i, &q) in &self.listed {
            if let Some(p) = row.get_mut(i as usize) {
                *p += weight * (q - self.shared);
            }
        }
    }

    /// Listed entries within [`NEGLIGIBLE`] of the shared probability need
    /// no entry.
    fn prune(&mut self) {
        let shared = self.shared;
        self.listed.retain(|_, q| (*q - shared).abs() > NEGLIGIBLE);
    }

    /// Identities listed (the row's memory).
    pub fn listed(&self) -> usize {
        self.listed.len()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn dense(r: &Background, n: usize) -> Vec<f64> {
        let mut row = vec![0.0; n];
        r.add_to(&mut row, 1.0);
        row
    }

    #[test]
    fn reads_and_mixes_follow_bayes_and_the_kernel_on_dense_rows() {
        let n = 5;
        let (mut a, mut b) = (Background::uniform(n), Background::certain(3));
        // A read of 2 at accuracy 0.9 on a uniform row: 0.9 against
        // 0.025 for each of the four others.
        let evidence = a.read(2, 0.9, 0.025);
        assert!((evidence - (0.9 + 4.0 * 0.025) / 5.0).abs() < 1e-15);
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
    fn a_read_no_identity_explains_changes_nothing_and_rows_stay_sparse() {
        let mut r = Background::certain(1);
        assert_eq!(r.read(0, 0.9, 0.0), 0.0);
        assert_eq!(r, Background::certain(1));
        // Mixing two uniform rows lists nothing.
        let (mut a, mut b) = (Background::uniform(1000), Background::uniform(1000));
        Background::mix(&mut a, &mut b, 0.5);
        assert_eq!((a.listed(), b.listed()), (0, 0));
    }
}
