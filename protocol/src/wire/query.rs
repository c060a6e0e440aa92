//! The user-facing answers, JSON with Zenoh's JSON encoding.
//! `P/query/marginals`, `P/query/track/<t>`, `P/query/identity`,
//! `P/query/identity/<t>`, `P/query/positions` and `P/query/stats`; an answer that cannot be
//! given is an error reply carrying [`QueryError`].

use super::coordinator_to_leader::LeaderStats;
use super::coordinator_to_sensor::SensorStatus;
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

/// One track's identity marginals, sparsely: `listed` (identity,
/// probability), identities ascending; every identity not listed has
/// probability `rest`. P(track carries i) = [`IdentityRow::probability`].
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
pub struct IdentityRow {
    pub rest: f64,
    pub listed: Vec<(u32, f64)>,
}

impl IdentityRow {
    /// The row of a dense vector: its non-zero entries, the rest 0.
    pub fn from_dense(row: &[f64]) -> Self {
        IdentityRow {
            rest: 0.0,
            listed: row
                .iter()
                .enumerate()
                .filter(|&(_, &p)| p != 0.0)
                .map(|(i, &p)| (i as u32, p))
                .collect(),
        }
    }

    /// A row from (identity, probability) pairs in any order, repeated
    /// identities summed; every other identity at `rest`.
    pub fn collect(rest: f64, mut entries: Vec<(u32, f64)>) -> Self {
        entries.sort_by_key(|&(i, _)| i);
        let mut listed: Vec<(u32, f64)> = Vec::with_capacity(entries.len());
        for (i, p) in entries {
            match listed.last_mut() {
                Some((j, q)) if *j == i => *q += p,
                _ => listed.push((i, p)),
            }
        }
        IdentityRow { rest, listed }
    }

    /// P(the track carries identity `i`).
    pub fn probability(&self, i: u32) -> f64 {
        match self.listed.binary_search_by_key(&i, |&(j, _)| j) {
            Ok(at) => self.listed[at].1,
            Err(_) => self.rest,
        }
    }

    /// The row as n numbers.
    pub fn dense(&self, n: usize) -> Vec<f64> {
        let mut row = vec![self.rest; n];
        for &(i, p) in &self.listed {
            if let Some(x) = row.get_mut(i as usize) {
                *x = p;
            }
        }
        row
    }

    /// Σ_i p\[i\] over n identities.
    pub fn total(&self, n: usize) -> f64 {
        let listed: f64 = self.listed.iter().map(|&(_, p)| p).sum();
        listed + self.rest * n.saturating_sub(self.listed.len()) as f64
    }
}

/// Who is on which track: `p_identity[t]` = track t's marginals by row
/// ([`IdentityRow`]), computed by the coordinator when asked — from the
/// leaders' trees of the factored identity belief, or from their rows of
/// the information matrix by `marginals` (exact, metropolis, sinkhorn,
/// bethe); `predicted_identity` is the most likely one-to-one assignment
/// under them.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct IdentityAnswer {
    pub watermark: Watermark,
    pub tracks: u32,
    pub p_identity: Vec<IdentityRow>,
    pub predicted_identity: Vec<u32>,
    pub marginals: String,
    pub leaders: u32,
    pub finished: bool,
    /// Present when some block was answered by Metropolis: how far the
    /// sampled marginals can be trusted.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub sampling: Option<SamplingReport>,
}

/// The convergence diagnostic of the blocks an identity answer sampled by
/// Metropolis (a split-chain check, like Gelman–Rubin's split R̂).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct SamplingReport {
    /// How many independent blocks were sampled.
    pub blocks: u32,
    /// The largest |p₁ − p₂| between the marginals of the first and second
    /// half of a chain: about the sampling error of the worst marginal
    /// (0.01 or below: the chain has mixed; ask with more `samples` if not).
    pub half_difference: f64,
    /// The smallest share of proposals accepted.
    pub acceptance: f64,
}

/// Who is on one track: the track's row of [`IdentityAnswer`] and the
/// identity the assignment gives it.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct IdentityTrackAnswer {
    pub watermark: Watermark,
    pub track: u32,
    pub p_identity: IdentityRow,
    pub predicted_identity: u32,
    pub marginals: String,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub sampling: Option<SamplingReport>,
}

/// Where every track was last seen (`positions[t]`, null before its first
/// `move`) and the index in `leaders` of the leader that surveils it
/// (`owners[t]`; 65535 while none does, before its first event on a
/// factored stream: `sensor_to_leader::UNHELD`), after the watermark's events; `leaders` with where each
/// sits (its region: the points nearer to it than to any other).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct PositionsAnswer {
    pub watermark: Watermark,
    pub tracks: u32,
    pub positions: Vec<Option<[f64; 2]>>,
    pub owners: Vec<u16>,
    pub leaders: Vec<LeaderPlace>,
    pub finished: bool,
}

/// A leader and where it sits (null: tracks stay with leader t mod L).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct LeaderPlace {
    pub name: String,
    /// Under fitted cells the centre of its region; under fixed places
    /// the place itself.
    pub at: Option<[f64; 2]>,
    /// Its region `[x0, y0, x1, y1]` when regions are rectangles (fitted
    /// cells, cut to the box of the tracks seen); absent under fixed
    /// places, whose regions are the points nearest each place.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub region: Option<[f64; 4]>,
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct StatsAnswer {
    pub leaders: Vec<LeaderStats>,
    /// Each sensor gateway's count of bad requests.
    #[serde(default)]
    pub sensors: Vec<SensorStatus>,
    #[serde(default)]
    pub coordinator: CoordinatorStats,
}

/// The coordinator's counters: of bad input, and of how fresh cuts' sums
/// came.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct CoordinatorStats {
    /// Queries refused before any work: a malformed, repeated or unknown
    /// parameter, a track that is not a number.
    pub rejected: u64,
    /// Replies from leaders or the sensor (partial sums, cuts) that did
    /// not decode or did not fit the stream: the query they were for got
    /// an error.
    pub bad_replies: u64,
    /// Queries answered `degraded: …`: a leader missing, recovering, or
    /// not at the cut (never numbers without its share).
    #[serde(default)]
    pub degraded: u64,
    /// Fresh cuts whose every leader pushed its sums on reaching them.
    #[serde(default)]
    pub cuts_pushed: u64,
    /// Fresh cuts where a push did not come in time (lost, or a leader far
    /// behind) and every leader was asked instead.
    #[serde(default)]
    pub cuts_asked: u64,
    /// Factored answers computed by the contradiction rule: the leaders'
    /// components together held no red count the prior allows (sure
    /// sightings that contradict each other across components).
    #[serde(default)]
    pub query_repairs: u64,
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct QueryError {
    pub error: String,
}
