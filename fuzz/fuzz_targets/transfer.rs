#![no_main]
//! cargo-fuzz target `transfer`: [`idmesh_protocol::fuzzing::transfer`].

libfuzzer_sys::fuzz_target!(|data: &[u8]| idmesh_protocol::fuzzing::transfer(data));
