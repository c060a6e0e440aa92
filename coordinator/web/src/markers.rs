//! Beliefs out to RViz: with `--ros2-markers TOPIC` (or a topology's
//! `[web] ros2_markers`, in the gateway `idmesh up` serves), the gateway
//! publishes at a fixed rate a `visualization_msgs/msg/MarkerArray` on
//! that ROS 2 topic as rmw_zenoh does — the data key
//! `<domain>/<topic>/visualization_msgs::msg::dds_::MarkerArray_/<RIHS01 hash>`,
//! a CDR payload, rmw_zenoh's attachment on every sample, and liveliness
//! tokens for a node and its publisher, so that `ros2 topic list` lists
//! the topic and RViz (on rmw_zenoh) draws it.
//!
//! Each look asks `query/positions` and `query/marginals` (and
//! `query/identity`, which a stream without identities refuses: then the
//! texts say P(red)) and draws every track with a position: a sphere
//! coloured from P(red) and its likely identity above it
//! ([`markers`](idmesh_extract::adapters::ros2::markers)). A look the
//! deployment does not answer publishes nothing.

use crate::asker::Asker;
use idmesh_extract::adapters::ros2::geometry::Time;
use idmesh_extract::adapters::ros2::markers::{
    marker_array, TrackView, MARKER_ARRAY, MARKER_ARRAY_HASH,
};
use idmesh_extract::adapters::ros2::rmw::{Attachment, Graph};
use idmesh_extract::adapters::ros2::{cdr, keys};
use serde::Deserialize;
use std::sync::Arc;
use std::time::{Duration, SystemTime, UNIX_EPOCH};

/// Where and how often the markers go.
#[derive(Debug, Clone)]
pub struct MarkersConfig {
    /// The ROS domain id.
    pub domain: u32,
    /// The fully qualified topic (`/idmesh/markers`).
    pub topic: String,
    /// The markers' `header.frame_id` (RViz's fixed frame).
    pub frame: String,
    /// Time between two arrays.
    pub every: Duration,
    /// Write Humble's `TypeHashNotSupported` in the key and tokens in
    /// place of the type hash (Humble's rmw_zenoh subscribes to that).
    pub humble: bool,
}

/// What Humble's rmw_zenoh writes where later releases write the type
/// hash.
pub const NO_TYPE_HASH: &str = "TypeHashNotSupported";

/// The ROS node the gateway appears as.
const NODE: &str = "idmesh_web";

#[derive(Deserialize)]
struct Positions {
    positions: Vec<Option<[f64; 2]>>,
}

#[derive(Deserialize)]
struct Marginals {
    p_red: Vec<f64>,
}

#[derive(Deserialize)]
struct Row {
    rest: f64,
    listed: Vec<(u32, f64)>,
}

#[derive(Deserialize)]
struct Identities {
    p_identity: Vec<Row>,
    predicted_identity: Vec<u32>,
}

/// Publishes until the task is dropped; logs why it cannot start.
pub(crate) async fn publish(asker: Arc<Asker>, config: MarkersConfig) {
    if let Err(e) = run(&asker, &config).await {
        tracing::warn!(error = %e, topic = %config.topic, "no ROS 2 markers");
    }
}

async fn run(asker: &Asker, config: &MarkersConfig) -> Result<(), zenoh::Error> {
    let session = &asker.session;
    let dds = keys::dds_type_name(MARKER_ARRAY).unwrap_or_default();
    let hash = if config.humble {
        NO_TYPE_HASH
    } else {
        MARKER_ARRAY_HASH
    };
    let key = keys::data_key(config.domain, &config.topic, &dds, hash);
    let zid = session.zid();
    let graph = Graph {
        domain: config.domain,
        zid: zid.to_string(),
        namespace: "/".into(),
        node: NODE.into(),
    };
    let publisher = session.declare_publisher(key.clone()).await?;
    let _node = session
        .liveliness()
        .declare_token(graph.node_token())
        .await?;
    let _publisher = session
        .liveliness()
        .declare_token(graph.publisher_token(1, &config.topic, &dds, hash))
        .await?;
    tracing::info!(%key, "publishing ROS 2 markers");
    let mut ticks = tokio::time::interval(config.every);
    ticks.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Delay);
    let mut sequence: i64 = 0;
    loop {
        ticks.tick().await;
        let Some(views) = look(asker).await else {
            continue;
        };
        let now = SystemTime::now()
            .duration_since(UNIX_EPOCH)
            .unwrap_or_default();
        let stamp = Time {
            sec: now.as_secs() as i32,
            nanosec: now.subsec_nanos(),
        };
        let array = marker_array(&views, &config.frame, stamp);
        let Ok(payload) = cdr::encode(&array) else {
            continue;
        };
        sequence += 1;
        let attachment = Attachment {
            sequence_number: sequence,
            source_timestamp: now.as_nanos() as i64,
            source_gid: zid.to_le_bytes(),
        };
        if let Err(e) = publisher.put(payload).attachment(attachment.encode()).await {
            tracing::warn!(error = %e, "a MarkerArray not published");
        }
    }
}

/// The tracks as the deployment answers now, or `None` when it does not.
async fn look(asker: &Asker) -> Option<Vec<TrackView>> {
    let positions = asker.ask(&asker.keys.query_positions(), "positions").await;
    let positions: Positions = serde_json::from_slice(&positions.body)
        .ok()
        .filter(|_| positions.ok())?;
    let marginals = asker.ask(&asker.keys.query_marginals(), "marginals").await;
    let marginals: Marginals = serde_json::from_slice(&marginals.body)
        .ok()
        .filter(|_| marginals.ok())?;
    let identity = asker.ask(&asker.keys.query_identity(), "identity").await;
    let identities: Option<Identities> = identity
        .ok()
        .then(|| serde_json::from_slice(&identity.body).ok())
        .flatten();
    Some(views(&positions, &marginals, identities.as_ref()))
}

fn views(
    positions: &Positions,
    marginals: &Marginals,
    identities: Option<&Identities>,
) -> Vec<TrackView> {
    positions
        .positions
        .iter()
        .zip(&marginals.p_red)
        .enumerate()
        .filter_map(|(track, (at, &p_red))| {
            let at = (*at)?;
            let identity = identities.and_then(|ids| likely(ids, track));
            Some(TrackView {
                track: track as u32,
                at,
                p_red,
                identity,
            })
        })
        .collect()
}

/// Track `track`'s likely identity and its probability.
fn likely(ids: &Identities, track: usize) -> Option<(u32, f64)> {
    let identity = *ids.predicted_identity.get(track)?;
    let row = ids.p_identity.get(track)?;
    let p = row
        .listed
        .iter()
        .find(|(i, _)| *i == identity)
        .map_or(row.rest, |(_, p)| *p);
    Some((identity, p))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn tracks_without_a_position_are_not_drawn() {
        let positions = Positions {
            positions: vec![Some([1.0, 2.0]), None],
        };
        let marginals = Marginals {
            p_red: vec![0.25, 0.5],
        };
        let ids = Identities {
            p_identity: vec![
                Row {
                    rest: 0.1,
                    listed: vec![(1, 0.9)],
                },
                Row {
                    rest: 0.5,
                    listed: vec![],
                },
            ],
            predicted_identity: vec![1, 0],
        };
        let v = views(&positions, &marginals, Some(&ids));
        assert_eq!(v.len(), 1);
        assert_eq!(v[0].identity, Some((1, 0.9)));
        assert_eq!(v[0].p_red, 0.25);
    }
}
