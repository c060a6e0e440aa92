#![no_main]
//! cargo-fuzz target `resent`: [`idmesh_protocol::fuzzing::resent`].

libfuzzer_sys::fuzz_target!(|data: &[u8]| idmesh_protocol::fuzzing::resent(data));
