//! Meetings: two tracks that come within the mixing distance may leave
//! with each other's target (the property paper's Section 6 mixing event).
//!
//! - [`mixing`] — which pairs enter contact, once per meeting (release
//!   distance hysteresis).
//! - [`meeting`] — what is known of a meeting when it starts: distance,
//!   predicted closest approach, relative speed.
//! - [`meeting_model`] — the swap probability of a meeting, and its fit.

pub(crate) mod meeting;
pub(crate) mod meeting_model;
pub(crate) mod mixing;

pub use meeting::Meeting;
pub use meeting_model::CalibrationError;
pub use meeting_model::MeetingModel;
pub use mixing::{Entering, MixDetector};
