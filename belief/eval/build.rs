//! Stamps the evaluation (and so the `idmesh` binary) with a digest of the
//! sources that decide the numbers of `idmesh eval`: the property filters, the simulators, the trace
//! format and the evaluation itself. `eval` writes the stamp into the
//! results.md it generates, and a test checks that the committed
//! docs/results.md carries the stamp of the code as it is, so the document
//! cannot silently go stale when the engine changes.
//!
//! Comment lines and indentation are left out of the digest: rewording a doc
//! comment or reformatting does not call for a new evaluation.

use std::hash::Hasher;
use std::path::{Path, PathBuf};

/// Folders and files, relative to this crate, whose code the evaluation
/// runs: the engine, the simulators, the trace format, the grid and the
/// factory that builds its filters (not the replays: `idmesh eval` scores
/// its traces with its own loop, `src/eval/score.rs`).
const SOURCES: &[&str] = &[
    "../../belief/src",
    "../../sensor/sim/src/scenario",
    "../../sensor/sim/src/motion",
    "../../protocol/src/trace",
    "src/eval",
    "src/filters.rs",
];

/// Inside those, code the evaluation does not run (identity beliefs have
/// their own document, docs/design/identity.md).
const LEFT_OUT: &[&str] = &["../../belief/src/identity"];

/// Where this crate is in the workspace: file names enter the digest
/// relative to the workspace root, so moving the crate again does not
/// change the stamp.
const CRATE: &str = "belief/eval";

fn main() {
    let mut files = Vec::new();
    for source in SOURCES {
        println!("cargo:rerun-if-changed={source}");
        collect(Path::new(source), &mut files);
    }
    files.sort();
    let mut digest = fnv::FnvHasher::default();
    for file in &files {
        let text = std::fs::read_to_string(file)
            .unwrap_or_else(|e| panic!("{}: cannot read: {e}", file.display()));
        digest.write(workspace_name(file).as_bytes());
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

/// `file` named from the workspace root: `belief/src/lib.rs`,
/// `belief/eval/src/filters.rs`.
fn workspace_name(file: &Path) -> String {
    let name = file.to_string_lossy();
    match name.strip_prefix("../../") {
        Some(outside) => outside.to_string(),
        None => format!("{CRATE}/{name}"),
    }
}

/// Every `.rs` file at `dir` (a file itself, or a folder walked).
fn collect(dir: &Path, files: &mut Vec<PathBuf>) {
    if LEFT_OUT.iter().any(|out| dir == Path::new(out)) {
        return;
    }
    if dir.is_file() {
        files.push(dir.to_path_buf());
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
