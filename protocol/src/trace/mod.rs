//! The trace format (shared/spec/trace.md; version 2, which adds the
//! `detect` line, in docs/guide/trace-format.md): the record of what the
//! sensors of a field reported, plus ground truth when there is any.
//!
//! - [`line`](self::line) — one type per line kind.
//! - [`parse`](self::parse) — text to a [`Line`], with precise messages.
//! - [`validate`](self::validate) — the spec's rules, per line and per
//!   sequence ([`Validator`]).
//! - [`problem`](self::problem) — why a line is rejected ([`Problem`]).
//! - [`error`](self::error) — [`TraceError`], a problem at `FILE:LINE`.
//! - [`reader`](self::reader), [`writer`](self::writer) — validating
//!   [`TraceReader`] and [`TraceWriter`].

pub mod as_json;
pub mod error;
pub mod line;
pub mod parse;
pub mod problem;
pub mod reader;
pub mod validate;
pub mod writer;

#[cfg(test)]
mod tests;

pub use error::TraceError;
pub use line::{
    Detect, Header, Identify, Line, Mix, Move, Observe, Truth, FORMAT, SCORE_SUM_TOLERANCE,
    SUPPORTED_VERSIONS, VERSION, VERSION_2,
};
pub use problem::Problem;
pub use reader::{NumberedLine, TraceReader};
pub use validate::{check_scores, Validator};
pub use writer::TraceWriter;
