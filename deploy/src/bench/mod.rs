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
//! - [`accuracy`] (`--accuracy`, on its own): the live answers' tracking
//!   error on the Table III crowds against the centralized engine's, asked
//!   at every truth line.
//!
//! Figures are ratios against that floor, because the machine is noisy.

mod accuracy;
pub use accuracy::Crowds;
mod cpu;
mod ingest;
mod interval;
mod latency;
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
    /// Factored: leaders' interests shrink.
    pub shrink_interest: bool,
    /// Factored: the regional rule.
    pub regional: bool,
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
    /// Also write the report here.
    pub out: Option<PathBuf>,
    /// Only the ingestion figures.
    pub ingest: bool,
    /// The sensor and the leaders journal (`state_dir`), as a deployment
    /// that survives a kill does.
    pub journal: bool,
    /// Only the accuracy figure, on these Table III crowds.
    pub accuracy: Option<accuracy::Crowds>,
}

pub fn run(options: &BenchOptions) -> Result<()> {
    std::fs::create_dir_all(&options.dir)
        .with_context(|| format!("cannot create {}", options.dir.display()))?;
    let runtime = tokio::runtime::Builder::new_multi_thread()
        .worker_threads(1)
        .enable_all()
        .build()?;
    if let Some(crowds) = &options.accuracy {
        let report = accuracy::run(&runtime, crowds, &options.dir)?;
        return finish(&report, options);
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
    let mut report = String::new();
    if options.ingest {
        let header = ingest::header_only(&trace, &options.dir)?;
        let deployment = runtime.block_on(Deployment::start(options, &header, 1, None, true))?;
        eprintln!("bench: one producer feeding a live sensor");
        let figures = runtime.block_on(ingest::measure(&deployment, &trace, options.queries));
        runtime.block_on(deployment.close());
        ingest::report(&figures?, options, &mut report)?;
        let mut several = Vec::new();
        for count in 1..=3 {
            let deployment = runtime.block_on(Deployment::start_sensors(
                options, &header, &trace, 3, None, true, count,
            ))?;
            eprintln!("bench: {count} live sensor(s), each fed by its own producer");
            let figures = runtime.block_on(sensors::measure(
                &deployment,
                &trace,
                count,
                options.queries.min(200),
            ));
            runtime.block_on(deployment.close());
            several.push(figures?);
        }
        sensors::report(&several, &mut report)?;
        return finish(&report, options);
    }
    writeln!(
        report,
        "Crowd of {} targets ({} red), {} s simulated; {}; {}; every process on this machine's loopback.\n",
        options.targets,
        options.red,
        options.duration,
        match options.belief {
            BeliefKind::Factored => format!(
                "the factored belief (components of at most {} tracks, local split rule{}, leaders' interests {})",
                default_max_component(),
                if options.regional { ", regional rule" } else { "" },
                if options.shrink_interest { "shrinking" } else { "growing" }
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
    // Latency with four leaders: at rest after the stream (the leaders
    // answer where they rest), and during a paced stream (every query
    // places a fresh cut).
    let leaders = 4;
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
                runtime.block_on(Deployment::start(options, &trace, count, None, false))?;
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
    if options.repeat > 1 {
        writeln!(
            report,
            "Each leader count streamed {} times, in rounds; each row is the stream with the median leaders' CPU.\n",
            options.repeat
        )?;
    }
    let paired = throughput::paired_cpu(&runs);
    let streams: Vec<throughput::Stream> = runs
        .into_iter()
        .filter_map(throughput::median_by_cpu)
        .collect();
    throughput::report(&streams, &paired, &mut report)?;
    if options.queries == 0 {
        return finish(&report, options);
    }
    let rest = match rest {
        Some(rest) => rest,
        None => {
            let deployment =
                runtime.block_on(Deployment::start(options, &trace, leaders, None, false))?;
            runtime.block_on(throughput::measure(&deployment))?;
            let rest = at_rest(&deployment)?;
            runtime.block_on(deployment.close());
            rest
        }
    };
    latency::report(&rest, "stream over", &mut report)?;
    eprintln!(
        "bench: {} marginals queries with {leaders} leaders during a stream at {} events/s",
        options.queries, options.stream_rate
    );
    let rate = Some(options.stream_rate);
    let deployment = runtime.block_on(Deployment::start(options, &trace, leaders, rate, false))?;
    runtime.block_on(throughput::first_moving_answer(&deployment))?;
    let streaming = runtime.block_on(latency::measure(&deployment, options.queries, true))?;
    runtime.block_on(deployment.close());
    latency::report(
        &streaming,
        &format!("during a stream at {} events/s", options.stream_rate),
        &mut report,
    )?;
    finish(&report, options)
}

/// Prints the report, and writes it to `--out` if given.
fn finish(report: &str, options: &BenchOptions) -> Result<()> {
    print!("{report}");
    if let Some(out) = &options.out {
        std::fs::write(out, report).with_context(|| format!("cannot write {}", out.display()))?;
    }
    Ok(())
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
        Self::start_sensors(options, trace, trace, leaders, rate, live, 1).await
    }

    /// [`Deployment::start`] with `sensors` sensors (their leaders' batches
    /// sent by each in turn), the leaders placed over `placed_by`'s field.
    async fn start_sensors(
        options: &BenchOptions,
        trace: &Path,
        placed_by: &Path,
        leaders: usize,
        rate: Option<f64>,
        live: bool,
        sensors: usize,
    ) -> Result<Self> {
        let mut topology = loopback::topology(
            &std::fs::canonicalize(trace)?,
            placed_by,
            leaders,
            sensors,
            Ports::Free,
        )?;
        topology.prefix = format!("idmesh/bench-{leaders}-{}", std::process::id());
        topology.belief = options.belief;
        topology.shrink_interest = options.shrink_interest;
        topology.regional = options.regional;
        topology.distributed_rule = true;
        topology.budget = options.budget;
        // Streaming flat out, leaders can be seconds behind the sensor.
        topology.query_timeout_ms = 60_000;
        // Beside the topology; a journal of an earlier run would be
        // resumed, so it goes first.
        topology.state_dir = options.journal.then(|| PathBuf::from("state"));
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

    async fn close(self) {
        let _ = self.session.close().await;
    }

    pub fn keys(&self) -> Keys {
        Keys::new(self.topology.prefix.clone())
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
