//! `idmesh bench --replication`: what the leaders' standbys cost. The
//! same crowd streams through three journaling leaders (`state_dir` in
//! the bench's folder, every other setting at its default) with standbys
//! off and on, in alternating rounds so that the machine's drift spreads
//! over both, and the report gives, per setting, the median round's
//! events per second, the leaders' bytes sent per 1,000 events (their
//! transfers plus the snapshots sent to standbys) and their processes'
//! fsyncs (journals, snapshots and the copies kept for others), with the
//! ratio of events per second on to off by round and the interval that
//! holds its median.
//!
//! A standby's copy is a whole snapshot sent at each snapshot the role
//! writes (every `snapshot_every` inputs, and at rest), so its cost grows
//! with the state and falls with the snapshots' spacing; what it buys is
//! in `docs/host-loss.md`.

use super::interval::{median, median_interval, CONFIDENCE};
use super::throughput::{self, lower_median, Stream};
use super::{page_of, write, BenchOptions, Deployment, Made};
use anyhow::Result;
use std::fmt::Write as _;
use std::path::Path;
use std::time::Instant;

/// Leaders of every stream: each role has another process to stand by.
const LEADERS: usize = 3;

/// Inputs between snapshots. Streamed flat out, a leader's inputs are a
/// few hundred large batches and the transfers, so the default (5,000)
/// would take no snapshot before the stream is over, and the figures
/// would not see the copies; a paced stream's batches are small and
/// many, and reach it.
const SNAPSHOT_EVERY: usize = 50;

/// What one setting gave over its rounds.
struct Setting {
    standbys: bool,
    rounds: Vec<Stream>,
}

impl Setting {
    /// The round with the median events per second.
    fn median_round(&self) -> Option<&Stream> {
        lower_median(self.rounds.iter().collect(), |s| s.events_per_second())
    }
}

/// Totals of `stream`'s leaders: bytes sent (transfers and standby
/// copies), of them the copies', fsyncs of their processes, snapshots.
fn totals(stream: &Stream) -> [u64; 4] {
    let sum = |f: fn(&idmesh_protocol::wire::coordinator_to_leader::LeaderStats) -> u64| {
        stream.stats.iter().map(f).sum::<u64>()
    };
    [
        sum(|l| l.bytes_sent + l.standby_bytes),
        sum(|l| l.standby_bytes),
        sum(|l| l.fsyncs),
        sum(|l| l.snapshots),
    ]
}

pub fn run(runtime: &tokio::runtime::Runtime, options: &BenchOptions, trace: &Path) -> Result<()> {
    let started = Instant::now();
    let mut settings = [false, true].map(|standbys| Setting {
        standbys,
        rounds: Vec::new(),
    });
    for round in 0..options.repeat.max(1) {
        for setting in &mut settings {
            let options = BenchOptions {
                journal: true,
                standbys: setting.standbys,
                snapshot_every: Some(SNAPSHOT_EVERY),
                ..options.clone()
            };
            let deployment =
                runtime.block_on(Deployment::start(&options, trace, LEADERS, None, false))?;
            eprintln!(
                "bench: {LEADERS} journaling leaders, standbys {}, round {}",
                if setting.standbys { "on" } else { "off" },
                round + 1
            );
            let stream = runtime.block_on(throughput::measure(&deployment));
            runtime.block_on(deployment.close());
            setting.rounds.push(stream?);
        }
    }
    let report = report(options, &settings)?;
    print!("{report}");
    if let Some(out) = &options.out {
        let made = Made::since(started);
        let args = format!(
            "bench --replication --targets {} --red {} --duration {} --seed {} --repeat {} --out {}",
            options.targets,
            options.red,
            options.duration,
            options.seed,
            options.repeat,
            out.display()
        );
        write(out, &page_of("what standbys cost", &args, &report, &made))?;
    }
    Ok(())
}

fn report(options: &BenchOptions, settings: &[Setting; 2]) -> Result<String> {
    let mut report = String::new();
    writeln!(
        report,
        "Crowd of {} targets ({} red), {} s simulated, streamed flat out through {LEADERS} \
         leaders, each its own process journaling to this machine's disk (`state_dir`, \
         fsync every 100 ms, a snapshot every {SNAPSHOT_EVERY} inputs and at rest), with \
         standbys off and on, {} round(s) each, alternating. Each row is the round with the median \
         events per second. Bytes and fsyncs are the leaders' (the sensor's journal is the \
         same in both).\n",
        options.targets,
        options.red,
        options.duration,
        options.repeat.max(1)
    )?;
    writeln!(
        report,
        "| standbys | events | events/s | bytes sent per 1,000 events | of them standby copies | fsyncs | fsyncs per 1,000 events | snapshots |"
    )?;
    writeln!(report, "|---|---|---|---|---|---|---|---|")?;
    for setting in settings {
        let Some(stream) = setting.median_round() else {
            continue;
        };
        let [bytes, copies, fsyncs, snapshots] = totals(stream);
        let per_1000 = |x: u64| 1000.0 * x as f64 / stream.events.max(1) as f64;
        writeln!(
            report,
            "| {} | {} | {:.0} | {:.0} | {:.0} | {fsyncs} | {:.3} | {snapshots} |",
            if setting.standbys { "on" } else { "off" },
            stream.events,
            stream.events_per_second(),
            per_1000(bytes),
            per_1000(copies),
            per_1000(fsyncs),
        )?;
    }
    let ratios: Vec<f64> = settings[0]
        .rounds
        .iter()
        .zip(&settings[1].rounds)
        .map(|(off, on)| on.events_per_second() / off.events_per_second())
        .collect();
    let interval = match median_interval(&ratios) {
        Some((low, high, confidence)) => format!(
            "[{low:.2}, {high:.2}] holds the median with {:.0}% confidence",
            confidence * 100.0
        ),
        None => format!(
            "too few rounds for a {:.0}% interval of the median (six at least)",
            CONFIDENCE * 100.0
        ),
    };
    let each: Vec<String> = ratios.iter().map(|r| format!("{r:.2}")).collect();
    writeln!(
        report,
        "\nEvents per second with standbys against without, round by round: median {:.2}; \
         {interval}; every round: {}.",
        median(&ratios),
        each.join(", ")
    )?;
    Ok(report)
}
