//! Several live sensors and no single sequencer, with real processes on
//! loopback: a Python producer (`examples/regions_producer.py`,
//! eclipse-zenoh) splits a trace's events by region and feeds two, then
//! three sensors concurrently — targets cross between the sensors'
//! regions, mixes across two regions go to both sensors — and the answers
//! at the trace's truth points and at the end equal `idmesh replay` of the
//! whole trace to 1e-9, for the Radon and the factored belief. Every event
//! is counted once at the leaders' sensors (a mix given to two sensors is
//! merged once), and each answer's watermark names every sensor.

use idmesh_tests::{assert_same_marginals, floats};
use idmesh_tests::{
    assert_truth_points, crowd, grid_over, header_only, replay_lines, replay_summary, trace_events,
    truth_lines, watermark_events, Deployment, Factored, Settings, SplitSetting,
};
use serde_json::Value;
use std::path::Path;
use std::process::Command;
use std::time::Duration;

/// The factored options of both sides (small components: splits happen).
const FACTORED: Factored = Factored {
    max_component: 3,
    split: SplitSetting::Original,
    regional: false,
    spread_above: 0,
};
const FACTORED_REPLAY: &[&str] = &[
    "--method",
    "factored",
    "--coupling",
    "local",
    "--max-component",
    "3",
    "--split",
    "original",
];
const RADON_REPLAY: &[&str] = &["--method", "overcomplete"];

fn fed_by_region(name: &str, sensors: usize, factored: bool, seed: u64) {
    let (dir, _scratch) = idmesh_tests::scratch(&format!("idmesh-{name}"));
    let trace = crowd(&dir, 12, 4, 90.0, seed);
    let replay = if factored {
        FACTORED_REPLAY
    } else {
        RADON_REPLAY
    };
    let central = replay_summary(&trace, replay);
    let central_lines = replay_lines(&trace, replay);
    let truths = truth_lines(&trace);
    let settings = Settings {
        leaders: 3,
        sensors,
        live: true,
        sensor_trace: Some(header_only(&trace, &dir)),
        factored: factored.then_some(FACTORED),
        ..Settings::default()
    };
    let deployment = Deployment::start_each(name, &trace, &settings);
    let first = deployment.first_answer(Duration::from_secs(30));
    for s in 0..sensors {
        assert_eq!(first["watermark"][format!("sensor-{s}")], 0, "{first}");
    }
    let events = trace_events(&trace).len() as u64;
    let (points, sent) = std::thread::scope(|scope| {
        let asked = scope.spawn(|| deployment.at_truth_points("marginals", &truths));
        // The questions are placed (held at their points) before any event.
        std::thread::sleep(Duration::from_millis(1500));
        let sent = report_of(regions_producer(&deployment, &trace, sensors, 20));
        (asked.join().expect("the questions"), sent)
    });
    assert_eq!(sent["events"], events, "{sent}");
    let doubled = sent["doubled"].as_u64().expect("doubled");
    let accepted: u64 = (0..sensors)
        .map(|s| {
            sent["sensors"][format!("sensor-{s}")]["accepted"]
                .as_u64()
                .unwrap_or(0)
        })
        .sum();
    assert_eq!(accepted, events + doubled, "{sent}");
    for s in 0..sensors {
        let report = &sent["sensors"][format!("sensor-{s}")];
        assert!(
            report["accepted"].as_u64().unwrap_or(0) > 0,
            "sensor-{s} took nothing: {sent}"
        );
        assert_eq!(report["errors"].as_array().map(Vec::len), Some(0), "{sent}");
    }
    assert_truth_points(&points, &truths, &central_lines, name);
    let answer = deployment.answer_when(&["marginals"], Duration::from_secs(60), |a| {
        a["finished"] == true && watermark_events(a) == events
    });
    assert_same_marginals(&answer, &floats(&central["final_p_red"]), name);
    let watermark = answer["watermark"].as_object().expect("a watermark");
    assert_eq!(watermark.len(), sensors, "{answer}");
    let stats = deployment.sensor_stats();
    assert_eq!(stats.len(), sensors);
    for sensor in &stats {
        assert_eq!(sensor["merged"], events, "{sensor}");
        assert_eq!(sensor["merged_twice"], doubled, "{sensor}");
        assert_eq!(sensor["rejected"], 0, "{sensor}");
    }
    let ingested: u64 = stats
        .iter()
        .map(|s| s["ingested"].as_u64().unwrap_or(0))
        .sum();
    assert_eq!(ingested, events + doubled);
}

#[test]
fn two_live_sensors_fed_by_region_give_the_answer_of_replay() {
    fed_by_region("sensors2-radon", 2, false, 6);
    fed_by_region("sensors2-factored", 2, true, 7);
}

#[test]
fn three_live_sensors_fed_by_region_give_the_answer_of_replay() {
    fed_by_region("sensors3-radon", 3, false, 8);
    fed_by_region("sensors3-factored", 3, true, 9);
}

/// `examples/regions_producer.py` feeding `sensors` sensors of
/// `deployment` the regions of `trace`, `batch` lines a request, started.
fn regions_producer(
    deployment: &Deployment,
    trace: &Path,
    sensors: usize,
    batch: usize,
) -> std::process::Child {
    let python = idmesh_tests::python_with_zenoh(Path::new(env!("CARGO_TARGET_TMPDIR")));
    let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("../examples/regions_producer.py");
    Command::new(&python)
        .arg(&script)
        .arg(trace)
        .args([deployment.sensor_endpoint(), &deployment.prefix])
        .args(["--batch", &batch.to_string()])
        .args(
            grid_over(trace, sensors)
                .iter()
                .enumerate()
                .flat_map(|(s, (x, y))| ["--sensor".to_string(), format!("sensor-{s}@{x},{y}")]),
        )
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .expect("python runs")
}

/// The producer's report once it is done.
fn report_of(producer: std::process::Child) -> Value {
    let output = producer.wait_with_output().expect("the producer ends");
    assert!(
        output.status.success(),
        "the producer failed: {}",
        String::from_utf8_lossy(&output.stderr)
    );
    serde_json::from_slice(&output.stdout).expect("the producer's JSON")
}

/// One sensor of two, journaling, SIGKILLed while the producer feeds both:
/// queries meanwhile say `degraded`, naming it (the order cannot pass its
/// events); started again on its journal it resumes where it was, the
/// producer's requests to it go through again, and the final answer is
/// replay's, every event merged exactly once at both sensors and every
/// leader having applied what it applies in the same run left alone.
#[test]
fn a_sensor_of_two_killed_mid_stream_comes_back_and_nothing_is_lost_or_doubled() {
    let name = "sensors-kill";
    let (dir, _scratch) = idmesh_tests::scratch(&format!("idmesh-{name}"));
    let trace = crowd(&dir, 12, 4, 150.0, 11);
    let central = replay_summary(&trace, RADON_REPLAY);
    let settings = Settings {
        leaders: 2,
        sensors: 2,
        live: true,
        journal: true,
        sensor_trace: Some(header_only(&trace, &dir)),
        ..Settings::default()
    };
    let events = trace_events(&trace).len() as u64;
    let finished = |deployment: &Deployment| {
        deployment.answer_when(&["marginals"], Duration::from_secs(60), |a| {
            a["finished"] == true && watermark_events(a) == events
        })
    };
    let calm = Deployment::start_each("sensors-calm", &trace, &settings);
    calm.first_answer(Duration::from_secs(30));
    report_of(regions_producer(&calm, &trace, 2, 2));
    assert_same_marginals(&finished(&calm), &floats(&central["final_p_red"]), "calm");
    let calm_applied = calm.applied();
    drop(calm);

    let mut deployment = Deployment::start_each(name, &trace, &settings);
    deployment.first_answer(Duration::from_secs(30));
    let producer = regions_producer(&deployment, &trace, 2, 2);
    // Mid-stream: some events of both sensors merged, far from all.
    deployment.answer_when(&["marginals"], Duration::from_secs(60), |a| {
        watermark_events(a) > events / 5
    });
    deployment.kill("sensor-1");
    let error = deployment
        .query(&["marginals"])
        .expect_err("no answer without sensor-1");
    assert!(
        error.contains("degraded") && error.contains("sensor-1"),
        "{error}"
    );
    std::thread::sleep(Duration::from_millis(500));
    deployment.launch("sensor", "sensor-1");
    let sent = report_of(producer);
    let answer = finished(&deployment);
    assert_same_marginals(&answer, &floats(&central["final_p_red"]), name);
    let doubled = sent["doubled"].as_u64().expect("doubled");
    let stats = deployment.sensor_stats();
    for sensor in &stats {
        assert_eq!(sensor["merged"], events, "{sensor}");
        assert_eq!(sensor["merged_twice"], doubled, "{sensor}");
    }
    // Each sensor took each of its events once: what sensor-1 took before
    // it was killed came back from its journal, and a request sent again
    // after the restart is a duplicate.
    let ingested: u64 = stats
        .iter()
        .map(|s| s["ingested"].as_u64().unwrap_or(0))
        .sum();
    assert_eq!(ingested, events + doubled, "{stats:?}");
    assert_eq!(
        deployment.applied(),
        calm_applied,
        "what the leaders applied"
    );
}
