//! The role's standby: the process that would adopt this role if its own
//! died (the next live role's process in the deployment's list, which the
//! host works out from the liveliness tokens) keeps a copy of the role's
//! last snapshot on its own disk. Every snapshot goes to it
//! ([`Output::ToStandby`]), and again when the standby changes or has not
//! answered in [`STANDBY_RETRY`]; its acknowledgement
//! ([`StandbyStored`]) says which mark it holds.
//!
//! With a standby ([`Timers::standby`]: more than one leader process, and
//! a journal), the durable mark the role publishes is [`standby_mark`]:
//! the older of its own snapshot's mark and the mark its *current*
//! standby holds. The sensor and the peers thus never forget what the
//! adopter could not rebuild: a host lost with its disk costs the time to
//! adopt and catch up, never the role.
//!
//! [`Timers::standby`]: super::Timers::standby

use super::{Node, Now, Output};
use idmesh_protocol::wire::decode;
use idmesh_protocol::wire::leader_to_leader::StandbyStored;
use idmesh_protocol::wire::leader_to_sensor::Durable;
use std::time::Duration;

/// How long the standby may leave a copy unacknowledged before the last
/// snapshot is sent again (a copy or its answer lost, a standby that was
/// not yet listening).
pub const STANDBY_RETRY: Duration = Duration::from_secs(2);

/// What the node knows of its standby.
#[derive(Debug, Clone, Default)]
pub(super) struct Standby {
    /// The role whose process is the standby now (None: no other process
    /// is alive, or none is known yet).
    pub to: Option<String>,
    /// The newest mark the current standby said it holds.
    pub acked: Option<Durable>,
    /// The mark last sent to the current standby, and when.
    pub offered: Option<(Durable, Now)>,
}

/// The durable mark a role with a standby may publish: field-wise the
/// older of its own snapshot's mark (`own`) and the mark its standby holds
/// (`standby`); none while either is missing. A mark the standby does not
/// hold is never published: the sensor and the peers would forget what an
/// adopter on another disk needs.
pub(crate) fn standby_mark(own: Option<&Durable>, standby: Option<&Durable>) -> Option<Durable> {
    let (own, standby) = (own?, standby?);
    Some(Durable {
        batch: own.batch.min(standby.batch),
        position: own.position.min(standby.position),
        ..own.clone()
    })
}

/// Whether `mark` is at or past `than` in both fields.
pub(super) fn not_behind(mark: &Durable, than: &Durable) -> bool {
    mark.batch >= than.batch && mark.position >= than.position
}

impl Node {
    /// The mark to publish at the sweep, with a journal: the last
    /// snapshot's, held back to what the standby holds when there is one.
    pub(super) fn journaled_mark(&self) -> Option<Durable> {
        match self.timers.standby {
            false => self.safe.clone(),
            true => standby_mark(self.safe.as_ref(), self.standby.acked.as_ref()),
        }
    }

    /// The host says which role's process is the standby now: a new one
    /// is sent the last snapshot at once, and holds nothing until it says
    /// so.
    pub(super) fn standby_changed(&mut self, now: Now, to: Option<String>, out: &mut Vec<Output>) {
        if !self.timers.standby || self.standby.to == to {
            return;
        }
        tracing::info!(leader = %self.leader.name(), standby = ?to, "the role's standby changed");
        self.standby = Standby {
            to,
            ..Standby::default()
        };
        self.offer_standby(now, out);
    }

    /// A standby's acknowledgement (`StandbyStored` bytes): the mark it
    /// holds, if it is the current standby (an earlier one's word counts
    /// for nothing: it is not the process that would adopt the role).
    pub(super) fn standby_stored(&mut self, bytes: &[u8], origin: &str, out: &mut Vec<Output>) {
        let stored = match decode::<StandbyStored>(bytes) {
            Ok(stored) => stored,
            Err(e) => return self.count_rejected("a standby acknowledgement", origin, &e, out),
        };
        if stored.role != self.leader.name() || self.standby.to.as_deref() != Some(&stored.standby)
        {
            tracing::debug!(leader = %self.leader.name(), standby = %stored.standby,
                host = %stored.host, "an acknowledgement from a standby that is not the current one");
            return;
        }
        tracing::debug!(leader = %self.leader.name(), standby = %stored.standby, host = %stored.host,
            batch = stored.mark.batch, position = stored.mark.position, "the standby keeps a snapshot");
        let newer = match &self.standby.acked {
            Some(acked) => not_behind(&stored.mark, acked),
            None => true,
        };
        if newer {
            self.standby.acked = Some(stored.mark);
        }
    }

    /// Sends the last snapshot to the standby, if there are both.
    pub(super) fn offer_standby(&mut self, now: Now, out: &mut Vec<Output>) {
        let (Some(to), Some(mark)) = (&self.standby.to, &self.safe) else {
            return;
        };
        if !self.timers.standby || self.failure.is_some() {
            return;
        }
        self.standby.offered = Some((mark.clone(), now));
        out.push(Output::ToStandby {
            to: to.clone(),
            mark: mark.clone(),
        });
    }

    /// At the sweep: the last snapshot again, if the standby has not
    /// acknowledged it within [`STANDBY_RETRY`].
    pub(super) fn standby_sweep(&mut self, now: Now, out: &mut Vec<Output>) {
        let held = match (&self.standby.acked, &self.safe) {
            (Some(acked), Some(safe)) => not_behind(acked, safe),
            (_, None) => true,
            (None, Some(_)) => false,
        };
        let waited = self
            .standby
            .offered
            .as_ref()
            .is_none_or(|(_, at)| now.saturating_sub(*at) >= STANDBY_RETRY);
        if !held && waited {
            self.offer_standby(now, out);
        }
    }
}
