//! # idmesh-extract — from what a tracker reports to events
//!
//! The sensor stage between a tracker and the belief. A tracker reports,
//! frame after frame, where each of its tracks is (`move`), and sometimes
//! what its classifier thinks a track is (class scores) or an identity it
//! read (`detect`, trace format version 2). The [`Extractor`] turns those
//! reports into the events the belief consumes, as the property paper's
//! Section 6 derives them from motion: a `mix` when two tracks meet (with a
//! swap probability from a [`MeetingModel`]), an `observe` when a track is
//! isolated and has class scores (likelihoods from a [`ScoreMapping`]), an
//! `identify` for every identity read.
//!
//! The extractor has no randomness: the same reports in the same order
//! give the same events, and its state serializes so that a live sensor
//! can journal it and resume. The simulator (`idmesh-sim`) is this stage
//! plus drawn swaps: it uses the same [`FrameSensing`] on the positions it
//! simulates.
//!
//! A map of the crate (private modules, what other crates use re-exported
//! below by concern; `adapters` stays a public namespace, one module per
//! outside format):
//! - `geometry` — points in metres, a neighbour grid.
//! - `meetings` — which pairs meet ([`MixDetector`], one meeting, one
//!   mix) and how likely a meeting swaps them ([`MeetingModel`]).
//! - `observing` — which tracks are isolated enough to observe
//!   ([`ObservationScheduler`]) and what class scores say
//!   ([`ScoreMapping`], with its calibration).
//! - `frame` — meetings and observations of one frame of positions.
//! - `extractor` — reports in, trace lines out: roster, time order,
//!   snapshot and restore.
//! - `pipeline` — a whole run: rows in, a validated trace out, a tally
//!   of reports, events and bad rows by reason.
//! - [`adapters`] — MOTChallenge, ETH/UCY obsmat and four-column files,
//!   JSON lines; each row an error `FILE:LINE: reason` or a report.

pub mod adapters;
mod extractor;
mod frame;
mod geometry;
mod meetings;
mod observing;
mod pipeline;

// Points in metres, a neighbour grid.
pub use geometry::{NeighbourGrid, Vec2};
// Meetings and observations, and the models that weigh them.
pub use frame::FrameSensing;
pub use meetings::{CalibrationError, Entering, Meeting, MeetingModel, MixDetector};
pub use observing::{ObservationScheduler, ScoreMapping};
// Reports in, trace lines out.
pub use extractor::{Extractor, ExtractorConfig, IdentityRead, Report, ReportError, RosterPolicy};
// A whole run: rows in, a validated trace and a tally out.
pub use pipeline::{every_id, extract_jsonl, extract_rows, read_reports, Run, Tally};
