//! The leaders' part of a schedule, as `leader/src/driver.rs` runs it:
//! each leader's [`Node`] stepped with its inputs, its outputs carried out
//! (puts, gets with a timeout, transfers, its journal on a disk that a
//! crash may cut short), and leaders crashed and started again from their
//! journal and snapshot.

use super::coordinator::ToCoordinator;
use super::sensor::ToSensor;
use super::{Event, Msg, World, ASK_TIMEOUT};
use crate::sim::network::Endpoint;
use crate::sim::Violation;
use idmesh_leader::journal::Kind;
use idmesh_leader::{Ask, Input, Node, Output, Timers};
use idmesh_protocol::wire::leader_to_leader::TransfersSent;
use idmesh_protocol::wire::leader_to_sensor::{Durable, Followed, Resent};
use idmesh_protocol::wire::{decode, encode};
use rand::Rng;
use std::time::Duration;

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

/// A get a leader made, waiting for its answer.
pub(super) struct PendingAsk {
    pub(super) leader: usize,
    pub(super) life: u64,
    pub(super) kind: AskKind,
}

pub(super) enum AskKind {
    Follow,
    Resend,
    Transfers(String),
}

/// A leader's durable state, in memory: what survives a crash.
#[derive(Default)]
pub(super) struct Disk {
    pub(super) snapshot: Option<Vec<u8>>,
    pub(super) entries: Vec<(Kind, Vec<u8>)>,
    /// Entries fsynced (a power cut loses the rest).
    pub(super) synced: usize,
}

pub(super) struct LeaderSlot {
    pub(super) name: String,
    pub(super) node: Option<Node>,
    /// Incarnation: answers to the gets of an earlier life are dropped.
    pub(super) life: u64,
    pub(super) disk: Disk,
    /// The last durable mark it published (position).
    pub(super) published: u64,
    pub(super) snapshot_every: usize,
    /// Its journal was found damaged at the crash: the restart drops this
    /// many entries (the damaged one and every one after it).
    pub(super) damaged: Option<u64>,
}

impl World {
    pub(super) fn timers(&self, i: usize) -> Timers {
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
    pub(super) fn start_leader(&mut self, i: usize) -> Result<(), Violation> {
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

    pub(super) fn crash(&mut self, i: usize) -> Result<(), Violation> {
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
    pub(super) fn step(&mut self, i: usize, input: Input) -> Result<(), Violation> {
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

    /// Does what leader `i`'s node asked for, as its driver does.
    pub(super) fn carry_out(&mut self, i: usize, outputs: Vec<Output>) -> Result<(), Violation> {
        for output in outputs {
            match output {
                Output::Journal { kind, bytes } => self.leaders[i].disk.entries.push((kind, bytes)),
                Output::Send { to, seqs, body } => self.send_transfer(i, &to, &seqs, body)?,
                Output::AskFollow(follow) => {
                    let ask = self.ask(i, AskKind::Follow);
                    let bytes = encode(&follow);
                    self.tell_sensor(i, ToSensor::Follow { ask, bytes });
                }
                Output::Progress(progress) => {
                    self.tell_sensor(i, ToSensor::Progress(encode(&progress)))
                }
                Output::Unfollow(unfollow) => {
                    self.tell_sensor(i, ToSensor::Unfollow(encode(&unfollow)))
                }
                Output::AskResend(resend) => {
                    let ask = self.ask(i, AskKind::Resend);
                    let bytes = encode(&resend);
                    self.tell_sensor(i, ToSensor::Resend { ask, bytes });
                }
                Output::AskTransfers { peer, wanted } => {
                    let Some(j) = self.leaders.iter().position(|l| l.name == peer) else {
                        return Err(Violation::new(format!("transfers asked of unknown {peer}")));
                    };
                    let ask = self.ask(i, AskKind::Transfers(peer));
                    let bytes = encode(&wanted);
                    self.tell_leader(i, j, ToLeader::SentWanted { ask, bytes });
                }
                // The simulated coordinator asks for every answer: a push
                // is a shortcut whose loss the real one mends by asking,
                // so here every push is one lost.
                Output::Push(_) => {}
                Output::Answer { id, answer } => {
                    let reply = answer.map(|p| encode(&*p));
                    let partial = ToCoordinator::Partial {
                        id,
                        leader: i,
                        reply,
                    };
                    self.send(
                        Endpoint::Leader(i),
                        Endpoint::Coordinator,
                        Msg::Coordinator(partial),
                    );
                }
                Output::AnswerSent { id, answer } => {
                    // The asker is whoever made get `id`, if it still waits.
                    let Some(asker) = self.asks.get(&id).map(|a| a.leader) else {
                        continue;
                    };
                    let reply = answer.map(|t| encode(&t));
                    self.tell_leader(i, asker, ToLeader::Reply { ask: id, reply });
                }
                Output::Persist { mark } => self.persist(i, mark),
                // The simulated leaders run without a standby
                // (`Timers::standby` off): nothing is asked of one.
                Output::ToStandby { .. } => {}
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

    /// Leader `i` sends transfers to leader `to` (the first copy lost when
    /// the schedule aims at transfers).
    fn send_transfer(
        &mut self,
        i: usize,
        to: &str,
        seqs: &[u64],
        body: Vec<u8>,
    ) -> Result<(), Violation> {
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
            return Ok(());
        }
        self.tell_leader(i, j, ToLeader::Transfer(body));
        Ok(())
    }

    /// Leader `i`'s journal is synced; a durable mark, if it has one, is
    /// published to the sensor and the other leaders.
    fn persist(&mut self, i: usize, mark: Option<Durable>) {
        let slot = &mut self.leaders[i];
        slot.disk.synced = slot.disk.entries.len();
        let Some(mark) = mark else {
            return;
        };
        slot.published = slot.published.max(mark.position);
        let bytes = encode(&mark);
        self.tell_sensor(i, ToSensor::Durable(bytes.clone()));
        for j in (0..self.leaders.len()).filter(|&j| j != i) {
            self.tell_leader(i, j, ToLeader::Durable(bytes.clone()));
        }
    }

    fn tell_sensor(&mut self, i: usize, what: ToSensor) {
        let msg = Msg::Sensor { from: i, what };
        self.send(Endpoint::Leader(i), Endpoint::Sensor, msg);
    }

    fn tell_leader(&mut self, i: usize, j: usize, what: ToLeader) {
        let msg = Msg::Leader { to: j, what };
        self.send(Endpoint::Leader(i), Endpoint::Leader(j), msg);
    }

    /// Registers a get of leader `i`; it is answered, or times out.
    pub(super) fn ask(&mut self, i: usize, kind: AskKind) -> u64 {
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
    pub(super) fn answer_ask(
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
                result: reply
                    .and_then(|bytes| decode::<TransfersSent>(&bytes).map_err(|e| e.to_string())),
            },
        };
        self.step(i, input)
    }

    pub(super) fn at_leader(&mut self, i: usize, what: ToLeader) -> Result<(), Violation> {
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
}
