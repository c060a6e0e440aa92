//! One answer at a consistent cut.

use idmesh_belief::predict_red;
use idmesh_leader::combine;
use idmesh_protocol::wire::coordinator_to_leader::{LeaderStats, Partial};
use idmesh_protocol::wire::coordinator_to_sensor::CutPlaced;
use idmesh_protocol::wire::decode;
use idmesh_protocol::wire::keys::Keys;
use idmesh_protocol::wire::query::{MarginalsAnswer, Watermark};
use std::collections::BTreeMap;
use std::time::Duration;
use zenoh::query::{ConsolidationMode, QueryTarget};
use zenoh::Session;

#[derive(Debug, thiserror::Error)]
pub enum GatherError {
    #[error("no sensor gateway answered: the stream has no source yet")]
    NoSensor,
    #[error("no leader is listed by the sensor")]
    NoLeaders,
    #[error("leaders {missing:?} did not answer within {timeout:?}; no partial answer is given")]
    Missing {
        missing: Vec<String>,
        timeout: Duration,
    },
    #[error("{0}")]
    Failed(String),
    #[error("the belief has no mass at this cut: the observations contradict each other")]
    Degenerate,
}

/// What a marginals query found.
#[derive(Debug, Clone)]
pub struct Gathered {
    pub cut: CutPlaced,
    pub answer: MarginalsAnswer,
}

pub async fn marginals(
    session: &Session,
    keys: &Keys,
    timeout: Duration,
) -> Result<Gathered, GatherError> {
    let cut = place_cut(session, keys, timeout).await?;
    if cut.leaders.is_empty() {
        return Err(GatherError::NoLeaders);
    }
    let selector = format!("{}?cut={}", keys.every_leader_partial(), cut.seq);
    let replies = session
        .get(selector)
        .consolidation(ConsolidationMode::None)
        .target(QueryTarget::All)
        .timeout(timeout)
        .await
        .map_err(|e| GatherError::Failed(format!("query the leaders: {e}")))?;
    let mut parts: BTreeMap<String, Partial> = BTreeMap::new();
    let mut errors = Vec::new();
    while let Ok(reply) = replies.recv_async().await {
        match reply.result() {
            Ok(sample) => match decode::<Partial>(&sample.payload().to_bytes()) {
                Ok(p) if p.cut == cut.seq => {
                    parts.insert(p.leader.clone(), p);
                }
                Ok(p) => errors.push(format!(
                    "{} answered cut {} for {}",
                    p.leader, p.cut, cut.seq
                )),
                Err(e) => errors.push(e.to_string()),
            },
            Err(e) => errors.push(String::from_utf8_lossy(&e.payload().to_bytes()).into_owned()),
        }
        if cut.leaders.iter().all(|l| parts.contains_key(l)) {
            break;
        }
    }
    if !errors.is_empty() {
        return Err(GatherError::Failed(errors.join("; ")));
    }
    let missing: Vec<String> = cut
        .leaders
        .iter()
        .filter(|l| !parts.contains_key(*l))
        .cloned()
        .collect();
    if !missing.is_empty() {
        return Err(GatherError::Missing { missing, timeout });
    }
    let parts: Vec<Partial> = parts.into_values().collect();
    let sums = combine(&parts);
    let p_red = sums
        .marginals(cut.tracks as usize)
        .map_err(|_| GatherError::Degenerate)?;
    let predicted_red = predict_red(&p_red, cut.red.map(|k| k as usize));
    let mut watermark = Watermark::new();
    watermark.insert(cut.sensor.clone(), cut.events);
    let answer = MarginalsAnswer {
        watermark,
        tracks: cut.tracks,
        red: cut.red,
        p_red,
        predicted_red,
        leaders: parts.len() as u32,
        coefficients: sums.coefficients,
        finished: cut.finished,
    };
    Ok(Gathered { cut, answer })
}

async fn place_cut(
    session: &Session,
    keys: &Keys,
    timeout: Duration,
) -> Result<CutPlaced, GatherError> {
    let replies = session
        .get(keys.every_sensor_cut())
        .consolidation(ConsolidationMode::None)
        .target(QueryTarget::All)
        .timeout(timeout)
        .await
        .map_err(|e| GatherError::Failed(format!("ask for a cut: {e}")))?;
    while let Ok(reply) = replies.recv_async().await {
        if let Ok(sample) = reply.result() {
            return decode::<CutPlaced>(&sample.payload().to_bytes())
                .map_err(|e| GatherError::Failed(e.to_string()));
        }
    }
    Err(GatherError::NoSensor)
}

/// Every leader's counters.
pub async fn stats(
    session: &Session,
    keys: &Keys,
    timeout: Duration,
) -> Result<Vec<LeaderStats>, GatherError> {
    let replies = session
        .get(keys.every_leader_stats())
        .consolidation(ConsolidationMode::None)
        .target(QueryTarget::All)
        .timeout(timeout)
        .await
        .map_err(|e| GatherError::Failed(format!("query the leaders: {e}")))?;
    let mut all = Vec::new();
    while let Ok(reply) = replies.recv_async().await {
        if let Ok(sample) = reply.result() {
            if let Ok(stats) = serde_json::from_slice::<LeaderStats>(&sample.payload().to_bytes()) {
                all.push(stats);
            }
        }
    }
    if all.is_empty() {
        return Err(GatherError::NoLeaders);
    }
    all.sort_by(|a, b| a.leader.cmp(&b.leader));
    Ok(all)
}
