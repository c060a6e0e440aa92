//! The N! assignments of N identities to N tracks, listed in lexicographic
//! order and indexed by their Lehmer-code rank, so that a distribution over
//! assignments is a plain `Vec<f64>` and the transposition of two tracks
//! (the mixing event of Shin et al., IPSN 2005, Definition 2) is a
//! permutation of that index array.
//!
//! The rank of π is Σ_k d_k·(N − 1 − k)!, where the Lehmer digit d_k counts
//! the identities smaller than π(k) not used by π(0..k); with the used
//! identities kept in a bit mask each digit is one popcount, so ranking is
//! O(N). Rank order is lexicographic order, so the table is built with
//! next-permutation steps and `get(rank(π)) == π`.

use idmesh_belief::BeliefError;

/// The most tracks we enumerate: 9! = 362,880 assignments (3.3 MB of table).
pub(crate) const MAX_ENUMERATED_TRACKS: usize = 9;

/// All permutations of 0..n, in lexicographic (= Lehmer rank) order.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct Permutations {
    n: usize,
    count: usize,
    /// Row-major: permutation r is table[r·n .. (r + 1)·n].
    table: Vec<u8>,
    factorial: Vec<usize>,
}

impl Permutations {
    /// Enumerates the permutations of 0..n, 1 ≤ n ≤ [`MAX_ENUMERATED_TRACKS`].
    pub(crate) fn new(n: usize) -> Result<Self, BeliefError> {
        if n == 0 {
            return Err(BeliefError::NoTracks);
        }
        if n > MAX_ENUMERATED_TRACKS {
            return Err(BeliefError::TooLarge {
                method: "exact permutation filter",
                needed: (1..=n).map(|k| k as f64).product(),
                limit: factorial(MAX_ENUMERATED_TRACKS),
            });
        }
        let factorial: Vec<usize> = (0..=n).map(factorial).collect();
        let count = factorial[n];
        let mut table = Vec::with_capacity(count * n);
        let mut perm: Vec<u8> = (0..n as u8).collect();
        loop {
            table.extend_from_slice(&perm);
            if !next_permutation(&mut perm) {
                break;
            }
        }
        debug_assert_eq!(table.len(), count * n);
        Ok(Permutations {
            n,
            count,
            table,
            factorial,
        })
    }

    /// n.
    pub fn size(&self) -> usize {
        self.n
    }

    /// n!.
    pub fn count(&self) -> usize {
        self.count
    }

    /// The permutation of rank `rank` (< n!): entry t is the identity on
    /// track t.
    pub fn get(&self, rank: usize) -> &[u8] {
        &self.table[rank * self.n..(rank + 1) * self.n]
    }

    /// Bayes' rule for an identity read over `probs`, a distribution
    /// indexed by rank: each assignment weighed by `right` if it puts
    /// identity `read` on track `track`, `wrong` if not, then normalised.
    /// All-or-nothing: a read of probability zero (or not finite), or a
    /// likelihood that is not finite, is refused and changes nothing.
    pub(crate) fn condition_on_read(
        &self,
        probs: &mut [f64],
        track: usize,
        read: u8,
        right: f64,
        wrong: f64,
    ) -> Result<(), BeliefError> {
        self.condition(|r| r, probs, track, read, right, wrong)
    }

    /// [`Permutations::condition_on_read`] over a sparse distribution:
    /// `probs[i]` is the probability of the assignment of rank `ranks[i]`,
    /// every other assignment has probability 0 (and keeps it). The same
    /// numbers as the dense rule (zeros add nothing to the evidence).
    pub(crate) fn condition_entries_on_read(
        &self,
        ranks: &[u32],
        probs: &mut [f64],
        track: usize,
        read: u8,
        right: f64,
        wrong: f64,
    ) -> Result<(), BeliefError> {
        self.condition(|i| ranks[i] as usize, probs, track, read, right, wrong)
    }

    /// Bayes' rule over `probs`, entry i the probability of the
    /// assignment of rank `rank_of(i)`; all-or-nothing, a likelihood that
    /// is not finite refused (0·∞ on an assignment of probability 0 would
    /// otherwise decide the evidence).
    fn condition(
        &self,
        rank_of: impl Fn(usize) -> usize,
        probs: &mut [f64],
        track: usize,
        read: u8,
        right: f64,
        wrong: f64,
    ) -> Result<(), BeliefError> {
        if !(right.is_finite() && wrong.is_finite()) {
            return Err(BeliefError::ImpossibleObservation {
                probability: f64::NAN,
            });
        }
        let posterior: Vec<f64> = probs
            .iter()
            .enumerate()
            .map(|(i, &p)| {
                p * if self.get(rank_of(i))[track] == read {
                    right
                } else {
                    wrong
                }
            })
            .collect();
        // The evidence's probability under the prior belief.
        let evidence: f64 = posterior.iter().sum();
        if !(evidence.is_finite() && evidence > 0.0) {
            return Err(BeliefError::ImpossibleObservation {
                probability: evidence,
            });
        }
        for (slot, p) in probs.iter_mut().zip(posterior) {
            *slot = p / evidence;
        }
        Ok(())
    }

    /// The rank of a permutation of 0..n (not checked: callers pass
    /// permutations they built).
    pub(crate) fn rank(&self, perm: &[u8]) -> usize {
        let mut unused: u32 = (1u32 << self.n) - 1;
        let mut rank = 0;
        for (k, &v) in perm.iter().enumerate() {
            let digit = (unused & ((1u32 << v) - 1)).count_ones() as usize;
            rank += digit * self.factorial[self.n - 1 - k];
            unused &= !(1u32 << v);
        }
        rank
    }

    /// The rank of permutation `rank` with the identities on tracks `a` and
    /// `b` exchanged: π ∘ (a b).
    pub(crate) fn rank_swapped(&self, rank: usize, a: usize, b: usize) -> usize {
        let mut perm = [0u8; MAX_ENUMERATED_TRACKS];
        perm[..self.n].copy_from_slice(self.get(rank));
        perm.swap(a, b);
        self.rank(&perm[..self.n])
    }
}

/// n! as usize (n ≤ 20).
fn factorial(n: usize) -> usize {
    (1..=n).product()
}

/// Steps `perm` to the next permutation in lexicographic order; false when
/// it was the last one.
fn next_permutation(perm: &mut [u8]) -> bool {
    let n = perm.len();
    if n < 2 {
        return false;
    }
    let mut i = n - 1;
    while i > 0 && perm[i - 1] >= perm[i] {
        i -= 1;
    }
    if i == 0 {
        return false;
    }
    let mut j = n - 1;
    while perm[j] <= perm[i - 1] {
        j -= 1;
    }
    perm.swap(i - 1, j);
    perm[i..].reverse();
    true
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn rank_inverts_the_table() {
        for n in 1..=6 {
            let perms = Permutations::new(n).unwrap();
            assert_eq!(perms.count(), factorial(n));
            for r in 0..perms.count() {
                assert_eq!(perms.rank(perms.get(r)), r);
            }
        }
        let perms = Permutations::new(3).unwrap();
        assert_eq!(perms.get(0), &[0, 1, 2]);
        assert_eq!(perms.get(5), &[2, 1, 0]);
    }

    #[test]
    fn swapping_is_an_involution() {
        let perms = Permutations::new(5).unwrap();
        for r in 0..perms.count() {
            let s = perms.rank_swapped(r, 1, 3);
            assert_ne!(s, r);
            assert_eq!(perms.rank_swapped(s, 1, 3), r);
            let (p, q) = (perms.get(r), perms.get(s));
            assert_eq!((p[1], p[3]), (q[3], q[1]));
        }
    }

    #[test]
    fn limits() {
        assert_eq!(Permutations::new(0), Err(BeliefError::NoTracks));
        assert!(matches!(
            Permutations::new(10),
            Err(BeliefError::TooLarge { .. })
        ));
        assert_eq!(Permutations::new(9).unwrap().count(), 362_880);
    }
}
