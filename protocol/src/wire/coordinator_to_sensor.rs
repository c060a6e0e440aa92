//! A cut of the event stream for a query: the sensor puts a `Cut` item with
//! the query's tag into every leader's stream and says where (postcard reply
//! to a get on `P/sensor/<name>/cut?tag=<tag>`, `;rows` for an identity
//! query, whose cut asks the leaders for their rows too). Also the
//! gateway's counters, which the coordinator's stats answer includes, and
//! where the tracks are (JSON, like the counters).
//!
//! What a cut must be ([`Valid`]) sits below the types.

use super::valid::MAX_TRACKS;
use super::Valid;
use serde::{Deserialize, Serialize};

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct CutPlaced {
    pub version: u16,
    /// The epoch of the sensor role's holder that placed it
    /// ([`super::epoch`]; 0 without voters).
    pub epoch: u64,
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
    /// Several sensors: the events of each sensor's intake the cut
    /// includes, by sensor (the answer's watermark). Empty with one
    /// sensor: `events` is its.
    pub origins: Vec<(String, u64)>,
}
super::versioned!(CutPlaced, "cut");
super::epoch::epoched!(CutPlaced);

/// A sensor gateway's counters (in its stats answer, [`SensorStatus`];
/// its compacted journal keeps them).
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct SensorStats {
    pub sensor: String,
    /// Bad input refused: follow and resend requests undecodable,
    /// malformed, or naming a leader or track the stream does not have;
    /// ingest requests it could not read; ingested lines refused (bad or
    /// out of order, counted below too).
    pub rejected: u64,
    /// Lines taken from producers (ingest key and standard input) into the
    /// sensor's order.
    #[serde(default)]
    pub ingested: u64,
    /// Ingested lines a producer sent again: acknowledged, not applied
    /// twice.
    #[serde(default)]
    pub duplicates: u64,
    /// Ingested lines refused for what they say (malformed, an unknown
    /// track, not an event).
    #[serde(default)]
    pub bad_lines: u64,
    /// Ingested lines refused because their counter skipped ahead of the
    /// producer's next one.
    #[serde(default)]
    pub out_of_order: u64,
    /// Producers heard from.
    #[serde(default)]
    pub producers: u64,
    /// Times flow control held the stream: the sensor found itself its
    /// window past the slowest leader's progress.
    #[serde(default)]
    pub window_holds: u64,
    /// Several sensors: ingested lines refused as late, at or before a
    /// position this sensor had passed (an earlier time than its last
    /// event's, or a tick's).
    #[serde(default)]
    pub late: u64,
    /// Several sensors: events merged from every sensor's intake (its own
    /// included), and those merged twice that were applied once (one
    /// producer's event given to two sensors).
    #[serde(default)]
    pub merged: u64,
    #[serde(default)]
    pub merged_twice: u64,
    /// Journal records found damaged in one copy of the sensor's journal
    /// when it restarted, and taken from the other.
    #[serde(default)]
    pub journal_repaired: u64,
    /// Messages read from ROS 2 topics (`[sensor.ros2]`), and those
    /// refused because they did not decode (counted in `rejected` too).
    #[serde(default)]
    pub ros2_messages: u64,
    #[serde(default)]
    pub ros2_bad: u64,
}

/// What a sensor's stats key answers (JSON, `P/sensor/<name>/stats`): its
/// counters, which its journal keeps, and where its role stands now,
/// which it does not.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct SensorStatus {
    #[serde(flatten)]
    pub counters: SensorStats,
    /// With voters, the epoch at which the answering process holds the
    /// sensor role (0 without voters).
    #[serde(default)]
    pub epoch: u64,
    /// The standby the sensor's journal is replicated to now; None: no
    /// standby is up (the journal is on this process's disk alone), or
    /// the topology names none.
    #[serde(default)]
    pub standby: Option<String>,
}

/// Where every track was last seen and which leader surveils it, at the
/// point of the stream the sensor's router has reached (JSON,
/// `P/sensor/<name>/positions`). Only the sensor knows positions: leaders
/// are sent the handovers they cause, never the moves.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct SensorPositions {
    pub sensor: String,
    /// Trace events routed so far: the positions include exactly these.
    pub events: u64,
    pub finished: bool,
    /// The leaders, in stream order, and where each sits (None: the
    /// topology places no leader, tracks stay with leader t mod L).
    pub leaders: Vec<String>,
    pub places: Vec<Option<[f64; 2]>>,
    /// Each leader's region as a rectangle `[x0, y0, x1, y1]` when the
    /// regions are rectangles (fitted cells, cut to the box of the tracks
    /// seen); empty when they are not (fixed places: the points nearest
    /// each place) or not drawn yet. A leader's place is its centre.
    #[serde(default)]
    pub regions: Vec<Option<[f64; 4]>>,
    /// Per track: its last `move` position (None before any), and the
    /// index in `leaders` of the leader that surveils it
    /// ([`UNHELD`](super::sensor_to_leader::UNHELD) until its first item
    /// adopts it).
    pub positions: Vec<Option<[f64; 2]>>,
    pub owners: Vec<u16>,
}

impl SensorPositions {
    /// Checks what a reply from the network must be before it is believed:
    /// one owner per position, owners among the leaders (or unheld),
    /// finite numbers.
    pub fn check(&self) -> Result<(), String> {
        if self.places.len() != self.leaders.len() {
            return Err(format!(
                "{} places for {} leaders",
                self.places.len(),
                self.leaders.len()
            ));
        }
        if !self.regions.is_empty() && self.regions.len() != self.leaders.len() {
            return Err(format!(
                "{} regions for {} leaders",
                self.regions.len(),
                self.leaders.len()
            ));
        }
        if self.owners.len() != self.positions.len() {
            return Err(format!(
                "{} owners for {} tracks",
                self.owners.len(),
                self.positions.len()
            ));
        }
        if let Some(o) = self
            .owners
            .iter()
            .find(|&&o| o as usize >= self.leaders.len() && o != super::sensor_to_leader::UNHELD)
        {
            return Err(format!(
                "owner {o} is not one of the {} leaders",
                self.leaders.len()
            ));
        }
        let finite = |p: &Option<[f64; 2]>| p.is_none_or(|[x, y]| x.is_finite() && y.is_finite());
        if !self.positions.iter().chain(&self.places).all(finite) {
            return Err("a position is not a finite number".into());
        }
        let box_ok = |r: &Option<[f64; 4]>| {
            r.is_none_or(|r| r.iter().all(|v| v.is_finite()) && r[0] <= r[2] && r[1] <= r[3])
        };
        if !self.regions.iter().all(box_ok) {
            return Err("a region is not a rectangle of finite numbers".into());
        }
        Ok(())
    }
}

impl Valid for CutPlaced {
    fn problem(&self) -> Option<String> {
        let n = self.tracks;
        if !(1..=MAX_TRACKS).contains(&n) {
            return Some(format!("tracks = {n} is not in 1..={MAX_TRACKS}"));
        }
        match self.red {
            Some(k) if k > n => Some(format!("red = {k} > tracks = {n}")),
            _ => None,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::wire::{decode, encode, VERSION};

    #[test]
    fn positions_that_do_not_fit_are_refused_naming_why() {
        let good = SensorPositions {
            sensor: "s".into(),
            events: 3,
            finished: false,
            leaders: vec!["l0".into(), "l1".into()],
            places: vec![Some([0.0, 0.0]), Some([5.0, 5.0])],
            regions: vec![Some([0.0, 0.0, 2.5, 5.0]), None],
            positions: vec![Some([1.0, 2.0]), None],
            owners: vec![0, 1],
        };
        assert_eq!(good.check(), Ok(()));
        let owner = SensorPositions {
            owners: vec![0, 2],
            ..good.clone()
        };
        assert!(owner.check().unwrap_err().contains("owner 2"));
        // A track no leader surveils yet (early in a stream) is fine.
        let unheld = SensorPositions {
            owners: vec![0, super::super::sensor_to_leader::UNHELD],
            ..good.clone()
        };
        assert_eq!(unheld.check(), Ok(()));
        let short = SensorPositions {
            owners: vec![0],
            ..good.clone()
        };
        assert!(short.check().unwrap_err().contains("1 owners for 2 tracks"));
        let nan = SensorPositions {
            positions: vec![Some([f64::NAN, 0.0]), None],
            ..good.clone()
        };
        assert!(nan.check().unwrap_err().contains("finite"));
        let regions = SensorPositions {
            regions: vec![None],
            ..good.clone()
        };
        assert!(regions.check().unwrap_err().contains("1 regions"));
        let inside_out = SensorPositions {
            regions: vec![Some([3.0, 0.0, 1.0, 5.0]), None],
            ..good.clone()
        };
        assert!(inside_out.check().unwrap_err().contains("rectangle"));
        let places = SensorPositions {
            places: vec![None],
            ..good
        };
        assert!(places
            .check()
            .unwrap_err()
            .contains("1 places for 2 leaders"));
    }

    #[test]
    fn cuts_are_checked() {
        let cut = CutPlaced {
            version: VERSION,
            epoch: 0,
            sensor: "s".into(),
            seq: 1,
            events: 0,
            leaders: vec!["a".into()],
            tracks: 4,
            red: Some(5),
            finished: false,
            identities: false,
            origins: Vec::new(),
        };
        assert!(decode::<CutPlaced>(&encode(&cut))
            .unwrap_err()
            .to_string()
            .contains("red = 5"));
    }
}
