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
//! deterministic.

use crate::error::BeliefError;
use crate::identity::permutation::{Permutations, MAX_ENUMERATED_TRACKS};
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
/// identity `identities[x]`; `probs[r]` is the probability that local track
/// j carries local identity `perm_r[j]` for every j, perm_r the
/// permutation of rank r.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Group {
    pub(crate) tracks: Vec<u32>,
    pub(crate) identities: Vec<u32>,
    pub(crate) probs: Vec<f64>,
}

impl Group {
    /// One track that surely carries one identity.
    pub fn certain(track: u32, identity: u32) -> Self {
        Group {
            tracks: vec![track],
            identities: vec![identity],
            probs: vec![1.0],
        }
    }

    /// A group read from outside the process (a leader's transfer): its
    /// tracks, identities and the probability of each assignment by rank,
    /// checked as [`Group::check`] does.
    pub fn from_parts(
        tracks: Vec<u32>,
        identities: Vec<u32>,
        probs: Vec<f64>,
    ) -> Result<Self, BeliefError> {
        let group = Group {
            tracks,
            identities,
            probs,
        };
        group.check()?;
        Ok(group)
    }

    /// Every assignment of `identities` to `tracks` equally likely.
    pub fn uniform(tracks: Vec<u32>, identities: Vec<u32>) -> Result<Self, BeliefError> {
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
            probs: vec![1.0 / count as f64; count],
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

    /// P(assignment) by local Lehmer rank.
    pub fn probabilities(&self) -> &[f64] {
        &self.probs
    }

    pub(crate) fn table(&self) -> &'static Permutations {
        // Every group is built through `permutations`, or checked by
        // `check` after deserialization, so the size is in range.
        permutations(self.size()).unwrap_or_else(|_| unreachable!("group sizes are checked"))
    }

    /// The local index of global track `track`.
    pub(crate) fn local_track(&self, track: u32) -> Option<usize> {
        self.tracks.iter().position(|&t| t == track)
    }

    /// Checks the invariants of a group read from outside the process.
    pub fn check(&self) -> Result<(), BeliefError> {
        let k = self.size();
        let bad = |detail: String| Err(BeliefError::BadComponent { detail });
        if k == 0 || k > MAX_GROUP || self.identities.len() != k {
            return bad(format!(
                "a group of {k} tracks and {} identities",
                self.identities.len()
            ));
        }
        let count: usize = (1..=k).product();
        if self.probs.len() != count {
            return bad(format!(
                "{} probabilities for {k}! assignments",
                self.probs.len()
            ));
        }
        if self.probs.iter().any(|p| !(p.is_finite() && *p >= 0.0)) {
            return bad("a probability that is negative or not finite".into());
        }
        let total: f64 = self.probs.iter().sum();
        if (total - 1.0).abs() > 1e-6 {
            return bad(format!("probabilities summing to {total}"));
        }
        Ok(())
    }

    /// The group of `self` and `other` together, independent: the product
    /// of the two distributions. Local tracks and identities of `other`
    /// follow those of `self`.
    pub fn join(&self, other: &Group) -> Result<Group, BeliefError> {
        let (k1, k2) = (self.size(), other.size());
        let k = k1 + k2;
        let table = permutations(k)?;
        let (t1, t2) = (self.table(), other.table());
        let mut probs = vec![0.0; table.count()];
        let mut perm = [0u8; MAX_GROUP];
        for (r1, &p1) in self.probs.iter().enumerate() {
            if p1 == 0.0 {
                continue;
            }
            perm[..k1].copy_from_slice(t1.get(r1));
            for (r2, &p2) in other.probs.iter().enumerate() {
                if p2 == 0.0 {
                    continue;
                }
                for (slot, &x) in perm[k1..k].iter_mut().zip(t2.get(r2)) {
                    *slot = x + k1 as u8;
                }
                probs[table.rank(&perm[..k])] = p1 * p2;
            }
        }
        let mut tracks = self.tracks.clone();
        tracks.extend_from_slice(&other.tracks);
        let mut identities = self.identities.clone();
        identities.extend_from_slice(&other.identities);
        Ok(Group {
            tracks,
            identities,
            probs,
        })
    }

    /// Mixes local tracks `a` and `b` (Definition 2, eq. 1): q(π) =
    /// (1 − s)·p(π) + s·p(π∘(a b)). Cannot fail.
    pub fn mix(&mut self, a: usize, b: usize, swap: f64) {
        let table = self.table();
        for r in 0..self.probs.len() {
            let partner = table.rank_swapped(r, a, b);
            if r < partner {
                let (p, q) = (self.probs[r], self.probs[partner]);
                self.probs[r] = (1.0 - swap) * p + swap * q;
                self.probs[partner] = (1.0 - swap) * q + swap * p;
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
        self.table()
            .condition_on_read(&mut self.probs, track, read, right, wrong)
    }

    /// m\[j\]\[x\] = P(local track j carries local identity x): one pass over
    /// the k! assignments.
    pub fn local_marginals(&self) -> Vec<Vec<f64>> {
        let k = self.size();
        let table = self.table();
        let mut m = vec![vec![0.0; k]; k];
        for (r, &p) in self.probs.iter().enumerate() {
            if p != 0.0 {
                for (j, &x) in table.get(r).iter().enumerate() {
                    m[j][x as usize] += p;
                }
            }
        }
        m
    }
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
        for (r, &p) in self.probs.iter().enumerate() {
            if p != 0.0 {
                out[flags_of(table.get(r), ports)] += p;
            }
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
        for (r, &p) in self.probs.iter().enumerate() {
            if p != 0.0 {
                let perm = table.get(r);
                let w = p * weights[flags_of(perm, ports)];
                if w == 0.0 {
                    continue;
                }
                total += w;
                for (j, &x) in perm.iter().enumerate() {
                    m[j][x as usize] += w;
                }
            }
        }
        if !(total.is_finite() && total > 0.0) {
            return None;
        }
        m.iter_mut().flatten().for_each(|p| *p /= total);
        Some(m)
    }

    /// Multiplies every assignment's probability by `weight(assignment)`
    /// and renormalizes; all-or-nothing.
    pub(crate) fn reweight(&mut self, weight: impl Fn(&[u8]) -> f64) -> Result<(), BeliefError> {
        let table = self.table();
        let posterior: Vec<f64> = self
            .probs
            .iter()
            .enumerate()
            .map(|(r, &p)| {
                if p == 0.0 {
                    0.0
                } else {
                    p * weight(table.get(r))
                }
            })
            .collect();
        let total: f64 = posterior.iter().sum();
        if !(total.is_finite() && total > 0.0) {
            return Err(BeliefError::ImpossibleObservation { probability: total });
        }
        self.probs = posterior;
        self.probs.iter_mut().for_each(|p| *p /= total);
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
        let mut probs = vec![0.0; target.count()];
        let mut buf = [0u8; MAX_GROUP];
        for (r, &p) in self.probs.iter().enumerate() {
            if p != 0.0 && map(table.get(r), &mut buf[..k]) {
                probs[target.rank(&buf[..k])] += p;
            }
        }
        let mass: f64 = probs.iter().sum();
        if !(mass.is_finite() && mass > 0.0) {
            return Err(BeliefError::Degenerate { normalizer: mass });
        }
        probs.iter_mut().for_each(|p| *p /= mass);
        Ok((
            Group {
                tracks,
                identities,
                probs,
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
        assert_eq!(g.probabilities(), &[1.0]);
        let bad = Group {
            tracks: vec![0, 1],
            identities: vec![0, 1],
            probs: vec![0.5, 0.6],
        };
        assert!(bad.check().is_err());
        assert!(Group::uniform(vec![0], vec![]).is_err());
        assert!(permutations(MAX_GROUP + 1).is_err());
    }
}
