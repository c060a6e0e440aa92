//! # idmesh-leader — the leader
//!
//! A leader surveils the tracks in its region, holds the coefficient sets
//! that touch them, applies the events that may change its sets, hands sets
//! to peers when tracks cross regions or mix across them, and answers the
//! coordinator with partial sums at consistent cuts (Section 5.4 of the
//! property-management paper; docs/design/architecture.md says why it converges).
//!
//! A map of the crate (private modules behind the re-exports below;
//! `door` and `journal` stay public namespaces):
//! - `state` — [`Leader`], the protocol as a pure state machine: a
//!   file per concern (inbox and reordering, applying, transfers, cuts,
//!   counters).
//! - `machine` — [`Node`], the leader's timers and recovery
//!   policy as a pure state machine around [`Leader`]: inputs and time in,
//!   outputs out (raft-rs `RawNode` style).
//! - `driver` — the tokio/Zenoh I/O around it, one per role:
//!   `driver::run`.
//! - [`door`] — bytes from the network to inputs, or rejected unharmed.
//! - `host` — the leader process: its own role, and the roles of
//!   processes gone for good that it adopts ([`run`]).
//! - [`journal`] — the durable state: a snapshot plus the input log a
//!   restarted (or adopted) leader replays.
//! - `standby` — the copy of another role's snapshot a process keeps
//!   as that role's standby, and the adoption that starts from it.
//! - With voters in the topology, who holds each role, claimed through
//!   them at an epoch, and the lease that stops a role the map gave to
//!   another, is `idmesh-claims` (`placement/claims/`), which the
//!   sensor's standby shares.
//! - The lock that lets one process at a time run a role (a role cut off
//!   by a partition is not adopted) is `idmesh-ownership`
//!   (`protocol/ownership/`), which the sensor shares.
//! - `error` — [`LeaderError`].

mod copies;
pub mod door;
mod driver;
mod error;
mod host;
pub mod journal;
mod machine;
mod standby;
mod state;

// The protocol as a pure state machine, and what goes wrong.
pub use error::LeaderError;
pub use state::{Action, Leader};
// The leader's timers and recovery policy around it, also pure.
pub use machine::{Ask, Holder, Input, Node, Output, Timers};
// The leader process.
pub use host::{run, HostConfig};
