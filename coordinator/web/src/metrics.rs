//! `GET /metrics` in the OpenMetrics text format (prometheus-client).
//!
//! Nothing is pushed to the gateway: a scrape asks `query/stats` and
//! `query/positions` (the stream's event count) and writes what they say,
//! so the numbers are the deployment's own counters at that moment, with
//! labels `role` (leader, sensor, coordinator) and `process` (the process
//! that runs it; for a leader role adopted from a process gone for good,
//! the adopter) and, for leaders, `leader` (the role). Beside them the
//! gateway's own histograms of query latency, by question and outcome.
//! `idmesh_up{role="stats"}` is 0 when the stats could not be had (then
//! only the gateway's own metrics follow).

use crate::asker::{Asker, LatencyFamily};
use axum::extract::State;
use axum::http::{header, StatusCode};
use axum::response::{IntoResponse, Response};
use idmesh_protocol::wire::coordinator_to_leader::LeaderStats;
use idmesh_protocol::wire::coordinator_to_sensor::SensorStatus;
use idmesh_protocol::wire::query::{PositionsAnswer, StatsAnswer};
use prometheus_client::collector::Collector;
use prometheus_client::encoding::{DescriptorEncoder, EncodeMetric};
use prometheus_client::metrics::counter::ConstCounter;
use prometheus_client::metrics::gauge::ConstGauge;
use prometheus_client::metrics::MetricType;
use prometheus_client::registry::Registry;
use std::sync::Arc;

pub(crate) const CONTENT_TYPE: &str = "application/openmetrics-text; version=1.0.0; charset=utf-8";

type Labels = Vec<(String, String)>;

/// A leader counter: (metric name without `idmesh_leader_` and `_total`,
/// help, the value).
type LeaderField = (&'static str, &'static str, fn(&LeaderStats) -> u64);

const LEADER_COUNTERS: [LeaderField; 23] = [
    ("items", "stream items applied", |s| s.items),
    (
        "belief_repairs",
        "colour events the factored belief could not take as they stood (splits retried, sightings smoothed or set aside)",
        |s| s.belief_repairs,
    ),
    (
        "identity_repairs",
        "valid identity events the trees could not take as they stood (repaired)",
        |s| s.identity_repairs,
    ),
    ("mixes", "mix events applied", |s| s.mixes),
    ("observations", "observations applied", |s| s.observations),
    ("handovers", "handovers applied", |s| s.handovers),
    ("identifies", "identity reads applied", |s| s.identifies),
    ("batches", "event batches received", |s| s.batches),
    (
        "bytes_received",
        "bytes of batches and transfers received",
        |s| s.bytes_received,
    ),
    (
        "bytes_sent",
        "bytes of transfers sent to other leaders",
        |s| s.bytes_sent,
    ),
    ("transfers_sent", "transfers sent to other leaders", |s| {
        s.transfers_sent
    }),
    (
        "transfers_received",
        "transfers received from other leaders",
        |s| s.transfers_received,
    ),
    ("sets_sent", "sets handed to other leaders", |s| s.sets_sent),
    ("follows", "follow requests to the sensor", |s| s.follows),
    ("unfollows", "unfollow requests to the sensor", |s| {
        s.unfollows
    }),
    ("omp_runs", "OMP runs on this leader's sets", |s| s.omp_runs),
    ("duplicates", "batches and transfers that came twice", |s| {
        s.duplicates
    }),
    ("gaps", "gaps in the batch numbers", |s| s.gaps),
    ("rejected", "inputs refused at the door", |s| s.rejected),
    ("snapshots", "snapshots written", |s| s.snapshots),
    ("recoveries", "restarts and adoptions caught up", |s| {
        s.recoveries
    }),
    (
        "journal_damage",
        "restarts that found the journal damaged",
        |s| s.journal_damage,
    ),
    (
        "journal_dropped",
        "journal entries dropped with damage (fetched again)",
        |s| s.journal_dropped,
    ),
];

const LEADER_GAUGES: [LeaderField; 7] = [
    ("coefficients", "sets (coefficients) held", |s| {
        s.coefficients
    }),
    ("rows_held", "rows of the information matrix held", |s| {
        s.rows_held
    }),
    (
        "tree_tracks",
        "tracks whose factored identity tree is held",
        |s| s.tree_tracks,
    ),
    ("tracks_owned", "tracks this leader surveils", |s| {
        s.tracks_owned
    }),
    ("tracks_followed", "tracks in this leader's interest", |s| {
        s.tracks_followed
    }),
    ("position", "seq of the last item applied", |s| s.position),
    (
        "transfers_kept",
        "transfers kept for peers not yet safe past them",
        |s| s.transfers_kept,
    ),
];

/// The deployment's counters at one scrape.
#[derive(Debug)]
struct Snapshot {
    stats: Option<StatsAnswer>,
    positions: Option<PositionsAnswer>,
}

fn labels(pairs: &[(&str, &str)]) -> Labels {
    pairs
        .iter()
        .map(|(k, v)| (k.to_string(), v.to_string()))
        .collect()
}

fn leader_labels(s: &LeaderStats) -> Labels {
    let process = if s.host.is_empty() {
        &s.leader
    } else {
        &s.host
    };
    labels(&[
        ("role", "leader"),
        ("leader", &s.leader),
        ("process", process),
    ])
}

impl Collector for Snapshot {
    fn encode(&self, mut encoder: DescriptorEncoder) -> Result<(), std::fmt::Error> {
        let up = ConstGauge::new(i64::from(self.stats.is_some()));
        let mut family =
            encoder.encode_descriptor("up", "1 if query/stats answered", None, up.metric_type())?;
        up.encode(family.encode_family(&labels(&[("role", "stats")]))?)?;
        if let Some(positions) = &self.positions {
            encode_sensor_events(&mut encoder, positions)?;
        }
        let Some(stats) = &self.stats else {
            return Ok(());
        };
        encode_leaders(&mut encoder, &stats.leaders)?;
        encode_rejected(&mut encoder, stats)?;
        encode_ros2(&mut encoder, stats)?;
        encode_sensor_roles(&mut encoder, stats)?;
        encode_coordinator(&mut encoder, stats)
    }
}

/// The trace events the sensor has routed, by sensor.
fn encode_sensor_events(
    encoder: &mut DescriptorEncoder<'_>,
    positions: &PositionsAnswer,
) -> Result<(), std::fmt::Error> {
    let counter = ConstCounter::new(0u64);
    let mut family = encoder.encode_descriptor(
        "sensor_events",
        "trace events the sensor has routed",
        None,
        counter.metric_type(),
    )?;
    for (sensor, &events) in &positions.watermark {
        let labels = labels(&[("role", "sensor"), ("process", sensor)]);
        ConstCounter::new(events).encode(family.encode_family(&labels)?)?;
    }
    Ok(())
}

/// Every leader's counters and gauges, and how long its last recovery took.
fn encode_leaders(
    encoder: &mut DescriptorEncoder<'_>,
    leaders: &[LeaderStats],
) -> Result<(), std::fmt::Error> {
    for (name, help, field) in LEADER_COUNTERS {
        let name = format!("leader_{name}");
        let mut family =
            encoder.encode_descriptor(&name, help, None, ConstCounter::new(0u64).metric_type())?;
        for s in leaders {
            ConstCounter::new(field(s)).encode(family.encode_family(&leader_labels(s))?)?;
        }
    }
    for (name, help, field) in LEADER_GAUGES {
        let name = format!("leader_{name}");
        let mut family =
            encoder.encode_descriptor(&name, help, None, ConstGauge::new(0i64).metric_type())?;
        for s in leaders {
            let value = i64::try_from(field(s)).unwrap_or(i64::MAX);
            ConstGauge::new(value).encode(family.encode_family(&leader_labels(s))?)?;
        }
    }
    let mut family = encoder.encode_descriptor(
        "leader_recovery_seconds",
        "how long the last recovery took",
        None,
        ConstGauge::new(0.0f64).metric_type(),
    )?;
    for s in leaders {
        ConstGauge::new(s.recovery_seconds).encode(family.encode_family(&leader_labels(s))?)?;
    }
    Ok(())
}

/// Bad input refused, by every role.
fn encode_rejected(
    encoder: &mut DescriptorEncoder<'_>,
    stats: &StatsAnswer,
) -> Result<(), std::fmt::Error> {
    let mut family = encoder.encode_descriptor(
        "rejected",
        "bad input refused (leaders: at the door; sensors: follow, resend and ingest requests, ingested lines; coordinator: queries)",
        None,
        ConstCounter::new(0u64).metric_type(),
    )?;
    for s in &stats.leaders {
        ConstCounter::new(s.rejected).encode(family.encode_family(&leader_labels(s))?)?;
    }
    // One label set per family (parsers insist): `leader` is empty for
    // the roles that are not leaders.
    for s in &stats.sensors {
        let labels = labels(&[
            ("role", "sensor"),
            ("leader", ""),
            ("process", &s.counters.sensor),
        ]);
        ConstCounter::new(s.counters.rejected).encode(family.encode_family(&labels)?)?;
    }
    let rejected_by_coordinator = labels(&[
        ("role", "coordinator"),
        ("leader", ""),
        ("process", "coordinator"),
    ]);
    ConstCounter::new(stats.coordinator.rejected)
        .encode(family.encode_family(&rejected_by_coordinator)?)?;
    Ok(())
}

/// Messages every sensor read from ROS 2 topics, and those it refused.
fn encode_ros2(
    encoder: &mut DescriptorEncoder<'_>,
    stats: &StatsAnswer,
) -> Result<(), std::fmt::Error> {
    let fields: [SensorField<ConstCounter<u64>>; 2] = [
        (
            "sensor_ros2_messages",
            "messages read from ROS 2 topics",
            |s| ConstCounter::new(s.counters.ros2_messages),
        ),
        (
            "sensor_ros2_bad",
            "ROS 2 messages refused: they did not decode",
            |s| ConstCounter::new(s.counters.ros2_bad),
        ),
    ];
    let kind = ConstCounter::new(0u64).metric_type();
    encode_per_sensor(encoder, stats, kind, fields)
}

/// Each sensor role: the epoch its process holds it at, and whether its
/// journal is replicated to a standby now (0: on one disk alone).
fn encode_sensor_roles(
    encoder: &mut DescriptorEncoder<'_>,
    stats: &StatsAnswer,
) -> Result<(), std::fmt::Error> {
    let fields: [SensorField<ConstGauge<i64>>; 2] = [
        (
            "sensor_epoch",
            "the epoch the sensor role is held at (0 without voters)",
            |s| ConstGauge::new(s.epoch as i64),
        ),
        (
            "sensor_replicated",
            "1 while the sensor's journal is replicated to a standby, 0 while it is on one disk",
            |s| ConstGauge::new(i64::from(s.standby.is_some())),
        ),
    ];
    encode_per_sensor(encoder, stats, ConstGauge::new(0i64).metric_type(), fields)
}

/// A family of one metric per sensor: its name, its help, and the
/// sensor's metric.
type SensorField<M> = (&'static str, &'static str, fn(&SensorStatus) -> M);

/// Each field's family, of metrics of `kind`, with one metric per sensor
/// labelled by its process.
fn encode_per_sensor<M: EncodeMetric>(
    encoder: &mut DescriptorEncoder<'_>,
    stats: &StatsAnswer,
    kind: MetricType,
    fields: impl IntoIterator<Item = SensorField<M>>,
) -> Result<(), std::fmt::Error> {
    for (name, help, field) in fields {
        let mut family = encoder.encode_descriptor(name, help, None, kind)?;
        for s in &stats.sensors {
            let labels = labels(&[("role", "sensor"), ("process", &s.counters.sensor)]);
            field(s).encode(family.encode_family(&labels)?)?;
        }
    }
    Ok(())
}

/// The coordinator's own counters.
fn encode_coordinator(
    encoder: &mut DescriptorEncoder<'_>,
    stats: &StatsAnswer,
) -> Result<(), std::fmt::Error> {
    let coordinator = labels(&[("role", "coordinator"), ("process", "coordinator")]);
    for (name, help, value) in [
        (
            "coordinator_bad_replies",
            "replies from leaders or the sensor that were no good",
            stats.coordinator.bad_replies,
        ),
        (
            "coordinator_degraded_answers",
            "queries answered degraded (a leader missing or not at the cut)",
            stats.coordinator.degraded,
        ),
        (
            "coordinator_cuts_pushed",
            "fresh cuts whose every leader pushed its sums on reaching them",
            stats.coordinator.cuts_pushed,
        ),
        (
            "coordinator_cuts_asked",
            "fresh cuts whose leaders were asked, a push not having come in time",
            stats.coordinator.cuts_asked,
        ),
        (
            "coordinator_query_repairs",
            "factored answers the contradiction rule gave (the leaders' components held no count the prior allows)",
            stats.coordinator.query_repairs,
        ),
    ] {
        let counter = ConstCounter::new(value);
        let family = encoder.encode_descriptor(name, help, None, counter.metric_type())?;
        let mut family = family;
        counter.encode(family.encode_family(&coordinator)?)?;
    }
    Ok(())
}

/// The whole exposition at this moment.
pub(crate) async fn exposition(asker: &Asker) -> Result<String, std::fmt::Error> {
    let keys = &asker.keys;
    let (stats_key, positions_key) = (keys.query_stats(), keys.query_positions());
    let (stats, positions) = tokio::join!(
        asker.ask(&stats_key, "stats"),
        asker.ask(&positions_key, "positions")
    );
    let snapshot = Snapshot {
        stats: stats
            .ok()
            .then(|| serde_json::from_slice(&stats.body).ok())
            .flatten(),
        positions: positions
            .ok()
            .then(|| serde_json::from_slice(&positions.body).ok())
            .flatten(),
    };
    render(snapshot, asker.latency.clone())
}

/// The exposition of `snapshot` and the gateway's latency histograms.
fn render(snapshot: Snapshot, latency: LatencyFamily) -> Result<String, std::fmt::Error> {
    let mut registry = Registry::with_prefix("idmesh");
    registry.register_collector(Box::new(snapshot));
    // Seconds by name, not by a UNIT line: some OpenMetrics parsers
    // refuse units on histograms.
    registry.register(
        "web_query_latency_seconds",
        "how long the gateway waited for the coordinator, by question and outcome",
        latency,
    );
    let mut text = String::new();
    prometheus_client::encoding::text::encode(&mut text, &registry)?;
    Ok(text)
}

pub(crate) async fn metrics(State(asker): State<Arc<Asker>>) -> Response {
    match exposition(&asker).await {
        Ok(text) => ([(header::CONTENT_TYPE, CONTENT_TYPE)], text).into_response(),
        Err(_) => (
            StatusCode::INTERNAL_SERVER_ERROR,
            "the metrics could not be encoded",
        )
            .into_response(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::asker::{latency_family, query_labels};
    use idmesh_protocol::wire::coordinator_to_sensor::SensorStats;
    use idmesh_protocol::wire::query::CoordinatorStats;
    use openmetrics_parser::openmetrics::parse_openmetrics;
    use openmetrics_parser::OpenMetricsValue;

    fn leader(name: &str, host: &str, items: u64, rejected: u64) -> LeaderStats {
        LeaderStats {
            leader: name.into(),
            host: host.into(),
            items,
            rejected,
            ..LeaderStats::default()
        }
    }

    fn value(text: &str, family: &str, label: (&str, &str)) -> f64 {
        let exposition = parse_openmetrics(text).expect("OpenMetrics");
        let family = &exposition.families[family];
        let sample = family
            .iter_samples()
            .find(|s| {
                s.get_labelset()
                    .ok()
                    .and_then(|l| l.get_label_value(label.0).map(|v| v == label.1))
                    .unwrap_or(false)
            })
            .unwrap_or_else(|| panic!("{label:?} in {}", family.family_name));
        match &sample.value {
            OpenMetricsValue::Counter(c) => c.value.as_f64(),
            OpenMetricsValue::Gauge(g) => g.as_f64(),
            other => panic!("{other:?}"),
        }
    }

    /// Every role in one exposition: a parser that insists on one label
    /// set per family reads it, and each number is the one the stats say
    /// (an adopted role is labelled with the process that runs it).
    #[test]
    fn every_role_is_one_parseable_family_member_with_its_own_numbers() {
        let stats = StatsAnswer {
            leaders: vec![
                leader("leader-0", "", 40, 1),
                leader("leader-1", "leader-0", 7, 0),
            ],
            sensors: vec![SensorStatus {
                counters: SensorStats {
                    sensor: "sensor-0".into(),
                    rejected: 2,
                    ros2_messages: 9,
                    ..SensorStats::default()
                },
                epoch: 4,
                standby: Some("sensor-0-standby".into()),
            }],
            coordinator: CoordinatorStats {
                rejected: 3,
                bad_replies: 0,
                degraded: 5,
                ..CoordinatorStats::default()
            },
        };
        let snapshot = Snapshot {
            stats: Some(stats),
            positions: None,
        };
        let latency = latency_family();
        latency
            .get_or_create(&query_labels("marginals", "ok"))
            .observe(0.003);
        let text = render(snapshot, latency).expect("encodes");
        assert_eq!(
            value(&text, "idmesh_leader_items", ("leader", "leader-0")),
            40.0
        );
        assert_eq!(
            value(&text, "idmesh_leader_items", ("process", "leader-0")),
            40.0
        );
        assert_eq!(
            value(&text, "idmesh_leader_items", ("leader", "leader-1")),
            7.0
        );
        assert_eq!(value(&text, "idmesh_rejected", ("role", "leader")), 1.0);
        assert_eq!(value(&text, "idmesh_rejected", ("role", "sensor")), 2.0);
        assert_eq!(
            value(&text, "idmesh_sensor_epoch", ("process", "sensor-0")),
            4.0
        );
        assert_eq!(
            value(&text, "idmesh_sensor_replicated", ("process", "sensor-0")),
            1.0
        );
        assert_eq!(
            value(
                &text,
                "idmesh_sensor_ros2_messages",
                ("process", "sensor-0")
            ),
            9.0
        );
        assert_eq!(
            value(&text, "idmesh_rejected", ("role", "coordinator")),
            3.0
        );
        assert_eq!(
            value(
                &text,
                "idmesh_coordinator_degraded_answers",
                ("role", "coordinator")
            ),
            5.0
        );
        assert!(text.contains("idmesh_leader_items_total{role=\"leader\",leader=\"leader-1\",process=\"leader-0\"} 7"), "{text}");
        assert!(text.ends_with("# EOF\n"));
    }

    /// Without stats (the coordinator down) the scrape still parses: `up`
    /// says 0 and only the gateway's own metrics follow.
    #[test]
    fn without_stats_up_is_zero_and_the_rest_still_parses() {
        let snapshot = Snapshot {
            stats: None,
            positions: None,
        };
        let text = render(snapshot, latency_family()).expect("encodes");
        assert_eq!(value(&text, "idmesh_up", ("role", "stats")), 0.0);
        assert!(!text.contains("idmesh_leader_items"));
    }
}
