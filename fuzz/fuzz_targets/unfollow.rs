#![no_main]
//! cargo-fuzz target `unfollow`: [`idmesh_protocol::fuzzing::unfollow`].

libfuzzer_sys::fuzz_target!(|data: &[u8]| idmesh_protocol::fuzzing::unfollow(data));
