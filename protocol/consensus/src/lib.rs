//! Who holds each role of a deployment, decided by consensus.
//!
//! A deployment without shared storage can lose a host for good; another
//! process must then take its roles, and a host that was only cut off
//! must never act beside its successor. The voters named in a topology
//! (three or five, one per host) replicate a small map, role → (holder,
//! epoch), through Raft — tikv's raft-rs, not a protocol of our own. A
//! holder changes only by a committed claim, and every change of holder
//! raises the role's epoch; a message a role sends carries its epoch, and
//! a receiver refuses one older than the epoch it last saw for that role
//! (the fence).
//!
//! - [`RoleMap`] is the replicated state machine: how a claim or a
//!   release is decided, a pure function of the map and the command.
//! - [`Voter`] is one voter's pure machine: raft-rs's `RawNode` over its
//!   log, the map its committed entries built, and what it must send.
//!   It reads no clock and does no I/O: the caller ticks it, steps it
//!   with the messages that came, and carries out what it returns, so a
//!   seeded simulator can drive many of them through any schedule.
//!
//! - [`DurableLog`] is a voter's log on disk: what each step asks to
//!   persist, fsynced before the step's messages leave, and the storage
//!   it gives back after a crash.
//!
//! The log lives in raft-rs's `MemStorage`: the simulator keeps it across
//! a restart, as a disk would; a process reopens its [`DurableLog`]. The
//! map is rebuilt from the committed log on restart.

mod durable;
mod role_map;
mod voter;

pub use durable::{DurableError, DurableLog, KIND};
/// A voter's log in memory (raft-rs's): what [`DurableLog::open`] gives
/// back, and what a simulator keeps across a voter's restart as its disk.
pub use raft::storage::MemStorage;
pub use role_map::{Command, Holding, Outcome, RoleEntry, RoleMap, RolesAnswer};
pub use voter::{ConsensusError, Envelope, Persist, Ready, Voter, VoterConfig};
