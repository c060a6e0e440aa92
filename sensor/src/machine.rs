//! The sensor gateway as a pure, synchronous state machine: trace lines
//! and requests in, batches and answers out. No I/O and no clock, so the
//! Zenoh actor ([`crate::driver`]) only paces lines and moves bytes, and the
//! deterministic network simulator (`tests/src/sim`) runs the very same
//! code.
//!
//! It holds the [`Router`] (sequencing and routing), one [`BatchLog`] per
//! leader (every batch sent, until the leader's durable mark passes it),
//! the durable marks, and the [`Cuts`] waiting for their point. `Q` is the
//! driver's handle on a cut request (a Zenoh query, a simulated one): the
//! gateway gives it back with the answer.
//!
//! Journaled ([`Gateway::journaled`]), it also writes down every change of
//! its state as a [`Record`] in the order it happened — lines routed (from
//! the trace, an ingest request, standard input) with the cuts placed
//! among them, cuts, granted follows, flushes, the end — for the driver to
//! put on disk ([`Gateway::unjournaled`]) before anything that depends on
//! them leaves. [`Gateway::restore`] feeds them through again: the same
//! seqs, batches, batch logs, producer counters and interests. Durable
//! marks are not journaled: they only let the gateway forget, and a
//! restored gateway keeps everything until the leaders publish theirs
//! again.
//!
//! It also keeps the track numbers a producer's decoder gave named track
//! ids (a ROS 2 topic's names and UUIDs, [`Gateway::name_tracks`]): they
//! are no part of the routing, but the producer's lines carry them, so a
//! restored sensor must number those ids as before
//! ([`Gateway::named_tracks`]).

use crate::batch_log::BatchLog;
use crate::cuts::{place, CutParameters, Cuts, Placed, Request, Wanted};
use crate::extraction::Extraction;
use crate::ingest::{Ingest, IngestRefusal, Offer};
use crate::journal::Record;
use crate::mesh::Mesh;
use crate::router::Router;
use idmesh_protocol::trace::Line;
use idmesh_protocol::wire::coordinator_to_sensor::SensorStats;
use idmesh_protocol::wire::leader_to_sensor::{
    Durable, Follow, Followed, Progress, Resend, Resent, Unfollow,
};
use idmesh_protocol::wire::producer_to_sensor::{IngestAck, LineRefused};
use idmesh_protocol::wire::sensor_to_leader::Batch;
use serde::{Deserialize, Serialize};

use idmesh_protocol::wire::epoch::{Epoched, Fence};
use idmesh_protocol::wire::{decode, encode, Valid, Versioned, VERSION};
use std::collections::BTreeMap;

/// What routing lines gives: the cuts they reached, for the journal the
/// line each came after, and the lines the extractor refused (index, why).
type Routed<Q> = (Vec<Placed<Q>>, Vec<(u32, Wanted)>, Vec<(usize, String)>);

mod meshed;
pub mod replication;
pub mod standbys;

/// What became of a cut request.
pub enum CutOutcome<Q> {
    /// Placed now: flush, then answer the query.
    Placed(Placed<Q>),
    /// Held until the stream reaches its point ([`Gateway::line`] places
    /// it).
    Scheduled,
    /// Refused, with why.
    Refused(Q, String),
}

/// A leader with nothing to be sent is sent an empty batch (only how far
/// the stream got) once the stream is this many seqs past the last batch it
/// was sent: it keeps the leader's position, and so what the sensor may
/// forget (durable marks) and how stale its answers could look, within
/// that distance, at a cost of one batch per this many seqs.
pub(crate) const IDLE_BATCH_EVERY: u64 = 4096;

/// A leader's progress as the sensor knows it ([`Progress`]).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
struct Mark {
    through: u64,
    batch: u64,
}

pub struct Gateway<Q> {
    name: String,
    /// The epoch at which this process holds the sensor role (0 without
    /// voters), stamped on every batch and reply to a leader, so that the
    /// leaders refuse a former holder once they have heard its successor.
    epoch: u64,
    /// Everything the journal rebuilds (and a snapshot holds).
    state: Journaled,
    /// How far each leader has got (its progress marks).
    progress: Vec<Option<Mark>>,
    /// The marks [`Gateway::stalled`] saw last.
    stall_checked: Vec<Option<Mark>>,
    /// An idle leader is sent a batch this many seqs past its last one.
    idle_every: u64,
    /// Flow control: route at most this many seqs past the slowest
    /// leader's progress (None: as fast as the source gives).
    window: Option<u64>,
    cuts: Cuts<Q>,
    /// Changes of state are recorded for the journal.
    journaling: bool,
    /// Recorded, not yet taken by the driver.
    records: Vec<Record>,
    /// One sensor of several: the queries for each cut asked, by tag,
    /// until the merge places or refuses it ...
    waiting: BTreeMap<u64, Vec<Q>>,
    /// ... and then their answers and refusals, for the driver to send.
    answers: Vec<Placed<Q>>,
    refusals: Vec<(Q, String)>,
    /// The named track ids each producer's decoder numbered, in number
    /// order. Outside [`Journaled`], so that a snapshot keeps the layout
    /// older journals hold: a compacted journal states them in records of
    /// their own after its snapshot.
    named: BTreeMap<String, Vec<String>>,
    /// The newest epoch heard from each leader role: what a former holder
    /// (cut off, still running) asks or marks is refused. Not journaled:
    /// after a restart the holder's next message sets it again (the
    /// journal's follow records, replayed, set most of it).
    fence: Fence,
}

/// The part of a gateway's state that its journal's records rebuild, and
/// so what a compacted journal's snapshot holds whole. Progress marks are
/// not in it: leaders publish them again.
#[derive(Serialize, Deserialize)]
struct Journaled {
    router: Router,
    /// The batches sent to each leader that it may still ask for.
    sent: Vec<BatchLog>,
    /// The last durable position each leader published.
    durable: Vec<Option<u64>>,
    /// The `through` of the last batch sent to each leader.
    sent_through: Vec<u64>,
    /// Each leader is owed a batch at the next flush even with nothing
    /// for it (it followed tracks: the items sent with the follow wait for
    /// a batch to say the stream got that far; or it was not yet told the
    /// stream finished).
    owed: Vec<bool>,
    /// Which producers' lines enter the order.
    ingest: Ingest,
    /// The whole source has been read.
    finished: bool,
    /// Requests refused: a bad one is answered with why and changes
    /// nothing.
    stats: SensorStats,
    /// Lines of the trace file routed so far.
    traced: u64,
    /// The number of the last line of standard input read.
    stdin_read: u64,
    /// One sensor of several: its intake and the merge of all.
    mesh: Option<Mesh>,
    /// With extraction on: the stage that turns reports into events.
    #[serde(default)]
    extraction: Option<Extraction>,
}

/// A journal the gateway cannot be rebuilt from (a trace shorter than the
/// journal says, a request it held refused now).
#[derive(Debug, thiserror::Error)]
#[error("journal record {record}: {problem}")]
pub struct RestoreError {
    pub record: usize,
    pub problem: String,
}

impl<Q> Gateway<Q> {
    /// A gateway named `name` streaming through `router`; `finished` when
    /// the source has nothing to stream at all.
    pub fn new(name: &str, router: Router, finished: bool) -> Self {
        let leaders = router.leaders();
        let ingest = Ingest::new(name, router.header());
        Gateway {
            name: name.to_string(),
            state: Journaled {
                router,
                sent: (0..leaders).map(|_| BatchLog::default()).collect(),
                durable: vec![None; leaders],
                sent_through: vec![0; leaders],
                owed: vec![false; leaders],
                ingest,
                finished,
                stats: SensorStats {
                    sensor: name.to_string(),
                    ..SensorStats::default()
                },
                traced: 0,
                stdin_read: 0,
                mesh: None,
                extraction: None,
            },
            progress: vec![None; leaders],
            stall_checked: vec![None; leaders],
            idle_every: IDLE_BATCH_EVERY,
            window: None,
            cuts: Cuts::default(),
            journaling: false,
            records: Vec::new(),
            waiting: BTreeMap::new(),
            answers: Vec::new(),
            refusals: Vec::new(),
            named: BTreeMap::new(),
            fence: Fence::default(),
            epoch: 0,
        }
    }

    /// Holds the sensor role at `epoch` (the voters' claim).
    pub fn at_epoch(mut self, epoch: u64) -> Self {
        self.epoch = epoch;
        self
    }

    /// The voters moved the role held here to `epoch` (the sensor went on
    /// without its standby): what leaves from now on carries it, batches
    /// already flushed too ([`Gateway::restamp`]).
    pub fn advance_epoch(&mut self, epoch: u64) {
        self.epoch = self.epoch.max(epoch);
    }

    /// The epoch at which this gateway holds the sensor role (0 without
    /// voters).
    pub fn epoch(&self) -> u64 {
        self.epoch
    }

    /// `batches` flushed before the role moved to its current epoch, as
    /// they leave now: at that epoch.
    pub fn restamp(&self, batches: &mut [(usize, Batch)]) {
        self.stamp(batches.iter_mut().map(|(_, batch)| batch));
    }

    /// Routes at most `window` seqs past the slowest leader's progress
    /// ([`Gateway::room`]).
    pub fn windowed(mut self, window: u64) -> Self {
        self.window = Some(window);
        self
    }

    /// Sends a leader with nothing queued a batch once the stream is
    /// `seqs` past its last one (default [`IDLE_BATCH_EVERY`]; the
    /// simulator makes it small, so that its short streams take that path).
    pub fn idle_batches_every(mut self, seqs: u64) -> Self {
        self.idle_every = seqs.max(1);
        self
    }

    /// How many more seqs the flow control lets the stream take now (None:
    /// no window): the seqs past the slowest leader's progress, or none
    /// while that is under half the window. The actor reads no more of a
    /// pulled source (trace file, standard input) while it is 0; progress
    /// marks open it again. A restored gateway starts from no progress at
    /// all, and leaders publish theirs at every sweep.
    pub fn room(&self) -> Option<u64> {
        let head = self.state.router.seq();
        // A leader that applied everything it was sent, with nothing
        // queued for it, is not behind: items for others are not sent to
        // it, so it is as far as the stream.
        let slowest = (0..self.progress.len())
            .filter(|&i| self.serves(i))
            .map(|i| match self.progress[i] {
                Some(m)
                    if m.through >= self.state.sent_through[i] && !self.state.router.queued(i) =>
                {
                    head
                }
                Some(m) => m.through,
                None => 0,
            })
            .min()
            .unwrap_or(0);
        // Less than half the window free counts as none: a stream let in
        // a few seqs at every progress mark would send each leader a
        // batch (and get a mark back) per few seqs.
        self.window.map(|w| {
            let free = (slowest + w).saturating_sub(head);
            if free < w.div_ceil(2) {
                0
            } else {
                free
            }
        })
    }

    /// The batches to publish again while the window holds the stream:
    /// each leader's from the one it waits for, when its progress mark
    /// names a batch below the last sent and has not moved since the
    /// previous call. Call it at an interval longer than a leader's sweep
    /// (its marks come at least that often), so that a leader busy with
    /// what is in flight is not sent it twice.
    pub fn stalled(&mut self) -> Vec<(usize, Batch)> {
        let mut again = Vec::new();
        for i in 0..self.state.sent.len() {
            if !self.serves(i) {
                continue;
            }
            let mark = self.progress[i];
            let unchanged = mark.is_some() && self.stall_checked[i] == mark;
            self.stall_checked[i] = mark;
            let Some(mark) =
                mark.filter(|m| unchanged && m.batch < self.state.sent[i].next_number())
            else {
                continue;
            };
            let name = &self.state.router.begin().leaders[i];
            if let Ok(batches) = self.state.sent[i].from(name, mark.batch) {
                let batches = self.restamped(batches);
                again.extend(batches.into_iter().map(|b| (i, b)));
            }
        }
        again
    }

    /// Batches kept from earlier, as this holder sends them again: at its
    /// epoch (they may have been sent first by a former holder).
    fn restamped(&self, mut batches: Vec<Batch>) -> Vec<Batch> {
        self.stamp(&mut batches);
        batches
    }

    /// Stamps `batches` with the epoch the role is held at here.
    fn stamp<'a>(&self, batches: impl IntoIterator<Item = &'a mut Batch>) {
        for batch in batches {
            batch.epoch = self.epoch;
        }
    }

    /// Counts journal records that were damaged in one copy of the
    /// journal and taken from the other when the sensor restarted.
    pub(crate) fn note_journal_repaired(&mut self, records: usize) {
        self.state.stats.journal_repaired += records as u64;
    }

    /// The stream found its window full and waits (counted in the stats).
    pub(crate) fn hold(&mut self) {
        self.state.stats.window_holds += 1;
    }

    /// A leader published how far it has got (`Progress` bytes).
    pub fn progress(&mut self, bytes: &[u8], origin: &str) {
        let Some((i, mark)) = self.mark::<Progress>(bytes, origin, |m| &m.leader) else {
            return;
        };
        // The latest, not the highest: a leader that restarted from its
        // journal may be behind what it said before it died. (A late old
        // mark only holds the stream a moment longer.)
        self.progress[i] = Some(Mark {
            through: mark.through,
            batch: mark.batch,
        });
    }

    /// Records every change of state for the journal (take them with
    /// [`Gateway::unjournaled`]).
    pub fn journaled(mut self) -> Self {
        self.journaling = true;
        let stream = self.stream();
        self.note(Record::Stream(stream));
        self
    }

    /// The stream's `Begin`, as its journal names it.
    fn stream(&self) -> Vec<u8> {
        postcard::to_stdvec(self.state.router.begin()).unwrap_or_default()
    }

    /// The journal compacted: the stream's record, a snapshot of the
    /// whole state (what a replay of every record so far rebuilds, less the
    /// progress marks, which leaders publish again) and the named track
    /// ids' numbers, one record per producer. Take it once every record
    /// has been taken ([`Gateway::unjournaled`]), and put it in the
    /// journal's place ([`Journal::compact`](crate::journal::Journal::compact)):
    /// a restart then reads one snapshot instead of the whole stream's
    /// records.
    pub fn compacted(&self) -> Result<Vec<Record>, postcard::Error> {
        let mut records = vec![
            Record::Stream(self.stream()),
            Record::Snapshot(postcard::to_stdvec(&self.state)?),
        ];
        records.extend(self.named.iter().map(|(producer, ids)| Record::TrackIds {
            producer: producer.clone(),
            first: 0,
            ids: ids.clone(),
        }));
        Ok(records)
    }

    /// Named track ids of `producer` given the numbers `first`, `first +
    /// 1`, … by its decoder: kept, and recorded for the journal, so that
    /// they are on disk with (before) the offer whose lines carry them.
    /// Refused if they do not follow the numbers it gave before.
    pub(crate) fn name_tracks(
        &mut self,
        producer: &str,
        first: u32,
        ids: Vec<String>,
    ) -> Result<(), String> {
        if ids.is_empty() {
            return Ok(());
        }
        self.take_track_ids(producer, first, &ids)?;
        self.note(Record::TrackIds {
            producer: producer.to_string(),
            first,
            ids,
        });
        Ok(())
    }

    /// The named track ids each producer's decoder numbered, in number
    /// order: what a restored sensor gives its decoders back.
    pub(crate) fn named_tracks(&self) -> &BTreeMap<String, Vec<String>> {
        &self.named
    }

    /// Adds `ids`, numbered from `first`, to `producer`'s named ids. A
    /// number it already has must name the same id (a compacted journal
    /// states them again); the others must come next.
    fn take_track_ids(&mut self, producer: &str, first: u32, ids: &[String]) -> Result<(), String> {
        if ids.is_empty() {
            return Ok(());
        }
        let known = self.named.entry(producer.to_string()).or_default();
        for (number, id) in (first as usize..).zip(ids) {
            match known.get(number) {
                Some(had) if had == id => {}
                Some(had) => {
                    return Err(format!(
                        "{producer}: track {number} is id {had:?}, not {id:?}"
                    ))
                }
                None if number == known.len() => known.push(id.clone()),
                None => {
                    return Err(format!(
                        "{producer}: id {id:?} numbered {number}, but only {} ids were numbered \
                         before it",
                        known.len()
                    ))
                }
            }
        }
        Ok(())
    }

    /// Takes the state a [`Record::Snapshot`] holds.
    fn restore_snapshot(&mut self, bytes: &[u8]) -> Result<(), String> {
        let state: Journaled =
            postcard::from_bytes(bytes).map_err(|e| format!("the snapshot does not read: {e}"))?;
        let leaders = self.state.router.leaders();
        let lengths = [
            state.sent.len(),
            state.durable.len(),
            state.sent_through.len(),
            state.owed.len(),
        ];
        if lengths != [leaders; 4] {
            return Err(format!(
                "the snapshot is of {} leaders, the stream has {leaders}",
                state.sent.len()
            ));
        }
        self.state = state;
        Ok(())
    }

    /// What changed since the last call, in order: append it to the
    /// journal before sending anything.
    pub fn unjournaled(&mut self) -> Vec<Record> {
        std::mem::take(&mut self.records)
    }

    /// Lines of the trace file routed so far: a restored gateway's trace
    /// goes on from there.
    pub fn traced(&self) -> u64 {
        self.state.traced
    }

    /// Rebuilds the state `records` (a journal, in order) describe, on a
    /// new gateway over the same stream; `trace` is the trace file's
    /// lines. Nothing is recorded again.
    pub fn restore(&mut self, records: Vec<Record>, trace: &[Line]) -> Result<(), RestoreError> {
        let journaling = std::mem::replace(&mut self.journaling, false);
        for (i, record) in records.into_iter().enumerate() {
            self.replay(record, trace)
                .map_err(|problem| RestoreError { record: i, problem })?;
        }
        self.journaling = journaling;
        Ok(())
    }

    fn replay(&mut self, record: Record, trace: &[Line]) -> Result<(), String> {
        match record {
            Record::Snapshot(bytes) => self.restore_snapshot(&bytes)?,
            Record::Stream(begin) => {
                if begin != self.stream() {
                    return Err("the journal is of another stream (its tracks, leaders or \
                                settings differ): move it away to start this one afresh"
                        .into());
                }
            }
            Record::Trace { count, cuts } => {
                let from = self.state.traced as usize;
                let lines = usize::try_from(count)
                    .ok()
                    .and_then(|count| trace.get(from..from.checked_add(count)?))
                    .ok_or_else(|| {
                        format!(
                            "the journal routed {} lines of the trace, which has {}",
                            self.state.traced.saturating_add(count),
                            trace.len()
                        )
                    })?;
                self.state.traced += count;
                self.replay_lines(lines, &cuts);
            }
            Record::Offer {
                producer,
                counter,
                payload,
                cuts,
            } => {
                let offer = Offer {
                    producer: producer.as_deref(),
                    counter: counter.as_deref(),
                    payload: &payload,
                    time: None,
                    finish: false,
                };
                let judged = self
                    .state
                    .ingest
                    .offer(offer, &mut self.state.stats)
                    .map_err(|e| format!("an ingest request it accepted is refused now: {e}"))?;
                self.replay_lines(&judged.accepted, &cuts);
            }
            Record::Read { number, text, cuts } => {
                self.state.stdin_read = number;
                if let Ok(Some(line)) =
                    self.state
                        .ingest
                        .read(number as usize, &text, &mut self.state.stats)
                {
                    self.replay_lines(&[line], &cuts);
                }
            }
            Record::Cut(wanted) => {
                self.state.router.cut(wanted);
            }
            Record::Follow(bytes) => {
                self.follow(&bytes)
                    .map_err(|e| format!("a follow it granted is refused now: {e}"))?;
            }
            Record::Flush => {
                self.flush();
            }
            Record::End => {
                self.end();
            }
            Record::Unfollow(bytes) => {
                self.unfollow(&bytes)
                    .map_err(|e| format!("an unfollow it took is refused now: {e}"))?;
            }
            Record::Mesh(record) => self.replay_mesh(record)?,
            Record::TrackIds {
                producer,
                first,
                ids,
            } => self.take_track_ids(&producer, first, &ids)?,
        }
        Ok(())
    }

    /// Routes `lines` again, placing each cut after the line it followed.
    fn replay_lines(&mut self, lines: &[Line], cuts: &[(u32, Wanted)]) {
        for (i, line) in lines.iter().enumerate() {
            // Refused again as it was then, and counted again.
            let _ = self.route_line(line);
            for (_, wanted) in cuts.iter().filter(|(after, _)| *after as usize == i) {
                self.state.router.cut(*wanted);
            }
        }
    }

    /// Records a change of state (when journaled); consecutive trace
    /// lines share one record.
    fn note(&mut self, record: Record) {
        if !self.journaling {
            return;
        }
        if let (
            Some(Record::Trace { count, cuts }),
            Record::Trace {
                count: more,
                cuts: theirs,
            },
        ) = (self.records.last_mut(), &record)
        {
            if let Ok(base) = u32::try_from(*count) {
                cuts.extend(theirs.iter().map(|&(i, w)| (base.saturating_add(i), w)));
                *count += more;
                return;
            }
        }
        self.records.push(record);
    }

    /// Routes `lines` in order; the cuts they reached (to answer after
    /// the next flush) and, for the journal, after which line each came.
    fn route(&mut self, lines: &[Line]) -> (Vec<Placed<Q>>, Vec<(u32, Wanted)>) {
        let (placed, cuts, _) = self.route_judged(lines);
        (placed, cuts)
    }

    /// [`Gateway::route`], and the lines the extractor refused: (index
    /// in `lines`, why).
    fn route_judged(&mut self, lines: &[Line]) -> Routed<Q> {
        let mut placed = Vec::new();
        let mut cuts = Vec::new();
        let mut refused = Vec::new();
        for (i, line) in lines.iter().enumerate() {
            if let Err(reason) = self.route_line(line) {
                refused.push((i, reason));
            }
            let before = placed.len();
            self.cuts.reached(
                &mut self.state.router,
                (&self.name, self.epoch),
                &mut placed,
            );
            cuts.extend(placed[before..].iter().map(|p| (i as u32, p.wanted)));
        }
        (placed, cuts, refused)
    }

    /// The stream will end after `end` events: cuts asked for beyond it
    /// are refused at once.
    pub(crate) fn ending_at(mut self, end: u64) -> Self {
        self.cuts = Cuts::ending_at(end);
        self
    }

    pub fn router(&self) -> &Router {
        &self.state.router
    }

    pub fn finished(&self) -> bool {
        self.state.finished
    }

    /// The gateway's counters (what its stats key serves).
    pub fn stats(&self) -> &SensorStats {
        &self.state.stats
    }

    /// The counter the next line of `producer` must carry.
    pub fn producer_next(&self, producer: &str) -> u64 {
        self.state.ingest.next_counter(producer)
    }

    /// A ROS 2 message taken (`bad`: refused, it did not decode).
    pub(crate) fn count_ros2(&mut self, bad: bool) {
        self.state.stats.ros2_messages += 1;
        if bad {
            self.state.stats.ros2_bad += 1;
            self.state.stats.rejected += 1;
        }
    }

    /// Batches kept for leader `i` to ask for again.
    #[cfg(test)]
    pub(crate) fn kept(&self, i: usize) -> usize {
        self.state.sent.get(i).map_or(0, BatchLog::len)
    }

    /// Routes the trace file's next line; returns the cuts whose point it
    /// reached (answer them after the next [`Gateway::flush`]).
    pub fn line(&mut self, line: &Line) -> Vec<Placed<Q>> {
        let (placed, cuts) = self.route(std::slice::from_ref(line));
        self.state.traced += 1;
        self.note(Record::Trace { count: 1, cuts });
        placed
    }

    /// An ingest request from a producer: its acknowledgement once every
    /// line it accepted is routed (in the sensor's order, with its seq),
    /// and the cuts those lines reached; flush, then answer both. A
    /// request it cannot read, or one after the stream finished, is
    /// refused whole (counted).
    pub fn ingest(
        &mut self,
        offer: Offer<'_>,
    ) -> Result<(IngestAck, Vec<Placed<Q>>), IngestRefusal> {
        if self.state.mesh.is_some() {
            return Ok((self.ingest_meshed(offer)?, Vec::new()));
        }
        if self.state.finished {
            self.state.stats.rejected += 1;
            return Err(IngestRefusal::Finished);
        }
        if offer.time.is_some() || offer.finish {
            self.state.stats.rejected += 1;
            return Err(IngestRefusal::OnlyMesh);
        }
        let judged = self.state.ingest.offer(offer, &mut self.state.stats)?;
        let (placed, cuts, refused) = self.route_judged(&judged.accepted);
        self.note(Record::Offer {
            producer: offer.producer.map(str::to_owned),
            counter: offer.counter.map(str::to_owned),
            payload: offer.payload.to_vec(),
            cuts,
        });
        let mut ack = judged.ack;
        // Reports the extractor refused in the stream's order (out of
        // time order after another producer's later frame): taken off the
        // accepted counters, answered with why.
        for (i, reason) in refused.into_iter().rev() {
            let counter = ack.accepted.remove(i);
            ack.errors.push(LineRefused {
                counter,
                line: counter - ack.first + 1,
                reason,
            });
        }
        ack.errors.sort_by_key(|e| e.counter);
        ack.events = self.state.router.events();
        Ok((ack, placed))
    }

    /// Line `number` of a trace read from standard input: routed (the cuts
    /// it reached, as [`Gateway::line`]), or why it was skipped (counted).
    /// A line numbered no later than one read before is passed over
    /// silently: a restored sensor fed the same input again goes on after
    /// the last line it journaled, as a trace file does.
    pub fn read(&mut self, number: usize, text: &str) -> Result<Vec<Placed<Q>>, String> {
        if number as u64 <= self.state.stdin_read {
            return Ok(Vec::new());
        }
        self.state.stdin_read = number as u64;
        let read = self.state.ingest.read(number, text, &mut self.state.stats);
        let (placed, cuts, refused) = match &read {
            Ok(Some(line)) => self.route_judged(std::slice::from_ref(line)),
            _ => (Vec::new(), Vec::new(), Vec::new()),
        };
        self.note(Record::Read {
            number: number as u64,
            text: text.to_string(),
            cuts,
        });
        // A report the extractor refused (time order, a track twice in a
        // frame) is a bad line of the input like any other.
        if let Some((_, reason)) = refused.into_iter().next() {
            return Err(format!("stdin:{number}: {reason}"));
        }
        read.map(|_| placed)
    }

    /// The source is exhausted: from the next flush on, batches say the
    /// stream is finished; every cut still waiting is refused.
    pub fn end(&mut self) -> Vec<(Q, String)> {
        if let Some(mesh) = self.state.mesh.as_mut() {
            // One sensor of several: its own part is over; the stream ends
            // when every sensor's is, and all is merged.
            mesh.finish();
            self.note(Record::End);
            self.drain();
            return Vec::new();
        }
        self.finish_extraction();
        self.state.finished = true;
        self.state.owed.fill(true);
        self.note(Record::End);
        self.cuts.refuse_all(&self.state.router)
    }

    /// Turns extraction on: the stream's lines are a tracker's reports,
    /// and what the router is given are the events derived from them
    /// ([`crate::extraction`]).
    pub(crate) fn extracting(mut self, extraction: Extraction) -> Self {
        self.state.ingest.extracting();
        self.state.extraction = Some(extraction);
        self
    }

    /// Routes one line of the stream's order: as it is, or, with
    /// extraction on, the events it completes. A report the extractor
    /// refuses (a rule that depends on the stream so far, such as time
    /// order across producers; what a single line shows was checked where
    /// it came in) is counted and logged, and its reason returned so that
    /// a producer still waiting for its acknowledgement is told.
    fn route_line(&mut self, line: &Line) -> Result<(), String> {
        let Some(extraction) = self.state.extraction.as_mut() else {
            self.state.router.line(line);
            return Ok(());
        };
        match extraction.take(line) {
            Ok(lines) => {
                for line in &lines {
                    self.state.router.line(line);
                }
                Ok(())
            }
            Err(reason) => {
                self.state.stats.rejected += 1;
                self.state.stats.bad_lines += 1;
                tracing::warn!(sensor = %self.name, %reason, "a report the extractor refused");
                Err(reason)
            }
        }
    }

    /// The reports are over: the events of the frame still open go out.
    fn finish_extraction(&mut self) {
        if let Some(extraction) = self.state.extraction.as_mut() {
            for line in extraction.finish() {
                self.state.router.line(&line);
            }
        }
    }

    /// The leaders' queued items as their next batches, in the stream's
    /// order of leaders, each with the index of its leader and kept for it
    /// to ask for again. A leader with nothing queued is sent nothing —
    /// most of a crowd's events are not its tracks' — unless it is owed a
    /// batch (it followed tracks, or the stream finished) or the stream is
    /// [`IDLE_BATCH_EVERY`] seqs ([`Gateway::idle_batches_every`]) past its
    /// last batch: then a batch saying only how far the stream got. A cut
    /// is an item for every leader, so each is sent it.
    pub fn flush(&mut self) -> Vec<(usize, Batch)> {
        let through = self.state.router.seq();
        let events = self.state.router.events();
        self.note(Record::Flush);
        let mut batches = Vec::with_capacity(self.state.sent.len());
        for i in 0..self.state.sent.len() {
            if !self.serves(i) {
                // Another sensor sends this leader the same items.
                self.state.router.take(i);
                continue;
            }
            let due = self.state.router.queued(i)
                || self.state.owed[i]
                || through >= self.state.sent_through[i] + self.idle_every;
            if !due {
                continue;
            }
            let log = &mut self.state.sent[i];
            let batch = Batch {
                version: VERSION,
                epoch: self.epoch,
                sensor: self.name.clone(),
                number: log.next_number(),
                through,
                events,
                finished: self.state.finished,
                items: self.state.router.take(i),
            };
            log.push(batch.clone());
            batches.push((i, batch));
            self.state.sent_through[i] = through;
            self.state.owed[i] = false;
        }
        batches
    }

    /// A cut request: placed now, scheduled, or refused.
    pub fn cut(&mut self, query: Q, parameters: &CutParameters) -> CutOutcome<Q> {
        if self.state.mesh.is_some() {
            return self.cut_meshed(query, parameters);
        }
        match self
            .cuts
            .request(query, parameters, &self.state.router, self.state.finished)
        {
            Request::Now { wanted, query } => {
                self.note(Record::Cut(wanted));
                CutOutcome::Placed(place(
                    &mut self.state.router,
                    (&self.name, self.epoch),
                    wanted,
                    query,
                    self.state.finished,
                ))
            }
            Request::Scheduled => CutOutcome::Scheduled,
            Request::Refused { query, reason } => CutOutcome::Refused(query, reason),
            Request::Malformed { query, reason } => {
                self.count::<()>("cut", &Err(reason.clone()));
                CutOutcome::Refused(query, reason)
            }
        }
    }

    /// A leader asks to follow more tracks (`Follow` bytes): the items it
    /// missed, or why not (counted). Flush after a success: the items
    /// routed to it from now on include the new tracks.
    pub fn follow(&mut self, bytes: &[u8]) -> Result<Followed, String> {
        let answer = decode::<Follow>(bytes)
            .map_err(|e| e.to_string())
            .and_then(|f| {
                if !self.serves(f.leader as usize) {
                    return Err(format!(
                        "follow request from leader index {}, which another sensor serves",
                        f.leader
                    ));
                }
                self.admit_epoch(Follow::WHAT, f.leader as usize, f.epoch)?;
                let items = self.state.router.follow(&f).map_err(|e| e.to_string())?;
                Ok((f.leader as usize, items))
            });
        self.count("follow", &answer);
        let (leader, items) = answer?;
        self.note(Record::Follow(bytes.to_vec()));
        self.state.owed[leader] = true;
        Ok(Followed {
            version: VERSION,
            epoch: self.epoch,
            items,
        })
    }

    /// A leader of a factored stream stops following tracks (`Unfollow`
    /// bytes): how many it dropped (a stale request drops none), or why
    /// not (counted).
    pub fn unfollow(&mut self, bytes: &[u8]) -> Result<usize, String> {
        let answer = decode::<Unfollow>(bytes)
            .map_err(|e| e.to_string())
            .and_then(|u| {
                self.admit_epoch(Unfollow::WHAT, u.leader as usize, u.epoch)?;
                self.state.router.unfollow(&u).map_err(|e| e.to_string())
            });
        self.count("unfollow", &answer);
        if answer.as_ref().is_ok_and(|&dropped| dropped > 0) {
            self.note(Record::Unfollow(bytes.to_vec()));
        }
        answer
    }

    /// A leader asks for batches again (`Resend` bytes).
    pub fn resend(&mut self, bytes: &[u8]) -> Result<Resent, String> {
        let answer = decode::<Resend>(bytes)
            .map_err(|e| e.to_string())
            .and_then(|request| {
                let i = self
                    .leader_index(&request.leader)
                    .filter(|&i| self.serves(i))
                    .ok_or_else(|| {
                        format!(
                            "resend request from {:?}, which is not a leader this sensor serves",
                            request.leader
                        )
                    })?;
                self.fence
                    .admit(Resend::WHAT, &request.leader, request.epoch)
                    .map_err(|stale| stale.to_string())?;
                self.state.sent[i].from(&request.leader, request.from)
            })
            .map(|batches| Resent {
                version: VERSION,
                epoch: self.epoch,
                batches: self.restamped(batches),
            });
        self.count("resend", &answer);
        answer
    }

    /// A leader published its durable mark (`Durable` bytes): drop its
    /// batches below it, and the items every leader has passed.
    pub fn durable(&mut self, bytes: &[u8], origin: &str) {
        let Some((i, mark)) = self.mark::<Durable>(bytes, origin, |m| &m.leader) else {
            return;
        };
        let batches = self.state.sent[i].forget(&mark);
        self.state.durable[i] = Some(self.state.durable[i].unwrap_or(0).max(mark.position));
        let passed = self.state.durable.iter().copied().min().flatten();
        let items = passed.map_or(0, |seq| self.state.router.forget(seq));
        tracing::trace!(leader = %mark.leader, batches, items, kept = self.state.sent[i].len(),
            logged = self.state.router.logged(), "forgot what is safe");
    }

    /// A leader's mark (durable or progress) with the index of the leader
    /// it names; None if it cannot be read (counted as rejected) or names a
    /// leader not of this stream (logged). Marks are puts: nobody to
    /// answer.
    fn mark<M: serde::de::DeserializeOwned + Valid + Epoched>(
        &mut self,
        bytes: &[u8],
        origin: &str,
        leader: impl Fn(&M) -> &String,
    ) -> Option<(usize, M)> {
        let mark = match decode::<M>(bytes) {
            Ok(mark) => mark,
            Err(e) => {
                self.state.stats.rejected += 1;
                tracing::warn!(from = %origin, problem = %e,
                    rejected = self.state.stats.rejected, "{} rejected", M::WHAT);
                return None;
            }
        };
        let Some(i) = self.leader_index(leader(&mark)) else {
            tracing::warn!(leader = %leader(&mark), "{} from a leader not of this stream", M::WHAT);
            return None;
        };
        if let Err(stale) = self.fence.admit(M::WHAT, leader(&mark), mark.epoch()) {
            self.state.stats.rejected += 1;
            tracing::warn!(from = %origin, rejected = self.state.stats.rejected, "{stale}");
            return None;
        }
        Some((i, mark))
    }

    /// The fence on a request of leader `i` at `epoch`: why not, if the
    /// request comes from a former holder of the role.
    fn admit_epoch(&mut self, what: &'static str, i: usize, epoch: u64) -> Result<(), String> {
        let Some(role) = self.state.router.begin().leaders.get(i) else {
            return Ok(());
        };
        self.fence
            .admit(what, role, epoch)
            .map_err(|stale| stale.to_string())
    }

    /// Whether this sensor sends leader `i` its batches (every leader,
    /// unless it is one sensor of several).
    fn serves(&self, i: usize) -> bool {
        self.state.mesh.as_ref().is_none_or(|m| m.serves(i))
    }

    /// The index of the leader named `name` in the stream's order.
    fn leader_index(&self, name: &str) -> Option<usize> {
        self.state
            .router
            .begin()
            .leaders
            .iter()
            .position(|n| n == name)
    }

    /// Counts a refused request.
    fn count<R>(&mut self, what: &str, answer: &Result<R, String>) {
        if let Err(e) = answer {
            self.state.stats.rejected += 1;
            tracing::warn!(what, error = %e, rejected = self.state.stats.rejected, "bad request rejected");
        }
    }
}
