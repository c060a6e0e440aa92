#![no_main]
//! cargo-fuzz target `follow`: [`idmesh_protocol::fuzzing::follow`].

libfuzzer_sys::fuzz_target!(|data: &[u8]| idmesh_protocol::fuzzing::follow(data));
