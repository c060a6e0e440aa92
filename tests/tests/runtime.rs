//! The distributed runtime, as real processes on loopback: the answer of a
//! deployment equals the centralized engine's.

use idmesh_tests::{crowd, replay_lines, replay_summary, truth_lines, Deployment, Settings};
use serde_json::Value;
use std::path::Path;
use std::time::Duration;

fn floats(v: &Value) -> Vec<f64> {
    array(v, Value::as_f64)
}

fn integers(v: &Value) -> Vec<u64> {
    array(v, Value::as_u64)
}

fn array<T>(v: &Value, item: impl Fn(&Value) -> Option<T>) -> Vec<T> {
    v.as_array()
        .expect("an array")
        .iter()
        .map(|x| item(x).unwrap_or_else(|| panic!("{x} in {v}")))
        .collect()
}

/// Exact conditioning, no pruning: through 1, 2, 4 and 8 leaders the
/// coordinator's marginals equal `idmesh replay --method overcomplete` to
/// 1e-9, on a crowd whose tracks move between leaders and mix across them
/// (leaders at fixed places, so that tracks are handed over at their moves
/// across borders; the defaults' fitted regions are tests/tests/factored.rs's).
#[test]
fn exact_answers_equal_the_centralized_engine_through_1_2_4_8_leaders() {
    let (dir, _scratch) = idmesh_tests::scratch("idmesh-exact");
    let trace = crowd(&dir, 12, 4, 90.0, 5);
    let central = replay_summary(&trace, &["--method", "overcomplete"]);
    let expected = floats(&central["final_p_red"]);
    for leaders in [1, 2, 4, 8] {
        let settings = Settings {
            leaders,
            distributed_rule: false,
            budget: 0,
            overcomplete: false,
            rate: None,
            fixed_places: true,
            ..Settings::default()
        };
        let deployment = Deployment::start(&format!("exact{leaders}"), &trace, &settings);
        let answer = deployment.final_marginals(Duration::from_secs(60));
        let got = floats(&answer["p_red"]);
        assert_eq!(got.len(), expected.len());
        for (t, (g, e)) in got.iter().zip(&expected).enumerate() {
            assert!(
                (g - e).abs() < 1e-9,
                "{leaders} leaders, track {t}: {g} vs {e}"
            );
        }
        assert_eq!(answer["leaders"], leaders);
        let stats = deployment.query(&["stats"]).expect("stats answer");
        let leaders_stats = stats[0]["leaders"].as_array().unwrap();
        assert_eq!(leaders_stats.len(), leaders);
        if leaders > 1 {
            // Tracks did cross regions, and sets did move between leaders.
            let handovers: u64 = leaders_stats
                .iter()
                .map(|l| l["handovers"].as_u64().unwrap())
                .sum();
            let sent: u64 = leaders_stats
                .iter()
                .map(|l| l["sets_sent"].as_u64().unwrap())
                .sum();
            assert!(handovers > 0 && sent > 0, "{stats:?}");
        }
    }
}

/// The paper's distributed rule with a budget, thresholding: the
/// deployment's mean error over the trace's truth lines stays within 0.02
/// of the centralized run's with the same settings.
#[test]
fn distributed_rule_with_a_budget_stays_within_two_points_of_the_centralized_run() {
    scored_against_the_centralized_run("rule", "threshold", false);
}

/// The same with the overcomplete method: each leader runs OMP on its own
/// sets before thresholding.
#[test]
fn overcomplete_leaders_stay_within_two_points_of_the_centralized_run() {
    scored_against_the_centralized_run("omp", "overcomplete", true);
}

/// Streams a crowd through 4 leaders and asks, while it streams, for the
/// answer right after the events that precede each truth line (where the
/// centralized replay answers); compares the mean errors over the points.
fn scored_against_the_centralized_run(name: &str, method: &str, overcomplete: bool) {
    let (dir, _scratch) = idmesh_tests::scratch(&format!("idmesh-{name}"));
    let trace = crowd(&dir, 50, 10, 120.0, 9);
    let central = replay_lines(
        &trace,
        &["--method", method, "--budget", "200", "--distributed-rule"],
    );
    let truths = truth_lines(&trace);
    assert_eq!(central.len(), truths.len());
    let deployment = Deployment::start(
        name,
        &trace,
        &Settings {
            leaders: 4,
            distributed_rule: true,
            budget: 200,
            overcomplete,
            rate: Some(2000.0),
            ..Settings::default()
        },
    );
    deployment.first_answer(Duration::from_secs(30));
    let answers = deployment.at_truth_points("marginals", &truths);
    let mut scored = 0;
    let (mut distributed_error, mut central_error) = (0.0, 0.0);
    for &(i, ref answer) in &answers {
        let sum: f64 = floats(&answer["p_red"]).iter().sum();
        assert!((sum - 10.0).abs() < 1e-9, "marginals sum to {sum}");
        distributed_error += error(
            &integers(&answer["predicted_red"]),
            &integers(&truths[i].line["red"]),
            50,
        );
        central_error += error(
            &integers(&central[i]["predicted_red"]),
            &integers(&truths[i].line["red"]),
            50,
        );
        scored += 1;
    }
    assert!(
        scored * 10 >= truths.len() * 8,
        "only {scored} of {} truth points answered\n{}",
        truths.len(),
        deployment.log()
    );
    let (distributed_error, central_error) = (
        distributed_error / scored as f64,
        central_error / scored as f64,
    );
    eprintln!(
        "{method}: {scored} truth points, mean error {distributed_error:.4} distributed, {central_error:.4} centralized"
    );
    assert!(
        (distributed_error - central_error).abs() <= 0.02,
        "{method}: distributed {distributed_error} vs centralized {central_error}"
    );
    let stats = deployment.query(&["stats"]).expect("stats answer");
    let omp_runs: u64 = stats[0]["leaders"]
        .as_array()
        .unwrap()
        .iter()
        .map(|l| l["omp_runs"].as_u64().unwrap())
        .sum();
    assert_eq!(
        omp_runs > 0,
        overcomplete,
        "OMP runs at the leaders: {omp_runs}"
    );
}

/// The fraction of tracks labelled wrongly.
fn error(predicted: &[u64], truth: &[u64], tracks: usize) -> f64 {
    let missed = truth.iter().filter(|t| !predicted.contains(t)).count();
    let wrong = predicted.iter().filter(|t| !truth.contains(t)).count();
    (missed + wrong) as f64 / tracks as f64
}

/// Queries fired while the stream runs see marginals that sum to k and a
/// watermark that only moves forward.
#[test]
fn queries_during_the_stream_sum_to_k_and_the_watermark_only_grows() {
    let (dir, _scratch) = idmesh_tests::scratch("idmesh-live");
    let trace = crowd(&dir, 20, 6, 200.0, 2);
    let deployment = Deployment::start(
        "live",
        &trace,
        &Settings {
            leaders: 4,
            distributed_rule: false,
            budget: 300,
            overcomplete: false,
            rate: Some(400.0),
            ..Settings::default()
        },
    );
    // The first answers may come before the leaders are up: wait for one.
    deployment.first_answer(Duration::from_secs(30));
    let replies = deployment
        .query(&["marginals", "--repeat", "40", "--interval-ms", "50"])
        .expect("every query answered");
    let mut last = 0;
    let mut moved = false;
    for reply in &replies {
        let sum: f64 = floats(&reply["p_red"]).iter().sum();
        assert!((sum - 6.0).abs() < 1e-9, "marginals sum to {sum}: {reply}");
        let events = reply["watermark"]["sensor-0"].as_u64().unwrap();
        assert!(
            events >= last,
            "watermark went back from {last} to {events}"
        );
        moved |= events > last && last > 0;
        last = events;
    }
    assert!(moved, "the stream did not advance during the queries");
}

/// Any Zenoh client can ask: Python's eclipse-zenoh (in a venv the test
/// makes under target/ on first use) gets the coordinator's answer as JSON
/// with Zenoh's JSON encoding.
#[test]
fn a_python_zenoh_client_gets_the_marginals_as_json() {
    let (dir, _scratch) = idmesh_tests::scratch("idmesh-python");
    let trace = crowd(&dir, 10, 3, 60.0, 4);
    let deployment = Deployment::start(
        "python",
        &trace,
        &Settings {
            leaders: 2,
            distributed_rule: false,
            budget: 0,
            overcomplete: false,
            rate: None,
            ..Settings::default()
        },
    );
    let ours = deployment.final_marginals(Duration::from_secs(60));
    let script = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("python/query_marginals.py");
    let python = idmesh_tests::python_with_zenoh(Path::new(env!("CARGO_TARGET_TMPDIR")));
    let output = std::process::Command::new(python)
        .arg(script)
        .arg(&deployment.coordinator)
        .arg(&deployment.prefix)
        .output()
        .expect("python3 runs");
    assert!(
        output.status.success(),
        "the Python client failed: {}",
        String::from_utf8_lossy(&output.stderr)
    );
    let answer: Value = serde_json::from_slice(&output.stdout).expect("the client printed JSON");
    assert_eq!(answer["p_red"], ours["p_red"]);
    assert_eq!(answer["tracks"], 10);
    assert!(
        answer["encoding"].as_str().unwrap().contains("json"),
        "{answer}"
    );
}
