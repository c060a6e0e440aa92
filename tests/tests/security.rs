//! Security, with real processes on loopback: mutual TLS between every
//! process and the access rules generated from the topology.
//!
//! Certificates are made here for the run (rcgen): a CA, one certificate
//! per process (common name = its name), one for the client `operator`
//! listed in the topology, one for an `intruder` signed by the same CA but
//! listed nowhere, and one from another CA. The intruder is a Zenoh session
//! of this test that puts a well-formed event batch — a mix of tracks 1 and
//! 3, numbered as the next batch leader-0 expects — on leader-0's event key
//! and asks every leader for its counters. Without access control (TLS
//! only) the leader applies that batch and answers; with it, nothing of the
//! intruder's is heard, the legitimate client still gets the centralized
//! engine's answer, and a certificate from another CA cannot connect. A
//! producer listed in `[security] producers` (`camera-7`) feeds a live
//! sensor; the client and the intruder cannot.

use idmesh_protocol::wire::sensor_to_leader::{Batch, Item, Sequenced};
use idmesh_protocol::wire::{encode, VERSION};
use idmesh_tests::{assert_same_marginals, floats};
use idmesh_tests::{
    crowd, header_only, replay_summary, trace_events, Deployment, Secured, Settings,
};
use rcgen::{
    BasicConstraints, CertificateParams, DnType, ExtendedKeyUsagePurpose, IsCa, KeyPair,
    KeyUsagePurpose,
};
use serde_json::Value;
use std::future::Future;
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};
use zenoh::query::{ConsolidationMode, QueryTarget};
use zenoh::Session;

const LEADERS: usize = 2;
const CLIENT: &str = "operator";
const INTRUDER: &str = "intruder";
const PRODUCER: &str = "camera-7";

/// A CA named `ca` and certificates it signs for `names`, as files in
/// `dir`: `ca.pem`, `<name>.pem`, `<name>.key`. Every certificate serves
/// both ends of a link (server and client auth) on loopback.
fn certificates(dir: &Path, ca: &str, names: &[String]) -> PathBuf {
    std::fs::create_dir_all(dir).unwrap();
    let ca_key = KeyPair::generate().unwrap();
    let mut params = CertificateParams::new(Vec::<String>::new()).unwrap();
    params.distinguished_name.push(DnType::CommonName, ca);
    params.is_ca = IsCa::Ca(BasicConstraints::Unconstrained);
    params.key_usages = vec![KeyUsagePurpose::KeyCertSign, KeyUsagePurpose::CrlSign];
    let ca_cert = params.self_signed(&ca_key).unwrap();
    std::fs::write(dir.join("ca.pem"), ca_cert.pem()).unwrap();
    for name in names {
        let key = KeyPair::generate().unwrap();
        let mut params =
            CertificateParams::new(vec!["localhost".to_string(), "127.0.0.1".to_string()]).unwrap();
        params.distinguished_name.push(DnType::CommonName, name);
        params.extended_key_usages = vec![
            ExtendedKeyUsagePurpose::ServerAuth,
            ExtendedKeyUsagePurpose::ClientAuth,
        ];
        let cert = params.signed_by(&key, &ca_cert, &ca_key).unwrap();
        std::fs::write(dir.join(format!("{name}.pem")), cert.pem()).unwrap();
        std::fs::write(dir.join(format!("{name}.key")), key.serialize_pem()).unwrap();
    }
    dir.to_path_buf()
}

/// Everyone the good CA signs for: the processes, the client, the
/// producer, the intruder.
fn names() -> Vec<String> {
    let mut names = vec!["coordinator".to_string(), "sensor-0".to_string()];
    names.extend((0..LEADERS).map(|i| format!("leader-{i}")));
    names.extend([
        CLIENT.to_string(),
        PRODUCER.to_string(),
        INTRUDER.to_string(),
    ]);
    names
}

/// A secured deployment of `LEADERS` leaders streaming a small crowd as
/// fast as it goes, and the centralized engine's final marginals.
fn deployment(
    name: &str,
    access_control: bool,
) -> (idmesh_tests::Scratch, Deployment, PathBuf, Vec<f64>) {
    let (dir, scratch) = idmesh_tests::scratch(&format!("idmesh-security-{name}"));
    let certs = certificates(&dir.join("certs"), "idmesh test CA", &names());
    let trace = crowd(&dir, 12, 4, 60.0, 5);
    let central = replay_summary(&trace, &["--method", "overcomplete"]);
    let expected = floats(&central["final_p_red"]);
    let deployment = Deployment::start(
        name,
        &trace,
        &Settings {
            leaders: LEADERS,
            security: Some(Secured {
                certs: certs.clone(),
                access_control,
                client: CLIENT.into(),
                producers: Vec::new(),
            }),
            ..Settings::default()
        },
    );
    (scratch, deployment, certs, expected)
}

/// Every leader's counters of what it received and applied, as the
/// legitimate client reads them (not what it keeps for others: that drops
/// on its own as peers make their state safe).
fn leader_stats(deployment: &Deployment) -> Vec<Value> {
    let mut leaders = deployment.leader_stats();
    for l in &mut leaders {
        if let Some(l) = l.as_object_mut() {
            l.remove("transfers_kept");
        }
    }
    leaders
}

fn counter(stats: &[Value], leader: &str, field: &str) -> u64 {
    stats
        .iter()
        .find(|l| l["leader"] == leader)
        .and_then(|l| l[field].as_u64())
        .unwrap_or_else(|| panic!("{leader} {field} in {stats:?}"))
}

/// Runs `f` on a runtime of its own, failing after `limit`.
fn within<T>(limit: Duration, f: impl Future<Output = T>) -> T {
    tokio::runtime::Builder::new_multi_thread()
        .worker_threads(1)
        .enable_all()
        .build()
        .unwrap()
        .block_on(async {
            tokio::time::timeout(limit, f)
                .await
                .unwrap_or_else(|_| panic!("not done within {limit:?}"))
        })
}

/// A Zenoh session of this test's own, showing certificate `name` of
/// `certs` over mutual TLS (QUIC) to `connect` (tcp/ endpoints of the
/// topology).
async fn session(
    certs: &Path,
    name: &str,
    client: bool,
    connect: &[String],
) -> zenoh::Result<Session> {
    let mut config = zenoh::Config::default();
    let tls: Vec<String> = connect.iter().map(|e| e.replace("tcp/", "quic/")).collect();
    let file = |f: String| serde_json::to_string(&certs.join(f)).unwrap();
    let mode = if client { "\"client\"" } else { "\"peer\"" };
    for (key, value) in [
        ("mode", mode.to_string()),
        ("connect/endpoints", serde_json::to_string(&tls).unwrap()),
        ("scouting/multicast/enabled", "false".into()),
        (
            "transport/link/tls/root_ca_certificate",
            file("ca.pem".into()),
        ),
        (
            "transport/link/tls/connect_certificate",
            file(format!("{name}.pem")),
        ),
        (
            "transport/link/tls/connect_private_key",
            file(format!("{name}.key")),
        ),
        ("transport/link/tls/enable_mtls", "true".into()),
    ] {
        config.insert_json5(key, &value)?;
    }
    tokio::time::timeout(Duration::from_secs(10), zenoh::open(config))
        .await
        .map_err(|_| "opening the session timed out")?
}

/// How many replies a get on `key` gets (every queryable asked, none
/// merged), waiting at most 2 s.
async fn replies(session: &Session, key: &str) -> usize {
    let replies = session
        .get(key)
        .consolidation(ConsolidationMode::None)
        .target(QueryTarget::All)
        .timeout(Duration::from_secs(2))
        .await
        .expect("the get is sent");
    let mut answered = 0;
    while let Ok(Ok(reply)) =
        tokio::time::timeout(Duration::from_secs(3), replies.recv_async()).await
    {
        answered += reply.result().is_ok() as usize;
    }
    answered
}

/// Puts on leader-0's event key the batch it would apply next: a mix of
/// tracks 1 and 3, far beyond the stream's last item, both owned by
/// leader-1 (so leader-0 applies it alone, waiting for nobody). Whether
/// the session saw leader-0's subscriber, within 3 s; the batch is put
/// either way.
async fn put_mix(session: &Session, prefix: &str, number: u64) -> bool {
    let seq = 1 << 40;
    let batch = Batch {
        version: VERSION,
        epoch: 0,
        sensor: "sensor-0".into(),
        number,
        through: seq,
        events: 0,
        finished: true,
        items: vec![Sequenced {
            seq,
            // Two tracks of leader-1 by the stream's first owners: well
            // formed in every way leader-0's door checks, and leader-0 is
            // no party to it, so it applies it without waiting for anyone.
            item: Item::Mix {
                adopted: Vec::new(),
                a: 1,
                b: 3,
                swap: 0.5,
                owner_a: 1,
                owner_b: 1,
                handed: None,
            },
        }],
    };
    let publisher = session
        .declare_publisher(format!("{prefix}/leader/leader-0/events"))
        .await
        .expect("a publisher");
    let started = Instant::now();
    let mut matched = false;
    while !matched && started.elapsed() < Duration::from_secs(3) {
        matched = publisher
            .matching_status()
            .await
            .is_ok_and(|m| m.matching());
        tokio::time::sleep(Duration::from_millis(50)).await;
    }
    publisher.put(encode(&batch)).await.expect("put");
    // Let it leave before the session closes.
    tokio::time::sleep(Duration::from_millis(300)).await;
    matched
}

fn endpoints(deployment: &Deployment) -> Vec<String> {
    deployment
        .endpoints
        .iter()
        .map(|(_, e)| e.clone())
        .collect()
}

fn endpoint(deployment: &Deployment, name: &str) -> String {
    deployment
        .endpoints
        .iter()
        .find(|(n, _)| n == name)
        .map(|(_, e)| e.clone())
        .unwrap_or_else(|| panic!("no endpoint for {name}"))
}

/// TLS alone keeps out whoever has no certificate from the CA, not a
/// process that has one: the intruder reads every leader's counters and
/// leader-0 applies its batch. This is what the next test's rules stop —
/// and the proof that the intruder's batch would be applied if let in.
/// The TLS stall: a secured deployment of four leaders streaming
/// some 2,000 events once stalled for good in 7 of 12 runs, each time after
/// Zenoh's TLS link between two leaders closed and reopened and one
/// transfer was lost on it (idmesh fetched lost transfers only on a
/// restart). Now every run must finish with the centralized engine's
/// answer: 3 runs here, 12 with `IDMESH_LONG_TESTS=1` (CI), each a fresh
/// deployment. The link warnings Zenoh logged are counted and printed.
/// Secured links are QUIC since run 11 of a CI run aborted the sensor
/// inside Zenoh's TLS link (eclipse-zenoh/zenoh#2557, docs/guide/lan.md): an
/// abort fails this test, as every process must live to the answer.
#[test]
fn a_long_secured_stream_finishes_every_time() {
    let runs = if idmesh_tests::long_tests() { 12 } else { 3 };
    let (dir, _scratch) = idmesh_tests::scratch("idmesh-security-long");
    let mut names = vec!["coordinator".to_string(), "sensor-0".to_string()];
    names.extend((0..4).map(|i| format!("leader-{i}")));
    names.push(CLIENT.to_string());
    let certs = certificates(&dir.join("certs"), "idmesh test CA", &names);
    // Some 3,000 lines (360 mixes and observations among the moves),
    // streamed over about 8 s: longer than the report's stream.
    let trace = crowd(&dir, 16, 4, 160.0, 21);
    let central = replay_summary(&trace, &["--method", "overcomplete"]);
    let expected = floats(&central["final_p_red"]);
    let mut reopened = 0;
    for run in 0..runs {
        let deployment = Deployment::start(
            &format!("tls-long-{run}"),
            &trace,
            &Settings {
                leaders: 4,
                rate: Some(400.0),
                security: Some(Secured {
                    certs: certs.clone(),
                    access_control: true,
                    client: CLIENT.into(),
                    producers: Vec::new(),
                }),
                ..Settings::default()
            },
        );
        assert_same_marginals(
            &deployment.final_marginals(Duration::from_secs(120)),
            &expected,
            &format!("secured run {} of {runs}", run + 1),
        );
        let kept =
            deployment.leaders_total_when("transfers_kept", Duration::from_secs(10), |k| k == 0);
        assert_eq!(
            kept,
            0,
            "run {}: transfers kept after every leader applied them",
            run + 1
        );
        reopened += deployment
            .log()
            .lines()
            .filter(|l| l.contains("WARN") && l.to_lowercase().contains("link"))
            .count();
    }
    eprintln!(
        "{runs} secured runs of {} mixes and observations finished with the centralized answer; Zenoh logged {reopened} warnings about links on the way",
        central["events"]
    );
}

#[test]
fn without_access_control_a_certified_intruder_reads_leaders_and_is_applied() {
    let (_scratch, deployment, certs, expected) = deployment("tls-only", false);
    assert_same_marginals(
        &deployment.final_marginals(Duration::from_secs(90)),
        &expected,
        "over TLS",
    );
    let before = leader_stats(&deployment);
    let (read, matched) = within(Duration::from_secs(30), async {
        let intruder = session(&certs, INTRUDER, false, &endpoints(&deployment))
            .await
            .expect("a CA-signed certificate connects");
        tokio::time::sleep(Duration::from_millis(500)).await;
        let read = replies(&intruder, &format!("{}/leader/*/stats", deployment.prefix)).await;
        let number = counter(&before, "leader-0", "batches");
        let matched = put_mix(&intruder, &deployment.prefix, number).await;
        let _ = intruder.close().await;
        (read, matched)
    });
    assert_eq!(read, LEADERS, "the intruder reads every leader's counters");
    assert!(matched, "the intruder sees leader-0's event subscriber");
    let started = Instant::now();
    loop {
        let after = leader_stats(&deployment);
        if counter(&after, "leader-0", "mixes") == counter(&before, "leader-0", "mixes") + 1 {
            break;
        }
        assert!(
            started.elapsed() < Duration::from_secs(10),
            "leader-0 did not apply the intruder's mix: {after:?}"
        );
        std::thread::sleep(Duration::from_millis(200));
    }
}

/// With access control, only listed identities are heard: the intruder's
/// batch is not applied (every leader's counters stay as they were) and
/// its gets — and the listed client's own gets on leader keys — are not
/// answered; the client still gets the centralized engine's answer; a
/// certificate from another CA, even one named like the sensor, cannot
/// connect at all.
#[test]
fn with_access_control_only_listed_identities_are_heard() {
    let (_scratch, deployment, certs, expected) = deployment("acl", true);
    let rogue = certificates(
        &deployment.dir.join("rogue"),
        "some other CA",
        &["sensor-0".to_string()],
    );
    assert_same_marginals(
        &deployment.final_marginals(Duration::from_secs(90)),
        &expected,
        "under access control",
    );
    let before = leader_stats(&deployment);
    // The generated rules let the coordinator ask the sensor for its
    // counters too (`"sensors": []` under `[security]`).
    let stats = deployment.query(&["stats"]).expect("stats answer");
    let sensors = stats[0]["sensors"].as_array().expect("sensors");
    assert_eq!(sensors.len(), 1, "the sensor's counters: {stats:?}");
    assert_eq!(sensors[0]["sensor"], "sensor-0");
    // The leaders' sums pushed at each fresh cut reach the coordinator
    // under the rules: no cut had to be asked for instead.
    let cuts = &stats[0]["coordinator"];
    eprintln!("under access control: {cuts}");
    assert_eq!(cuts["cuts_asked"], 0, "pushes blocked: {cuts}");
    let prefix = deployment.prefix.clone();
    within(Duration::from_secs(60), async {
        let intruder = session(&certs, INTRUDER, false, &endpoints(&deployment))
            .await
            .expect("a CA-signed certificate still connects");
        tokio::time::sleep(Duration::from_millis(500)).await;
        let read = replies(&intruder, &format!("{prefix}/leader/*/stats")).await;
        assert_eq!(read, 0, "no leader answers the intruder");
        let asked = replies(&intruder, &format!("{prefix}/query/stats")).await;
        assert_eq!(asked, 0, "the coordinator does not answer it");
        let number = counter(&before, "leader-0", "batches");
        let matched = put_mix(&intruder, &prefix, number).await;
        assert!(
            !matched,
            "leader-0's subscriber is hidden from the intruder"
        );
        let _ = intruder.close().await;

        // The listed client, as a peer of leader-0, cannot put events either.
        let leader_0 = endpoint(&deployment, "leader-0");
        let operator = session(&certs, CLIENT, false, std::slice::from_ref(&leader_0))
            .await
            .expect("the client's certificate connects");
        let matched = put_mix(&operator, &prefix, number).await;
        assert!(!matched, "leader-0's subscriber is hidden from a client");
        let _ = operator.close().await;

        // The listed client asks the coordinator: its API, not leader keys.
        let coordinator = std::slice::from_ref(&deployment.coordinator);
        let client = session(&certs, CLIENT, true, coordinator)
            .await
            .expect("the client connects");
        let asked = replies(&client, &format!("{prefix}/query/stats")).await;
        assert_eq!(asked, 1, "the client's question is answered");
        let read = replies(&client, &format!("{prefix}/leader/*/stats")).await;
        assert_eq!(read, 0, "but not its get on leader keys");
        let _ = client.close().await;

        let rogue = session(&rogue, "sensor-0", true, coordinator).await;
        assert!(
            rogue.is_err(),
            "a certificate from another CA cannot connect"
        );
    });
    std::thread::sleep(Duration::from_secs(1));
    assert_eq!(
        leader_stats(&deployment),
        before,
        "no leader applied anything the intruder or the client put"
    );
    assert_same_marginals(
        &deployment.final_marginals(Duration::from_secs(30)),
        &expected,
        "after the intrusion",
    );
}

/// `GET url`: (status, body as text).
fn http_get(url: &str) -> (u16, String) {
    let response = match ureq::get(url).timeout(Duration::from_secs(30)).call() {
        Ok(r) => r,
        Err(ureq::Error::Status(_, r)) => r,
        Err(e) => panic!("GET {url}: {e}"),
    };
    let status = response.status();
    (status, response.into_string().expect("a text body"))
}

/// Under access control the web gateway is the listed client, with its
/// certificate, and nothing else changes: its answers are the Zenoh API's,
/// its metrics and readiness come through the coordinator's API.
#[test]
fn the_web_gateway_connects_as_the_listed_client_and_answers_as_the_api_does() {
    let (_scratch, deployment, _certs, expected) = deployment("web", true);
    let zenoh = deployment.final_marginals(Duration::from_secs(60));
    assert_same_marginals(&zenoh, &expected, "secured, asked over Zenoh");
    let gateway = idmesh_tests::Gateway::start(&deployment);
    let prefix = &deployment.prefix;

    let (status, body) = http_get(&gateway.at(&format!("{prefix}/query/marginals")));
    assert_eq!(status, 200, "{body}");
    let web: Value = serde_json::from_str(&body).expect("JSON");
    assert_eq!(web, zenoh, "the gateway's answer is the Zenoh API's");

    let (status, body) = http_get(&gateway.at("readyz"));
    assert_eq!(
        status, 200,
        "every role answers the secured gateway: {body}"
    );
    let (status, metrics) = http_get(&gateway.at("metrics"));
    assert_eq!(status, 200);
    let stats = deployment.query(&["stats"]).expect("stats")[0].clone();
    for leader in stats["leaders"].as_array().expect("leaders") {
        let name = leader["leader"].as_str().expect("a name");
        let label = format!("leader=\"{name}\"");
        let value = format!(" {}", leader["items"]);
        assert!(
            metrics
                .lines()
                .any(|l| l.starts_with("idmesh_leader_items_total{")
                    && l.contains(&label)
                    && l.ends_with(&value)),
            "idmesh_leader_items_total of {name} is not{value} in the metrics:\n{metrics}"
        );
    }
    // A leader key is not a question of the query API, secured or not.
    let (status, _) = http_get(&gateway.at(&format!("{prefix}/leader/leader-0/stats")));
    assert_eq!(status, 404);
}

/// `lines` sent to the sensor's ingest key as producer `producer` from
/// `counter`: the acknowledgement (JSON), the error reply, or None when
/// no reply came within 3 s (nobody the session may ask serves the key).
async fn ingest(
    session: &Session,
    prefix: &str,
    producer: &str,
    counter: usize,
    lines: &[String],
) -> Option<Result<Value, String>> {
    let selector = format!("{prefix}/sensor/sensor-0/ingest?producer={producer};counter={counter}");
    let replies = session
        .get(selector)
        .payload(lines.join("\n"))
        .timeout(Duration::from_secs(3))
        .await
        .expect("the get is sent");
    let reply = tokio::time::timeout(Duration::from_secs(4), replies.recv_async())
        .await
        .ok()?
        .ok()?;
    Some(match reply.result() {
        Ok(sample) => Ok(serde_json::from_slice(&sample.payload().to_bytes()).expect("JSON")),
        Err(e) => Err(e.payload().try_to_string().unwrap_or_default().into_owned()),
    })
}

/// Under access control a producer listed in `[security] producers` feeds
/// a live sensor over mutual TLS and the answer is the centralized
/// engine's; the listed client and a certified intruder, sending the same
/// lines to the same key, get no reply and nothing of theirs is taken.
#[test]
fn with_access_control_only_listed_producers_feed_the_sensor() {
    let (dir, _scratch) = idmesh_tests::scratch("idmesh-security-feed");
    let certs = certificates(&dir.join("certs"), "idmesh test CA", &names());
    let trace = crowd(&dir, 12, 4, 40.0, 6);
    let central = replay_summary(&trace, &["--method", "overcomplete"]);
    let expected = floats(&central["final_p_red"]);
    let header = header_only(&trace, &dir);
    let deployment = Deployment::start(
        "aclfeed",
        &trace,
        &Settings {
            leaders: LEADERS,
            live: true,
            sensor_trace: Some(header),
            security: Some(Secured {
                certs: certs.clone(),
                access_control: true,
                client: CLIENT.into(),
                producers: vec![PRODUCER.into()],
            }),
            ..Settings::default()
        },
    );
    deployment.first_answer(Duration::from_secs(60));
    let events = trace_events(&trace);
    let prefix = deployment.prefix.clone();
    let sensor = vec![endpoint(&deployment, "sensor-0")];
    within(Duration::from_secs(120), async {
        for stranger in [CLIENT, INTRUDER] {
            let session = session(&certs, stranger, true, &sensor)
                .await
                .expect("a CA-signed certificate connects");
            tokio::time::sleep(Duration::from_millis(500)).await;
            let reply = ingest(&session, &prefix, stranger, 0, &events[..10]).await;
            assert!(reply.is_none(), "{stranger} fed the sensor: {reply:?}");
            let _ = session.close().await;
        }
        let producer = session(&certs, PRODUCER, true, &sensor)
            .await
            .expect("the producer connects");
        let mut counter = 0;
        for chunk in events.chunks(50) {
            let mut reply = None;
            // The session may take a moment to see the sensor's queryable.
            for _ in 0..20 {
                reply = ingest(&producer, &prefix, PRODUCER, counter, chunk).await;
                if reply.is_some() {
                    break;
                }
                tokio::time::sleep(Duration::from_millis(200)).await;
            }
            let ack = reply
                .expect("the sensor acknowledges the listed producer")
                .expect("lines accepted");
            assert_eq!(ack["next"], (counter + chunk.len()) as u64, "{ack}");
            counter += chunk.len();
        }
        let _ = producer.close().await;
    });
    let total = events.len() as u64;
    let last = deployment.answer_when(&["marginals"], Duration::from_secs(60), |a| {
        a["watermark"]["sensor-0"].as_u64() == Some(total)
    });
    assert_same_marginals(&last, &expected, "fed by the listed producer");
    let stats = deployment.query(&["stats"]).expect("stats answer");
    let sensor_stats = &stats[0]["sensors"][0];
    assert_eq!(sensor_stats["ingested"], total, "{sensor_stats}");
    assert_eq!(
        sensor_stats["producers"], 1,
        "only the listed producer: {sensor_stats}"
    );
}

/// Voters and a sensor standby in a secured deployment under the
/// generated access rules: the voters elect a leader of their group over
/// mutual TLS, the listed client reads every voter's map through the
/// coordinator, every role is claimed through them, and when the sensor
/// is killed its standby takes the role over (its rules let it serve the
/// sensor's keys, the sensor's replicate its journal to it) and the
/// stream ends as the offline twin does.
#[test]
fn voters_and_a_sensor_standby_under_access_control_take_over_and_answer() {
    let (dir, _scratch) = idmesh_tests::scratch("idmesh-security-voters");
    let mut names = names();
    names.extend((1..=3).map(|i| format!("voter-{i}")));
    names.push("sensor-0-standby".into());
    let certs = certificates(&dir.join("certs"), "idmesh test CA", &names);
    let trace = crowd(&dir, 12, 4, 60.0, 5);
    let mut deployment = Deployment::start_each(
        "secured-voters",
        &trace,
        &Settings {
            leaders: LEADERS,
            voters: 3,
            sensor_standbys: 1,
            journal: true,
            own_disks: true,
            rate: Some(300.0),
            takeover_after_ms: Some(1000),
            security: Some(Secured {
                certs,
                access_control: true,
                client: CLIENT.into(),
                producers: Vec::new(),
            }),
            ..Settings::default()
        },
    );
    let twin = deployment.twin_summary(&trace);
    let deadline = Instant::now() + Duration::from_secs(30);
    loop {
        let answers = deployment.query(&["roles"]).unwrap_or_default();
        let leader = answers.first().map(|a| a["leader"].clone());
        let agreed = answers.len() == 3
            && leader
                .as_ref()
                .is_some_and(|l| answers.iter().any(|a| &a["voter"] == l))
            && answers
                .iter()
                .all(|a| Some(&a["leader"]) == leader.as_ref());
        let held = |role: &str| {
            answers.first().is_some_and(|a| {
                a["roles"]
                    .as_array()
                    .is_some_and(|r| r.iter().any(|e| e["role"] == role && e["holder"] == role))
            })
        };
        if agreed && held("sensor-0") && held("leader-0") {
            break;
        }
        assert!(
            Instant::now() < deadline,
            "no leader the three voters agree on, or roles not claimed: {answers:?}\n{}",
            deployment.log()
        );
        std::thread::sleep(Duration::from_millis(200));
    }
    deployment.first_answer(Duration::from_secs(30));
    let copy = deployment
        .dir
        .join("state-sensor-0-standby")
        .join("sensor-0.standby.journal");
    let deadline = Instant::now() + Duration::from_secs(30);
    while idmesh_sensor::journal::read(&copy).map_or(0, |r| r.len()) == 0 {
        assert!(
            Instant::now() < deadline,
            "the sensor never replicated to its standby:\n{}",
            deployment.log()
        );
        std::thread::sleep(Duration::from_millis(100));
    }
    deployment.kill("sensor-0");
    let last = deployment.final_marginals(Duration::from_secs(60));
    assert_same_marginals(
        &last,
        &floats(&twin["final_p_red"]),
        "after the standby took the sensor role over",
    );
    assert!(
        deployment.log().contains("taking over from the copy"),
        "the standby took the role over:\n{}",
        deployment.log()
    );
    drop(deployment);
}
