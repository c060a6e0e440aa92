//! # A factored identity belief: exact over small groups of tracks
//!
//! The belief over the N! assignments of identities to tracks is kept as a
//! product of independent groups ([`Group`]): each holds k tracks, the k
//! identities they carry between them, and the exact distribution over
//! the k! assignments — the exact filter of Shin et al., *Lazy Inference
//! on Object Identities in Wireless Sensor Networks* (IPSN 2005, Section
//! 2), on the blocks that mixing has connected since a known start (the
//! blocks of [`crate::blocks`]) instead of on all N tracks. It
//! mirrors the factored property belief ([`idmesh_belief::FactoredBelief`]): exact
//! components that join when their tracks mix and are split, by a
//! projection, when they would outgrow a cap.
//!
//! - A read multiplies the likelihood into the group of its track and
//!   renormalizes that group: exact. A read of an identity the group does
//!   not hold, nor a group linked to it, has the same likelihood under
//!   every assignment the belief allows and changes nothing.
//! - A mix of two tracks of one group is the exact mixing rule on that
//!   group; a mix across groups joins them (their product) and then mixes;
//!   a sure swap (probability 1) only exchanges the two tracks' places,
//!   and a mix of probability 0 does nothing.
//! - When the join would hold more than [`FactoredIdentityOptions::max_group`]
//!   slots, each of the two groups first gives up the part the mix needs
//!   ([`split`]): among the cuts (tracks A holding the mixed track,
//!   identities I_A) of largest P(π(A) = I_A) for each size, the one of
//!   least loss — the split step of Huang, Guestrin and Guibas's
//!   split/join filters. A *hard* cut conditions on E = {π(A) = I_A} and
//!   loses (1 − P(E)) + I(A; B | E). A *linked* cut ([`links`],
//!   `linked`, the default) keeps the assignments that send one identity
//!   across: each side gets a port (one more slot) and the two sides agree
//!   on whether something crossed — riffled independence (Huang and
//!   Guestrin, *Riffled Independence for Ranked Data*, NIPS 2009, Section
//!   3) restricted to interleavings one exchange from the cut; it loses
//!   the mass of two or more exchanges and I(A; B | e). The join picks,
//!   among the whole groups, hard and linked parts that fit the cap, the
//!   pair of least loss. A cut of a track whose identity is certain is
//!   exact.
//!
//! Without splits (every group of mixed tracks within the cap) the belief
//! equals the exact filter; marginals cost O(support·k) per group (its
//! assignments of non-zero probability, at most k!) plus belief
//! propagation over the trees of linked groups (2-vector messages). A
//! group's table is stored sparsely unless most of its assignments are
//! possible ([`assignments`]), so memory grows with the tracks and the
//! mixes, not with k! per group. The belief is plain data (serde), pure,
//! synchronous and deterministic.
//!
//! ## What cuts lose
//! A cut conditions on the event it keeps, and a dropped link on nothing
//! having crossed: the assignments they rule out are gone from the
//! tables, and on long streams the truth is often among them (random
//! waypoint, 100 tracks, cap 8: the true identity at probability 0 on 7%
//! of a truth line's tracks), which made the belief over-confident. So
//! every track keeps a *leak* λ_t, the probability that its identity lies
//! outside its group's table, and its marginals are (1 − λ_t)·table +
//! λ_t·background, the background one independent row per track
//! ([`background`]):
//! - a cut adds to each of its tracks the probability, under the table
//!   it cuts, that the track carried an identity of the other side (for a
//!   linked cut, the share of that which two or more exchanges make); a
//!   dropped link, that a track carried its star;
//! - a mix mixes the two tracks' rows and leaks as the kernel moves their
//!   targets ((1 − s)·a + s·b, after the cuts the join made);
//! - a read applies Bayes' rule to the row, and to λ_t by how likely the
//!   read was under the table (through the links) and under the row.
//!
//! Nothing lost, every λ is 0 and the belief is the tables'
//! ([`FactoredIdentity::table_marginals`], doubly stochastic); with a
//! leak, rows still sum to one but columns only nearly.
//!
//! Measured by examples/identity_factored.rs in idmesh-eval (the tables
//! in docs/identity-results.md): without leaks the belief was
//! over-confident on every large trace, and its log-loss two to three
//! times the information matrix's. At n ≤ 9 and the default cap nothing
//! is cut and the belief is exact.

mod answer;
mod assignments;
mod background;
mod group;
mod links;
mod repair;
mod share;
mod split;

#[cfg(test)]
mod tests;

pub use background::Background;
pub use group::{Group, MAX_GROUP};
pub use share::{assemble, HeldTree, IdentityShare};
pub use split::Cut;

use super::event::{check_assignment, check_identify, check_mix, Identify, IdentityEvent};
use super::filter::{IdentityFilter, Marginals};
use super::sparse_marginals::SparseMarginals;
use idmesh_belief::BeliefError;
use idmesh_belief::Mix;

/// The default cap on a group's slots (tracks and ports): the largest
/// group we enumerate. Measured on random-waypoint traces
/// (examples/identity_factored.rs in idmesh-eval; docs/identity-results.md):
/// a cap below n leaves lossy cuts, and even linked ones leave errors of
/// up to 1.0 at n = 9, while a cap of n is exact; a mix in a full, dense
/// group of 9 costs about 9!·9 steps (about 1.5 ms), in a sparse one
/// about its support times a rank and a sort.
pub const DEFAULT_MAX_GROUP: usize = MAX_GROUP;

/// The default of [`FactoredIdentityOptions::certain`].
pub(crate) const DEFAULT_CERTAIN: f64 = 1e-4;

/// Options of a factored identity belief.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct FactoredIdentityOptions {
    /// The most slots one group may hold — its tracks and its ports (one
    /// per link) — 2 ..= [`MAX_GROUP`]: the size of its table.
    pub max_group: usize,
    /// After a read, a track of its group whose identity has probability
    /// at least 1 − `certain` is cut off into a group of its own (losing
    /// at most `certain` of the mass), so that groups shrink as reads come
    /// in and later joins need no lossy cut. 0 = only sure tracks. A link
    /// (see `linked`) whose exchange probability falls to `certain` or
    /// below is dropped the same way.
    pub certain: f64,
    /// Lossy cuts keep a link between the two sides (one port, i.e. one
    /// more slot of the cap, on each) so that the assignments one exchange
    /// away from the cut stay possible and later reads can move mass back
    /// ([`links`]); false = hard cuts only (the split step alone).
    pub linked: bool,
}

impl Default for FactoredIdentityOptions {
    fn default() -> Self {
        FactoredIdentityOptions {
            max_group: DEFAULT_MAX_GROUP,
            certain: DEFAULT_CERTAIN,
            linked: true,
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
pub(crate) struct SplitStats {
    /// Cuts made.
    pub cuts: u64,
    /// Cuts that lost something (cost above 1e-12).
    pub lossy_cuts: u64,
    /// Lossy cuts that kept a link.
    pub linked_cuts: u64,
    /// Links dropped (conditioned on nothing having crossed).
    pub dropped_links: u64,
    /// Σ (1 − P(E)) over the cuts (a linked cut: the mass of two or more
    /// exchanges), plus P(e = 1) of every dropped link.
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

/// A product of exact groups, independent or linked in trees.
#[derive(Debug, Clone, serde::Serialize, serde::Deserialize)]
#[serde(try_from = "Stored")]
pub struct FactoredIdentity {
    n: usize,
    options: FactoredIdentityOptions,
    groups: Vec<Group>,
    stats: SplitStats,
    /// Each track's leak and background row ([`background`]).
    backgrounds: Vec<Background>,
    /// group_of[t] = index in `groups` of the group of track t, ports
    /// (ids ≥ n) included; `usize::MAX` for a free port id (derived).
    #[serde(skip)]
    group_of: Vec<usize>,
    /// holder[i] = index in `groups` of the group holding identity i < n
    /// (derived).
    #[serde(skip)]
    holder: Vec<usize>,
    /// link_used[l]: ports n + 2l and n + 2l + 1 are in use (derived).
    #[serde(skip)]
    link_used: Vec<bool>,
    /// Valid events the tables could not take as they stood ([`repair`]):
    /// a count of this process's, not part of the belief.
    #[serde(skip)]
    repairs: u64,
}

impl PartialEq for FactoredIdentity {
    /// The stored state; the derived indices are a function of it.
    fn eq(&self, other: &Self) -> bool {
        (
            self.n,
            self.options,
            &self.groups,
            self.stats,
            &self.backgrounds,
        ) == (
            other.n,
            other.options,
            &other.groups,
            other.stats,
            &other.backgrounds,
        )
    }
}

/// The serialized form, checked on the way in.
#[derive(serde::Deserialize)]
struct Stored {
    n: usize,
    options: FactoredIdentityOptions,
    groups: Vec<Group>,
    stats: SplitStats,
    backgrounds: Vec<Background>,
}

impl TryFrom<Stored> for FactoredIdentity {
    type Error = BeliefError;

    fn try_from(s: Stored) -> Result<Self, BeliefError> {
        s.options.validate()?;
        let bad = |detail: String| BeliefError::BadComponent { detail };
        let mut track_seen = vec![false; s.n];
        let mut identity_seen = vec![false; s.n];
        let mut ports = std::collections::BTreeSet::new();
        let slots: usize = s.groups.iter().map(Group::size).sum();
        for (gi, g) in s.groups.iter().enumerate() {
            g.check()?;
            for port in g.ports(s.n) {
                if port.star == usize::MAX || !ports.insert((port.id, gi)) {
                    return Err(bad(format!("port {} without its star", port.id)));
                }
            }
            if g.identities
                .iter()
                .any(|&i| i as usize >= s.n && g.local_track(i).is_none())
            {
                return Err(bad("a star without its phantom track".into()));
            }
        }
        let groups_of: std::collections::BTreeMap<u32, usize> = ports.iter().copied().collect();
        if groups_of.len() != ports.len() {
            return Err(bad("a port in two groups".into()));
        }
        for (&id, &gi) in &groups_of {
            let partner = (s.n + ((id as usize - s.n) ^ 1)) as u32;
            if groups_of.get(&partner).is_none_or(|&h| h == gi) {
                return Err(bad(format!(
                    "port {id} without its partner in another group"
                )));
            }
        }
        for g in &s.groups {
            g.check()?;
            if g.size() > s.options.max_group {
                return Err(bad(format!(
                    "a group of {} tracks above the cap of {}",
                    g.size(),
                    s.options.max_group
                )));
            }
            for (list, what) in [(&g.tracks, "track"), (&g.identities, "identity")] {
                for &x in list {
                    if x as usize >= s.n {
                        // A port: ids beyond n + 2 per slot of the groups
                        // are out of range.
                        if x as usize >= s.n + 2 * slots {
                            return Err(bad(format!("{what} {x} of {} out of range", s.n)));
                        }
                        continue;
                    }
                    let seen = if what == "track" {
                        &mut track_seen
                    } else {
                        &mut identity_seen
                    };
                    if seen[x as usize] {
                        return Err(bad(format!("{what} {x} in two groups")));
                    }
                    seen[x as usize] = true;
                }
            }
        }
        if s.n == 0 || track_seen.iter().chain(&identity_seen).any(|&x| !x) {
            return Err(bad(format!("groups that do not cover the {} tracks", s.n)));
        }
        if s.backgrounds.len() != s.n {
            return Err(bad(format!(
                "{} background rows for {} tracks",
                s.backgrounds.len(),
                s.n
            )));
        }
        let mut belief = FactoredIdentity {
            n: s.n,
            options: s.options,
            groups: s.groups,
            stats: s.stats,
            backgrounds: s.backgrounds,
            group_of: Vec::new(),
            holder: Vec::new(),
            link_used: Vec::new(),
            repairs: 0,
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
        let backgrounds = assignment.iter().map(|&i| Background::certain(i)).collect();
        Ok(Self::new(n, options, groups, backgrounds))
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
        let backgrounds = vec![Background::uniform(n); n];
        Ok(Self::new(n, options, vec![group], backgrounds))
    }

    fn new(
        n: usize,
        options: FactoredIdentityOptions,
        groups: Vec<Group>,
        backgrounds: Vec<Background>,
    ) -> Self {
        let mut belief = FactoredIdentity {
            n,
            options,
            groups,
            stats: SplitStats::default(),
            backgrounds,
            group_of: Vec::new(),
            holder: Vec::new(),
            link_used: Vec::new(),
            repairs: 0,
        };
        belief.reindex();
        belief
    }

    /// Identities listed in the background rows (each row stores only
    /// those that differ from its shared probability): with the tables,
    /// what the belief's memory grows with.
    pub(crate) fn background_entries(&self) -> usize {
        self.backgrounds.iter().map(Background::listed).sum()
    }

    /// An estimate of the bytes the belief holds on the heap: every
    /// group's table as stored (by capacity: 8 bytes an assignment when
    /// dense, 12 an entry when sparse) and its labels (4 bytes a track and
    /// an identity), the groups' own slots, the background rows (8 bytes a
    /// row for its leak and shared probability, 12 an identity listed) and
    /// the derived indices. Allocator overhead and the rows' tree nodes are
    /// left out: a figure to compare representations and sizes with, not
    /// the process's resident memory.
    pub fn memory_bytes(&self) -> usize {
        let groups: usize = self.groups.iter().map(Group::heap_bytes).sum::<usize>()
            + self.groups.capacity() * std::mem::size_of::<Group>();
        let backgrounds = 8 * self.backgrounds.len() + 12 * self.background_entries();
        let indices = std::mem::size_of::<usize>() * (self.group_of.len() + self.holder.len())
            + self.link_used.len();
        groups + backgrounds + indices
    }

    /// The groups, in no particular order. Tracks and identities with ids
    /// ≥ n are ports ([`links`]): a link's two ports are n + 2l and
    /// n + 2l + 1.
    #[cfg(test)]
    pub(crate) fn groups(&self) -> &[Group] {
        &self.groups
    }

    /// The most tracks in one group, ports included.
    #[cfg(test)]
    pub(crate) fn largest_group(&self) -> usize {
        self.groups.iter().map(Group::size).max().unwrap_or(0)
    }

    /// What the splits have cost so far.
    #[cfg(test)]
    pub(crate) fn split_stats(&self) -> SplitStats {
        self.stats
    }

    /// Recomputes `group_of` from the groups.
    fn reindex(&mut self) {
        let top = self
            .groups
            .iter()
            .flat_map(|g| g.tracks.iter())
            .map(|&t| t as usize + 1)
            .max()
            .unwrap_or(0)
            .max(self.n);
        let links = (top - self.n).div_ceil(2);
        self.group_of = vec![usize::MAX; self.n + 2 * links];
        self.holder = vec![0; self.n];
        self.link_used = vec![false; links];
        for (g, group) in self.groups.iter().enumerate() {
            for &t in &group.tracks {
                self.group_of[t as usize] = g;
                if t as usize >= self.n {
                    self.link_used[(t as usize - self.n) / 2] = true;
                }
            }
            for &i in &group.identities {
                if (i as usize) < self.n {
                    self.holder[i as usize] = g;
                }
            }
        }
    }

    /// Points the indices at group g's tracks and identities.
    fn point_at(&mut self, g: usize) {
        let group = &self.groups[g];
        for &t in &group.tracks {
            self.group_of[t as usize] = g;
        }
        for &i in &group.identities {
            if (i as usize) < self.n {
                self.holder[i as usize] = g;
            }
        }
    }

    /// Replaces groups `old` (distinct indices) by `new`.
    fn replace(&mut self, mut old: Vec<usize>, new: Vec<Group>) {
        old.sort_unstable_by(|a, b| b.cmp(a));
        for g in old {
            self.groups.swap_remove(g);
            if g < self.groups.len() {
                self.point_at(g);
            }
        }
        for group in new {
            self.groups.push(group);
            self.point_at(self.groups.len() - 1);
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
    /// take: (slots in the cap, cost, what to do) — the whole group costs
    /// nothing; a hard cut costs (1 − P(E)) + I; a linked cut takes one
    /// more slot and costs what it cannot keep.
    fn options_for(&self, g: usize, keep: usize, must: Option<u32>) -> Vec<(usize, f64, Part)> {
        let group = &self.groups[g];
        let k = group.size();
        let ports = group.ports(self.n);
        let mut out = vec![(k, 0.0, Part::Whole)];
        let must = must
            .and_then(|p| group.local_track(p))
            .map_or(0, |j| 1u32 << j);
        // The cuts are found on the group's own table, but the group sits
        // in a tree: where the rest of the tree rules a flag value out (a
        // message with a zero), a cut may keep only assignments the tree
        // gives no mass, and the belief would be left without any.
        let messages = match ports.is_empty() {
            true => Vec::new(),
            false => links::Messages::new(self).toward_group(g).1,
        };
        let tree_rules_out = messages.iter().any(|m| m[0] <= 0.0 || m[1] <= 0.0);
        let keeps_mass = |cut: &Cut, exchanges: u32| {
            !tree_rules_out || group.kept_tree_mass(&ports, &messages, cut, exchanges) > 0.0
        };
        for cut in split::best_cuts(group, keep, must, &ports)
            .into_iter()
            .flatten()
        {
            if keeps_mass(&cut, 0) {
                out.push((cut.size(), cut.cost(), Part::Hard(cut)));
            }
            if self.options.linked && cut.cost() > self.options.certain && keeps_mass(&cut, 1) {
                let placeholder = (self.n + 2 * self.link_used.len()) as u32;
                if let Ok(linked) =
                    split::apply_linked(group, &cut, &ports, placeholder, placeholder + 1)
                {
                    out.push((cut.size() + 1, linked.cost(), Part::Linked(cut)));
                }
            }
        }
        out
    }

    /// Cuts every real track of group `g` whose identity is (near) certain
    /// off into a group of its own, one at a time (each cut conditions the
    /// rest on the track's likeliest identity, losing 1 − p of the mass).
    fn cut_certain(&mut self, g: usize) -> Result<(), BeliefError> {
        let (ports, messages) = links::Messages::new(self).toward_group(g);
        let by_id: std::collections::HashMap<u32, [f64; 2]> =
            ports.iter().map(|p| p.id).zip(messages).collect();
        let mut rest = self.groups[g].clone();
        let mut pieces = Vec::new();
        while rest.real_size(self.n) >= 2 {
            let ports = rest.ports(self.n);
            let messages: Vec<[f64; 2]> = ports.iter().map(|p| by_id[&p.id]).collect();
            let Some(m) = rest.weighted_marginals(&ports, &messages) else {
                break;
            };
            // Rounding keeps a sure track's p a few ulps below 1.
            let threshold = 1.0 - self.options.certain - 1e-12;
            let n = self.n as u32;
            let found = m.iter().enumerate().find_map(|(j, row)| {
                if rest.tracks[j] >= n {
                    return None;
                }
                let (x, &p) = row
                    .iter()
                    .enumerate()
                    .filter(|&(x, _)| rest.identities[x] < n)
                    .max_by(|a, b| a.1.total_cmp(b.1))?;
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
            self.leak_cut(&rest, &cut, 1.0);
            self.record(&cut);
            pieces.push(single);
            rest = remaining;
        }
        if !pieces.is_empty() {
            pieces.push(rest);
            self.replace(vec![g], pieces);
        }
        Ok(())
    }

    /// The table's probability (links included, the leak left out) that
    /// track `t` carries identity `i`: one entry of [`Self::table_marginals`].
    fn table_probability(&self, t: u32, i: u32) -> Result<f64, BeliefError> {
        let g = self.group_of[t as usize];
        let j = self.local(t)?;
        let mut bp = links::Messages::new(self);
        let local = bp.group_marginals(g)?;
        // The groups across g's links, whose phantoms say what a star is.
        let mut far = std::collections::BTreeMap::new();
        for port in self.groups[g].ports(self.n) {
            let h = self.group_of[self.partner(port.id) as usize];
            if let std::collections::btree_map::Entry::Vacant(entry) = far.entry(h) {
                entry.insert(bp.group_marginals(h)?);
            }
        }
        let mut p = 0.0;
        self.spread_row(
            &self.groups[g],
            &local[j],
            |h| far.get(&h).map(Vec::as_slice),
            |id, q| {
                if id == i as usize {
                    p += q;
                }
            },
        );
        Ok(p)
    }

    /// Hands `add` the mass of one track's row of local marginals of
    /// `group` on each identity: a real identity's directly, a star's
    /// spread over what the partner's phantom carries when something
    /// crossed (`far(h)`: group h's local marginals).
    fn spread_row<'a>(
        &self,
        group: &Group,
        row: &[f64],
        far: impl Fn(usize) -> Option<&'a [Vec<f64>]>,
        mut add: impl FnMut(usize, f64),
    ) {
        let n = self.n;
        for (x, &p) in row.iter().enumerate() {
            let i = group.identities[x] as usize;
            if i < n {
                add(i, p);
            } else if p > 0.0 {
                let q = self.partner(i as u32);
                let h = self.group_of[q as usize];
                let other = &self.groups[h];
                let (Some(jq), Some(xq), Some(local)) = (
                    other.local_track(q),
                    other.identities.iter().position(|&y| y == q),
                    far(h),
                ) else {
                    continue;
                };
                let row = &local[jq];
                let crossed = 1.0 - row[xq];
                if crossed <= 0.0 {
                    continue;
                }
                for (y, &r) in row.iter().enumerate() {
                    let id = other.identities[y] as usize;
                    if id < n {
                        add(id, p * r / crossed);
                    }
                }
            }
        }
    }

    /// After a read on track `t` whose likelihood under the table was
    /// `table` (None: t does not leak): the read on t's row and leak.
    fn after_read(&mut self, t: u32, read: &Identify, table: Option<f64>) {
        let wrong = read.wrong_read_likelihood(self.n);
        self.backgrounds[t as usize].read(self.n, read.identity, read.accuracy, wrong, table);
    }

    /// Before `cut` of `group` (a hard one, or the excluded part `share`
    /// of a linked one): each real track leaks the probability that it
    /// carries an identity of the other side, which the cut rules out.
    fn leak_cut(&mut self, group: &Group, cut: &Cut, share: f64) {
        if share <= 0.0 {
            return;
        }
        let m = group.local_marginals();
        for (j, row) in m.iter().enumerate() {
            let t = group.tracks[j] as usize;
            let Some(background) = self.backgrounds.get_mut(t) else {
                continue;
            };
            let inside = cut.tracks & (1 << j) != 0;
            let crossing: f64 = row
                .iter()
                .enumerate()
                .filter(|&(x, _)| (cut.identities & (1 << x) != 0) != inside)
                .map(|(_, &p)| p)
                .sum();
            background.lose(share * crossing);
        }
    }

    /// Counts a cut made and what it lost.
    fn record(&mut self, cut: &Cut) {
        self.stats.cuts += 1;
        if cut.cost() > 1e-12 {
            self.stats.lossy_cuts += 1;
        }
        self.add_loss(1.0 - cut.mass, cut.mutual_information);
    }

    /// Adds a lost mass and a lost information to the running totals.
    pub(crate) fn add_loss(&mut self, mass: f64, information: f64) {
        let (mass, information) = (mass.max(0.0), information.max(0.0));
        self.stats.lost_mass += mass;
        self.stats.lost_information += information;
        self.stats.total_variation_bound += mass + (information / 2.0).sqrt();
    }

    /// After a change to the group of `track`: its links too unlikely to
    /// matter are dropped and its certain tracks cut off.
    fn settle(&mut self, track: u32) -> Result<(), BeliefError> {
        self.prune_links(track)?;
        let g = self.group_of[track as usize];
        self.cut_certain(g)
    }

    /// Mixes tracks of two groups, joining (parts of) them.
    fn mix_across(&mut self, a: u32, b: u32, swap: f64) -> Result<(), BeliefError> {
        let (ga, gb) = (self.group_of[a as usize], self.group_of[b as usize]);
        let (la, lb) = (self.local(a)?, self.local(b)?);
        let (ka, kb) = (self.groups[ga].size(), self.groups[gb].size());
        let cap = self.options.max_group;
        let too_big = self.groups[ga].size() + self.groups[gb].size() > MAX_GROUP;
        // Groups of one tree of links: the parts keep the ends of the path
        // between them, so that a direct link collapses on the join.
        let path = self.path(ga, gb);
        let ends = path
            .as_ref()
            .and_then(|p| Some((*p.first()?, self.partner(*p.last()?))));
        let collapses = path.as_ref().is_some_and(|p| p.len() == 1);
        let freed = if collapses { 2 } else { 0 };
        if ka + kb > cap + freed || too_big {
            // The pair of parts with the least total loss that fits the
            // cap; on (near) ties the smaller join, which is cheaper and
            // keeps more of the rest exact.
            let choose = |oa: &[(usize, f64, Part)], ob: &[(usize, f64, Part)], room: usize| {
                let mut best: Option<(f64, usize, usize, usize)> = None;
                for (i, &(sa, ca, pa)) in oa.iter().enumerate() {
                    for (j, &(sb, cb, pb)) in ob.iter().enumerate() {
                        if sa + sb > room || !self.fits(&pa, ga, &pb, gb) {
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
                best.map(|(_, _, i, j)| (oa[i].2, ob[j].2))
            };
            let kept_ends = choose(
                &self.options_for(ga, la, ends.map(|e| e.0)),
                &self.options_for(gb, lb, ends.map(|e| e.1)),
                cap + freed,
            );
            // Without room for the path's ends the parts are cut freely
            // (the cycle is then broken below). Sizes 1 and 1 always fit a
            // cap of at least 2.
            let (pa, pb) = match kept_ends {
                Some(parts) => parts,
                None => choose(
                    &self.options_for(ga, la, None),
                    &self.options_for(gb, lb, None),
                    cap,
                )
                .ok_or(BeliefError::BadComponent {
                    detail: format!("no parts of {ka} and {kb} tracks fit a cap of {cap}"),
                })?,
            };
            self.cut_to_parts([(ga, pa), (gb, pb)])?;
        }
        self.break_cycle_between(a, b)?;
        let (ga, gb) = (self.group_of[a as usize], self.group_of[b as usize]);
        let joined = self.groups[ga].join(&self.groups[gb])?;
        let (mut joined, freed) = Self::collapse(&joined, self.n)?;
        self.release(freed);
        let (ja, jb) = (
            joined.local_track(a).unwrap_or(0),
            joined.local_track(b).unwrap_or(0),
        );
        joined.mix(ja, jb, swap);
        self.replace(vec![ga, gb], vec![joined]);
        Ok(())
    }

    /// Cuts each of two groups to its chosen part (a whole group is left
    /// as it is), and drops the links a rest of ports alone pins.
    fn cut_to_parts(&mut self, parts: [(usize, Part); 2]) -> Result<(), BeliefError> {
        let mut old = Vec::new();
        let mut new = Vec::new();
        for (g, part) in parts {
            match part {
                Part::Whole => {}
                Part::Hard(cut) => {
                    let group = self.groups[g].clone();
                    self.leak_cut(&group, &cut, 1.0);
                    let (part, rest) = split::apply(&group, &cut)?;
                    self.record(&cut);
                    old.push(g);
                    new.extend([part, rest]);
                }
                Part::Linked(cut) => {
                    let (pa, pb) = self.new_link();
                    let ports = self.groups[g].ports(self.n);
                    let group = self.groups[g].clone();
                    let linked = split::apply_linked(&group, &cut, &ports, pa, pb)?;
                    // It keeps the assignments with at most one
                    // exchange: of those with any (1 − P(E)), it loses
                    // the ones with two or more.
                    let any = 1.0 - cut.mass;
                    if any > 0.0 {
                        self.leak_cut(&group, &cut, ((1.0 - linked.mass) / any).min(1.0));
                    }
                    self.stats.cuts += 1;
                    self.stats.lossy_cuts += 1;
                    self.stats.linked_cuts += 1;
                    self.add_loss(1.0 - linked.mass, linked.mutual_information);
                    old.push(g);
                    new.extend([linked.a, linked.b]);
                }
            }
        }
        // A rest holding ports alone pins their links to "nothing
        // crossed": they are dropped, exactly.
        let orphans: Vec<u32> = new
            .iter()
            .filter(|g| g.real_size(self.n) == 0)
            .flat_map(|g| g.ports(self.n))
            .map(|p| p.id)
            .collect();
        self.replace(old, new);
        for p in orphans {
            if self.group_of[p as usize] != usize::MAX {
                let e = self.exchange(p)?;
                self.drop_link(p, e)?;
            }
        }
        Ok(())
    }

    /// Before tracks `a` and `b` are joined: if their groups are linked
    /// through others, the join would close a cycle of links.
    fn break_cycle_between(&mut self, a: u32, b: u32) -> Result<(), BeliefError> {
        let (ga, gb) = (self.group_of[a as usize], self.group_of[b as usize]);
        if let Some(path) = self.path(ga, gb) {
            if path.len() > 1 {
                // Joining would close a cycle of links: the least likely
                // exchange on the path is ruled out first.
                let mut weakest: Option<(f64, u32)> = None;
                for &p in &path {
                    let e = self.exchange(p)?;
                    if weakest.is_none_or(|(w, _)| e < w) {
                        weakest = Some((e, p));
                    }
                }
                if let Some((e, p)) = weakest {
                    self.drop_link(p, e)?;
                }
            }
        }
        Ok(())
    }
}

impl FactoredIdentity {
    /// Frees the links collapsed on a join (named by their lower port).
    fn release(&mut self, freed: Vec<u32>) {
        for id in freed {
            self.link_used[(id as usize - self.n) / 2] = false;
            self.group_of[id as usize] = usize::MAX;
            self.group_of[id as usize + 1] = usize::MAX;
        }
    }

    /// Whether the join of two parts stays within the largest table (the
    /// product is built before its links collapse).
    fn fits(&self, a: &Part, ga: usize, b: &Part, gb: usize) -> bool {
        let size = |p: &Part, g: usize| match p {
            Part::Whole => self.groups[g].size(),
            Part::Hard(c) => c.size(),
            Part::Linked(c) => c.size() + 1,
        };
        size(a, ga) + size(b, gb) <= MAX_GROUP
    }
}

/// What a join takes of a group.
#[derive(Debug, Clone, Copy)]
enum Part {
    Whole,
    Hard(Cut),
    Linked(Cut),
}

impl IdentityFilter for FactoredIdentity {
    fn size(&self) -> usize {
        self.n
    }

    fn mix(&mut self, mix: Mix) -> Result<(), BeliefError> {
        check_mix(self.n, &mix)?;
        self.guarded(IdentityEvent::Mix(mix), &[mix.a, mix.b], |belief| {
            belief.mix_tables(mix)
        })
    }

    fn identify(&mut self, identify: Identify) -> Result<(), BeliefError> {
        check_identify(self.n, &identify)?;
        self.guarded(
            IdentityEvent::Identify(identify),
            &[identify.track],
            |belief| belief.identify_tables(identify),
        )
    }

    /// The tables' marginals mixed with each track's leak: track t
    /// carries identity i with (1 − λ_t)·table + λ_t·background. Rows sum
    /// to one; a column sums to one when nothing leaked (what cuts lost is
    /// spread by rows that ignore exclusivity).
    fn marginals(&self) -> Result<Marginals, BeliefError> {
        // One path for both forms, so that they agree to the last bit.
        Ok(FactoredIdentity::sparse_marginals(self)?.dense())
    }

    fn sparse_marginals(&self) -> Result<SparseMarginals, BeliefError> {
        FactoredIdentity::sparse_marginals(self)
    }
}

impl FactoredIdentity {
    /// A checked mix on the tables and rows, unguarded (see [`repair`]).
    fn mix_tables(&mut self, mix: Mix) -> Result<(), BeliefError> {
        let (a, b, swap) = (mix.a, mix.b, mix.swap);
        if swap == 0.0 {
            return Ok(());
        }
        let (ga, gb) = (self.group_of[a as usize], self.group_of[b as usize]);
        if ga == gb {
            let (la, lb) = (self.local(a)?, self.local(b)?);
            self.groups[ga].mix(la, lb, swap);
        } else if swap == 1.0 {
            // A sure swap: the two targets exchanged tracks, nothing mixed.
            let (la, lb) = (self.local(a)?, self.local(b)?);
            self.groups[ga].tracks[la] = b;
            self.groups[gb].tracks[lb] = a;
            self.group_of.swap(a as usize, b as usize);
        } else {
            self.mix_across(a, b, swap)?;
        }
        // After the cuts the join made (what they leaked is the targets'
        // before they mix).
        let (row_a, row_b) = self.rows_of(a, b);
        Background::mix(row_a, row_b, swap);
        Ok(())
    }

    /// The background rows of two distinct tracks (a checked mix's).
    fn rows_of(&mut self, a: u32, b: u32) -> (&mut Background, &mut Background) {
        let (low, high) = (a.min(b) as usize, a.max(b) as usize);
        let (left, right) = self.backgrounds.split_at_mut(high);
        (&mut left[low], &mut right[0])
    }

    /// A checked read on the tables and rows, unguarded (see [`repair`]).
    fn identify_tables(&mut self, identify: Identify) -> Result<(), BeliefError> {
        let t = identify.track;
        let g = self.group_of[t as usize];
        let track = self.local(t)?;
        let (right, wrong) = (identify.accuracy, identify.wrong_read_likelihood(self.n));
        // The read's likelihood under the table, which weighs a leak
        // against the row (a belief propagation over t's tree: only for a
        // track that leaks).
        let evidence = if self.backgrounds[t as usize].leak() > 0.0 {
            let m = self.table_probability(t, identify.identity)?;
            Some(right * m + wrong * (1.0 - m))
        } else {
            None
        };
        let group = &mut self.groups[g];
        if let Some(read) = group
            .identities
            .iter()
            .position(|&i| i == identify.identity)
        {
            group.read(track, read, right, wrong)?;
            self.after_read(t, &identify, evidence);
            return self.settle(t);
        }
        // An identity of a linked group: the track may carry it through the
        // link's star.
        let h = self.holder[identify.identity as usize];
        let link = self.groups[g]
            .ports(self.n)
            .into_iter()
            .find(|p| self.group_of[self.partner(p.id) as usize] == h);
        if let Some(port) = link {
            // Room to re-join the two sides: the link collapses, exactly,
            // and the read applies to the joined group.
            let (kg, kh) = (self.groups[g].size(), self.groups[h].size());
            if kg + kh <= MAX_GROUP && kg + kh - 2 <= self.options.max_group {
                let joined = self.groups[g].join(&self.groups[h])?;
                let (mut joined, freed) = Self::collapse(&joined, self.n)?;
                let (Some(j), Some(x)) = (
                    joined.local_track(t),
                    joined
                        .identities
                        .iter()
                        .position(|&i| i == identify.identity),
                ) else {
                    return Err(BeliefError::BadComponent {
                        detail: format!(
                            "track {t} or identity {} lost on a join",
                            identify.identity
                        ),
                    });
                };
                joined.read(j, x, right, wrong)?;
                self.release(freed);
                self.replace(vec![g, h], vec![joined]);
                self.after_read(t, &identify, evidence);
                return self.settle(t);
            }
            let real = self.groups[h]
                .tracks
                .iter()
                .find(|&&x| (x as usize) < self.n);
            let other = real.copied().unwrap_or(t);
            self.read_across(g, track, port.id, identify.identity, right, wrong)?;
            self.after_read(t, &identify, evidence);
            self.settle(t)?;
            return self.settle(other);
        }
        // Every assignment the table allows puts another identity on the
        // track: the likelihood is `wrong` throughout, and only the leak
        // can explain the read better.
        if wrong > 0.0 {
            self.after_read(t, &identify, evidence);
            Ok(())
        } else {
            Err(BeliefError::ImpossibleObservation { probability: 0.0 })
        }
    }
}
