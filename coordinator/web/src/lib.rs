//! # idmesh-web — the deployment seen from a browser, `curl` and Prometheus
//!
//! An HTTP server (axum) that is itself just a Zenoh client of a running
//! deployment: it asks the coordinator's query API like `idmesh query`
//! does, holds no belief and has no rights of its own (under `[security]`
//! it shows a client certificate listed in `clients`).
//!
//! - `rest` — `GET /<key expression>` answers with the coordinator's JSON
//!   (Zenoh's REST-plugin convention); `Accept: text/event-stream` streams a
//!   fresh answer every `interval=` ms instead (Server-Sent Events).
//! - `page` — the live map at `/`: tracks at their last position coloured
//!   by P(red), leaders and their regions, counters, the degraded state.
//!   Every asset is compiled into the binary: no CDN, no internet.
//! - `metrics` — `GET /metrics` in the OpenMetrics text format: every
//!   process's counters from `query/stats`, the gateway's own query
//!   latency histograms.
//! - `health` — `/healthz` (the gateway is up) and `/readyz` (every role
//!   of the deployment answers).
//! - `asker` — one get to the coordinator, timed, its outcome turned into
//!   an HTTP status.

mod asker;
mod health;
mod metrics;
mod page;
mod rest;

use asker::Asker;
use axum::routing::get;
use axum::Router;
use idmesh_protocol::wire::keys::Keys;
use std::future::Future;
use std::sync::Arc;
use std::time::Duration;

/// What the gateway needs to know of the deployment it serves.
#[derive(Debug, Clone)]
pub struct WebConfig {
    /// The deployment's key prefix (`idmesh/default`).
    pub keys: Keys,
    /// How long one get may wait for the coordinator (longer than the
    /// coordinator's own query timeout, so that its `degraded` answer
    /// arrives rather than none).
    pub timeout: Duration,
}

#[derive(Debug, thiserror::Error)]
pub enum WebError {
    #[error("the HTTP server failed: {0}")]
    Serve(#[from] std::io::Error),
}

/// Serves the gateway on `listener` until `shutdown`.
pub async fn serve(
    session: zenoh::Session,
    config: WebConfig,
    listener: tokio::net::TcpListener,
    shutdown: impl Future<Output = ()> + Send + 'static,
) -> Result<(), WebError> {
    let app = app(session, config);
    axum::serve(listener, app)
        .with_graceful_shutdown(shutdown)
        .await?;
    Ok(())
}

/// Every route of the gateway.
pub(crate) fn app(session: zenoh::Session, config: WebConfig) -> Router {
    let asker = Arc::new(Asker::new(session, config.keys.clone(), config.timeout));
    Router::new()
        .route("/", get(page::index))
        .route("/map.js", get(page::script))
        .route("/map.css", get(page::style))
        .route("/metrics", get(metrics::metrics))
        .route("/healthz", get(health::healthz))
        .route("/readyz", get(health::readyz))
        .fallback(rest::rest)
        .with_state(asker)
}
