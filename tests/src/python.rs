//! A Python 3 with the Zenoh client the external-client tests need
//! (`eclipse-zenoh` 1.10.x, the Zenoh release the processes speak) and
//! `rosbags` (ROS 2 messages in CDR and rosbag2 bags, written by an
//! encoder idmesh did not write, for the ROS 2 tests), in a
//! virtual environment under the target folder, made on first use: a
//! newcomer's `cargo test` needs only `python3` on the PATH and access to
//! PyPI, nothing installed by hand.

use std::path::{Path, PathBuf};
use std::process::Command;
use std::sync::Mutex;

/// The pip requirement: the client's minor version must match the mesh's.
pub(crate) const ZENOH_CLIENT: &str = "eclipse-zenoh>=1.10,<1.11";
/// ROS 2 messages without a ROS install.
pub(crate) const ROSBAGS: &str = "rosbags>=0.10,<0.12";

/// The venv's `python`, made (or found ready) in `target_tmp/python-venv`.
/// Panics, saying what failed and how to fix it, when it cannot be made.
pub fn python_with_zenoh(target_tmp: &Path) -> PathBuf {
    // Tests of one binary may ask at once; tests of different binaries run
    // one binary after another, so a lock within the process is enough.
    static MAKING: Mutex<()> = Mutex::new(());
    let _making = MAKING.lock().unwrap_or_else(|e| e.into_inner());
    let venv = target_tmp.join("python-venv");
    let python = venv.join("bin/python");
    if imports_zenoh(&python) {
        return python;
    }
    run(
        Command::new("python3")
            .args(["-m", "venv", "--clear"])
            .arg(&venv),
        "python3 -m venv (is Python 3 with its venv module installed?)",
    );
    run(
        Command::new(&python).args([
            "-m",
            "pip",
            "install",
            "--quiet",
            "--disable-pip-version-check",
            ZENOH_CLIENT,
            ROSBAGS,
        ]),
        "pip install eclipse-zenoh rosbags (is PyPI reachable?)",
    );
    assert!(
        imports_zenoh(&python),
        "{} cannot import zenoh after installing it",
        python.display()
    );
    python
}

fn imports_zenoh(python: &Path) -> bool {
    python.exists()
        && Command::new(python)
            .args(["-c", "import zenoh, rosbags"])
            .output()
            .is_ok_and(|o| o.status.success())
}

fn run(command: &mut Command, what: &str) {
    let output = command
        .output()
        .unwrap_or_else(|e| panic!("{what}: cannot start: {e}"));
    assert!(
        output.status.success(),
        "{what} failed: {}{}",
        String::from_utf8_lossy(&output.stdout),
        String::from_utf8_lossy(&output.stderr)
    );
}

/// Runs the project's Python example `examples/SCRIPT` with `args` under
/// [`python_with_zenoh`] (its venv in `target_tmp`) and waits for it: the
/// one JSON line it prints. Panics with what it said if it fails.
pub fn run_example<I, S>(target_tmp: &Path, script: &str, args: I) -> serde_json::Value
where
    I: IntoIterator<Item = S>,
    S: AsRef<std::ffi::OsStr>,
{
    let python = python_with_zenoh(target_tmp);
    let path = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../examples")
        .join(script);
    let output = Command::new(&python)
        .arg(&path)
        .args(args)
        .output()
        .expect("python runs");
    assert!(
        output.status.success(),
        "examples/{script} failed: {}",
        String::from_utf8_lossy(&output.stderr)
    );
    serde_json::from_slice(&output.stdout)
        .unwrap_or_else(|e| panic!("examples/{script} printed no JSON line: {e}"))
}
