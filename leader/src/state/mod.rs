//! The leader as a pure state machine: items of its event stream in, sets
//! for other leaders and follow requests out. No I/O, so the whole protocol
//! can be run in one process by tests (see `tests` below) and the actor in
//! [`actor`](crate::driver) only moves bytes.
//!
//! Section 5.4 of the property-management paper, with one departure: a set
//! is held by exactly one of the leaders that surveil its tracks (the paper
//! keeps a replica at each of them). Every item is applied, in seq order, by
//! every leader whose sets it may change ([`Interest`]), so there are no
//! replicas to keep consistent: the belief is the sum of the leaders' shares
//! ([`RadonShare`]), whatever the split.
//!
//! Sets move only at the two points where the paper moves them, always to
//! a leader that takes part in the same item, so the receiver knows to wait:
//! - a mix of tracks of two leaders (Algorithm 4): after the rollup each
//!   sends the other the sets left with none of its own tracks (the image
//!   of a set whose only own track was the mixed one);
//! - a handover: a track leaves a leader's region; the sets left with none
//!   of its own tracks go to the new leader.
//!
//! The empty set (k unknown) never moves. Thresholding is local, each
//! leader against its own budget (Section 5.4.3: "fully distributive").
//!
//! On an identity stream each leader also holds the rows of the information
//! matrix of the tracks it surveils ([`InformationRows`]; Shin et al., IPSN
//! 2005, Section 4): a read is applied to the owner's row with no message;
//! a cross-leader mix puts each leader's row of its mixed track, as it was
//! before the mix, in the transfer it sends anyway, and both fit the same
//! pair; a handover moves the track's row with its sets.
//!
//! On a factored stream the rows stay with the leader surveilling their
//! track too, wherever the components go: a row changes only at a read, a
//! mix of its track (exact and pairwise: only rows a and b) or a handover,
//! all items its owner applies, so components and rows move apart.
//! - A mix of tracks of two leaders (0 < swap < 1): the leader surveilling
//!   b puts its row of b, as it was, in the transfer it sends the leader
//!   surveilling a (empty of components if it holds neither) and waits for
//!   that leader's transfer; the leader surveilling a waits for the row as
//!   for the components, fits the pair as the centralized matrix does, and
//!   sends b's new row back — with b's component under the regional rule,
//!   alone otherwise. One fit, so the two leaders cannot disagree.
//! - A certain exchange (swap 1) across two leaders: each sends the other
//!   its row as on a Radon stream (with the singleton under the regional
//!   rule) and the two swap (`row_mix`).
//! - A handover moves the row with the components sent.
//!
//! On a stream whose leaders hold the factored identity belief instead
//! (`Begin::factored_identity`, the default on a factored stream with a
//! known start) there are no rows: each linked tree of groups
//! ([`IdentityShare`]) lies whole with one leader, which follows its
//! tracks and applies their reads. A mix (0 < swap < 1) needs its two
//! trees in one place: every holder of either sends it, with what it
//! sends anyway, to the leader surveilling `a`, which waits for both as it
//! waits for components and mixes them there. A sure swap is relabelled
//! by each holder where it is. Trees stay where they were mixed; a
//! handover moves none.
//!
//! Rows are in the snapshot with the rest of `Started`, and a journal
//! replays the transfers that carried them. With rows no transfer is taken
//! in without stopping ([`Leader::lazy_transfers`]): the pending rule
//! names the components a transfer may bring, not rows.

use crate::error::LeaderError;
use idmesh_belief::FactoredShare;
use idmesh_belief::{Growth as BeliefGrowth, RadonShare, Sparsify};
use idmesh_belief::{Mix, Observe};
use idmesh_identity::factored::IdentityShare;
use idmesh_identity::KNOWN_START_CONFIDENCE;
use idmesh_identity::{Identify, IdentityEvent, InformationRows};
use idmesh_placement::{start, start_factored, start_identity};
use idmesh_protocol::wire::bounds::Bounds;
use idmesh_protocol::wire::coordinator_to_leader::{LeaderStats, Partial};
use idmesh_protocol::wire::identity::WireTree;
use idmesh_protocol::wire::interest::Interest;
use idmesh_protocol::wire::leader_to_leader::{Transfer, WireRow, WireSet};
use idmesh_protocol::wire::leader_to_sensor::{Durable, Follow, Unfollow};
use idmesh_protocol::wire::sensor_to_leader::{Batch, Begin, Growth, Handed, Item, Sequenced};
use idmesh_protocol::wire::VERSION;
use serde::{Deserialize, Serialize};
use std::collections::{BTreeMap, HashMap, VecDeque};
use std::sync::Arc;

mod apply;
mod cuts;
pub use cuts::Answer;
mod inbox;
mod pending;
mod stats;
#[cfg(test)]
mod tests;
mod transfers;

/// What the leader asks its actor to do.
#[derive(Debug, Clone, PartialEq)]
pub enum Action {
    /// Send these sets to leader `to` (an index into `Begin::leaders`).
    Send { to: u16, transfer: Transfer },
    /// Ask the sensor to follow more tracks; answer with
    /// [`Leader::followed`].
    Follow(Follow),
    /// Tell the sensor to stop routing these tracks here (fire and
    /// forget: a lost request costs items, not answers).
    Unfollow(Unfollow),
    /// The partial sums at a cut are ready.
    CutReady(Arc<Answer>),
}

/// Where the leader is stopped, if anywhere.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
enum Waiting {
    /// For the sets of leader `from` at item `seq`.
    Transfer { seq: u64, from: u16 },
    /// For the components of both tracks of mix `mix`, item `seq`, which
    /// their holders send this leader, the one surveilling `mix.a` (a
    /// factored stream: whoever holds them, see [`apply`]). Under the
    /// regional rule a mix across regions is kept apart and the component
    /// of `mix.b` goes `back` to the leader surveilling it. On an identity
    /// stream across two leaders, the `partner` surveilling `mix.b` sends
    /// its row of it too, and gets the fitted row back. A mix that takes
    /// a track (`handed`) waits for the singleton of that track, and its
    /// row, from the leader that surveilled it, and sends nothing back.
    Components {
        seq: u64,
        mix: Mix,
        back: Option<u16>,
        partner: Option<u16>,
        handed: Option<Handed>,
    },
    /// For the sensor's answer to a follow request made at `seq`.
    Follow { seq: u64 },
}

/// A transfer from leader `from` of item `seq` still on its way, which
/// can bring only components of `tracks` ([`Leader::lazy_transfers`]).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
struct Pending {
    seq: u64,
    from: u16,
    tracks: Vec<u32>,
}

#[derive(Serialize, Deserialize)]
struct Started {
    /// This leader's index in `begin.leaders`.
    me: u16,
    begin: Begin,
    share: RadonShare,
    own: Vec<bool>,
    interest: Interest,
    /// The rows of the information matrix of the tracks owned, on an
    /// identity stream.
    rows: Option<InformationRows>,
    /// A cross-leader mix whose fit waits for the partner's row.
    row_mix: Option<Mix>,
    /// The trees of the factored identity belief held here, on a stream
    /// whose leaders hold that belief (`Begin::factored_identity`; `rows`
    /// is then None).
    trees: Option<IdentityShare>,
    /// The components of the factored belief held here, on a factored
    /// stream (`share` is then empty).
    factored: Option<FactoredShare>,
    /// The tracks whose start component and row this leader keeps while,
    /// as far as it knows, no leader surveils them (`Begin::owners`):
    /// given as passive parts in its answers.
    #[serde(default)]
    passive: std::collections::BTreeSet<u32>,
    /// Of those, the tracks whose start tree is still kept here: a tree
    /// that brings one (its track was adopted and mixed elsewhere) makes
    /// the start give way, while the track's start component may stay
    /// passive.
    #[serde(default)]
    passive_trees: std::collections::BTreeSet<u32>,
}

impl Started {
    /// Whether the stream runs the factored belief's regional rule.
    fn regional(&self) -> bool {
        self.begin.factored.is_some_and(|f| f.regional)
    }
}

/// Serialized whole as a snapshot ([`Leader::snapshot`]): the state a
/// journal would rebuild, so that the journal can start again empty.
#[derive(Serialize, Deserialize)]
pub struct Leader {
    name: String,
    started: Option<Started>,
    /// Items received and not yet applied, by seq (duplicates collapse).
    queue: BTreeMap<u64, Item>,
    /// Every item for this leader with seq ≤ frontier has been received.
    frontier: u64,
    /// Seq of the last item applied (0 before any).
    position: u64,
    /// Next batch number expected from the sensor.
    next_batch: u64,
    /// The sensor that sent the batches (named in its errors).
    sensor: Option<String>,
    /// Batches that came ahead of a missing one, by number, with their size.
    ahead: BTreeMap<u64, (Batch, usize)>,
    /// Every transfer sent, with its receiver: a restarted peer asks for
    /// the ones it lost while it was down.
    sent: Vec<(u16, Transfer)>,
    /// The follow request waiting for its answer (asked again after a
    /// restart).
    asked: Option<Follow>,
    /// Transfers that arrived before the leader reached their item.
    transfers: HashMap<(u64, u16), Transfer>,
    /// Transfers of the item being waited for already taken (a factored
    /// stream gathers several at one item): a second copy is a duplicate.
    taken: Vec<(u64, u16)>,
    waiting: Option<Waiting>,
    #[serde(with = "cuts::kept")]
    cuts: VecDeque<Arc<Answer>>,
    /// The watermark and end-of-stream flag of the last batch.
    events: u64,
    finished: bool,
    stats: LeaderStats,
    /// A batch held ahead before the Begin was refused once the Begin
    /// came: the sensor is asked for it again at once, not at the next gap.
    refetch: bool,
    /// Tracks left the interest (a factored stream) and not yet told the
    /// sensor, and the item of the last of them.
    unfollowing: Vec<u32>,
    unfollow_after: u64,
    /// Tracks that may have come to be held here since the leader last
    /// followed what it holds (a factored stream: those of the components
    /// received, and those a relabel exchanged), checked by
    /// [`Leader::follow_held`]: reading every track held at every transfer
    /// cost a leader in proportion to all it holds.
    to_follow: Vec<u32>,
    /// Transfers this leader has not got yet, in seq order (a factored
    /// stream under the regional rule, see [`Leader::lazy_transfers`]):
    /// the leader goes on past their items and takes each in when it
    /// comes, or waits for them all before an item that touches a pending
    /// track. Last, so that a snapshot written before it existed fails to
    /// read rather than misreads.
    pending: Vec<Pending>,
    /// No transfer came and no pending one was noted since the pending
    /// ones were last matched with the transfers here
    /// ([`Leader::take_pending`]), which can then skip looking: it runs
    /// before every item, and looked up every pending transfer each time.
    /// False after a restore, so that the first pass looks.
    #[serde(skip)]
    pending_checked: bool,
    /// The last answer where the leader rests, with whether it holds the
    /// rows, until an input changes anything: a deployment at rest is
    /// asked again and again, and a factored answer reads every component.
    #[serde(skip)]
    resting: Option<(bool, Arc<Answer>)>,
    /// Trees of the factored identity belief taken out for the leader
    /// that mixes them at the item being applied: they go in the transfer
    /// this leader sends that leader at the item, or alone
    /// ([`Leader::send_trees_left`]).
    #[serde(skip)]
    trees_out: Option<(u16, Vec<WireTree>)>,
    /// The epoch at which this process holds the role (0 without voters),
    /// stamped on every message it sends ([`idmesh_protocol::wire::epoch`]).
    /// The holder's, not the state's: a snapshot taken by one holder is
    /// restored by the next at its own epoch.
    #[serde(skip)]
    epoch: u64,
}

impl Leader {
    pub fn new(name: impl Into<String>) -> Self {
        let name = name.into();
        Leader {
            stats: LeaderStats {
                version: VERSION,
                leader: name.clone(),
                ..LeaderStats::default()
            },
            name,
            started: None,
            queue: BTreeMap::new(),
            frontier: 0,
            position: 0,
            next_batch: 0,
            sensor: None,
            ahead: BTreeMap::new(),
            sent: Vec::new(),
            asked: None,
            transfers: HashMap::new(),
            taken: Vec::new(),
            waiting: None,
            pending: Vec::new(),
            pending_checked: false,
            cuts: VecDeque::new(),
            events: 0,
            finished: false,
            refetch: false,
            unfollowing: Vec::new(),
            unfollow_after: 0,
            to_follow: Vec::new(),
            resting: None,
            trees_out: None,
            epoch: 0,
        }
    }

    /// The epoch this process holds the role at.
    pub(crate) fn epoch(&self) -> u64 {
        self.epoch
    }

    /// Holds the role at `epoch` from now on: what is sent from here, the
    /// follow request still out and the answers kept for late queries
    /// included (restored from a former holder's snapshot, they carry its
    /// epoch).
    pub(crate) fn set_epoch(&mut self, epoch: u64) {
        self.epoch = epoch;
        if let Some(asked) = &mut self.asked {
            asked.epoch = epoch;
        }
        self.resting = None;
        for cut in &mut self.cuts {
            if cut.sums.epoch != epoch {
                *cut = Arc::new(cut.restamped(epoch));
            }
        }
    }

    pub(crate) fn name(&self) -> &str {
        &self.name
    }

    /// The whole state, as bytes ([`Leader::restore`] reads them back).
    pub(crate) fn snapshot(&self) -> Vec<u8> {
        postcard::to_allocvec(self).unwrap_or_default()
    }

    /// The leader a snapshot was taken of.
    pub(crate) fn restore(bytes: &[u8]) -> Result<Leader, LeaderError> {
        postcard::from_bytes(bytes).map_err(|e| LeaderError::Snapshot(e.to_string()))
    }

    pub fn position(&self) -> u64 {
        self.position
    }

    /// How far this leader has got through the stream: every item for it
    /// at or before this seq is applied. Past the last item it applied,
    /// up to the one it is stopped at (or, stopped at none, as far as its
    /// last batch says the stream got), since items for others are not
    /// sent to it. The sensor's flow control reads it.
    pub fn done_through(&self) -> u64 {
        let stopped_at = match self.waiting {
            Some(Waiting::Transfer { seq, .. })
            | Some(Waiting::Components { seq, .. })
            | Some(Waiting::Follow { seq }) => Some(seq),
            None => self
                .queue
                .first_key_value()
                .map(|(seq, _)| *seq)
                .filter(|seq| *seq <= self.frontier),
        };
        stopped_at
            .map_or(self.frontier, |seq| seq.saturating_sub(1))
            .max(self.position)
    }

    /// Whether the leader has applied every item it was sent and is
    /// stopped at none: [`Leader::done_through`] is as far as its batches
    /// go.
    pub(crate) fn caught_up(&self) -> bool {
        self.done_through() >= self.frontier
    }

    /// The stream's field, once it began: what inputs must fit
    /// ([`crate::door`]).
    pub(crate) fn bounds(&self) -> Option<Bounds> {
        self.started.as_ref().map(|s| Bounds::of(&s.begin))
    }

    /// The share this leader holds (for tests and diagnostics).
    #[cfg(test)]
    pub(crate) fn share(&self) -> Option<&RadonShare> {
        self.started.as_ref().map(|s| &s.share)
    }

    /// The components this leader holds, on a factored stream.
    #[cfg(test)]
    pub(crate) fn factored(&self) -> Option<&FactoredShare> {
        self.started.as_ref().and_then(|s| s.factored.as_ref())
    }

    /// The leaders of the stream, once it began.
    pub(crate) fn leaders(&self) -> &[String] {
        self.started
            .as_ref()
            .map_or(&[], |s| s.begin.leaders.as_slice())
    }

    /// This leader's index in the stream's list, once it began.
    pub fn index(&self) -> Option<u16> {
        self.started.as_ref().map(|s| s.me)
    }

    /// The name of leader `index` of the stream's list.
    pub(crate) fn peer(&self, index: u16) -> Option<&str> {
        let started = self.started.as_ref()?;
        started
            .begin
            .leaders
            .get(index as usize)
            .map(String::as_str)
    }

    fn me(&self) -> Result<u16, LeaderError> {
        self.started
            .as_ref()
            .map(|s| s.me)
            .ok_or(LeaderError::Unexpected("an item before the stream's Begin"))
    }

    fn started(&mut self) -> Result<&mut Started, LeaderError> {
        self.started
            .as_mut()
            .ok_or(LeaderError::Unexpected("an item before the stream's Begin"))
    }

    /// How far this leader is, as a mark for the others: the next batch
    /// it expects and the last item it has everything of, its transfers
    /// included (the others keep what they sent after it).
    pub fn durable(&self) -> Durable {
        Durable {
            epoch: self.epoch,
            version: VERSION,
            leader: self.name.clone(),
            batch: self.next_batch,
            position: self.received_through(),
        }
    }

    /// The last item this leader has applied and received every transfer
    /// of: its position, or just before the first item whose transfer has
    /// not come. A peer asked for what it sent is asked from here.
    pub(crate) fn received_through(&self) -> u64 {
        self.pending.first().map_or(self.position, |p| {
            self.position.min(p.seq.saturating_sub(1))
        })
    }

    /// The number of the next batch this leader will apply.
    pub fn next_batch(&self) -> u64 {
        self.next_batch
    }
}
