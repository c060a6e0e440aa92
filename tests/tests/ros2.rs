//! ROS 2 in and out, checked against an encoder idmesh did not write
//! (`rosbags`, through `tests/python/ros2_tracker.py`):
//!
//! - a bag of `vision_msgs/msg/Detection2DArray` written by rosbags gives,
//!   through `idmesh extract --format rosbag2`, the very trace the same
//!   reports give as JSON lines;
//! - the same messages published over Zenoh on rmw_zenoh's key to a live
//!   deployment (one of them truncated: counted, the stream goes on) give
//!   the answer `idmesh replay --topology` computes from the reports (the
//!   twin), whether the key carries Jazzy's type hash or Humble's
//!   `TypeHashNotSupported`, and the web gateway's `MarkerArray` decodes with rosbags, with
//!   rmw_zenoh's attachment and liveliness tokens, and shows what `idmesh
//!   query` answers.

use idmesh_extract::adapters::ros2::markers::MARKER_ARRAY_HASH;
use idmesh_extract::adapters::ros2::{MessageType, TopicOptions};
use idmesh_extract::ExtractorConfig;
use idmesh_sensor::ros2::Ros2Config;
use idmesh_tests::{
    assert_same_marginals, floats, header_only, idmesh, python_with_zenoh, Deployment, Factored,
    Gateway, Settings,
};
use serde_json::{json, Value};
use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::Duration;

/// Metres per pixel of the test's detector.
const SCALE: f64 = 0.5;
const TOPIC: &str = "/tracker/detections";

/// Four tracks for `frames` frames at 10 Hz, in pixels: 0 and 1 walk
/// towards each other and meet, 2 and 3 stand apart; every detection has
/// class scores.
fn frames(count: u32) -> Vec<Value> {
    (0..count)
        .map(|f| {
            let t = f64::from(f) / f64::from(count);
            let detections = vec![
                json!({"id":"0","x":24.0 * t,"y":0.0,"classes":[["red",0.9],["blue",0.1]]}),
                json!({"id":"1","x":24.0 * (1.0 - t),"y":1.0,"classes":[["red",0.2],["blue",0.8]]}),
                json!({"id":"2","x":60.0,"y":30.0 + f64::from(f % 3),"classes":[["red",0.7]]}),
                json!({"id":"3","x":-60.0,"y":10.0,"classes":[["blue",0.6],["red",0.4]]}),
            ];
            json!({"sec": f / 10, "nanosec": (f % 10) * 100_000_000, "detections": detections})
        })
        .collect()
}

/// What the adapter makes of a frame, as JSON lines of the trace format
/// (computed as it does: the stamp's seconds, pixels times the scale,
/// a sum of scores short of one to `other`).
fn report_lines(frame: &Value) -> Vec<String> {
    let time = frame["sec"].as_f64().unwrap() + frame["nanosec"].as_f64().unwrap() * 1e-9;
    frame["detections"]
        .as_array()
        .unwrap()
        .iter()
        .map(|d| {
            let mut scores = serde_json::Map::new();
            for c in d["classes"].as_array().unwrap() {
                scores.insert(c[0].as_str().unwrap().into(), c[1].clone());
            }
            let sum: f64 = scores.values().map(|v| v.as_f64().unwrap()).sum();
            if sum < 1.0 - 1e-9 {
                scores.insert("other".into(), json!(1.0 - sum));
            }
            json!({"kind":"detect","time":time,"track":d["id"].as_str().unwrap().parse::<u32>().unwrap(),
                "x": d["x"].as_f64().unwrap() * SCALE + 0.0, "y": d["y"].as_f64().unwrap() * SCALE + 0.0,
                "scores": scores})
            .to_string()
        })
        .collect()
}

fn write_frames(dir: &Path, frames: &[Value]) -> PathBuf {
    let path = dir.join("frames.json");
    std::fs::write(&path, serde_json::to_string(frames).unwrap()).unwrap();
    path
}

/// Runs `command`; its standard output, or a panic naming `what` and
/// what it said.
fn stdout_of(command: &mut Command, what: &str) -> Vec<u8> {
    let output = command.output().expect("the command starts");
    assert!(
        output.status.success(),
        "{what} failed: {}",
        String::from_utf8_lossy(&output.stderr)
    );
    output.stdout
}

/// Runs `tests/python/ros2_tracker.py` with `args`: the JSON line it prints.
fn tracker(args: &[&str]) -> Value {
    let tmp = Path::new(env!("CARGO_TARGET_TMPDIR"));
    let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("python/ros2_tracker.py");
    let mut command = Command::new(python_with_zenoh(tmp));
    command.arg(script).args(args);
    let out = stdout_of(&mut command, &format!("ros2_tracker.py {args:?}"));
    serde_json::from_slice(&out).expect("one JSON line")
}

/// `idmesh extract` with `args`: the trace it prints.
fn extract(args: &[&str]) -> String {
    let mut command = Command::new(idmesh());
    command.arg("extract").args(args);
    String::from_utf8(stdout_of(&mut command, &format!("idmesh extract {args:?}"))).unwrap()
}

fn scratch(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("idmesh-ros2-{name}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

#[test]
fn a_rosbags_bag_extracts_as_its_reports_do_as_json_lines() {
    let dir = scratch("bag");
    let frames = frames(60);
    let spec = write_frames(&dir, &frames);
    let bag = dir.join("bag");
    tracker(&["bag", bag.to_str().unwrap(), spec.to_str().unwrap()]);
    let mcap = std::fs::read_dir(&bag)
        .unwrap()
        .filter_map(Result::ok)
        .map(|e| e.path())
        .find(|p| p.extension().is_some_and(|e| e == "mcap"))
        .expect("rosbags wrote an .mcap file");
    let lines: Vec<String> = frames.iter().flat_map(report_lines).collect();
    let jsonl = dir.join("reports.jsonl");
    std::fs::write(&jsonl, lines.join("\n") + "\n").unwrap();
    let scale = SCALE.to_string();
    let from_bag = extract(&[
        "--format",
        "rosbag2",
        mcap.to_str().unwrap(),
        "--scale",
        &scale,
        "--roster",
        "first-frame",
    ]);
    let from_lines = extract(&["--format", "jsonl", jsonl.to_str().unwrap()]);
    assert!(from_bag.contains("\"kind\":\"mix\""), "{from_bag}");
    assert!(from_bag.contains("\"kind\":\"observe\""), "{from_bag}");
    assert_eq!(from_bag, from_lines);
    let _ = std::fs::remove_dir_all(&dir);
}

/// The marker array the gateway publishes, as rosbags decoded it.
/// The marker array on `topic` (no leading slash) whose key ends in
/// `hash`, as rosbags decoded it.
fn markers(deployment: &Deployment, topic: &str, hash: &str) -> Value {
    let key = format!("0/{topic}/visualization_msgs::msg::dds_::MarkerArray_/{hash}");
    tracker(&["markers", &deployment.coordinator, &key, "15"])
}

fn check_markers(got: &Value, positions: &Value, marginals: &Value) {
    assert!(got.get("error").is_none(), "{got}");
    let attachment = &got["attachment"];
    assert_eq!(
        attachment["keys"],
        json!(["sequence_number", "source_timestamp", "source_gid"])
    );
    assert_eq!(attachment["gid_len"], 16);
    assert!(attachment["sequence_number"].as_i64().unwrap() >= 1);
    let tokens: Vec<&str> = got["tokens"]
        .as_array()
        .unwrap()
        .iter()
        .filter_map(Value::as_str)
        .collect();
    assert!(
        tokens
            .iter()
            .any(|t| t.starts_with("@ros2_lv/0/") && t.ends_with("/NN/%/%/idmesh_web")),
        "{tokens:?}"
    );
    assert!(tokens.iter().any(|t| t.contains("/MP/%/%/idmesh_web/%idmesh%markers/visualization_msgs::msg::dds_::MarkerArray_/RIHS01_")), "{tokens:?}");
    let markers = got["markers"].as_array().unwrap();
    let p_red = marginals["p_red"].as_array().unwrap();
    for (track, at) in positions["positions"]
        .as_array()
        .unwrap()
        .iter()
        .enumerate()
    {
        let sphere = markers
            .iter()
            .find(|m| m["ns"] == "idmesh/tracks" && m["id"] == track)
            .unwrap_or_else(|| panic!("no sphere of track {track}: {got}"));
        assert_eq!(sphere["x"], at[0]);
        assert_eq!(sphere["y"], at[1]);
        let p = p_red[track].as_f64().unwrap();
        assert!(
            (sphere["r"].as_f64().unwrap() - p).abs() < 1e-6,
            "{sphere} vs {p}"
        );
        assert!((sphere["b"].as_f64().unwrap() - (1.0 - p)).abs() < 1e-6);
        let text = markers
            .iter()
            .find(|m| m["ns"] == "idmesh/identities" && m["id"] == track)
            .unwrap();
        assert_eq!(text["text"], format!("track {track}: P(red) {p:.2}"));
    }
}

/// A live deployment reading [`TOPIC`], fed `frames` by rosbags and the
/// Python Zenoh client on rmw_zenoh's key with `hash` in its last chunk,
/// frame `bad` truncated; it
/// checks the answer equals the twin's (`idmesh replay --topology` on the
/// reports the sensor took) and the bad message was counted.
fn fed_deployment(name: &str, dir: &Path, frames: &[Value], bad: usize, hash: &str) -> Deployment {
    // The twin's reports: every frame the sensor takes (the truncated one
    // is refused) but the last, which a live stream keeps open.
    let header = json!({"kind":"header","format":"idmesh-trace","version":2,"tracks":4,"red":2});
    let mut lines = vec![header.to_string()];
    for (i, frame) in frames.iter().enumerate() {
        if i != bad && i + 1 < frames.len() {
            lines.extend(report_lines(frame));
        }
    }
    let reports = dir.join("reports.jsonl");
    std::fs::write(&reports, lines.join("\n") + "\n").unwrap();
    let mut topic = TopicOptions::new(TOPIC, MessageType::Detection2DArray);
    topic.scale = SCALE;
    let settings = Settings {
        leaders: 2,
        live: true,
        factored: Some(Factored::default()),
        extract: Some(ExtractorConfig::default()),
        sensor_trace: Some(header_only(&reports, dir)),
        ros2: Some(Ros2Config {
            domain: 0,
            topics: vec![topic],
        }),
        ..Settings::default()
    };
    let deployment = Deployment::start_each(name, &reports, &settings);
    deployment.first_answer(Duration::from_secs(30));
    let twin = deployment.twin_summary(&reports);
    // The lines the watermark counts: every event and move line the
    // reports make.
    let events = extract(&[reports.to_str().unwrap()])
        .lines()
        .filter(|l| !l.contains("\"kind\":\"header\""))
        .count() as u64;
    let spec = write_frames(dir, frames);
    let key = format!("0/tracker/detections/vision_msgs::msg::dds_::Detection2DArray_/{hash}");
    let bad = bad.to_string();
    tracker(&[
        "publish",
        deployment.sensor_endpoint(),
        &key,
        spec.to_str().unwrap(),
        "--bad",
        &bad,
    ]);
    let answer = deployment.answer_when(&["marginals"], Duration::from_secs(30), |a| {
        a["watermark"]["sensor-0"].as_u64() == Some(events)
    });
    assert_same_marginals(&answer, &floats(&twin["final_p_red"]), "ROS 2 topic");
    let stats = &deployment.sensor_stats()[0];
    assert_eq!(stats["ros2_messages"], frames.len() as u64, "{stats}");
    assert_eq!(stats["ros2_bad"], 1, "{stats}");
    deployment
}

#[test]
fn a_ros2_topic_feeds_a_deployment_as_its_twin_and_a_bad_message_is_counted() {
    let dir = scratch("live");
    // Jazzy's key form (a type hash).
    let hash = format!("RIHS01_{}", "0".repeat(64));
    let deployment = fed_deployment("ros2-live", &dir, &frames(40), 7, &hash);
    assert!(
        deployment.log().contains("a ROS 2 message refused"),
        "the bad message is not named in the log"
    );
    drop(deployment);
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn the_markers_decode_with_rosbags_and_show_what_query_answers() {
    let dir = scratch("markers");
    // Humble's key form: the sensor subscribes with `*` for the hash.
    let deployment = fed_deployment("ros2-markers", &dir, &frames(30), 3, "TypeHashNotSupported");
    let _gateway = Gateway::start_with(
        &deployment,
        &["--ros2-markers", "/idmesh/markers", "--ros2-rate", "5"],
    );
    // Subscribed with the hash rosbags computes from the type description
    // (REP 2011): the gateway's constant must be that hash.
    let hash = tracker(&["hash"])["hash"].as_str().unwrap().to_string();
    assert_eq!(hash, MARKER_ARRAY_HASH);
    let got = markers(&deployment, "idmesh/markers", &hash);
    let positions = deployment.query(&["positions"]).unwrap().remove(0);
    let marginals = deployment.query(&["marginals"]).unwrap().remove(0);
    check_markers(&got, &positions, &marginals);
    // For Humble subscribers: `TypeHashNotSupported` in the key.
    let _humble = Gateway::start_with(
        &deployment,
        &["--ros2-markers", "/idmesh/humble", "--ros2-humble"],
    );
    let got = markers(&deployment, "idmesh/humble", "TypeHashNotSupported");
    assert!(got.get("error").is_none(), "{got}");
    assert!(!got["markers"].as_array().unwrap().is_empty(), "{got}");
    drop(deployment);
    let _ = std::fs::remove_dir_all(&dir);
}
