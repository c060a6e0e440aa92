//! The `idmesh` binary's distributed runtime as a library: what the
//! binary runs (`src/main.rs` and its subcommands) and what the process
//! tests (`idmesh-tests`) can build their deployments with, starting with
//! the topology ([`runtime::topology::Topology`]).

pub mod runtime;
