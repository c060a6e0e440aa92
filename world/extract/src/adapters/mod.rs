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
//! - [`ros2`] — ROS 2 tracker messages (`vision_msgs` detections,
//!   Autoware's tracked objects) in CDR, live or in rosbag2 MCAP bags.

pub mod eth_ucy;
pub mod homography;
pub mod jsonl;
pub mod mot;
pub mod ros2;

use crate::extractor::{Report, ReportError};
use idmesh_protocol::trace::Problem;
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
    /// The line breaks a rule of the trace format (a line of reports is a
    /// trace line).
    #[error("{0}")]
    Line(Problem),
    /// The row reads but the extractor refuses the report.
    #[error("{0}")]
    Report(ReportError),
}

impl RowProblem {
    /// A short, stable name of the reason, for counting rejected rows.
    pub(crate) fn reason(&self) -> &'static str {
        match self {
            RowProblem::Malformed(_) => "malformed row",
            RowProblem::Line(problem) => match problem {
                Problem::UnknownTrack { .. } => "unknown track",
                Problem::NonFiniteTime { .. } => "non-finite time",
                Problem::NonFinitePosition { .. } | Problem::DetectNonFinitePosition { .. } => {
                    "non-finite position"
                }
                Problem::EmptyScores
                | Problem::BadScore { .. }
                | Problem::ScoresDoNotSumToOne { .. } => "bad scores",
                Problem::HalfIdentityRead
                | Problem::DetectNoIdentities
                | Problem::DetectUnknownIdentity { .. }
                | Problem::DetectBadAccuracy(_) => "bad identity read",
                _ => "malformed row",
            },
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
    pub(crate) fn malformed(file: &str, line: usize, reason: impl Into<String>) -> Self {
        RowError {
            file: file.to_string(),
            line,
            problem: RowProblem::Malformed(reason.into()),
        }
    }

    pub(crate) fn report(file: &str, line: usize, error: ReportError) -> Self {
        RowError {
            file: file.to_string(),
            line,
            problem: RowProblem::Report(error),
        }
    }
}

/// Every row of a file: a report or why not.
pub(crate) type Rows = Vec<Result<Located, RowError>>;

/// How many bad lines a reader of reports goes on past (`--max-errors`,
/// the same on `idmesh extract`, `idmesh replay --topology` and a sensor's
/// own input): each bad line is named and counted; the first one past the
/// budget stops the reading. With 0, the default, the first bad line does.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub struct ErrorBudget {
    /// Bad lines allowed.
    pub max: usize,
    /// Bad lines so far.
    pub count: usize,
}

/// Reading stopped at a bad line: the line's own message, and, when a
/// budget was spent, how many came before.
#[derive(Debug, Clone, PartialEq, Error)]
pub enum Stopped<E: std::fmt::Display + std::fmt::Debug> {
    /// The first bad line, with no budget.
    #[error("{0}")]
    First(E),
    /// More bad lines than the budget; the last one.
    #[error("{last} (bad line {count}: more than --max-errors {max})")]
    TooMany { last: E, count: usize, max: usize },
}

impl ErrorBudget {
    pub fn new(max: usize) -> Self {
        ErrorBudget { max, count: 0 }
    }

    /// Counts one bad line: `Ok` while within the budget (the caller skips
    /// the line and names it), else why reading stops.
    pub fn spend<E: std::fmt::Display + std::fmt::Debug>(
        &mut self,
        error: E,
    ) -> Result<E, Stopped<E>> {
        self.count += 1;
        if self.max == 0 {
            Err(Stopped::First(error))
        } else if self.count > self.max {
            Err(Stopped::TooMany {
                last: error,
                count: self.count,
                max: self.max,
            })
        } else {
            Ok(error)
        }
    }
}

/// A frame number as seconds, checking the frame rate.
pub(crate) fn frame_time(frame: f64, fps: f64) -> f64 {
    frame / fps
}

/// Checks a frame rate (frames per second).
pub(crate) fn check_fps(fps: f64) -> Result<(), String> {
    if fps.is_finite() && fps > 0.0 {
        Ok(())
    } else {
        Err(format!("frame rate must be finite and > 0, got {fps}"))
    }
}
