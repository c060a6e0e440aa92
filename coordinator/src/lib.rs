//! # idmesh-coordinator — lazy answers to user queries
//!
//! Collects local results from leaders only when a query asks for them
//! (built by the distributed-runtime issue).
