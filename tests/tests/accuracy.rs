//! `idmesh bench --accuracy` as a user runs it, on its smallest point:
//! the n = 20 Table III crowds from the uniform prior (both swaps), each
//! through a live factored, a live factored under the regional rule and a
//! live Radon deployment of four leaders. It must exit 0 with a row per
//! swap and belief, every truth line answered, a row of the regional
//! rule's cost per swap, and write the same text to `--out`. (That the live
//! factored answers equal the centralized engine's is
//! tests/tests/factored.rs's business; the command checks it again on
//! these crowds and would fail.)

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
    let all: Vec<Vec<&str>> = stdout
        .lines()
        .filter(|l| l.starts_with("| 20 |"))
        .map(|l| l.trim_matches('|').split('|').map(str::trim).collect())
        .collect();
    // The live table's rows have 9 columns, the cost table's 7.
    let (rows, costs): (Vec<_>, Vec<_>) = all.into_iter().partition(|r| r.len() == 9);
    let mut seen: Vec<(&str, &str)> = rows.iter().map(|r| (r[1], r[3])).collect();
    seen.sort();
    assert_eq!(
        seen,
        [
            ("0.1", "factored"),
            ("0.1", "factored, regional rule"),
            ("0.1", "radon"),
            ("0.5", "factored"),
            ("0.5", "factored, regional rule"),
            ("0.5", "radon")
        ],
        "{stdout}"
    );
    assert_eq!(costs.len(), 2, "a cost row per swap: {stdout}");
    for cost in &costs {
        assert_eq!(cost.len(), 7, "{stdout}");
        let local: f64 = cost[3].parse().unwrap();
        assert!((0.0..0.5).contains(&local), "{stdout}");
        // "0.3143 (-0.0080)": the error and its difference from the local rule.
        for cell in &cost[4..] {
            let (error, diff) = cell.split_once(" (").expect("error (difference)");
            let (error, diff): (f64, f64) = (
                error.parse().unwrap(),
                diff.trim_end_matches(')').parse().unwrap(),
            );
            assert!((error - local - diff).abs() < 2e-4, "{cell}: {stdout}");
        }
    }
    for row in &rows {
        assert_eq!(row[2], "uniform prior", "{stdout}");
        let truths: usize = row[4].parse().unwrap();
        assert!(truths > 100, "{truths} truth lines: {stdout}");
        let live: f64 = row[5].parse().unwrap();
        let central: f64 = row[6].parse().unwrap();
        assert!((0.0..0.5).contains(&live), "{stdout}");
        assert!((0.0..0.5).contains(&central), "{stdout}");
        if row[3] != "radon" {
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
