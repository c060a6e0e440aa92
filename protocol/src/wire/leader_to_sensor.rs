//! A leader that received sets with tracks it did not follow asks the
//! sensor to route those tracks' events to it from now on, and gets back the
//! items it was not sent since `after` (postcard, as the payload of a get on
//! `P/sensor/<name>/follow`).
//!
//! Each message's rules ([`Valid`], and [`Bounds`] for a follow reply)
//! sit below the types.

use super::bounds::{invalid, Bounds};
use super::sensor_to_leader::{check_items, Batch, Sequenced};
use super::valid::distinct;
use super::{Valid, WireError};
use serde::{Deserialize, Serialize};

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Follow {
    pub version: u16,
    /// The sending role's epoch ([`super::epoch`]).
    pub epoch: u64,
    pub leader: u16,
    pub after: u64,
    pub tracks: Vec<u32>,
}
super::versioned!(Follow, "follow request");
super::epoch::epoched!(Follow);

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Followed {
    pub version: u16,
    /// The epoch of the sensor role's holder that answered.
    pub epoch: u64,
    /// Every item after `after` that touches the tracks (as the interest
    /// rule grows them), up to the stream's head when the sensor answered.
    pub items: Vec<Sequenced>,
}
super::versioned!(Followed, "follow reply");
super::epoch::epoched!(Followed);

/// A leader of a factored stream no longer needs these tracks' events: it
/// neither surveils them nor holds a component with them, since item
/// `after` (it sent their components away, or a track left its region).
/// Fire and forget (put on `P/sensor/<name>/unfollow`): a lost request
/// costs items the leader ignores, never an answer. The sensor drops a
/// track only if it was last followed for this leader before `after` — a
/// request that arrives late, after the leader followed the track again
/// (a component came back, a handover), must not undo that.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Unfollow {
    pub version: u16,
    /// The sending role's epoch ([`super::epoch`]).
    pub epoch: u64,
    pub leader: u16,
    pub after: u64,
    pub tracks: Vec<u32>,
}
super::versioned!(Unfollow, "unfollow request");
super::epoch::epoched!(Unfollow);

/// A leader that lost batches of its stream (a gap in their numbers, or
/// the time it was down) asks for them again: every batch numbered `from`
/// or later that the sensor sent it (postcard, the payload of a get on
/// `P/sensor/<name>/resend`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Resend {
    pub version: u16,
    /// The sending role's epoch ([`super::epoch`]).
    pub epoch: u64,
    /// The leader's name: one that lost the stream's Begin does not know
    /// its index yet.
    pub leader: String,
    pub from: u64,
}
super::versioned!(Resend, "resend request");
super::epoch::epoched!(Resend);

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Resent {
    pub version: u16,
    /// The epoch of the sensor role's holder that answered (its batches
    /// carry it too).
    pub epoch: u64,
    /// The batches, in number order, as first sent.
    pub batches: Vec<Batch>,
}
super::versioned!(Resent, "resend reply");
super::epoch::epoched!(Resent);

/// How far a leader's state is safe on disk (or, with no journal, applied):
/// it will never ask for batches numbered below `batch` again, nor for the
/// transfers of items at or before `position`. Published on
/// `P/leader/<name>/durable` whenever it moves; the sensor drops what it
/// keeps below it (its batch log, and items every leader has passed), and
/// peers drop the transfers they keep for this leader. This is what keeps
/// every log of a long-running deployment bounded.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Durable {
    pub version: u16,
    /// The sending role's epoch ([`super::epoch`]).
    pub epoch: u64,
    pub leader: String,
    /// Every batch numbered below this one is applied and kept.
    pub batch: u64,
    /// Every item at or before this seq is applied and kept.
    pub position: u64,
}
super::versioned!(Durable, "durable mark");
super::epoch::epoched!(Durable);

/// How far a leader has got: every item numbered at or before `through`
/// that the sensor sent it is applied (it waits for nothing before it),
/// and `batch` is the number of the next batch it waits for. Published on
/// `P/leader/<name>/progress` after every input that moves it when the
/// sensor has a window (without one nothing waits for it), and again at
/// every sweep (a put lost, or a sensor restarted, is mended within
/// one). The sensor's flow control: it routes at most its window of seqs
/// past the slowest leader's progress, so a leader that follows tracks is
/// sent at most a window of items it missed on them; and a stream the
/// window holds publishes again the batches a leader still waits for
/// (with nothing sent after them, nothing else would show one was lost).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Progress {
    pub version: u16,
    /// The sending role's epoch ([`super::epoch`]).
    pub epoch: u64,
    pub leader: String,
    pub through: u64,
    pub batch: u64,
}
super::versioned!(Progress, "progress mark");
super::epoch::epoched!(Progress);

impl Valid for Follow {
    fn problem(&self) -> Option<String> {
        distinct("follow tracks", &self.tracks).err()
    }
}

impl Valid for Unfollow {
    fn problem(&self) -> Option<String> {
        distinct("unfollow tracks", &self.tracks).err()
    }
}

impl Valid for Followed {
    fn problem(&self) -> Option<String> {
        check_items(&self.items, false).err()
    }
}

impl Valid for Resend {
    fn problem(&self) -> Option<String> {
        self.leader
            .is_empty()
            .then(|| "a resend request names no leader".into())
    }
}

impl Valid for Durable {
    fn problem(&self) -> Option<String> {
        self.leader
            .is_empty()
            .then(|| "a durable mark names no leader".into())
    }
}

impl Valid for Progress {
    fn problem(&self) -> Option<String> {
        self.leader
            .is_empty()
            .then(|| "a progress mark names no leader".into())
    }
}

impl Valid for Resent {
    fn problem(&self) -> Option<String> {
        let mut previous: Option<u64> = None;
        for (i, batch) in self.batches.iter().enumerate() {
            if previous.is_some_and(|p| batch.number <= p) {
                return Some(format!("batch {i}: number {} out of order", batch.number));
            }
            previous = Some(batch.number);
            if let Some(e) = batch.problem() {
                return Some(format!("batch {i} (number {}): {e}", batch.number));
            }
        }
        None
    }
}

impl Bounds {
    /// The items of a follow reply.
    pub fn check_followed(&self, items: &[Sequenced]) -> Result<(), WireError> {
        self.check_items(items)
            .map_err(|problem| invalid("follow reply", problem))
    }
}
