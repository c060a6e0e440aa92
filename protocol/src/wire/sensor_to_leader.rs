//! The event stream from the sensor gateway to one leader.
//!
//! The sensor stamps every item with a sequence number that is global to the
//! deployment (the order in which the sensor read the events) and sends each
//! leader only the items that concern it (see [`interest`](super::interest)),
//! in batches, over one FIFO link: a leader that has a batch has every item
//! meant for it with a smaller seq. `through` says how far the stream has
//! got even when nothing in it was for this leader.

use super::factored::FactoredStart;
use serde::{Deserialize, Serialize};

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Batch {
    pub version: u16,
    pub sensor: String,
    /// Counts batches to this leader from 0: a gap is a lost batch.
    pub number: u64,
    /// Every item for this leader with seq ≤ `through` is in this batch or
    /// an earlier one.
    pub through: u64,
    /// Trace events read through `through` (the watermark there).
    pub events: u64,
    /// The sensor has read its whole source: nothing comes after `through`.
    pub finished: bool,
    pub items: Vec<Sequenced>,
}
super::versioned!(Batch, "event batch");

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Sequenced {
    pub seq: u64,
    pub item: Item,
}

/// How an observation grows sets (the conditioning rule in force).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub enum Growth {
    /// Exact conditioning: every set grows (Algorithm 2).
    All,
    /// The distributed rule: sets meeting these tracks (the observed
    /// track's mixing log) grow (Algorithm 5).
    Meeting(Vec<u32>),
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub enum Item {
    /// The start of the stream: the field and who owns which track.
    Begin(Begin),
    /// Targets on tracks a and b mixed. `owner_a`/`owner_b` are the leaders
    /// (indices into `Begin::leaders`) surveilling them at this point.
    /// `handed`: under the regional rule with fitted regions, a mix of
    /// tracks of two leaders takes both to one of them; the track that
    /// changes leader rides on the mix (handed over from `from` to the
    /// owners named, before the mix), so that the mix is one item at each
    /// of the two leaders, as a mix kept apart is. `adopted`: the tracks
    /// of the two (none, one or both) that no leader surveilled before
    /// this item, their first: each is adopted here by the owner named for
    /// it ([`Begin::owners`]).
    Mix {
        a: u32,
        b: u32,
        swap: f64,
        owner_a: u16,
        owner_b: u16,
        handed: Option<Handed>,
        adopted: Vec<u32>,
    },
    Observe {
        track: u32,
        red: f64,
        blue: f64,
        growth: Growth,
        /// Every leader must apply it: exact conditioning, or a certain
        /// sighting, which removes the sets that do not fix the track.
        global: bool,
        /// The track's first item: no leader surveilled it, and this one
        /// adopts it ([`Begin::owners`]).
        adopted_by: Option<u16>,
    },
    /// A sensor read `identity` on track `track` (identity streams), sent
    /// only to `owner`, the leader surveilling the track, which holds the
    /// track's row of the information matrix: evidence costs no message
    /// between leaders.
    Identify {
        track: u32,
        identity: u32,
        accuracy: f64,
        owner: u16,
        /// The track's first item: `owner` adopts it ([`Begin::owners`]).
        adopted: bool,
    },
    /// Track `track` left the region of leader `from` for that of `to`.
    Handover { track: u32, from: u16, to: u16 },
    /// A consistent cut asked for by a query: every leader computes its
    /// partial sums here. `events` counts the trace events before it; `tag`
    /// is the query's, so leaders asked for it before it reaches them know
    /// which cut to wait for. `rows`: an identity query, leaders add their
    /// rows of the information matrix to their answer.
    Cut { events: u64, tag: u64, rows: bool },
}

/// The track a mix takes from another leader ([`Item::Mix`]): it was
/// surveilled by `from` until this item.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub struct Handed {
    pub track: u32,
    pub from: u16,
}

/// The owner of a track no leader surveils yet ([`Begin::owners`]).
pub const UNHELD: u16 = u16::MAX;

/// Of `leaders` leaders, the one that keeps an unheld `track`'s start
/// component and row ([`Begin::owners`]): `track mod L`.
pub fn keeper(track: u32, leaders: usize) -> u16 {
    (track as usize % leaders.max(1)) as u16
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Begin {
    pub tracks: u32,
    /// k, when known.
    pub red: Option<u32>,
    pub initial_red: Option<Vec<u32>>,
    /// The leaders' names, in the order the indices refer to.
    pub leaders: Vec<String>,
    /// The owner (leader index) of every track at the start, or
    /// [`UNHELD`]: on a factored stream under the regional rule a track
    /// is surveilled from its first item on, which adopts it
    /// ([`Item::adoptions`]; docs/design/architecture.md, "Newcomers"). Until then its start component is kept, followed by
    /// nobody, by its *keeper* ([`Begin::keeper`]), which gives it as a
    /// passive part in its answers ([`Partial::passive`](super::coordinator_to_leader::Partial::passive)).
    pub owners: Vec<u16>,
    pub distributed_rule: bool,
    /// Each leader's coefficient budget (0 = no pruning).
    pub budget: u32,
    /// Over budget, re-express with OMP after runs of mixing before
    /// thresholding (the overcomplete method), each leader on its own sets.
    pub omp: bool,
    /// An identity stream (one identity per track): each leader keeps the
    /// rows of the information matrix of the tracks it surveils.
    pub identities: bool,
    /// The known identity on every track at the start; None = uniform.
    pub initial_identity: Option<Vec<u32>>,
    /// The leaders hold the factored belief with these settings (None:
    /// the Radon belief).
    pub factored: Option<FactoredStart>,
    /// On an identity stream with a known start and the factored belief,
    /// the leaders hold the factored identity belief (docs/design/identity.md)
    /// with groups of at most this many slots (2..=9) instead of the rows
    /// of the information matrix: each linked tree of groups whole, at one
    /// leader. None: the rows.
    pub factored_identity: Option<u32>,
}

impl Begin {
    /// The leader that keeps the start component (and row) of `track` while
    /// no leader surveils it ([`Begin::owners`]): [`keeper`].
    pub fn keeper(&self, track: u32) -> u16 {
        keeper(track, self.leaders.len())
    }

    /// Whether `track` starts unheld ([`UNHELD`]).
    pub fn starts_unheld(&self, track: u32) -> bool {
        self.owners.get(track as usize) == Some(&UNHELD)
    }

    /// Whether leader `me` holds the start component (and row) of `track`:
    /// it surveils the track, or keeps it unheld.
    pub fn holds_at_start(&self, track: u32, me: u16) -> bool {
        match self.owners.get(track as usize) {
            Some(&UNHELD) => self.keeper(track) == me,
            Some(&owner) => owner == me,
            None => false,
        }
    }
}

impl Item {
    /// The tracks this item adopts, each with the leader adopting it: the
    /// tracks it is the first item of on a stream whose tracks start
    /// unheld ([`Begin::owners`]). The adopting leader takes the track's
    /// start component and row before applying the item.
    pub fn adoptions(&self) -> Vec<(u32, u16)> {
        match self {
            Item::Mix {
                a,
                b,
                owner_a,
                owner_b,
                adopted,
                ..
            } => adopted
                .iter()
                .map(|&t| (t, if t == *a { *owner_a } else { *owner_b }))
                .filter(|&(t, _)| t == *a || t == *b)
                .collect(),
            Item::Observe {
                track,
                adopted_by: Some(leader),
                ..
            } => vec![(*track, *leader)],
            Item::Identify {
                track,
                owner,
                adopted: true,
                ..
            } => vec![(*track, *owner)],
            _ => Vec::new(),
        }
    }
}
