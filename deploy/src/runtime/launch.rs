//! `idmesh up` starts the processes of a topology that run on this host,
//! each as its own OS process, starts again one that fails (with a backoff:
//! `supervise`), and stops them all on Ctrl-C; on the coordinator's host it
//! also serves the topology's `[web]` gateway itself, as `demo` does (a
//! task, not a child: it holds no state, there is nothing to restart).
//! `idmesh demo`
//! is `up` on a built-in loopback topology: it simulates a crowd, streams it
//! through four leaders, and prints live answers.

use super::loopback::{self, Ports};
use super::mesh::{self, MeshOptions};
use super::query::ask;
use super::supervise::{Supervisor, Verdict};
use super::topology::Member;
use super::topology::{Topology, WebSection};
use anyhow::{bail, Context, Result};
use idmesh_protocol::wire::keys::{Keys, DEFAULT_PREFIX};
use idmesh_protocol::wire::query::{IdentityAnswer, MarginalsAnswer, StatsAnswer};
use std::ffi::OsString;
use std::path::{Path, PathBuf};
use std::process::{Child, Command};
use std::time::{Duration, Instant};

pub struct Processes {
    config: PathBuf,
    /// (name, role, the running process).
    children: Vec<(String, &'static str, Child)>,
}

impl Processes {
    /// Starts every process of `config` whose host is `host` (all if None).
    pub(crate) fn start(config: &Path, host: Option<&str>) -> Result<Self> {
        let processes = Self::start_some(config, |m| host.is_none_or(|h| m.host == h))?;
        if processes.children.is_empty() {
            bail!(
                "{}: no process runs on host {:?}",
                config.display(),
                host.unwrap_or("")
            );
        }
        Ok(processes)
    }

    /// Starts the processes of `config` that `keep` picks.
    pub fn start_some(config: &Path, keep: impl Fn(&Member) -> bool) -> Result<Self> {
        let topology = Topology::load(config)?;
        let exe = std::env::current_exe().context("cannot find the idmesh binary")?;
        let mut children = Vec::new();
        let members: Vec<_> = topology.members().into_iter().filter(keep).collect();
        for m in members {
            let child = spawn(&exe, config, m.role, &m.name)?;
            children.push((m.name, m.role, child));
        }
        Ok(Processes {
            config: config.to_path_buf(),
            children,
        })
    }

    /// Starts process `name` again, as it was started first.
    fn restart(&mut self, name: &str) -> Result<()> {
        let exe = std::env::current_exe().context("cannot find the idmesh binary")?;
        let Some((_, role, child)) = self.children.iter_mut().find(|(n, ..)| n == name) else {
            bail!("no process {name} to start again");
        };
        *child = spawn(&exe, &self.config, role, name)?;
        Ok(())
    }

    /// Every child's name and process id.
    pub fn pids(&self) -> impl Iterator<Item = (&str, u32)> {
        self.children
            .iter()
            .map(|(name, _, child)| (name.as_str(), child.id()))
    }

    /// The first child to exit, if any has.
    pub fn exited(&mut self) -> Option<(String, std::process::ExitStatus)> {
        self.all_exited().into_iter().next()
    }

    /// Every child that has exited since it was last started (each
    /// reported until it is started again).
    fn all_exited(&mut self) -> Vec<(String, std::process::ExitStatus)> {
        let mut out = Vec::new();
        for (name, _, child) in &mut self.children {
            if let Ok(Some(status)) = child.try_wait() {
                out.push((name.clone(), status));
            }
        }
        out
    }

    /// SIGTERM to all, then SIGKILL to whoever is still there after 5 s.
    pub(crate) fn stop(&mut self) {
        for (_, _, child) in &mut self.children {
            // SAFETY: kill(2) on a pid we spawned and have not reaped.
            unsafe {
                libc::kill(child.id() as i32, libc::SIGTERM);
            }
        }
        let deadline = Instant::now() + Duration::from_secs(5);
        for (name, _, child) in &mut self.children {
            loop {
                match child.try_wait() {
                    Ok(Some(_)) => break,
                    _ if Instant::now() > deadline => {
                        tracing::warn!(%name, "did not stop in time; killing it");
                        let _ = child.kill();
                        let _ = child.wait();
                        break;
                    }
                    _ => std::thread::sleep(Duration::from_millis(20)),
                }
            }
        }
        self.children.clear();
    }
}

/// The arguments, after the binary, that run process `name` of the
/// topology `config` as `role`: what `up` starts each child with, and
/// what a systemd unit's `ExecStart` runs (`super::systemd`), so that the
/// two start a process the same way.
pub(crate) fn role_command(role: &str, config: &Path, name: &str) -> Vec<OsString> {
    vec![
        role.into(),
        "--config".into(),
        config.into(),
        "--name".into(),
        name.into(),
    ]
}

/// `idmesh <role> --config <config> --name <name>` as a child.
fn spawn(exe: &Path, config: &Path, role: &str, name: &str) -> Result<Child> {
    let child = Command::new(exe)
        .args(role_command(role, config, name))
        .spawn()
        .with_context(|| format!("cannot start {role} {name}"))?;
    tracing::info!(role, %name, pid = child.id(), "started");
    Ok(child)
}

impl Drop for Processes {
    fn drop(&mut self) {
        self.stop();
    }
}

/// `idmesh up`: runs until Ctrl-C, starting again each process that fails
/// (its neighbours untouched), or until every process has ended of itself.
pub fn up(config: &Path, host: Option<&str>) -> Result<()> {
    let mut processes = Processes::start(config, host)?;
    let topology = Topology::load(config)?;
    let names: Vec<String> = processes.children.iter().map(|(n, ..)| n.clone()).collect();
    eprintln!(
        "up: started {} ({}){} · queries: idmesh query marginals --connect {}{} · Ctrl-C stops",
        names.join(", "),
        config.display(),
        host.map(|h| format!(" on host {h}")).unwrap_or_default(),
        topology.coordinator_endpoints(),
        if topology.prefix == DEFAULT_PREFIX {
            String::new()
        } else {
            format!(" --prefix {}", topology.prefix)
        },
    );
    let runtime = tokio::runtime::Builder::new_multi_thread()
        .worker_threads(1)
        .enable_all()
        .build()?;
    let mut supervisor = Supervisor::new(names.iter().map(String::as_str), Instant::now());
    runtime.block_on(async {
        if let Some(web) = topology.web.clone() {
            if host.is_none_or(|h| h == topology.coordinator.host) {
                // A task: it waits for the coordinator to listen, and the
                // processes are watched meanwhile.
                tokio::spawn(serve_web(topology.clone(), web));
            }
        }
        loop {
            tokio::select! {
                _ = super::roles::shutdown() => return,
                _ = tokio::time::sleep(Duration::from_millis(200)) => {}
            }
            supervise(&mut processes, &mut supervisor);
            if supervisor.all_ended() {
                eprintln!("up: every process has ended");
                return;
            }
        }
    });
    processes.stop();
    Ok(())
}

/// The topology's `[web]` gateway, a Zenoh client of its coordinators,
/// until the runtime stops. One that cannot start is said so, and the
/// deployment runs on without it (as the demo's map).
async fn serve_web(topology: Topology, web: WebSection) {
    let started = async {
        let markers = web.markers.config(WebSection::field)?;
        let session = super::web::client(&topology.coordinator_endpoints(), None).await?;
        super::web::spawn(session, &topology.prefix, &web.listen, markers).await
    };
    match started.await {
        Ok(url) => eprintln!("up: live map and HTTP API on {url}"),
        Err(e) => eprintln!("up: no web gateway: {e:#}"),
    }
}

/// One look at the children: exits judged, due restarts made.
fn supervise(processes: &mut Processes, supervisor: &mut Supervisor) {
    let now = Instant::now();
    for (name, status) in processes.all_exited() {
        match supervisor.exited(&name, status.success(), now) {
            Some(Verdict::Restart { after, failures }) => tracing::warn!(
                %name,
                %status,
                failures,
                restart_in_ms = after.as_millis() as u64,
                "a process failed; starting it again after a backoff"
            ),
            Some(Verdict::Ended) => tracing::info!(%name, "a process ended"),
            None => {}
        }
    }
    for name in supervisor.due(now) {
        if let Err(e) = processes.restart(&name) {
            // Counted as a failure: the next try waits longer.
            tracing::warn!(%name, "cannot start it again: {e:#}");
            supervisor.exited(&name, false, now);
        }
    }
}

#[derive(Debug, Clone)]
pub struct DemoOptions {
    pub events: Option<u64>,
    pub targets: usize,
    pub red: usize,
    pub seed: u64,
    /// Events per second.
    pub rate: f64,
    pub dir: PathBuf,
    /// Where the web gateway listens; None = no gateway.
    pub web: Option<String>,
    /// The gateway's ROS 2 markers; None = none.
    pub markers: Option<idmesh_web::MarkersConfig>,
}

/// `idmesh demo`: a crowd simulated here (colours and identity reads), four
/// leaders, live answers to both questions.
pub fn demo(options: &DemoOptions) -> Result<()> {
    std::fs::create_dir_all(&options.dir)
        .with_context(|| format!("cannot create {}", options.dir.display()))?;
    let trace = options.dir.join("crowd.jsonl");
    // Ten minutes of crowd, or as long as `--events` needs.
    let mut duration = 600.0;
    loop {
        simulate_crowd(
            options.targets,
            options.red,
            duration,
            options.seed,
            true,
            &trace,
        )?;
        let have = count_events(&trace)?;
        match options.events {
            Some(wanted) if have < wanted => {
                duration *= 1.2 * wanted as f64 / have.max(1) as f64;
            }
            _ => break,
        }
    }
    // Every belief setting at its default: what a deployment of one's own
    // runs (the factored belief for the colours, the factored identity
    // belief's trees for the identities, regions fitted to the crowd).
    let mut topology = loopback::topology(&trace, 4, 1, Ports::From(7447))?;
    topology.sensors[0].rate = Some(options.rate);
    topology.sensors[0].events = options.events;
    let config = options.dir.join("topology.toml");
    topology.save(&config)?;
    let coordinator = topology.coordinator.listen;
    eprintln!(
        "demo: topology {} · coordinator on {coordinator} · Ctrl-C stops",
        config.display()
    );
    let mut processes = Processes::start(&config, None)?;
    let runtime = tokio::runtime::Builder::new_multi_thread()
        .worker_threads(1)
        .enable_all()
        .build()?;
    let web = options
        .web
        .as_deref()
        .map(|at| (at, options.markers.clone()));
    let result = runtime.block_on(watch(&mut processes, &coordinator, web));
    processes.stop();
    result
}

/// Prints a live answer every second until Ctrl-C; `web`: where the
/// gateway listens, and its markers.
async fn watch(
    processes: &mut Processes,
    coordinator: &str,
    web: Option<(&str, Option<idmesh_web::MarkersConfig>)>,
) -> Result<()> {
    let session = mesh::open(&MeshOptions {
        client: false,
        listen: vec![],
        connect: vec![coordinator.to_string()],
        ..MeshOptions::default()
    })
    .await?;
    let keys = Keys::new(DEFAULT_PREFIX);
    // The live map: a busy port costs the demo its map, not its answers.
    if let Some((address, markers)) = web {
        match super::web::spawn(session.clone(), DEFAULT_PREFIX, address, markers).await {
            Ok(url) => eprintln!("demo: live map and HTTP API on {url}"),
            Err(e) => eprintln!("demo: no live map: {e:#}"),
        }
    }
    let ctrl_c = super::roles::shutdown();
    tokio::pin!(ctrl_c);
    loop {
        tokio::select! {
            _ = &mut ctrl_c => break,
            _ = tokio::time::sleep(Duration::from_secs(1)) => {}
        }
        if let Some((name, status)) = processes.exited() {
            bail!("{name} exited with {status}");
        }
        let started = Instant::now();
        match ask(&session, &keys.query_marginals(), Duration::from_secs(3)).await {
            Ok(body) => {
                let a: MarginalsAnswer = serde_json::from_slice(&body)?;
                let events: u64 = a.watermark.values().sum();
                let sure: Vec<String> = a
                    .predicted_red
                    .iter()
                    .map(|&t| format!("{t}:{:.2}", a.p_red[t as usize]))
                    .collect();
                let took = started.elapsed().as_secs_f64() * 1e3;
                println!(
                    "{events:>7} events{} · {} · {took:>5.1} ms · red: {}",
                    if a.finished { " (all)" } else { "" },
                    sets_per_leader(&session, &keys, a.coefficients).await,
                    sure.join(" ")
                );
            }
            Err(e) => println!("query: {e}"),
        }
        match ask(&session, &keys.query_identity(), Duration::from_secs(3)).await {
            Ok(body) => {
                let a: IdentityAnswer = serde_json::from_slice(&body)?;
                let sure = a
                    .p_identity
                    .iter()
                    .zip(&a.predicted_identity)
                    .filter(|(row, &i)| row.probability(i) >= 0.9)
                    .count();
                let first: Vec<String> = a
                    .predicted_identity
                    .iter()
                    .take(8)
                    .enumerate()
                    .map(|(t, i)| format!("{t}→{i}"))
                    .collect();
                println!(
                    "{:>14} identities ({}): {sure} of {} tracks sure (P ≥ 0.9) · {} …",
                    "",
                    a.marginals,
                    a.tracks,
                    first.join(" ")
                );
            }
            Err(e) => println!("identity query: {e}"),
        }
    }
    let _ = session.close().await;
    Ok(())
}

/// "N held: leader-0 n0 · leader-1 n1 · …", the coefficients (Radon sets,
/// or the entries of factored components' tables) each leader holds, from
/// the leaders' counters: the total alone would hide a leader that holds
/// none.
async fn sets_per_leader(session: &zenoh::Session, keys: &Keys, total: u64) -> String {
    let held = match ask(session, &keys.query_stats(), Duration::from_secs(3)).await {
        Ok(body) => match serde_json::from_slice::<StatsAnswer>(&body) {
            Ok(stats) => stats
                .leaders
                .iter()
                .map(|l| format!("{} {}", l.leader, l.coefficients))
                .collect::<Vec<_>>()
                .join(" · "),
            Err(e) => format!("counters unreadable: {e}"),
        },
        Err(e) => format!("no counters: {e}"),
    };
    format!("{total} held: {held}")
}

/// Simulates a social-force crowd into `out` (the demo's and the bench's
/// stream), with identity reads when `identities`.
pub fn simulate_crowd(
    targets: usize,
    red: usize,
    duration: f64,
    seed: u64,
    identities: bool,
    out: &Path,
) -> Result<()> {
    let crowd = idmesh_sim::Scenario::crowd().identities(identities);
    simulate_into(crowd, targets, red, duration, seed, out)
}

/// Simulates `scenario` with n = `targets`, k = `red`, `duration` seconds
/// and `seed` into the trace file `out`.
pub fn simulate_into(
    scenario: idmesh_sim::Scenario,
    targets: usize,
    red: usize,
    duration: f64,
    seed: u64,
    out: &Path,
) -> Result<()> {
    write_simulation(
        scenario
            .targets(targets)
            .red(red)
            .duration(duration)
            .seed(seed),
        out,
    )
}

/// Generates `scenario` as it is set and writes its trace to `out`.
pub fn write_simulation(scenario: idmesh_sim::Scenario, out: &Path) -> Result<()> {
    let trace = scenario.generate().context("the simulation failed")?;
    let path = out.display().to_string();
    let file = std::fs::File::create(out).with_context(|| format!("{path}: cannot create"))?;
    idmesh_sim::write_trace(&trace, std::io::BufWriter::new(file), path)?;
    Ok(())
}

/// The events of a trace (every line but the header and truth lines): what
/// a watermark counts.
pub(crate) fn count_events(trace: &Path) -> Result<u64> {
    let mut reader = idmesh_protocol::trace::TraceReader::open(trace)?;
    reader.read_header()?;
    let mut events = 0;
    while let Some(n) = reader.read_line()? {
        if n.line.is_event() {
            events += 1;
        }
    }
    Ok(events)
}

/// The bounding box of the trace's positions: (min x, min y, max x, max y).
pub fn field_corners(trace: &Path) -> Result<(f64, f64, f64, f64)> {
    let mut reader = idmesh_protocol::trace::TraceReader::open(trace)?;
    reader.read_header()?;
    let mut b = (
        f64::INFINITY,
        f64::INFINITY,
        f64::NEG_INFINITY,
        f64::NEG_INFINITY,
    );
    while let Some(n) = reader.read_line()? {
        if let idmesh_protocol::trace::Line::Move(m) = n.line {
            b = (b.0.min(m.x), b.1.min(m.y), b.2.max(m.x), b.3.max(m.y));
        }
    }
    if !b.0.is_finite() {
        return Ok((0.0, 0.0, 1.0, 1.0));
    }
    Ok(b)
}
