//! Stamps the `idmesh` binary with a digest of the sources that decide the
//! numbers of `idmesh eval`: the property filters, the simulators, the trace
//! format and the evaluation itself. `eval` writes the stamp into the
//! results.md it generates, and a test checks that the committed
//! docs/results.md carries the stamp of the code as it is, so the document
//! cannot silently go stale when the engine changes.
//!
//! Comment lines and indentation are left out of the digest: rewording a doc
//! comment or reformatting does not call for a new evaluation.

use std::hash::Hasher;
use std::path::{Path, PathBuf};

/// Folders, relative to this crate, whose code the evaluation runs.
const SOURCES: &[&str] = &[
    "../belief/src",
    "../sensor/src/scenario",
    "../sensor/src/motion",
    "../protocol/src/trace",
    "src/eval",
];

/// Inside those, code the evaluation does not run (identity beliefs have
/// their own document, docs/identity.md).
const LEFT_OUT: &[&str] = &["../belief/src/identity"];

fn main() {
    let mut files = Vec::new();
    for dir in SOURCES {
        println!("cargo:rerun-if-changed={dir}");
        collect(Path::new(dir), &mut files);
    }
    files.sort();
    let mut digest = fnv::FnvHasher::default();
    for file in &files {
        let text = std::fs::read_to_string(file)
            .unwrap_or_else(|e| panic!("{}: cannot read: {e}", file.display()));
        digest.write(file.to_string_lossy().as_bytes());
        for line in text.lines().map(str::trim) {
            if !line.is_empty() && !line.starts_with("//") {
                digest.write(line.as_bytes());
                digest.write(b"\n");
            }
        }
    }
    println!(
        "cargo:rustc-env=IDMESH_RESULTS_STAMP={:016x}",
        digest.finish()
    );
}

fn collect(dir: &Path, files: &mut Vec<PathBuf>) {
    if LEFT_OUT.iter().any(|out| dir == Path::new(out)) {
        return;
    }
    let entries =
        std::fs::read_dir(dir).unwrap_or_else(|e| panic!("{}: cannot list: {e}", dir.display()));
    for entry in entries {
        let path = entry
            .unwrap_or_else(|e| panic!("{}: cannot list: {e}", dir.display()))
            .path();
        if path.is_dir() {
            collect(&path, files);
        } else if path.extension().is_some_and(|e| e == "rs") {
            files.push(path);
        }
    }
}
