//! A LAN made of Linux network namespaces, for tests that need hosts
//! whose links fail: one namespace per host, each with one interface
//! (`eth0`, a private address in 10.213.0.0/24) on a bridge that lives in
//! a namespace of its own — the switch. Nothing is added to the namespace
//! the test runs in: every address, route and packet stays inside the
//! namespaces this module made, which [`Lan`]'s `Drop` deletes (with
//! every process still running in them), even when the test panics.
//!
//! On it, [`LanDeployment`] runs a topology the way a user runs one on
//! real machines: `idmesh up --config lan.toml --host <name>` on every
//! host (`ip netns exec`), and `idmesh query` from the coordinator's host
//! (or a client host of its own, [`LanDeployment::ask_from`]).
//! The faults a LAN has: a host's switch port down then up
//! ([`Lan::link`]), a whole host killed and started again
//! ([`LanDeployment::kill_host`], [`LanDeployment::start_host`]), a slow
//! link (`tc ... tbf` on both ends of one host's cable, [`Lan::slow`];
//! netem is not available on every kernel, tbf is).
//!
//! Making namespaces needs root (CAP_SYS_ADMIN and CAP_NET_ADMIN):
//! [`Lan::new`] says why not, and a test skips with that one line.

use crate::deployment::{answer_until, query_output};
use crate::idmesh;
use idmesh_deploy::runtime::topology::{
    BeliefKind, LeaderProcess, Process, SensorProcess, SensorStandbyProcess, Topology,
};
use serde_json::Value;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

/// The namespaces of every LAN this crate makes start so; the pid of the
/// test process follows, so that a run can remove what a killed run left.
const PREFIX: &str = "idmlan";

/// The subnet every host's address is in (private, and only ever
/// configured inside the LAN's own namespaces).
const SUBNET: &str = "10.213.0";

/// One host of the LAN.
#[derive(Debug, Clone)]
pub struct Host {
    pub name: String,
    /// Its network namespace.
    pub netns: String,
    /// Its address on the LAN.
    pub addr: String,
    /// Its cable's end on the switch (in the switch's namespace).
    port: String,
}

/// Namespaces on a bridge; deleted, with their processes, on drop.
pub struct Lan {
    switch: String,
    pub hosts: Vec<Host>,
}

fn ip(args: &[&str]) -> Result<(), String> {
    run("ip", args)
}

fn run(program: &str, args: &[&str]) -> Result<(), String> {
    let output = Command::new(program)
        .args(args)
        .output()
        .map_err(|e| format!("{program}: {e}"))?;
    if output.status.success() {
        Ok(())
    } else {
        Err(format!(
            "{program} {}: {}",
            args.join(" "),
            String::from_utf8_lossy(&output.stderr).trim()
        ))
    }
}

/// The pids of every process in namespace `netns`.
fn pids(netns: &str) -> Vec<i32> {
    Command::new("ip")
        .args(["netns", "pids", netns])
        .output()
        .map(|o| {
            String::from_utf8_lossy(&o.stdout)
                .split_whitespace()
                .filter_map(|p| p.parse().ok())
                .collect()
        })
        .unwrap_or_default()
}

/// Sends `signal` to every process in `netns`.
fn signal_all(netns: &str, signal: i32) {
    for pid in pids(netns) {
        // SAFETY: kill(2) has no memory effects; a pid gone meanwhile is
        // an error we ignore.
        unsafe {
            libc::kill(pid, signal);
        }
    }
}

/// Stops every process in `netns`: SIGTERM, then SIGKILL after `grace`.
fn stop_all(netns: &str, grace: Duration) {
    signal_all(netns, libc::SIGTERM);
    let deadline = Instant::now() + grace;
    while !pids(netns).is_empty() && Instant::now() < deadline {
        std::thread::sleep(Duration::from_millis(50));
    }
    signal_all(netns, libc::SIGKILL);
    let deadline = Instant::now() + Duration::from_secs(5);
    while !pids(netns).is_empty() && Instant::now() < deadline {
        std::thread::sleep(Duration::from_millis(20));
    }
}

/// Deletes the namespaces earlier runs of this crate left behind (their
/// test process is gone: killed before its `Drop` ran).
fn remove_leftovers() {
    let Ok(out) = Command::new("ip").args(["netns", "list"]).output() else {
        return;
    };
    for line in String::from_utf8_lossy(&out.stdout).lines() {
        let Some(name) = line.split_whitespace().next() else {
            continue;
        };
        let Some(rest) = name.strip_prefix(PREFIX) else {
            continue;
        };
        let pid = rest.split('-').next().unwrap_or("");
        let alive = !pid.is_empty() && Path::new("/proc").join(pid).exists();
        if !alive {
            stop_all(name, Duration::from_secs(1));
            let _ = ip(&["netns", "del", name]);
        }
    }
}

impl Lan {
    /// A switch and `hosts` hosts, each cabled to it and up; or why the
    /// namespaces could not be made (not root, no `ip`).
    pub fn new(hosts: &[&str]) -> Result<Lan, String> {
        remove_leftovers();
        let id = std::process::id();
        let mut lan = Lan {
            switch: format!("{PREFIX}{id}-sw"),
            hosts: Vec::new(),
        };
        // Dropped on any error below: what was made is deleted.
        ip(&["netns", "add", &lan.switch])?;
        ip(&["-n", &lan.switch, "link", "set", "lo", "up"])?;
        ip(&["-n", &lan.switch, "link", "add", "br0", "type", "bridge"])?;
        ip(&["-n", &lan.switch, "link", "set", "br0", "up"])?;
        for (i, name) in hosts.iter().enumerate() {
            let host = Host {
                name: name.to_string(),
                netns: format!("{PREFIX}{id}-h{i}"),
                addr: format!("{SUBNET}.{}", i + 1),
                port: format!("p{i}"),
            };
            ip(&["netns", "add", &host.netns])?;
            lan.hosts.push(host.clone());
            let (sw, ns) = (lan.switch.as_str(), host.netns.as_str());
            // Both ends are made where they live: no interface ever
            // appears in the test's own namespace.
            ip(&[
                "-n", sw, "link", "add", &host.port, "type", "veth", "peer", "name", "eth0",
                "netns", ns,
            ])?;
            ip(&["-n", sw, "link", "set", &host.port, "master", "br0"])?;
            ip(&["-n", sw, "link", "set", &host.port, "up"])?;
            ip(&["-n", ns, "link", "set", "lo", "up"])?;
            let cidr = format!("{}/24", host.addr);
            ip(&["-n", ns, "addr", "add", &cidr, "dev", "eth0"])?;
            ip(&["-n", ns, "link", "set", "eth0", "up"])?;
        }
        Ok(lan)
    }

    pub(crate) fn host(&self, name: &str) -> &Host {
        self.hosts
            .iter()
            .find(|h| h.name == name)
            .unwrap_or_else(|| panic!("no host {name}"))
    }

    /// Host `name`'s switch port up or down: as a cable pulled out, the
    /// host keeps running and its packets go nowhere.
    pub fn link(&self, name: &str, up: bool) {
        let host = self.host(name);
        let state = if up { "up" } else { "down" };
        ip(&["-n", &self.switch, "link", "set", &host.port, state])
            .unwrap_or_else(|e| panic!("{e}"));
    }

    /// Host `name`'s cable limited to `rate` (tc's units, e.g. `2mbit`)
    /// both ways, by a token bucket on each end.
    pub fn slow(&self, name: &str, rate: &str) {
        let host = self.host(name);
        for (ns, dev) in [(&host.netns, "eth0"), (&self.switch, &host.port)] {
            run(
                "tc",
                &[
                    "-n", ns, "qdisc", "replace", "dev", dev, "root", "tbf", "rate", rate, "burst",
                    "32kbit", "latency", "400ms",
                ],
            )
            .unwrap_or_else(|e| panic!("{e}"));
        }
    }

    /// Host `name`'s cable back to full speed (the token buckets of
    /// [`Lan::slow`] removed; none there is no error).
    pub fn fast(&self, name: &str) {
        let host = self.host(name);
        for (ns, dev) in [(&host.netns, "eth0"), (&self.switch, &host.port)] {
            let _ = run("tc", &["-n", ns, "qdisc", "del", "dev", dev, "root"]);
        }
    }

    /// Runs `program args` in host `name`'s namespace.
    pub(crate) fn command(&self, name: &str, program: &Path) -> Command {
        let mut command = Command::new("ip");
        command
            .args(["netns", "exec", &self.host(name).netns])
            .arg(program);
        command
    }
}

impl Drop for Lan {
    fn drop(&mut self) {
        for host in &self.hosts {
            stop_all(&host.netns, Duration::from_secs(5));
            let _ = ip(&["netns", "del", &host.netns]);
        }
        let _ = ip(&["netns", "del", &self.switch]);
    }
}

/// A process of a LAN topology: its role, name and host.
#[derive(Debug, Clone)]
pub struct Member {
    /// `coordinator`, `coordinator_replica`, `voter`, `sensor`, `leader`,
    /// or `sensor_standby` (a `[[sensor_standby]]` for the sensor named
    /// by `stands_by`).
    pub role: &'static str,
    pub name: String,
    pub host: String,
    /// The sensor a `sensor_standby` stands by for (None for the others).
    pub stands_by: Option<String>,
}

/// Asks a LAN deployment's coordinators (the first, then its replicas)
/// from the asking host (the coordinator's, unless
/// [`LanDeployment::ask_from`] names another).
#[derive(Debug, Clone)]
pub struct Asker {
    netns: String,
    connect: String,
    prefix: String,
}

impl Asker {
    /// `idmesh query <args> --json`: the parsed replies, or the error text.
    pub fn query(&self, args: &[&str]) -> Result<Vec<Value>, String> {
        let output = Command::new("ip")
            .args(["netns", "exec", &self.netns])
            .arg(idmesh())
            .arg("query")
            .args(args)
            .args([
                "--json",
                "--connect",
                &self.connect,
                "--prefix",
                &self.prefix,
            ])
            .output()
            .expect("idmesh query runs");
        match query_output(&output) {
            (answers, _, true) => Ok(answers),
            (_, errors, false) => Err(errors),
        }
    }
}

/// A deployment across the hosts of a [`Lan`]: one topology file, `idmesh
/// up --host` on each host.
pub struct LanDeployment<'a> {
    pub lan: &'a Lan,
    pub dir: PathBuf,
    pub prefix: String,
    pub config: PathBuf,
    pub coordinator_host: String,
    /// The host `idmesh query` runs on: the coordinator's, or the one
    /// [`LanDeployment::ask_from`] names.
    pub asking_host: String,
    /// Every coordinator's endpoint, comma-separated: the first, then its
    /// replicas (what `idmesh query --connect` takes).
    pub coordinator: String,
    /// Each host's own `lan.toml` ([`LanSettings::own_disks`]).
    own_configs: Vec<(String, PathBuf)>,
    /// `idmesh up` by host.
    ups: Vec<(String, Child)>,
}

/// What a LAN topology sets beyond where its processes run.
#[derive(Debug, Clone, Default)]
pub struct LanSettings {
    /// The sensor's events per second.
    pub rate: f64,
    /// `takeover_after_ms` (0 = a role is never adopted: its process is
    /// restarted).
    pub takeover_after_ms: u64,
    pub query_timeout_ms: u64,
    /// Inputs between a leader's snapshots (`snapshot_every`; 0 = 200).
    pub snapshot_every: usize,
    /// Every host has a disk of its own: its own copy of `lan.toml`
    /// (`<host>/lan.toml` in the deployment's directory), whose relative
    /// `state_dir` is so `<host>/state`. Otherwise every host's processes
    /// read the one `lan.toml`, and share its `state` directory.
    pub own_disks: bool,
}

impl<'a> LanDeployment<'a> {
    /// Writes `lan.toml` for `members` (the coordinator and sensor on the
    /// first host of theirs, leaders placed on a grid over the trace's
    /// field; voters named `voter-1`, …, coordinator replicas and sensor
    /// standbys as the members name them) under a fresh directory; starts
    /// nothing.
    pub fn configure(
        lan: &'a Lan,
        name: &str,
        trace: &Path,
        members: &[Member],
        settings: &LanSettings,
    ) -> LanDeployment<'a> {
        let dir = std::env::temp_dir().join(format!("idmesh-lan-{name}-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir).unwrap();
        let prefix = format!("idmesh/lan-{name}-{}", std::process::id());
        let mut topology = lan_topology(lan, trace, members, settings);
        topology.prefix = prefix.clone();
        let config = dir.join("lan.toml");
        topology.save(&config).unwrap();
        let mut own_configs = Vec::new();
        if settings.own_disks {
            for host in &lan.hosts {
                let own = dir.join(&host.name).join("lan.toml");
                std::fs::create_dir_all(own.parent().unwrap()).unwrap();
                topology.save(&own).unwrap();
                own_configs.push((host.name.clone(), own));
            }
        }
        LanDeployment {
            lan,
            dir,
            prefix,
            config,
            coordinator_host: topology.coordinator.host.clone(),
            asking_host: topology.coordinator.host.clone(),
            coordinator: topology.coordinator_endpoints(),
            own_configs,
            ups: Vec::new(),
        }
    }

    /// Where host `host` keeps its state: its own directory with
    /// [`LanSettings::own_disks`], the shared one otherwise.
    pub fn state_dir(&self, host: &str) -> PathBuf {
        self.config_of(host).parent().unwrap().join("state")
    }

    /// The topology file host `host`'s processes read.
    fn config_of(&self, host: &str) -> &Path {
        self.own_configs
            .iter()
            .find(|(h, _)| h == host)
            .map_or(&self.config, |(_, path)| path)
    }

    /// `idmesh up --config lan.toml --host <host>` in the host's namespace
    /// (its log: `<host>.log` in the deployment's directory).
    pub fn start_host(&mut self, host: &str) {
        let log = std::fs::OpenOptions::new()
            .create(true)
            .append(true)
            .open(self.dir.join(format!("{host}.log")))
            .unwrap();
        let child = self
            .lan
            .command(host, idmesh())
            .arg("up")
            .arg("--config")
            .arg(self.config_of(host))
            .arg("--host")
            .arg(host)
            .env(
                "RUST_LOG",
                "warn,idmesh_leader=info,idmesh_sensor=info,idmesh_coordinator=info",
            )
            .stdout(Stdio::null())
            .stderr(log)
            .spawn()
            .expect("ip netns exec idmesh up starts");
        self.ups.push((host.to_string(), child));
    }

    /// Every process on `host` killed at once (SIGKILL): a host that
    /// lost its power.
    pub fn kill_host(&mut self, host: &str) {
        signal_all(&self.lan.host(host).netns, libc::SIGKILL);
        let deadline = Instant::now() + Duration::from_secs(5);
        while !pids(&self.lan.host(host).netns).is_empty() && Instant::now() < deadline {
            std::thread::sleep(Duration::from_millis(20));
        }
        for (_, child) in self.ups.iter_mut().filter(|(h, _)| h == host) {
            let _ = child.wait();
        }
        self.ups.retain(|(h, _)| h != host);
    }

    /// SIGKILL to the role process named `name` on `host` (`kill -9`: its
    /// `idmesh up` starts it again after its backoff); whether one ran.
    pub fn kill_process(&self, host: &str, name: &str) -> bool {
        let mut killed = false;
        for pid in pids(&self.lan.host(host).netns) {
            let Ok(raw) = std::fs::read(format!("/proc/{pid}/cmdline")) else {
                continue;
            };
            let args: Vec<&[u8]> = raw.split(|&b| b == 0).collect();
            let named = args
                .windows(2)
                .any(|w| w[0] == b"--name" && w[1] == name.as_bytes());
            if named && !args.iter().any(|a| *a == b"up") {
                // SAFETY: kill(2) has no memory effects; a pid gone
                // meanwhile is an error we ignore.
                unsafe {
                    libc::kill(pid, libc::SIGKILL);
                }
                killed = true;
            }
        }
        killed
    }

    /// `idmesh query` runs from `host` from now on (a client host of its
    /// own, which survives the coordinator's host being lost or cut off).
    pub fn ask_from(&mut self, host: &str) {
        self.asking_host = self.lan.host(host).name.clone();
    }

    /// `idmesh query <args> --json` from the asking host: the parsed
    /// replies, or the error text.
    pub fn query(&self, args: &[&str]) -> Result<Vec<Value>, String> {
        self.asker().query(args)
    }

    /// What asks this deployment's coordinators, as [`LanDeployment::query`]
    /// does, for a thread that asks while the test strikes.
    pub fn asker(&self) -> Asker {
        Asker {
            netns: self.lan.host(&self.asking_host).netns.clone(),
            connect: self.coordinator.clone(),
            prefix: self.prefix.clone(),
        }
    }

    /// Asks `marginals` until an answer satisfies `wanted`: the answer
    /// and when it came, or panics after `patience` with the logs.
    pub fn marginals_when(
        &self,
        patience: Duration,
        wanted: impl Fn(&Value) -> bool,
    ) -> (Value, Instant) {
        self.answer_when(&["marginals"], patience, wanted)
    }

    /// Asks `idmesh query <args>` until an answer satisfies `wanted`: the
    /// answer and when it came, or panics after `patience` with the logs.
    pub fn answer_when(
        &self,
        args: &[&str],
        patience: Duration,
        wanted: impl Fn(&Value) -> bool,
    ) -> (Value, Instant) {
        let answer = answer_until(patience, || self.query(args), wanted, || self.logs());
        (answer, Instant::now())
    }

    /// Whether `host`'s log has a line containing `text`.
    pub fn logged(&self, host: &str, text: &str) -> bool {
        std::fs::read_to_string(self.dir.join(format!("{host}.log")))
            .is_ok_and(|log| log.lines().any(|l| l.contains(text)))
    }

    /// The last lines of every host's log.
    pub fn logs(&self) -> String {
        let mut all = String::new();
        for host in &self.lan.hosts {
            let text = std::fs::read_to_string(self.dir.join(format!("{}.log", host.name)))
                .unwrap_or_default();
            let lines: Vec<&str> = text.lines().collect();
            let tail = &lines[lines.len().saturating_sub(60)..];
            all.push_str(&format!("--- {} ---\n{}\n", host.name, tail.join("\n")));
        }
        all
    }
}

/// The topology of `members` on `lan` streaming `trace` (no prefix yet):
/// every process listens on its host's address.
fn lan_topology(lan: &Lan, trace: &Path, members: &[Member], settings: &LanSettings) -> Topology {
    // Ports only need to differ on one host, but differing everywhere
    // reads better.
    let listen = |i: usize, host: &str| format!("tcp/{}:{}", lan.host(host).addr, 7460 + i);
    let mut coordinator = None;
    let (mut replicas, mut voters) = (Vec::new(), Vec::new());
    let mut sensors = Vec::new();
    let mut sensor_standbys = Vec::new();
    let mut leaders = Vec::new();
    for (i, m) in members.iter().enumerate() {
        let (name, host) = (m.name.clone(), m.host.clone());
        let process = || Process {
            host: host.clone(),
            ..Process::new(name.clone(), listen(i, &m.host))
        };
        match m.role {
            "coordinator" => coordinator = Some(process()),
            "coordinator_replica" => replicas.push(process()),
            "voter" => voters.push(process()),
            "sensor" => sensors.push(SensorProcess {
                host: host.clone(),
                rate: Some(settings.rate),
                ..SensorProcess::new(name.clone(), listen(i, &m.host), trace)
            }),
            "sensor_standby" => sensor_standbys.push(SensorStandbyProcess {
                name: name.clone(),
                host: host.clone(),
                listen: listen(i, &m.host),
                sensor: m
                    .stands_by
                    .clone()
                    .unwrap_or_else(|| panic!("{name}: a sensor_standby names its sensor")),
            }),
            "leader" => leaders.push(LeaderProcess {
                host: host.clone(),
                ..LeaderProcess::new(name.clone(), listen(i, &m.host))
            }),
            other => panic!("{}: no role {other:?}", m.name),
        }
    }
    let coordinator = coordinator.expect("a coordinator among the members");
    let mut topology = Topology::new(coordinator, sensors, leaders);
    topology.coordinator_replicas = replicas;
    topology.voters = voters;
    topology.sensor_standbys = sensor_standbys;
    // The Radon belief: the LAN tests compare with `idmesh replay
    // --method overcomplete` (the topology's default is factored).
    topology.belief = BeliefKind::Radon;
    topology.query_timeout_ms = settings.query_timeout_ms;
    topology.state_dir = Some(PathBuf::from("state"));
    topology.takeover_after_ms = settings.takeover_after_ms;
    topology.snapshot_every = match settings.snapshot_every {
        0 => 200,
        n => n,
    };
    topology
}

impl Drop for LanDeployment<'_> {
    fn drop(&mut self) {
        // Every process of every host (the `up`s and what they started,
        // and anything an `up` left behind).
        for host in &self.lan.hosts {
            stop_all(&host.netns, Duration::from_secs(5));
        }
        for (_, child) in &mut self.ups {
            let _ = child.wait();
        }
        // Its folder (topology, state, logs) goes with a passing test; a
        // failing one keeps it to be read, as does
        // `IDMESH_KEEP_TEST_DIRS=1`.
        if !std::thread::panicking() && !crate::keep_test_dirs() {
            let _ = std::fs::remove_dir_all(&self.dir);
        }
    }
}
