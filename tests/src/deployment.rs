//! A real deployment for a test: a topology on free loopback ports (with a
//! `[security]` section if asked), `idmesh up` (or every process on its
//! own, for tests that kill and restart one), and queries through `idmesh
//! query`.

use crate::idmesh;
use idmesh_deploy::runtime::ports::pick_free_ports;
pub use idmesh_deploy::runtime::security::SecuritySection;
pub use idmesh_deploy::runtime::topology::{
    BeliefKind, FaultSection, LeaderFaultSection, Process, RegionsSetting, SensorStandbyProcess,
    Sparsification, SplitSetting, Topology, WebSection,
};
pub use idmesh_deploy::runtime::web::MarkerOptions;
use serde_json::Value;
use std::path::{Path, PathBuf};
use std::process::{Child, ChildStdin, Command, ExitStatus, Stdio};
use std::time::{Duration, Instant};

#[derive(Debug, Clone, Default)]
pub struct Settings {
    pub leaders: usize,
    pub distributed_rule: bool,
    pub budget: u32,
    /// OMP before thresholding at the leaders (`sparsify = "overcomplete"`).
    pub overcomplete: bool,
    /// Events per second; None = as fast as possible.
    pub rate: Option<f64>,
    /// Leaders journal their inputs (`state_dir`), so they can restart.
    pub journal: bool,
    /// Inputs between a leader's snapshots (`snapshot_every`; None = the
    /// default).
    pub snapshot_every: Option<usize>,
    /// How long a leader process may be gone before its role is adopted
    /// (`takeover_after_ms`; None = the default).
    pub takeover_after_ms: Option<u64>,
    /// The sensor's `[sensor.faults]` section (every sensor's).
    pub faults: FaultSection,
    /// The leaders' `[leader_faults]` section.
    pub leader_faults: LeaderFaultSection,
    /// A `[security]` section: mutual TLS, and access control if asked.
    pub security: Option<Secured>,
    /// The sensor's stream stays open for producers (`live = true`).
    pub live: bool,
    /// The sensor's flow control (`window = N`); None: no window.
    pub window: Option<u64>,
    /// The sensor compacts its journal after this many bytes
    /// (`compact_journal_after`); None: the default.
    pub compact_journal_after: Option<u64>,
    /// The sensor's `trace`, when it is not the trace the leaders are
    /// placed over (say, the header alone, for a live stream).
    pub sensor_trace: Option<PathBuf>,
    /// How long the coordinator may compute one identity answer
    /// (`marginals_timeout_ms`; None = the default).
    pub marginals_timeout_ms: Option<u64>,
    /// The factored belief with these settings (`belief = "factored"`).
    /// None: `belief = "radon"`, which the runtime's tests compare with
    /// `idmesh replay --method overcomplete` (the topology's own default
    /// is factored).
    pub factored: Option<Factored>,
    /// How many sensors (`[[sensor]]`, named `sensor-0`, `sensor-1`, …,
    /// each with the settings above); 0 or 1: one `[sensor]`. Leaders are
    /// served by the sensors in turn.
    pub sensors: usize,
    /// Leaders at fixed places on a grid over the trace's field
    /// (`regions = "fixed"`: a track is handed over at every `move` across
    /// a border), instead of regions fitted to the crowd.
    pub fixed_places: bool,
    /// Every sensor extracts its events from a tracker's reports with
    /// these settings (`[sensor.extract]`).
    pub extract: Option<idmesh_extract::ExtractorConfig>,
    /// Bad lines of a sensor's own input it goes past (`max_errors`).
    pub max_errors: usize,
    /// Coordinators beside the first (`[[coordinator_replica]]`, named
    /// `coordinator-1`, …); queries are given every coordinator's
    /// endpoint.
    pub coordinator_replicas: usize,
    /// The sensor reads these ROS 2 topics (`[sensor.ros2]`).
    pub ros2: Option<idmesh_sensor::ros2::Ros2Config>,
    /// The web gateway `idmesh up` serves (`[web]`).
    pub web: Option<WebSection>,
    /// Voters (`[[voter]]`, named `voter-1`, …), each with its log in
    /// the state directory.
    pub voters: usize,
    /// With `journal`: every leader process has a state directory of its
    /// own (`state-<name>`), as on hosts that each have their own disk. Each
    /// is given its own copy of the topology, differing in `state_dir`
    /// only (processes started one by one: [`Deployment::start_each`]).
    pub own_disks: bool,
    /// How many standbys the (first) sensor has (`[[sensor_standby]]`,
    /// in order [`standby_name`]), started before it; with `own_disks`
    /// the sensor and its standbys have a state directory of their own
    /// too.
    pub sensor_standbys: usize,
}

/// The factored belief's settings in a topology.
#[derive(Debug, Clone)]
pub struct Factored {
    pub max_component: u32,
    pub split: SplitSetting,
    pub regional: bool,
    /// `spread_above`: 0 here unless a test says, since the tests' small
    /// crowds are there to exercise leaders sharing a crowd, which a
    /// topology's default holds whole.
    pub spread_above: u32,
}

impl Default for Factored {
    /// A topology's defaults, but every crowd spread.
    fn default() -> Self {
        Factored {
            max_component: idmesh_deploy::runtime::topology::default_max_component(),
            split: SplitSetting::default(),
            regional: true,
            spread_above: 0,
        }
    }
}

/// A secured deployment: `certs` holds `ca.pem` and `<name>.pem`/`.key`
/// for every process (`coordinator`, `sensor-0`, `leader-<i>`) and for
/// `client`, whose certificate `idmesh query` shows.
#[derive(Debug, Clone)]
pub struct Secured {
    pub certs: PathBuf,
    pub access_control: bool,
    /// The one client the topology lists, and the one queries are made as.
    pub client: String,
    /// The producers it lists (they may feed the sensor's ingest key).
    pub producers: Vec<String>,
}

pub struct Deployment {
    pub dir: PathBuf,
    /// Every coordinator's endpoint, comma-separated (what `idmesh query
    /// --connect` takes).
    pub coordinator: String,
    pub prefix: String,
    /// Every process's name and listening endpoint, as the topology has it.
    pub endpoints: Vec<(String, String)>,
    security: Option<Secured>,
    config: PathBuf,
    /// `idmesh up`, or every process by its name.
    children: Vec<(String, Child)>,
    /// Processes given a topology of their own ([`Settings::own_disks`]).
    own_configs: Vec<(String, PathBuf)>,
}

/// The bounding box of a trace's positions (`move` and `detect` lines).
pub(crate) fn corners(trace: &Path) -> (f64, f64, f64, f64) {
    let text = std::fs::read_to_string(trace).expect("trace readable");
    let mut b = (
        f64::INFINITY,
        f64::INFINITY,
        f64::NEG_INFINITY,
        f64::NEG_INFINITY,
    );
    for line in text.lines() {
        let v: Value = serde_json::from_str(line).expect("trace line is JSON");
        if v["kind"] == "move" || v["kind"] == "detect" {
            let (x, y) = (v["x"].as_f64().unwrap(), v["y"].as_f64().unwrap());
            b = (b.0.min(x), b.1.min(y), b.2.max(x), b.3.max(y));
        }
    }
    b
}

/// Answers at a trace's truth points (`points`: truth line index and
/// answer) equal the centralized engine's lines there (`central`, from
/// [`replay_lines`]) to 1e-9; at least half of the `truths` were answered
/// (points the stream passed before the question reached it are not).
pub fn assert_truth_points(
    points: &[(usize, Value)],
    truths: &[Truth],
    central: &[Value],
    what: &str,
) {
    assert!(
        points.len() * 2 >= truths.len(),
        "{what}: {} of {} truth points answered",
        points.len(),
        truths.len()
    );
    for (i, answer) in points {
        crate::compare::assert_same_marginals(
            answer,
            &crate::compare::floats(&central[*i]["p_red"]),
            &format!("{what}: truth point {i}"),
        );
    }
}

/// The name of sensor `sensor`'s standby number `i` (from 0) in a test
/// deployment: `<sensor>-standby`, then `<sensor>-standby-2`, ….
pub fn standby_name(sensor: &str, i: usize) -> String {
    match i {
        0 => format!("{sensor}-standby"),
        i => format!("{sensor}-standby-{}", i + 1),
    }
}

/// The events an answer includes: its watermark's, summed over the
/// sensors (one sensor of several counts the events of its intake).
pub fn watermark_events(answer: &Value) -> u64 {
    answer["watermark"]
        .as_object()
        .map_or(0, |w| w.values().filter_map(Value::as_u64).sum())
}

/// `count` places on a grid over the field `trace`'s moves span (row by
/// row): where the tests' producers put their sensors.
pub fn grid_over(trace: &Path, count: usize) -> Vec<(f64, f64)> {
    idmesh_placement::grid_places(corners(trace), count)
}

/// The topology of test deployment `name` streaming `trace` with
/// `settings`: the loopback layout ([`Topology::loopback`]) on free ports;
/// its leaders' regions are fitted to the crowd (the default).
pub(crate) fn topology(name: &str, trace: &Path, settings: &Settings) -> Topology {
    let sensors = settings.sensors.max(1);
    let ports = pick_free_ports(1 + settings.leaders + sensors).expect("free loopback ports");
    let sensor_trace = settings.sensor_trace.as_deref().unwrap_or(trace);
    let mut topology = Topology::loopback(sensor_trace, settings.leaders, sensors, &ports);
    let voter_ports = pick_free_ports(settings.voters).expect("free loopback ports");
    topology.voters = voter_ports
        .iter()
        .enumerate()
        .map(|(i, port)| Process::new(format!("voter-{}", i + 1), format!("tcp/127.0.0.1:{port}")))
        .collect();
    if settings.voters > 0 {
        topology.state_dir = Some(PathBuf::from("state"));
    }
    let ports = pick_free_ports(settings.sensor_standbys).expect("free loopback ports");
    let sensor = topology.sensor().name.clone();
    topology.sensor_standbys = (0..settings.sensor_standbys)
        .map(|i| SensorStandbyProcess {
            name: standby_name(&sensor, i),
            host: "local".into(),
            listen: format!("tcp/127.0.0.1:{}", ports[i]),
            sensor: sensor.clone(),
        })
        .collect();
    let replica_ports =
        pick_free_ports(settings.coordinator_replicas).expect("free loopback ports");
    topology.coordinator_replicas = replica_ports
        .iter()
        .enumerate()
        .map(|(i, port)| {
            Process::new(
                format!("coordinator-{}", i + 1),
                format!("tcp/127.0.0.1:{port}"),
            )
        })
        .collect();
    if settings.fixed_places {
        topology.regions = RegionsSetting::Fixed;
        for (leader, (x, y)) in topology
            .leader
            .iter_mut()
            .zip(grid_over(trace, settings.leaders))
        {
            leader.at = Some([x, y]);
        }
    }
    topology.prefix = format!("idmesh/test-{name}-{}", std::process::id());
    topology.distributed_rule = settings.distributed_rule;
    topology.budget = settings.budget;
    topology.sparsify = if settings.overcomplete {
        Sparsification::Overcomplete
    } else {
        Sparsification::Threshold
    };
    topology.query_timeout_ms = 10_000;
    match &settings.factored {
        Some(factored) => {
            topology.belief = BeliefKind::Factored;
            topology.max_component = factored.max_component;
            topology.split = factored.split;
            topology.regional = factored.regional;
            topology.spread_above = factored.spread_above;
        }
        None => topology.belief = BeliefKind::Radon,
    }
    if settings.journal {
        topology.state_dir = Some(PathBuf::from("state"));
    }
    if let Some(every) = settings.snapshot_every {
        topology.snapshot_every = every;
    }
    if let Some(ms) = settings.takeover_after_ms {
        topology.takeover_after_ms = ms;
    }
    if let Some(ms) = settings.marginals_timeout_ms {
        topology.marginals_timeout_ms = ms;
    }
    for sensor in &mut topology.sensors {
        sensor.window = settings.window;
        sensor.compact_journal_after = settings.compact_journal_after;
        sensor.live = settings.live;
        sensor.rate = settings.rate;
        sensor.faults = settings.faults.clone();
        sensor.extract = settings.extract.clone();
        sensor.max_errors = settings.max_errors;
        sensor.ros2 = settings.ros2.clone();
    }
    topology.leader_faults = settings.leader_faults.clone();
    topology.web = settings.web.clone();
    topology.security = settings.security.as_ref().map(|secured| SecuritySection {
        access_control: secured.access_control,
        clients: vec![secured.client.clone()],
        producers: secured.producers.clone(),
        ..SecuritySection::new(&secured.certs)
    });
    topology
}

impl Deployment {
    /// Starts a deployment streaming `trace` under `idmesh up`.
    pub fn start(name: &str, trace: &Path, settings: &Settings) -> Deployment {
        let mut deployment = Self::configure(name, trace, settings);
        let child = deployment.spawn(&["up"]);
        deployment.children.push(("up".into(), child));
        deployment
    }

    /// `idmesh replay --topology` of this deployment's topology over
    /// `trace`: the centralized twin's answers at the truth lines.
    pub fn twin(&self, trace: &Path) -> Vec<Value> {
        let config = self.config.to_string_lossy().into_owned();
        replay_lines(trace, &["--topology", &config])
    }

    /// The summary of the centralized twin (`idmesh replay --topology`)
    /// on `trace`: its `final_p_red` is the answer once the stream is in.
    pub fn twin_summary(&self, trace: &Path) -> Value {
        let config = self.config.to_string_lossy().into_owned();
        replay_summary(trace, &["--topology", &config])
    }

    /// The same deployment with every process started on its own (the
    /// sensor last, once the others are up), so that one can be killed and
    /// started again.
    pub fn start_each(name: &str, trace: &Path, settings: &Settings) -> Deployment {
        let mut deployment = Self::configure(name, trace, settings);
        deployment.launch("coordinator", "coordinator");
        for i in 1..=settings.coordinator_replicas {
            deployment.launch("coordinator", &format!("coordinator-{i}"));
        }
        for i in 1..=settings.voters {
            deployment.launch("voter", &format!("voter-{i}"));
        }
        for i in 0..settings.leaders {
            deployment.launch("leader", &format!("leader-{i}"));
        }
        for i in 0..settings.sensor_standbys {
            deployment.launch("sensor-standby", &standby_name("sensor-0", i));
        }
        for s in 0..settings.sensors.max(1) {
            deployment.launch("sensor", &format!("sensor-{s}"));
        }
        deployment
    }

    /// The coordinator and the leaders, each on its own, and no sensor
    /// (the test starts it, e.g. with [`Deployment::launch_piped`]).
    pub fn start_without_sensor(name: &str, trace: &Path, settings: &Settings) -> Deployment {
        let mut deployment = Self::configure(name, trace, settings);
        deployment.launch("coordinator", "coordinator");
        for i in 0..settings.leaders {
            deployment.launch("leader", &format!("leader-{i}"));
        }
        deployment
    }

    /// Starts process `name` in `role` with `extra` arguments (e.g.
    /// `--stdin`) and standard input a pipe the test writes.
    pub fn launch_piped(&mut self, role: &str, name: &str, extra: &[&str]) -> ChildStdin {
        let mut command = self.command(&[role, "--name", name]);
        command.args(extra).stdin(Stdio::piped());
        let mut child = command.spawn().expect("idmesh starts");
        let stdin = child.stdin.take().expect("a piped stdin");
        self.children.push((name.to_string(), child));
        stdin
    }

    /// The topology file.
    pub fn config(&self) -> &Path {
        &self.config
    }

    /// Waits for process `name` (started with [`Deployment::launch`] or
    /// [`Deployment::launch_piped`]) to end by itself: its exit status, or
    /// a panic after `patience`.
    pub fn wait_for(&mut self, name: &str, patience: Duration) -> ExitStatus {
        let started = Instant::now();
        let (_, child) = self
            .children
            .iter_mut()
            .find(|(n, _)| n == name)
            .unwrap_or_else(|| panic!("no process {name}"));
        loop {
            if let Some(status) = child.try_wait().expect("wait for it") {
                return status;
            }
            assert!(
                started.elapsed() < patience,
                "{name} still runs after {patience:?}"
            );
            std::thread::sleep(Duration::from_millis(50));
        }
    }

    /// Starts process `name` in `role`.
    pub fn launch(&mut self, role: &str, name: &str) {
        let child = self.spawn(&[role, "--name", name]);
        self.children.push((name.to_string(), child));
    }

    /// Starts process `name` in `role` again once it has ended by itself
    /// (as `idmesh up` would), waiting for that up to `patience`: the
    /// status it ended with.
    pub fn relaunch(&mut self, role: &str, name: &str, patience: Duration) -> ExitStatus {
        let status = self.wait_for(name, patience);
        self.children.retain(|(n, _)| n != name);
        self.launch(role, name);
        status
    }

    /// Waits until the deployment's log holds `needle`; panics with the
    /// log after `patience`.
    pub fn await_log(&self, needle: &str, patience: Duration) {
        let started = Instant::now();
        while !self.log().contains(needle) {
            assert!(
                started.elapsed() < patience,
                "no {needle:?} in the log within {patience:?}:\n{}",
                self.log()
            );
            std::thread::sleep(Duration::from_millis(100));
        }
    }

    /// Runs process `name` in `role` and waits for it to end by itself (one
    /// expected to refuse to start); its exit status, or a panic after
    /// `patience`. What it said is in [`Deployment::log`].
    pub fn run_to_end(&self, role: &str, name: &str, patience: Duration) -> ExitStatus {
        let mut child = self.spawn(&[role, "--name", name]);
        let started = Instant::now();
        loop {
            if let Some(status) = child.try_wait().expect("wait for it") {
                return status;
            }
            if started.elapsed() > patience {
                let _ = child.kill();
                let _ = child.wait();
                panic!("{name} still runs after {patience:?}\n{}", self.log());
            }
            std::thread::sleep(Duration::from_millis(50));
        }
    }

    /// The pid of process `name` (started with [`Deployment::start_each`]).
    pub fn pid(&self, name: &str) -> Option<u32> {
        self.children
            .iter()
            .find(|(n, _)| n == name)
            .map(|(_, c)| c.id())
    }

    /// The pids of the role processes `idmesh up` started for this
    /// deployment, by name (read from /proc: they are `up`'s children).
    pub fn supervised(&self) -> std::collections::BTreeMap<String, u32> {
        let config = self.config.to_string_lossy().into_owned();
        let mut out = std::collections::BTreeMap::new();
        for entry in std::fs::read_dir("/proc").into_iter().flatten().flatten() {
            let Ok(pid) = entry.file_name().to_string_lossy().parse::<u32>() else {
                continue;
            };
            let Ok(raw) = std::fs::read(entry.path().join("cmdline")) else {
                continue;
            };
            let args: Vec<String> = raw
                .split(|&b| b == 0)
                .map(|a| String::from_utf8_lossy(a).into_owned())
                .collect();
            let ours = args.contains(&config) && !args.iter().any(|a| a == "up");
            if let (true, Some(i)) = (ours, args.iter().position(|a| a == "--name")) {
                if let Some(name) = args.get(i + 1) {
                    out.insert(name.clone(), pid);
                }
            }
        }
        out
    }

    /// SIGSTOP to process `name` (`resume` sends SIGCONT): frozen, it
    /// neither sends nor answers, but keeps its connections, its state
    /// and its roles, as a host cut off and later back does.
    pub fn pause(&self, name: &str) {
        self.signal(name, "-STOP");
    }

    /// SIGCONT to process `name`, paused by [`Deployment::pause`].
    pub fn resume(&self, name: &str) {
        self.signal(name, "-CONT");
    }

    fn signal(&self, name: &str, signal: &str) {
        let (_, child) = self
            .children
            .iter()
            .find(|(n, _)| n == name)
            .unwrap_or_else(|| panic!("no process {name}"));
        let sent = Command::new("kill")
            .args([signal, &child.id().to_string()])
            .status()
            .expect("kill runs");
        assert!(sent.success(), "kill {signal} {name}");
    }

    /// SIGKILL to process `name`: no chance to flush or say goodbye.
    pub fn kill(&mut self, name: &str) {
        let i = self
            .children
            .iter()
            .position(|(n, _)| n == name)
            .unwrap_or_else(|| panic!("no process {name}"));
        let (_, mut child) = self.children.remove(i);
        child.kill().expect("SIGKILL");
        child.wait().expect("reaped");
    }

    fn spawn(&self, args: &[&str]) -> Child {
        self.command(args).spawn().expect("idmesh starts")
    }

    fn command(&self, args: &[&str]) -> Command {
        let log = std::fs::OpenOptions::new()
            .create(true)
            .append(true)
            .open(self.dir.join("up.log"))
            .unwrap();
        // A process with a topology of its own (its own state directory).
        let name = args
            .iter()
            .position(|a| *a == "--name")
            .and_then(|i| args.get(i + 1));
        let config = self
            .own_configs
            .iter()
            .find(|(n, _)| Some(&n.as_str()) == name)
            .map_or(&self.config, |(_, path)| path);
        let mut command = Command::new(idmesh());
        command
            .args(args)
            .arg("--config")
            .arg(config)
            .env(
                "RUST_LOG",
                std::env::var("IDMESH_TEST_LOG").unwrap_or_else(|_| "warn".into()),
            )
            .stdout(Stdio::null())
            .stderr(log);
        command
    }

    /// The sensor's listening endpoint.
    pub fn sensor_endpoint(&self) -> &str {
        self.endpoint("sensor-0")
    }

    /// Process `name`'s listening endpoint.
    pub(crate) fn endpoint(&self, name: &str) -> &str {
        &self
            .endpoints
            .iter()
            .find(|(n, _)| n == name)
            .unwrap_or_else(|| panic!("no process {name}"))
            .1
    }

    fn configure(name: &str, trace: &Path, settings: &Settings) -> Deployment {
        let dir =
            std::env::temp_dir().join(format!("idmesh-deployment-{name}-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir).unwrap();
        let topology = topology(name, trace, settings);
        let config = dir.join("topology.toml");
        topology.save(&config).unwrap();
        let mut own_configs = Vec::new();
        if settings.own_disks && settings.journal {
            let mut names: Vec<String> = topology.leader.iter().map(|l| l.name.clone()).collect();
            if settings.sensor_standbys > 0 {
                names.push(topology.sensor().name.clone());
                names.extend(topology.sensor_standbys.iter().map(|s| s.name.clone()));
            }
            for name in names {
                let mut own = topology.clone();
                own.state_dir = Some(PathBuf::from(format!("state-{name}")));
                let path = dir.join(format!("topology-{name}.toml"));
                own.save(&path).unwrap();
                own_configs.push((name, path));
            }
        }
        Deployment {
            dir,
            coordinator: topology.coordinator_endpoints(),
            prefix: topology.prefix.clone(),
            endpoints: topology
                .members()
                .into_iter()
                .map(|m| (m.name, m.listen))
                .collect(),
            security: settings.security.clone(),
            config,
            children: Vec::new(),
            own_configs,
        }
    }

    /// `idmesh query <args> --json`: the parsed replies, or the error text.
    pub fn query(&self, args: &[&str]) -> Result<Vec<Value>, String> {
        let (answers, errors, success) = self.run_query(args);
        if success {
            Ok(answers)
        } else {
            Err(errors)
        }
    }

    /// Like [`Deployment::query`], but takes what was answered when some
    /// questions were refused.
    pub(crate) fn query_lenient(&self, args: &[&str]) -> Vec<Value> {
        let (answers, errors, _) = self.run_query(args);
        eprintln!("{errors}");
        answers
    }

    /// The JSON lines `idmesh query` printed, its stderr, and whether it
    /// succeeded.
    fn run_query(&self, args: &[&str]) -> (Vec<Value>, String, bool) {
        let output = Command::new(idmesh())
            .arg("query")
            .args(args)
            .args([
                "--json",
                "--connect",
                &self.coordinator,
                "--prefix",
                &self.prefix,
            ])
            .args(self.client_tls_args())
            .output()
            .expect("idmesh query runs");
        query_output(&output)
    }

    /// `--ca`, `--cert`, `--key` of the deployment's client, for a
    /// secured deployment (none otherwise).
    pub(crate) fn client_tls_args(&self) -> Vec<String> {
        self.security
            .iter()
            .flat_map(|s| {
                let file = |name: String| s.certs.join(name).display().to_string();
                [
                    "--ca".to_string(),
                    file("ca.pem".into()),
                    "--cert".into(),
                    file(format!("{}.pem", s.client)),
                    "--key".into(),
                    file(format!("{}.key", s.client)),
                ]
            })
            .collect()
    }

    /// The marginals once the whole stream is in, or panics after `patience`.
    pub fn final_marginals(&self, patience: Duration) -> Value {
        self.answer_when(&["marginals"], patience, |answer| {
            answer["finished"] == true
        })
    }

    /// Waits until the deployment answers a marginals query at all.
    pub fn first_answer(&self, patience: Duration) -> Value {
        self.answer_when(&["marginals"], patience, |_| true)
    }

    /// Asks `question` (e.g. `["identity"]`) until an answer satisfies
    /// `wanted`.
    pub fn answer_when(
        &self,
        question: &[&str],
        patience: Duration,
        wanted: impl Fn(&Value) -> bool,
    ) -> Value {
        let args: Vec<&str> = question
            .iter()
            .copied()
            .chain(["--timeout-ms", "5000"])
            .collect();
        answer_until(patience, || self.query(&args), wanted, || self.log())
    }

    /// Asks `question` (e.g. `marginals`) right after the events before
    /// every truth line, all at once (`--at-events`): the answers, each with
    /// the index of its truth line. Points the stream passed before the
    /// question reached it are refused (stderr).
    pub fn at_truth_points(&self, question: &str, truths: &[Truth]) -> Vec<(usize, Value)> {
        let points: Vec<String> = truths.iter().map(|t| t.events.to_string()).collect();
        self.query_lenient(&[question, "--at-events", &points.join(",")])
            .into_iter()
            .map(|answer| {
                let events = watermark_events(&answer);
                let i = truths
                    .iter()
                    .position(|t| t.events == events)
                    .unwrap_or_else(|| panic!("an answer at {events} events, not a truth point"));
                (i, answer)
            })
            .collect()
    }

    /// Every sensor's counters in `query/stats`, by name.
    pub fn sensor_stats(&self) -> Vec<Value> {
        let stats = self.query(&["stats"]).expect("stats answer");
        stats[0]["sensors"].as_array().expect("sensors").clone()
    }

    /// The coordinator's counter `field` (`idmesh query stats`).
    pub fn coordinator_counter(&self, field: &str) -> u64 {
        let stats = self.query(&["stats"]).expect("stats answer");
        stats[0]["coordinator"][field]
            .as_u64()
            .unwrap_or_else(|| panic!("{field} in {}", stats[0]["coordinator"]))
    }

    /// Every leader's counters (`idmesh query stats`).
    pub fn leader_stats(&self) -> Vec<Value> {
        let stats = self.query(&["stats"]).expect("stats answer");
        stats[0]["leaders"].as_array().expect("leaders").clone()
    }

    /// Leader `name`'s counters.
    pub fn leader(&self, name: &str) -> Value {
        self.leader_stats()
            .into_iter()
            .find(|l| l["leader"] == name)
            .unwrap_or_else(|| panic!("{name} in the stats"))
    }

    /// What each leader applied, by kind: (leader, mixes, observations,
    /// handovers) — cuts excluded, queries place them. Equal to an
    /// undisturbed run's, no event was lost or applied twice.
    pub fn applied(&self) -> Vec<(String, u64, u64, u64)> {
        self.leader_stats()
            .iter()
            .map(|l| {
                (
                    l["leader"].as_str().unwrap().to_string(),
                    l["mixes"].as_u64().unwrap(),
                    l["observations"].as_u64().unwrap(),
                    l["handovers"].as_u64().unwrap(),
                )
            })
            .collect()
    }

    /// The stream's items each leader applied (mixes, observations,
    /// handovers and identity reads; the `Begin` and the cuts that queries
    /// place, which every leader gets, left out).
    pub fn items_per_leader(&self) -> Vec<u64> {
        let count = |l: &Value, field: &str| l[field].as_u64().unwrap_or(0);
        self.leader_stats()
            .iter()
            .map(|l| {
                ["mixes", "observations", "handovers", "identifies"]
                    .iter()
                    .map(|f| count(l, f))
                    .sum()
            })
            .collect()
    }

    /// A counter of `idmesh query stats`, summed over the leaders.
    pub fn leaders_total(&self, field: &str) -> u64 {
        self.leader_stats()
            .iter()
            .map(|l| {
                l[field]
                    .as_u64()
                    .unwrap_or_else(|| panic!("{field} in {l}"))
            })
            .sum()
    }

    /// [`Deployment::leaders_total`] once `wanted` holds of it, or its
    /// last value after `patience` (counters that settle after the stream,
    /// such as what is kept for others).
    pub fn leaders_total_when(
        &self,
        field: &str,
        patience: Duration,
        wanted: impl Fn(u64) -> bool,
    ) -> u64 {
        let started = Instant::now();
        loop {
            let total = self.leaders_total(field);
            if wanted(total) || started.elapsed() > patience {
                return total;
            }
            std::thread::sleep(Duration::from_millis(200));
        }
    }

    pub fn log(&self) -> String {
        std::fs::read_to_string(self.dir.join("up.log")).unwrap_or_default()
    }
}

impl Drop for Deployment {
    fn drop(&mut self) {
        // SIGTERM lets `up` stop its children; then make sure.
        for (_, child) in &self.children {
            unsafe {
                libc::kill(child.id() as i32, libc::SIGTERM);
            }
        }
        let deadline = Instant::now() + Duration::from_secs(10);
        for (_, child) in &mut self.children {
            while Instant::now() < deadline {
                if let Ok(Some(_)) = child.try_wait() {
                    break;
                }
                std::thread::sleep(Duration::from_millis(50));
            }
            let _ = child.kill();
            let _ = child.wait();
        }
        // Kept after a failure, for its logs and state; gone otherwise.
        if !std::thread::panicking() {
            let _ = std::fs::remove_dir_all(&self.dir);
        }
    }
}

/// Whether a `stats` answer shows leader role `role` hosted by the
/// process named `host` (its own, or one that adopted it).
pub fn hosted_on(stats: &Value, role: &str, host: &str) -> bool {
    stats["leaders"]
        .as_array()
        .into_iter()
        .flatten()
        .any(|l| l["leader"] == role && l["host"] == host)
}

/// What `idmesh query --json` printed: its JSON lines, its stderr, and
/// whether it succeeded.
pub(crate) fn query_output(output: &std::process::Output) -> (Vec<Value>, String, bool) {
    let answers = String::from_utf8_lossy(&output.stdout)
        .lines()
        .map(|l| serde_json::from_str(l).expect("query prints JSON"))
        .collect();
    (
        answers,
        String::from_utf8_lossy(&output.stderr).into_owned(),
        output.status.success(),
    )
}

/// Asks (`ask`) every 100 ms until the first reply satisfies `wanted`,
/// or panics after `patience` with the last answer or error and `log()`.
pub(crate) fn answer_until(
    patience: Duration,
    ask: impl Fn() -> Result<Vec<Value>, String>,
    wanted: impl Fn(&Value) -> bool,
    log: impl Fn() -> String,
) -> Value {
    let started = Instant::now();
    let mut last = String::new();
    while started.elapsed() < patience {
        match ask() {
            Ok(replies) if wanted(&replies[0]) => return replies[0].clone(),
            Ok(replies) => last = replies[0]["watermark"].to_string(),
            Err(e) => last = e,
        }
        std::thread::sleep(Duration::from_millis(100));
    }
    panic!(
        "no answer as wanted within {patience:?}; last: {last}\n{}",
        log()
    );
}

/// What every leader applied ([`Deployment::applied`]) when `trace`
/// streams through a deployment with `settings` left alone — its final
/// answer checked against `expected`, the centralized engine's — for a
/// disturbed run of the same to equal.
pub fn undisturbed_applied(
    name: &str,
    trace: &Path,
    settings: &Settings,
    expected: &[f64],
) -> Vec<(String, u64, u64, u64)> {
    let calm = Deployment::start_each(name, trace, settings);
    crate::compare::assert_same_marginals(
        &calm.final_marginals(Duration::from_secs(60)),
        expected,
        "left alone",
    );
    calm.applied()
}

/// The events of a trace (mix, observe, move, identify lines), as text:
/// what a producer feeds a live sensor.
pub fn trace_events(trace: &Path) -> Vec<String> {
    std::fs::read_to_string(trace)
        .unwrap()
        .lines()
        .filter(|l| {
            let v: serde_json::Value = serde_json::from_str(l).unwrap();
            matches!(
                v["kind"].as_str(),
                Some("mix" | "observe" | "move" | "identify")
            )
        })
        .map(str::to_owned)
        .collect()
}

/// A trace of the header of `trace` alone, written into `dir`: a live
/// sensor's field.
pub fn header_only(trace: &Path, dir: &Path) -> PathBuf {
    let text = std::fs::read_to_string(trace).unwrap();
    let header = text.lines().next().unwrap();
    let path = dir.join("header.jsonl");
    std::fs::write(&path, format!("{header}\n")).unwrap();
    path
}

/// `idmesh simulate` a crowd into `dir`.
pub fn crowd(dir: &Path, targets: usize, red: usize, duration: f64, seed: u64) -> PathBuf {
    simulate_crowd(dir, targets, red, duration, seed, false)
}

/// A crowd whose identities are read now and then too (`identify` lines).
pub fn crowd_with_identities(
    dir: &Path,
    targets: usize,
    red: usize,
    duration: f64,
    seed: u64,
) -> PathBuf {
    simulate_crowd(dir, targets, red, duration, seed, true)
}

/// A valid identity trace (version 1) of `tracks` walkers from the known
/// start "track t carries identity t": mixes mostly of neighbours in a
/// ring (as crowds mix), each swapping a hidden truth with its
/// probability; reads of the true identity with their accuracy, of
/// another one otherwise, sure reads (accuracy 1, always true) among
/// them; a truth line every 100 events. Long enough that the factored
/// identity belief cuts groups, and sure reads land on identities its
/// cuts sent elsewhere.
pub fn valid_identity_trace(dir: &Path, tracks: usize, events: usize, seed: u64) -> PathBuf {
    use rand::{Rng, SeedableRng};
    use std::fmt::Write as _;
    std::fs::create_dir_all(dir).unwrap();
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
    let n = tracks as u32;
    let mut truth: Vec<u32> = (0..n).collect();
    let mut text = serde_json::json!({
        "kind": "header", "format": "idmesh-trace", "version": 1,
        "tracks": tracks, "identities": tracks, "initial_identity": truth,
    })
    .to_string();
    text.push('\n');
    for e in 0..events {
        let time = (e / 10) as f64;
        if e % 100 == 0 {
            let line = serde_json::json!({"kind": "truth", "time": time, "identity": truth});
            writeln!(text, "{line}").unwrap();
        }
        let line = if rng.gen_bool(0.7) {
            let a = rng.gen_range(0..n);
            let b = (a + rng.gen_range(1..4)) % n;
            let swap = [0.5, 0.5, 0.3, 0.9, 1.0][rng.gen_range(0..5)];
            if rng.gen_bool(swap) {
                truth.swap(a as usize, b as usize);
            }
            serde_json::json!({"kind": "mix", "time": time, "a": a, "b": b, "swap": swap})
        } else {
            let track = rng.gen_range(0..n);
            let accuracy = [1.0, 1.0, 0.9, 0.7][rng.gen_range(0..4)];
            let identity = if accuracy >= 1.0 || rng.gen_bool(accuracy) {
                truth[track as usize]
            } else {
                (truth[track as usize] + rng.gen_range(1..n)) % n
            };
            serde_json::json!({"kind": "identify", "time": time, "track": track,
                "identity": identity, "accuracy": accuracy})
        };
        writeln!(text, "{line}").unwrap();
    }
    let line =
        serde_json::json!({"kind": "truth", "time": (events / 10) as f64, "identity": truth});
    writeln!(text, "{line}").unwrap();
    let out = dir.join(format!("valid-identities-{tracks}-{events}-{seed}.jsonl"));
    std::fs::write(&out, text).unwrap();
    out
}

fn simulate_crowd(
    dir: &Path,
    targets: usize,
    red: usize,
    duration: f64,
    seed: u64,
    identities: bool,
) -> PathBuf {
    std::fs::create_dir_all(dir).unwrap();
    let kind = if identities {
        "identity-crowd"
    } else {
        "crowd"
    };
    let out = dir.join(format!("{kind}-{targets}-{red}-{seed}.jsonl"));
    let (targets, red) = (targets.to_string(), red.to_string());
    let (duration, seed) = (duration.to_string(), seed.to_string());
    let mut args = vec!["--model", "crowd", "--targets", &targets, "--red", &red];
    args.extend(identities.then_some("--identities"));
    args.extend(["--duration", &duration, "--seed", &seed]);
    simulate(&args, out)
}

/// `idmesh simulate ARGS --out OUT`, which must succeed: OUT.
fn simulate(args: &[&str], out: PathBuf) -> PathBuf {
    let status = Command::new(idmesh())
        .arg("simulate")
        .args(args)
        .arg("--out")
        .arg(&out)
        .stderr(Stdio::null())
        .status()
        .expect("simulate runs");
    assert!(status.success(), "idmesh simulate {args:?} failed");
    out
}

/// A random-waypoint crowd (`idmesh simulate --model waypoint`), denser
/// in the middle of its field than at the edges, stopped after `events`
/// mix and observe events.
pub fn waypoint_crowd(dir: &Path, targets: usize, red: usize, events: u64, seed: u64) -> PathBuf {
    std::fs::create_dir_all(dir).unwrap();
    let out = dir.join(format!("waypoint-{targets}-{red}-{seed}.jsonl"));
    let (targets, red) = (targets.to_string(), red.to_string());
    let (events, seed) = (events.to_string(), seed.to_string());
    simulate(
        &[
            "--model",
            "waypoint",
            "--targets",
            &targets,
            "--red",
            &red,
            "--events",
            &events,
            "--seed",
            &seed,
        ],
        out,
    )
}

/// The summary line of `idmesh replay` on `trace` with `args`.
pub fn replay_summary(trace: &Path, args: &[&str]) -> Value {
    replay(trace, args).pop().expect("a summary line")
}

/// The answers of `idmesh replay` at the truth lines, summary left out.
pub fn replay_lines(trace: &Path, args: &[&str]) -> Vec<Value> {
    let mut lines = replay(trace, args);
    lines.pop();
    lines
}

fn replay(trace: &Path, args: &[&str]) -> Vec<Value> {
    let output = Command::new(idmesh())
        .arg("replay")
        .arg("--trace")
        .arg(trace)
        .args(args)
        .output()
        .expect("replay runs");
    assert!(
        output.status.success(),
        "{}",
        String::from_utf8_lossy(&output.stderr)
    );
    String::from_utf8_lossy(&output.stdout)
        .lines()
        .map(|l| serde_json::from_str(l).expect("replay prints JSON lines"))
        .collect()
}

/// A truth line of a trace, and how many events (the lines the sensor
/// counts: mix, observe, move, identify) precede it.
pub struct Truth {
    pub events: u64,
    pub line: Value,
}

pub fn truth_lines(trace: &Path) -> Vec<Truth> {
    let text = std::fs::read_to_string(trace).unwrap();
    let mut events = 0;
    let mut truths = Vec::new();
    for line in text.lines() {
        let v: Value = serde_json::from_str(line).unwrap();
        match v["kind"].as_str() {
            Some("mix" | "observe" | "move" | "identify") => events += 1,
            Some("truth") => truths.push(Truth { events, line: v }),
            _ => {}
        }
    }
    truths
}
