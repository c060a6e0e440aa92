//! One schedule: the sensor gateway, L leaders and the coordinator's
//! gathering, in one thread, exchanging messages through a [`Network`]
//! that loses, doubles, delays (hence reorders) and cuts them off, while
//! leaders crash and come back from their journal and snapshot. Every
//! process runs its real pure state machine ([`Gateway`], [`Node`],
//! [`crate::sim`]'s use of `idmesh_coordinator::machine`); what the
//! actors do with Zenoh — puts, gets with a timeout, subscriptions — is
//! done here with virtual time.

use super::network::{Endpoint, Network};
use super::scenario::{exact_marginals, Scenario};
use super::Violation;
use idmesh_coordinator::machine::{
    at_rest_of, check, marginals_of, read_cut, GatherError, Memory, Partials,
};
use idmesh_identity::factored::assemble;
use idmesh_identity::{IdentityFilter, InformationOptions, InformationRows};
use idmesh_leader::journal::Kind;
use idmesh_leader::{Ask, Input, Node, Output, Timers};
use idmesh_placement::{from_wire_tree, identity_options};
use idmesh_protocol::wire::coordinator_to_leader::Partial;
use idmesh_protocol::wire::coordinator_to_sensor::CutPlaced;
use idmesh_protocol::wire::identity::WireTree;
use idmesh_protocol::wire::leader_to_leader::TransfersSent;
use idmesh_protocol::wire::leader_to_sensor::{Followed, Resent};
use idmesh_protocol::wire::query::MarginalsAnswer;
use idmesh_protocol::wire::sensor_to_leader::Batch;
use idmesh_protocol::wire::{decode, encode};
use idmesh_sensor::journal::Record;
use idmesh_sensor::{CutOutcome, CutParameters, Gateway, Offer, Placed, Router};
use rand::Rng;
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use std::collections::{BTreeMap, BTreeSet, HashMap};
use std::time::Duration;

/// Virtual milliseconds.
pub(crate) type Ms = u64;

/// How long a get waits for its answer (the leaders' `follow_timeout`).
const ASK_TIMEOUT: Ms = 1000;
/// How long the coordinator waits for the leaders and the sensor.
const QUERY_TIMEOUT: Ms = 1500;
/// After the stream and its faults are over, how long the deployment has
/// to give the final answer.
const FINAL_PATIENCE: Ms = 60_000;

/// The actor's interval between looks for stalled leaders (ms).
const STALL_CHECK: Ms = 600;

/// A message on the wire, by receiver.
#[derive(Debug, Clone)]
pub(crate) enum Msg {
    /// An input of leader `to`'s node; `ask` is set on the answer to one
    /// of its own gets.
    Leader {
        to: usize,
        what: ToLeader,
    },
    Sensor {
        from: usize,
        what: ToSensor,
    },
    Coordinator(ToCoordinator),
}

#[derive(Debug, Clone)]
pub(crate) enum ToLeader {
    Batch(Vec<u8>),
    Transfer(Vec<u8>),
    Durable(Vec<u8>),
    Partial {
        id: u64,
        ask: Ask,
        base: Option<u64>,
    },
    SentWanted {
        ask: u64,
        bytes: Vec<u8>,
    },
    /// The answer to the leader's get `ask`.
    Reply {
        ask: u64,
        reply: Result<Vec<u8>, String>,
    },
}

#[derive(Debug, Clone)]
pub(crate) enum ToSensor {
    Follow {
        ask: u64,
        bytes: Vec<u8>,
    },
    Resend {
        ask: u64,
        bytes: Vec<u8>,
    },
    Durable(Vec<u8>),
    /// How far a leader has got (flow control).
    Progress(Vec<u8>),
    /// A leader stops following tracks (fire and forget).
    Unfollow(Vec<u8>),
    /// The coordinator asks for a cut (from = usize::MAX).
    Cut {
        id: u64,
        parameters: CutParameters,
    },
}

#[derive(Debug, Clone)]
pub(crate) enum ToCoordinator {
    Cut {
        id: u64,
        reply: Result<Vec<u8>, String>,
    },
    Partial {
        id: u64,
        leader: usize,
        reply: Result<Vec<u8>, String>,
    },
}

/// What happens at a point of virtual time.
#[derive(Debug, Clone)]
pub enum Event {
    Deliver(Msg),
    Tick {
        leader: usize,
        life: u64,
    },
    AskTimeout(u64),
    SensorStep,
    QueryStart,
    QueryTimeout(u64),
    Crash(usize),
    Restart(usize),
    /// The sensor is killed and started again from its journal.
    SensorCrash,
    Isolate(usize),
    Heal(usize),
    /// The faults stop and the final query starts.
    Calm,
}

/// A get a leader made, waiting for its answer.
struct PendingAsk {
    leader: usize,
    life: u64,
    kind: AskKind,
}

enum AskKind {
    Follow,
    Resend,
    Transfers(String),
}

/// A leader's durable state, in memory: what survives a crash.
#[derive(Default)]
struct Disk {
    snapshot: Option<Vec<u8>>,
    entries: Vec<(Kind, Vec<u8>)>,
    /// Entries fsynced (a power cut loses the rest).
    synced: usize,
}

struct LeaderSlot {
    name: String,
    node: Option<Node>,
    /// Incarnation: answers to the gets of an earlier life are dropped.
    life: u64,
    disk: Disk,
    /// The last durable mark it published (position).
    published: u64,
    snapshot_every: usize,
    /// Its journal was found damaged at the crash: the restart drops this
    /// many entries (the damaged one and every one after it).
    damaged: Option<u64>,
}

/// A query of the coordinator, in one of its two phases.
struct Query {
    /// Answers completed before it started had at most this watermark.
    floor: u64,
    last: Option<CutPlaced>,
    phase: Phase,
    /// Ids of the current phase (messages of an earlier phase are stale).
    id: u64,
    replied: BTreeSet<usize>,
    partials: Partials,
    cut: Option<Result<CutPlaced, GatherError>>,
    final_query: bool,
}

#[derive(PartialEq, Eq)]
enum Phase {
    Rest,
    Fresh,
}

/// Faults aimed at one kind of message, on top of a seed's random ones
/// (each must heal without a restart).
#[derive(Debug, Clone, Default)]
pub struct Aimed {
    /// The first copy of every transfer between leaders is lost, on a
    /// live link (no partition, no crash): as when a TLS link closes and
    /// reopens under it. Only asking the sender again gets it through.
    pub lose_transfers: bool,
    /// The sensor refuses every resend request (an error reply) until
    /// this virtual time, then answers them again.
    pub refuse_resends_until: Ms,
    /// One leader is cut off from everyone for this long (ms) from a
    /// random point mid-stream, much longer than a get's timeout: its
    /// requests fail for seconds, and must go on being made until the
    /// partition heals.
    pub long_partition: Ms,
}

/// What a schedule did (for the report and the failure message).
#[derive(Debug, Default, Clone)]
pub struct Tally {
    pub answered: u64,
    pub failed_queries: u64,
    pub crashes: u64,
    /// Of those, the crashes whose journal was found damaged at the
    /// restart (cut before a random entry).
    pub journal_damages: u64,
    /// Sensor kills, each restarted from its journal.
    pub sensor_crashes: u64,
    /// Of those, the kills whose journal was compacted first (to the
    /// stream and a snapshot; a later kill's journal then holds that
    /// snapshot and the records after it).
    pub sensor_compactions: u64,
    pub messages: u64,
    pub dropped: u64,
    /// Summed over the leaders at the end: transfers received, follow
    /// and unfollow requests made, handovers applied.
    pub transfers: u64,
    pub follows: u64,
    pub unfollows: u64,
    pub handovers: u64,
    /// Mixes that took a track of another leader.
    pub tracks_taken: u64,
    /// Times the sensor found its flow-control window full.
    pub window_waits: u64,
    /// Schedules whose leaders held the factored belief.
    pub factored: u64,
    /// Schedules with identities (factored), and identity answers checked.
    pub identities: u64,
    pub identity_answers: u64,
    /// Of them, answers made of the leaders' trees of the factored
    /// identity belief (a known start).
    pub tree_answers: u64,
    /// Valid identity events the leaders' trees could not take as they
    /// stood, taken by the repair rule (summed over the leaders at the
    /// end, journal replays counted again).
    pub identity_repairs: u64,
    /// Factored leaders' replies told as a change to an answer the
    /// coordinator keeps (`Partial::base`).
    pub changes: u64,
}

pub(crate) struct World {
    rng: ChaCha8Rng,
    now: Ms,
    net: Network,
    scenario: Scenario,
    gateway: Gateway<u64>,
    /// The gateway's journal: every record it made (each is on disk
    /// before what depends on it leaves, and the sensor dies only between
    /// two events).
    journal: Vec<Record>,
    next_line: usize,
    /// In half the schedules the lines reach the sensor from a producer
    /// on the ingest key rather than from a trace: its own seeded choices
    /// (a reply lost and history resent, a counter ahead of itself, a
    /// second producer's junk), so the network's schedule is the same
    /// either way.
    producer: Option<ChaCha8Rng>,
    leaders: Vec<LeaderSlot>,
    asks: HashMap<u64, PendingAsk>,
    next_id: u64,
    memory: Memory,
    queries: BTreeMap<u64, Query>,
    /// The highest watermark of an answer given so far.
    answered_events: u64,
    /// The items routed to each leader (batches and follow replies).
    routed: Vec<BTreeSet<u64>>,
    final_answer: Option<MarginalsAnswer>,
    calm: bool,
    pub tally: Tally,
    last_error: String,
    aimed: Aimed,
    /// Transfers lost once already (by sender, receiver and seq).
    lost_once: BTreeSet<(usize, usize, u64)>,
    /// When the held sensor last looked for stalled leaders.
    stall_checked: Ms,
    /// Draws whether and where a crashed leader's journal is damaged (its
    /// own stream: the schedule's other draws stay as they were).
    damage: ChaCha8Rng,
}

impl World {
    /// A world for one seed's schedule, with the `aimed` faults added
    /// (none: [`Aimed::default`]).
    pub(crate) fn aimed(mut rng: ChaCha8Rng, aimed: Aimed) -> Result<World, Violation> {
        let scenario = Scenario::random(&mut rng).map_err(Violation::setup)?;
        let scenario_factored = scenario.factored.is_some();
        let scenario_identities = scenario.identity.is_some();
        let router = Router::new(scenario.router(), &scenario.header)
            .map_err(|e| Violation::setup(e.to_string()))?;
        let gateway = scenario.gateway(router);
        let net = Network::random(&mut rng, scenario.leaders.len());
        let leaders = scenario
            .leaders
            .iter()
            .map(|l| LeaderSlot {
                name: l.name.clone(),
                node: None,
                life: 0,
                disk: Disk::default(),
                published: 0,
                snapshot_every: 0,
                damaged: None,
            })
            .collect::<Vec<_>>();
        let count = leaders.len();
        let mut world = World {
            rng,
            now: 0,
            net,
            scenario,
            gateway,
            journal: Vec::new(),
            next_line: 0,
            producer: None,
            leaders,
            asks: HashMap::new(),
            next_id: 0,
            memory: Memory::default(),
            queries: BTreeMap::new(),
            answered_events: 0,
            routed: vec![BTreeSet::new(); count],
            final_answer: None,
            calm: false,
            tally: Tally {
                factored: scenario_factored as u64,
                identities: scenario_identities as u64,
                ..Tally::default()
            },
            last_error: String::new(),
            aimed,
            lost_once: BTreeSet::new(),
            stall_checked: 0,
            damage: ChaCha8Rng::seed_from_u64(0),
        };
        // Drawn from a copy: the schedule's own draws stay as they were.
        let mut side = world.rng.clone();
        if side.gen_bool(0.5) {
            world.producer = Some(ChaCha8Rng::seed_from_u64(side.gen()));
        }
        world.damage = ChaCha8Rng::seed_from_u64(side.gen::<u64>() ^ 0xda3a_9ed0);
        // In a third of the schedules the sensor is killed once mid-stream.
        if side.gen_bool(1.0 / 3.0) {
            let lines = world.scenario.lines.len() as Ms;
            world
                .net
                .at(side.gen_range(1..=40 * lines + 1), Event::SensorCrash);
        }
        for i in 0..count {
            world.leaders[i].snapshot_every = world.rng.gen_range(3..=30);
            world.start_leader(i)?;
        }
        world.flush();
        world.net.at(1, Event::SensorStep);
        // Queries at random points of the stream, and the faults.
        let span = 40 * world.scenario.lines.len() as Ms + 200;
        for _ in 0..world.rng.gen_range(0..=4) {
            let at = world.rng.gen_range(0..span);
            world.net.at(at, Event::QueryStart);
        }
        world.net.schedule_faults(&mut world.rng, span, count);
        let mut calm = span + 100;
        if world.aimed.long_partition > 0 {
            let (at, leader) = (world.rng.gen_range(0..span), world.rng.gen_range(0..count));
            world.net.at(at, Event::Isolate(leader));
            let heal = at + world.aimed.long_partition;
            world.net.at(heal, Event::Heal(leader));
            // The partition heals before the faults stop: healing is the
            // deployment's job, not the calm's.
            calm = calm.max(heal + 100);
        }
        world.net.at(calm, Event::Calm);
        Ok(world)
    }

    /// Runs the schedule to its end: the final answer, checked.
    pub fn run(&mut self) -> Result<(), Violation> {
        while let Some((at, event)) = self.net.next() {
            self.now = at;
            if self.calm && self.now > self.calm_deadline() {
                break;
            }
            self.handle(event)?;
            if self.final_answer.is_some() {
                return self.check_end();
            }
        }
        Err(Violation::new(format!(
            "no final answer within {FINAL_PATIENCE} ms of the faults ending (t = {} ms); last error: {}; {}",
            self.now,
            self.last_error,
            self.where_everyone_is()
        )))
    }

    /// Where the sensor and every leader stand: what a stuck schedule's
    /// failure says.
    fn where_everyone_is(&self) -> String {
        let mut text = format!(
            "the sensor at seq {} (room {:?}, finished {}, line {} of {})",
            self.gateway.router().seq(),
            self.gateway.room(),
            self.gateway.finished(),
            self.next_line,
            self.scenario.lines.len()
        );
        for (i, slot) in self.leaders.iter().enumerate() {
            match &slot.node {
                Some(node) => {
                    let l = node.leader();
                    text.push_str(&format!(
                        "; leader {i} at {} (done through {}, next batch {}, missing {:?}, transfer {:?}, components {:?}, follow {})",
                        l.position(),
                        l.done_through(),
                        l.next_batch(),
                        l.missing_batches(),
                        l.waiting_for_transfer(),
                        l.waiting_for_components(),
                        l.pending_follow().is_some()
                    ))
                }
                None => text.push_str(&format!("; leader {i} down")),
            }
        }
        text
    }

    fn calm_deadline(&self) -> Ms {
        40 * self.scenario.lines.len() as Ms + 300 + self.aimed.long_partition + FINAL_PATIENCE
    }

    fn fresh_id(&mut self) -> u64 {
        self.next_id += 1;
        self.next_id
    }

    fn handle(&mut self, event: Event) -> Result<(), Violation> {
        match event {
            Event::Deliver(msg) => self.deliver(msg),
            Event::Tick { leader, life } => {
                if self.leaders[leader].life == life && self.leaders[leader].node.is_some() {
                    self.step(leader, Input::Tick)?;
                    let sweep = 250;
                    self.net.at(self.now + sweep, Event::Tick { leader, life });
                }
                Ok(())
            }
            Event::AskTimeout(ask) => {
                if let Some(pending) = self.asks.remove(&ask) {
                    self.answer_ask(pending, Err("no answer in time".into()))?;
                }
                Ok(())
            }
            Event::SensorStep => self.sensor_step(),
            Event::QueryStart => {
                self.start_query(false);
                Ok(())
            }
            Event::QueryTimeout(id) => self.complete_query(id),
            Event::Crash(i) => {
                if !self.calm {
                    self.crash(i)?;
                }
                Ok(())
            }
            Event::SensorCrash => {
                if !self.calm {
                    self.sensor_crash()?;
                }
                Ok(())
            }
            Event::Restart(i) => {
                if self.leaders[i].node.is_none() {
                    self.start_leader(i)?;
                }
                Ok(())
            }
            Event::Isolate(i) => {
                if !self.calm {
                    self.net.isolate(Endpoint::Leader(i));
                }
                Ok(())
            }
            Event::Heal(i) => {
                self.net.heal(Endpoint::Leader(i));
                Ok(())
            }
            Event::Calm => {
                self.calm = true;
                self.net.calm();
                for i in 0..self.leaders.len() {
                    if self.leaders[i].node.is_none() {
                        self.start_leader(i)?;
                    }
                }
                // Under flow control the stream may still be going (the
                // window held it while faults lost marks and batches):
                // the final question waits for its end, which must come
                // before the patience runs out.
                if !self.gateway.finished() {
                    self.net.at(self.now + 250, Event::Calm);
                    return Ok(());
                }
                self.start_query(true);
                Ok(())
            }
        }
    }

    // --- the sensor -----------------------------------------------------

    /// Reads the next few lines, as the gateway's actor does by chunks.
    fn sensor_step(&mut self) -> Result<(), Violation> {
        let lines = self.scenario.lines.len();
        let mut chunk = self.rng.gen_range(1..=4usize);
        // Flow control: held, the sensor looks again later, as the actor
        // does when no progress mark wakes it.
        if let Some(room) = self.gateway.room() {
            if room == 0 && self.next_line < lines {
                self.tally.window_waits += 1;
                // As the actor's stall check: batches a leader still
                // waits for, again, at an interval longer than a sweep.
                if self.now >= self.stall_checked + STALL_CHECK {
                    self.stall_checked = self.now;
                    for (i, batch) in self.gateway.stalled() {
                        self.send_batch(i, &batch);
                    }
                }
                let wait = self.rng.gen_range(1..=40);
                self.net.at(self.now + wait, Event::SensorStep);
                return Ok(());
            }
            chunk = chunk.min(room as usize);
        }
        let mut placed = Vec::new();
        let end = (self.next_line + chunk).min(lines);
        if self.producer.is_some() {
            placed = self.ingest(self.next_line, end)?;
        } else {
            for line in &self.scenario.lines[self.next_line..end] {
                placed.extend(self.gateway.line(line));
            }
        }
        self.next_line = end;
        let refused = if self.next_line >= lines && !self.gateway.finished() {
            self.gateway.end()
        } else {
            Vec::new()
        };
        self.flush();
        for p in placed {
            self.reply_cut(p.query, Ok(encode(&p.answer)));
        }
        for (id, why) in refused {
            self.reply_cut(id, Err(why));
        }
        if self.next_line < lines {
            let wait = self.rng.gen_range(1..=40);
            self.net.at(self.now + wait, Event::SensorStep);
        }
        Ok(())
    }

    /// Lines `from..to` sent by the producer (its counters are the line
    /// numbers), as a producer whose replies are lost now and then does:
    /// each mistake must be refused or deduplicated and route nothing;
    /// the request itself must be taken whole.
    fn ingest(&mut self, from: usize, to: usize) -> Result<Vec<Placed<u64>>, Violation> {
        let Some(mut producer) = self.producer.take() else {
            return Ok(Vec::new());
        };
        let text = |lines: &[idmesh_protocol::trace::Line]| {
            lines
                .iter()
                .map(|l| serde_json::to_string(l).unwrap_or_default())
                .collect::<Vec<_>>()
                .join("\n")
        };
        let lines = &self.scenario.lines;
        let events = self.gateway.router().events();
        let mut placed = Vec::new();
        let offer = |gateway: &mut Gateway<u64>, who: &str, counter: usize, payload: &str| {
            let counter = counter.to_string();
            gateway
                .ingest(Offer {
                    producer: Some(who),
                    counter: Some(&counter),
                    payload: payload.as_bytes(),
                    time: None,
                    finish: false,
                })
                .map_err(|e| Violation::new(format!("ingest from {who} refused: {e}")))
        };
        if producer.gen_bool(0.2) {
            let ahead = from + producer.gen_range(1..=3);
            let (ack, reached) = offer(&mut self.gateway, "sim", ahead, &text(&lines[from..to]))?;
            if !ack.accepted.is_empty() || !reached.is_empty() || ack.next != from as u64 {
                return Err(Violation::new(format!(
                    "counter {ahead} ahead of {from} was taken: {ack:?}"
                )));
            }
        }
        if producer.gen_bool(0.1) {
            let (ack, _) = offer(
                &mut self.gateway,
                &format!("junk-{from}"),
                0,
                "{\"kind\":\"mix\"",
            )?;
            if !ack.accepted.is_empty() || ack.errors.len() != 1 {
                return Err(Violation::new(format!(
                    "a malformed line was taken: {ack:?}"
                )));
            }
        }
        let (ack, reached) = offer(&mut self.gateway, "sim", from, &text(&lines[from..to]))?;
        let wanted: Vec<u64> = (from as u64..to as u64).collect();
        if ack.accepted != wanted || ack.events != events + wanted.len() as u64 {
            return Err(Violation::new(format!(
                "lines {from}..{to} not taken whole: {ack:?}"
            )));
        }
        placed.extend(reached);
        if producer.gen_bool(0.3) {
            // The reply was lost: the producer sends again, with history.
            let back = producer.gen_range(0..=from);
            let (ack, reached) = offer(&mut self.gateway, "sim", back, &text(&lines[back..to]))?;
            if !ack.accepted.is_empty() || !reached.is_empty() || ack.duplicates.len() != to - back
            {
                return Err(Violation::new(format!(
                    "lines {back}..{to} sent again were taken again: {ack:?}"
                )));
            }
        }
        self.producer = Some(producer);
        Ok(placed)
    }

    /// The leaders' next batches, on their way.
    fn flush(&mut self) {
        for (i, batch) in self.gateway.flush() {
            self.note_routed(i, &batch);
            self.send_batch(i, &batch);
        }
    }

    /// The sensor puts `batch` on leader `i`'s event key.
    fn send_batch(&mut self, i: usize, batch: &Batch) {
        self.send(
            Endpoint::Sensor,
            Endpoint::Leader(i),
            Msg::Leader {
                to: i,
                what: ToLeader::Batch(encode(batch)),
            },
        );
    }

    fn note_routed(&mut self, i: usize, batch: &Batch) {
        self.routed[i].extend(batch.items.iter().map(|s| s.seq));
    }

    fn reply_cut(&mut self, id: u64, reply: Result<Vec<u8>, String>) {
        self.send(
            Endpoint::Sensor,
            Endpoint::Coordinator,
            Msg::Coordinator(ToCoordinator::Cut { id, reply }),
        );
    }

    fn at_sensor(&mut self, from: usize, what: ToSensor) -> Result<(), Violation> {
        match what {
            ToSensor::Follow { ask, bytes } => {
                let answer = self.gateway.follow(&bytes);
                // Its items count as routed once the leader takes the
                // reply ([`World::answer_ask`]): one lost on the way, or a
                // duplicate request's, never reaches it.
                if answer.is_ok() {
                    self.flush();
                }
                self.reply_leader(from, ask, answer.map(|f| encode(&f)));
            }
            ToSensor::Resend { ask, bytes } => {
                let answer = if self.now < self.aimed.refuse_resends_until {
                    Err("resend refused (the simulator's aimed fault)".to_string())
                } else {
                    self.gateway.resend(&bytes).map(|r| encode(&r))
                };
                self.reply_leader(from, ask, answer);
            }
            ToSensor::Durable(bytes) => self.gateway.durable(&bytes, "sim"),
            ToSensor::Progress(bytes) => self.gateway.progress(&bytes, "sim"),
            // A leader's own request is well formed: a refusal is a bug.
            ToSensor::Unfollow(bytes) => {
                self.gateway.unfollow(&bytes).map_err(|e| {
                    Violation::new(format!("the sensor refused leader {from}'s unfollow: {e}"))
                })?;
            }
            ToSensor::Cut { id, parameters } => match self.gateway.cut(id, &parameters) {
                CutOutcome::Placed(p) => {
                    self.flush();
                    self.reply_cut(id, Ok(encode(&p.answer)));
                }
                CutOutcome::Scheduled => {}
                CutOutcome::Refused(id, why) => self.reply_cut(id, Err(why)),
            },
        }
        Ok(())
    }

    fn reply_leader(&mut self, to: usize, ask: u64, reply: Result<Vec<u8>, String>) {
        self.send(
            Endpoint::Sensor,
            Endpoint::Leader(to),
            Msg::Leader {
                to,
                what: ToLeader::Reply { ask, reply },
            },
        );
    }

    // --- the leaders ----------------------------------------------------

    fn timers(&self, i: usize) -> Timers {
        let mut timers = Timers::new(
            Duration::from_millis(ASK_TIMEOUT),
            true,
            Some(self.leaders[i].snapshot_every),
        );
        timers.sweep = Duration::from_millis(250);
        timers.flow_control = self.scenario.window.is_some();
        timers
    }

    /// Starts leader `i` (again): from its disk, as `Node::recover` does
    /// for the actor.
    fn start_leader(&mut self, i: usize) -> Result<(), Violation> {
        let timers = self.timers(i);
        let slot = &mut self.leaders[i];
        slot.life += 1;
        let damaged = slot.damaged.take();
        let disk = &slot.disk;
        let (node, out) = Node::recover(
            &slot.name,
            &slot.name,
            disk.snapshot.as_deref(),
            disk.entries.iter().map(|(k, b)| (*k, b.as_slice())),
            false,
            damaged,
            timers,
            Duration::from_millis(self.now),
        )
        .map_err(|e| Violation::new(format!("{} cannot recover: {e}", slot.name)))?;
        if node.leader().durable().position < slot.published {
            return Err(Violation::new(format!(
                "{} came back at position {} below the durable mark {} it published",
                slot.name,
                node.leader().durable().position,
                slot.published
            )));
        }
        slot.node = Some(node);
        let life = slot.life;
        let phase = self.rng.gen_range(1..=250);
        self.net
            .at(self.now + phase, Event::Tick { leader: i, life });
        self.carry_out(i, out)
    }

    /// The sensor killed and started again: a new gateway restored from the
    /// journal must be where the old one was — the same seq, events and
    /// trace position (the producer's counter is checked by its next
    /// request, which must be taken whole). Cuts it held for a later point
    /// die with it: their queries time out. Half the time the journal is
    /// compacted first, as the process does once it has grown.
    fn sensor_crash(&mut self) -> Result<(), Violation> {
        self.tally.sensor_crashes += 1;
        self.journal.extend(self.gateway.unjournaled());
        if self.rng.gen_bool(0.5) {
            self.tally.sensor_compactions += 1;
            self.journal = self
                .gateway
                .compacted()
                .map_err(|e| Violation::new(format!("the sensor cannot snapshot: {e}")))?;
        }
        let router = Router::new(self.scenario.router(), &self.scenario.header)
            .map_err(|e| Violation::setup(e.to_string()))?;
        let mut restored = self.scenario.gateway(router);
        restored
            .restore(self.journal.clone(), &self.scenario.lines)
            .map_err(|e| Violation::new(format!("the sensor cannot restore: {e}")))?;
        let where_ = |g: &Gateway<u64>| {
            (
                g.router().seq(),
                g.router().events(),
                g.finished(),
                g.traced(),
            )
        };
        if where_(&restored) != where_(&self.gateway) {
            return Err(Violation::new(format!(
                "the sensor restored from its journal at (seq, events, finished, trace lines) {:?}, not {:?}",
                where_(&restored),
                where_(&self.gateway)
            )));
        }
        self.gateway = restored;
        Ok(())
    }

    fn crash(&mut self, i: usize) -> Result<(), Violation> {
        let Some(node) = self.leaders[i].node.take() else {
            return Ok(());
        };
        self.tally.crashes += 1;
        let before = node.leader().position();
        drop(node);
        let power_cut = self.rng.gen_bool(0.5);
        let disk = &mut self.leaders[i].disk;
        if power_cut {
            disk.entries.truncate(disk.synced);
        }
        let down = self.rng.gen_range(50..=2000);
        self.net.at(self.now + down, Event::Restart(i));
        if !power_cut {
            // A killed process loses nothing it journaled: it must come
            // back exactly where it was.
            let timers = self.timers(i);
            let slot = &self.leaders[i];
            let (probe, _) = Node::recover(
                &slot.name,
                &slot.name,
                slot.disk.snapshot.as_deref(),
                slot.disk.entries.iter().map(|(k, b)| (*k, b.as_slice())),
                false,
                None,
                timers,
                Duration::from_millis(self.now),
            )
            .map_err(|e| Violation::new(format!("{} cannot recover: {e}", slot.name)))?;
            if probe.leader().position() != before {
                return Err(Violation::new(format!(
                    "{} replayed its journal to position {} but was at {before}",
                    slot.name,
                    probe.leader().position()
                )));
            }
        }
        // In a quarter of the crashes the journal is found damaged at the
        // restart: the reader returns no entry from the damaged one on, so
        // the leader comes back from its snapshot and the entries before
        // it, behind where it was, and must fetch the rest again. (Damage
        // in the snapshot is an error, not a schedule.)
        let slot = &mut self.leaders[i];
        let entries = slot.disk.entries.len();
        if entries > 0 && self.damage.gen_bool(0.25) {
            let at = self.damage.gen_range(0..entries);
            slot.disk.entries.truncate(at);
            slot.disk.synced = slot.disk.synced.min(at);
            slot.damaged = Some((entries - at) as u64);
            self.tally.journal_damages += 1;
        }
        Ok(())
    }

    /// Hands leader `i` one input and carries out what it asks.
    fn step(&mut self, i: usize, input: Input) -> Result<(), Violation> {
        let now = Duration::from_millis(self.now);
        let Some(node) = self.leaders[i].node.as_mut() else {
            return Ok(());
        };
        let before = node.leader().position();
        let out = node.step(now, input);
        let after = node.leader().position();
        if after < before {
            return Err(Violation::new(format!(
                "{} went back from position {before} to {after}",
                self.leaders[i].name
            )));
        }
        if let Some(failure) = node.failure() {
            let failure = failure.to_string();
            return Err(Violation::new(format!(
                "{} failed: {failure}",
                self.leaders[i].name
            )));
        }
        self.carry_out(i, out)
    }

    fn carry_out(&mut self, i: usize, outputs: Vec<Output>) -> Result<(), Violation> {
        for output in outputs {
            match output {
                Output::Journal { kind, bytes } => self.leaders[i].disk.entries.push((kind, bytes)),
                Output::Send { to, seqs, body } => {
                    let Some(j) = self.leaders.iter().position(|l| l.name == to) else {
                        return Err(Violation::new(format!("transfer to unknown {to}")));
                    };
                    // Lost once: a message with a transfer not lost before.
                    let lost = self.aimed.lose_transfers
                        && seqs
                            .iter()
                            .filter(|&&seq| self.lost_once.insert((i, j, seq)))
                            .count()
                            > 0;
                    if lost {
                        self.tally.messages += 1;
                        self.tally.dropped += 1;
                        continue;
                    }
                    self.send(
                        Endpoint::Leader(i),
                        Endpoint::Leader(j),
                        Msg::Leader {
                            to: j,
                            what: ToLeader::Transfer(body),
                        },
                    );
                }
                Output::AskFollow(follow) => {
                    let ask = self.ask(i, AskKind::Follow);
                    self.send(
                        Endpoint::Leader(i),
                        Endpoint::Sensor,
                        Msg::Sensor {
                            from: i,
                            what: ToSensor::Follow {
                                ask,
                                bytes: encode(&follow),
                            },
                        },
                    );
                }
                Output::Progress(progress) => self.send(
                    Endpoint::Leader(i),
                    Endpoint::Sensor,
                    Msg::Sensor {
                        from: i,
                        what: ToSensor::Progress(encode(&progress)),
                    },
                ),
                Output::Unfollow(unfollow) => self.send(
                    Endpoint::Leader(i),
                    Endpoint::Sensor,
                    Msg::Sensor {
                        from: i,
                        what: ToSensor::Unfollow(encode(&unfollow)),
                    },
                ),
                Output::AskResend(resend) => {
                    let ask = self.ask(i, AskKind::Resend);
                    self.send(
                        Endpoint::Leader(i),
                        Endpoint::Sensor,
                        Msg::Sensor {
                            from: i,
                            what: ToSensor::Resend {
                                ask,
                                bytes: encode(&resend),
                            },
                        },
                    );
                }
                Output::AskTransfers { peer, wanted } => {
                    let Some(j) = self.leaders.iter().position(|l| l.name == peer) else {
                        return Err(Violation::new(format!("transfers asked of unknown {peer}")));
                    };
                    let ask = self.ask(i, AskKind::Transfers(peer));
                    self.send(
                        Endpoint::Leader(i),
                        Endpoint::Leader(j),
                        Msg::Leader {
                            to: j,
                            what: ToLeader::SentWanted {
                                ask,
                                bytes: encode(&wanted),
                            },
                        },
                    );
                }
                // The simulated coordinator asks for every answer: a push
                // is a shortcut whose loss the real one mends by asking,
                // so here every push is one lost.
                Output::Push(_) => {}
                Output::Answer { id, answer } => {
                    let reply = answer.map(|p| encode(&*p));
                    self.send(
                        Endpoint::Leader(i),
                        Endpoint::Coordinator,
                        Msg::Coordinator(ToCoordinator::Partial {
                            id,
                            leader: i,
                            reply,
                        }),
                    );
                }
                Output::AnswerSent { id, answer } => {
                    // The asker is whoever made get `id`, if it still waits.
                    let Some(asker) = self.asks.get(&id).map(|a| a.leader) else {
                        continue;
                    };
                    let reply = answer.map(|t| encode(&t));
                    self.send(
                        Endpoint::Leader(i),
                        Endpoint::Leader(asker),
                        Msg::Leader {
                            to: asker,
                            what: ToLeader::Reply { ask: id, reply },
                        },
                    );
                }
                Output::Persist { mark } => {
                    let slot = &mut self.leaders[i];
                    slot.disk.synced = slot.disk.entries.len();
                    if let Some(mark) = mark {
                        slot.published = slot.published.max(mark.position);
                        let bytes = encode(&mark);
                        self.send(
                            Endpoint::Leader(i),
                            Endpoint::Sensor,
                            Msg::Sensor {
                                from: i,
                                what: ToSensor::Durable(bytes.clone()),
                            },
                        );
                        for j in (0..self.leaders.len()).filter(|&j| j != i) {
                            self.send(
                                Endpoint::Leader(i),
                                Endpoint::Leader(j),
                                Msg::Leader {
                                    to: j,
                                    what: ToLeader::Durable(bytes.clone()),
                                },
                            );
                        }
                    }
                }
                Output::Snapshot(state) => {
                    let disk = &mut self.leaders[i].disk;
                    disk.snapshot = Some(state);
                    disk.entries.clear();
                    disk.synced = 0;
                }
            }
        }
        Ok(())
    }

    /// Registers a get of leader `i`; it is answered, or times out.
    fn ask(&mut self, i: usize, kind: AskKind) -> u64 {
        let id = self.fresh_id();
        self.asks.insert(
            id,
            PendingAsk {
                leader: i,
                life: self.leaders[i].life,
                kind,
            },
        );
        self.net.at(self.now + ASK_TIMEOUT, Event::AskTimeout(id));
        id
    }

    /// A get's answer (or its timeout) back in the leader that asked.
    fn answer_ask(
        &mut self,
        pending: PendingAsk,
        reply: Result<Vec<u8>, String>,
    ) -> Result<(), Violation> {
        let i = pending.leader;
        if self.leaders[i].life != pending.life {
            return Ok(());
        }
        let input = match pending.kind {
            AskKind::Follow => {
                if let Ok(followed) = reply.as_deref().map(decode::<Followed>) {
                    let followed = followed.map_err(|e| Violation::new(e.to_string()))?;
                    self.routed[i].extend(followed.items.iter().map(|s| s.seq));
                }
                Input::Followed(reply)
            }
            AskKind::Resend => Input::Resent(reply.and_then(|bytes| {
                decode::<Resent>(&bytes)
                    .map(|r| r.batches)
                    .map_err(|e| e.to_string())
            })),
            AskKind::Transfers(peer) => Input::Transfers {
                peer,
                result: reply.and_then(|bytes| {
                    decode::<TransfersSent>(&bytes)
                        .map(|t| t.transfers)
                        .map_err(|e| e.to_string())
                }),
            },
        };
        self.step(i, input)
    }

    fn at_leader(&mut self, i: usize, what: ToLeader) -> Result<(), Violation> {
        if self.leaders[i].node.is_none() {
            // Nobody subscribes or answers for a leader that is down.
            return Ok(());
        }
        let origin = format!("sim/{}", self.leaders[i].name);
        let input = match what {
            ToLeader::Batch(bytes) => Input::Message {
                kind: Kind::Batch,
                bytes,
                origin,
            },
            ToLeader::Transfer(bytes) => Input::Message {
                kind: Kind::Transfer,
                bytes,
                origin,
            },
            ToLeader::Durable(bytes) => Input::Durable { bytes, origin },
            ToLeader::Partial { id, ask, base } => Input::Partial { id, ask, base },
            ToLeader::SentWanted { ask, bytes } => Input::SentWanted {
                id: ask,
                bytes,
                origin,
            },
            ToLeader::Reply { ask, reply } => {
                return match self.asks.remove(&ask) {
                    Some(pending) => self.answer_ask(pending, reply),
                    None => Ok(()),
                };
            }
        };
        self.step(i, input)
    }

    // --- the coordinator ------------------------------------------------

    fn start_query(&mut self, final_query: bool) {
        let id = self.fresh_id();
        let last = self.memory.finished();
        let mut query = Query {
            floor: self.answered_events,
            last: last.clone(),
            phase: Phase::Rest,
            id,
            replied: BTreeSet::new(),
            partials: Partials::new(None),
            cut: None,
            final_query,
        };
        match last {
            Some(_) => {
                for j in 0..self.leaders.len() {
                    let rows = self.scenario.identity.is_some();
                    self.ask_leader(j, id, Ask::Quiet { rows });
                }
            }
            None => self.fresh_phase(&mut query),
        }
        self.net
            .at(self.now + QUERY_TIMEOUT, Event::QueryTimeout(query.id));
        self.queries.insert(query.id, query);
    }

    fn fresh_phase(&mut self, query: &mut Query) {
        let id = self.fresh_id();
        let tag = self.rng.gen::<u64>();
        query.phase = Phase::Fresh;
        query.id = id;
        query.replied.clear();
        query.partials = Partials::new(Some(tag));
        query.cut = None;
        self.send(
            Endpoint::Coordinator,
            Endpoint::Sensor,
            Msg::Sensor {
                from: usize::MAX,
                what: ToSensor::Cut {
                    id,
                    parameters: CutParameters {
                        tag: Some(tag.to_string()),
                        // An identity stream's cuts carry the rows too:
                        // every answer is checked for both.
                        rows: self.scenario.identity.is_some(),
                        events: None,
                    },
                },
            },
        );
        for j in 0..self.leaders.len() {
            self.ask_leader(j, id, Ask::Cut(tag));
        }
    }

    fn ask_leader(&mut self, j: usize, id: u64, ask: Ask) {
        self.send(
            Endpoint::Coordinator,
            Endpoint::Leader(j),
            Msg::Leader {
                to: j,
                what: ToLeader::Partial {
                    id,
                    ask,
                    // As the coordinator does: the leaders answer with
                    // what changed since the newest answer it keeps.
                    base: self.memory.base(),
                },
            },
        );
    }

    fn at_coordinator(&mut self, what: ToCoordinator) -> Result<(), Violation> {
        let (id, done) = match what {
            ToCoordinator::Cut { id, reply } => {
                let Some(query) = self.queries.get_mut(&id) else {
                    return Ok(());
                };
                if query.cut.is_none() {
                    query.cut = Some(read_cut(reply, "sim/cut", &self.memory));
                }
                // No cut, no answer: an error there stops the wait.
                let failed = matches!(query.cut, Some(Err(_)));
                (id, failed || query.replied.len() == self.leaders.len())
            }
            ToCoordinator::Partial { id, leader, reply } => {
                let Some(query) = self.queries.get_mut(&id) else {
                    return Ok(());
                };
                if !query.replied.insert(leader) {
                    // A duplicate: Zenoh would not deliver it twice.
                    return Ok(());
                }
                let change = reply
                    .as_ref()
                    .ok()
                    .and_then(|bytes| decode::<Partial>(bytes).ok());
                if change.is_some_and(|p| p.base.is_some()) {
                    self.tally.changes += 1;
                }
                query.partials.reply(reply, "sim/partial", &self.memory);
                let all = query.replied.len() == self.leaders.len();
                (
                    id,
                    all && (query.phase == Phase::Rest || query.cut.is_some()),
                )
            }
        };
        if done {
            self.complete_query(id)?;
        }
        Ok(())
    }

    /// The phase of query `id` is over (all answered, or its time is up).
    fn complete_query(&mut self, id: u64) -> Result<(), Violation> {
        let Some(mut query) = self.queries.remove(&id) else {
            return Ok(());
        };
        let timeout = Duration::from_millis(QUERY_TIMEOUT);
        let partials = std::mem::take(&mut query.partials);
        let (parts, errors) = partials.into_parts();
        let result = match query.phase {
            Phase::Rest => {
                let last = query.last.clone().expect("a rest phase has a last cut");
                match at_rest_of(last, parts, errors, timeout, &self.memory) {
                    Some(collected) => Ok(collected),
                    None => {
                        self.fresh_phase(&mut query);
                        self.net
                            .at(self.now + QUERY_TIMEOUT, Event::QueryTimeout(query.id));
                        self.queries.insert(query.id, query);
                        return Ok(());
                    }
                }
            }
            Phase::Fresh => match query.cut.take() {
                None => Err(GatherError::NoSensor),
                Some(Err(e)) => Err(e),
                Some(Ok(cut)) => check(cut, parts, errors, timeout, &self.memory).inspect(|c| {
                    self.memory.remember(&c.cut);
                }),
            },
        };
        let answered = result.and_then(|collected| {
            let answer = marginals_of(&collected, &self.memory)?;
            let rows: Vec<(u32, Vec<f64>)> = collected
                .rows()
                .into_iter()
                .map(|r| (r.track, r.ln_likelihoods.clone()))
                .collect();
            let trees: Vec<WireTree> = collected.trees().into_iter().cloned().collect();
            Ok((answer, (rows, trees)))
        });
        match answered {
            Ok((answer, (rows, trees))) => {
                if self.scenario.identity.is_some() {
                    let events = answer.watermark.values().copied().sum::<u64>();
                    self.answered_identity(events, rows, trees)?;
                }
                self.answered(&query, answer)
            }
            Err(e) => {
                self.tally.failed_queries += 1;
                self.last_error = e.to_string();
                if query.final_query {
                    // Ask again shortly, as a user would.
                    self.net.at(self.now + 500, Event::Calm);
                    self.calm = true;
                }
                Ok(())
            }
        }
    }

    /// Checks an answer against the centralized engine and the answers
    /// before it.
    fn answered(&mut self, query: &Query, answer: MarginalsAnswer) -> Result<(), Violation> {
        self.tally.answered += 1;
        let events = answer.watermark.values().copied().sum::<u64>();
        let sum: f64 = answer.p_red.iter().sum();
        if (sum - self.scenario.red as f64).abs() > 1e-9 {
            return Err(Violation::new(format!(
                "marginals sum to {sum}, not k = {}: {:?}",
                self.scenario.red, answer.p_red
            )));
        }
        if events < query.floor {
            return Err(Violation::new(format!(
                "the watermark went back: {events} after an answer at {}",
                query.floor
            )));
        }
        let Some(want) = self.scenario.centralized.get(events as usize) else {
            return Err(Violation::new(format!(
                "an answer at {events} events, beyond the stream's {}",
                self.scenario.lines.len()
            )));
        };
        for (t, (got, want)) in answer.p_red.iter().zip(want).enumerate() {
            if (got - want).abs() > 1e-9 {
                return Err(Violation::new(format!(
                    "at {events} events track {t}: the deployment says {got}, the centralized engine {want}\n  deployment {:?}\n  centralized {want:?}",
                    answer.p_red
                )));
            }
        }
        self.answered_events = self.answered_events.max(events);
        if query.final_query {
            if events != self.scenario.lines.len() as u64 || !answer.finished {
                return Err(Violation::new(format!(
                    "the final answer is at {events} events of {} (finished: {})",
                    self.scenario.lines.len(),
                    answer.finished
                )));
            }
            self.final_answer = Some(answer);
        }
        Ok(())
    }

    /// Checks the rows or trees an answer at `events` events gathered
    /// against the centralized identity belief there: rows put together
    /// must be the information matrix (the same operations on each row, in
    /// the same order), trees put together the factored identity belief,
    /// and the identity answer made of them must be its.
    fn answered_identity(
        &mut self,
        events: u64,
        rows: Vec<(u32, Vec<f64>)>,
        trees: Vec<WireTree>,
    ) -> Result<(), Violation> {
        let Some(central) = &self.scenario.identity else {
            return Ok(());
        };
        let Some(want_marginals) = central.marginals.get(events as usize) else {
            return Err(Violation::new(format!(
                "an identity answer at {events} events, beyond the stream's {}",
                self.scenario.lines.len()
            )));
        };
        let Some(all_rows) = &central.rows else {
            if !rows.is_empty() {
                return Err(Violation::new(format!(
                    "at {events} events rows of an information matrix where the leaders hold trees"
                )));
            }
            let n = want_marginals.len();
            let held = trees
                .into_iter()
                .map(from_wire_tree)
                .collect::<Result<Vec<_>, _>>()
                .map_err(|e| Violation::new(format!("at {events} events a tree: {e}")))?;
            let cap = self.scenario.identity_cap;
            let whole = assemble(n, identity_options(cap), held).map_err(|e| {
                Violation::new(format!(
                    "at {events} events the leaders' trees do not make a belief: {e}"
                ))
            })?;
            let marginals = whole
                .marginals()
                .map_err(|e| Violation::new(e.to_string()))?;
            for (t, (got, want)) in marginals.iter().zip(want_marginals).enumerate() {
                if !got.iter().zip(want).all(|(g, w)| (g - w).abs() <= 1e-9) {
                    return Err(Violation::new(format!(
                        "at {events} events track {t}'s identities: the deployment's trees say {got:?}, the centralized factored identity belief {want:?}"
                    )));
                }
            }
            self.tally.identity_answers += 1;
            self.tally.tree_answers += 1;
            return Ok(());
        };
        let Some(want) = all_rows.get(events as usize) else {
            return Err(Violation::new(format!(
                "an identity answer at {events} events, beyond the stream's {}",
                self.scenario.lines.len()
            )));
        };
        let n = want.len();
        let held: Vec<u32> = rows.iter().map(|(t, _)| *t).collect();
        let matrix = InformationRows::assemble(n, rows, InformationOptions::default())
            .map_err(|e| {
                Violation::new(format!(
                    "at {events} events the leaders' rows (of tracks {held:?}) do not make a matrix: {e}"
                ))
            })?;
        let close = |got: f64, want: f64| got == want || (got - want).abs() <= 1e-9;
        let got = matrix.log_likelihoods();
        for (t, (got, want)) in got.iter().zip(want).enumerate() {
            if got.len() != want.len() || !got.iter().zip(want).all(|(g, w)| close(*g, *w)) {
                return Err(Violation::new(format!(
                    "at {events} events the row of track {t}: the deployment has {got:?}, the centralized information matrix {want:?}"
                )));
            }
        }
        let marginals = exact_marginals(&matrix).map_err(Violation::new)?;
        for (t, (got, want)) in marginals.iter().zip(want_marginals).enumerate() {
            if !got.iter().zip(want).all(|(g, w)| (g - w).abs() <= 1e-9) {
                return Err(Violation::new(format!(
                    "at {events} events track {t}'s identities: the deployment says {got:?}, the centralized engine {want:?}"
                )));
            }
        }
        self.tally.identity_answers += 1;
        Ok(())
    }

    /// No item applied twice or lost: every leader applied, strictly in
    /// order, exactly the items routed to it up to where it is.
    fn check_end(&mut self) -> Result<(), Violation> {
        for (i, slot) in self.leaders.iter().enumerate() {
            let Some(node) = &slot.node else {
                return Err(Violation::new(format!("{} is down at the end", slot.name)));
            };
            let stats = node.leader().stats();
            self.tally.transfers += stats.transfers_received;
            self.tally.follows += stats.follows;
            self.tally.unfollows += stats.unfollows;
            self.tally.handovers += stats.handovers;
            self.tally.tracks_taken += stats.tracks_taken;
            self.tally.identity_repairs += stats.identity_repairs;
            let due = self.routed[i].range(..=stats.position).count() as u64;
            if stats.items != due {
                return Err(Violation::new(format!(
                    "{} applied {} items, but {due} were routed to it up to its position {}",
                    slot.name, stats.items, stats.position
                )));
            }
        }
        Ok(())
    }

    // --- the wire -------------------------------------------------------

    fn send(&mut self, from: Endpoint, to: Endpoint, msg: Msg) {
        self.tally.messages += 1;
        if !self.net.send(&mut self.rng, self.now, from, to, msg) {
            self.tally.dropped += 1;
        }
    }

    fn deliver(&mut self, msg: Msg) -> Result<(), Violation> {
        match msg {
            Msg::Leader { to, what } => self.at_leader(to, what),
            Msg::Sensor { from, what } => self.at_sensor(from, what),
            Msg::Coordinator(what) => self.at_coordinator(what),
        }
    }
}
