//! # idmesh-leader — the leader
//!
//! A leader surveils the tracks in its region, holds the coefficient sets
//! that touch them, applies the events that may change its sets, hands sets
//! to peers when tracks cross regions or mix across them, and answers the
//! coordinator with partial sums at consistent cuts (Section 5.4 of the
//! property-management paper; docs/architecture.md says why it converges).
//!
//! A map of the crate:
//! - [`state`] — [`Leader`], the protocol as a pure state machine.
//! - [`actor`] — the tokio/Zenoh process around it: [`actor::run`].
//! - [`door`] — bytes from the network to inputs, or rejected unharmed.
//! - [`journal`] — the durable input log a restarted leader replays.
//! - [`error`] — [`LeaderError`].

pub mod actor;
pub mod door;
pub mod error;
pub mod journal;
pub mod state;

pub use error::LeaderError;
pub use state::{combine, field_of, start, Action, Leader};
