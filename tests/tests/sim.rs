//! The deterministic network simulator over many seeded schedules
//! (`idmesh_tests::sim`): drops, duplicates, delays, reordering,
//! partitions, crashes and restarts from the journal, queries at random
//! points; every answer checked against the centralized engine.
//!
//! `IDMESH_SIM_SEEDS=N` runs N schedules (default 5000), from
//! `IDMESH_SIM_FIRST` (default 0); `IDMESH_SIM_SEED=s` replays schedule s
//! alone. A failing seed is printed with the line that replays it.

use idmesh_tests::sim;
use std::time::Instant;

fn env(name: &str) -> Option<u64> {
    std::env::var(name).ok().and_then(|v| v.parse().ok())
}

#[test]
fn every_schedule_answers_like_the_centralized_engine() {
    let seeds: Vec<u64> = match env("IDMESH_SIM_SEED") {
        Some(seed) => vec![seed],
        None => {
            let first = env("IDMESH_SIM_FIRST").unwrap_or(0);
            (first..first + env("IDMESH_SIM_SEEDS").unwrap_or(5000)).collect()
        }
    };
    let started = Instant::now();
    let mut total = sim::Tally::default();
    let mut failures = Vec::new();
    for &seed in &seeds {
        match sim::run(seed) {
            Ok(tally) => {
                total.answered += tally.answered;
                total.failed_queries += tally.failed_queries;
                total.crashes += tally.crashes;
                total.messages += tally.messages;
                total.dropped += tally.dropped;
                total.transfers += tally.transfers;
                total.follows += tally.follows;
                total.handovers += tally.handovers;
            }
            Err(violation) => {
                eprintln!("seed {seed}: {violation}\n  replay: IDMESH_SIM_SEED={seed} cargo test --release -p idmesh-tests --test sim");
                failures.push(seed);
            }
        }
    }
    let seconds = started.elapsed().as_secs_f64();
    eprintln!(
        "{} schedules in {seconds:.2} s ({:.0} schedules/s): {} answers checked, {} queries refused, {} crashes, {} messages ({} lost), {} transfers, {} follows, {} handovers",
        seeds.len(),
        seeds.len() as f64 / seconds,
        total.answered,
        total.failed_queries,
        total.crashes,
        total.messages,
        total.dropped,
        total.transfers,
        total.follows,
        total.handovers
    );
    assert!(failures.is_empty(), "failing seeds: {failures:?}");
    assert!(
        total.answered >= seeds.len() as u64,
        "every schedule gives its final answer"
    );
}
