//! Metrics: how well the pipeline separated and tracked.
//!
//! - [`separation`] — Amari index and max |corr| (FastICA quality).
//! - [`tracking`] — error distance, its deviation and coverage (Section
//!   VI-B).
//! - [`assign`] — pairing estimated paths with targets.

pub mod assign;
pub mod separation;
pub mod tracking;

pub use tracking::TrackingMetrics;
