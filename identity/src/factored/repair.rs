//! What the factored identity belief does when its tables cannot take a
//! valid event.
//!
//! The belief is an approximation: its cuts and dropped links rule out
//! assignments the exact filter keeps ([`super`], "What cuts lose"), so a
//! stream the world could have produced can still bring an event that the
//! tables of its trees give no mass — a sure read (accuracy 1) of an
//! identity that a cut sent to another group, or an operation whose
//! result the rest of a linked tree rules out. The exact filter would take
//! such an event; the approximation must too, and must never stop a
//! leader. So every event runs *guarded*:
//!
//! 1. The linked trees of the event's tracks are saved (what an event may
//!    touch: [`super::share`] relies on the same bound) and the event is
//!    applied. Almost always it succeeds and that is all.
//! 2. If it fails and the event is a sure read (accuracy 1) of identity y
//!    on track t, and y is held within t's own tree, the belief missed a
//!    swap: the real track u ≠ t most likely to carry y within the group
//!    that holds y is mixed with t at probability [`SMOOTHING`], and the
//!    read applied once more. The read then keeps the swapped branch
//!    alone: t carries y and u what t carried, everything else as it
//!    was. (Not across trees: another tree may be held by another leader,
//!    and an event reads its own trees only.)
//! 3. If the event still fails, the trees are put back as they were and
//!    each of their groups is *smoothed*: [`SMOOTHING`] of its mass is
//!    spread evenly over its well-formed assignments, the rest keeps its
//!    table ((1 − ε)·table + ε·uniform). Nothing the tables held is lost
//!    beyond ε, and every assignment and every flag of a link is possible
//!    again, so the event is applied once more.
//! 4. If that fails too, the trees are put back once more and the event's
//!    tracks fall back to their rows: their leak λ becomes 1, so their
//!    answer is the row ([`super::background`]), and the event is applied
//!    to the rows alone (a mix mixes the two rows; a read applies Bayes'
//!    rule to the row, and a sure read the row too rules out makes the row
//!    certain of it).
//!
//! Each repair is counted ([`FactoredIdentity::repairs`]; a leader
//! reports the count in its stats and `/metrics`) and logged once, with
//! the event, at the warn level. The rule is a function of the trees'
//! contents alone (not of where groups sit in memory or how links are
//! numbered), so a leader holding the trees and the centralized belief of
//! `idmesh replay` repair alike and still answer alike.

use super::background::Background;
use super::group::Group;
use super::{FactoredIdentity, SplitStats};
use crate::event::IdentityEvent;
use idmesh_belief::BeliefError;
use std::collections::BTreeSet;

/// The share of a group's mass a repair spreads evenly over its
/// assignments: small enough to change no answer beyond 10⁻⁹, large enough
/// to stay far above the smallest normal number through the products and
/// messages of a tree.
pub(crate) const SMOOTHING: f64 = 1e-9;

/// How a repaired event was finally taken.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Repair {
    /// After a swap the belief missed.
    MissedSwap,
    /// After the trees' groups were smoothed.
    Smoothed,
    /// By the rows of the event's tracks alone.
    Rows,
}

/// The trees of an event's tracks as they were before it.
struct Saved {
    groups: Vec<Group>,
    backgrounds: Vec<(u32, Background)>,
    stats: SplitStats,
}

impl FactoredIdentity {
    /// How many valid events the tables could not take as they stood (see
    /// the module documentation): counted since this belief was built or
    /// read back, not stored with it.
    pub fn repairs(&self) -> u64 {
        self.repairs
    }

    /// Applies `op` (the event `event`, on `tracks`), repairing the belief
    /// if its tables cannot take it. Only errors of the belief's own make
    /// come here: the event was checked against the field before.
    pub(super) fn guarded(
        &mut self,
        event: IdentityEvent,
        tracks: &[u32],
        op: impl Fn(&mut Self) -> Result<(), BeliefError>,
    ) -> Result<(), BeliefError> {
        let saved = self.save(tracks);
        let Err(first) = op(self) else {
            return Ok(());
        };
        self.restore(&saved);
        let repair = if self.missed_swap(&event, &op) {
            Repair::MissedSwap
        } else {
            self.smooth(tracks);
            if op(self).is_ok() {
                Repair::Smoothed
            } else {
                self.restore(&saved);
                self.fall_back_to_rows(&event);
                Repair::Rows
            }
        };
        self.repairs += 1;
        tracing::warn!(
            ?event,
            error = %first,
            ?repair,
            "the identity belief's tables could not take a valid event; repaired"
        );
        Ok(())
    }

    /// Step 2 of the rule: a sure read explained by a swap the belief
    /// missed. Whether it took the read (the belief is as it was when it
    /// did not).
    fn missed_swap(
        &mut self,
        event: &IdentityEvent,
        op: &impl Fn(&mut Self) -> Result<(), BeliefError>,
    ) -> bool {
        let IdentityEvent::Identify(read) = *event else {
            return false;
        };
        if read.wrong_read_likelihood(self.n) > 0.0 {
            return false;
        }
        if !self
            .trees_of(&[read.track])
            .contains(&self.holder[read.identity as usize])
        {
            return false;
        }
        let Some(u) = self.likeliest_carrier(read.identity, read.track) else {
            return false;
        };
        let swap = idmesh_belief::Mix {
            a: read.track,
            b: u,
            swap: SMOOTHING,
        };
        // The swap reaches u's tree too: both are put back on a failure.
        let saved = self.save(&[read.track, u]);
        let took = self.mix_tables(swap).is_ok() && op(self).is_ok();
        if !took {
            self.restore(&saved);
        }
        took
    }

    /// The real track other than `not` most likely to carry identity `i`
    /// by the table of the group holding i (within its tree); ties to the
    /// lowest track.
    fn likeliest_carrier(&self, i: u32, not: u32) -> Option<u32> {
        let h = self.holder[i as usize];
        let group = &self.groups[h];
        let x = group.identities.iter().position(|&y| y == i)?;
        let m = super::links::Messages::new(self).group_marginals(h).ok()?;
        group
            .tracks
            .iter()
            .enumerate()
            .filter(|&(_, &t)| (t as usize) < self.n && t != not)
            .map(|(j, &t)| (m[j][x], t))
            .filter(|&(p, _)| p > 0.0)
            .max_by(|a, b| a.0.total_cmp(&b.0).then(b.1.cmp(&a.1)))
            .map(|(_, t)| t)
    }

    /// The groups of the linked trees of `tracks`, by index, each once.
    pub(crate) fn trees_of(&self, tracks: &[u32]) -> Vec<usize> {
        let mut tree: Vec<usize> = Vec::new();
        let mut seen = BTreeSet::new();
        for &t in tracks {
            let first = self.group_of[t as usize];
            if !seen.insert(first) {
                continue;
            }
            let mut at = tree.len();
            tree.push(first);
            while at < tree.len() {
                for port in self.groups[tree[at]].ports(self.n) {
                    let h = self.group_of[self.partner(port.id) as usize];
                    if h != usize::MAX && seen.insert(h) {
                        tree.push(h);
                    }
                }
                at += 1;
            }
        }
        tree
    }

    fn save(&self, tracks: &[u32]) -> Saved {
        let groups: Vec<Group> = self
            .trees_of(tracks)
            .into_iter()
            .map(|g| self.groups[g].clone())
            .collect();
        let backgrounds = groups
            .iter()
            .flat_map(|g| g.tracks.iter())
            .filter(|&&t| (t as usize) < self.n)
            .map(|&t| (t, self.backgrounds[t as usize].clone()))
            .collect();
        Saved {
            groups,
            backgrounds,
            stats: self.stats,
        }
    }

    /// Puts the saved trees back in place of whatever a failed event left
    /// of them (groups holding their tracks or identities, and groups left
    /// holding ports alone).
    fn restore(&mut self, saved: &Saved) {
        let n = self.n;
        let mut old: BTreeSet<usize> = BTreeSet::new();
        for g in &saved.groups {
            for &t in g.tracks.iter().filter(|&&t| (t as usize) < n) {
                old.insert(self.group_of[t as usize]);
            }
            for &i in g.identities.iter().filter(|&&i| (i as usize) < n) {
                old.insert(self.holder[i as usize]);
            }
        }
        old.extend(
            self.groups
                .iter()
                .enumerate()
                .filter(|(_, g)| g.real_size(n) == 0)
                .map(|(g, _)| g),
        );
        for g in old.into_iter().rev() {
            self.groups.swap_remove(g);
        }
        self.groups.extend(saved.groups.iter().cloned());
        for (t, background) in &saved.backgrounds {
            self.backgrounds[*t as usize] = background.clone();
        }
        self.stats = saved.stats;
        self.reindex();
    }

    /// Smooths every group of the trees of `tracks` by [`SMOOTHING`].
    fn smooth(&mut self, tracks: &[u32]) {
        for g in self.trees_of(tracks) {
            self.groups[g].smooth(SMOOTHING, self.n);
        }
    }

    /// The last resort: the event's tracks answer by their rows (leak 1),
    /// and the event applies to the rows alone.
    fn fall_back_to_rows(&mut self, event: &IdentityEvent) {
        match *event {
            IdentityEvent::Mix(mix) => {
                let (a, b) = self.rows_of(mix.a, mix.b);
                a.lose(1.0);
                b.lose(1.0);
                Background::mix(a, b, mix.swap);
            }
            IdentityEvent::Identify(read) => {
                let (n, wrong) = (self.n, read.wrong_read_likelihood(self.n));
                let row = &mut self.backgrounds[read.track as usize];
                row.lose(1.0);
                row.read_or_believe(n, read.identity, read.accuracy, wrong);
            }
        }
    }
}
