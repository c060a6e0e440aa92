//! The user-facing answers, JSON with Zenoh's JSON encoding.
//! `P/query/marginals`, `P/query/track/<t>` and `P/query/stats`; an answer
//! that cannot be given is an error reply carrying [`QueryError`].

use super::coordinator_to_leader::LeaderStats;
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;

/// Which events an answer includes: per sensor, how many of its events.
pub type Watermark = BTreeMap<String, u64>;

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct MarginalsAnswer {
    pub watermark: Watermark,
    pub tracks: u32,
    pub red: Option<u32>,
    pub p_red: Vec<f64>,
    pub predicted_red: Vec<u32>,
    pub leaders: u32,
    pub coefficients: u64,
    /// The sensor read its whole source: the answer covers the stream.
    pub finished: bool,
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct TrackAnswer {
    pub watermark: Watermark,
    pub track: u32,
    pub p_red: f64,
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct StatsAnswer {
    pub leaders: Vec<LeaderStats>,
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct QueryError {
    pub error: String,
}
