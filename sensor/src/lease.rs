//! The sensor role's lease as the process's tasks share it: the epoch the
//! role is held at, and whether the hold is lost.
//!
//! The lease task ([`crate::keep_lease`]) reads the map every quarter of a
//! second, and moves the role to a new epoch when the replication to the
//! standby ([`crate::standby`]) asks ([`LeaseClock::advanced_since`]):
//! records the standby did not acknowledge leave only once an advance
//! asked after the standby was last seen gone has moved the epoch on.
//!
//! - The standby's copy, in sync only at the old epoch, can then no
//!   longer win the role (its takeover names that epoch). Without the
//!   advance a standby cut off from the sensor while both still reached
//!   the voters found the sensor's token gone and took the role over from
//!   a copy that lacked what the sensor had published meanwhile.
//! - The advance succeeds only while the role is held here, so it also
//!   says no successor exists. A standby drops its token once the voters
//!   have given it the role; without that check a sensor frozen past the
//!   takeover time and woken found its standby gone and published what
//!   its successor never held, at its old epoch, before its lease task had
//!   noticed anything: leaders that had not yet heard the new epoch took
//!   both streams, and waited on each other for good.

use std::time::Instant;
use tokio::sync::watch;

/// Shared between the lease task and the sensor's I/O (cloned).
#[derive(Debug, Clone)]
pub struct LeaseClock {
    state: watch::Sender<Hold>,
}

#[derive(Debug, Clone, Copy, Default)]
struct Hold {
    /// The epoch the role is held at.
    epoch: u64,
    /// The map gives the role to another, or no voter led for the lease.
    lost: bool,
    /// The replication wants the epoch moved on by an advance asked at or
    /// after this instant (the newest such wish).
    advance_wanted: Option<Instant>,
    /// When the newest advance that moved the epoch on was asked.
    advanced: Option<Instant>,
}

impl LeaseClock {
    /// The lease of a role held at `epoch`.
    pub fn new(epoch: u64) -> Self {
        LeaseClock {
            state: watch::Sender::new(Hold {
                epoch,
                ..Hold::default()
            }),
        }
    }

    /// The epoch the role is held at now.
    pub fn epoch(&self) -> u64 {
        self.state.borrow().epoch
    }

    /// Whether an advance is wanted that none asked since has made: the
    /// lease task then moves the epoch on ([`crate::keep_lease`]).
    pub fn advance_due(&self) -> bool {
        let hold = self.state.borrow();
        hold.advance_wanted
            .is_some_and(|wanted| hold.advanced.is_none_or(|done| done < wanted))
    }

    /// An advance asked at `asked` moved the role to `epoch`.
    pub fn advanced(&self, asked: Instant, epoch: u64) {
        self.state.send_modify(|hold| {
            hold.epoch = hold.epoch.max(epoch);
            if hold.advanced.is_none_or(|a| a < asked) {
                hold.advanced = Some(asked);
            }
        });
    }

    /// Waits until the voters have moved the role to a new epoch by an
    /// advance asked at or after `since`: that epoch, or None once the
    /// hold is lost.
    pub async fn advanced_since(&self, since: Instant) -> Option<u64> {
        self.state.send_modify(|hold| {
            if hold.advance_wanted.is_none_or(|w| w < since) {
                hold.advance_wanted = Some(since);
            }
        });
        let mut hold = self.state.subscribe();
        let hold = hold
            .wait_for(|h| h.lost || h.advanced.is_some_and(|a| a >= since))
            .await
            .ok()?;
        (!hold.lost).then_some(hold.epoch)
    }

    /// The hold is lost: whatever waits for an advance gives up.
    pub fn lose(&self) {
        self.state.send_modify(|hold| hold.lost = true);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::time::Duration;

    #[tokio::test]
    async fn only_an_advance_asked_after_the_instant_moves_the_epoch_for_it() {
        let clock = LeaseClock::new(4);
        let before = Instant::now();
        clock.advanced(before, 5);
        assert!(!clock.advance_due());
        let since = before + Duration::from_millis(1);
        let waiting = {
            let clock = clock.clone();
            tokio::spawn(async move { clock.advanced_since(since).await })
        };
        tokio::time::sleep(Duration::from_millis(20)).await;
        assert!(!waiting.is_finished(), "an older advance counted");
        assert!(clock.advance_due());
        clock.advanced(since + Duration::from_millis(5), 6);
        assert_eq!(waiting.await.ok().flatten(), Some(6));
        assert!(!clock.advance_due());
        assert_eq!(clock.epoch(), 6);
        clock.lose();
        assert_eq!(clock.advanced_since(Instant::now()).await, None);
    }

    #[tokio::test]
    async fn a_lost_hold_ends_the_wait_unmoved() {
        let clock = LeaseClock::new(2);
        let since = Instant::now();
        let waiting = {
            let clock = clock.clone();
            tokio::spawn(async move { clock.advanced_since(since).await })
        };
        clock.lose();
        assert_eq!(waiting.await.ok().flatten(), None);
        clock.advanced(Instant::now(), 3);
        assert_eq!(clock.advanced_since(since).await, None, "lost stays lost");
    }
}
