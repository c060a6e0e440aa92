//! Metrics: how well the pipeline separated and tracked.
//!
//! - [`separation`] — Amari index and max |corr| (FastICA quality).

pub mod separation;
