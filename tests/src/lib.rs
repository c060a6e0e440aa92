//! Shared pieces of the multi-process tests in `tests/tests/`: each starts
//! the real `idmesh` binary and checks what a user would see; and the
//! deterministic network simulator ([`sim`]) that searches the
//! interleavings those tests cannot (a public namespace: `sim::run`,
//! `sim::run_aimed`). The other modules are private behind the
//! re-exports below.

mod browser;
mod compare;
mod deployment;
mod lan;
pub mod nemesis;
mod python;
pub mod sim;
mod web;

// Deployments on loopback: settings, traces to feed them, what to check.
pub use deployment::{
    assert_truth_points, crowd, crowd_with_identities, grid_over, header_only, hosted_on,
    replay_lines, replay_summary, standby_name, trace_events, truth_lines, undisturbed_applied,
    valid_identity_trace, watermark_events, waypoint_crowd, Deployment, Factored, FaultSection,
    LeaderFaultSection, MarkerOptions, Secured, Settings, SplitSetting, Truth, WebSection,
};
// A deployment over several hosts' worth of processes, as a LAN runs it.
pub use lan::{Asker, Lan, LanDeployment, LanSettings, Member};
// Comparing answers: marginals, identity matrices, floats.
pub use compare::{
    assert_same_marginals, floats, identity_difference, identity_marginals, identity_matrix,
    identity_row,
};
// The web gateway, a headless browser, and the Python examples.
pub use browser::Chromium;
pub use python::{python_with_zenoh, run_example};
pub use web::Gateway;

use serde_json::Value;
use std::path::{Path, PathBuf};
use std::process::Command;
use std::sync::OnceLock;

/// Whether the tests keep their folders under the temporary directory
/// even when they pass: `IDMESH_KEEP_TEST_DIRS=1`.
pub fn keep_test_dirs() -> bool {
    std::env::var("IDMESH_KEEP_TEST_DIRS").is_ok_and(|v| v == "1")
}

/// A test's folder under the temporary directory, `<name>-<pid>`, and the
/// guard that removes it once the test has passed (kept by it to the end
/// of the test). A failing test keeps it to be read, as does
/// [`keep_test_dirs`].
pub fn scratch(name: &str) -> (std::path::PathBuf, Scratch) {
    let dir = std::env::temp_dir().join(format!("{name}-{}", std::process::id()));
    (dir.clone(), Scratch(dir))
}

/// Removes a test's folder when dropped, unless the test is failing.
pub struct Scratch(std::path::PathBuf);

impl Drop for Scratch {
    fn drop(&mut self) {
        if !std::thread::panicking() && !keep_test_dirs() {
            let _ = std::fs::remove_dir_all(&self.0);
        }
    }
}

/// Whether the long runs run at their full lengths: `IDMESH_LONG_TESTS=1`
/// (CI sets it). Without it they run shorter, so a newcomer's `cargo test`
/// finishes in about a quarter of an hour; what they check is the same.
pub fn long_tests() -> bool {
    std::env::var("IDMESH_LONG_TESTS").is_ok_and(|v| v == "1")
}

/// A `cargo` command as a person would run it from a shell: without the
/// variables Cargo sets for the test it runs (`CARGO_MANIFEST_DIR`,
/// `CARGO_PKG_NAME`, `OUT_DIR`, …). Build scripts ask to rerun when those
/// change (ring's does), so a build started from a test with them set
/// would rebuild ring, rustls and Zenoh after every `cargo test` from a
/// shell, and the next shell build would rebuild them again.
pub fn cargo_command(cargo: impl AsRef<std::ffi::OsStr>) -> Command {
    let mut command = Command::new(cargo);
    for (name, _) in std::env::vars_os() {
        let Some(name) = name.to_str() else { continue };
        let set_for_tests = ["CARGO_PKG_", "CARGO_MANIFEST_", "CARGO_BIN_"]
            .iter()
            .any(|prefix| name.starts_with(prefix))
            || [
                "CARGO_CRATE_NAME",
                "CARGO_PRIMARY_PACKAGE",
                "CARGO_TARGET_TMPDIR",
                "CARGO_RUSTC_CURRENT_DIR",
                "OUT_DIR",
            ]
            .contains(&name);
        if set_for_tests {
            command.env_remove(name);
        }
    }
    command
}

/// The `idmesh` binary, built (or found fresh) once per test process.
///
/// Cargo builds a package's binaries only for that package's own
/// integration tests, so this package asks Cargo for it: `cargo build
/// --bin idmesh` in the profile these tests were built in, whose JSON
/// messages name the executable. When it is fresh that is a no-op, and it
/// never runs a stale binary.
pub fn idmesh() -> &'static Path {
    static BINARY: OnceLock<PathBuf> = OnceLock::new();
    BINARY.get_or_init(|| {
        let cargo = option_env!("CARGO").unwrap_or("cargo");
        let manifest = Path::new(env!("CARGO_MANIFEST_DIR")).join("../Cargo.toml");
        let mut command = cargo_command(cargo);
        command.args(["build", "--quiet", "--message-format=json"]);
        command.args(["-p", "idmesh-deploy", "--bin", "idmesh", "--manifest-path"]);
        command.arg(&manifest);
        // target/<profile>/deps/<this test>: build in the same profile.
        let exe = std::env::current_exe().expect("the test knows where it is");
        let profile_dir = exe
            .parent()
            .and_then(Path::parent)
            .and_then(Path::file_name)
            .and_then(|name| name.to_str())
            .unwrap_or("debug");
        match profile_dir {
            "debug" => {}
            "release" => {
                command.arg("--release");
            }
            other => {
                command.args(["--profile", other]);
            }
        }
        let output = command.output().expect("cargo runs");
        let messages: Vec<Value> = String::from_utf8_lossy(&output.stdout)
            .lines()
            .filter_map(|line| serde_json::from_str::<Value>(line).ok())
            .collect();
        if !output.status.success() {
            let diagnostics: Vec<&str> = messages
                .iter()
                .filter(|m| m["reason"] == "compiler-message")
                .filter_map(|m| m["message"]["rendered"].as_str())
                .collect();
            panic!(
                "building idmesh failed:\n{}{}",
                diagnostics.concat(),
                String::from_utf8_lossy(&output.stderr)
            );
        }
        messages
            .iter()
            .filter(|m| m["reason"] == "compiler-artifact")
            .find_map(|m| m["executable"].as_str().map(PathBuf::from))
            .expect("cargo names the idmesh executable")
    })
}
