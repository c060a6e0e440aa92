//! # idmesh-coordinator — answers user queries lazily
//!
//! Nothing is pushed to the coordinator between queries (like the lazy
//! information matrix of the identity paper). A query asks the sensor
//! gateway for a cut of the event stream; every leader's partial sums at
//! that cut (Σ m, Σ m·W(|α|+1)/W(|α|) and per track the part of P(t red)·Z
//! that its sets fix — never the sets — or, factored, its components'
//! count vectors) are put by the leader when the cut reaches it, or asked
//! for; the coordinator adds them, normalizes and answers in JSON, with the
//! cut's watermark. A leader that does not answer in time makes the query
//! fail, naming it.
//!
//! A map of the crate (private modules behind the re-exports below;
//! `machine` stays a public namespace: the pure functions the simulation
//! tests drive one query through):
//! - [`machine`] — the coordinator's pure part: the replies to one query,
//!   whether they make a complete answer at one consistent cut, and the
//!   marginals they add up to.
//! - `driver` — the Zenoh I/O: the queryables of the user API
//!   ([`run`]) and the gets that collect the replies
//!   (`driver::gather`).
//! - `pushed` — the leaders' answers put at the cuts they reach, handed
//!   to the query waiting for each.
//! - `identity` — identity marginals from the leaders' rows of the
//!   information matrix, computed only when asked.
//! - `request` — a query's key and parameters, checked before any work.

mod driver;
mod identity;
pub mod machine;
mod pushed;
mod request;

// The coordinator process, its settings, and why a query failed.
pub use driver::gather::GatherError;
pub use driver::{run, CoordinatorConfig};
