//! The `idmesh` binary's distributed runtime as a library: what the
//! binary runs (`src/main.rs` and its subcommands) and what the process
//! tests (`idmesh-tests`) build their deployments with — the typed
//! topology ([`runtime::topology::Topology`], written by the same code
//! that reads it) and the one picker of free ports
//! ([`runtime::ports::pick_free_ports`]).

pub mod runtime;
