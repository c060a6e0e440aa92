//! The headless browser the web test drives: Debian's `chromium`, found on
//! the PATH or installed on first use (`apt-get install chromium`, as root),
//! so a newcomer's `cargo test` needs nothing installed by hand.

use std::path::PathBuf;
use std::process::Command;
use std::sync::Mutex;

/// Where Chromium's executable is, installing it when it is missing.
/// Panics, saying what failed and how to fix it, when it cannot be had.
pub fn chromium() -> PathBuf {
    static INSTALLING: Mutex<()> = Mutex::new(());
    let _installing = INSTALLING.lock().unwrap_or_else(|e| e.into_inner());
    if let Some(found) = on_path() {
        return found;
    }
    for step in [
        &["apt-get", "update", "-qq"][..],
        &["apt-get", "install", "-y", "-qq", "chromium"][..],
    ] {
        let output = Command::new(step[0])
            .args(&step[1..])
            .env("DEBIAN_FRONTEND", "noninteractive")
            .output()
            .unwrap_or_else(|e| {
                panic!(
                    "chromium is not installed and `{}` cannot start: {e}",
                    step.join(" ")
                )
            });
        assert!(
            output.status.success(),
            "chromium is not installed and `{}` failed (install Debian's `chromium` as root): {}",
            step.join(" "),
            String::from_utf8_lossy(&output.stderr)
        );
    }
    on_path().expect("chromium is on the PATH after `apt-get install chromium`")
}

fn on_path() -> Option<PathBuf> {
    let path = std::env::var_os("PATH")?;
    std::env::split_paths(&path)
        .map(|dir| dir.join("chromium"))
        .find(|candidate| candidate.is_file())
}
