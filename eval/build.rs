//! Stamps the evaluation (and so the `idmesh` binary) with a digest of the
//! sources that decide the numbers of `idmesh eval`: the property filters,
//! the simulators and the event extractor, the trace format and the
//! evaluation itself. `eval` writes the stamp into the
//! results.md it generates, and a test checks that the committed
//! docs/results.md carries the stamp of the code as it is, so the document
//! cannot silently go stale when the engine changes.
//!
//! Comment lines and indentation are left out of the digest: rewording a doc
//! comment or reformatting does not call for a new evaluation.

include!("digest.rs");

/// Folders and files, relative to this crate, whose code the evaluation
/// runs: the engine, the simulators, the trace format, the grid and the
/// factory that builds its filters (not the replays: `idmesh eval` scores
/// its traces with its own loop, `src/eval/score.rs`).
const SOURCES: &[&str] = &[
    "../belief/src",
    "../world/sim/src/scenario",
    "../world/sim/src/motion",
    "../world/sim/src/events",
    "../world/extract/src",
    "../placement/src",
    "../protocol/src/trace",
    "src/eval",
    "src/filters.rs",
];

/// Inside those, code the evaluation does not run: none. (The identity
/// beliefs, which it does not run, are their own crate, `identity/`, with
/// their own document, docs/design/identity.md.)
const LEFT_OUT: &[&str] = &[];

/// Where this crate is in the workspace: file names enter the digest
/// relative to the workspace root, so moving the crate again does not
/// change the stamp.
const CRATE: &str = "eval";

fn main() {
    println!("cargo:rerun-if-changed=digest.rs");
    println!(
        "cargo:rustc-env=IDMESH_RESULTS_STAMP={:016x}",
        sources_digest(SOURCES, LEFT_OUT, CRATE)
    );
}
