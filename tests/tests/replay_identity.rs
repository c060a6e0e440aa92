//! `idmesh replay` on identity traces, as a user runs it: simulate a crowd
//! with RFID-like reads, replay it through every identity method, and check
//! the answers are probability matrices and the assignment a permutation.

use idmesh_tests::idmesh;
use serde_json::Value;
use std::process::Command;

#[test]
fn every_identity_method_replays_a_simulated_trace() {
    let dir = std::path::Path::new(env!("CARGO_TARGET_TMPDIR")).join("identity");
    std::fs::create_dir_all(&dir).unwrap();
    let trace = dir.join("crowd6.jsonl");
    let status = Command::new(idmesh())
        .args([
            "simulate",
            "--targets",
            "6",
            "--events",
            "120",
            "--identities",
            "--seed",
            "5",
            "--out",
        ])
        .arg(&trace)
        .status()
        .unwrap();
    assert!(status.success());
    for method in [
        &["--method", "exact-perm"][..],
        &["--method", "belief-matrix"],
        &["--method", "information-matrix", "--marginals", "exact"],
        &["--method", "information-matrix", "--marginals", "sinkhorn"],
        &[
            "--method",
            "information-matrix",
            "--marginals",
            "metropolis",
            "--samples",
            "2000",
        ],
        &["--method", "property-bits", "--bits", "3"],
    ] {
        let output = Command::new(idmesh())
            .args(["replay", "--trace"])
            .arg(&trace)
            .args(method)
            .output()
            .unwrap();
        assert!(
            output.status.success(),
            "{method:?}: {}",
            String::from_utf8_lossy(&output.stderr)
        );
        let stdout = String::from_utf8(output.stdout).unwrap();
        let lines: Vec<Value> = stdout
            .lines()
            .map(|l| serde_json::from_str(l).unwrap())
            .collect();
        let (summary, answers) = lines.split_last().unwrap();
        assert_eq!(summary["kind"], "summary");
        let error = summary["error"].as_f64().unwrap();
        assert!((0.0..=1.0).contains(&error));
        assert!(!answers.is_empty());
        for answer in answers {
            let p = idmesh_tests::identity_matrix(&answer["p_identity"]);
            assert_eq!(p.len(), 6);
            for row in p {
                let sum: f64 = row.iter().sum();
                assert!((sum - 1.0).abs() < 1e-6, "{method:?}: row sums to {sum}");
            }
            let mut assignment: Vec<u64> = answer["predicted_identity"]
                .as_array()
                .unwrap()
                .iter()
                .map(|x| x.as_u64().unwrap())
                .collect();
            assignment.sort_unstable();
            assert_eq!(assignment, (0..6).collect::<Vec<u64>>());
        }
    }
}

#[test]
fn identity_flags_are_refused_on_property_methods() {
    let output = Command::new(idmesh())
        .args([
            "replay", "--trace", "x.jsonl", "--method", "exact", "--bits", "3",
        ])
        .output()
        .unwrap();
    assert!(!output.status.success());
    assert!(String::from_utf8_lossy(&output.stderr).contains("--bits"));
}
