//! Applying one item of the stream to the share (and the rows): the
//! `Begin`, mixes, observations, handovers, identity reads and cuts;
//! local sparsification after each item (Section 5.4.3).

use super::inbox::row_from;
use super::transfers::{tracks_of, wire_row, NOT_HELD};
use super::*;

impl Leader {
    pub(super) fn apply(
        &mut self,
        seq: u64,
        item: Item,
        actions: &mut Vec<Action>,
    ) -> Result<(), LeaderError> {
        self.stats.items += 1;
        if let Item::Begin(begin) = &item {
            return self.begin(begin.clone());
        }
        let me = self.me()?;
        self.settle_passive(&item)?;
        // Tracks this item is the first of, adopted here: theirs from now.
        for (track, leader) in item.adoptions() {
            if leader == me {
                self.adopt_here(track)?;
            }
        }
        let started = self.started()?;
        started.interest.note(&item);
        match item {
            Item::Begin(_) => {}
            Item::Mix {
                a,
                b,
                swap,
                owner_a,
                owner_b,
                handed,
                ..
            } => self.apply_mix(seq, Mix { a, b, swap }, (owner_a, owner_b), handed, actions)?,
            Item::Observe {
                track,
                red,
                blue,
                growth,
                ..
            } => self.apply_observe(Observe { track, red, blue }, &growth)?,
            Item::Handover { track, from, to } => {
                self.apply_handover(seq, track, (from, to), me, actions)?
            }
            Item::Identify {
                track,
                identity,
                accuracy,
                ..
            } => self.apply_identify(Identify {
                track,
                identity,
                accuracy,
            })?,
            Item::Cut { events, tag, rows } => {
                actions.push(Action::CutReady(self.reach_cut(seq, tag, events, rows)?));
            }
        }
        Ok(())
    }

    /// A mix: into the factored belief and the trees, or the Radon share
    /// (and rows), handing over what leaves this leader's tracks when
    /// the mix is across two leaders.
    fn apply_mix(
        &mut self,
        seq: u64,
        mix: Mix,
        (owner_a, owner_b): (u16, u16),
        handed: Option<Handed>,
        actions: &mut Vec<Action>,
    ) -> Result<(), LeaderError> {
        self.stats.mixes += 1;
        let (a, b) = (mix.a, mix.b);
        let me = self.me()?;
        let started = self.started()?;
        if started.factored.is_some() {
            self.trees_leave(seq, mix, owner_a)?;
            match handed {
                Some(handed) => self.factored_take(seq, mix, owner_a, handed, actions)?,
                None => self.factored_mix(seq, mix, owner_a, owner_b, actions)?,
            }
            return self.send_trees_left(seq, actions);
        }
        if handed.is_some() {
            return Err(LeaderError::Unexpected(
                "a mix that takes a track on a Radon stream",
            ));
        }
        started.share.mix(mix)?;
        // My mixed track and the other leader, for a mix across two.
        let across = match (owner_a == me, owner_b == me) {
            (true, false) => Some((a, owner_b)),
            (false, true) => Some((b, owner_a)),
            (true, true) => {
                if let Some(rows) = &mut started.rows {
                    rows.mix(mix)?;
                }
                None
            }
            (false, false) => None,
        };
        if let Some((mine, other)) = across {
            // Algorithm 4: both leaders of a cross-leader mix hand
            // over what left their tracks, and wait for the other.
            // The row of the mixed track goes along, unmixed: the
            // fit needs both, and both leaders compute it.
            let row = match &started.rows {
                Some(rows) => {
                    started.row_mix = Some(mix);
                    vec![wire_row(rows, mine)?]
                }
                None => Vec::new(),
            };
            self.send_homeless(seq, other, &[], row, actions)?;
            self.waiting = Some(Waiting::Transfer { seq, from: other });
        }
        Ok(())
    }

    /// An observation, applied by whoever holds the track's belief.
    fn apply_observe(&mut self, observe: Observe, growth: &Growth) -> Result<(), LeaderError> {
        self.stats.observations += 1;
        let track = observe.track;
        let started = self.started()?;
        if let Some(held) = &mut started.factored {
            // Only the holder of the track's component applies it
            // (a leader that followed the track before hears it too).
            if held.holds(track) {
                held.observe(observe)?;
            }
            return Ok(());
        }
        match growth {
            Growth::All => started.share.observe(observe, BeliefGrowth::All)?,
            Growth::Meeting(p) => started.share.observe(observe, BeliefGrowth::Meeting(p))?,
        }
        Ok(())
    }

    /// A handover of `track` from leader `from` to leader `to`: the
    /// track's belief and row go with it.
    fn apply_handover(
        &mut self,
        seq: u64,
        track: u32,
        (from, to): (u16, u16),
        me: u16,
        actions: &mut Vec<Action>,
    ) -> Result<(), LeaderError> {
        self.stats.handovers += 1;
        let started = self.started()?;
        let regional = started.regional();
        if let (Some(held), true) = (&mut started.factored, regional) {
            // The regional rule: the track leaves its component
            // (its holder splits it off), so that what the old
            // region keeps and what goes to the new one are apart.
            held.split_off(track)?;
        }
        let slot = started
            .own
            .get_mut(track as usize)
            .ok_or(LeaderError::Unexpected("a handover of an unknown track"))?;
        if from == me {
            *slot = false;
            let row = match &mut started.rows {
                Some(rows) => {
                    let ln_likelihoods = rows.take(track).ok_or(NOT_HELD)?;
                    vec![WireRow {
                        track,
                        ln_likelihoods,
                    }]
                }
                None => Vec::new(),
            };
            let mut gone = self.send_homeless(seq, to, &[track], row, actions)?;
            gone.push(track);
            self.unfollow(seq, gone)?;
        } else if to == me {
            *slot = true;
            // Under the regional rule, taken in when it comes
            // (state/pending.rs).
            if self.lazy_transfers() {
                self.note_pending(Pending {
                    seq,
                    from,
                    tracks: vec![track],
                });
            } else {
                self.waiting = Some(Waiting::Transfer { seq, from });
            }
        }
        Ok(())
    }

    /// An identity read, applied by whoever holds the track's tree (or
    /// the rows, on a Radon stream).
    fn apply_identify(&mut self, read: Identify) -> Result<(), LeaderError> {
        let track = read.track;
        let started = self.started()?;
        if let Some(trees) = &mut started.trees {
            // Only the holder of the track's tree applies it (a
            // leader that held it before may hear it too).
            if trees.holds(track) {
                trees.apply(&IdentityEvent::Identify(read))?;
                self.stats.identifies += 1;
            }
            return Ok(());
        }
        let rows = started.rows.as_mut().ok_or(LeaderError::Unexpected(
            "an identity read on a stream without identities",
        ))?;
        rows.identify(read)?;
        self.stats.identifies += 1;
        Ok(())
    }

    pub(super) fn begin(&mut self, begin: Begin) -> Result<(), LeaderError> {
        let me = begin
            .leaders
            .iter()
            .position(|l| *l == self.name)
            .ok_or_else(|| LeaderError::NotListed(self.name.clone()))? as u16;
        let (share, interest) = start(&begin, me)?;
        let factored = start_factored(&begin, me)?;
        let trees = start_identity(&begin, me)?;
        let own: Vec<bool> = begin.owners.iter().map(|&o| o == me).collect();
        let passive: std::collections::BTreeSet<u32> = (0..begin.tracks)
            .filter(|&t| begin.starts_unheld(t) && begin.keeper(t) == me)
            .collect();
        let rows = if begin.identities && trees.is_none() {
            let held = (0..begin.tracks).filter(|&t| begin.holds_at_start(t, me));
            Some(InformationRows::start(
                begin.tracks as usize,
                held,
                begin.initial_identity.as_deref(),
                KNOWN_START_CONFIDENCE,
            )?)
        } else {
            None
        };
        // Transfers that came before the Begin were checked on their own
        // only ([`crate::door`]): what does not fit the field goes now.
        let bounds = Bounds::of(&begin);
        let before = self.transfers.len();
        self.transfers
            .retain(|_, transfer| bounds.check_transfer(transfer, me).is_ok());
        self.stats.rejected += (before - self.transfers.len()) as u64;
        self.started = Some(Started {
            me,
            begin,
            share,
            own,
            interest,
            rows,
            row_mix: None,
            trees,
            factored,
            passive_trees: passive.clone(),
            passive,
        });
        Ok(())
    }

    /// Before an item that names tracks this leader keeps passive: the
    /// item adopts the track here (its start component and row stay, and
    /// are the adopted track's), or it comes after the track's adoption
    /// elsewhere, of which a keeper is not told (what it kept is stale,
    /// and goes).
    fn settle_passive(&mut self, item: &Item) -> Result<(), LeaderError> {
        let me = self.me()?;
        let started = self.started()?;
        if started.passive.is_empty() {
            return Ok(());
        }
        let named = match *item {
            Item::Mix { a, b, .. } => [Some(a), Some(b)],
            Item::Observe { track, .. }
            | Item::Identify { track, .. }
            | Item::Handover { track, .. } => [Some(track), None],
            Item::Begin(_) | Item::Cut { .. } => [None, None],
        };
        let adoptions = item.adoptions();
        for track in named.into_iter().flatten() {
            if !adoptions.contains(&(track, me)) {
                self.drop_passive(track)?;
            } else {
                let started = self.started()?;
                started.passive_trees.remove(&track);
                started.passive.remove(&track);
            }
        }
        Ok(())
    }

    /// Drops what this leader kept of `track` as its keeper, if it still
    /// keeps it: the track was adopted elsewhere, of which a keeper is not
    /// told, so what it kept is stale. Before an item that names the
    /// track, and before a transfer brings the track's component (which
    /// can come first: a mix of two other tracks sends the component the
    /// adopter made of it).
    pub(super) fn drop_passive(&mut self, track: u32) -> Result<(), LeaderError> {
        let started = self.started()?;
        let kept_tree = started.passive_trees.remove(&track);
        if !started.passive.remove(&track) {
            return Ok(());
        }
        if let Some(held) = &mut started.factored {
            held.drop_start(track)?;
        }
        if let Some(rows) = &mut started.rows {
            rows.take(track);
        }
        if let (Some(trees), true) = (&mut started.trees, kept_tree) {
            trees.drop_start(track)?;
        }
        Ok(())
    }

    /// Track `track`, which no leader surveilled, is this leader's from
    /// this item on: with the start component and row it kept as the
    /// track's keeper, or made here (an untouched track's are the start
    /// belief's, so nobody sends them).
    fn adopt_here(&mut self, track: u32) -> Result<(), LeaderError> {
        let started = self.started()?;
        let slot = started
            .own
            .get_mut(track as usize)
            .ok_or(LeaderError::Unexpected("an adoption of an unknown track"))?;
        *slot = true;
        if let Some(held) = &mut started.factored {
            if !held.holds(track) {
                held.adopt(track)?;
            }
        }
        let initial = started.begin.initial_identity.as_deref();
        if let Some(rows) = &mut started.rows {
            if !rows.holds(track) {
                rows.adopt(track, initial, KNOWN_START_CONFIDENCE)?;
            }
        }
        if let Some(trees) = started.trees.as_mut().filter(|s| !s.holds(track)) {
            let identity = initial.and_then(|i| i.get(track as usize)).copied().ok_or(
                LeaderError::Unexpected(
                    "an adopted track without a known start on a stream of identity trees",
                ),
            )?;
            trees.adopt(track, identity)?;
        }
        Ok(())
    }

    /// A mix on a factored stream. A mix of two components needs both in
    /// one place: every holder of the component of either track sends it
    /// to the leader surveilling track `a` (`owner_a`), which waits until
    /// it holds both and then mixes them (merge, or merge and split). The
    /// rule needs no knowledge of who holds what: the holders know what
    /// they hold, and the receiver knows it surveils `a`. A certain swap
    /// (a relabelling) and a non-event move nothing. Under the regional
    /// rule a mix across two regions is kept apart, and the component of
    /// `b` goes back to `owner_b`, which waits for it
    /// ([`Leader::factored_mix_here`]; docs/design/architecture.md, "Components
    /// that stay in their region").
    fn factored_mix(
        &mut self,
        seq: u64,
        mix: Mix,
        owner_a: u16,
        owner_b: u16,
        actions: &mut Vec<Action>,
    ) -> Result<(), LeaderError> {
        let me = self.me()?;
        let held = self.factored_mut("a factored mix on a Radon stream")?;
        let (has_a, has_b) = (held.holds(mix.a), held.holds(mix.b));
        if mix.swap == 0.0 {
            return Ok(());
        }
        if mix.swap == 1.0 {
            return self.factored_relabel(seq, mix, owner_a, owner_b, actions);
        }
        // The regional rule keeps a mix across two regions apart, and the
        // component of b goes back to its region's leader, which waits
        // for it.
        let started = self.started()?;
        let back = (started.regional() && owner_a != owner_b).then_some(owner_b);
        // On an identity stream the rows of a and b must meet too: the
        // leader surveilling b sends its row to `owner_a` with what it
        // sends anyway, and gets the fitted row back.
        let partner = (started.rows.is_some() && owner_a != owner_b).then_some(owner_b);
        if me == owner_a {
            if self.ready_to_mix(mix, row_from(mix, partner, None))? {
                self.factored_mix_here(seq, mix, back, partner, actions)?;
            } else {
                self.waiting = Some(Waiting::Components {
                    seq,
                    mix,
                    back,
                    partner,
                    handed: None,
                });
            }
            return Ok(());
        }
        let started = self.started()?;
        let row = match (&started.rows, partner == Some(me)) {
            (Some(rows), true) => vec![wire_row(rows, mix.b)?],
            _ => Vec::new(),
        };
        let held = self.factored_mut("a factored mix on a Radon stream")?;
        let mut sent = Vec::new();
        if has_a || has_b || !row.is_empty() {
            let components = match has_a || has_b {
                true => held.take_of(&[mix.a, mix.b], |_| true),
                false => Vec::new(),
            };
            sent = tracks_of(&components);
            self.send(seq, owner_a, Vec::new(), row, components, actions)?;
            if back != Some(me) {
                self.unfollow(seq, sent.clone())?;
            }
        }
        if partner == Some(me) && back.is_none() {
            // The fitted row of b comes back; nothing else does.
            self.waiting = Some(Waiting::Transfer { seq, from: owner_a });
        } else if back == Some(me) {
            if self.lazy_transfers() {
                // What comes back is b's component, which went out.
                sent.push(mix.b);
                self.note_pending(Pending {
                    seq,
                    from: owner_a,
                    tracks: sent,
                });
            } else {
                self.waiting = Some(Waiting::Transfer { seq, from: owner_a });
            }
        }
        Ok(())
    }

    /// A mix that takes a track of another leader (`handed`, item `seq`;
    /// docs/design/architecture.md, "Components that stay in their
    /// region"): the handover riding on the mix, then the mix within one
    /// region. The old leader splits the track off its component and sends
    /// the singleton (and the track's row) to `taker`, as at a handover,
    /// and goes on; `taker` surveils the track from here, waits for the
    /// singleton and mixes as it mixes two tracks of its own. What the
    /// centralized engine does at the same line: `split_off`, then `mix`
    /// (`idmesh_placement::Regional`).
    fn factored_take(
        &mut self,
        seq: u64,
        mix: Mix,
        taker: u16,
        handed: Handed,
        actions: &mut Vec<Action>,
    ) -> Result<(), LeaderError> {
        let me = self.me()?;
        let started = self.started()?;
        if !(started.regional() && mix.swap > 0.0 && mix.swap < 1.0) {
            return Err(LeaderError::Unexpected(
                "a mix that takes a track outside the regional rule, or not uncertain",
            ));
        }
        let track = handed.track;
        let slot = started
            .own
            .get_mut(track as usize)
            .ok_or(LeaderError::Unexpected("a mix taking an unknown track"))?;
        if me == handed.from {
            *slot = false;
            let row = match &mut started.rows {
                Some(rows) => vec![WireRow {
                    track,
                    ln_likelihoods: rows.take(track).ok_or(NOT_HELD)?,
                }],
                None => Vec::new(),
            };
            self.factored_mut("a factored mix on a Radon stream")?
                .split_off(track)?;
            let mut gone = self.send_homeless(seq, taker, &[track], row, actions)?;
            gone.push(track);
            return self.unfollow(seq, gone);
        }
        if me != taker {
            return Ok(());
        }
        *slot = true;
        self.stats.tracks_taken += 1;
        let row_from = self.started()?.rows.as_ref().map(|_| (handed.from, track));
        if self.ready_to_mix(mix, row_from)? {
            return self.factored_mix_here(seq, mix, None, None, actions);
        }
        self.waiting = Some(Waiting::Components {
            seq,
            mix,
            back: None,
            partner: None,
            handed: Some(handed),
        });
        Ok(())
    }

    /// A certain exchange of tracks `mix.a` and `mix.b` (item `seq`): their
    /// holders relabel in place, and then follow the track their component
    /// now holds from this item on (an observation of it must reach them).
    /// Under the regional rule, across two regions, both tracks are first
    /// split off their components and the two singletons change holders:
    /// the leader surveilling each track sends the other's, and waits for
    /// its own, so that every component stays in its holder's region.
    fn factored_relabel(
        &mut self,
        seq: u64,
        mix: Mix,
        owner_a: u16,
        owner_b: u16,
        actions: &mut Vec<Action>,
    ) -> Result<(), LeaderError> {
        let me = self.me()?;
        let started = self.started()?;
        let apart = started.regional() && owner_a != owner_b;
        // A sure swap moves no tree: each holder relabels its own.
        if let Some(trees) = started.trees.as_mut() {
            if trees.holds(mix.a) || trees.holds(mix.b) {
                trees.relabel(mix)?;
            }
        }
        // On an identity stream the two rows are exchanged as on a Radon
        // stream: a leader surveilling one of two tracks of two leaders
        // sends the other its row as it was, and fits the pair when the
        // other's comes (`row_mix`); one surveilling both swaps them here.
        let mut row = Vec::new();
        if let Some(rows) = &mut started.rows {
            if owner_a == owner_b && owner_a == me {
                rows.mix(mix)?;
            } else if me == owner_a || me == owner_b {
                let mine = if me == owner_a { mix.a } else { mix.b };
                row.push(wire_row(rows, mine)?);
                started.row_mix = Some(mix);
            }
        }
        let held = self.factored_mut("a factored mix on a Radon stream")?;
        let (has_a, has_b) = (held.holds(mix.a), held.holds(mix.b));
        if apart {
            held.split_off(mix.a)?;
            held.split_off(mix.b)?;
        }
        if has_a || has_b {
            held.mix(mix, seq)?;
        }
        if apart && (me == owner_a || me == owner_b) {
            // The singleton of the other leader's track goes there.
            let (theirs, to) = match me == owner_a {
                true => (mix.b, owner_b),
                false => (mix.a, owner_a),
            };
            let components = held.take_of(&[theirs], |tracks| tracks == [theirs]);
            let gone = tracks_of(&components);
            self.send(seq, to, Vec::new(), row, components, actions)?;
            self.unfollow(seq, gone)?;
            // The relabel changed which tracks the components held here
            // carry.
            self.to_follow.extend([mix.a, mix.b]);
            if self.lazy_transfers() {
                // A tree relabelled here may hold the other leader's
                // track now (trees are not kept in regions): followed
                // from here, before the singleton comes (no component of
                // either track is held here until then).
                let outside = self.follow_held()?;
                if !outside.is_empty() {
                    self.follow(seq, outside, actions)?;
                }
                // What comes is the singleton of this leader's track.
                let mine = if theirs == mix.b { mix.a } else { mix.b };
                self.note_pending(Pending {
                    seq,
                    from: to,
                    tracks: vec![mine],
                });
            } else {
                self.waiting = Some(Waiting::Transfer { seq, from: to });
            }
            return Ok(());
        }
        self.to_follow.extend([mix.a, mix.b]);
        if !row.is_empty() {
            // The rows of two leaders, exchanged: the tracks the relabel
            // brought are followed once the other's row is in.
            let to = if me == owner_a { owner_b } else { owner_a };
            self.send(seq, to, Vec::new(), row, Vec::new(), actions)?;
            self.waiting = Some(Waiting::Transfer { seq, from: to });
            return Ok(());
        }
        let new_tracks = self.follow_held()?;
        if !new_tracks.is_empty() {
            self.follow(seq, new_tracks, actions)?;
        }
        Ok(())
    }

    /// Mix `mix` (item `seq`) of two components both held here; kept apart
    /// when it has to go `back`, and then the component of `mix.b` (unless
    /// it holds `mix.a` too) is sent to that leader, which waits for this
    /// transfer even if it is empty.
    ///
    /// On an identity stream the rows of `mix.a` and `mix.b` are both
    /// here by then (the `partner` surveilling b sent its row, as it was
    /// before the mix): they are fitted together, as the centralized
    /// matrix fits them, and the new row of b goes back to the partner in
    /// the transfer it waits for (with b's component, kept apart).
    pub(super) fn factored_mix_here(
        &mut self,
        seq: u64,
        mix: Mix,
        back: Option<u16>,
        partner: Option<u16>,
        actions: &mut Vec<Action>,
    ) -> Result<(), LeaderError> {
        let mut row = Vec::new();
        if let Some(trees) = &mut self.started()?.trees {
            // Both trees are here (they came with the components).
            trees.apply(&IdentityEvent::Mix(mix))?;
        }
        if let Some(rows) = &mut self.started()?.rows {
            rows.mix(mix)?;
            if partner.is_some() {
                let ln_likelihoods = rows.take(mix.b).ok_or(NOT_HELD)?;
                row.push(WireRow {
                    track: mix.b,
                    ln_likelihoods,
                });
            }
        }
        let held = self.factored_mut("a factored mix on a Radon stream")?;
        let Some(to) = back else {
            held.mix(mix, seq)?;
            if let Some(to) = partner {
                self.send(seq, to, Vec::new(), row, Vec::new(), actions)?;
            }
            return Ok(());
        };
        held.mix_apart(mix, seq)?;
        let components = held.take_of(&[mix.b], |tracks| !tracks.contains(&mix.a));
        let gone = tracks_of(&components);
        // Under the regional rule `back` is the partner: one transfer.
        self.send(seq, to, Vec::new(), row, components, actions)?;
        self.unfollow(seq, gone)?;
        Ok(())
    }

    /// Whether the leader surveilling `mix.a` holds all a mix needs: the
    /// components of both tracks and, on an identity stream across two
    /// leaders, the `partner`'s row of b.
    pub(super) fn ready_to_mix(
        &mut self,
        mix: Mix,
        row_from: Option<(u16, u32)>,
    ) -> Result<bool, LeaderError> {
        let started = self.started()?;
        let row = match (&started.rows, row_from) {
            (Some(rows), Some((_, track))) => rows.holds(track),
            _ => true,
        };
        let trees = started
            .trees
            .as_ref()
            .is_none_or(|s| s.holds(mix.a) && s.holds(mix.b));
        let held = self.factored_mut("a factored mix on a Radon stream")?;
        Ok(row && trees && held.holds(mix.a) && held.holds(mix.b))
    }

    /// The factored share of a started stream; `what` names the misuse
    /// if the stream holds the Radon belief.
    pub(super) fn factored_mut(
        &mut self,
        what: &'static str,
    ) -> Result<&mut FactoredShare, LeaderError> {
        self.started()?
            .factored
            .as_mut()
            .ok_or(LeaderError::Unexpected(what))
    }

    /// Item `seq` is fully applied.
    pub(super) fn finish(&mut self, seq: u64) {
        self.position = seq;
        self.taken.clear();
        if let Some(started) = &mut self.started {
            let budget = started.begin.budget as usize;
            if budget > 0 {
                let sparsify = if started.begin.omp {
                    Sparsify::overcomplete(budget)
                } else {
                    Sparsify::threshold(budget)
                };
                // A numerical failure of OMP leaves the share thresholded.
                if let Err(e) = started.share.sparsify(&sparsify) {
                    tracing::warn!(leader = %self.name, seq, error = %e, "OMP failed; thresholded instead");
                }
            }
        }
    }
}
