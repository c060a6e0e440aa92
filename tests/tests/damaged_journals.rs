//! Damaged journals, with real processes on loopback: a role killed
//! mid-stream whose journal is then damaged — 32 bytes overwritten in the
//! middle of a leader's, 40 bits flipped in it, its last record torn; the
//! sensor's overwritten in one copy (after it first refuses to start with
//! both copies damaged) — is started again, and the deployment finishes
//! with `idmesh replay`'s final answer to 1e-9: nothing the damage took
//! was lost for good, and no damaged record was taken for a good one.
//!
//! The four cases run at once, each its own deployment (two leaders, a
//! 2,023-event crowd at 200 events/s, journals and snapshots).

use idmesh_journal::{Ending, Record, RECORD_HEAD};
use idmesh_tests::{assert_same_marginals, crowd, floats, replay_summary, Deployment, Settings};
use serde_json::Value;
use std::path::Path;
use std::time::{Duration, Instant};

/// The whole records of the log at `path` now (it may be being written).
fn records(path: &Path, kind: &'static str) -> Vec<Record> {
    match idmesh_journal::read(path, kind) {
        Ok(Some(contents)) => contents.records,
        _ => Vec::new(),
    }
}

/// Waits until the log at `path` holds at least `least` whole records
/// (and, for a leader, a snapshot was written beside it: the durable mark
/// has moved, so the sensor and the peer forgot what came before it).
fn wait_for_records(
    deployment: &Deployment,
    path: &Path,
    kind: &'static str,
    least: usize,
    snapshot: Option<&Path>,
) -> usize {
    let started = Instant::now();
    loop {
        let n = records(path, kind).len();
        if n >= least && snapshot.is_none_or(Path::exists) {
            return n;
        }
        if started.elapsed() > Duration::from_secs(60) {
            panic!(
                "{} holds {n} records (snapshot: {:?}) after 60 s\n{}",
                path.display(),
                snapshot.map(Path::exists),
                deployment.log()
            );
        }
        std::thread::sleep(Duration::from_millis(20));
    }
}

/// What the damage did to a leader's journal, for the checks after.
struct Damaged {
    /// Where the journal reads as damaged now (None: a torn tail).
    at: Option<u64>,
    /// Records it held whole before.
    records: usize,
}

/// 32 bytes overwritten in the middle record of the journal.
fn overwrite(path: &Path, kind: &'static str) -> Damaged {
    let whole = records(path, kind);
    if whole.is_empty() {
        // Killed just after a snapshot started the journal again: there
        // is nothing to damage, and the restart must still answer right.
        println!("{}: an empty journal, nothing to overwrite", path.display());
        return Damaged {
            at: None,
            records: 0,
        };
    }
    let middle = &whole[whole.len() / 2];
    let mut bytes = std::fs::read(path).unwrap();
    let from = middle.offset as usize + 5;
    let to = (from + 32).min(bytes.len());
    bytes[from..to].copy_from_slice(&b"this was not written by idmesh.."[..to - from]);
    std::fs::write(path, bytes).unwrap();
    Damaged {
        at: Some(middle.offset),
        records: whole.len(),
    }
}

/// 40 single bits flipped in the middle third of the journal's records.
fn flip_bits(path: &Path, kind: &'static str) -> Damaged {
    let whole = records(path, kind);
    let (first, last) = (&whole[whole.len() / 3], &whole[2 * whole.len() / 3]);
    let span = (first.offset * 8, last.end() * 8);
    let mut bytes = std::fs::read(path).unwrap();
    let mut state: u64 = 0x9e37_79b9_7f4a_7c15;
    let mut lowest = u64::MAX;
    for _ in 0..40 {
        // A small LCG: the flips are the same every run.
        state = state
            .wrapping_mul(6_364_136_223_846_793_005)
            .wrapping_add(1_442_695_040_888_963_407);
        let bit = span.0 + (state >> 11) % (span.1 - span.0);
        bytes[(bit / 8) as usize] ^= 1 << (bit % 8);
        lowest = lowest.min(bit / 8);
    }
    std::fs::write(path, bytes).unwrap();
    let hit = whole.iter().rfind(|r| r.offset <= lowest).unwrap();
    Damaged {
        at: Some(hit.offset),
        records: whole.len(),
    }
}

/// The last record cut in half: the process died writing it.
fn tear(path: &Path, kind: &'static str) -> Damaged {
    let whole = records(path, kind);
    let last = whole.last().unwrap();
    let file = std::fs::OpenOptions::new().write(true).open(path).unwrap();
    file.set_len(last.offset + (RECORD_HEAD + last.payload.len()) as u64 / 2)
        .unwrap();
    Damaged {
        at: None,
        records: whole.len(),
    }
}

fn settings() -> Settings {
    Settings {
        leaders: 2,
        rate: Some(200.0),
        journal: true,
        // Small, so that the killed leader has written snapshots (and its
        // mark moved) before its journal is damaged.
        snapshot_every: Some(60),
        // Restarted, never replaced.
        takeover_after_ms: Some(0),
        ..Settings::default()
    }
}

/// A leader killed mid-stream, its journal damaged by `damage`, started
/// again: the final answer is still `expected`.
fn leader_case(
    name: &str,
    trace: &Path,
    expected: &[f64],
    damage: fn(&Path, &'static str) -> Damaged,
) -> String {
    let started = Instant::now();
    let mut deployment = Deployment::start_each(name, trace, &settings());
    deployment.first_answer(Duration::from_secs(60));
    let journal = deployment.dir.join("state").join("leader-1.journal");
    let snapshot = deployment
        .dir
        .join("state")
        .join("leader-1.journal.snapshot");
    let kind = idmesh_leader::journal::JOURNAL;
    wait_for_records(&deployment, &journal, kind, 24, Some(&snapshot));
    deployment.kill("leader-1");
    let damaged = damage(&journal, kind);
    let read = idmesh_journal::read(&journal, kind).unwrap().unwrap();
    // Killed between writing a snapshot and starting the journal again:
    // the journal's entries are all in the snapshot, so the leader drops
    // them unread and its damage is no damage (the journal's own rule).
    let superseded = idmesh_journal::read(&snapshot, idmesh_leader::journal::SNAPSHOT)
        .unwrap()
        .is_some_and(|s| s.generation > read.generation);
    let damaged = if superseded {
        println!("{name}: killed between a snapshot and the journal's restart");
        Damaged {
            at: None,
            ..damaged
        }
    } else {
        damaged
    };
    match (damaged.at, &read.ending) {
        (Some(at), Ending::Damaged(d)) => assert_eq!(d.at, at, "{name}: {d}"),
        (None, Ending::Torn { .. }) => {}
        (None, _) if superseded || damaged.records == 0 => {}
        (_, ending) => panic!("{name}: the journal reads as {ending:?}"),
    }
    deployment.launch("leader", "leader-1");
    let last = deployment.final_marginals(Duration::from_secs(120));
    assert_same_marginals(&last, expected, name);
    let back = deployment.leader("leader-1");
    let dropped = back["journal_dropped"].as_u64().unwrap();
    match damaged.at {
        Some(_) => {
            assert_eq!(back["journal_damage"], 1, "{name}: {back}");
            assert!(
                dropped >= 2 && dropped as usize <= damaged.records,
                "{name}: {dropped} of {} entries dropped",
                damaged.records
            );
            assert!(
                journal.with_extension("journal.damaged").exists(),
                "{name}: the damaged journal is kept beside it"
            );
            assert!(
                deployment.log().contains("the journal is damaged"),
                "{name}: said so"
            );
        }
        None => assert_eq!(
            back["journal_damage"], 0,
            "{name}: a torn tail is no damage"
        ),
    }
    assert!(back["recoveries"].as_u64().unwrap() >= 1, "{name}: {back}");
    format!(
        "{name}: {} of {} journal entries dropped, final answer {:.1} s after the start",
        dropped,
        damaged.records,
        started.elapsed().as_secs_f64()
    )
}

/// The sensor killed mid-stream: with the same record damaged in both
/// copies of its journal it refuses to start, naming the file and the
/// byte; with one copy whole it repairs the other and the deployment
/// finishes with `expected`.
fn sensor_case(trace: &Path, expected: &[f64]) -> String {
    let name = "sensor-damaged";
    let started = Instant::now();
    let mut deployment = Deployment::start_each(name, trace, &settings());
    deployment.first_answer(Duration::from_secs(60));
    let journal = deployment.dir.join("state").join("sensor-0.journal");
    let copy = idmesh_sensor::journal::copy_path(&journal);
    let kind = idmesh_sensor::journal::KIND;
    let held = wait_for_records(&deployment, &journal, kind, 24, None);
    deployment.kill("sensor-0");
    let whole_copy = std::fs::read(&copy).unwrap();
    let Damaged { at, .. } = overwrite(&journal, kind);
    let at = at.unwrap();
    let mut both = whole_copy.clone();
    both[at as usize + RECORD_HEAD - 1] ^= 0x20;
    std::fs::write(&copy, &both).unwrap();
    let status = deployment.run_to_end("sensor", "sensor-0", Duration::from_secs(30));
    assert!(
        !status.success(),
        "started on a journal damaged in both copies"
    );
    let log = deployment.log();
    let said = format!("{} is damaged at byte {at}", journal.display());
    assert!(
        log.contains(&said) && log.contains("does not start"),
        "the refusal says where: {said}\n{log}"
    );
    // The copy whole again: the sensor repairs the journal from it.
    std::fs::write(&copy, &whole_copy).unwrap();
    deployment.launch("sensor", "sensor-0");
    let last = deployment.final_marginals(Duration::from_secs(120));
    assert_same_marginals(&last, expected, name);
    let sensor: Value = deployment
        .sensor_stats()
        .into_iter()
        .find(|s| s["sensor"] == "sensor-0")
        .expect("sensor-0's stats");
    let repaired = sensor["journal_repaired"].as_u64().unwrap();
    assert!(repaired >= 1, "{sensor}");
    format!(
        "{name}: {repaired} of {held} journal records taken from the copy, final answer {:.1} s after the start",
        started.elapsed().as_secs_f64()
    )
}

#[test]
fn roles_whose_journals_were_damaged_recover_and_the_answer_is_the_centralized_one() {
    let started = Instant::now();
    let (dir, _scratch) = idmesh_tests::scratch("idmesh-damaged");
    let trace = crowd(&dir, 16, 5, 110.0, 7);
    let central = replay_summary(&trace, &["--method", "overcomplete"]);
    let expected = floats(&central["final_p_red"]);
    type Case = fn(&Path, &'static str) -> Damaged;
    let leader_cases: [(&str, Case); 3] = [
        ("leader-overwritten", overwrite),
        ("leader-bits-flipped", flip_bits),
        ("leader-torn", tear),
    ];
    let outcomes: Vec<(String, std::thread::Result<String>)> = std::thread::scope(|scope| {
        let mut running = Vec::new();
        for (name, damage) in leader_cases {
            let (trace, expected) = (&trace, &expected);
            running.push((
                name.to_string(),
                scope.spawn(move || leader_case(name, trace, expected, damage)),
            ));
        }
        let (trace_ref, expected_ref) = (&trace, &expected);
        running.push((
            "sensor-damaged".into(),
            scope.spawn(move || sensor_case(trace_ref, expected_ref)),
        ));
        running
            .into_iter()
            .map(|(name, handle)| (name, handle.join()))
            .collect()
    });
    let mut failed = Vec::new();
    for (name, outcome) in outcomes {
        match outcome {
            Ok(said) => eprintln!("{said}"),
            Err(_) => failed.push(name),
        }
    }
    eprintln!(
        "four damaged deployments in {:.1} s",
        started.elapsed().as_secs_f64()
    );
    assert!(failed.is_empty(), "cases that failed: {failed:?}");
}
