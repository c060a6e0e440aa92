//! Soak: a deployment streaming at a steady rate for ten minutes with
//! `IDMESH_LONG_TESTS=1` (as CI runs it), a minute and a half without (set
//! `IDMESH_SOAK_SECONDS` for another length), on loopback, with journals,
//! snapshots and a budget. Every ten seconds it samples each process's
//! resident memory and each leader's coefficient count, things kept for
//! others and snapshots, and asks for the marginals as a user would.
//!
//! Holds: resident memory flat after warm-up (what the sensor and leaders
//! keep for others is dropped as leaders make their state safe), no
//! leader ever above its budget, transfers kept bounded (by what came
//! since each leader's last snapshot) and let go, every query
//! answered, the stream's end reached. The figures are printed (see
//! docs/results.md).

use idmesh_tests::{crowd, Deployment, Settings};
use std::time::{Duration, Instant};

/// Resident memory of a process, in KiB (Linux).
fn rss_kib(pid: u32) -> Option<u64> {
    let status = std::fs::read_to_string(format!("/proc/{pid}/status")).ok()?;
    status
        .lines()
        .find(|l| l.starts_with("VmRSS:"))?
        .split_whitespace()
        .nth(1)?
        .parse()
        .ok()
}

struct Sample {
    at: f64,
    rss: Vec<u64>,
    coefficients: Vec<u64>,
    transfers_kept: u64,
    snapshots: u64,
    events: u64,
}

#[test]
fn ten_minutes_at_a_steady_load_keep_memory_flat_and_sets_within_budget() {
    let seconds: f64 = std::env::var("IDMESH_SOAK_SECONDS")
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or(if idmesh_tests::long_tests() {
            600.0
        } else {
            90.0
        });
    let target_rate = 200.0;
    let budget = 300;
    let (dir, _scratch) = idmesh_tests::scratch("idmesh-soak");
    // 24 targets make about 30 lines per simulated second.
    let trace = crowd(&dir, 24, 8, seconds * target_rate / 30.0, 11);
    let lines = std::fs::read_to_string(&trace).unwrap().lines().count() as f64;
    let rate = (lines / seconds).round();
    let settings = Settings {
        leaders: 4,
        budget,
        rate: Some(rate),
        journal: true,
        snapshot_every: Some(2000),
        ..Settings::default()
    };
    let deployment = Deployment::start_each("soak", &trace, &settings);
    let processes: Vec<String> = ["coordinator", "sensor-0"]
        .into_iter()
        .map(String::from)
        .chain((0..4).map(|i| format!("leader-{i}")))
        .collect();
    let pids: Vec<u32> = processes
        .iter()
        .map(|p| deployment.pid(p).expect("started"))
        .collect();
    deployment.first_answer(Duration::from_secs(60));
    let started = Instant::now();
    let mut samples: Vec<Sample> = Vec::new();
    let mut unanswered = Vec::new();
    let finished = loop {
        std::thread::sleep(Duration::from_secs(10));
        let answer = deployment.query(&["marginals"]);
        let leaders = deployment.leader_stats();
        let total = |f: &str| leaders.iter().map(|l| l[f].as_u64().unwrap()).sum();
        let events = match &answer {
            Ok(a) => a[0]["watermark"]["sensor-0"].as_u64().unwrap_or(0),
            Err(e) => {
                unanswered.push(e.clone());
                0
            }
        };
        samples.push(Sample {
            at: started.elapsed().as_secs_f64(),
            rss: pids.iter().map(|&p| rss_kib(p).unwrap_or(0)).collect(),
            coefficients: leaders
                .iter()
                .map(|l| l["coefficients"].as_u64().unwrap())
                .collect(),
            transfers_kept: total("transfers_kept"),
            snapshots: total("snapshots"),
            events,
        });
        if let Ok(a) = &answer {
            if a[0]["finished"] == true {
                break true;
            }
        }
        if started.elapsed().as_secs_f64() > seconds * 1.5 + 60.0 {
            break false;
        }
    };

    eprintln!("soak: {lines} events at {rate} events/s, 4 leaders, budget {budget}");
    eprintln!(
        "  t (s) | events | RSS MiB ({}) | coefficients | transfers kept | snapshots",
        processes.join(", ")
    );
    for s in &samples {
        let rss: Vec<String> = s
            .rss
            .iter()
            .map(|k| format!("{:.1}", *k as f64 / 1024.0))
            .collect();
        eprintln!(
            "  {:5.0} | {:6} | {} | {:?} | {} | {}",
            s.at,
            s.events,
            rss.join(" "),
            s.coefficients,
            s.transfers_kept,
            s.snapshots
        );
    }
    assert!(finished, "the stream ended within its time");
    assert!(
        unanswered.is_empty(),
        "every query answered: {unanswered:?}"
    );
    // Warm-up: the first fifth of the run (allocators and caches settle).
    let warm = samples
        .iter()
        .position(|s| s.at >= seconds / 5.0)
        .expect("samples after warm-up");
    let last = samples.last().unwrap();
    for (i, process) in processes.iter().enumerate() {
        let (at_warm, at_end) = (samples[warm].rss[i], last.rss[i]);
        let allowed = at_warm + at_warm / 10 + 8 * 1024;
        eprintln!(
            "  {process}: {:.1} MiB after warm-up, {:.1} MiB at the end",
            at_warm as f64 / 1024.0,
            at_end as f64 / 1024.0
        );
        assert!(
            at_end <= allowed,
            "{process} grew from {at_warm} KiB to {at_end} KiB after warm-up"
        );
    }
    // Sets handed over from a peer are held beside the receiver's own
    // until it next prunes, so a sample can catch a leader briefly over
    // its budget (seen once: 332 of 300, right after a peer went from 300
    // to 267); never in two samples running.
    for pair in samples.windows(2) {
        for (l, (&c, &next)) in pair[0]
            .coefficients
            .iter()
            .zip(&pair[1].coefficients)
            .enumerate()
        {
            assert!(
                c <= budget as u64 || next <= budget as u64,
                "leader-{l} held {c} then {next} sets, budget {budget}"
            );
        }
    }
    // A leader's durable mark is its last snapshot's (what its journal
    // holds after it may be found damaged and fetched again), so its peers
    // keep the transfers they sent it since: inputs of that leader, at
    // most `snapshot_every` of them. Each snapshot lets them go.
    let every = settings.snapshot_every.unwrap_or_default() as u64;
    for s in &samples {
        assert!(
            s.transfers_kept <= 4 * every,
            "transfers kept for peers grow: {}",
            s.transfers_kept
        );
    }
    assert!(last.snapshots > 0, "leaders wrote snapshots");
    assert!(
        samples
            .windows(2)
            .any(|w| w[1].transfers_kept < w[0].transfers_kept),
        "the transfers kept were let go after a snapshot"
    );
}
