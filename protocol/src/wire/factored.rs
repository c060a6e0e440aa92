//! The factored belief on the wire (docs/design/architecture.md, "The factored
//! belief"): the settings a `Begin` carries, a component as it moves
//! between leaders in a [`Transfer`](super::leader_to_leader::Transfer),
//! and what a leader tells the coordinator of each component it holds at a
//! cut (count vector and per-track red weights), from which the
//! coordinator evaluates the count coupling.

use super::valid::distinct_tracks;
use serde::{Deserialize, Serialize};

/// The largest component on the wire: 2^20 numbers (the belief's own limit
/// for the Original split; tables beyond it are refused unread).
pub(crate) const MAX_COMPONENT: u32 = 20;

/// The factored belief's settings, the same for every leader.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub struct FactoredStart {
    /// The most tracks of one component.
    pub max_component: u32,
    pub split: WireSplit,
    /// Leaders' interests shrink: a leader follows exactly the tracks it
    /// surveils and those of the components it holds, and unfollows the
    /// rest ([`Interest::fixed`](super::interest::Interest::fixed)).
    /// Otherwise they grow on mixes, as on a Radon stream.
    pub shrink: bool,
    /// The regional rule (docs/design/architecture.md, "Components that stay in
    /// their region"): a mix of tracks in two leaders' regions keeps their
    /// components apart (projected back, never merged), and a track handed
    /// over to another region is split off its component, so a component
    /// stays where its holder surveils it. An approximation that
    /// `idmesh replay --regions` runs too.
    pub regional: bool,
    /// A crowd of more tracks than this is spread over the leaders; one of
    /// at most this many is held whole by the first leader, which weighs
    /// every split by the whole belief (docs/design/beliefs.md, "Who weighs
    /// a split"): what `idmesh replay` computes. A stream of one leader is
    /// held whole whatever its size ([`FactoredStart::whole`]).
    pub spread_above: u32,
}

/// The crowd size a deployment spreads above unless its topology says
/// (docs/design/beliefs.md, "Who weighs a split", says why this size).
pub const DEFAULT_SPREAD_ABOVE: u32 = 64;

/// Whether the first of `leaders` leaders holds a crowd of `tracks`
/// tracks whole on a stream that spreads crowds above `spread_above`: one
/// leader holds any crowd whole ([`FactoredStart::whole`]; replay and the
/// evaluation decide by it too).
pub fn held_whole(tracks: u32, leaders: usize, spread_above: u32) -> bool {
    leaders <= 1 || tracks <= spread_above
}

/// How a component too large to keep is split (`belief::SplitRule`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub enum WireSplit {
    Original,
    Recent,
    LeastLoss { rounds: u32 },
}

/// A component moving to another leader: its table over the subsets of
/// `tracks` (bit i ↔ `tracks[i]`), its log scale, and each track's
/// last-mix clock.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct WireComponent {
    pub tracks: Vec<u32>,
    pub table: Vec<f64>,
    pub log_scale: f64,
    pub last_mix: Vec<u64>,
}

/// A component at a cut, as the coordinator couples it: its count vector
/// (|tracks| + 1 numbers) and per track the weight of each count with the
/// track red.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct WireCounts {
    pub tracks: Vec<u32>,
    pub counts: Vec<f64>,
    pub red: Vec<Vec<f64>>,
}

fn weights(what: &str, v: &[f64]) -> Result<(), String> {
    match v.iter().find(|x| !(x.is_finite() && **x >= 0.0)) {
        Some(x) => Err(format!("{what}: weight {x} is not a finite number >= 0")),
        None => Ok(()),
    }
}

fn size(what: &str, tracks: &[u32]) -> Result<(), String> {
    let m = tracks.len();
    if m == 0 || m > MAX_COMPONENT as usize {
        return Err(format!("{what} of {m} tracks (1..={MAX_COMPONENT})"));
    }
    distinct_tracks(what, tracks, u32::MAX)
}

impl FactoredStart {
    pub fn check(&self) -> Result<(), String> {
        if !(1..=MAX_COMPONENT).contains(&self.max_component) {
            return Err(format!(
                "begin factored max_component = {} is not in 1..={MAX_COMPONENT}",
                self.max_component
            ));
        }
        Ok(())
    }

    /// Whether the first leader holds the whole belief of a stream of
    /// `tracks` tracks among `leaders` leaders: it surveils every track,
    /// the others none, and its splits are weighed by all of it.
    pub fn whole(&self, tracks: u32, leaders: usize) -> bool {
        held_whole(tracks, leaders, self.spread_above)
    }

    /// Whether each leader follows exactly the tracks it surveils: under
    /// the regional rule with shrinking interests every component stays in
    /// its holder's region, so the sensor ends a leader's interest in a
    /// track at the track's handover away, and the leader asks for no
    /// unfollow of it.
    pub fn follows_regions(&self) -> bool {
        self.regional && self.shrink
    }
}

impl WireComponent {
    /// Distinct tracks, 2^m finite non-negative numbers, a clock per track.
    pub(crate) fn check(&self) -> Result<(), String> {
        size("component", &self.tracks)?;
        let m = self.tracks.len();
        if self.table.len() != 1 << m || self.last_mix.len() != m {
            return Err(format!(
                "component of {m} tracks with {} numbers and {} clocks",
                self.table.len(),
                self.last_mix.len()
            ));
        }
        weights("component", &self.table)?;
        if !self.log_scale.is_finite() {
            return Err(format!("component log scale = {}", self.log_scale));
        }
        Ok(())
    }
}

impl WireCounts {
    /// Distinct tracks, m + 1 counts and m red vectors of m + 1, all finite
    /// and non-negative.
    pub(crate) fn check(&self) -> Result<(), String> {
        size("counts", &self.tracks)?;
        let m = self.tracks.len();
        if self.counts.len() != m + 1 || self.red.len() != m {
            return Err(format!(
                "counts of {m} tracks with {} counts and {} red vectors",
                self.counts.len(),
                self.red.len()
            ));
        }
        weights("counts", &self.counts)?;
        for w in &self.red {
            if w.len() != m + 1 {
                return Err(format!("a red vector of {} counts for {m} tracks", w.len()));
            }
            weights("red weights", w)?;
        }
        Ok(())
    }
}
