//! The sensor gateway: the process that turns a trace (a file or a live
//! simulation) into the deployment's event stream.
//!
//! - [`router`] — sequences the events, keeps the log, and routes each item
//!   to the leaders whose sets it may change (pure, no I/O).
//! - [`core`] — the gateway as a pure state machine: router, batch logs,
//!   durable marks and cuts; lines and requests in, batches and answers
//!   out.
//! - [`actor`] — publishes the stream over Zenoh at a rate, places cuts for
//!   queries and answers leaders' follow requests.
//! - [`feed`] — where events come from: a trace file, standard input,
//!   producers on the ingest key.
//! - [`ingest`] — live ingestion: which producers' lines (ingest key,
//!   standard input) enter the order; dedup, validation, counters (pure).
//! - [`cuts`] — cut requests: now, or at a future event count.
//! - [`mesh`] — several sensors: each one's intake, merged by all into
//!   one order (pure).
//! - [`peers`] — several sensors: the tasks that fetch every other
//!   sensor's intake.
//! - [`journal`] — what changed the gateway's state, on disk, so a
//!   sensor killed and restarted resumes where it was.
//! - [`batch_log`] — the batches sent each leader, kept until it says its
//!   state is safe past them.

pub mod actor;
pub mod batch_log;
pub mod core;
pub mod cuts;
pub mod feed;
pub mod ingest;
pub mod journal;
pub mod mesh;
pub mod peers;
pub mod router;

pub use router::{LeaderPlace, Router, RouterConfig, RouterError};

#[cfg(test)]
mod tests;
