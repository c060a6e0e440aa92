#![no_main]
//! cargo-fuzz target `batch`: [`idmesh_protocol::fuzzing::batch`].

libfuzzer_sys::fuzz_target!(|data: &[u8]| idmesh_protocol::fuzzing::batch(data));
