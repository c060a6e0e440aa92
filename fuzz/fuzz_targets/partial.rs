#![no_main]
//! cargo-fuzz target `partial`: [`idmesh_protocol::fuzzing::partial`].

libfuzzer_sys::fuzz_target!(|data: &[u8]| idmesh_protocol::fuzzing::partial(data));
