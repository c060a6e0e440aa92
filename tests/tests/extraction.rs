//! A sensor that extracts its events from what a tracker reports — `move`
//! and `detect` lines (trace format version 2) — serves what `idmesh
//! replay` computes from `idmesh extract`'s trace of the same reports: the
//! same extractor runs in both, on the stream's one order. The reports are
//! the real pedestrian scenes' positions; every deployment serves exactly
//! the events `idmesh extract` writes (its answer's watermark counts them)
//! and replay's answer of that trace to 1e-9.

use idmesh_extract::ExtractorConfig;
use idmesh_tests::{floats, idmesh, run_example};
use idmesh_tests::{
    replay_summary, trace_events, watermark_events, Deployment, Factored, Settings,
};
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
    let obsmat = idmesh_sim::data_dir().join(format!("{scene}/obsmat/obsmat.txt"));
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
    let (dir, _scratch) = idmesh_tests::scratch("idmesh-extraction");
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
    let replayed = replay_summary(&extracted, &["--leaders", "2", "--spread-above", "0"]);
    assert_close(
        "replay of idmesh extract's trace",
        &last["p_red"],
        &replayed["final_p_red"],
    );
    drop(deployment);
}

/// A scene's reports (hotel) piped into `idmesh sensor --stdin
/// --max-errors 1` a few lines at a time, with an event among them where
/// reports are expected: the event is refused by name and counted, and the
/// answer is replay's of `idmesh extract`'s trace.
#[test]
fn reports_piped_into_an_extracting_sensor_give_replays_answer() {
    use std::io::Write;
    let (dir, _scratch) = idmesh_tests::scratch("idmesh-extraction-stdin");
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
    let mut pipe = deployment.launch_piped("sensor", "sensor-0", &["--stdin", "--max-errors", "1"]);
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
    let replayed = replay_summary(&extracted, &["--leaders", "2", "--spread-above", "0"]);
    assert_close("piped reports", &answer["p_red"], &replayed["final_p_red"]);
    assert!(
        deployment.log().contains("send move and detect lines"),
        "the event is refused with why"
    );
    drop(deployment);
}

/// The Python tracker loop (`examples/tracker.py`, eclipse-zenoh) sends
/// each frame of a scene's reports (eth) as `detect` lines to a live extracting
/// sensor's ingest key: every line is accepted, and once the last frame
/// is in (it closes the one before; a live stream's last frame waits for
/// the next), the answer equals replay of `idmesh extract`'s trace of
/// every frame but the last.
#[test]
fn a_python_tracker_loop_on_the_ingest_key_gives_replays_answer() {
    use idmesh_tests::header_only;
    let (dir, _scratch) = idmesh_tests::scratch("idmesh-extraction-py");
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
    let replayed = replay_summary(&extracted, &["--leaders", "2", "--spread-above", "0"]);

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
}

/// Two live sensors, each fed the reports of a scene (zara02) in its own region by
/// `examples/regions_producer.py`: the extractor runs on the merged
/// order at both, so a meeting of tracks reported to two sensors is one
/// mix, and the final answer equals replay of `idmesh extract`'s trace
/// of all the reports.
#[test]
fn two_extracting_sensors_fed_by_region_give_replays_answer() {
    use idmesh_tests::{grid_over, header_only};
    let (dir, _scratch) = idmesh_tests::scratch("idmesh-extraction-2s");
    let (_, reports) = scene_reports(&dir, "zara02", 120, 8, &[]);
    let extracted = dir.join("extracted.jsonl");
    extracted_events(&reports, &extracted);
    let mixes = lines_of_kind(&extracted, "mix");
    assert!(mixes >= 20, "{mixes} mixes extracted");
    let replayed = replay_summary(&extracted, &["--leaders", "2", "--spread-above", "0"]);
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
}

/// A real scene, as a tracker that confuses close, slow meetings would
/// report it (`idmesh simulate --model pedestrians --tracker-output`),
/// fed to a sensor that extracts: the deployment serves what replay of
/// the *simulator's* trace computes — positions in, the simulator's
/// events and answers out.
#[test]
fn a_real_scenes_tracker_output_served_live_answers_as_the_simulator() {
    let (dir, _scratch) = idmesh_tests::scratch("idmesh-extraction-scene");
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
    let simulator = replay_summary(&simulated, &["--leaders", "2", "--spread-above", "0"]);
    assert_close(
        "replay of the simulator's trace",
        &last["p_red"],
        &simulator["final_p_red"],
    );
    drop(deployment);
}

/// `idmesh <args>` with the temporary folder `tmp`: its exit status and
/// what it wrote on stderr.
fn idmesh_in(tmp: &Path, args: &[&str]) -> (bool, String, String) {
    let output = Command::new(idmesh())
        .args(args)
        .env("TMPDIR", tmp)
        .env("RUST_LOG", "warn")
        .output()
        .expect("idmesh runs");
    (
        output.status.success(),
        String::from_utf8_lossy(&output.stdout).into_owned(),
        String::from_utf8_lossy(&output.stderr).into_owned(),
    )
}

/// The reason of a `FILE:LINE: reason` message for line `line` in `text`
/// (a process's stderr or log), whatever names the file.
fn reason_at(text: &str, line: usize) -> String {
    let mark = format!(":{line}: ");
    let found = text
        .lines()
        .find_map(|l| l.split_once(&mark).map(|(_, reason)| reason.to_string()))
        .unwrap_or_else(|| panic!("no message for line {line} in:\n{text}"));
    // A log line may go on with its fields.
    found
        .split(" rejected=")
        .next()
        .unwrap_or(&found)
        .trim()
        .to_string()
}

/// What a tracker got wrong, fed both ways: to the offline twin (`idmesh
/// extract`, `idmesh replay --topology`) and to a deployment (its sensor's
/// trace file, standard input). Every case has the same outcome both ways,
/// with the same words: `truth` lines among the reports are passed over; a
/// malformed line stops every reader at the default `--max-errors 0`,
/// naming its line, and is skipped and counted by every reader given
/// `--max-errors 1` (the answers then equal to 1e-9); `detect` lines under
/// a version-1 header are refused by every reader at their first line; and
/// no run leaves a file in the temporary folder, failed or not.
#[test]
fn the_twin_and_the_deployment_take_and_refuse_the_same_reports() {
    use std::io::Write;
    let (dir, _scratch) = idmesh_tests::scratch("idmesh-extraction-agree");
    let tmp = dir.join("tmp");
    let (_, reports) = scene_reports(&dir, "zara01", 40, 3, &[]);
    std::fs::create_dir_all(&tmp).unwrap();
    let text = std::fs::read_to_string(&reports).unwrap();
    let lines: Vec<&str> = text.lines().collect();
    let header: Value = serde_json::from_str(lines[0]).unwrap();
    let k = header["red"].as_u64().unwrap_or(1);
    let red: Vec<u64> = (0..k).collect();
    // Truth lines every 100 reports, and one malformed line.
    let mut mixed = vec![lines[0].to_string()];
    let mut bad_line = 0;
    for (i, line) in lines[1..].iter().enumerate() {
        mixed.push(line.to_string());
        if i % 100 == 99 {
            let time = serde_json::from_str::<Value>(line).unwrap()["time"].clone();
            mixed.push(format!(r#"{{"kind":"truth","time":{time},"red":{red:?}}}"#));
        }
        if i == lines.len() / 2 {
            mixed.push("{\"kind\":\"move\",".into());
            bad_line = mixed.len();
        }
    }
    let mixed_path = dir.join("mixed.jsonl");
    std::fs::write(&mixed_path, mixed.join("\n") + "\n").unwrap();
    let without_bad: Vec<&str> = mixed
        .iter()
        .enumerate()
        .filter(|(i, _)| i + 1 != bad_line)
        .map(|(_, l)| l.as_str())
        .collect();
    let truth_path = dir.join("truth.jsonl");
    std::fs::write(&truth_path, without_bad.join("\n") + "\n").unwrap();
    let v1_path = dir.join("v1.jsonl");
    let v1: Vec<String> = std::iter::once(lines[0].replace("\"version\":2", "\"version\":1"))
        .chain(lines[1..20].iter().map(|l| l.to_string()))
        .collect();
    assert!(v1[0].contains("\"version\":1") && v1[1].contains("\"detect\""));
    std::fs::write(&v1_path, v1.join("\n") + "\n").unwrap();
    let path = |p: &Path| p.display().to_string();
    let extract = |trace: &Path, extra: &[&str]| {
        let out = dir.join("out.jsonl");
        let mut args = vec![
            "extract".to_string(),
            path(trace),
            "--out".into(),
            path(&out),
        ];
        args.extend(extra.iter().map(|s| s.to_string()));
        let args: Vec<&str> = args.iter().map(String::as_str).collect();
        idmesh_in(&tmp, &args)
    };
    let empty_tmp = |what: &str| {
        let left: Vec<_> = std::fs::read_dir(&tmp)
            .unwrap()
            .map(|e| e.unwrap().path())
            .collect();
        assert!(
            left.is_empty(),
            "{what} left {left:?} in the temporary folder"
        );
    };

    // Truth lines: taken (passed over) by extract; the same trace as
    // without them.
    let (ok, _, err) = extract(&truth_path, &[]);
    assert!(ok, "extract refused truth lines: {err}");
    let with_truth = std::fs::read_to_string(dir.join("out.jsonl")).unwrap();
    let (ok, _, _) = extract(&reports, &[]);
    assert!(ok);
    assert_eq!(
        with_truth,
        std::fs::read_to_string(dir.join("out.jsonl")).unwrap()
    );

    // A deployment whose sensors stop at the first bad line (the default).
    let settings = Settings {
        leaders: 1,
        factored: Some(Factored::default()),
        extract: Some(ExtractorConfig::default()),
        sensor_trace: Some(mixed_path.clone()),
        ..Settings::default()
    };
    let mut strict = Deployment::start_without_sensor("extraction-strict", &reports, &settings);
    let topology = path(strict.config());
    // The malformed line: extract, the twin and the sensor's trace file
    // stop at it, with one message.
    let (ok, _, extract_err) = extract(&mixed_path, &[]);
    assert!(!ok, "extract went past a malformed line");
    let malformed = reason_at(&extract_err, bad_line);
    assert!(malformed.starts_with("malformed JSON"), "{malformed}");
    let twin = [
        "replay",
        "--trace",
        &path(&mixed_path),
        "--topology",
        &topology,
    ];
    let (ok, _, twin_err) = idmesh_in(&tmp, &twin);
    assert!(!ok, "the twin went past a malformed line");
    assert_eq!(
        reason_at(&twin_err, bad_line),
        malformed,
        "the twin's words"
    );
    empty_tmp("a failed replay --topology");
    let status = strict.run_to_end("sensor", "sensor-0", Duration::from_secs(30));
    assert!(!status.success(), "the sensor went past a malformed line");
    assert_eq!(
        reason_at(&strict.log(), bad_line),
        malformed,
        "the sensor's words"
    );
    // Detect lines under a version-1 header: refused at line 2 by every
    // reader, standard input included.
    let (ok, _, extract_err) = extract(&v1_path, &[]);
    assert!(!ok, "extract took detect lines under a version-1 header");
    let v1_reason = reason_at(&extract_err, 2);
    assert!(
        v1_reason.starts_with("detect: a version-1 trace"),
        "{v1_reason}"
    );
    let (ok, _, twin_err) = idmesh_in(
        &tmp,
        &[
            "replay",
            "--trace",
            &path(&v1_path),
            "--topology",
            &topology,
        ],
    );
    assert!(!ok, "the twin took detect lines under a version-1 header");
    assert_eq!(reason_at(&twin_err, 2), v1_reason);
    // The sensor streaming the same file as its trace.
    let v1_topology = dir.join("v1.toml");
    let toml = std::fs::read_to_string(strict.config()).unwrap();
    assert!(toml.contains(&path(&mixed_path)), "{toml}");
    std::fs::write(
        &v1_topology,
        toml.replace(&path(&mixed_path), &path(&v1_path)),
    )
    .unwrap();
    let sensor = [
        "sensor",
        "--config",
        &path(&v1_topology),
        "--name",
        "sensor-0",
    ];
    let (ok, _, sensor_err) = idmesh_in(&tmp, &sensor);
    assert!(!ok, "the sensor took detect lines under a version-1 header");
    assert_eq!(reason_at(&sensor_err, 2), v1_reason, "the sensor's words");
    let mut pipe = strict.launch_piped("sensor", "sensor-0", &["--stdin"]);
    for line in &v1 {
        let _ = writeln!(pipe, "{line}");
    }
    drop(pipe);
    let status = strict.wait_for("sensor-0", Duration::from_secs(60));
    assert!(
        !status.success(),
        "the sensor on stdin took detect lines under a version-1 header"
    );
    let log = strict.log();
    assert!(log.contains(&format!("stdin:2: {v1_reason}")), "{log}");
    drop(strict);

    // With --max-errors 1: every reader skips the malformed line (and
    // passes over the truth lines), and the answers agree.
    let (ok, _, extract_err) = extract(&mixed_path, &["--max-errors", "1"]);
    assert!(ok, "{extract_err}");
    assert_eq!(reason_at(&extract_err, bad_line), malformed);
    let extracted = std::fs::read_to_string(dir.join("out.jsonl")).unwrap();
    assert_eq!(
        extracted, with_truth,
        "the bad line skipped, the rest taken"
    );
    let forgiving = Settings {
        max_errors: 1,
        rate: Some(5000.0),
        ..settings.clone()
    };
    let deployment = Deployment::start("extraction-forgiving", &reports, &forgiving);
    let last = deployment.final_marginals(Duration::from_secs(90));
    assert_eq!(
        reason_at(&deployment.log(), bad_line),
        malformed,
        "the sensor's words"
    );
    let twin = [
        "replay",
        "--trace",
        &path(&mixed_path),
        "--topology",
        &path(deployment.config()),
    ];
    let (ok, out, twin_err) = idmesh_in(&tmp, &twin);
    assert!(ok, "{twin_err}");
    assert_eq!(
        reason_at(&twin_err, bad_line),
        malformed,
        "the twin's words"
    );
    empty_tmp("replay --topology");
    let summary: Value = serde_json::from_str(out.lines().last().unwrap()).unwrap();
    assert_close(
        "the trace file, bad line skipped",
        &last["p_red"],
        &summary["final_p_red"],
    );
    drop(deployment);
    // Standard input: the same line skipped and counted, the same answer.
    let mut piped = Deployment::start_without_sensor("extraction-piped", &reports, &settings);
    let mut pipe = piped.launch_piped("sensor", "sensor-0", &["--stdin", "--max-errors", "1"]);
    for line in &mixed {
        writeln!(pipe, "{line}").expect("the sensor reads its input");
    }
    drop(pipe);
    let answer = piped.final_marginals(Duration::from_secs(60));
    assert_close(
        "standard input, bad line skipped",
        &answer["p_red"],
        &summary["final_p_red"],
    );
    assert!(piped
        .log()
        .contains(&format!("stdin:{bad_line}: {malformed}")));
    let stats = piped.sensor_stats();
    assert_eq!(stats[0]["bad_lines"], 1, "{stats:?}");
    drop(piped);
    empty_tmp("every run");
}

/// A MOTChallenge file teaches the belief only with what comes beside
/// it: alone (positions, k) it gives a trace without one observation,
/// which `idmesh extract` warns about and whose answer is k/n for every
/// track; with the reads file of `examples/mot/`, or with its class
/// column, the answer moves. On standard input the file reads the same.
#[test]
fn a_mot_file_with_class_scores_moves_the_answer_and_one_without_is_warned_about() {
    let (dir, _scratch) = idmesh_tests::scratch("idmesh-extraction-mot");
    std::fs::create_dir_all(&dir).unwrap();
    let examples = Path::new(env!("CARGO_MANIFEST_DIR")).join("../examples/mot");
    let results = examples.join("results.txt");
    let extract = |name: &str, input: &Path, extra: &[&str]| {
        let out = dir.join(name);
        let output = Command::new(idmesh())
            .args([
                "extract", "--format", "mot", "--fps", "25", "--scale", "0.02", "--red", "2",
            ])
            .args(extra)
            .arg(input)
            .arg("--out")
            .arg(&out)
            .env("RUST_LOG", "warn")
            .output()
            .expect("idmesh extract runs");
        let stderr = String::from_utf8_lossy(&output.stderr).into_owned();
        assert!(output.status.success(), "{stderr}");
        (out, stderr)
    };
    let answer = |trace: &Path| floats(&replay_summary(trace, &[])["final_p_red"]);

    let (alone, warned) = extract("alone.jsonl", &results, &[]);
    assert!(
        warned.contains("the trace holds no observation"),
        "{warned}"
    );
    assert_eq!(lines_of_kind(&alone, "observe"), 0);
    assert!(std::fs::read_to_string(&alone)
        .unwrap()
        .contains("\"red\":2"));
    for p in answer(&alone) {
        assert!((p - 0.5).abs() < 1e-9, "k/n with nothing seen: {p}");
    }

    let reads = examples.join("reads.jsonl");
    let reads = reads.to_str().unwrap();
    let (taught, quiet) = extract("taught.jsonl", &results, &["--reads", reads]);
    assert!(!quiet.contains("no observation"), "{quiet}");
    assert!(lines_of_kind(&taught, "observe") >= 4);
    let moved = answer(&taught);
    assert!(moved.iter().all(|p| (p - 0.5).abs() > 0.1), "{moved:?}");

    // The same file on standard input (the first frame's roster: every
    // walker is in it) gives the same trace.
    let piped = dir.join("piped.jsonl");
    let status = Command::new(idmesh())
        .args([
            "extract", "--format", "mot", "--fps", "25", "--scale", "0.02", "--red", "2",
        ])
        .args(["--reads", reads, "--out"])
        .arg(&piped)
        .stdin(std::fs::File::open(&results).unwrap())
        .status()
        .expect("idmesh extract runs");
    assert!(status.success());
    assert_eq!(
        std::fs::read_to_string(&piped).unwrap(),
        std::fs::read_to_string(&taught).unwrap()
    );

    // MOT16's class and visibility columns: walkers 1 and 3 of class 1
    // (red), 2 and 4 of class 2, every box fully visible.
    let text = std::fs::read_to_string(&results).unwrap();
    let classed: String = text
        .lines()
        .map(|l| {
            let fields: Vec<&str> = l.split(',').collect();
            let class = if fields[1] == "1" || fields[1] == "3" {
                1
            } else {
                2
            };
            format!("{},{class},1\n", fields[..7].join(","))
        })
        .collect();
    let classed_path = dir.join("classed.txt");
    std::fs::write(&classed_path, classed).unwrap();
    let (by_class, _) = extract(
        "classed.jsonl",
        &classed_path,
        &["--class-label", "1=red,2=blue"],
    );
    assert!(lines_of_kind(&by_class, "observe") >= 4);
    let p = answer(&by_class);
    assert!(p[2] > 0.9 && p[3] < 0.1, "{p:?}");
}
