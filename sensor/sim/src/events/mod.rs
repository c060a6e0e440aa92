//! From ground-truth motion to the events a tracker would report, as in the
//! paper's Section 6: "We log a mixing event whenever two targets get close
//! to each other within some distance and an observation event whenever one
//! target is separated from all the other targets for some distance."
//!
//! - [`event`] — the generator's own timed events (`mix`, `observe`, `move`,
//!   `truth`), independent of the wire types of `idmesh-protocol`.
//! - [`sensor_model`] — what an observation reports about a red or blue
//!   target (default: the colour-histogram model of the trace spec).
//! - [`assignment`] — which target is on which track, and how a mix that
//!   the tracker resolves wrongly exchanges them.
//! - [`mixing`] — detecting pairs that come within the mixing distance.
//! - [`observing`] — detecting isolated targets, at a limited rate.
//! - [`extractor`] — the three above together, step by step.

pub mod assignment;
pub mod event;
pub mod extractor;
pub mod mixing;
pub mod observing;
pub mod sensor_model;

pub use assignment::Assignment;
pub use event::{SimEvent, TimedEvent};
pub use extractor::{ExtractionParams, Extractor};
pub use mixing::MixDetector;
pub use observing::ObservationScheduler;
pub use sensor_model::{SensorModel, SensorOutcome};
