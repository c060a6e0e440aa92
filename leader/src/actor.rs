//! The leader process: the [`Leader`] state machine behind Zenoh.
//!
//! One task owns the state; everything else (stream batches, transfers from
//! peers, the sensor's follow replies, the coordinator's queries) reaches it
//! through channels, so items are applied strictly one at a time. The
//! coordinator asks for a cut by its tag at the same time as it asks the
//! sensor to place it, so a query usually comes before its cut: it is held
//! until the cut arrives, or answered with an error once it has waited the
//! query timeout.

use crate::error::MeshError;
use crate::state::{Action, Leader};
use idmesh_protocol::wire::coordinator_to_leader::Partial;
use idmesh_protocol::wire::keys::Keys;
use idmesh_protocol::wire::leader_to_leader::Transfer;
use idmesh_protocol::wire::leader_to_sensor::Followed;
use idmesh_protocol::wire::sensor_to_leader::{Batch, Sequenced};
use idmesh_protocol::wire::{decode, encode};
use std::future::Future;
use std::time::{Duration, Instant};
use tokio::sync::mpsc;
use zenoh::qos::CongestionControl;
use zenoh::query::{ConsolidationMode, Query, QueryTarget};
use zenoh::Session;

#[derive(Debug, Clone)]
pub struct LeaderConfig {
    pub name: String,
    pub keys: Keys,
    /// The sensor gateway to ask when sets bring tracks to follow.
    pub sensor: String,
    /// How long to wait for the sensor's follow reply, and how long a query
    /// is held for a cut that has not arrived.
    pub follow_timeout: Duration,
}

/// Runs a leader until `shutdown` completes.
pub async fn run(
    session: Session,
    config: LeaderConfig,
    shutdown: impl Future<Output = ()>,
) -> Result<(), MeshError> {
    let keys = &config.keys;
    let name = config.name.clone();
    let events = session
        .declare_subscriber(keys.leader_events(&name))
        .await
        .map_err(|e| MeshError::new("declare the event subscriber", e))?;
    let transfers = session
        .declare_subscriber(keys.leader_transfer(&name))
        .await
        .map_err(|e| MeshError::new("declare the transfer subscriber", e))?;
    let partials = session
        .declare_queryable(keys.leader_partial(&name))
        .await
        .map_err(|e| MeshError::new("declare the partial-sums queryable", e))?;
    let stats = session
        .declare_queryable(keys.leader_stats(&name))
        .await
        .map_err(|e| MeshError::new("declare the stats queryable", e))?;
    // Declared last: whoever sees the token can use everything above.
    let _token = session
        .liveliness()
        .declare_token(keys.alive("leader", &name))
        .await
        .map_err(|e| MeshError::new("declare the liveliness token", e))?;
    tracing::info!(leader = %name, "leader up");

    let (followed_tx, mut followed_rx) =
        mpsc::unbounded_channel::<Result<Vec<Sequenced>, String>>();
    let mut leader = Leader::new(name.clone());
    let mut held: Vec<Held> = Vec::new();
    let mut failure: Option<String> = None;
    let mut sweep = tokio::time::interval(Duration::from_millis(250));
    tokio::pin!(shutdown);

    loop {
        let actions = tokio::select! {
            _ = &mut shutdown => break,
            sample = events.recv_async() => {
                let Ok(sample) = sample else { break };
                let bytes = sample.payload().to_bytes();
                match decode::<Batch>(&bytes) {
                    Ok(batch) => leader.batch(batch, bytes.len()),
                    Err(e) => {
                        tracing::error!(leader = %name, error = %e, "dropped an undecodable batch");
                        continue;
                    }
                }
            }
            sample = transfers.recv_async() => {
                let Ok(sample) = sample else { break };
                let bytes = sample.payload().to_bytes();
                match decode::<Transfer>(&bytes) {
                    Ok(transfer) => leader.transfer(transfer, bytes.len()),
                    Err(e) => {
                        tracing::error!(leader = %name, error = %e, "dropped an undecodable transfer");
                        continue;
                    }
                }
            }
            reply = followed_rx.recv() => {
                match reply {
                    Some(Ok(items)) => leader.followed(items),
                    Some(Err(e)) => {
                        failure = Some(format!("follow request failed: {e}"));
                        tracing::error!(leader = %name, error = %e, "follow request failed");
                        continue;
                    }
                    None => break,
                }
            }
            query = partials.recv_async() => {
                let Ok(query) = query else { break };
                answer_partial(&leader, &failure, query, &mut held).await;
                continue;
            }
            _ = sweep.tick(), if !held.is_empty() => {
                expire(&mut held, config.follow_timeout).await;
                continue;
            }
            query = stats.recv_async() => {
                let Ok(query) = query else { break };
                let body = serde_json::to_vec(&leader.stats()).unwrap_or_default();
                if let Err(e) = query
                    .reply(keys.leader_stats(&name), body)
                    .encoding(zenoh::bytes::Encoding::APPLICATION_JSON)
                    .await
                {
                    tracing::warn!(leader = %name, error = %e, "could not answer a stats query");
                }
                continue;
            }
        };
        let actions = match actions {
            Ok(actions) => actions,
            Err(e) => {
                tracing::error!(leader = %name, error = %e, "leader cannot go on applying its stream");
                failure = Some(e.to_string());
                continue;
            }
        };
        for action in actions {
            match action {
                Action::Send { to, transfer } => {
                    let Some(peer) = leader.peer(to).map(str::to_owned) else {
                        failure = Some(format!("transfer to unknown leader index {to}"));
                        continue;
                    };
                    let body = encode(&transfer);
                    tracing::debug!(leader = %name, to = %peer, seq = transfer.seq, sets = transfer.sets.len(), "hand over sets");
                    leader.note_sent(body.len());
                    if let Err(e) = session
                        .put(keys.leader_transfer(&peer), body)
                        .congestion_control(CongestionControl::Block)
                        .await
                    {
                        failure = Some(format!("could not send sets to {peer}: {e}"));
                    }
                }
                Action::Follow(follow) => {
                    let session = session.clone();
                    let key = keys.sensor_follow(&config.sensor);
                    let tx = followed_tx.clone();
                    let timeout = config.follow_timeout;
                    tokio::spawn(async move {
                        let result = ask_to_follow(&session, &key, encode(&follow), timeout).await;
                        let _ = tx.send(result);
                    });
                }
                Action::CutReady(partial) => {
                    let ready: Vec<Held> = held.extract_if(.., |h| h.tag == partial.tag).collect();
                    for h in ready {
                        reply_partial(&h.query, &partial).await;
                    }
                }
            }
        }
    }
    tracing::info!(leader = %name, "leader stopped");
    Ok(())
}

async fn ask_to_follow(
    session: &Session,
    key: &str,
    body: Vec<u8>,
    timeout: Duration,
) -> Result<Vec<Sequenced>, String> {
    let replies = session
        .get(key)
        .payload(body)
        .consolidation(ConsolidationMode::None)
        .target(QueryTarget::All)
        .timeout(timeout)
        .await
        .map_err(|e| e.to_string())?;
    match tokio::time::timeout(timeout + Duration::from_secs(1), replies.recv_async()).await {
        Ok(Ok(reply)) => match reply.result() {
            Ok(sample) => decode::<Followed>(&sample.payload().to_bytes())
                .map(|f| f.items)
                .map_err(|e| e.to_string()),
            Err(e) => Err(String::from_utf8_lossy(&e.payload().to_bytes()).into_owned()),
        },
        Ok(Err(_)) => Err("the sensor did not answer".into()),
        Err(_) => Err("the sensor did not answer in time".into()),
    }
}

/// A partial-sums query waiting for its cut.
struct Held {
    tag: u64,
    since: Instant,
    query: Query,
}

async fn answer_partial(
    leader: &Leader,
    failure: &Option<String>,
    query: Query,
    held: &mut Vec<Held>,
) {
    if let Some(failure) = failure {
        let _ = query
            .reply_err(format!("leader {} failed: {failure}", leader.name()))
            .await;
        return;
    }
    if query.parameters().contains_key("quiet") {
        // `;rows`: an identity query wants the rows of the information matrix.
        match leader.quiet(query.parameters().contains_key("rows")) {
            Some(partial) => reply_partial(&query, &partial).await,
            None => {
                let _ = query
                    .reply_err(format!("leader {} is not at a quiet point", leader.name()))
                    .await;
            }
        }
        return;
    }
    let tag = query
        .parameters()
        .get("tag")
        .and_then(|c| c.parse::<u64>().ok());
    let Some(tag) = tag else {
        let _ = query
            .reply_err(
                "a partial-sums query needs tag=<u64> (the tag of the cut it asks for) or quiet",
            )
            .await;
        return;
    };
    match leader.cut(tag) {
        Some(partial) => reply_partial(&query, partial).await,
        None => held.push(Held {
            tag,
            since: Instant::now(),
            query,
        }),
    }
}

/// Answers with an error every query that has waited longer than `timeout`
/// for its cut (the sensor never placed it, or the stream is stuck).
async fn expire(held: &mut Vec<Held>, timeout: Duration) {
    let expired: Vec<Held> = held
        .extract_if(.., |h| h.since.elapsed() > timeout)
        .collect();
    for h in expired {
        let _ = h
            .query
            .reply_err(format!(
                "the cut tagged {} did not reach this leader within {timeout:?}",
                h.tag
            ))
            .await;
    }
}

async fn reply_partial(query: &Query, partial: &Partial) {
    if let Err(e) = query.reply(query.key_expr().clone(), encode(partial)).await {
        tracing::warn!(error = %e, "could not answer a partial-sums query");
    }
}
