//! # idmesh-sensor — the sensor process
//!
//! The process that turns a trace (a file, standard input, producers on
//! the ingest key) into the deployment's event stream: it sequences the
//! events, routes each item to the leaders whose sets it may change, keeps
//! every batch until the leader says its state is safe past it, and places
//! the consistent cuts the coordinator's queries are answered at (Section
//! 5.4 of the property-management paper; docs/design/architecture.md).
//! What the events are made from — simulated crowds, real pedestrian
//! scenes — is the pure crate `idmesh-sim` (`world/sim/`).
//!
//! A map of the crate, the pure state machine first (private modules
//! behind the re-exports below; `journal` stays a public namespace: its
//! records, reading and paths):
//! - `machine` — the sensor as a pure state machine ([`Gateway`]):
//!   router, batch logs, durable marks and cuts; lines and requests in,
//!   batches and answers out.
//! - `driver` — the tokio/Zenoh I/O around it: publishes the stream at a
//!   rate, places cuts for queries and answers leaders' follow requests.
//! - `router` — sequences the events and routes each item to the leaders
//!   whose sets it may change (pure).
//! - `feed` — where events come from: a trace file, standard input,
//!   producers on the ingest key.
//! - `extraction` — with extraction on, a tracker's reports (positions,
//!   class scores, identity reads) become the stream's events
//!   (`idmesh-extract`, in the stream's one order).
//! - `ingest` — live ingestion: which producers' lines (ingest key,
//!   standard input) enter the order; dedup, validation, counters (pure).
//! - `cuts` — cut requests: now, or at a future event count.
//! - `mesh` — several sensors: each one's intake, merged by all into
//!   one order (pure).
//! - `peers` — several sensors: the tasks that fetch every other
//!   sensor's intake.
//! - [`journal`] — what changed the sensor's state, on disk, so a sensor
//!   killed and restarted resumes where it was.
//! - `batch_log` — the batches sent each leader, kept until it says its
//!   state is safe past them.
//! - `standby` — the sensor's journal replicated to its standby on
//!   another host (the pure rules in `machine::replication`), and the
//!   standby that takes the sensor role over through the voters.

mod batch_log;
mod cuts;
mod driver;
mod extraction;
mod feed;
mod ingest;
pub mod journal;
mod lease;
mod machine;
mod mesh;
mod peers;
pub mod ros2;
mod router;
mod standby;

// The sensor as a pure state machine, and what it answers a cut.
pub use cuts::{CutParameters, Placed};
pub use machine::{CutOutcome, Gateway};
// Sequencing and routing the events to the leaders.
pub use router::{LeaderPlace, Router, RouterConfig, RouterError};
// Where events come from: a trace, standard input, live producers, a tracker.
pub use extraction::Extraction;
pub use feed::{lines_of, InputLine, Source};
pub use ingest::Offer;
// The process: its I/O loop, its settings and the other sensors.
pub use driver::{run, Faults, GatewayConfig};
pub use mesh::MeshConfig;
// The sensor's standby: its copy of the journal, its takeover, the lease.
pub use lease::LeaseClock;
// The replication of the journal to the standby, as a pure machine (the
// network simulator drives it as the driver does).
pub use machine::replication::{Apply, Copy, Presence, Replication, Step};
pub use machine::standbys::{Change, Standbys};
pub use standby::{
    claim_own, keep_lease, serving_from, stand_by, standby_path, Owned, StandbyConfig,
    StandbyError, Standing, TookOver, STANDBY_ROLE,
};
#[cfg(test)]
mod tests;
