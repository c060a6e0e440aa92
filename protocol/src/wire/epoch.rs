//! The fence: every message a leader role sends carries the role's epoch,
//! and every receiver refuses one older than the newest it has seen from
//! that role.
//!
//! Who holds a role, and at which epoch, is decided by the voters
//! (`idmesh-consensus`): a takeover commits the role to its new holder at
//! the next epoch. A former holder that was only cut off (a partition, a
//! host frozen and woken) may still run for a while and send; once a
//! receiver has heard the new holder, it refuses the former one, so two
//! holders never both change what the sensor keeps and routes, what a peer
//! forgets, or what the coordinator answers. Without voters every role
//! sends epoch 0 and the fence admits everything, as before.
//!
//! A fence admits the first epoch it hears from a role and any newer one;
//! it keeps no clock and forgets nothing but by being dropped, so a
//! receiver that restarts hears the holder's next message first and
//! fences from there.

use std::collections::BTreeMap;

/// A message a role sends, stamped with the role's epoch.
pub trait Epoched {
    /// The epoch of the role's holder that sent it (0 without voters).
    fn epoch(&self) -> u64;
}

/// A message from a former holder of `role`.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("{what} from {role} at epoch {epoch}, older than its epoch {current}: a former holder of the role, fenced off")]
pub struct Stale {
    pub what: &'static str,
    pub role: String,
    pub epoch: u64,
    pub current: u64,
}

/// The newest epoch a receiver has seen from each role.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct Fence {
    seen: BTreeMap<String, u64>,
}

impl Fence {
    /// Admits `epoch` from `role` (and remembers it if it is the newest),
    /// or refuses it as a former holder's; `what` names the message.
    pub fn admit(&mut self, what: &'static str, role: &str, epoch: u64) -> Result<(), Stale> {
        match self.seen.get_mut(role) {
            Some(current) if epoch < *current => Err(Stale {
                what,
                role: role.to_string(),
                epoch,
                current: *current,
            }),
            Some(current) => {
                *current = epoch;
                Ok(())
            }
            None => {
                self.seen.insert(role.to_string(), epoch);
                Ok(())
            }
        }
    }

    /// The newest epoch seen from any role (0 if none).
    pub fn newest(&self) -> u64 {
        self.seen.values().copied().max().unwrap_or(0)
    }

    /// The newest epoch seen from `role` (0 if none).
    pub fn current(&self, role: &str) -> u64 {
        self.seen.get(role).copied().unwrap_or(0)
    }
}

macro_rules! epoched {
    ($($t:ty),*) => {
        $(impl $crate::wire::epoch::Epoched for $t {
            fn epoch(&self) -> u64 {
                self.epoch
            }
        })*
    };
}
pub(crate) use epoched;

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_former_holder_is_refused_once_its_successor_is_heard() {
        let mut fence = Fence::default();
        assert!(fence.admit("durable mark", "leader-1", 1).is_ok());
        assert!(fence.admit("durable mark", "leader-1", 1).is_ok());
        // Another role's epochs are its own.
        assert!(fence.admit("durable mark", "leader-2", 0).is_ok());
        assert!(fence.admit("durable mark", "leader-1", 2).is_ok());
        let stale = fence.admit("durable mark", "leader-1", 1).unwrap_err();
        assert_eq!((stale.epoch, stale.current), (1, 2));
        assert!(stale.to_string().contains("fenced"), "{stale}");
        assert_eq!(fence.current("leader-1"), 2);
        assert_eq!(fence.current("leader-3"), 0);
    }

    #[test]
    fn without_voters_every_epoch_is_zero_and_admitted() {
        let mut fence = Fence::default();
        for _ in 0..3 {
            assert!(fence.admit("progress mark", "leader-0", 0).is_ok());
        }
    }
}
