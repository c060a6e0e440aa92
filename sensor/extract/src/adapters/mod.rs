//! Readers of what trackers and annotators write, each turning a file (or
//! standard input) into [`Report`]s with their line numbers, or an error
//! `FILE:LINE: reason` per bad row — never a row skipped silently.
//!
//! - [`mot`] — MOTChallenge result files, image boxes to the ground by a
//!   scale or a [`homography`].
//! - [`eth_ucy`] — the ETH/UCY `obsmat` (8 columns) and four-column
//!   (`biwi`, `crowds`, `students`) annotation files.
//! - [`jsonl`] — JSON lines, one `move` or `detect` line of the trace
//!   format (version 2) per line, with an optional header.

pub mod eth_ucy;
pub mod homography;
pub mod jsonl;
pub mod mot;

use crate::extractor::{Report, ReportError};
use thiserror::Error;

/// A report and the 1-based line it came from.
#[derive(Debug, Clone, PartialEq)]
pub struct Located {
    pub line: usize,
    pub report: Report,
}

/// What is wrong with a row.
#[derive(Debug, Clone, PartialEq, Error)]
pub enum RowProblem {
    /// The row is not what its format requires.
    #[error("{0}")]
    Malformed(String),
    /// The row reads but the extractor refuses the report.
    #[error("{0}")]
    Report(ReportError),
}

impl RowProblem {
    /// A short, stable name of the reason, for counting rejected rows.
    pub fn reason(&self) -> &'static str {
        match self {
            RowProblem::Malformed(_) => "malformed row",
            RowProblem::Report(e) => e.reason(),
        }
    }
}

/// A bad row, at its place.
#[derive(Debug, Clone, PartialEq, Error)]
#[error("{file}:{line}: {problem}")]
pub struct RowError {
    pub file: String,
    pub line: usize,
    pub problem: RowProblem,
}

impl RowError {
    pub fn malformed(file: &str, line: usize, reason: impl Into<String>) -> Self {
        RowError {
            file: file.to_string(),
            line,
            problem: RowProblem::Malformed(reason.into()),
        }
    }

    pub fn report(file: &str, line: usize, error: ReportError) -> Self {
        RowError {
            file: file.to_string(),
            line,
            problem: RowProblem::Report(error),
        }
    }
}

/// Every row of a file: a report or why not.
pub type Rows = Vec<Result<Located, RowError>>;

/// A frame number as seconds, checking the frame rate.
pub(crate) fn frame_time(frame: f64, fps: f64) -> f64 {
    frame / fps
}

/// Checks a frame rate (frames per second).
pub fn check_fps(fps: f64) -> Result<(), String> {
    if fps.is_finite() && fps > 0.0 {
        Ok(())
    } else {
        Err(format!("frame rate must be finite and > 0, got {fps}"))
    }
}
