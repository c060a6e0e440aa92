//! The README as a newcomer meets it: on a fresh clone of the repository
//! (the tracked files as they are in the working tree, nothing else — no
//! warm `target/`, no stray traces), its commands run as written — and so
//! do those of the guide pages it sends a newcomer to for the rest
//! ([`PAGES`]: replaying traces, the query API, the secure deployment).
//!
//! - Long-running commands (the demo, `up`) and set-up (install,
//!   certificates) are in `sh` blocks; this test finds each verbatim in
//!   the page that now says it ([`COMMANDS`]), runs it in the clone, and
//!   stops the long-running ones with Ctrl-C (SIGINT to their process
//!   group) as a user would.
//! - Everything in `console` blocks of those pages is run and its output
//!   checked by `trycmd` — while the demo and the two example deployments
//!   run, since those blocks ask them questions. A `console` block on any
//!   other page of `docs/` fails the test: it would be checked by nobody.
//!
//! Two adaptations, and only these: `cargo` builds into this test's own
//! target folder (`CARGO_TARGET_DIR`, so nothing is built twice), and
//! `cargo install` installs into a folder of this test (`--root`) rather
//! than `~/.cargo/bin`; `idmesh` then resolves to that installed binary.

use idmesh_tests::python_with_zenoh;
use std::io::Read;
use std::os::unix::process::CommandExt;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

const INSTALL: &str = "cargo install --locked --path deploy";
const DEMO: &str = "cargo run --release -p idmesh-deploy -- demo";
const CERTS: &str = "sh deploy/examples/make-certs.sh deploy/examples/certs coordinator sensor-0 leader-0 leader-1 operator";
const UP: &str = "idmesh up --config deploy/examples/topology.toml";
const UP_SECURE: &str = "idmesh up --config deploy/examples/secure.toml";
const TEST: &str = "cargo test --workspace --release";

/// The pages whose `console` blocks this test runs: the README and the
/// guide pages that hold commands a newcomer runs against the demo and
/// the example deployments (relative to the repository's root).
const README: &str = "README.md";
const REPLAY: &str = "docs/guide/replay.md";
const QUERY_API: &str = "docs/guide/query-api.md";
const SECURITY: &str = "docs/guide/security.md";
const PAGES: [&str; 4] = [README, REPLAY, QUERY_API, SECURITY];

/// Each command this test runs, and the page that says it.
const COMMANDS: [(&str, &str); 6] = [
    (INSTALL, README),
    (DEMO, README),
    (CERTS, SECURITY),
    (UP, README),
    (UP_SECURE, SECURITY),
    (TEST, README),
];

/// The repository this test was built from.
fn repository() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .parent()
        .expect("tests/ is inside the repository")
        .to_path_buf()
}

/// The target folder this test runs from: target/<profile>/deps/<test>.
fn target_dir() -> PathBuf {
    let exe = std::env::current_exe().expect("the test knows where it is");
    exe.ancestors()
        .nth(3)
        .expect("target/<profile>/deps")
        .to_path_buf()
}

/// A fresh clone of the working tree: every file git tracks, with its
/// working-tree contents and modification time, and nothing git does not
/// track. Its folders keep their modification times too: the build scripts
/// ask to rerun when a source folder changes, and Cargo dates a folder by
/// the newest entry in it, the folder itself included. A folder dated now
/// would rerun them, and the clone's build would then rewrite the shared
/// target folder's libraries in place, from other paths, under the
/// `cargo test` that runs this test (its doc-tests, built last, would find
/// their dependencies changed beneath them).
fn fresh_clone(repository: &Path, clone: &Path) {
    let listed = Command::new("git")
        .args(["ls-files", "-z", "--cached"])
        .current_dir(repository)
        .output()
        .expect("git runs");
    assert!(
        listed.status.success(),
        "git ls-files failed: the test needs a git checkout"
    );
    let _ = std::fs::remove_dir_all(clone);
    let mut folders = std::collections::BTreeSet::new();
    for name in listed.stdout.split(|&b| b == 0).filter(|n| !n.is_empty()) {
        let name = std::str::from_utf8(name).expect("UTF-8 file names");
        let (from, to) = (repository.join(name), clone.join(name));
        let Ok(metadata) = std::fs::symlink_metadata(&from) else {
            continue; // deleted in the working tree, not yet committed
        };
        std::fs::create_dir_all(to.parent().unwrap()).unwrap();
        std::fs::copy(&from, &to).unwrap();
        let file = std::fs::File::options().write(true).open(&to).unwrap();
        file.set_modified(metadata.modified().unwrap()).unwrap();
        folders.extend(Path::new(name).ancestors().skip(1).map(Path::to_path_buf));
    }
    // Deepest first: dating a folder does not change its parent's date.
    for folder in folders.iter().rev() {
        let Ok(modified) = std::fs::metadata(repository.join(folder)).and_then(|m| m.modified())
        else {
            continue;
        };
        let dated = std::fs::File::open(clone.join(folder)).and_then(|f| f.set_modified(modified));
        dated.unwrap_or_else(|e| panic!("{}: cannot date the folder: {e}", folder.display()));
    }
}

/// A README command, split as a shell would, run in `clone`.
fn command(line: &str, clone: &Path, env: &Env) -> Command {
    let words: Vec<&str> = line.split_whitespace().collect();
    let program = match words[0] {
        "cargo" => env.cargo.clone(),
        "idmesh" => env.installed.join("bin/idmesh"),
        other => PathBuf::from(other),
    };
    // As from a shell: see `cargo_command`.
    let mut command = idmesh_tests::cargo_command(program);
    command
        .args(&words[1..])
        .current_dir(clone)
        .env("CARGO_TARGET_DIR", &env.target)
        .env("PATH", &env.path)
        .env_remove("RUST_LOG");
    command
}

struct Env {
    cargo: PathBuf,
    target: PathBuf,
    installed: PathBuf,
    path: String,
}

/// Runs a set-up command to its end; panics with its output if it fails.
fn run(line: &str, clone: &Path, env: &Env) {
    let mut command = command(line, clone, env);
    if line == INSTALL {
        command.arg("--root").arg(&env.installed);
    }
    let output = command.output().unwrap_or_else(|e| panic!("{line}: {e}"));
    assert!(
        output.status.success(),
        "{line} failed:\n{}{}",
        String::from_utf8_lossy(&output.stdout),
        String::from_utf8_lossy(&output.stderr)
    );
}

/// A long-running command, in its own process group as a terminal's
/// foreground job is, with its output kept.
struct Running {
    line: &'static str,
    child: Child,
}

impl Running {
    fn start(line: &'static str, clone: &Path, env: &Env) -> Running {
        let child = command(line, clone, env)
            .process_group(0)
            .stdout(Stdio::piped())
            .stderr(Stdio::piped())
            .spawn()
            .unwrap_or_else(|e| panic!("{line}: {e}"));
        Running { line, child }
    }

    /// Ctrl-C: SIGINT to the whole group. Returns success and the output.
    fn interrupt(mut self) -> (bool, String, String) {
        // SAFETY: kill(2) on the process group of a child we have not reaped.
        unsafe {
            libc::kill(-(self.child.id() as i32), libc::SIGINT);
        }
        let deadline = Instant::now() + Duration::from_secs(30);
        let status = loop {
            if let Some(status) = self.child.try_wait().unwrap() {
                break status;
            }
            assert!(
                Instant::now() < deadline,
                "{}: Ctrl-C did not stop it",
                self.line
            );
            std::thread::sleep(Duration::from_millis(50));
        };
        let (mut out, mut err) = (String::new(), String::new());
        self.child
            .stdout
            .take()
            .unwrap()
            .read_to_string(&mut out)
            .unwrap();
        self.child
            .stderr
            .take()
            .unwrap()
            .read_to_string(&mut err)
            .unwrap();
        (status.success(), out, err)
    }
}

impl Drop for Running {
    fn drop(&mut self) {
        // SAFETY: as above; a no-op once the group is gone.
        unsafe {
            libc::kill(-(self.child.id() as i32), libc::SIGKILL);
        }
        let _ = self.child.wait();
    }
}

/// Every Markdown page under `dir` that trycmd would run commands of.
fn pages_with_console_blocks(dir: &Path) -> Vec<PathBuf> {
    let mut found = Vec::new();
    for entry in std::fs::read_dir(dir).unwrap_or_else(|e| panic!("{}: {e}", dir.display())) {
        let path = entry.unwrap().path();
        if path.is_dir() {
            found.extend(pages_with_console_blocks(&path));
        } else if path.extension().is_some_and(|e| e == "md")
            && runs_commands(&std::fs::read_to_string(&path).unwrap())
        {
            found.push(path);
        }
    }
    found
}

/// Whether trycmd would run a block of this Markdown text: a fenced block
/// marked `console` or `trycmd` (and not `ignore`), or with no info string
/// at all, as trycmd reads them.
fn runs_commands(text: &str) -> bool {
    let mut lines = text.lines();
    while let Some(line) = lines.next() {
        let ticks = line.len() - line.trim_start_matches('`').len();
        if ticks < 3 {
            continue;
        }
        let mut info = line[ticks..].trim().split(',');
        let lang = info.next().unwrap_or_default();
        if lang.is_empty() || (matches!(lang, "console" | "trycmd") && !info.any(|i| i == "ignore"))
        {
            return true;
        }
        let fence = &line[..ticks];
        for line in lines.by_ref() {
            if line.starts_with(fence) {
                break;
            }
        }
    }
    false
}

/// Waits until `idmesh query marginals` (with `extra`) gets an answer.
fn wait_for_answer(clone: &Path, env: &Env, extra: &str, what: &Running) {
    let deadline = Instant::now() + Duration::from_secs(600);
    let line = format!("idmesh query marginals --json {extra}");
    loop {
        let output = command(&line, clone, env).output().unwrap();
        if output.status.success() {
            return;
        }
        assert!(
            Instant::now() < deadline,
            "{}: no answer to `{line}` within 10 minutes: {}",
            what.line,
            String::from_utf8_lossy(&output.stderr)
        );
        std::thread::sleep(Duration::from_millis(500));
    }
}

#[test]
fn the_readme_works_as_written_on_a_fresh_clone() {
    let repository = repository();
    for (line, page) in COMMANDS {
        let text = std::fs::read_to_string(repository.join(page))
            .unwrap_or_else(|e| panic!("{page}: {e}"));
        assert!(text.contains(line), "{page} no longer says `{line}`");
    }
    for page in pages_with_console_blocks(&repository.join("docs")) {
        let name = page.strip_prefix(&repository).unwrap().to_string_lossy();
        assert!(
            PAGES.contains(&name.as_ref()),
            "{name} has a `console` block (or a bare fence) that no test runs: add \
             the page to PAGES in tests/tests/readme.rs, or make the block `sh` or `text`"
        );
    }
    let work = Path::new(env!("CARGO_TARGET_TMPDIR")).join("readme");
    let clone = work.join("idmesh");
    fresh_clone(&repository, &clone);
    // shared/ lives beside the repository, as the README says.
    let shared = repository.join("../shared");
    if shared.exists() && !work.join("shared").exists() {
        std::os::unix::fs::symlink(std::fs::canonicalize(&shared).unwrap(), work.join("shared"))
            .unwrap();
    }
    let installed = work.join("install");
    let env = Env {
        cargo: std::env::var_os("CARGO").map_or_else(|| "cargo".into(), PathBuf::from),
        target: target_dir(),
        path: format!(
            "{}:{}",
            installed.join("bin").display(),
            std::env::var("PATH").unwrap_or_default()
        ),
        installed,
    };

    run(INSTALL, &clone, &env);
    run(CERTS, &clone, &env);
    let demo = Running::start(DEMO, &clone, &env);
    wait_for_answer(&clone, &env, "", &demo);
    let up = Running::start(UP, &clone, &env);
    wait_for_answer(
        &clone,
        &env,
        "--connect tcp/127.0.0.1:7460 --prefix idmesh/example",
        &up,
    );
    let secure = Running::start(UP_SECURE, &clone, &env);
    let certs = "--ca deploy/examples/certs/ca.pem --cert deploy/examples/certs/operator.pem \
                 --key deploy/examples/certs/operator.key";
    wait_for_answer(
        &clone,
        &env,
        &format!("--connect tcp/127.0.0.1:7470 --prefix idmesh/secure {certs}"),
        &secure,
    );

    std::env::set_current_dir(&clone).unwrap();
    let python = python_with_zenoh(Path::new(env!("CARGO_TARGET_TMPDIR")));
    // One page after another, each page's blocks in order: trycmd runs the
    // cases it is given at once, and these share the deployments.
    for page in PAGES {
        trycmd::TestCases::new()
            .case(clone.join(page))
            .register_bin("idmesh", env.installed.join("bin/idmesh"))
            .register_bin("python3", python.clone())
            .env("PATH", &env.path)
            .timeout(Duration::from_secs(600))
            .run();
    }

    for (running, says) in [
        (
            secure,
            "up: started coordinator, sensor-0, leader-0, leader-1",
        ),
        (up, "up: started coordinator, sensor-0, leader-0, leader-1"),
    ] {
        let line = running.line;
        let (stopped, _, err) = running.interrupt();
        assert!(stopped, "{line}: Ctrl-C did not end it cleanly:\n{err}");
        assert!(err.contains(says), "{line} did not say it started:\n{err}");
    }
    let (stopped, out, err) = demo.interrupt();
    assert!(stopped, "{DEMO}: Ctrl-C did not end it cleanly:\n{err}");
    // Its last live line says what each of its four leaders holds: a
    // crowd of 40 is held whole by the first (the topology's default
    // `spread_above`), the others hold none of it.
    let live = out
        .lines()
        .rfind(|l| l.contains(" events") && l.contains(" held: leader-0 "))
        .unwrap_or_else(|| panic!("the demo printed no live answer:\n{out}\n{err}"));
    let held: Vec<u64> = live
        .split(" held: ")
        .nth(1)
        .and_then(|rest| rest.split(" · red:").next())
        .map(|list| {
            list.split(" · ")
                .filter_map(|part| part.rsplit(' ').next()?.parse().ok())
                .collect()
        })
        .unwrap_or_default();
    assert!(
        held.len() == 4 && held[0] > 0 && held[1..].iter().all(|&n| n == 0),
        "the first leader of the demo holds the whole belief: {live}"
    );
    assert!(!err.contains("WARN"), "the demo warned:\n{err}");
}
