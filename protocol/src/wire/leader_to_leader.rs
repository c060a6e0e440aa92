//! Sets handed from one leader to another (Algorithm 4's exchange at a
//! cross-leader mix, and the handover when a track changes region). A
//! transfer is tied to the seq of the item that caused it; the receiver
//! adds the sets at exactly that point of its own stream.
//!
//! On an identity stream the same transfer carries rows of the information
//! matrix (Shin et al., Section 4): at a cross-leader mix, each leader's
//! row of its mixed track as it was before the mix (both then compute the
//! same fit); at a handover, the row of the track that changes region.

use super::factored::WireComponent;
use super::identity::WireTree;
use serde::{Deserialize, Serialize};

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Transfer {
    pub version: u16,
    /// Index of the sending leader.
    pub from: u16,
    pub seq: u64,
    pub sets: Vec<WireSet>,
    pub rows: Vec<WireRow>,
    /// Components of the factored belief (a factored stream; sets are
    /// then empty).
    pub components: Vec<WireComponent>,
    /// Trees of the factored identity belief, sent to the leader that
    /// mixes them (`Begin::factored_identity`).
    ///
    /// [`Begin::factored_identity`]: super::sensor_to_leader::Begin::factored_identity
    pub trees: Vec<WireTree>,
}
super::versioned!(Transfer, "transfer");

/// A set φ_{red|blue} with its mass on the absolute (log) scale.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct WireSet {
    pub red: Vec<u32>,
    pub blue: Vec<u32>,
    pub ln_mass: f64,
}

/// Row `track` of an information matrix: accumulated log-likelihoods, one
/// per identity.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct WireRow {
    pub track: u32,
    pub ln_likelihoods: Vec<f64>,
}

/// A restarted leader asks a peer for the transfers the peer sent it with
/// seq after `after` (sent while it was down, they were lost): postcard,
/// the payload of a get on `P/leader/<peer>/sent`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct TransfersWanted {
    pub version: u16,
    /// The asking leader's index.
    pub to: u16,
    pub after: u64,
}
super::versioned!(TransfersWanted, "transfers request");

/// Transfers in order: every transfer one input of the sender made for
/// this leader, put on `P/leader/<l>/transfer` as one message (a crowd's
/// batch hands several tracks to the same neighbour, and each message costs
/// both processes a wake-up); and the reply to a [`TransfersWanted`].
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct TransfersSent {
    pub version: u16,
    pub transfers: Vec<Transfer>,
}
super::versioned!(TransfersSent, "transfers reply");
