//! Faults, with real processes on loopback: a leader killed in the middle
//! of a stream and started again, a leader killed for good (its role
//! adopted by another process), and a network that loses and doubles
//! batches, change no answer — the final marginals equal the centralized
//! engine's to 1e-9 (exact conditioning, no pruning), so no event was lost
//! and none applied twice.

use idmesh_consensus::RolesAnswer;
use idmesh_tests::{assert_same_marginals, floats};
use idmesh_tests::{
    crowd, hosted_on, replay_summary, standby_name, trace_events, undisturbed_applied,
    watermark_events, Deployment, FaultSection, LeaderFaultSection, Settings,
};
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

/// SIGKILL to a leader while the stream runs: queries meanwhile get an
/// error naming it (never numbers without it); started again, it replays
/// its journal, fetches what it missed from the sensor and its peers, and
/// the final answer and every leader's applied events equal those of the
/// same deployment without the crash.
#[test]
fn a_leader_killed_mid_stream_and_restarted_changes_no_answer() {
    let (dir, _scratch) = idmesh_tests::scratch("idmesh-crash");
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

    let calm_applied = undisturbed_applied("calm", &trace, &settings, &expected);

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
    assert_eq!(crashed.applied(), calm_applied);
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
    assert_eq!(gone.applied(), calm_applied);
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

/// Hosts with disks of their own: every leader process keeps its state
/// in its own directory, snapshots often (so the sensor and the peers
/// have long forgotten the stream's start), and leader-1 is killed for
/// good. Its heir, leader-2, finds no journal of the role on its disk but
/// the standby copy of its last snapshot it kept, adopts the role from it
/// and catches up from the sensor and the peers, who kept what came after
/// that copy: the final answer is the twin's to 1e-9, and nobody floods
/// the logs asking for what is gone.
#[test]
fn a_leader_lost_with_its_disk_is_adopted_from_its_standby_copy() {
    let (dir, _scratch) = idmesh_tests::scratch("idmesh-own-disks");
    let trace = crowd(&dir, 12, 4, 90.0, 5);
    let settings = Settings {
        leaders: 4,
        rate: Some(500.0),
        journal: true,
        own_disks: true,
        snapshot_every: Some(10),
        takeover_after_ms: Some(1000),
        ..Settings::default()
    };
    let mut gone = Deployment::start_each("own-disks", &trace, &settings);
    let twin = gone.twin_summary(&trace);
    let first = gone.first_answer(Duration::from_secs(30));
    assert_eq!(first["finished"], false, "the stream has begun, not ended");
    let started = Instant::now();
    // Several snapshots, and so several durable marks, before the kill.
    let patience = Instant::now() + Duration::from_secs(20);
    while gone.leader("leader-1")["snapshots"].as_u64().unwrap_or(0) < 5 {
        assert!(Instant::now() < patience, "leader-1 wrote no snapshots");
        std::thread::sleep(Duration::from_millis(100));
    }
    let heir_disk = gone.dir.join("state-leader-2");
    let kept_copy = heir_disk.join("leader-1.standby.snapshot").exists();
    assert!(!heir_disk.join("leader-1.journal").exists(), "disks apart");
    eprintln!(
        "killing leader-1 {:.2} s after the first answer",
        started.elapsed().as_secs_f64()
    );
    gone.kill("leader-1");
    let killed = Instant::now();
    final_is_twins(&gone, &twin, "after a host lost with its disk");
    assert!(
        kept_copy,
        "leader-2 kept leader-1's snapshot before the kill"
    );
    let adopted = gone.leader("leader-1");
    assert_eq!(adopted["host"], "leader-2", "its standby adopted it");
    assert!(heir_disk.join("leader-1.journal.snapshot").exists());
    eprintln!(
        "leader-1 lost with its disk: adopted from the standby copy and caught up {:.3} s \
         after recovery began; final answer {:.2} s after the kill",
        adopted["recovery_seconds"].as_f64().unwrap_or(f64::NAN),
        killed.elapsed().as_secs_f64()
    );
    let log = gone.log();
    let asked_again = log.matches("resend request failed").count();
    let dropped = log.matches("were dropped").count();
    let sensor_rejected: u64 = gone
        .sensor_stats()
        .iter()
        .map(|s| s["rejected"].as_u64().unwrap_or(0))
        .sum();
    eprintln!("resend refusals logged: {asked_again}; sensor rejected: {sensor_rejected}");
    assert_eq!(dropped, 0, "nothing the role needed was forgotten:\n{log}");
    assert!(asked_again <= 4, "{asked_again} resend refusals logged");
    assert!(sensor_rejected <= 4, "the sensor refused {sensor_rejected}");
    drop(gone);
}

/// Four leaders on disks of their own, a snapshot every 10 inputs, a
/// takeover after 2 s, at `rate` events per second.
fn own_disks(rate: f64) -> Settings {
    Settings {
        leaders: 4,
        rate: Some(rate),
        journal: true,
        own_disks: true,
        snapshot_every: Some(10),
        takeover_after_ms: Some(2000),
        ..Settings::default()
    }
}

/// A deployment of [`own_disks`] leaders at `rate` streaming a small
/// crowd, under way: its folder, its trace, the deployment and its
/// offline twin's summary.
fn under_way(name: &str, rate: f64) -> (PathBuf, Deployment, serde_json::Value) {
    let dir = std::env::temp_dir().join(format!("idmesh-{name}-{}", std::process::id()));
    let trace = crowd(&dir, 12, 4, 90.0, 5);
    let deployment = Deployment::start_each(name, &trace, &own_disks(rate));
    let twin = deployment.twin_summary(&trace);
    let first = deployment.first_answer(Duration::from_secs(30));
    assert_eq!(first["finished"], false, "the stream has begun, not ended");
    (dir, deployment, twin)
}

/// The heir's disk is gone: its state folder emptied.
fn wipe(deployment: &Deployment, process: &str) {
    let disk = deployment.dir.join(format!("state-{process}"));
    std::fs::remove_dir_all(&disk).expect("the disk wiped");
    std::fs::create_dir_all(&disk).expect("an empty disk");
}

/// Waits until `role` has written `snapshots` snapshots.
fn snapshots_written(deployment: &Deployment, role: &str, snapshots: u64) {
    let patience = Instant::now() + Duration::from_secs(20);
    while deployment.leader(role)["snapshots"].as_u64().unwrap_or(0) < snapshots {
        assert!(Instant::now() < patience, "{role} wrote no snapshots");
        std::thread::sleep(Duration::from_millis(100));
    }
}

/// Two leader processes killed at once, and the heir of one's role — its
/// standby, the one process with a copy of it — started again before the
/// takeover time is up: it never saw that role's token go, but it knows
/// the role ran (its copy, the marks it heard), presumes it lost and
/// adopts it from its copy; the final answer is the offline twin's.
#[test]
fn a_role_lost_while_its_heir_was_down_is_adopted_by_the_heir() {
    let (dir, mut deployment, twin) = under_way("heir-down", 300.0);
    snapshots_written(&deployment, "leader-1", 3);
    // leader-2 is next in line for leader-1's role, and its standby.
    deployment.kill("leader-1");
    deployment.kill("leader-2");
    deployment.launch("leader", "leader-2");
    final_is_twins(
        &deployment,
        &twin,
        "after a role lost while its heir was down",
    );
    let adopted = deployment.leader("leader-1");
    assert_eq!(
        adopted["host"], "leader-2",
        "its heir adopted it: {adopted}"
    );
    assert_eq!(deployment.log().matches("were dropped").count(), 0);
    drop(deployment);
    std::fs::remove_dir_all(&dir).ok();
}

/// A role's heir started afresh (an empty disk) just as the role is lost:
/// it knows nothing of the role and lets its turn pass; the next in line,
/// which took the role's standby copies while the heir was down, adopts
/// it in the next turn, and the final answer is the offline twin's.
#[test]
fn a_role_its_fresh_heir_knows_nothing_of_is_adopted_in_the_next_turn() {
    let (dir, mut deployment, twin) = under_way("fresh-heir", 150.0);
    deployment.kill("leader-2");
    wipe(&deployment, "leader-2");
    // leader-3 now keeps leader-1's copies, and adopts leader-2's role.
    let copy = deployment
        .dir
        .join("state-leader-3/leader-1.standby.snapshot");
    let patience = Instant::now() + Duration::from_secs(20);
    let hosted_by_3 = |d: &Deployment| {
        d.leader_stats()
            .iter()
            .any(|l| l["leader"] == "leader-2" && l["host"] == "leader-3")
    };
    while !copy.exists() || !hosted_by_3(&deployment) {
        assert!(
            Instant::now() < patience,
            "leader-3 took over neither:\n{}",
            deployment.log()
        );
        std::thread::sleep(Duration::from_millis(100));
    }
    snapshots_written(&deployment, "leader-1", 3);
    deployment.kill("leader-1");
    deployment.launch("leader", "leader-2");
    final_is_twins(
        &deployment,
        &twin,
        "after a role lost as its heir started afresh",
    );
    let adopted = deployment.leader("leader-1");
    assert_eq!(
        adopted["host"], "leader-3",
        "the next in line adopted it: {adopted}"
    );
    assert_eq!(deployment.log().matches("were dropped").count(), 0);
    drop(deployment);
    std::fs::remove_dir_all(&dir).ok();
}

/// A role's heir down for a while (its disk kept), the role's copies
/// going to the next in line meanwhile, and the role lost just as the
/// heir comes back: the heir's own copy is older than what the sensor
/// still holds, so it asks the others for theirs, takes the newer one,
/// adopts the role from it, and the final answer is the offline twin's.
#[test]
fn an_heir_with_an_old_copy_takes_the_newest_from_another_process() {
    let (dir, mut deployment, twin) = under_way("copy-asked", 150.0);
    snapshots_written(&deployment, "leader-1", 2);
    deployment.kill("leader-2");
    // leader-3 keeps leader-1's copies now; leader-1 moves on.
    let copy = deployment
        .dir
        .join("state-leader-3/leader-1.standby.snapshot");
    let patience = Instant::now() + Duration::from_secs(20);
    while !copy.exists() {
        assert!(
            Instant::now() < patience,
            "leader-3 kept no copy:\n{}",
            deployment.log()
        );
        std::thread::sleep(Duration::from_millis(100));
    }
    let written = deployment.leader("leader-1")["snapshots"]
        .as_u64()
        .unwrap_or(0);
    snapshots_written(&deployment, "leader-1", written + 3);
    deployment.kill("leader-1");
    deployment.launch("leader", "leader-2");
    final_is_twins(
        &deployment,
        &twin,
        "after a role lost as its heir came back with an old copy",
    );
    let adopted = deployment.leader("leader-1");
    assert_eq!(
        adopted["host"], "leader-2",
        "its heir adopted it: {adopted}"
    );
    let log = deployment.log();
    assert!(log.contains("took a newer standby copy"), "{log}");
    assert_eq!(log.matches("were dropped").count(), 0, "{log}");
    drop(deployment);
    std::fs::remove_dir_all(&dir).ok();
}

/// `idmesh up` supervises: a leader killed under it (kill -9) is started
/// again after its backoff while its neighbours run on, and the answer is
/// the centralized engine's.
#[test]
fn up_starts_a_killed_process_again_and_leaves_its_neighbours() {
    let (dir, _scratch) = idmesh_tests::scratch("idmesh-supervised");
    let trace = crowd(&dir, 12, 4, 60.0, 8);
    let central = replay_summary(&trace, &["--method", "overcomplete"]);
    let expected = floats(&central["final_p_red"]);
    let settings = Settings {
        leaders: 3,
        rate: Some(500.0),
        journal: true,
        takeover_after_ms: Some(0),
        ..Settings::default()
    };
    let deployment = Deployment::start("supervised", &trace, &settings);
    let first = deployment.first_answer(Duration::from_secs(30));
    assert_eq!(first["finished"], false, "the stream has begun, not ended");
    let before = deployment.supervised();
    assert_eq!(
        before.len(),
        5,
        "coordinator, sensor, three leaders: {before:?}"
    );
    // SAFETY: kill(2) on a process of this test's deployment.
    unsafe {
        libc::kill(before["leader-1"] as i32, libc::SIGKILL);
    }
    let killed = Instant::now();
    let after = loop {
        let now = deployment.supervised();
        if now
            .get("leader-1")
            .is_some_and(|&pid| pid != before["leader-1"])
        {
            break now;
        }
        assert!(
            killed.elapsed() < Duration::from_secs(10),
            "leader-1 was not started again: {now:?}"
        );
        std::thread::sleep(Duration::from_millis(50));
    };
    for (name, pid) in &before {
        if name != "leader-1" {
            assert_eq!(after.get(name), Some(pid), "{name} was left alone");
        }
    }
    let last = deployment.final_marginals(Duration::from_secs(60));
    assert_same_marginals(&last, &expected, "after a supervised restart");
    eprintln!(
        "leader-1 started again by up {:.2} s after the kill",
        killed.elapsed().as_secs_f64()
    );
}

/// Every batch published twice and every fifth not at all: leaders drop
/// the doubles, notice the gaps and ask the sensor again; the answer is the
/// centralized engine's.
#[test]
fn lost_and_doubled_batches_change_no_answer() {
    let (dir, _scratch) = idmesh_tests::scratch("idmesh-lossy");
    let trace = crowd(&dir, 12, 4, 90.0, 5);
    let central = replay_summary(&trace, &["--method", "overcomplete"]);
    let expected = floats(&central["final_p_red"]);
    let deployment = Deployment::start(
        "lossy",
        &trace,
        &Settings {
            leaders: 4,
            rate: Some(2000.0),
            faults: FaultSection {
                duplicate: true,
                drop_every: Some(5),
            },
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

/// A transfer lost on a live link — as when Zenoh's TLS link
/// between two leaders closes and reopens — is noticed and fetched again
/// from its sender without any restart: every third transfer each leader
/// sends is lost on purpose, and the final answer is still the centralized
/// engine's, with nothing kept for anyone at the end.
#[test]
fn transfers_lost_on_a_live_link_are_fetched_again() {
    let (dir, _scratch) = idmesh_tests::scratch("idmesh-lost-transfers");
    let trace = crowd(&dir, 12, 4, 90.0, 5);
    let central = replay_summary(&trace, &["--method", "overcomplete"]);
    let expected = floats(&central["final_p_red"]);
    let deployment = Deployment::start(
        "lost-transfers",
        &trace,
        &Settings {
            leaders: 4,
            rate: Some(2000.0),
            leader_faults: LeaderFaultSection {
                drop_transfer_every: Some(3),
                ..LeaderFaultSection::default()
            },
            ..Settings::default()
        },
    );
    assert_same_marginals(
        &deployment.final_marginals(Duration::from_secs(60)),
        &expected,
        "transfers lost on the way",
    );
    let received = deployment.leaders_total("transfers_received");
    assert!(received > 3, "leaders exchanged transfers: {received}");
    let kept = deployment.leaders_total_when("transfers_kept", Duration::from_secs(10), |k| k == 0);
    assert_eq!(kept, 0, "transfers kept after every leader applied them");
}

/// Roles go home: leader-1's process is killed, leader-2's
/// process adopts the role; leader-1's process comes back, stands by and
/// asks for it; leader-2 hands it back (state moved through the shared
/// journal) and leader-1's process hosts its own role again — load back
/// in balance — with the final answer still the centralized engine's.
#[test]
fn an_adopted_role_goes_home_when_its_process_returns() {
    let (dir, _scratch) = idmesh_tests::scratch("idmesh-home");
    let trace = crowd(&dir, 12, 4, 90.0, 5);
    let central = replay_summary(&trace, &["--method", "overcomplete"]);
    let expected = floats(&central["final_p_red"]);
    let settings = Settings {
        leaders: 4,
        rate: Some(300.0),
        journal: true,
        snapshot_every: Some(40),
        takeover_after_ms: Some(1000),
        ..Settings::default()
    };
    let mut deployment = Deployment::start_each("home", &trace, &settings);
    deployment.first_answer(Duration::from_secs(30));
    deployment.kill("leader-1");
    let killed = Instant::now();
    // Adopted by the next live process.
    let adopted = deployment.answer_when(&["stats"], Duration::from_secs(30), |s| {
        hosted_on(s, "leader-1", "leader-2")
    });
    assert!(adopted["leaders"].is_array());
    let adoption = killed.elapsed();
    deployment.launch("leader", "leader-1");
    let back = Instant::now();
    deployment.answer_when(&["stats"], Duration::from_secs(30), |s| {
        hosted_on(s, "leader-1", "leader-1")
    });
    let handed_back = back.elapsed();
    let last = deployment.final_marginals(Duration::from_secs(60));
    assert_same_marginals(&last, &expected, "after the role went home");
    assert_eq!(deployment.leader("leader-1")["host"], "leader-1");
    eprintln!(
        "role adopted {:.2} s after the kill (takeover_after 1 s); handed back {:.2} s after its process returned",
        adoption.as_secs_f64(),
        handed_back.as_secs_f64()
    );
}

/// A coordinator and a replica (`[[coordinator_replica]]`): the first is
/// killed for good mid-stream (SIGKILL, never started again) and queries
/// given both endpoints go on being answered by the replica, within a
/// few seconds, to the end; the final answer equals the twin's to 1e-9.
#[test]
fn a_coordinator_killed_for_good_is_replaced_by_its_replica() {
    let (dir, _scratch) = idmesh_tests::scratch("idmesh-coordinators");
    let trace = crowd(&dir, 16, 4, 60.0, 3);
    let settings = Settings {
        leaders: 2,
        rate: Some(1000.0),
        factored: Some(idmesh_tests::Factored::default()),
        coordinator_replicas: 1,
        ..Settings::default()
    };
    let mut deployment = Deployment::start_each("coordinators", &trace, &settings);
    let twin = deployment.twin_summary(&trace);
    let first = deployment.first_answer(Duration::from_secs(30));
    assert_eq!(first["finished"], false, "the stream has begun, not ended");
    deployment.kill("coordinator");
    let killed = Instant::now();
    let answered = deployment.answer_when(&["marginals"], Duration::from_secs(30), |_| true);
    eprintln!(
        "the first answer after the coordinator's kill came {:.2} s after it, at {} events",
        killed.elapsed().as_secs_f64(),
        idmesh_tests::watermark_events(&answered)
    );
    final_is_twins(&deployment, &twin, "after the coordinator's loss");
}

/// Three voters beside a deployment elect a leader of their group; with
/// that voter killed for good the two left agree on another (a majority
/// still decides); started again, it rejoins from its log in the group's
/// term. (The roles do not read the voters' map yet.)
#[test]
fn voters_keep_a_leader_with_one_gone_and_take_it_back() {
    let (dir, _scratch) = idmesh_tests::scratch("idmesh-voters");
    let trace = crowd(&dir, 12, 3, 30.0, 5);
    let settings = Settings {
        leaders: 1,
        rate: Some(200.0),
        voters: 3,
        ..Settings::default()
    };
    let mut deployment = Deployment::start_each("voters", &trace, &settings);
    // (the leader they all name, its term), once `voters` answer and agree.
    let agreed = |deployment: &Deployment, voters: usize| -> Option<(u64, u64)> {
        let answers = deployment.query(&["roles"]).ok()?;
        let leader = answers.first()?["leader"].as_u64()?;
        let term = answers.first()?["term"].as_u64()?;
        // The leader among them: followers name a dead one until their
        // election timeout.
        let all = answers.len() == voters
            && answers.iter().any(|a| a["voter"] == leader)
            && answers
                .iter()
                .all(|a| a["leader"] == leader && a["term"] == term);
        all.then_some((leader, term))
    };
    let wait = |deployment: &Deployment, voters: usize, what: &str| -> (u64, u64) {
        let deadline = Instant::now() + Duration::from_secs(30);
        loop {
            if let Some(found) = agreed(deployment, voters) {
                return found;
            }
            assert!(
                Instant::now() < deadline,
                "{what}: {:?}",
                deployment.query(&["roles"])
            );
            std::thread::sleep(Duration::from_millis(200));
        }
    };
    let (leader, term) = wait(&deployment, 3, "three voters agreeing on a leader");
    let gone = format!("voter-{leader}");
    deployment.kill(&gone);
    let (next, later) = wait(&deployment, 2, "the two left agreeing on another leader");
    assert_ne!(next, leader);
    assert!(later > term, "term {later} after {term}");
    deployment.launch("voter", &gone);
    let (_, back) = wait(&deployment, 3, "the voter back from its log");
    assert!(back >= later);
}

/// The final answer, within 60 s, equals the offline twin's (`twin`, its
/// summary); `after` says after what, should it not.
fn final_is_twins(deployment: &Deployment, twin: &serde_json::Value, after: &str) {
    let last = deployment.final_marginals(Duration::from_secs(60));
    assert_same_marginals(&last, &floats(&twin["final_p_red"]), after);
}

/// Waits until the sensor standby's copy at `copy` is in sync at the
/// epoch `holder` holds the sensor role at now; that epoch.
fn copy_in_sync(deployment: &Deployment, copy: &Path, holder: &str) -> u64 {
    let in_sync = copy.with_extension("journal.epoch");
    let deadline = Instant::now() + Duration::from_secs(30);
    loop {
        let held = held_by(deployment, "sensor-0", holder, Duration::from_secs(30));
        let at = idmesh_journal::read_number(&in_sync, "sensor-copy");
        if matches!(at, Ok(Some(epoch)) if epoch == held) {
            return held;
        }
        assert!(
            Instant::now() < deadline,
            "the copy {} never in sync at epoch {held} ({at:?}):\n{}",
            copy.display(),
            deployment.log()
        );
        std::thread::sleep(Duration::from_millis(200));
    }
}

/// Waits until the first sensor's stats name one of `standbys` as the one
/// its journal is replicated to; that one.
fn replicated_to<'a>(deployment: &Deployment, standbys: &'a [String]) -> &'a str {
    let deadline = Instant::now() + Duration::from_secs(30);
    loop {
        let stats = deployment.sensor_stats()[0].clone();
        if let Some(name) = standbys.iter().find(|n| stats["standby"] == n.as_str()) {
            return name;
        }
        assert!(
            Instant::now() < deadline,
            "the stats never named a standby of {standbys:?}: {stats}\n{}",
            deployment.log()
        );
        std::thread::sleep(Duration::from_millis(200));
    }
}

/// Three leaders, each on a disk of its own, under three voters, with a
/// snapshot every 10 inputs and a takeover after 1 s at `rate` events per
/// second: the deployment the host-loss tests strike.
fn apart_under_voters(rate: f64) -> Settings {
    Settings {
        leaders: 3,
        rate: Some(rate),
        journal: true,
        own_disks: true,
        voters: 3,
        snapshot_every: Some(10),
        takeover_after_ms: Some(1000),
        ..Settings::default()
    }
}

/// Who holds `role` in the voters' map, and at which epoch (from the
/// leading voter's answer).
fn holding(deployment: &Deployment, role: &str) -> Option<(String, u64)> {
    let answers = deployment.query(&["roles"]).ok()?;
    let answers = answers
        .into_iter()
        .map(serde_json::from_value::<RolesAnswer>);
    let leading = RolesAnswer::newest(answers.collect::<Result<Vec<_>, _>>().ok()?)?;
    let entry = leading.get(role)?;
    Some((entry.holder.clone()?, entry.epoch))
}

/// Waits until the voters' map gives `role` to `holder`; its epoch.
fn held_by(deployment: &Deployment, role: &str, holder: &str, within: Duration) -> u64 {
    let deadline = Instant::now() + within;
    loop {
        if let Some((h, epoch)) = holding(deployment, role) {
            if h == holder {
                return epoch;
            }
        }
        assert!(
            Instant::now() < deadline,
            "{role} never held by {holder}: {:?}",
            deployment.query(&["roles"])
        );
        std::thread::sleep(Duration::from_millis(200));
    }
}

/// Three voters decide who holds each leader role, and the leaders keep
/// their state on disks of their own. leader-1's process is frozen
/// (SIGSTOP: a host cut off, its process still there) past the takeover
/// time: the voters give its role to leader-2 at the next epoch, which
/// runs it from its standby copy. Woken, the former holder finds the map
/// moved on and stops the role (what it sent at its old epoch is refused
/// by the fence), stands by, and gets its role back home at a later
/// epoch. Every epoch has one holder; the final answer equals the twin's.
#[test]
fn a_frozen_leader_is_superseded_through_the_voters_and_its_role_goes_home() {
    let (dir, _scratch) = idmesh_tests::scratch("idmesh-frozen");
    let trace = crowd(&dir, 12, 4, 150.0, 5);
    let settings = apart_under_voters(300.0);
    let deployment = Deployment::start_each("frozen", &trace, &settings);
    let twin = deployment.twin_summary(&trace);
    let first = held_by(&deployment, "leader-1", "leader-1", Duration::from_secs(30));
    deployment.first_answer(Duration::from_secs(30));
    deployment.pause("leader-1");
    let frozen = Instant::now();
    let taken = held_by(&deployment, "leader-1", "leader-2", Duration::from_secs(40));
    assert!(
        taken > first,
        "a takeover raises the epoch: {first} then {taken}"
    );
    eprintln!(
        "leader-1 frozen: the voters gave its role to leader-2 at epoch {taken} {:.1} s later",
        frozen.elapsed().as_secs_f64()
    );
    deployment.resume("leader-1");
    let home = held_by(&deployment, "leader-1", "leader-1", Duration::from_secs(40));
    assert!(home > taken, "home at a later epoch: {taken} then {home}");
    final_is_twins(
        &deployment,
        &twin,
        "after a holder superseded and its role back home",
    );
    let log = deployment.log();
    // Woken, it stops the role: its lease lapsed while it was frozen, or
    // the map it reads gives the role to another.
    assert!(
        log.contains("for the lease: stopping the role")
            || log.contains("the voters gave the role to another"),
        "the woken holder stopped the role:\n{log}"
    );
    drop(deployment);
}

/// The sensor's host lost for good (kill -9, its disk gone with it) about
/// two fifths into the stream: its standby, on another disk, holds every
/// record the sensor acted on (the sensor waited for it before anything
/// left), claims the sensor role through the voters once the sensor's
/// token has been gone for the takeover time, and serves as the sensor
/// from its copy. Producers and leaders follow without change, and the
/// final answer is the offline twin's.
#[test]
fn a_sensor_lost_with_its_host_is_taken_over_by_its_standby() {
    let (dir, _scratch) = idmesh_tests::scratch("idmesh-sensor-standby");
    let trace = crowd(&dir, 12, 4, 60.0, 5);
    let settings = Settings {
        sensor_standbys: 1,
        ..apart_under_voters(400.0)
    };
    let started = Instant::now();
    let mut deployment = Deployment::start_each("sensor-standby", &trace, &settings);
    let twin = deployment.twin_summary(&trace);
    let total = trace_events(&trace).len() as u64;
    deployment.first_answer(Duration::from_secs(30));
    // Two fifths in (the harness panics with the logs if not within 30 s).
    deployment.answer_when(&["marginals"], Duration::from_secs(30), |a| {
        watermark_events(a) * 5 >= total * 2
    });
    let copy = deployment
        .dir
        .join("state-sensor-0-standby")
        .join("sensor-0.standby.journal");
    let held = idmesh_sensor::journal::read(&copy).map_or(0, |records| records.len());
    assert!(held > 0, "the standby keeps a copy on its own disk");
    assert!(
        !deployment
            .dir
            .join("state-sensor-0-standby")
            .join("sensor-0.journal")
            .exists(),
        "disks apart"
    );
    let first = held_by(&deployment, "sensor-0", "sensor-0", Duration::from_secs(10));
    deployment.kill("sensor-0");
    let killed = Instant::now();
    let taken = held_by(
        &deployment,
        "sensor-0",
        "sensor-0-standby",
        Duration::from_secs(30),
    );
    let takeover = killed.elapsed().as_secs_f64();
    assert!(
        taken > first,
        "a takeover raises the epoch: {first} then {taken}"
    );
    final_is_twins(&deployment, &twin, "after the sensor's host was lost");
    let log = deployment.log();
    assert!(
        log.contains("taking over from the copy"),
        "the standby took the sensor role over from its copy:\n{log}"
    );
    eprintln!(
        "sensor-0 killed at two fifths of {total} events ({held} records in the standby's \
         copy); held by its standby at epoch {taken} {takeover:.2} s after the kill; final \
         answer {:.2} s after the kill; test {:.1} s",
        killed.elapsed().as_secs_f64(),
        started.elapsed().as_secs_f64()
    );
    drop(deployment);
}

/// The sensor role moves to its standby and back. The sensor frozen past
/// the takeover time: its standby takes the role over. Woken, the former
/// sensor ends (its hold is gone); started again, it finds the role held
/// by its standby and stands by for it, its own journal emptied and
/// filled again with the holder's; started again, it keeps that copy.
/// Then the holder's host is lost (kill -9): the former sensor takes the
/// role back from that copy, at the next epoch. The final answer is the
/// offline twin's.
#[test]
fn a_sensor_role_taken_over_keeps_a_standby_and_moves_back_when_that_host_is_lost() {
    let (dir, _scratch) = idmesh_tests::scratch("idmesh-sensor-back");
    let trace = crowd(&dir, 12, 4, 60.0, 5);
    let settings = Settings {
        sensor_standbys: 1,
        ..apart_under_voters(60.0)
    };
    let mut deployment = Deployment::start_each("sensor-back", &trace, &settings);
    let twin = deployment.twin_summary(&trace);
    let first = held_by(&deployment, "sensor-0", "sensor-0", Duration::from_secs(30));
    deployment.first_answer(Duration::from_secs(30));
    deployment.pause("sensor-0");
    let taken = held_by(
        &deployment,
        "sensor-0",
        "sensor-0-standby",
        Duration::from_secs(40),
    );
    assert!(taken > first, "a takeover raises the epoch");
    deployment.resume("sensor-0");
    let ended = deployment.relaunch("sensor", "sensor-0", Duration::from_secs(30));
    assert!(
        !ended.success(),
        "the woken former sensor ends with an error"
    );
    deployment.await_log(
        "of an earlier holding: emptied, standing by for the holder",
        Duration::from_secs(30),
    );
    // The holder sends it its whole journal once it sees it stand by.
    let own = deployment
        .dir
        .join("state-sensor-0")
        .join("sensor-0.journal");
    let in_sync = own.with_extension("journal.epoch");
    let started = Instant::now();
    while idmesh_sensor::journal::read(&own).map_or(0, |records| records.len()) == 0
        || !in_sync.exists()
    {
        assert!(
            started.elapsed() < Duration::from_secs(30),
            "the holder never sent its journal to the former sensor:\n{}",
            deployment.log()
        );
        std::thread::sleep(Duration::from_millis(100));
    }
    // Started again while standing by, it keeps that copy: it is the
    // holder's, not its own earlier holding.
    deployment.kill("sensor-0");
    deployment.launch("sensor", "sensor-0");
    deployment.await_log(
        "its copy of the holder's: kept, standing by for the holder",
        Duration::from_secs(30),
    );
    assert!(
        idmesh_sensor::journal::read(&own).is_ok_and(|records| !records.is_empty()),
        "the copy survived the restart"
    );
    // The holder went on without it meanwhile (a new epoch): only once the
    // copy has caught up can it take the role.
    copy_in_sync(&deployment, &own, "sensor-0-standby");
    deployment.kill("sensor-0-standby");
    let back = held_by(&deployment, "sensor-0", "sensor-0", Duration::from_secs(30));
    assert!(
        back > taken,
        "back home at a later epoch: {taken} then {back}"
    );
    final_is_twins(
        &deployment,
        &twin,
        "after the sensor role moved to its standby and back",
    );
    drop(deployment);
}

/// The sensor's process frozen (SIGSTOP: its host cut off, the process
/// still there) past the takeover time: the voters give the sensor role
/// to its standby at the next epoch, which serves from its copy. Woken,
/// the former sensor finds the map moved on (or its lease lapsed) and
/// stops serving; what it sends meanwhile at its old epoch is refused by
/// the leaders' fence. The final answer is the offline twin's.
#[test]
fn a_frozen_sensor_is_superseded_by_its_standby_and_stops_when_woken() {
    let (dir, _scratch) = idmesh_tests::scratch("idmesh-sensor-frozen");
    let trace = crowd(&dir, 12, 4, 60.0, 5);
    let settings = Settings {
        sensor_standbys: 1,
        ..apart_under_voters(200.0)
    };
    let started = Instant::now();
    let deployment = Deployment::start_each("sensor-frozen", &trace, &settings);
    let twin = deployment.twin_summary(&trace);
    let first = held_by(&deployment, "sensor-0", "sensor-0", Duration::from_secs(30));
    deployment.first_answer(Duration::from_secs(30));
    deployment.pause("sensor-0");
    let frozen = Instant::now();
    let taken = held_by(
        &deployment,
        "sensor-0",
        "sensor-0-standby",
        Duration::from_secs(40),
    );
    assert!(
        taken > first,
        "a takeover raises the epoch: {first} then {taken}"
    );
    let takeover = frozen.elapsed().as_secs_f64();
    deployment.resume("sensor-0");
    final_is_twins(
        &deployment,
        &twin,
        "after the sensor was superseded by its standby",
    );
    let log = deployment.log();
    assert!(
        log.contains("the voters gave the sensor role to another: stopping")
            || log.contains("no leading voter for the lease: stopping the sensor role")
            || log.contains("the voters did not move the role here to a new epoch"),
        "the woken sensor stopped serving:\n{log}"
    );
    eprintln!(
        "sensor-0 frozen: held by its standby at epoch {taken} {takeover:.1} s later; test \
         {:.1} s",
        started.elapsed().as_secs_f64()
    );
    drop(deployment);
}

/// The sensor's standby cut off from the sensor while the voters still
/// reach both (here: frozen, which the sensor cannot tell from cut off).
/// The sensor goes on without it only once the voters have moved the
/// sensor role to a new epoch, and publishes what the copy lacks. Then
/// the sensor's host is lost and the standby wakes: its copy is in sync
/// only at the old epoch, so its claim loses and the role waits for the
/// sensor rather than going on from a copy that misses what leaders
/// already applied. Back from its own disk, the sensor serves again and
/// the final answer is the offline twin's.
#[test]
fn a_sensor_going_on_without_its_standby_fences_off_the_standbys_copy() {
    let (dir, _scratch) = idmesh_tests::scratch("idmesh-sensor-alone");
    let trace = crowd(&dir, 12, 4, 60.0, 5);
    let settings = Settings {
        sensor_standbys: 1,
        ..apart_under_voters(60.0)
    };
    let mut deployment = Deployment::start_each("sensor-alone", &trace, &settings);
    let twin = deployment.twin_summary(&trace);
    let before = watermark_events(&deployment.first_answer(Duration::from_secs(30)));
    // Once the copy is in sync at the epoch the sensor holds now (it may
    // have moved on once already, if it started before its standby).
    let copy = deployment
        .dir
        .join("state-sensor-0-standby")
        .join("sensor-0.standby.journal");
    let first = copy_in_sync(&deployment, &copy, "sensor-0");
    deployment.pause("sensor-0-standby");
    let deadline = Instant::now() + Duration::from_secs(40);
    let moved = loop {
        match holding(&deployment, "sensor-0") {
            Some((holder, epoch)) if epoch > first => {
                assert_eq!(holder, "sensor-0", "the standby was frozen");
                break epoch;
            }
            _ => assert!(
                Instant::now() < deadline,
                "the sensor never moved its role on without its standby:\n{}",
                deployment.log()
            ),
        }
        std::thread::sleep(Duration::from_millis(200));
    };
    // What the standby's copy lacks reaches the leaders.
    deployment.answer_when(&["marginals"], Duration::from_secs(30), |a| {
        watermark_events(a) > before
    });
    deployment.kill("sensor-0");
    deployment.resume("sensor-0-standby");
    deployment.await_log(
        "moved past the epoch this copy is in sync at",
        Duration::from_secs(40),
    );
    std::thread::sleep(Duration::from_secs(2));
    assert_eq!(
        holding(&deployment, "sensor-0"),
        Some(("sensor-0".to_string(), moved)),
        "the standby's stale copy must not win the role"
    );
    deployment.launch("sensor", "sensor-0");
    final_is_twins(
        &deployment,
        &twin,
        "after the sensor went on alone and came back",
    );
    drop(deployment);
}

/// A sensor with two standbys, each on a disk of its own. The one the
/// sensor replicates to is lost for good (kill -9): the sensor moves its
/// role to a new epoch, so that copy, behind from then on, can never win
/// it, and sends its whole journal to the other, which is in sync at that
/// epoch before anything more leaves. Then the sensor's host is lost too:
/// the second standby takes the role over from its copy, and the final
/// answer is the offline twin's. Two hosts lost one after the other, and
/// the stream goes on.
#[test]
fn a_sensor_with_two_standbys_outlives_the_loss_of_one_and_then_its_own_host() {
    let (dir, _scratch) = idmesh_tests::scratch("idmesh-sensor-two-standbys");
    let trace = crowd(&dir, 12, 4, 60.0, 5);
    let settings = Settings {
        sensor_standbys: 2,
        ..apart_under_voters(60.0)
    };
    let mut deployment = Deployment::start_each("sensor-two-standbys", &trace, &settings);
    let twin = deployment.twin_summary(&trace);
    deployment.first_answer(Duration::from_secs(30));
    let state = deployment.dir.clone();
    let copy_of = |name: &str| {
        state
            .join(format!("state-{name}"))
            .join("sensor-0.standby.journal")
    };
    let names = [standby_name("sensor-0", 0), standby_name("sensor-0", 1)];
    // The standby replicated to, as the sensor's stats name it: its copy
    // is in sync at the epoch the sensor holds its role at.
    let lost = replicated_to(&deployment, &names);
    let first = copy_in_sync(&deployment, &copy_of(lost), "sensor-0");
    let stats = deployment.sensor_stats()[0].clone();
    assert!(stats["epoch"].as_u64() >= Some(first), "{stats}");
    let other = names.iter().find(|n| *n != lost).expect("two standbys");
    deployment.kill(lost);
    let moved = copy_in_sync(&deployment, &copy_of(other), "sensor-0");
    assert_eq!(replicated_to(&deployment, &names), other);
    assert!(
        moved > first,
        "the sensor moved its role on before it replicated to {other}: epoch {first}, then {moved}"
    );
    deployment.kill("sensor-0");
    let taken = held_by(&deployment, "sensor-0", other, Duration::from_secs(30));
    assert!(
        taken > moved,
        "a takeover raises the epoch: {moved} then {taken}"
    );
    final_is_twins(
        &deployment,
        &twin,
        "after the sensor's standby and then its host were lost",
    );
    let log = deployment.log();
    assert!(
        log.contains(&format!(
            "the sensor goes on without it until another is chosen standby={lost}"
        )),
        "the sensor said which standby it lost:\n{log}"
    );
}
