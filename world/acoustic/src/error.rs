//! What can go wrong in an acoustic tracking run.

use super::pipeline::separate::FastIcaError;
use idmesh_protocol::trace::TraceError;

/// An acoustic run's error: which setting is wrong, or which step failed
/// where.
#[derive(Debug, thiserror::Error)]
pub enum AcousticError {
    #[error("acoustic config: {0}")]
    Config(String),
    #[error("separation of sensor group {group} in time slot {slot}: {source}")]
    Separation {
        group: usize,
        slot: usize,
        #[source]
        source: FastIcaError,
    },
    #[error("acoustic trace: {0}")]
    Trace(#[from] TraceError),
}
