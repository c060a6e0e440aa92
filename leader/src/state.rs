//! The leader as a pure state machine: items of its event stream in, sets
//! for other leaders and follow requests out. No I/O, so the whole protocol
//! can be run in one process by tests (see `tests` below) and the actor in
//! [`actor`](crate::actor) only moves bytes.
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

use crate::error::LeaderError;
use idmesh_belief::identity::information::KNOWN_START_CONFIDENCE;
use idmesh_belief::identity::{Identify, InformationRows};
use idmesh_belief::radon::{
    Atom, Growth as BeliefGrowth, PartialSums, RadonOptions, RadonShare, Sparsify,
};
use idmesh_belief::{Field, Mix, Observe, RedCount, TrackSet};
use idmesh_protocol::wire::bounds::Bounds;
use idmesh_protocol::wire::coordinator_to_leader::{LeaderStats, Partial};
use idmesh_protocol::wire::interest::Interest;
use idmesh_protocol::wire::leader_to_leader::{Transfer, WireRow, WireSet};
use idmesh_protocol::wire::leader_to_sensor::{Durable, Follow};
use idmesh_protocol::wire::sensor_to_leader::{Batch, Begin, Growth, Item, Sequenced};
use idmesh_protocol::wire::VERSION;
use serde::{Deserialize, Serialize};
use std::collections::{BTreeMap, HashMap, VecDeque};

/// How many recent cuts a leader keeps answers for.
const CUTS_KEPT: usize = 256;

/// What the leader asks its actor to do.
#[derive(Debug, Clone, PartialEq)]
pub enum Action {
    /// Send these sets to leader `to` (an index into `Begin::leaders`).
    Send { to: u16, transfer: Transfer },
    /// Ask the sensor to follow more tracks; answer with
    /// [`Leader::followed`].
    Follow(Follow),
    /// The partial sums at a cut are ready.
    CutReady(Partial),
}

/// Where the leader is stopped, if anywhere.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
enum Waiting {
    /// For the sets of leader `from` at item `seq`.
    Transfer { seq: u64, from: u16 },
    /// For the sensor's answer to a follow request made at `seq`.
    Follow { seq: u64 },
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
    /// Batches that came ahead of a missing one, by number, with their size.
    ahead: BTreeMap<u64, (Batch, usize)>,
    /// Every transfer sent, with its receiver: a restarted peer asks for
    /// the ones it lost while it was down.
    sent: Vec<(u16, Transfer)>,
    /// The follow request waiting for its answer (asked again after a
    /// restart).
    asked: Option<Follow>,
    /// Sets and rows that arrived before the leader reached their item.
    transfers: HashMap<(u64, u16), (Vec<WireSet>, Vec<WireRow>)>,
    waiting: Option<Waiting>,
    cuts: VecDeque<Partial>,
    /// The watermark and end-of-stream flag of the last batch.
    events: u64,
    finished: bool,
    stats: LeaderStats,
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
            ahead: BTreeMap::new(),
            sent: Vec::new(),
            asked: None,
            transfers: HashMap::new(),
            waiting: None,
            cuts: VecDeque::new(),
            events: 0,
            finished: false,
        }
    }

    pub fn name(&self) -> &str {
        &self.name
    }

    /// The whole state, as bytes ([`Leader::restore`] reads them back).
    pub fn snapshot(&self) -> Vec<u8> {
        postcard::to_allocvec(self).unwrap_or_default()
    }

    /// The leader a snapshot was taken of.
    pub fn restore(bytes: &[u8]) -> Result<Leader, LeaderError> {
        postcard::from_bytes(bytes).map_err(|e| LeaderError::Snapshot(e.to_string()))
    }

    /// Names the process running this leader (for its counters).
    pub fn set_host(&mut self, host: &str) {
        self.stats.host = host.to_string();
    }

    /// How long the last recovery (restart or adoption) took to catch up.
    pub fn note_recovered(&mut self, seconds: f64) {
        self.stats.recoveries += 1;
        self.stats.recovery_seconds = seconds;
    }

    /// Counts a snapshot taken.
    pub fn note_snapshot(&mut self) {
        self.stats.snapshots += 1;
    }

    pub fn position(&self) -> u64 {
        self.position
    }

    pub fn stats(&self) -> LeaderStats {
        let mut stats = self.stats.clone();
        stats.position = self.position;
        stats.transfers_kept = self.sent.len() as u64;
        if let Some(s) = &self.started {
            stats.coefficients = s.share.len() as u64;
            stats.omp_runs = s.share.omp_runs();
            stats.tracks_owned = s.own.iter().filter(|&&o| o).count() as u64;
            stats.tracks_followed = s.interest.len() as u64;
            stats.rows_held = s.rows.as_ref().map_or(0, |r| r.len() as u64);
        }
        stats
    }

    /// The stream's field, once it began: what inputs must fit
    /// ([`crate::door`]).
    pub fn bounds(&self) -> Option<Bounds> {
        self.started.as_ref().map(|s| Bounds::of(&s.begin))
    }

    /// Counts an input refused at the door; returns the count so far.
    pub fn note_rejected(&mut self) -> u64 {
        self.stats.rejected += 1;
        self.stats.rejected
    }

    /// Counts bytes the actor sent for this leader.
    pub fn note_sent(&mut self, bytes: usize) {
        self.stats.bytes_sent += bytes as u64;
    }

    /// The answer at the cut tagged `tag`, if this leader has passed it
    /// recently.
    pub fn cut(&self, tag: u64) -> Option<&Partial> {
        self.cuts.iter().find(|p| p.tag == tag)
    }

    /// The partial sums now, if the leader is at a quiet point: it has
    /// applied every item the sensor sent it and waits for no peer. Leaders
    /// quiet at the same seq together hold the belief at that seq (every
    /// set sent before it has been received), which is how the coordinator
    /// answers a finished stream without placing a cut.
    /// With `rows`, the leader's rows of the information matrix too.
    pub fn quiet(&self, rows: bool) -> Option<Partial> {
        if self.waiting.is_some() || !self.queue.is_empty() {
            return None;
        }
        self.partial(self.frontier, 0, self.events, rows)
    }

    /// The partial sums of the share as it is (None before the Begin),
    /// with the rows held when `rows` asks for them.
    fn partial(&self, cut: u64, tag: u64, events: u64, rows: bool) -> Option<Partial> {
        let started = self.started.as_ref()?;
        let sums = started.share.partial_sums();
        let rows = match (&started.rows, rows) {
            (Some(held), true) => held
                .rows()
                .map(|(track, row)| to_wire(track, row))
                .collect(),
            _ => Vec::new(),
        };
        Some(Partial {
            version: VERSION,
            leader: self.name.clone(),
            cut,
            tag,
            events,
            finished: self.finished,
            log_scale: sums.log_scale,
            total: sums.total,
            outside: sums.outside,
            inside: sums.inside,
            coefficients: sums.coefficients,
            rows,
        })
    }

    /// The share this leader holds (for tests and diagnostics).
    pub fn share(&self) -> Option<&RadonShare> {
        self.started.as_ref().map(|s| &s.share)
    }

    /// A batch of the event stream arrived. Batches are applied in number
    /// order: one seen before is dropped (counted as a duplicate), one
    /// ahead of a missing one waits for it ([`Leader::missing_batches`]
    /// says which to ask the sensor for again).
    pub fn batch(&mut self, batch: Batch, bytes: usize) -> Result<Vec<Action>, LeaderError> {
        if batch.number < self.next_batch || self.ahead.contains_key(&batch.number) {
            self.stats.duplicates += 1;
            return Ok(Vec::new());
        }
        if batch.number > self.next_batch {
            if self.ahead.is_empty() {
                self.stats.gaps += 1;
            }
            self.ahead.insert(batch.number, (batch, bytes));
            return Ok(Vec::new());
        }
        let mut actions = self.take_batch(batch, bytes)?;
        while let Some(entry) = self.ahead.first_entry() {
            if *entry.key() != self.next_batch {
                break;
            }
            let (batch, bytes) = entry.remove();
            // Held before the Begin, it was checked on its own only: a
            // misfit is dropped like a lost batch (the next gap asks for
            // it again).
            if let Some(Err(e)) = self.bounds().map(|b| b.check_batch(&batch)) {
                tracing::warn!(leader = %self.name, number = batch.number, error = %e, "batch rejected");
                self.stats.rejected += 1;
                break;
            }
            actions.extend(self.take_batch(batch, bytes)?);
        }
        Ok(actions)
    }

    /// The first batch number missing before one that arrived, if any.
    pub fn missing_batches(&self) -> Option<u64> {
        (!self.ahead.is_empty()).then_some(self.next_batch)
    }

    /// The number of the next batch this leader will apply.
    pub fn next_batch(&self) -> u64 {
        self.next_batch
    }

    /// The transfers sent to leader `to` for items after `after`.
    pub fn sent_to(&self, to: u16, after: u64) -> Vec<Transfer> {
        self.sent
            .iter()
            .filter(|(receiver, t)| *receiver == to && t.seq > after)
            .map(|(_, t)| t.clone())
            .collect()
    }

    /// Every transfer sent, with its receiver (resent after a restart: the
    /// peers drop the ones they have).
    pub fn all_sent(&self) -> &[(u16, Transfer)] {
        &self.sent
    }

    /// Leader `name` has its state safe through item `position`: it will
    /// never ask for the transfers of items up to there again, so they are
    /// dropped. Returns how many were.
    pub fn forget_sent(&mut self, name: &str, position: u64) -> usize {
        let Some(to) = self.leaders().iter().position(|l| l == name) else {
            return 0;
        };
        let before = self.sent.len();
        self.sent
            .retain(|(receiver, t)| *receiver as usize != to || t.seq > position);
        before - self.sent.len()
    }

    /// How far this leader is, as a mark for the others: the next batch
    /// it expects and the last item it applied.
    pub fn durable(&self) -> Durable {
        Durable {
            version: VERSION,
            leader: self.name.clone(),
            batch: self.next_batch,
            position: self.position,
        }
    }

    /// The follow request still waiting for the sensor's answer.
    pub fn pending_follow(&self) -> Option<&Follow> {
        self.asked.as_ref()
    }

    /// The leaders of the stream, once it began.
    pub fn leaders(&self) -> &[String] {
        self.started
            .as_ref()
            .map_or(&[], |s| s.begin.leaders.as_slice())
    }

    /// This leader's index in the stream's list, once it began.
    pub fn index(&self) -> Option<u16> {
        self.started.as_ref().map(|s| s.me)
    }

    /// Applies the next batch in number order.
    fn take_batch(&mut self, batch: Batch, bytes: usize) -> Result<Vec<Action>, LeaderError> {
        self.next_batch += 1;
        self.stats.batches += 1;
        self.stats.bytes_received += bytes as u64;
        for Sequenced { seq, item } in batch.items {
            if seq > self.position {
                self.queue.insert(seq, item);
            }
            self.frontier = self.frontier.max(seq);
        }
        self.frontier = self.frontier.max(batch.through);
        self.events = batch.events;
        self.finished = batch.finished;
        self.advance()
    }

    /// Sets from another leader arrived. A leader never passes an item
    /// whose transfer it waits for, so one for an item already passed, or
    /// already here, is a duplicate (a restarted peer resends what it
    /// sent): dropped and counted.
    pub fn transfer(
        &mut self,
        transfer: Transfer,
        bytes: usize,
    ) -> Result<Vec<Action>, LeaderError> {
        if transfer.seq <= self.position
            || self.transfers.contains_key(&(transfer.seq, transfer.from))
        {
            self.stats.duplicates += 1;
            return Ok(Vec::new());
        }
        self.stats.transfers_received += 1;
        self.stats.bytes_received += bytes as u64;
        self.transfers.insert(
            (transfer.seq, transfer.from),
            (transfer.sets, transfer.rows),
        );
        self.advance()
    }

    /// The sensor answered a follow request: the items this leader missed.
    pub fn followed(&mut self, items: Vec<Sequenced>) -> Result<Vec<Action>, LeaderError> {
        let Some(Waiting::Follow { seq }) = self.waiting else {
            return Err(LeaderError::Unexpected("a follow reply nobody asked for"));
        };
        self.asked = None;
        for Sequenced { seq: s, item } in items {
            if s > seq {
                self.queue.insert(s, item);
            }
        }
        self.waiting = None;
        self.finish(seq);
        self.advance()
    }

    /// Applies queued items in seq order until one must wait.
    fn advance(&mut self) -> Result<Vec<Action>, LeaderError> {
        let mut actions = Vec::new();
        loop {
            match self.waiting {
                Some(Waiting::Transfer { seq, from }) => {
                    match self.transfers.remove(&(seq, from)) {
                        Some((sets, rows)) => {
                            self.waiting = None;
                            self.receive_rows(rows)?;
                            self.receive_sets(seq, sets, &mut actions)?;
                            if self.waiting.is_some() {
                                return Ok(actions);
                            }
                            self.finish(seq);
                        }
                        None => return Ok(actions),
                    }
                }
                Some(Waiting::Follow { .. }) => return Ok(actions),
                None => {}
            }
            let Some(next) = self.queue.first_entry() else {
                return Ok(actions);
            };
            if *next.key() > self.frontier {
                return Ok(actions);
            }
            let (seq, item) = next.remove_entry();
            let _span = tracing::debug_span!("item", leader = %self.name, seq).entered();
            self.apply(seq, item, &mut actions)?;
            if self.waiting.is_none() {
                self.finish(seq);
            }
        }
    }

    fn started(&mut self) -> Result<&mut Started, LeaderError> {
        self.started
            .as_mut()
            .ok_or(LeaderError::Unexpected("an item before the stream's Begin"))
    }

    fn apply(
        &mut self,
        seq: u64,
        item: Item,
        actions: &mut Vec<Action>,
    ) -> Result<(), LeaderError> {
        self.stats.items += 1;
        if let Item::Begin(begin) = &item {
            return self.begin(begin.clone());
        }
        let me = self.me()?;
        let started = self.started()?;
        started.interest.note(&item);
        match item {
            Item::Begin(_) => {}
            Item::Mix {
                a,
                b,
                swap,
                owner_a,
                owner_b,
            } => {
                self.stats.mixes += 1;
                let mix = Mix { a, b, swap };
                let started = self.started()?;
                started.share.mix(mix)?;
                // My mixed track and the other leader, for a mix across two.
                let across = match (owner_a == me, owner_b == me) {
                    (true, false) => Some((a, owner_b)),
                    (false, true) => Some((b, owner_a)),
                    (true, true) => {
                        if let Some(rows) = &mut started.rows {
                            rows.mix(mix)?;
                        }
                        None
                    }
                    (false, false) => None,
                };
                if let Some((mine, other)) = across {
                    // Algorithm 4: both leaders of a cross-leader mix hand
                    // over what left their tracks, and wait for the other.
                    // The row of the mixed track goes along, unmixed: the
                    // fit needs both, and both leaders compute it.
                    let row = match &started.rows {
                        Some(rows) => {
                            started.row_mix = Some(mix);
                            vec![wire_row(rows, mine)?]
                        }
                        None => Vec::new(),
                    };
                    self.send_homeless(seq, other, row, actions)?;
                    self.waiting = Some(Waiting::Transfer { seq, from: other });
                }
            }
            Item::Observe {
                track,
                red,
                blue,
                growth,
                ..
            } => {
                self.stats.observations += 1;
                let observe = Observe { track, red, blue };
                let started = self.started()?;
                match &growth {
                    Growth::All => started.share.observe(observe, BeliefGrowth::All)?,
                    Growth::Meeting(p) => {
                        started.share.observe(observe, BeliefGrowth::Meeting(p))?
                    }
                }
            }
            Item::Handover { track, from, to } => {
                self.stats.handovers += 1;
                let started = self.started()?;
                let slot = started
                    .own
                    .get_mut(track as usize)
                    .ok_or(LeaderError::Unexpected("a handover of an unknown track"))?;
                if from == me {
                    *slot = false;
                    let row = match &mut started.rows {
                        Some(rows) => {
                            let ln_likelihoods = rows.take(track).ok_or(NOT_HELD)?;
                            vec![WireRow {
                                track,
                                ln_likelihoods,
                            }]
                        }
                        None => Vec::new(),
                    };
                    self.send_homeless(seq, to, row, actions)?;
                } else if to == me {
                    *slot = true;
                    self.waiting = Some(Waiting::Transfer { seq, from });
                }
            }
            Item::Identify {
                track,
                identity,
                accuracy,
                ..
            } => {
                self.stats.identifies += 1;
                let rows = self
                    .started()?
                    .rows
                    .as_mut()
                    .ok_or(LeaderError::Unexpected(
                        "an identity read on a stream without identities",
                    ))?;
                rows.identify(Identify {
                    track,
                    identity,
                    accuracy,
                })?;
            }
            Item::Cut { events, tag, rows } => {
                let partial = self
                    .partial(seq, tag, events, rows)
                    .ok_or(LeaderError::Unexpected("a cut before the stream's Begin"))?;
                if self.cuts.len() == CUTS_KEPT {
                    self.cuts.pop_front();
                }
                self.cuts.push_back(partial.clone());
                actions.push(Action::CutReady(partial));
            }
        }
        Ok(())
    }

    fn me(&self) -> Result<u16, LeaderError> {
        self.started
            .as_ref()
            .map(|s| s.me)
            .ok_or(LeaderError::Unexpected("an item before the stream's Begin"))
    }

    /// The name of leader `index` of the stream's list.
    pub fn peer(&self, index: u16) -> Option<&str> {
        let started = self.started.as_ref()?;
        started
            .begin
            .leaders
            .get(index as usize)
            .map(String::as_str)
    }

    fn begin(&mut self, begin: Begin) -> Result<(), LeaderError> {
        let me = begin
            .leaders
            .iter()
            .position(|l| *l == self.name)
            .ok_or_else(|| LeaderError::NotListed(self.name.clone()))? as u16;
        let (share, interest) = start(&begin, me)?;
        let own: Vec<bool> = begin.owners.iter().map(|&o| o == me).collect();
        let rows = if begin.identities {
            let held = (0..begin.tracks).filter(|&t| own[t as usize]);
            Some(InformationRows::start(
                begin.tracks as usize,
                held,
                begin.initial_identity.as_deref(),
                KNOWN_START_CONFIDENCE,
            )?)
        } else {
            None
        };
        // Transfers that came before the Begin were checked on their own
        // only ([`crate::door`]): what does not fit the field goes now.
        let bounds = Bounds::of(&begin);
        let before = self.transfers.len();
        self.transfers
            .retain(|&(_, from), (sets, rows)| bounds.check_parts(from, sets, rows, me).is_ok());
        self.stats.rejected += (before - self.transfers.len()) as u64;
        self.started = Some(Started {
            me,
            begin,
            share,
            own,
            interest,
            rows,
            row_mix: None,
        });
        Ok(())
    }

    /// Takes out the sets with none of this leader's tracks (but not φ_∅)
    /// and sends them, with `rows`, to `to` as the transfer of item `seq`.
    fn send_homeless(
        &mut self,
        seq: u64,
        to: u16,
        rows: Vec<WireRow>,
        actions: &mut Vec<Action>,
    ) -> Result<(), LeaderError> {
        let me = self.me()?;
        let started = self.started()?;
        let own = &started.own;
        let sets: Vec<WireSet> = started
            .share
            .extract(|atom| {
                let mut tracks = atom.tracks().peekable();
                tracks.peek().is_some() && !tracks.any(|t| own[t as usize])
            })
            .into_iter()
            .map(|(atom, ln_mass)| WireSet {
                red: atom.red.tracks().to_vec(),
                blue: atom.blue.tracks().to_vec(),
                ln_mass,
            })
            .collect();
        self.stats.transfers_sent += 1;
        self.stats.sets_sent += sets.len() as u64;
        let transfer = Transfer {
            version: VERSION,
            from: me,
            seq,
            sets,
            rows,
        };
        self.sent.push((to, transfer.clone()));
        actions.push(Action::Send { to, transfer });
        Ok(())
    }

    /// Rows received with a transfer: the partner's row of a cross-leader
    /// mix (the fit is made now), or the row of a track handed over.
    fn receive_rows(&mut self, received: Vec<WireRow>) -> Result<(), LeaderError> {
        let started = self.started()?;
        let pending = started.row_mix.take();
        let Some(rows) = &mut started.rows else {
            return match received.is_empty() {
                true => Ok(()),
                false => Err(LeaderError::BadTransfer(
                    "rows of an information matrix on a stream without identities".into(),
                )),
            };
        };
        match pending {
            Some(mix) => {
                let partner = match received.as_slice() {
                    [row]
                        if !rows.holds(row.track) && (row.track == mix.a || row.track == mix.b) =>
                    {
                        row
                    }
                    _ => {
                        return Err(LeaderError::BadTransfer(format!(
                        "a mix of tracks {} and {} needs the partner's one row, got rows of {:?}",
                        mix.a,
                        mix.b,
                        received.iter().map(|r| r.track).collect::<Vec<_>>()
                    )))
                    }
                };
                rows.mix_with(mix, &partner.ln_likelihoods)
                    .map_err(|e| LeaderError::BadTransfer(e.to_string()))?;
            }
            None => {
                for row in received {
                    rows.insert(row.track, row.ln_likelihoods)
                        .map_err(|e| LeaderError::BadTransfer(e.to_string()))?;
                }
            }
        }
        Ok(())
    }

    /// Adds sets received at item `seq`; asks to follow tracks they bring.
    fn receive_sets(
        &mut self,
        seq: u64,
        sets: Vec<WireSet>,
        actions: &mut Vec<Action>,
    ) -> Result<(), LeaderError> {
        let me = self.me()?;
        let started = self.started()?;
        let tracks = started.begin.tracks;
        let mut atoms = Vec::with_capacity(sets.len());
        for set in sets {
            if let Some(&t) = set.red.iter().chain(&set.blue).find(|&&t| t >= tracks) {
                return Err(LeaderError::BadTransfer(format!(
                    "set with track {t} of {tracks}"
                )));
            }
            if set.ln_mass.is_nan() || set.ln_mass == f64::INFINITY {
                return Err(LeaderError::BadTransfer(format!(
                    "set with log mass {}",
                    set.ln_mass
                )));
            }
            atoms.push((
                Atom::new(
                    TrackSet::from_tracks(set.red.iter().copied()),
                    TrackSet::from_tracks(set.blue.iter().copied()),
                ),
                set.ln_mass,
            ));
        }
        let mut new_tracks: Vec<u32> = Vec::new();
        for (atom, _) in &atoms {
            for t in atom.tracks() {
                if started.interest.add(t) {
                    new_tracks.push(t);
                }
            }
        }
        started.share.absorb(atoms);
        if !new_tracks.is_empty() {
            new_tracks.sort_unstable();
            self.stats.follows += 1;
            let follow = Follow {
                version: VERSION,
                leader: me,
                after: seq,
                tracks: new_tracks,
            };
            self.asked = Some(follow.clone());
            actions.push(Action::Follow(follow));
            self.waiting = Some(Waiting::Follow { seq });
        }
        Ok(())
    }

    /// Item `seq` is fully applied.
    fn finish(&mut self, seq: u64) {
        self.position = seq;
        if let Some(started) = &mut self.started {
            let budget = started.begin.budget as usize;
            if budget > 0 {
                let sparsify = if started.begin.omp {
                    Sparsify::overcomplete(budget)
                } else {
                    Sparsify::threshold(budget)
                };
                // A numerical failure of OMP leaves the share thresholded.
                if let Err(e) = started.share.sparsify(&sparsify) {
                    tracing::warn!(leader = %self.name, seq, error = %e, "OMP failed; thresholded instead");
                }
            }
        }
    }
}

/// An owned track's row is missing: the state is broken.
const NOT_HELD: LeaderError =
    LeaderError::Unexpected("an event on an owned track whose row this leader does not hold");

/// Row `track` as it goes on the wire.
fn wire_row(rows: &InformationRows, track: u32) -> Result<WireRow, LeaderError> {
    Ok(to_wire(track, rows.row(track).ok_or(NOT_HELD)?))
}

fn to_wire(track: u32, row: &[f64]) -> WireRow {
    WireRow {
        track,
        ln_likelihoods: row.to_vec(),
    }
}

/// Leader `me`'s share of the start belief and its interest: each set
/// starts with the leader of its first track, φ_∅ with leader 0. The sensor
/// computes the same to route the first items.
pub fn start(begin: &Begin, me: u16) -> Result<(RadonShare, Interest), LeaderError> {
    let tracks = begin.tracks as usize;
    if begin.owners.len() != tracks
        || begin
            .owners
            .iter()
            .any(|&o| o as usize >= begin.leaders.len())
    {
        return Err(LeaderError::Unexpected(
            "a Begin whose owners do not match its tracks and leaders",
        ));
    }
    let options = RadonOptions {
        distributed_rule: begin.distributed_rule,
        ..RadonOptions::default()
    };
    let mut share = RadonShare::start(field_of(begin), &options)?;
    let owners = &begin.owners;
    share.extract(|atom| atom.tracks().min().map(|t| owners[t as usize]).unwrap_or(0) != me);
    let holds_empty = share.atoms().any(|(a, _)| a.tracks().next().is_none());
    let mut interest = Interest::new(me, tracks, holds_empty);
    for (atom, _) in share.atoms() {
        for t in atom.tracks() {
            interest.add(t);
        }
    }
    interest.note(&Item::Begin(begin.clone()));
    Ok((share, interest))
}

/// The field a stream's Begin describes (as `idmesh replay` reads a header).
pub fn field_of(begin: &Begin) -> Field {
    let tracks = begin.tracks as usize;
    Field {
        tracks,
        red: match begin.red {
            Some(k) => RedCount::Known(k as usize),
            None => RedCount::unknown_uniform(tracks),
        },
        initial_red: begin.initial_red.clone(),
    }
}

/// The answer to a query from every leader's partial sums.
pub fn combine(parts: &[Partial]) -> PartialSums {
    let sums: Vec<PartialSums> = parts
        .iter()
        .map(|p| PartialSums {
            log_scale: p.log_scale,
            total: p.total,
            outside: p.outside,
            inside: p.inside.clone(),
            coefficients: p.coefficients,
        })
        .collect();
    PartialSums::combine(&sums)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn begin(leaders: &[&str], owners: Vec<u16>) -> Item {
        Item::Begin(Begin {
            tracks: owners.len() as u32,
            red: Some(2),
            initial_red: Some(vec![0, 1]),
            leaders: leaders.iter().map(|l| l.to_string()).collect(),
            owners,
            distributed_rule: false,
            budget: 0,
            omp: false,
            identities: false,
            initial_identity: None,
        })
    }

    fn batch(number: u64, items: Vec<(u64, Item)>, through: u64, finished: bool) -> Batch {
        Batch {
            version: VERSION,
            sensor: "sensor-0".into(),
            number,
            through,
            events: through,
            finished,
            items: items
                .into_iter()
                .map(|(seq, item)| Sequenced { seq, item })
                .collect(),
        }
    }

    fn mix(a: u32, b: u32, owner_a: u16, owner_b: u16) -> Item {
        Item::Mix {
            a,
            b,
            swap: 0.5,
            owner_a,
            owner_b,
        }
    }

    #[test]
    fn a_leader_rests_only_when_it_has_applied_all_it_was_sent_and_waits_for_nobody() {
        let mut leader = Leader::new("a");
        assert!(leader.quiet(false).is_none(), "no Begin yet");
        leader
            .batch(
                batch(0, vec![(1, begin(&["a", "b"], vec![0, 0, 1, 1]))], 1, false),
                0,
            )
            .unwrap();
        let rest = leader.quiet(false).expect("quiet after the Begin");
        assert_eq!((rest.cut, rest.finished), (1, false));
        // A mix with b's track: the leader must wait for b's sets.
        let actions = leader
            .batch(batch(1, vec![(2, mix(0, 2, 0, 1))], 2, true), 0)
            .unwrap();
        assert!(actions
            .iter()
            .any(|a| matches!(a, Action::Send { to: 1, .. })));
        assert!(leader.quiet(false).is_none(), "waiting for b's sets");
        leader
            .transfer(
                Transfer {
                    version: VERSION,
                    from: 1,
                    seq: 2,
                    sets: Vec::new(),
                    rows: Vec::new(),
                },
                0,
            )
            .unwrap();
        let rest = leader.quiet(false).expect("quiet once b's sets are in");
        assert_eq!((rest.cut, rest.events, rest.finished), (2, 2, true));
    }

    #[test]
    fn a_cut_is_answered_by_its_tag_and_a_gap_waits_for_the_missing_batch() {
        let mut leader = Leader::new("a");
        leader
            .batch(
                batch(0, vec![(1, begin(&["a"], vec![0, 0, 0]))], 1, false),
                0,
            )
            .unwrap();
        let cut = Item::Cut {
            events: 7,
            tag: 42,
            rows: false,
        };
        let actions = leader
            .batch(batch(1, vec![(2, mix(0, 2, 0, 0)), (3, cut)], 3, false), 0)
            .unwrap();
        assert!(actions
            .iter()
            .any(|a| matches!(a, Action::CutReady(p) if p.tag == 42 && p.cut == 3)));
        let partial = leader.cut(42).expect("kept for late queries");
        assert_eq!(partial.events, 7);
        assert!(leader.cut(41).is_none());
        // Batch 3 before batch 2: held, and batch 2 is asked for.
        let ahead = batch(3, vec![(5, mix(1, 2, 0, 0))], 5, false);
        assert!(leader.batch(ahead.clone(), 0).unwrap().is_empty());
        assert_eq!(leader.missing_batches(), Some(2));
        assert_eq!(leader.position(), 3);
        leader
            .batch(batch(2, vec![(4, mix(0, 1, 0, 0))], 4, false), 0)
            .unwrap();
        assert_eq!(leader.missing_batches(), None);
        assert_eq!(leader.position(), 5);
        // Both again: dropped, counted, nothing applied twice.
        leader.batch(ahead, 0).unwrap();
        leader.batch(batch(2, vec![], 4, false), 0).unwrap();
        let stats = leader.stats();
        assert_eq!((stats.mixes, stats.duplicates, stats.gaps), (3, 2, 1));
    }

    /// Delivered twice, with batches out of order, an exchange between two
    /// leaders ends in the same shares as delivered once in order.
    #[test]
    fn duplicates_and_reordered_batches_change_nothing() {
        let begin = begin(&["a", "b"], vec![0, 0, 1, 1]);
        let items = [
            (2, mix(0, 2, 0, 1)),
            (3, mix(1, 3, 0, 1)),
            (4, mix(0, 1, 0, 0)),
            (5, mix(2, 3, 1, 1)),
        ];
        let batches = |leader: &str| -> Vec<Batch> {
            let mut out = vec![batch(0, vec![(1, begin.clone())], 1, false)];
            for (i, (seq, item)) in items.iter().enumerate() {
                let wanted = match item {
                    Item::Mix {
                        owner_a, owner_b, ..
                    } => {
                        let me = if leader == "a" { 0 } else { 1 };
                        *owner_a == me || *owner_b == me
                    }
                    _ => true,
                };
                let sent = if wanted {
                    vec![(*seq, item.clone())]
                } else {
                    vec![]
                };
                out.push(batch(i as u64 + 1, sent, *seq, i + 1 == items.len()));
            }
            out
        };
        // Runs both leaders to the end, delivering each one's batches in
        // `order` (indices, repeats allowed) and every transfer twice.
        // With `snapshots`, both leaders are replaced by what their
        // snapshot restores before every delivery.
        let run = |order: &[usize], snapshots: bool| {
            let (mut a, mut b) = (Leader::new("a"), Leader::new("b"));
            let (batches_a, batches_b) = (batches("a"), batches("b"));
            let mut mail: Vec<(u16, Transfer)> = Vec::new();
            for &i in order {
                if snapshots {
                    a = Leader::restore(&a.snapshot()).unwrap();
                    b = Leader::restore(&b.snapshot()).unwrap();
                }
                for (leader, batches) in [(&mut a, &batches_a), (&mut b, &batches_b)] {
                    for action in leader.batch(batches[i].clone(), 0).unwrap() {
                        if let Action::Send { to, transfer } = action {
                            mail.push((to, transfer));
                        }
                    }
                }
                while let Some((to, transfer)) = mail.pop() {
                    for _ in 0..2 {
                        let leader = if to == 0 { &mut a } else { &mut b };
                        for action in leader.transfer(transfer.clone(), 0).unwrap() {
                            if let Action::Send { to, transfer } = action {
                                mail.push((to, transfer));
                            }
                        }
                    }
                }
            }
            let shares: Vec<Vec<(Atom, f64)>> = [&a, &b]
                .iter()
                .map(|l| {
                    let mut atoms: Vec<(Atom, f64)> = l
                        .share()
                        .unwrap()
                        .atoms()
                        .map(|(atom, m)| (atom.clone(), m))
                        .collect();
                    atoms.sort_by(|x, y| format!("{:?}", x.0).cmp(&format!("{:?}", y.0)));
                    atoms
                })
                .collect();
            (shares, a.position(), b.position(), a.stats().duplicates)
        };
        let once = run(&[0, 1, 2, 3, 4], false);
        let shuffled = run(&[0, 3, 1, 1, 4, 2, 0, 3, 4], false);
        // a is not sent the last mix (b's tracks only).
        assert_eq!((once.1, once.2), (4, 5));
        assert_eq!((shuffled.1, shuffled.2), (4, 5));
        assert_eq!(once.0, shuffled.0);
        assert!(shuffled.3 > once.3, "duplicates were seen and dropped");
        // Restored from snapshots at every step, held batches, transfers
        // waited for and all: the same shares.
        let restored = run(&[0, 3, 1, 1, 4, 2, 0, 3, 4], true);
        assert_eq!((restored.1, restored.2, restored.3), (4, 5, shuffled.3));
        for (x, y) in restored.0.iter().flatten().zip(shuffled.0.iter().flatten()) {
            assert_eq!(x.0, y.0);
            assert!((x.1 - y.1).abs() < 1e-12, "{x:?} vs {y:?}");
        }
    }

    /// Two leaders on an identity stream, driven by hand: reads cost no
    /// message, a cross-leader mix exchanges the two rows, a handover moves
    /// one; the rows put together equal the centralized information matrix.
    #[test]
    fn identity_rows_live_with_their_tracks_and_only_mixes_and_handovers_move_them() {
        use idmesh_belief::identity::{IdentityFilter, InformationMatrix, InformationOptions};
        let start = vec![2, 0, 3, 1];
        let begin = Item::Begin(Begin {
            tracks: 4,
            red: None,
            initial_red: None,
            leaders: vec!["a".into(), "b".into()],
            owners: vec![0, 0, 1, 1],
            distributed_rule: false,
            budget: 0,
            omp: false,
            identities: true,
            initial_identity: Some(start.clone()),
        });
        let read = |track, identity, owner| Item::Identify {
            track,
            identity,
            accuracy: 0.8,
            owner,
        };
        let mut central = InformationMatrix::from_assignment(
            &start,
            KNOWN_START_CONFIDENCE,
            InformationOptions::default(),
        )
        .unwrap();
        let (mut a, mut b) = (Leader::new("a"), Leader::new("b"));
        a.batch(batch(0, vec![(1, begin.clone())], 1, false), 0)
            .unwrap();
        b.batch(batch(0, vec![(1, begin)], 1, false), 0).unwrap();

        // Reads: applied where the row is, nothing sent.
        let actions = a
            .batch(batch(1, vec![(2, read(0, 1, 0))], 2, false), 0)
            .unwrap();
        assert!(actions.is_empty(), "{actions:?}");
        let actions = b
            .batch(batch(1, vec![(3, read(3, 3, 1))], 3, false), 0)
            .unwrap();
        assert!(actions.is_empty(), "{actions:?}");
        for (track, identity) in [(0, 1), (3, 3)] {
            central
                .identify(Identify {
                    track,
                    identity,
                    accuracy: 0.8,
                })
                .unwrap();
        }

        // A mix across the two: each sends its row, unmixed, and waits.
        let mix = |seq| {
            (
                seq,
                Item::Mix {
                    a: 1,
                    b: 2,
                    swap: 0.3,
                    owner_a: 0,
                    owner_b: 1,
                },
            )
        };
        let sent_by_a = a.batch(batch(2, vec![mix(4)], 4, false), 0).unwrap();
        let sent_by_b = b.batch(batch(2, vec![mix(4)], 4, false), 0).unwrap();
        central
            .mix(Mix {
                a: 1,
                b: 2,
                swap: 0.3,
            })
            .unwrap();
        let transfer = |actions: Vec<Action>| match actions.as_slice() {
            [Action::Send { transfer, .. }] => transfer.clone(),
            other => panic!("one transfer expected, got {other:?}"),
        };
        let (to_b, to_a) = (transfer(sent_by_a), transfer(sent_by_b));
        assert_eq!(to_b.rows.iter().map(|r| r.track).collect::<Vec<_>>(), [1]);
        assert_eq!(to_a.rows.iter().map(|r| r.track).collect::<Vec<_>>(), [2]);
        a.transfer(to_a, 0).unwrap();
        b.transfer(to_b, 0).unwrap();

        // Track 0 moves to b: its row goes along.
        let handover = (
            5,
            Item::Handover {
                track: 0,
                from: 0,
                to: 1,
            },
        );
        let sent = a
            .batch(batch(3, vec![handover.clone()], 5, true), 0)
            .unwrap();
        b.batch(batch(3, vec![handover], 5, true), 0).unwrap();
        b.transfer(transfer(sent), 0).unwrap();
        assert_eq!(a.stats().rows_held, 1);
        assert_eq!(b.stats().rows_held, 3);
        assert_eq!((a.stats().identifies, b.stats().identifies), (1, 1));

        let rows = [a.quiet(true).unwrap(), b.quiet(true).unwrap()]
            .into_iter()
            .flat_map(|p| p.rows)
            .map(|r| (r.track, r.ln_likelihoods));
        let assembled = InformationRows::assemble(4, rows, InformationOptions::default()).unwrap();
        assert_eq!(assembled.log_likelihoods(), central.log_likelihoods());
        assert!(
            a.quiet(false).unwrap().rows.is_empty(),
            "rows only when asked"
        );
    }
}
