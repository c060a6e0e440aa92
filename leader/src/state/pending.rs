//! Transfers taken in without stopping (a factored stream under the
//! regional rule).
//!
//! Under the regional rule a leader is sent a component at three items:
//! a handover to it (the track's singleton), a mix across two regions of
//! which it surveils b (b's component, which it sent the leader
//! surveilling a, comes back kept apart), and a certain exchange across
//! two regions (the singleton of its own track). Stopping at the item
//! until the transfer comes chained the leaders together: each waited for
//! a peer that was itself stopped at an earlier item, so the leaders
//! advanced in lockstep, one transfer at a time, and every transfer cost a
//! wake-up and a pass of its own. In `idmesh bench` (10,000 targets, 4
//! leaders) 99% of the transfers a leader sent went out from a pass that
//! the arrival of a transfer had started.
//!
//! Nothing needs what such a transfer brings before an item that touches
//! one of its tracks, so the leader notes it ([`super::Pending`], with the
//! tracks it can bring) and goes on. Items are still applied strictly in
//! seq order; only the arrival of the components moves later. That
//! changes no answer, because they take part in nothing until then:
//! - an item that touches a pending track waits until the transfers
//!   bringing its tracks have come, and a cut (an answer holds everything
//!   up to it) until every pending transfer has;
//! - every component a leader holds lies in its region, and the old
//!   holder splits a track off before it goes, so what comes is what the
//!   pending entry names (checked when it comes: anything else is refused
//!   as a broken invariant);
//! - the split rule a leader runs weighs a component by itself only (the
//!   local rule), so the components held meanwhile are mixed and split as
//!   they would be with the pending ones present;
//! - a pending track is surveilled here, so a handover in between would
//!   not have sent its component away: the leader finds it among the
//!   changed components at its next handover, as it would have;
//! - the leader's durable mark and its requests for lost transfers count
//!   from before the first pending item ([`Leader::received_through`]),
//!   so peers keep what it still lacks, and a leader with a pending
//!   transfer is not quiet.
//!
//! A mix across regions still stops the leader surveilling a until b's
//! component comes: it needs both to mix.

use super::*;

impl Leader {
    /// Whether the transfers of handovers, of mixes across regions coming
    /// back and of exchanges across regions are taken in without stopping:
    /// a factored stream under the regional rule, without identities (the
    /// rows of the information matrix move with a handover and are fit at
    /// once).
    pub(super) fn lazy_transfers(&self) -> bool {
        self.started
            .as_ref()
            .is_some_and(|s| s.factored.is_some() && s.regional() && s.rows.is_none())
    }

    /// A transfer this leader goes on without, to take in when it comes.
    pub(super) fn note_pending(&mut self, pending: Pending) {
        self.pending.push(pending);
        self.pending_checked = false;
    }

    /// Takes in every pending transfer that has come.
    pub(super) fn take_pending(&mut self) -> Result<(), LeaderError> {
        if self.pending_checked {
            return Ok(());
        }
        self.pending_checked = true;
        let mut i = 0;
        while i < self.pending.len() {
            let key = (self.pending[i].seq, self.pending[i].from);
            let Some(transfer) = self.transfers.remove(&key) else {
                i += 1;
                continue;
            };
            let p = self.pending.remove(i);
            let broken = |what: String| {
                LeaderError::BadTransfer(format!(
                    "leader {}'s transfer of item {} brought {what}, where the regional rule lets \
                     it bring components of tracks {:?} only",
                    p.from, p.seq, p.tracks
                ))
            };
            if !transfer.sets.is_empty() || !transfer.rows.is_empty() {
                return Err(broken("sets or rows".into()));
            }
            let mut tracks = transfer.components.iter().flat_map(|c| &c.tracks);
            if let Some(other) = tracks.find(|t| !p.tracks.contains(t)) {
                return Err(broken(format!("track {other}")));
            }
            self.receive_components(transfer.components)?;
            self.receive_trees(transfer.trees)?;
            // Its tracks are followed: surveilled here, or kept followed
            // while their component was away.
            let unfollowed = self.follow_held()?;
            if !unfollowed.is_empty() {
                return Err(broken(format!("tracks {unfollowed:?} not followed here")));
            }
        }
        Ok(())
    }

    /// Whether `item` must wait for a pending transfer: one bringing a track
    /// it touches, or, for a cut, a beginning or an identity read, any.
    pub(super) fn needs_pending(&self, item: &Item) -> bool {
        let touches = |t: u32| self.pending.iter().any(|p| p.tracks.contains(&t));
        match item {
            _ if self.pending.is_empty() => false,
            Item::Mix { swap, .. } if *swap == 0.0 => false,
            Item::Mix { a, b, .. } => touches(*a) || touches(*b),
            Item::Observe { track, .. } | Item::Handover { track, .. } => touches(*track),
            Item::Begin(_) | Item::Cut { .. } | Item::Identify { .. } => true,
        }
    }

    /// The earliest pending transfer: its item and its sender.
    pub(super) fn first_pending(&self) -> Option<(u64, u16)> {
        self.pending.first().map(|p| (p.seq, p.from))
    }
}
