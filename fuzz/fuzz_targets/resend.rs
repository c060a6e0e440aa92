#![no_main]
//! cargo-fuzz target `resend`: [`idmesh_protocol::fuzzing::resend`].

libfuzzer_sys::fuzz_target!(|data: &[u8]| idmesh_protocol::fuzzing::resend(data));
