//! `idmesh bench --accuracy` as a user runs it, on its smallest point:
//! the n = 20 Table III crowds from the uniform prior (both swaps), each
//! through a live factored and a live Radon deployment of four leaders.
//! It must exit 0 with a row per swap and belief, every truth line
//! answered, and write the same table to `--out`. (That the live factored
//! answers equal the centralized engine's is tests/tests/factored.rs's
//! business; the command checks it again on these crowds and would fail.)

use idmesh_tests::idmesh;
use std::path::Path;
use std::process::Command;

#[test]
fn the_accuracy_bench_answers_every_truth_line_of_the_smallest_table3_point() {
    let dir = Path::new(env!("CARGO_TARGET_TMPDIR")).join("accuracy");
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    let out = dir.join("live-accuracy.md");
    let output = Command::new(idmesh())
        .args([
            "bench",
            "--accuracy",
            "--sizes",
            "20",
            "--starts",
            "uniform",
        ])
        .arg("--dir")
        .arg(&dir)
        .arg("--out")
        .arg(&out)
        .env_remove("RUST_LOG")
        .output()
        .expect("idmesh runs");
    let stdout = String::from_utf8_lossy(&output.stdout).into_owned();
    let stderr = String::from_utf8_lossy(&output.stderr);
    assert!(output.status.success(), "{stdout}\n{stderr}");
    assert_eq!(std::fs::read_to_string(&out).unwrap(), stdout);
    let rows: Vec<Vec<&str>> = stdout
        .lines()
        .filter(|l| l.starts_with("| 20 |"))
        .map(|l| l.trim_matches('|').split('|').map(str::trim).collect())
        .collect();
    let mut seen: Vec<(&str, &str)> = rows.iter().map(|r| (r[1], r[3])).collect();
    seen.sort();
    assert_eq!(
        seen,
        [
            ("0.1", "factored"),
            ("0.1", "radon"),
            ("0.5", "factored"),
            ("0.5", "radon")
        ],
        "{stdout}"
    );
    for row in &rows {
        assert_eq!(row[2], "uniform prior", "{stdout}");
        let truths: usize = row[4].parse().unwrap();
        assert!(truths > 100, "{truths} truth lines: {stdout}");
        let live: f64 = row[5].parse().unwrap();
        let central: f64 = row[6].parse().unwrap();
        assert!((0.0..0.5).contains(&live), "{stdout}");
        assert!((0.0..0.5).contains(&central), "{stdout}");
        if row[3] == "factored" {
            let largest: f64 = row[7].parse().unwrap();
            assert!(largest <= 1e-9, "{stdout}");
            assert_eq!(live, central, "{stdout}");
        }
    }
    // Each crowd's trace is kept beside its topologies, for `idmesh replay`.
    for swap in ["0.1", "0.5"] {
        let folder = dir.join(format!("table3-n20-swap{swap}-uniform-seed0"));
        assert!(folder.join("trace.jsonl").exists(), "{}", folder.display());
    }
}

#[test]
fn an_accuracy_bench_of_no_table3_crowd_is_refused_by_name() {
    let dir = Path::new(env!("CARGO_TARGET_TMPDIR")).join("accuracy-none");
    let output = Command::new(idmesh())
        .args(["bench", "--accuracy", "--sizes", "30"])
        .arg("--dir")
        .arg(&dir)
        .output()
        .expect("idmesh runs");
    let stderr = String::from_utf8_lossy(&output.stderr);
    assert!(!output.status.success());
    assert!(
        stderr.contains("no Table III crowd has n in [30]"),
        "{stderr}"
    );
}
