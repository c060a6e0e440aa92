//! What a message must be to belong to a stream: every track below the n
//! of the stream's `Begin`, every leader index below the number of its
//! leaders, identity reads and rows only on an identity stream. A leader
//! knows these from its `Begin`, so it checks them at its door, before an
//! input is journaled or applied; the coordinator knows n from the cut.
//!
//! This module holds the field ([`Bounds`]) and the two checks every
//! message's bounds are written with (a track, a leader index). Each
//! message's own `check_*` method on [`Bounds`] sits in the message's
//! module beside its type (`Bounds::check_batch` in `sensor_to_leader`,
//! `Bounds::check_transfer` in `leader_to_leader`, ...), so this module
//! imports no message. The rules a message obeys on its own are
//! [`Valid`](super::Valid)'s.

use super::valid::require;
use super::WireError;

/// The size of a stream's field, from its `Begin`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Bounds {
    /// n: tracks are `0..tracks` (identities too, on an identity stream).
    pub tracks: u32,
    /// L: leader indices are `0..leaders`.
    pub leaders: usize,
    pub identities: bool,
    /// Tracks may start unheld and be adopted ([`super::sensor_to_leader::UNHELD`]): a factored
    /// stream under the regional rule.
    pub adopts: bool,
}

impl Bounds {
    /// `track` is a track of the field; `what` names where it was read.
    pub(crate) fn track(&self, what: &str, track: u32) -> Result<(), String> {
        let n = self.tracks;
        require(track < n, || {
            format!("{what} = {track} is not a track (there are {n})")
        })
    }

    /// `index` is a leader of the stream; `what` names where it was read.
    pub(crate) fn leader(&self, what: &str, index: u16) -> Result<(), String> {
        let l = self.leaders;
        require((index as usize) < l, || {
            format!("{what} = {index} is not a leader (there are {l})")
        })
    }
}

/// A broken bound as the error of message `what`, as [`Valid`](super::Valid)'s
/// errors are.
pub(crate) fn invalid(what: &'static str, problem: String) -> WireError {
    WireError::Invalid { what, problem }
}

/// The field the tests of every message's bounds share: 4 tracks, 2
/// leaders, no identities, tracks held from the start.
#[cfg(test)]
impl Bounds {
    pub(crate) fn of_tests() -> Self {
        Bounds {
            tracks: 4,
            leaders: 2,
            identities: false,
            adopts: false,
        }
    }
}
