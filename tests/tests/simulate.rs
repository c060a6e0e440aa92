//! `idmesh simulate` as a user runs it: a trace that is the same for the
//! same seed, different for another, and that replay reads and scores.

use idmesh_tests::idmesh;
use serde_json::Value;
use std::path::PathBuf;
use std::process::Command;

fn simulate(name: &str, extra: &[&str]) -> PathBuf {
    let dir = std::path::Path::new(env!("CARGO_TARGET_TMPDIR")).join("simulate");
    std::fs::create_dir_all(&dir).unwrap();
    let out = dir.join(format!("{name}.jsonl"));
    let status = Command::new(idmesh())
        .args(["simulate", "--targets", "12", "--events", "200", "--out"])
        .arg(&out)
        .args(extra)
        .status()
        .unwrap();
    assert!(status.success());
    out
}

#[test]
fn same_seed_same_trace_and_replay_scores_it() {
    let a = std::fs::read(simulate("a", &["--seed", "3"])).unwrap();
    let b = std::fs::read(simulate("b", &["--seed", "3"])).unwrap();
    let c = std::fs::read(simulate("c", &["--seed", "4"])).unwrap();
    assert_eq!(a, b);
    assert_ne!(a, c);
    let header: Value = serde_json::from_slice(a.split(|&x| x == b'\n').next().unwrap()).unwrap();
    assert_eq!(header["tracks"], 12);
    assert_eq!(header["red"], 6);

    let output = Command::new(idmesh())
        .args(["replay", "--method", "exact", "--trace"])
        .arg(simulate("d", &["--seed", "3"]))
        .output()
        .unwrap();
    assert!(
        output.status.success(),
        "{}",
        String::from_utf8_lossy(&output.stderr)
    );
    let stdout = String::from_utf8(output.stdout).unwrap();
    let summary: Value = serde_json::from_str(stdout.lines().last().unwrap()).unwrap();
    let events = summary["events"].as_u64().unwrap();
    assert_eq!(events, 200);
    let error = summary["error"].as_f64().unwrap();
    assert!((0.0..0.5).contains(&error), "error {error}");
}

#[test]
fn pedestrians_need_a_scene_and_bad_scenes_name_their_line() {
    let output = Command::new(idmesh())
        .args(["simulate", "--model", "pedestrians", "--out", "/dev/null"])
        .output()
        .unwrap();
    assert!(!output.status.success());
    let dir = std::path::Path::new(env!("CARGO_TARGET_TMPDIR")).join("simulate");
    std::fs::create_dir_all(&dir).unwrap();
    let scene = dir.join("broken_obsmat.txt");
    std::fs::write(&scene, "1 1 0.5 0 0.5 0 0 0\n2 1 zero 0 0.5 0 0 0\n").unwrap();
    let output = Command::new(idmesh())
        .args(["simulate", "--model", "pedestrians", "--scene"])
        .arg(&scene)
        .args(["--out", "/dev/null"])
        .output()
        .unwrap();
    assert!(!output.status.success());
    let stderr = String::from_utf8_lossy(&output.stderr);
    assert!(stderr.contains("broken_obsmat.txt:2:"), "{stderr}");
}

#[test]
fn a_missing_scene_is_named_once_with_its_os_error_once() {
    let output = Command::new(idmesh())
        .args([
            "simulate",
            "--model",
            "pedestrians",
            "--scene",
            "/nonexistent/obsmat.txt",
            "--out",
            "/dev/null",
        ])
        .output()
        .unwrap();
    assert!(!output.status.success());
    let stderr = String::from_utf8_lossy(&output.stderr);
    assert_eq!(
        stderr.trim_end(),
        "simulation failed: /nonexistent/obsmat.txt: cannot read the scene: \
         No such file or directory (os error 2)"
    );
}
