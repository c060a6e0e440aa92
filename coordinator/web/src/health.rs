//! `/healthz`: the gateway is up (it answers without asking anyone).
//! `/readyz`: every role of the deployment answers — the sensor (its
//! positions name the stream's leaders) and every one of those leader
//! roles in `query/stats`, through the coordinator. 503 names who is
//! missing.

use crate::asker::Asker;
use axum::extract::State;
use axum::http::{header, StatusCode};
use axum::response::{IntoResponse, Response};
use idmesh_protocol::wire::query::{PositionsAnswer, StatsAnswer};
use serde::Serialize;
use std::sync::Arc;

pub(crate) async fn healthz() -> Response {
    (
        [(header::CONTENT_TYPE, "application/json")],
        "{\"up\":true}",
    )
        .into_response()
}

/// What `/readyz` says.
#[derive(Debug, Serialize)]
pub(crate) struct Readiness {
    pub ready: bool,
    /// The leader roles of the stream, and those that did not answer.
    pub leaders: Vec<String>,
    pub missing: Vec<String>,
    /// Why the sensor or the coordinator could not be asked.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub error: Option<String>,
}

pub(crate) async fn readiness(asker: &Asker) -> Readiness {
    let keys = &asker.keys;
    let (positions_key, stats_key) = (keys.query_positions(), keys.query_stats());
    let (positions, stats) = tokio::join!(
        asker.ask(&positions_key, "positions"),
        asker.ask(&stats_key, "stats")
    );
    let not_ready = |error: String| Readiness {
        ready: false,
        leaders: Vec::new(),
        missing: Vec::new(),
        error: Some(error),
    };
    let positions: PositionsAnswer = match positions.error() {
        Some(e) => return not_ready(format!("the sensor's positions: {e}")),
        None => match serde_json::from_slice(&positions.body) {
            Ok(p) => p,
            Err(e) => return not_ready(format!("the positions answer: {e}")),
        },
    };
    let leaders: Vec<String> = positions.leaders.into_iter().map(|l| l.name).collect();
    let answering: Vec<String> = match stats.error() {
        Some(_) => Vec::new(),
        None => serde_json::from_slice::<StatsAnswer>(&stats.body)
            .map(|s| s.leaders.into_iter().map(|l| l.leader).collect())
            .unwrap_or_default(),
    };
    let missing: Vec<String> = leaders
        .iter()
        .filter(|l| !answering.contains(l))
        .cloned()
        .collect();
    Readiness {
        ready: missing.is_empty() && !leaders.is_empty(),
        leaders,
        missing,
        error: stats.error(),
    }
}

pub(crate) async fn readyz(State(asker): State<Arc<Asker>>) -> Response {
    let readiness = readiness(&asker).await;
    let status = if readiness.ready {
        StatusCode::OK
    } else {
        StatusCode::SERVICE_UNAVAILABLE
    };
    let body = serde_json::to_vec(&readiness).unwrap_or_default();
    (status, [(header::CONTENT_TYPE, "application/json")], body).into_response()
}
