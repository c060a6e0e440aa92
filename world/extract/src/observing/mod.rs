//! Observations: when a track is isolated, what its class scores say about
//! the property (the property paper's Section 6 observation event, and the
//! likelihood of its Section 3.4).
//!
//! - [`scheduler`] — which tracks are isolated and due for a look.
//! - [`score_mapping`] — class scores to `observe` likelihoods, and the
//!   temperature fit that calibrates them.

pub(crate) mod scheduler;
pub(crate) mod score_mapping;

pub use scheduler::ObservationScheduler;
pub use score_mapping::ScoreMapping;
