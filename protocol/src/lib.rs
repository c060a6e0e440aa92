//! # idmesh-protocol — everything on the wire
//!
//! Every message and key expression idmesh exchanges, and the trace format
//! (shared/spec/trace.md) that simulators write, sensors publish and replay
//! and scoring read. Types and their decoding only: no inference logic.
