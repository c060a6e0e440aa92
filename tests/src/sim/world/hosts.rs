//! Hosts, standbys and epochs, as `leader/src/host.rs` runs them: every
//! role is held by a process at an epoch of the voters' map (`voters.rs`:
//! raft-rs voters on the simulated wire); each role sends its snapshots to its standby (the
//! process that would adopt it) through the simulated network and hears
//! back what it holds; and two faults change who holds a role:
//!
//! - a host lost for good with its disk: its role is adopted by the heir
//!   process, from that process's standby copy (no journal, `adopted`),
//!   at the next epoch by a claim fencing off the old one;
//! - a holder cut off long enough to be superseded the same way, which
//!   keeps running at its old epoch; the cut heals, its messages reach the
//!   sensor, the peers and the coordinator, and the fence must refuse
//!   them once the new epoch was heard. It stops a while later, when it
//!   learns that the map moved on.
//!
//! The checks: no two processes are ever recorded holding one role at one
//! epoch, and a holder runs only at the epoch the map gives it; no
//! receiver applies a message older than the newest epoch it has heard
//! from that role (each such message must be refused, and is counted); an
//! adopted role comes back no lower than the durable mark the role
//! published (the standby rule), which also keeps it from needing a batch
//! the sensor forgot.

use super::leader::{Disk, Former, ToLeader, Who};
use super::voters::Purpose;
use super::{Event, Ms, World};
use crate::sim::network::Endpoint;
use crate::sim::Violation;
use idmesh_claims::Claimed;
use idmesh_consensus::{Command, RoleMap};
use idmesh_leader::Input;
use idmesh_protocol::wire::leader_to_leader::StandbyStored;
use idmesh_protocol::wire::leader_to_sensor::Durable;
use idmesh_protocol::wire::{encode, VERSION};
use rand::Rng;
use rand_chacha::ChaCha8Rng;
use std::collections::{BTreeMap, BTreeSet};

/// How long after its holder is gone its heir claims the role: its token
/// gone, the takeover time passed (ms).
const TAKEOVER: (Ms, Ms) = (300, 1500);

/// Who holds what, and where standby copies are kept.
pub(super) struct Hosts {
    /// The voters' committed map, role → (holder, epoch): that of the
    /// longest history a voter applied.
    pub(super) map: RoleMap,
    /// Every (role, epoch) a holder was started at, and its process.
    pub(super) held: BTreeMap<(usize, u64), String>,
    /// The processes alive and reachable (their tokens up).
    pub(super) alive: BTreeSet<String>,
    /// The standby copies on each process's disk: (process, role) → the
    /// snapshot's mark and the snapshot.
    pub(super) copies: BTreeMap<(String, usize), (Durable, Vec<u8>)>,
    /// Roles keep standbys (this schedule has host faults).
    pub(super) standbys: bool,
    /// The draws of the host faults (their own stream: a schedule
    /// without them draws as it did before they existed).
    pub(super) rng: ChaCha8Rng,
}

/// A host fault a schedule holds.
#[derive(Debug, Clone, Copy)]
pub(crate) enum HostFault {
    /// The process of a role is gone for good, with its disk.
    Lost,
    /// The holder of a role is cut off, superseded, and heals later.
    Superseded,
}

impl World {
    /// Commits `process`'s claim of role `i` (fencing off `fencing`), and
    /// returns the epoch it wins.
    pub(super) fn claim(
        &mut self,
        i: usize,
        process: &str,
        fencing: Option<u64>,
    ) -> Result<u64, Violation> {
        let role = self.leaders[i].name.clone();
        self.claim_role(&role, process, fencing)
    }

    /// Commits `process`'s claim of `role` (a leader's or the sensor's),
    /// fencing off `fencing`, in one step (`World::commit_now`: the
    /// roles' first claims), and returns the epoch it wins.
    pub(super) fn claim_role(
        &mut self,
        role: &str,
        process: &str,
        fencing: Option<u64>,
    ) -> Result<u64, Violation> {
        let command = Command::Claim {
            role: role.to_string(),
            holder: process.to_string(),
            fencing,
        };
        match self.commit_now(&command)? {
            Claimed::Won(epoch) => Ok(epoch),
            other => Err(Violation::new(format!(
                "{process}'s claim of {role} fencing {fencing:?} was not won: {other:?}"
            ))),
        }
    }

    /// `process` starts holding role `i` at `epoch`: the map must say so,
    /// and no other process may ever have held it at that epoch.
    pub(super) fn record_holder(
        &mut self,
        i: usize,
        epoch: u64,
        process: &str,
    ) -> Result<(), Violation> {
        let role = &self.leaders[i].name;
        let holding = self.hosts.map.get(role);
        if holding.is_none_or(|h| h.epoch != epoch || h.holder.as_deref() != Some(process)) {
            return Err(Violation::new(format!(
                "{process} runs {role} at epoch {epoch}, but the map says {holding:?}"
            )));
        }
        let recorded = self
            .hosts
            .held
            .entry((i, epoch))
            .or_insert_with(|| process.to_string());
        if recorded != process {
            return Err(Violation::new(format!(
                "two processes held {role} at epoch {epoch}: {recorded} and {process}"
            )));
        }
        Ok(())
    }

    /// The roles whose holder's process is alive and reachable.
    fn live_roles(&self) -> Vec<usize> {
        (0..self.leaders.len())
            .filter(|&j| {
                let slot = &self.leaders[j];
                !slot.orphaned && self.hosts.alive.contains(&slot.process)
            })
            .collect()
    }

    /// The role that inherits role `i`: the next live one after it, among
    /// those `among` keeps, cyclically (`idmesh_leader::host`'s heir).
    fn heir(&self, i: usize, among: impl Fn(usize) -> bool) -> Option<usize> {
        let live = self.live_roles();
        let count = self.leaders.len();
        (1..count)
            .map(|k| (i + k) % count)
            .find(|j| live.contains(j) && among(*j))
    }

    /// Tells every running holder its standby, if it changed: the heir of
    /// its role among the roles of the other processes.
    pub(super) fn tell_standbys(&mut self) -> Result<(), Violation> {
        if !self.hosts.standbys {
            return Ok(());
        }
        for i in 0..self.leaders.len() {
            if self.leaders[i].node.is_none() {
                continue;
            }
            let process = self.leaders[i].process.clone();
            let to = self
                .heir(i, |j| self.leaders[j].process != process)
                .map(|j| self.leaders[j].name.clone());
            if self.leaders[i].standby != to {
                self.leaders[i].standby.clone_from(&to);
                self.step(Who::holder(i), Input::Standby(to))?;
            }
        }
        Ok(())
    }

    /// `who` sends its last snapshot (of mark `mark`) to standby `to`. A
    /// former holder's copies are not modelled: it is cut off from the
    /// map, and its heir holds the role.
    pub(super) fn send_standby_copy(
        &mut self,
        who: Who,
        to: &str,
        mark: Durable,
    ) -> Result<(), Violation> {
        let j = self.role_index(to)?;
        if who.former {
            return Ok(());
        }
        let Some(state) = self.leaders[who.role].disk.snapshot.clone() else {
            return Ok(());
        };
        self.tally.standby_copies += 1;
        let copy = ToLeader::StandbyCopy {
            role: who.role,
            mark,
            state,
        };
        self.tell_leader(who, Who::holder(j), copy);
        Ok(())
    }

    /// Role `role`'s snapshot reached `who`: its process keeps it on its
    /// disk, and says so to the role.
    pub(super) fn keep_copy(
        &mut self,
        who: Who,
        role: usize,
        mark: Durable,
        state: Vec<u8>,
    ) -> Result<(), Violation> {
        if who.former {
            return Ok(());
        }
        let process = self.leaders[who.role].process.clone();
        // As `idmesh_leader::standby::keep`: a copy behind the one kept
        // (reordered on the way) leaves it, and the word names it.
        let key = (process.clone(), role);
        let mark = match self.hosts.copies.get(&key) {
            Some((kept, _)) if behind(&mark, kept) => kept.clone(),
            _ => {
                self.hosts.copies.insert(key, (mark.clone(), state));
                mark
            }
        };
        let stored = StandbyStored {
            version: VERSION,
            role: self.leaders[role].name.clone(),
            standby: self.leaders[who.role].name.clone(),
            host: process,
            mark,
        };
        let what = ToLeader::StandbyStored(encode(&stored));
        self.tell_leader(who, Who::holder(role), what);
        Ok(())
    }

    /// Whether role `p` may be struck by a host fault now: standbys kept,
    /// faults still on, and its process hosts it alone and is alive.
    fn may_strike(&self, p: usize) -> bool {
        let slot = &self.leaders[p];
        let alone = self
            .leaders
            .iter()
            .enumerate()
            .all(|(j, l)| j == p || l.process != slot.process);
        self.hosts.standbys
            && !self.calm
            && !slot.orphaned
            && slot.former.is_none()
            && alone
            && self.hosts.alive.contains(&slot.process)
    }

    /// Role `p`'s process is gone for good with its disk (its journal,
    /// its snapshot, the standby copies it kept): the role waits for its
    /// adoption.
    pub(super) fn host_lost(&mut self, p: usize) -> Result<(), Violation> {
        if !self.may_strike(p) {
            return Ok(());
        }
        self.tally.host_losses += 1;
        let slot = &mut self.leaders[p];
        let process = slot.process.clone();
        slot.node = None;
        slot.life += 1;
        slot.disk = Disk::default();
        slot.damaged = None;
        slot.orphaned = true;
        self.hosts.alive.remove(&process);
        self.hosts.copies.retain(|(at, _), _| *at != process);
        let delay = self.hosts.rng.gen_range(TAKEOVER.0..=TAKEOVER.1);
        self.net.at(self.now + delay, Event::Adopt(p));
        self.tell_standbys()
    }

    /// Role `p`'s holder is cut off for longer than the takeover: it goes
    /// on running as a former holder at its epoch, its role is adopted
    /// elsewhere, then the cut heals and it stops a while later.
    pub(super) fn superseded(&mut self, p: usize) -> Result<(), Violation> {
        if !self.may_strike(p) || self.leaders[p].node.is_none() {
            return Ok(());
        }
        self.tally.superseded += 1;
        let life = self.fresh_id();
        let slot = &mut self.leaders[p];
        let Some(node) = slot.node.take() else {
            return Ok(());
        };
        let (old_life, process) = (slot.life, slot.process.clone());
        slot.life += 1;
        slot.damaged = None;
        slot.orphaned = true;
        slot.former = Some(Former {
            node,
            life,
            disk: std::mem::take(&mut slot.disk),
            epoch: slot.epoch,
        });
        // Its gets still out are its own.
        for ask in self.asks.values_mut() {
            if ask.leader == Who::holder(p) && ask.life == old_life {
                ask.leader.former = true;
                ask.life = life;
            }
        }
        self.hosts.alive.remove(&process);
        self.net.isolate(Endpoint::Former(p));
        let rng = &mut self.hosts.rng;
        let phase = rng.gen_range(1..=250);
        let adopt = self.now + rng.gen_range(TAKEOVER.0..=TAKEOVER.1);
        self.net
            .at(self.now + phase, Event::FormerTick { leader: p, life });
        // Its cut heals only once the claim is won (`adopted`).
        self.net.at(adopt, Event::Adopt(p));
        self.tell_standbys()
    }

    /// The heir's process claims orphaned role `p` through the voters,
    /// fencing off the epoch it was held at.
    pub(super) fn adopt(&mut self, p: usize) -> Result<(), Violation> {
        if !self.leaders[p].orphaned {
            return Ok(());
        }
        let Some(heir) = self.heir(p, |_| true) else {
            return Err(Violation::new(format!(
                "no process left to adopt {}",
                self.leaders[p].name
            )));
        };
        let adopter = self.leaders[heir].process.clone();
        let command = Command::Claim {
            role: self.leaders[p].name.clone(),
            holder: adopter.clone(),
            fencing: Some(self.leaders[p].epoch),
        };
        self.start_claim(command, Purpose::Adopt { role: p, adopter });
        Ok(())
    }

    /// `adopter`'s claim of orphaned role `p` was won at `epoch`: the role
    /// starts there, from the standby copy that process keeps (or from
    /// nothing, if it keeps none).
    pub(super) fn adopted(
        &mut self,
        p: usize,
        adopter: String,
        epoch: u64,
    ) -> Result<(), Violation> {
        let copy = self.hosts.copies.get(&(adopter.clone(), p)).cloned();
        self.tally.adoptions += 1;
        self.tally.adopted_from_copies += copy.is_some() as u64;
        let slot = &mut self.leaders[p];
        slot.process = adopter;
        slot.epoch = epoch;
        slot.disk = Disk {
            snapshot: copy.map(|(_, state)| state),
            ..Disk::default()
        };
        slot.orphaned = false;
        if slot.former.is_some() {
            // The former holder's cut heals, and a while later it learns
            // that the map moved on.
            let rng = &mut self.hosts.rng;
            let heal = self.now + rng.gen_range(200..=2000);
            let stop = heal + rng.gen_range(500..=3000);
            self.net.at(heal, Event::HealFormer(p));
            self.net.at(stop, Event::StopFormer(p));
        }
        self.start_leader(p, true)
    }

    /// A former holder's sweep.
    pub(super) fn former_tick(&mut self, p: usize, life: u64) -> Result<(), Violation> {
        let who = Who {
            role: p,
            former: true,
        };
        if self.life_of(who) != life {
            return Ok(());
        }
        self.step(who, Input::Tick)?;
        self.net
            .at(self.now + 250, Event::FormerTick { leader: p, life });
        Ok(())
    }

    /// The former holder learns that the map moved on, and stops.
    pub(super) fn stop_former(&mut self, p: usize) {
        self.leaders[p].former = None;
        self.net.heal(Endpoint::Former(p));
    }

    /// Hands the current holder `who` an input from role `from`'s holder
    /// at `epoch`. If it has heard a newer epoch of that role, the input
    /// must be refused (its refusals grow) and is counted as fenced;
    /// `raises`: a message whose admission raises the receiver's fence.
    pub(super) fn step_fenced(
        &mut self,
        who: Who,
        from: usize,
        epoch: u64,
        raises: bool,
        input: Input,
    ) -> Result<(), Violation> {
        if who.former {
            return self.step(who, input);
        }
        let heard = self.leaders[who.role].heard.get(&from).copied();
        let Some(newest) = heard.filter(|&h| epoch < h) else {
            if raises {
                let heard = self.leaders[who.role].heard.entry(from).or_insert(epoch);
                *heard = (*heard).max(epoch);
            }
            return self.step(who, input);
        };
        let refused = |world: &mut World| {
            world
                .node_mut(who)
                .map_or(0, |n| n.leader().stats().rejected)
        };
        let before = refused(self);
        self.step(who, input)?;
        if refused(self) <= before {
            return Err(Violation::new(format!(
                "{} applied a message of {} at epoch {epoch}, older than the epoch {newest} it had heard",
                self.leaders[who.role].name, self.leaders[from].name
            )));
        }
        self.tally.fenced += 1;
        Ok(())
    }
}

/// Whether `mark` is behind `than`: past it in neither field, and not the
/// same.
fn behind(mark: &Durable, than: &Durable) -> bool {
    mark.batch <= than.batch
        && mark.position <= than.position
        && (mark.batch, mark.position) != (than.batch, than.position)
}
