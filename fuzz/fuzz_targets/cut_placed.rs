#![no_main]
//! cargo-fuzz target `cut_placed`: [`idmesh_protocol::fuzzing::cut_placed`].

libfuzzer_sys::fuzz_target!(|data: &[u8]| idmesh_protocol::fuzzing::cut_placed(data));
