//! `idmesh bench`: the distributed runtime's figures, measured on real
//! processes on this machine's loopback and printed as Markdown.
//!
//! - [`throughput`]: events per second through 1, 2, 4 … leaders, from the
//!   first event the coordinator sees to the answer that covers the whole
//!   trace; with the bytes each leader sent and received (the paper's
//!   Fig. 7(h), traffic per node).
//! - [`latency`]: `marginals` queries with four leaders, interleaved with
//!   the raw Zenoh round trips they are built from, measured in the same
//!   run: a get to one process and a get fanned out to every leader, both
//!   answered by the processes' ping queryables, which do no work.
//! - [`interval`]: how sure the median of the rounds' CPU ratios is.
//!
//! - [`sensors`] (with `--ingest`): one, two and three live sensors each
//!   fed by its own producer at once: events per second acknowledged and
//!   answered, and a put's way to the first answer that includes it.
//! - [`ingest`] (`--ingest`, on its own): events per second one producer
//!   gets acknowledged on a live sensor's ingest key, by lines per
//!   request, and a one-line ingest round trip against a raw get to the
//!   sensor in the same run.
//!
//! - [`identity`] (`--identity`, on its own): the identity belief at
//!   1,000 and 10,000 tracks, offline and through four leaders: memory,
//!   query time, the answer's size, live against offline.
//!
//! - [`replication`] (`--replication`, on its own): what the leaders'
//!   standbys cost in events per second, bytes and fsyncs per event.
//!
//! - [`accuracy`] (`--accuracy`, on its own): the live answers' tracking
//!   error on the Table III crowds against the centralized engine's, asked
//!   at every truth line.
//!
//! Figures are ratios against that floor, because the machine is noisy.

mod accuracy;
pub use accuracy::Crowds;
mod cpu;
mod extraction;
mod identity;
mod ingest;
mod interval;
mod latency;
mod regions;
mod replication;
mod sensors;
mod throughput;

use crate::runtime::launch::{simulate_crowd, Processes};
use crate::runtime::loopback::{self, Ports};
use crate::runtime::mesh::{self, MeshOptions};
use crate::runtime::query::ask;
use crate::runtime::topology::{default_max_component, BeliefKind, Topology};
use anyhow::{anyhow, bail, Context, Result};
use idmesh_protocol::wire::keys::Keys;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};
use zenoh::query::{ConsolidationMode, QueryTarget};

#[derive(Debug, Clone)]
pub struct BenchOptions {
    pub targets: usize,
    pub red: usize,
    /// Seconds of simulated crowd: the length of the stream.
    pub duration: f64,
    pub seed: u64,
    pub leaders: Vec<usize>,
    /// The leaders' belief.
    pub belief: BeliefKind,
    /// The sensor's flow control per leader (the topology's `window` is
    /// this times the leaders); None: no window.
    pub window: Option<u64>,
    /// Sets per leader (the Radon belief; the distributed rule runs with
    /// it).
    pub budget: u32,
    /// Streams per leader count; the median by leaders' CPU is reported.
    pub repeat: usize,
    /// Queries for the latency figures.
    pub queries: usize,
    /// Events per second of the stream queries are timed during.
    pub stream_rate: f64,
    pub dir: PathBuf,
    /// Also write a results page here ([`page`]; with `accuracy`, its
    /// report as printed).
    pub out: Option<PathBuf>,
    /// Only the ingestion figures.
    pub ingest: bool,
    /// The sensor and the leaders journal (`state_dir`), as a deployment
    /// that survives a kill does.
    pub journal: bool,
    /// Only the accuracy figure, on these Table III crowds.
    pub accuracy: Option<accuracy::Crowds>,
    /// Only the extraction figures (`extraction`): events from positions
    /// per second, and latency from a position to the answer.
    pub extraction: bool,
    /// Only the identity figures (`identity`): memory and query time of
    /// the identity belief at 1,000 and 10,000 tracks, offline and live.
    pub identity: bool,
    /// Only the replication figures (`replication`): three journaling
    /// leaders with standbys off and on.
    pub replication: bool,
    /// With `journal`: every leader role keeps a standby (the topology's
    /// `standbys`; the default).
    pub standbys: bool,
    /// With `journal`: inputs between a leader's snapshots (None: the
    /// topology's default).
    pub snapshot_every: Option<usize>,
}

pub fn run(options: &BenchOptions) -> Result<()> {
    let started = Instant::now();
    std::fs::create_dir_all(&options.dir)
        .with_context(|| format!("cannot create {}", options.dir.display()))?;
    let runtime = tokio::runtime::Builder::new_multi_thread()
        .worker_threads(1)
        .enable_all()
        .build()?;
    if let Some(crowds) = &options.accuracy {
        // Its own page (docs/live-accuracy.md, which the evaluation reads
        // back), written as it is printed.
        let report = accuracy::run(&runtime, crowds, &options.dir)?;
        print!("{report}");
        return match &options.out {
            Some(out) => write(out, &report),
            None => Ok(()),
        };
    }
    if options.extraction {
        return extraction::run(&runtime, options);
    }
    if options.identity {
        return identity::run(&runtime, options);
    }
    let trace = options.dir.join(format!(
        "crowd-{}-{}-{}.jsonl",
        options.targets, options.red, options.duration
    ));
    if !trace.exists() {
        eprintln!("bench: simulating {}", trace.display());
        simulate_crowd(
            options.targets,
            options.red,
            options.duration,
            options.seed,
            false,
            &trace,
        )?;
    }
    if options.replication {
        return replication::run(&runtime, options, &trace);
    }
    let report = if options.ingest {
        ingestion(&runtime, options, &trace)?
    } else {
        let mut report = report(options, &measure(&runtime, options, &trace)?)?;
        report.push_str(&regions::report(options, &trace)?);
        report
    };
    print!("{report}");
    if let Some(out) = &options.out {
        let made = Made::since(started);
        write(out, &page(options, &report, &made)?)?;
    }
    Ok(())
}

/// `--ingest`: one producer on a live sensor, then one to three sensors
/// each fed by its own; the report.
fn ingestion(
    runtime: &tokio::runtime::Runtime,
    options: &BenchOptions,
    trace: &Path,
) -> Result<String> {
    let mut report = String::new();
    let header = ingest::header_only(trace, &options.dir)?;
    let deployment = runtime.block_on(Deployment::start(options, &header, 1, None, true))?;
    eprintln!("bench: one producer feeding a live sensor");
    let figures = runtime.block_on(ingest::measure(&deployment, trace, options.queries));
    runtime.block_on(deployment.close());
    ingest::report(&figures?, options, &mut report)?;
    let mut several = Vec::new();
    for count in 1..=3 {
        let deployment = runtime.block_on(Deployment::start_sensors(
            options, &header, 3, None, true, count,
        ))?;
        eprintln!("bench: {count} live sensor(s), each fed by its own producer");
        let figures = runtime.block_on(sensors::measure(
            &deployment,
            trace,
            count,
            options.queries.min(200),
        ));
        runtime.block_on(deployment.close());
        several.push(figures?);
    }
    sensors::report(&several, &mut report)?;
    Ok(report)
}

/// What the bench measured (without `--ingest` or `--accuracy`).
pub struct Measured {
    /// Per leader count, the stream with the median leaders' CPU.
    pub streams: Vec<throughput::Stream>,
    /// Per leader count past one, its CPU against one leader's, by round.
    pub paired: Vec<throughput::PairedCpu>,
    /// Query latency with four leaders at rest after a stream, and during
    /// a paced stream (None with `--queries 0`).
    pub latency: Option<(latency::Latencies, latency::Latencies)>,
}

/// The leaders of the deployments queries are timed on.
const LATENCY_LEADERS: usize = 4;

/// Streams `trace` through every leader count, round by round, then times
/// queries.
fn measure(
    runtime: &tokio::runtime::Runtime,
    options: &BenchOptions,
    trace: &Path,
) -> Result<Measured> {
    // Latency with four leaders: at rest after the stream (the leaders
    // answer where they rest), and during a paced stream (every query
    // places a fresh cut).
    let leaders = LATENCY_LEADERS;
    let at_rest = |deployment: &Deployment| {
        eprintln!(
            "bench: {} marginals queries with {leaders} leaders at rest",
            options.queries
        );
        runtime.block_on(latency::measure(deployment, options.queries, false))
    };
    let mut runs: Vec<Vec<throughput::Stream>> =
        options.leaders.iter().map(|_| Vec::new()).collect();
    let mut rest = None;
    // In rounds, so that the machine's drift spreads over every count.
    for round in 0..options.repeat.max(1) {
        for (i, &count) in options.leaders.iter().enumerate() {
            let deployment =
                runtime.block_on(Deployment::start(options, trace, count, None, false))?;
            eprintln!(
                "bench: streaming through {count} leader(s), round {}",
                round + 1
            );
            runs[i].push(runtime.block_on(throughput::measure(&deployment))?);
            if count == leaders && rest.is_none() && options.queries > 0 {
                rest = Some(at_rest(&deployment)?);
            }
            runtime.block_on(deployment.close());
        }
    }
    let paired = throughput::paired_cpu(&runs);
    let streams: Vec<throughput::Stream> = runs
        .into_iter()
        .filter_map(throughput::median_by_cpu)
        .collect();
    if options.queries == 0 {
        return Ok(Measured {
            streams,
            paired,
            latency: None,
        });
    }
    let rest = match rest {
        Some(rest) => rest,
        None => {
            let deployment =
                runtime.block_on(Deployment::start(options, trace, leaders, None, false))?;
            runtime.block_on(throughput::measure(&deployment))?;
            let rest = at_rest(&deployment)?;
            runtime.block_on(deployment.close());
            rest
        }
    };
    eprintln!(
        "bench: {} marginals queries with {leaders} leaders during a stream at {} events/s",
        options.queries, options.stream_rate
    );
    let rate = Some(options.stream_rate);
    let deployment = runtime.block_on(Deployment::start(options, trace, leaders, rate, false))?;
    runtime.block_on(throughput::first_moving_answer(&deployment))?;
    let streaming = runtime.block_on(latency::measure(&deployment, options.queries, true))?;
    runtime.block_on(deployment.close());
    Ok(Measured {
        streams,
        paired,
        latency: Some((rest, streaming)),
    })
}

/// What the bench prints: the settings in a sentence, then the tables.
fn report(options: &BenchOptions, measured: &Measured) -> Result<String> {
    let mut report = String::new();
    writeln!(
        report,
        "Crowd of {} targets ({} red), {} s simulated; {}; {}; every process on this machine's loopback.\n",
        options.targets,
        options.red,
        options.duration,
        match options.belief {
            BeliefKind::Factored => format!(
                "the factored belief at the default settings (components of at most {} tracks, least-loss splits; one leader weighs its splits by the whole belief, several by the local rule under the regional rule, regions fitted to the crowd; the crowd is spread over several leaders whatever its size, `spread_above = 0`, since the bench measures them sharing it)",
                default_max_component(),
            ),
            BeliefKind::Radon => format!(
                "the Radon belief, distributed rule, budget {} sets per leader",
                options.budget
            ),
        },
        match options.window {
            Some(w) => format!(
                "the sensor at most {w} items per leader past the slowest leader (a window of {w} × L)"
            ),
            None => "no flow control".to_string(),
        }
    )?;
    if options.repeat > 1 {
        writeln!(
            report,
            "Each leader count streamed {} times, in rounds; each row is the stream with the median leaders' CPU.\n",
            options.repeat
        )?;
    }
    throughput::report(&measured.streams, &measured.paired, &mut report)?;
    if let Some((rest, streaming)) = &measured.latency {
        latency::report(rest, "stream over", &mut report)?;
        latency::report(
            streaming,
            &format!("during a stream at {} events/s", options.stream_rate),
            &mut report,
        )?;
    }
    Ok(report)
}

/// Where and when a page was made.
pub struct Made {
    /// [`idmesh_eval::description`].
    pub machine: String,
    /// YYYY-MM-DD.
    pub date: String,
    /// The whole run, wall clock.
    pub seconds: f64,
}

impl Made {
    /// This machine, today, a run that began at `started`.
    pub fn since(started: Instant) -> Made {
        Made {
            machine: idmesh_eval::description(),
            date: idmesh_eval::today(),
            seconds: started.elapsed().as_secs_f64(),
        }
    }
}

/// The stamp of the code that measured: the digest of the sources that
/// decide the bench's figures (build.rs).
fn stamp_line() -> String {
    format!(
        "<!-- idmesh bench stamp: sources {} -->",
        env!("IDMESH_BENCH_STAMP")
    )
}

/// The arguments of `idmesh bench` that reproduce a run of `options`:
/// every setting that decides a figure, spelled out (a changed default
/// would not change what the command runs), and `--out`. `--dir`, where
/// the scratch files go, is left out.
pub fn arguments(options: &BenchOptions) -> Vec<String> {
    let mut args: Vec<String> = vec!["bench".into()];
    let mut set = |name: &str, value: String| {
        args.push(format!("--{name}"));
        if !value.is_empty() {
            args.push(value);
        }
    };
    set("targets", options.targets.to_string());
    set("red", options.red.to_string());
    set("duration", options.duration.to_string());
    set("seed", options.seed.to_string());
    if options.ingest {
        set("ingest", String::new());
    } else {
        let counts: Vec<String> = options.leaders.iter().map(usize::to_string).collect();
        set("leaders", counts.join(","));
        set("repeat", options.repeat.to_string());
    }
    set("belief", options.belief.name().into());
    if options.belief == BeliefKind::Radon {
        set("budget", options.budget.to_string());
    }
    if let Some(window) = options.window {
        set("window", window.to_string());
    }
    if options.journal {
        set("journal", String::new());
    }
    set("queries", options.queries.to_string());
    if !options.ingest && options.queries > 0 {
        set("stream-rate", options.stream_rate.to_string());
    }
    if let Some(out) = &options.out {
        set("out", out.display().to_string());
    }
    args
}

/// The page `--out` writes: a title, the command that regenerates it, the
/// stamp of the code, the machine, the date and the wall time, the
/// settings, then `report` (what was printed).
pub fn page(options: &BenchOptions, report: &str, made: &Made) -> Result<String> {
    let args = arguments(options).join(" ");
    let mut out = String::new();
    writeln!(
        out,
        "# idmesh bench: {}\n\n\
         Generated by `idmesh {args}` — regenerate with\n\n\
         ```sh\ncargo run --release -p idmesh-deploy -- {args}\n```\n\n\
         {}\n",
        if options.ingest {
            "ingestion, on this machine's loopback"
        } else {
            "throughput, traffic, CPU and query latency, on this machine's loopback"
        },
        stamp_line(),
    )?;
    writeln!(
        out,
        "## Setup\n\n\
         Machine: {}. The whole run took {:.0} s (wall clock) on {}. Every process of \
         every deployment runs on this machine, over loopback.\n",
        made.machine, made.seconds, made.date
    )?;
    writeln!(out, "## Settings\n")?;
    writeln!(out, "| setting | value |")?;
    writeln!(out, "|---|---|")?;
    let yes_no = |b: bool| if b { "yes" } else { "no" };
    let mut row = |name: &str, value: String| writeln!(out, "| {name} | {value} |");
    row("targets (n)", options.targets.to_string())?;
    row("red (k)", options.red.to_string())?;
    row("simulated seconds", options.duration.to_string())?;
    row("crowd seed", options.seed.to_string())?;
    if !options.ingest {
        let counts: Vec<String> = options.leaders.iter().map(usize::to_string).collect();
        row("leader counts", counts.join(", "))?;
        row("rounds", options.repeat.max(1).to_string())?;
    }
    row("belief", options.belief.name().to_string())?;
    match options.belief {
        BeliefKind::Factored => {
            row(
                "largest component",
                format!("{} tracks", default_max_component()),
            )?;
            row("regional rule, fitted regions", "yes (the default)".into())?;
        }
        BeliefKind::Radon => row("sets per leader", options.budget.to_string())?,
    }
    row(
        "flow control, items per leader",
        options.window.map_or("none".into(), |w| w.to_string()),
    )?;
    row("journals", yes_no(options.journal).into())?;
    row("queries timed", options.queries.to_string())?;
    if !options.ingest && options.queries > 0 {
        row(
            "paced stream for latency, events/s",
            options.stream_rate.to_string(),
        )?;
        row("leaders for latency", LATENCY_LEADERS.to_string())?;
    }
    writeln!(out, "\n## Figures\n")?;
    out.push_str(report);
    Ok(out)
}

/// The page of a bench that runs on its own (`--extraction`,
/// `--identity`): a title, the command that regenerates it (`args`), the
/// stamp of the code, the machine, the date and the wall time, then
/// `report`.
fn page_of(title: &str, args: &str, report: &str, made: &Made) -> String {
    format!(
        "# idmesh bench: {title}\n\n\
         Generated by `idmesh {args}` — regenerate with\n\n\
         ```sh\ncargo run --release -p idmesh-deploy -- {args}\n```\n\n\
         {}\n\n\
         ## Setup\n\n\
         Machine: {}. The whole run took {:.0} s (wall clock) on {}. Every process runs on \
         this machine, over loopback.\n\n{report}",
        stamp_line(),
        made.machine,
        made.seconds,
        made.date
    )
}

fn write(out: &Path, text: &str) -> Result<()> {
    std::fs::write(out, text).with_context(|| format!("cannot write {}", out.display()))
}

/// One deployment for the bench: its processes, and a peer session joined
/// to all of them (so that pings to a leader take one hop, like the
/// coordinator's own gets).
pub struct Deployment {
    pub leaders: usize,
    pub topology: Topology,
    pub session: zenoh::Session,
    processes: [Processes; 2],
}

impl Deployment {
    /// `live`: the sensor stays open for producers once `trace` is out.
    async fn start(
        options: &BenchOptions,
        trace: &Path,
        leaders: usize,
        rate: Option<f64>,
        live: bool,
    ) -> Result<Self> {
        Self::start_sensors(options, trace, leaders, rate, live, 1).await
    }

    /// [`Deployment::start`] with `sensors` sensors (their leaders' batches
    /// sent by each in turn).
    async fn start_sensors(
        options: &BenchOptions,
        trace: &Path,
        leaders: usize,
        rate: Option<f64>,
        live: bool,
        sensors: usize,
    ) -> Result<Self> {
        let mut topology = loopback::topology(
            &std::fs::canonicalize(trace)?,
            leaders,
            sensors,
            Ports::Free,
        )?;
        topology.prefix = format!("idmesh/bench-{leaders}-{}", std::process::id());
        topology.belief = options.belief;
        // It measures leaders sharing a crowd: every crowd is spread (a
        // small one would otherwise be held whole by the first leader).
        topology.spread_above = 0;
        topology.distributed_rule = true;
        topology.budget = options.budget;
        // Streaming flat out, leaders can be seconds behind the sensor.
        topology.query_timeout_ms = 60_000;
        // Beside the topology; a journal of an earlier run would be
        // resumed, so it goes first.
        topology.state_dir = options.journal.then(|| PathBuf::from("state"));
        topology.standbys = options.standbys;
        if let Some(every) = options.snapshot_every {
            topology.snapshot_every = every;
        }
        for sensor in &mut topology.sensors {
            sensor.rate = rate;
            sensor.live = live;
            sensor.window = options.window.map(|w| w * leaders as u64);
        }
        if options.journal {
            let _ = std::fs::remove_dir_all(options.dir.join("state"));
        }
        let config = options
            .dir
            .join(format!("topology-{leaders}-{sensors}.toml"));
        Self::launch(&topology, &config).await
    }

    /// A deployment whose one sensor extracts its events with `extract`
    /// from what producers send to its ingest key, after `header`.
    async fn start_extracting(
        options: &BenchOptions,
        header: &Path,
        leaders: usize,
        extract: idmesh_extract::ExtractorConfig,
    ) -> Result<Self> {
        let mut topology =
            loopback::topology(&std::fs::canonicalize(header)?, leaders, 1, Ports::Free)?;
        topology.prefix = format!("idmesh/bench-extract-{leaders}-{}", std::process::id());
        for sensor in &mut topology.sensors {
            sensor.live = true;
            sensor.extract = Some(extract.clone());
        }
        let config = options.dir.join(format!("topology-extract-{leaders}.toml"));
        Self::launch(&topology, &config).await
    }

    /// Writes `topology` to `config` and starts its processes.
    async fn launch(topology: &Topology, config: &Path) -> Result<Self> {
        topology.save(config)?;
        let topology = Topology::load(config)?;
        let leaders = topology.leader.len();
        // The sensor starts last, once the coordinator and every leader's
        // counters answer here, so that the bench sees the stream from its
        // first events even when it is over in a fraction of a second (it
        // watches a leader's counters, [`throughput`]).
        let others = Processes::start_some(config, |m| m.role != "sensor")?;
        let connect = topology.members().into_iter().map(|m| m.listen).collect();
        let session = mesh::open(&MeshOptions {
            client: false,
            listen: vec![],
            connect,
            ..MeshOptions::default()
        })
        .await?;
        let keys = Keys::new(topology.prefix.clone());
        let coordinator = keys.ping("coordinator", &topology.coordinator.name);
        let started = Instant::now();
        while let Err(e) = ping(&session, &coordinator, 1).await {
            if started.elapsed() > STARTUP {
                return Err(e.context("the coordinator did not come up"));
            }
            tokio::time::sleep(Duration::from_millis(20)).await;
        }
        for leader in &topology.leader {
            let counters = keys.leader_stats(&leader.name);
            while let Err(e) = ask(&session, &counters, Duration::from_secs(1)).await {
                if started.elapsed() > STARTUP {
                    bail!("{} did not come up: {e}", leader.name);
                }
                tokio::time::sleep(Duration::from_millis(20)).await;
            }
        }
        let sensor = Processes::start_some(config, |m| m.role == "sensor")?;
        Ok(Deployment {
            leaders,
            topology,
            session,
            processes: [sensor, others],
        })
    }

    /// A get on `key` that returns once `answers` replies are in.
    pub async fn ping(&self, key: &str, answers: usize) -> Result<()> {
        ping(&self.session, key, answers).await
    }

    /// Pings `key` until `answers` replies come in (the bench's session
    /// reaches each process on its own), or fails after `within`.
    pub async fn wait_for(&self, key: &str, answers: usize, within: Duration) -> Result<()> {
        let started = Instant::now();
        while let Err(e) = self.ping(key, answers).await {
            if started.elapsed() > within {
                return Err(e);
            }
            tokio::time::sleep(Duration::from_millis(50)).await;
        }
        Ok(())
    }

    async fn close(self) {
        let _ = self.session.close().await;
    }

    pub fn keys(&self) -> Keys {
        Keys::new(self.topology.prefix.clone())
    }

    /// The first process to have exited, if any has.
    pub fn exited(&mut self) -> Option<(String, std::process::ExitStatus)> {
        self.processes.iter_mut().find_map(Processes::exited)
    }

    /// Every process's name and pid.
    pub fn pids(&self) -> impl Iterator<Item = (&str, u32)> {
        self.processes.iter().flat_map(Processes::pids)
    }

    /// Every process's CPU seconds so far.
    pub fn cpu_times(&self) -> Result<cpu::CpuTimes> {
        cpu::CpuTimes::read(self.processes.iter().flat_map(Processes::pids))
    }
}

/// How long a deployment may take to come up.
const STARTUP: Duration = Duration::from_secs(60);

/// A get on `key` (the processes' ping queryables) that returns once
/// `answers` replies are in; express, as the coordinator's own gets are.
async fn ping(session: &zenoh::Session, key: &str, answers: usize) -> Result<()> {
    let replies = session
        .get(key)
        .consolidation(ConsolidationMode::None)
        .target(QueryTarget::All)
        .express(true)
        .timeout(Duration::from_secs(10))
        .await
        .map_err(|e| anyhow!("ping {key}: {e}"))?;
    let mut got = 0;
    while got < answers {
        match replies.recv_async().await {
            Ok(reply) if reply.result().is_ok() => got += 1,
            Ok(_) => bail!("ping {key}: an error reply"),
            Err(_) => bail!("ping {key}: {got} of {answers} answered"),
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::latency::Latencies;
    use super::throughput::{Cpu, PairedCpu, Stream};
    use super::*;
    use idmesh_protocol::wire::coordinator_to_leader::LeaderStats;

    fn options() -> BenchOptions {
        BenchOptions {
            targets: 40,
            red: 10,
            duration: 3000.0,
            seed: 1,
            leaders: vec![1, 2, 4],
            belief: BeliefKind::Factored,
            window: Some(256),
            budget: 400,
            repeat: 6,
            queries: 100,
            stream_rate: 2000.0,
            dir: PathBuf::from("target/idmesh-bench"),
            out: Some(PathBuf::from("docs/bench.md")),
            ingest: false,
            journal: false,
            accuracy: None,
            extraction: false,
            identity: false,
            replication: false,
            standbys: true,
            snapshot_every: None,
        }
    }

    /// A stream through `items.len()` leaders: each leader's items and CPU.
    fn stream(items: &[u64], cpu: &[f64]) -> Stream {
        Stream {
            leaders: items.len(),
            events: 10_000,
            first_seen: 0,
            seconds: 2.0 / items.len() as f64,
            stats: items
                .iter()
                .enumerate()
                .map(|(i, &items)| LeaderStats {
                    leader: format!("leader-{i}"),
                    items,
                    bytes_sent: 1000 * i as u64,
                    ..LeaderStats::default()
                })
                .collect(),
            cpu: Cpu {
                sensor: 0.5,
                coordinator: 0.25,
                leaders: cpu.to_vec(),
            },
        }
    }

    fn latencies(ms: &[u64]) -> Latencies {
        let samples = |scale: u64| -> Vec<Duration> {
            ms.iter()
                .map(|&m| Duration::from_micros(m * scale))
                .collect()
        };
        Latencies {
            leaders: LATENCY_LEADERS,
            marginals: samples(1000),
            ping_one: samples(100),
            ping_leaders: samples(200),
            partials: samples(500),
        }
    }

    /// Six rounds of 1, 2 and 4 leaders, made up, with their latencies.
    fn measured() -> Measured {
        let ones: Vec<Stream> = (0..6).map(|_| stream(&[1000], &[1.0])).collect();
        let twos: Vec<Stream> = [1.1, 1.2, 1.3, 1.4, 1.5, 1.6]
            .iter()
            .map(|&c| stream(&[600, 400], &[c / 2.0, c / 2.0]))
            .collect();
        let fours: Vec<Stream> = [1.2, 1.3, 1.4, 1.5, 1.6, 1.7]
            .iter()
            .map(|&c| stream(&[300, 250, 250, 200], &[c / 4.0; 4]))
            .collect();
        let runs = vec![ones, twos, fours];
        let paired: Vec<PairedCpu> = throughput::paired_cpu(&runs);
        let streams = runs
            .into_iter()
            .filter_map(throughput::median_by_cpu)
            .collect();
        Measured {
            streams,
            paired,
            latency: Some((latencies(&[1, 2, 3, 4]), latencies(&[2, 3, 4, 5]))),
        }
    }

    fn made() -> Made {
        Made {
            machine: "Some CPU, 2 cores available, 8 GiB RAM, Linux 6.1".into(),
            date: "2026-11-28".into(),
            seconds: 812.4,
        }
    }

    #[test]
    fn the_page_says_how_to_regenerate_it_where_and_when_it_was_made_and_what_was_set() {
        let options = options();
        let report = report(&options, &measured()).unwrap();
        let page = page(&options, &report, &made()).unwrap();
        let command = "bench --targets 40 --red 10 --duration 3000 --seed 1 --leaders 1,2,4 \
                       --repeat 6 --belief factored --window 256 --queries 100 \
                       --stream-rate 2000 --out docs/bench.md";
        assert!(page.starts_with("# idmesh bench: "), "{page}");
        assert!(
            page.contains(&format!(
                "Generated by `idmesh {command}` — regenerate with"
            )),
            "{page}"
        );
        assert!(
            page.contains(&format!(
                "```sh\ncargo run --release -p idmesh-deploy -- {command}\n```"
            )),
            "{page}"
        );
        assert!(page.contains(&stamp_line()), "{page}");
        assert!(
            page.contains(
                "Machine: Some CPU, 2 cores available, 8 GiB RAM, Linux 6.1. The whole run \
                 took 812 s (wall clock) on 2026-11-28."
            ),
            "{page}"
        );
        for row in [
            "| targets (n) | 40 |",
            "| leader counts | 1, 2, 4 |",
            "| rounds | 6 |",
            "| regional rule, fitted regions | yes (the default) |",
            "| flow control, items per leader | 256 |",
            "| paced stream for latency, events/s | 2000 |",
        ] {
            assert!(page.contains(row), "{row}\n{page}");
        }
        // The tables, in the order printed, after the settings: all of
        // the report, as printed.
        let figures = page.find("## Figures").expect("a figures section");
        assert!(page[figures..].contains(&report));
        let mut at = figures;
        for title in [
            "### Throughput",
            "### Traffic per leader",
            "### CPU seconds",
            "### Scale-out goals",
            "### Query latency, 4 leaders, stream over",
            "### Query latency, 4 leaders, during a stream at 2000 events/s",
        ] {
            let found = page[at..]
                .find(title)
                .unwrap_or_else(|| panic!("{title} after the last\n{page}"));
            at += found;
        }
        // The busiest leader's items against an even share, and the CPU
        // ratio round by round with its interval, as computed.
        assert!(
            page.contains("| 2 | 1.20× (met) | 1.30× (met) | 1.30× (met; 97% interval 1.10–1.60×"),
            "{page}"
        );
        assert!(page.contains("| 4 | 1.20× (met) |"), "{page}");
        // No line of the page but the report's comes from anywhere else.
        assert!(report.starts_with("Crowd of 40 targets (10 red), 3000 s simulated;"));
    }

    #[test]
    fn the_ingest_page_names_its_own_command_and_leaves_out_what_it_does_not_run() {
        let options = BenchOptions {
            ingest: true,
            belief: BeliefKind::Radon,
            out: Some(PathBuf::from("ingest.md")),
            ..options()
        };
        assert_eq!(
            arguments(&options).join(" "),
            "bench --targets 40 --red 10 --duration 3000 --seed 1 --ingest --belief radon \
             --budget 400 --window 256 --queries 100 --out ingest.md"
        );
        let page = page(&options, "the figures\n", &made()).unwrap();
        assert!(page.contains("| sets per leader | 400 |"), "{page}");
        assert!(!page.contains("leader counts"), "{page}");
        assert!(page.ends_with("## Figures\n\nthe figures\n"), "{page}");
    }
}
