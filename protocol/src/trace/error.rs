//! A trace error with its place: `FILE:LINE: reason`, the way compilers
//! report, so an editor can jump to the line.

use super::problem::Problem;
use thiserror::Error;

/// An error reading or writing a trace, at a line of a named source.
#[derive(Debug, Error)]
pub enum TraceError {
    /// The line breaks a rule of the format.
    #[error("{file}:{line}: {problem}")]
    Invalid {
        file: String,
        line: usize,
        problem: Problem,
    },
    /// The source or sink itself failed (e.g. not UTF-8, disk full).
    #[error("{file}:{line}: {cause}")]
    Io {
        file: String,
        line: usize,
        cause: std::io::Error,
    },
}

impl TraceError {
    /// The name of the trace (e.g. its path).
    #[cfg(test)]
    pub(crate) fn file(&self) -> &str {
        match self {
            TraceError::Invalid { file, .. } | TraceError::Io { file, .. } => file,
        }
    }

    /// The 1-based line number.
    pub(crate) fn line(&self) -> usize {
        match self {
            TraceError::Invalid { line, .. } | TraceError::Io { line, .. } => *line,
        }
    }

    /// The rule the line breaks, when that is what went wrong.
    pub fn problem(&self) -> Option<&Problem> {
        match self {
            TraceError::Invalid { problem, .. } => Some(problem),
            TraceError::Io { .. } => None,
        }
    }
}
