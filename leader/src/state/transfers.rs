//! Sets and rows moving between leaders: what a mix across two leaders or
//! a handover sends (Algorithm 4), what is received (and the tracks it
//! makes the leader follow), and the transfers kept for a restarted peer.

use super::*;
use idmesh_belief::HeldComponent;
use idmesh_placement::{
    from_wire_component, from_wire_set, from_wire_tree, to_wire_component, to_wire_row,
    to_wire_set, to_wire_tree,
};
use idmesh_protocol::wire::factored::WireComponent;

impl Leader {
    /// The transfers sent to leader `to` for items after `after`.
    pub(crate) fn sent_to(&self, to: u16, after: u64) -> Vec<Transfer> {
        self.sent
            .iter()
            .filter(|(receiver, t)| *receiver == to && t.seq > after)
            .map(|(_, t)| t.clone())
            .collect()
    }

    /// Every transfer sent, with its receiver (resent after a restart: the
    /// peers drop the ones they have).
    pub(crate) fn all_sent(&self) -> &[(u16, Transfer)] {
        &self.sent
    }

    /// Leader `name` has its state safe through item `position`: it will
    /// never ask for the transfers of items up to there again, so they are
    /// dropped. Returns how many were.
    pub(crate) fn forget_sent(&mut self, name: &str, position: u64) -> usize {
        let Some(to) = self.leaders().iter().position(|l| l == name) else {
            return 0;
        };
        let before = self.sent.len();
        self.sent
            .retain(|(receiver, t)| *receiver as usize != to || t.seq > position);
        before - self.sent.len()
    }

    /// Takes out the sets with none of this leader's tracks (but not φ_∅),
    /// or on a factored stream the components with none of them, and sends
    /// them, with `rows`, to `to` as the transfer of item `seq`. Returns
    /// the tracks of the components sent. `released`: the tracks this
    /// leader stopped surveilling since the last call.
    pub(super) fn send_homeless(
        &mut self,
        seq: u64,
        to: u16,
        released: &[u32],
        rows: Vec<WireRow>,
        actions: &mut Vec<Action>,
    ) -> Result<Vec<u32>, LeaderError> {
        let started = self.started()?;
        let (own, passive) = (&started.own, &started.passive);
        if let Some(held) = &mut started.factored {
            // Every call takes all the components without a track of this
            // leader, so what the last one left has one: only components
            // changed since, or of a track released since, can be without.
            let components = held.take_changed(released, |tracks| {
                !tracks
                    .iter()
                    .any(|&t| own[t as usize] || passive.contains(&t))
            });
            let tracks = tracks_of(&components);
            self.send(seq, to, Vec::new(), rows, components, actions)?;
            return Ok(tracks);
        }
        let sets: Vec<WireSet> = started
            .share
            .extract(|atom| {
                let mut tracks = atom.tracks().peekable();
                tracks.peek().is_some() && !tracks.any(|t| own[t as usize])
            })
            .into_iter()
            .map(|(atom, ln_mass)| to_wire_set(&atom, ln_mass))
            .collect();
        self.send(seq, to, sets, rows, Vec::new(), actions)?;
        Ok(Vec::new())
    }

    /// Sends `to` the transfer of item `seq` (kept for a restarted peer).
    pub(super) fn send(
        &mut self,
        seq: u64,
        to: u16,
        sets: Vec<WireSet>,
        rows: Vec<WireRow>,
        components: Vec<HeldComponent>,
        actions: &mut Vec<Action>,
    ) -> Result<(), LeaderError> {
        let me = self.me()?;
        // Trees on their way to `to` at this item go with the rest.
        let trees = match self.trees_out.take() {
            Some((receiver, trees)) if receiver == to => trees,
            other => {
                self.trees_out = other;
                Vec::new()
            }
        };
        self.stats.transfers_sent += 1;
        self.stats.sets_sent += (sets.len() + components.len() + trees.len()) as u64;
        let transfer = Transfer {
            trees,
            version: VERSION,
            from: me,
            seq,
            sets,
            rows,
            components: components.into_iter().map(to_wire_component).collect(),
        };
        self.sent.push((to, transfer.clone()));
        actions.push(Action::Send { to, transfer });
        Ok(())
    }

    /// Rows received with a transfer: the partner's row of a cross-leader
    /// mix (the fit is made now), or the row of a track handed over.
    pub(super) fn receive_rows(&mut self, received: Vec<WireRow>) -> Result<(), LeaderError> {
        let started = self.started()?;
        let pending = started.row_mix.take();
        let Some(rows) = &mut started.rows else {
            return match received.is_empty() {
                true => Ok(()),
                false => Err(LeaderError::BadTransfer(
                    "rows of an information matrix on a stream without identities".into(),
                )),
            };
        };
        match pending {
            Some(mix) => {
                let partner = match received.as_slice() {
                    [row]
                        if !rows.holds(row.track) && (row.track == mix.a || row.track == mix.b) =>
                    {
                        row
                    }
                    _ => {
                        return Err(LeaderError::BadTransfer(format!(
                        "a mix of tracks {} and {} needs the partner's one row, got rows of {:?}",
                        mix.a,
                        mix.b,
                        received.iter().map(|r| r.track).collect::<Vec<_>>()
                    )))
                    }
                };
                rows.mix_with(mix, &partner.ln_likelihoods)
                    .map_err(|e| LeaderError::BadTransfer(e.to_string()))?;
            }
            None => {
                for row in received {
                    rows.insert(row.track, row.ln_likelihoods)
                        .map_err(|e| LeaderError::BadTransfer(e.to_string()))?;
                }
            }
        }
        Ok(())
    }

    /// Rows that came with the components of a factored mix (`mix`) from
    /// leader `from`: only the `partner` surveilling `mix.b` sends one,
    /// its row of `mix.b` as it was before the mix, held here until the
    /// fit ([`Leader::factored_mix_here`]).
    pub(super) fn receive_partner_row(
        &mut self,
        mix: Mix,
        row_from: Option<(u16, u32)>,
        from: u16,
        received: Vec<WireRow>,
    ) -> Result<(), LeaderError> {
        if received.is_empty() {
            return Ok(());
        }
        let rows = self.started()?.rows.as_mut();
        match (rows, received.as_slice()) {
            (Some(rows), [row])
                if row_from == Some((from, row.track)) && !rows.holds(row.track) =>
            {
                rows.insert(row.track, row.ln_likelihoods.clone())
                    .map_err(|e| LeaderError::BadTransfer(e.to_string()))
            }
            _ => Err(LeaderError::BadTransfer(format!(
                "leader {from} sent rows of {:?} with the components of a mix of tracks {} and \
                 {}, where only the row of {:?} may come",
                received.iter().map(|r| r.track).collect::<Vec<_>>(),
                mix.a,
                mix.b,
                row_from,
            ))),
        }
    }

    /// Adds sets received at item `seq`; asks to follow tracks they bring.
    pub(super) fn receive_sets(
        &mut self,
        seq: u64,
        sets: Vec<WireSet>,
        actions: &mut Vec<Action>,
    ) -> Result<(), LeaderError> {
        let started = self.started()?;
        let tracks = started.begin.tracks;
        let mut atoms = Vec::with_capacity(sets.len());
        for set in &sets {
            atoms.push(from_wire_set(set, tracks).map_err(LeaderError::BadTransfer)?);
        }
        let mut new_tracks: Vec<u32> = Vec::new();
        for (atom, _) in &atoms {
            for t in atom.tracks() {
                if started.interest.add(t) {
                    new_tracks.push(t);
                }
            }
        }
        started.share.absorb(atoms);
        if !new_tracks.is_empty() {
            self.follow(seq, new_tracks, actions)?;
        }
        Ok(())
    }
}

impl Leader {
    /// At a mix (0 < swap < 1) on a stream of identity trees, a leader
    /// other than `mixer` (the one surveilling `mix.a`) takes out the
    /// trees it holds of either track: they go to `mixer` in the transfer
    /// this leader sends it at the item, or alone
    /// ([`Leader::send_trees_left`]), and their tracks leave its interest
    /// unless it needs them for another reason.
    pub(super) fn trees_leave(
        &mut self,
        seq: u64,
        mix: Mix,
        mixer: u16,
    ) -> Result<(), LeaderError> {
        let me = self.me()?;
        let started = self.started()?;
        let Some(trees) = started.trees.as_mut() else {
            return Ok(());
        };
        if me == mixer || !(mix.swap > 0.0 && mix.swap < 1.0) {
            return Ok(());
        }
        let n = trees.tracks() as u32;
        let taken: Vec<WireTree> = trees
            .take_of(&[mix.a, mix.b])?
            .into_iter()
            .map(to_wire_tree)
            .collect();
        if taken.is_empty() {
            return Ok(());
        }
        let tracks: Vec<u32> = taken.iter().flat_map(|t| t.tracks(n)).collect();
        self.trees_out = Some((mixer, taken));
        self.unfollow(seq, tracks)
    }

    /// The trees taken out at item `seq` that no transfer took along:
    /// sent alone to the leader that mixes them, which waits for them.
    pub(super) fn send_trees_left(
        &mut self,
        seq: u64,
        actions: &mut Vec<Action>,
    ) -> Result<(), LeaderError> {
        let Some((to, trees)) = self.trees_out.take() else {
            return Ok(());
        };
        self.trees_out = Some((to, trees));
        self.send(seq, to, Vec::new(), Vec::new(), Vec::new(), actions)
    }

    /// Trees of the factored identity belief received: held from now on,
    /// their tracks followed ([`Leader::follow_held`]). A start this
    /// leader kept for nobody that is in the way is stale (its track was
    /// adopted elsewhere, and the keeper is not told) and gives way; any
    /// other overlap is a bad transfer.
    pub(super) fn receive_trees(&mut self, trees: Vec<WireTree>) -> Result<(), LeaderError> {
        if trees.is_empty() {
            return Ok(());
        }
        let started = self.started()?;
        let (held, passive) = match started.trees.as_mut() {
            Some(held) => (held, &mut started.passive_trees),
            None => {
                return Err(LeaderError::BadTransfer(
                    "trees of a factored identity belief on a stream without them".into(),
                ))
            }
        };
        let n = held.tracks() as u32;
        let mut arrived = Vec::new();
        for wire in trees {
            let tracks: Vec<u32> = wire.tracks(n).collect();
            let tree = from_wire_tree(wire).map_err(|e| LeaderError::BadTransfer(e.to_string()))?;
            for t in held.in_the_way(&tree) {
                if !passive.remove(&t) {
                    return Err(LeaderError::BadTransfer(format!(
                        "a tree that overlaps the tree of track {t}, held here"
                    )));
                }
                held.drop_start(t)?;
            }
            held.put(tree)
                .map_err(|e| LeaderError::BadTransfer(e.to_string()))?;
            arrived.extend(tracks);
        }
        self.to_follow.extend(arrived);
        Ok(())
    }

    /// Components received (a factored stream): held from now on. The
    /// tracks they bring are followed once the item's components are all
    /// in ([`Leader::follow_held`]).
    pub(super) fn receive_components(
        &mut self,
        components: Vec<WireComponent>,
    ) -> Result<(), LeaderError> {
        if components.is_empty() {
            return Ok(());
        }
        // A track kept here as its keeper, adopted elsewhere since: its
        // component comes, and the stale start component goes.
        for c in &components {
            for &t in &c.tracks {
                self.drop_passive(t)?;
            }
        }
        let held = self.started()?.factored.as_mut().ok_or_else(|| {
            LeaderError::BadTransfer("components of a factored belief on a Radon stream".into())
        })?;
        let tracks: Vec<u32> = components
            .iter()
            .flat_map(|c| c.tracks.iter().copied())
            .collect();
        held.put(components.into_iter().map(from_wire_component).collect())
            .map_err(|e| LeaderError::BadTransfer(e.to_string()))?;
        self.to_follow.extend(tracks);
        Ok(())
    }

    /// The tracks of the components held here that this leader does not
    /// follow yet, now added to its interest: it must hear every event on
    /// them from item `seq` on, so the caller asks the sensor to follow
    /// them from there. Read from what is held rather than from what one
    /// transfer brought: the components of one mix can come in several
    /// transfers, and the leader returns to waiting between them (once,
    /// the tracks of the first were noted and never followed, and a later
    /// sighting of one of them never reached its holder).
    pub(super) fn follow_held(&mut self) -> Result<Vec<u32>, LeaderError> {
        let mut candidates = std::mem::take(&mut self.to_follow);
        let started = self.started()?;
        let Some(held) = &started.factored else {
            return Ok(Vec::new());
        };
        candidates.sort_unstable();
        candidates.dedup();
        let trees = started.trees.as_ref();
        Ok(candidates
            .into_iter()
            .filter(|&t| {
                (held.holds(t) || trees.is_some_and(|s| s.holds(t))) && started.interest.add(t)
            })
            .collect())
    }

    /// Of `candidates`, the tracks this leader no longer needs since item
    /// `seq` — it neither surveils them nor holds their component (it sent
    /// it away, or the track left its region) — leave its interest, and
    /// the sensor will be told to stop routing them here
    /// ([`Leader::flush_unfollows`]). A factored stream whose interests
    /// shrink only: others only grow.
    pub(super) fn unfollow(&mut self, seq: u64, candidates: Vec<u32>) -> Result<(), LeaderError> {
        let mut pending = std::mem::take(&mut self.unfollowing);
        let before = pending.len();
        let started = self.started()?;
        if let (Some(held), false) = (&started.factored, started.interest.grows()) {
            let (own, interest) = (&started.own, &mut started.interest);
            let trees = started.trees.as_ref();
            pending.extend(candidates.into_iter().filter(|&t| {
                !own.get(t as usize).copied().unwrap_or(false)
                    && !held.holds(t)
                    && !trees.is_some_and(|s| s.holds(t))
                    && interest.remove(t)
            }));
        }
        if pending.len() > before {
            self.unfollow_after = seq;
        }
        self.unfollowing = pending;
        Ok(())
    }

    /// One request for every track unfollowed since the last, made when
    /// an input has been taken in: a crowd that moves a component at
    /// nearly every mix would otherwise ask at nearly every item. One
    /// request for several items says `after` the last of them; a track
    /// followed again meanwhile (a component came back, a handover) is
    /// left out, so the request drops only tracks unneeded since then.
    pub(super) fn flush_unfollows(&mut self, actions: &mut Vec<Action>) -> Result<(), LeaderError> {
        if self.unfollowing.is_empty() {
            return Ok(());
        }
        let me = self.me()?;
        let mut tracks = std::mem::take(&mut self.unfollowing);
        let interest = &self.started()?.interest;
        tracks.retain(|&t| !interest.follows(t));
        tracks.sort_unstable();
        tracks.dedup();
        if tracks.is_empty() {
            return Ok(());
        }
        self.stats.unfollows += 1;
        actions.push(Action::Unfollow(Unfollow {
            epoch: self.epoch,
            version: VERSION,
            leader: me,
            after: self.unfollow_after,
            tracks,
        }));
        Ok(())
    }

    /// Asks the sensor to follow `tracks` from item `seq` on, and waits
    /// for its answer.
    pub(super) fn follow(
        &mut self,
        seq: u64,
        mut tracks: Vec<u32>,
        actions: &mut Vec<Action>,
    ) -> Result<(), LeaderError> {
        let me = self.me()?;
        tracks.sort_unstable();
        self.stats.follows += 1;
        let follow = Follow {
            epoch: self.epoch,
            version: VERSION,
            leader: me,
            after: seq,
            tracks,
        };
        self.asked = Some(follow.clone());
        actions.push(Action::Follow(follow));
        self.waiting = Some(Waiting::Follow { seq });
        Ok(())
    }
}

/// Every track of `components`.
pub(super) fn tracks_of(components: &[HeldComponent]) -> Vec<u32> {
    components
        .iter()
        .flat_map(|c| c.tracks.iter().copied())
        .collect()
}

/// An owned track's row is missing: the state is broken.
pub(super) const NOT_HELD: LeaderError =
    LeaderError::Unexpected("an event on an owned track whose row this leader does not hold");

/// Row `track` as it goes on the wire.
pub(super) fn wire_row(rows: &InformationRows, track: u32) -> Result<WireRow, LeaderError> {
    Ok(to_wire_row(track, rows.row(track).ok_or(NOT_HELD)?))
}
