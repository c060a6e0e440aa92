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
//! - `history` — `GET /history`: the last minutes of the charts' figures
//!   (events/s, query latency), sampled by the gateway whether or not a
//!   page is open, so a page opened late starts with the recent past.
//! - `health` — `/healthz` (the gateway is up) and `/readyz` (every role
//!   of the deployment answers).
//! - `markers` — beliefs out to RViz: a `visualization_msgs/MarkerArray`
//!   on a ROS 2 topic over rmw_zenoh, at a fixed rate (`--ros2-markers`).
//! - `asker` — one get to the coordinator, timed, its outcome turned into
//!   an HTTP status.

mod asker;
mod health;
mod history;
mod markers;
mod metrics;
mod page;
mod rest;

use asker::Asker;
use axum::extract::FromRef;
use axum::routing::get;
use axum::Router;
use history::History;
use idmesh_protocol::wire::keys::Keys;
use std::future::Future;
use std::sync::Arc;
use std::time::Duration;

pub use markers::MarkersConfig;

/// What the gateway needs to know of the deployment it serves.
#[derive(Debug, Clone)]
pub struct WebConfig {
    /// The deployment's key prefix (`idmesh/default`).
    pub keys: Keys,
    /// How long one get may wait for the coordinator (longer than the
    /// coordinator's own query timeout, so that its `degraded` answer
    /// arrives rather than none).
    pub timeout: Duration,
    /// Publish the beliefs as ROS 2 markers (None: no).
    pub markers: Option<MarkersConfig>,
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
    let markers = config.markers.clone();
    let gateway = Gateway::new(session, config);
    let sampler = tokio::spawn(history::sample(
        gateway.asker.clone(),
        gateway.history.clone(),
    ));
    let markers = markers.map(|m| tokio::spawn(markers::publish(gateway.asker.clone(), m)));
    let served = axum::serve(listener, app(gateway))
        .with_graceful_shutdown(shutdown)
        .await;
    sampler.abort();
    if let Some(markers) = markers {
        markers.abort();
    }
    Ok(served?)
}

/// What the routes share: the client side to the deployment, and the
/// history the gateway keeps.
#[derive(Clone)]
pub(crate) struct Gateway {
    asker: Arc<Asker>,
    history: Arc<History>,
}

impl Gateway {
    fn new(session: zenoh::Session, config: WebConfig) -> Self {
        Gateway {
            asker: Arc::new(Asker::new(session, config.keys, config.timeout)),
            history: Arc::new(History::new(history::CAPACITY)),
        }
    }
}

impl FromRef<Gateway> for Arc<Asker> {
    fn from_ref(gateway: &Gateway) -> Self {
        gateway.asker.clone()
    }
}

impl FromRef<Gateway> for Arc<History> {
    fn from_ref(gateway: &Gateway) -> Self {
        gateway.history.clone()
    }
}

/// Every route of the gateway.
pub(crate) fn app(gateway: Gateway) -> Router {
    Router::new()
        .route("/", get(page::index))
        .route("/map.js", get(page::script))
        .route("/labels.js", get(page::labels))
        .route("/map.css", get(page::style))
        .route("/history", get(history::history))
        .route("/metrics", get(metrics::metrics))
        .route("/healthz", get(health::healthz))
        .route("/readyz", get(health::readyz))
        .fallback(rest::rest)
        .with_state(gateway)
}
