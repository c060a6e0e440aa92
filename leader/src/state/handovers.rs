//! Handovers taken in without stopping (a factored stream under the
//! regional rule).
//!
//! A leader that a track is handed over to needs the track's component,
//! which the old leader sends when it reaches the same item. Stopping there
//! until it comes chains the leaders together: each waits for a peer that
//! may itself be stopped at an earlier handover, so the leaders advance in
//! lockstep, one transfer at a time, and every transfer costs a wake-up
//! and a pass of its own. In `idmesh bench` (10,000 targets, 4 leaders)
//! 99% of the transfers a leader sent went out from a pass that the
//! arrival of a transfer had started.
//!
//! Nothing needs the component before an item that touches the track, so
//! the leader notes the handover ([`super::Pending`]) and goes on. Items
//! are still applied strictly in seq order; only the arrival of the
//! component moves later. That changes no answer, because the component
//! takes part in nothing until then:
//! - under the regional rule the old leader splits the track off before
//!   it goes, and every component a leader holds lies in its region, so
//!   the transfer brings the track's singleton and nothing else (checked
//!   when it comes: anything else is refused as a broken invariant);
//! - an item that touches a pending track, and a cut (an answer holds
//!   everything up to it), wait until every pending transfer has come;
//! - the split rule a leader runs weighs a component by itself only (the
//!   local rule), so the components held meanwhile are mixed and split as
//!   they would be with the singleton present;
//! - the singleton's track is surveilled here (it was just handed over),
//!   so a handover in between would not have sent it away: the leader
//!   finds it among the changed components at its next handover, as it
//!   would have;
//! - the leader's durable mark and its requests for lost transfers count
//!   from before the first pending handover
//!   ([`Leader::received_through`]), so peers keep what it still lacks, and
//!   a leader with a pending transfer is not quiet.

use super::*;

impl Leader {
    /// Whether handovers to this leader are taken in without stopping: a
    /// factored stream under the regional rule, without identities (the
    /// rows of the information matrix move with the handover and are fit
    /// at once).
    pub(super) fn lazy_handovers(&self) -> bool {
        self.started
            .as_ref()
            .is_some_and(|s| s.factored.is_some() && s.regional() && s.rows.is_none())
    }

    /// Takes in every pending handover's transfer that has come.
    pub(super) fn take_pending(&mut self) -> Result<(), LeaderError> {
        let mut i = 0;
        while i < self.pending.len() {
            let p = self.pending[i];
            let Some(transfer) = self.transfers.remove(&(p.seq, p.from)) else {
                i += 1;
                continue;
            };
            self.pending.remove(i);
            let broken = |what: String| {
                LeaderError::BadTransfer(format!(
                    "the transfer of the handover of track {} at item {} brought {what} \
                     (under the regional rule it brings the track alone)",
                    p.track, p.seq
                ))
            };
            if !transfer.sets.is_empty() || !transfer.rows.is_empty() {
                return Err(broken("sets or rows".into()));
            }
            let tracks = transfer.components.iter().flat_map(|c| &c.tracks);
            if let Some(other) = tracks.clone().find(|&&t| t != p.track) {
                return Err(broken(format!("track {other}")));
            }
            self.receive_components(transfer.components)?;
            // The track is followed since its handover.
            let unfollowed = self.follow_held()?;
            if !unfollowed.is_empty() {
                return Err(broken(format!("tracks {unfollowed:?} not followed here")));
            }
        }
        Ok(())
    }

    /// Whether `item` must wait until every pending handover's transfer
    /// has come.
    pub(super) fn needs_pending(&self, item: &Item) -> bool {
        let touches = |t: u32| self.pending.iter().any(|p| p.track == t);
        match item {
            _ if self.pending.is_empty() => false,
            Item::Mix { swap, .. } if *swap == 0.0 => false,
            Item::Mix { a, b, .. } => touches(*a) || touches(*b),
            Item::Observe { track, .. } | Item::Handover { track, .. } => touches(*track),
            Item::Begin(_) | Item::Cut { .. } | Item::Identify { .. } => true,
        }
    }

    /// The earliest pending handover whose transfer has not come.
    pub(super) fn first_pending(&self) -> Option<(u64, u16)> {
        self.pending.first().map(|p| (p.seq, p.from))
    }
}
