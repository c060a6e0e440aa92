//! Why a leader could not apply what it was sent.

use idmesh_belief::BeliefError;

#[derive(Debug, thiserror::Error)]
pub enum LeaderError {
    #[error("event batch {got} arrived where {expected} was expected: batches were lost")]
    Gap { expected: u64, got: u64 },
    #[error(
        "sets of item {seq} from leader {from} arrived after this leader passed it (at {position})"
    )]
    LateTransfer { seq: u64, from: u16, position: u64 },
    #[error("this leader ({0}) is not in the stream's list of leaders")]
    NotListed(String),
    #[error("bad transfer: {0}")]
    BadTransfer(String),
    #[error("protocol violation: {0}")]
    Unexpected(&'static str),
    #[error(transparent)]
    Belief(#[from] BeliefError),
}

/// A Zenoh call failed (declaring, sending, querying).
#[derive(Debug, thiserror::Error)]
#[error("zenoh: {what}: {message}")]
pub struct MeshError {
    pub what: &'static str,
    pub message: String,
}

impl MeshError {
    pub fn new(what: &'static str, error: impl std::fmt::Display) -> Self {
        MeshError {
            what,
            message: error.to_string(),
        }
    }
}
