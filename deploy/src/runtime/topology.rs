//! The topology file: every process of a deployment, where it runs and
//! listens, and the belief settings they share. One file for a whole LAN;
//! `idmesh up --host NAME` starts the processes of one host.
//!
//! ```toml
//! prefix = "idmesh/default"      # key-expression prefix
//! belief = "factored"            # components held by leaders, coupled by
//!                                # the coordinator; or "radon"
//! identity = "factored"          # identity streams with a known start on
//!                                # the factored belief: the factored
//!                                # identity belief; or "information-matrix"
//! max_component = 6              # factored: most tracks of a component
//! split = "least-loss"           # factored: or "original", "recent"
//! regional = true                # factored: components stay in their
//!                                # region (false: they span leaders, who
//!                                # then do not scale out)
//! regions = "fitted"             # cells fitted to the crowd and redrawn as
//!                                # it moves; or "fixed": each leader's `at`
//! # The Radon belief's settings: of every stream under belief = "radon".
//! distributed_rule = false       # Algorithm 5 instead of exact conditioning
//! budget = 0                     # sets per leader (0 = no pruning)
//! sparsify = "threshold"         # or "overcomplete": OMP, then threshold
//! query_timeout_ms = 2000
//! marginals_timeout_ms = 30000   # longest the coordinator computes one
//!                                # identity answer before it stops and
//!                                # says so (a big block, many samples)
//! state_dir = "state"            # journals of the leaders and the sensor
//!                                # (<name>.journal, relative to this file);
//!                                # absent = no journal, a leader or sensor
//!                                # that dies cannot come back
//! fsync_ms = 100                 # longest a journal entry waits for fsync
//! snapshot_every = 5000          # inputs between snapshots (0 = never)
//! takeover_after_ms = 3000       # a leader process gone this long has its
//!                                # role adopted by a live one (0 = never;
//!                                # needs state_dir shared by the leaders)
//! standbys = true                # with state_dir: each leader role's
//!                                # snapshots also go to another leader's
//!                                # disk (false: the leaders share one)
//!
//! [coordinator]
//! name = "coordinator"
//! listen = "tcp/127.0.0.1:7447"
//!
//! # [[sensor_standby]]          # a copy of the sensor's journal on another
//! # name = "sensor-0-standby"    # host's disk; with [[voter]]s it takes the
//! # sensor = "sensor-0"          # sensor role over when the sensor's host
//! # listen = "tcp/127.0.0.1:7453" # is lost (needs state_dir)
//!
//! # [[coordinator_replica]]      # more coordinators, each answering every
//! # name = "coordinator-b"       # question (clients given every endpoint:
//! # listen = "tcp/127.0.0.1:7448" # one answers when another is gone)
//!
//! [sensor]
//! name = "sensor-0"
//! listen = "tcp/127.0.0.1:7452"
//! trace = "crowd.jsonl"          # relative to this file
//! rate = 2000                    # events/s; absent = as fast as possible
//! events = 5000                  # stop the stream after this many events
//! live = false                   # true: stay open for producers' events
//!                                # (P/sensor/<name>/ingest) after the trace
//! window = 2048                  # flow control: route at most this many
//!                                # items past the slowest leader's progress
//!                                # (absent = no window)
//! compact_journal_after = 16777216 # with state_dir: snapshot the sensor's
//!                                # journal once it grew by this many bytes
//! max_errors = 0                 # bad input lines skipped (named, counted)
//!                                # before the next stops the sensor
//! # [sensor.extract]             # the lines are a tracker's reports (move,
//! # mix_distance = 1.0           # detect): the sensor derives the events
//! # meeting_model = { constant = 0.5 } # (docs/guide/extracting.md)
//! # [sensor.ros2]                # read ROS 2 tracker topics over rmw_zenoh
//! # domain = 0                   # (docs/guide/ros2.md; needs [sensor.extract])
//! # topics = [{ topic = "/tracker/detections",
//! #   type = "vision_msgs/msg/Detection2DArray", scale = 0.02, offset = [0, 0] }]
//! # [sensor.faults]              # tests only: a lossy, doubling network
//! # duplicate = true             # every batch published twice
//! # drop_every = 7               # every 7th batch to a leader not published
//! # [leader_faults]              # tests only: a link that loses transfers
//! # drop_transfer_every = 5      # every 5th transfer message a leader puts, lost
//! # drop_push_every = 2          # every 2nd answer pushed at a cut, lost
//!
//! [[leader]]
//! name = "leader-0"
//! listen = "tcp/127.0.0.1:7448"
//! # at = [10.0, 10.0]            # regions = "fixed" only: tracks go to the
//!                                # nearest leader
//!
//! # [security]                   # optional: mutual TLS and access control
//! # certs = "certs"              # ca.pem, <name>.pem, <name>.key
//! # clients = ["operator"]       # client certificates that may query
//!
//! # [web]                        # the HTTP gateway (live map, REST, SSE,
//! # listen = "127.0.0.1:8080"    # /metrics) `idmesh up` serves on the
//! #                              # coordinator's host; not with [security]
//! # ros2_markers = "/idmesh/markers" # beliefs out to RViz, as `idmesh web
//! # ros2_rate = 2                # --ros2-markers` (docs/guide/ros2.md):
//! # ros2_frame = "map"           # ros2_domain, ros2_rate, ros2_frame,
//! # ros2_humble = false          # ros2_humble as its --ros2-* flags
//! ```
//!
//! With `[security]` (see [`super::security`]) every endpoint is reached
//! over mutual TLS in QUIC: `tcp/host:port` here means `quic/host:port`
//! (UDP, same port). Ready-made files:
//! `deploy/examples/topology.toml` (plain) and `deploy/examples/secure.toml`
//! (with the certificates of `deploy/examples/make-certs.sh`) on one
//! machine; `deploy/examples/lan.toml` and `secure-lan.toml` on three.

use super::security::SecuritySection;
use super::web::MarkerOptions;
use anyhow::{bail, Context, Result};
use idmesh_protocol::wire::factored::{FactoredStart, WireSplit};
use idmesh_protocol::wire::keys::DEFAULT_PREFIX;
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};

/// A deployment's topology. Read from TOML by [`Topology::load`] and
/// written by [`Topology::to_toml`] (every field it holds, those at their
/// defaults left out), which reads back into the same value: code that
/// makes a topology (the demo, the bench, the tests' harnesses) builds
/// one of these ([`Topology::new`], [`Topology::loopback`]) and writes it.
#[derive(Debug, Clone, PartialEq, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct Topology {
    #[serde(default = "default_prefix", skip_serializing_if = "is_default_prefix")]
    pub prefix: String,
    /// Which belief the leaders hold (property streams). Written even at
    /// its default: it is what a reader of the file looks for first.
    #[serde(default)]
    pub belief: BeliefKind,
    /// Which identity belief the leaders hold on an identity stream.
    #[serde(default, skip_serializing_if = "is_default")]
    pub identity: IdentityKind,
    /// Factored: the most tracks of one component.
    #[serde(
        default = "default_max_component",
        skip_serializing_if = "is_default_max_component"
    )]
    pub max_component: u32,
    /// Factored: how a component too large to keep is split.
    #[serde(default, skip_serializing_if = "is_default")]
    pub split: SplitSetting,
    /// A setting that was removed: leaders always unfollow the tracks they
    /// neither surveil nor hold a component of. Read only to say so.
    #[serde(rename = "shrink_interest", default, skip_serializing)]
    pub removed_shrink_interest: Option<toml::Value>,
    /// Factored: the regional rule (a mix across two leaders' regions
    /// keeps its components apart; a track handed over is split off its
    /// component), an approximation that keeps components in their
    /// holder's region, so that leaders scale out (docs/guide/deploying.md,
    /// "Belief settings", has its measured cost); `idmesh replay
    /// --topology` runs it too.
    #[serde(default = "yes", skip_serializing_if = "is_true")]
    pub regional: bool,
    /// Factored: a crowd of more tracks than this is spread over the
    /// leaders; one of at most this many is held whole by the first leader,
    /// whose splits weigh the whole belief (docs/guide/deploying.md,
    /// "Belief settings"). 0 spreads every crowd.
    #[serde(
        default = "default_spread_above",
        skip_serializing_if = "is_default_spread_above"
    )]
    pub spread_above: u32,
    /// How tracks are shared among leaders by where they are.
    #[serde(default, skip_serializing_if = "is_default")]
    pub regions: RegionsSetting,
    #[serde(default, skip_serializing_if = "is_default")]
    pub distributed_rule: bool,
    #[serde(default, skip_serializing_if = "is_default")]
    pub budget: u32,
    #[serde(default, skip_serializing_if = "is_default")]
    pub sparsify: Sparsification,
    #[serde(
        default = "default_timeout",
        skip_serializing_if = "is_default_timeout"
    )]
    pub query_timeout_ms: u64,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub state_dir: Option<PathBuf>,
    #[serde(default = "default_fsync", skip_serializing_if = "is_default_fsync")]
    pub fsync_ms: u64,
    /// A leader writes its whole state and starts its journal again after
    /// this many inputs (0 = never: the journal grows with the stream).
    #[serde(
        default = "default_snapshot_every",
        skip_serializing_if = "is_default_snapshot_every"
    )]
    pub snapshot_every: usize,
    /// How long a leader role may be without its liveliness token before a
    /// live leader process adopts it (0 = never).
    #[serde(
        default = "default_takeover_after",
        skip_serializing_if = "is_default_takeover_after"
    )]
    pub takeover_after_ms: u64,
    /// With `state_dir` and more than one leader: every leader role sends
    /// its snapshots to a standby on another leader process's disk, which
    /// an adopter starts from when the role's host is gone for good. Off
    /// (false) only where the leaders share a disk that outlives any host.
    #[serde(default = "yes", skip_serializing_if = "is_true")]
    pub standbys: bool,
    /// How long the coordinator may compute one identity answer's
    /// marginals before it stops the computation and answers why.
    #[serde(
        default = "default_marginals_timeout",
        skip_serializing_if = "is_default_marginals_timeout"
    )]
    pub marginals_timeout_ms: u64,
    pub coordinator: Process,
    /// Further coordinators (`[[coordinator_replica]]`), best each on a
    /// host of its own. A coordinator holds no state of the stream, so
    /// every one answers every question as the first does; clients given
    /// every coordinator's endpoint (`idmesh query --connect A,B`, the web
    /// gateway's `--connect`) are answered by another when one's host is
    /// gone (docs/guide/deploying.md, "A second coordinator").
    #[serde(
        default,
        rename = "coordinator_replica",
        skip_serializing_if = "Vec::is_empty"
    )]
    pub coordinator_replicas: Vec<Process>,
    /// The voters (`[[voter]]`) that decide who holds each role by Raft
    /// (`idmesh-voter`): three or five, one per host, so that a majority
    /// outlives any one host. Each keeps its log in `state_dir`. The roles
    /// do not read their map yet: the shared-disk lock still decides
    /// takeovers.
    #[serde(default, rename = "voter", skip_serializing_if = "Vec::is_empty")]
    pub voters: Vec<Process>,
    /// Processes standing by for a sensor (`[[sensor_standby]]`), each on
    /// another host than its sensor, with its own disk: the sensor's
    /// journal is replicated to it, and with voters it takes the sensor
    /// role over when the sensor's host is lost
    /// (docs/guide/deploying.md, "A standby for the sensor").
    #[serde(
        default,
        rename = "sensor_standby",
        skip_serializing_if = "Vec::is_empty"
    )]
    pub sensor_standbys: Vec<SensorStandbyProcess>,
    /// One `[sensor]`, or several `[[sensor]]` (docs/design/architecture.md,
    /// "Several sensors"): each takes its producers' events, and every
    /// sensor merges them all into one order. Written as it is read: one
    /// table for one sensor.
    #[serde(
        rename = "sensor",
        deserialize_with = "one_or_many",
        serialize_with = "one_or_many_out"
    )]
    pub sensors: Vec<SensorProcess>,
    pub leader: Vec<LeaderProcess>,
    /// Faults every leader injects on purpose (tests).
    #[serde(default, skip_serializing_if = "is_default")]
    pub leader_faults: LeaderFaultSection,
    /// Mutual TLS and access control; None = plain TCP, anyone may connect.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub security: Option<SecuritySection>,
    /// The web gateway `idmesh up` serves beside the coordinator
    /// (`[web]`); None = none (`idmesh web` can still be started beside
    /// the deployment).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub web: Option<WebSection>,
    /// Where the file was read from (relative paths start there); neither
    /// read nor written.
    #[serde(skip)]
    pub dir: PathBuf,
}

/// How a deployment shares tracks among its leaders by their positions.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Deserialize, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum RegionsSetting {
    /// Cells fitted to where the crowd's items are, redrawn as it moves
    /// (`idmesh_placement::Fitted`): each leader is sent about as many.
    #[default]
    Fitted,
    /// Each track to the leader whose `at` is nearest its last position.
    Fixed,
}

fn yes() -> bool {
    true
}

fn is_true(b: &bool) -> bool {
    *b
}

/// The belief the leaders hold on a property stream. The factored belief
/// is the default: the most accurate of the project's methods
/// (docs/results.md). On a stream with identities the leaders keep the
/// information matrix's rows beside whichever belief this names, each
/// row with the leader surveilling its track.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Deserialize, Serialize, clap::ValueEnum)]
#[serde(rename_all = "lowercase")]
pub enum BeliefKind {
    /// The factored belief: each component held by one leader, the count
    /// coupling evaluated by the coordinator at a query.
    #[default]
    Factored,
    /// The Radon belief of Section 5.4, sets shared out among leaders.
    Radon,
}

/// The identity belief the leaders hold on an identity stream. The
/// factored identity belief is the default wherever it can be held — a
/// known start (`initial_identity`) and `belief = "factored"` — being
/// exact up to 9 mixed tracks and calibrated beyond
/// (docs/identity-results.md); elsewhere, and when asked, the rows of the
/// information matrix (Shin et al., Section 4), each with the leader
/// surveilling its track.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Deserialize, Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum IdentityKind {
    #[default]
    Factored,
    InformationMatrix,
}

impl BeliefKind {
    /// As the topology file writes it.
    pub fn name(self) -> &'static str {
        match self {
            BeliefKind::Factored => "factored",
            BeliefKind::Radon => "radon",
        }
    }
}

/// The split rule of the factored belief (`belief::SplitRule`; always
/// the local coupling, which leaders can run).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Deserialize, Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum SplitSetting {
    Original,
    Recent,
    /// One round of pair exchanges (the default: docs/coupling-accuracy.md
    /// measures what it buys against the exact filter).
    #[default]
    LeastLoss,
}

/// The crowd size a factored stream spreads above unless the topology says.
pub fn default_spread_above() -> u32 {
    idmesh_protocol::wire::factored::DEFAULT_SPREAD_ABOVE
}

/// The most tracks of a factored component unless the topology says.
pub fn default_max_component() -> u32 {
    idmesh_belief::FactoredOptions::default().max_component as u32
}

impl Topology {
    /// The group cap of the factored identity belief the stream's `Begin`
    /// asks for (None: the information matrix's rows).
    pub(crate) fn factored_identity(&self) -> Option<u32> {
        (self.identity == IdentityKind::Factored)
            .then_some(idmesh_protocol::wire::identity::DEFAULT_MAX_GROUP)
    }

    /// The factored settings the stream's `Begin` carries (None: Radon).
    pub fn factored(&self) -> Option<FactoredStart> {
        (self.belief == BeliefKind::Factored).then_some(FactoredStart {
            max_component: self.max_component,
            split: match self.split {
                SplitSetting::Original => WireSplit::Original,
                SplitSetting::Recent => WireSplit::Recent,
                SplitSetting::LeastLoss => WireSplit::LeastLoss { rounds: 1 },
            },
            // Leaders always unfollow what they no longer need: without
            // it they follow every track a component ever brought them.
            shrink: true,
            regional: self.regional,
            spread_above: self.spread_above,
        })
    }
}

/// How leaders bring their sets within the budget.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Deserialize, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum Sparsification {
    /// Drop the lightest sets (Section 5.3.2).
    #[default]
    Threshold,
    /// OMP re-expresses the heaviest of them first (Section 5.3.1).
    Overcomplete,
}

#[derive(Debug, Clone, PartialEq, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct Process {
    pub name: String,
    #[serde(default = "default_host", skip_serializing_if = "is_default_host")]
    pub host: String,
    pub listen: String,
}

impl Process {
    /// Process `name` listening on `listen`, on host `local`.
    pub fn new(name: impl Into<String>, listen: impl Into<String>) -> Self {
        Process {
            name: name.into(),
            host: default_host(),
            listen: listen.into(),
        }
    }
}

/// A process standing by for sensor `sensor`: it keeps a copy of its
/// journal under its own `state_dir` and, with voters, takes the sensor
/// role over when the sensor has been gone for `takeover_after_ms`.
#[derive(Debug, Clone, PartialEq, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct SensorStandbyProcess {
    pub name: String,
    #[serde(default = "default_host", skip_serializing_if = "is_default_host")]
    pub host: String,
    pub listen: String,
    /// The sensor it stands by for.
    pub sensor: String,
}

#[derive(Debug, Clone, PartialEq, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct SensorProcess {
    pub name: String,
    #[serde(default = "default_host", skip_serializing_if = "is_default_host")]
    pub host: String,
    pub listen: String,
    pub trace: PathBuf,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub rate: Option<f64>,
    #[serde(default, skip_serializing_if = "is_default")]
    pub realtime: bool,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub events: Option<u64>,
    /// The stream stays open once the trace (or standard input) is done:
    /// it takes producers' events on `P/sensor/<name>/ingest` until the
    /// sensor stops.
    #[serde(default, skip_serializing_if = "is_default")]
    pub live: bool,
    /// Flow control: the sensor routes at most this many seqs past the
    /// slowest leader's progress (None: as fast as the source gives).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub window: Option<u64>,
    /// With `state_dir`: the sensor's journal is compacted to a snapshot
    /// of its state once it has grown by this many bytes (and by at least
    /// the snapshot's own size); absent: 16 MiB.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub compact_journal_after: Option<u64>,
    /// Extraction on (`[sensor.extract]`, its settings; an empty table
    /// for the defaults): the sensor's lines are a tracker's reports —
    /// `move` and `detect` lines — and it derives the events itself, as
    /// `idmesh extract` does (docs/guide/extracting.md).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub extract: Option<idmesh_extract::ExtractorConfig>,
    /// Bad lines of the sensor's own input (its trace of reports,
    /// standard input) skipped, each named and counted, before the next
    /// one stops it; 0 (the default): the first one does. `idmesh sensor
    /// --max-errors` overrides it; `idmesh replay --topology` counts the
    /// same (docs/guide/extracting.md, "Bad rows").
    #[serde(default, skip_serializing_if = "is_default")]
    pub max_errors: usize,
    /// ROS 2 tracker topics the sensor reads over rmw_zenoh
    /// (`[sensor.ros2]`, docs/guide/ros2.md); needs `[sensor.extract]`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub ros2: Option<idmesh_sensor::ros2::Ros2Config>,
    #[serde(default, skip_serializing_if = "is_default")]
    pub faults: FaultSection,
}

impl SensorProcess {
    /// Sensor `name` listening on `listen` and streaming `trace` (relative
    /// to the topology file), on host `local`, every setting at its
    /// default.
    pub fn new(
        name: impl Into<String>,
        listen: impl Into<String>,
        trace: impl Into<PathBuf>,
    ) -> Self {
        SensorProcess {
            name: name.into(),
            host: default_host(),
            listen: listen.into(),
            trace: trace.into(),
            rate: None,
            realtime: false,
            events: None,
            live: false,
            window: None,
            compact_journal_after: None,
            extract: None,
            max_errors: 0,
            ros2: None,
            faults: FaultSection::default(),
        }
    }
}

/// Faults the sensor injects on purpose (see `idmesh_sensor::driver`).
#[derive(Debug, Clone, Default, PartialEq, Eq, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct FaultSection {
    #[serde(default, skip_serializing_if = "is_default")]
    pub duplicate: bool,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub drop_every: Option<u64>,
}

/// Faults the leaders inject on purpose: a transfer lost on a live link,
/// as a TLS link that closes and reopens loses one.
#[derive(Debug, Clone, Default, PartialEq, Eq, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct LeaderFaultSection {
    /// Every n-th transfer message a leader puts (the transfers one input
    /// made for one peer) is not put.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub drop_transfer_every: Option<u64>,
    /// Every n-th answer a leader pushes at a cut is not put (the
    /// coordinator then asks for it).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub drop_push_every: Option<u64>,
}

#[derive(Debug, Clone, PartialEq, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct LeaderProcess {
    pub name: String,
    #[serde(default = "default_host", skip_serializing_if = "is_default_host")]
    pub host: String,
    pub listen: String,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub at: Option<[f64; 2]>,
    /// With several sensors: the one that sends this leader its batches
    /// (absent: the sensors take the leaders in turn, in the file's
    /// order).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub sensor: Option<String>,
}

impl LeaderProcess {
    /// Leader `name` listening on `listen`, on host `local`, unplaced.
    pub fn new(name: impl Into<String>, listen: impl Into<String>) -> Self {
        LeaderProcess {
            name: name.into(),
            host: default_host(),
            listen: listen.into(),
            at: None,
            sensor: None,
        }
    }
}

/// `[web]`: the HTTP gateway — live map, REST and Server-Sent Events,
/// `/metrics` (docs/guide/web.md) — that `idmesh up` serves on the
/// coordinator's host, a Zenoh client of the coordinators, and the ROS 2
/// markers it publishes: what `idmesh web` is told on its command line
/// and the topology does not already say (its coordinators and prefix).
///
/// Its keys are `listen` and those of [`MarkerOptions`] (`ros2_markers`,
/// `ros2_rate`, …, the flags of `idmesh web` without their `--`), in one
/// table; a key neither knows is refused by name.
#[derive(Debug, Clone, PartialEq)]
pub struct WebSection {
    /// Where the HTTP server listens (port 0: any free one, printed).
    pub listen: String,
    pub markers: MarkerOptions,
}

impl WebSection {
    /// Serves the live map on `listen`, without markers.
    pub fn new(listen: impl Into<String>) -> Self {
        WebSection {
            listen: listen.into(),
            markers: MarkerOptions::default(),
        }
    }

    /// A field of the section as a topology says it, for errors
    /// (`[web] ros2_rate`).
    pub(crate) fn field(name: &str) -> String {
        format!("[web] {name}")
    }
}

/// `[web] listen` unless the file says.
fn default_web_listen() -> String {
    "127.0.0.1:8080".to_string()
}

// `listen` and the markers' keys share one table: serde's `flatten` would
// take the markers' keys but pass over a misspelt one silently, so the
// table is split by hand and the markers read with their own
// `deny_unknown_fields`.

impl Serialize for WebSection {
    fn serialize<S: serde::Serializer>(&self, serializer: S) -> Result<S::Ok, S::Error> {
        use serde::ser::Error;
        let mut table = match toml::Value::try_from(&self.markers).map_err(S::Error::custom)? {
            toml::Value::Table(table) => table,
            _ => {
                return Err(S::Error::custom(
                    "[web]: the markers' settings are no table",
                ))
            }
        };
        table.insert("listen".into(), toml::Value::String(self.listen.clone()));
        table.serialize(serializer)
    }
}

impl<'de> Deserialize<'de> for WebSection {
    fn deserialize<D: serde::Deserializer<'de>>(deserializer: D) -> Result<Self, D::Error> {
        use serde::de::Error;
        let mut table = toml::Table::deserialize(deserializer)?;
        let listen = match table.remove("listen") {
            None => default_web_listen(),
            Some(toml::Value::String(listen)) => listen,
            Some(other) => {
                return Err(D::Error::custom(format!(
                    "[web] listen = {other}: an address and port, like \"127.0.0.1:8080\""
                )))
            }
        };
        let markers = MarkerOptions::deserialize(toml::Value::Table(table))
            .map_err(|e| D::Error::custom(format!("[web]: {}", e.to_string().trim_end())))?;
        Ok(WebSection { listen, markers })
    }
}

/// `[web]`: the markers' settings make sense, and the gateway can reach
/// the deployment as `up` runs it.
fn check_web(web: &WebSection, secured: bool) -> Result<()> {
    if web.listen.trim().is_empty() {
        bail!(
            "{} is empty: an address and port, like \"127.0.0.1:8080\"",
            WebSection::field("listen")
        );
    }
    web.markers.config(WebSection::field)?;
    if secured {
        // The gateway `up` serves has no client certificate of its own,
        // and none of the processes' may be lent to it.
        bail!(
            "[web] is for a deployment without [security]: on a secured one run `idmesh web` \
             beside it with the certificate of a client listed in [security] clients \
             (--ca, --cert, --key; docs/guide/web.md)"
        );
    }
    Ok(())
}

/// A sensor's `[sensor.ros2]`: topics that make sense, on a sensor that
/// extracts (the messages are a tracker's reports), the only one.
fn check_ros2(sensor: &SensorProcess, sensors: usize) -> Result<()> {
    let Some(ros2) = &sensor.ros2 else {
        return Ok(());
    };
    ros2.validate()
        .map_err(|e| anyhow::anyhow!("sensor {}: {e}", sensor.name))?;
    if sensor.extract.is_none() {
        bail!(
            "sensor {}: [sensor.ros2] reads a tracker's reports: it needs [sensor.extract]",
            sensor.name
        );
    }
    if sensors > 1 {
        bail!(
            "sensor {}: [sensor.ros2] is for a deployment of one sensor",
            sensor.name
        );
    }
    Ok(())
}

/// `[sensor]` (one table) or `[[sensor]]` (several), each read as a
/// sensor's table so that a mistake in it is named as one.
fn one_or_many<'de, D: serde::Deserializer<'de>>(
    deserializer: D,
) -> Result<Vec<SensorProcess>, D::Error> {
    use serde::de::Error;
    let one = |value: toml::Value| SensorProcess::deserialize(value).map_err(D::Error::custom);
    match toml::Value::deserialize(deserializer)? {
        toml::Value::Array(many) => many.into_iter().map(one).collect(),
        table => Ok(vec![one(table)?]),
    }
}

/// `sensors` as [`one_or_many`] reads them: one table for one sensor, an
/// array of tables for several.
fn one_or_many_out<S: serde::Serializer>(
    sensors: &[SensorProcess],
    serializer: S,
) -> Result<S::Ok, S::Error> {
    match sensors {
        [one] => one.serialize(serializer),
        many => many.serialize(serializer),
    }
}

fn default_prefix() -> String {
    DEFAULT_PREFIX.to_string()
}

fn default_host() -> String {
    "local".to_string()
}

fn default_timeout() -> u64 {
    2000
}

fn default_marginals_timeout() -> u64 {
    30_000
}

fn default_fsync() -> u64 {
    100
}

fn default_snapshot_every() -> usize {
    5000
}

fn default_takeover_after() -> u64 {
    3000
}

// Whether a field holds its default, so that the written file leaves it
// out (serde's `skip_serializing_if` takes a function of a reference).

fn is_default<T: Default + PartialEq>(value: &T) -> bool {
    *value == T::default()
}

fn is_default_prefix(prefix: &str) -> bool {
    prefix == DEFAULT_PREFIX
}

fn is_default_host(host: &str) -> bool {
    host == default_host()
}

fn is_default_spread_above(size: &u32) -> bool {
    *size == default_spread_above()
}

fn is_default_max_component(max: &u32) -> bool {
    *max == default_max_component()
}

fn is_default_timeout(ms: &u64) -> bool {
    *ms == default_timeout()
}

fn is_default_marginals_timeout(ms: &u64) -> bool {
    *ms == default_marginals_timeout()
}

fn is_default_fsync(ms: &u64) -> bool {
    *ms == default_fsync()
}

fn is_default_snapshot_every(every: &usize) -> bool {
    *every == default_snapshot_every()
}

fn is_default_takeover_after(ms: &u64) -> bool {
    *ms == default_takeover_after()
}

/// A process of the deployment, whatever its role.
#[derive(Debug, Clone, PartialEq)]
pub struct Member {
    pub role: &'static str,
    pub name: String,
    pub host: String,
    pub listen: String,
}

impl Topology {
    /// A topology of these processes, every setting at its default (as a
    /// file naming only them reads), `dir` empty.
    pub fn new(
        coordinator: Process,
        sensors: Vec<SensorProcess>,
        leader: Vec<LeaderProcess>,
    ) -> Self {
        Topology {
            identity: IdentityKind::default(),
            prefix: default_prefix(),
            belief: BeliefKind::default(),
            max_component: default_max_component(),
            split: SplitSetting::default(),
            removed_shrink_interest: None,
            regional: true,
            spread_above: default_spread_above(),
            regions: RegionsSetting::default(),
            distributed_rule: false,
            budget: 0,
            sparsify: Sparsification::default(),
            query_timeout_ms: default_timeout(),
            state_dir: None,
            fsync_ms: default_fsync(),
            snapshot_every: default_snapshot_every(),
            takeover_after_ms: default_takeover_after(),
            standbys: true,
            marginals_timeout_ms: default_marginals_timeout(),
            coordinator,
            coordinator_replicas: Vec::new(),
            voters: Vec::new(),
            sensor_standbys: Vec::new(),
            sensors,
            leader,
            leader_faults: LeaderFaultSection::default(),
            security: None,
            web: None,
            dir: PathBuf::new(),
        }
    }

    /// The topology as a TOML file says it, [`Topology::load`]'s input:
    /// read back, it is this topology again (but for `dir`, which is where
    /// the file is). Fails only on a path that is not UTF-8.
    pub(crate) fn to_toml(&self) -> Result<String> {
        toml::to_string(self).context("the topology cannot be written as TOML")
    }

    /// Writes [`Topology::to_toml`] to `path`.
    pub fn save(&self, path: &Path) -> Result<()> {
        std::fs::write(path, self.to_toml()?)
            .with_context(|| format!("{}: cannot write the topology", path.display()))
    }

    pub fn load(path: &Path) -> Result<Self> {
        let text = std::fs::read_to_string(path)
            .with_context(|| format!("{}: cannot read the topology", path.display()))?;
        let mut topology: Topology =
            toml::from_str(&text).map_err(|e| anyhow::anyhow!("{}: {e}", path.display()))?;
        topology.dir = path.parent().map(Path::to_path_buf).unwrap_or_default();
        topology
            .check()
            .with_context(|| format!("{}", path.display()))?;
        Ok(topology)
    }

    fn check(&self) -> Result<()> {
        if self.leader.is_empty() {
            bail!("at least one [[leader]] is needed");
        }
        let members = self.members();
        for (i, m) in members.iter().enumerate() {
            if members[..i].iter().any(|o| o.name == m.name) {
                bail!("two processes are named {:?}", m.name);
            }
            if members[..i].iter().any(|o| o.listen == m.listen) {
                bail!("two processes listen on {}", m.listen);
            }
        }
        if self.removed_shrink_interest.is_some() {
            bail!(
                "shrink_interest was removed: leaders always unfollow the tracks they neither \
                 surveil nor hold a component of; delete the line"
            );
        }
        let placed = self.leader.iter().filter(|l| l.at.is_some()).count();
        match self.regions {
            RegionsSetting::Fixed if placed != self.leader.len() => {
                bail!("regions = \"fixed\": give every leader a position (at = [x, y])")
            }
            RegionsSetting::Fitted if placed > 0 => {
                let leader = self.leader.iter().find(|l| l.at.is_some()).map(|l| &l.name);
                bail!(
                    "leader {}: `at` places a leader only under regions = \"fixed\"; by \
                     default regions are fitted to the crowd and redrawn as it moves \
                     (docs/guide/deploying.md, \"Regions\"): delete `at`, or set \
                     regions = \"fixed\"",
                    leader.map_or("", String::as_str)
                )
            }
            _ => {}
        }
        if self.sensors.is_empty() {
            bail!("a [sensor] is needed");
        }
        for sensor in &self.sensors {
            if sensor.faults.drop_every.is_some_and(|n| n < 2) {
                bail!(
                    "sensor {}: faults.drop_every must be 2 or more (1 would drop every batch)",
                    sensor.name
                );
            }
            check_ros2(sensor, self.sensors.len())?;
            if let Some(rate) = sensor.rate {
                if !(rate.is_finite() && rate > 0.0) {
                    bail!(
                        "sensor {}: rate {rate} must be a positive number of events per second",
                        sensor.name
                    );
                }
            }
            if self.sensors.len() > 1 && sensor.trace != self.sensors[0].trace {
                bail!(
                    "sensor {}: several sensors share one stream, so one trace (its header): {} \
                     is not {}",
                    sensor.name,
                    sensor.trace.display(),
                    self.sensors[0].trace.display()
                );
            }
        }
        for leader in &self.leader {
            if let Some(sensor) = &leader.sensor {
                if !self.sensors.iter().any(|s| &s.name == sensor) {
                    bail!(
                        "leader {}: sensor {sensor:?} is not in the topology",
                        leader.name
                    );
                }
            }
        }
        self.check_voters()?;
        self.check_sensor_standbys()?;
        if let Some(security) = &self.security {
            security.check(members.iter().map(|m| m.name.as_str()))?;
        }
        if let Some(web) = &self.web {
            check_web(web, self.security.is_some())?;
        }
        if let Some(factored) = self.factored() {
            factored
                .check()
                .map_err(|e| anyhow::anyhow!("belief = \"factored\": {e}"))?;
            if self.max_component > 12 && self.split != SplitSetting::Original {
                bail!(
                    "belief = \"factored\": max_component = {} with split = {:?} \
                     (at most 12 unless the split is \"original\")",
                    self.max_component,
                    self.split
                );
            }
        }
        Ok(())
    }

    /// Voters keep their logs in `state_dir`.
    fn check_voters(&self) -> Result<()> {
        if self.voters.is_empty() {
            return Ok(());
        }
        if self.state_dir.is_none() {
            bail!("[[voter]]: give state_dir, where each voter keeps its log");
        }
        Ok(())
    }

    /// A standby stands by for a sensor of the topology (a sensor may have
    /// several, in the order given) and keeps its copy in `state_dir`.
    fn check_sensor_standbys(&self) -> Result<()> {
        for standby in &self.sensor_standbys {
            let name = &standby.name;
            if !self.sensors.iter().any(|s| s.name == standby.sensor) {
                bail!(
                    "[[sensor_standby]] {name}: sensor {:?} is not in the topology",
                    standby.sensor
                );
            }
            if self.state_dir.is_none() {
                bail!("[[sensor_standby]] {name}: give state_dir, where it keeps its copy of the sensor's journal");
            }
        }
        Ok(())
    }

    /// The processes standing by for sensor `sensor`, in the topology's
    /// order.
    pub(crate) fn standbys_of(&self, sensor: &str) -> Vec<String> {
        self.sensor_standbys
            .iter()
            .filter(|s| s.sensor == sensor)
            .map(|s| s.name.clone())
            .collect()
    }

    /// Where process `me`, holding sensor role `sensor`, replicates its
    /// journal: the role's own process and its standbys, in that order,
    /// but for `me`.
    pub(crate) fn replicas_of(&self, sensor: &str, me: &str) -> Vec<String> {
        std::iter::once(sensor.to_string())
            .chain(self.standbys_of(sensor))
            .filter(|name| name != me)
            .collect()
    }

    pub fn members(&self) -> Vec<Member> {
        let mut all: Vec<Member> = self
            .coordinators()
            .map(|c| Member {
                role: "coordinator",
                name: c.name.clone(),
                host: c.host.clone(),
                listen: c.listen.clone(),
            })
            .collect();
        all.extend(self.sensors.iter().map(|s| Member {
            role: "sensor",
            name: s.name.clone(),
            host: s.host.clone(),
            listen: s.listen.clone(),
        }));
        all.extend(self.leader.iter().map(|l| Member {
            role: "leader",
            name: l.name.clone(),
            host: l.host.clone(),
            listen: l.listen.clone(),
        }));
        all.extend(self.voters.iter().map(|v| Member {
            role: "voter",
            name: v.name.clone(),
            host: v.host.clone(),
            listen: v.listen.clone(),
        }));
        all.extend(self.sensor_standbys.iter().map(|s| Member {
            role: "sensor-standby",
            name: s.name.clone(),
            host: s.host.clone(),
            listen: s.listen.clone(),
        }));
        all
    }

    pub(crate) fn member(&self, name: &str) -> Result<Member> {
        self.members()
            .into_iter()
            .find(|m| m.name == name)
            .with_context(|| format!("no process named {name:?} in the topology"))
    }

    pub(crate) fn trace_path(&self) -> PathBuf {
        self.dir.join(&self.sensor().trace)
    }

    /// Every coordinator: the first, then its replicas.
    pub fn coordinators(&self) -> impl Iterator<Item = &Process> {
        std::iter::once(&self.coordinator).chain(&self.coordinator_replicas)
    }

    /// Every coordinator's endpoint, comma-separated: what a client's
    /// `--connect` takes so that another answers when one is gone.
    pub fn coordinator_endpoints(&self) -> String {
        self.coordinators()
            .map(|c| c.listen.as_str())
            .collect::<Vec<_>>()
            .join(",")
    }

    /// The first sensor (the only one, mostly).
    pub fn sensor(&self) -> &SensorProcess {
        &self.sensors[0]
    }

    /// The sensor named `name`.
    pub(crate) fn sensor_named(&self, name: &str) -> Result<&SensorProcess> {
        self.sensors
            .iter()
            .find(|s| s.name == name)
            .with_context(|| format!("no sensor named {name:?} in the topology"))
    }

    /// The sensor that sends leader `i` its batches.
    pub(crate) fn sensor_of_leader(&self, i: usize) -> &SensorProcess {
        self.leader[i]
            .sensor
            .as_deref()
            .and_then(|name| self.sensors.iter().find(|s| s.name == name))
            .unwrap_or(&self.sensors[i % self.sensors.len()])
    }

    /// Where leader `name` keeps its journal, if leaders keep one.
    /// The leaders' state directory, resolved against the file's folder.
    pub(crate) fn state_path(&self) -> Option<PathBuf> {
        self.state_dir.as_ref().map(|dir| self.dir.join(dir))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The topology `to_toml` writes, read back as `load` reads it (`dir`
    /// aside: where a file is is not in it).
    fn read_back(topology: &Topology) -> Topology {
        let text = topology.to_toml().unwrap();
        let mut back: Topology = toml::from_str(&text).unwrap_or_else(|e| panic!("{e}\n{text}"));
        back.dir = topology.dir.clone();
        back
    }

    #[test]
    fn every_example_reads_back_from_what_it_writes() {
        let examples = Path::new(env!("CARGO_MANIFEST_DIR")).join("examples");
        let mut read = 0;
        for entry in std::fs::read_dir(&examples).unwrap() {
            let path = entry.unwrap().path();
            if path.extension().is_none_or(|e| e != "toml") {
                continue;
            }
            let topology = Topology::load(&path).unwrap();
            assert_eq!(read_back(&topology), topology, "{}", path.display());
            read += 1;
        }
        assert!(read >= 5, "{read} examples");
        let dir = std::env::temp_dir().join(format!("idmesh-topology-rt-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let file = dir.join("topology.toml");
        std::fs::write(&file, documented_example()).unwrap();
        let documented = Topology::load(&file);
        std::fs::remove_dir_all(&dir).unwrap();
        let documented = documented.unwrap();
        assert_eq!(read_back(&documented), documented);
    }

    /// A topology built in code with every field away from its default,
    /// several sensors and every section: written, it reads back equal,
    /// and `load` takes the file.
    #[test]
    fn a_topology_built_in_code_reads_back_as_it_was_built() {
        let sensor = |i: usize| SensorProcess {
            host: "gateway".into(),
            rate: Some(2500.5),
            realtime: true,
            events: Some(7000),
            live: true,
            window: Some(4096),
            compact_journal_after: Some(1 << 20),
            extract: Some(idmesh_extract::ExtractorConfig {
                mix_distance: 1.5,
                meeting_model: idmesh_extract::MeetingModel::Approach {
                    p_max: 0.5,
                    sigma: 0.4,
                    v0: 0.8,
                },
                ..Default::default()
            }),
            faults: FaultSection {
                duplicate: true,
                drop_every: Some(7),
            },
            ..SensorProcess::new(
                format!("s{i}"),
                format!("tcp/10.0.0.1:74{i}0"),
                "crowd.jsonl",
            )
        };
        let leader = |i: usize| LeaderProcess {
            host: "east".into(),
            at: Some([0.1 + i as f64 / 3.0, -12.5]),
            sensor: Some(format!("s{}", i % 2)),
            ..LeaderProcess::new(format!("l{i}"), format!("tcp/10.0.0.2:75{i}0"))
        };
        let mut topology = Topology::new(
            Process::new("c", "tcp/10.0.0.1:7447"),
            vec![sensor(0), sensor(1)],
            (0..3).map(leader).collect(),
        );
        topology.prefix = "idmesh/built".into();
        topology.belief = BeliefKind::Radon;
        topology.max_component = 9;
        topology.split = SplitSetting::Recent;
        topology.regional = false;
        topology.regions = RegionsSetting::Fixed;
        topology.distributed_rule = true;
        topology.budget = 300;
        topology.sparsify = Sparsification::Overcomplete;
        topology.query_timeout_ms = 1234;
        topology.state_dir = Some("state".into());
        topology.fsync_ms = 7;
        topology.snapshot_every = 0;
        topology.takeover_after_ms = 0;
        topology.marginals_timeout_ms = 5;
        topology.leader_faults = LeaderFaultSection {
            drop_transfer_every: Some(5),
            drop_push_every: Some(2),
        };
        topology.security = Some(SecuritySection {
            access_control: false,
            clients: vec!["operator".into()],
            producers: vec!["camera".into()],
            verify_names: false,
            ..SecuritySection::new("certs")
        });
        assert_eq!(read_back(&topology), topology);
        let text = topology.to_toml().unwrap();
        assert!(
            text.contains("[[sensor]]") && text.contains("[sensor.faults]"),
            "{text}"
        );

        // One sensor is one `[sensor]` table, as people write it.
        topology.sensors.truncate(1);
        for leader in &mut topology.leader {
            leader.sensor = None;
        }
        assert_eq!(read_back(&topology), topology);
        let text = topology.to_toml().unwrap();
        assert!(
            text.contains("\n[sensor]\n") && !text.contains("[[sensor]]"),
            "{text}"
        );

        let dir =
            std::env::temp_dir().join(format!("idmesh-topology-built-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("t.toml");
        topology.save(&path).unwrap();
        let loaded = Topology::load(&path);
        std::fs::remove_dir_all(&dir).unwrap();
        let mut loaded = loaded.unwrap();
        assert_eq!(loaded.dir, dir);
        loaded.dir = PathBuf::new();
        assert_eq!(loaded, topology);
    }

    /// `Topology::new` is what a file naming only the processes reads
    /// as, and it is written as little more than those processes: every
    /// setting at its default is left out.
    #[test]
    fn defaults_are_those_of_a_file_that_says_nothing_and_are_not_written() {
        let text = r#"
[coordinator]
name = "c"
listen = "tcp/127.0.0.1:1"
[sensor]
name = "s"
listen = "tcp/127.0.0.1:2"
trace = "x.jsonl"
[[leader]]
name = "l0"
listen = "tcp/127.0.0.1:3"
"#;
        let parsed: Topology = toml::from_str(text).unwrap();
        let built = Topology::new(
            Process::new("c", "tcp/127.0.0.1:1"),
            vec![SensorProcess::new("s", "tcp/127.0.0.1:2", "x.jsonl")],
            vec![LeaderProcess::new("l0", "tcp/127.0.0.1:3")],
        );
        assert_eq!(parsed, built);
        let written = built.to_toml().unwrap();
        let lines: Vec<&str> = written.lines().filter(|l| !l.is_empty()).collect();
        assert_eq!(
            lines,
            [
                "belief = \"factored\"",
                "[coordinator]",
                "name = \"c\"",
                "listen = \"tcp/127.0.0.1:1\"",
                "[sensor]",
                "name = \"s\"",
                "listen = \"tcp/127.0.0.1:2\"",
                "trace = \"x.jsonl\"",
                "[[leader]]",
                "name = \"l0\"",
                "listen = \"tcp/127.0.0.1:3\"",
            ],
            "{written}"
        );
    }

    /// The TOML listing of this module's documentation.
    fn documented_example() -> String {
        let source = include_str!("topology.rs");
        let start = source.find("//! ```toml\n").expect("a ```toml listing");
        source[start..]
            .lines()
            .skip(1)
            .take_while(|l| *l != "//! ```")
            .map(|l| l.strip_prefix("//!").unwrap_or(l).trim_start_matches(' '))
            .collect::<Vec<_>>()
            .join("\n")
    }

    #[test]
    fn the_documented_example_and_the_shipped_examples_load_as_they_are() {
        let dir = std::env::temp_dir().join(format!("idmesh-topology-doc-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let file = dir.join("topology.toml");
        std::fs::write(&file, documented_example()).unwrap();
        let documented = Topology::load(&file);
        std::fs::remove_dir_all(&dir).unwrap();
        let documented = documented.unwrap();
        assert_eq!(documented.sensor().events, Some(5000));
        assert_eq!(documented.trace_path(), dir.join("crowd.jsonl"));

        let examples = Path::new(env!("CARGO_MANIFEST_DIR")).join("examples");
        for name in ["topology.toml", "secure.toml"] {
            let topology = Topology::load(&examples.join(name)).unwrap();
            assert!(topology.trace_path().exists(), "{name}: no trace");
            assert_eq!(topology.leader.len(), 2, "{name}");
        }
        // Two sensors, each serving the leader of its region.
        let sensors = Topology::load(&examples.join("sensors.toml")).unwrap();
        assert!(sensors.trace_path().exists(), "sensors.toml: no trace");
        let names: Vec<&str> = sensors.sensors.iter().map(|s| s.name.as_str()).collect();
        assert_eq!(names, ["sensor-west", "sensor-east"]);
        assert_eq!(sensors.sensor_of_leader(1).name, "sensor-east");
        assert_eq!(sensors.members().len(), 5);
        // Three machines on a LAN, plain and secured: the gateway runs the
        // coordinator and the sensor, east and west two leaders each.
        for name in ["lan.toml", "secure-lan.toml"] {
            let topology = Topology::load(&examples.join(name)).unwrap();
            assert!(topology.trace_path().exists(), "{name}: no trace");
            let on = |host: &str| topology.members().iter().filter(|m| m.host == host).count();
            assert_eq!((on("gateway"), on("east"), on("west")), (2, 2, 2), "{name}");
            assert_eq!(topology.security.is_some(), name.starts_with("secure"));
        }
        // Five machines, each with a disk of its own: whichever is lost, a
        // majority of voters, a coordinator, a holder or standby of the
        // sensor role and two leader processes remain elsewhere.
        let ha = Topology::load(&examples.join("host-loss.toml")).unwrap();
        assert!(ha.trace_path().exists(), "host-loss.toml: no trace");
        let members = ha.members();
        let hosts: std::collections::BTreeSet<&str> =
            members.iter().map(|m| m.host.as_str()).collect();
        assert_eq!(hosts.len(), 5);
        for lost in hosts {
            let left = |role: &str| {
                members
                    .iter()
                    .filter(|m| m.role == role && m.host != lost)
                    .count()
            };
            assert!(left("voter") * 2 > ha.voters.len(), "{lost}: voters");
            assert!(left("coordinator") >= 1, "{lost}: coordinators");
            assert!(
                left("sensor") + left("sensor-standby") >= 2,
                "{lost}: sensor"
            );
            assert!(left("leader") >= 2, "{lost}: leaders");
        }
    }

    #[test]
    fn several_sensors_share_the_leaders_in_turn_and_one_trace() {
        let dir = std::env::temp_dir().join(format!("idmesh-topology-s-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("t.toml");
        let sensor = |i: usize, trace: &str| {
            format!("[[sensor]]\nname = \"s{i}\"\nlisten = \"tcp/127.0.0.1:2{i}\"\ntrace = \"{trace}\"\n")
        };
        let leader = |i: usize, extra: &str| {
            format!("[[leader]]\nname = \"l{i}\"\nlisten = \"tcp/127.0.0.1:3{i}\"\n{extra}")
        };
        let coordinator = "[coordinator]\nname = \"c\"\nlisten = \"tcp/127.0.0.1:1\"\n";
        let text = [
            coordinator.to_string(),
            sensor(0, "x.jsonl"),
            sensor(1, "x.jsonl"),
            leader(0, ""),
            leader(1, ""),
            leader(2, "sensor = \"s0\"\n"),
        ]
        .concat();
        std::fs::write(&path, &text).unwrap();
        let t = Topology::load(&path).unwrap();
        let served: Vec<&str> = (0..3)
            .map(|i| t.sensor_of_leader(i).name.as_str())
            .collect();
        assert_eq!(served, ["s0", "s1", "s0"]);
        std::fs::write(&path, text.replace("sensor = \"s0\"", "sensor = \"s9\"")).unwrap();
        let e = format!("{:#}", Topology::load(&path).unwrap_err());
        assert!(
            e.contains("leader l2: sensor \"s9\" is not in the topology"),
            "{e}"
        );
        let two_traces = [
            coordinator.to_string(),
            sensor(0, "x.jsonl"),
            sensor(1, "y.jsonl"),
            leader(0, ""),
        ]
        .concat();
        std::fs::write(&path, two_traces).unwrap();
        let e = format!("{:#}", Topology::load(&path).unwrap_err());
        assert!(
            e.contains("sensor s1: several sensors share one stream"),
            "{e}"
        );
        // A mistake inside one of several sensors' tables is named.
        std::fs::write(
            &path,
            text.replace("trace = \"x.jsonl\"\n", "trace = \"x.jsonl\"\nbogus = 1\n"),
        )
        .unwrap();
        let e = format!("{:#}", Topology::load(&path).unwrap_err());
        assert!(e.contains("bogus"), "{e}");
        std::fs::remove_dir_all(&dir).unwrap();
    }

    /// A coordinator, a sensor and a leader on loopback.
    const SMALL: &str = r#"
[coordinator]
name = "c"
listen = "tcp/127.0.0.1:1"
[sensor]
name = "s"
listen = "tcp/127.0.0.1:2"
trace = "x.jsonl"
[[leader]]
name = "l0"
listen = "tcp/127.0.0.1:3"
"#;

    #[test]
    fn a_topology_with_a_mistake_is_rejected_naming_it() {
        let dir = tempfile::Builder::new()
            .prefix("idmesh-topology-")
            .tempdir()
            .unwrap();
        let path = dir.path().join("t.toml");
        let good = SMALL;
        std::fs::write(&path, good).unwrap();
        let t = Topology::load(&path).unwrap();
        assert_eq!(t.members().len(), 3);
        assert_eq!(t.prefix, DEFAULT_PREFIX);
        std::fs::write(&path, good.replace(":3", ":2")).unwrap();
        let e = format!("{:#}", Topology::load(&path).unwrap_err());
        assert!(e.contains("listen on tcp/127.0.0.1:2"), "{e}");
        std::fs::write(&path, format!("{good}\nbogus = 1\n")).unwrap();
        let e = format!("{:#}", Topology::load(&path).unwrap_err());
        assert!(e.contains("bogus"), "{e}");
        let secured = format!("{good}\n[security]\ncerts = \"certs\"\nclients = [\"l0\"]\n");
        std::fs::write(&path, secured).unwrap();
        let e = format!("{:#}", Topology::load(&path).unwrap_err());
        assert!(
            e.contains("[security] clients") && e.contains("\"l0\""),
            "{e}"
        );
    }

    /// `[[voter]]`s are processes of the topology; they need `state_dir`
    /// (their logs).
    #[test]
    fn voters_are_members_that_need_a_state_dir() {
        let dir =
            std::env::temp_dir().join(format!("idmesh-topology-voters-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("t.toml");
        let voters = "[[voter]]\nname = \"v1\"\nlisten = \"tcp/127.0.0.1:11\"\n\
                      [[voter]]\nname = \"v2\"\nlisten = \"tcp/127.0.0.1:12\"\n\
                      [[voter]]\nname = \"v3\"\nlisten = \"tcp/127.0.0.1:13\"\n";
        std::fs::write(&path, format!("state_dir = \"state\"\n{SMALL}{voters}")).unwrap();
        let t = Topology::load(&path).unwrap();
        let roles: Vec<&str> = t.members().iter().map(|m| m.role).collect();
        assert_eq!(roles.iter().filter(|r| **r == "voter").count(), 3);
        std::fs::write(&path, format!("{SMALL}{voters}")).unwrap();
        let e = format!("{:#}", Topology::load(&path).unwrap_err());
        assert!(e.contains("[[voter]]") && e.contains("state_dir"), "{e}");
        std::fs::remove_dir_all(&dir).ok();
    }

    /// A `[[sensor_standby]]` is a member that stands by for a sensor of
    /// the topology, needs `state_dir`, and reads back as written.
    #[test]
    fn a_sensor_standby_names_its_sensor_and_needs_a_state_dir() {
        let dir =
            std::env::temp_dir().join(format!("idmesh-topology-standby-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("t.toml");
        let named = |name: &str, sensor: &str, port: u16| {
            format!(
                "[[sensor_standby]]\nname = \"{name}\"\nsensor = \"{sensor}\"\n\
                 listen = \"tcp/127.0.0.1:{port}\"\n"
            )
        };
        let standby = |sensor: &str| named("s-standby", sensor, 14);
        std::fs::write(
            &path,
            format!(
                "state_dir = \"state\"\n{SMALL}{}{}",
                standby("s"),
                named("s-second", "s", 15)
            ),
        )
        .unwrap();
        let t = Topology::load(&path).unwrap();
        let member = t.member("s-standby").unwrap();
        assert_eq!(member.role, "sensor-standby");
        // Several, in the order given; whoever holds the role replicates
        // to the others.
        assert_eq!(t.standbys_of("s"), ["s-standby", "s-second"]);
        assert_eq!(t.replicas_of("s", "s"), ["s-standby", "s-second"]);
        assert_eq!(t.replicas_of("s", "s-standby"), ["s", "s-second"]);
        assert_eq!(read_back(&t), t);
        std::fs::write(&path, format!("{SMALL}{}", standby("s"))).unwrap();
        let e = format!("{:#}", Topology::load(&path).unwrap_err());
        assert!(
            e.contains("[[sensor_standby]]") && e.contains("state_dir"),
            "{e}"
        );
        std::fs::write(
            &path,
            format!("state_dir = \"state\"\n{SMALL}{}", standby("t")),
        )
        .unwrap();
        let e = format!("{:#}", Topology::load(&path).unwrap_err());
        assert!(e.contains("sensor \"t\" is not in the topology"), "{e}");
        std::fs::remove_dir_all(&dir).ok();
    }

    /// `[web]` takes `listen` and `idmesh web`'s marker settings under
    /// their names; written, it reads back equal; a bad or unknown key is
    /// refused naming it.
    #[test]
    fn a_web_section_takes_the_marker_settings_and_a_bad_one_is_named() {
        let dir = std::env::temp_dir().join(format!("idmesh-topology-web-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("t.toml");
        let base = SMALL;
        let web = r#"
[web]
listen = "127.0.0.1:0"
ros2_markers = "/idmesh/markers"
ros2_domain = 3
ros2_rate = 5
ros2_frame = "odom"
ros2_humble = true
"#;
        let load = |text: &str| {
            std::fs::write(&path, format!("{base}{text}")).unwrap();
            Topology::load(&path).map_err(|e| format!("{e:#}"))
        };
        let t = load(web).unwrap();
        let section = t.web.clone().unwrap();
        assert_eq!(section.listen, "127.0.0.1:0");
        let markers = section.markers.config(WebSection::field).unwrap().unwrap();
        assert_eq!(markers.topic, "/idmesh/markers");
        assert_eq!((markers.domain, markers.frame.as_str()), (3, "odom"));
        assert_eq!(markers.every, std::time::Duration::from_millis(200));
        assert!(markers.humble);
        assert_eq!(read_back(&t), t);
        // The defaults: the map on 127.0.0.1:8080, no markers.
        let plain = load("[web]\n").unwrap().web.unwrap();
        assert_eq!(plain, WebSection::new("127.0.0.1:8080"));
        assert!(plain.markers.config(WebSection::field).unwrap().is_none());
        let bad = |from: &str, to: &str, says: &str| {
            assert!(web.contains(from), "{from}");
            let e = load(&web.replace(from, to)).expect_err(to);
            assert!(e.contains(says), "{to}: {e}");
        };
        bad(
            "ros2_rate = 5",
            "ros2_rate = 0",
            "[web] ros2_rate must be in (0, 1000]",
        );
        bad("ros2_rate = 5", "ros2_rate = \"fast\"", "ros2_rate");
        bad(
            "ros2_markers = \"/idmesh/markers\"",
            "ros2_markers = \"idmesh\"",
            "[web] ros2_markers \"idmesh\": a fully qualified ROS topic",
        );
        bad(
            "ros2_markers = \"/idmesh/markers\"",
            "ros2_marker = \"/idmesh/markers\"",
            "unknown field `ros2_marker`",
        );
        bad(
            "ros2_markers = \"/idmesh/markers\"\n",
            "",
            "[web] ros2_domain sets the ROS 2 markers",
        );
        bad(
            "listen = \"127.0.0.1:0\"",
            "listen = 8080",
            "[web] listen = 8080",
        );
        let secured = format!("{web}[security]\ncerts = \"certs\"\nclients = [\"operator\"]\n");
        let e = load(&secured).expect_err("refused");
        assert!(
            e.contains("[web] is for a deployment without [security]"),
            "{e}"
        );
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn a_ros2_section_loads_on_a_sensor_that_extracts() {
        let dir = std::env::temp_dir().join(format!("idmesh-topology-ros2-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("t.toml");
        let base = r#"
[coordinator]
name = "c"
listen = "tcp/127.0.0.1:1"
[[leader]]
name = "l0"
listen = "tcp/127.0.0.1:3"
[sensor]
name = "s"
listen = "tcp/127.0.0.1:2"
trace = "x.jsonl"
live = true
"#;
        let ros2 = r#"
[sensor.ros2]
domain = 7
topics = [
  { topic = "/tracker/detections", type = "vision_msgs/msg/Detection2DArray", scale = 0.02, offset = [1.0, -1.0], labels = { person = "red" } },
  { topic = "/objects", type = "autoware_perception_msgs/msg/TrackedObjects" },
]
"#;
        std::fs::write(&path, format!("{base}[sensor.extract]\n{ros2}")).unwrap();
        let t = Topology::load(&path).unwrap();
        let section = t.sensor().ros2.clone().unwrap();
        assert_eq!(section.domain, 7);
        assert_eq!(section.topics[0].scale, 0.02);
        assert_eq!(section.topics[0].labels["person"], "red");
        assert_eq!(section.topics[1].offset, [0.0, 0.0]);
        // Written, it reads back equal.
        let text = toml::to_string(&t).unwrap();
        let back: Topology = toml::from_str(&text).unwrap_or_else(|e| panic!("{e}\n{text}"));
        assert_eq!(back.sensor().ros2, t.sensor().ros2);
        std::fs::write(&path, format!("{base}{ros2}")).unwrap();
        let e = format!("{:#}", Topology::load(&path).unwrap_err());
        assert!(e.contains("needs [sensor.extract]"), "{e}");
        let zero = ros2.replace("scale = 0.02", "scale = 0");
        std::fs::write(&path, format!("{base}[sensor.extract]\n{zero}")).unwrap();
        let e = format!("{:#}", Topology::load(&path).unwrap_err());
        assert!(e.contains("scale must be finite and > 0"), "{e}");
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
