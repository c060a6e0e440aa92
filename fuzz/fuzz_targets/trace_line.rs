#![no_main]
//! cargo-fuzz target `trace_line`: [`idmesh_protocol::fuzzing::trace_line`].

libfuzzer_sys::fuzz_target!(|data: &[u8]| idmesh_protocol::fuzzing::trace_line(data));
