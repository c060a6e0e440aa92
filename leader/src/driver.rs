//! The leader process: the [`Node`] state machine behind Zenoh. It only
//! moves bytes and clocks: what to do with them — the door, the journal
//! order, holding queries for their cut, asking again for what was lost,
//! recovering after a restart — is the node's ([`crate::machine`]).
//!
//! One task owns the node; everything else (stream batches, transfers from
//! peers, the replies to its gets, the coordinator's queries, the sweep's
//! clock) reaches it through channels, so inputs are applied strictly one
//! at a time. The journal is a file ([`crate::journal`]); batches asked for
//! again come from the sensor's replay queryable (exact, by batch number,
//! rather than zenoh-ext's advanced subscriber, whose bounded cache and
//! sample-level recovery do not know our batch numbers).

use crate::error::{MeshError, RunError};
use crate::journal::{Journal, JournalError, JournalOptions, Kind, Recovered};
use crate::machine::{Ask, Input, Node, Output, Timers};
use crate::standby;
use idmesh_ownership::{Ownership, HANDOVER_PATIENCE};
use idmesh_protocol::wire::coordinator_to_leader::Partial;
use idmesh_protocol::wire::keys::Keys;
use idmesh_protocol::wire::leader_to_leader::{StandbyCopy, TransfersSent};
use idmesh_protocol::wire::leader_to_sensor::{Durable, Resent};
use idmesh_protocol::wire::sensor_to_leader::Batch;
use idmesh_protocol::wire::valid::MAX_SNAPSHOT_BYTES;
use idmesh_protocol::wire::{decode, encode, VERSION};
use std::collections::hash_map::Entry;
use std::collections::HashMap;
use std::future::Future;
use std::sync::Arc;
use std::time::{Duration, Instant};
use tokio::sync::{mpsc, watch};
use zenoh::pubsub::Publisher;
use zenoh::qos::CongestionControl;
use zenoh::query::{ConsolidationMode, Query, QueryTarget};
use zenoh::Session;

#[derive(Debug, Clone)]
pub(crate) struct LeaderConfig {
    /// The role: the leader's name in the stream and on its keys.
    pub name: String,
    /// The process running it (itself, or the one that adopted the role).
    pub host: String,
    /// The epoch the voters gave `host` for the role (0 without voters),
    /// on every message it sends.
    pub epoch: u64,
    /// The role was adopted from a process gone for good: catch up even if
    /// its journal is empty.
    pub adopted: bool,
    pub keys: Keys,
    /// The sensor gateway to ask when sets bring tracks to follow.
    pub sensor: String,
    /// How long to wait for the sensor's follow reply, and how long a query
    /// is held for a cut that has not arrived.
    pub follow_timeout: Duration,
    /// Where to keep the input journal; None = no journal (a leader that
    /// dies cannot come back).
    pub journal: Option<JournalOptions>,
    /// Write a snapshot (and start the journal again) after this many
    /// inputs; None = never (the journal grows with the stream).
    pub snapshot_every: Option<usize>,
    /// Tests only: every n-th transfer message (the transfers one step
    /// made for a peer) is not put, as if the link lost it (a TLS link
    /// that closes and reopens does).
    pub drop_transfer_every: Option<u64>,
    /// Tests only: every n-th answer pushed at a cut is not put (the
    /// coordinator asks for it instead).
    pub drop_push_every: Option<u64>,
    /// The sensor streams under a window ([`Timers::flow_control`]).
    pub flow_control: bool,
    /// Which role's process is this role's standby now, as the host
    /// works it out from the liveliness tokens; None = no standby (one
    /// leader process, or no journal).
    pub standby: Option<watch::Receiver<Option<String>>>,
}

/// Replies to the gets the leader makes, back in its one task.
type Reply = Input;

/// Runs a leader until `shutdown` completes. With a journal that already
/// holds entries, the leader first replays them (rebuilding the state it
/// had when it died), then catches up ([`Node::recover`]).
pub async fn run(
    session: Session,
    config: LeaderConfig,
    shutdown: impl Future<Output = ()>,
) -> Result<(), RunError> {
    let keys = &config.keys;
    let name = config.name.clone();
    // The journal's lock before anything is declared: a role whose journal
    // another process holds runs there (cut off, or still handing it
    // over), and must not also run here, not even its queryables.
    let owned = match &config.journal {
        Some(options) => Some((options, own(&options.path, &config.host).await?)),
        None => None,
    };
    let Inbox {
        events,
        transfers,
        partials,
        stats,
        sent,
        durables,
        copies,
        stored,
    } = Inbox::declare(&session, keys, &name).await?;
    let (reply_tx, mut replies) = mpsc::unbounded_channel::<Reply>();
    let started = Instant::now();
    let (mut journal, recovered) = open_journal(owned)?;
    // The token claims the role (a process coming back finds it taken);
    // queries meanwhile are told the leader is recovering.
    let token = session
        .liveliness()
        .declare_token(keys.alive("leader", &name))
        .await
        .map_err(|e| MeshError::new("declare the liveliness token", e))?;
    let last_snapshot = recovered.snapshot.clone();
    let (mut node, first) = start_node(&config, recovered, journal.is_some(), started)?;
    let mut standby = config.standby.clone().filter(|_| journal.is_some());
    tracing::info!(leader = %name, host = %config.host, "leader up");

    let mut driver = Driver::new(&session, &config, &mut journal, &reply_tx, last_snapshot);
    driver.carry_out(&mut node, first, started).await;
    let mut sweep = tokio::time::interval(node.timers().sweep);
    tokio::pin!(shutdown);

    loop {
        let input = tokio::select! {
            _ = &mut shutdown => break,
            sample = events.recv_async() => {
                let Ok(sample) = sample else { break };
                Input::Message { kind: Kind::Batch, bytes: sample.payload().to_bytes().into_owned(), origin: sample.key_expr().to_string() }
            }
            sample = transfers.recv_async() => {
                let Ok(sample) = sample else { break };
                Input::Message { kind: Kind::Transfer, bytes: sample.payload().to_bytes().into_owned(), origin: sample.key_expr().to_string() }
            }
            reply = replies.recv() => match reply {
                None => break,
                Some(reply) => reply,
            },
            query = partials.recv_async() => {
                let Ok(query) = query else { break };
                let (ask, base) = partial_ask(&query);
                Input::Partial { id: driver.hold(query), ask, base }
            }
            query = sent.recv_async() => {
                let Ok(query) = query else { break };
                let bytes = query.payload().map(|p| p.to_bytes().into_owned()).unwrap_or_default();
                let origin = query.key_expr().to_string();
                Input::SentWanted { id: driver.hold(query), bytes, origin }
            }
            sample = durables.recv_async() => {
                let Ok(sample) = sample else { break };
                Input::Durable { bytes: sample.payload().to_bytes().into_owned(), origin: sample.key_expr().to_string() }
            }
            sample = stored.recv_async() => {
                let Ok(sample) = sample else { break };
                Input::StandbyStored { bytes: sample.payload().to_bytes().into_owned(), origin: sample.key_expr().to_string() }
            }
            to = next_standby(&mut standby) => Input::Standby(to),
            sample = copies.recv_async() => {
                let Ok(sample) = sample else { break };
                driver.keep_copy(&sample.payload().to_bytes()).await;
                continue;
            }
            _ = sweep.tick() => Input::Tick,
            query = stats.recv_async() => {
                let Ok(query) = query else { break };
                let body = serde_json::to_vec(&node.leader().stats()).unwrap_or_default();
                answer_stats(&query, keys, &name, body).await;
                continue;
            }
        };
        let outputs = node.step(started.elapsed(), input);
        driver.carry_out(&mut node, outputs, started).await;
    }
    if let Some(j) = &mut journal {
        let _ = j.sync();
    }
    // The lock before the token: whoever waits for the token to go (a
    // process taking its role back) finds the journal free.
    drop(journal);
    drop(token);
    tracing::info!(leader = %name, "leader stopped");
    Ok(())
}

type Samples =
    zenoh::pubsub::Subscriber<zenoh::handlers::FifoChannelHandler<zenoh::sample::Sample>>;
type Queries = zenoh::query::Queryable<zenoh::handlers::FifoChannelHandler<Query>>;

/// The journal `owned` names (with its lock), opened, and what it held.
fn open_journal(
    owned: Option<(&JournalOptions, Ownership)>,
) -> Result<(Option<Journal>, Recovered), RunError> {
    Ok(match owned {
        Some((options, owner)) => {
            let (journal, recovered) = Journal::open(options, owner)?;
            (Some(journal), recovered)
        }
        None => (None, Recovered::default()),
    })
}

/// The standby the host names next (waits for ever without one).
async fn next_standby(standby: &mut Option<watch::Receiver<Option<String>>>) -> Option<String> {
    let Some(receiver) = standby else {
        return std::future::pending().await;
    };
    if receiver.changed().await.is_err() {
        // The host is gone: the role is stopping.
        *standby = None;
        return std::future::pending().await;
    }
    receiver.borrow_and_update().clone()
}

/// What reaches a leader from the mesh: the stream's batches, its peers'
/// transfers and durable marks, the queries it answers, other roles'
/// snapshots to keep as their standby, and its own standby's word.
struct Inbox {
    events: Samples,
    transfers: Samples,
    partials: Queries,
    stats: Queries,
    sent: Queries,
    durables: Samples,
    copies: Samples,
    stored: Samples,
}

impl Inbox {
    /// Declares the leader `name`'s subscribers and queryables.
    async fn declare(session: &Session, keys: &Keys, name: &str) -> Result<Self, MeshError> {
        let events = session
            .declare_subscriber(keys.leader_events(name))
            .await
            .map_err(|e| MeshError::new("declare the event subscriber", e))?;
        let transfers = session
            .declare_subscriber(keys.leader_transfer(name))
            .await
            .map_err(|e| MeshError::new("declare the transfer subscriber", e))?;
        let partials = session
            .declare_queryable(keys.leader_partial(name))
            .await
            .map_err(|e| MeshError::new("declare the partial-sums queryable", e))?;
        let stats = session
            .declare_queryable(keys.leader_stats(name))
            .await
            .map_err(|e| MeshError::new("declare the stats queryable", e))?;
        let sent = session
            .declare_queryable(keys.leader_sent(name))
            .await
            .map_err(|e| MeshError::new("declare the sent-transfers queryable", e))?;

        let durables = session
            .declare_subscriber(keys.every_leader_durable())
            .await
            .map_err(|e| MeshError::new("declare the durable-mark subscriber", e))?;
        let copies = session
            .declare_subscriber(keys.leader_standby(name))
            .await
            .map_err(|e| MeshError::new("declare the standby-copy subscriber", e))?;
        let stored = session
            .declare_subscriber(keys.leader_stored(name))
            .await
            .map_err(|e| MeshError::new("declare the standby-acknowledgement subscriber", e))?;
        Ok(Inbox {
            events,
            transfers,
            partials,
            stats,
            sent,
            durables,
            copies,
            stored,
        })
    }
}

/// The node as the journal leaves it: `recovered` replayed (rebuilding
/// the state it had when it died), and what it asks to do first to catch
/// up.
fn start_node(
    config: &LeaderConfig,
    recovered: Recovered,
    journaled: bool,
    started: Instant,
) -> Result<(Node, Vec<Output>), RunError> {
    let timers = Timers {
        flow_control: config.flow_control,
        standby: config.standby.is_some() && journaled,
        ..Timers::new(config.follow_timeout, journaled, config.snapshot_every)
    };
    let (node, first) = Node::recover(
        &config.name,
        crate::Holder {
            process: &config.host,
            epoch: config.epoch,
        },
        recovered.snapshot.as_deref(),
        recovered
            .entries
            .iter()
            .map(|e| (e.kind, e.bytes.as_slice())),
        config.adopted,
        recovered.damage.as_ref().map(|d| d.records()),
        timers,
        started.elapsed(),
    )?;
    Ok((node, first))
}

/// What a partial-sums query asks, and the tag of the answer the
/// coordinator keeps, if it said one.
fn partial_ask(query: &Query) -> (Ask, Option<u64>) {
    let parameters = query.parameters();
    Ask::parse_with_base(
        parameters.contains_key("quiet"),
        // `;rows`: an identity query wants the rows of the
        // information matrix.
        parameters.contains_key("rows"),
        parameters.get("tag"),
        parameters.get("base"),
    )
}

/// Answers a stats query with `body`, the leader's counters.
async fn answer_stats(query: &Query, keys: &Keys, name: &str, body: Vec<u8>) {
    if let Err(e) = query
        .reply(keys.leader_stats(name), body)
        .encoding(zenoh::bytes::Encoding::APPLICATION_JSON)
        .await
    {
        tracing::warn!(leader = %name, error = %e, "could not answer a stats query");
    }
}

/// The role's journal lock for `host`, waiting a little for a process
/// that is letting go of it (handing the role back).
async fn own(journal: &std::path::Path, host: &str) -> Result<Ownership, RunError> {
    let deadline = Instant::now() + HANDOVER_PATIENCE;
    loop {
        if let Some(owner) = Ownership::try_take(journal, host).map_err(JournalError::from)? {
            return Ok(owner);
        }
        if Instant::now() >= deadline {
            return Err(JournalError::from(Ownership::refused(journal)).into());
        }
        tokio::time::sleep(Duration::from_millis(50)).await;
    }
}

/// Carries out what the node asks: the journal, the puts and gets, the
/// answers to queries it was handed by id.
struct Driver<'a> {
    session: &'a Session,
    config: &'a LeaderConfig,
    journal: &'a mut Option<Journal>,
    /// Queries handed to the node, waiting for its answer.
    queries: HashMap<u64, Query>,
    next_id: u64,
    reply_tx: &'a mpsc::UnboundedSender<Reply>,
    /// Transfer messages put so far (for the injected losses).
    transfers_put: u64,
    /// Answers pushed at cuts (put or, as a fault, lost).
    pushes: u64,
    /// The publishers of the keys this leader puts on again and again (its
    /// peers' transfers, its progress), declared at their first put: a
    /// declared key travels as a number and its routes are kept, where a
    /// plain put resolves its key's matches every time (in a profile of
    /// four leaders on the 10,000-target crowd, 3% of their CPU).
    publishers: HashMap<String, Publisher<'static>>,
    /// The last snapshot written (or recovered from): what goes to the
    /// standby.
    last_snapshot: Option<Vec<u8>>,
}

/// Tests only: whether the `count`-th message of a kind is lost on
/// purpose, every `every`-th being lost.
fn lost_on_purpose(every: Option<u64>, count: u64) -> bool {
    every.is_some_and(|n| n > 0 && count.is_multiple_of(n))
}

impl<'a> Driver<'a> {
    /// A driver with nothing under way; `last_snapshot` is the one the
    /// journal was recovered from.
    fn new(
        session: &'a Session,
        config: &'a LeaderConfig,
        journal: &'a mut Option<Journal>,
        reply_tx: &'a mpsc::UnboundedSender<Reply>,
        last_snapshot: Option<Vec<u8>>,
    ) -> Self {
        Driver {
            session,
            config,
            journal,
            queries: HashMap::new(),
            next_id: 0,
            reply_tx,
            transfers_put: 0,
            pushes: 0,
            publishers: HashMap::new(),
            last_snapshot,
        }
    }

    /// Keeps `query` until the node answers it; returns its id.
    fn hold(&mut self, query: Query) -> u64 {
        self.next_id += 1;
        self.queries.insert(self.next_id, query);
        self.next_id
    }

    async fn carry_out(&mut self, node: &mut Node, outputs: Vec<Output>, started: Instant) {
        let keys = &self.config.keys;
        let name = &self.config.name;
        let mut failed: Option<String> = None;
        for output in outputs {
            match output {
                Output::Journal { kind, bytes } => {
                    if let Some(j) = self.journal.as_mut() {
                        if let Err(e) = j.append(kind, &bytes) {
                            tracing::error!(leader = %name, error = %e, "cannot journal an input");
                            failed = Some(e.to_string());
                        }
                    }
                }
                Output::Send { to, seqs, body } => {
                    self.transfers_put += 1;
                    if lost_on_purpose(self.config.drop_transfer_every, self.transfers_put) {
                        tracing::info!(leader = %name, %to, ?seqs, "fault injected: transfers lost");
                        continue;
                    }
                    tracing::trace!(leader = %name, %to, ?seqs, "put transfers");
                    let key = keys.leader_transfer(&to);
                    if let Err(e) = self.put(key, CongestionControl::Block, body).await {
                        tracing::warn!(leader = %name, error = %e, "could not send sets to {to}");
                    }
                }
                Output::AskFollow(follow) => self.ask(
                    keys.sensor_follow(&self.config.sensor),
                    encode(&follow),
                    Input::Followed,
                ),
                // Fire and forget: a lost request costs items this leader
                // ignores, never an answer.
                Output::Unfollow(unfollow) => {
                    let key = keys.sensor_unfollow(&self.config.sensor);
                    let put = self.session.put(key, encode(&unfollow));
                    if let Err(e) = put.congestion_control(CongestionControl::Drop).await {
                        tracing::debug!(leader = %name, error = %e, "an unfollow request was lost");
                    }
                }
                Output::AskResend(resend) => self.ask(
                    keys.sensor_resend(&self.config.sensor),
                    encode(&resend),
                    |reply| Input::Resent(reply.and_then(|bytes| batches_of(&bytes))),
                ),
                Output::AskTransfers { peer, wanted } => {
                    let (session, tx, timeout) = (
                        self.session.clone(),
                        self.reply_tx.clone(),
                        self.config.follow_timeout,
                    );
                    let key = keys.leader_sent(&peer);
                    tokio::spawn(async move {
                        let result = ask(&session, &key, encode(&wanted), timeout)
                            .await
                            .and_then(|bytes| transfers_of(&bytes));
                        let _ = tx.send(Input::Transfers { peer, result });
                    });
                }
                Output::Push(partial) => self.push(partial).await,
                Output::Answer { id, answer } => self.answer_partial(id, answer).await,
                Output::AnswerSent { id, answer } => self.answer_sent(id, answer).await,
                Output::Persist { mark } => {
                    // A snapshot that could not be written must not be
                    // published as safe.
                    if failed.is_none() {
                        failed = self.persist(mark).await.err();
                    }
                }
                Output::Progress(progress) => {
                    tracing::trace!(leader = %name, through = progress.through, "put progress");
                    // Lost, it is published again at the next sweep.
                    let key = keys.leader_progress(name);
                    let put = self.put(key, CongestionControl::Drop, encode(&progress));
                    if let Err(e) = put.await {
                        tracing::debug!(leader = %name, error = %e, "a progress mark was lost");
                    }
                }
                Output::Snapshot(state) => match self.snapshot(&state) {
                    Ok(()) => self.last_snapshot = Some(state),
                    Err(why) => failed = Some(why),
                },
                Output::ToStandby { to, mark } => {
                    // A snapshot that could not be written is not sent.
                    if failed.is_none() {
                        if let Some(bytes) = self.send_standby(to, mark).await {
                            node.note_standby_sent(bytes);
                        }
                    }
                }
            }
        }
        if let Some(why) = failed {
            let more = node.step(started.elapsed(), Input::Failed(why));
            // A failed node asks for nothing more than answers.
            Box::pin(self.carry_out(node, more, started)).await;
        }
    }

    /// Puts the answer the node computed at a cut, for the coordinator
    /// (unless a fault is injected).
    async fn push(&mut self, partial: Arc<Partial>) {
        let keys = &self.config.keys;
        let name = &self.config.name;
        self.pushes += 1;
        if lost_on_purpose(self.config.drop_push_every, self.pushes) {
            tracing::info!(leader = %name, tag = partial.tag, "fault injected: pushed answer lost");
            return;
        }
        let key = keys.leader_pushed(name, partial.tag);
        // Express: a query waits for it. Dropped rather than
        // waited on when the link is full: the coordinator
        // then asks.
        let put = self
            .session
            .put(key, encode(&*partial))
            .express(true)
            .congestion_control(CongestionControl::Drop);
        if let Err(e) = put.await {
            tracing::debug!(leader = %name, error = %e, "a pushed answer was lost");
        }
    }

    /// Answers the partial-sums query held as `id`.
    async fn answer_partial(&mut self, id: u64, answer: Result<Arc<Partial>, String>) {
        let Some(query) = self.queries.remove(&id) else {
            return;
        };
        let sent = match answer {
            Ok(partial) => {
                query
                    .reply(query.key_expr().clone(), encode(&*partial))
                    .await
            }
            Err(why) => query.reply_err(why).await,
        };
        if let Err(e) = sent {
            tracing::warn!(error = %e, "could not answer a partial-sums query");
        }
    }

    /// Answers the request for sent transfers held as `id`.
    async fn answer_sent(&mut self, id: u64, answer: Result<TransfersSent, String>) {
        let Some(query) = self.queries.remove(&id) else {
            return;
        };
        let sent = match answer {
            Ok(body) => query.reply(query.key_expr().clone(), encode(&body)).await,
            Err(why) => query.reply_err(why).await,
        };
        if let Err(e) = sent {
            tracing::warn!(error = %e, "could not answer a request for sent transfers");
        }
    }

    /// Syncs the journal, then publishes `mark` as safe; why not, if the
    /// journal could not be synced.
    async fn persist(&mut self, mark: Option<Durable>) -> Result<(), String> {
        let keys = &self.config.keys;
        let name = &self.config.name;
        if let Some(j) = self.journal.as_mut() {
            j.sync().map_err(|e| e.to_string())?;
        }
        if let Some(mark) = mark {
            if let Err(e) = self
                .session
                .put(keys.leader_durable(name), encode(&mark))
                .await
            {
                tracing::warn!(leader = %name, error = %e, "could not publish the durable mark");
            }
        }
        Ok(())
    }

    /// Writes the snapshot `state` and starts the journal again; why not,
    /// if it could not be written.
    fn snapshot(&mut self, state: &[u8]) -> Result<(), String> {
        let name = &self.config.name;
        if let Some(j) = self.journal.as_mut() {
            let at = Instant::now();
            match j.compact(state) {
                Ok(()) => {
                    tracing::debug!(leader = %name, seconds = at.elapsed().as_secs_f64(), "snapshot written")
                }
                Err(e) => {
                    tracing::error!(leader = %name, error = %e, "cannot write a snapshot");
                    return Err(e.to_string());
                }
            }
        }
        Ok(())
    }

    /// Puts the last snapshot, whose mark is `mark`, on standby `to`'s
    /// key; the standby answers on this role's `stored` key. Returns the
    /// bytes sent.
    async fn send_standby(&mut self, to: String, mark: Durable) -> Option<usize> {
        let name = &self.config.name;
        let state = self.last_snapshot.as_ref()?;
        if state.len() > MAX_SNAPSHOT_BYTES {
            tracing::error!(leader = %name, bytes = state.len(), most = MAX_SNAPSHOT_BYTES,
                "the snapshot is too large to send to the standby: the role's durable mark stops moving");
            return None;
        }
        let copy = StandbyCopy {
            version: VERSION,
            role: name.clone(),
            to: to.clone(),
            mark,
            state: state.clone(),
        };
        let body = encode(&copy);
        let bytes = body.len();
        tracing::debug!(leader = %name, standby = %to, bytes, "snapshot to the standby");
        let key = self.config.keys.leader_standby(&to);
        match self.put(key, CongestionControl::Block, body).await {
            Ok(()) => Some(bytes),
            Err(e) => {
                tracing::warn!(leader = %name, standby = %to, error = %e, "could not send the snapshot to the standby");
                None
            }
        }
    }

    /// Another role's snapshot, sent here as its standby: written to this
    /// process's state directory, then acknowledged with its mark.
    async fn keep_copy(&mut self, bytes: &[u8]) {
        let name = &self.config.name;
        let Some(dir) = self.config.journal.as_ref().and_then(|j| j.path.parent()) else {
            return;
        };
        let copy = match decode::<StandbyCopy>(bytes) {
            // The role's own snapshot, sent to its process standing by
            // to take it home: that process's host keeps it, not this.
            Ok(copy) if copy.role == *name => return,
            Ok(copy) if copy.to == *name => copy,
            Ok(copy) => {
                tracing::warn!(leader = %name, role = %copy.role, to = %copy.to, "a standby copy for another role: not kept");
                return;
            }
            Err(e) => {
                tracing::warn!(leader = %name, error = %e, "a standby copy refused");
                return;
            }
        };
        let at = Instant::now();
        let stored = match standby::keep(dir, &copy, &self.config.host) {
            Ok(stored) => stored,
            Err(e) => {
                tracing::error!(leader = %name, role = %copy.role, error = %e, "cannot keep a standby copy");
                return;
            }
        };
        tracing::debug!(leader = %name, role = %copy.role, bytes = copy.state.len(),
            seconds = at.elapsed().as_secs_f64(), "standby copy kept");
        let key = self.config.keys.leader_stored(&copy.role);
        if let Err(e) = self
            .put(key, CongestionControl::Block, encode(&stored))
            .await
        {
            tracing::warn!(leader = %name, role = %copy.role, error = %e, "could not acknowledge a standby copy");
        }
    }

    /// Puts `body` on `key` through its publisher, declared (with
    /// `congestion`) at the key's first put.
    async fn put(
        &mut self,
        key: String,
        congestion: CongestionControl,
        body: Vec<u8>,
    ) -> zenoh::Result<()> {
        let publisher = match self.publishers.entry(key) {
            Entry::Occupied(held) => held.into_mut(),
            Entry::Vacant(new) => {
                let publisher = self
                    .session
                    .declare_publisher(new.key().clone())
                    .congestion_control(congestion)
                    .await?;
                new.insert(publisher)
            }
        };
        publisher.put(body).await
    }

    /// Makes one get in its own task; its answer comes back to the
    /// leader's task as `reply(answer)`.
    fn ask(&self, key: String, body: Vec<u8>, reply: fn(Result<Vec<u8>, String>) -> Reply) {
        let (session, tx, timeout) = (
            self.session.clone(),
            self.reply_tx.clone(),
            self.config.follow_timeout,
        );
        tokio::spawn(async move {
            let answer = ask(&session, &key, body, timeout).await;
            let _ = tx.send(reply(answer));
        });
    }
}

/// The transfers a peer's reply carries.
fn transfers_of(bytes: &[u8]) -> Result<TransfersSent, String> {
    decode::<TransfersSent>(bytes).map_err(|e| e.to_string())
}

/// The batches a resend reply carries.
fn batches_of(bytes: &[u8]) -> Result<Vec<Batch>, String> {
    decode::<Resent>(bytes)
        .map(|r| r.batches)
        .map_err(|e| e.to_string())
}

/// One get, answered by one process: the reply's bytes, or why not.
async fn ask(
    session: &Session,
    key: &str,
    body: Vec<u8>,
    timeout: Duration,
) -> Result<Vec<u8>, String> {
    let replies = session
        .get(key)
        .payload(body)
        .consolidation(ConsolidationMode::None)
        .target(QueryTarget::All)
        .timeout(timeout)
        .await
        .map_err(|e| e.to_string())?;
    match tokio::time::timeout(timeout + Duration::from_secs(1), replies.recv_async()).await {
        Ok(Ok(reply)) => match reply.result() {
            Ok(sample) => Ok(sample.payload().to_bytes().into_owned()),
            Err(e) => Err(String::from_utf8_lossy(&e.payload().to_bytes()).into_owned()),
        },
        Ok(Err(_)) => Err(format!("{key}: nobody answered")),
        Err(_) => Err(format!("{key}: no answer in time")),
    }
}
