//! A sensor that extracts its events from what a tracker reports — `move`
//! and `detect` lines (trace format version 2) — serves what `idmesh
//! replay` computes from `idmesh extract`'s trace of the same reports: the
//! same extractor runs in both, on the stream's one order. The reports are
//! the real pedestrian scenes' positions; every deployment serves exactly
//! the events `idmesh extract` writes (its answer's watermark counts them)
//! and replay's answer of that trace to 1e-9.

use idmesh_extract::ExtractorConfig;
use idmesh_tests::compare::floats;
use idmesh_tests::deployment::{
    replay_summary, trace_events, watermark_events, Deployment, Factored, Settings,
};
use idmesh_tests::idmesh;
use idmesh_tests::python::run_example;
use serde_json::Value;
use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::Duration;

/// A real scene's positions as a tracker reports them: `idmesh simulate
/// --model pedestrians` on the ETH/UCY `scene` (its first `duration`
/// seconds, the tracker's swaps drawn by the meeting model `model` names,
/// the default without) writes its own trace and what its simulated
/// tracker reported (`--tracker-output`: a version-2 trace of `detect`
/// lines, every track's position each step, class scores where the colour
/// sensor saw one): (simulated, reports).
fn scene_reports(
    dir: &Path,
    scene: &str,
    duration: u32,
    seed: u64,
    model: &[&str],
) -> (PathBuf, PathBuf) {
    std::fs::create_dir_all(dir).unwrap();
    let obsmat =
        idmesh_sim::motion::pedestrians::data_dir().join(format!("{scene}/obsmat/obsmat.txt"));
    let simulated = dir.join(format!("{scene}-simulated.jsonl"));
    let reports = dir.join(format!("{scene}-reports.jsonl"));
    let status = Command::new(idmesh())
        .args(["simulate", "--model", "pedestrians", "--scene"])
        .arg(&obsmat)
        .args([
            "--duration",
            &duration.to_string(),
            "--seed",
            &seed.to_string(),
        ])
        .args(model)
        .arg("--out")
        .arg(&simulated)
        .arg("--tracker-output")
        .arg(&reports)
        .status()
        .expect("idmesh simulate runs");
    assert!(status.success(), "idmesh simulate of {scene} failed");
    (simulated, reports)
}

/// How many lines of `kind` the trace at `path` holds.
fn lines_of_kind(path: &Path, kind: &str) -> usize {
    let text = std::fs::read_to_string(path).unwrap();
    text.matches(&format!("\"kind\":\"{kind}\"")).count()
}

/// `idmesh extract` of `reports` into `out`: how many events its trace
/// holds (mix, observe, identify and move lines).
fn extracted_events(reports: &Path, out: &Path) -> u64 {
    extract(reports, out);
    trace_events(out).len() as u64
}

/// `idmesh extract --format jsonl` of `reports` into `out`.
fn extract(reports: &Path, out: &Path) {
    let status = Command::new(idmesh())
        .args(["extract", "--format", "jsonl"])
        .arg(reports)
        .arg("--out")
        .arg(out)
        .status()
        .expect("idmesh extract runs");
    assert!(status.success(), "idmesh extract failed");
}

fn assert_close(what: &str, got: &Value, want: &Value) {
    let (got, want) = (floats(got), floats(want));
    assert_eq!(got.len(), want.len(), "{what}");
    for (t, (g, w)) in got.iter().zip(&want).enumerate() {
        assert!((g - w).abs() < 1e-9, "{what}, track {t}: {g} vs {w}");
    }
}

/// A scene's reports (zara01) from a trace file through a sensor that
/// extracts, two leaders at the default
/// settings: the final answer equals the twin's (`idmesh replay
/// --topology`, which extracts the reports as the sensor does) and
/// replay of `idmesh extract`'s trace with the deployment's settings.
#[test]
fn a_sensor_fed_positions_serves_what_replay_of_the_extracted_trace_computes() {
    let dir = std::env::temp_dir().join(format!("idmesh-extraction-{}", std::process::id()));
    let (_, reports) = scene_reports(&dir, "zara01", 150, 4, &[]);
    let extracted = dir.join("extracted.jsonl");
    let events = extracted_events(&reports, &extracted);
    let count = |kind| lines_of_kind(&extracted, kind);
    assert!(count("mix") >= 20, "{} mixes extracted", count("mix"));
    assert!(count("observe") >= 20, "{} observations", count("observe"));

    let settings = Settings {
        leaders: 2,
        rate: Some(5000.0),
        factored: Some(Factored::default()),
        extract: Some(ExtractorConfig::default()),
        ..Settings::default()
    };
    let deployment = Deployment::start("extraction", &reports, &settings);
    let last = deployment.final_marginals(Duration::from_secs(90));
    assert_eq!(watermark_events(&last), events, "the sensor's events");
    let twin = deployment.twin_summary(&reports);
    assert_close("the twin", &last["p_red"], &twin["final_p_red"]);
    let replayed = replay_summary(&extracted, &["--leaders", "2"]);
    assert_close(
        "replay of idmesh extract's trace",
        &last["p_red"],
        &replayed["final_p_red"],
    );
    drop(deployment);
    let _ = std::fs::remove_dir_all(&dir);
}

/// A scene's reports (hotel) piped into `idmesh sensor --stdin` a few lines at a
/// time, with an event among them where reports are expected: the event
/// is refused by name and counted, and the answer is replay's of
/// `idmesh extract`'s trace.
#[test]
fn reports_piped_into_an_extracting_sensor_give_replays_answer() {
    use std::io::Write;
    let dir = std::env::temp_dir().join(format!("idmesh-extraction-stdin-{}", std::process::id()));
    let (_, reports) = scene_reports(&dir, "hotel", 150, 6, &[]);
    let extracted = dir.join("extracted.jsonl");
    let events = extracted_events(&reports, &extracted);
    let settings = Settings {
        leaders: 2,
        factored: Some(Factored::default()),
        extract: Some(ExtractorConfig::default()),
        ..Settings::default()
    };
    let mut deployment = Deployment::start_without_sensor("extraction-stdin", &reports, &settings);
    let mut pipe = deployment.launch_piped("sensor", "sensor-0", &["--stdin"]);
    let text = std::fs::read_to_string(&reports).unwrap();
    let lines: Vec<&str> = text.lines().collect();
    for (i, chunk) in lines.chunks(200).enumerate() {
        for line in chunk {
            writeln!(pipe, "{line}").expect("the sensor reads its input");
        }
        if i == 3 {
            let time = chunk
                .last()
                .and_then(|l| serde_json::from_str::<Value>(l).ok());
            let time = time.map_or(0.0, |l| l["time"].as_f64().unwrap_or(0.0));
            writeln!(
                pipe,
                "{{\"kind\":\"mix\",\"time\":{time},\"a\":0,\"b\":1,\"swap\":0.5}}"
            )
            .unwrap();
        }
        pipe.flush().unwrap();
    }
    drop(pipe);
    let answer = deployment.final_marginals(Duration::from_secs(60));
    assert_eq!(watermark_events(&answer), events, "the sensor's events");
    let replayed = replay_summary(&extracted, &["--leaders", "2"]);
    assert_close("piped reports", &answer["p_red"], &replayed["final_p_red"]);
    assert!(
        deployment.log().contains("send move and detect lines"),
        "the event is refused with why"
    );
    drop(deployment);
    let _ = std::fs::remove_dir_all(&dir);
}

/// The Python tracker loop (`examples/tracker.py`, eclipse-zenoh) sends
/// each frame of a scene's reports (eth) as `detect` lines to a live extracting
/// sensor's ingest key: every line is accepted, and once the last frame
/// is in (it closes the one before; a live stream's last frame waits for
/// the next), the answer equals replay of `idmesh extract`'s trace of
/// every frame but the last.
#[test]
fn a_python_tracker_loop_on_the_ingest_key_gives_replays_answer() {
    use idmesh_tests::deployment::header_only;
    let dir = std::env::temp_dir().join(format!("idmesh-extraction-py-{}", std::process::id()));
    let (_, reports) = scene_reports(&dir, "eth", 120, 7, &[]);
    let text = std::fs::read_to_string(&reports).unwrap();
    let lines: Vec<&str> = text.lines().collect();
    let last_time = serde_json::from_str::<Value>(lines[lines.len() - 1]).unwrap()["time"].clone();
    let but_last: Vec<&str> = lines
        .iter()
        .copied()
        .filter(|l| serde_json::from_str::<Value>(l).unwrap()["time"] != last_time)
        .collect();
    let closed = dir.join("closed.jsonl");
    std::fs::write(&closed, but_last.join("\n") + "\n").unwrap();
    let extracted = dir.join("extracted.jsonl");
    extract(&closed, &extracted);
    let events = trace_events(&extracted).len() as u64;
    let replayed = replay_summary(&extracted, &["--leaders", "2"]);

    let settings = Settings {
        leaders: 2,
        live: true,
        factored: Some(Factored::default()),
        extract: Some(ExtractorConfig::default()),
        sensor_trace: Some(header_only(&reports, &dir)),
        ..Settings::default()
    };
    let deployment = Deployment::start_each("extraction-py", &reports, &settings);
    deployment.first_answer(Duration::from_secs(30));
    let reports_arg = reports.display().to_string();
    let sent = run_example(
        Path::new(env!("CARGO_TARGET_TMPDIR")),
        "tracker.py",
        [
            reports_arg.as_str(),
            deployment.sensor_endpoint(),
            &deployment.prefix,
            "sensor-0",
        ],
    );
    assert_eq!(sent["accepted"], sent["sent"], "{sent}");
    assert_eq!(
        sent["sent"].as_u64(),
        Some(lines.len() as u64 - 1),
        "{sent}"
    );
    let answer = deployment.answer_when(&["marginals"], Duration::from_secs(60), |a| {
        a["watermark"]["sensor-0"].as_u64() == Some(events)
    });
    assert_close("python tracker", &answer["p_red"], &replayed["final_p_red"]);
    drop(deployment);
    let _ = std::fs::remove_dir_all(&dir);
}

/// Two live sensors, each fed the reports of a scene (zara02) in its own region by
/// `examples/regions_producer.py`: the extractor runs on the merged
/// order at both, so a meeting of tracks reported to two sensors is one
/// mix, and the final answer equals replay of `idmesh extract`'s trace
/// of all the reports.
#[test]
fn two_extracting_sensors_fed_by_region_give_replays_answer() {
    use idmesh_tests::deployment::{grid_over, header_only};
    let dir = std::env::temp_dir().join(format!("idmesh-extraction-2s-{}", std::process::id()));
    let (_, reports) = scene_reports(&dir, "zara02", 120, 8, &[]);
    let extracted = dir.join("extracted.jsonl");
    extracted_events(&reports, &extracted);
    let mixes = lines_of_kind(&extracted, "mix");
    assert!(mixes >= 20, "{mixes} mixes extracted");
    let replayed = replay_summary(&extracted, &["--leaders", "2"]);
    let settings = Settings {
        leaders: 2,
        sensors: 2,
        live: true,
        factored: Some(Factored::default()),
        extract: Some(ExtractorConfig::default()),
        sensor_trace: Some(header_only(&reports, &dir)),
        ..Settings::default()
    };
    let deployment = Deployment::start_each("extraction-2s", &reports, &settings);
    deployment.first_answer(Duration::from_secs(30));
    let mut args = vec![
        reports.display().to_string(),
        deployment.sensor_endpoint().to_string(),
        deployment.prefix.clone(),
        "--batch".into(),
        "100".into(),
    ];
    for (s, (x, y)) in grid_over(&reports, 2).iter().enumerate() {
        args.extend(["--sensor".to_string(), format!("sensor-{s}@{x},{y}")]);
    }
    let sent = run_example(
        Path::new(env!("CARGO_TARGET_TMPDIR")),
        "regions_producer.py",
        &args,
    );
    for s in 0..2 {
        let report = &sent["sensors"][format!("sensor-{s}")];
        assert!(report["accepted"].as_u64().unwrap_or(0) > 0, "{sent}");
        assert_eq!(report["errors"].as_array().map(Vec::len), Some(0), "{sent}");
    }
    let answer = deployment.answer_when(&["marginals"], Duration::from_secs(60), |a| {
        a["finished"] == true
    });
    // Several sensors count their intake, the reports, in the order they
    // merge; the extraction runs after the merge.
    let lines = std::fs::read_to_string(&reports).unwrap().lines().count() as u64;
    assert_eq!(
        watermark_events(&answer),
        lines - 1,
        "the two sensors' reports"
    );
    assert_close("two sensors", &answer["p_red"], &replayed["final_p_red"]);
    drop(deployment);
    let _ = std::fs::remove_dir_all(&dir);
}

/// A real scene, as a tracker that confuses close, slow meetings would
/// report it (`idmesh simulate --model pedestrians --tracker-output`),
/// fed to a sensor that extracts: the deployment serves what replay of
/// the *simulator's* trace computes — positions in, the simulator's
/// events and answers out.
#[test]
fn a_real_scenes_tracker_output_served_live_answers_as_the_simulator() {
    let dir = std::env::temp_dir().join(format!("idmesh-extraction-scene-{}", std::process::id()));
    let model = [
        "--meeting-model",
        "approach",
        "--p-max",
        "0.8",
        "--sigma",
        "0.35",
    ];
    let (simulated, reports) = scene_reports(&dir, "zara01", 150, 2, &model);
    assert!(lines_of_kind(&simulated, "mix") >= 20);

    let extract = ExtractorConfig {
        meeting_model: idmesh_extract::MeetingModel::Approach {
            p_max: 0.8,
            sigma: 0.35,
            v0: 1.0,
        },
        ..ExtractorConfig::default()
    };
    let settings = Settings {
        leaders: 2,
        rate: Some(5000.0),
        factored: Some(Factored::default()),
        extract: Some(extract),
        ..Settings::default()
    };
    let deployment = Deployment::start("extraction-scene", &reports, &settings);
    let last = deployment.final_marginals(Duration::from_secs(90));
    let simulator = replay_summary(&simulated, &["--leaders", "2"]);
    assert_close(
        "replay of the simulator's trace",
        &last["p_red"],
        &simulator["final_p_red"],
    );
    drop(deployment);
    let _ = std::fs::remove_dir_all(&dir);
}
