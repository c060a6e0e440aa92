//! The coordinator process: the user API's queryables. Each query is
//! answered in its own task, with a span, so slow leaders do not hold up
//! other users.

pub(crate) mod gather;
mod identity;

use crate::identity::Method;
use crate::pushed::Pushes;
use crate::request::Request;
use gather::{At, GatherError, Memory};
use idmesh_protocol::wire::keys::Keys;
use idmesh_protocol::wire::query::{
    IdentityAnswer, IdentityTrackAnswer, QueryError, StatsAnswer, TrackAnswer,
};
use serde::Serialize;
use std::future::Future;
use std::sync::Arc;
use std::time::Duration;
use tracing::Instrument;
use zenoh::bytes::{Encoding, ZBytes};
use zenoh::query::Query;
use zenoh::Session;

#[derive(Debug, Clone)]
pub struct CoordinatorConfig {
    pub name: String,
    pub keys: Keys,
    /// How long a leader may take to answer.
    pub timeout: Duration,
    /// How long one identity answer's marginals may take to compute
    /// before the computation is stopped and the asker told why.
    pub marginals_timeout: Duration,
}

pub async fn run(
    session: Session,
    config: CoordinatorConfig,
    shutdown: impl Future<Output = ()>,
) -> Result<(), zenoh::Error> {
    let keys = config.keys.clone();
    let marginals = session.declare_queryable(keys.query_marginals()).await?;
    let tracks = session.declare_queryable(keys.query_any_track()).await?;
    let stats = session.declare_queryable(keys.query_stats()).await?;
    let positions = session.declare_queryable(keys.query_positions()).await?;
    let identities = session.declare_queryable(keys.query_identity()).await?;
    let identity_tracks = session
        .declare_queryable(keys.query_any_identity_track())
        .await?;
    let _token = session
        .liveliness()
        .declare_token(keys.alive("coordinator", &config.name))
        .await?;
    // Leaders' answers pushed at the cuts they reach, for the queries
    // waiting for them (taken on Zenoh's thread: a lookup and a send).
    let pushes = Arc::new(Pushes::default());
    let taker = pushes.clone();
    let _pushed = session
        .declare_subscriber(keys.every_leader_pushed())
        .callback(move |sample| {
            taker.take(
                sample.key_expr().as_str(),
                sample.payload().to_bytes().into_owned(),
            )
        })
        .await?;
    tracing::info!(coordinator = %config.name, "coordinator up");
    let memory = Arc::new(Memory::default());
    tokio::pin!(shutdown);
    loop {
        let (kind, query) = tokio::select! {
            _ = &mut shutdown => break,
            q = marginals.recv_async() => ("marginals", q),
            q = tracks.recv_async() => ("track", q),
            q = stats.recv_async() => ("stats", q),
            q = positions.recv_async() => ("positions", q),
            q = identities.recv_async() => ("identity", q),
            q = identity_tracks.recv_async() => ("identity track", q),
        };
        let Ok(query) = query else { break };
        let session = session.clone();
        let config = config.clone();
        let span = tracing::info_span!("query", kind, key = %query.key_expr());
        tokio::spawn(
            answer(session, config, memory.clone(), pushes.clone(), kind, query).instrument(span),
        );
    }
    Ok(())
}

async fn answer(
    session: Session,
    config: CoordinatorConfig,
    memory: Arc<Memory>,
    pushes: Arc<Pushes>,
    kind: &'static str,
    query: Query,
) {
    let keys = &config.keys;
    let parameters = query.parameters();
    let request = Request::parse(kind, query.key_expr().as_str(), parameters.iter());
    let result: Result<ZBytes, String> = match request {
        Err(error) => {
            // A bad question is the asker's fault: counted, answered with
            // why, and no leader is bothered with it.
            memory.note_rejected();
            tracing::warn!(%error, rejected = memory.stats().rejected, "query rejected");
            Err(error)
        }
        Ok(Request::Marginals(at)) => {
            gather::marginals(&session, keys, config.timeout, &memory, &pushes, at)
                .await
                .map(|g| memory.marginals_json(g.answer).into())
                .map_err(|e| e.to_string())
        }
        Ok(Request::Track(at, track)) => {
            self::track(&session, &config, &memory, &pushes, at, track).await
        }
        Ok(Request::Identity(at, method)) => identities(&session, &config, &memory, at, method)
            .await
            .map(|a| json(&a)),
        Ok(Request::IdentityTrack(at, track, method)) => {
            identity_track(&session, &config, &memory, at, track, method).await
        }
        Ok(Request::Positions) => gather::positions(&session, keys, config.timeout, &memory)
            .await
            .map(|a| json(&a))
            .map_err(|e| e.to_string()),
        Ok(Request::Stats) => match gather::stats(&session, keys, config.timeout).await {
            Ok(leaders) => Ok(json(&StatsAnswer {
                leaders,
                sensors: gather::sensor_stats(&session, keys, config.timeout).await,
                coordinator: memory.stats(),
            })),
            Err(e) => Err(e.to_string()),
        },
    };
    let sent = match result {
        Ok(body) => {
            query
                .reply(query.key_expr().clone(), body)
                .encoding(Encoding::APPLICATION_JSON)
                .await
        }
        Err(error) => {
            if error.starts_with("degraded") {
                memory.note_degraded();
            }
            // The asker gets the reason in the error reply; the log says it
            // only when asked (`RUST_LOG=info`): a stream that has not
            // started yet, or a leader being restarted, is not the
            // coordinator's fault.
            tracing::info!(%error, "query not answered");
            query
                .reply_err(json(&QueryError { error }))
                .encoding(Encoding::APPLICATION_JSON)
                .await
        }
    };
    if let Err(e) = sent {
        tracing::warn!(error = %e, "could not send the reply");
    }
}

async fn track(
    session: &Session,
    config: &CoordinatorConfig,
    memory: &Memory,
    pushes: &Arc<Pushes>,
    at: At,
    track: u32,
) -> Result<ZBytes, String> {
    let gathered = gather::marginals(session, &config.keys, config.timeout, memory, pushes, at)
        .await
        .map_err(|e: GatherError| e.to_string())?;
    let p_red = *gathered.answer.p_red.get(track as usize).ok_or_else(|| {
        format!(
            "track {track} is out of range: there are {} tracks",
            gathered.answer.tracks
        )
    })?;
    Ok(json(&TrackAnswer {
        watermark: gathered.answer.watermark,
        track,
        p_red,
    }))
}

/// Who is on one track: the track's row of the identity answer.
async fn identity_track(
    session: &Session,
    config: &CoordinatorConfig,
    memory: &Memory,
    at: At,
    track: u32,
    method: Method,
) -> Result<ZBytes, String> {
    let answer = identities(session, config, memory, at, method).await?;
    let out_of_range = || {
        format!(
            "track {track} is out of range: there are {} tracks",
            answer.tracks
        )
    };
    let p_identity = answer
        .p_identity
        .get(track as usize)
        .cloned()
        .ok_or_else(out_of_range)?;
    let predicted_identity = *answer
        .predicted_identity
        .get(track as usize)
        .ok_or_else(out_of_range)?;
    Ok(json(&IdentityTrackAnswer {
        watermark: answer.watermark,
        track,
        p_identity,
        predicted_identity,
        marginals: answer.marginals,
        sampling: answer.sampling,
    }))
}

/// Every track's identities, by the method the query names
/// (`?marginals=<method>[;samples=S][;seed=X]`).
async fn identities(
    session: &Session,
    config: &CoordinatorConfig,
    memory: &Memory,
    at: At,
    method: Method,
) -> Result<IdentityAnswer, String> {
    identity::identity(session, config, memory, at, method)
        .await
        .map_err(|e| e.to_string())
}

fn json(value: &impl Serialize) -> ZBytes {
    serde_json::to_vec(value).unwrap_or_default().into()
}
