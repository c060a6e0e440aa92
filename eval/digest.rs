// The digest of source files that a build script stamps a binary with,
// shared by the build scripts of idmesh-eval (the stamp of docs/results.md)
// and idmesh-deploy (the stamp of `idmesh bench --out`'s page), each of
// which includes this file.
//
// Comment lines and indentation are left out of the digest: rewording a
// doc comment or reformatting does not call for a new run. Files enter it
// named from the workspace root, so moving a crate does not change it by
// itself.

/// The digest of every `.rs` file under `sources` (folders walked, or files
/// of any kind named on their own), those under `left_out` excepted; the
/// paths are relative to the crate, which is `crate_dir` in the workspace.
/// Tells Cargo to run the build script again when any of them changes.
fn sources_digest(sources: &[&str], left_out: &[&str], crate_dir: &str) -> u64 {
    use std::hash::Hasher;
    use std::path::Path;
    let mut files = Vec::new();
    for source in sources {
        println!("cargo:rerun-if-changed={source}");
        collect(Path::new(source), left_out, &mut files);
    }
    files.sort();
    let mut digest = fnv::FnvHasher::default();
    for file in &files {
        let text = std::fs::read_to_string(file)
            .unwrap_or_else(|e| panic!("{}: cannot read: {e}", file.display()));
        digest.write(workspace_name(file, crate_dir).as_bytes());
        for line in text.lines().map(str::trim) {
            if !line.is_empty() && !line.starts_with("//") {
                digest.write(line.as_bytes());
                digest.write(b"\n");
            }
        }
    }
    digest.finish()
}

/// `file` named from the workspace root: `belief/src/lib.rs`,
/// `eval/src/filters.rs`.
fn workspace_name(file: &std::path::Path, crate_dir: &str) -> String {
    let name = file.to_string_lossy();
    let mut outside = name.as_ref();
    let mut up = 0;
    while let Some(rest) = outside.strip_prefix("../") {
        outside = rest;
        up += 1;
    }
    let mut parts: Vec<&str> = crate_dir.split('/').collect();
    parts.truncate(parts.len().saturating_sub(up));
    parts.push(outside);
    parts.retain(|p| !p.is_empty());
    parts.join("/")
}

/// Every `.rs` file at `dir` (a file itself, or a folder walked).
fn collect(dir: &std::path::Path, left_out: &[&str], files: &mut Vec<std::path::PathBuf>) {
    if left_out.iter().any(|out| dir == std::path::Path::new(out)) {
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
            collect(&path, left_out, files);
        } else if path.extension().is_some_and(|e| e == "rs") {
            files.push(path);
        }
    }
}
