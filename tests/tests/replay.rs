//! `idmesh replay` as a user runs it: the real binary on small traces
//! written to a scratch directory, checking stdout, stderr and the exit
//! status.

use idmesh_tests::idmesh;
use serde_json::Value;
use std::path::{Path, PathBuf};
use std::process::{Command, Output};

/// Writes `trace` to a scratch file named after the test.
fn trace_file(name: &str, trace: &str) -> PathBuf {
    let dir = Path::new(env!("CARGO_TARGET_TMPDIR")).join("replay");
    std::fs::create_dir_all(&dir).unwrap();
    let path = dir.join(format!("{name}.jsonl"));
    std::fs::write(&path, trace).unwrap();
    path
}

fn replay(trace: &Path, extra: &[&str]) -> Output {
    Command::new(idmesh())
        .arg("replay")
        .arg("--trace")
        .arg(trace)
        .args(extra)
        .env_remove("RUST_LOG")
        .output()
        .expect("idmesh runs")
}

/// The JSON lines on stdout of a successful run.
fn lines(output: &Output) -> Vec<Value> {
    assert!(
        output.status.success(),
        "idmesh failed: {}",
        String::from_utf8_lossy(&output.stderr)
    );
    String::from_utf8(output.stdout.clone())
        .unwrap()
        .lines()
        .map(|line| serde_json::from_str(line).expect("stdout is JSON lines"))
        .collect()
}

/// stderr of a run that must fail.
fn failure(output: &Output) -> String {
    assert!(
        !output.status.success(),
        "idmesh succeeded: {}",
        String::from_utf8_lossy(&output.stdout)
    );
    assert_eq!(output.status.code(), Some(1));
    String::from_utf8(output.stderr.clone()).unwrap()
}

fn numbers(value: &Value) -> Vec<f64> {
    value
        .as_array()
        .expect("an array")
        .iter()
        .map(|x| x.as_f64().expect("a number"))
        .collect()
}

fn assert_close(got: &[f64], want: &[f64]) {
    assert_eq!(got.len(), want.len(), "{got:?} vs {want:?}");
    for (g, w) in got.iter().zip(want) {
        assert!((g - w).abs() < 1e-9, "{got:?} vs {want:?}");
    }
}

/// The worked example of the paper's Table I (0-based tracks).
const TABLE1: &str = r#"{"kind":"header","format":"idmesh-trace","version":1,"tracks":4,"red":2,"initial_red":[0,1]}
{"kind":"mix","time":1,"a":0,"b":2,"swap":0.5}
{"kind":"mix","time":2,"a":2,"b":3,"swap":0.5}
{"kind":"observe","time":3,"track":2,"red":1,"blue":0}
{"kind":"truth","time":3,"red":[1,2]}
"#;

fn check_table1(method: &str) {
    let trace = trace_file(&format!("table1-{method}"), TABLE1);
    let out = lines(&replay(&trace, &["--method", method]));
    assert_eq!(out.len(), 2, "{out:?}");
    assert_eq!(out[0]["time"], 3.0);
    assert_close(&numbers(&out[0]["p_red"]), &[0.0, 1.0, 1.0, 0.0]);
    assert_eq!(out[0]["predicted_red"], serde_json::json!([1, 2]));
    assert!(out[0]["coefficients"].as_u64().unwrap() >= 1);
    let summary = &out[1];
    assert_eq!(summary["kind"], "summary");
    assert_eq!(summary["method"], method);
    assert_eq!(summary["events"], 3);
    assert_eq!(summary["error"], 0.0);
    assert!(summary["seconds"].as_f64().unwrap() >= 0.0);
    assert!(summary["max_coefficients"].as_u64().unwrap() >= 1);
}

#[test]
fn table1_overcomplete() {
    check_table1("overcomplete");
}

#[test]
fn table1_exact() {
    check_table1("exact");
}

#[test]
fn every_method_replays_table1() {
    let trace = trace_file("table1-all", TABLE1);
    for extra in [
        &["--method", "overcomplete", "--budget", "2"][..],
        &["--method", "overcomplete", "--distributed-rule"],
        &["--method", "threshold", "--budget", "4"],
        &["--method", "order1"],
        &["--method", "order2"],
        &["--method", "order3"],
    ] {
        let out = lines(&replay(&trace, extra));
        assert_eq!(out.len(), 2, "{extra:?}: {out:?}");
        assert_eq!(out[1]["method"], extra[1]);
        let p = numbers(&out[0]["p_red"]);
        assert_eq!(p.len(), 4);
        assert!(p.iter().all(|x| (-1e-9..=1.0 + 1e-9).contains(x)), "{p:?}");
        assert!(out[1]["error"].as_f64().is_some());
    }
}

#[test]
fn the_shipped_example_is_table1() {
    let example = Path::new(env!("CARGO_MANIFEST_DIR")).join("../examples/table1.jsonl");
    let out = lines(&replay(&example, &[]));
    assert_close(&numbers(&out[0]["p_red"]), &[0.0, 1.0, 1.0, 0.0]);
    assert_eq!(out[1]["error"], 0.0);
}

#[test]
fn more_red_than_tracks_is_refused_at_the_header() {
    let trace = trace_file(
        "too-many-red",
        r#"{"kind":"header","format":"idmesh-trace","version":1,"tracks":2,"red":3}
{"kind":"mix","time":0,"a":0,"b":1,"swap":0.5}
"#,
    );
    let stderr = failure(&replay(&trace, &[]));
    assert!(
        stderr.contains(&format!(
            "{}:1: header: red = 3 but there are only 2 tracks",
            trace.display()
        )),
        "{stderr}"
    );
}

#[test]
fn a_negative_likelihood_names_its_line() {
    let trace = trace_file(
        "negative-likelihood",
        r#"{"kind":"header","format":"idmesh-trace","version":1,"tracks":4,"red":2}
{"kind":"mix","time":0,"a":0,"b":1,"swap":0.5}
{"kind":"observe","time":1,"track":1,"red":-0.5,"blue":0.2}
{"kind":"truth","time":1,"red":[0,1]}
"#,
    );
    let output = replay(&trace, &[]);
    let stderr = failure(&output);
    assert_eq!(
        stderr.trim_end(),
        format!(
            "{}:3: observe: likelihood red = -0.5 is negative",
            trace.display()
        )
    );
    // Nothing was answered: the error came before the truth line.
    assert!(output.stdout.is_empty());
}

#[test]
fn an_unknown_track_names_its_line() {
    let trace = trace_file(
        "unknown-track",
        r#"{"kind":"header","format":"idmesh-trace","version":1,"tracks":4,"red":1}
{"kind":"mix","time":0,"a":0,"b":9,"swap":0.5}
"#,
    );
    let stderr = failure(&replay(&trace, &[]));
    assert!(
        stderr.contains(&format!(
            "{}:2: mix: b = 9 is not a track: there are 4 tracks (0..4)",
            trace.display()
        )),
        "{stderr}"
    );
}

#[test]
fn malformed_json_names_its_line() {
    let trace = trace_file(
        "malformed",
        "{\"kind\":\"header\",\"format\":\"idmesh-trace\",\"version\":1,\"tracks\":4}\n{\"kind\":\"mix\",\n",
    );
    let stderr = failure(&replay(&trace, &[]));
    assert!(
        stderr.starts_with(&format!("{}:2: malformed JSON: ", trace.display())),
        "{stderr}"
    );
}

#[test]
fn a_sighting_the_stream_rules_out_is_taken_by_the_repair_rule() {
    // Track 0 is known red and k = 1: nothing else can be red, yet a sure
    // read says track 1 is. Every filter takes it by the repair rule and
    // says so once on stderr; none stops. The factored belief by default
    // weighs by the whole belief, so it finds the contradiction at the
    // sighting as the exact filter does; under the local rule (what each
    // of several leaders runs) only the query finds it, and answers by
    // the contradiction rule.
    let trace = trace_file(
        "contradicting",
        r#"{"kind":"header","format":"idmesh-trace","version":1,"tracks":3,"initial_red":[0]}
{"kind":"observe","time":0,"track":1,"red":1,"blue":0}
"#,
    );
    let factored_local: &[&str] = &["--method", "factored", "--coupling", "local"];
    for method in [
        "overcomplete",
        "exact",
        "particles",
        "order1",
        "factored",
        "local",
    ] {
        let args: &[&str] = match method {
            "local" => factored_local,
            _ => &["--method", method],
        };
        let output = replay(&trace, args);
        let out = lines(&output);
        let p: Vec<f64> = serde_json::from_value(out[0]["final_p_red"].clone()).unwrap();
        // Counted in the summary: the sighting (and the local rule's query).
        let repairs = if method == "local" { 2 } else { 1 };
        assert_eq!(out[0]["repairs"], repairs, "{method}");
        assert!(
            (p.iter().sum::<f64>() - 1.0).abs() < 1e-9,
            "{method}: {p:?}"
        );
        if method != "local" {
            assert!((p[1] - 1.0).abs() < 1e-9, "{method}: {p:?}");
        }
        // Said once: the sighting's repair (the low-order filter's shrink
        // is its nature and silent), and the local rule's query.
        let said = match method {
            "order1" => 0,
            "local" => 2,
            _ => 1,
        };
        let stderr = String::from_utf8_lossy(&output.stderr);
        assert_eq!(
            stderr.matches("logged once").count(),
            said,
            "{method}: {stderr}"
        );
    }
}

#[test]
fn unknown_red_count_uses_the_uniform_count_prior() {
    // k unknown, uniform over 0..=3 and then over sets: seeing track 0 red
    // for sure leaves P(track 1 red) = P(track 2 red) = 2/3.
    let trace = trace_file(
        "unknown-k",
        r#"{"kind":"header","format":"idmesh-trace","version":1,"tracks":3}
{"kind":"observe","time":0,"track":0,"red":1,"blue":0}
{"kind":"truth","time":0,"red":[0,2]}
"#,
    );
    for method in ["overcomplete", "exact"] {
        let out = lines(&replay(&trace, &["--method", method]));
        assert_close(&numbers(&out[0]["p_red"]), &[1.0, 2.0 / 3.0, 2.0 / 3.0]);
        // Unknown k: every track at least as likely red as not is predicted.
        assert_eq!(out[0]["predicted_red"], serde_json::json!([0, 1, 2]));
        assert!((out[1]["error"].as_f64().unwrap() - 1.0 / 3.0).abs() < 1e-9);
    }
}

#[test]
fn positions_and_identity_reads_are_skipped_and_no_truth_means_null_error() {
    let trace = trace_file(
        "no-truth",
        r#"{"kind":"header","format":"idmesh-trace","version":1,"tracks":3,"red":1,"identities":3}
{"kind":"move","time":0,"track":0,"x":1,"y":2}
{"kind":"identify","time":0,"track":0,"identity":1,"accuracy":0.9}
{"kind":"mix","time":1,"a":0,"b":1,"swap":0.5}
"#,
    );
    let output = replay(&trace, &[]);
    let out = lines(&output);
    assert_eq!(out.len(), 1);
    assert_eq!(out[0]["events"], 1);
    assert_eq!(out[0]["error"], Value::Null);
    assert!(output.stderr.is_empty(), "logs are off by default");
}

#[test]
fn threshold_needs_a_budget() {
    let trace = trace_file("threshold-no-budget", TABLE1);
    let stderr = failure(&replay(&trace, &["--method", "threshold"]));
    assert!(
        stderr.contains("--method threshold needs --budget"),
        "{stderr}"
    );
}

#[test]
fn a_missing_trace_is_reported() {
    let missing = Path::new(env!("CARGO_TARGET_TMPDIR")).join("replay/does-not-exist.jsonl");
    let stderr = failure(&replay(&missing, &[]));
    assert!(stderr.starts_with("cannot open trace "), "{stderr}");
}

#[test]
fn debug_logs_go_to_stderr_only() {
    let trace = trace_file("logs", TABLE1);
    let output = Command::new(idmesh())
        .args(["replay", "--trace"])
        .arg(&trace)
        .env("RUST_LOG", "debug")
        .output()
        .unwrap();
    let out = lines(&output);
    assert_eq!(out.len(), 2);
    let stderr = String::from_utf8(output.stderr).unwrap();
    assert!(stderr.contains("replay"), "{stderr}");
    assert!(stderr.contains("line=4"), "{stderr}");
}
