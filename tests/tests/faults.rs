//! Faults, with real processes on loopback: a leader killed in the middle
//! of a stream and started again, a leader killed for good (its role
//! adopted by another process), and a network that loses and doubles
//! batches, change no answer — the final marginals equal the centralized
//! engine's to 1e-9 (exact conditioning, no pruning), so no event was lost
//! and none applied twice.

use idmesh_tests::compare::{assert_same_marginals, floats};
use idmesh_tests::deployment::{crowd, replay_summary, Deployment, Settings};
use std::time::{Duration, Instant};

/// What each leader applied, by kind (cuts excluded: queries place them).
fn applied(deployment: &Deployment) -> Vec<(String, u64, u64, u64)> {
    deployment
        .leader_stats()
        .iter()
        .map(|l| {
            (
                l["leader"].as_str().unwrap().to_string(),
                l["mixes"].as_u64().unwrap(),
                l["observations"].as_u64().unwrap(),
                l["handovers"].as_u64().unwrap(),
            )
        })
        .collect()
}

/// SIGKILL to a leader while the stream runs: queries meanwhile get an
/// error naming it (never numbers without it); started again, it replays
/// its journal, fetches what it missed from the sensor and its peers, and
/// the final answer and every leader's applied events equal those of the
/// same deployment without the crash.
#[test]
fn a_leader_killed_mid_stream_and_restarted_changes_no_answer() {
    let dir = std::env::temp_dir().join(format!("idmesh-crash-{}", std::process::id()));
    let trace = crowd(&dir, 12, 4, 90.0, 5);
    let central = replay_summary(&trace, &["--method", "overcomplete"]);
    let expected = floats(&central["final_p_red"]);
    let settings = Settings {
        leaders: 4,
        rate: Some(500.0),
        journal: true,
        // Small, so that the killed leader comes back from a snapshot and
        // the journal after it.
        snapshot_every: Some(40),
        // Restarted, not replaced: no adoption however slow the restart.
        takeover_after_ms: Some(0),
        ..Settings::default()
    };
    let settings_gone = Settings {
        takeover_after_ms: Some(1500),
        ..settings.clone()
    };

    let calm = Deployment::start_each("calm", &trace, &settings);
    assert_same_marginals(
        &calm.final_marginals(Duration::from_secs(60)),
        &expected,
        "no crash",
    );
    let calm_applied = applied(&calm);
    drop(calm);

    let mut crashed = Deployment::start_each("crash", &trace, &settings);
    let first = crashed.first_answer(Duration::from_secs(30));
    assert_eq!(first["finished"], false, "the stream has begun, not ended");
    std::thread::sleep(Duration::from_millis(400));
    crashed.kill("leader-1");
    let down = Instant::now();
    let error = crashed
        .query(&["marginals"])
        .expect_err("no answer without leader-1");
    assert!(error.contains("leader-1"), "the error names it: {error}");
    std::thread::sleep(Duration::from_millis(600));
    crashed.launch("leader", "leader-1");
    let last = crashed.final_marginals(Duration::from_secs(60));
    eprintln!(
        "leader-1 down {:.2} s; final answer {:.2} s after the kill",
        0.6,
        down.elapsed().as_secs_f64()
    );
    assert_same_marginals(&last, &expected, "after a crash");
    assert_eq!(applied(&crashed), calm_applied);
    assert!(
        crashed.leaders_total("snapshots") > 0,
        "leaders wrote snapshots"
    );
    // Every transfer was received and made safe: none is kept any more.
    let kept = crashed.leaders_total_when("transfers_kept", Duration::from_secs(10), |k| k == 0);
    assert_eq!(kept, 0, "transfers kept after every leader made them safe");
    let back = crashed.leader("leader-1");
    assert_eq!(back["host"], "leader-1");
    eprintln!(
        "leader-1 restarted: caught up {:.3} s after it started again",
        back["recovery_seconds"].as_f64().unwrap()
    );
    drop(crashed);

    // Killed for good: after `takeover_after_ms` the next live leader
    // process (leader-2) adopts the role from its snapshot and journal and
    // fetches the rest; meanwhile answers are refused as degraded.
    let mut gone = Deployment::start_each("gone", &trace, &settings_gone);
    let first = gone.first_answer(Duration::from_secs(30));
    assert_eq!(first["finished"], false, "the stream has begun, not ended");
    std::thread::sleep(Duration::from_millis(400));
    gone.kill("leader-1");
    let killed = Instant::now();
    let error = gone
        .query(&["marginals"])
        .expect_err("no answer while leader-1's role has no process");
    assert!(error.contains("degraded"), "the error says so: {error}");
    let last = gone.final_marginals(Duration::from_secs(90));
    assert_same_marginals(&last, &expected, "after a takeover");
    assert_eq!(applied(&gone), calm_applied);
    let adopted = gone.leader("leader-1");
    assert_eq!(
        adopted["host"], "leader-2",
        "the next live process adopted it"
    );
    assert!(adopted["recoveries"].as_u64().unwrap() >= 1);
    eprintln!(
        "leader-1 gone for good: adopted and caught up {:.3} s after recovery began; final answer {:.2} s after the kill",
        adopted["recovery_seconds"].as_f64().unwrap(),
        killed.elapsed().as_secs_f64()
    );
}

/// Every batch published twice and every fifth not at all: leaders drop
/// the doubles, notice the gaps and ask the sensor again; the answer is the
/// centralized engine's.
#[test]
fn lost_and_doubled_batches_change_no_answer() {
    let dir = std::env::temp_dir().join(format!("idmesh-lossy-{}", std::process::id()));
    let trace = crowd(&dir, 12, 4, 90.0, 5);
    let central = replay_summary(&trace, &["--method", "overcomplete"]);
    let expected = floats(&central["final_p_red"]);
    let deployment = Deployment::start(
        "lossy",
        &trace,
        &Settings {
            leaders: 4,
            rate: Some(2000.0),
            faults: Some("duplicate = true\ndrop_every = 5".into()),
            ..Settings::default()
        },
    );
    assert_same_marginals(
        &deployment.final_marginals(Duration::from_secs(60)),
        &expected,
        "lossy network",
    );
    assert!(
        deployment.leaders_total("duplicates") > 0,
        "doubles were seen"
    );
    assert!(deployment.leaders_total("gaps") > 0, "gaps were seen");
    let kept = deployment.leaders_total_when("transfers_kept", Duration::from_secs(10), |k| k == 0);
    assert_eq!(kept, 0, "transfers kept after every leader applied them");
}
