//! Why a pedestrian scene could not be loaded. A malformed file is reported
//! as `FILE:LINE: reason`, like a compiler, so the line can be found at once.

use std::path::PathBuf;
use thiserror::Error;

#[derive(Debug, Error)]
pub enum SceneError {
    /// The file could not be read.
    // The OS error is the source, not part of the message: a report that
    // prints the chain (`{:#}`) would name it twice.
    #[error("{}: cannot read the scene", path.display())]
    Io {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
    /// The file was read but a line (or, for an empty file, the end of the
    /// file) is not what the format requires.
    #[error("{file}:{line}: {reason}")]
    Malformed {
        file: String,
        line: usize,
        reason: String,
    },
    /// The file is fine but the requested window of it is not possible.
    #[error("{file}: {reason}")]
    Window { file: String, reason: String },
}

impl From<idmesh_extract::adapters::RowError> for SceneError {
    fn from(e: idmesh_extract::adapters::RowError) -> Self {
        SceneError::Malformed {
            file: e.file,
            line: e.line,
            reason: e.problem.to_string(),
        }
    }
}
