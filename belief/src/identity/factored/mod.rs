//! # A factored identity belief: exact over small groups of tracks
//!
//! The belief over the N! assignments of identities to tracks is kept as a
//! product of independent groups ([`Group`]): each holds k tracks, the k
//! identities they carry between them, and the exact distribution over
//! the k! assignments — the exact filter of Shin et al., *Lazy Inference
//! on Object Identities in Wireless Sensor Networks* (IPSN 2005, Section
//! 2), on the blocks that mixing has connected since a known start (the
//! blocks of [`crate::identity::blocks`]) instead of on all N tracks. It
//! mirrors the factored property belief ([`crate::factored`]): exact
//! components that join when their tracks mix and are split, by a
//! projection, when they would outgrow a cap.
//!
//! - A read multiplies the likelihood into the group of its track and
//!   renormalizes that group: exact. A read of an identity the group does
//!   not hold has the same likelihood under every assignment the belief
//!   allows and changes nothing.
//! - A mix of two tracks of one group is the exact mixing rule on that
//!   group; a mix across groups joins them (their product) and then mixes;
//!   a sure swap (probability 1) only exchanges the two tracks' places,
//!   and a mix of probability 0 does nothing.
//! - When the join would hold more than [`FactoredIdentityOptions::max_group`]
//!   tracks, each of the two groups first gives up the part the mix needs
//!   ([`split`]): the cut (tracks A holding the mixed track, identities
//!   I_A) with the least loss, (1 − P(π(A) = I_A)) + I(A; B | E), the split
//!   step of Huang, Guestrin and Guibas's split/join filters. A cut of a
//!   track whose identity is certain is exact.
//!
//! Without splits (every group of mixed tracks within the cap) the belief
//! equals the exact filter; marginals cost O(k!·k) per group. The belief is
//! plain data (serde), pure, synchronous and deterministic.

pub mod group;
pub mod split;

#[cfg(test)]
mod tests;

pub use group::{Group, MAX_GROUP};
pub use split::Cut;

use super::event::{check_assignment, check_identify, check_mix, Identify};
use super::filter::{IdentityFilter, Marginals};
use crate::error::BeliefError;
use crate::event::Mix;

/// The default cap on a group's tracks: the largest group we enumerate.
/// Measured on random-waypoint traces (examples/identity_factored.rs in
/// idmesh-eval; docs/design/identity.md, "Factored identity belief"): a
/// cap below n leaves lossy cuts whose zeros later reads cannot undo
/// (largest |Δp| 1.0 at n = 9, cap 8), while a cap of n is exact; a mix in
/// a full group of 9 costs about 9!·9 steps (about 1.5 ms).
pub const DEFAULT_MAX_GROUP: usize = MAX_GROUP;

/// The default of [`FactoredIdentityOptions::certain`].
pub const DEFAULT_CERTAIN: f64 = 1e-4;

/// Options of a factored identity belief.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct FactoredIdentityOptions {
    /// The most tracks one group may hold, 2 ..= [`MAX_GROUP`].
    pub max_group: usize,
    /// After a read, a track of its group whose identity has probability
    /// at least 1 − `certain` is cut off into a group of its own (losing
    /// at most `certain` of the mass), so that groups shrink as reads come
    /// in and later joins need no lossy cut. 0 = only sure tracks.
    pub certain: f64,
}

impl Default for FactoredIdentityOptions {
    fn default() -> Self {
        FactoredIdentityOptions {
            max_group: DEFAULT_MAX_GROUP,
            certain: DEFAULT_CERTAIN,
        }
    }
}

impl FactoredIdentityOptions {
    fn validate(&self) -> Result<(), BeliefError> {
        if !(0.0..0.5).contains(&self.certain) {
            return Err(BeliefError::BadComponent {
                detail: format!(
                    "a certainty threshold of {} (it must be in [0, ½))",
                    self.certain
                ),
            });
        }
        if (2..=MAX_GROUP).contains(&self.max_group) {
            Ok(())
        } else {
            Err(BeliefError::BadComponent {
                detail: format!(
                    "a group cap of {} tracks (it must be 2 to {MAX_GROUP})",
                    self.max_group
                ),
            })
        }
    }
}

/// What the splits have cost so far.
#[derive(Debug, Clone, Copy, PartialEq, Default, serde::Serialize, serde::Deserialize)]
pub struct SplitStats {
    /// Cuts made.
    pub cuts: u64,
    /// Cuts that lost something (cost above 1e-12).
    pub lossy_cuts: u64,
    /// Σ (1 − P(E)) over the cuts.
    pub lost_mass: f64,
    /// Σ I(A; B | E) over the cuts, nats.
    pub lost_information: f64,
    /// Σ ((1 − P(E)) + √(I(A; B | E)/2)) over the cuts: a bound on the
    /// total variation each cut adds between the belief and what it
    /// replaces (conditioning on E moves 1 − P(E); the product of the
    /// sides is KL = I from the conditioned belief, so by Pinsker at most
    /// √(I/2) away). Mixes are Markov kernels and cannot increase a total
    /// variation, so on a stream without reads every |Δp| against the
    /// exact filter stays below this sum; a read can amplify it.
    pub total_variation_bound: f64,
}

/// A product of independent exact groups.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(try_from = "Stored")]
pub struct FactoredIdentity {
    n: usize,
    options: FactoredIdentityOptions,
    groups: Vec<Group>,
    stats: SplitStats,
    /// group_of[t] = index in `groups` of the group of track t (derived).
    #[serde(skip)]
    group_of: Vec<usize>,
}

/// The serialized form, checked on the way in.
#[derive(serde::Deserialize)]
struct Stored {
    n: usize,
    options: FactoredIdentityOptions,
    groups: Vec<Group>,
    stats: SplitStats,
}

impl TryFrom<Stored> for FactoredIdentity {
    type Error = BeliefError;

    fn try_from(s: Stored) -> Result<Self, BeliefError> {
        s.options.validate()?;
        let bad = |detail: String| BeliefError::BadComponent { detail };
        let mut track_seen = vec![false; s.n];
        let mut identity_seen = vec![false; s.n];
        for g in &s.groups {
            g.check()?;
            if g.size() > s.options.max_group {
                return Err(bad(format!(
                    "a group of {} tracks above the cap of {}",
                    g.size(),
                    s.options.max_group
                )));
            }
            for (&t, &i) in g.tracks.iter().zip(&g.identities) {
                for (seen, x, what) in [
                    (&mut track_seen, t, "track"),
                    (&mut identity_seen, i, "identity"),
                ] {
                    let slot = seen
                        .get_mut(x as usize)
                        .ok_or_else(|| bad(format!("{what} {x} of {} out of range", s.n)))?;
                    if *slot {
                        return Err(bad(format!("{what} {x} in two groups")));
                    }
                    *slot = true;
                }
            }
        }
        if s.n == 0 || track_seen.iter().any(|&x| !x) {
            return Err(bad(format!("groups that do not cover the {} tracks", s.n)));
        }
        let mut belief = FactoredIdentity {
            n: s.n,
            options: s.options,
            groups: s.groups,
            stats: s.stats,
            group_of: Vec::new(),
        };
        belief.reindex();
        Ok(belief)
    }
}

impl FactoredIdentity {
    /// Track t surely carries identity `assignment[t]`: N groups of one.
    pub fn from_assignment(
        assignment: &[u32],
        options: FactoredIdentityOptions,
    ) -> Result<Self, BeliefError> {
        options.validate()?;
        let n = assignment.len();
        if n == 0 {
            return Err(BeliefError::NoTracks);
        }
        check_assignment(n, assignment)?;
        let groups = assignment
            .iter()
            .enumerate()
            .map(|(t, &i)| Group::certain(t as u32, i))
            .collect();
        Ok(Self::new(n, options, groups))
    }

    /// Every assignment equally likely: one group of all N tracks, so N
    /// must be within the cap.
    pub fn uniform(n: usize, options: FactoredIdentityOptions) -> Result<Self, BeliefError> {
        options.validate()?;
        if n == 0 {
            return Err(BeliefError::NoTracks);
        }
        if n > options.max_group {
            return Err(BeliefError::TooLargeBlock {
                method: "the factored identity belief (uniform start)",
                block: n,
                tracks: n,
                limit: options.max_group,
            });
        }
        let all: Vec<u32> = (0..n as u32).collect();
        let group = Group::uniform(all.clone(), all)?;
        Ok(Self::new(n, options, vec![group]))
    }

    fn new(n: usize, options: FactoredIdentityOptions, groups: Vec<Group>) -> Self {
        let mut belief = FactoredIdentity {
            n,
            options,
            groups,
            stats: SplitStats::default(),
            group_of: Vec::new(),
        };
        belief.reindex();
        belief
    }

    /// The options.
    pub fn options(&self) -> FactoredIdentityOptions {
        self.options
    }

    /// The groups, in no particular order.
    pub fn groups(&self) -> &[Group] {
        &self.groups
    }

    /// The most tracks in one group.
    pub fn largest_group(&self) -> usize {
        self.groups.iter().map(Group::size).max().unwrap_or(0)
    }

    /// What the splits have cost so far.
    pub fn split_stats(&self) -> SplitStats {
        self.stats
    }

    /// Recomputes `group_of` from the groups.
    fn reindex(&mut self) {
        self.group_of = vec![0; self.n];
        for (g, group) in self.groups.iter().enumerate() {
            for &t in &group.tracks {
                self.group_of[t as usize] = g;
            }
        }
    }

    /// Replaces groups `old` (distinct indices) by `new`.
    fn replace(&mut self, mut old: Vec<usize>, new: Vec<Group>) {
        old.sort_unstable_by(|a, b| b.cmp(a));
        for g in old {
            self.groups.swap_remove(g);
            if let Some(moved) = self.groups.get(g) {
                for &t in &moved.tracks {
                    self.group_of[t as usize] = g;
                }
            }
        }
        for group in new {
            let g = self.groups.len();
            for &t in &group.tracks {
                self.group_of[t as usize] = g;
            }
            self.groups.push(group);
        }
    }

    /// The local index of track `t` in its group.
    fn local(&self, t: u32) -> Result<usize, BeliefError> {
        self.groups[self.group_of[t as usize]]
            .local_track(t)
            .ok_or_else(|| BeliefError::BadComponent {
                detail: format!("track {t} is not in the group that claims it"),
            })
    }

    /// The parts of group `g` holding local track `keep` that a join may
    /// take, one per size: (size, cost, the cut — none for the whole
    /// group, which costs nothing).
    fn options_for(&self, g: usize, keep: usize) -> Vec<(usize, f64, Option<Cut>)> {
        let group = &self.groups[g];
        let k = group.size();
        let cuts = split::best_cuts(group, keep);
        let mut out: Vec<(usize, f64, Option<Cut>)> = cuts
            .into_iter()
            .enumerate()
            .filter_map(|(s, c)| c.map(|c| (s, c.cost(), Some(c))))
            .collect();
        out.push((k, 0.0, None));
        out
    }

    /// Cuts every track of group `g` whose identity is (near) certain off
    /// into a group of its own, one at a time (each cut conditions the
    /// rest on the track's likeliest identity, losing 1 − p of the mass).
    fn cut_certain(&mut self, g: usize) {
        let mut rest = self.groups[g].clone();
        let mut pieces = Vec::new();
        while rest.size() >= 2 {
            let m = rest.local_marginals();
            // Rounding keeps a sure track's p a few ulps below 1.
            let threshold = 1.0 - self.options.certain - 1e-12;
            let found = m.iter().enumerate().find_map(|(j, row)| {
                let (x, &p) = row.iter().enumerate().max_by(|a, b| a.1.total_cmp(b.1))?;
                (p >= threshold).then_some((j, x, p))
            });
            let Some((j, x, p)) = found else { break };
            let cut = Cut {
                tracks: 1 << j,
                identities: 1 << x,
                mass: p,
                mutual_information: 0.0,
            };
            let Ok((single, remaining)) = split::apply(&rest, &cut) else {
                break;
            };
            self.record(&cut);
            pieces.push(single);
            rest = remaining;
        }
        if !pieces.is_empty() {
            pieces.push(rest);
            self.replace(vec![g], pieces);
        }
    }

    /// Counts a cut made and what it lost.
    fn record(&mut self, cut: &Cut) {
        self.stats.cuts += 1;
        if cut.cost() > 1e-12 {
            self.stats.lossy_cuts += 1;
        }
        self.stats.lost_mass += (1.0 - cut.mass).max(0.0);
        self.stats.lost_information += cut.mutual_information;
        self.stats.total_variation_bound +=
            (1.0 - cut.mass).max(0.0) + (cut.mutual_information.max(0.0) / 2.0).sqrt();
    }

    /// Mixes tracks of two groups, joining (parts of) them.
    fn mix_across(&mut self, a: u32, b: u32, swap: f64) -> Result<(), BeliefError> {
        let (ga, gb) = (self.group_of[a as usize], self.group_of[b as usize]);
        let (la, lb) = (self.local(a)?, self.local(b)?);
        let (ka, kb) = (self.groups[ga].size(), self.groups[gb].size());
        let cap = self.options.max_group;
        let (mut parts, mut rests) = (Vec::new(), Vec::new());
        let mut cuts = Vec::new();
        if ka + kb <= cap {
            parts.push(self.groups[ga].clone());
            parts.push(self.groups[gb].clone());
        } else {
            // The pair of parts with the least total loss that fits the
            // cap; on (near) ties the smaller join, which is cheaper and
            // keeps more of the rest exact.
            let (oa, ob) = (self.options_for(ga, la), self.options_for(gb, lb));
            let mut best: Option<(f64, usize, usize, usize)> = None;
            for (i, &(sa, ca, _)) in oa.iter().enumerate() {
                for (j, &(sb, cb, _)) in ob.iter().enumerate() {
                    if sa + sb > cap {
                        continue;
                    }
                    let cost = ca + cb;
                    let better = match best {
                        None => true,
                        Some((c, size, _, _)) => {
                            cost < c - 1e-12 || (cost <= c + 1e-12 && sa + sb < size)
                        }
                    };
                    if better {
                        best = Some((cost, sa + sb, i, j));
                    }
                }
            }
            // Sizes 1 and 1 always fit a cap of at least 2.
            let (_, _, i, j) = best.ok_or(BeliefError::BadComponent {
                detail: format!("no parts of {ka} and {kb} tracks fit a cap of {cap}"),
            })?;
            for (g, cut) in [(ga, oa[i].2), (gb, ob[j].2)] {
                match cut {
                    None => parts.push(self.groups[g].clone()),
                    Some(cut) => {
                        let (part, rest) = split::apply(&self.groups[g], &cut)?;
                        parts.push(part);
                        rests.push(rest);
                        cuts.push(cut);
                    }
                }
            }
        }
        let mut joined = parts[0].join(&parts[1])?;
        let (ja, jb) = (
            joined.local_track(a).unwrap_or(0),
            joined.local_track(b).unwrap_or(0),
        );
        joined.mix(ja, jb, swap);
        for cut in &cuts {
            self.record(cut);
        }
        rests.push(joined);
        self.replace(vec![ga, gb], rests);
        Ok(())
    }
}

impl IdentityFilter for FactoredIdentity {
    fn size(&self) -> usize {
        self.n
    }

    fn mix(&mut self, mix: Mix) -> Result<(), BeliefError> {
        check_mix(self.n, &mix)?;
        let (a, b, swap) = (mix.a, mix.b, mix.swap);
        if swap == 0.0 {
            return Ok(());
        }
        let (ga, gb) = (self.group_of[a as usize], self.group_of[b as usize]);
        if ga == gb {
            let (la, lb) = (self.local(a)?, self.local(b)?);
            self.groups[ga].mix(la, lb, swap);
            return Ok(());
        }
        if swap == 1.0 {
            // A sure swap: the two targets exchanged tracks, nothing mixed.
            let (la, lb) = (self.local(a)?, self.local(b)?);
            self.groups[ga].tracks[la] = b;
            self.groups[gb].tracks[lb] = a;
            self.group_of.swap(a as usize, b as usize);
            return Ok(());
        }
        self.mix_across(a, b, swap)
    }

    fn identify(&mut self, identify: Identify) -> Result<(), BeliefError> {
        check_identify(self.n, &identify)?;
        let g = self.group_of[identify.track as usize];
        let track = self.local(identify.track)?;
        let (right, wrong) = (identify.accuracy, identify.wrong_read_likelihood(self.n));
        let group = &mut self.groups[g];
        match group
            .identities
            .iter()
            .position(|&i| i == identify.identity)
        {
            Some(read) => {
                group.read(track, read, right, wrong)?;
                self.cut_certain(g);
                Ok(())
            }
            // Every assignment the belief allows puts another identity on
            // the track: the likelihood is `wrong` throughout.
            None if wrong > 0.0 => Ok(()),
            None => Err(BeliefError::ImpossibleObservation { probability: 0.0 }),
        }
    }

    fn marginals(&self) -> Result<Marginals, BeliefError> {
        let mut m = vec![vec![0.0; self.n]; self.n];
        for group in &self.groups {
            let local = group.local_marginals();
            for (j, row) in local.iter().enumerate() {
                let t = group.tracks[j] as usize;
                for (x, &p) in row.iter().enumerate() {
                    m[t][group.identities[x] as usize] = p;
                }
            }
        }
        Ok(m)
    }
}
