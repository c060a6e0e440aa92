//! A leader's part of a factored identity belief, and the whole put back
//! together from the parts at a query.
//!
//! Nothing an identity event does reads beyond the linked tree of groups
//! of the tracks it touches ([`crate::factored`]): a read acts on
//! its track's group and the groups linked to it, a mix on the trees of its
//! two tracks, and the leak and row of a track go with its group. So whole
//! trees can be held by different leaders, each applying the events of the
//! trees it holds exactly as the centralized belief does, provided a mix
//! finds both trees in one place ([`IdentityShare::take`] and
//! [`IdentityShare::put`] move them). At a query the coordinator puts the
//! trees of every leader together ([`assemble`]) and computes the
//! marginals the centralized belief would.
//!
//! A share is a whole [`FactoredIdentity`] whose groups not held here are
//! placeholders: singletons pairing the tracks and identities of the trees
//! held elsewhere, never read (no held tree links to them), replaced when
//! a tree arrives. Link ports are numbered per share; a tree that arrives
//! is renumbered into free slots, which changes no number (ports are only
//! names of separators).

use super::{Background, FactoredIdentity, FactoredIdentityOptions, Group, SplitStats, Stored};
use crate::event::IdentityEvent;
use crate::filter::IdentityFilter;
use idmesh_belief::BeliefError;
use serde::{Deserialize, Serialize};
use std::collections::{BTreeMap, BTreeSet};

/// One linked tree of groups as it moves between leaders, with the leak
/// and row of each of its real tracks.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct HeldTree {
    pub groups: Vec<Group>,
    pub backgrounds: Vec<(u32, Background)>,
}

impl HeldTree {
    /// Its real tracks (below n), in order.
    pub fn tracks(&self, n: usize) -> BTreeSet<u32> {
        self.groups
            .iter()
            .flat_map(|g| g.tracks.iter().copied())
            .filter(|&t| (t as usize) < n)
            .collect()
    }

    /// Its real identities (below n), in order.
    fn identities(&self, n: usize) -> BTreeSet<u32> {
        self.groups
            .iter()
            .flat_map(|g| g.identities.iter().copied())
            .filter(|&i| (i as usize) < n)
            .collect()
    }
}

/// The trees of a factored identity belief one leader holds.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct IdentityShare {
    belief: FactoredIdentity,
    held: Vec<bool>,
}

impl IdentityShare {
    /// The share of a known start (track t surely carries `initial[t]`)
    /// holding the tracks `held` says.
    pub fn start(
        initial: &[u32],
        options: FactoredIdentityOptions,
        held: impl Fn(u32) -> bool,
    ) -> Result<Self, BeliefError> {
        let belief = FactoredIdentity::from_assignment(initial, options)?;
        let held = (0..initial.len() as u32).map(held).collect();
        Ok(IdentityShare { belief, held })
    }

    /// Whether this share holds track `t`'s tree.
    pub fn holds(&self, t: u32) -> bool {
        self.held.get(t as usize).copied().unwrap_or(false)
    }

    /// Applies an event whose tracks this share holds (a mix's two trees
    /// gathered here first), as the centralized belief does.
    pub fn apply(&mut self, event: &IdentityEvent) -> Result<(), BeliefError> {
        let tracks = match event {
            IdentityEvent::Mix(m) => vec![m.a, m.b],
            IdentityEvent::Identify(r) => vec![r.track],
        };
        if let Some(&t) = tracks.iter().find(|&&t| !self.holds(t)) {
            return Err(BeliefError::BadComponent {
                detail: format!("an identity event on track {t}, whose tree is held elsewhere"),
            });
        }
        self.belief.apply(event)
    }

    /// Valid events the trees held here could not take as they stood
    /// ([`super::repair`]), since this share was built or read back.
    pub fn repairs(&self) -> u64 {
        self.belief.repairs()
    }

    /// The tracks whose trees this share holds, in order.
    pub fn held_tracks(&self) -> impl Iterator<Item = u32> + '_ {
        self.held
            .iter()
            .enumerate()
            .filter(|(_, h)| **h)
            .map(|(t, _)| t as u32)
    }

    /// The number of tracks (and identities) of the whole belief.
    pub fn tracks(&self) -> usize {
        self.belief.n
    }

    /// A sure swap of `mix.a` and `mix.b` (swap 1), held here apart or
    /// together: the two targets exchanged tracks and nothing mixed, so
    /// the holder of each tree relabels it where it is — the track it held
    /// is the other's now, with its leak and row — and holds the other
    /// track instead. What the centralized belief does at a sure swap of
    /// two groups, done by each holder on its own.
    pub fn relabel(&mut self, mix: idmesh_belief::Mix) -> Result<(), BeliefError> {
        let (a, b) = (mix.a, mix.b);
        if mix.swap != 1.0 {
            return Err(BeliefError::BadComponent {
                detail: format!("a relabel of tracks {a} and {b} with swap {}", mix.swap),
            });
        }
        let (ha, hb) = (self.holds(a), self.holds(b));
        if !(ha || hb) {
            return Err(BeliefError::BadComponent {
                detail: format!("a relabel of tracks {a} and {b}, neither held here"),
            });
        }
        self.belief.apply(&IdentityEvent::Mix(mix))?;
        self.held.swap(a as usize, b as usize);
        Ok(())
    }

    /// Track `t`, which no item has named yet, is held here from now on:
    /// its tree is its start, the certain singleton of `identity` (its
    /// initial identity, which no tree held anywhere carries), which takes
    /// the place of its placeholder.
    pub fn adopt(&mut self, t: u32, identity: u32) -> Result<(), BeliefError> {
        let n = self.belief.n;
        if t as usize >= n || identity as usize >= n {
            return Err(BeliefError::UnknownTrack {
                track: t.max(identity),
                tracks: n,
            });
        }
        if self.holds(t) {
            return Err(BeliefError::BadComponent {
                detail: format!("an adoption of track {t}, held here already"),
            });
        }
        let b = &self.belief;
        let (g, h) = (b.group_of[t as usize], b.holder[identity as usize]);
        let placeholder = |g: usize| {
            b.groups[g].size() == 1 && b.groups[g].tracks.iter().all(|&x| !self.holds(x))
        };
        if !(placeholder(g) && placeholder(h)) {
            return Err(BeliefError::BadComponent {
                detail: format!(
                    "an adoption of track {t} with identity {identity}, which a held tree carries"
                ),
            });
        }
        let mut new = vec![Group::certain(t, identity)];
        if g != h {
            // What the two placeholders paired besides, paired again.
            new.push(Group::certain(
                b.groups[h].tracks[0],
                b.groups[g].identities[0],
            ));
        }
        self.belief.backgrounds[t as usize] = Background::certain(identity);
        self.held[t as usize] = true;
        let mut old = vec![g];
        if g != h {
            old.push(h);
        }
        self.swap_groups(old, new);
        Ok(())
    }

    /// Track `t`'s start, kept here while no leader surveilled it, is no
    /// longer this share's (the track was adopted elsewhere): its
    /// singleton stays as a placeholder.
    pub fn drop_start(&mut self, t: u32) -> Result<(), BeliefError> {
        let b = &self.belief;
        let alone = self.holds(t) && b.groups[b.group_of[t as usize]].size() == 1;
        if !alone {
            return Err(BeliefError::BadComponent {
                detail: format!("track {t}'s start is not kept here alone"),
            });
        }
        self.held[t as usize] = false;
        Ok(())
    }

    /// The tracks held here that taking `tree` in would displace: its own
    /// tracks, or the tracks of the groups here that carry its
    /// identities. [`IdentityShare::put`] refuses a tree while any is
    /// left; a start kept for nobody, stale since its track was adopted
    /// elsewhere, can give way first ([`IdentityShare::drop_start`]).
    pub fn in_the_way(&self, tree: &HeldTree) -> Vec<u32> {
        let b = &self.belief;
        let n = b.n;
        let mut groups: BTreeSet<usize> = tree
            .tracks(n)
            .iter()
            .map(|&t| b.group_of[t as usize])
            .collect();
        groups.extend(tree.identities(n).iter().map(|&i| b.holder[i as usize]));
        let mut tracks: Vec<u32> = groups
            .into_iter()
            .flat_map(|g| b.groups[g].tracks.iter().copied())
            .filter(|&t| self.holds(t))
            .collect();
        tracks.sort_unstable();
        tracks.dedup();
        tracks
    }

    /// Gives up the trees of those of `tracks` held here, each once.
    pub fn take_of(&mut self, tracks: &[u32]) -> Result<Vec<HeldTree>, BeliefError> {
        let mut trees = Vec::new();
        for &t in tracks {
            if self.holds(t) {
                trees.push(self.take(t)?);
            }
        }
        Ok(trees)
    }

    /// The groups linked (directly or not) to the group of track `t`,
    /// by index, in the order a breadth-first walk meets them.
    fn tree_of(&self, t: u32) -> Vec<usize> {
        self.belief.trees_of(&[t])
    }

    /// The groups at `indices` as a tree, with their tracks' leaks and
    /// rows.
    fn tree_at(&self, indices: &[usize]) -> HeldTree {
        let mut tree = HeldTree {
            groups: indices
                .iter()
                .map(|&g| self.belief.groups[g].clone())
                .collect(),
            backgrounds: Vec::new(),
        };
        tree.backgrounds = tree
            .tracks(self.belief.n)
            .into_iter()
            .map(|t| (t, self.belief.backgrounds[t as usize].clone()))
            .collect();
        tree
    }

    /// Gives up the tree of track `t` (which must be held here): its
    /// groups and their tracks' leaks and rows, for [`IdentityShare::put`]
    /// elsewhere. Placeholders take its place.
    pub fn take(&mut self, t: u32) -> Result<HeldTree, BeliefError> {
        if !self.holds(t) {
            return Err(BeliefError::BadComponent {
                detail: format!("track {t}'s tree is not held here"),
            });
        }
        let n = self.belief.n;
        let indices = self.tree_of(t);
        let tree = self.tree_at(&indices);
        let tracks = tree.tracks(n);
        let identities = tree.identities(n);
        let placeholders = pair(&tracks, &identities);
        for &t in &tracks {
            self.held[t as usize] = false;
        }
        self.swap_groups(indices, placeholders);
        Ok(tree)
    }

    /// Takes a tree in: the placeholders of its tracks and identities give
    /// way (what else they paired is paired again), its ports are
    /// renumbered into free link slots, and its tracks are held here.
    pub fn put(&mut self, tree: HeldTree) -> Result<(), BeliefError> {
        let n = self.belief.n;
        let tracks = tree.tracks(n);
        let identities = tree.identities(n);
        if let Some(&t) = tracks.iter().find(|&&t| self.holds(t)) {
            return Err(BeliefError::BadComponent {
                detail: format!("a tree with track {t}, which is held here already"),
            });
        }
        let b = &self.belief;
        let mut displaced: BTreeSet<usize> = BTreeSet::new();
        for &t in &tracks {
            displaced.insert(b.group_of[t as usize]);
        }
        for &i in &identities {
            displaced.insert(b.holder[i as usize]);
        }
        let (mut left_tracks, mut left_identities) = (BTreeSet::new(), BTreeSet::new());
        for &g in &displaced {
            let group = &b.groups[g];
            if group.size() != 1 || group.tracks.iter().any(|&t| self.holds(t)) {
                return Err(BeliefError::BadComponent {
                    detail: "a tree that overlaps a tree held here".into(),
                });
            }
            left_tracks.extend(group.tracks.iter().filter(|t| !tracks.contains(t)));
            left_identities.extend(group.identities.iter().filter(|i| !identities.contains(i)));
        }
        let mut new = pair(&left_tracks, &left_identities);
        let kept = b
            .groups
            .iter()
            .enumerate()
            .filter(|(g, _)| !displaced.contains(g));
        let used = link_slots(kept.map(|(_, g)| g), n).collect();
        new.extend(renumber(tree.groups, n, &used));
        for (t, background) in tree.backgrounds {
            let slot =
                self.belief
                    .backgrounds
                    .get_mut(t as usize)
                    .ok_or(BeliefError::UnknownTrack {
                        track: t,
                        tracks: n,
                    })?;
            *slot = background;
        }
        for &t in &tracks {
            self.held[t as usize] = true;
        }
        self.swap_groups(displaced.into_iter().collect(), new);
        Ok(())
    }

    /// Groups `old` (by index) give way to `new`, and the indices are
    /// rebuilt (new ports may lie beyond the old link slots).
    fn swap_groups(&mut self, mut old: Vec<usize>, new: Vec<Group>) {
        old.sort_unstable_by(|a, b| b.cmp(a));
        for g in old {
            self.belief.groups.swap_remove(g);
        }
        self.belief.groups.extend(new);
        self.belief.reindex();
    }

    /// The table entries of the tree of track `t` (held here): what moving
    /// it would send (the assignments of non-zero probability: trees
    /// travel sparse), for a rule that moves the smaller of two trees.
    pub fn tree_entries(&self, t: u32) -> Result<usize, BeliefError> {
        if !self.holds(t) {
            return Err(BeliefError::BadComponent {
                detail: format!("track {t}'s tree is not held here"),
            });
        }
        Ok(self
            .tree_of(t)
            .iter()
            .map(|&g| self.belief.groups[g].support())
            .sum())
    }

    /// Every tree held here, for the coordinator's [`assemble`].
    pub fn held_trees(&self) -> Vec<HeldTree> {
        let mut done = vec![false; self.belief.groups.len()];
        let mut trees = Vec::new();
        for t in 0..self.belief.n as u32 {
            let g = self.belief.group_of[t as usize];
            if !self.holds(t) || done[g] {
                continue;
            }
            let indices = self.tree_of(t);
            for &g in &indices {
                done[g] = true;
            }
            trees.push(self.tree_at(&indices));
        }
        trees
    }
}

/// Singletons pairing `tracks` with `identities` in order (placeholders).
fn pair(tracks: &BTreeSet<u32>, identities: &BTreeSet<u32>) -> Vec<Group> {
    tracks
        .iter()
        .zip(identities)
        .map(|(&t, &i)| Group::certain(t, i))
        .collect()
}

/// The link slot of every port of `groups` (ports n + 2l and n + 2l + 1
/// are link l's two ends).
fn link_slots<'a>(
    groups: impl Iterator<Item = &'a Group> + 'a,
    n: usize,
) -> impl Iterator<Item = usize> + 'a {
    groups
        .flat_map(move |g| g.ports(n))
        .map(move |p| (p.id as usize - n) / 2)
}

/// `groups` with their links moved to the lowest link slots not in
/// `used`, each link's two ports together (side A keeps the even id).
fn renumber(mut groups: Vec<Group>, n: usize, used: &BTreeSet<usize>) -> Vec<Group> {
    let mut slots: BTreeMap<usize, usize> = BTreeMap::new();
    let mut free = (0..).filter(|s| !used.contains(s));
    for slot in link_slots(groups.iter(), n) {
        if let std::collections::btree_map::Entry::Vacant(entry) = slots.entry(slot) {
            if let Some(to) = free.next() {
                entry.insert(to);
            }
        }
    }
    let map = |id: &mut u32| {
        if *id as usize >= n {
            let local = *id as usize - n;
            if let Some(&to) = slots.get(&(local / 2)) {
                *id = (n + 2 * to + local % 2) as u32;
            }
        }
    };
    for group in &mut groups {
        group.tracks.iter_mut().for_each(map);
        group.identities.iter_mut().for_each(map);
    }
    groups
}

/// The whole belief from every leader's trees (each tree held by one
/// leader, every track in one): checked as a stored belief is, its ports
/// renumbered into one set of link slots.
pub fn assemble(
    n: usize,
    options: FactoredIdentityOptions,
    trees: Vec<HeldTree>,
) -> Result<FactoredIdentity, BeliefError> {
    let mut groups = Vec::new();
    let mut used = BTreeSet::new();
    let mut backgrounds: Vec<Option<Background>> = vec![None; n];
    for tree in trees {
        let renumbered = renumber(tree.groups, n, &used);
        used.extend(link_slots(renumbered.iter(), n));
        groups.extend(renumbered);
        for (t, background) in tree.backgrounds {
            let slot = backgrounds
                .get_mut(t as usize)
                .ok_or(BeliefError::UnknownTrack {
                    track: t,
                    tracks: n,
                })?;
            if slot.replace(background).is_some() {
                return Err(BeliefError::BadComponent {
                    detail: format!("track {t} in two trees"),
                });
            }
        }
    }
    let backgrounds = backgrounds
        .into_iter()
        .enumerate()
        .map(|(t, b)| {
            b.ok_or_else(|| BeliefError::BadComponent {
                detail: format!("track {t} in no tree"),
            })
        })
        .collect::<Result<Vec<_>, _>>()?;
    FactoredIdentity::try_from(Stored {
        n,
        options,
        groups,
        stats: SplitStats::default(),
        backgrounds,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::event::Identify;
    use crate::filter::max_abs_difference;
    use crate::workload::{generate, IdentityWorkloadSpec};
    use proptest::prelude::*;
    use rand::{Rng, SeedableRng};

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(40))]

        /// Leaders that each hold whole trees, gather a mix's two trees
        /// before applying it and now and then hand a tree to another,
        /// hold between them the centralized belief: put back together,
        /// its marginals are the centralized ones after every event.
        #[test]
        fn shares_that_gather_trees_hold_the_centralized_belief(
            n in 5usize..=9,
            cap in 3usize..=6,
            linked in any::<bool>(),
            leaders in 2usize..=3,
            seed in any::<u64>(),
            moves in any::<u64>(),
        ) {
            let w = generate(&IdentityWorkloadSpec {
                tracks: n,
                events: 60,
                mix_share: 0.6,
                swap: 0.5,
                accuracy: 0.9,
                neighbourhood: n,
                seed,
            })
            .unwrap();
            let options = FactoredIdentityOptions {
                max_group: cap,
                linked,
                ..FactoredIdentityOptions::default()
            };
            let mut central = FactoredIdentity::from_assignment(&w.initial, options).unwrap();
            let mut shares: Vec<IdentityShare> = (0..leaders)
                .map(|l| {
                    IdentityShare::start(&w.initial, options, |t| t as usize % leaders == l)
                        .unwrap()
                })
                .collect();
            let mut rng = rand::rngs::StdRng::seed_from_u64(moves);
            let holder = |shares: &[IdentityShare], t: u32| {
                shares.iter().position(|s| s.holds(t)).expect("a holder")
            };
            for e in &w.events {
                central.apply(e).unwrap();
                let at = match e {
                    IdentityEvent::Mix(m) => {
                        let (la, lb) = (holder(&shares, m.a), holder(&shares, m.b));
                        if la != lb {
                            let tree = shares[lb].take(m.b).unwrap();
                            shares[la].put(tree).unwrap();
                        }
                        la
                    }
                    IdentityEvent::Identify(r) => holder(&shares, r.track),
                };
                shares[at].apply(e).unwrap();
                if rng.gen_bool(0.3) {
                    let t = rng.gen_range(0..n as u32);
                    let (from, to) = (holder(&shares, t), rng.gen_range(0..leaders));
                    if from != to {
                        let tree = shares[from].take(t).unwrap();
                        shares[to].put(tree).unwrap();
                    }
                }
                let trees = shares.iter().flat_map(IdentityShare::held_trees).collect();
                let whole = assemble(n, options, trees).unwrap();
                let d = max_abs_difference(&whole.marginals().unwrap(), &central.marginals().unwrap());
                prop_assert!(d < 1e-12, "{} after {:?}", d, e);
            }
        }
    }

    /// A sure swap of two tracks held apart is relabelled by each holder
    /// where it is; adopting an untouched track there makes its start;
    /// put back together, the centralized belief.
    #[test]
    fn holders_relabel_sure_swaps_and_adopt_untouched_tracks_apart() {
        let options = FactoredIdentityOptions::default();
        let initial = [3, 1, 4, 0, 2];
        let mut central = FactoredIdentity::from_assignment(&initial, options).unwrap();
        let mut a = IdentityShare::start(&initial, options, |t| t < 2).unwrap();
        let mut b = IdentityShare::start(&initial, options, |t| (2..4).contains(&t)).unwrap();
        let mix = |a, b, swap| idmesh_belief::Mix { a, b, swap };
        let read = |track, identity| {
            IdentityEvent::Identify(Identify {
                track,
                identity,
                accuracy: 0.8,
            })
        };
        // A mix inside each share, then a sure swap across them.
        for e in [
            IdentityEvent::Mix(mix(0, 1, 0.3)),
            IdentityEvent::Mix(mix(2, 3, 0.4)),
        ] {
            central.apply(&e).unwrap();
        }
        a.apply(&IdentityEvent::Mix(mix(0, 1, 0.3))).unwrap();
        b.apply(&IdentityEvent::Mix(mix(2, 3, 0.4))).unwrap();
        central.apply(&IdentityEvent::Mix(mix(1, 2, 1.0))).unwrap();
        a.relabel(mix(1, 2, 1.0)).unwrap();
        b.relabel(mix(1, 2, 1.0)).unwrap();
        assert!(a.holds(2) && !a.holds(1) && b.holds(1) && !b.holds(2));
        assert!(a.relabel(mix(1, 4, 0.5)).is_err(), "only sure swaps");
        // Reads where the tracks are held now.
        central.apply(&read(2, 4)).unwrap();
        a.apply(&read(2, 4)).unwrap();
        central.apply(&read(1, 3)).unwrap();
        b.apply(&read(1, 3)).unwrap();
        // Track 4, untouched, is adopted by b (neither kept it) and mixed.
        assert!(a.adopt(4, 3).is_err(), "identity 3 is in a held tree");
        b.adopt(4, initial[4]).unwrap();
        assert!(b.adopt(4, initial[4]).is_err(), "held already");
        let e = IdentityEvent::Mix(mix(4, 1, 0.5));
        central.apply(&e).unwrap();
        b.apply(&e).unwrap();
        let trees = a.held_trees().into_iter().chain(b.held_trees()).collect();
        let whole = assemble(5, options, trees).unwrap();
        let d = max_abs_difference(&whole.marginals().unwrap(), &central.marginals().unwrap());
        assert!(d < 1e-12, "{d}");
        // A start kept for nobody gives way.
        let mut keeper = IdentityShare::start(&initial, options, |t| t == 4).unwrap();
        keeper.drop_start(4).unwrap();
        assert!(!keeper.holds(4));
        assert!(keeper.drop_start(4).is_err());
    }

    #[test]
    fn a_share_refuses_what_it_does_not_hold() {
        let options = FactoredIdentityOptions::default();
        let mut a = IdentityShare::start(&[0, 1, 2], options, |t| t < 2).unwrap();
        let mut b = IdentityShare::start(&[0, 1, 2], options, |t| t == 2).unwrap();
        let mix = IdentityEvent::Mix(idmesh_belief::Mix {
            a: 1,
            b: 2,
            swap: 0.5,
        });
        assert!(a.apply(&mix).is_err(), "track 2 is b's");
        assert!(a.take(2).is_err());
        assert!(a.tree_entries(2).is_err());
        // Alone, a track's tree is one group of one assignment.
        assert_eq!(b.tree_entries(2).unwrap(), 1);
        let tree = b.take(2).unwrap();
        assert!(!b.holds(2));
        a.put(tree.clone()).unwrap();
        assert!(a.put(tree).is_err(), "held here already");
        a.apply(&mix).unwrap();
        // Mixed, 1 and 2 share a group of 2! assignments: what the tree
        // moved sends.
        assert_eq!(a.tree_entries(2).unwrap(), 2);
        let sent: usize = a
            .clone()
            .take(1)
            .unwrap()
            .groups
            .iter()
            .map(|g| g.support())
            .sum();
        assert_eq!(sent, 2);
        // Every track in one tree: the whole belief; a track twice or in
        // none is refused.
        let trees = a.held_trees();
        assert!(assemble(3, options, trees.clone()).is_ok());
        assert!(assemble(3, options, trees[..trees.len() - 1].to_vec()).is_err());
        let mut twice = trees.clone();
        twice.push(trees[0].clone());
        assert!(assemble(3, options, twice).is_err());
    }
}
