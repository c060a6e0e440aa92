//! The fuzz targets on stable, in every `cargo test`: each target on
//! 10,000 seeded inputs (mutated well-formed messages and traces, random
//! bytes), then on every file of the regression corpus
//! `fuzz/regressions/<target>/` — inputs that once broke a target, or
//! that cargo-fuzz found worth keeping. Nightly's coverage-guided run of
//! the same functions is `scripts/fuzz-smoke`.

use idmesh_protocol::fuzzing::{smoke, target, TARGETS};
use std::path::PathBuf;

const RUNS: usize = 10_000;

fn regressions() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../fuzz/regressions")
}

#[test]
fn every_target_survives_ten_thousand_seeded_inputs() {
    for (i, (name, _)) in TARGETS.iter().enumerate() {
        let accepted = smoke(name, RUNS, 0x1d_e5_40 + i as u64);
        eprintln!("{name}: {RUNS} inputs, {accepted} accepted");
        // The mutations must reach past the decoder sometimes, and not
        // always: otherwise the run tests only one side of it.
        assert!(
            accepted > 0 && accepted < RUNS,
            "{name}: {accepted} of {RUNS} accepted"
        );
    }
}

#[test]
fn every_regression_input_is_handled() {
    let Ok(folders) = std::fs::read_dir(regressions()) else {
        panic!("no regression corpus at {}", regressions().display());
    };
    let mut files = 0;
    for folder in folders.flatten() {
        let name = folder.file_name().to_string_lossy().into_owned();
        let run =
            target(&name).unwrap_or_else(|| panic!("fuzz/regressions/{name}: no such target"));
        for file in std::fs::read_dir(folder.path())
            .into_iter()
            .flatten()
            .flatten()
        {
            let bytes = std::fs::read(file.path()).expect("a regression file");
            eprintln!("{name}/{}", file.file_name().to_string_lossy());
            run(&bytes);
            files += 1;
        }
    }
    assert!(files > 0, "the regression corpus is empty");
}

/// Writes every target's seeds to `fuzz/seeds/<target>/` (committed; the
/// starting corpus of `scripts/fuzz-smoke`). Run it after changing a
/// message: `cargo test -p idmesh-protocol --test fuzz_smoke -- --ignored`.
#[test]
#[ignore]
fn write_the_seed_corpus() {
    let root = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../fuzz/seeds");
    for (name, _) in TARGETS {
        let folder = root.join(name);
        let _ = std::fs::remove_dir_all(&folder);
        std::fs::create_dir_all(&folder).expect("a seed folder");
        for (i, seed) in idmesh_protocol::fuzzing::seeds(name).iter().enumerate() {
            std::fs::write(folder.join(format!("seed-{i}")), seed).expect("a seed file");
        }
    }
}
