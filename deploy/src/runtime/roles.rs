//! `idmesh sensor|leader|coordinator --config T --name N`: one process of a
//! deployment. Each opens its Zenoh session from the topology (listen on
//! its endpoint, connect to everyone else's; with `[security]`, over mutual
//! TLS under the access rules generated for it), logs under a span named
//! after it, and stops cleanly on Ctrl-C or SIGTERM.

use super::mesh::{self, MeshOptions};
use super::routing_loss;
use super::security::rules;
use super::topology::{SensorProcess, Sparsification, Topology};
use anyhow::{anyhow, Context, Result};
use idmesh_claims::Claims;
use idmesh_consensus::VoterConfig;
use idmesh_coordinator::CoordinatorConfig;
use idmesh_extract::read_reports;
use idmesh_leader::HostConfig;
use idmesh_protocol::trace::{Header, Line, Problem, TraceReader};
use idmesh_protocol::wire::keys::Keys;
use idmesh_sensor::journal::{Journal, Record};
use idmesh_sensor::{
    lines_of, stand_by, standby_path, Extraction, Faults, GatewayConfig, InputLine, LeaderPlace,
    LeaseClock, MeshConfig, Owned, Router, RouterConfig, Source, StandbyConfig, Standing, TookOver,
};
use idmesh_voter::VoterProcess;
use std::fs::File;
use std::io::BufReader;
use std::path::Path;
use std::time::Duration;
use tracing::Instrument;

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Role {
    /// With `stdin`: the trace comes from standard input. `max_errors`:
    /// `--max-errors`, which overrides the topology's.
    Sensor {
        stdin: bool,
        max_errors: Option<usize>,
    },
    Leader,
    Coordinator,
    Voter,
    /// A sensor's standby (`[[sensor_standby]]`).
    SensorStandby,
}

impl Role {
    /// The kind of topology member that runs this role.
    fn member(self) -> &'static str {
        match self {
            Role::Sensor { .. } => "sensor",
            Role::Leader => "leader",
            Role::Coordinator => "coordinator",
            Role::Voter => "voter",
            Role::SensorStandby => "sensor-standby",
        }
    }
}

/// The runtime's worker threads for a role. A leader's work is one task
/// that owns its node (and, after a takeover, one per role it adopted),
/// woken by every batch and transfer: a second worker has nothing to run
/// but is woken to look for work to steal all the same. With one, the
/// leaders' CPU on the 10,000-target crowd fell by about a tenth, at one
/// leader and at four alike (`idmesh bench`, docs/bench.md). Zenoh's own
/// threads are apart from these.
/// The sensor and the coordinator answer queries while they stream and
/// couple, and keep two.
fn workers(role: Role) -> usize {
    match role {
        Role::Leader | Role::Voter => 1,
        Role::Sensor { .. } | Role::Coordinator | Role::SensorStandby => 2,
    }
}

pub fn run(role: Role, config: &Path, name: &str) -> Result<()> {
    without_huge_pages();
    let topology = Topology::load(config)?;
    let member = topology.member(name)?;
    let expected = role.member();
    if member.role != expected {
        return Err(anyhow!(
            "{name:?} is a {} in the topology, not a {expected}",
            member.role
        ));
    }
    let options = peer_options(&topology, name)?;
    // The sensor's journal is its before it joins the mesh: a second
    // sensor process on it (the same topology started twice, a shared
    // state directory) is refused here, naming who holds it, before it
    // could take a port, a key or a record.
    let journal = match (&role, topology.state_path()) {
        (Role::Sensor { .. }, Some(dir)) => {
            let path = dir.join(format!("{name}.journal"));
            let (journal, records) = Journal::open(&path, name)?;
            let journal = match topology.sensor_named(name)?.compact_journal_after {
                Some(bytes) => journal.compact_after(bytes),
                None => journal,
            };
            Some((journal, records))
        }
        _ => None,
    };
    let runtime = tokio::runtime::Builder::new_multi_thread()
        .worker_threads(workers(role))
        .enable_all()
        .build()?;
    let span = tracing::info_span!("process", name = %name);
    runtime.block_on(
        async move {
            let session = mesh::open(&options).await?;
            let keys = Keys::new(topology.prefix.clone());
            mesh::answer_pings(&session, keys.ping(expected, name), name.to_string()).await?;
            let result = match role {
                Role::Sensor { stdin, max_errors } => {
                    let input = Input { stdin, max_errors };
                    own_sensor(session.clone(), &topology, name, keys, input, journal).await
                }
                Role::SensorStandby => sensor_standby(session.clone(), &topology, name, keys).await,
                Role::Leader => {
                    let index = topology
                        .leader
                        .iter()
                        .position(|l| l.name == name)
                        .unwrap_or_default();
                    let sensor = topology.sensor_of_leader(index);
                    idmesh_leader::run(
                        session.clone(),
                        HostConfig {
                            name: name.to_string(),
                            keys,
                            leaders: topology.leader.iter().map(|l| l.name.clone()).collect(),
                            sensor: sensor.name.clone(),
                            follow_timeout: Duration::from_millis(topology.query_timeout_ms),
                            state_dir: topology.state_path(),
                            fsync_every: Duration::from_millis(topology.fsync_ms),
                            snapshot_every: (topology.snapshot_every > 0)
                                .then_some(topology.snapshot_every),
                            takeover_after: (topology.takeover_after_ms > 0)
                                .then(|| Duration::from_millis(topology.takeover_after_ms)),
                            drop_transfer_every: topology.leader_faults.drop_transfer_every,
                            drop_push_every: topology.leader_faults.drop_push_every,
                            flow_control: sensor.window.is_some(),
                            lease: (!topology.voters.is_empty()).then_some(VOTERS_LEASE),
                            standbys: topology.standbys,
                        },
                        shutdown(),
                    )
                    .await
                    .map_err(anyhow::Error::from)
                }
                Role::Coordinator => idmesh_coordinator::run(
                    session.clone(),
                    CoordinatorConfig {
                        name: name.to_string(),
                        keys,
                        timeout: Duration::from_millis(topology.query_timeout_ms),
                        marginals_timeout: Duration::from_millis(topology.marginals_timeout_ms),
                    },
                    shutdown(),
                )
                .await
                .map_err(|e| anyhow!("coordinator: {e}")),
                Role::Voter => {
                    let process = voter_process(&topology, name, keys)?;
                    idmesh_voter::run(session.clone(), process, shutdown())
                        .await
                        .map_err(|e| anyhow!("voter: {e}"))
                }
            };
            let _ = session.close().await;
            result.and(routing_loss::check())
        }
        .instrument(span),
    )
}

/// With voters: how long a leader process runs its roles without a map
/// read from a leading voter. Longer than an election (one to two
/// seconds), so that a new election does not stop the roles.
const VOTERS_LEASE: Duration = Duration::from_secs(5);

/// Voter `name`'s place in the group: its id is its place among the
/// topology's `[[voter]]`s, from 1; its log is `<state_dir>/<name>.raft`.
/// Elections take 10 ticks of 100 ms (one to two seconds, drawn), a
/// leader's heartbeat every 2.
fn voter_process(topology: &Topology, name: &str, keys: Keys) -> Result<VoterProcess> {
    let index = topology
        .voters
        .iter()
        .position(|v| v.name == name)
        .ok_or_else(|| anyhow!("no voter named {name:?} in the topology"))?;
    let dir = topology
        .state_path()
        .ok_or_else(|| anyhow!("[[voter]]: give state_dir, where each voter keeps its log"))?;
    std::fs::create_dir_all(&dir)
        .map_err(|e| anyhow!("{}: cannot create the state directory: {e}", dir.display()))?;
    Ok(VoterProcess {
        voter: VoterConfig {
            id: index as u64 + 1,
            voters: (1..=topology.voters.len() as u64).collect(),
            election_ticks: 10,
            heartbeat_ticks: 2,
            fixed_timeouts: false,
        },
        keys,
        log: dir.join(format!("{name}.raft")),
        tick: Duration::from_millis(100),
    })
}

/// Turns transparent huge pages off for this process. The allocator asks
/// for them, and the kernel then zeroes 2 MiB at the first touch of each,
/// however little of it a process uses: a leader's or a coordinator's
/// memory is small and spread over many threads' heaps, and with four
/// leaders on one host the zeroing was a tenth of their CPU. Measured in
/// `idmesh bench` (10,000 targets, 100 s; 5 runs each, interleaved, means):
/// four leaders together 0.82 → 0.73 CPU s, one leader alone 0.50 → 0.49.
/// Like Redis and most databases, a deployment's processes run without
/// them. Best effort: a kernel without the setting leaves them on.
fn without_huge_pages() {
    // SAFETY: PR_SET_THP_DISABLE takes plain integers and touches only
    // this process's memory settings.
    let refused = unsafe { libc::prctl(libc::PR_SET_THP_DISABLE, 1, 0, 0, 0) } != 0;
    if refused {
        tracing::debug!("transparent huge pages left on: the kernel refused to turn them off");
    }
}

/// How process `name` joins the mesh: it listens on its endpoint and
/// connects to everyone else's; in a secured topology over mutual TLS with
/// its own certificate, under the access rules generated for it.
fn peer_options(topology: &Topology, name: &str) -> Result<MeshOptions> {
    let member = topology.member(name)?;
    let (tls, access_control) = match &topology.security {
        Some(security) => {
            let tls = security.tls_for(&topology.dir, name)?;
            let rules = security
                .access_control
                .then(|| rules::access_control(topology, name));
            tracing::info!(%name, access_control = rules.is_some(), "mutual TLS");
            (Some(tls), rules)
        }
        None => (None, None),
    };
    Ok(MeshOptions {
        client: false,
        listen: vec![member.listen],
        connect: topology
            .members()
            .into_iter()
            .filter(|m| m.name != name)
            .map(|m| m.listen)
            .collect(),
        tls,
        access_control,
        unbatched: member.role == "coordinator",
        // Peers keep trying their peers for as long as they run.
        connect_patience: None,
    })
}

/// What the sensor reads besides its ingest key: standard input or its
/// trace, and how many bad lines it goes past.
struct Input {
    stdin: bool,
    max_errors: Option<usize>,
}

/// How a sensor runs: its input, its journal, the standbys its journal
/// is replicated to (one at a time), and with voters the lease it holds the role under
/// (its epoch; without voters 0).
struct SensorRun {
    input: Input,
    journal: Option<(Journal, Vec<Record>)>,
    standbys: Vec<String>,
    lease: Option<Lease>,
}

/// The sensor role held through the voters: what keeps its lease, and
/// the clock the sensor's I/O reads it on.
struct Lease {
    claims: Claims,
    role: String,
    me: String,
    /// The epoch the role is held at (moved on when the sensor goes on
    /// without its standby).
    clock: LeaseClock,
}

/// Sensor `name` in its own process. With a standby its journal is
/// replicated to it, and with voters too the sensor serves once it holds
/// its role, until its lease is lost. A role its standby took over is
/// not taken back: this process stands by for the holder instead, and
/// serves again only if that one goes.
async fn own_sensor(
    session: zenoh::Session,
    topology: &Topology,
    name: &str,
    keys: Keys,
    input: Input,
    journal: Option<(Journal, Vec<Record>)>,
) -> Result<()> {
    let standbys = topology.replicas_of(name, name);
    // Without a standby nothing could take the role over: the sensor
    // neither claims it nor keeps a lease (a cut-off sensor that stopped
    // would stop the stream for good).
    let lease = match (standbys.is_empty(), topology.voters.is_empty()) {
        (false, false) => {
            let mut claims = Claims::new(session.clone(), keys.clone(), name, VOTERS_LEASE);
            match idmesh_sensor::claim_own(&mut claims, name, name).await {
                Owned::Here(epoch) => {
                    tracing::info!(sensor = %name, epoch, "the voters give this process its sensor role");
                    if let Some((journal, _)) = &journal {
                        idmesh_sensor::serving_from(journal.path(), epoch)?;
                    }
                    Some(Lease::new(claims, name, name, epoch))
                }
                Owned::Elsewhere => {
                    // Its journal is the copy it keeps from now on.
                    drop(journal);
                    return sensor_standby_for(session, topology, name, name, keys).await;
                }
            }
        }
        _ => None,
    };
    let run = SensorRun {
        input,
        journal,
        standbys,
        lease,
    };
    sensor(session, topology, name, keys, run).await
}

impl Lease {
    fn new(claims: Claims, role: &str, me: &str, epoch: u64) -> Self {
        Lease {
            claims,
            role: role.to_string(),
            me: me.to_string(),
            clock: LeaseClock::new(epoch),
        }
    }
}

/// Set when a sensor stopped because its role's lease was lost.
#[derive(Clone, Default)]
struct LeaseLost(std::sync::Arc<std::sync::atomic::AtomicBool>);

impl LeaseLost {
    /// A sensor that stopped for its lease ends its process with an
    /// error, not as one told to stop: `idmesh up` then starts it again,
    /// and it claims the role anew once a voter leads (the same holder
    /// keeps its epoch and its journal), or waits while another holds
    /// it. Ended cleanly, it would stay down, and a second loss of the
    /// voters' majority would stop the stream for good.
    fn check(&self, role: &str) -> Result<()> {
        match self.0.load(std::sync::atomic::Ordering::Relaxed) {
            true => Err(anyhow!(
                "sensor {role}: stopped serving, its lease on the role lost (no leading voter, \
                 or the role given to another); to be started again, to claim it anew"
            )),
            false => Ok(()),
        }
    }
}

/// Until Ctrl-C or SIGTERM, or until the sensor role's lease is lost
/// (then `lost` says so). The lease is kept by a task of its own, started
/// here and now: the sensor's I/O waits on its clock
/// (`idmesh_sensor::LeaseClock`) before it first polls this future, and
/// whenever it is not polling it.
fn lease_or_shutdown(
    lease: Option<Lease>,
    lost: LeaseLost,
) -> impl std::future::Future<Output = ()> {
    let kept =
        lease.map(|l| tokio::spawn(idmesh_sensor::keep_lease(l.claims, l.role, l.me, l.clock)));
    async move {
        match kept {
            Some(mut kept) => {
                tokio::select! {
                    _ = shutdown() => kept.abort(),
                    _ = &mut kept => {
                        lost.0.store(true, std::sync::atomic::Ordering::Relaxed);
                    }
                }
            }
            None => shutdown().await,
        }
    }
}

/// A sensor's standby: keeps its copy of the sensor's journal and, once
/// the voters give it the sensor role, serves as the sensor from it.
async fn sensor_standby(
    session: zenoh::Session,
    topology: &Topology,
    name: &str,
    keys: Keys,
) -> Result<()> {
    let this = topology
        .sensor_standbys
        .iter()
        .find(|s| s.name == name)
        .ok_or_else(|| anyhow!("no sensor standby named {name:?} in the topology"))?;
    sensor_standby_for(session, topology, name, &this.sensor, keys).await
}

/// Process `me` standing by for sensor role `role`: one of the role's
/// `[[sensor_standby]]`, or the role's own process once a standby took
/// the role over (its own journal, of that earlier holding, becomes the
/// copy). Whichever serves replicates its journal to one of the others,
/// so the role keeps a standby through every takeover.
async fn sensor_standby_for(
    session: zenoh::Session,
    topology: &Topology,
    me: &str,
    role: &str,
    keys: Keys,
) -> Result<()> {
    let dir = topology.state_path().ok_or_else(|| {
        anyhow!("[[sensor_standby]]: give state_dir, where it keeps its copy of the journal")
    })?;
    std::fs::create_dir_all(&dir)
        .map_err(|e| anyhow!("{}: cannot create the state directory: {e}", dir.display()))?;
    let home = me == role;
    let config = StandbyConfig {
        name: me.to_string(),
        sensor: role.to_string(),
        keys: keys.clone(),
        journal: match home {
            true => dir.join(format!("{role}.journal")),
            false => standby_path(&dir, role),
        },
        takeover_after: Duration::from_millis(topology.takeover_after_ms),
        lease: (!topology.voters.is_empty() && topology.takeover_after_ms > 0)
            .then_some(VOTERS_LEASE),
        earlier_holding: home,
    };
    let Standing::TookOver(took) = stand_by(&session, &config, shutdown()).await? else {
        return Ok(());
    };
    let TookOver {
        epoch,
        journal,
        records,
        claims,
    } = *took;
    let journal = match topology.sensor_named(role)?.compact_journal_after {
        Some(bytes) => journal.compact_after(bytes),
        None => journal,
    };
    let run = SensorRun {
        input: Input {
            stdin: false,
            max_errors: None,
        },
        journal: Some((journal, records)),
        // The others stand by now, the role's own process first.
        standbys: topology.replicas_of(role, me),
        lease: Some(Lease::new(claims, role, me, epoch)),
    };
    sensor(session, topology, role, keys, run).await
}

/// Serves sensor role `name` until shut down or, with voters, until its
/// lease is lost (an error then, see [`LeaseLost`]).
async fn sensor(
    session: zenoh::Session,
    topology: &Topology,
    name: &str,
    keys: Keys,
    run: SensorRun,
) -> Result<()> {
    let SensorRun {
        input,
        journal,
        standbys,
        lease,
    } = run;
    let epoch = lease.as_ref().map_or(0, |l| l.clock.epoch());
    let clock = lease.as_ref().map(|l| l.clock.clone());
    let lost = LeaseLost::default();
    let stop = lease_or_shutdown(lease, lost.clone());
    let this = topology.sensor_named(name)?;
    let max_errors = input.max_errors.unwrap_or(this.max_errors);
    let (header, source) = sensor_source(topology, this, input.stdin, max_errors)?;
    let extraction = this
        .extract
        .clone()
        .map(|config| Extraction::new(config, &header))
        .transpose()
        .map_err(|problem| anyhow!("sensor {name}: {problem}"))?;
    let router = Router::new(
        RouterConfig {
            factored_identity: topology.factored_identity(),
            sensor: this.name.clone(),
            leaders: topology
                .leader
                .iter()
                .map(|l| LeaderPlace {
                    name: l.name.clone(),
                    at: l.at.map(|[x, y]| (x, y)),
                })
                .collect(),
            distributed_rule: topology.distributed_rule,
            budget: topology.budget,
            omp: topology.sparsify == Sparsification::Overcomplete,
            factored: topology.factored(),
            // With extraction the stream's moves are the extractor's,
            // known only as they come.
            placed: match &extraction {
                Some(_) => idmesh_placement::leading_places(header.tracks, std::iter::empty()),
                None => idmesh_placement::leading_places(header.tracks, &source.lines),
            },
            regions: None,
        },
        &header,
    )?;
    let mesh = (topology.sensors.len() > 1).then(|| MeshConfig {
        sensors: topology.sensors.iter().map(|s| s.name.clone()).collect(),
        me: topology
            .sensors
            .iter()
            .position(|s| s.name == name)
            .unwrap_or_default(),
        serves: (0..topology.leader.len())
            .map(|i| topology.sensor_of_leader(i).name == name)
            .collect(),
    });
    let config = GatewayConfig {
        name: this.name.clone(),
        keys,
        rate: this.rate,
        realtime: this.realtime,
        limit: this.events,
        wait_for_leaders: Duration::from_secs(60),
        live: this.live,
        window: this.window,
        faults: Faults {
            duplicate: this.faults.duplicate,
            drop_every: this.faults.drop_every,
        },
        mesh,
        extraction,
        max_errors,
        ros2: this.ros2.clone(),
        standbys,
        epoch,
        lease: clock,
    };
    idmesh_sensor::run(session, config, router, source, journal, stop).await?;
    lost.check(name)
}

/// The sensor's trace: its header and lines, from standard input as they
/// come, or from the trace file (reports to extract, or extracted lines).
fn sensor_source(
    topology: &Topology,
    this: &SensorProcess,
    input_is_stdin: bool,
    max_errors: usize,
) -> Result<(Header, Source)> {
    if input_is_stdin {
        let (header, input) = stdin_trace()?;
        Ok((
            header,
            Source {
                lines: Vec::new(),
                input: Some(input),
            },
        ))
    } else if let Some(config) = &this.extract {
        // Reports: read as `idmesh replay --topology` and `idmesh extract`
        // read them.
        let path = topology.trace_path();
        let file =
            File::open(&path).with_context(|| format!("cannot open trace {}", path.display()))?;
        let reports = read_reports(
            BufReader::new(file),
            &path.display().to_string(),
            config,
            max_errors,
        )?;
        for reason in &reports.skipped {
            tracing::warn!(%reason, "trace line skipped");
        }
        Ok((
            reports.header,
            Source {
                lines: reports.lines.into_iter().map(|(_, line)| line).collect(),
                input: None,
            },
        ))
    } else {
        let path = topology.trace_path();
        let mut reader = TraceReader::open(&path)
            .with_context(|| format!("cannot open trace {}", path.display()))?;
        let header = reader.read_header()?;
        let mut lines = Vec::new();
        while let Some(numbered) = reader.read_line()? {
            numbered.line.require_extracted().map_err(|problem| {
                anyhow::anyhow!("{}:{}: {problem}", path.display(), numbered.number)
            })?;
            lines.push(numbered.line);
        }
        Ok((header, Source { lines, input: None }))
    }
}

/// The header on standard input's first line (a stream cannot start
/// without its field), and the rest of the input, read as it comes.
fn stdin_trace() -> Result<(Header, tokio::sync::mpsc::Receiver<InputLine>)> {
    let mut input = std::io::BufReader::new(std::io::stdin());
    let mut first = String::new();
    std::io::BufRead::read_line(&mut input, &mut first).context("stdin: cannot read")?;
    let text = first.trim_end_matches(['\n', '\r']);
    let header = match Line::parse(text) {
        _ if first.is_empty() => {
            return Err(anyhow!("stdin:1: {}", Problem::Empty));
        }
        Ok(Line::Header(header)) => header,
        Ok(other) => {
            return Err(anyhow!(
                "stdin:1: {}",
                Problem::HeaderNotFirst { kind: other.kind() }
            ))
        }
        Err(problem) => return Err(anyhow!("stdin:1: {problem}")),
    };
    header
        .validate()
        .map_err(|problem| anyhow!("stdin:1: {problem}"))?;
    Ok((header, lines_of(input, 2)))
}

/// Ctrl-C or SIGTERM.
pub(crate) async fn shutdown() {
    let mut term = match tokio::signal::unix::signal(tokio::signal::unix::SignalKind::terminate()) {
        Ok(term) => term,
        Err(_) => {
            let _ = tokio::signal::ctrl_c().await;
            return;
        }
    };
    tokio::select! {
        _ = tokio::signal::ctrl_c() => {}
        _ = term.recv() => {}
        // The session drops what its peers send: stopped, to be started
        // again with a new one.
        _ = routing_loss::lost() => {}
    }
}
