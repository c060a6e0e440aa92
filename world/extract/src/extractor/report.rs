//! What a tracker reports about one track in one frame: where it is, and
//! optionally class scores and an identity read. The trace format's
//! `move` and `detect` lines (version 2) carry exactly this.

use idmesh_protocol::trace::{Detect, Move};
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;

/// One report. `track` is the tracker's own id (any u32); the
/// [`Roster`](super::Roster) maps it to a trace track.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Report {
    pub time: f64,
    pub track: u32,
    pub x: f64,
    pub y: f64,
    /// Class label to score, summing to 1.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub scores: Option<BTreeMap<String, f64>>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub identity: Option<IdentityRead>,
}

/// An identity read: `identity` is right with probability `accuracy`.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct IdentityRead {
    pub identity: u32,
    pub accuracy: f64,
}

impl Report {
    /// A position-only report.
    pub fn at(time: f64, track: u32, x: f64, y: f64) -> Self {
        Report {
            time,
            track,
            x,
            y,
            scores: None,
            identity: None,
        }
    }
}

impl From<&Report> for Detect {
    /// The `detect` line that carries a report (its scores and identity
    /// read, when it has them).
    fn from(r: &Report) -> Self {
        Detect {
            time: r.time,
            track: r.track,
            x: r.x,
            y: r.y,
            scores: r.scores.clone(),
            identity: r.identity.map(|i| i.identity),
            accuracy: r.identity.map(|i| i.accuracy),
        }
    }
}

impl From<Move> for Report {
    fn from(m: Move) -> Self {
        Report::at(m.time, m.track, m.x, m.y)
    }
}

impl From<Detect> for Report {
    /// A half identity read (one of identity and accuracy) is dropped
    /// here; the trace reader refuses such a line before it gets here.
    fn from(d: Detect) -> Self {
        Report {
            time: d.time,
            track: d.track,
            x: d.x,
            y: d.y,
            scores: d.scores,
            identity: d
                .identity
                .zip(d.accuracy)
                .map(|(identity, accuracy)| IdentityRead { identity, accuracy }),
        }
    }
}
