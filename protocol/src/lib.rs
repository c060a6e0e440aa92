//! # idmesh-protocol — everything on the wire
//!
//! Every message and key expression idmesh exchanges, and the trace format
//! (shared/spec/trace.md) that simulators write, sensors publish and replay
//! and scoring read. Types and their decoding only: no inference logic.
//!
//! A map of the crate (three public namespaces, each a vocabulary its
//! users navigate by name; the rest is private behind the facade below):
//! - [`trace`] — the trace format, version 1: one type per line kind
//!   ([`trace::Line`]), the spec's validity rules, a validating
//!   [`trace::TraceReader`] and a validating [`trace::TraceWriter`].
//! - [`wire`] — the distributed runtime's messages (postcard, versioned),
//!   its key expressions, the routing rule of the event stream and the
//!   JSON answers of the query API.
//! - [`start`] — [`StreamStart`]: what a trace header and a stream's
//!   `Begin` both say of the field.
//! - [`fuzzing`] — the fuzz targets of every decoder above, shared by
//!   cargo-fuzz (`fuzz/`) and the stable smoke run (`tests/fuzz_smoke.rs`).

pub mod fuzzing;
mod start;
pub mod trace;
pub mod wire;

// What a trace header and a stream's `Begin` share.
pub use start::StreamStart;
