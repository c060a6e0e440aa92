//! Stamps the `idmesh` binary with a digest of the sources that decide the
//! figures of `idmesh bench`: the processes it starts (every role and
//! what they share), the beliefs they hold, the crowd it simulates, the
//! bench itself, and the versions of every dependency (Zenoh's among
//! them). `idmesh bench --out` writes the stamp into the page it
//! generates, so a page says which code measured it.
//!
//! The digest is idmesh-eval's (`eval/digest.rs`): comment lines
//! and indentation are left out.

include!("../eval/digest.rs");

/// Folders and files, relative to this crate.
const SOURCES: &[&str] = &[
    "src",
    "../protocol/src",
    "../placement/src",
    "../protocol/ownership/src",
    "../belief/src",
    "../identity/src",
    "../sensor/src",
    "../world/sim/src",
    "../leader/src",
    "../coordinator/src",
    "../Cargo.lock",
];

/// Inside those, what the bench does not run.
const LEFT_OUT: &[&str] = &["src/acoustic.rs", "src/simulate.rs"];

/// Where this crate is in the workspace.
const CRATE: &str = "deploy";

fn main() {
    println!("cargo:rerun-if-changed=../eval/digest.rs");
    println!(
        "cargo:rustc-env=IDMESH_BENCH_STAMP={:016x}",
        sources_digest(SOURCES, LEFT_OUT, CRATE)
    );
}
