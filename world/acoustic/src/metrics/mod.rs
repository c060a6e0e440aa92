//! Metrics: how well the pipeline separated and tracked.
//!
//! - [`separation`] — Amari index and max |corr| (FastICA quality).
//! - [`tracking`] — error distance, its deviation and coverage (Section
//!   VI-B).
//! - [`assign`] — pairing estimated paths with targets.

pub(crate) mod assign;
pub(crate) mod separation;
pub(crate) mod tracking;
