#![no_main]
//! cargo-fuzz target `trace_reader`: [`idmesh_protocol::fuzzing::trace_reader`].

libfuzzer_sys::fuzz_target!(|data: &[u8]| idmesh_protocol::fuzzing::trace_reader(data));
