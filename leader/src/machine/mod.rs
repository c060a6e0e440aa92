//! The leader's timers and recovery policy as a pure, synchronous state
//! machine around [`Leader`], in the style of raft-rs's `RawNode`: the
//! driver hands it inputs ([`Input`]: bytes off the network, the answers
//! to its own requests, queries, and [`Input::Tick`] every
//! [`Timers::sweep`]) with the time, and carries out what it asks
//! ([`Output`]: journal this, send that, ask the sensor, answer a query,
//! sync and publish a mark, write a snapshot). It does no I/O and reads
//! no clock, so everything here runs the same in the Zenoh actor
//! ([`crate::driver`]) and in the deterministic network simulator of
//! `tests/src/sim`.
//!
//! The policy (docs/design/architecture.md, "When a leader dies"):
//! - every input passes the door ([`crate::door`]), is journaled, then
//!   applied; what the door refuses is counted and changes nothing;
//! - a gap in batch numbers, a held query older than [`Timers::late`] (the
//!   batch with its cut, or the stream's last, may be lost), or a recovery
//!   whose resend was not answered yet: ask the sensor for every batch
//!   from the next one expected, one request at a time;
//! - a transfer waited for longer than [`Timers::late`] (lost in the
//!   network, or sent while this leader was down): ask that peer for what
//!   it sent this leader;
//! - a follow request that failed or came back unusable: asked again;
//! - a query held for its cut nearly as long as
//!   [`Timers::query_timeout`]: answered with an error naming what the
//!   leader waits for (a peer's sets, the sensor's batches), in time for
//!   the coordinator to say who is missing;
//! - on every tick the journal is synced and, if that worked and it moved,
//!   the durable mark published;
//! - after every [`Timers::snapshot_every`] journaled inputs, a snapshot;
//!   and at a tick with nothing journaled since the last one, if anything
//!   was since the last snapshot (a leader at rest).
//!
//! The durable mark tells the sensor and the peers what they may forget
//! of what they keep for this leader. With a journal it is the state of
//! the last snapshot, not of the last fsync: a snapshot is one
//! checksummed file written whole, while the journal after it may be
//! found damaged at a restart, and then everything from the damaged
//! entry on is dropped and must still be there to fetch again
//! ([`crate::journal`]). What the others keep for a leader is thus what
//! came since its last snapshot: at most [`Timers::snapshot_every`]
//! inputs, and nothing once it rests.
//!
//! With more than one leader process, the mark also waits for the role's
//! standby (the process that would adopt it) to hold a copy of that
//! snapshot on its own disk ([`standby`]): an adopter on another disk
//! starts from that copy, and the others still keep what came after it.
//!
//! A restarted (or adopted) leader ([`Node::recover`]) replays its
//! snapshot and journal, sends again every transfer it sent, asks the
//! sensor for the batches after its journal's last and every peer for the
//! transfers they sent it since, and answers queries "recovering" until
//! all of them have answered. A journal cut short by damage is one more
//! such restart: the leader is where its journal ended, behind where it
//! was, and fetches the rest the same way.

mod queries;
mod recovery;
mod standby;

pub use queries::Ask;
pub use recovery::Holder;

use crate::door;
use crate::journal::Kind;
use crate::state::{Action, Leader};
use idmesh_protocol::wire::coordinator_to_leader::Partial;
use idmesh_protocol::wire::epoch::{Fence, Stale};
use idmesh_protocol::wire::leader_to_leader::{Transfer, TransfersSent, TransfersWanted};
use idmesh_protocol::wire::leader_to_sensor::{
    Durable, Follow, Followed, Progress, Resend, Unfollow,
};
use idmesh_protocol::wire::sensor_to_leader::Batch;
use idmesh_protocol::wire::{decode, encode, Versioned, WireError, VERSION};
use std::collections::{BTreeMap, BTreeSet};
use std::sync::Arc;
use std::time::Duration;

/// The time of an input: since an origin the driver picks (its start).
pub(crate) type Now = Duration;

/// The node's clocks and limits.
#[derive(Debug, Clone, PartialEq)]
pub struct Timers {
    /// How often the driver ticks: journal sync, durable mark, expiry and
    /// the checks for lost messages.
    pub sweep: Duration,
    /// A query held this long, or a transfer waited for this long, means a
    /// message was probably lost: ask again.
    pub late: Duration,
    /// How long a query is held for its cut before it is answered with an
    /// error.
    pub query_timeout: Duration,
    /// The inputs are journaled (and a restart can replay them).
    pub journal: bool,
    /// Write a snapshot after this many journaled inputs.
    pub snapshot_every: Option<usize>,
    /// The sensor streams under a window (`[sensor] window`), which its
    /// leaders' progress marks open: a mark after every input that moves
    /// the leader. Without one nobody waits for them, and a mark goes only
    /// at the sweep (a message per batch saved).
    pub flow_control: bool,
    /// The role keeps a copy of its snapshots with its standby, and its
    /// durable mark waits for it ([`standby`]): more than one leader
    /// process, and a journal.
    pub standby: bool,
}

impl Timers {
    /// The runtime's clocks: a 250 ms sweep, 500 ms before a message is
    /// taken for lost.
    pub fn new(query_timeout: Duration, journal: bool, snapshot_every: Option<usize>) -> Self {
        Timers {
            sweep: Duration::from_millis(250),
            late: Duration::from_millis(500),
            query_timeout,
            journal,
            snapshot_every,
            flow_control: true,
            standby: false,
        }
    }
}

/// What the driver hands the node.
#[derive(Debug, Clone)]
pub enum Input {
    /// An input of the state machine from the network (a batch on the
    /// leader's event key, a transfer on its transfer key), with where it
    /// came from.
    Message {
        kind: Kind,
        bytes: Vec<u8>,
        origin: String,
    },
    /// The sensor's answer to [`Output::AskFollow`] (a `Followed`).
    Followed(Result<Vec<u8>, String>),
    /// The sensor's answer to [`Output::AskResend`].
    Resent(Result<Vec<Batch>, String>),
    /// A peer's answer to [`Output::AskTransfers`].
    Transfers {
        peer: String,
        result: Result<TransfersSent, String>,
    },
    /// A durable mark some leader published (`Durable` bytes).
    Durable { bytes: Vec<u8>, origin: String },
    /// The coordinator asks for partial sums; answered by an
    /// [`Output::Answer`] with the same `id`, now or later.
    Partial {
        id: u64,
        ask: Ask,
        /// The tag of the answer the coordinator keeps, if it said one.
        base: Option<u64>,
    },
    /// A restarted peer asks for the transfers this leader sent it
    /// (`TransfersWanted` bytes); answered by [`Output::AnswerSent`].
    SentWanted {
        id: u64,
        bytes: Vec<u8>,
        origin: String,
    },
    /// The process that would adopt this role changed (None: none is
    /// alive): the role's standby, which keeps its snapshots.
    Standby(Option<String>),
    /// The standby's word that it keeps a snapshot (`StandbyStored`
    /// bytes).
    StandbyStored { bytes: Vec<u8>, origin: String },
    /// The sweep's clock.
    Tick,
    /// The driver could not write the journal or the snapshot: the leader
    /// refuses queries from now on.
    Failed(String),
}

/// What the node asks the driver to do, in order.
#[derive(Debug, Clone, PartialEq)]
pub enum Output {
    /// Append this input to the journal before carrying out what follows.
    Journal { kind: Kind, bytes: Vec<u8> },
    /// Put `body` on peer `to`'s transfer key: an encoded
    /// `TransfersSent`, every transfer one step made for that peer (of the
    /// items `seqs`), in order. One message for all of them: a crowd's
    /// batch hands several tracks to the same neighbour, and each message
    /// costs both processes a wake-up.
    Send {
        to: String,
        seqs: Vec<u64>,
        body: Vec<u8>,
    },
    /// Ask the sensor to follow tracks; its answer comes back as
    /// [`Input::Followed`].
    AskFollow(Follow),
    /// Tell the sensor to stop following tracks; nothing comes back (a
    /// lost request costs items the leader ignores).
    Unfollow(Unfollow),
    /// Ask the sensor for batches again; [`Input::Resent`].
    AskResend(Resend),
    /// Ask a peer for the transfers it sent here; [`Input::Transfers`].
    AskTransfers {
        peer: String,
        wanted: TransfersWanted,
    },
    /// This leader's partial sums at the cut it has just reached, put
    /// unasked for the coordinator that placed it (`P/leader/L/pushed/T`):
    /// told as a change to its answer at the cut before (`base`), which
    /// that coordinator usually keeps. A push lost, or one the coordinator
    /// cannot use, costs only the get it then makes, which the answers
    /// kept at recent cuts serve.
    Push(Arc<Partial>),
    /// The answer to [`Input::Partial`] `id`.
    Answer {
        id: u64,
        answer: Result<Arc<Partial>, String>,
    },
    /// The answer to [`Input::SentWanted`] `id`.
    AnswerSent {
        id: u64,
        answer: Result<TransfersSent, String>,
    },
    /// Sync the journal (if there is one); if that worked, publish `mark`
    /// on the leader's durable key (when there is one).
    Persist { mark: Option<Durable> },
    /// Replace the journal by this snapshot of the whole state.
    Snapshot(Vec<u8>),
    /// Put the last snapshot written (whose durable mark is `mark`) on
    /// the key of standby `to`, for its process to keep.
    ToStandby { to: String, mark: Durable },
    /// Publish how far the leader has got (the sensor's flow control).
    Progress(Progress),
}

/// A leader restarted (or adopted) and not yet caught up.
#[derive(Debug, Clone)]
struct Recovery {
    since: Now,
    /// The sensor has answered the resend of what the journal misses.
    batches: bool,
    /// Peers yet to answer the request for transfers.
    peers: Vec<String>,
}

/// A partial-sums query waiting for its cut.
#[derive(Debug, Clone)]
struct Held {
    id: u64,
    tag: u64,
    /// The answer the coordinator keeps ([`Node::told`]).
    base: Option<u64>,
    since: Now,
}

/// The leader with its timers and recovery policy.
pub struct Node {
    leader: Leader,
    timers: Timers,
    /// The leader's own inconsistency (a journal it cannot write, an input
    /// it admitted but cannot apply): every query is refused from then on.
    failure: Option<String>,
    recovery: Option<Recovery>,
    held: Vec<Held>,
    /// A resend request is out.
    resending: bool,
    /// Resend requests the sensor refused in a row, and the time before
    /// which none is asked again ([`resend_backoff`]).
    resend_refusals: u32,
    resend_not_before: Now,
    /// The sensor's word that it no longer holds the batches this role
    /// needs (said once in the log; in every answer while it holds).
    unrebuildable: Option<String>,
    /// The follow request is out (None: ask again on the next tick).
    following: bool,
    /// Transfers this step made, by peer, not yet put in messages.
    outgoing: Vec<(String, Vec<Transfer>)>,
    /// Transfer requests out, by peer, and when they were made.
    asking: BTreeMap<String, Now>,
    /// Transfer requests a peer failed in a row (down, or its role not
    /// yet adopted), and the time before which it is not asked again
    /// ([`transfers_backoff`]).
    transfers_failed: BTreeMap<String, (u32, Now)>,
    /// When the leader started waiting for the transfer it waits for.
    waiting_since: Option<((u64, u16), Now)>,
    /// When the leader started waiting for the components of the mix at
    /// an item (a factored stream).
    components_since: Option<(u64, Now)>,
    published: Option<Durable>,
    /// The durable mark of the last snapshot written (or recovered from):
    /// the one published when there is a journal.
    safe: Option<Durable>,
    /// [`Node::journaled`] at the last sweep: unchanged at the next, the
    /// leader rests.
    journaled_at_sweep: usize,
    /// The progress mark last published.
    progressed: u64,
    /// The tag of the cut whose answer this leader last pushed: the next
    /// push is told as a change to it.
    pushed: Option<u64>,
    /// Inputs journaled since the last snapshot.
    journaled: usize,
    /// The newest epoch heard from each peer role: a former holder's
    /// transfers and durable marks are refused.
    fence: Fence,
    /// (role, epoch) of the former holders already warned about.
    fenced_warned: BTreeSet<(String, u64)>,
    /// The role's standby and what it holds.
    standby: standby::Standby,
}

impl Node {
    /// A node for a leader that starts with nothing behind it.
    pub(crate) fn new(leader: Leader, timers: Timers) -> Self {
        Node {
            leader,
            timers,
            failure: None,
            recovery: None,
            held: Vec::new(),
            resending: false,
            resend_refusals: 0,
            resend_not_before: Duration::ZERO,
            unrebuildable: None,
            following: false,
            outgoing: Vec::new(),
            asking: BTreeMap::new(),
            transfers_failed: BTreeMap::new(),
            waiting_since: None,
            components_since: None,
            published: None,
            safe: None,
            journaled_at_sweep: 0,
            progressed: 0,
            pushed: None,
            journaled: 0,
            fence: Fence::default(),
            fenced_warned: BTreeSet::new(),
            standby: standby::Standby::default(),
        }
    }

    pub fn leader(&self) -> &Leader {
        &self.leader
    }

    /// Counts the bytes of a snapshot the driver sent to the standby.
    pub(crate) fn note_standby_sent(&mut self, bytes: usize) {
        self.leader.note_standby_sent(bytes);
    }

    pub(crate) fn timers(&self) -> &Timers {
        &self.timers
    }

    /// Why the leader refuses every query, if it does.
    pub fn failure(&self) -> Option<&str> {
        self.failure.as_deref()
    }

    /// Since when the leader has been catching up, if it is.
    /// Why this role cannot be rebuilt from the stream, if the sensor
    /// said so.
    pub(crate) fn unrebuildable(&self) -> Option<&str> {
        self.unrebuildable.as_deref()
    }

    pub(crate) fn recovering_since(&self) -> Option<Now> {
        self.recovery.as_ref().map(|r| r.since)
    }

    /// Queries held for their cut.
    #[cfg(test)]
    pub(crate) fn held(&self) -> usize {
        self.held.len()
    }

    /// Hands the node one input at time `now`; returns what to do, in order.
    pub fn step(&mut self, now: Now, input: Input) -> Vec<Output> {
        let mut out = Vec::new();
        match input {
            Input::Message {
                kind,
                bytes,
                origin,
            } => self.input(kind, bytes, &origin, &mut out),
            Input::Followed(Ok(bytes)) => {
                self.following = false;
                self.input(Kind::Followed, bytes, "the sensor's follow reply", &mut out);
                // A reply that was no use: the leader still waits for one.
                self.ask_follow(&mut out);
            }
            Input::Followed(Err(e)) => {
                // Lost, or the sensor was unreachable: asked again on the
                // next tick (the sensor answers a repeated follow the same).
                self.following = false;
                tracing::warn!(leader = %self.leader.name(), error = %e, "follow request failed; asking again");
            }
            Input::Resent(result) => {
                self.resending = false;
                match result {
                    Ok(batches) => {
                        self.resend_refusals = 0;
                        self.resend_not_before = Duration::ZERO;
                        self.unrebuildable = None;
                        if let Some(r) = &mut self.recovery {
                            r.batches = true;
                        }
                        for batch in batches {
                            let bytes = encode(&batch);
                            self.input(Kind::Batch, bytes, "the sensor's resend reply", &mut out);
                        }
                    }
                    Err(e) => self.resend_refused(now, &e),
                }
            }
            Input::Transfers { peer, result } => {
                self.transfers_answered(now, &peer, result, &mut out)
            }
            Input::Durable { bytes, origin } => match decode::<Durable>(&bytes) {
                Ok(mark) if mark.leader != self.leader.name() => {
                    match self.fence.admit(Durable::WHAT, &mark.leader, mark.epoch) {
                        Ok(()) => {
                            self.leader.forget_sent(&mark.leader, mark.position);
                        }
                        Err(stale) => self.fenced(stale, &origin, &mut out),
                    }
                }
                Ok(_) => {}
                Err(e) => self.reject("a durable mark", &origin, &e, &mut out),
            },
            Input::Partial { id, ask, base } => self.partial(now, id, ask, base, &mut out),
            Input::SentWanted { id, bytes, origin } => {
                let answer = decode::<TransfersWanted>(&bytes).map(|wanted| TransfersSent {
                    epoch: self.leader.epoch(),
                    version: VERSION,
                    transfers: self.leader.sent_to(wanted.to, wanted.after),
                });
                if let Err(e) = &answer {
                    self.reject("a request for sent transfers", &origin, e, &mut out);
                }
                out.push(Output::AnswerSent {
                    id,
                    answer: answer.map_err(|e| e.to_string()),
                });
            }
            Input::Standby(to) => self.standby_changed(now, to, &mut out),
            Input::StandbyStored { bytes, origin } => {
                self.standby_stored(&bytes, &origin, &mut out)
            }
            Input::Tick => {
                self.tick(now, &mut out);
                // Again at every sweep, moved or not: a put lost, or a
                // sensor that restarted knowing nothing, is mended here.
                self.progress(true, &mut out);
            }
            Input::Failed(why) => {
                tracing::error!(leader = %self.leader.name(), error = %why, "leader failed");
                self.failure = Some(why);
            }
        }
        self.after_input(now, &mut out);
        self.send_outgoing(&mut out);
        out
    }

    /// One input of the state machine: through the door, journaled,
    /// applied, its actions carried out.
    fn input(&mut self, kind: Kind, bytes: Vec<u8>, origin: &str, out: &mut Vec<Output>) {
        let input = match door::admit(&self.leader, kind, &bytes) {
            Ok(input) => input,
            Err(problem) => {
                let what = format!("{kind:?} of {} bytes", bytes.len());
                self.reject(&what, origin, &problem, out);
                return;
            }
        };
        if let Err(stale) = self.admit_epoch(&input) {
            self.fenced(stale, origin, out);
            return;
        }
        let size = bytes.len();
        if self.timers.journal {
            self.journaled += 1;
            out.push(Output::Journal { kind, bytes });
        }
        match door::apply(&mut self.leader, input, size) {
            Ok(actions) => self.act(actions, out),
            Err(e) => {
                tracing::error!(leader = %self.leader.name(), error = %e, "leader cannot go on applying its stream");
                self.failure = Some(e.to_string());
            }
        }
    }

    /// The fence on a peer's transfers, and on the sensor's batches and
    /// follow replies: refused if their sender is a former holder of its
    /// role (a peer's, or the sensor's), cut off but still running.
    fn admit_epoch(&mut self, input: &door::Input) -> Result<(), Stale> {
        match input {
            door::Input::Batch(batch) => self.fence.admit(Batch::WHAT, &batch.sensor, batch.epoch),
            // A leader's follow replies come from the one sensor that
            // sends it batches; fenced on their own.
            door::Input::Followed(followed) => {
                self.fence
                    .admit(Followed::WHAT, SENSOR_FOLLOWS, followed.epoch)
            }
            door::Input::Transfers { epoch, transfers } => {
                let Some(first) = transfers.first() else {
                    return Ok(());
                };
                let Some(from) = self.leader.peer(first.from) else {
                    // Before the Begin a sender's index names no role yet.
                    // A transfer older than the newest epoch heard of any
                    // role may be a former holder's: refused, and asked
                    // for again once begun. No role could fence another.
                    let newest = self.fence.newest();
                    return match *epoch < newest {
                        true => Err(Stale {
                            what: TransfersSent::WHAT,
                            role: format!("leader #{}", first.from),
                            epoch: *epoch,
                            current: newest,
                        }),
                        false => Ok(()),
                    };
                };
                self.fence.admit(TransfersSent::WHAT, from, *epoch)
            }
        }
    }

    /// A message of a former holder of its role, refused by the fence:
    /// counted as rejected and logged (once per role and epoch).
    fn fenced(&mut self, stale: Stale, origin: &str, out: &mut Vec<Output>) {
        self.note_refusal(out);
        if self.fenced_warned.insert((stale.role.clone(), stale.epoch)) {
            tracing::warn!(leader = %self.leader.name(), from = %origin, "{stale}");
        }
    }

    /// Carries out what the state machine asks for.
    fn act(&mut self, actions: Vec<Action>, out: &mut Vec<Output>) {
        for action in actions {
            match action {
                Action::Send { to, transfer } => self.send(to, transfer),
                Action::Follow(_) => {
                    self.following = false;
                    self.ask_follow(out);
                }
                Action::Unfollow(unfollow) => out.push(Output::Unfollow(unfollow)),
                Action::CutReady(partial) => {
                    let ready: Vec<Held> = self
                        .held
                        .extract_if(.., |h| h.tag == partial.tag())
                        .collect();
                    for h in ready {
                        out.push(Output::Answer {
                            id: h.id,
                            answer: Ok(self.told(&partial, h.base)),
                        });
                    }
                    // Identity queries ask for rows: they keep asking.
                    if partial.sums.rows.is_empty() {
                        out.push(Output::Push(self.told(&partial, self.pushed)));
                        self.pushed = Some(partial.tag());
                    }
                }
            }
        }
    }

    /// Puts one transfer on the way to leader index `to`: it leaves with
    /// the others this step makes for that peer ([`Node::send_outgoing`]).
    fn send(&mut self, to: u16, transfer: Transfer) {
        let Some(peer) = self.leader.peer(to).map(str::to_owned) else {
            self.failure = Some(format!("transfer to unknown leader index {to}"));
            return;
        };
        tracing::debug!(leader = %self.leader.name(), to = %peer, seq = transfer.seq, sets = transfer.sets.len(), "hand over sets");
        match self.outgoing.iter_mut().find(|(p, _)| *p == peer) {
            Some((_, transfers)) => transfers.push(transfer),
            None => self.outgoing.push((peer, vec![transfer])),
        }
    }

    /// One message per peer with every transfer this step made for it, in
    /// the order they were made.
    fn send_outgoing(&mut self, out: &mut Vec<Output>) {
        for (to, transfers) in std::mem::take(&mut self.outgoing) {
            let seqs = transfers.iter().map(|t| t.seq).collect();
            let body = encode(&TransfersSent {
                epoch: self.leader.epoch(),
                version: VERSION,
                transfers,
            });
            self.leader.note_sent(body.len());
            out.push(Output::Send { to, seqs, body });
        }
    }

    /// Asks the sensor to follow the tracks the leader waits for, unless a
    /// request is already out.
    fn ask_follow(&mut self, out: &mut Vec<Output>) {
        if self.following {
            return;
        }
        if let Some(follow) = self.leader.pending_follow() {
            self.following = true;
            out.push(Output::AskFollow(follow.clone()));
        }
    }

    /// A resend request failed: asked again at once the first time (a
    /// lost reply), then only after a backoff that doubles with each
    /// refusal in a row, so that a sensor that cannot answer is not
    /// flooded. A sensor that dropped the batches this leader needs (its
    /// durable mark was passed by a holder whose state is gone) is said
    /// once, as an error, and by every answer while it lasts: the role
    /// cannot be rebuilt from the stream.
    fn resend_refused(&mut self, now: Now, error: &str) {
        self.resend_refusals += 1;
        let wait = resend_backoff(self.resend_refusals, self.timers.late);
        self.resend_not_before = now + wait;
        let name = self.leader.name().to_string();
        if error.contains("were dropped") {
            if self.unrebuildable.is_none() {
                tracing::error!(leader = %name, %error,
                    "the sensor no longer holds the batches this role needs: it cannot be \
                     rebuilt from the stream, and its answers stay degraded; asking again \
                     with a backoff");
            }
            self.unrebuildable = Some(error.to_string());
        } else if self.resend_refusals.is_power_of_two() {
            tracing::warn!(leader = %name, %error, refusals = self.resend_refusals,
                retry_in_ms = wait.as_millis() as u64, "resend request failed; asking again");
        }
    }

    /// A peer's answer to a transfer request (or why there was none): its
    /// transfers taken one by one, or the request asked again later.
    fn transfers_answered(
        &mut self,
        now: Now,
        peer: &str,
        result: Result<TransfersSent, String>,
        out: &mut Vec<Output>,
    ) {
        self.asking.remove(peer);
        if let Some(r) = &mut self.recovery {
            // A peer that is down itself sends its transfers again when it
            // comes back.
            r.peers.retain(|p| *p != peer);
        }
        match result {
            Ok(sent) => {
                self.transfers_failed.remove(peer);
                // One input each: one a peer got wrong is refused alone.
                for t in sent.transfers {
                    let bytes = encode(&TransfersSent {
                        epoch: sent.epoch,
                        version: VERSION,
                        transfers: vec![t],
                    });
                    self.input(Kind::Transfer, bytes, "a peer's sent transfers", out);
                }
            }
            Err(e) => self.transfers_refused(now, peer, &e),
        }
    }

    /// A peer did not answer a transfer request: asked again at once the
    /// first time (a reply lost), then after a backoff that doubles with
    /// each failure in a row (a peer that is down, its role not adopted
    /// yet, is not asked four times a second), logged when the count of
    /// failures reaches a power of two.
    fn transfers_refused(&mut self, now: Now, peer: &str, error: &str) {
        let failed = self
            .transfers_failed
            .entry(peer.to_string())
            .or_insert((0, now));
        failed.0 += 1;
        failed.1 = now + transfers_backoff(failed.0, self.timers.late);
        if failed.0.is_power_of_two() {
            tracing::warn!(leader = %self.leader.name(), %peer, %error, failures = failed.0,
                retry_in_ms = (failed.1 - now).as_millis() as u64,
                "a peer did not resend its transfers; asking again");
        }
    }

    /// Asks the sensor for every batch from the next one expected, unless
    /// a request is already out or a refusal's backoff still runs.
    fn ask_resend(&mut self, now: Now, out: &mut Vec<Output>) {
        if self.resending || now < self.resend_not_before {
            return;
        }
        self.resending = true;
        out.push(Output::AskResend(Resend {
            epoch: self.leader.epoch(),
            version: VERSION,
            leader: self.leader.name().to_string(),
            from: self.leader.next_batch(),
        }));
    }

    /// Asks `peer` for every transfer it sent this leader after its
    /// position, unless a request to it is already out.
    fn ask_transfers(&mut self, now: Now, peer: &str, out: &mut Vec<Output>) {
        let Some(me) = self.leader.index() else {
            return;
        };
        if self.asking.contains_key(peer)
            || self
                .transfers_failed
                .get(peer)
                .is_some_and(|&(_, not_before)| now < not_before)
        {
            return;
        }
        self.asking.insert(peer.to_string(), now);
        out.push(Output::AskTransfers {
            peer: peer.to_string(),
            wanted: TransfersWanted {
                epoch: self.leader.epoch(),
                version: VERSION,
                to: me,
                after: self.leader.received_through(),
            },
        });
    }

    /// The sweep: sync and mark, expire held queries, ask again for what
    /// seems lost.
    fn tick(&mut self, now: Now, out: &mut Vec<Output>) {
        // At rest with inputs journaled since the last snapshot: a snapshot,
        // so that the mark below lets the others forget all they keep.
        let resting = self.journaled > 0 && self.journaled == self.journaled_at_sweep;
        if resting && self.failure.is_none() && self.snapshots() {
            self.snapshot(now, out);
        }
        self.journaled_at_sweep = self.journaled;
        // With a journal, the others may forget what the last snapshot
        // holds (the journal after it may yet be found damaged); without
        // one, what was applied (a leader that dies does not come back).
        // With a standby, what it also holds, and never a step back.
        let mark = match self.timers.journal {
            true => self.journaled_mark(),
            false => Some(self.leader.durable()),
        };
        let onwards = match (&mark, &self.published) {
            (Some(mark), Some(published)) if self.timers.standby => {
                standby::not_behind(mark, published)
            }
            _ => true,
        };
        let publish = self.failure.is_none() && mark.is_some() && self.published != mark && onwards;
        if publish {
            self.published.clone_from(&mark);
        }
        if self.timers.journal || publish {
            out.push(Output::Persist {
                mark: mark.filter(|_| publish),
            });
        }
        if self.timers.standby {
            self.standby_sweep(now, out);
        }
        self.expire(now, out);
        let late = self
            .held
            .iter()
            .any(|h| now.saturating_sub(h.since) > self.timers.late);
        let unanswered = self.recovery.as_ref().is_some_and(|r| !r.batches);
        if self.leader.missing_batches().is_some() || late || unanswered {
            self.ask_resend(now, out);
        }
        // A transfer waited for too long: lost on the way, or sent while
        // this leader was down. The peer keeps what it sent.
        if let Some(((_, from), since)) = self.waiting_since {
            if now.saturating_sub(since) > self.timers.late {
                if let Some(peer) = self.leader.peer(from).map(str::to_owned) {
                    self.ask_transfers(now, &peer, out);
                }
            }
        }
        // Components waited for too long (a factored stream): their
        // holders are not known here, so every peer is asked.
        if let Some((_, since)) = self.components_since {
            if now.saturating_sub(since) > self.timers.late {
                let me = self.leader.name().to_owned();
                let peers: Vec<String> = self
                    .leader
                    .leaders()
                    .iter()
                    .filter(|l| **l != me)
                    .cloned()
                    .collect();
                for peer in peers {
                    self.ask_transfers(now, &peer, out);
                }
            }
        }
        // A transfer request that got no answer (the driver always answers,
        // if only with a timeout, but a lost one must not block forever).
        let stale = self.timers.query_timeout + self.timers.late;
        self.asking.retain(|_, at| now.saturating_sub(*at) <= stale);
        self.ask_follow(out);
    }

    /// Bookkeeping after every input: a gap asks for the missing batches,
    /// the wait for a transfer is timed, recovery may be over, a snapshot
    /// may be due.
    fn after_input(&mut self, now: Now, out: &mut Vec<Output>) {
        if self.leader.missing_batches().is_some() {
            self.ask_resend(now, out);
        }
        let waiting = self.leader.waiting_for_transfer();
        if waiting != self.waiting_since.map(|w| w.0) {
            self.waiting_since = waiting.map(|w| (w, now));
        }
        let components = self.leader.waiting_for_components();
        if components != self.components_since.map(|w| w.0) {
            self.components_since = components.map(|w| (w, now));
        }
        if self.recovery.as_ref().is_some_and(|r| {
            r.batches && r.peers.is_empty() && self.leader.missing_batches().is_none()
        }) {
            let seconds = self
                .recovery
                .take()
                .map_or(0.0, |r| now.saturating_sub(r.since).as_secs_f64());
            self.leader.note_recovered(seconds);
            tracing::info!(leader = %self.leader.name(), seconds, position = self.leader.position(), "caught up");
        }
        self.progress(false, out);
        // Every input journaled is applied: the state can replace them.
        if let (true, Some(every)) = (self.timers.journal, self.timers.snapshot_every) {
            if self.journaled >= every {
                self.snapshot(now, out);
            }
        }
    }

    /// Whether this leader writes snapshots.
    fn snapshots(&self) -> bool {
        self.timers.journal && self.timers.snapshot_every.is_some()
    }

    /// The whole state, to replace the journal and to go to the standby;
    /// its durable mark is published from the next sweep on (after the
    /// driver wrote it, and the standby holds it).
    fn snapshot(&mut self, now: Now, out: &mut Vec<Output>) {
        self.journaled = 0;
        self.journaled_at_sweep = 0;
        self.leader.note_snapshot();
        self.safe = Some(self.leader.durable());
        out.push(Output::Snapshot(self.leader.snapshot()));
        self.offer_standby(now, out);
    }

    /// Publishes the leader's progress if it moved and a window waits for
    /// it (or `again`, at the sweep).
    ///
    /// Between sweeps, only once the leader has caught up with what it was
    /// sent: the sensor then counts it as no bound on its window at all.
    /// A mark from a leader stopped mid-batch for a peer's transfer moves
    /// the window only as far as the stop, and the transfer comes soon;
    /// published at every pass a transfer started, such marks were three a
    /// batch at four leaders on the 10,000-target crowd, a quarter of all
    /// the messages a leader put. A leader stopped for long is still heard
    /// at every sweep.
    fn progress(&mut self, again: bool, out: &mut Vec<Output>) {
        let through = self.leader.done_through();
        let moved =
            through > self.progressed && self.timers.flow_control && self.leader.caught_up();
        if self.failure.is_some() || !(again || moved) {
            return;
        }
        self.progressed = through;
        out.push(Output::Progress(Progress {
            epoch: self.leader.epoch(),
            version: VERSION,
            leader: self.leader.name().to_string(),
            through,
            batch: self.leader.next_batch(),
        }));
    }

    /// Counts and logs a message from the network the leader refused: it
    /// changes nothing else.
    fn reject(&mut self, what: &str, from: &str, problem: &WireError, out: &mut Vec<Output>) {
        self.count_rejected(what, from, problem, out);
    }

    /// Counts a refusal, logs it, and journals that it happened (not what
    /// came), so the count survives a restart.
    pub(super) fn count_rejected(
        &mut self,
        what: &str,
        from: &str,
        problem: &dyn std::fmt::Display,
        out: &mut Vec<Output>,
    ) {
        let rejected = self.note_refusal(out);
        tracing::warn!(leader = %self.leader.name(), from, what, %problem, rejected, "input rejected");
    }

    /// Counts a refusal and journals that it happened (not what came), so
    /// the count survives a restart; the count so far.
    fn note_refusal(&mut self, out: &mut Vec<Output>) -> u64 {
        let rejected = self.leader.note_rejected();
        if self.timers.journal {
            out.push(Output::Journal {
                kind: Kind::Rejected,
                bytes: Vec::new(),
            });
        }
        rejected
    }
}

/// The most a refused resend request waits before it is asked again.
/// The name the fence keeps the sensor's follow replies under (they
/// name no sensor; a leader has one that it follows through).
const SENSOR_FOLLOWS: &str = "the sensor's follow replies";

pub const MAX_RESEND_BACKOFF: Duration = Duration::from_secs(30);

/// The longest wait before a peer that failed transfer requests is asked
/// again: short, since its role is adopted within the takeover time and
/// then answers.
pub const MAX_TRANSFERS_BACKOFF: Duration = Duration::from_secs(4);

/// The wait before asking a peer for transfers again after `failures`
/// failed requests in a row: as [`resend_backoff`], at most
/// [`MAX_TRANSFERS_BACKOFF`].
pub(crate) fn transfers_backoff(failures: u32, late: Duration) -> Duration {
    resend_backoff(failures, late).min(MAX_TRANSFERS_BACKOFF)
}

/// The wait before asking again after `refusals` refused resend requests
/// in a row: none after one (a reply lost on the way), then `late`,
/// doubling with each refusal, at most [`MAX_RESEND_BACKOFF`].
pub(crate) fn resend_backoff(refusals: u32, late: Duration) -> Duration {
    if refusals <= 1 {
        return Duration::ZERO;
    }
    let doublings = (refusals - 2).min(16);
    (late * 2u32.pow(doublings)).min(MAX_RESEND_BACKOFF)
}

#[cfg(test)]
mod tests;
