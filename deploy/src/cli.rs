//! The command line: one subcommand per role idmesh plays. Parsing only;
//! what a subcommand does lives in its own module.

use crate::runtime::topology::BeliefKind;
use crate::runtime::web::MarkerOptions;
use clap::{Args, Parser, Subcommand, ValueEnum};
use idmesh_eval::eval::EvalArgs;
use idmesh_eval::replay::MarginalChoice;
use idmesh_eval::replay::ReplayArgs;
use std::path::PathBuf;

/// idmesh keeps track of who is who among moving targets: a belief over
/// which tracks carry a property, answered on demand.
#[derive(Debug, Parser)]
#[command(name = "idmesh", version, about, long_about = None)]
pub struct Cli {
    #[command(subcommand)]
    pub command: Command,
}

#[derive(Debug, Subcommand)]
pub enum Command {
    /// Replay a trace through one filter offline: one JSON line with the
    /// answers at every `truth` line, then a summary line.
    Replay(ReplayCommand),
    /// Simulate targets moving in a field (or replay real pedestrians) and
    /// write the sensors' events as a trace.
    Simulate(SimulateArgs),
    /// Turn what a tracker reports (positions, class scores, identity
    /// reads) into events: read MOTChallenge, ETH/UCY or JSON-lines input
    /// and write a version-2 trace of mix, observe, identify and move lines.
    Extract(ExtractArgs),
    /// Track indistinguishable targets from the summed sound the sensors
    /// hear (blind source separation) and write the recovered paths and
    /// their mixes as a trace.
    Acoustic(AcousticArgs),
    /// Run the evaluation grid (methods × scenarios on both cores): print
    /// the tables, write results.md and the SVG plots to --out-dir.
    Eval(EvalArgs),
    /// Run the sensor gateway of a topology: stream its trace (or standard
    /// input) to the leaders, with what producers send on its ingest key.
    Sensor(SensorArgs),
    /// Run a leader of a topology.
    Leader(RoleArgs),
    /// Run the coordinator of a topology: answer queries.
    Coordinator(RoleArgs),
    /// Run a voter of a topology: one member of the group that decides
    /// who holds each role.
    Voter(RoleArgs),
    /// Run a sensor's standby of a topology: keep a copy of the sensor's
    /// journal and, with voters, take the sensor role over when the
    /// sensor's host is lost.
    SensorStandby(RoleArgs),
    /// Start every process of a topology on this host; Ctrl-C stops them.
    Up(UpArgs),
    /// A coordinator, four leaders and a sensor on loopback, streaming a
    /// simulated crowd, with live answers; the coordinator listens on
    /// tcp/127.0.0.1:7447.
    Demo(DemoArgs),
    /// Ask a running deployment: marginals, one track, identities, or the
    /// processes' counters.
    Query(QueryArgs),
    /// Serve a running deployment over HTTP: REST and Server-Sent Events
    /// over the query API, the live map at /, Prometheus metrics at
    /// /metrics, /healthz and /readyz.
    Web(WebArgs),
    /// Measure the distributed runtime on loopback: events/s through 1, 2,
    /// 4 leaders, bytes per leader, and marginals latency against the raw
    /// Zenoh round trip; prints Markdown.
    Bench(BenchArgs),
}

/// `idmesh replay`: the offline tools' arguments, and what only a
/// deployment's twin reads.
#[derive(Debug, Clone, Args)]
#[command(allow_negative_numbers = true)]
pub struct ReplayCommand {
    #[command(flatten)]
    pub args: ReplayArgs,
    /// With --topology of sensors that extract: bad lines of the reports
    /// skipped (each named on stderr and counted) before the next one
    /// stops the replay, as the sensor counts them; default: the
    /// topology's `max_errors` (0: the first bad line stops it).
    #[arg(long, value_name = "N", requires = "topology")]
    pub max_errors: Option<usize>,
}

#[derive(Debug, Clone, Args)]
#[command(allow_negative_numbers = true)]
pub struct BenchArgs {
    /// n, the targets of the simulated crowd.
    #[arg(long, default_value_t = 40)]
    pub targets: usize,
    /// k, how many of them are red.
    #[arg(long, default_value_t = 10)]
    pub red: usize,
    /// Seconds of simulated crowd (the stream's length; the default,
    /// about 1.4 million events, keeps each leader busy for seconds, so
    /// that its CPU time is its work and not its process's upkeep, and
    /// takes fitted regions through many redraws).
    #[arg(long, default_value_t = 30000.0)]
    pub duration: f64,
    /// The crowd simulation's seed.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Leader counts to stream through, comma-separated.
    #[arg(long, value_delimiter = ',', default_value = "1,2,4,8")]
    pub leaders: Vec<usize>,
    /// The leaders' belief: factored (components, coupled at a query) or
    /// radon (sets, with --budget and the distributed rule).
    #[arg(long, value_enum, default_value = "factored")]
    pub belief: BeliefKind,
    /// Flow control, per leader: with L leaders the sensor routes at most
    /// L times this many items past the slowest leader's progress (the
    /// topology's `[sensor] window`), so that each leader has about as
    /// many in flight whatever L; absent = no window.
    #[arg(long)]
    pub window: Option<u64>,
    /// Sets per leader (the Radon belief).
    #[arg(long, default_value_t = 400)]
    pub budget: u32,
    /// Streams per leader count, in rounds (1, 2, 4, 1, 2, 4, …); the
    /// report gives the one with the median leaders' CPU, since this
    /// machine's CPU seconds vary by a fifth between runs.
    #[arg(long, default_value_t = 1)]
    pub repeat: usize,
    /// Marginals queries (and as many raw gets of each kind) for latency;
    /// 0: no latency figures (the streams' throughput and CPU alone).
    #[arg(long, default_value_t = 2000)]
    pub queries: usize,
    /// Events per second of the stream that queries are timed during.
    #[arg(long, default_value_t = 2000.0)]
    pub stream_rate: f64,
    /// Where the trace and topologies are written.
    #[arg(long, default_value = "target/idmesh-bench")]
    pub dir: PathBuf,
    /// Also write a results page here: the report as printed, after a
    /// title, the command that regenerates it, the stamp of the code, the
    /// machine, the date, the wall time and the settings. With
    /// --accuracy: the accuracy report alone (docs/live-accuracy.md, which
    /// `idmesh eval` reads back).
    #[arg(long)]
    pub out: Option<PathBuf>,
    /// Only the ingestion figures: one producer on a live sensor's ingest
    /// key, against the raw round trip to the sensor.
    #[arg(long)]
    pub ingest: bool,
    /// The sensor and the leaders journal what they take (`state_dir` in
    /// the bench's folder), so the figures include the fsyncs.
    #[arg(long)]
    pub journal: bool,
    /// Only the accuracy figure: the live answers' tracking error on the
    /// Table III crowds (four leaders, factored and Radon, asked at every
    /// truth line) against the centralized engine's.
    #[arg(long, conflicts_with = "ingest")]
    pub accuracy: bool,
    /// Only the extraction figures: reports a sensor turns into events per
    /// second (1,000 to 100,000 tracks), and the latency from a position
    /// to the first answer with its mix, against the raw round trip.
    #[arg(long, conflicts_with_all = ["ingest", "accuracy"])]
    pub extraction: bool,
    /// Only the identity figures: the default identity belief on crowds of
    /// 1,000 and 10,000 people with identities, offline (as `idmesh
    /// replay`) and through four leaders: memory, query time, the answer's
    /// size, and the live answer against the offline one.
    #[arg(long, conflicts_with_all = ["ingest", "accuracy", "extraction"])]
    pub identity: bool,
    /// Only the replication figures: three journaling leaders with their
    /// standbys off and on, in alternating rounds (--repeat): events per
    /// second, and the leaders' bytes sent and fsyncs per event.
    #[arg(long, conflicts_with_all = ["ingest", "accuracy", "extraction", "identity"])]
    pub replication: bool,
    /// With --accuracy: the Table III n to run, comma-separated.
    #[arg(
        long,
        value_delimiter = ',',
        default_value = "20,60,100",
        requires = "accuracy"
    )]
    pub sizes: Vec<usize>,
    /// With --accuracy: the starts to run, comma-separated.
    #[arg(
        long,
        value_enum,
        value_delimiter = ',',
        default_value = "known,uniform",
        requires = "accuracy"
    )]
    pub starts: Vec<idmesh_eval::eval::Start>,
    /// With --accuracy: seeds per point (the evaluation's seeds 0, 1, …).
    #[arg(long, default_value_t = 1, value_parser = clap::value_parser!(u64).range(1..), requires = "accuracy")]
    pub seeds: u64,
}

#[derive(Debug, Clone, Args)]
#[command(allow_negative_numbers = true)]
pub struct RoleArgs {
    /// The topology file.
    #[arg(long)]
    pub config: PathBuf,
    /// This process's name in it.
    #[arg(long)]
    pub name: String,
}

#[derive(Debug, Clone, Args)]
#[command(allow_negative_numbers = true)]
pub struct SensorArgs {
    #[command(flatten)]
    pub role: RoleArgs,
    /// Read the trace from standard input (a pipe, `tail -f`) instead of
    /// the topology's `trace` file: the header first, then events as they
    /// come; a bad line is skipped and counted. The stream ends with the
    /// input, unless the topology's sensor is `live`.
    #[arg(long)]
    pub stdin: bool,
    /// Bad lines of its input (standard input, or a trace of reports)
    /// skipped, each named in the log and counted, before the next one
    /// stops the sensor; default: the topology's `max_errors` (0: the
    /// first bad line stops it). Producers on the ingest key are answered
    /// line by line instead.
    #[arg(long, value_name = "N")]
    pub max_errors: Option<usize>,
}

#[derive(Debug, Clone, Args)]
#[command(allow_negative_numbers = true)]
pub struct UpArgs {
    /// The topology file (see deploy/examples/ and
    /// deploy/src/runtime/topology.rs).
    #[arg(long)]
    pub config: PathBuf,
    /// Start only the processes of this host (default: all); with --emit,
    /// write only this host's units.
    #[arg(long)]
    pub host: Option<String>,
    /// Start nothing: write what runs the processes instead. `--emit
    /// systemd DIR` writes, for each host of the topology, DIR/<host>/ with
    /// an idmesh-<name>.service per process (the command line `up` runs it
    /// with; restarted on failure), an idmesh.target that groups them, and
    /// config/, the folder to copy to --config-dir (docs/guide/lan.md).
    #[arg(long, num_args = 2, value_names = ["KIND", "DIR"])]
    pub emit: Option<Vec<String>>,
    /// With --emit: the idmesh binary the units run, an absolute path as
    /// the hosts have it (default /usr/local/bin/idmesh).
    #[arg(long, value_name = "PATH", requires = "emit")]
    pub binary: Option<PathBuf>,
    /// With --emit: the folder, an absolute path, where each host keeps
    /// the topology file and what it names, which the units read (default
    /// /etc/idmesh).
    #[arg(long, value_name = "DIR", requires = "emit")]
    pub config_dir: Option<PathBuf>,
}

#[derive(Debug, Clone, Args)]
#[command(allow_negative_numbers = true)]
pub struct DemoArgs {
    /// Stop streaming after this many events (queries go on until Ctrl-C).
    #[arg(long)]
    pub events: Option<u64>,
    /// n, the targets of the simulated crowd.
    #[arg(long, default_value_t = 40)]
    pub targets: usize,
    /// k, how many of them are red.
    #[arg(long, default_value_t = 10)]
    pub red: usize,
    /// The crowd simulation's seed.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Events per second the sensor streams.
    #[arg(long, default_value_t = 200.0)]
    pub rate: f64,
    /// Where the simulated trace and the topology are written.
    #[arg(long, default_value = "target/idmesh-demo")]
    pub dir: PathBuf,
    /// Where the live map and HTTP API listen ("off": not at all).
    #[arg(long, default_value = "127.0.0.1:8080")]
    pub web: String,
    /// The web gateway's ROS 2 markers, as `idmesh web` takes them.
    #[command(flatten)]
    pub markers: MarkerOptions,
}

impl DemoArgs {
    pub fn options(&self) -> anyhow::Result<crate::runtime::launch::DemoOptions> {
        let web = (self.web != "off").then(|| self.web.clone());
        let markers = self.markers.config(flag)?;
        if web.is_none() && markers.is_some() {
            anyhow::bail!("--ros2-markers: the web gateway publishes them, and --web off has none");
        }
        Ok(crate::runtime::launch::DemoOptions {
            events: self.events,
            targets: self.targets,
            red: self.red,
            seed: self.seed,
            rate: self.rate,
            dir: self.dir.clone(),
            web,
            markers,
        })
    }
}

#[derive(Debug, Clone, Args)]
#[command(allow_negative_numbers = true)]
pub struct QueryArgs {
    /// What to ask: marginals | track | identity | positions | stats.
    pub what: String,
    /// The track, for `track` (needed) and `identity` (optional: one track's
    /// identities instead of every track's).
    pub track: Option<u32>,
    /// How `identity` turns the information matrix into marginals (default:
    /// exact up to 16 tracks, auto beyond: exact, half-Bethe or Metropolis
    /// block by block).
    #[arg(long, value_enum)]
    pub marginals: Option<MarginalChoice>,
    /// Counted Metropolis steps per block, for `--marginals metropolis`
    /// (default 10,000): more when the answer says the chain has not mixed.
    #[arg(long)]
    pub samples: Option<u64>,
    /// The coordinator's endpoint; or every coordinator's, separated by
    /// commas (the first and its replicas), so that another answers when
    /// one is gone.
    #[arg(long, default_value = "tcp/127.0.0.1:7447")]
    pub connect: String,
    /// The deployment's key prefix (the topology's `prefix`).
    #[arg(long, default_value = idmesh_protocol::wire::keys::DEFAULT_PREFIX)]
    pub prefix: String,
    /// Print the JSON reply as it came.
    #[arg(long)]
    pub json: bool,
    /// How long to wait for the coordinator; longer than its own query
    /// timeout, so that its "degraded" answer arrives rather than none.
    #[arg(long, default_value_t = 15000)]
    pub timeout_ms: u64,
    /// Ask this many times, --interval-ms apart.
    #[arg(long, default_value_t = 1)]
    pub repeat: u32,
    /// Answers right after these event counts of the stream (comma-separated;
    /// all asked at once, each waits for its point; a point already passed
    /// is an error). For marginals, track and identity.
    #[arg(long, value_delimiter = ',')]
    pub at_events: Vec<u64>,
    /// Milliseconds between the answers of --repeat.
    #[arg(long, default_value_t = 1000)]
    pub interval_ms: u64,
    #[command(flatten)]
    pub tls: ClientTlsArgs,
}

impl QueryArgs {
    pub fn options(&self) -> anyhow::Result<crate::runtime::query::QueryOptions> {
        use crate::runtime::query::{QueryOptions, Question};
        let what = match (self.what.as_str(), self.track) {
            ("marginals", None) => Question::Marginals,
            ("stats", None) => Question::Stats,
            ("roles", None) => Question::Roles,
            ("positions", None) => Question::Positions,
            ("track", Some(t)) => Question::Track(t),
            ("identity", track) => Question::Identity(track),
            ("track", None) => {
                anyhow::bail!("query track needs a track number: idmesh query track 12")
            }
            (other, _) => {
                anyhow::bail!(
                    "unknown query {other:?}: marginals, track T, identity [T], positions, stats or roles"
                )
            }
        };
        if matches!(
            what,
            Question::Stats | Question::Positions | Question::Roles
        ) && !self.at_events.is_empty()
        {
            anyhow::bail!("--at-events is for marginals, track and identity");
        }
        if self.marginals.is_some() && !matches!(what, Question::Identity(_)) {
            anyhow::bail!("--marginals is for identity queries");
        }
        if self.samples.is_some() && self.marginals != Some(MarginalChoice::Metropolis) {
            anyhow::bail!("--samples is for --marginals metropolis");
        }
        Ok(QueryOptions {
            what,
            connect: self.connect.clone(),
            prefix: self.prefix.clone(),
            json: self.json,
            timeout: std::time::Duration::from_millis(self.timeout_ms),
            repeat: self.repeat,
            interval: std::time::Duration::from_millis(self.interval_ms),
            at_events: self.at_events.clone(),
            marginals: self.marginals.map(|m| m.name().to_string()),
            samples: self.samples,
            tls: self.tls.tls()?,
        })
    }
}

/// How a client (`idmesh query`, `idmesh web`) shows itself to a secured
/// deployment: none of these for a plain one.
#[derive(Debug, Clone, Args)]
pub struct ClientTlsArgs {
    /// A secured deployment: the CA certificate of its `[security] certs`.
    #[arg(long)]
    pub ca: Option<PathBuf>,
    /// This client's certificate (its common name listed in `[security]
    /// clients`); the endpoint is then reached over TLS.
    #[arg(long)]
    pub cert: Option<PathBuf>,
    /// This client's private key.
    #[arg(long)]
    pub key: Option<PathBuf>,
}

impl ClientTlsArgs {
    pub fn tls(&self) -> anyhow::Result<Option<crate::runtime::security::Tls>> {
        Ok(crate::runtime::security::Tls::from_options(
            self.ca.as_deref(),
            self.cert.as_deref(),
            self.key.as_deref(),
        )?)
    }
}

#[derive(Debug, Clone, Args)]
pub struct WebArgs {
    /// Where the HTTP server listens (port 0: any free port; the address
    /// is printed).
    #[arg(long, default_value = "127.0.0.1:8080")]
    pub listen: String,
    /// The coordinator's endpoint; or every coordinator's, separated by
    /// commas (the first and its replicas), so that another answers when
    /// one is gone.
    #[arg(long, default_value = "tcp/127.0.0.1:7447")]
    pub connect: String,
    /// The deployment's key prefix (the topology's `prefix`).
    #[arg(long, default_value = idmesh_protocol::wire::keys::DEFAULT_PREFIX)]
    pub prefix: String,
    /// How long one question may wait for the coordinator.
    #[arg(long, default_value_t = 15000)]
    pub timeout_ms: u64,
    #[command(flatten)]
    pub markers: MarkerOptions,
    #[command(flatten)]
    pub tls: ClientTlsArgs,
}

/// A field of [`MarkerOptions`] as the command line spells it
/// (`ros2_rate` is `--ros2-rate`).
fn flag(field: &str) -> String {
    format!("--{}", field.replace('_', "-"))
}

impl WebArgs {
    pub fn options(&self) -> anyhow::Result<crate::runtime::web::WebOptions> {
        Ok(crate::runtime::web::WebOptions {
            listen: self.listen.clone(),
            connect: self.connect.clone(),
            prefix: self.prefix.clone(),
            timeout: std::time::Duration::from_millis(self.timeout_ms),
            tls: self.tls.tls()?,
            markers: self.markers.config(flag)?,
        })
    }
}

#[derive(Debug, Clone, Args)]
#[command(allow_negative_numbers = true)]
pub struct SimulateArgs {
    /// The motion model.
    #[arg(long, value_enum, default_value_t = Motion::Crowd)]
    pub model: Motion,
    /// For `--model pedestrians`: a scene file of shared/data/pedestrians
    /// (obsmat.txt or one of the 4-column files).
    #[arg(long, value_name = "FILE", required_if_eq("model", "pedestrians"))]
    pub scene: Option<PathBuf>,
    /// n, the number of targets (pedestrians: a cap on the people taken).
    #[arg(long)]
    pub targets: Option<usize>,
    /// k, the number of red targets (default n/2).
    #[arg(long)]
    pub red: Option<usize>,
    /// Seconds of motion (default 300; pedestrians: to the end of the scene).
    #[arg(long, conflicts_with = "events")]
    pub duration: Option<f64>,
    /// Stop after this many mix + observe events instead.
    #[arg(long)]
    pub events: Option<usize>,
    /// Two targets closer than this (metres) mix.
    #[arg(long)]
    pub mix_distance: Option<f64>,
    /// A target farther than this (metres) from every other is observed.
    #[arg(long)]
    pub observe_distance: Option<f64>,
    /// How likely a meeting is to exchange the two targets' tracks.
    #[command(flatten)]
    pub meetings: MeetingArgs,
    /// Seconds between `truth` lines.
    #[arg(long)]
    pub truth_interval: Option<f64>,
    /// Leave the initial red tracks out of the header (uniform prior).
    #[arg(long)]
    pub hide_initial: bool,
    /// Also write identity reads (`identify` lines) and true identities:
    /// an identity trace for the identity methods of replay.
    #[arg(long)]
    pub identities: bool,
    /// Accuracy of an identity read (with --identities).
    #[arg(long, default_value_t = 0.9)]
    pub identity_accuracy: f64,
    /// The simulation's seed: the same seed, the same trace.
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// Where to write the trace.
    #[arg(long, value_name = "FILE")]
    pub out: PathBuf,
    /// Also write what the simulated tracker reported (a version-2 trace
    /// of `detect` lines: every track's position each step, class scores
    /// where the sensor saw a colour): `idmesh extract` with the same
    /// distances and meeting model turns it into this trace's events.
    #[arg(long, value_name = "FILE")]
    pub tracker_output: Option<PathBuf>,
}

/// The meeting model, shared by `simulate` (which draws swaps with it)
/// and `extract` (which writes its probability on each mix).
#[derive(Debug, Clone, Args)]
#[command(allow_negative_numbers = true)]
pub struct MeetingArgs {
    /// The meeting model: a constant swap probability, or one from the
    /// closest distance and relative speed of the meeting.
    #[arg(long, value_enum, default_value_t = MeetingChoice::Constant)]
    pub meeting_model: MeetingChoice,
    /// constant: the swap probability of every meeting.
    #[arg(long, default_value_t = 0.5)]
    pub swap: f64,
    /// approach: the swap probability of a standing, touching pair.
    #[arg(long, default_value_t = 0.5)]
    pub p_max: f64,
    /// approach: metres over which confusion falls with closest distance.
    #[arg(long, default_value_t = 0.5)]
    pub sigma: f64,
    /// approach: the relative speed (m/s) at which confusion halves.
    #[arg(long, default_value_t = 1.0)]
    pub v0: f64,
}

impl MeetingArgs {
    pub fn model(&self) -> idmesh_extract::MeetingModel {
        use idmesh_extract::MeetingModel;
        match self.meeting_model {
            MeetingChoice::Constant => MeetingModel::Constant(self.swap),
            MeetingChoice::Approach => MeetingModel::Approach {
                p_max: self.p_max,
                sigma: self.sigma,
                v0: self.v0,
            },
        }
    }
}

#[derive(Debug, Clone, Args)]
#[command(allow_negative_numbers = true)]
pub struct ExtractArgs {
    /// The tracker's output; standard input when absent or `-`.
    #[arg(value_name = "INPUT")]
    pub input: Option<PathBuf>,
    /// The input's format.
    #[arg(long, value_enum, default_value_t = ReportFormat::Jsonl)]
    pub format: ReportFormat,
    /// Frames per second: frame f is at f / fps seconds (mot, obsmat,
    /// biwi; ETH's obsmat is at 15, the other ETH/UCY files at 25).
    #[arg(long)]
    pub fps: Option<f64>,
    /// mot: metres per pixel, from the box's bottom centre; rosbag2:
    /// metres per unit of the messages' positions (default 1).
    #[arg(long, conflicts_with = "homography")]
    pub scale: Option<f64>,
    /// rosbag2: read this topic only (default: every topic of a type the
    /// adapter reads).
    #[arg(long, value_name = "TOPIC")]
    pub topic: Option<String>,
    /// mot: a 3x3 homography from pixels to metres (ETH/UCY H.txt format).
    #[arg(long, value_name = "H.txt")]
    pub homography: Option<PathBuf>,
    /// Which tracks there are: every id of the input (a first pass over the
    /// file), or the ids of the first frame (default for jsonl without a
    /// header, and for mot on standard input).
    #[arg(long, value_enum)]
    pub roster: Option<RosterChoice>,
    /// k, the number of red targets: the trace's header declares it, and
    /// the belief starts from k/n (a tracker's output does not say it;
    /// without it replay starts every track at one half).
    #[arg(long, value_name = "K")]
    pub red: Option<usize>,
    /// mot: class scores and identity reads of the boxes, from a file of
    /// JSON lines keyed by frame and track id, in frame order
    /// (`{"frame":12,"id":3,"scores":{"red":0.8,"blue":0.2}}`,
    /// `"identity":2,"accuracy":0.9`).
    #[arg(long, value_name = "FILE")]
    pub reads: Option<PathBuf>,
    /// mot, nine-column rows (`…,conf,class,visibility`): the label of a
    /// MOTChallenge class id, `ID=LABEL` (repeatable, or comma-separated);
    /// its boxes score (1 + visibility) / 2 for it.
    #[arg(long, value_name = "ID=LABEL", value_delimiter = ',', value_parser = parse_class_label)]
    pub class_label: Vec<(u32, String)>,
    /// mot: how many frames a row may come behind the latest frame read
    /// (rows are read in frame order, never the whole file at once).
    #[arg(long, value_name = "FRAMES", default_value_t = idmesh_extract::adapters::mot::DEFAULT_WINDOW)]
    pub reorder_window: u64,
    /// Two tracks closer than this (metres) meet.
    #[arg(long, default_value_t = 1.0)]
    pub mix_distance: f64,
    /// A pair meets again only after parting beyond this times the mixing
    /// distance (>= 1).
    #[arg(long, default_value_t = 1.25)]
    pub release_factor: f64,
    /// A track farther than this (metres) from every other is observed.
    #[arg(long, default_value_t = 3.5)]
    pub observe_distance: f64,
    /// At most one observation per track per this many seconds.
    #[arg(long, default_value_t = 3.0)]
    pub observe_interval: f64,
    #[command(flatten)]
    pub meetings: MeetingArgs,
    /// The class label of the property (its score becomes the red
    /// likelihood).
    #[arg(long, default_value = "red")]
    pub label: String,
    /// The temperature of the score mapping (1: scores are calibrated).
    #[arg(long, default_value_t = 1.0)]
    pub temperature: f64,
    /// Seconds between move lines (0: every frame).
    #[arg(long, default_value_t = 1.0)]
    pub move_interval: f64,
    /// Write no move lines.
    #[arg(long)]
    pub no_moves: bool,
    /// Identity reads are expected: the header declares one identity per
    /// track (a jsonl header with identities turns this on too).
    #[arg(long)]
    pub identities: bool,
    /// Bad rows skipped, each named on stderr and counted, before the next
    /// one stops the run; with the default 0 the first bad row stops it
    /// (as a sensor and `idmesh replay --topology` count theirs).
    #[arg(long, value_name = "N", default_value_t = 0)]
    pub max_errors: usize,
    /// Where to write the trace; standard output when absent.
    #[arg(long, value_name = "FILE")]
    pub out: Option<PathBuf>,
}

/// `ID=LABEL`: a MOTChallenge class id and its label.
fn parse_class_label(text: &str) -> Result<(u32, String), String> {
    let (id, label) = text
        .split_once('=')
        .ok_or_else(|| format!("expected ID=LABEL (e.g. 1=red), got {text:?}"))?;
    let id = id
        .trim()
        .parse()
        .map_err(|_| format!("class id {id:?} is not a whole number"))?;
    let label = label.trim();
    if label.is_empty() {
        return Err(format!("no label for class {id}"));
    }
    Ok((id, label.to_string()))
}

/// Input formats of `extract`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum ReportFormat {
    /// MOTChallenge results: frame,id,bb_left,bb_top,bb_width,bb_height,conf,x,y,z.
    Mot,
    /// ETH/UCY obsmat: frame ped_id pos_x pos_z pos_y v_x v_z v_y.
    Obsmat,
    /// ETH/UCY four columns: frame ped_id x y.
    Biwi,
    /// One move or detect trace line per line, an optional header first.
    Jsonl,
    /// A rosbag2 bag in MCAP of vision_msgs Detection2DArray /
    /// Detection3DArray or Autoware TrackedObjects messages.
    Rosbag2,
}

/// Roster policies of `extract`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum RosterChoice {
    /// Every id in the input.
    All,
    /// The ids of the first frame; a later newcomer is a bad row.
    FirstFrame,
}

/// Meeting models of `extract`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum MeetingChoice {
    /// --swap for every meeting.
    Constant,
    /// p_max · exp(−closest² / 2σ²) · v0 / (v0 + relative speed).
    Approach,
}

#[derive(Debug, Clone, Args)]
#[command(allow_negative_numbers = true)]
pub struct AcousticArgs {
    /// How many acoustic sensors are deployed at random in the field.
    #[arg(long, default_value_t = 1000)]
    pub sensors: usize,
    /// How many targets move and emit sound.
    #[arg(long, default_value_t = 10)]
    pub targets: usize,
    /// Zigzag paths instead of random straight legs.
    #[arg(long)]
    pub zigzag: bool,
    /// The simulation's seed: the same seed, the same trace.
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// Where to write the trace.
    #[arg(long, value_name = "FILE")]
    pub out: PathBuf,
}

/// Motion models of `simulate`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum Motion {
    /// A social-force crowd, dense and interacting.
    Crowd,
    /// Random waypoint with pauses.
    Waypoint,
    /// Real pedestrian trajectories (--scene).
    Pedestrians,
}

#[cfg(test)]
mod tests {
    use super::*;
    use clap::CommandFactory;
    use idmesh_eval::eval::Preset;
    use idmesh_eval::replay::Method;

    #[test]
    fn the_command_line_is_well_formed() {
        Cli::command().debug_assert();
    }

    #[test]
    fn every_option_of_every_subcommand_says_what_it_is() {
        let mut undescribed = Vec::new();
        for sub in Cli::command().get_subcommands() {
            if sub.get_about().is_none() {
                undescribed.push(sub.get_name().to_string());
            }
            for arg in sub.get_arguments() {
                let id = arg.get_id().as_str();
                if id != "help" && id != "version" && arg.get_help().is_none() {
                    undescribed.push(format!("{} {id}", sub.get_name()));
                }
            }
        }
        assert!(undescribed.is_empty(), "no --help text: {undescribed:?}");
    }

    #[test]
    fn a_negative_number_is_refused_by_name_not_taken_for_a_flag() {
        for (args, wanted) in [
            (
                &["idmesh", "replay", "--trace", "t", "--budget", "-3"][..],
                "expected a whole number of coefficients (1 or more), got \"-3\"",
            ),
            (
                &["idmesh", "replay", "--trace", "t", "--particles", "-1"],
                "expected a whole number of particles (1 or more), got \"-1\"",
            ),
            (&["idmesh", "eval", "--jobs", "-1"], "-1"),
            (&["idmesh", "demo", "--targets", "-5"], "-5"),
            (&["idmesh", "query", "track", "-2"], "-2"),
        ] {
            let error = Cli::try_parse_from(args).unwrap_err().to_string();
            assert!(
                !error.contains("unexpected argument") && error.contains(wanted),
                "{args:?}: {error}"
            );
        }
    }

    #[test]
    fn method_names_match_the_command_line() {
        for method in Method::value_variants() {
            let value = method.to_possible_value().unwrap();
            assert_eq!(value.get_name(), method.name());
        }
    }

    /// `idmesh web` and `idmesh demo` take the same marker flags, checked
    /// alike, the error naming the flag.
    #[test]
    fn web_and_demo_take_the_same_marker_flags() {
        let flags = [
            "--ros2-markers",
            "/idmesh/markers",
            "--ros2-rate",
            "4",
            "--ros2-humble",
        ];
        let web = Cli::try_parse_from(["idmesh", "web"].into_iter().chain(flags)).unwrap();
        let demo = Cli::try_parse_from(["idmesh", "demo"].into_iter().chain(flags)).unwrap();
        let (Command::Web(web), Command::Demo(demo)) = (web.command, demo.command) else {
            panic!("parsed as web and demo")
        };
        assert_eq!(web.markers, demo.markers);
        let markers = demo.options().unwrap().markers.expect("markers asked for");
        assert_eq!(markers.every, std::time::Duration::from_millis(250));
        assert!(markers.humble);
        assert!(web.options().unwrap().markers.is_some());
        let error = |args: &[&str]| {
            let cli = Cli::try_parse_from(args).unwrap();
            match cli.command {
                Command::Web(web) => web.options().map(|_| ()),
                Command::Demo(demo) => demo.options().map(|_| ()),
                _ => panic!("web or demo"),
            }
            .unwrap_err()
            .to_string()
        };
        let e = error(&["idmesh", "demo", "--ros2-markers", "/m", "--ros2-rate", "0"]);
        assert!(e.starts_with("--ros2-rate must be"), "{e}");
        let e = error(&["idmesh", "web", "--ros2-frame", "odom"]);
        assert!(e.starts_with("--ros2-frame sets the ROS 2 markers"), "{e}");
        let e = error(&["idmesh", "demo", "--web", "off", "--ros2-markers", "/m"]);
        assert!(e.contains("--web off"), "{e}");
    }

    #[test]
    fn replay_arguments() {
        let cli = Cli::try_parse_from([
            "idmesh",
            "replay",
            "--trace",
            "t.jsonl",
            "--method",
            "threshold",
            "--budget",
            "64",
            "--distributed-rule",
        ])
        .unwrap();
        let Command::Replay(ReplayCommand { args, .. }) = cli.command else {
            panic!("parsed as replay")
        };
        assert_eq!(args.method, Some(Method::Threshold));
        assert_eq!(args.budget, Some(64));
        assert!(args.distributed_rule);
        assert!(
            Cli::try_parse_from(["idmesh", "replay", "--trace", "t", "--budget", "0"]).is_err()
        );
    }

    #[test]
    fn particle_and_eval_arguments() {
        let cli = Cli::try_parse_from([
            "idmesh",
            "replay",
            "--trace",
            "t.jsonl",
            "--method",
            "particles",
            "--particles",
            "5000",
            "--seed",
            "9",
        ])
        .unwrap();
        let Command::Replay(ReplayCommand { args, .. }) = cli.command else {
            panic!("parsed as replay")
        };
        assert_eq!(args.method, Some(Method::Particles));
        assert_eq!((args.particles, args.seed), (Some(5000), Some(9)));
        assert!(
            Cli::try_parse_from(["idmesh", "replay", "--trace", "t", "--particles", "0"]).is_err()
        );

        let cli =
            Cli::try_parse_from(["idmesh", "eval", "--preset", "full", "--out-dir", "x"]).unwrap();
        let Command::Eval(args) = cli.command else {
            panic!("parsed as eval")
        };
        assert_eq!(args.preset, Preset::Full);
        assert_eq!(args.out_dir, Some(PathBuf::from("x")));
        assert_eq!((args.jobs, args.seeds), (2, None));
        assert!(Cli::try_parse_from(["idmesh", "eval", "--jobs", "0"]).is_err());
    }
}
