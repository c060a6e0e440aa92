//! Three voter processes' drivers in one test, each with its own Zenoh
//! session on loopback and its own log: they elect a leader, decide a
//! claim proposed over Zenoh, decide another with one voter stopped (a
//! host gone), and the stopped voter, started again from its log, catches
//! up to the map.

use idmesh_consensus::{Command, VoterConfig};
use idmesh_protocol::wire::keys::Keys;
use idmesh_voter::{propose, run, RolesAnswer, VoterProcess};
use std::time::{Duration, Instant};
use tokio::sync::oneshot;
use zenoh::Session;

const IDS: [u64; 3] = [1, 2, 3];

fn free_port() -> u16 {
    let listener = std::net::TcpListener::bind("127.0.0.1:0").unwrap();
    listener.local_addr().unwrap().port()
}

/// A peer session listening on `port` and connecting to `others`.
async fn session(port: u16, others: &[u16]) -> Session {
    let mut config = zenoh::Config::default();
    let set = |config: &mut zenoh::Config, key: &str, value: String| {
        config.insert_json5(key, &value).unwrap();
    };
    set(&mut config, "mode", "\"peer\"".into());
    set(&mut config, "scouting/multicast/enabled", "false".into());
    let listen = vec![format!("tcp/127.0.0.1:{port}")];
    set(
        &mut config,
        "listen/endpoints",
        serde_json::to_string(&listen).unwrap(),
    );
    let connect: Vec<String> = others
        .iter()
        .map(|p| format!("tcp/127.0.0.1:{p}"))
        .collect();
    set(
        &mut config,
        "connect/endpoints",
        serde_json::to_string(&connect).unwrap(),
    );
    zenoh::open(config).await.unwrap()
}

struct Running {
    stop: oneshot::Sender<()>,
    done: tokio::task::JoinHandle<()>,
}

fn start(session: Session, id: u64, keys: &Keys, dir: &std::path::Path) -> Running {
    let config = VoterProcess {
        voter: VoterConfig {
            id,
            voters: IDS.to_vec(),
            election_ticks: 10,
            heartbeat_ticks: 2,
            fixed_timeouts: false,
        },
        keys: keys.clone(),
        log: dir.join(format!("voter-{id}.raft")),
        tick: Duration::from_millis(20),
    };
    let (stop, stopped) = oneshot::channel();
    let done = tokio::spawn(async move {
        run(session, config, async {
            let _ = stopped.await;
        })
        .await
        .unwrap();
    });
    Running { stop, done }
}

/// Every voter's answer to `query/roles`.
async fn answers(session: &Session, keys: &Keys) -> Vec<RolesAnswer> {
    // Every voter's queryable, each reply kept.
    let replies = session
        .get(keys.query_roles())
        .target(zenoh::query::QueryTarget::All)
        .consolidation(zenoh::query::ConsolidationMode::None)
        .timeout(Duration::from_secs(2))
        .await
        .unwrap();
    let mut out = Vec::new();
    while let Ok(reply) = replies.recv_async().await {
        if let Ok(sample) = reply.result() {
            out.push(serde_json::from_slice(&sample.payload().to_bytes()).unwrap());
        }
    }
    out.sort_by_key(|a: &RolesAnswer| a.voter);
    out
}

fn holder(answer: &RolesAnswer, role: &str) -> Option<(String, u64)> {
    let entry = answer.roles.iter().find(|e| e.role == role)?;
    Some((entry.holder.clone()?, entry.epoch))
}

/// Claims `role` for `holder` (proposing again while it is not decided)
/// until `voters` voters show it; returns its epoch.
async fn claim(session: &Session, keys: &Keys, role: &str, who: &str, voters: usize) -> u64 {
    let deadline = Instant::now() + Duration::from_secs(20);
    loop {
        let now = answers(session, keys).await;
        let shown: Vec<u64> = now
            .iter()
            .filter_map(|a| holder(a, role).filter(|(h, _)| h == who).map(|(_, e)| e))
            .collect();
        if shown.len() >= voters {
            return shown[0];
        }
        assert!(Instant::now() < deadline, "{role} for {who}: {now:?}");
        let fencing = now
            .iter()
            .filter_map(|a| holder(a, role))
            .map(|(_, e)| e)
            .max();
        let command = Command::Claim {
            role: role.into(),
            holder: who.into(),
            fencing,
        };
        propose(session, keys, &command).await.unwrap();
        tokio::time::sleep(Duration::from_millis(200)).await;
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn three_voters_decide_with_one_gone_and_it_catches_up() {
    let dir = tempfile::tempdir().unwrap();
    let keys = Keys::new(format!("idmesh/voter-test-{}", std::process::id()));
    let ports: Vec<u16> = (0..4).map(|_| free_port()).collect();
    let mut running = Vec::new();
    for (i, &id) in IDS.iter().enumerate() {
        let s = session(ports[i], &ports[..i]).await;
        running.push(Some(start(s, id, &keys, dir.path())));
    }
    let client = session(ports[3], &ports[..3]).await;

    assert_eq!(claim(&client, &keys, "leader-0", "east", 3).await, 1);
    // A host is gone: its voter stops. Two of three still decide.
    let gone = running[2].take().unwrap();
    let _ = gone.stop.send(());
    gone.done.await.unwrap();
    assert_eq!(claim(&client, &keys, "leader-0", "west", 2).await, 2);
    // Back from its log, it learns what was decided without it.
    let s = session(free_port(), &ports[..2]).await;
    running[2] = Some(start(s, 3, &keys, dir.path()));
    let deadline = Instant::now() + Duration::from_secs(20);
    loop {
        let now = answers(&client, &keys).await;
        let caught_up = now
            .iter()
            .find(|a| a.voter == 3)
            .and_then(|a| holder(a, "leader-0"))
            == Some(("west".into(), 2));
        if caught_up {
            break;
        }
        assert!(
            Instant::now() < deadline,
            "voter 3 did not catch up: {now:?}"
        );
        tokio::time::sleep(Duration::from_millis(100)).await;
    }
    for r in running.into_iter().flatten() {
        let _ = r.stop.send(());
        r.done.await.unwrap();
    }
}
