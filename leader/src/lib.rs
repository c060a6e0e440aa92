//! # idmesh-leader — the leader actor
//!
//! An async process that owns the coefficient sets touching the tracks it
//! surveils, applies events and exchanges sets with peers (Section 5.4 of the
//! property-management paper; built by the distributed-runtime issue).
