//! The leaders' part of a schedule, as `leader/src/driver.rs` runs it:
//! each leader's [`Node`] stepped with its inputs, its outputs carried out
//! (puts, gets with a timeout, transfers, its journal on a disk that a
//! crash may cut short), and leaders crashed and started again from their
//! journal and snapshot.
//!
//! A role is acted for by its current holder and, for a while after a
//! takeover, by a former holder cut off and superseded that still runs
//! ([`Who`]); `hosts.rs` says how roles change hands.

use super::coordinator::ToCoordinator;
use super::sensor::ToSensor;
use super::{Event, Msg, World, ASK_TIMEOUT};
use crate::sim::network::Endpoint;
use crate::sim::Violation;
use idmesh_leader::journal::Kind;
use idmesh_leader::{Ask, Holder, Input, Node, Output, Timers};
use idmesh_protocol::wire::leader_to_leader::TransfersSent;
use idmesh_protocol::wire::leader_to_sensor::{Durable, Followed, Resent};
use idmesh_protocol::wire::{decode, encode};
use rand::Rng;
use std::collections::BTreeMap;
use std::time::Duration;

#[derive(Debug, Clone)]
pub(crate) enum ToLeader {
    Batch(Vec<u8>),
    /// Transfers from role `from`'s holder at `epoch`.
    Transfer {
        bytes: Vec<u8>,
        from: usize,
        epoch: u64,
    },
    /// A durable mark of role `from`'s holder at `epoch`.
    Durable {
        bytes: Vec<u8>,
        from: usize,
        epoch: u64,
    },
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
    /// Role `role`'s last snapshot, for this role's process to keep as
    /// its standby.
    StandbyCopy {
        role: usize,
        mark: Durable,
        state: Vec<u8>,
    },
    /// The standby's word that it keeps a copy (`StandbyStored` bytes).
    StandbyStored(Vec<u8>),
}

/// Who acts: role `role`'s current holder, or its `former` holder (cut
/// off and superseded, still running until it learns so).
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord)]
pub(crate) struct Who {
    pub(crate) role: usize,
    pub(crate) former: bool,
}

impl Who {
    pub(crate) fn holder(role: usize) -> Who {
        Who {
            role,
            former: false,
        }
    }

    pub(crate) fn endpoint(self) -> Endpoint {
        match self.former {
            false => Endpoint::Leader(self.role),
            true => Endpoint::Former(self.role),
        }
    }
}

/// A get a leader made, waiting for its answer.
pub(super) struct PendingAsk {
    pub(super) leader: Who,
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

/// A former holder of a role: cut off, superseded at a newer epoch, and
/// still running on its own disk until it stops.
pub(super) struct Former {
    pub(super) node: Node,
    pub(super) life: u64,
    pub(super) disk: Disk,
    pub(super) epoch: u64,
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
    /// The process holding the role, and the epoch it holds it at.
    pub(super) process: String,
    pub(super) epoch: u64,
    /// Lost with its host, or cut off and superseded: nobody acts for it
    /// until the adoption commits (no restart, no calm brings it back).
    pub(super) orphaned: bool,
    /// The former holder still running, if there is one.
    pub(super) former: Option<Former>,
    /// The standby the holder was last told.
    pub(super) standby: Option<String>,
    /// The newest epoch of each peer role whose durable mark reached the
    /// current holder since it started (its fence is at least this).
    pub(super) heard: BTreeMap<usize, u64>,
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
        timers.standby = self.hosts.standbys;
        timers
    }

    /// Starts leader `i` (again): from its disk, as `Node::recover` does
    /// for the actor (`adopted`: by another process, from its standby
    /// copy).
    pub(super) fn start_leader(&mut self, i: usize, adopted: bool) -> Result<(), Violation> {
        let timers = self.timers(i);
        let (process, epoch) = (self.leaders[i].process.clone(), self.leaders[i].epoch);
        self.record_holder(i, epoch, &process)?;
        let slot = &mut self.leaders[i];
        slot.life += 1;
        slot.heard.clear();
        slot.standby = None;
        let damaged = slot.damaged.take();
        let disk = &slot.disk;
        let (node, out) = Node::recover(
            &slot.name,
            Holder {
                process: &process,
                epoch,
            },
            disk.snapshot.as_deref(),
            disk.entries.iter().map(|(k, b)| (*k, b.as_slice())),
            adopted,
            damaged,
            timers,
            Duration::from_millis(self.now),
        )
        .map_err(|e| Violation::new(format!("{} cannot recover: {e}", slot.name)))?;
        if node.leader().durable().position < slot.published {
            return Err(Violation::new(format!(
                "{} came back (in {process} at epoch {epoch}{}) at position {} below the durable mark {} it published",
                slot.name,
                if adopted { ", adopted" } else { "" },
                node.leader().durable().position,
                slot.published
            )));
        }
        slot.node = Some(node);
        let life = slot.life;
        let phase = self.rng.gen_range(1..=250);
        self.net
            .at(self.now + phase, Event::Tick { leader: i, life });
        self.carry_out(Who::holder(i), out)?;
        self.tell_standbys()
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
                Holder {
                    process: &slot.process,
                    epoch: slot.epoch,
                },
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

    pub(super) fn node_mut(&mut self, who: Who) -> Option<&mut Node> {
        let slot = &mut self.leaders[who.role];
        match who.former {
            false => slot.node.as_mut(),
            true => slot.former.as_mut().map(|f| &mut f.node),
        }
    }

    /// The disk `who` journals to (None: a former holder gone since).
    fn disk_mut(&mut self, who: Who) -> Option<&mut Disk> {
        let slot = &mut self.leaders[who.role];
        match who.former {
            false => Some(&mut slot.disk),
            true => slot.former.as_mut().map(|f| &mut f.disk),
        }
    }

    /// The epoch `who` holds its role at.
    pub(super) fn epoch_of(&self, who: Who) -> u64 {
        let slot = &self.leaders[who.role];
        match who.former {
            false => slot.epoch,
            true => slot.former.as_ref().map_or(0, |f| f.epoch),
        }
    }

    /// `who`'s incarnation (0: none).
    pub(super) fn life_of(&self, who: Who) -> u64 {
        let slot = &self.leaders[who.role];
        match who.former {
            false => slot.life,
            true => slot.former.as_ref().map_or(0, |f| f.life),
        }
    }

    /// Hands `who` one input and carries out what it asks.
    pub(super) fn step(&mut self, who: Who, input: Input) -> Result<(), Violation> {
        let now = Duration::from_millis(self.now);
        let name = self.leaders[who.role].name.clone();
        let Some(node) = self.node_mut(who) else {
            return Ok(());
        };
        let before = node.leader().position();
        let out = node.step(now, input);
        let after = node.leader().position();
        if after < before {
            return Err(Violation::new(format!(
                "{name} went back from position {before} to {after}"
            )));
        }
        if let Some(failure) = node.failure() {
            let failure = failure.to_string();
            return Err(Violation::new(format!("{name} failed: {failure}")));
        }
        self.carry_out(who, out)
    }

    /// Does what `who`'s node asked for, as its driver does.
    pub(super) fn carry_out(&mut self, who: Who, outputs: Vec<Output>) -> Result<(), Violation> {
        for output in outputs {
            match output {
                Output::Journal { kind, bytes } => {
                    if let Some(disk) = self.disk_mut(who) {
                        disk.entries.push((kind, bytes));
                    }
                }
                Output::Send { to, seqs, body } => self.send_transfer(who, &to, &seqs, body)?,
                Output::AskFollow(follow) => {
                    let ask = self.ask(who, AskKind::Follow);
                    let bytes = encode(&follow);
                    self.tell_sensor(who, ToSensor::Follow { ask, bytes });
                }
                Output::Progress(progress) => {
                    self.tell_sensor(who, ToSensor::Progress(encode(&progress)))
                }
                Output::Unfollow(unfollow) => {
                    self.tell_sensor(who, ToSensor::Unfollow(encode(&unfollow)))
                }
                Output::AskResend(resend) => {
                    let ask = self.ask(who, AskKind::Resend);
                    let bytes = encode(&resend);
                    self.tell_sensor(who, ToSensor::Resend { ask, bytes });
                }
                Output::AskTransfers { peer, wanted } => {
                    let j = self.role_index(&peer)?;
                    let ask = self.ask(who, AskKind::Transfers(peer));
                    let bytes = encode(&wanted);
                    self.tell_leader(who, Who::holder(j), ToLeader::SentWanted { ask, bytes });
                }
                // The simulated coordinator asks for every answer: a push
                // is a shortcut whose loss the real one mends by asking,
                // so here every push is one lost.
                Output::Push(_) => {}
                Output::Answer { id, answer } => {
                    let reply = answer.map(|p| encode(&*p));
                    let partial = ToCoordinator::Partial {
                        id,
                        from: who,
                        reply,
                    };
                    let msg = Msg::Coordinator(partial);
                    self.send(who.endpoint(), Endpoint::Coordinator, msg);
                }
                Output::AnswerSent { id, answer } => {
                    // The asker is whoever made get `id`, if it still waits.
                    let Some(asker) = self.asks.get(&id).map(|a| a.leader) else {
                        continue;
                    };
                    let reply = answer.map(|t| encode(&t));
                    self.tell_leader(who, asker, ToLeader::Reply { ask: id, reply });
                }
                Output::Persist { mark } => self.persist(who, mark),
                Output::ToStandby { to, mark } => self.send_standby_copy(who, &to, mark)?,
                Output::Snapshot(state) => {
                    if let Some(disk) = self.disk_mut(who) {
                        disk.snapshot = Some(state);
                        disk.entries.clear();
                        disk.synced = 0;
                    }
                }
            }
        }
        Ok(())
    }

    /// The index of the role named `name`.
    pub(super) fn role_index(&self, name: &str) -> Result<usize, Violation> {
        self.leaders
            .iter()
            .position(|l| l.name == name)
            .ok_or_else(|| Violation::new(format!("a message for unknown role {name}")))
    }

    /// `who` sends transfers to role `to` (the first copy lost when the
    /// schedule aims at transfers).
    fn send_transfer(
        &mut self,
        who: Who,
        to: &str,
        seqs: &[u64],
        body: Vec<u8>,
    ) -> Result<(), Violation> {
        let j = self.role_index(to)?;
        let i = who.role;
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
        let epoch = self.epoch_of(who);
        let what = ToLeader::Transfer {
            bytes: body,
            from: i,
            epoch,
        };
        self.tell_leader(who, Who::holder(j), what);
        Ok(())
    }

    /// `who`'s journal is synced; a durable mark, if it has one, is
    /// published to the sensor and the other leaders.
    fn persist(&mut self, who: Who, mark: Option<Durable>) {
        if let Some(disk) = self.disk_mut(who) {
            disk.synced = disk.entries.len();
        }
        let Some(mark) = mark else {
            return;
        };
        let i = who.role;
        let slot = &mut self.leaders[i];
        slot.published = slot.published.max(mark.position);
        let bytes = encode(&mark);
        let epoch = self.epoch_of(who);
        self.tell_sensor(who, ToSensor::Durable(bytes.clone()));
        for j in (0..self.leaders.len()).filter(|&j| j != i) {
            let what = ToLeader::Durable {
                bytes: bytes.clone(),
                from: i,
                epoch,
            };
            self.tell_leader(who, Who::holder(j), what);
        }
    }

    fn tell_sensor(&mut self, who: Who, what: ToSensor) {
        let epoch = self.epoch_of(who);
        let msg = Msg::Sensor {
            from: who,
            epoch,
            what,
        };
        self.send(who.endpoint(), Endpoint::Sensor, msg);
    }

    pub(super) fn tell_leader(&mut self, from: Who, to: Who, what: ToLeader) {
        let msg = match to.former {
            false => Msg::Leader { to: to.role, what },
            true => Msg::Former { to: to.role, what },
        };
        self.send(from.endpoint(), to.endpoint(), msg);
    }

    /// Registers a get of `who`; it is answered, or times out.
    pub(super) fn ask(&mut self, who: Who, kind: AskKind) -> u64 {
        let id = self.fresh_id();
        let life = self.life_of(who);
        self.asks.insert(
            id,
            PendingAsk {
                leader: who,
                life,
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
        let who = pending.leader;
        if self.life_of(who) != pending.life {
            return Ok(());
        }
        let input = match pending.kind {
            AskKind::Follow => {
                if let Ok(followed) = reply.as_deref().map(decode::<Followed>) {
                    let followed = followed.map_err(|e| Violation::new(e.to_string()))?;
                    // Routed to the role, whichever of its holders took
                    // the reply.
                    self.routed[who.role].extend(followed.items.iter().map(|s| s.seq));
                }
                Input::Followed(reply)
            }
            AskKind::Resend => Input::Resent(reply.and_then(|bytes| {
                decode::<Resent>(&bytes)
                    .map(|r| r.batches)
                    .map_err(|e| e.to_string())
            })),
            AskKind::Transfers(peer) => {
                let result = reply
                    .and_then(|bytes| decode::<TransfersSent>(&bytes).map_err(|e| e.to_string()));
                let stale = match &result {
                    Ok(sent) if !sent.transfers.is_empty() => {
                        Some((self.role_index(&peer)?, sent.epoch))
                    }
                    _ => None,
                };
                let input = Input::Transfers { peer, result };
                return match stale {
                    Some((from, epoch)) => self.step_fenced(who, from, epoch, false, input),
                    None => self.step(who, input),
                };
            }
        };
        self.step(who, input)
    }

    pub(super) fn at_leader(&mut self, who: Who, what: ToLeader) -> Result<(), Violation> {
        if self.node_mut(who).is_none() {
            // Nobody subscribes or answers for a leader that is down.
            return Ok(());
        }
        let origin = format!("sim/{}", self.leaders[who.role].name);
        let input = match what {
            ToLeader::Batch(bytes) => Input::Message {
                kind: Kind::Batch,
                bytes,
                origin,
            },
            ToLeader::Transfer { bytes, from, epoch } => {
                let input = Input::Message {
                    kind: Kind::Transfer,
                    bytes,
                    origin,
                };
                return self.step_fenced(who, from, epoch, false, input);
            }
            ToLeader::Durable { bytes, from, epoch } => {
                let input = Input::Durable { bytes, origin };
                return self.step_fenced(who, from, epoch, true, input);
            }
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
            ToLeader::StandbyCopy { role, mark, state } => {
                return self.keep_copy(who, role, mark, state)
            }
            ToLeader::StandbyStored(bytes) => Input::StandbyStored { bytes, origin },
        };
        self.step(who, input)
    }
}
