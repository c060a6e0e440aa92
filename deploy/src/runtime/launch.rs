//! `idmesh up` starts the processes of a topology that run on this host,
//! each as its own OS process, and stops them all on Ctrl-C. `idmesh demo`
//! is `up` on a built-in loopback topology: it simulates a crowd, streams it
//! through four leaders, and prints live answers.

use super::loopback::{self, Ports};
use super::mesh::{self, MeshOptions};
use super::query::ask;
use super::topology::Topology;
use super::topology::{BeliefKind, Member, Sparsification};
use anyhow::{bail, Context, Result};
use idmesh_protocol::wire::keys::{Keys, DEFAULT_PREFIX};
use idmesh_protocol::wire::query::{IdentityAnswer, MarginalsAnswer, StatsAnswer};
use std::path::{Path, PathBuf};
use std::process::{Child, Command};
use std::time::{Duration, Instant};

pub struct Processes {
    children: Vec<(String, Child)>,
}

impl Processes {
    /// Starts every process of `config` whose host is `host` (all if None).
    pub fn start(config: &Path, host: Option<&str>) -> Result<Self> {
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
            let child = Command::new(&exe)
                .arg(m.role)
                .arg("--config")
                .arg(config)
                .arg("--name")
                .arg(&m.name)
                .spawn()
                .with_context(|| format!("cannot start {} {}", m.role, m.name))?;
            tracing::info!(role = m.role, name = %m.name, pid = child.id(), "started");
            children.push((m.name, child));
        }
        Ok(Processes { children })
    }

    /// Every child's name and process id.
    pub fn pids(&self) -> impl Iterator<Item = (&str, u32)> {
        self.children
            .iter()
            .map(|(name, child)| (name.as_str(), child.id()))
    }

    /// The first child to exit, if any has.
    pub fn exited(&mut self) -> Option<(String, std::process::ExitStatus)> {
        for (name, child) in &mut self.children {
            if let Ok(Some(status)) = child.try_wait() {
                return Some((name.clone(), status));
            }
        }
        None
    }

    /// SIGTERM to all, then SIGKILL to whoever is still there after 5 s.
    pub fn stop(&mut self) {
        for (_, child) in &mut self.children {
            // SAFETY: kill(2) on a pid we spawned and have not reaped.
            unsafe {
                libc::kill(child.id() as i32, libc::SIGTERM);
            }
        }
        let deadline = Instant::now() + Duration::from_secs(5);
        for (name, child) in &mut self.children {
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

impl Drop for Processes {
    fn drop(&mut self) {
        self.stop();
    }
}

/// `idmesh up`: runs until Ctrl-C or until a process fails.
pub fn up(config: &Path, host: Option<&str>) -> Result<()> {
    let mut processes = Processes::start(config, host)?;
    let topology = Topology::load(config)?;
    let names: Vec<&str> = processes.children.iter().map(|(n, _)| n.as_str()).collect();
    eprintln!(
        "up: started {} ({}){} · queries: idmesh query marginals --connect {}{} · Ctrl-C stops",
        names.join(", "),
        config.display(),
        host.map(|h| format!(" on host {h}")).unwrap_or_default(),
        topology.coordinator.listen,
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
    let failed = runtime.block_on(async {
        loop {
            tokio::select! {
                _ = super::roles::shutdown() => return None,
                _ = tokio::time::sleep(Duration::from_millis(200)) => {
                    if let Some(exit) = processes.exited() {
                        return Some(exit);
                    }
                }
            }
        }
    });
    processes.stop();
    match failed {
        Some((name, status)) if !status.success() => bail!("{name} exited with {status}"),
        _ => Ok(()),
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
    let mut topology = loopback::topology(&trace, &trace, 4, 1, Ports::From(7447))?;
    // The demo shows the Radon belief's sets per leader (the README says
    // so), pruned by OMP to a budget, beside the identities' rows; a
    // topology that names no belief runs the factored one on the same
    // stream ([`BeliefKind`]).
    topology.belief = BeliefKind::Radon;
    topology.distributed_rule = true;
    topology.budget = 400;
    topology.sparsify = Sparsification::Overcomplete;
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
    let result = runtime.block_on(watch(&mut processes, &coordinator, options.web.as_deref()));
    processes.stop();
    result
}

/// Prints a live answer every second until Ctrl-C.
async fn watch(processes: &mut Processes, coordinator: &str, web: Option<&str>) -> Result<()> {
    let session = mesh::open(&MeshOptions {
        client: false,
        listen: vec![],
        connect: vec![coordinator.to_string()],
        ..MeshOptions::default()
    })
    .await?;
    let keys = Keys::new(DEFAULT_PREFIX);
    // The live map: a busy port costs the demo its map, not its answers.
    if let Some(address) = web {
        match super::web::spawn(session.clone(), DEFAULT_PREFIX, address).await {
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
                    .filter(|(row, &i)| row.get(i as usize).is_some_and(|&p| p >= 0.9))
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

/// "N sets: leader-0 n0 · leader-1 n1 · …" from the leaders' counters: the
/// total alone would hide that one leader may hold every set (a set lives
/// at one leader surveilling one of its tracks, and sets that grow to span
/// the field all qualify for the first).
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
    format!("{total} sets: {held}")
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
    let trace = idmesh_sim::Scenario::crowd()
        .targets(targets)
        .red(red)
        .duration(duration)
        .seed(seed)
        .identities(identities)
        .generate()
        .context("the crowd simulation failed")?;
    let path = out.display().to_string();
    let file = std::fs::File::create(out).with_context(|| format!("{path}: cannot create"))?;
    idmesh_sim::scenario::trace_out::write_trace(&trace, std::io::BufWriter::new(file), path)?;
    Ok(())
}

/// The events of a trace (every line but the header and truth lines): what
/// a watermark counts.
pub fn count_events(trace: &Path) -> Result<u64> {
    let mut reader = idmesh_protocol::TraceReader::open(trace)?;
    reader.read_header()?;
    let mut events = 0;
    while let Some(n) = reader.read_line()? {
        if n.line.is_event() {
            events += 1;
        }
    }
    Ok(events)
}

/// Where a loopback deployment of `leaders` leaders over `trace` places
/// them: the centres of a grid over the field its moves span, moved by
/// Lloyd's iterations (k-means) towards the centres of the positions
/// nearest to each, so that each leader's region (the positions nearest to
/// it) holds about as many of the crowd's positions as the others; then
/// moved on until each is sent about as many items
/// ([`idmesh_placement::balanced`]): a crowd meets more often where it is
/// denser, so even shares of its positions load the leaders in the middle
/// of it most. Deterministic: the same trace, the same places.
pub fn leader_places(trace: &Path, leaders: usize) -> Result<Vec<(f64, f64)>> {
    const ROUNDS: usize = 30;
    let mut places = idmesh_placement::grid_places(field_corners(trace)?, leaders);
    let mut positions = Vec::new();
    let mut reader = idmesh_protocol::TraceReader::open(trace)?;
    let header = reader.read_header()?;
    let mut workload = idmesh_placement::Workload::new(header.tracks);
    while let Some(n) = reader.read_line()? {
        if let idmesh_protocol::Line::Move(m) = &n.line {
            positions.push((m.x, m.y));
        }
        workload.push(&n.line);
    }
    if positions.is_empty() || leaders < 2 {
        return Ok(places);
    }
    for _ in 0..ROUNDS {
        let regions = regions_of(&places);
        let mut sums = vec![(0.0, 0.0, 0usize); leaders];
        for &(x, y) in &positions {
            let nearest = regions.nearest(x, y).map_or(0, usize::from);
            let s = &mut sums[nearest];
            *s = (s.0 + x, s.1 + y, s.2 + 1);
        }
        // A leader nearest to no position keeps its place.
        for (place, &(sx, sy, count)) in places.iter_mut().zip(&sums) {
            if count > 0 {
                *place = (sx / count as f64, sy / count as f64);
            }
        }
    }
    Ok(idmesh_placement::balanced(places, &workload))
}

/// The regions of leaders at `places` (the sensor's rule: a position
/// belongs to the nearest place, the first of equals).
fn regions_of(places: &[(f64, f64)]) -> idmesh_placement::Regions {
    let places: Vec<_> = places.iter().map(|&p| Some(p)).collect();
    idmesh_placement::Regions::new(&places, 0)
}

/// The bounding box of the trace's positions: (min x, min y, max x, max y).
pub fn field_corners(trace: &Path) -> Result<(f64, f64, f64, f64)> {
    let mut reader = idmesh_protocol::TraceReader::open(trace)?;
    reader.read_header()?;
    let mut b = (
        f64::INFINITY,
        f64::INFINITY,
        f64::NEG_INFINITY,
        f64::NEG_INFINITY,
    );
    while let Some(n) = reader.read_line()? {
        if let idmesh_protocol::Line::Move(m) = n.line {
            b = (b.0.min(m.x), b.1.min(m.y), b.2.max(m.x), b.3.max(m.y));
        }
    }
    if !b.0.is_finite() {
        return Ok((0.0, 0.0, 1.0, 1.0));
    }
    Ok(b)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A crowd denser towards one corner (positions on a grid whose lines
    /// crowd together there): the grid's centres give the corner's leader
    /// most of it; the places k-means moves them to share it out better,
    /// and the same trace gives the same places.
    #[test]
    fn leaders_are_placed_where_the_crowd_is() {
        let dir = std::env::temp_dir().join(format!("idmesh-places-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let trace = dir.join("t.jsonl");
        let mut text =
            "{\"kind\":\"header\",\"format\":\"idmesh-trace\",\"version\":1,\"tracks\":400,\"red\":1}\n"
                .to_string();
        let mut positions = Vec::new();
        for t in 0..400u32 {
            let (i, j) = ((t % 20) as f64 / 19.0, (t / 20) as f64 / 19.0);
            let (x, y) = (100.0 * i * i, 100.0 * j * j);
            positions.push((x, y));
            text.push_str(&format!(
                "{{\"kind\":\"move\",\"time\":0,\"track\":{t},\"x\":{x},\"y\":{y}}}\n"
            ));
        }
        std::fs::write(&trace, text).unwrap();
        let places = leader_places(&trace, 4).unwrap();
        assert_eq!(places, leader_places(&trace, 4).unwrap());
        assert!(leader_places(&dir.join("gone.jsonl"), 2).is_err());
        std::fs::remove_dir_all(&dir).unwrap();
        let busiest = |places: &[(f64, f64)]| {
            let mut counts = vec![0usize; places.len()];
            let regions = regions_of(places);
            for &(x, y) in &positions {
                counts[regions.nearest(x, y).map_or(0, usize::from)] += 1;
            }
            counts.into_iter().max().unwrap()
        };
        let grid = [(25.0, 25.0), (75.0, 25.0), (25.0, 75.0), (75.0, 75.0)];
        let (on_grid, placed) = (busiest(&grid), busiest(&places));
        assert!(
            placed < on_grid,
            "{placed} vs {on_grid} on the grid, at {places:?}"
        );
    }
}
