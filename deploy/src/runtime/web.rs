//! `idmesh web`: the HTTP/SSE gateway ([`idmesh_web`]) on a Zenoh client
//! session to a deployment's coordinator, like `idmesh query` (and, on a
//! secured deployment, with a client certificate listed in `[security]
//! clients`). Prints its address on stdout once it listens.

use super::mesh::{self, MeshOptions};
use super::security::Tls;
use anyhow::{Context, Result};
use idmesh_protocol::wire::keys::Keys;
use std::time::Duration;

#[derive(Debug, Clone)]
pub struct WebOptions {
    /// Where the HTTP server listens (`127.0.0.1:8080`; port 0 = any free).
    pub listen: String,
    /// The coordinator's Zenoh endpoint.
    pub connect: String,
    pub prefix: String,
    pub timeout: Duration,
    pub tls: Option<Tls>,
    /// Beliefs out to RViz as ROS 2 markers.
    pub markers: Option<idmesh_web::MarkersConfig>,
}

/// How long the gateway waits for the coordinator to listen when it
/// starts.
const CONNECT_PATIENCE: Duration = Duration::from_secs(30);

pub fn run(options: &WebOptions) -> Result<()> {
    let runtime = tokio::runtime::Builder::new_multi_thread()
        .worker_threads(2)
        .enable_all()
        .build()?;
    runtime.block_on(async {
        let session = mesh::open(&MeshOptions {
            client: true,
            listen: vec![],
            connect: mesh::endpoint_list(&options.connect),
            tls: options.tls.clone(),
            // Started beside a deployment, the gateway may come up before
            // the coordinator listens: it waits for it a while.
            connect_patience: Some(CONNECT_PATIENCE),
            ..MeshOptions::default()
        })
        .await?;
        let listener = bind(&options.listen).await?;
        println!("idmesh web: http://{}/", listener.local_addr()?);
        let config = idmesh_web::WebConfig {
            keys: Keys::new(options.prefix.clone()),
            timeout: options.timeout,
            markers: options.markers.clone(),
        };
        idmesh_web::serve(session.clone(), config, listener, super::roles::shutdown()).await?;
        let _ = session.close().await;
        Ok(())
    })
}

/// The HTTP listener, or an error naming the address.
pub(crate) async fn bind(address: &str) -> Result<tokio::net::TcpListener> {
    tokio::net::TcpListener::bind(address)
        .await
        .with_context(|| format!("the web gateway cannot listen on {address}"))
}

/// The gateway inside another command (`idmesh demo`), on its session,
/// until the runtime stops; its address, or why it could not start.
pub(crate) async fn spawn(session: zenoh::Session, prefix: &str, address: &str) -> Result<String> {
    let listener = bind(address).await?;
    let url = format!("http://{}/", listener.local_addr()?);
    let config = idmesh_web::WebConfig {
        keys: Keys::new(prefix),
        timeout: Duration::from_secs(15),
        markers: None,
    };
    tokio::spawn(async move {
        if let Err(e) = idmesh_web::serve(session, config, listener, std::future::pending()).await {
            tracing::warn!(error = %e, "the web gateway stopped");
        }
    });
    Ok(url)
}
