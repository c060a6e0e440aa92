//! The sensor's standby, as `sensor/src/standby.rs` and the sensor's
//! driver run it: the sensor holds its role at an epoch of the voters'
//! map; every group of records it appends to its journal goes to the
//! standby ([`Replication`]), whose copy takes it ([`Copy`]), and nothing
//! that depends on them leaves before the standby said it holds them.
//! While the standby is away the sensor goes on alone, once the voters
//! have moved its role to a new epoch (an advance), so that the copy left
//! behind could no longer win a claim. When it is back it is sent the
//! whole journal, compacted.
//!
//! The exchange is one blocking step of the driver (`Wire::sync` waits
//! for the answer before anything leaves), so it is run here inside the
//! sensor's step, with its own losses: a message or its answer lost (the
//! same records again), the standby restarted (its copy's position
//! forgotten: the whole journal again), the journal compacted (the whole
//! journal again).
//!
//! And the fault the standby is for: the sensor's host lost for good
//! with its disk. After the takeover time the standby claims the role
//! through the voters (`voters.rs`) naming its copy's epoch, wins the
//! next epoch, and serves from its copy:
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
use idmesh_sensor::{Apply, Copy, Gateway, Replication, Router, Step};
use rand::Rng;
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;

/// The sensor role in the voters' map, and the processes that hold it.
const ROLE: &str = "sensor-0";
const SENSOR: &str = "sensor-0";
const STANDBY: &str = "sensor-0-standby";

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

/// The sensor's standby in a schedule that keeps one.
pub(crate) struct SensorStandby {
    /// The sensor's side of the replication, for its current run.
    replication: Replication,
    /// Runs of the sensor so far: each restart is a new incarnation.
    incarnation: u64,
    /// The standby's copy: where it is, and its records as its disk holds
    /// them.
    copy: Copy,
    records: Vec<Vec<u8>>,
    /// The standby's token is present (it is up and reachable).
    up: bool,
    /// The voters moved the role to a new epoch since the standby went.
    advanced: bool,
    /// The sensor's host is gone: where its gateway stood.
    lost: Option<Standing>,
    /// The standby holds the role now (it keeps no standby of its own).
    adopted: bool,
    /// The standby's draws (their own stream).
    rng: ChaCha8Rng,
}

impl SensorStandby {
    /// Whether the sensor's host is gone and the role not yet adopted.
    pub(super) fn down(&self) -> bool {
        self.lost.is_some() && !self.adopted
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
        for _ in 0..rng.gen_range(0..=2) {
            let at = rng.gen_range(0..span);
            self.net.at(at, Event::StandbyAway);
            self.net
                .at(at + rng.gen_range(50..=1500), Event::StandbyBack);
        }
        for _ in 0..rng.gen_range(0..=2) {
            self.net.at(rng.gen_range(0..span), Event::StandbyRestart);
        }
        if rng.gen_bool(0.5) {
            self.net.at(rng.gen_range(0..span), Event::SensorHostLoss);
        }
        let epoch = self.claim_role(ROLE, SENSOR, None)?;
        self.gateway.advance_epoch(epoch);
        let mut replication = Replication::new(SENSOR, 1);
        replication.at_epoch(epoch);
        replication.standby(true);
        self.tally.sensor_standbys += 1;
        self.sensor_standby = Some(SensorStandby {
            replication,
            incarnation: 1,
            copy: Copy::default(),
            records: Vec::new(),
            up: true,
            advanced: false,
            lost: None,
            adopted: false,
            rng,
        });
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
        if s.adopted || s.lost.is_some() {
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
                Step::Release => return self.going_alone(s),
                Step::Send(message) => message,
                Step::NeedWhole => {
                    self.tally.standby_wholes += 1;
                    let whole = self.compacted()?;
                    s.replication
                        .whole(whole.iter().map(journal::encode).collect())
                }
            };
            self.tally.replications += 1;
            let answer = match s.up && !s.rng.gen_bool(0.1) {
                // Lost on the way: no answer in time.
                false => None,
                true => {
                    match s.copy.take(&message) {
                        Apply::Replace(records) => s.records = records.to_vec(),
                        Apply::Append(records) => s.records.extend_from_slice(records),
                        Apply::Nothing => {}
                    }
                    // Its answer lost on the way back, or given.
                    (!s.rng.gen_bool(0.1)).then_some(s.copy.position)
                }
            };
            step = s.replication.answered(answer);
        }
        Err(Violation::new(
            "the sensor's records never reached its standby in 1000 tries".into(),
        ))
    }

    /// The records may leave. Without its standby the sensor first has the
    /// voters move its role to a new epoch (once per absence), and the
    /// copy left behind must then lose any claim naming its epoch.
    fn going_alone(&mut self, s: &mut SensorStandby) -> Result<(), Violation> {
        if s.replication.present() || s.advanced {
            return Ok(());
        }
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
        s.advanced = true;
        s.replication.at_epoch(epoch);
        self.gateway.advance_epoch(epoch);
        self.tally.sensor_advances += 1;
        let mut map = self.hosts.map.clone();
        let claim = Command::Claim {
            role: ROLE.into(),
            holder: STANDBY.into(),
            fencing: s.copy.epoch,
        };
        if let Outcome::Changed { .. } = map.apply(&claim) {
            return Err(Violation::new(format!(
                "the sensor went on alone at epoch {epoch}, but its standby's copy (in sync at {:?}) could still claim the role",
                s.copy.epoch
            )));
        }
        Ok(())
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
        if let Some(s) = self.sensor_standby.as_mut().filter(|s| !s.adopted) {
            s.incarnation += 1;
            s.replication = Replication::new(SENSOR, s.incarnation);
            s.replication.at_epoch(epoch);
            if s.up {
                s.replication.standby(true);
            }
        }
    }

    /// The standby's token went away (its host cut off, or down).
    pub(super) fn standby_away(&mut self) {
        if let Some(s) = self.sensor_standby.as_mut().filter(|s| !s.adopted && s.up) {
            s.up = false;
            s.advanced = false;
            s.replication.standby(false);
        }
    }

    /// The standby's token is back: it is sent the whole journal now.
    pub(super) fn standby_back(&mut self) -> Result<(), Violation> {
        let Some(s) = self.sensor_standby.as_mut().filter(|s| !s.adopted && !s.up) else {
            return Ok(());
        };
        s.up = true;
        if s.lost.is_some() {
            return Ok(());
        }
        s.replication.standby(true);
        self.sync()
    }

    /// The standby's process restarted too quickly for its token to be
    /// missed: its copy is on its disk, but where it stands in the
    /// sensor's run is not.
    pub(super) fn standby_restart(&mut self) {
        if let Some(s) = self.sensor_standby.as_mut().filter(|s| !s.adopted) {
            self.tally.standby_restarts += 1;
            s.copy.position = None;
        }
    }

    /// The sensor's host is gone for good with its disk. Struck only while
    /// the standby is up (its copy then holds everything that left): one
    /// away waits for its return.
    pub(super) fn sensor_host_lost(&mut self) -> Result<(), Violation> {
        let Some(s) = self.sensor_standby.as_mut() else {
            return Ok(());
        };
        if self.calm || s.adopted || s.lost.is_some() {
            return Ok(());
        }
        if !s.up {
            self.net.at(self.now + 100, Event::SensorHostLoss);
            return Ok(());
        }
        s.lost = Some(standing(&self.gateway));
        let delay = s.rng.gen_range(TAKEOVER.0..=TAKEOVER.1);
        self.tally.sensor_host_losses += 1;
        self.journal.clear();
        self.net.at(self.now + delay, Event::SensorAdopt);
        Ok(())
    }

    /// The standby claims the sensor role through the voters, naming its
    /// copy's epoch.
    pub(super) fn sensor_adopt(&mut self) {
        let Some(s) = self.sensor_standby.as_ref().filter(|s| s.down()) else {
            return;
        };
        let command = Command::Claim {
            role: ROLE.into(),
            holder: STANDBY.into(),
            fencing: s.copy.epoch,
        };
        self.start_claim(command, Purpose::SensorAdopt);
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
        let Some(lost) = s.lost else {
            return Ok(());
        };
        let records = s
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
        s.adopted = true;
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
