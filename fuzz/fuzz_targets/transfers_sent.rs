#![no_main]
//! cargo-fuzz target `transfers_sent`: [`idmesh_protocol::fuzzing::transfers_sent`].

libfuzzer_sys::fuzz_target!(|data: &[u8]| idmesh_protocol::fuzzing::transfers_sent(data));
