//! Sets handed from one leader to another (Algorithm 4's exchange at a
//! cross-leader mix, and the handover when a track changes region). A
//! transfer is tied to the seq of the item that caused it; the receiver
//! adds the sets at exactly that point of its own stream.

use serde::{Deserialize, Serialize};

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Transfer {
    pub version: u16,
    /// Index of the sending leader.
    pub from: u16,
    pub seq: u64,
    pub sets: Vec<WireSet>,
}
super::versioned!(Transfer, "transfer");

/// A set φ_{red|blue} with its mass on the absolute (log) scale.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct WireSet {
    pub red: Vec<u32>,
    pub blue: Vec<u32>,
    pub ln_mass: f64,
}
