//! Bad input from the network, with real processes on loopback: while a
//! stream runs, a Zenoh session of the test's own puts garbage on a
//! leader's event and transfer keys (truncated and random bytes, a batch
//! with a NaN likelihood, a swap of 1.5, a track out of range, a wrong
//! version), sends the leader a bad request for its sent transfers, the
//! sensor bad follow and resend requests and the coordinator malformed
//! queries. Every bad message is refused and counted
//! where it landed, every bad request gets an error reply, and the final
//! marginals still equal the centralized engine's to 1e-9: nothing bad was
//! applied and nothing good was lost.

use idmesh_protocol::wire::leader_to_leader::{Transfer, TransfersSent, WireSet};
use idmesh_protocol::wire::leader_to_sensor::{Follow, Resend};
use idmesh_protocol::wire::sensor_to_leader::{Batch, Growth, Item, Sequenced};
use idmesh_protocol::wire::{encode, VERSION};
use idmesh_tests::{assert_same_marginals, crowd, floats, replay_summary, Deployment, Settings};
use serde_json::Value;
use std::future::IntoFuture;
use std::time::Duration;
use zenoh::Session;

/// Every await of this test is bounded by this.
const PATIENCE: Duration = Duration::from_secs(20);

async fn bounded<T>(what: &str, future: impl IntoFuture<Output = T>) -> T {
    tokio::time::timeout(PATIENCE, future.into_future())
        .await
        .unwrap_or_else(|_| panic!("{what}: no result within {PATIENCE:?}"))
}

/// A peer of the deployment's mesh: connected to every process's endpoint
/// (peers do not relay for one another), as any process on the LAN could.
async fn intruder(deployment: &Deployment) -> Session {
    let endpoints: Vec<String> = deployment
        .endpoints
        .iter()
        .map(|(_, endpoint)| endpoint.clone())
        .collect();
    let mut config = zenoh::Config::default();
    config
        .insert_json5(
            "connect/endpoints",
            &serde_json::to_string(&endpoints).unwrap(),
        )
        .unwrap();
    config
        .insert_json5("listen/endpoints", "[\"tcp/127.0.0.1:0\"]")
        .unwrap();
    config
        .insert_json5("scouting/multicast/enabled", "false")
        .unwrap();
    let session = bounded("open a session", zenoh::open(config))
        .await
        .expect("a zenoh session");
    // Let the processes' declarations reach it before it puts anything.
    tokio::time::sleep(Duration::from_secs(1)).await;
    session
}

fn batch(items: Vec<Item>) -> Batch {
    Batch {
        version: VERSION,
        epoch: 0,
        sensor: "sensor-0".into(),
        number: 3,
        through: 1_000,
        events: 1_000,
        finished: false,
        items: items
            .into_iter()
            .enumerate()
            .map(|(i, item)| Sequenced {
                seq: 900 + i as u64,
                item,
            })
            .collect(),
    }
}

fn mix(a: u32, b: u32, swap: f64) -> Item {
    Item::Mix {
        adopted: Vec::new(),
        a,
        b,
        swap,
        owner_a: 0,
        owner_b: 0,
        handed: None,
    }
}

/// Bad messages, each with what is wrong with it.
type Messages = Vec<(&'static str, Vec<u8>)>;

/// The garbage for a leader's event key and its transfer key.
fn garbage() -> (Messages, Messages) {
    let whole = encode(&batch(vec![mix(0, 1, 0.5)]));
    let mut wrong_version = batch(vec![mix(0, 1, 0.5)]);
    wrong_version.version = VERSION + 1;
    let random: Vec<u8> = (0..300u32).map(|i| (i * 7919 % 253) as u8).collect();
    let events = vec![
        ("truncated batch", whole[..whole.len() / 2].to_vec()),
        ("random bytes", random.clone()),
        (
            "NaN likelihood",
            encode(&batch(vec![Item::Observe {
                adopted_by: None,
                track: 2,
                red: f64::NAN,
                blue: 0.5,
                growth: Growth::All,
                global: true,
            }])),
        ),
        ("swap 1.5", encode(&batch(vec![mix(0, 1, 1.5)]))),
        ("track out of range", encode(&batch(vec![mix(0, 999, 0.5)]))),
        ("wrong version", encode(&wrong_version)),
    ];
    // What a peer puts on the transfer key: its transfers in one message.
    let transfer = |red: Vec<u32>, ln_mass: f64, version| {
        encode(&TransfersSent {
            epoch: 0,
            version,
            transfers: vec![Transfer {
                trees: Vec::new(),
                components: Vec::new(),
                version,
                from: 1,
                seq: 950,
                sets: vec![WireSet {
                    red,
                    blue: vec![],
                    ln_mass,
                }],
                rows: vec![],
            }],
        })
    };
    let transfers = vec![
        ("random transfer", random[..77].to_vec()),
        ("NaN mass", transfer(vec![1], f64::NAN, VERSION)),
        (
            "transfer track out of range",
            transfer(vec![999], 0.0, VERSION),
        ),
        (
            "transfer wrong version",
            transfer(vec![1], 0.0, VERSION + 1),
        ),
    ];
    (events, transfers)
}

/// A get answered by one process: its reply, Ok or the error's payload.
async fn get(
    session: &Session,
    selector: String,
    payload: Option<Vec<u8>>,
) -> Result<Vec<u8>, String> {
    let mut get = session
        .get(selector.as_str())
        .timeout(Duration::from_secs(15));
    if let Some(payload) = payload {
        get = get.payload(payload);
    }
    let replies = bounded("get", get).await.expect("a get");
    let reply = bounded("a reply", replies.recv_async())
        .await
        .unwrap_or_else(|_| panic!("{selector}: nobody answered"));
    match reply.result() {
        Ok(sample) => Ok(sample.payload().to_bytes().into_owned()),
        Err(e) => Err(String::from_utf8_lossy(&e.payload().to_bytes()).into_owned()),
    }
}

#[test]
fn garbage_on_the_wire_is_refused_counted_and_changes_no_answer() {
    let (dir, _scratch) = idmesh_tests::scratch("idmesh-garbage");
    let trace = crowd(&dir, 12, 4, 90.0, 5);
    let central = replay_summary(&trace, &["--method", "overcomplete"]);
    let expected = floats(&central["final_p_red"]);
    let deployment = Deployment::start(
        "garbage",
        &trace,
        &Settings {
            leaders: 2,
            rate: Some(300.0),
            ..Settings::default()
        },
    );
    let first = deployment.first_answer(Duration::from_secs(30));
    assert_eq!(first["finished"], false, "the stream has begun, not ended");
    let prefix = deployment.prefix.clone();
    let (events, transfers) = garbage();
    // The leader's inputs, and one bad request for its sent transfers.
    let bad_messages = (events.len() + transfers.len()) as u64 + 1;

    let runtime = tokio::runtime::Builder::new_multi_thread()
        .worker_threads(2)
        .enable_all()
        .build()
        .unwrap();
    let session = runtime.block_on(async {
        let session = intruder(&deployment).await;
        // Garbage on leader-0's two keys, while the stream runs.
        for (key, messages) in [("events", &events), ("transfer", &transfers)] {
            for (what, bytes) in messages {
                bounded(
                    what,
                    session.put(format!("{prefix}/leader/leader-0/{key}"), bytes.clone()),
                )
                .await
                .unwrap_or_else(|e| panic!("{what}: {e}"));
            }
        }
        // Bad requests to the sensor: answered with why, nothing changed.
        let sensor = |what: &str| format!("{prefix}/sensor/sensor-0/{what}");
        let bad_requests = [
            (sensor("follow"), b"\x03\x00\xff\xff\xff\xff\xff".to_vec()),
            (
                sensor("follow"),
                encode(&Follow {
                    epoch: 0,
                    version: VERSION,
                    leader: 0,
                    after: 1,
                    tracks: vec![999],
                }),
            ),
            (
                sensor("resend"),
                encode(&Resend {
                    epoch: 0,
                    version: VERSION,
                    leader: "mallory".into(),
                    from: 0,
                }),
            ),
        ];
        for (selector, payload) in bad_requests.clone() {
            let answer = get(&session, selector.clone(), Some(payload)).await;
            let error = answer.expect_err(&selector);
            eprintln!("{selector}: {error}");
            assert!(!error.is_empty());
        }
        // A peer's request for sent transfers that is not one.
        let sent = format!("{prefix}/leader/leader-0/sent");
        let error = get(&session, sent.clone(), Some(vec![0xff, 0xff]))
            .await
            .expect_err(&sent);
        eprintln!("{sent}: {error}");
        // Malformed queries to the coordinator: an error reply each.
        let query = |q: &str| format!("{prefix}/query/{q}");
        let malformed = [
            query("marginals?events=abc"),
            query("marginals?event=5"),
            query("track/abc"),
            query("identity?marginals=guess"),
            query("stats?events=3"),
        ];
        for selector in malformed.iter().cloned().chain([query("track/999")]) {
            let error = get(&session, selector.clone(), None)
                .await
                .expect_err(&selector);
            let error: Value = serde_json::from_str(&error)
                .unwrap_or_else(|e| panic!("{selector}: the error is JSON ({e}): {error}"));
            eprintln!("{selector}: {}", error["error"]);
            assert!(
                error["error"].as_str().is_some_and(|e| !e.is_empty()),
                "{selector}"
            );
        }
        (session, malformed.len() as u64, bad_requests.len() as u64)
    });
    let (session, malformed, bad_requests) = session;

    let last = deployment.final_marginals(Duration::from_secs(90));
    assert_same_marginals(&last, &expected, "after garbage");

    let stats = &deployment.query(&["stats"]).expect("stats")[0];
    for leader in stats["leaders"].as_array().unwrap() {
        let wanted = if leader["leader"] == "leader-0" {
            bad_messages
        } else {
            0
        };
        assert_eq!(leader["rejected"], wanted, "{leader}");
    }
    assert_eq!(stats["coordinator"]["rejected"], malformed, "{stats}");
    assert_eq!(stats["sensors"][0]["rejected"], bad_requests, "{stats}");

    // A process that answers the leaders' partial-sums get with garbage:
    // asked where the leaders rest, its reply is refused and counted; the
    // query then places a fresh cut, which the stream's own leaders answer
    // by pushing their sums, and the process, no leader of the stream,
    // changes no answer.
    let spoiled = runtime.block_on(async {
        let key = format!("{prefix}/leader/mallory/partial");
        let fake = bounded("declare", session.declare_queryable(key.as_str()))
            .await
            .unwrap();
        // Serves until aborted below (its receive waits for the next get).
        let fake_task = tokio::spawn(async move {
            while let Ok(query) = fake.recv_async().await {
                let reply = query.reply(query.key_expr().clone(), vec![3u8, 0xff, 0xff]);
                let _ = bounded("the fake reply", reply).await;
            }
        });
        tokio::time::sleep(Duration::from_millis(500)).await;
        let answer = get(&session, format!("{prefix}/query/marginals"), None)
            .await
            .expect("answered by the stream's leaders");
        fake_task.abort();
        bounded("close", session.close()).await.unwrap();
        serde_json::from_slice::<Value>(&answer).expect("a JSON answer")
    });
    let stats = &deployment.query(&["stats"]).expect("stats")[0];
    assert!(
        stats["coordinator"]["bad_replies"].as_u64() >= Some(1),
        "{stats}"
    );
    assert!(
        stats["coordinator"]["cuts_pushed"].as_u64() >= Some(1),
        "{stats}"
    );
    let last = deployment.final_marginals(Duration::from_secs(30));
    assert_eq!(
        spoiled["p_red"], last["p_red"],
        "the garbage changed the answer"
    );
}
