//! # idmesh-eval — the evaluation harness
//!
//! What the `idmesh` binary runs offline, on traces, with no network: the
//! numbers of docs/results.md and the tools to check a filter by hand.
//!
//! - [`replay`] — `idmesh replay`: one filter over a recorded trace, a
//!   JSON line of answers at every `truth` line and a summary.
//! - [`eval`] — `idmesh eval`: the grid of methods × scenarios behind
//!   docs/results.md, its tables and plots, stamped with the digest of the
//!   code that decides its numbers (`build.rs`).
//! - `filters` — the one factory that turns a method into a running
//!   property filter, for both.
//! - `machine` — the machine and the date a generated page names
//!   (results.md's, and `idmesh bench --out`'s).
//!
//! `eval` and `replay` stay public namespaces, one per subcommand (each
//! has its arguments and its entry point); their submodules, `filters`
//! and `machine` are private behind re-exports.

pub mod eval;
mod filters;
mod machine;
pub mod replay;

// The machine and the date a generated page names.
pub use machine::{description, today};
