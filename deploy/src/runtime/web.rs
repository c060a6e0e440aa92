//! `idmesh web`: the HTTP/SSE gateway ([`idmesh_web`]) on a Zenoh client
//! session to a deployment's coordinator, like `idmesh query` (and, on a
//! secured deployment, with a client certificate listed in `[security]
//! clients`). Prints its address on stdout once it listens. The same
//! gateway runs inside `idmesh demo` and, for a topology with a `[web]`
//! section, inside `idmesh up` ([`spawn`]).
//!
//! Its ROS 2 markers are set by one struct wherever they are given
//! ([`MarkerOptions`]): `idmesh web` and `idmesh demo` take it as flags,
//! a topology's `[web]` as keys of the same names, checked by the same
//! code.

use super::mesh::{self, MeshOptions};
use super::security::Tls;
use anyhow::{bail, Context, Result};
use idmesh_protocol::wire::keys::Keys;
use idmesh_web::MarkersConfig;
use serde::{Deserialize, Serialize};
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
    pub markers: Option<MarkersConfig>,
}

/// Marker arrays a second unless told.
const DEFAULT_RATE: f64 = 2.0;

/// The markers' frame unless told.
const DEFAULT_FRAME: &str = "map";

/// The most marker arrays a second: each look asks the coordinator two or
/// three questions.
const MAX_RATE: f64 = 1000.0;

/// Where the gateway publishes the beliefs as ROS 2 markers, and how: the
/// flags of `idmesh web` and `idmesh demo` (`--ros2-markers TOPIC`,
/// `--ros2-rate`, …) and the keys of a topology's `[web]` section
/// (`ros2_markers = "/idmesh/markers"`, `ros2_rate = …`), one struct so
/// that both say the same and are checked alike ([`MarkerOptions::config`]).
#[derive(Debug, Clone, PartialEq, clap::Args, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct MarkerOptions {
    /// Publish the beliefs as a visualization_msgs/MarkerArray on this
    /// ROS 2 topic over rmw_zenoh (docs/guide/ros2.md).
    #[arg(long, value_name = "TOPIC")]
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub ros2_markers: Option<String>,
    /// The ROS domain id of the markers.
    #[arg(long, default_value_t = 0)]
    #[serde(default, skip_serializing_if = "is_zero")]
    pub ros2_domain: u32,
    /// Marker arrays per second.
    #[arg(long, default_value_t = DEFAULT_RATE)]
    #[serde(default = "default_rate", skip_serializing_if = "is_default_rate")]
    pub ros2_rate: f64,
    /// The markers' frame (RViz's fixed frame).
    #[arg(long, default_value = DEFAULT_FRAME)]
    #[serde(default = "default_frame", skip_serializing_if = "is_default_frame")]
    pub ros2_frame: String,
    /// For ROS 2 Humble: `TypeHashNotSupported` in the markers' key in
    /// place of the type hash.
    #[arg(long)]
    #[serde(default, skip_serializing_if = "std::ops::Not::not")]
    pub ros2_humble: bool,
}

impl MarkerOptions {
    /// The flags of `idmesh web` that set these options (none without a
    /// topic): what a unit file runs for a topology's `[web]`.
    pub fn flags(&self) -> Vec<String> {
        let Some(topic) = &self.ros2_markers else {
            return Vec::new();
        };
        let mut flags = vec![
            "--ros2-markers".to_string(),
            topic.clone(),
            "--ros2-domain".to_string(),
            self.ros2_domain.to_string(),
            "--ros2-rate".to_string(),
            self.ros2_rate.to_string(),
            "--ros2-frame".to_string(),
            self.ros2_frame.clone(),
        ];
        if self.ros2_humble {
            flags.push("--ros2-humble".to_string());
        }
        flags
    }
}

fn default_rate() -> f64 {
    DEFAULT_RATE
}

fn default_frame() -> String {
    DEFAULT_FRAME.to_string()
}

fn is_zero(domain: &u32) -> bool {
    *domain == 0
}

fn is_default_rate(rate: &f64) -> bool {
    *rate == DEFAULT_RATE
}

fn is_default_frame(frame: &str) -> bool {
    frame == DEFAULT_FRAME
}

impl Default for MarkerOptions {
    /// No markers; every setting at the default the flags and keys have.
    fn default() -> Self {
        MarkerOptions {
            ros2_markers: None,
            ros2_domain: 0,
            ros2_rate: DEFAULT_RATE,
            ros2_frame: default_frame(),
            ros2_humble: false,
        }
    }
}

impl MarkerOptions {
    /// The markers these options ask for (None without `ros2_markers`),
    /// or why they cannot be. `field` names a field as its user wrote it
    /// (`--ros2-rate` on the command line, `[web] ros2_rate` in a
    /// topology), so that the one check speaks the language of both.
    pub fn config(&self, field: impl Fn(&str) -> String) -> Result<Option<MarkersConfig>> {
        let rate = self.ros2_rate;
        if !(rate.is_finite() && rate > 0.0 && rate <= MAX_RATE) {
            bail!(
                "{} must be in (0, {MAX_RATE}] arrays a second, got {rate}",
                field("ros2_rate")
            );
        }
        if self.ros2_frame.trim().is_empty() {
            bail!(
                "{} is empty: the markers' frame, like map",
                field("ros2_frame")
            );
        }
        let Some(topic) = &self.ros2_markers else {
            // A setting of markers that are not asked for is a mistake
            // (a forgotten topic), not something to pass over.
            let told = [
                ("ros2_domain", self.ros2_domain != 0),
                ("ros2_rate", !is_default_rate(&self.ros2_rate)),
                ("ros2_frame", !is_default_frame(&self.ros2_frame)),
                ("ros2_humble", self.ros2_humble),
            ];
            if let Some((name, _)) = told.iter().find(|(_, set)| *set) {
                bail!(
                    "{} sets the ROS 2 markers, which are off without {} TOPIC",
                    field(name),
                    field("ros2_markers")
                );
            }
            return Ok(None);
        };
        let part = idmesh_extract::adapters::ros2::keys::topic_part(topic);
        if !topic.starts_with('/') || part.is_empty() || topic.contains(['*', '$', '?', '#']) {
            bail!(
                "{} {topic:?}: a fully qualified ROS topic, like /idmesh/markers",
                field("ros2_markers")
            );
        }
        Ok(Some(MarkersConfig {
            domain: self.ros2_domain,
            topic: topic.clone(),
            frame: self.ros2_frame.clone(),
            every: Duration::from_secs_f64(1.0 / rate),
            humble: self.ros2_humble,
        }))
    }
}

/// How long the gateway waits for the coordinator to listen when it
/// starts.
const CONNECT_PATIENCE: Duration = Duration::from_secs(30);

/// How long one question of a gateway inside another command (`demo`,
/// `up`) may wait for the coordinator: `idmesh web`'s default.
const INNER_TIMEOUT: Duration = Duration::from_secs(15);

pub fn run(options: &WebOptions) -> Result<()> {
    let runtime = tokio::runtime::Builder::new_multi_thread()
        .worker_threads(2)
        .enable_all()
        .build()?;
    runtime.block_on(async {
        let session = client(&options.connect, options.tls.clone()).await?;
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

/// A Zenoh client session to the coordinators of `connect` (one endpoint,
/// or several separated by commas).
pub(crate) async fn client(connect: &str, tls: Option<Tls>) -> Result<zenoh::Session> {
    mesh::open(&MeshOptions {
        client: true,
        listen: vec![],
        connect: mesh::endpoint_list(connect),
        tls,
        // Started beside a deployment, the gateway may come up before
        // the coordinator listens: it waits for it a while.
        connect_patience: Some(CONNECT_PATIENCE),
        ..MeshOptions::default()
    })
    .await
}

/// The HTTP listener, or an error naming the address.
pub(crate) async fn bind(address: &str) -> Result<tokio::net::TcpListener> {
    tokio::net::TcpListener::bind(address)
        .await
        .with_context(|| format!("the web gateway cannot listen on {address}"))
}

/// The gateway inside another command (`idmesh demo`, `idmesh up`), on
/// its session, publishing `markers` if asked, until the runtime stops;
/// its address, or why it could not start.
pub(crate) async fn spawn(
    session: zenoh::Session,
    prefix: &str,
    address: &str,
    markers: Option<MarkersConfig>,
) -> Result<String> {
    let listener = bind(address).await?;
    let url = format!("http://{}/", listener.local_addr()?);
    let config = idmesh_web::WebConfig {
        keys: Keys::new(prefix),
        timeout: INNER_TIMEOUT,
        markers,
    };
    tokio::spawn(async move {
        if let Err(e) = idmesh_web::serve(session, config, listener, std::future::pending()).await {
            tracing::warn!(error = %e, "the web gateway stopped");
        }
    });
    Ok(url)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn flag(field: &str) -> String {
        format!("--{}", field.replace('_', "-"))
    }

    #[test]
    fn markers_are_checked_naming_the_field_as_it_was_given() {
        assert!(MarkerOptions::default().config(flag).unwrap().is_none());
        let asked = MarkerOptions {
            ros2_markers: Some("/idmesh/markers".into()),
            ros2_domain: 4,
            ros2_rate: 5.0,
            ..MarkerOptions::default()
        };
        let config = asked.config(flag).unwrap().unwrap();
        assert_eq!(config.every, Duration::from_millis(200));
        assert_eq!((config.domain, config.frame.as_str()), (4, "map"));
        let error = |options: MarkerOptions| options.config(flag).unwrap_err().to_string();
        for rate in [0.0, -1.0, f64::NAN, 1001.0] {
            let e = error(MarkerOptions {
                ros2_rate: rate,
                ..asked.clone()
            });
            assert!(e.starts_with("--ros2-rate must be in (0, 1000]"), "{e}");
        }
        for topic in ["idmesh/markers", "/", "/idmesh/*"] {
            let e = error(MarkerOptions {
                ros2_markers: Some(topic.into()),
                ..asked.clone()
            });
            assert!(e.starts_with(&format!("--ros2-markers {topic:?}")), "{e}");
        }
        let e = error(MarkerOptions {
            ros2_frame: " ".into(),
            ..asked.clone()
        });
        assert!(e.starts_with("--ros2-frame is empty"), "{e}");
        // A setting without a topic: the forgotten topic is named.
        let e = error(MarkerOptions {
            ros2_markers: None,
            ..asked
        });
        assert!(
            e.starts_with("--ros2-domain sets the ROS 2 markers") && e.contains("--ros2-markers"),
            "{e}"
        );
        let e = MarkerOptions {
            ros2_humble: true,
            ..MarkerOptions::default()
        }
        .config(|f| format!("[web] {f}"))
        .unwrap_err()
        .to_string();
        assert!(e.starts_with("[web] ros2_humble sets"), "{e}");
    }
}
