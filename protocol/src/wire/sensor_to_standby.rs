//! The sensor's journal, replicated to its standby: the process on
//! another host (its own disk) that keeps a copy of the journal and takes
//! the sensor role over when the sensor's host is lost.
//!
//! The sensor asks (a Zenoh get on `P/sensor/<name>/replicate`) with a
//! [`Replicate`] — the records it just appended, or its whole journal in
//! compacted form — and the standby answers, once they are on its disk
//! and fsynced, with a [`Replicated`]: how far its copy goes. Nothing that
//! depends on the records leaves the sensor before that answer (while the
//! standby is up), so what the sensor acknowledged is never lost with its
//! host.
//!
//! Positions count records within one *reset*: a whole journal sent
//! starts a reset (numbered by the sender, within its `incarnation`, a
//! number drawn at its start), and appends go on from its end. A copy
//! whose position is not where an append starts takes nothing and says
//! where it is; the sensor then sends the whole journal again.

use super::valid::{require, MAX_SNAPSHOT_BYTES};
use super::Valid;
use serde::{Deserialize, Serialize};

/// Records of the sensor's journal for its standby's copy.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Replicate {
    pub version: u16,
    /// The sensor whose journal this is.
    pub sensor: String,
    /// The epoch at which the sender holds the sensor role (0 without
    /// voters). The standby notes the newest it holds every record of:
    /// a takeover names that epoch, and loses once the sensor has moved
    /// past it (as it does before it goes on without the standby).
    pub epoch: u64,
    /// The sensor process's run (drawn at its start): positions of one
    /// run mean nothing to another.
    pub incarnation: u64,
    /// The reset these records belong to.
    pub reset: u64,
    /// `records` replace the copy (a new reset, from position 0): the
    /// whole journal, compacted.
    pub whole: bool,
    /// The position of the first record within the reset.
    pub first: u64,
    /// The records, each as the journal holds it (postcard).
    pub records: Vec<Vec<u8>>,
}
super::versioned!(Replicate, "journal replication");

/// The standby's word on its copy: which run and reset of the sensor it
/// follows, and how many records of that reset it holds on disk.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub struct Position {
    pub incarnation: u64,
    pub reset: u64,
    pub count: u64,
}

/// The standby's answer to a [`Replicate`].
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Replicated {
    pub version: u16,
    /// The standby process.
    pub standby: String,
    /// Its copy's position (None: it holds no copy of this run).
    pub position: Option<Position>,
}
super::versioned!(Replicated, "replication acknowledgement");

impl Valid for Replicate {
    fn problem(&self) -> Option<String> {
        let checks = || -> Result<(), String> {
            require(!self.sensor.is_empty(), || "it names no sensor".into())?;
            require(!self.whole || self.first == 0, || {
                format!("a whole journal that starts at record {}", self.first)
            })?;
            let bytes: usize = self.records.iter().map(Vec::len).sum();
            require(bytes <= MAX_SNAPSHOT_BYTES, || {
                format!("{bytes} bytes of records (at most {MAX_SNAPSHOT_BYTES})")
            })
        };
        checks().err()
    }
}

impl Valid for Replicated {
    fn problem(&self) -> Option<String> {
        require(!self.standby.is_empty(), || "it names no standby".into()).err()
    }
}
