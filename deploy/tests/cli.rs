//! The `idmesh` binary's front door, run as a user runs it: `--help`
//! names every role and tool, and a wrong subcommand or a missing file is
//! refused with a message naming it and a non-zero exit.
//!
//! Being an integration test of this crate, it also makes `cargo test
//! --workspace` build the binary itself, in the test build's stage and
//! with its features, so the process tests find it built.

use std::process::{Command, Output};

fn idmesh(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_idmesh"))
        .args(args)
        .env_remove("RUST_LOG")
        .output()
        .expect("idmesh runs")
}

#[test]
fn help_names_every_subcommand() {
    let out = idmesh(&["--help"]);
    assert!(out.status.success());
    let help = String::from_utf8_lossy(&out.stdout);
    for subcommand in [
        "replay",
        "simulate",
        "extract",
        "acoustic",
        "eval",
        "sensor",
        "leader",
        "coordinator",
        "up",
        "demo",
        "query",
        "web",
        "bench",
    ] {
        assert!(
            help.lines()
                .any(|l| l.trim_start().starts_with(&format!("{subcommand} "))),
            "--help does not list {subcommand}:\n{help}"
        );
    }
}

#[test]
fn a_wrong_subcommand_or_a_missing_file_is_refused_by_name() {
    for (args, named) in [
        (&["frobnicate"][..], "'frobnicate'"),
        (
            &["replay", "--trace", "/nonexistent/x.jsonl"][..],
            "/nonexistent/x.jsonl",
        ),
        (
            &["up", "--config", "/nonexistent/t.toml"][..],
            "/nonexistent/t.toml",
        ),
    ] {
        let out = idmesh(args);
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert!(!out.status.success(), "{args:?} succeeded");
        assert!(stderr.contains(named), "{args:?}: {stderr}");
    }
}
