//! Which tracker ids are the trace's tracks. A trace has a fixed set of
//! tracks `0..n`, named in its header before any event; a tracker names
//! its tracks as it likes (MOTChallenge ids start at 1 and have gaps). The
//! roster fixes the set and maps tracker ids to trace tracks in ascending
//! id order:
//!
//! - [`RosterPolicy::Declared`] — the ids are known up front (a header, or
//!   a whole file scanned before extraction);
//! - [`RosterPolicy::FirstFrame`] — the ids of the first frame (every
//!   report at the first time) are the tracks.
//!
//! Either way a report of an id outside the roster is refused
//! ([`ReportError::UnknownTrack`](super::ReportError::UnknownTrack)):
//! the belief is over a fixed set of targets, so a newcomer cannot join
//! mid-stream; the caller counts it and decides whether to go on.

use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;

/// How the set of tracks is fixed.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub enum RosterPolicy {
    /// These tracker ids, in any order (tracks are numbered in ascending
    /// id order).
    Declared(Vec<u32>),
    /// The ids of the first frame.
    FirstFrame,
}

/// The tracker ids and their trace tracks, once fixed.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Roster {
    /// Tracker id to trace track.
    track_of: BTreeMap<u32, u32>,
    /// Trace track to tracker id.
    ids: Vec<u32>,
}

impl Roster {
    /// The roster of these ids (duplicates collapse).
    pub(crate) fn of(ids: impl IntoIterator<Item = u32>) -> Roster {
        let mut ids: Vec<u32> = ids.into_iter().collect();
        ids.sort_unstable();
        ids.dedup();
        let track_of = ids
            .iter()
            .enumerate()
            .map(|(t, &id)| (id, t as u32))
            .collect();
        Roster { track_of, ids }
    }

    /// The trace track of tracker id `id`.
    pub(crate) fn track_of(&self, id: u32) -> Option<u32> {
        self.track_of.get(&id).copied()
    }

    pub fn len(&self) -> usize {
        self.ids.len()
    }
}
