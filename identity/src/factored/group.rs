//! One group of a factored identity belief: k tracks that mixed with each
//! other, the k identities they carry between them, and the exact
//! distribution over the k! assignments of those identities to those
//! tracks — the exact filter of Shin et al. (IPSN 2005, Section 2) on a
//! block of the belief instead of on all N tracks.
//!
//! Assignments are indexed by Lehmer rank in a table of all k!
//! permutations of 0..k ([`Permutations`]), shared by every group of the
//! same size through a process-wide cache: the tables are pure functions
//! of k, so sharing them keeps the belief itself plain data (serde) and
//! deterministic. The distribution itself is stored sparsely (the
//! assignments of non-zero probability) or densely, whichever takes fewer
//! bytes ([`super::assignments`]): most assignments of a large group are
//! exactly 0.

use super::assignments::{self, Assignments};
use super::split::Cut;
use crate::permutation::{Permutations, MAX_ENUMERATED_TRACKS};
use idmesh_belief::BeliefError;
use std::sync::OnceLock;

/// The most tracks one group may hold: the largest table of assignments
/// we enumerate (9! = 362,880).
pub const MAX_GROUP: usize = MAX_ENUMERATED_TRACKS;

/// The table of all permutations of 0..k, built once per k per process.
pub(crate) fn permutations(k: usize) -> Result<&'static Permutations, BeliefError> {
    static TABLES: [OnceLock<Permutations>; MAX_GROUP + 1] =
        [const { OnceLock::new() }; MAX_GROUP + 1];
    let slot = TABLES.get(k).ok_or(BeliefError::TooLarge {
        method: "factored identity group",
        needed: (1..=k).map(|x| x as f64).product(),
        limit: (1..=MAX_GROUP).product(),
    })?;
    if let Some(table) = slot.get() {
        return Ok(table);
    }
    let table = Permutations::new(k)?;
    Ok(slot.get_or_init(|| table))
}

/// The exact distribution over the assignments of one group.
///
/// Local track j is global track `tracks[j]`; local identity x is global
/// identity `identities[x]`; the probability of rank r is the probability
/// that local track j carries local identity `perm_r[j]` for every j,
/// perm_r the permutation of rank r.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Group {
    pub(crate) tracks: Vec<u32>,
    pub(crate) identities: Vec<u32>,
    pub(crate) probs: Assignments,
}

impl Group {
    /// One track that surely carries one identity.
    pub(crate) fn certain(track: u32, identity: u32) -> Self {
        Group {
            tracks: vec![track],
            identities: vec![identity],
            probs: Assignments::from_sorted(1, vec![(0, 1.0)]),
        }
    }

    /// A group read from outside the process (a leader's transfer): its
    /// tracks, identities and the assignments of non-zero probability,
    /// (rank, probability) with ranks below k! and strictly increasing,
    /// probabilities finite, non-negative and summing to one (within
    /// 1e-6). Entries of probability 0 are dropped.
    pub fn from_parts(
        tracks: Vec<u32>,
        identities: Vec<u32>,
        entries: Vec<(u32, f64)>,
    ) -> Result<Self, BeliefError> {
        let count = check_sizes(tracks.len(), identities.len())?;
        assignments::check_ranks(entries.iter().map(|e| e.0), count)?;
        assignments::check_probabilities(entries.iter().map(|e| e.1))?;
        Ok(Group {
            tracks,
            identities,
            probs: Assignments::from_sorted(count, entries),
        })
    }

    /// Every assignment of `identities` to `tracks` equally likely.
    pub(crate) fn uniform(tracks: Vec<u32>, identities: Vec<u32>) -> Result<Self, BeliefError> {
        let k = tracks.len();
        if k == 0 || identities.len() != k {
            return Err(BeliefError::BadComponent {
                detail: format!("{k} tracks and {} identities", identities.len()),
            });
        }
        let count = permutations(k)?.count();
        Ok(Group {
            tracks,
            identities,
            probs: Assignments::from_dense(vec![1.0 / count as f64; count]),
        })
    }

    /// The number of tracks (= identities).
    pub fn size(&self) -> usize {
        self.tracks.len()
    }

    /// The global tracks, in local order.
    pub fn tracks(&self) -> &[u32] {
        &self.tracks
    }

    /// The global identities, in local order.
    pub fn identities(&self) -> &[u32] {
        &self.identities
    }

    /// The assignments of non-zero probability: (local Lehmer rank,
    /// probability), in increasing rank.
    pub fn entries(&self) -> impl Iterator<Item = (u32, f64)> + '_ {
        self.probs.entries()
    }

    /// The number of assignments of non-zero probability.
    pub fn support(&self) -> usize {
        self.probs.support()
    }

    /// The number of assignments, k!.
    pub fn assignments(&self) -> usize {
        self.table().count()
    }

    /// P(assignment) of local Lehmer rank `rank` (0 out of range).
    pub(crate) fn probability(&self, rank: u32) -> f64 {
        self.probs.get(rank)
    }

    /// The heap bytes of the group: its table as stored and its labels.
    pub(crate) fn heap_bytes(&self) -> usize {
        self.probs.heap_bytes() + 4 * (self.tracks.capacity() + self.identities.capacity())
    }

    pub(crate) fn table(&self) -> &'static Permutations {
        // Every group is built through `permutations`, or checked by
        // `check` after deserialization, so the size is in range.
        permutations(self.size()).unwrap_or_else(|_| unreachable!("group sizes are checked"))
    }

    /// Stores the group's table densely whatever its support (the
    /// reference the tests compare the sparse representation with).
    #[cfg(test)]
    pub(crate) fn densify(&mut self) {
        let count = self.assignments();
        self.probs.densify(count);
    }

    /// The local index of global track `track`.
    pub(crate) fn local_track(&self, track: u32) -> Option<usize> {
        self.tracks.iter().position(|&t| t == track)
    }

    /// Checks the invariants of a group read from outside the process.
    pub(crate) fn check(&self) -> Result<(), BeliefError> {
        let count = check_sizes(self.size(), self.identities.len())?;
        self.probs.check(count)
    }

    /// The group of `self` and `other` together, independent: the product
    /// of the two distributions. Local tracks and identities of `other`
    /// follow those of `self`.
    pub(crate) fn join(&self, other: &Group) -> Result<Group, BeliefError> {
        let (k1, k2) = (self.size(), other.size());
        let k = k1 + k2;
        let table = permutations(k)?;
        let (t1, t2) = (self.table(), other.table());
        // The product of the two supports. A joined assignment is the
        // first's followed by the second's (shifted past k1), so ranks come
        // out in increasing order.
        let mut entries = Vec::with_capacity(self.support() * other.support());
        let mut perm = [0u8; MAX_GROUP];
        for (r1, p1) in self.entries() {
            perm[..k1].copy_from_slice(t1.get(r1 as usize));
            for (r2, p2) in other.entries() {
                for (slot, &x) in perm[k1..k].iter_mut().zip(t2.get(r2 as usize)) {
                    *slot = x + k1 as u8;
                }
                entries.push((table.rank(&perm[..k]) as u32, p1 * p2));
            }
        }
        let mut tracks = self.tracks.clone();
        tracks.extend_from_slice(&other.tracks);
        let mut identities = self.identities.clone();
        identities.extend_from_slice(&other.identities);
        Ok(Group {
            tracks,
            identities,
            probs: Assignments::from_sorted(table.count(), assignments::accumulate(entries)),
        })
    }

    /// Mixes local tracks `a` and `b` (Definition 2, eq. 1): q(π) =
    /// (1 − s)·p(π) + s·p(π∘(a b)). Cannot fail.
    pub fn mix(&mut self, a: usize, b: usize, swap: f64) {
        let table = self.table();
        match &mut self.probs {
            Assignments::Dense(probs) => {
                // The support counted on the way, so that staying dense
                // (the common case: a mix only grows the support) costs
                // no second pass.
                let mut support = 0;
                for r in 0..probs.len() {
                    let partner = table.rank_swapped(r, a, b);
                    if r < partner {
                        let (p, q) = (probs[r], probs[partner]);
                        let (x, y) = ((1.0 - swap) * p + swap * q, (1.0 - swap) * q + swap * p);
                        probs[r] = x;
                        probs[partner] = y;
                        support += usize::from(x != 0.0) + usize::from(y != 0.0);
                    }
                }
                if !assignments::prefers_dense(support, probs.len()) {
                    self.probs.settle();
                }
            }
            Assignments::Sparse { ranks, probs } => {
                // Each assignment keeps (1 − s) of its mass and sends s to
                // its partner; the two lists merged by rank. Where both an
                // assignment and its partner are listed, the sum is the
                // dense rule's (1 − s)·p + s·q, term for term.
                let mut moved: Vec<(u32, f64)> = ranks
                    .iter()
                    .zip(probs.iter())
                    .map(|(&r, &p)| (table.rank_swapped(r as usize, a, b) as u32, swap * p))
                    .collect();
                // The swap is a bijection: no rank twice.
                moved.sort_unstable_by_key(|e| e.0);
                let mut merged = Vec::with_capacity(ranks.len() + moved.len());
                let mut kept = ranks.iter().zip(probs.iter()).peekable();
                let mut moved = moved.into_iter().peekable();
                loop {
                    let next = match (kept.peek(), moved.peek()) {
                        (Some(&(&r, &p)), Some(&(m, q))) => {
                            if r < m {
                                kept.next();
                                (r, (1.0 - swap) * p)
                            } else if m < r {
                                moved.next();
                                (m, q)
                            } else {
                                kept.next();
                                moved.next();
                                (r, (1.0 - swap) * p + q)
                            }
                        }
                        (Some(&(&r, &p)), None) => {
                            kept.next();
                            (r, (1.0 - swap) * p)
                        }
                        (None, Some(&(m, q))) => {
                            moved.next();
                            (m, q)
                        }
                        (None, None) => break,
                    };
                    merged.push(next);
                }
                self.probs = Assignments::from_sorted(table.count(), merged);
            }
        }
    }

    /// Bayes' rule for a read on local track `track` whose likelihood is
    /// `right` if the track carries local identity `read`, `wrong`
    /// otherwise. All-or-nothing: an impossible read changes nothing.
    pub fn read(
        &mut self,
        track: usize,
        read: usize,
        right: f64,
        wrong: f64,
    ) -> Result<(), BeliefError> {
        // Local identities are below the group's size (at most 9): one that
        // does not fit a u8 is carried by no assignment, as u8::MAX is.
        let read = u8::try_from(read).unwrap_or(u8::MAX);
        let table = self.table();
        match &mut self.probs {
            Assignments::Dense(probs) => {
                table.condition_on_read(probs, track, read, right, wrong)?;
            }
            Assignments::Sparse { ranks, probs } => {
                table.condition_entries_on_read(ranks, probs, track, read, right, wrong)?;
                // A likelihood of 0 (or an underflow) zeroes assignments.
                if probs.contains(&0.0) {
                    let entries = ranks.iter().copied().zip(probs.iter().copied()).collect();
                    self.probs = Assignments::from_sorted(table.count(), entries);
                }
                return Ok(());
            }
        }
        self.probs.settle();
        Ok(())
    }

    /// m\[j\]\[x\] = P(local track j carries local identity x): one pass over
    /// the assignments of non-zero probability.
    pub(crate) fn local_marginals(&self) -> Vec<Vec<f64>> {
        let k = self.size();
        let table = self.table();
        let mut m = vec![vec![0.0; k]; k];
        for (r, p) in self.entries() {
            for (j, &x) in table.get(r as usize).iter().enumerate() {
                m[j][x as usize] += p;
            }
        }
        m
    }
}

/// k! for a group of `tracks` tracks and `identities` identities, or an
/// error if they differ or k is not 1..=[`MAX_GROUP`].
fn check_sizes(tracks: usize, identities: usize) -> Result<usize, BeliefError> {
    if tracks == 0 || tracks > MAX_GROUP || identities != tracks {
        return Err(BeliefError::BadComponent {
            detail: format!("a group of {tracks} tracks and {identities} identities"),
        });
    }
    Ok((1..=tracks).product())
}

/// A port of a group: one end of a link between two groups (see
/// [`super::links`]). Its phantom track and its star identity share the
/// port's global id (≥ n); the group's table holds both.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) struct Port {
    /// The port's global id (phantom track = star identity = `id`).
    pub id: u32,
    /// The local index of the phantom track.
    pub phantom: usize,
    /// The local index of the star identity.
    pub star: usize,
}

/// Bit i of the result: port i's phantom does not carry its star, i.e. an
/// identity crossed the link (its exchange flag).
pub(crate) fn flags_of(perm: &[u8], ports: &[Port]) -> usize {
    ports.iter().enumerate().fold(0, |acc, (i, p)| {
        acc | (usize::from(perm[p.phantom] as usize != p.star) << i)
    })
}

impl Group {
    /// The group's ports: tracks with a global id ≥ `n`, in local order.
    pub(crate) fn ports(&self, n: usize) -> Vec<Port> {
        self.tracks
            .iter()
            .enumerate()
            .filter(|&(_, &t)| t as usize >= n)
            .map(|(j, &t)| Port {
                id: t,
                phantom: j,
                star: self
                    .identities
                    .iter()
                    .position(|&i| i == t)
                    .unwrap_or(usize::MAX),
            })
            .collect()
    }

    /// The port with global id `id` (≥ `n`), or an error naming it.
    pub(crate) fn port(&self, n: usize, id: u32) -> Result<Port, BeliefError> {
        self.ports(n)
            .into_iter()
            .find(|x| x.id == id)
            .ok_or(BeliefError::BadComponent {
                detail: format!("port {id} is not in its group"),
            })
    }

    /// The number of real tracks (ids below `n`).
    pub(crate) fn real_size(&self, n: usize) -> usize {
        self.tracks.iter().filter(|&&t| (t as usize) < n).count()
    }

    /// F\[c\] = the factor's mass on the assignments whose exchange flags
    /// ([`flags_of`]) are c: 2^|ports| entries.
    pub(crate) fn flag_table(&self, ports: &[Port]) -> Vec<f64> {
        let table = self.table();
        let mut out = vec![0.0; 1 << ports.len()];
        for (r, p) in self.entries() {
            out[flags_of(table.get(r as usize), ports)] += p;
        }
        out
    }

    /// The local marginals of the factor weighed by `messages[i][flag of
    /// port i]` (the belief of the group inside its tree of links),
    /// normalized; none when the weights vanish.
    pub(crate) fn weighted_marginals(
        &self,
        ports: &[Port],
        messages: &[[f64; 2]],
    ) -> Option<Vec<Vec<f64>>> {
        if ports.is_empty() {
            return Some(self.local_marginals());
        }
        let k = self.size();
        let table = self.table();
        let weights = config_weights(ports.len(), messages);
        let mut m = vec![vec![0.0; k]; k];
        let mut total = 0.0;
        for (r, p) in self.entries() {
            let perm = table.get(r as usize);
            let w = p * weights[flags_of(perm, ports)];
            if w == 0.0 {
                continue;
            }
            total += w;
            for (j, &x) in perm.iter().enumerate() {
                m[j][x as usize] += w;
            }
        }
        if !(total.is_finite() && total > 0.0) {
            return None;
        }
        m.iter_mut().flatten().for_each(|p| *p /= total);
        Some(m)
    }

    /// Spreads `share` of the group's mass evenly over its well-formed
    /// assignments ((1 − share)·table + share·uniform; well-formed: no
    /// port's phantom carries another port's star, an identity crossing
    /// two links, which no cut builds and no answer can read): every such
    /// assignment and every flag of a link possible again
    /// ([`super::repair`]). `n` tells ports from tracks.
    pub(crate) fn smooth(&mut self, share: f64, n: usize) {
        let table = self.table();
        let count = table.count();
        let ports = self.ports(n);
        let stars: u32 = ports.iter().fold(0, |acc, p| acc | (1 << p.star));
        let well_formed = |perm: &[u8]| {
            ports.iter().all(|p| {
                let x = perm[p.phantom] as usize;
                x == p.star || stars & (1 << x) == 0
            })
        };
        let formed: Vec<bool> = (0..count).map(|r| well_formed(table.get(r))).collect();
        let even = share / formed.iter().filter(|&&f| f).count().max(1) as f64;
        let mut probs: Vec<f64> = formed.iter().map(|&f| if f { even } else { 0.0 }).collect();
        for (r, p) in self.entries() {
            probs[r as usize] += (1.0 - share) * p;
        }
        let total: f64 = probs.iter().sum();
        let entries = probs
            .into_iter()
            .enumerate()
            .filter(|&(_, p)| p > 0.0)
            .map(|(r, p)| (r as u32, p / total))
            .collect();
        self.probs = Assignments::from_sorted(count, entries);
    }

    /// The mass, weighed by `messages[i][flag of port i]` (the group's
    /// belief inside its tree of links), of the assignments that send at
    /// most `exchanges` identities across `cut` (0: a hard cut keeps them,
    /// 1: a linked one).
    pub(crate) fn kept_tree_mass(
        &self,
        ports: &[Port],
        messages: &[[f64; 2]],
        cut: &Cut,
        exchanges: u32,
    ) -> f64 {
        let table = self.table();
        let weights = config_weights(ports.len(), messages);
        // A linked cut keeps one exchange only between real tracks and
        // real identities: a port's phantom or star never crosses.
        let of_port = ports
            .iter()
            .fold(0u32, |acc, p| acc | (1 << p.phantom) | (1 << (16 + p.star)));
        self.entries()
            .filter_map(|(r, p)| {
                let perm = table.get(r as usize);
                let (mut crossing, mut by_port) = (0u32, false);
                for (j, &x) in perm.iter().enumerate() {
                    let inside = cut.tracks & (1 << j) != 0;
                    if inside != (cut.identities & (1 << x) != 0) {
                        crossing += u32::from(inside);
                        by_port |= of_port & ((1 << j) | (1 << (16 + x as u32))) != 0;
                    }
                }
                (crossing == 0 || (crossing <= exchanges && !by_port))
                    .then(|| p * weights[flags_of(perm, ports)])
            })
            .sum()
    }

    /// Multiplies every assignment's probability by `weight(assignment)`
    /// and renormalizes; all-or-nothing.
    pub(crate) fn reweight(&mut self, weight: impl Fn(&[u8]) -> f64) -> Result<(), BeliefError> {
        let table = self.table();
        let mut posterior: Vec<(u32, f64)> = self
            .entries()
            .map(|(r, p)| (r, p * weight(table.get(r as usize))))
            .collect();
        let total: f64 = posterior.iter().map(|e| e.1).sum();
        if !(total.is_finite() && total > 0.0) {
            return Err(BeliefError::ImpossibleObservation { probability: total });
        }
        posterior.iter_mut().for_each(|e| e.1 /= total);
        self.probs = Assignments::from_sorted(table.count(), posterior);
        Ok(())
    }

    /// A group on `tracks` and `identities` whose assignment of rank r is
    /// the sum of the probabilities of the assignments of `self` that
    /// `map` sends to it (`map` writes the new local assignment and says
    /// whether the old one is kept), normalized; with the kept mass.
    pub(crate) fn relabel(
        &self,
        tracks: Vec<u32>,
        identities: Vec<u32>,
        mut map: impl FnMut(&[u8], &mut [u8]) -> bool,
    ) -> Result<(Group, f64), BeliefError> {
        let k = tracks.len();
        let target = permutations(k)?;
        let table = self.table();
        let mut sent = Vec::new();
        let mut buf = [0u8; MAX_GROUP];
        for (r, p) in self.entries() {
            if map(table.get(r as usize), &mut buf[..k]) {
                sent.push((target.rank(&buf[..k]) as u32, p));
            }
        }
        let mut probs = assignments::accumulate(sent);
        let mass: f64 = probs.iter().map(|e| e.1).sum();
        if !(mass.is_finite() && mass > 0.0) {
            return Err(BeliefError::Degenerate { normalizer: mass });
        }
        probs.iter_mut().for_each(|e| e.1 /= mass);
        Ok((
            Group {
                tracks,
                identities,
                probs: Assignments::from_sorted(target.count(), probs),
            },
            mass,
        ))
    }
}

/// w\[c\] = Π_i messages\[i\]\[bit i of c\], for every flag configuration c.
pub(crate) fn config_weights(ports: usize, messages: &[[f64; 2]]) -> Vec<f64> {
    (0..1usize << ports)
        .map(|c| {
            messages
                .iter()
                .enumerate()
                .map(|(i, m)| m[(c >> i) & 1])
                .product()
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    /// The dense code this representation replaced: join, mix and read on
    /// a `Vec<f64>` by rank, the reference the groups must equal.
    mod reference {
        use super::*;

        pub(crate) fn join(p1: &[f64], k1: usize, p2: &[f64], k2: usize) -> Vec<f64> {
            let k = k1 + k2;
            let table = permutations(k).unwrap();
            let (t1, t2) = (permutations(k1).unwrap(), permutations(k2).unwrap());
            let mut probs = vec![0.0; table.count()];
            let mut perm = [0u8; MAX_GROUP];
            for (r1, &a) in p1.iter().enumerate() {
                if a == 0.0 {
                    continue;
                }
                perm[..k1].copy_from_slice(t1.get(r1));
                for (r2, &b) in p2.iter().enumerate() {
                    if b == 0.0 {
                        continue;
                    }
                    for (slot, &x) in perm[k1..k].iter_mut().zip(t2.get(r2)) {
                        *slot = x + k1 as u8;
                    }
                    probs[table.rank(&perm[..k])] = a * b;
                }
            }
            probs
        }

        pub fn mix(probs: &mut [f64], k: usize, a: usize, b: usize, swap: f64) {
            let table = permutations(k).unwrap();
            for r in 0..probs.len() {
                let partner = table.rank_swapped(r, a, b);
                if r < partner {
                    let (p, q) = (probs[r], probs[partner]);
                    probs[r] = (1.0 - swap) * p + swap * q;
                    probs[partner] = (1.0 - swap) * q + swap * p;
                }
            }
        }
    }

    /// One group three ways: as the belief stores it, forced dense after
    /// every step, and the old dense code's vector.
    #[derive(Clone)]
    struct Three {
        natural: Group,
        dense: Group,
        old: Vec<f64>,
    }

    impl Three {
        fn certain(t: u32) -> Self {
            let mut dense = Group::certain(t, t);
            dense.densify();
            Three {
                natural: Group::certain(t, t),
                dense,
                old: vec![1.0],
            }
        }

        fn agree(&self) -> Result<(), TestCaseError> {
            let old: Vec<(u32, f64)> = self
                .old
                .iter()
                .enumerate()
                .filter(|e| *e.1 != 0.0)
                .map(|(r, &p)| (r as u32, p))
                .collect();
            // Bit for bit: the same sums in the same order.
            prop_assert_eq!(self.natural.entries().collect::<Vec<_>>(), old.clone());
            prop_assert_eq!(self.dense.entries().collect::<Vec<_>>(), old);
            prop_assert!(self.dense.probs.is_dense());
            let (a, b) = (self.natural.local_marginals(), self.dense.local_marginals());
            for (x, y) in a.iter().flatten().zip(b.iter().flatten()) {
                prop_assert!((x - y).abs() < 1e-12, "{} against {}", x, y);
            }
            prop_assert!(self.natural.check().is_ok());
            Ok(())
        }
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(64))]

        /// Random streams of joins, mixes and reads (some impossible) give
        /// the same tables through sparse and dense storage as through
        /// the dense code they replaced.
        #[test]
        fn sparse_and_dense_storage_agree(
            steps in prop::collection::vec((0u8..3, 0usize..64, 0usize..64, 0usize..64, 0u8..6), 1..40)
        ) {
            let mut groups: Vec<Three> = (0..8).map(Three::certain).collect();
            for (kind, x, y, z, w) in steps {
                let g = x % groups.len();
                let k = groups[g].natural.size();
                match kind {
                    0 => {
                        let h = y % groups.len();
                        if h == g || k + groups[h].natural.size() > 7 {
                            continue;
                        }
                        let (first, second) = (groups[g].clone(), groups[h].clone());
                        let old = reference::join(
                            &first.old, k, &second.old, second.natural.size(),
                        );
                        let mut dense = first.dense.join(&second.dense).unwrap();
                        dense.densify();
                        let joined = Three {
                            natural: first.natural.join(&second.natural).unwrap(),
                            dense,
                            old,
                        };
                        let (lo, hi) = (g.min(h), g.max(h));
                        groups.remove(hi);
                        groups.remove(lo);
                        groups.push(joined);
                    }
                    1 if k >= 2 => {
                        let (a, b) = (y % k, (y % k + 1 + z % (k - 1)) % k);
                        let swap = [0.5, 0.3, 1.0, 0.0, 0.9, 1e-3][w as usize];
                        let t = &mut groups[g];
                        t.natural.mix(a, b, swap);
                        t.dense.mix(a, b, swap);
                        t.dense.densify();
                        reference::mix(&mut t.old, k, a, b, swap);
                    }
                    _ => {
                        let (track, read) = (y % k, z % k);
                        // A wrong read of weight 0 rules assignments out
                        // (and may be impossible: then nothing changes).
                        let (right, wrong) = [(0.9, 0.1), (0.7, 0.0), (0.0, 1.0), (0.6, 0.2), (1.0, 0.0), (0.5, 0.5)][w as usize];
                        let t = &mut groups[g];
                        let table = permutations(k).unwrap();
                        let old = table.condition_on_read(&mut t.old, track, read as u8, right, wrong);
                        let natural = t.natural.read(track, read, right, wrong);
                        let dense = t.dense.read(track, read, right, wrong);
                        t.dense.densify();
                        prop_assert_eq!(old.is_ok(), natural.is_ok());
                        prop_assert_eq!(old.is_ok(), dense.is_ok());
                    }
                }
                for t in &groups {
                    t.agree()?;
                }
            }
        }
    }

    #[test]
    fn from_parts_checks_the_entries() {
        let ok = Group::from_parts(vec![0, 1], vec![3, 4], vec![(0, 0.25), (1, 0.75)]);
        assert_eq!(
            ok.unwrap().entries().collect::<Vec<_>>(),
            vec![(0, 0.25), (1, 0.75)]
        );
        // Zeros are dropped, not refused.
        let zero = Group::from_parts(vec![0, 1], vec![3, 4], vec![(0, 0.0), (1, 1.0)]).unwrap();
        assert_eq!((zero.support(), zero.assignments()), (1, 2));
        let refused = |entries: Vec<(u32, f64)>| match Group::from_parts(
            vec![0, 1, 2],
            vec![3, 4, 5],
            entries,
        ) {
            Err(BeliefError::BadComponent { detail }) => detail,
            other => panic!("{other:?}"),
        };
        assert!(refused(vec![(2, 0.5), (1, 0.5)]).contains("not strictly increasing"));
        assert!(refused(vec![(1, 0.5), (1, 0.5)]).contains("not strictly increasing"));
        assert!(refused(vec![(0, 0.5), (6, 0.5)]).contains("rank 6 among 6"));
        assert!(refused(vec![(0, 0.5), (1, f64::NAN)]).contains("not finite"));
        assert!(refused(vec![(0, 1.5), (1, -0.5)]).contains("negative"));
        assert!(refused(vec![(0, 0.5), (1, 0.6)]).contains("summing to"));
        assert!(Group::from_parts(vec![0], vec![], vec![(0, 1.0)]).is_err());
        assert!(Group::from_parts(vec![], vec![], vec![]).is_err());
    }

    #[test]
    fn join_is_the_product_and_mix_is_exact() {
        let a = Group::certain(4, 1);
        let mut b = Group::uniform(vec![0, 2], vec![0, 3]).unwrap();
        b.read(0, 0, 0.9, 0.1).unwrap();
        let mut g = a.join(&b).unwrap();
        assert_eq!(g.tracks(), &[4, 0, 2]);
        assert_eq!(g.identities(), &[1, 0, 3]);
        let m = g.local_marginals();
        assert!((m[0][0] - 1.0).abs() < 1e-15);
        assert!((m[1][1] - 0.9).abs() < 1e-15 && (m[2][1] - 0.1).abs() < 1e-15);
        // Mixing track 4 (local 0) and track 0 (local 1) with swap ¼.
        g.mix(0, 1, 0.25);
        let m = g.local_marginals();
        assert!((m[0][0] - 0.75).abs() < 1e-15);
        assert!((m[1][0] - 0.25).abs() < 1e-15);
        assert!((m[0][1] - 0.25 * 0.9).abs() < 1e-15);
        assert!(g.check().is_ok());
    }

    #[test]
    fn impossible_reads_change_nothing_and_bad_groups_are_refused() {
        let mut g = Group::certain(0, 0);
        assert!(g.read(0, 0, 0.0, 1.0).is_err());
        assert_eq!(g.entries().collect::<Vec<_>>(), vec![(0, 1.0)]);
        let bad = Group {
            tracks: vec![0, 1],
            identities: vec![0, 1],
            probs: Assignments::Dense(vec![0.5, 0.6]),
        };
        assert!(bad.check().is_err());
        let unsorted = Group {
            tracks: vec![0, 1],
            identities: vec![0, 1],
            probs: Assignments::Sparse {
                ranks: vec![1, 0],
                probs: vec![0.5, 0.5],
            },
        };
        assert!(unsorted.check().is_err());
        assert!(Group::uniform(vec![0], vec![]).is_err());
        assert!(permutations(MAX_GROUP + 1).is_err());
    }
}
