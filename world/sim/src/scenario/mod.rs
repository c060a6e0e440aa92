//! Scenarios: the whole path from a motion model to a trace, as in the
//! paper's Section 6 — "simulated crowds of up to 100 moving targets
//! wearing either red or blue clothes", mixing and observation events
//! extracted by distance, the share of mixes steered by the distances.
//!
//! - [`builder`] — the [`Scenario`] builder, its options and defaults.
//! - [`options`] — model, red choice and run length.
//! - [`run`] — generation (deterministic per seed).
//! - [`trace`] — the [`GeneratedTrace`] it returns.
//! - [`progress`] — the progress hook for a command line's progress bar.
//! - [`trace_out`] — writing a [`GeneratedTrace`] as a trace file.
//! - [`error`] — what can go wrong.
//! - [`identity`] — identity traces: identities, the RFID reader model;
//!   [`identity_out`] weaves them into the trace lines.

pub(crate) mod builder;
pub(crate) mod error;
pub(crate) mod identity;
pub(crate) mod identity_out;
pub(crate) mod options;
pub(crate) mod progress;
pub(crate) mod run;
pub(crate) mod trace;
pub(crate) mod trace_out;

pub use builder::Scenario;
pub use error::ScenarioError;
pub use identity::IdentityTrace;
pub use options::Model;
pub use options::SceneSource;
pub use trace::GeneratedTrace;
pub use trace::{TraceHeader, TraceStats};

#[cfg(test)]
mod extract_agreement_tests;
#[cfg(test)]
mod identity_tests;
#[cfg(test)]
mod tests;
