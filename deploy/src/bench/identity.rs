//! `idmesh bench --identity`: identities at scale, offline and live.
//!
//! For crowds of 1,000 and 10,000 people (the crowd simulator with
//! identities), at the default settings:
//! - **Offline**, in this process, as `idmesh replay` runs it: the
//!   factored identity belief over the whole trace, its memory, and one
//!   query (the marginals by row and the most likely assignment) timed a
//!   few times; the largest block of tracks the mixes connected (what the
//!   information matrix would have to answer as one).
//! - **Live**: a deployment of four leaders replays the trace; once it is
//!   over, identity queries to the coordinator are timed, the answer's
//!   size is weighed, its marginals are compared with the offline
//!   belief's, and each process's peak memory is read from the operating
//!   system.

use super::interval::{median, median_interval};
use super::{write, BenchOptions, Deployment, Made};
use crate::runtime::launch::simulate_crowd;
use crate::runtime::query::ask;
use anyhow::{anyhow, bail, Context, Result};
use idmesh_identity::identity_event_of;
use idmesh_identity::mixing_block_sizes;
use idmesh_identity::SparseMarginals;
use idmesh_identity::{FactoredIdentity, FactoredIdentityOptions, IdentityEvent, IdentityFilter};
use idmesh_protocol::trace::{Line, NumberedLine, TraceReader};
use idmesh_protocol::wire::query::IdentityAnswer;
use std::fmt::Write as _;
use std::path::Path;
use std::time::{Duration, Instant};

/// Crowd sizes.
const SIZES: [usize; 2] = [1_000, 10_000];
/// Leaders of the live deployment.
const LEADERS: usize = 4;
/// Queries timed, offline and live.
const QUERIES: usize = 7;
/// How long a stream may take to go through the deployment.
const STREAM_TIMEOUT: Duration = Duration::from_secs(1_800);

/// What one crowd measured.
struct Measured {
    tracks: usize,
    events: u64,
    /// Tracks of the largest component of the mixing graph.
    largest_block: usize,
    offline_events_seconds: f64,
    offline_bytes: usize,
    offline_query: Vec<f64>,
    live: Live,
}

/// What the live deployment measured.
struct Live {
    /// From starting the deployment to the answer that covers the stream.
    stream_seconds: f64,
    query: Vec<f64>,
    answer_bytes: usize,
    listed: usize,
    /// Largest |live − offline| over every marginal.
    difference: f64,
    same_assignment: bool,
    /// Peak resident memory (VmHWM) of the coordinator and of the
    /// busiest leader, bytes.
    coordinator_peak: u64,
    leader_peak: u64,
}

/// The offline belief after the whole trace, with its timing.
struct Offline {
    belief: FactoredIdentity,
    events: u64,
    seconds: f64,
    largest_block: usize,
}

fn offline(trace: &Path) -> Result<Offline> {
    let path = trace.display().to_string();
    let file = std::fs::File::open(trace).with_context(|| format!("{path}: cannot open"))?;
    let reader = TraceReader::new(std::io::BufReader::new(file), path.clone());
    let mut belief: Option<FactoredIdentity> = None;
    let (mut events, mut seconds) = (0u64, 0.0);
    let mut mixes: Vec<(usize, usize)> = Vec::new();
    for numbered in reader {
        let NumberedLine { number, line } = numbered.map_err(|e| anyhow!("{e}"))?;
        if let Line::Header(header) = &line {
            let start = header
                .initial_identity
                .as_ref()
                .ok_or_else(|| anyhow!("{path}:{number}: the crowd has no known start"))?;
            belief = Some(FactoredIdentity::from_assignment(
                start,
                FactoredIdentityOptions::default(),
            )?);
            continue;
        }
        let Some(event) = identity_event_of(&line) else {
            continue;
        };
        let belief = belief
            .as_mut()
            .ok_or_else(|| anyhow!("{path}:{number}: an event before the header"))?;
        let clock = Instant::now();
        belief
            .apply(&event)
            .map_err(|e| anyhow!("{path}:{number}: {e}"))?;
        seconds += clock.elapsed().as_secs_f64();
        events += 1;
        if let IdentityEvent::Mix(mix) = event {
            if mix.swap > 0.0 {
                mixes.push((mix.a as usize, mix.b as usize));
            }
        }
    }
    let belief = belief.ok_or_else(|| anyhow!("{path}: no header"))?;
    let largest_block = mixing_block_sizes(belief.size(), mixes)
        .first()
        .copied()
        .unwrap_or(0);
    Ok(Offline {
        belief,
        events,
        seconds,
        largest_block,
    })
}

/// One offline query: the marginals by row and the assignment under them.
fn offline_query(belief: &FactoredIdentity) -> Result<(SparseMarginals, Vec<u32>, f64)> {
    let clock = Instant::now();
    let p = belief.sparse_marginals()?;
    let best = p.most_likely()?;
    Ok((p, best, clock.elapsed().as_secs_f64()))
}

/// Peak resident memory of a process, bytes.
fn peak_memory(name: &str, pid: u32) -> Result<u64> {
    let status = procfs::process::Process::new(pid as i32)
        .and_then(|p| p.status())
        .with_context(|| format!("the memory of {name} (pid {pid})"))?;
    status
        .vmhwm
        .map(|kb| kb * 1024)
        .ok_or_else(|| anyhow!("{name} (pid {pid}) reports no peak memory"))
}

async fn live(
    options: &BenchOptions,
    trace: &Path,
    offline: &(SparseMarginals, Vec<u32>),
) -> Result<Live> {
    let started = Instant::now();
    let mut deployment = Deployment::start(options, trace, LEADERS, None, false).await?;
    let key = deployment.keys().query_identity();
    let timeout = Duration::from_secs(120);
    // Until the answer covers the whole stream.
    let answer = loop {
        if started.elapsed() > STREAM_TIMEOUT {
            bail!("the stream did not go through within {STREAM_TIMEOUT:?}");
        }
        if let Some((name, status)) = deployment.exited() {
            bail!("{name} exited ({status}) before the stream went through");
        }
        match ask(&deployment.session, &key, timeout).await {
            Ok(body) => {
                let answer: IdentityAnswer = serde_json::from_slice(&body)?;
                if answer.finished {
                    break answer;
                }
            }
            Err(e) => eprintln!("bench: not yet: {e}"),
        }
        tokio::time::sleep(Duration::from_secs(2)).await;
    };
    let stream_seconds = started.elapsed().as_secs_f64();
    let mut query = Vec::with_capacity(QUERIES);
    let mut answer_bytes = 0;
    for _ in 0..QUERIES {
        let clock = Instant::now();
        let body = ask(&deployment.session, &key, timeout).await?;
        query.push(clock.elapsed().as_secs_f64());
        answer_bytes = body.len();
    }
    let got = SparseMarginals::new(answer.p_identity)?;
    let (mut coordinator_peak, mut leader_peak) = (0, 0);
    for (name, pid) in deployment.pids() {
        let peak = peak_memory(name, pid)?;
        if name.contains("coordinator") {
            coordinator_peak = coordinator_peak.max(peak);
        } else if name.contains("leader") {
            leader_peak = leader_peak.max(peak);
        }
    }
    deployment.close().await;
    Ok(Live {
        stream_seconds,
        query,
        answer_bytes,
        listed: got.listed(),
        difference: got.max_abs_difference(&offline.0),
        same_assignment: answer.predicted_identity == offline.1,
        coordinator_peak,
        leader_peak,
    })
}

fn measure(
    runtime: &tokio::runtime::Runtime,
    options: &BenchOptions,
    tracks: usize,
) -> Result<Measured> {
    let trace = options.dir.join(format!(
        "identity-crowd-{tracks}-{}-{}.jsonl",
        options.duration, options.seed
    ));
    if !trace.exists() {
        eprintln!("bench: simulating {}", trace.display());
        simulate_crowd(
            tracks,
            options.red.min(tracks),
            options.duration,
            options.seed,
            true,
            &trace,
        )?;
    }
    eprintln!("bench: {tracks} tracks offline");
    let o = offline(&trace)?;
    let mut offline_query_times = Vec::with_capacity(QUERIES);
    let mut answer = None;
    for _ in 0..QUERIES {
        let (p, best, seconds) = offline_query(&o.belief)?;
        offline_query_times.push(seconds);
        answer = Some((p, best));
    }
    let answer = answer.ok_or_else(|| anyhow!("no offline query"))?;
    eprintln!("bench: {tracks} tracks through {LEADERS} leaders");
    let live = runtime.block_on(live(options, &trace, &answer))?;
    Ok(Measured {
        tracks,
        events: o.events,
        largest_block: o.largest_block,
        offline_events_seconds: o.seconds,
        offline_bytes: o.belief.memory_bytes(),
        offline_query: offline_query_times,
        live,
    })
}

/// "0.31 [0.29, 0.35]": a median of seconds with its interval.
fn seconds(values: &[f64]) -> String {
    match median_interval(values) {
        Some((lo, hi, _)) => format!("{:.3} [{lo:.3}, {hi:.3}]", median(values)),
        None => format!("{:.3}", median(values)),
    }
}

fn mb(bytes: f64) -> String {
    format!("{:.1}", bytes / 1e6)
}

pub fn run(runtime: &tokio::runtime::Runtime, options: &BenchOptions) -> Result<()> {
    let started = Instant::now();
    std::fs::create_dir_all(&options.dir)?;
    let measured: Vec<Measured> = SIZES
        .iter()
        .map(|&n| measure(runtime, options, n))
        .collect::<Result<_>>()?;
    let mut report = String::new();
    writeln!(
        report,
        "## Identities at scale\n\n\
         The crowd simulator with identities ({} simulated seconds, seed {}), at the default \
         settings: the factored identity belief (groups of up to 9 tracks, linked cuts, \
         leaks). **Offline** is this process running the trace as `idmesh replay` does; \
         **live** is a deployment of {LEADERS} leaders on this machine's loopback, asked \
         once the stream is through. A query is the marginals by row and the most likely \
         assignment under them; {QUERIES} of each, the median with its interval in brackets \
         (seconds). \"Largest block\": tracks the mixes connected into one component, which \
         the information matrix answers as one block. \"Live − offline\": the largest \
         difference between the live answer's marginals and the offline belief's over every \
         entry, and whether the assignments agree. Peak memory: the operating system's \
         high-water mark (VmHWM) of the coordinator and of the largest leader; the offline \
         belief's own memory is its tables and background rows as stored.\n",
        options.duration, options.seed
    )?;
    writeln!(
        report,
        "| tracks | events | largest block | offline: µs/event | offline: belief MB | offline: query s | live: stream s | live: query s | answer MB | listed entries | live − offline | same assignment | coordinator peak MB | leader peak MB |"
    )?;
    writeln!(
        report,
        "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|"
    )?;
    for m in &measured {
        writeln!(
            report,
            "| {} | {} | {} | {:.0} | {} | {} | {:.0} | {} | {} | {} | {:.1e} | {} | {} | {} |",
            m.tracks,
            m.events,
            m.largest_block,
            m.offline_events_seconds * 1e6 / m.events.max(1) as f64,
            mb(m.offline_bytes as f64),
            seconds(&m.offline_query),
            m.live.stream_seconds,
            seconds(&m.live.query),
            mb(m.live.answer_bytes as f64),
            m.live.listed,
            m.live.difference,
            if m.live.same_assignment { "yes" } else { "no" },
            mb(m.live.coordinator_peak as f64),
            mb(m.live.leader_peak as f64),
        )?;
    }
    print!("{report}");
    if let Some(out) = &options.out {
        let made = Made::since(started);
        write(out, &page(out, options, &report, &made))?;
    }
    Ok(())
}

fn page(out: &Path, options: &BenchOptions, report: &str, made: &Made) -> String {
    let args = format!(
        "bench --identity --duration {} --seed {} --red {} --out {}",
        options.duration,
        options.seed,
        options.red,
        out.display()
    );
    super::page_of("identities at scale", &args, report, made)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The offline half on a small crowd: every identity event applied,
    /// a block no larger than the crowd, and an answer whose assignment
    /// is one-to-one.
    #[test]
    fn a_small_crowd_replays_offline_and_answers() {
        let dir =
            std::env::temp_dir().join(format!("idmesh-bench-identity-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let trace = dir.join("crowd.jsonl");
        simulate_crowd(60, 5, 10.0, 3, true, &trace).unwrap();
        let o = offline(&trace).unwrap();
        assert!(o.events > 0);
        assert!((1..=60).contains(&o.largest_block), "{}", o.largest_block);
        let (p, best, _) = offline_query(&o.belief).unwrap();
        assert_eq!(p.size(), 60);
        let mut sorted = best.clone();
        sorted.sort_unstable();
        assert_eq!(sorted, (0..60).collect::<Vec<u32>>());
        assert!(o.belief.memory_bytes() > 0);
        std::fs::remove_dir_all(&dir).ok();
    }
}
