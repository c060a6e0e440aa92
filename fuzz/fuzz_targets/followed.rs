#![no_main]
//! cargo-fuzz target `followed`: [`idmesh_protocol::fuzzing::followed`].

libfuzzer_sys::fuzz_target!(|data: &[u8]| idmesh_protocol::fuzzing::followed(data));
