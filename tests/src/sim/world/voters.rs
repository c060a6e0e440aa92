//! The voters, as `voter/src/driver.rs` runs them, and a claimant's word
//! with them, as `idmesh_claims::Claims` has it: who holds each role is
//! decided by three raft-rs voters (`idmesh_consensus::Voter`, the real
//! machine, on an in-memory log that a restart keeps, as its disk would).
//!
//! In the schedules that claim a role mid-stream (host faults, or a
//! sensor standby) the voters run on the simulated clock: ticked every
//! [`TICK`] ms, their raft messages on the schedule's faulty wire (lost,
//! doubled, delayed), one of them crashed or cut off for a while and back
//! now and then, or lost for good; in some schedules two of them, the
//! majority, for a while, and no claim is decided until one is back. The
//! holders' leases are not modelled (a holder that reads no map for five
//! seconds stops its role): the roles run on through such a loss, which
//! is safe, since no successor can win a claim without a majority.
//! A claim is made as a process makes it: proposed to every voter (the
//! leader alone takes it), then, after a wait that doubles, every voter's
//! map read back through the wire, the newest leading one's kept
//! (`RolesAnswer::newest`) and the claim decided by `claim_decision`, or
//! proposed again. The adoption that waits on it goes on only once won.
//!
//! Two claims are made in one step instead ([`World::commit_now`]): the
//! roles' first claims, before the stream, and the sensor's advance when
//! it goes on without its standby, which its driver waits for before the
//! records leave (the standby exchange is one blocking step here too).
//! Their raft messages are then carried at once, with no faults, and the
//! voters ticked in that same instant while no leader is known.
//!
//! The check: every voter applies the one history of commands, in one
//! order — each outcome a voter applies, also again from its log after a
//! restart, must be the one any voter applied at that place. The map the
//! other checks read is the one of the longest history
//! (`Hosts::map`).

use super::network::Endpoint;
use super::{Event, Ms, Msg, World};
use crate::sim::Violation;
use idmesh_claims::{advance_decision, claim_decision, Claimed};
use idmesh_consensus::{Command, Envelope, MemStorage, Outcome, RolesAnswer, Voter, VoterConfig};
use rand::Rng;
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use std::collections::{BTreeMap, VecDeque};

/// How many voters; the period of their clock (as a deployment's voters:
/// elections after ten ticks or more, heartbeats every two).
const VOTERS: u64 = 3;
const TICK: Ms = 100;

/// How long a claimant waits first, and at most, between proposing and
/// reading the map back (`Claims::decide`); how long it gathers the
/// voters' answers to one read.
const FIRST_WAIT: Ms = 100;
const LONGEST_WAIT: Ms = 1000;
const READ_WINDOW: Ms = 250;

/// What a claimant's claim is for: what goes on once it is won.
#[derive(Debug, Clone)]
pub(super) enum Purpose {
    /// Orphaned leader role `role`, by process `adopter`.
    Adopt { role: usize, adopter: String },
    /// The sensor role, by its standby.
    SensorAdopt,
}

/// What happens to the voters at a point of virtual time.
#[derive(Debug, Clone)]
pub(crate) enum VoterEvent {
    /// A period of their clock.
    Tick,
    /// `voters` voters (one, or two: the majority) crash (`crash`) or are
    /// cut off; they are back.
    Fault {
        crash: bool,
        voters: usize,
    },
    Back,
    /// A claimant reads the map back, and decides on what it read.
    ClaimRead(u64),
    ClaimDecide(u64),
}

/// A message for a voter.
#[derive(Debug, Clone)]
pub(crate) enum ToVoter {
    Raft(Envelope),
    Propose(Command),
    /// Claim `claim`'s read of the map (`query/roles`).
    Read {
        claim: u64,
    },
}

/// A claim under way.
struct Claim {
    command: Command,
    purpose: Purpose,
    wait: Ms,
    answers: Vec<RolesAnswer>,
}

/// The voters of a schedule.
pub(super) struct Voters {
    machines: Vec<Option<Voter>>,
    disks: Vec<MemStorage>,
    configs: Vec<VoterConfig>,
    /// Outcomes each voter applied since it last started.
    applied: Vec<usize>,
    /// The one history every voter applies.
    history: Vec<Outcome>,
    /// They run on the clock (this schedule claims mid-stream).
    clocked: bool,
    /// The voters cut off now.
    cut: Vec<u64>,
    claims: BTreeMap<u64, Claim>,
    /// Raft messages carried at once by `commit_now`.
    instant: Option<VecDeque<Envelope>>,
    /// Their own draws (a schedule without them draws as before).
    pub(super) rng: ChaCha8Rng,
}

impl Voters {
    pub(super) fn new() -> Result<Voters, Violation> {
        let ids: Vec<u64> = (1..=VOTERS).collect();
        let configs: Vec<VoterConfig> = ids
            .iter()
            .map(|&id| VoterConfig {
                id,
                voters: ids.clone(),
                // Fixed timeouts, one schedule per seed; apart, or the
                // voters, ticked together, would all stand at once and
                // split the vote for ever (raft-rs draws them apart from
                // a thread RNG no seed reaches).
                election_ticks: 10 + 3 * (id as usize - 1),
                heartbeat_ticks: 2,
                fixed_timeouts: true,
            })
            .collect();
        let disks: Vec<MemStorage> = ids.iter().map(|_| Voter::fresh_storage(&ids)).collect();
        let machines = configs
            .iter()
            .zip(&disks)
            .map(|(c, d)| Voter::new(c, d.clone()).map(Some))
            .collect::<Result<Vec<_>, _>>()
            .map_err(|e| Violation::setup(e.to_string()))?;
        Ok(Voters {
            machines,
            disks,
            configs,
            applied: vec![0; VOTERS as usize],
            history: Vec::new(),
            clocked: false,
            cut: Vec::new(),
            claims: BTreeMap::new(),
            instant: None,
            rng: ChaCha8Rng::seed_from_u64(0),
        })
    }

    fn up(&self, id: u64) -> bool {
        self.machines[id as usize - 1].is_some()
    }

    /// The map of the newest voter that leads with every commit applied.
    fn leading_map(&self) -> Option<RolesAnswer> {
        RolesAnswer::newest(self.machines.iter().flatten().map(Voter::roles_answer))
    }
}

impl World {
    /// The voters run on the clock from `seed`'s stream, with one fault
    /// drawn before `span`: a voter (the leader, half the time) crashed
    /// and restarted, or cut off and healed; half the crashes are for
    /// good, its host lost (the other two decide from then on). Where
    /// `majority_may_go`, a quarter of the faults strike two voters for a
    /// while: no claim is decided until one is back (not where the
    /// sensor's advance, committed within one step, may need them).
    pub(super) fn clock_voters(&mut self, seed: u64, span: Ms, majority_may_go: bool) {
        let v = &mut self.voters;
        v.clocked = true;
        v.rng = ChaCha8Rng::seed_from_u64(seed ^ 0x0070_7e55);
        self.net
            .at(self.now + TICK, Event::Voters(VoterEvent::Tick));
        if v.rng.gen_bool(0.75) {
            let at = v.rng.gen_range(0..span);
            let back = at + v.rng.gen_range(200..=3000);
            let crash = v.rng.gen_bool(0.5);
            let voters = match majority_may_go && v.rng.gen_bool(0.25) {
                true => 2,
                false => 1,
            };
            self.net
                .at(at, Event::Voters(VoterEvent::Fault { crash, voters }));
            if !crash || voters > 1 || v.rng.gen_bool(0.5) {
                self.net.at(back, Event::Voters(VoterEvent::Back));
            }
        }
    }

    /// What `event` does to the voters and the claims under way.
    pub(super) fn voters_event(&mut self, event: VoterEvent) -> Result<(), Violation> {
        match event {
            VoterEvent::Tick => self.voter_tick(),
            VoterEvent::Fault { crash, voters } => {
                if !self.calm {
                    self.voter_fault(crash, voters);
                }
                Ok(())
            }
            VoterEvent::Back => self.voter_back(),
            VoterEvent::ClaimRead(id) => {
                self.claim_read(id);
                Ok(())
            }
            VoterEvent::ClaimDecide(id) => self.claim_decide(id),
        }
    }

    /// `count` voters fail: the leader or one drawn, and the next ones.
    fn voter_fault(&mut self, crash: bool, count: usize) {
        let v = &mut self.voters;
        let leader = v.leading_map().map(|m| m.voter);
        let first = match leader.filter(|_| v.rng.gen_bool(0.5)) {
            Some(id) => id,
            None => v.rng.gen_range(1..=VOTERS),
        };
        self.tally.voter_faults += 1;
        self.tally.voter_majority_losses += (count > 1) as u64;
        for k in 0..count as u64 {
            let id = (first - 1 + k) % VOTERS + 1;
            match crash {
                true => v.machines[id as usize - 1] = None,
                false => {
                    v.cut.push(id);
                    self.net.isolate(Endpoint::Voter(id));
                }
            }
        }
    }

    /// The failed voters are back: restarted from their logs, or healed.
    fn voter_back(&mut self) -> Result<(), Violation> {
        for id in std::mem::take(&mut self.voters.cut) {
            self.net.heal(Endpoint::Voter(id));
        }
        for i in 0..VOTERS as usize {
            if self.voters.machines[i].is_none() {
                let v = &mut self.voters;
                let voter = Voter::new(&v.configs[i], v.disks[i].clone())
                    .map_err(|e| Violation::new(format!("voter {} cannot restart: {e}", i + 1)))?;
                v.machines[i] = Some(voter);
                // It applies its committed log again, from the start.
                v.applied[i] = 0;
                self.pump(i as u64 + 1)?;
            }
        }
        Ok(())
    }

    /// One period of the voters' clock.
    fn voter_tick(&mut self) -> Result<(), Violation> {
        self.tick_voters()?;
        self.net
            .at(self.now + TICK, Event::Voters(VoterEvent::Tick));
        Ok(())
    }

    /// Every voter up ticks once and carries its ready state through.
    fn tick_voters(&mut self) -> Result<(), Violation> {
        for id in 1..=VOTERS {
            if let Some(voter) = self.voters.machines[id as usize - 1].as_mut() {
                voter.tick();
                self.pump(id)?;
            }
        }
        Ok(())
    }

    /// A message reached voter `to`.
    pub(super) fn at_voter(&mut self, to: u64, what: ToVoter) -> Result<(), Violation> {
        let Some(voter) = self.voters.machines[to as usize - 1].as_mut() else {
            return Ok(());
        };
        match what {
            // What raft refuses it takes as lost.
            ToVoter::Raft(envelope) => {
                let _ = voter.step(envelope.message);
            }
            // The leader alone takes a proposal (`voter/src/driver.rs`).
            ToVoter::Propose(command) => {
                if voter.is_leader() {
                    let _ = voter.propose(&command);
                }
            }
            ToVoter::Read { claim } => {
                let answer = voter.roles_answer();
                let reply = Msg::Claimant { claim, answer };
                self.send_voters(Endpoint::Voter(to), Endpoint::Claimant, reply);
                return Ok(());
            }
        }
        self.pump(to)
    }

    /// Voter `id` carries its ready state through: its messages go on the
    /// wire (or at once, in `commit_now`), and what it applied is checked
    /// against the one history.
    fn pump(&mut self, id: u64) -> Result<(), Violation> {
        let i = id as usize - 1;
        let Some(voter) = self.voters.machines[i].as_mut() else {
            return Ok(());
        };
        let sent = voter.advance();
        let outcomes = voter.take_outcomes();
        let mut extended = false;
        for outcome in outcomes {
            let at = self.voters.applied[i];
            match self.voters.history.get(at) {
                Some(first) if *first != outcome => {
                    return Err(Violation::new(format!(
                        "voter {id} applied {outcome:?} as command {at}, where another applied {first:?}"
                    )))
                }
                Some(_) => {}
                None => {
                    self.voters.history.push(outcome);
                    extended = true;
                }
            }
            self.voters.applied[i] += 1;
        }
        if extended {
            if let Some(voter) = &self.voters.machines[i] {
                self.hosts.map = voter.map().clone();
            }
        }
        for envelope in sent {
            self.tally.voter_messages += 1;
            match self.voters.instant.as_mut() {
                Some(queue) => queue.push_back(envelope),
                None => {
                    let (from, to) = (envelope.from, envelope.to);
                    let msg = Msg::Voter {
                        to,
                        what: ToVoter::Raft(envelope),
                    };
                    self.send_voters(Endpoint::Voter(from), Endpoint::Voter(to), msg);
                }
            }
        }
        Ok(())
    }

    /// Puts `msg` on the wire with the voters' own draws.
    fn send_voters(&mut self, from: Endpoint, to: Endpoint, msg: Msg) {
        let _ = self.net.send(
            &mut self.voters.rng,
            self.now,
            from,
            to,
            Event::Deliver(msg),
        );
    }

    /// Starts claiming for `purpose` with `command`.
    pub(super) fn start_claim(&mut self, command: Command, purpose: Purpose) {
        let id = self.fresh_id();
        self.tally.claims += 1;
        let claim = Claim {
            command,
            purpose,
            wait: FIRST_WAIT,
            answers: Vec::new(),
        };
        self.voters.claims.insert(id, claim);
        self.propose(id);
    }

    /// Claim `id` is proposed to every voter; the map is read back after
    /// its wait, which doubles each time.
    fn propose(&mut self, id: u64) {
        let Some(claim) = self.voters.claims.get_mut(&id) else {
            return;
        };
        let (command, wait) = (claim.command.clone(), claim.wait);
        claim.wait = (claim.wait * 2).min(LONGEST_WAIT);
        for to in 1..=VOTERS {
            let msg = Msg::Voter {
                to,
                what: ToVoter::Propose(command.clone()),
            };
            self.send_voters(Endpoint::Claimant, Endpoint::Voter(to), msg);
        }
        self.net
            .at(self.now + wait, Event::Voters(VoterEvent::ClaimRead(id)));
    }

    /// Claim `id` reads every voter's map.
    fn claim_read(&mut self, id: u64) {
        let Some(claim) = self.voters.claims.get_mut(&id) else {
            return;
        };
        claim.answers.clear();
        for to in 1..=VOTERS {
            let msg = Msg::Voter {
                to,
                what: ToVoter::Read { claim: id },
            };
            self.send_voters(Endpoint::Claimant, Endpoint::Voter(to), msg);
        }
        self.net.at(
            self.now + READ_WINDOW,
            Event::Voters(VoterEvent::ClaimDecide(id)),
        );
    }

    /// A voter's map reached claim `id`'s claimant.
    pub(super) fn claimant_heard(&mut self, id: u64, answer: RolesAnswer) {
        if let Some(claim) = self.voters.claims.get_mut(&id) {
            claim.answers.push(answer);
        }
    }

    /// Claim `id`'s read is over: decided by the newest leading map, or
    /// proposed again.
    fn claim_decide(&mut self, id: u64) -> Result<(), Violation> {
        let Some(claim) = self.voters.claims.get_mut(&id) else {
            return Ok(());
        };
        let answers = std::mem::take(&mut claim.answers);
        let decided = RolesAnswer::newest(answers).and_then(|map| decision(&claim.command, &map));
        match decided {
            None => {
                self.propose(id);
                Ok(())
            }
            Some(Claimed::Won(epoch)) => {
                let Some(claim) = self.voters.claims.remove(&id) else {
                    return Ok(());
                };
                self.claim_won(claim.purpose, epoch)
            }
            Some(other) => Err(Violation::new(format!(
                "{:?}: the claim of an orphaned role was not won: {other:?}",
                claim.command
            ))),
        }
    }

    /// What a claim won for `purpose` at `epoch` lets go on.
    fn claim_won(&mut self, purpose: Purpose, epoch: u64) -> Result<(), Violation> {
        match purpose {
            Purpose::Adopt { role, adopter } => self.adopted(role, adopter, epoch),
            Purpose::SensorAdopt => self.sensor_adopted_at(epoch),
        }
    }

    /// `command` committed in this instant: its raft messages carried at
    /// once and without faults, the voters ticked while none leads; the
    /// map's answer to it.
    pub(super) fn commit_now(&mut self, command: &Command) -> Result<Claimed, Violation> {
        self.voters.instant = Some(VecDeque::new());
        let decided = self.commit_instantly(command);
        self.voters.instant = None;
        decided
    }

    fn commit_instantly(&mut self, command: &Command) -> Result<Claimed, Violation> {
        let mut proposed = None;
        for _ in 0..500 {
            let leading = self.voters.leading_map();
            if let Some(decided) = leading.as_ref().and_then(|map| decision(command, map)) {
                return Ok(decided);
            }
            match leading {
                // A new leader: proposed to it.
                Some(map) if proposed != Some(map.term) => {
                    proposed = Some(map.term);
                    if let Some(voter) = self.voters.machines[map.voter as usize - 1].as_mut() {
                        let _ = voter.propose(command);
                    }
                    self.pump(map.voter)?;
                }
                // None, or one that cannot commit (cut off): time passes
                // for the voters until another is elected.
                _ => self.tick_voters()?,
            }
            self.carry_instantly()?;
        }
        Err(Violation::new(format!(
            "the voters did not decide {command:?} in one step"
        )))
    }

    /// Carries every raft message `commit_now` queued, and what they
    /// make the voters send, to voters up and not cut off.
    fn carry_instantly(&mut self) -> Result<(), Violation> {
        while let Some(envelope) = self.voters.instant.as_mut().and_then(VecDeque::pop_front) {
            let to = envelope.to;
            if !self.voters.up(to)
                || self
                    .voters
                    .cut
                    .iter()
                    .any(|&c| c == to || c == envelope.from)
            {
                continue;
            }
            if let Some(voter) = self.voters.machines[to as usize - 1].as_mut() {
                let _ = voter.step(envelope.message);
            }
            self.pump(to)?;
        }
        Ok(())
    }
}

/// What `map` says of `command`: a claim's or an advance's decision
/// (`idmesh_claims`), None while undecided.
fn decision(command: &Command, map: &RolesAnswer) -> Option<Claimed> {
    match command {
        Command::Claim {
            role,
            holder,
            fencing,
        } => claim_decision(map.get(role), holder, *fencing),
        Command::Advance { role, holder, from } => advance_decision(map.get(role), holder, *from),
        Command::Release { .. } => None,
    }
}
