//! The sensor process: streams a trace through the [`Gateway`] over Zenoh.
//! What to route, keep, place and answer is the gateway's (pure, see
//! [`crate::machine`]); this actor paces the lines and moves the bytes.
//!
//! One task owns the gateway. It publishes each leader's items as a batch on
//! the leader's own key (congestion control Block: an event is never
//! dropped), places cuts for the coordinator and answers follow requests
//! between chunks, so a cut is always a point of the same global order the
//! leaders apply. After the source is exhausted it keeps serving cuts and
//! follows until shut down, so queries keep being answered.
//!
//! Events come from a trace file (paced), standard input (as it comes) and
//! producers on `P/sensor/<name>/ingest` ([`crate::feed`]); the same task
//! takes all three, so they share one order. An ingest request is
//! answered only after its accepted lines are routed and the batches
//! holding them are published: what a producer sees acknowledged is in
//! the sensor's order.
//!
//! Every batch sent is kept, by leader and number, so that a leader that
//! lost some (a gap in the numbers, or the time it was down and
//! restarting) gets them again on `P/sensor/<name>/resend`, until the
//! leader publishes a durable mark past it ([`crate::batch_log`]); items every
//! leader has passed leave the router's log the same way. The logs live in
//! memory; with a journal ([`GatewayConfig::journal`]) what changed them is
//! appended to it and fsynced before any batch, acknowledgement or follow
//! reply that depends on it leaves, and a sensor started again on the same
//! journal rebuilds its state from it ([`crate::journal`]), goes on with
//! its trace after the last line it routed, and leaders that missed
//! batches ask for them again as after their own restart. [`Faults`] drops
//! or doubles batches on purpose, for the tests that show neither matters.

use crate::cuts::{CutParameters, Placed};
use crate::feed::{InputLine, Source};
use crate::ingest::Offer;
use crate::journal::{Journal, JournalError, Record};
use crate::machine::{CutOutcome, Gateway, RestoreError};
use crate::mesh::MeshConfig;
use crate::peers::{Fetch, Peers};
use crate::ros2::{Message, Named, Ros2Input};
use crate::router::Router;
use crate::standby::Replicator;
use idmesh_extract::adapters::ErrorBudget;
use idmesh_protocol::trace::Line;
use idmesh_protocol::wire::coordinator_to_sensor::SensorStatus;
use idmesh_protocol::wire::encode;
use idmesh_protocol::wire::keys::Keys;
use idmesh_protocol::wire::producer_to_sensor::{COUNTER, FINISH, PRODUCER, TIME};
use idmesh_protocol::wire::sensor_to_leader::Batch;
use std::future::Future;
use std::time::{Duration, Instant};
use tracing::Instrument;
use zenoh::pubsub::Publisher;
use zenoh::qos::CongestionControl;
use zenoh::query::Query;
use zenoh::sample::Sample;
use zenoh::Session;

#[derive(Debug, Clone)]
pub struct GatewayConfig {
    pub name: String,
    pub keys: Keys,
    /// Events per second; None = as fast as the leaders take them.
    pub rate: Option<f64>,
    /// Pace by the trace's own times instead (`rate` then scales them).
    pub realtime: bool,
    /// Stop after this many events.
    pub limit: Option<u64>,
    /// How long to wait for every leader to be up.
    pub wait_for_leaders: Duration,
    /// The stream stays open for producers once its trace and input are
    /// done: it never finishes, and takes ingested events until shut down.
    pub live: bool,
    /// Flow control: route at most this many seqs past the slowest
    /// leader's progress (None: as fast as the source gives).
    pub window: Option<u64>,
    pub faults: Faults,
    /// One sensor of several: which, and which leaders it serves
    /// ([`crate::mesh`]). Its events come from producers only, and its
    /// part of the stream ends when they say `finish`.
    pub mesh: Option<MeshConfig>,
    /// Extraction on: the source's lines are a tracker's reports
    /// ([`crate::extraction`]).
    pub extraction: Option<crate::extraction::Extraction>,
    /// Bad lines of standard input skipped (each named in the log and
    /// counted) before the next one stops the sensor (`--max-errors`, as
    /// `idmesh extract` and `idmesh replay --topology` count theirs); 0:
    /// the first one does.
    pub max_errors: usize,
    /// ROS 2 tracker topics read over rmw_zenoh ([`crate::ros2`]).
    pub ros2: Option<crate::ros2::Ros2Config>,
    /// The processes standing by for this sensor, in order of
    /// preference: every record of the journal is replicated to one of
    /// them ([`crate::standby`]); empty: none.
    pub standbys: Vec<String>,
    /// The epoch at which this process holds the sensor role (the
    /// voters' claim; 0 without voters), on every batch and reply.
    pub epoch: u64,
    /// With voters, the role's lease as the lease task keeps it: what the
    /// standby did not acknowledge leaves only under it ([`crate::lease`]).
    pub lease: Option<crate::LeaseClock>,
}

/// Faults injected on purpose (tests): the network losing or doubling
/// event batches.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct Faults {
    /// Every batch is published twice.
    pub duplicate: bool,
    /// Every n-th batch to each leader is not published at all (it stays
    /// in the log, for the leader to ask for again).
    pub drop_every: Option<u64>,
}

#[derive(Debug, thiserror::Error)]
pub enum GatewayError {
    #[error("zenoh: {what}: {message}")]
    Mesh { what: &'static str, message: String },
    #[error(transparent)]
    Journal(#[from] JournalError),
    #[error(transparent)]
    Standby(#[from] crate::standby::StandbyError),
    #[error("sensor journal {path}: cannot resume from it: {source}")]
    Restore { path: String, source: RestoreError },
    /// The journal's track numbers of a ROS 2 topic's named ids, which its
    /// decoder cannot take back.
    #[error("sensor journal: the track numbers of {producer}'s named ids: {problem}")]
    TrackIds { producer: String, problem: String },
    #[error(
        "sensor {0}: one sensor of several takes events from producers only \
         (P/sensor/<name>/ingest): its trace may hold the header alone, and it reads no \
         standard input"
    )]
    MeshSource(String),
    /// A bad line of standard input past `--max-errors`.
    #[error("{0}")]
    Input(String),
    #[error("leaders {missing:?} did not come up within {waited:?}")]
    LeadersMissing {
        missing: Vec<String>,
        waited: Duration,
    },
}

fn mesh(what: &'static str) -> impl FnOnce(zenoh::Error) -> GatewayError {
    move |e| GatewayError::Mesh {
        what,
        message: e.to_string(),
    }
}

/// How many of `lines` the stream sends, and how many events they hold:
/// `limit` counts events, as watermarks and `?events=N` do, not lines
/// (truth lines carry no event).
fn stream_length(lines: &[Line], limit: Option<u64>) -> (usize, u64) {
    let mut events = 0u64;
    for (i, line) in lines.iter().enumerate() {
        if line.is_event() {
            if limit.is_some_and(|limit| events == limit) {
                return (i, events);
            }
            events += 1;
        }
    }
    (lines.len(), events)
}

/// Unfollow requests waiting to be taken before the oldest are dropped.
const UNFOLLOWS_KEPT: usize = 4096;

/// Progress marks waiting to be taken before the oldest are dropped.
const PROGRESS_KEPT: usize = 1024;

/// A chunk of the trace (what is routed between two flushes, and between
/// two looks at queries) ends once it has routed this many seqs (items)
/// per leader, or the window's room if less ...
const CHUNK_SEQS: u64 = 512;

/// ... or after this many lines per leader. Counting seqs rather than
/// lines matters where regions are many: most of a crowd's lines are
/// moves, which are items only at a handover, and a chunk of 512 lines
/// sent every leader a batch (and got a progress mark back) for a few
/// handovers each.
const CHUNK_LINES: usize = 8192;

/// The bounds of a chunk for `leaders` leaders: (seqs, lines). Per leader,
/// because a chunk's items are shared out among the leaders: with bounds
/// that did not grow with them, each of L leaders got a batch of about
/// 1/L of them per chunk, so L leaders together took L times the batches
/// (and sent back L times the progress marks) of one leader for the same
/// stream. A stream paced to its times routes only what is due, so the
/// bounds matter only to one that is behind.
fn chunk_bounds(leaders: usize) -> (u64, usize) {
    let leaders = leaders.max(1);
    (CHUNK_SEQS * leaders as u64, CHUNK_LINES * leaders)
}

/// How often a stream the window holds looks again without a mark (marks
/// wake it at once; this only bounds a wait on a lost one).
const WINDOW_RECHECK: Duration = Duration::from_millis(50);

/// How often a stream the window holds asks [`Gateway::stalled`] for
/// batches a leader still waits for: longer than a leader's sweep, at
/// which it publishes its mark whether it moved or not.
const STALL_CHECK: Duration = Duration::from_millis(600);

type Queries = zenoh::query::Queryable<zenoh::handlers::FifoChannelHandler<Query>>;
type Samples =
    zenoh::pubsub::Subscriber<zenoh::handlers::FifoChannelHandler<zenoh::sample::Sample>>;
type LatestSamples = zenoh::pubsub::Subscriber<zenoh::handlers::RingChannelHandler<Sample>>;

/// What the sensor declares on the mesh: the queries it answers, the
/// leaders' requests and marks it hears, and its liveliness token.
struct Endpoints {
    cut_requests: Queries,
    follows: Queries,
    unfollows: LatestSamples,
    resends: Queries,
    durables: Samples,
    progress: LatestSamples,
    stats: Queries,
    positions: Queries,
    ingests: Queries,
    intakes: Queries,
    /// Held for as long as the sensor runs.
    _token: zenoh::liveliness::LivelinessToken,
}

impl Endpoints {
    /// Declares the endpoints of sensor `name`.
    async fn declare(session: &Session, keys: &Keys, name: &str) -> Result<Self, GatewayError> {
        let cut_requests = session
            .declare_queryable(keys.sensor_cut(name))
            .await
            .map_err(mesh("declare the cut queryable"))?;
        let follows = session
            .declare_queryable(keys.sensor_follow(name))
            .await
            .map_err(mesh("declare the follow queryable"))?;
        // A ring, not a queue: when requests come faster than the loop takes
        // them, the oldest are dropped (each only saves traffic) rather than
        // stalling Zenoh's receiving task, and with it every request to the
        // sensor.
        let unfollows = session
            .declare_subscriber(keys.sensor_unfollow(name))
            .with(zenoh::handlers::RingChannel::new(UNFOLLOWS_KEPT))
            .await
            .map_err(mesh("declare the unfollow subscriber"))?;
        let resends = session
            .declare_queryable(keys.sensor_resend(name))
            .await
            .map_err(mesh("declare the resend queryable"))?;
        let durables = session
            .declare_subscriber(keys.every_leader_durable())
            .await
            .map_err(mesh("declare the durable-mark subscriber"))?;
        // Only the latest mark of each leader matters: a ring, so a flood of
        // them never stalls Zenoh's receiving task.
        let progress = session
            .declare_subscriber(keys.every_leader_progress())
            .with(zenoh::handlers::RingChannel::new(PROGRESS_KEPT))
            .await
            .map_err(mesh("declare the progress-mark subscriber"))?;
        let stats = session
            .declare_queryable(keys.sensor_stats(name))
            .await
            .map_err(mesh("declare the stats queryable"))?;
        let positions = session
            .declare_queryable(keys.sensor_positions(name))
            .await
            .map_err(mesh("declare the positions queryable"))?;
        let ingests = session
            .declare_queryable(keys.sensor_ingest(name))
            .await
            .map_err(mesh("declare the ingest queryable"))?;
        let intakes = session
            .declare_queryable(keys.sensor_intake(name))
            .await
            .map_err(mesh("declare the intake queryable"))?;
        let _token = session
            .liveliness()
            .declare_token(keys.alive("sensor", name))
            .await
            .map_err(mesh("declare the liveliness token"))?;
        Ok(Endpoints {
            cut_requests,
            follows,
            unfollows,
            resends,
            durables,
            progress,
            stats,
            positions,
            ingests,
            intakes,
            _token,
        })
    }
}

/// One event publisher per leader, in the stream's order of leaders.
async fn declare_publishers(
    session: &Session,
    keys: &Keys,
    names: &[String],
) -> Result<Vec<Publisher<'static>>, GatewayError> {
    let mut publishers = Vec::with_capacity(names.len());
    for name in names {
        publishers.push(
            session
                .declare_publisher(keys.leader_events(name))
                .congestion_control(CongestionControl::Block)
                .await
                .map_err(mesh("declare an event publisher"))?,
        );
    }
    Ok(publishers)
}

/// The gateway for the stream as `config` describes it: `lines` from
/// the trace, ending (`ends`) after `end` events or not.
fn start_gateway(
    config: &GatewayConfig,
    router: Router,
    lines: &[Line],
    ends: bool,
    end: u64,
) -> Gateway<Query> {
    let mut gateway: Gateway<Query> =
        Gateway::new(&config.name, router, lines.is_empty() && ends).at_epoch(config.epoch);
    // How many events the reports make is known only once they are
    // extracted: a cut asked for beyond the end waits, and is refused
    // when the stream ends.
    if ends && config.extraction.is_none() {
        gateway = gateway.ending_at(end);
    }
    if let Some(extraction) = config.extraction.clone() {
        gateway = gateway.extracting(extraction);
    }
    if let Some(window) = config.window {
        gateway = gateway.windowed(window);
    }
    if let Some(mesh) = &config.mesh {
        gateway = gateway.meshed(mesh);
    }
    gateway
}

/// With a journal: the gateway as its records leave it (the trace's
/// `lines` it routed included), recording every change of state from now
/// on.
fn resume(
    mut gateway: Gateway<Query>,
    journal: Option<(Journal, Vec<Record>)>,
    lines: &[Line],
    name: &str,
) -> Result<(Gateway<Query>, Option<Journal>), GatewayError> {
    let Some((journal, records)) = journal else {
        return Ok((gateway, None));
    };
    let path = journal.path().to_path_buf();
    let restored = records.len();
    gateway
        .restore(records, lines)
        .map_err(|source| GatewayError::Restore {
            path: path.display().to_string(),
            source,
        })?;
    gateway.note_journal_repaired(journal.repaired());
    if restored > 0 {
        tracing::info!(sensor = %name, journal = %path.display(), records = restored,
            events = gateway.router().events(), seq = gateway.router().seq(),
            trace_lines = gateway.traced(), "resumed from the journal");
    }
    Ok((gateway.journaled(), Some(journal)))
}

/// Where the stream is in the trace's own lines, and how it is paced.
struct TraceCursor<'a> {
    lines: &'a [Line],
    /// The next line to route.
    next: usize,
    /// The stream ends when the lines are out.
    ends: bool,
    started: Instant,
    /// The time of the first timed line.
    first_time: f64,
    /// The window had room at the last look.
    open: bool,
}

impl TraceCursor<'_> {
    /// How many lines are due now, and when the next one is.
    fn due(&mut self, config: &GatewayConfig, gateway: &mut Gateway<Query>) -> (usize, Duration) {
        let (due, wait) = if gateway.finished() || self.next >= self.lines.len() {
            (0, Duration::from_secs(3600))
        } else {
            let chunk_lines = chunk_bounds(gateway.router().leaders()).1;
            let (due, wait) = due_lines(
                config,
                self.lines,
                self.next,
                self.started,
                self.first_time,
                chunk_lines,
            );
            // Held, the stream waits for progress marks.
            match gateway.room() {
                Some(0) if due > 0 => {
                    if self.open {
                        gateway.hold();
                    }
                    (0, wait.min(WINDOW_RECHECK))
                }
                _ => (due, wait),
            }
        };
        self.open = gateway.room() != Some(0);
        (due, wait)
    }

    /// Routes a chunk of at most `due` lines (as many as the window lets
    /// in), publishes it and answers the cuts it reached.
    async fn route(
        &mut self,
        due: usize,
        config: &GatewayConfig,
        gateway: &mut Gateway<Query>,
        wire: &mut Wire,
    ) -> Result<(), GatewayError> {
        let lines = self.lines;
        // A line takes at most a seq or two: the window holds to
        // within one line.
        let chunk_seqs = chunk_bounds(gateway.router().leaders()).0;
        let budget = gateway.room().unwrap_or(chunk_seqs).min(chunk_seqs);
        let end = gateway.router().seq() + budget;
        let mut placed = Vec::new();
        let mut taken = 0;
        for line in &lines[self.next..self.next + due] {
            placed.extend(gateway.line(line));
            taken += 1;
            if gateway.router().seq() >= end {
                break;
            }
        }
        let due = taken;
        self.next += due;
        let refused = if self.next >= lines.len() && self.ends {
            gateway.end()
        } else {
            Vec::new()
        };
        wire.flush(gateway)
            .instrument(tracing::debug_span!(
                "chunk",
                from = self.next - due,
                lines = due
            ))
            .await?;
        for p in placed {
            reply_placed(p).await;
        }
        if gateway.finished() {
            tracing::info!(sensor = %config.name, events = gateway.router().events(), seconds = self.started.elapsed().as_secs_f64(), "source exhausted");
            for (query, reason) in refused {
                let _ = bounded("a refusal", query.reply_err(reason)).await;
            }
        }
        // Let queries in between chunks.
        tokio::task::yield_now().await;
        Ok(())
    }
}

/// Streams `source` until done (a live one until `shutdown`), then serves
/// queries until `shutdown`. With a `journal` (opened, and so owned, before
/// the process joined the mesh: [`Journal::open`]) it first restores what
/// the records say, then records every change of state in it.
pub async fn run(
    session: Session,
    config: GatewayConfig,
    router: Router,
    source: Source,
    journal: Option<(Journal, Vec<Record>)>,
    shutdown: impl Future<Output = ()>,
) -> Result<(), GatewayError> {
    let keys = &config.keys;
    let endpoints = Endpoints::declare(&session, keys, &config.name).await?;
    let names = router.begin().leaders.clone();
    let publishers = declare_publishers(&session, keys, &names).await?;
    wait_for_leaders(&session, keys, &names, config.wait_for_leaders).await?;
    let Source { lines, input } = source;
    if config.mesh.is_some() && (input.is_some() || lines.iter().any(Line::is_event)) {
        return Err(GatewayError::MeshSource(config.name.clone()));
    }
    // The stream ends by itself when the trace's lines are out and there
    // is no input to wait for; a live one only when the sensor stops (and
    // one sensor of several when its producers say so).
    let ends = input.is_none() && !config.live && config.mesh.is_none();
    tracing::info!(sensor = %config.name, leaders = names.len(), events = lines.len(),
        stdin = input.is_some(), ends, "streaming");

    let (length, end) = stream_length(&lines, config.limit);
    let lines = &lines[..length];
    let budget = ErrorBudget::new(config.max_errors);
    let gateway = start_gateway(&config, router, lines, ends, end);
    let (mut gateway, journal) = resume(gateway, journal, lines, &config.name)?;
    // A resumed trace goes on after the last line it routed.
    let lines = &lines[(gateway.traced() as usize).min(lines.len())..];
    if ends && lines.is_empty() && !gateway.finished() {
        // It died after its last line, before saying the stream is over.
        gateway.end();
    }
    let replicator = match (config.standbys.is_empty(), &journal) {
        (false, Some(_)) => Some(
            Replicator::start(
                &session,
                keys,
                &config.name,
                &config.standbys,
                config.lease.clone(),
            )
            .await?,
        ),
        _ => None,
    };
    let mut wire = Wire {
        faults: config.faults,
        publishers,
        journal,
        replicator,
    };
    wire.flush(&mut gateway).await?;
    let peers = config
        .mesh
        .as_ref()
        .map(|_| Peers::start(&session, keys, gateway.wanted()));
    let trace = TraceCursor {
        lines,
        next: 0,
        ends,
        started: Instant::now(),
        first_time: lines.iter().find_map(line_time).unwrap_or(0.0),
        open: true,
    };
    let ros2 = match &config.ros2 {
        Some(ros2) => Some(Ros2Input::start(&session, ros2, gateway.named_tracks()).await?),
        None => None,
    };
    let sensor = Sensor {
        config: &config,
        gateway,
        wire,
        peers,
        trace,
        budget,
        held: Vec::new(),
        ros2,
    };
    serve(sensor, endpoints, input, shutdown).await
}

/// The sensor as it streams and serves: its gateway, what it publishes
/// and records with, its peers (one sensor of several), where it is in
/// its trace, and the intake requests it holds.
struct Sensor<'a> {
    config: &'a GatewayConfig,
    gateway: Gateway<Query>,
    wire: Wire,
    peers: Option<Peers>,
    trace: TraceCursor<'a>,
    /// What is left of `--max-errors` for standard input.
    budget: ErrorBudget,
    /// Peers' intake requests with nothing new to answer yet.
    held: Vec<HeldIntake>,
    /// ROS 2 topics read, if any.
    ros2: Option<Ros2Input>,
}

impl Sensor<'_> {
    /// [`settle`], for one sensor of several.
    async fn settle(&mut self) -> Result<(), GatewayError> {
        settle(
            &mut self.gateway,
            &mut self.wire,
            self.peers.as_ref(),
            &mut self.held,
        )
        .await
    }

    /// Standard input ended: so does a stream that is not live once the
    /// trace's own lines are out.
    async fn input_ended(&mut self) -> Result<(), GatewayError> {
        let gateway = &mut self.gateway;
        tracing::info!(sensor = %self.config.name, events = gateway.router().events(), "standard input ended");
        if self.trace.next >= self.trace.lines.len() && !self.config.live && !gateway.finished() {
            let refused = gateway.end();
            self.wire.flush(gateway).await?;
            for (query, reason) in refused {
                let _ = bounded("a refusal", query.reply_err(reason)).await;
            }
        }
        Ok(())
    }
}

/// Streams the trace's lines and standard input `input`, and serves what
/// comes on `endpoints`, until `shutdown`.
async fn serve(
    mut sensor: Sensor<'_>,
    endpoints: Endpoints,
    mut input: Option<tokio::sync::mpsc::Receiver<InputLine>>,
    shutdown: impl Future<Output = ()>,
) -> Result<(), GatewayError> {
    let (s, ep) = (&mut sensor, &endpoints);
    let mut stall_check = tokio::time::interval(STALL_CHECK);
    stall_check.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Delay);
    tokio::pin!(shutdown);
    loop {
        let (due, wait) = s.trace.due(s.config, &mut s.gateway);
        if due > 0 {
            s.trace
                .route(due, s.config, &mut s.gateway, &mut s.wire)
                .await?;
        }
        tokio::select! {
            biased;
            _ = &mut shutdown => break,
            query = ep.cut_requests.recv_async() => {
                let Ok(query) = query else { break };
                cut(&mut s.gateway, &mut s.wire, query, s.peers.as_ref()).await?;
                // Every cut already asked for is placed or scheduled
                // before the stream moves on: a client asking for many
                // points at once (`--at-events`) must not find the stream
                // past them because its questions were let in one per chunk.
                while let Ok(Some(query)) = ep.cut_requests.try_recv() {
                    cut(&mut s.gateway, &mut s.wire, query, s.peers.as_ref()).await?;
                }
                s.settle().await?;
            }
            fetched = next_fetched(&mut s.peers) => {
                let Some((peer, fetched)) = fetched else { continue };
                take_fetched(&mut s.gateway, s.peers.as_mut(), &peer, fetched);
                s.settle().await?;
            }
            query = ep.intakes.recv_async() => {
                let Ok(query) = query else { break };
                s.held.push(HeldIntake { request: payload(&query), query, until: Instant::now() + HOLD_INTAKE });
                s.settle().await?;
            }
            _ = tokio::time::sleep_until(next_release(&s.held)), if !s.held.is_empty() => {
                answer_intakes(&mut s.gateway, &mut s.wire, &mut s.held).await?;
            }
            query = ep.follows.recv_async() => {
                let Ok(query) = query else { break };
                follow(&mut s.gateway, &mut s.wire, &query).await?;
            }
            sample = ep.unfollows.recv_async() => {
                let Ok(sample) = sample else { break };
                take_unfollows(&mut s.gateway, sample, &ep.unfollows);
            }
            sample = ep.durables.recv_async() => {
                let Ok(sample) = sample else { break };
                s.gateway.durable(&sample.payload().to_bytes(), sample.key_expr().as_str());
            }
            _ = stall_check.tick(), if !s.trace.open => {
                let again = s.gateway.stalled();
                s.wire.again(again).await;
            }
            sample = ep.progress.recv_async() => {
                let Ok(sample) = sample else { break };
                take_progress(&mut s.gateway, sample, &ep.progress);
            }
            query = ep.resends.recv_async() => {
                let Ok(query) = query else { break };
                let answer = s.gateway.resend(&payload(&query));
                reply_to(&query, answer, "resend").await;
            }
            query = ep.stats.recv_async() => {
                let Ok(query) = query else { break };
                let standby = s.wire.replicator.as_ref().and_then(Replicator::current);
                answer_stats(&s.gateway, standby, &query).await;
            }
            query = ep.positions.recv_async() => {
                let Ok(query) = query else { break };
                answer_positions(&s.gateway, &query, &s.config.name).await;
            }
            query = ep.ingests.recv_async() => {
                let Ok(query) = query else { break };
                ingest(&mut s.gateway, &mut s.wire, query).await?;
                s.settle().await?;
            }
            message = next_ros2(&mut s.ros2) => take_ros2(s, message).await?,
            sample = standby_changed(&s.wire.replicator) => {
                let Some(sample) = sample else { continue };
                s.wire.standby_token(&sample, &mut s.gateway).await?;
            }
            read = next_input(&mut input), if input.is_some() && s.trace.open => {
                let Some(read) = read else {
                    input = None;
                    s.input_ended().await?;
                    continue;
                };
                take_stdin(&mut s.gateway, &mut s.wire, read, &mut input, &mut s.budget).await?;
            }
            _ = tokio::time::sleep(wait), if due == 0 || s.trace.next < s.trace.lines.len() => {}
        }
    }
    Ok(())
}

/// Unfollow requests: `first` and whatever else has come since. Dropping
/// tracks can only mean fewer items from now on: nothing to flush. A
/// refusal is counted and logged.
fn take_unfollows(gateway: &mut Gateway<Query>, first: Sample, unfollows: &LatestSamples) {
    let mut next = Some(first);
    while let Some(sample) = next {
        if let Ok(dropped) = gateway.unfollow(&sample.payload().to_bytes()) {
            tracing::trace!(dropped, "unfollowed");
        }
        next = unfollows.try_recv().ok().flatten();
    }
}

/// Progress marks: `first` and whatever else has come since.
fn take_progress(gateway: &mut Gateway<Query>, first: Sample, progress: &LatestSamples) {
    let mut next = Some(first);
    while let Some(sample) = next {
        gateway.progress(&sample.payload().to_bytes(), sample.key_expr().as_str());
        next = progress.try_recv().ok().flatten();
    }
}

/// A peer's intake slice fetched (or its refusal, or its silence), and
/// whether the peer answered: a merge waiting for peers that do not
/// answer refuses its waiting cuts, degraded.
fn take_fetched(
    gateway: &mut Gateway<Query>,
    peers: Option<&mut Peers>,
    peer: &str,
    fetched: Fetch,
) {
    let answered = !matches!(fetched, Fetch::Silent(_));
    match fetched {
        Fetch::Slice(bytes) => {
            if let Err(e) = gateway.peer(&bytes) {
                tracing::warn!(%peer, error = %e, "a peer's intake slice refused");
            }
        }
        Fetch::Refused(e) => tracing::warn!(%peer, error = %e, "a peer refused to give its intake"),
        Fetch::Silent(e) => tracing::debug!(%peer, error = %e, "a peer gave no intake"),
    }
    if let Some(peers) = peers {
        peers.answered(peer, answered);
        if let Some(reason) = degraded(gateway, peers) {
            gateway.refuse_waiting(&reason);
        }
    }
}

/// A leader's follow request: answered once the interests it grew are
/// on disk, then what they route is published.
async fn follow(
    gateway: &mut Gateway<Query>,
    wire: &mut Wire,
    query: &Query,
) -> Result<(), GatewayError> {
    let answer = gateway.follow(&payload(query));
    let followed = answer.is_ok();
    // The interests it grew are on disk before the leader
    // counts on them.
    wire.sync(gateway).await?;
    reply_to(query, answer, "follow").await;
    if followed {
        wire.flush(gateway).await?;
    }
    Ok(())
}

/// Answers a stats query with the sensor's counters, the epoch it holds
/// its role at and the standby its journal is replicated to.
async fn answer_stats(gateway: &Gateway<Query>, standby: Option<&str>, query: &Query) {
    let stats = SensorStatus {
        counters: gateway.stats().clone(),
        epoch: gateway.epoch(),
        standby: standby.map(str::to_string),
    };
    let body = serde_json::to_vec(&stats).unwrap_or_default();
    if let Some(Err(e)) = bounded(
        "stats",
        query
            .reply(query.key_expr().clone(), body)
            .encoding(zenoh::bytes::Encoding::APPLICATION_JSON),
    )
    .await
    {
        tracing::warn!(error = %e, "could not answer a stats query");
    }
}

/// Answers a positions query. Answered between chunks: the positions
/// after exactly `events` events, a point of the stream like a cut.
async fn answer_positions(gateway: &Gateway<Query>, query: &Query, name: &str) {
    let body = serde_json::to_vec(&gateway.router().positions(name, gateway.finished()))
        .unwrap_or_default();
    if let Some(Err(e)) = bounded(
        "positions",
        query
            .reply(query.key_expr().clone(), body)
            .encoding(zenoh::bytes::Encoding::APPLICATION_JSON),
    )
    .await
    {
        tracing::warn!(error = %e, "could not answer a positions query");
    }
}

/// Routes a line of standard input and what the pipe already holds
/// behind it (as much of it as the window lets in), in one batch.
async fn take_stdin(
    gateway: &mut Gateway<Query>,
    wire: &mut Wire,
    read: InputLine,
    input: &mut Option<tokio::sync::mpsc::Receiver<InputLine>>,
    budget: &mut ErrorBudget,
) -> Result<(), GatewayError> {
    let mut placed = Vec::new();
    take_input(gateway, read, &mut placed, budget)?;
    // What the pipe already holds goes in the same batch (as
    // much of it as the window lets in).
    let chunk_seqs = chunk_bounds(gateway.router().leaders()).0;
    let room = gateway.room().map_or(chunk_seqs, |r| r.min(chunk_seqs)) as usize;
    for _ in 1..room {
        let Some(rx) = input.as_mut() else { break };
        match rx.try_recv() {
            Ok(read) => take_input(gateway, read, &mut placed, budget)?,
            Err(_) => break,
        }
    }
    wire.flush(gateway).await?;
    for p in placed {
        reply_placed(p).await;
    }
    Ok(())
}

/// The next line of standard input; `None` at its end (or with none).
async fn next_input(
    input: &mut Option<tokio::sync::mpsc::Receiver<InputLine>>,
) -> Option<InputLine> {
    match input {
        Some(rx) => rx.recv().await,
        None => None,
    }
}

/// Routes one line of standard input, or says why not: a bad line is
/// skipped (the gateway counted it) while `budget` lasts, and stops the
/// sensor past it; an unreadable input is logged and read no further (the
/// channel closes behind it).
fn take_input(
    gateway: &mut Gateway<Query>,
    read: InputLine,
    placed: &mut Vec<Placed<Query>>,
    budget: &mut ErrorBudget,
) -> Result<(), GatewayError> {
    match read {
        Ok((number, text)) => match gateway.read(number, &text) {
            Ok(reached) => placed.extend(reached),
            Err(reason) => {
                let reason = budget
                    .spend(reason)
                    .map_err(|stop| GatewayError::Input(stop.to_string()))?;
                tracing::warn!(%reason, rejected = gateway.stats().rejected, "input line skipped")
            }
        },
        Err(reason) => tracing::error!(%reason, "standard input is read no further"),
    }
    Ok(())
}

/// An ingest request: its lines judged and the accepted ones routed and
/// published, then the acknowledgement (JSON) — or why the whole request
/// was refused.
async fn ingest(
    gateway: &mut Gateway<Query>,
    wire: &mut Wire,
    query: Query,
) -> Result<(), GatewayError> {
    let body = payload(&query);
    let parameters = query.parameters();
    let offer = Offer {
        producer: parameters.get(PRODUCER),
        counter: parameters.get(COUNTER),
        payload: &body,
        time: parameters.get(TIME),
        finish: parameters.contains_key(FINISH),
    };
    match gateway.ingest(offer) {
        Ok((ack, placed)) => {
            // Published before the acknowledgement leaves: a query asked
            // after it places its cut after these lines. (A request of
            // duplicates alone routed nothing: no batch for it.) One sensor
            // of several acknowledges its intake; `settle` publishes what
            // the merge lets go.
            let routed = !ack.accepted.is_empty() || !placed.is_empty();
            if routed && gateway.mesh().is_none() {
                wire.flush(gateway).await?;
            }
            // What it judged (counters used up) is on disk before it says so.
            wire.sync(gateway).await?;
            let body = serde_json::to_vec(&ack).unwrap_or_default();
            if let Some(Err(e)) = bounded(
                "an ingest acknowledgement",
                query
                    .reply(query.key_expr().clone(), body)
                    .encoding(zenoh::bytes::Encoding::APPLICATION_JSON),
            )
            .await
            {
                tracing::warn!(error = %e, "could not acknowledge an ingest request");
            }
            for p in placed {
                reply_placed(p).await;
            }
        }
        Err(refusal) => {
            tracing::warn!(error = %refusal, rejected = gateway.stats().rejected, "ingest request refused");
            let _ = bounded("a refusal", query.reply_err(refusal.to_string())).await;
        }
    }
    Ok(())
}

/// The next ROS 2 message; never, without ROS 2 topics.
async fn next_ros2(ros2: &mut Option<Ros2Input>) -> Option<Message> {
    match ros2 {
        Some(ros2) => ros2.next().await,
        None => std::future::pending().await,
    }
}

/// A ROS 2 message: counted, and its reports offered to ingestion as
/// its topic's lines, then routed and published like a producer's.
async fn take_ros2(s: &mut Sensor<'_>, message: Option<Message>) -> Result<(), GatewayError> {
    let (Some(input), Some(message)) = (s.ros2.as_mut(), message) else {
        s.ros2 = None;
        return Ok(());
    };
    let lines = input.lines(message);
    s.gateway.count_ros2(lines.is_err());
    // The numbers it gave named ids for the first time go into the
    // journal ahead of the offer whose lines carry them (one append).
    let named = input.newly_named();
    let newly_named = !named.is_empty();
    for Named {
        producer,
        first,
        ids,
    } in named
    {
        if let Err(problem) = s.gateway.name_tracks(&producer, first, ids) {
            // Each decoder numbers its own ids on from the last: never.
            tracing::error!(%producer, %problem, "track numbers of named ids not kept");
        }
    }
    let Ok(Some(lines)) = lines else {
        if newly_named {
            // Numbers no offer carries yet are on disk all the same, so
            // that a restart gives the next id the number it gets now.
            s.wire.sync(&mut s.gateway).await?;
        }
        return Ok(());
    };
    let counter = s.gateway.producer_next(&lines.producer).to_string();
    let offer = Offer {
        producer: Some(&lines.producer),
        counter: Some(&counter),
        payload: lines.text.as_bytes(),
        time: None,
        finish: false,
    };
    match s.gateway.ingest(offer) {
        Ok((ack, placed)) => {
            for refused in &ack.errors {
                tracing::warn!(producer = %lines.producer, reason = %refused.reason,
                    "a report of a ROS 2 message refused");
            }
            if !ack.accepted.is_empty() || !placed.is_empty() {
                s.wire.flush(&mut s.gateway).await?;
            }
            s.wire.sync(&mut s.gateway).await?;
            for p in placed {
                reply_placed(p).await;
            }
        }
        Err(refusal) => {
            tracing::warn!(producer = %lines.producer, error = %refusal, "ROS 2 reports refused")
        }
    }
    s.settle().await
}

/// Places, schedules or refuses the cut `query` asks for. One sensor of
/// several refuses at once a cut the merge cannot place because it waits
/// for a peer that does not answer: degraded, naming it, never an answer
/// without its events.
async fn cut(
    gateway: &mut Gateway<Query>,
    wire: &mut Wire,
    query: Query,
    peers: Option<&Peers>,
) -> Result<(), GatewayError> {
    if let Some(reason) = peers.and_then(|peers| degraded(gateway, peers)) {
        let _ = bounded("a refusal", query.reply_err(reason)).await;
        return Ok(());
    }
    let parameters = query.parameters();
    let parameters = CutParameters {
        tag: parameters.get("tag").map(str::to_owned),
        rows: parameters.contains_key("rows"),
        events: parameters.get("events").map(str::to_owned),
    };
    match gateway.cut(query, &parameters) {
        CutOutcome::Placed(p) => {
            wire.flush(gateway).await?;
            reply_placed(p).await;
        }
        CutOutcome::Scheduled => {}
        CutOutcome::Refused(query, reason) => {
            let _ = bounded("a refusal", query.reply_err(reason)).await;
        }
    }
    Ok(())
}

/// Why no cut can be placed now, if the merge waits for a peer that does
/// not answer: degraded, naming it.
fn degraded(gateway: &Gateway<Query>, peers: &Peers) -> Option<String> {
    let down: Vec<String> = gateway
        .waiting_for()
        .into_iter()
        .filter(|s| peers.unreachable().contains(s))
        .collect();
    (!down.is_empty()).then(|| {
        format!(
            "degraded: sensors {down:?} do not answer; the stream's order cannot pass their \
             events, so no cut is placed"
        )
    })
}

/// One sensor of several, after anything that may have moved its merge
/// or its intake: the batches it made, the cut answers and refusals it
/// made ready, the held intake requests it now has something for, then
/// what to fetch from each peer next.
async fn settle(
    gateway: &mut Gateway<Query>,
    wire: &mut Wire,
    peers: Option<&Peers>,
    held: &mut Vec<HeldIntake>,
) -> Result<(), GatewayError> {
    let Some(peers) = peers else {
        return Ok(());
    };
    wire.flush(gateway).await?;
    for placed in gateway.answered() {
        reply_placed(placed).await;
    }
    for (query, reason) in gateway.refused() {
        let _ = bounded("a refusal", query.reply_err(reason)).await;
    }
    if !held.is_empty() {
        answer_intakes(gateway, wire, held).await?;
    }
    peers.ask(gateway.wanted());
    Ok(())
}

/// How long a peer's intake request with nothing new for it is held
/// before it is answered anyway.
const HOLD_INTAKE: Duration = Duration::from_millis(100);

/// A peer's intake request (its bytes), held until there is something new
/// for it or until `until`.
struct HeldIntake {
    query: Query,
    request: Vec<u8>,
    until: Instant,
}

/// When the first held intake request is due.
fn next_release(held: &[HeldIntake]) -> tokio::time::Instant {
    let until = held
        .iter()
        .map(|h| h.until)
        .min()
        .unwrap_or_else(Instant::now);
    tokio::time::Instant::from_std(until)
}

/// Answers every held intake request that has something new for its peer
/// (or has waited long enough, or cannot be answered: an error reply);
/// keeps the rest.
async fn answer_intakes(
    gateway: &mut Gateway<Query>,
    wire: &mut Wire,
    held: &mut Vec<HeldIntake>,
) -> Result<(), GatewayError> {
    let now = Instant::now();
    let mut answers = Vec::new();
    let mut kept = Vec::with_capacity(held.len());
    for h in held.drain(..) {
        match gateway.intake(&h.request) {
            Ok((_, false)) if now < h.until => kept.push(h),
            Ok((slice, _)) => answers.push((h.query, Ok(slice))),
            Err(e) => answers.push((h.query, Err(e))),
        }
    }
    *held = kept;
    // A watermark a request moved is on disk before a peer merges by it.
    wire.sync(gateway).await?;
    for (query, answer) in answers {
        reply_to(&query, answer, "intake").await;
    }
    Ok(())
}

/// The next fetch of a peer's intake (never, for the only sensor).
async fn next_fetched(peers: &mut Option<Peers>) -> Option<crate::peers::Fetched> {
    match peers {
        Some(peers) => peers.reply().await,
        None => std::future::pending().await,
    }
}

/// The postcard request a get carries.
fn payload(query: &Query) -> Vec<u8> {
    query
        .payload()
        .map(|p| p.to_bytes().into_owned())
        .unwrap_or_default()
}

/// Answers a `what` request with its reply, or with why there is none
/// (the gateway counted it).
async fn reply_to<R: serde::Serialize>(
    query: &Query,
    answer: Result<R, String>,
    what: &'static str,
) {
    match answer {
        Ok(reply) => {
            tracing::debug!(what, "answered");
            if let Some(Err(e)) =
                bounded(what, query.reply(query.key_expr().clone(), encode(&reply))).await
            {
                tracing::warn!(what, error = %e, "could not answer a request");
            }
        }
        Err(e) => {
            let _ = bounded(what, query.reply_err(e)).await;
        }
    }
}

async fn reply_placed(placed: Placed<Query>) {
    let query = placed.query;
    if let Some(Err(e)) = bounded(
        "a cut",
        query.reply(query.key_expr().clone(), encode(&placed.answer)),
    )
    .await
    {
        tracing::warn!(error = %e, "could not answer a cut");
    }
}

/// How long one send may hold the loop. A peer cut off by a partition can
/// hold a send until Zenoh gives its link up (seconds); given up after
/// this, the message is lost to that peer — a leader notices the gap and
/// asks again, a client asks again — and the stream, the cuts and every
/// other peer go on.
const SEND_PATIENCE: Duration = Duration::from_secs(1);

/// `send`, unless it takes longer than [`SEND_PATIENCE`].
async fn bounded<T>(
    what: &'static str,
    send: impl std::future::IntoFuture<Output = T>,
) -> Option<T> {
    match tokio::time::timeout(SEND_PATIENCE, send.into_future()).await {
        Ok(sent) => Some(sent),
        Err(_) => {
            tracing::info!(what, patience = ?SEND_PATIENCE, "a send took too long: given up (it is asked for again)");
            None
        }
    }
}

/// Puts a snapshot of the gateway in its journal's place (every record
/// has just been appended, so the two agree).
fn compact(journal: &mut Journal, gateway: &Gateway<Query>) -> Result<(), GatewayError> {
    let (before, started) = (journal.bytes(), std::time::Instant::now());
    match gateway.compacted() {
        Ok(records) => {
            journal.compact(&records)?;
            tracing::info!(journal = %journal.path().display(), before, after = journal.bytes(),
                ms = started.elapsed().as_secs_f64() * 1e3, "sensor journal compacted");
        }
        // Not fatal: the journal stays whole, and grows.
        Err(e) => {
            tracing::error!(error = %e, "could not snapshot the sensor's state");
            journal.postpone();
        }
    }
    Ok(())
}

/// The next change of the standby's token (never, without a standby).
async fn standby_changed(replicator: &Option<Replicator>) -> Option<Sample> {
    match replicator {
        Some(replicator) => replicator.changed().await,
        None => std::future::pending().await,
    }
}

/// The event keys, the faults injected on them, the journal and its
/// replication to the standby.
struct Wire {
    faults: Faults,
    publishers: Vec<Publisher<'static>>,
    journal: Option<Journal>,
    replicator: Option<Replicator>,
}

impl Wire {
    /// Puts what changed the gateway's state on disk (fsynced), if it
    /// keeps a journal, and on the standby's disk, if it has one up.
    async fn sync(&mut self, gateway: &mut Gateway<Query>) -> Result<(), GatewayError> {
        let records = gateway.unjournaled();
        let Some(journal) = &mut self.journal else {
            return Ok(());
        };
        journal.append(&records)?;
        let compacted = journal.due();
        if compacted {
            compact(journal, gateway)?;
        }
        if let Some(replicator) = &mut self.replicator {
            if let Some(epoch) = replicator.replicate(&records, compacted, gateway).await? {
                gateway.advance_epoch(epoch);
            }
        }
        Ok(())
    }

    /// The standby's token changed: one that is back is sent the whole
    /// journal now, not at the next record.
    async fn standby_token(
        &mut self,
        sample: &Sample,
        gateway: &mut Gateway<Query>,
    ) -> Result<(), GatewayError> {
        let back = self
            .replicator
            .as_mut()
            .is_some_and(|replicator| replicator.token(sample));
        if back {
            self.sync(gateway).await?;
        }
        Ok(())
    }

    /// Sends the leaders their queued items ([`Gateway::flush`]) — once
    /// the journal holds them.
    async fn flush(&mut self, gateway: &mut Gateway<Query>) -> Result<(), GatewayError> {
        let mut batches = gateway.flush();
        self.sync(gateway).await?;
        gateway.restamp(&mut batches);
        for (i, batch) in batches {
            let Some(publisher) = self.publishers.get(i) else {
                continue;
            };
            let number = batch.number;
            let dropped = self
                .faults
                .drop_every
                .is_some_and(|n| n > 0 && number % n == n - 1);
            if dropped {
                tracing::debug!(leader = i, number, "fault: batch not published");
                continue;
            }
            let body = encode(&batch);
            for _ in 0..if self.faults.duplicate { 2 } else { 1 } {
                if let Some(Err(e)) = bounded("a batch", publisher.put(body.clone())).await {
                    tracing::error!(error = %e, "could not publish a batch");
                }
            }
        }
        Ok(())
    }

    /// Publishes batches again (a stream the window holds, for a leader
    /// that still waits for them).
    async fn again(&mut self, batches: Vec<(usize, Batch)>) {
        for (i, batch) in batches {
            let Some(publisher) = self.publishers.get(i) else {
                continue;
            };
            tracing::debug!(
                leader = i,
                number = batch.number,
                "window held: batch published again"
            );
            if let Some(Err(e)) = bounded("a batch", publisher.put(encode(&batch))).await {
                tracing::error!(error = %e, "could not publish a batch again");
            }
        }
    }
}

fn line_time(line: &Line) -> Option<f64> {
    match line {
        Line::Mix(m) => Some(m.time),
        Line::Observe(o) => Some(o.time),
        Line::Move(m) => Some(m.time),
        Line::Identify(i) => Some(i.time),
        Line::Truth(t) => Some(t.time),
        Line::Detect(d) => Some(d.time),
        Line::Header(_) => None,
    }
}

fn due_lines(
    config: &GatewayConfig,
    lines: &[Line],
    next: usize,
    started: Instant,
    first_time: f64,
    chunk: usize,
) -> (usize, Duration) {
    let elapsed = started.elapsed().as_secs_f64();
    let rest = lines.len() - next;
    if config.realtime {
        let speed = config.rate.unwrap_or(1.0);
        let mut due = 0;
        while due < rest.min(chunk) {
            let t = line_time(&lines[next + due]).unwrap_or(first_time) - first_time;
            if t / speed > elapsed {
                let wait = (t / speed - elapsed).max(0.0);
                return (due, Duration::from_secs_f64(wait.min(0.05)));
            }
            due += 1;
        }
        return (due, Duration::ZERO);
    }
    match config.rate {
        None => (rest.min(chunk), Duration::ZERO),
        Some(rate) => {
            let allowed = (elapsed * rate) as usize;
            let due = allowed.saturating_sub(next).min(rest).min(chunk);
            (due, Duration::from_millis(if due == 0 { 2 } else { 0 }))
        }
    }
}

async fn wait_for_leaders(
    session: &Session,
    keys: &Keys,
    names: &[String],
    patience: Duration,
) -> Result<(), GatewayError> {
    let started = Instant::now();
    loop {
        let mut up = Vec::new();
        if let Ok(replies) = session
            .liveliness()
            .get(keys.alive_role("leader"))
            .timeout(Duration::from_secs(1))
            .await
        {
            while let Ok(reply) = replies.recv_async().await {
                if let Ok(sample) = reply.result() {
                    if let Some(name) = Keys::chunk(sample.key_expr().as_str(), 0) {
                        up.push(name.to_string());
                    }
                }
            }
        }
        let missing: Vec<String> = names.iter().filter(|n| !up.contains(n)).cloned().collect();
        if missing.is_empty() {
            return Ok(());
        }
        if started.elapsed() > patience {
            return Err(GatewayError::LeadersMissing {
                missing,
                waited: patience,
            });
        }
        tokio::time::sleep(Duration::from_millis(100)).await;
    }
}

#[cfg(test)]
mod tests {
    use super::stream_length;
    use idmesh_protocol::trace::{Line, Mix, Truth};

    fn mix() -> Line {
        Line::Mix(Mix {
            time: 0.0,
            a: 0,
            b: 1,
            swap: 0.5,
        })
    }

    fn truth() -> Line {
        Line::Truth(Truth {
            time: 0.0,
            red: Some(vec![0]),
            identity: None,
        })
    }

    #[test]
    fn an_event_limit_counts_events_not_truth_lines() {
        let lines = [mix(), truth(), mix(), truth(), mix(), mix()];
        assert_eq!(stream_length(&lines, Some(3)), (5, 3));
        assert_eq!(stream_length(&lines, Some(4)), (6, 4));
        assert_eq!(stream_length(&lines, Some(9)), (6, 4));
        assert_eq!(stream_length(&lines, None), (6, 4));
        assert_eq!(stream_length(&lines, Some(0)), (0, 0));
    }
}
