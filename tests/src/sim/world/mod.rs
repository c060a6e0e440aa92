//! One schedule: the sensor gateway, L leaders and the coordinator's
//! gathering, in one thread, exchanging messages through a [`Network`]
//! that loses, doubles, delays (hence reorders) and cuts them off, while
//! leaders crash and come back from their journal and snapshot. Every
//! process runs its real pure state machine ([`Gateway`], [`Node`],
//! [`crate::sim`]'s use of `idmesh_coordinator::machine`); what the
//! actors do with Zenoh — puts, gets with a timeout, subscriptions — is
//! done here with virtual time.
//!
//! The files mirror the drivers: `sensor.rs` does what
//! `sensor/src/driver.rs` does, `leader.rs` what `leader/src/driver.rs`
//! does, `coordinator.rs` what `coordinator/src/driver/` does, `hosts.rs`
//! what `leader/src/host.rs` does (who holds a role at which epoch,
//! standbys, adoptions), `voters.rs` what `voter/src/driver.rs` and a
//! claimant (`idmesh-claims`) do. This one
//! holds the world itself: its clock and events, the wire between the
//! roles, and the checks no one role can make.

mod coordinator;
mod hosts;
mod leader;
mod sensor;
mod sensor_standby;
mod voters;

use super::network::{self, Endpoint, Network};
use super::scenario::Scenario;
use super::Violation;
use coordinator::{Query, ToCoordinator};
use hosts::{HostFault, Hosts};
use idmesh_coordinator::machine::Memory;
use idmesh_leader::Input;
use idmesh_protocol::wire::query::MarginalsAnswer;
use idmesh_sensor::journal::Record;
use idmesh_sensor::Gateway;
use idmesh_sensor::Router;
use leader::{Disk, LeaderSlot, PendingAsk, ToLeader, Who};
use rand::Rng;
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use sensor::ToSensor;
use sensor_standby::SensorStandby;
use std::collections::{BTreeMap, BTreeSet, HashMap};
use voters::{ToVoter, VoterEvent, Voters};

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
    /// An input of role `to`'s former holder (cut off and superseded,
    /// still running).
    Former {
        to: usize,
        what: ToLeader,
    },
    /// From `from` holding its role at `epoch` (the coordinator's cuts:
    /// role `usize::MAX`).
    Sensor {
        from: Who,
        epoch: u64,
        what: ToSensor,
    },
    Coordinator(ToCoordinator),
    /// For voter `to`.
    Voter {
        to: u64,
        what: ToVoter,
    },
    /// A voter's map, for the claimant of claim `claim`.
    Claimant {
        claim: u64,
        answer: idmesh_consensus::RolesAnswer,
    },
}

/// What happens at a point of virtual time.
#[derive(Debug, Clone)]
pub(crate) enum Event {
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
    /// A role's process is gone for good, with its disk.
    HostLoss(usize),
    /// A role's holder is cut off long enough to be superseded.
    Supersede(usize),
    /// The heir of an orphaned role claims it (its token gone for the
    /// takeover time).
    Adopt(usize),
    /// A former holder's cut heals; later it stops.
    HealFormer(usize),
    StopFormer(usize),
    FormerTick {
        leader: usize,
        life: u64,
    },
    /// A sensor's standby goes away (its token gone), comes back, or
    /// restarts without its token being missed.
    StandbyAway(usize),
    StandbyBack(usize),
    StandbyRestart(usize),
    /// The sensor's host is gone for good, with its disk.
    SensorHostLoss,
    /// The sensor's standby claims the sensor role (its token gone for
    /// the takeover time).
    SensorAdopt,
    /// The voters' clock, their faults, a claimant's reads.
    Voters(VoterEvent),
    /// The faults stop and the final query starts.
    Calm,
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
    /// Of them, schedules of several leaders whose crowd the first held
    /// whole (splits weighed by all of it).
    pub held_whole: u64,
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
    /// Hosts lost with their disk, holders cut off and superseded, and
    /// the roles adopted after either (of them, from a standby copy).
    pub host_losses: u64,
    pub superseded: u64,
    pub adoptions: u64,
    pub adopted_from_copies: u64,
    /// Snapshots sent to a standby.
    pub standby_copies: u64,
    /// Messages of a former holder refused by a receiver that had heard
    /// a newer epoch of the role (the sensor, a peer, the coordinator).
    pub fenced: u64,
    /// Schedules whose sensor kept a standby, of them two; replication
    /// messages sent to them, of them whole journals; the standbys'
    /// restarts; the sensor's role moved to a new epoch (to go on without
    /// the standby that went, or before a run chooses among two); the
    /// other standby chosen after one went; the sensor's host lost, and
    /// its role adopted from a standby's copy.
    pub sensor_standbys: u64,
    pub two_standbys: u64,
    pub replications: u64,
    pub standby_wholes: u64,
    pub standby_restarts: u64,
    pub sensor_advances: u64,
    pub standby_switches: u64,
    pub sensor_host_losses: u64,
    pub sensor_adoptions: u64,
    /// Raft messages the voters sent; voter faults; claims made through
    /// the voters on the clock.
    pub voter_messages: u64,
    pub voter_faults: u64,
    /// Of those, faults that took two voters, the majority, for a while.
    pub voter_majority_losses: u64,
    pub claims: u64,
}

impl Tally {
    /// The tally of a schedule before it runs: what its scenario is.
    fn of(scenario: &Scenario) -> Tally {
        Tally {
            factored: scenario.factored.is_some() as u64,
            held_whole: scenario.held_whole() as u64,
            identities: scenario.identity.is_some() as u64,
            ..Tally::default()
        }
    }
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
    /// Who holds which role, standbys and their copies.
    hosts: Hosts,
    /// The newest epoch of each role the sensor has been handed a
    /// message of since it started, and the coordinator an answer of.
    sensor_heard: BTreeMap<usize, u64>,
    coordinator_heard: BTreeMap<String, u64>,
    /// The sensor's standby, in the schedules that keep one.
    sensor_standby: Option<SensorStandby>,
    /// The voters, who decide who holds each role.
    voters: Voters,
}

impl World {
    /// A world for one seed's schedule, with the `aimed` faults added
    /// (none: [`Aimed::default`]).
    pub(crate) fn aimed(mut rng: ChaCha8Rng, aimed: Aimed) -> Result<World, Violation> {
        let scenario = Scenario::random(&mut rng).map_err(Violation::setup)?;
        let router = Router::new(scenario.router(), &scenario.header)
            .map_err(|e| Violation::setup(e.to_string()))?;
        let gateway = scenario.gateway(router);
        let net = network::random(&mut rng);
        let leaders = slots(&scenario);
        let tally = Tally::of(&scenario);
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
            tally,
            last_error: String::new(),
            aimed,
            lost_once: BTreeSet::new(),
            stall_checked: 0,
            damage: ChaCha8Rng::seed_from_u64(0),
            hosts: Hosts {
                map: Default::default(),
                held: BTreeMap::new(),
                alive: BTreeSet::new(),
                copies: BTreeMap::new(),
                standbys: false,
                rng: ChaCha8Rng::seed_from_u64(0),
            },
            sensor_heard: BTreeMap::new(),
            coordinator_heard: BTreeMap::new(),
            sensor_standby: None,
            voters: Voters::new()?,
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
        let host_fault = world.draw_host_fault(side.gen());
        let span = 40 * world.scenario.lines.len() as Ms + 200;
        world.draw_sensor_standby(side.gen(), span)?;
        // Claims mid-stream go through voters on the clock.
        let voters_seed = side.gen();
        if world.hosts.standbys || world.sensor_standby.is_some() {
            let majority_may_go = world.sensor_standby.is_none();
            world.clock_voters(voters_seed, span, majority_may_go);
        }
        for i in 0..count {
            let name = world.leaders[i].name.clone();
            world.leaders[i].epoch = world.claim(i, &name, None)?;
            world.hosts.alive.insert(name);
        }
        for i in 0..count {
            world.leaders[i].snapshot_every = world.rng.gen_range(3..=30);
            world.start_leader(i, false)?;
        }
        world.flush()?;
        world.net.at(1, Event::SensorStep);
        // Queries at random points of the stream, and the faults.
        for _ in 0..world.rng.gen_range(0..=4) {
            let at = world.rng.gen_range(0..span);
            world.net.at(at, Event::QueryStart);
        }
        network::schedule_faults(&mut world.net, &mut world.rng, span, count);
        if let Some(fault) = host_fault {
            world.schedule_host_fault(fault, span);
        }
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
        while let Some((at, event)) = self.net.pop() {
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

    /// Whether this schedule's roles keep standbys, and the host fault it
    /// holds if any: a third of the schedules with more than one leader
    /// (half of them a host lost, half a holder superseded). Drawn from
    /// its own stream, seeded by `seed`.
    fn draw_host_fault(&mut self, seed: u64) -> Option<HostFault> {
        self.hosts.rng = ChaCha8Rng::seed_from_u64(seed ^ 0x5eed_4057);
        if self.leaders.len() < 2 || !self.hosts.rng.gen_bool(1.0 / 3.0) {
            return None;
        }
        self.hosts.standbys = true;

        Some(match self.hosts.rng.gen_bool(0.5) {
            true => HostFault::Lost,
            false => HostFault::Superseded,
        })
    }

    /// `fault` strikes a random role at a random point before `span`.
    fn schedule_host_fault(&mut self, fault: HostFault, span: Ms) {
        let at = self.hosts.rng.gen_range(0..span);
        let role = self.hosts.rng.gen_range(0..self.leaders.len());
        let event = match fault {
            HostFault::Lost => Event::HostLoss(role),
            HostFault::Superseded => Event::Supersede(role),
        };
        self.net.at(at, event);
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
                    self.step(Who::holder(leader), Input::Tick)?;
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
                if !self.calm && !self.sensor_down() {
                    self.sensor_crash()?;
                }
                Ok(())
            }
            Event::Restart(i) => {
                if self.leaders[i].node.is_none() && !self.leaders[i].orphaned {
                    self.start_leader(i, false)?;
                }
                Ok(())
            }
            Event::HostLoss(i) => self.host_lost(i),
            Event::Supersede(i) => self.superseded(i),
            Event::Adopt(i) => self.adopt(i),
            Event::HealFormer(i) => {
                self.net.heal(Endpoint::Former(i));
                Ok(())
            }
            Event::StopFormer(i) => {
                self.stop_former(i);
                Ok(())
            }
            Event::FormerTick { leader, life } => self.former_tick(leader, life),
            Event::StandbyAway(i) => {
                self.standby_away(i);
                Ok(())
            }
            Event::StandbyBack(i) => self.standby_back(i),
            Event::StandbyRestart(i) => {
                self.standby_restart(i);
                Ok(())
            }
            Event::SensorHostLoss => self.sensor_host_lost(),
            Event::SensorAdopt => self.sensor_adopt(),
            Event::Voters(event) => self.voters_event(event),
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
                    // An orphaned role waits for its adoption.
                    if self.leaders[i].node.is_none() && !self.leaders[i].orphaned {
                        self.start_leader(i, false)?;
                    }
                }
                // Under flow control the stream may still be going (the
                // window held it while faults lost marks and batches):
                // the final question waits for its end, which must come
                // before the patience runs out.
                // The final answer is the current holders': it waits for
                // every orphaned role's adoption and every former holder
                // to stop.
                let settled = self
                    .leaders
                    .iter()
                    .all(|l| !l.orphaned && l.former.is_none());
                if !self.gateway.finished() || !settled || self.sensor_down() {
                    self.net.at(self.now + 250, Event::Calm);
                    return Ok(());
                }
                self.start_query(true);
                Ok(())
            }
        }
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
        // A role's subscriptions and queryables are its former holder's
        // too, while it runs: it hears what the role hears.
        if let (Endpoint::Leader(j), Msg::Leader { what, .. }) = (to, &msg) {
            let heard = matches!(
                what,
                ToLeader::Batch(_)
                    | ToLeader::Transfer { .. }
                    | ToLeader::Durable { .. }
                    | ToLeader::Partial { .. }
            );
            if heard && self.leaders[j].former.is_some() {
                let copy = Msg::Former {
                    to: j,
                    what: what.clone(),
                };
                self.send(from, Endpoint::Former(j), copy);
            }
        }
        self.tally.messages += 1;
        if !self
            .net
            .send(&mut self.rng, self.now, from, to, Event::Deliver(msg))
        {
            self.tally.dropped += 1;
        }
    }

    fn deliver(&mut self, msg: Msg) -> Result<(), Violation> {
        match msg {
            Msg::Leader { to, what } => self.at_leader(Who::holder(to), what),
            Msg::Former { to, what } => self.at_leader(
                Who {
                    role: to,
                    former: true,
                },
                what,
            ),
            // A sensor whose host is gone hears nothing.
            Msg::Sensor { .. } if self.sensor_down() => Ok(()),
            Msg::Sensor { from, epoch, what } => self.at_sensor_fenced(from, epoch, what),
            Msg::Coordinator(what) => self.at_coordinator(what),
            Msg::Voter { to, what } => self.at_voter(to, what),
            Msg::Claimant { claim, answer } => {
                self.claimant_heard(claim, answer);
                Ok(())
            }
        }
    }
}

/// A slot per leader role, each held by the process of its own name.
fn slots(scenario: &Scenario) -> Vec<LeaderSlot> {
    scenario
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
            process: l.name.clone(),
            epoch: 0,
            orphaned: false,
            former: None,
            standby: None,
            heard: BTreeMap::new(),
        })
        .collect()
}
