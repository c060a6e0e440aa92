#![no_main]
//! cargo-fuzz target `transfers_wanted`: [`idmesh_protocol::fuzzing::transfers_wanted`].

libfuzzer_sys::fuzz_target!(|data: &[u8]| idmesh_protocol::fuzzing::transfers_wanted(data));
