//! Stamps the crate with a digest of the sources that decide the numbers of
//! the `acoustic_trends` example: the tracker itself and that program. The
//! example writes the stamp into docs/acoustic-trends.md, and a test checks
//! that the committed file carries the stamp of the code as it is, as
//! docs/results.md does for the property beliefs.

include!("../../eval/digest.rs");

/// Folders and files, relative to this crate, whose code the trends run.
const SOURCES: &[&str] = &["src", "examples/acoustic_trends.rs"];

/// Where this crate is in the workspace (see `sources_digest`).
const CRATE: &str = "world/acoustic";

fn main() {
    println!("cargo:rerun-if-changed=../../eval/digest.rs");
    println!(
        "cargo:rustc-env=IDMESH_ACOUSTIC_STAMP={:016x}",
        sources_digest(SOURCES, &[], CRATE)
    );
}
