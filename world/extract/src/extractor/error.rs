//! Why a report was refused. The extractor never skips a report silently:
//! each refused one is an error the caller counts (by [`ReportError::reason`])
//! and reports with its place, `FILE:LINE: reason`.

use idmesh_protocol::trace::Problem;
use thiserror::Error;

/// A refused report; the extractor's state is as before it.
#[derive(Debug, Clone, PartialEq, Error)]
pub enum ReportError {
    #[error("time {time} is not a finite number")]
    NonFiniteTime { time: f64 },
    #[error("position {field} = {value} is not a finite number")]
    NonFinitePosition { field: &'static str, value: f64 },
    #[error("time {time} is before time {previous} of an earlier report: reports must come in time order")]
    OutOfOrder { time: f64, previous: f64 },
    #[error("track {track} is not in the roster of {tracks} tracks fixed {fixed}: a track that appears mid-stream is refused")]
    UnknownTrack {
        track: u32,
        tracks: usize,
        fixed: &'static str,
    },
    #[error("track {track} is reported twice at time {time}")]
    DuplicateTrack { track: u32, time: f64 },
    /// The scores break the trace format's rule (in [0, 1], summing to 1).
    #[error("{0}")]
    Scores(Problem),
    #[error("identity read {identity} is not one of the {identities} identities (one per track)")]
    UnknownIdentity { identity: u32, identities: usize },
    #[error("identity read accuracy = {0} is not in (0, 1]")]
    BadAccuracy(f64),
    #[error("an identity read needs identities: turn them on in the extractor's configuration")]
    IdentitiesOff,
}

impl ReportError {
    /// A short, stable name of the reason, for counting rejected rows.
    pub(crate) fn reason(&self) -> &'static str {
        match self {
            ReportError::NonFiniteTime { .. } => "non-finite time",
            ReportError::NonFinitePosition { .. } => "non-finite position",
            ReportError::OutOfOrder { .. } => "out of time order",
            ReportError::UnknownTrack { .. } => "unknown track",
            ReportError::DuplicateTrack { .. } => "duplicate track",
            ReportError::Scores(_) => "bad scores",
            ReportError::UnknownIdentity { .. }
            | ReportError::BadAccuracy(_)
            | ReportError::IdentitiesOff => "bad identity read",
        }
    }
}
