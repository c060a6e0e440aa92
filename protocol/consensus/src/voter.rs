//! One voter: raft-rs's `RawNode` over its log, and the [`RoleMap`] its
//! committed entries built. A pure machine (raft-rs's own design): no
//! clock, no I/O. The caller [`tick`](Voter::tick)s it at a fixed period,
//! [`step`](Voter::step)s it with every message that came for it,
//! [`propose`](Voter::propose)s commands, and after each of those sends
//! the [`Envelope`]s [`advance`](Voter::advance) returns.

use crate::role_map::{Command, Outcome, RoleEntry, RoleMap, RolesAnswer};
use raft::eraftpb::{Entry, EntryType, HardState, Message};
use raft::storage::MemStorage;
use raft::{Config, RawNode, StateRole};
use slog::{o, Discard, Logger};

/// A voter's place in the group.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct VoterConfig {
    /// This voter's id (1 and up).
    pub id: u64,
    /// Every voter's id, this one's among them.
    pub voters: Vec<u64>,
    /// Ticks without a leader's word before a follower stands for election.
    pub election_ticks: usize,
    /// Ticks between a leader's heartbeats.
    pub heartbeat_ticks: usize,
    /// Every election timeout exactly `election_ticks`, for a seeded
    /// simulator: raft-rs draws them from `election_ticks` to twice that
    /// with a thread RNG no seed reaches, so one seed would not give one
    /// schedule. Deployments leave it false (the draw is what keeps
    /// candidates from splitting the vote).
    pub fixed_timeouts: bool,
}

/// A message for another voter.
#[derive(Debug, Clone)]
pub struct Envelope {
    pub from: u64,
    pub to: u64,
    pub message: Message,
}

impl Envelope {
    /// The bytes a driver sends: `from`, `to` (u64 little-endian) and the
    /// message in raft-rs's own protobuf encoding.
    pub fn encode(&self) -> Result<Vec<u8>, ConsensusError> {
        use protobuf::Message as _;
        let mut out = Vec::with_capacity(16 + self.message.compute_size() as usize);
        out.extend_from_slice(&self.from.to_le_bytes());
        out.extend_from_slice(&self.to.to_le_bytes());
        self.message
            .write_to_vec(&mut out)
            .map_err(|e| ConsensusError::Wire(e.to_string()))?;
        Ok(out)
    }

    /// An envelope from the bytes [`Envelope::encode`] wrote, or why not.
    pub fn decode(bytes: &[u8]) -> Result<Envelope, ConsensusError> {
        use protobuf::Message as _;
        let word = |at: usize| -> Result<u64, ConsensusError> {
            let b: [u8; 8] = bytes
                .get(at..at + 8)
                .and_then(|b| b.try_into().ok())
                .ok_or_else(|| ConsensusError::Wire(format!("{} bytes: too short", bytes.len())))?;
            Ok(u64::from_le_bytes(b))
        };
        let (from, to) = (word(0)?, word(8)?);
        let message = Message::parse_from_bytes(&bytes[16..])
            .map_err(|e| ConsensusError::Wire(e.to_string()))?;
        if message.from != from || message.to != to {
            return Err(ConsensusError::Wire(format!(
                "envelope from {from} to {to} holds a message from {} to {}",
                message.from, message.to
            )));
        }
        Ok(Envelope { from, to, message })
    }
}

/// What one [`Voter::ready`] step asks of its driver: make `persist`
/// durable, then send `send`. Raft's promises (a vote given once per term,
/// an entry acknowledged only once stored) hold across a crash only if
/// nothing in `send` leaves before `persist` is on disk.
#[derive(Debug, Clone, Default)]
pub struct Ready {
    pub persist: Persist,
    pub send: Vec<Envelope>,
}

/// The log's new entries (which replace any stored from the first one's
/// index on) and the hard state (term, vote, commit) if it changed.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Persist {
    pub entries: Vec<Entry>,
    pub hard_state: Option<HardState>,
}

impl Persist {
    pub fn is_empty(&self) -> bool {
        self.entries.is_empty() && self.hard_state.is_none()
    }
}

#[derive(Debug, thiserror::Error)]
pub enum ConsensusError {
    #[error("raft: {0}")]
    Raft(#[from] raft::Error),
    #[error("a command that does not encode: {0}")]
    Encode(#[from] postcard::Error),
    #[error("a raft message that does not decode: {0}")]
    Wire(String),
    #[error("voter {id}: not among the voters {voters:?}")]
    NotAVoter { id: u64, voters: Vec<u64> },
}

/// One voter (see the module documentation).
pub struct Voter {
    node: RawNode<MemStorage>,
    map: RoleMap,
    /// What committed commands did, oldest first, until taken.
    outcomes: Vec<Outcome>,
}

impl std::fmt::Debug for Voter {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Voter")
            .field("id", &self.node.raft.id)
            .field("term", &self.node.raft.term)
            .field("leader", &self.node.raft.leader_id)
            .field("map", &self.map)
            .finish()
    }
}

impl Voter {
    /// A voter on `storage`: a new one (`MemStorage` made with the voters'
    /// configuration), or the one a voter that stopped left behind, whose
    /// committed log rebuilds the map as it is applied again.
    pub fn new(config: &VoterConfig, storage: MemStorage) -> Result<Self, ConsensusError> {
        if !config.voters.contains(&config.id) {
            return Err(ConsensusError::NotAVoter {
                id: config.id,
                voters: config.voters.clone(),
            });
        }
        let raft_config = Config {
            id: config.id,
            election_tick: config.election_ticks,
            heartbeat_tick: config.heartbeat_ticks,
            // A leader that lost touch with a quorum steps down, so that
            // a cut-off voter does not go on believing it leads.
            check_quorum: true,
            pre_vote: true,
            min_election_tick: config.election_ticks,
            max_election_tick: if config.fixed_timeouts {
                config.election_ticks + 1
            } else {
                2 * config.election_ticks
            },
            ..Config::default()
        };
        raft_config.validate()?;
        let logger = Logger::root(Discard, o!());
        Ok(Voter {
            node: RawNode::new(&raft_config, storage, &logger)?,
            map: RoleMap::default(),
            outcomes: Vec::new(),
        })
    }

    /// Storage for a new group of `voters`.
    pub fn fresh_storage(voters: &[u64]) -> MemStorage {
        MemStorage::new_with_conf_state((voters.to_vec(), vec![]))
    }

    /// This voter's storage (what a restart starts from).
    pub fn storage(&self) -> MemStorage {
        self.node.raft.raft_log.store.clone()
    }

    pub fn id(&self) -> u64 {
        self.node.raft.id
    }

    /// Whether this voter leads its group now.
    pub fn is_leader(&self) -> bool {
        self.node.raft.state == StateRole::Leader
    }

    /// Whether this voter leads with a map that holds every claim
    /// committed so far: a new leader learns where the last one's commits
    /// end only once it commits an entry of its own term (its empty
    /// entry), and its map may lack some of them until then. Only such a
    /// voter's map is to be trusted as the group's.
    pub fn leads_with_current_map(&self) -> bool {
        self.is_leader() && self.node.raft.apply_to_current_term()
    }

    /// The leader this voter knows of (0: none).
    pub fn leader(&self) -> u64 {
        self.node.raft.leader_id
    }

    pub fn term(&self) -> u64 {
        self.node.raft.term
    }

    /// The map as this voter's committed log built it.
    pub fn map(&self) -> &RoleMap {
        &self.map
    }

    /// What this voter answers on `query/roles`: its map, with the group's
    /// leader and term as it knows them. A leader whose map may still
    /// lack its predecessor's last claims does not say it leads, so that
    /// readers wait for one that holds them.
    pub fn roles_answer(&self) -> RolesAnswer {
        RolesAnswer {
            voter: self.id(),
            leader: match self.is_leader() && !self.leads_with_current_map() {
                true => 0,
                false => self.leader(),
            },
            term: self.term(),
            roles: self
                .map
                .roles()
                .map(|(role, holding)| RoleEntry {
                    role: role.clone(),
                    holder: holding.holder.clone(),
                    epoch: holding.epoch,
                })
                .collect(),
        }
    }

    /// What committed commands did since the last call.
    pub fn take_outcomes(&mut self) -> Vec<Outcome> {
        std::mem::take(&mut self.outcomes)
    }

    /// One period of the caller's clock.
    pub fn tick(&mut self) {
        self.node.tick();
    }

    /// A message that came from another voter.
    pub fn step(&mut self, message: Message) -> Result<(), ConsensusError> {
        self.node.step(message)?;
        Ok(())
    }

    /// Proposes `command`; it is decided when committed (an
    /// [`Outcome`] then), or lost if this voter's leader changes first.
    /// A follower forwards it to the leader it knows.
    pub fn propose(&mut self, command: &Command) -> Result<(), ConsensusError> {
        let data = postcard::to_allocvec(command)?;
        self.node.propose(vec![], data)?;
        Ok(())
    }

    /// Carries the node's ready state through, for a voter whose log
    /// lives in memory only (the simulator's, which keeps the storage as a
    /// disk would): the messages to send.
    pub fn advance(&mut self) -> Vec<Envelope> {
        self.ready().send
    }

    /// Carries the node's ready state through: entries stored in the
    /// in-memory log, committed commands applied to the map; returns what
    /// the driver must make durable (a [`DurableLog`](crate::DurableLog))
    /// before it sends the messages.
    pub fn ready(&mut self) -> Ready {
        let mut out = Vec::new();
        if !self.node.has_ready() {
            return Ready::default();
        }
        let store = self.storage();
        let hard_state = store.rl().hard_state().clone();
        let mut ready = self.node.ready();
        let entries = ready.entries().clone();
        self.send(ready.take_messages(), &mut out);
        if *ready.snapshot() != raft::eraftpb::Snapshot::default() {
            // The log is never compacted, so no snapshot is sent; a store
            // that refused one would be a bug in raft-rs's contract.
            let _ = store.wl().apply_snapshot(ready.snapshot().clone());
        }
        self.apply(ready.take_committed_entries());
        if !ready.entries().is_empty() {
            let _ = store.wl().append(ready.entries());
        }
        if let Some(hs) = ready.hs() {
            store.wl().set_hardstate(hs.clone());
        }
        self.send(ready.take_persisted_messages(), &mut out);
        let mut light = self.node.advance(ready);
        if let Some(commit) = light.commit_index() {
            store.wl().mut_hard_state().set_commit(commit);
        }
        self.send(light.take_messages(), &mut out);
        self.apply(light.take_committed_entries());
        self.node.advance_apply();
        let now = store.rl().hard_state().clone();
        Ready {
            persist: Persist {
                entries,
                hard_state: (now != hard_state).then_some(now),
            },
            send: out,
        }
    }

    fn send(&self, messages: Vec<Message>, out: &mut Vec<Envelope>) {
        let from = self.id();
        out.extend(messages.into_iter().map(|message| Envelope {
            from,
            to: message.to,
            message,
        }));
    }

    fn apply(&mut self, entries: Vec<raft::eraftpb::Entry>) {
        for entry in entries {
            if entry.get_entry_type() != EntryType::EntryNormal || entry.data.is_empty() {
                // A new leader's empty entry; membership never changes.
                continue;
            }
            // Every entry was encoded by `propose` from a command, so one
            // that does not decode cannot be; it is skipped on every voter
            // alike, which keeps the maps equal.
            if let Ok(command) = postcard::from_bytes::<Command>(&entry.data) {
                let outcome = self.map.apply(&command);
                self.outcomes.push(outcome);
            }
        }
    }
}
