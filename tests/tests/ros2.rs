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
//!   `TypeHashNotSupported`, and the web gateway's `MarkerArray` — from
//!   `idmesh web --ros2-markers` and from the `[web]` section `idmesh up`
//!   serves — decodes with rosbags, with rmw_zenoh's attachment and
//!   liveliness tokens, and shows what `idmesh query` answers;
//! - named ids keep their track numbers when the sensor is SIGKILLed and
//!   restarted from its journal, so the answer is still the twin's of the
//!   reports a bag of the same messages extracts as.

use idmesh_extract::adapters::ros2::markers::MARKER_ARRAY_HASH;
use idmesh_extract::adapters::ros2::{MessageType, TopicOptions};
use idmesh_extract::ExtractorConfig;
use idmesh_sensor::ros2::Ros2Config;
use idmesh_tests::{
    assert_same_marginals, floats, header_only, idmesh, python_with_zenoh, Deployment, Factored,
    Gateway, MarkerOptions, Settings, WebSection,
};
use serde_json::{json, Value};
use std::collections::BTreeMap;
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

/// The track numbers of `frames`' ids, by the adapter's rule
/// (docs/guide/ros2.md): an id that is a whole number is that track, any
/// other the next number in the order ids first appear, from 0.
fn numbering(frames: &[Value]) -> BTreeMap<String, u32> {
    let mut numbers = BTreeMap::new();
    let mut named = 0;
    for detection in frames
        .iter()
        .flat_map(|f| f["detections"].as_array().unwrap())
    {
        let id = detection["id"].as_str().unwrap();
        if numbers.contains_key(id) {
            continue;
        }
        let number = id.parse::<u32>().unwrap_or_else(|_| {
            named += 1;
            named - 1
        });
        numbers.insert(id.to_string(), number);
    }
    numbers
}

/// What the adapter makes of a frame, as JSON lines of the trace format
/// (computed as it does: the track its id's number in `numbers`, the
/// stamp's seconds, pixels times the scale, a sum of scores short of one
/// to `other`).
fn report_lines(frame: &Value, numbers: &BTreeMap<String, u32>) -> Vec<String> {
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
            json!({"kind":"detect","time":time,"track":numbers[d["id"].as_str().unwrap()],
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

/// A rosbag2 bag of `frames` written by rosbags in `dir`: its `.mcap`.
fn bag_of(dir: &Path, frames: &[Value]) -> PathBuf {
    let spec = write_frames(dir, frames);
    let bag = dir.join("bag");
    tracker(&["bag", bag.to_str().unwrap(), spec.to_str().unwrap()]);
    std::fs::read_dir(&bag)
        .unwrap()
        .filter_map(Result::ok)
        .map(|e| e.path())
        .find(|p| p.extension().is_some_and(|e| e == "mcap"))
        .expect("rosbags wrote an .mcap file")
}

#[test]
fn a_rosbags_bag_extracts_as_its_reports_do_as_json_lines() {
    let dir = scratch("bag");
    let frames = frames(60);
    let mcap = bag_of(&dir, &frames);
    let numbers = numbering(&frames);
    let lines: Vec<String> = frames
        .iter()
        .flat_map(|f| report_lines(f, &numbers))
        .collect();
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

/// The marker array on `topic` (no leading slash) whose key ends in
/// `hash`, as rosbags decoded it.
fn markers(deployment: &Deployment, topic: &str, hash: &str) -> Value {
    let key = format!("0/{topic}/visualization_msgs::msg::dds_::MarkerArray_/{hash}");
    tracker(&["markers", &deployment.coordinator, &key, "15"])
}

/// `got` (see [`markers`]) was published on `topic` (no leading slash)
/// as rmw_zenoh publishes, and shows the answers `positions` and
/// `marginals`.
fn check_markers(got: &Value, topic: &str, positions: &Value, marginals: &Value) {
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
    let publisher = format!(
        "/MP/%/%/idmesh_web/%{}/visualization_msgs::msg::dds_::MarkerArray_/RIHS01_",
        topic.replace('/', "%")
    );
    assert!(tokens.iter().any(|t| t.contains(&publisher)), "{tokens:?}");
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

/// The reports of `frames` (numbered by `numbers`) under the stream's
/// header, written to `dir/name`: what the twin (`idmesh replay
/// --topology`) reads.
fn write_reports(
    dir: &Path,
    name: &str,
    frames: &[&Value],
    numbers: &BTreeMap<String, u32>,
) -> PathBuf {
    let header = json!({"kind":"header","format":"idmesh-trace","version":2,"tracks":4,"red":2});
    let mut lines = vec![header.to_string()];
    for frame in frames {
        lines.extend(report_lines(frame, numbers));
    }
    let path = dir.join(name);
    std::fs::write(&path, lines.join("\n") + "\n").unwrap();
    path
}

/// The lines a watermark counts once the sensor took `reports`: every
/// event and move line they make.
fn events_of(reports: &Path) -> u64 {
    extract(&[reports.to_str().unwrap()])
        .lines()
        .filter(|l| !l.contains("\"kind\":\"header\""))
        .count() as u64
}

/// A live deployment's settings: its sensor reads [`TOPIC`] with the
/// stream's header alone for a trace, and extracts.
fn live_settings(reports: &Path, dir: &Path) -> Settings {
    let mut topic = TopicOptions::new(TOPIC, MessageType::Detection2DArray);
    topic.scale = SCALE;
    Settings {
        leaders: 2,
        live: true,
        factored: Some(Factored::default()),
        extract: Some(ExtractorConfig::default()),
        sensor_trace: Some(header_only(reports, dir)),
        ros2: Some(Ros2Config {
            domain: 0,
            topics: vec![topic],
        }),
        ..Settings::default()
    }
}

/// Publishes `frames` on [`TOPIC`]'s rmw_zenoh key (`hash` in its last
/// chunk) to the deployment's sensor, with `extra` arguments (`--bad N`).
fn publish(deployment: &Deployment, dir: &Path, frames: &[Value], hash: &str, extra: &[&str]) {
    let spec = write_frames(dir, frames);
    let key = format!("0/tracker/detections/vision_msgs::msg::dds_::Detection2DArray_/{hash}");
    let mut args = vec![
        "publish",
        deployment.sensor_endpoint(),
        &key,
        spec.to_str().unwrap(),
    ];
    args.extend(extra);
    tracker(&args);
}

/// A live deployment reading [`TOPIC`], fed `frames` by rosbags and the
/// Python Zenoh client on rmw_zenoh's key with `hash` in its last chunk,
/// frame `bad` truncated; it
/// checks the answer equals the twin's (`idmesh replay --topology` on the
/// reports the sensor took) and the bad message was counted. With `web`,
/// the deployment runs under `idmesh up`, which serves that `[web]`
/// gateway; else each process on its own.
fn fed_deployment(
    name: &str,
    dir: &Path,
    frames: &[Value],
    bad: usize,
    hash: &str,
    web: Option<WebSection>,
) -> Deployment {
    // The twin's reports: every frame the sensor takes (the truncated one
    // is refused) but the last, which a live stream keeps open.
    let taken: Vec<&Value> = frames[..frames.len() - 1]
        .iter()
        .enumerate()
        .filter(|&(i, _)| i != bad)
        .map(|(_, f)| f)
        .collect();
    let reports = write_reports(dir, "reports.jsonl", &taken, &numbering(frames));
    let settings = Settings {
        web: web.clone(),
        ..live_settings(&reports, dir)
    };
    let deployment = match web {
        Some(_) => Deployment::start(name, &reports, &settings),
        None => Deployment::start_each(name, &reports, &settings),
    };
    deployment.first_answer(Duration::from_secs(30));
    let twin = deployment.twin_summary(&reports);
    let events = events_of(&reports);
    publish(&deployment, dir, frames, hash, &["--bad", &bad.to_string()]);
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
    let deployment = fed_deployment("ros2-live", &dir, &frames(40), 7, &hash, None);
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
    // Under `idmesh up`, whose topology's `[web]` publishes markers too
    // (its HTTP port any free one: only the markers are looked at).
    let web = WebSection {
        markers: MarkerOptions {
            ros2_markers: Some("/idmesh/up".into()),
            ros2_rate: 5.0,
            ..MarkerOptions::default()
        },
        ..WebSection::new("127.0.0.1:0")
    };
    // Humble's key form: the sensor subscribes with `*` for the hash.
    let frames = frames(30);
    let hash = "TypeHashNotSupported";
    let deployment = fed_deployment("ros2-markers", &dir, &frames, 3, hash, Some(web));
    let _gateway = Gateway::start_with(
        &deployment,
        &["--ros2-markers", "/idmesh/markers", "--ros2-rate", "5"],
    );
    // Subscribed with the hash rosbags computes from the type description
    // (REP 2011): the gateway's constant must be that hash.
    let hash = tracker(&["hash"])["hash"].as_str().unwrap().to_string();
    assert_eq!(hash, MARKER_ARRAY_HASH);
    let positions = deployment.query(&["positions"]).unwrap().remove(0);
    let marginals = deployment.query(&["marginals"]).unwrap().remove(0);
    // From `idmesh web --ros2-markers`, and from `idmesh up`'s `[web]`.
    for topic in ["idmesh/markers", "idmesh/up"] {
        let got = markers(&deployment, topic, &hash);
        check_markers(&got, topic, &positions, &marginals);
    }
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

/// `count` frames of tracks named, not numbered: "bravo" and "alpha" walk
/// at each other, meet and part, and stand still for the last three
/// frames; "charlie" stands apart; "delta" stands apart from frame `late`
/// on. Before `late` the detections come as bravo, alpha, charlie; from
/// it delta first and the others reversed, so that a decoder numbering
/// afresh there would give every id another number.
fn named_frames(count: u32, late: u32) -> Vec<Value> {
    (0..count)
        .map(|f| {
            let t = f64::from(f.min(count - 3)) / f64::from(count - 3);
            let bravo = json!({"id":"bravo","x":24.0 * t,"y":0.0,"classes":[["red",0.9],["blue",0.1]]});
            let alpha = json!({"id":"alpha","x":24.0 * (1.0 - t),"y":1.0,"classes":[["red",0.2],["blue",0.8]]});
            let charlie = json!({"id":"charlie","x":60.0,"y":30.0,"classes":[["red",0.7]]});
            let delta = json!({"id":"delta","x":-60.0,"y":10.0,"classes":[["blue",0.6],["red",0.4]]});
            let detections = if f < late {
                vec![bravo, alpha, charlie]
            } else {
                vec![delta, charlie, alpha, bravo]
            };
            json!({"sec": f / 10, "nanosec": (f % 10) * 100_000_000, "detections": detections})
        })
        .collect()
}

/// A sensor reading named ids is SIGKILLed after the first half of the
/// frames and started again from its journal (compacted every kilobyte,
/// so it resumes from a snapshot and the numbers stated after it), then
/// fed the rest, where the old ids come in another order and a new one
/// first. The ids' numbers were on disk; the answer is the twin's of the
/// reports numbered in the order the ids first appear — the reports a bag
/// of the same messages extracts as — and every id seen before the
/// restart is still the track that stands where it stands.
#[test]
fn named_ids_keep_their_tracks_when_the_sensor_restarts_from_its_journal() {
    use idmesh_sensor::journal::{read, Record};
    let dir = scratch("restart");
    let late = 20;
    let frames = named_frames(40, late);
    let numbers = numbering(&frames);
    let all: Vec<&Value> = frames.iter().collect();
    // Offline: the bag's ids are numbered as these reports number them.
    let complete = write_reports(&dir, "complete.jsonl", &all, &numbers);
    let mcap = bag_of(&dir, &frames);
    let scale = SCALE.to_string();
    let from_bag = extract(&[
        "--format",
        "rosbag2",
        mcap.to_str().unwrap(),
        "--scale",
        &scale,
        "--red",
        "2",
    ]);
    assert_eq!(from_bag, extract(&[complete.to_str().unwrap()]));

    // The twin's reports: every frame but the last, which a live stream
    // keeps open.
    let reports = write_reports(&dir, "reports.jsonl", &all[..all.len() - 1], &numbers);
    let first = write_reports(&dir, "first.jsonl", &all[..late as usize - 1], &numbers);
    let settings = Settings {
        journal: true,
        compact_journal_after: Some(1024),
        ..live_settings(&reports, &dir)
    };
    let mut deployment = Deployment::start_each("ros2-restart", &reports, &settings);
    deployment.first_answer(Duration::from_secs(30));
    let twin = deployment.twin_summary(&reports);
    let hash = "TypeHashNotSupported";
    publish(&deployment, &dir, &frames[..late as usize], hash, &[]);
    let before = events_of(&first);
    deployment.answer_when(&["marginals"], Duration::from_secs(30), |a| {
        a["watermark"]["sensor-0"].as_u64() == Some(before)
    });
    deployment.kill("sensor-0");

    // On disk: the numbers of the ids seen so far, stated after the
    // snapshot of the compacted journal (and after it, if any came since).
    let records = read(&deployment.dir.join("state").join("sensor-0.journal")).unwrap();
    assert!(
        matches!(records[..], [Record::Stream(_), Record::Snapshot(_), ..]),
        "compacted: {:?}",
        records.iter().take(3).collect::<Vec<_>>()
    );
    let mut journaled: Vec<String> = Vec::new();
    for record in &records {
        if let Record::TrackIds {
            producer,
            first,
            ids,
        } = record
        {
            assert_eq!(producer, &format!("ros2:{TOPIC}"));
            journaled.truncate(*first as usize);
            journaled.extend(ids.iter().cloned());
        }
    }
    let seen = numbering(&frames[..late as usize]);
    let mut in_order: Vec<(&String, &u32)> = seen.iter().collect();
    in_order.sort_by_key(|&(_, n)| *n);
    let in_order: Vec<String> = in_order.into_iter().map(|(id, _)| id.clone()).collect();
    assert_eq!(journaled, in_order);

    deployment.launch("sensor", "sensor-0");
    deployment.first_answer(Duration::from_secs(30));
    publish(&deployment, &dir, &frames[late as usize..], hash, &[]);
    let events = events_of(&reports);
    let answer = deployment.answer_when(&["marginals"], Duration::from_secs(30), |a| {
        a["watermark"]["sensor-0"].as_u64() == Some(events)
    });
    assert_same_marginals(
        &answer,
        &floats(&twin["final_p_red"]),
        "ROS 2 topic, restarted",
    );
    // Each id seen before the restart is still its track: the deployment
    // puts the track where the offline trace of the reports last moved
    // it, and there, at that time, the messages had that id.
    let positions = deployment.query(&["positions"]).unwrap().remove(0);
    let offline = extract(&[reports.to_str().unwrap()]);
    let moves: Vec<Value> = offline
        .lines()
        .map(|l| serde_json::from_str::<Value>(l).unwrap())
        .filter(|l| l["kind"] == "move")
        .collect();
    for (id, &number) in &seen {
        let moved = moves.iter().rev().find(|m| m["track"] == number).unwrap();
        let at = [moved["x"].as_f64().unwrap(), moved["y"].as_f64().unwrap()];
        let got = floats(&positions["positions"][number as usize]);
        assert_eq!(got, at, "track {number} ({id}): {positions}");
        let time = moved["time"].as_f64().unwrap();
        let frame = frames
            .iter()
            .find(|f| {
                let t = f["sec"].as_f64().unwrap() + f["nanosec"].as_f64().unwrap() * 1e-9;
                (t - time).abs() < 1e-9
            })
            .unwrap();
        let detection = frame["detections"]
            .as_array()
            .unwrap()
            .iter()
            .find(|d| d["id"] == id.as_str())
            .unwrap();
        let reported = [
            detection["x"].as_f64().unwrap() * SCALE,
            detection["y"].as_f64().unwrap() * SCALE,
        ];
        assert_eq!(reported, at, "{id} at {time} s");
    }
    drop(deployment);
    let _ = std::fs::remove_dir_all(&dir);
}
