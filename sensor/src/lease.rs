//! The sensor role's lease as the process's tasks share it: when the
//! voters' map last confirmed that this process holds the role, and
//! whether the hold is lost.
//!
//! The lease task ([`crate::keep_lease`]) reads the map every quarter of a
//! second and notes each confirmation here with the instant its read was
//! *asked*. The replication to the standby ([`crate::standby`]) reads it:
//! records the standby did not acknowledge leave only under a
//! confirmation asked after the standby was last seen gone. A standby
//! drops its token only once the voters have given it the role, so such
//! a read names the new holder if there is one. Without that check a
//! sensor frozen past the takeover time and woken found its standby gone
//! and published what its successor never held, at its old epoch, before
//! its lease task had noticed anything: leaders that had not yet heard
//! the new epoch took both streams, and waited on each other for good.

use std::time::Instant;
use tokio::sync::watch;

/// Shared between the lease task and the sensor's I/O (cloned).
#[derive(Debug, Clone)]
pub struct LeaseClock {
    state: watch::Sender<Hold>,
}

#[derive(Debug, Clone, Copy, Default)]
struct Hold {
    /// When the newest read that confirmed the hold was asked.
    confirmed: Option<Instant>,
    /// The map gives the role to another, or no voter led for the lease.
    lost: bool,
}

impl Default for LeaseClock {
    fn default() -> Self {
        LeaseClock {
            state: watch::Sender::new(Hold::default()),
        }
    }
}

impl LeaseClock {
    /// A read of the map asked at `asked` showed the role still held here.
    pub fn confirm(&self, asked: Instant) {
        self.state.send_modify(|hold| {
            if hold.confirmed.is_none_or(|c| c < asked) {
                hold.confirmed = Some(asked);
            }
        });
    }

    /// The hold is lost: whatever waits for a confirmation gives up.
    pub fn lose(&self) {
        self.state.send_modify(|hold| hold.lost = true);
    }

    /// Waits for a confirmation asked at or after `since`: true once there
    /// is one, false once the hold is lost.
    pub async fn confirmed_since(&self, since: Instant) -> bool {
        let mut hold = self.state.subscribe();
        let Ok(hold) = hold
            .wait_for(|h| h.lost || h.confirmed.is_some_and(|c| c >= since))
            .await
        else {
            return false;
        };
        !hold.lost
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::time::Duration;

    #[tokio::test]
    async fn only_a_read_asked_after_the_instant_confirms() {
        let clock = LeaseClock::default();
        let before = Instant::now();
        clock.confirm(before);
        let since = before + Duration::from_millis(1);
        let waiting = {
            let clock = clock.clone();
            tokio::spawn(async move { clock.confirmed_since(since).await })
        };
        tokio::time::sleep(Duration::from_millis(20)).await;
        assert!(!waiting.is_finished(), "an older read confirmed");
        clock.confirm(since + Duration::from_millis(5));
        assert!(waiting.await.is_ok_and(|confirmed| confirmed));
    }

    #[tokio::test]
    async fn a_lost_hold_ends_the_wait_unconfirmed() {
        let clock = LeaseClock::default();
        let since = Instant::now();
        let waiting = {
            let clock = clock.clone();
            tokio::spawn(async move { clock.confirmed_since(since).await })
        };
        clock.lose();
        assert!(waiting.await.is_ok_and(|confirmed| !confirmed));
        clock.confirm(Instant::now());
        assert!(!clock.confirmed_since(since).await, "lost stays lost");
    }
}
