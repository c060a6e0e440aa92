//! # idmesh-voter — one member of the group that decides who holds a role
//!
//! A deployment without shared storage names three or five voters in its
//! topology, one per host. Together they replicate the role map (role →
//! holder, epoch) through Raft (`idmesh-consensus`, tikv's raft-rs); a
//! majority alive decides, so the loss of any one host leaves the map
//! decidable. This crate is the voter's process: the pure machine is
//! `idmesh_consensus::Voter`, and [`driver`] is its I/O — the log on disk
//! (`DurableLog`, fsynced before a step's messages leave), raft's messages
//! over Zenoh (`<prefix>/raft/<id>`), commands proposed on
//! `<prefix>/raft/propose`, and the map answered on `<prefix>/query/roles`.
//!
//! Nothing here decides *when* a role should move: the processes that
//! want a role propose claims ([`propose`]), naming the epoch they fence
//! off, and read the map back.

pub mod driver;

pub use driver::{propose, run, VoterError, VoterProcess};
pub use idmesh_consensus::{RoleEntry, RolesAnswer};
