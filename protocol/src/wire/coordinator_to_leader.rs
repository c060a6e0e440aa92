//! What a leader tells the coordinator: its partial sums at a cut (a get on
//! `P/leader/*/partial?tag=<tag>`, answered once the cut with that tag has
//! reached the leader), or at the quiet point it rests at (`?quiet`: it has
//! applied everything the sensor sent and waits for nothing), and its
//! counters (`P/leader/*/stats`).
//!
//! The partial sums' rules ([`Valid`], and [`Bounds`] against the field of
//! the query) sit below the types.

use super::bounds::{invalid, Bounds};
use super::factored::WireCounts;
use super::identity::WireTree;
use super::leader_to_leader::WireRow;
use super::valid::{distinct, require, MAX_TRACKS};
use super::{Valid, WireError};
use serde::{Deserialize, Serialize};

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Partial {
    pub version: u16,
    /// The sending role's epoch ([`super::epoch`]).
    pub epoch: u64,
    pub leader: String,
    /// The seq of the cut item and the query's tag it carried; for a quiet
    /// answer, the seq the leader has applied everything through, tag 0.
    pub cut: u64,
    pub tag: u64,
    /// Trace events up to `cut`, and whether the stream was over there.
    pub events: u64,
    pub finished: bool,
    pub log_scale: f64,
    pub total: f64,
    pub outside: f64,
    pub inside: Vec<(u32, f64)>,
    pub coefficients: u64,
    /// The leader's rows of the information matrix, when the query asked
    /// for them (identity queries); empty otherwise.
    pub rows: Vec<WireRow>,
    /// On a factored stream, every component this leader holds (the sums
    /// above are then 0), or with `base` only what changed; None on a
    /// Radon stream.
    pub components: Option<Vec<WireCounts>>,
    /// A factored answer told as a change to this leader's answer at the
    /// cut tagged `base`, which the coordinator said it keeps (`;base=`),
    /// or, in an answer pushed at a cut, the cut this leader pushed at before:
    /// `components` are then only those not in that answer as they are
    /// now, and `gone` the first tracks of that answer's components that
    /// are no longer held here as they were. Between two queries a few
    /// components change, so a reply is a few hundred bytes where the
    /// whole share of a 10,000-track crowd is over 100 kB. None: whole.
    pub base: Option<u64>,
    pub gone: Vec<u32>,
    /// The tracks whose start component (a part of one track) and row
    /// this leader gives only as their keeper ([`Begin::owners`]): no
    /// leader surveilled them when it last heard of them, so where another
    /// leader's answer holds one, that one is the track's (the keeper is
    /// not told of an adoption elsewhere).
    ///
    /// [`Begin::owners`]: super::sensor_to_leader::Begin::owners
    pub passive: Vec<u32>,
    /// The trees of the factored identity belief this leader holds, when
    /// the query asked for rows on a stream whose leaders hold that
    /// belief; passive ones (a start kept) for the tracks in `passive`.
    pub trees: Vec<WireTree>,
}
super::versioned!(Partial, "partial sums");
super::epoch::epoched!(Partial);

/// A leader's counters, also the JSON of `P/query/stats` (one per leader).
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct LeaderStats {
    pub version: u16,
    pub leader: String,
    /// Stream items applied, and of them mixes, observations, handovers.
    pub items: u64,
    pub mixes: u64,
    pub observations: u64,
    pub handovers: u64,
    /// Of the mixes, those that took a track of another leader here.
    #[serde(default)]
    pub tracks_taken: u64,
    pub batches: u64,
    pub bytes_received: u64,
    pub transfers_sent: u64,
    pub transfers_received: u64,
    pub sets_sent: u64,
    pub bytes_sent: u64,
    pub follows: u64,
    /// Unfollow requests to the sensor (a factored stream: tracks whose
    /// components left this leader).
    #[serde(default)]
    pub unfollows: u64,
    /// OMP runs on this leader's sets (the overcomplete method).
    pub omp_runs: u64,
    /// Batches and transfers that came twice (dropped), and gaps in the
    /// batch numbers (the missing batches were asked for again).
    pub duplicates: u64,
    pub gaps: u64,
    /// Inputs refused at the door (undecodable, malformed, or not of this
    /// stream's field): neither journaled nor applied. Counted since the
    /// process started, plus those its journal replay met again.
    #[serde(default)]
    pub rejected: u64,
    /// Identity reads applied (each to a row held here, with no message).
    pub identifies: u64,
    /// Rows of the information matrix held now.
    pub rows_held: u64,
    /// Tracks whose tree of the factored identity belief is held here
    /// now (each tree whole at one leader; starts kept for nobody left
    /// out).
    #[serde(default)]
    pub tree_tracks: u64,
    /// Valid identity events the trees held here could not take as they
    /// stood, taken by the factored identity belief's repair rule
    /// (counted since the process started, plus those its journal replay
    /// met again).
    #[serde(default)]
    pub identity_repairs: u64,
    /// Colour events the factored belief held here could not take as
    /// they stood: splits retried under other count weights, and sightings
    /// of a colour the belief had ruled out, taken by smoothing their
    /// component (counted since the process started, plus those its
    /// journal replay met again).
    #[serde(default)]
    pub belief_repairs: u64,
    pub coefficients: u64,
    pub tracks_owned: u64,
    pub tracks_followed: u64,
    /// The seq of the last item applied.
    pub position: u64,
    /// The stream's events as of the last batch received, whether that
    /// batch said the stream is over, and whether the leader is quiet
    /// (applied every item it was sent and waits for no peer): every
    /// leader finished and quiet holds the whole stream, which is how a
    /// bench can tell a stream is through without a query's cost.
    #[serde(default)]
    pub stream_events: u64,
    #[serde(default)]
    pub stream_finished: bool,
    #[serde(default)]
    pub quiet: bool,
    /// Transfers kept for peers that have not yet said their state is safe
    /// past them (bounded: peers publish durable marks).
    #[serde(default)]
    pub transfers_kept: u64,
    /// Snapshots written (each lets the journal start again empty).
    #[serde(default)]
    pub snapshots: u64,
    /// The process running this leader: itself, or the one that adopted
    /// the role when its own process was gone for good.
    #[serde(default)]
    pub host: String,
    /// Restarts and adoptions caught up, and how long the last one took
    /// (from start to having applied all it missed).
    #[serde(default)]
    pub recoveries: u64,
    #[serde(default)]
    pub recovery_seconds: f64,
    /// Restarts that found the journal damaged (a record that does not
    /// check, with whole ones after it), and the journal entries dropped
    /// with the damage: the leader came back from what preceded it and
    /// fetched the rest again from the sensor and its peers.
    #[serde(default)]
    pub journal_damage: u64,
    #[serde(default)]
    pub journal_dropped: u64,
    /// Bytes of snapshots sent to this role's standby (counted in no other
    /// byte counter).
    #[serde(default)]
    pub standby_bytes: u64,
    /// fsyncs of journals, snapshots and standby copies by the process
    /// running this leader since it started (every role it runs, and the
    /// copies it keeps for others).
    #[serde(default)]
    pub fsyncs: u64,
}
super::versioned!(LeaderStats, "leader stats");

impl Valid for Partial {
    fn problem(&self) -> Option<String> {
        self.check().err()
    }
}

impl Partial {
    fn check(&self) -> Result<(), String> {
        // The scale of an empty share is whatever it was left at; its sums
        // are 0. Anything not a number would poison the coordinator's sum.
        require(
            !self.log_scale.is_nan() && self.log_scale != f64::INFINITY,
            || format!("log scale = {}", self.log_scale),
        )?;
        for (what, value) in [("total", self.total), ("outside", self.outside)] {
            require(value.is_finite(), || format!("{what} = {value}"))?;
        }
        let mut previous: Option<u32> = None;
        for &(t, x) in &self.inside {
            require(previous.is_none_or(|p| t > p), || {
                format!("inside: track {t} out of order or repeated")
            })?;
            require(t < MAX_TRACKS, || {
                format!("inside: track {t} is out of range")
            })?;
            require(x.is_finite(), || format!("inside: track {t} = {x}"))?;
            previous = Some(t);
        }
        let tracks: Vec<u32> = self.rows.iter().map(|r| r.track).collect();
        distinct("rows", &tracks)?;
        for row in &self.rows {
            row.check()?;
        }
        for (i, c) in self.components.iter().flatten().enumerate() {
            c.check().map_err(|e| format!("component {i}: {e}"))?;
        }
        require(self.base.is_none() || self.components.is_some(), || {
            "a change to a base answer without components".into()
        })?;
        require(self.base.is_some() || self.gone.is_empty(), || {
            "components gone without a base answer".into()
        })?;
        distinct("gone", &self.gone)?;
        require(self.passive.windows(2).all(|w| w[0] < w[1]), || {
            "passive: tracks out of order or repeated".into()
        })?;
        for (what, tracks) in [("gone", &self.gone), ("passive", &self.passive)] {
            if let Some(t) = tracks.iter().find(|&&t| t >= MAX_TRACKS) {
                return Err(format!("{what}: track {t} is out of range"));
            }
        }
        Ok(())
    }
}

impl Bounds {
    /// A leader's partial sums for a query about this field.
    pub fn check_partial(&self, partial: &Partial) -> Result<(), WireError> {
        let check = || -> Result<(), String> {
            for &(t, _) in &partial.inside {
                self.track("inside track", t)?;
            }
            for &t in &partial.gone {
                self.track("gone component's track", t)?;
            }
            self.check_rows(&partial.rows)?;
            self.check_trees(&partial.trees)
        };
        check().map_err(|problem| invalid("partial sums", problem))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::wire::{decode, encode, VERSION};

    #[test]
    fn partials_are_checked() {
        let partial = Partial {
            epoch: 0,
            trees: Vec::new(),
            components: None,
            base: None,
            gone: Vec::new(),
            passive: Vec::new(),
            version: VERSION,
            leader: "a".into(),
            cut: 1,
            tag: 0,
            events: 0,
            finished: false,
            log_scale: 0.0,
            total: 1.0,
            outside: 0.25,
            inside: vec![(0, 0.5), (3, 0.25)],
            coefficients: 2,
            rows: vec![],
        };
        assert!(decode::<Partial>(&encode(&partial)).is_ok());
        let bad = Partial {
            inside: vec![(3, 0.5), (0, 0.25)],
            ..partial.clone()
        };
        assert!(decode::<Partial>(&encode(&bad)).is_err());
        let bad = Partial {
            total: f64::INFINITY,
            ..partial.clone()
        };
        assert!(decode::<Partial>(&encode(&bad)).is_err());
        // A change to a base answer: only of components, each track gone once.
        let change = Partial {
            components: Some(Vec::new()),
            base: Some(7),
            gone: vec![2, 5],
            ..partial.clone()
        };
        assert!(decode::<Partial>(&encode(&change)).is_ok());
        for (bad, expected) in [
            (
                Partial {
                    gone: vec![2, 2],
                    ..change.clone()
                },
                "gone",
            ),
            (
                Partial {
                    components: None,
                    ..change.clone()
                },
                "without components",
            ),
            (
                Partial {
                    base: None,
                    ..change
                },
                "without a base",
            ),
        ] {
            let e = decode::<Partial>(&encode(&bad)).unwrap_err().to_string();
            assert!(e.contains(expected), "{e}");
        }
    }
}
