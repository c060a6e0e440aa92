//! The trace format (shared/spec/trace.md; version 2, which adds the
//! `detect` line, in docs/guide/trace-format.md): the record of what the
//! sensors of a field reported, plus ground truth when there is any.
//!
//! Private modules, their items re-exported below: `line` (one type per
//! line kind), `parse` (text to a [`Line`], with precise messages),
//! `validate` (the spec's rules, per line and per sequence: [`Validator`]),
//! `problem` (why a line is rejected: [`Problem`]), `error` ([`TraceError`],
//! a problem at `FILE:LINE`), `reader` and `writer` (validating
//! [`TraceReader`] and [`TraceWriter`]). Public: [`as_json`], the serde
//! `with` module of a line as its JSON object.

pub mod as_json;
mod error;
mod line;
mod parse;
mod problem;
mod reader;
mod validate;
mod writer;

#[cfg(test)]
mod tests;

// One type per line kind, and the format's name and versions.
pub use line::{
    Detect, Header, Identify, Line, Mix, Move, Observe, Truth, FORMAT, VERSION, VERSION_2,
};
// The spec's rules, and why a line breaks them.
pub use error::TraceError;
pub use problem::Problem;
pub use validate::{check_scores, Validator};
// Reading and writing whole traces, validated.
pub use reader::{NumberedLine, TraceReader};
pub use writer::TraceWriter;
