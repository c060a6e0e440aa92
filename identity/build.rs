//! Stamps the crate with digests of the sources that decide the numbers of
//! the `identity_results` and `identity_calibration` examples: the identity
//! engine and each program. The examples write their stamp into
//! docs/identity-paper.md and docs/identity-calibration.md, and tests check
//! that the committed files carry the stamps of the code as it is, as
//! docs/results.md does for the property beliefs.

include!("../eval/digest.rs");

/// Folders and files, relative to this crate, whose code each program runs.
const PAPER: &[&str] = &["src", "examples/identity_results.rs"];
const CALIBRATION: &[&str] = &["src", "examples/identity_calibration.rs"];

/// Where this crate is in the workspace (see `sources_digest`).
const CRATE: &str = "identity";

fn main() {
    println!("cargo:rerun-if-changed=../eval/digest.rs");
    println!(
        "cargo:rustc-env=IDMESH_IDENTITY_PAPER_STAMP={:016x}",
        sources_digest(PAPER, &[], CRATE)
    );
    println!(
        "cargo:rustc-env=IDMESH_IDENTITY_CALIBRATION_STAMP={:016x}",
        sources_digest(CALIBRATION, &[], CRATE)
    );
}
