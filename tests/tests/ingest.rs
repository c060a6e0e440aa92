//! Live ingestion with real processes on loopback: events that
//! reach the sensor as they happen — through a pipe on its standard input,
//! or from any producer on its ingest key — give the answer the trace file
//! gives, which is the centralized engine's (`idmesh replay`) to 1e-9; and
//! what a producer gets wrong (bad lines, an unknown track, counters out of
//! order, its whole history sent again) is refused or deduplicated as
//! `idmesh_protocol::wire::producer_to_sensor` documents, counted in
//! `query/stats`, and changes nothing.

use idmesh_tests::{assert_same_marginals, floats};
use idmesh_tests::{
    assert_truth_points, crowd, header_only, replay_lines, replay_summary, trace_events,
    truth_lines, undisturbed_applied, Deployment, Settings,
};
use serde_json::Value;
use std::io::Write;
use std::path::{Path, PathBuf};
use std::time::Duration;

/// The answer once the sensor's watermark reaches `events`.
fn answer_at(deployment: &Deployment, events: u64) -> Value {
    deployment.answer_when(&["marginals"], Duration::from_secs(60), |a| {
        a["watermark"]["sensor-0"].as_u64() == Some(events)
    })
}

/// The sensor's counters in `query/stats`.
fn sensor_stats(deployment: &Deployment) -> Value {
    let stats = deployment.query(&["stats"]).expect("stats answer");
    stats[0]["sensors"][0].clone()
}

/// `idmesh sensor --stdin --max-errors 1`, the trace written into its
/// pipe a few lines at a time (one bad line among them, skipped and
/// counted), gives the trace file's answer: the centralized engine's, to
/// 1e-9, once the input ends.
#[test]
fn a_trace_piped_into_the_sensor_gives_the_answer_of_the_trace_file() {
    let (dir, _scratch) = idmesh_tests::scratch("idmesh-stdin");
    let trace = crowd(&dir, 12, 4, 90.0, 5);
    let central = replay_summary(&trace, &["--method", "overcomplete"]);
    let settings = Settings {
        leaders: 2,
        ..Settings::default()
    };
    let mut deployment = Deployment::start_without_sensor("stdin", &trace, &settings);
    let mut pipe = deployment.launch_piped("sensor", "sensor-0", &["--stdin", "--max-errors", "1"]);
    let text = std::fs::read_to_string(&trace).unwrap();
    let lines: Vec<&str> = text.lines().collect();
    let bad_at = lines.len() / 2;
    for (i, chunk) in lines.chunks(40).enumerate() {
        for line in chunk {
            writeln!(pipe, "{line}").expect("the sensor reads its input");
        }
        if i * 40 <= bad_at && bad_at < (i + 1) * 40 {
            writeln!(
                pipe,
                "{{\"kind\":\"mix\",\"time\":1e9,\"a\":3,\"b\":99,\"swap\":0.5}}"
            )
            .unwrap();
        }
        pipe.flush().unwrap();
        std::thread::sleep(Duration::from_millis(5));
    }
    drop(pipe);
    let answer = deployment.final_marginals(Duration::from_secs(60));
    assert_same_marginals(&answer, &floats(&central["final_p_red"]), "piped trace");
    let events = trace_events(&trace).len() as u64;
    assert_eq!(answer["watermark"]["sensor-0"], events);
    let sensor = sensor_stats(&deployment);
    assert_eq!(sensor["ingested"], events, "{sensor}");
    assert_eq!(
        (&sensor["bad_lines"], &sensor["rejected"]),
        (&1.into(), &1.into())
    );
    assert!(
        deployment.log().contains("b = 99 is not a track"),
        "the bad line is logged with why"
    );
}

/// A Python producer (eclipse-zenoh, `examples/producer.py`) feeds a live
/// sensor, whose trace is the header alone, through its ingest key: every
/// event acknowledged once, and the answers at the trace's truth points
/// (asked before the producer starts) and at the end equal `idmesh replay`
/// to 1e-9.
#[test]
fn a_python_producer_on_the_ingest_key_gives_the_answer_of_replay() {
    let (dir, _scratch) = idmesh_tests::scratch("idmesh-ingest-py");
    let trace = crowd(&dir, 12, 4, 90.0, 6);
    let central = replay_summary(&trace, &["--method", "overcomplete"]);
    let central_lines = replay_lines(&trace, &["--method", "overcomplete"]);
    let truths = truth_lines(&trace);
    let settings = Settings {
        leaders: 2,
        live: true,
        sensor_trace: Some(header_only(&trace, &dir)),
        ..Settings::default()
    };
    let deployment = Deployment::start_each("ingestpy", &trace, &settings);
    let first = deployment.first_answer(Duration::from_secs(30));
    assert_eq!(first["watermark"]["sensor-0"], 0);
    assert_eq!(first["finished"], false);
    // The venv is made (or found) before the questions wait on the events.
    idmesh_tests::python_with_zenoh(Path::new(env!("CARGO_TARGET_TMPDIR")));
    let trace_arg = trace.display().to_string();
    let points = std::thread::scope(|scope| {
        let asked = scope.spawn(|| deployment.at_truth_points("marginals", &truths));
        // The questions are placed (held at their points) before any event.
        std::thread::sleep(Duration::from_millis(1500));
        let sent = idmesh_tests::run_example(
            Path::new(env!("CARGO_TARGET_TMPDIR")),
            "producer.py",
            [
                trace_arg.as_str(),
                deployment.sensor_endpoint(),
                &deployment.prefix,
                "sensor-0",
                "--producer",
                "camera-7",
                "--batch",
                "50",
            ],
        );
        let events = trace_events(&trace).len() as u64;
        assert_eq!(sent["accepted"], events, "{sent}");
        assert_eq!(
            (&sent["duplicates"], sent["errors"].as_array().map(Vec::len)),
            (&0.into(), Some(0))
        );
        assert_eq!(sent["events"], events);
        asked.join().expect("the questions")
    });
    assert_truth_points(&points, &truths, &central_lines, "python producer");
    let events = trace_events(&trace).len() as u64;
    let answer = answer_at(&deployment, events);
    assert_same_marginals(&answer, &floats(&central["final_p_red"]), "ingested");
    let sensor = sensor_stats(&deployment);
    assert_eq!(
        (
            &sensor["ingested"],
            &sensor["producers"],
            &sensor["rejected"]
        ),
        (&events.into(), &1.into(), &0.into()),
        "{sensor}"
    );
}

/// A producer of the test's own (a Rust Zenoh client) gets everything
/// wrong once: counters that skip ahead (refused, `next` named), a second
/// producer's bad lines (malformed, an unknown track, a truth line: each
/// refused naming its line and why), its whole history sent again
/// (duplicates, acknowledged), requests that cannot be read (an error
/// reply). The counters in `query/stats` say so, and the final answer is
/// still `idmesh replay`'s to 1e-9.
#[test]
fn what_a_producer_gets_wrong_is_refused_or_deduplicated_counted_and_changes_nothing() {
    let (dir, _scratch) = idmesh_tests::scratch("idmesh-ingest-bad");
    let trace = crowd(&dir, 10, 3, 60.0, 8);
    let central = replay_summary(&trace, &["--method", "overcomplete"]);
    let settings = Settings {
        leaders: 2,
        live: true,
        sensor_trace: Some(header_only(&trace, &dir)),
        ..Settings::default()
    };
    let deployment = Deployment::start_each("ingestbad", &trace, &settings);
    deployment.first_answer(Duration::from_secs(30));
    let history = trace_events(&trace);
    let total = history.len() as u64;
    let half = history.len() / 2;
    let runtime = tokio::runtime::Runtime::new().unwrap();
    let replies = runtime.block_on(async {
        let producer = Producer::connect(deployment.sensor_endpoint(), &deployment.prefix).await;
        let mut replies = Vec::new();
        for (i, chunk) in history[..half].chunks(64).enumerate() {
            replies.push(producer.send("p", (i * 64) as u64, chunk).await);
        }
        // Ahead of itself: refused, nothing taken.
        let ahead = (half + 10) as u64;
        replies.push(producer.send("p", ahead, &history[half..half + 3]).await);
        // Another producer's bad lines.
        let bad = [
            "{\"kind\":\"mix\",\"time\":1,\"a\":0,".to_string(),
            "{\"kind\":\"observe\",\"time\":1,\"track\":10,\"red\":0.9,\"blue\":0.1}".to_string(),
            "{\"kind\":\"truth\",\"time\":1,\"red\":[0,1,2]}".to_string(),
        ];
        replies.push(producer.send("q", 0, &bad).await);
        for (i, chunk) in history[half..].chunks(64).enumerate() {
            replies.push(producer.send("p", (half + i * 64) as u64, chunk).await);
        }
        // The whole history again.
        for (i, chunk) in history.chunks(64).enumerate() {
            replies.push(producer.send("p", (i * 64) as u64, chunk).await);
        }
        // Requests that cannot be read: no producer, no counter.
        let key = format!("{}/sensor/sensor-0/ingest", deployment.prefix);
        replies.push(producer.raw(&key, &history[0]).await);
        replies.push(
            producer
                .raw(&format!("{key}?producer=p"), &history[0])
                .await,
        );
        replies
    });
    let acks: Vec<&Value> = replies.iter().filter_map(|r| r.as_ref().ok()).collect();
    let accepted: usize = acks
        .iter()
        .map(|a| a["accepted"].as_array().unwrap().len())
        .sum();
    let duplicates: usize = acks
        .iter()
        .map(|a| a["duplicates"].as_array().unwrap().len())
        .sum();
    assert_eq!((accepted as u64, duplicates as u64), (total, total));
    let ahead = acks
        .iter()
        .find(|a| a["first"] == (half + 10) as u64)
        .expect("the out-of-order request");
    assert_eq!(ahead["next"], half as u64);
    assert!(ahead["accepted"].as_array().unwrap().is_empty());
    for error in ahead["errors"].as_array().unwrap() {
        let reason = error["reason"].as_str().unwrap();
        assert!(
            reason.contains("out of order") && reason.contains(&format!("send again from {half}")),
            "{reason}"
        );
    }
    let bad = acks
        .iter()
        .find(|a| a["producer"] == "q")
        .expect("q's answer");
    let errors = bad["errors"].as_array().unwrap();
    let named: Vec<(u64, &str)> = errors
        .iter()
        .map(|e| (e["line"].as_u64().unwrap(), e["reason"].as_str().unwrap()))
        .collect();
    assert_eq!(named.len(), 3, "{bad}");
    assert!(
        named[0].0 == 1 && named[0].1.contains("malformed JSON"),
        "{named:?}"
    );
    assert!(
        named[1].0 == 2 && named[1].1.contains("track = 10 is not a track"),
        "{named:?}"
    );
    assert!(
        named[2].0 == 3 && named[2].1.contains("not an event"),
        "{named:?}"
    );
    assert_eq!(bad["next"], 3, "a bad line uses up its counter");
    let refused: Vec<&String> = replies.iter().filter_map(|r| r.as_ref().err()).collect();
    assert_eq!(refused.len(), 2);
    assert!(refused[0].contains("no producer"), "{}", refused[0]);
    assert!(refused[1].contains("no counter"), "{}", refused[1]);

    let answer = answer_at(&deployment, total);
    assert_same_marginals(
        &answer,
        &floats(&central["final_p_red"]),
        "after the mistakes",
    );
    let sensor = sensor_stats(&deployment);
    assert_eq!(sensor["ingested"], total, "{sensor}");
    assert_eq!(sensor["duplicates"], total, "{sensor}");
    assert_eq!(sensor["out_of_order"], 3, "{sensor}");
    assert_eq!(sensor["bad_lines"], 3, "{sensor}");
    assert_eq!(sensor["producers"], 2, "{sensor}");
    assert_eq!(sensor["rejected"], 3 + 3 + 2, "{sensor}");
}

/// A Zenoh client that sends trace lines to a sensor's ingest key.
struct Producer {
    session: zenoh::Session,
    key: String,
}

impl Producer {
    async fn connect(endpoint: &str, prefix: &str) -> Producer {
        Self::try_connect(endpoint, prefix)
            .await
            .expect("a zenoh session")
    }

    /// A client session to the sensor, if it can be opened now.
    async fn try_connect(endpoint: &str, prefix: &str) -> Option<Producer> {
        let mut config = zenoh::Config::default();
        config.insert_json5("mode", "\"client\"").unwrap();
        config
            .insert_json5(
                "connect/endpoints",
                &serde_json::to_string(&[endpoint]).unwrap(),
            )
            .unwrap();
        config
            .insert_json5("scouting/multicast/enabled", "false")
            .unwrap();
        let session = tokio::time::timeout(Duration::from_secs(10), zenoh::open(config))
            .await
            .ok()?
            .ok()?;
        Some(Producer {
            session,
            key: format!("{prefix}/sensor/sensor-0/ingest"),
        })
    }

    /// `lines` from `producer`, the first numbered `counter`: the
    /// acknowledgement, or the error reply.
    async fn send(&self, producer: &str, counter: u64, lines: &[String]) -> Result<Value, String> {
        self.try_send(producer, counter, lines)
            .await
            .expect("a reply")
    }

    /// [`Producer::send`], or None when no reply came.
    async fn try_send(
        &self,
        producer: &str,
        counter: u64,
        lines: &[String],
    ) -> Option<Result<Value, String>> {
        let selector = format!("{}?producer={producer};counter={counter}", self.key);
        self.try_raw(&selector, &lines.join("\n")).await
    }

    async fn raw(&self, selector: &str, payload: &str) -> Result<Value, String> {
        self.try_raw(selector, payload).await.expect("a reply")
    }

    /// The reply, or None when none came (nobody serves the key: the
    /// sensor is down).
    async fn try_raw(&self, selector: &str, payload: &str) -> Option<Result<Value, String>> {
        let replies = self
            .session
            .get(selector)
            .payload(payload.to_string())
            .timeout(Duration::from_secs(10))
            .await
            .expect("a get");
        let reply = replies.recv_async().await.ok()?;
        Some(match reply.result() {
            Ok(sample) => Ok(serde_json::from_slice(&sample.payload().to_bytes()).expect("JSON")),
            Err(e) => Err(e.payload().try_to_string().unwrap_or_default().into_owned()),
        })
    }
}

/// Feeds `history` to the sensor as producer `p`, `per` lines a request,
/// resending a request until it is acknowledged (reconnecting: the sensor
/// may be down for a while); `sent` says how far it got. Returns the lines
/// acknowledged as accepted and as duplicates; a line refused fails.
async fn feed_until_acknowledged(
    endpoint: &str,
    prefix: &str,
    history: &[String],
    per: usize,
    sent: &std::sync::atomic::AtomicUsize,
) -> (u64, u64) {
    let (mut accepted, mut duplicates) = (0u64, 0u64);
    let mut producer: Option<Producer> = None;
    let mut at = 0;
    while at < history.len() {
        let Some(session) = &producer else {
            producer = match tokio::time::timeout(
                Duration::from_secs(5),
                Producer::try_connect(endpoint, prefix),
            )
            .await
            {
                Ok(Some(p)) => Some(p),
                _ => {
                    tokio::time::sleep(Duration::from_millis(200)).await;
                    None
                }
            };
            continue;
        };
        let lines = &history[at..(at + per).min(history.len())];
        match session.try_send("p", at as u64, lines).await {
            Some(Ok(ack)) => {
                assert!(ack["errors"].as_array().unwrap().is_empty(), "{ack}");
                accepted += ack["accepted"].as_array().unwrap().len() as u64;
                duplicates += ack["duplicates"].as_array().unwrap().len() as u64;
                at += lines.len();
                sent.store(at, std::sync::atomic::Ordering::SeqCst);
                tokio::time::sleep(Duration::from_millis(15)).await;
            }
            Some(Err(e)) => panic!("request at {at} refused: {e}"),
            None => {
                producer = None;
                tokio::time::sleep(Duration::from_millis(200)).await;
            }
        }
    }
    (accepted, duplicates)
}

/// A live sensor killed (SIGKILL) mid-stream: every query after says
/// `degraded`, naming it, and gives no numbers without its events. (The
/// sensor keeps no journal here: it does not come back where it was; see
/// the next test for one that does.)
#[test]
fn queries_while_the_sensor_is_down_say_degraded_naming_it() {
    let (dir, _scratch) = idmesh_tests::scratch("idmesh-ingest-down");
    let trace = crowd(&dir, 10, 3, 30.0, 4);
    let settings = Settings {
        leaders: 2,
        live: true,
        sensor_trace: Some(header_only(&trace, &dir)),
        ..Settings::default()
    };
    let mut deployment = Deployment::start_each("ingestdown", &trace, &settings);
    deployment.first_answer(Duration::from_secs(30));
    let history = trace_events(&trace);
    let half = history.len() / 2;
    let runtime = tokio::runtime::Runtime::new().unwrap();
    let ack = runtime.block_on(async {
        let producer = Producer::connect(deployment.sensor_endpoint(), &deployment.prefix).await;
        producer.send("p", 0, &history[..half]).await
    });
    assert_eq!(ack.expect("acknowledged")["events"], half as u64);
    answer_at(&deployment, half as u64);
    deployment.kill("sensor-0");
    for question in [&["marginals"][..], &["track", "3"], &["positions"]] {
        let error = deployment
            .query(question)
            .expect_err("no answer without the sensor");
        assert!(
            error.contains("degraded") && error.contains("sensor-0"),
            "{question:?}: {error}"
        );
    }
    let stats = deployment.query(&["stats"]).expect("stats answer");
    assert!(
        stats[0]["coordinator"]["degraded"].as_u64().unwrap() >= 2,
        "{stats:?}"
    );
}

/// A second sensor process started on a journal another one holds (say,
/// `idmesh up` run twice) refuses to start, naming the lock and who holds
/// it, and the first streams on to replay's answer: two sensors appending
/// to one journal would interleave two streams in it.
#[test]
fn a_second_sensor_on_a_journal_in_use_refuses_to_start_and_the_first_goes_on() {
    let (dir, _scratch) = idmesh_tests::scratch("idmesh-ingest-twice");
    let trace = crowd(&dir, 10, 3, 60.0, 6);
    let central = replay_summary(&trace, &["--method", "overcomplete"]);
    let expected = floats(&central["final_p_red"]);
    let settings = Settings {
        leaders: 2,
        journal: true,
        rate: Some(300.0),
        ..Settings::default()
    };
    let deployment = Deployment::start_each("ingesttwice", &trace, &settings);
    let first = deployment.first_answer(Duration::from_secs(30));
    assert_eq!(first["finished"], false, "the first sensor still streams");
    let status = deployment.run_to_end("sensor", "sensor-0", Duration::from_secs(30));
    assert!(!status.success(), "the second sensor ran");
    let log = deployment.log();
    assert!(
        log.contains("sensor-0.journal.lock is held by sensor-0 (pid"),
        "the refusal names the lock and its holder:\n{log}"
    );
    let last = deployment.final_marginals(Duration::from_secs(60));
    for (t, (g, w)) in floats(&last["p_red"]).iter().zip(&expected).enumerate() {
        assert!((g - w).abs() < 1e-9, "track {t}: {g} vs {w}");
    }
}

/// What a sensor restart test starts from: a crowd, `idmesh replay`'s
/// final answer for it, its events, and two leaders and a sensor that
/// journal. What each leader applies when nothing is killed depends on how
/// the sensor is fed (a trace file starts its tracks where its leading
/// moves place them; a live feed cannot), so each test measures it for
/// its own feed.
struct Restart {
    /// Removes `dir` once the test passes.
    scratch: idmesh_tests::Scratch,
    dir: PathBuf,
    trace: PathBuf,
    expected: Vec<f64>,
    history: Vec<String>,
    settings: Settings,
}

impl Restart {
    fn case(name: &str, seed: u64) -> Restart {
        let (dir, scratch) = idmesh_tests::scratch(&format!("idmesh-{name}-restart"));
        let trace = crowd(&dir, 10, 3, 60.0, seed);
        let central = replay_summary(&trace, &["--method", "overcomplete"]);
        let expected = floats(&central["final_p_red"]);
        let settings = Settings {
            leaders: 2,
            journal: true,
            // Compacted many times over a stream this short: a restart
            // reads a snapshot and what came after it.
            compact_journal_after: Some(2048),
            ..Settings::default()
        };
        Restart {
            scratch,
            history: trace_events(&trace),
            dir,
            trace,
            expected,
            settings,
        }
    }
}

/// The sensor's journal was compacted: it starts with the stream and a
/// snapshot of the sensor's state, not with the stream's first records.
fn assert_compacted(deployment: &Deployment) {
    use idmesh_sensor::journal::{read, Record};
    let path = deployment.dir.join("state").join("sensor-0.journal");
    let records = read(&path).expect("a whole journal");
    assert!(
        matches!(records[..], [Record::Stream(_), Record::Snapshot(_), ..]),
        "{} starts with {:?}",
        path.display(),
        records.iter().take(2).collect::<Vec<_>>()
    );
}

/// A sensor that journals (`state_dir`), SIGKILLed mid-stream and started
/// again, resumes where it was — once while it streams its trace file,
/// once while a producer feeds it on the ingest key (resending each
/// request until it is acknowledged). While it is down every query says
/// `degraded` naming it; after, the final answer is `idmesh replay`'s to
/// 1e-9, the watermark is the trace's event count, and every leader
/// applied exactly the mixes, observations and handovers of the same
/// deployment left alone: no event lost, none applied twice. The producer
/// had every line accepted exactly once (none refused as out of order: the
/// sensor kept its counter) and the sensor's `ingested` counts each once.
/// The sensor compacts its journal every 2 kB, so each restart reads a
/// snapshot of its state and the records after it.
#[test]
fn a_sensor_killed_mid_stream_and_restarted_resumes_where_it_was() {
    let Restart {
        scratch: _scratch,
        dir,
        trace,
        expected,
        history,
        settings,
    } = Restart::case("sensor", 11);
    let total = history.len() as u64;
    let calm_applied = undisturbed_applied("sensorcalm", &trace, &settings, &expected);

    let down_says_degraded = |deployment: &Deployment| {
        let error = deployment
            .query(&["marginals"])
            .expect_err("no answer without the sensor");
        assert!(
            error.contains("degraded") && error.contains("sensor-0"),
            "{error}"
        );
    };

    // Killed while it streams its trace file.
    let paced = Settings {
        rate: Some(400.0),
        ..settings.clone()
    };
    let mut reading = Deployment::start_each("sensortrace", &trace, &paced);
    let before = reading.answer_when(&["marginals"], Duration::from_secs(60), |a| {
        a["watermark"]["sensor-0"].as_u64() >= Some(total / 3)
    });
    assert_eq!(before["finished"], false, "killed mid-stream");
    reading.kill("sensor-0");
    down_says_degraded(&reading);
    let relaunched = std::time::Instant::now();
    reading.launch("sensor", "sensor-0");
    reading.first_answer(Duration::from_secs(30));
    eprintln!(
        "the sensor answers again {:.2} s after it was started again",
        relaunched.elapsed().as_secs_f64()
    );
    let last = reading.final_marginals(Duration::from_secs(60));
    assert_same_marginals(&last, &expected, "after the sensor's restart (trace)");
    assert_eq!(last["watermark"]["sensor-0"], total);
    assert_eq!(reading.applied(), calm_applied, "trace");
    assert_compacted(&reading);
    drop(reading);

    // Killed while a producer feeds it.
    let live = Settings {
        live: true,
        sensor_trace: Some(header_only(&trace, &dir)),
        ..settings
    };
    let mut fed = Deployment::start_each("sensorfed", &trace, &live);
    fed.first_answer(Duration::from_secs(30));
    let sent = std::sync::atomic::AtomicUsize::new(0);
    let (endpoint, prefix) = (fed.sensor_endpoint().to_string(), fed.prefix.clone());
    let (accepted, duplicates) = std::thread::scope(|scope| {
        let producer = scope.spawn(|| {
            tokio::runtime::Runtime::new()
                .unwrap()
                .block_on(feed_until_acknowledged(
                    &endpoint, &prefix, &history, 8, &sent,
                ))
        });
        while sent.load(std::sync::atomic::Ordering::SeqCst) < history.len() / 3 {
            std::thread::sleep(Duration::from_millis(5));
        }
        fed.kill("sensor-0");
        let killed_at = sent.load(std::sync::atomic::Ordering::SeqCst);
        down_says_degraded(&fed);
        assert!(
            killed_at < history.len(),
            "the producer was not done when the sensor died"
        );
        fed.launch("sensor", "sensor-0");
        producer.join().expect("the producer")
    });
    assert_eq!(accepted, total, "every line accepted once");
    eprintln!("producer: {accepted} lines accepted, {duplicates} acknowledged again as duplicates");
    let last = answer_at(&fed, total);
    assert_same_marginals(&last, &expected, "after the sensor's restart (ingest)");
    let fed_applied = fed.applied();
    let fed_sensor = sensor_stats(&fed);
    assert_compacted(&fed);
    drop(fed);
    // A stream fed live cannot start its tracks where its leading moves
    // place them (it has not seen them when it begins), so the reference
    // is the same feed left alone.
    let calm_fed = {
        let calm = Deployment::start_each("sensorfedcalm", &trace, &live);
        calm.first_answer(Duration::from_secs(30));
        let sent = std::sync::atomic::AtomicUsize::new(0);
        tokio::runtime::Runtime::new()
            .unwrap()
            .block_on(feed_until_acknowledged(
                calm.sensor_endpoint(),
                &calm.prefix,
                &history,
                8,
                &sent,
            ));
        assert_same_marginals(&answer_at(&calm, total), &expected, "fed, left alone");
        calm.applied()
    };
    assert_eq!(fed_applied, calm_fed, "ingest");
    assert_eq!(fed_sensor["ingested"], total, "{fed_sensor}");
    assert_eq!(fed_sensor["out_of_order"], 0, "{fed_sensor}");
}

/// A journaling sensor reading a trace on its standard input, SIGKILLed
/// halfway through the pipe and started again with the same input piped
/// from its start, passes over the lines it read before: the final answer
/// is `idmesh replay`'s to 1e-9, the watermark the trace's event count,
/// and every leader applied what it applies without the kill.
#[test]
fn a_sensor_killed_while_reading_standard_input_and_fed_it_again_reads_each_line_once() {
    let Restart {
        scratch: _scratch,
        trace,
        expected,
        history,
        settings,
        ..
    } = Restart::case("stdin", 12);
    let total = history.len() as u64;
    let mut deployment = Deployment::start_without_sensor("stdinkill", &trace, &settings);
    let text = std::fs::read_to_string(&trace).unwrap();
    let lines: Vec<&str> = text.lines().collect();
    let mut pipe = deployment.launch_piped("sensor", "sensor-0", &["--stdin"]);
    for line in &lines[..lines.len() / 2] {
        writeln!(pipe, "{line}").expect("the sensor reads its input");
    }
    pipe.flush().unwrap();
    let before = deployment.answer_when(&["marginals"], Duration::from_secs(60), |a| {
        a["watermark"]["sensor-0"].as_u64() > Some(0)
    });
    deployment.kill("sensor-0");
    drop(pipe);
    let read = before["watermark"]["sensor-0"].as_u64().unwrap();
    assert!(read < total, "killed mid-input: {read} of {total}");
    let mut pipe = deployment.launch_piped("sensor", "sensor-0", &["--stdin"]);
    for line in &lines {
        writeln!(pipe, "{line}").expect("the sensor reads its input");
    }
    drop(pipe);
    let last = deployment.final_marginals(Duration::from_secs(60));
    assert_same_marginals(&last, &expected, "after the restart (stdin)");
    assert_eq!(last["watermark"]["sensor-0"], total);
    let applied = deployment.applied();
    assert_eq!(sensor_stats(&deployment)["ingested"], total);
    drop(deployment);
    // Standard input cannot start its tracks where the leading moves
    // place them (the stream begins before they are read), so the
    // reference is the same pipe left alone.
    let calm = {
        let mut calm = Deployment::start_without_sensor("stdincalm", &trace, &settings);
        let mut pipe = calm.launch_piped("sensor", "sensor-0", &["--stdin"]);
        for line in &lines {
            writeln!(pipe, "{line}").expect("the sensor reads its input");
        }
        drop(pipe);
        assert_same_marginals(
            &calm.final_marginals(Duration::from_secs(60)),
            &expected,
            "piped, left alone",
        );
        calm.applied()
    };
    assert_eq!(applied, calm);
}
