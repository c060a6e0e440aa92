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
//! - [`extractor`] — the simulated sensor, step by step: the meetings and
//!   isolated targets of each step come from `idmesh-extract` (the same
//!   [`FrameSensing`] that extracts events from a real tracker's reports);
//!   only the swaps and the sensor's outcomes are drawn here.
//!
//! Detecting mixes ([`MixDetector`]) and isolated targets
//! ([`ObservationScheduler`]) lives in `idmesh-extract`; they are
//! re-exported here for the simulator's users.

pub(crate) mod assignment;
pub(crate) mod event;
pub(crate) mod extractor;
pub(crate) mod sensor_model;

pub use idmesh_extract::MixDetector;
pub use idmesh_extract::ObservationScheduler;

pub(crate) use assignment::Assignment;
pub use event::{SimEvent, TimedEvent};
pub use extractor::{ExtractionParams, Extractor};
pub use sensor_model::SensorModel;
