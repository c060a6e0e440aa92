//! A cut of the event stream for a query: the sensor puts a `Cut` item with
//! the query's tag into every leader's stream and says where (postcard reply
//! to a get on `P/sensor/<name>/cut?tag=<tag>`, `;rows` for an identity
//! query, whose cut asks the leaders for their rows too). Also the
//! gateway's counters, which the coordinator's stats answer includes.

use serde::{Deserialize, Serialize};

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct CutPlaced {
    pub version: u16,
    pub sensor: String,
    /// The seq of the cut item.
    pub seq: u64,
    /// Trace events the cut includes (the watermark).
    pub events: u64,
    pub leaders: Vec<String>,
    pub tracks: u32,
    pub red: Option<u32>,
    /// The stream is over (the sensor read its whole source).
    pub finished: bool,
    /// An identity stream: leaders hold rows of an information matrix.
    pub identities: bool,
}
super::versioned!(CutPlaced, "cut");

/// A sensor gateway's counters (JSON, `P/sensor/<name>/stats`).
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct SensorStats {
    pub sensor: String,
    /// Follow and resend requests refused: undecodable, malformed, or
    /// naming a leader or track the stream does not have.
    pub rejected: u64,
}
