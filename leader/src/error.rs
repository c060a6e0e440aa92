//! Why a leader could not apply what it was sent.

use idmesh_belief::BeliefError;

#[derive(Debug, thiserror::Error)]
pub enum LeaderError {
    #[error("this leader ({0}) is not in the stream's list of leaders")]
    NotListed(String),
    #[error("bad transfer: {0}")]
    BadTransfer(String),
    #[error("protocol violation: {0}")]
    Unexpected(&'static str),
    #[error(transparent)]
    Belief(#[from] BeliefError),
    #[error(transparent)]
    Placement(#[from] idmesh_placement::PlacementError),
    #[error("unreadable snapshot: {0}")]
    Snapshot(String),
}

/// A Zenoh call failed (declaring, sending, querying).
#[derive(Debug, thiserror::Error)]
#[error("zenoh: {what}: {message}")]
pub struct MeshError {
    pub what: &'static str,
    pub message: String,
}

impl MeshError {
    pub(crate) fn new(what: &'static str, error: impl std::fmt::Display) -> Self {
        MeshError {
            what,
            message: error.to_string(),
        }
    }
}

/// Why a leader process stopped.
#[derive(Debug, thiserror::Error)]
pub enum RunError {
    #[error(transparent)]
    Mesh(#[from] MeshError),
    #[error(transparent)]
    Journal(#[from] crate::journal::JournalError),
    #[error("cannot restore the leader: {0}")]
    Restore(#[from] LeaderError),
}
