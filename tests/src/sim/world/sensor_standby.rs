//! The sensor's standbys, as `sensor/src/standby.rs` and the sensor's
//! driver run them: the sensor holds its role at an epoch of the voters'
//! map; it has one standby or two, and replicates to one at a time, as
//! [`Standbys`] chooses: every group of records it appends to its journal
//! goes to that standby ([`Replication`]), whose copy takes it ([`Copy`]),
//! and nothing that depends on them leaves before the standby said it
//! holds them. When that standby goes away the voters move the role to a
//! new epoch (an advance) before anything more leaves, so that the copy
//! left behind could no longer win a claim; then the sensor goes on with
//! the other standby, sent the whole journal, compacted, or alone.
//!
//! The exchange is one blocking step of the driver (`Wire::sync` waits
//! for the answer before anything leaves), so it is run here inside the
//! sensor's step, with its own losses: a message or its answer lost (the
//! same records again), the standby restarted (its copy's position
//! forgotten: the whole journal again), the journal compacted (the whole
//! journal again).
//!
//! And the fault the standbys are for: the sensor's host lost for good
//! with its disk. After the takeover time the standby replicated to
//! claims the role through the voters (`voters.rs`) naming its copy's
//! epoch (the other's claim must lose), wins the next epoch, and serves
//! from its copy:
//! the gateway it restores must stand exactly where the lost one stood
//! (nothing that left it, nothing acknowledged to a producer, is lost),
//! and its batches, at the new epoch, fence off whatever the lost sensor
//! still had on the wire.

use super::voters::Purpose;
use super::{Event, Ms, World};
use crate::sim::Violation;
use idmesh_claims::Claimed;
use idmesh_consensus::{Command, Outcome};
use idmesh_sensor::journal::{self, Record};
use idmesh_sensor::{Apply, Change, Copy, Gateway, Replication, Router, Standbys, Step};
use rand::Rng;
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;

/// The sensor role in the voters' map, and the processes that hold it.
const ROLE: &str = "sensor-0";
const SENSOR: &str = "sensor-0";
/// The sensor's standbys, in order (a schedule keeps the first, or
/// both).
const STANDBYS: [&str; 2] = ["sensor-0-standby", "sensor-0-standby-2"];

/// How long after the sensor's host is gone its standby claims the role
/// (its token gone for the takeover time; ms).
const TAKEOVER: (Ms, Ms) = (300, 1500);

/// Where a gateway stands: seq, events, finished, trace lines read.
pub(super) type Standing = (u64, u64, bool, u64);

/// Where `gateway` stands.
pub(super) fn standing(gateway: &Gateway<u64>) -> Standing {
    (
        gateway.router().seq(),
        gateway.router().events(),
        gateway.finished(),
        gateway.traced(),
    )
}

/// One standby: its copy, where it is and its records as its disk holds
/// them, and whether its token is present (it is up and reachable).
struct Kept {
    copy: Copy,
    records: Vec<Vec<u8>>,
    up: bool,
}

/// The sensor's standbys in a schedule that keeps them.
pub(crate) struct SensorStandby {
    /// The sensor's side of the replication, for its current run.
    replication: Replication,
    /// Which standby it replicates to, for its current run.
    choice: Standbys,
    /// Runs of the sensor so far: each restart is a new incarnation.
    incarnation: u64,
    /// Each standby's copy, in [`STANDBYS`]' order.
    kept: Vec<Kept>,
    /// The sensor's host is gone: where its gateway stood, and the
    /// standby that claims the role.
    lost: Option<(Standing, usize)>,
    /// The standby that holds the role now (it keeps no standby of its
    /// own).
    adopted: Option<usize>,
    /// The standby last chosen, in any run.
    last: Option<usize>,
    /// The standbys' draws (their own stream).
    rng: ChaCha8Rng,
}

impl SensorStandby {
    /// Whether the sensor's host is gone and the role not yet adopted.
    pub(super) fn down(&self) -> bool {
        self.lost.is_some() && self.adopted.is_none()
    }

    /// A new run of the replication, at `epoch`, knowing which standbys
    /// are up: with two, none is chosen before the role has moved on.
    fn start_run(&mut self, epoch: u64) {
        let names = STANDBYS[..self.kept.len()].iter().map(|n| n.to_string());
        self.replication = Replication::new(SENSOR, self.incarnation);
        self.replication.at_epoch(epoch);
        self.choice = Standbys::new(names.collect(), true);
        for i in 0..self.kept.len() {
            if self.kept[i].up {
                self.token(i, true);
            }
        }
    }

    /// Standby `i`'s token came or went: told to the choice, and what
    /// changed to the replication. Whether one was chosen, or one is
    /// there to be chosen once the role has moved on.
    fn token(&mut self, i: usize, up: bool) -> bool {
        self.kept[i].up = up;
        let mut chosen = false;
        for change in self.choice.token(STANDBYS[i], up) {
            chosen |= self.apply(change);
        }
        chosen || self.choice.waiting()
    }

    fn apply(&mut self, change: Change) -> bool {
        let chosen = matches!(change, Change::Chosen(_));
        self.replication.standby(chosen);
        if chosen {
            self.last = self.current();
        }
        chosen
    }

    /// The standby replicated to, by its index.
    fn current(&self) -> Option<usize> {
        let name = self.choice.current()?;
        STANDBYS.iter().position(|n| *n == name)
    }
}

impl World {
    /// In a quarter of the schedules the sensor keeps a standby, drawn
    /// from `seed`'s own stream; in half of those its host is lost for
    /// good at a random point before `span`. Every such schedule sees the
    /// standby go away and come back, and restart, now and then.
    pub(super) fn draw_sensor_standby(&mut self, seed: u64, span: Ms) -> Result<(), Violation> {
        let mut rng = ChaCha8Rng::seed_from_u64(seed ^ 0x5e50_5b1e);
        if std::env::var("IDMESH_SIM_SENSOR_STANDBY").is_ok_and(|v| v == "0") || !rng.gen_bool(0.25)
        {
            return Ok(());
        }
        let standbys = rng.gen_range(1..=2);
        for _ in 0..rng.gen_range(0..=2 * standbys) {
            let (at, i) = (rng.gen_range(0..span), rng.gen_range(0..standbys));
            self.net.at(at, Event::StandbyAway(i));
            self.net
                .at(at + rng.gen_range(50..=1500), Event::StandbyBack(i));
        }
        for _ in 0..rng.gen_range(0..=2) {
            let (at, i) = (rng.gen_range(0..span), rng.gen_range(0..standbys));
            self.net.at(at, Event::StandbyRestart(i));
        }
        if rng.gen_bool(0.5) {
            self.net.at(rng.gen_range(0..span), Event::SensorHostLoss);
        }
        let epoch = self.claim_role(ROLE, SENSOR, None)?;
        self.gateway.advance_epoch(epoch);
        self.tally.sensor_standbys += 1;
        self.tally.two_standbys += u64::from(standbys == 2);
        let mut s = SensorStandby {
            replication: Replication::new(SENSOR, 1),
            choice: Standbys::new(Vec::new(), true),
            incarnation: 1,
            kept: (0..standbys)
                .map(|_| Kept {
                    copy: Copy::default(),
                    records: Vec::new(),
                    up: true,
                })
                .collect(),
            lost: None,
            adopted: None,
            last: None,
            rng,
        };
        s.start_run(epoch);
        self.sensor_standby = Some(s);
        Ok(())
    }

    /// Whether the sensor's host is gone and its role not yet adopted:
    /// nothing reaches it, it reads nothing.
    pub(super) fn sensor_down(&self) -> bool {
        self.sensor_standby.as_ref().is_some_and(|s| s.down())
    }

    /// What changed the gateway's state, on the sensor's disk and then on
    /// its standby's, before anything that depends on it leaves
    /// (`Wire::sync` in sensor/src/driver.rs).
    pub(super) fn sync(&mut self) -> Result<(), Violation> {
        let records = self.gateway.unjournaled();
        self.journal.extend(records.iter().cloned());
        let Some(mut standby) = self.sensor_standby.take() else {
            return Ok(());
        };
        let replicated = self.replicate(&mut standby, &records);
        self.sensor_standby = Some(standby);
        replicated
    }

    /// `records`, just appended, to the standby and back, until they may
    /// leave (`Replicator::replicate`).
    fn replicate(&mut self, s: &mut SensorStandby, records: &[Record]) -> Result<(), Violation> {
        if s.adopted.is_some() || s.lost.is_some() {
            return Ok(());
        }
        // Now and then the journal has grown enough to be compacted: its
        // compacted form goes to the standby next.
        if s.rng.gen_bool(0.03) {
            self.journal = self.compacted()?;
            s.replication.compacted();
        }
        let encoded = records.iter().map(journal::encode).collect();
        let mut step = s.replication.appended(encoded);
        for _ in 0..1000 {
            let message = match step {
                Step::Release if s.choice.fence_due() => {
                    self.fence(s)?;
                    match s.choice.fenced() {
                        Some(change) => {
                            // The next standby, made whole at the new
                            // epoch before anything leaves.
                            let before = s.last;
                            s.apply(change);
                            if before.is_some_and(|b| Some(b) != s.last) {
                                self.tally.standby_switches += 1;
                            }
                            step = s.replication.appended(Vec::new());
                            continue;
                        }
                        None => return Ok(()),
                    }
                }
                Step::Release => return Ok(()),
                Step::Send(message) => message,
                Step::NeedWhole => {
                    self.tally.standby_wholes += 1;
                    let whole = self.compacted()?;
                    s.replication
                        .whole(whole.iter().map(journal::encode).collect())
                }
            };
            self.tally.replications += 1;
            let to = s.current();
            let answer = match to.filter(|_| !s.rng.gen_bool(0.1)) {
                // Lost on the way: no answer in time.
                None => None,
                Some(i) => {
                    let kept = &mut s.kept[i];
                    match kept.copy.take(&message) {
                        Apply::Replace(records) => kept.records = records.to_vec(),
                        Apply::Append(records) => kept.records.extend_from_slice(records),
                        Apply::Nothing => {}
                    }
                    // Its answer lost on the way back, or given.
                    let position = kept.copy.position;
                    (!s.rng.gen_bool(0.1)).then_some(position)
                }
            };
            step = s.replication.answered(answer);
        }
        Err(Violation::new(
            "the sensor's records never reached its standby in 1000 tries".into(),
        ))
    }

    /// Before anything the standby that went did not acknowledge may
    /// leave (or, with two, before the run chooses one) the sensor has the
    /// voters move its role to a new epoch; no copy may then win a claim
    /// naming its epoch.
    fn fence(&mut self, s: &mut SensorStandby) -> Result<(), Violation> {
        let from = self.gateway.epoch();
        let command = Command::Advance {
            role: ROLE.into(),
            holder: SENSOR.into(),
            from,
        };
        let epoch = match self.commit_now(&command)? {
            Claimed::Won(epoch) => epoch,
            other => {
                return Err(Violation::new(format!(
                    "the sensor could not move its role past epoch {from}: {other:?}"
                )))
            }
        };
        s.replication.at_epoch(epoch);
        self.gateway.advance_epoch(epoch);
        self.tally.sensor_advances += 1;
        for (i, kept) in s.kept.iter().enumerate() {
            if self.could_claim(i, kept.copy.epoch) {
                return Err(Violation::new(format!(
                    "the sensor moved its role to epoch {epoch}, but {}'s copy (in sync at {:?}) could still claim it",
                    STANDBYS[i], kept.copy.epoch
                )));
            }
        }
        Ok(())
    }

    /// Whether standby `i`, its copy in sync at `epoch`, would win a claim
    /// of the role on the map as it stands.
    fn could_claim(&self, i: usize, epoch: Option<u64>) -> bool {
        let mut map = self.hosts.map.clone();
        let claim = Command::Claim {
            role: ROLE.into(),
            holder: STANDBYS[i].into(),
            fencing: epoch,
        };
        matches!(map.apply(&claim), Outcome::Changed { .. })
    }

    fn compacted(&self) -> Result<Vec<Record>, Violation> {
        self.gateway
            .compacted()
            .map_err(|e| Violation::new(format!("the sensor cannot snapshot: {e}")))
    }

    /// The sensor was killed and started again from its own journal: a new
    /// run of the replication, at the epoch it holds, which sends the
    /// whole journal first.
    pub(super) fn sensor_restarted(&mut self) {
        let epoch = self.gateway.epoch();
        if let Some(s) = self.sensor_standby.as_mut().filter(|s| s.adopted.is_none()) {
            s.incarnation += 1;
            s.start_run(epoch);
        }
    }

    /// Standby `i`'s token went away (its host cut off, or down).
    pub(super) fn standby_away(&mut self, i: usize) {
        if let Some(s) = self.sensor_standby.as_mut().filter(|s| s.adopted.is_none()) {
            if s.kept[i].up {
                s.token(i, false);
            }
        }
    }

    /// Standby `i`'s token is back: if chosen, or to be chosen once the
    /// role moved on, it is sent the whole journal now.
    pub(super) fn standby_back(&mut self, i: usize) -> Result<(), Violation> {
        let Some(s) = self.sensor_standby.as_mut().filter(|s| s.adopted.is_none()) else {
            return Ok(());
        };
        if s.kept[i].up {
            return Ok(());
        }
        if s.lost.is_some() {
            s.kept[i].up = true;
            return Ok(());
        }
        match s.token(i, true) {
            true => self.sync(),
            false => Ok(()),
        }
    }

    /// Standby `i`'s process restarted too quickly for its token to be
    /// missed: its copy is on its disk, but where it stands in the
    /// sensor's run is not.
    pub(super) fn standby_restart(&mut self, i: usize) {
        if let Some(s) = self.sensor_standby.as_mut().filter(|s| s.adopted.is_none()) {
            self.tally.standby_restarts += 1;
            s.kept[i].copy.position = None;
        }
    }

    /// The sensor's host is gone for good with its disk. Struck only while
    /// a standby is replicated to (its copy then holds everything that
    /// left): otherwise it waits until one is.
    pub(super) fn sensor_host_lost(&mut self) -> Result<(), Violation> {
        let Some(s) = self.sensor_standby.as_mut() else {
            return Ok(());
        };
        if self.calm || s.adopted.is_some() || s.lost.is_some() {
            return Ok(());
        }
        let Some(claimant) = s.current() else {
            self.net.at(self.now + 100, Event::SensorHostLoss);
            return Ok(());
        };
        s.lost = Some((standing(&self.gateway), claimant));
        let delay = s.rng.gen_range(TAKEOVER.0..=TAKEOVER.1);
        self.tally.sensor_host_losses += 1;
        self.journal.clear();
        self.net.at(self.now + delay, Event::SensorAdopt);
        Ok(())
    }

    /// The standby replicated to claims the sensor role through the
    /// voters, naming its copy's epoch; the other's claim, naming its
    /// own, must lose.
    pub(super) fn sensor_adopt(&mut self) -> Result<(), Violation> {
        let Some(s) = self.sensor_standby.as_ref().filter(|s| s.down()) else {
            return Ok(());
        };
        let Some((_, claimant)) = s.lost else {
            return Ok(());
        };
        for (i, kept) in s.kept.iter().enumerate().filter(|(i, _)| *i != claimant) {
            if self.could_claim(i, kept.copy.epoch) {
                return Err(Violation::new(format!(
                    "{} was replicated to, but {}'s copy (in sync at {:?}) could claim the sensor role",
                    STANDBYS[claimant], STANDBYS[i], kept.copy.epoch
                )));
            }
        }
        let command = Command::Claim {
            role: ROLE.into(),
            holder: STANDBYS[claimant].into(),
            fencing: s.kept[claimant].copy.epoch,
        };
        self.start_claim(command, Purpose::SensorAdopt);
        Ok(())
    }

    /// The standby won the sensor role at `epoch` and serves from its
    /// copy: its gateway must stand where the lost one stood, and a
    /// producer's next line must be the one after what it was told was
    /// taken.
    pub(super) fn sensor_adopted_at(&mut self, epoch: u64) -> Result<(), Violation> {
        let Some(mut s) = self.sensor_standby.take() else {
            return Ok(());
        };
        let adopted = self.serve_from_copy(&mut s, epoch);
        self.sensor_standby = Some(s);
        adopted
    }

    fn serve_from_copy(&mut self, s: &mut SensorStandby, epoch: u64) -> Result<(), Violation> {
        let Some((lost, claimant)) = s.lost else {
            return Ok(());
        };
        let records = s.kept[claimant]
            .records
            .iter()
            .map(|r| journal::decode_record(r))
            .collect::<Result<Vec<_>, _>>()
            .map_err(|e| Violation::new(format!("the standby's copy does not read: {e}")))?;
        let router = Router::new(self.scenario.router(), &self.scenario.header)
            .map_err(|e| Violation::setup(e.to_string()))?;
        let mut restored = self.scenario.gateway(router);
        restored
            .restore(records.clone(), &self.scenario.lines)
            .map_err(|e| Violation::new(format!("the standby cannot serve from its copy: {e}")))?;
        restored.advance_epoch(epoch);
        if standing(&restored) != lost {
            return Err(Violation::new(format!(
                "the standby took the sensor role over at (seq, events, finished, trace lines) {:?}, but the lost sensor stood at {lost:?}",
                standing(&restored)
            )));
        }
        if self.producer.is_some() && restored.producer_next("sim") != self.next_line as u64 {
            return Err(Violation::new(format!(
                "the producer was told lines up to {} were taken, but the standby expects line {} next",
                self.next_line,
                restored.producer_next("sim")
            )));
        }
        s.adopted = Some(claimant);
        self.tally.sensor_adoptions += 1;
        self.gateway = restored;
        self.journal = records;
        // A new holder knows no epoch of the leaders' roles yet.
        self.sensor_heard.clear();
        // It reads on from where the lost sensor stopped.
        if self.next_line < self.scenario.lines.len() {
            self.net.at(self.now + 1, Event::SensorStep);
        }
        Ok(())
    }
}
